"""Contact search: which faces lie near a point (bucket grid) and which one it projects on (rank-independent tie rule).

Pure NumPy. The answer for a point depends only on the set of faces given and
their keys, never on their order, so every MPI partition of a surface picks the
same face as long as each rank is given (at least) all faces within the search
radius of the points it owns.
"""

import numpy as np

from qsc_petsc import fem
from qsc_petsc.contact.geometry import _dot, face_normal_at, project_on_faces

# distances equal within TIE_TOL * (face size) are a tie, decided by the face key
TIE_TOL = 1e-9
# closest_faces' edge band: points within this fraction of it past an edge keep their whole weight (a point on
# a symmetry plane beside a curved surface's edge lies ~1e-5 of the band past it)
EDGE_FULL = 0.1
# a face may cover this many grid cells on average before the cells are made coarser
_MAX_CELLS_PER_FACE = 27
# a point meets a face only if the face is turned towards it: n_point . n_face <= FACING (outward normals, the
# face's at its centroid), i.e. the two within 70 degrees of facing each other. A surface may hold faces
# that never meet the other one: a thin body's whole skin (the far side, within the search distance, read the
# body's thickness as a gap or a penetration), the sides beside a punch's face (their Gauss points, projected
# on the block with a gap of their height, opened the rows of the punch's edge), or a master's side face at a
# convex edge (a slave node on the edge line, shared with it, was held sideways). Perpendicular faces are out
# too: seen edge-on they meet nothing (hunt28_3).
FACING = -0.342            # -cos(70 degrees)


def _empty_pairs():
    return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)


def candidate_pairs(points, face_min, face_max, radius):
    """All (point, face) pairs whose face box [face_min - radius, face_max + radius] contains the point.

    Uniform bucket grid, O(p + m + pairs) after sorting: each face is entered in
    the cells its inflated box covers, each point looked up in its own cell,
    then the exact box test filters the candidates. Returns (point_idx,
    face_idx), int64, sorted by point then face.
    """
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    face_min = np.asarray(face_min, dtype=float).reshape(-1, 3)
    face_max = np.asarray(face_max, dtype=float).reshape(-1, 3)
    if face_min.shape != face_max.shape:
        raise ValueError(f"face_min {face_min.shape} and face_max {face_max.shape} must have the same shape")
    if not radius >= 0:
        raise ValueError(f"radius must be >= 0, got {radius}")
    lo = face_min - radius
    hi = face_max + radius
    if len(points) == 0 or len(lo) == 0:
        return _empty_pairs()

    # points outside the faces' overall box meet no face
    origin = lo.min(axis=0)
    top = hi.max(axis=0)
    pidx = np.flatnonzero(((points >= origin) & (points <= top)).all(axis=1))
    if len(pidx) == 0:
        return _empty_pairs()
    pts = points[pidx]

    extent = (hi - lo).max(axis=1)
    h = float(np.median(extent))
    span = float((top - origin).max())
    if not h > 0:
        h = span if span > 0 else 1.0
    while True:
        ncell = np.floor((top - origin) / h).astype(np.int64) + 1
        c0 = np.floor((lo - origin) / h).astype(np.int64)
        c1 = np.floor((hi - origin) / h).astype(np.int64)
        count = (c1 - c0 + 1).prod(axis=1)
        if count.sum() <= _MAX_CELLS_PER_FACE * len(lo) + 1000 and float(np.prod(ncell.astype(float))) < 2.0 ** 62:
            break
        h *= 2.0

    def cell_id(ix, iy, iz):
        return ix + ncell[0] * (iy + ncell[1] * iz)

    # every (cell, face) entry of the faces' inflated boxes
    face_of = np.repeat(np.arange(len(lo), dtype=np.int64), count)
    k = np.arange(count.sum(), dtype=np.int64) - np.repeat(np.cumsum(count) - count, count)
    nx = (c1[:, 0] - c0[:, 0] + 1)[face_of]
    ny = (c1[:, 1] - c0[:, 1] + 1)[face_of]
    entry_cell = cell_id(c0[face_of, 0] + k % nx, c0[face_of, 1] + (k // nx) % ny, c0[face_of, 2] + k // (nx * ny))

    # points sorted by their cell; each entry meets the points of its cell
    pc = np.floor((pts - origin) / h).astype(np.int64)
    pc = np.minimum(pc, ncell - 1)
    point_cell = cell_id(pc[:, 0], pc[:, 1], pc[:, 2])
    order = np.argsort(point_cell, kind="stable")
    sorted_cell = point_cell[order]
    start = np.searchsorted(sorted_cell, entry_cell, side="left")
    n_in = np.searchsorted(sorted_cell, entry_cell, side="right") - start
    pair_face = np.repeat(face_of, n_in)
    offset = np.arange(n_in.sum(), dtype=np.int64) - np.repeat(np.cumsum(n_in) - n_in, n_in)
    pair_point = order[np.repeat(start, n_in) + offset]

    # a point sits in one cell and a face enters a cell once: no duplicates
    p = pts[pair_point]
    hit = ((p >= lo[pair_face]) & (p <= hi[pair_face])).all(axis=1)
    pair_point, pair_face = pidx[pair_point[hit]], pair_face[hit]
    srt = np.lexsort((pair_face, pair_point))
    return pair_point[srt].astype(np.int64), pair_face[srt].astype(np.int64)


def facing_pairs(point_normal, face_normal):
    """Whether each (point, face) pair faces each other (FACING), their outward normals given per pair."""
    return _dot(point_normal, face_normal) <= FACING


def _nearest_candidates(points, face_xyz, radius, margin, facing=None):
    """The (point, face) pairs that may hold a point's nearest face within radius, or one within margin (p,) of
    it (ties, keep's faces): sorted by point, then face. facing (None, or (p, 3) the points' outward normals,
    with the faces' centroid normals (m, 3): (normals, face_normals)): only pairs that face each other.

    A point's distance to any vertex of a face bounds its distance to its nearest face from above, and its
    distance to a face's box bounds that face's distance from below: only faces whose box lies within the
    best vertex distance plus margin are kept for the projection. The boxes are searched within a radius
    that starts at the faces' median size and doubles for the points it does not settle (its nearest vertex
    plus margin beyond it), up to `radius`: a search_distance widened to reach a gap of many element sizes
    projected every face within it (two plates, 28k points on 16k faces, search_distance 10: 11 M pairs,
    40 s; hunt27_2)."""
    lo, hi = face_xyz.min(axis=1), face_xyz.max(axis=1)
    r = min(radius, float(np.median(hi - lo, axis=0).max()) or radius)
    todo = np.arange(len(points))
    found_p, found_f = [], []
    while len(todo):
        last = r >= radius
        pi, fi = candidate_pairs(points[todo], lo, hi, r)
        if facing is not None:
            turned = facing_pairs(facing[0][todo][pi], facing[1][fi])
            pi, fi = pi[turned], fi[turned]
        x = points[todo][pi]
        box = np.sqrt(_dot(*(2 * [np.maximum(lo[fi] - x, 0.0) + np.maximum(x - hi[fi], 0.0)])))
        vertex = np.full(len(pi), np.inf)
        for v in range(face_xyz.shape[1]):
            np.minimum(vertex, _dot(*(2 * [face_xyz[fi, v] - x])), out=vertex)
        best = np.full(len(todo), np.inf)
        np.minimum.at(best, pi, np.sqrt(vertex))
        reach = best + margin[todo]
        settled = last | (reach <= r)
        take = settled[pi] & (box <= reach[pi] * (1.0 + 1e-12))
        found_p.append(todo[pi[take]])
        found_f.append(fi[take])
        todo, r = todo[~settled], min(2.0 * r, radius)
    pi, fi = np.concatenate(found_p), np.concatenate(found_f)
    order = np.lexsort((fi, pi))
    return pi[order], fi[order]


def _entries(points, proj, pi, sel, band):
    """Per (point pi, projection sel): xi, shape, closest, normal, distance, signed_gap, inside and edge_factor
    (closest_faces' edge band: 0 where the point meets no face)."""
    e = {"xi": proj.xi[sel], "shape": proj.shape[sel], "closest": proj.closest[sel], "normal": proj.normal[sel],
         "distance": proj.distance[sel], "inside": proj.inside[sel]}
    r = points[pi] - e["closest"]
    e["signed_gap"] = _dot(r, e["normal"])
    e["edge_factor"] = np.ones(len(pi))
    off = np.flatnonzero(~e["inside"])
    if band is not None and len(off):
        n = e["normal"][off]
        along = _dot(r[off], n)
        r_plane = r[off] - along[:, None] * n
        # past the edge by more than it is off the face's plane: a point over a convex ridge of two faces (a
        # right angle: as much off the plane as past the edge) keeps its row, one that slid off beside the face
        # does not
        beside = np.maximum(np.sqrt(_dot(r_plane, r_plane)) - np.abs(along), 0.0)
        b = np.broadcast_to(band, (len(points),))[pi[off]]
        e["edge_factor"][off] = np.clip((b - beside) / ((1.0 - EDGE_FULL) * b), 0.0, 1.0)
    return e


def _shared(p, pi, fi, entry, is_first, level, face):
    """How many faces share each point (share (p,), 1 where one face takes it) and the entries of the faces
    other than the winner (extra: a dict of arrays over them, "point" and "face" included).

    A point at the same distance from several faces (within TIE_TOL, e.g. over the valley or the ridge of a
    kink) is shared among them equally: each takes 1 / share of its weight with its own projection and
    normal, so that the answer keeps the scene's mirror symmetries. The tie rule alone gave the whole point to
    one face, whose normal leans toward it: Gauss rows on configs/flat_punch.toml pushed the punch sideways by
    1.1e-5 of its normal force (master_slave 2.1e-5), nodal rows likewise at symmetric kinks. Only where the
    winner itself is at that distance (not a face kept within keep's slack) and meets the point (edge band)."""
    win_level = np.zeros(p, dtype=bool)
    win_level[pi[is_first]] = level[is_first]
    partner = (~is_first & level & win_level[pi] & (face[pi] >= 0) & (entry["edge_factor"] > 0.0))
    share = np.ones(p)
    np.add.at(share, pi[partner], 1.0)
    extra = {name: values[partner] for name, values in entry.items()}
    extra["point"], extra["face"] = pi[partner], fi[partner]
    return share, extra


def found_entries(found, names):
    """Every (point, face) entry of a closest_faces answer: the points that found a face, then the other faces of
    the shared ones (found["extra"]). Returns the point of each entry, {name: its values} for `names`, and each
    entry's part of its point's weight (edge_factor / share)."""
    ok = np.flatnonzero(found["face"] >= 0)
    extra = found["extra"]
    point = np.concatenate([ok, extra["point"]])
    values = {name: np.concatenate([found[name][ok], extra[name]]) for name in names}
    part = np.concatenate([found["edge_factor"][ok], extra["edge_factor"]]) / found["share"][point]
    return point, values, part


def closest_faces(points, face_xyz, face_type, face_key, radius, band=None, keep=None, keep_within=None,
                  normal=None):
    """The face each point projects on: the nearest within radius, ties broken by the smallest face_key row; with
    normal (p, 3), the points' outward unit normals, only faces turned towards the point (FACING) take it:

    * a point whose nearest faces (the winner and those it shares with) all turn towards it keeps them;
    * one in front of a nearest face turned away from it (signed gap above the tie tolerance) is outside the
      other body beside that face: it takes the nearest among the faces turned towards it with a weight that
      fades over the edge band (band) as that gap grows, and none past it (none at all without band). A plate
      node beside a chisel's edge, as near to its vertical face (in front of it) as to its bevel (behind that
      one's plane), read the bevel's plane as a penetration once the vertical face was left out, and two_pass
      pushed the chisel off 3.7x the force (hunt28_5);
    * any other (on or behind a face turned away: a node on the other's convex edge line, one past a thin
      plate's middle) takes the nearest among the faces turned towards it.

    points (p, 3); face_xyz (m, nv, 3); face_key (m, k) int64, e.g. each face's
    sorted global vertex ids (partition independent). Returns a dict of (p, ...)
    arrays: face (index into the given faces, -1 if none within radius), xi,
    shape, closest, normal (the face's outward normal at xi), distance,
    signed_gap = (point - closest) . normal (>= 0 when apart), inside,
    edge_factor.

    band (p,) [m] or None: the edge band. A point whose closest point is on its
    face's edge with the point beyond it (not inside: it has slid past the
    surface's edge, or sits over a convex kink) lies off the face's normal by
    the in-plane distance d_p = |(point - closest) minus its normal part|, and
    off the face's plane by d_n = |(point - closest) . normal|; with
    d = max(d_p - d_n, 0) (beside the face more than above it) its edge_factor
    is 1 up to d = EDGE_FULL band, falls linearly to 0 at d = band, and a point
    with d >= band meets no face. A point over a convex ridge of two faces
    (d_p = d_n at a right angle) keeps its row at any gap.
    A row of such a point would hold it against the face's plane extended past
    the edge, whose tilt times d moved its gap between searches by far more than
    the penetrations (formulation.md section 6; large sliding did not settle).
    edge_factor is 1 for inside points and without band, 0 where no face.

    share (p,): how many faces share the point, 1 but for a point at the same distance from several faces
    (_shared), whose winner is the one above and whose others are in extra: a dict of the same arrays over
    them, plus "point" (the point each is of); each face takes 1 / share of the point's weight.

    keep (p, k) or None: each point's face key at an earlier search (a row of -1: none), and keep_within (p,)
    [m]: a point whose kept face lies within that distance of the nearest takes it instead of the nearest, so
    that the choice between the faces of a kink does not swing from one search to the next. out["key"]: the
    keys of the faces chosen (-1 rows where none or shared), for the next search's keep.
    """
    if normal is None:
        out = _closest(points, face_xyz, face_type, face_key, radius, band, keep, keep_within)
        out.pop("nearest")
        return out
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    face_xyz = np.asarray(face_xyz, dtype=float)
    p = len(points)
    out = _closest(points, face_xyz, face_type, face_key, radius, band, keep, keep_within)
    if p == 0 or len(face_xyz) == 0:
        return out
    normal = np.asarray(normal, dtype=float).reshape(-1, 3)
    centroid = face_normal_at(face_type, face_xyz, np.broadcast_to(fem.CENTROID[face_type], (len(face_xyz), 2)))
    size = fem.face_size(face_xyz)
    extra = out["extra"]
    nearest = out.pop("nearest")
    has = nearest >= 0
    # per point: whether a nearest face turns away, and how far the point lies in front of such a face
    away, front = np.zeros(p, dtype=bool), np.full(p, -np.inf)
    f = nearest[has]
    turned = facing_pairs(normal[has], centroid[f])
    away[has] = ~turned
    front[has] = np.where(turned, -np.inf, out["signed_gap"][has] - TIE_TOL * size[f])
    xt = facing_pairs(normal[extra["point"]], centroid[extra["face"]])
    np.logical_or.at(away, extra["point"], ~xt)
    np.maximum.at(front, extra["point"], np.where(xt, -np.inf, extra["signed_gap"] - TIE_TOL * size[extra["face"]]))
    # in front of it: a weight that fades over the edge band as a point past an edge does (1 up to EDGE_FULL band,
    # 0 from band on), so that a node beside the other's side face takes what it took when the surface held no
    # side (a cube slid past the other's edge: the same rows with whole skins as with the touching faces)
    weight = np.ones(p)
    ahead = front > 0.0
    if band is None:
        weight[ahead] = 0.0
    else:
        b = np.broadcast_to(band, (p,))[ahead]
        weight[ahead] = np.clip((b - front[ahead]) / ((1.0 - EDGE_FULL) * b), 0.0, 1.0)
    redo = np.flatnonzero(away & (weight > 0.0))
    drop = np.flatnonzero(away)
    out["face"][drop] = -1
    out["key"][drop] = -1
    out["share"][drop] = 1.0
    out["edge_factor"][drop] = 0.0
    keep_extra = ~np.isin(extra["point"], drop)
    out["extra"] = {name: values[keep_extra] for name, values in extra.items()}
    if len(redo):
        sub = _closest(points[redo], face_xyz, face_type, face_key, radius,
                       None if band is None else np.broadcast_to(band, (p,))[redo],
                       None if keep is None else np.asarray(keep)[redo],
                       None if keep_within is None else np.broadcast_to(keep_within, (p,))[redo],
                       (normal[redo], centroid))
        sub.pop("nearest")
        sub["edge_factor"] = np.minimum(sub["edge_factor"], weight[redo])
        gone = sub["edge_factor"] <= 0.0
        sub["face"][gone], sub["key"][gone] = -1, -1
        for name, values in sub.items():
            if name != "extra":
                out[name][redo] = values
        sx = sub["extra"]
        sx["point"] = redo[sx["point"]]
        sx["edge_factor"] = np.minimum(sx["edge_factor"], weight[sx["point"]])
        kept = ~np.isin(sx["point"], redo[gone])
        out["extra"] = {name: np.concatenate([out["extra"][name], sx[name][kept]]) for name in out["extra"]}
    return out


def _closest(points, face_xyz, face_type, face_key, radius, band=None, keep=None, keep_within=None, facing=None):
    """closest_faces over the faces given, or, with facing ((p, 3) point normals, (m, 3) face centroid normals),
    over those turned towards each point; out["nearest"]: the winner's index whatever its edge band (-1: none)."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    face_xyz = np.asarray(face_xyz, dtype=float)
    nv = fem.FACE_NODES[face_type]
    if face_xyz.ndim != 3 or face_xyz.shape[1:] != (nv, 3):
        raise ValueError(f"face_xyz must have shape (m, {nv}, 3) for {face_type} faces, got {face_xyz.shape}")
    face_key = np.asarray(face_key, dtype=np.int64)
    if face_key.ndim == 1:
        face_key = face_key[:, None]
    if len(face_key) != len(face_xyz):
        raise ValueError(f"face_key has {len(face_key)} rows for {len(face_xyz)} faces")
    p = len(points)
    out = {"face": np.full(p, -1, dtype=np.int64), "xi": np.zeros((p, 2)), "shape": np.zeros((p, nv)),
           "closest": np.full((p, 3), np.nan), "normal": np.zeros((p, 3)), "distance": np.full(p, np.inf),
           "signed_gap": np.full(p, np.inf), "inside": np.zeros(p, dtype=bool), "edge_factor": np.zeros(p),
           "key": np.full((p, face_key.shape[1]), -1, dtype=np.int64), "share": np.ones(p)}
    out["extra"] = {name: values[:0] for name, values in out.items() if name not in ("key", "share")}
    out["extra"]["point"] = np.zeros(0, dtype=np.int64)
    out["nearest"] = np.full(p, -1, dtype=np.int64)
    if p == 0 or len(face_xyz) == 0:
        return out

    margin = TIE_TOL * float(fem.face_size(face_xyz).max()) + (0.0 if keep is None else
                                                                np.broadcast_to(keep_within, (p,)))
    pi, fi = _nearest_candidates(points, face_xyz, radius, np.broadcast_to(margin, (p,)), facing)
    proj = project_on_faces(points[pi], face_xyz[fi], face_type)
    near = proj.distance <= radius
    pi, fi = pi[near], fi[near]
    sel = np.flatnonzero(near)
    d = proj.distance[sel]
    if len(pi) == 0:
        return out

    dmin = np.full(p, np.inf)
    np.minimum.at(dmin, pi, d)
    tie_tol = TIE_TOL * fem.face_size(face_xyz[fi])
    slack = tie_tol
    kept = np.zeros(len(pi), dtype=bool)
    if keep is not None:
        kept = np.all(face_key[fi] == np.asarray(keep, dtype=np.int64)[pi], axis=1)
        slack = np.where(kept, np.maximum(slack, np.broadcast_to(keep_within, (p,))[pi]), slack)
    tie = d <= dmin[pi] + slack
    level = d[tie] <= dmin[pi[tie]] + tie_tol[tie]         # at the nearest distance, not only within keep's slack
    pi, fi, sel, kept = pi[tie], fi[tie], sel[tie], kept[tie]
    keys = face_key[fi]
    # the kept face first, then the tie rule
    order = np.lexsort(tuple(keys[:, j] for j in range(keys.shape[1] - 1, -1, -1)) + (~kept, pi))
    is_first = np.zeros(len(pi), dtype=bool)
    is_first[order[np.r_[True, pi[order][1:] != pi[order][:-1]]]] = True
    entry = _entries(points, proj, pi, sel, band)
    first = np.flatnonzero(is_first)
    who = pi[first]
    for name, values in entry.items():
        out[name][who] = values[first]
    out["face"][who] = np.where(entry["edge_factor"][first] > 0.0, fi[first], -1)
    out["nearest"][who] = fi[first]
    # the other faces at the winner's distance share the point's weight with it (_shared)
    out["share"], out["extra"] = _shared(p, pi, fi, entry, is_first, level, out["face"])
    # a shared point keeps no face: the tie rule's winner is not its mirror image's (a Gauss point on an edge of
    # the undeformed sliding_cubes kept the face on its lower-y side, its mirror image too, and they left the
    # scene 3.2e-6 of the normal force sideways)
    chosen = (out["face"] >= 0) & (out["share"] == 1)
    out["key"] = np.where(chosen[:, None], face_key[np.maximum(out["face"], 0)], -1)
    return out
