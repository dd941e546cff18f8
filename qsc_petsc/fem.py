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


def gauss_line(n):
    """n-point Gauss-Legendre rule on [-1, 1]: points (n,), weights (n,)."""
    return np.polynomial.legendre.leggauss(n)


def gauss_quad(n):
    """n x n Gauss rule on the reference square: points (n*n, 2), weights (n*n,)."""
    x, w = gauss_line(n)
    X, Y = np.meshgrid(x, x, indexing="ij")
    return np.column_stack([X.ravel(), Y.ravel()]), np.outer(w, w).ravel()


def gauss_hex(n):
    """n^3 Gauss rule on the reference cube."""
    x, w = gauss_line(n)
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


def gauss_tet(n):
    """Collapsed (Duffy) n^3 Gauss rule on the reference tetrahedron; weights sum to 1/6.

    n = 1 is the centroid rule (exact to degree 1)."""
    if n == 1:
        return np.full((1, 3), 0.25), np.array([1.0 / 6.0])
    x, w = gauss_line(n)
    a, b = 0.5 * (x + 1.0), 0.5 * w
    A, B, C = np.meshgrid(a, a, a, indexing="ij")
    WA, WB, WC = np.meshgrid(b, b, b, indexing="ij")
    xi = A
    eta = B * (1.0 - A)
    zeta = C * (1.0 - A) * (1.0 - B)
    W = WA * WB * WC * (1.0 - A) ** 2 * (1.0 - B)
    return np.column_stack([xi.ravel(), eta.ravel(), zeta.ravel()]), W.ravel()


GAUSS = {"hex": gauss_hex, "tet": gauss_tet, "quad": gauss_quad, "tri": gauss_tri}

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
