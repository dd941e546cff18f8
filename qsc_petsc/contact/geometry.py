"""Closest-point projection of points on linear triangles and bilinear (possibly warped) quadrilaterals.

Pure NumPy, vectorised over (point, face) pairs: entry i projects points[i] on
face_xyz[i]. Natural coordinates follow qsc_petsc.fem: N = (1 - xi - eta, xi,
eta) on triangles, (xi, eta) in [-1, 1]^2 on quads (VTK node order). Every
per-pair quantity is computed elementwise with a fixed order of operations, so
a pair gives bit-identical results wherever it sits in the input arrays (the
search's rank-independence relies on this).
"""

from dataclasses import dataclass

import numpy as np

from qsc_petsc import fem

# how far outside the face (in natural coordinates) an orthogonal projection
# still counts as "inside"; round-off on a shared edge is ~1e-15
INSIDE_TOL = 1e-8
NEWTON_TOL = 1e-13          # on the natural-coordinate update (xi is O(1))
NEWTON_MAX_IT = 30
_FAR = 2.0                  # |xi| beyond which a quad Newton iterate is abandoned for the edges

# quad edges as (start node, end node, xi at start, xi at end), in VTK order
_QUAD_EDGES = ((0, 1, (-1.0, -1.0), (1.0, -1.0)),
               (1, 2, (1.0, -1.0), (1.0, 1.0)),
               (2, 3, (1.0, 1.0), (-1.0, 1.0)),
               (3, 0, (-1.0, 1.0), (-1.0, -1.0)))
_TRI_EDGES = ((0, 1, (0.0, 0.0), (1.0, 0.0)),
              (1, 2, (1.0, 0.0), (0.0, 1.0)),
              (2, 0, (0.0, 1.0), (0.0, 0.0)))


@dataclass
class Projection:
    """Closest point of each point on its face: natural coordinates, shape values, point, normal, distance."""
    xi: np.ndarray          # (p, 2) natural coordinates of the closest point
    shape: np.ndarray       # (p, nv) N(xi)
    closest: np.ndarray     # (p, 3)
    normal: np.ndarray      # (p, 3) the face's outward unit normal at xi
    distance: np.ndarray    # (p,) |point - closest|
    inside: np.ndarray      # (p,) bool: the orthogonal projection falls in the face (up to INSIDE_TOL)


def _dot(a, b):
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def _interp(values, N):
    """sum_v N[:, v] * values[:, v] with a fixed summation order; values (p, nv, ...), N (p, nv)."""
    out = N[:, 0, None] * values[:, 0]
    for v in range(1, values.shape[1]):
        out = out + N[:, v, None] * values[:, v]
    return out


def cross(a, b):
    """a x b over the last axis (length 3), written out: NumPy's cross costs 3x as much on many short vectors."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def face_tangents_at(face_type, face_xyz, xi):
    """Tangents dx/dxi, dx/deta (p, 3), (p, 3) of face i at its own point xi[i] (fem.face_tangents evaluates all x all):
    on a quad (VTK order) dx/dxi = ((1 - eta) (x1 - x0) + (1 + eta) (x2 - x3)) / 4 and its like, written out."""
    x = face_xyz
    if face_type == "tri":
        return x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]
    xi = np.atleast_2d(xi)
    e, h = xi[:, 0, None], xi[:, 1, None]
    t1 = 0.25 * ((1.0 - h) * (x[:, 1] - x[:, 0]) + (1.0 + h) * (x[:, 2] - x[:, 3]))
    t2 = 0.25 * ((1.0 - e) * (x[:, 3] - x[:, 0]) + (1.0 + e) * (x[:, 2] - x[:, 1]))
    return t1, t2


def face_area_density_at(face_type, face_xyz, xi):
    """|dx/dxi x dx/deta| (p,) of face i at xi[i]: area per unit natural area."""
    n = cross(*face_tangents_at(face_type, face_xyz, xi))
    return np.sqrt(_dot(n, n))


def face_normal_at(face_type, face_xyz, xi):
    """Outward unit normal (p, 3) of face i at xi[i], the same convention as fem.face_normals."""
    n = cross(*face_tangents_at(face_type, face_xyz, xi))
    return n / np.sqrt(_dot(n, n))[:, None]


def _solve2(a11, a12, a22, b1, b2):
    """Solve the symmetric 2x2 systems [[a11, a12], [a12, a22]] x = b, elementwise."""
    det = a11 * a22 - a12 * a12
    return (a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det


def _closest_on_edges(points, face_xyz, edges):
    """Closest point on the straight edges of each face: xi (p, 2), squared distance (p,)."""
    best_d2 = np.full(len(points), np.inf)
    best_xi = np.zeros((len(points), 2))
    for i0, i1, xi0, xi1 in edges:
        a, b = face_xyz[:, i0], face_xyz[:, i1]
        e = b - a
        t = np.clip(_dot(points - a, e) / _dot(e, e), 0.0, 1.0)
        r = points - (a + t[:, None] * e)
        d2 = _dot(r, r)
        better = d2 < best_d2            # strict: the first edge wins a tie, the same for any input order
        best_d2 = np.where(better, d2, best_d2)
        xi = np.column_stack([xi0[0] + t * (xi1[0] - xi0[0]), xi0[1] + t * (xi1[1] - xi0[1])])
        best_xi = np.where(better[:, None], xi, best_xi)
    return best_xi, best_d2


def _project_tri(points, face_xyz):
    """Closed form: orthogonal projection on the plane, else the closest point on the three edges."""
    x0 = face_xyz[:, 0]
    e1, e2 = face_xyz[:, 1] - x0, face_xyz[:, 2] - x0
    r = points - x0
    xi, eta = _solve2(_dot(e1, e1), _dot(e1, e2), _dot(e2, e2), _dot(e1, r), _dot(e2, r))
    inside = (xi >= -INSIDE_TOL) & (eta >= -INSIDE_TOL) & (xi + eta <= 1.0 + INSIDE_TOL)
    xi_out = np.column_stack([xi, eta])
    if not inside.all():
        out = ~inside
        xi_out[out] = _closest_on_edges(points[out], face_xyz[out], _TRI_EDGES)[0]
    # round-off just outside the face: pull back onto it
    xi_out = np.clip(xi_out, 0.0, 1.0)
    s = xi_out[:, 0] + xi_out[:, 1]
    over = s > 1.0
    xi_out[over] /= s[over, None]
    return xi_out, inside


def _project_quad(points, face_xyz):
    """Newton on (x(xi) - p) . dx/dxi_a = 0 from the flat-quad guess; clamped to the edges if it lands outside."""
    p = len(points)
    x = face_xyz
    s = 0.25
    x_c = s * (x[:, 0] + x[:, 1] + x[:, 2] + x[:, 3])
    a1 = s * (-x[:, 0] + x[:, 1] + x[:, 2] - x[:, 3])      # dx/dxi at the centre
    a2 = s * (-x[:, 0] - x[:, 1] + x[:, 2] + x[:, 3])      # dx/deta at the centre
    a12 = s * (x[:, 0] - x[:, 1] + x[:, 2] - x[:, 3])      # the twist d2x/dxi deta (0 on a parallelogram)
    r0 = points - x_c
    g1, g2 = _solve2(_dot(a1, a1), _dot(a1, a2), _dot(a2, a2), _dot(a1, r0), _dot(a2, r0))
    xi = np.column_stack([g1, g2])
    converged = np.zeros(p, dtype=bool)
    todo = np.arange(p)
    for _ in range(NEWTON_MAX_IT):
        if len(todo) == 0:
            break
        q = xi[todo]
        t1 = a1[todo] + q[:, 1, None] * a12[todo]
        t2 = a2[todo] + q[:, 0, None] * a12[todo]
        # x(xi) - p from the centre's offset r0, not from the coordinates: far from the origin (|x| / h above ~500)
        # their difference's round-off, eps |x| / h in xi, kept every step above NEWTON_TOL and the point went to
        # an edge, with no row (a body 1000 m off: 16 % of the rows lost, exit 0; hunt30_1)
        r = q[:, 0, None] * a1[todo] + q[:, 1, None] * a2[todo] + (q[:, 0] * q[:, 1])[:, None] * a12[todo] - r0[todo]
        f1, f2 = _dot(r, t1), _dot(r, t2)
        j11, j22 = _dot(t1, t1), _dot(t2, t2)
        j12 = _dot(t1, t2) + _dot(r, a12[todo])
        # far from a strongly warped face the Hessian may be indefinite: fall back to Gauss-Newton there
        indefinite = j11 * j22 - j12 * j12 <= 1e-12 * j11 * j22
        j12 = np.where(indefinite, _dot(t1, t2), j12)
        d1, d2 = _solve2(j11, j12, j22, -f1, -f2)
        step = np.maximum(np.abs(d1), np.abs(d2))
        damp = np.minimum(1.0, 1.0 / np.maximum(step, 1e-300))     # at most a unit step in xi
        q = q + damp[:, None] * np.column_stack([d1, d2])
        # an iterate this far out means the closest point is on an edge: stop (not converged -> edges)
        far = (np.abs(q) >= _FAR).any(axis=1)
        xi[todo] = q
        done = step < NEWTON_TOL
        converged[todo[done & ~far]] = True
        todo = todo[~(done | far)]
    inside = converged & (np.abs(xi) <= 1.0 + INSIDE_TOL).all(axis=1)
    if not inside.all():
        out = ~inside
        xi[out] = _closest_on_edges(points[out], face_xyz[out], _QUAD_EDGES)[0]
    return np.clip(xi, -1.0, 1.0), inside


def project_on_faces(points, face_xyz, face_type):
    """Closest point of points[i] (p, 3) on face face_xyz[i] (p, nv, 3) of type "tri" or "quad"."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    face_xyz = np.asarray(face_xyz, dtype=float)
    if face_type not in fem.FACE_NODES:
        raise ValueError(f"face_type must be 'tri' or 'quad', got {face_type!r}")
    nv = fem.FACE_NODES[face_type]
    if face_xyz.shape != (len(points), nv, 3):
        raise ValueError(f"face_xyz must have shape ({len(points)}, {nv}, 3) for {face_type} faces, "
                         f"got {face_xyz.shape}")
    if len(points) == 0:
        return Projection(np.zeros((0, 2)), np.zeros((0, nv)), np.zeros((0, 3)), np.zeros((0, 3)),
                          np.zeros(0), np.zeros(0, dtype=bool))
    with np.errstate(divide="ignore", invalid="ignore"):
        if face_type == "tri":
            xi, inside = _project_tri(points, face_xyz)
        else:
            xi, inside = _project_quad(points, face_xyz)
    N, _ = fem.SHAPE[face_type](xi)
    closest = _interp(face_xyz, N)
    r = points - closest
    return Projection(xi=xi, shape=N, closest=closest, normal=face_normal_at(face_type, face_xyz, xi),
                      distance=np.sqrt(_dot(r, r)), inside=inside)
