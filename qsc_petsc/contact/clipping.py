"""Geometry of exact (segment) contact integration: candidate S/T face pairs, their overlaps clipped in S's plane, and quadrature points on the overlaps.

Pure NumPy (formulation.md section 8), vectorised over face pairs: the Python
loops run over clipping edges (<= 4), polygon vertices (<= 8) and Newton
iterations, never over pairs. Each pair is worked in the plane through the S
face's centroid normal to S there (2-D coordinates relative to that centroid,
so the round-off scales with the face, not with the model). Both faces are
projected on that plane along its normal; the edges of a bilinear quad are
straight, so its projection is the quadrilateral of its projected nodes, and a
point of the plane pulls back to S and T by inverting the projected (linear or
bilinear) maps. Natural coordinates follow qsc_petsc.fem.
"""

import numpy as np

from qsc_petsc import fem
from qsc_petsc.contact.geometry import cross, face_normal_at, face_tangents_at
from qsc_petsc.errors import MeshError
from qsc_petsc.fem import triangle_rule

NEWTON_TOL = 1e-13          # on the natural-coordinate update (xi is O(1))
NEWTON_MAX_IT = 50
# sub-triangles of an overlap smaller than this fraction of the S face (in S's plane) carry no area:
# what is left of edge or vertex contacts, and duplicated clip vertices
AREA_TOL = 1e-12
# a face may cover this many grid cells on average before the cells are made coarser
_MAX_CELLS_PER_FACE = 27
_CHUNK = 16384              # pairs worked at once: bounds the per-point temporaries (~1 kB per pair)


def _empty_pairs():
    return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)


def candidate_pairs(xs, xt, distance):
    """Index pairs (i, j) of S faces xs (m, nvs, 3) and T faces xt (n, nvt, 3) whose bounding boxes are within distance.

    The axis-aligned box of S face i, inflated by distance [m] on every side,
    overlaps the box of T face j (equivalently: on each axis the two boxes are
    at most distance apart). Uniform bucket grid, O((m + n) log(m + n) + pairs):
    each box is entered in the cells it covers, boxes sharing a cell are tested
    exactly, and a pair is kept only in the cell holding the low corner of the
    boxes' intersection, so no pair is listed twice. Returns (i, j), int64,
    sorted by i then j.
    """
    xs = np.asarray(xs, dtype=float)
    xt = np.asarray(xt, dtype=float)
    for name, a in (("xs", xs), ("xt", xt)):
        if a.ndim != 3 or a.shape[2] != 3:
            raise ValueError(f"candidate_pairs: {name} must have shape (faces, nodes, 3), got {a.shape}")
    if not distance >= 0:
        raise ValueError(f"candidate_pairs: distance must be >= 0, got {distance}")
    if len(xs) == 0 or len(xt) == 0:
        return _empty_pairs()
    lo = [xs.min(axis=1) - distance, xt.min(axis=1)]
    hi = [xs.max(axis=1) + distance, xt.max(axis=1)]

    # only the region both sets reach can hold a pair; boxes are cut to it
    origin = np.maximum(lo[0].min(axis=0), lo[1].min(axis=0))
    top = np.minimum(hi[0].max(axis=0), hi[1].max(axis=0))
    if (top < origin).any():
        return _empty_pairs()
    idx, clo, chi = [], [], []
    for k in range(2):
        a, b = np.maximum(lo[k], origin), np.minimum(hi[k], top)
        keep = np.flatnonzero((a <= b).all(axis=1))
        idx.append(keep)
        clo.append(a[keep])
        chi.append(b[keep])
    if len(idx[0]) == 0 or len(idx[1]) == 0:
        return _empty_pairs()

    # cells as large as the typical box of the coarser side: a few cells per box, few boxes per cell
    h = max(float(np.median((hi[k] - lo[k]).max(axis=1))) for k in range(2))
    span = float((top - origin).max())
    if not h > 0:
        h = span if span > 0 else 1.0
    nbox = len(idx[0]) + len(idx[1])
    while True:
        ncell = np.floor((top - origin) / h).astype(np.int64) + 1
        c0 = [np.floor((clo[k] - origin) / h).astype(np.int64) for k in range(2)]
        c1 = [np.floor((chi[k] - origin) / h).astype(np.int64) for k in range(2)]
        count = [(c1[k] - c0[k] + 1).prod(axis=1) for k in range(2)]
        total = int(count[0].sum() + count[1].sum())
        if total <= _MAX_CELLS_PER_FACE * nbox + 1000 and float(np.prod(ncell.astype(float))) < 2.0 ** 62:
            break
        h *= 2.0

    def cell_id(c):
        return c[..., 0] + ncell[0] * (c[..., 1] + ncell[1] * c[..., 2])

    def entries(k):
        """(box, cell) for every cell box k covers."""
        box = np.repeat(np.arange(len(c0[k]), dtype=np.int64), count[k])
        r = np.arange(len(box), dtype=np.int64) - np.repeat(np.cumsum(count[k]) - count[k], count[k])
        nx = (c1[k][:, 0] - c0[k][:, 0] + 1)[box]
        ny = (c1[k][:, 1] - c0[k][:, 1] + 1)[box]
        c = c0[k][box] + np.column_stack([r % nx, (r // nx) % ny, r // (nx * ny)])
        return box, cell_id(c)

    sbox, scell = entries(0)
    tbox, tcell = entries(1)
    order = np.argsort(tcell, kind="stable")
    tbox, tcell = tbox[order], tcell[order]
    start = np.searchsorted(tcell, scell, side="left")
    n_in = np.searchsorted(tcell, scell, side="right") - start
    ps = np.repeat(sbox, n_in)
    pc = np.repeat(scell, n_in)
    off = np.arange(len(ps), dtype=np.int64) - np.repeat(np.cumsum(n_in) - n_in, n_in)
    pt = tbox[np.repeat(start, n_in) + off]

    overlap = ((clo[0][ps] <= chi[1][pt]) & (clo[1][pt] <= chi[0][ps])).all(axis=1)
    ps, pt, pc = ps[overlap], pt[overlap], pc[overlap]
    low = np.maximum(clo[0][ps], clo[1][pt])
    own = cell_id(np.floor((low - origin) / h).astype(np.int64)) == pc
    i, j = idx[0][ps[own]], idx[1][pt[own]]
    srt = np.lexsort((j, i))
    return i[srt].astype(np.int64), j[srt].astype(np.int64)


def _cross2(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _corner_turns(P):
    """cross(P[k] - P[k-1], P[k+1] - P[k]) at every corner of polygons P (m, n, 2): all > 0 iff strictly convex and ccw."""
    return _cross2(P - np.roll(P, 1, axis=1), np.roll(P, -1, axis=1) - P)


def _clip(poly, count, clip):
    """Sutherland-Hodgman: convex polygons poly (m, w, 2) with count vertices, cut by the convex ccw polygons clip (m, c, 2).

    A vertex on a clip edge counts as inside; the crossing point is computed
    from the previous vertex, so an edge meets a clip line in one place.
    Returns the padded polygons and their vertex counts (0 when < 3 are left).
    """
    m = len(poly)
    for k in range(clip.shape[1]):
        a = clip[:, k, None, :]
        d = clip[:, (k + 1) % clip.shape[1], None, :] - a
        w = poly.shape[1]
        col = np.arange(w)[None, :]
        valid = col < count[:, None]
        prev = np.where(col == 0, np.maximum(count[:, None] - 1, 0), col - 1)
        s = _cross2(d, poly - a)                       # > 0 left of the edge: inside
        s_prev = np.take_along_axis(s, prev, axis=1)
        v_prev = np.take_along_axis(poly, prev[..., None], axis=1)
        inside = s >= 0.0
        crosses = valid & (inside != (s_prev >= 0.0))
        t = np.where(crosses, s_prev / np.where(crosses, s_prev - s, 1.0), 0.0)
        cand = np.stack([v_prev + t[..., None] * (poly - v_prev), poly], axis=2).reshape(m, 2 * w, 2)
        emit = np.stack([crosses, valid & inside], axis=2).reshape(m, 2 * w)
        count = emit.sum(axis=1)
        pos = np.cumsum(emit, axis=1) - 1
        r, c = np.nonzero(emit)
        poly = np.zeros((m, max(int(count.max()), 3), 2))
        poly[r, pos[r, c]] = cand[r, c]
        count = np.where(count >= 3, count, 0)
    return poly, count


def _monomials(face_type):
    """B (4, nv) with x(xi, eta) = c + xi a1 + eta a2 + xi eta a12, (c, a1, a2, a12) = B @ X, X (nv, d) the nodes.

    Read off fem's shape functions: c = x(0, 0), a1 and a2 the tangents there,
    a12 = dx/dxi(0, 1) - dx/dxi(0, 0) the twist (0 on triangles and parallelograms).
    """
    N, dN = fem.SHAPE[face_type](np.array([[0.0, 0.0], [0.0, 1.0]]))
    return np.vstack([N[0], dN[0, :, 0], dN[0, :, 1], dN[1, :, 0] - dN[0, :, 0]])


def _inverse_map(K, p, what, split=8):
    """Natural coordinates (t, r, 2) of plane points p (t, r, 2) in the maps K (t, 4, 2) (rows c, a1, a2, a12).

    Exact for affine maps; Newton from the affine guess otherwise, on all points
    together, then (from iteration `split`) on the stragglers alone. Components are
    kept in separate contiguous arrays: twice as fast as strided (..., 2) slices.
    """
    (cx, cy), (ax, ay), (bx, by), (tx, ty) = (K[:, k, :].T[:, :, None] for k in range(4))
    rx, ry = p[..., 0] - cx, p[..., 1] - cy
    det = ax * by - ay * bx
    xi, eta = (rx * by - ry * bx) / det, (ax * ry - ay * rx) / det
    if not (tx.any() or ty.any()):
        return np.stack([xi, eta], axis=-1)
    todo = None                                  # (triangle, point) of the stragglers, once split off
    done = np.zeros(xi.shape, dtype=bool)
    for it in range(NEWTON_MAX_IT):
        if it == split and todo is None:
            todo = np.nonzero(~done)
            ax, ay, bx, by, tx, ty = (v[todo[0], 0] for v in (ax, ay, bx, by, tx, ty))
            rx, ry, xi_all, eta_all = rx[todo], ry[todo], xi, eta
            xi, eta = xi[todo], eta[todo]
        t1x, t1y = ax + eta * tx, ay + eta * ty
        t2x, t2y = bx + xi * tx, by + xi * ty
        xe = xi * eta
        fx = rx - xi * ax - eta * bx - xe * tx
        fy = ry - xi * ay - eta * by - xe * ty
        det = t1x * t2y - t1y * t2x
        d1, d2 = (fx * t2y - fy * t2x) / det, (t1x * fy - t1y * fx) / det
        xi, eta = xi + d1, eta + d2
        done = np.maximum(np.abs(d1), np.abs(d2)) < NEWTON_TOL
        if todo is not None:
            xi_all[todo], eta_all[todo] = xi, eta
            keep = ~done
            todo = (todo[0][keep], todo[1][keep])
            ax, ay, bx, by, tx, ty, rx, ry, xi, eta = (v[keep] for v in (ax, ay, bx, by, tx, ty, rx, ry, xi, eta))
            done = done[keep]
        if done.all():
            return np.stack([xi, eta] if todo is None else [xi_all, eta_all], axis=-1)
    raise MeshError(f"segment_quadrature: the inverse bilinear map of the {what} face did not converge at "
                    f"{int((~done).sum())} point(s) in {NEWTON_MAX_IT} Newton iterations "
                    f"(face folded in the S face's plane)")


def _plane_frames(type_s, xs):
    """Centroid (m, 3), unit normal n (m, 3) and in-plane axes e1, e2 (m, 3) of S faces; (e1, e2, n) right-handed, e1 along dx/dxi."""
    xi_c = np.broadcast_to(fem.CENTROID[type_s], (len(xs), 2))
    N, _ = fem.SHAPE[type_s](xi_c[:1])
    centre = np.einsum("v,mvi->mi", N[0], xs)
    n = face_normal_at(type_s, xs, xi_c)
    t1, _ = face_tangents_at(type_s, xs, xi_c)
    e1 = t1 - np.einsum("mi,mi->m", t1, n)[:, None] * n
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    return centre, n, e1, cross(n, e1)


def not_convex(type_s, xs):
    """Whether each face xs (m, n, 3) is not strictly convex in its own plane (a reflex or straight corner, or a
    degenerate face): segment rows cannot clip it (segment_quadrature)."""
    if len(xs) == 0:
        return np.zeros(0, dtype=bool)
    centre, _, e1, e2 = _plane_frames(type_s, xs)
    r = xs - centre[:, None, :]
    p = np.stack([np.einsum("mvi,mi->mv", r, e1), np.einsum("mvi,mi->mv", r, e2)], axis=-1)
    return ~(_corner_turns(p) > 0.0).all(axis=1)


def _empty_result():
    return {"pair": np.zeros(0, dtype=np.int64), "x": np.zeros((0, 3)), "xi_s": np.zeros((0, 2)),
            "xi_t": np.zeros((0, 2)), "weight": np.zeros(0)}


def segment_quadrature(type_s, xs, type_t, xt, degree=4, area_tol=AREA_TOL, max_normal_dot=None, chunk=_CHUNK):
    """Quadrature of the overlap of each pair of faces: S face xs[k] (nvs, 3) and T face xt[k] (nvt, 3), k = 0..m-1.

    Both faces are projected on the plane through S's centroid normal to S
    there; the T polygon is clipped by the S polygon (Sutherland-Hodgman), the
    overlap cut into a fan of triangles, and triangle_rule(degree) put on each.
    Returns a dict of arrays over the q points, grouped by pair in increasing k:
      pair   (q,)   int64 index k of the face pair
      x      (q, 3) point on the S face
      xi_s   (q, 2) natural coordinates of x on S
      xi_t   (q, 2) natural coordinates on T of the point of T on the line through x along S's plane normal
      weight (q,)   area on the S surface [m^2]: the plane weight times |t1 x t2| / |(t1 x t2) . n| at xi_s,
                    so one pair's weights sum to its overlap's area on S (exactly when S is flat)
    Zero-area overlaps (faces touching along an edge or at a vertex) and
    sub-triangles smaller than area_tol times the S face give no points. A T face
    whose projection is folded or not strictly convex (seen edge-on from S) is
    skipped, as is, when max_normal_dot is given, every T face whose centroid
    normal n_T has n_S . n_T > max_normal_dot (e.g. -0.1 keeps only faces turned
    towards S). An S face not strictly convex in its own plane raises MeshError.
    """
    for name, ft in (("type_s", type_s), ("type_t", type_t)):
        if ft not in fem.FACE_NODES:
            raise ValueError(f"segment_quadrature: {name} must be 'tri' or 'quad', got {ft!r}")
    xs = np.asarray(xs, dtype=float)
    xt = np.asarray(xt, dtype=float)
    m = len(xs)
    for name, a, ft in (("xs", xs, type_s), ("xt", xt, type_t)):
        if a.shape != (m, fem.FACE_NODES[ft], 3):
            raise ValueError(f"segment_quadrature: {name} must have shape ({m}, {fem.FACE_NODES[ft]}, 3) "
                             f"for {ft} faces, got {a.shape}")
    bary, wr = triangle_rule(degree)
    parts = [_segment_chunk(type_s, xs[k:k + chunk], type_t, xt[k:k + chunk], bary, wr, area_tol, max_normal_dot, k)
             for k in range(0, m, max(int(chunk), 1))]
    if not parts:
        return _empty_result()
    return {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}


def _segment_chunk(type_s, xs, type_t, xt, bary, wr, area_tol, max_normal_dot, first):
    """segment_quadrature on pairs first .. first + len(xs) - 1."""
    m = len(xs)
    centre, n, e1, e2 = _plane_frames(type_s, xs)

    def to_plane(x):
        r = x - centre[:, None, :]
        return np.stack([np.einsum("mvi,mi->mv", r, e1), np.einsum("mvi,mi->mv", r, e2)], axis=-1)

    ps, pt = to_plane(xs), to_plane(xt)
    turn_s = _corner_turns(ps)
    bad = np.flatnonzero(~(turn_s > 0.0).all(axis=1))
    if len(bad):
        raise MeshError(f"segment_quadrature: S face of pair {first + bad[0]} is degenerate or not convex "
                        f"in its own plane ({len(bad)} such faces)")
    turn_t = _corner_turns(pt)
    ccw, cw = (turn_t > 0.0).all(axis=1), (turn_t < 0.0).all(axis=1)
    use = ccw | cw
    if max_normal_dot is not None:
        n_t = face_normal_at(type_t, xt, np.broadcast_to(fem.CENTROID[type_t], (m, 2)))
        use &= np.einsum("mi,mi->m", n, n_t) <= max_normal_dot
    # the in-plane boxes must overlap with positive area; most candidates of a tilted surface stop here
    for d in range(2):
        cs, ct = [ps[:, v, d] for v in range(ps.shape[1])], [pt[:, v, d] for v in range(pt.shape[1])]
        use &= np.maximum(np.minimum.reduce(cs), np.minimum.reduce(ct)) < \
            np.minimum(np.maximum.reduce(cs), np.maximum.reduce(ct))
    sel = np.flatnonzero(use)
    if len(sel) == 0:
        return _empty_result()
    subject = np.where(cw[sel, None, None], pt[sel, ::-1], pt[sel])       # clip ccw polygons only
    poly, count = _clip(subject, np.full(len(sel), pt.shape[1]), ps[sel])

    # fan from the first vertex; the overlap is convex
    if type_s == "tri":
        area_s = 0.5 * _cross2(ps[sel, 1] - ps[sel, 0], ps[sel, 2] - ps[sel, 0])
    else:
        area_s = 0.5 * _cross2(ps[sel, 2] - ps[sel, 0], ps[sel, 3] - ps[sel, 1])
    i = np.arange(1, poly.shape[1] - 1)
    v0 = poly[:, :1]
    tri_area = 0.5 * _cross2(poly[:, i] - v0, poly[:, i + 1] - v0)           # (k, w - 2)
    keep = (i[None, :] + 1 < count[:, None]) & (tri_area > area_tol * area_s[:, None])
    k, sub = np.nonzero(keep)
    if len(k) == 0:
        return _empty_result()
    tri = np.stack([poly[k, 0], poly[k, sub + 1], poly[k, sub + 2]], axis=1)      # (t, 3, 2)
    p = bary @ tri                                                                # (t, r, 2)
    w2 = tri_area[k, sub][:, None] * wr[None, :]
    pair = sel[k]

    # per triangle, broadcast over its rule points
    Bs, Bt = _monomials(type_s), _monomials(type_t)
    xi_s = _inverse_map(Bs @ ps[pair], p, "S")
    xi_t = _inverse_map(Bt @ pt[pair], p, "T")
    c, a1, a2, a12 = (K[:, None] for K in np.moveaxis(Bs @ xs[pair], 1, 0))
    x = c + xi_s[..., 0, None] * a1 + xi_s[..., 1, None] * a2 + (xi_s[..., 0] * xi_s[..., 1])[..., None] * a12
    a = cross(a1 + xi_s[..., 1, None] * a12, a2 + xi_s[..., 0, None] * a12)
    ratio = np.sqrt((a * a).sum(axis=-1)) / np.abs((a * n[pair, None]).sum(axis=-1))
    nq = p.shape[0] * p.shape[1]
    return {"pair": np.repeat(pair + first, len(wr)).astype(np.int64), "x": x.reshape(nq, 3),
            "xi_s": xi_s.reshape(nq, 2), "xi_t": xi_t.reshape(nq, 2), "weight": (w2 * ratio).reshape(nq)}
