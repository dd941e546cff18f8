"""Reference elements: shape functions, quadrature rules and face tables for hex, tet, quad and tri.

Pure NumPy. Node orderings follow VTK (so meshio and ParaView read our cells as they are):

* hex: 0(-1,-1,-1) 1(1,-1,-1) 2(1,1,-1) 3(-1,1,-1), then 4..7 the same at zeta = +1;
* tet: 0(0,0,0) 1(1,0,0) 2(0,1,0) 3(0,0,1);
* quad: 0(-1,-1) 1(1,-1) 2(1,1) 3(-1,1);  tri: 0(0,0) 1(1,0) 2(0,1), N = (1-xi-eta, xi, eta).

Face tables list each face's nodes counter-clockwise seen from outside, so that
(x1 - x0) x (x_last - x0) points out of the cell.
"""

import numpy as np

CELL_NODES = {"hex": 8, "tet": 4}
FACE_NODES = {"quad": 4, "tri": 3}
FACE_TYPE = {"hex": "quad", "tet": "tri"}

# hex faces in the order xmin, xmax, ymin, ymax, zmin, zmax of the reference cube
HEX_FACES = np.array([[3, 0, 4, 7], [1, 2, 6, 5], [0, 1, 5, 4],
                      [2, 3, 7, 6], [0, 3, 2, 1], [4, 5, 6, 7]])
# tet face i is the face opposite node i
TET_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
CELL_FACES = {"hex": HEX_FACES, "tet": TET_FACES}
# each cell's edges, as pairs of its local corners
CELL_EDGES = {"hex": ((0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7)),
              "tet": ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))}

_HEX_SIGNS = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                       [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=float)
_QUAD_SIGNS = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float)


def shape_hex(xi):
    """Trilinear shape functions N (nq, 8) and reference gradients dN (nq, 8, 3) at points xi (nq, 3)."""
    xi = np.atleast_2d(xi)
    s = _HEX_SIGNS
    f = 1.0 + xi[:, None, :] * s[None, :, :]          # (nq, 8, 3): 1 + s_d xi_d
    N = 0.125 * f.prod(axis=2)
    dN = np.empty(f.shape)
    dN[..., 0] = 0.125 * s[:, 0] * f[..., 1] * f[..., 2]
    dN[..., 1] = 0.125 * s[:, 1] * f[..., 0] * f[..., 2]
    dN[..., 2] = 0.125 * s[:, 2] * f[..., 0] * f[..., 1]
    return N, dN


def shape_tet(xi):
    """Linear tetrahedron shape functions N (nq, 4) and constant gradients dN (nq, 4, 3)."""
    xi = np.atleast_2d(xi)
    N = np.column_stack([1.0 - xi.sum(axis=1), xi[:, 0], xi[:, 1], xi[:, 2]])
    g = np.array([[-1.0, -1.0, -1.0], [1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]])
    return N, np.broadcast_to(g, (len(xi), 4, 3)).copy()


def shape_quad(xi):
    """Bilinear shape functions N (nq, 4) and reference gradients dN (nq, 4, 2) at xi (nq, 2)."""
    xi = np.atleast_2d(xi)
    s = _QUAD_SIGNS
    f = 1.0 + xi[:, None, :] * s[None, :, :]
    N = 0.25 * f[..., 0] * f[..., 1]
    dN = np.empty(f.shape)
    dN[..., 0] = 0.25 * s[:, 0] * f[..., 1]
    dN[..., 1] = 0.25 * s[:, 1] * f[..., 0]
    return N, dN


def shape_tri(xi):
    """Linear triangle shape functions N (nq, 3) and constant gradients dN (nq, 3, 2)."""
    xi = np.atleast_2d(xi)
    N = np.column_stack([1.0 - xi[:, 0] - xi[:, 1], xi[:, 0], xi[:, 1]])
    g = np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]])
    return N, np.broadcast_to(g, (len(xi), 3, 2)).copy()


SHAPE = {"hex": shape_hex, "tet": shape_tet, "quad": shape_quad, "tri": shape_tri}


def gauss_line(n, parts=1):
    """n-point Gauss-Legendre rule on [-1, 1], or on each of `parts` equal segments of it (a composite rule):
    points (parts * n,), weights (parts * n,)."""
    x, w = np.polynomial.legendre.leggauss(n)
    if parts == 1:
        return x, w
    left = -1.0 + 2.0 * np.arange(parts) / parts
    return (left[:, None] + (x + 1.0) / parts).ravel(), np.tile(w / parts, parts)


def gauss_quad(n):
    """n x n Gauss rule on the reference square: points (n*n, 2), weights (n*n,)."""
    x, w = gauss_line(n)
    X, Y = np.meshgrid(x, x, indexing="ij")
    return np.column_stack([X.ravel(), Y.ravel()]), np.outer(w, w).ravel()


def gauss_hex(n, parts=1):
    """n^3 Gauss rule on the reference cube (on each of its parts^3 sub-cubes: gauss_line)."""
    x, w = gauss_line(n, parts)
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    W = w[:, None, None] * w[None, :, None] * w[None, None, :]
    return np.column_stack([X.ravel(), Y.ravel(), Z.ravel()]), W.ravel()


def gauss_tri(n):
    """Collapsed (Duffy) n x n Gauss rule on the reference triangle, exact to degree 2n-2; weights sum to 1/2.

    n = 1 is the centroid rule (exact to degree 1): one collapsed point is not."""
    if n == 1:
        return np.full((1, 2), 1.0 / 3.0), np.array([0.5])
    x, w = gauss_line(n)
    a, b = 0.5 * (x + 1.0), 0.5 * w                    # on [0, 1]
    A, B = np.meshgrid(a, a, indexing="ij")
    WA, WB = np.meshgrid(b, b, indexing="ij")
    xi = A.ravel()
    eta = (B * (1.0 - A)).ravel()
    return np.column_stack([xi, eta]), (WA * WB * (1.0 - A)).ravel()


def gauss_tet(n, parts=1):
    """Collapsed (Duffy) n^3 Gauss rule on the reference tetrahedron (composite on parts^3 sub-cubes of the
    collapsed cube: gauss_line); weights sum to 1/6.

    n = 1 is the centroid rule (exact to degree 1)."""
    if n == 1 and parts == 1:
        return np.full((1, 3), 0.25), np.array([1.0 / 6.0])
    x, w = gauss_line(n, parts)
    a, b = 0.5 * (x + 1.0), 0.5 * w
    A, B, C = np.meshgrid(a, a, a, indexing="ij")
    WA, WB, WC = np.meshgrid(b, b, b, indexing="ij")
    xi = A
    eta = B * (1.0 - A)
    zeta = C * (1.0 - A) * (1.0 - B)
    W = WA * WB * WC * (1.0 - A) ** 2 * (1.0 - B)
    return np.column_stack([xi.ravel(), eta.ravel(), zeta.ravel()]), W.ravel()


GAUSS = {"hex": gauss_hex, "tet": gauss_tet, "quad": gauss_quad, "tri": gauss_tri}


def _orbit3(a):
    """The 3 barycentric points (a, a, 1 - 2a) and permutations."""
    b = np.full((3, 3), a)
    np.fill_diagonal(b, 1.0 - 2.0 * a)
    return b


def _orbit6(a, b):
    """The 6 barycentric points (a, b, 1 - a - b) and permutations."""
    c = 1.0 - a - b
    return np.array([[a, b, c], [a, c, b], [b, a, c], [b, c, a], [c, a, b], [c, b, a]])


def _unit(w):
    """Tabulated weights (15 digits) scaled to sum to 1 exactly."""
    return w / w.sum()


def symmetric_collapsed(n):
    """The collapsed n x n rule (gauss_tri) taken from each of the three vertices, each at a third of the weight:
    3 n^2 barycentric points, weights summing to 1, exact to degree 2n - 2. The collapsed rule is symmetric in the
    two vertices it does not collapse to, so the three together are in all three."""
    xi, w = gauss_tri(n)
    b = np.column_stack([1.0 - xi[:, 0] - xi[:, 1], xi[:, 0], xi[:, 1]])
    return np.vstack([np.roll(b, k, axis=1) for k in range(3)]), np.tile(2.0 * w / 3.0, 3)


def triangle_rule(degree):
    """Rule on a triangle exact for polynomials of total degree `degree`: barycentric points (r, 3), weights (r,)
    summing to 1, symmetric in the three vertices (so that a rule's points do not depend on the order a face
    lists its vertices in: a mirror image's faces list theirs otherwise).

    Rules with positive weights and interior points: Strang-Fix / Dunavant closed forms up to degree 5, Dunavant's
    12 points (degree 6) and 16 points (degree 8); symmetric_collapsed above.
    """
    degree = int(degree)
    if degree < 0:
        raise ValueError(f"triangle_rule: degree must be >= 0, got {degree}")
    if degree <= 1:
        return np.full((1, 3), 1.0 / 3.0), np.ones(1)
    if degree == 2:
        return _orbit3(1.0 / 6.0), np.full(3, 1.0 / 3.0)
    if degree <= 4:                          # 6 points; the 6-point degree-3 rule's weights are no better
        s = np.sqrt(38.0 - 44.0 * np.sqrt(0.4))
        a1, a2 = (8.0 - np.sqrt(10.0) + s) / 18.0, (8.0 - np.sqrt(10.0) - s) / 18.0
        r = np.sqrt(213125.0 - 53320.0 * np.sqrt(10.0))
        w1, w2 = (620.0 + r) / 3720.0, (620.0 - r) / 3720.0
        return np.vstack([_orbit3(a1), _orbit3(a2)]), np.repeat([w1, w2], 3)
    if degree == 5:                          # Radon's 7 points
        q = np.sqrt(15.0)
        return (np.vstack([np.full((1, 3), 1.0 / 3.0), _orbit3((6.0 - q) / 21.0), _orbit3((6.0 + q) / 21.0)]),
                np.concatenate([[9.0 / 40.0], np.full(3, (155.0 - q) / 1200.0), np.full(3, (155.0 + q) / 1200.0)]))
    if degree == 6:                          # Dunavant's 12 points
        return (np.vstack([_orbit3(0.063089014491502), _orbit3(0.249286745170910),
                           _orbit6(0.053145049844817, 0.310352451033784)]),
                _unit(np.repeat([0.050844906370207, 0.116786275726379, 0.082851075618374], [3, 3, 6])))
    if degree <= 8:                          # Dunavant's 16 points
        return (np.vstack([np.full((1, 3), 1.0 / 3.0), _orbit3(0.459292588292723), _orbit3(0.170569307751760),
                           _orbit3(0.050547228317031), _orbit6(0.008394777409958, 0.263112829634638)]),
                _unit(np.repeat([0.144315607677787, 0.095091634267285, 0.103217370534718, 0.032458497623198,
                                 0.027230314174435], [1, 3, 3, 3, 6])))
    return symmetric_collapsed((degree + 3) // 2)


# the contact Gauss option's triangle rule for gauss_points = n: symmetric, at least n^2 points and exact to degree
# 2n - 2 at least, as the n x n rule on a quad
_CONTACT_TRI_DEGREE = {1: 1, 2: 4, 3: 6, 4: 8}


def contact_face_rule(face_type, n):
    """The rule of a contact pass's Gauss points (integration = "gauss", gauss_points = n) on the reference face:
    points (q, 2), weights (q,). Quads: n x n Gauss. Triangles: a rule symmetric in the vertices (triangle_rule:
    1, 6, 12, 16 points for n = 1-4, symmetric_collapsed's 3 n^2 above), not the collapsed n x n rule, whose points
    follow the order of the face's vertices: a tet mesh and its mirror image took different points, and a
    symmetric punch on tets came out 13 % apart in traction at mirror nodes (hunt28_1)."""
    if face_type == "quad":
        return gauss_quad(n)
    b, w = triangle_rule(_CONTACT_TRI_DEGREE[n]) if n in _CONTACT_TRI_DEGREE else symmetric_collapsed(n)
    return b[:, 1:], 0.5 * w

# reference-element centroids (where cell stresses are reported)
CENTROID = {"hex": np.zeros(3), "tet": np.full(3, 0.25),
            "quad": np.zeros(2), "tri": np.full(2, 1.0 / 3.0)}


def cell_faces(cell_type, cells, local_faces):
    """Node lists (k, nv) of the faces `local_faces` (k,) of cells `cells` (k, n_cell_nodes)."""
    table = CELL_FACES[cell_type]
    return np.take_along_axis(np.asarray(cells), table[np.asarray(local_faces)], axis=1)


def face_tangents(face_type, xf, xi):
    """Surface tangents (m, nq, 3, 2) of faces with node coordinates xf (m, nv, 3) at reference points xi (nq, 2)."""
    _, dN = SHAPE[face_type](xi)
    return np.einsum("mvi,qva->mqia", xf, dN)


def face_normals(face_type, xf, xi):
    """Outward unit normals (m, nq, 3) and area densities |dA/dxi| (m, nq) of faces at reference points xi."""
    t = face_tangents(face_type, xf, xi)
    n = np.cross(t[..., 0], t[..., 1])
    jac = np.linalg.norm(n, axis=-1)
    return n / jac[..., None], jac


def centroid_normals(face_type, xf):
    """Outward unit normals (m, 3) of faces with node coordinates xf (m, nv, 3) at their reference centroids."""
    return face_normals(face_type, xf, CENTROID[face_type][None, :])[0][:, 0]


def face_nodal_areas(face_type, xf, n_gauss=2):
    """Tributary areas int_f N_i ds (m, nv) of each node of faces with coordinates xf (m, nv, 3)."""
    xi, w = GAUSS[face_type](n_gauss)
    N, _ = SHAPE[face_type](xi)
    _, jac = face_normals(face_type, xf, xi)
    return np.einsum("mq,q,qv->mv", jac, w, N)


def face_pressure_loads(face_type, xf, pressure, n_gauss=2):
    """Consistent nodal forces (m, nv, 3) of a pressure acting against the outward normal of each face.

    pressure: a number, per face (m,), or a function of points (n, 3) -> (n,) evaluated at the Gauss points."""
    xi, w = GAUSS[face_type](n_gauss)
    N, _ = SHAPE[face_type](xi)
    t = face_tangents(face_type, xf, xi)
    dA = np.cross(t[..., 0], t[..., 1])                # outward normal times area density
    if callable(pressure):
        p = pressure(np.einsum("qv,mvi->mqi", N, xf).reshape(-1, 3)).reshape(len(xf), len(w))
    else:
        p = np.broadcast_to(np.asarray(pressure, dtype=float).reshape(-1, 1), (len(xf), len(w)))
    return -np.einsum("mq,q,qv,mqi->mvi", p, w, N, dA)


def face_size(xf):
    """In-plane size of each face (m,): the square root of its area for quads, of twice its area for triangles."""
    nv = xf.shape[1]
    if nv == 4:
        a = 0.5 * np.linalg.norm(np.cross(xf[:, 2] - xf[:, 0], xf[:, 3] - xf[:, 1]), axis=1)
        return np.sqrt(a)
    a = 0.5 * np.linalg.norm(np.cross(xf[:, 1] - xf[:, 0], xf[:, 2] - xf[:, 0]), axis=1)
    return np.sqrt(2.0 * a)
