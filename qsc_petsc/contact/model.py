"""Contact in parallel: surface data across ranks, face exchange, both search passes, distributed G, g, W, and reports.

Each rank searches for the surface nodes it owns. The opposite surface's faces it may need
(bounding boxes within the search distance of its nodes) come from the other ranks in one
all-to-all. Rows are triplets with global ids assembled by their owners; a quasi-symmetric
row of slave node k can receive contributions computed on the rank that owns a master node l.
At solve time the product G^T m (ConstraintTerm.add_force) is the halo exchange of slave
multipliers: PETSc scatters row multipliers to the ranks owning the master dofs they act on.
"""

import itertools
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from .. import assembly, fem
from ..errors import MeshError, SceneError
from ..mesh import first_largest, on_all
from ..solver import DIE_AWAY, FLOOR_STRAIN, ConstraintTerm, array_digest
from . import quadrature
from . import rows as row_builders
from .geometry import _dot
from .penalty import gate_positions
from .search import FACING, candidate_pairs, closest_faces, facing_pairs

# the edge band (search.closest_faces) of a nodal or Gauss point, as a fraction of its own element size: a point
# that has slid past the opposite surface's edge (by more than it is off the face's plane) keeps its whole row for
# the first tenth of this distance beyond it (the lateral misfits of two bodies' bulging side faces, ~1e-3 h at 1 %
# strain), then fades out (a band of 0.5 still left nodal two_pass unsettled on the sliding cubes, 0.1 and 0.02
# settled alike)
EDGE_BAND = 0.1
# large sliding: a search after a solve keeps each point on the face it took at the increment's last search while
# that face lies within KEEP_TOL x the point's size of the nearest (search.closest_faces' keep): on a kinked
# surface a point near the edge of two faces took one at a search and the other at the next, and the searches
# went round that cycle without end (Gauss rows on configs/sliding_cubes.toml dragged 0.2 m and pressed 5 %: 23 of
# 729 points swapped faces). An increment's first search takes the nearest faces (kept across increments, a face
# chosen by the tie rule stayed as Poisson's expansion moved the node off it: two_cubes_dies with nodal rows
# lost its mirror symmetry, 1.3e-3 N of tangential force on 10.35 N)
# The answer then depends a little on the load path: nodal rows on the sliding cubes, 1 load step against
# 16, 1.7e-6 in the normal force (1.3e-8 before); only once the searches stalled (gap change below 0.1 and not
# halving) it kept 1.3e-8 but left two slides of 54 and two_pass nodal at a 10x mesh ratio unsettled again
KEEP_TOL = 1e-3
# ContactModel.report: a node traction at most this share of its surface's largest is round-off, not contact
PRESSED_SHARE = 1e-9
# the searches' reach is search_distance x h_eff widened by this share: a gap of exactly the search distance (an
# element size, the default) is within reach on every point. Each point's gap was round-off's to keep or drop: the
# patch pair with a gap of one element lost most of its segment points on 1 rank (24 % off, exit 0), 12 % on 3,
# and on 2 ranks none was within reach (exit 2; hunt33_3). Round-off of a gap stands below 1e-8 h where the
# coordinates keep their precision (COORDINATE_PRECISION)
REACH_SLACK = 1e-6


@dataclass
class Surface:
    """One named surface on this rank: its local faces and assembled nodal data of its owned nodes."""
    name: str
    body: int
    faces: np.ndarray          # (k, nv) local vertex indices of the local faces
    nodes: np.ndarray          # owned local vertices on the surface
    area: np.ndarray           # tributary area int N_k ds of each owned node [m^2]
    size: np.ndarray           # area-weighted mean size of the faces around each owned node [m]
    normal: np.ndarray         # area-weighted outward unit normal at each owned node
    mean_size: float           # mean face size over the whole surface (all ranks) [m]
    total_area: float
    template: object = None    # a Vec of the dofs' layout (nodal sums)


def _owned_rows(mesh, v):
    """Positions of owned local vertices v in an owned dof-array, reshaped (n_owned, 3)."""
    return mesh.gvert[v] - mesh.vertex_range[0]


def surface_data(mesh, name, template):
    """Faces and nodal area, size and normal of a surface, assembled over ranks; name may be a list of surfaces,
    taken as one (their faces' union: a face in two of them counts once)."""
    comm = mesh.comm
    names = [name] if isinstance(name, str) else list(name)
    c, lf = (np.concatenate(x) for x in zip(*(mesh.surface_faces(n) for n in names)))
    if len(names) > 1:
        _, keep = np.unique(c * 64 + lf, return_index=True)
        c, lf = c[keep], lf[keep]
        name = " + ".join(names)
    faces = mesh.face_nodes(c, lf)
    body = int(mesh.cell_body[c[0]]) if len(c) else -1
    body = comm.allreduce(body, op=MPI.MAX)
    xf = mesh.coords[faces]
    nodal = fem.face_nodal_areas(mesh.face_type, xf) if len(faces) else np.zeros((0, faces.shape[1]))
    size = fem.face_size(xf) if len(faces) else np.zeros(0)
    per_node = np.zeros(nodal.shape + (3,))
    per_node[..., 0], per_node[..., 1] = nodal, nodal * size[:, None]
    nodes = np.unique(np.concatenate([mesh.surface_vertices(n) for n in names]))
    nodes = nodes[mesh.owned[nodes]]
    a = _nodal_sums(mesh, faces, per_node, nodes, template)
    area = a[:, 0]
    keep = area > 0                       # a labelled vertex that touches the surface only elsewhere
    nodes, area, a = nodes[keep], area[keep], a[keep]
    S = Surface(name, body, faces, nodes, area, a[:, 1] / area, None, _mean_over(comm, size, 0.0),
                comm.allreduce(float(nodal.sum()), op=MPI.SUM), template)
    S.normal = nodal_normals(mesh, S, mesh.coords)
    return S


def _nodal_sums(mesh, faces, values, nodes, template):
    """Sums over ranks of values (k, nv, 3) given at each local face's nodes, read at owned local vertices nodes
    (collective)."""
    acc = template.duplicate()
    acc.set(0.0)
    dofs = (3 * mesh.gvert[faces][:, :, None] + np.arange(3)).ravel().astype(PETSc.IntType)
    acc.setValues(dofs, values.ravel(), addv=PETSc.InsertMode.ADD_VALUES)
    acc.assemble()
    out = acc.getArray().reshape(-1, 3)[_owned_rows(mesh, nodes)].copy()
    acc.destroy()
    return out


def nodal_normals(mesh, S, x, by="area"):
    """The outward unit normals of S's owned nodes with the local vertices at x (collective): the faces' centroid
    normals weighted by the nodes' tributary areas on them (by="area": S.normal, the tractions' normal), or by the
    faces' angles at the node (by="angle": the angle-weighted pseudo-normal by which a node faces another surface,
    search.FACING). The angles depend on the surface's shape, not on its mesh: the area-weighted normal of a whole
    skin's edge node leaned past the facing threshold when the sides' faces were large beside the contact face's
    (a punch one element tall, a thin wall on its edge: the node met no face, lost its row and sank in; hunt28_4),
    the angles put it at 45 degrees on any box edge, 55 at a corner."""
    xf = x[S.faces]
    if len(S.faces):
        normal = fem.centroid_normals(mesh.face_type, xf)
        weight = fem.face_nodal_areas(mesh.face_type, xf) if by == "area" else _corner_angles(xf)
    else:
        weight, normal = np.zeros((0, S.faces.shape[1])), np.zeros((0, 3))
    nvec = _nodal_sums(mesh, S.faces, weight[:, :, None] * normal[:, None, :], S.nodes, S.template)
    nrm = np.linalg.norm(nvec, axis=1)
    return nvec / np.where(nrm > 0, nrm, 1.0)[:, None]


def _corner_angles(xf):
    """The angles (k, nv) of faces with node coordinates xf (k, nv, 3) at their nodes."""
    before, after = np.roll(xf, 1, axis=1) - xf, np.roll(xf, -1, axis=1) - xf
    cos = np.einsum("kvi,kvi->kv", before, after) / (np.linalg.norm(before, axis=2) * np.linalg.norm(after, axis=2))
    return np.arccos(np.clip(cos, -1.0, 1.0))


def symmetry_planes(mesh, scene):
    """(axis, coordinate) of the model's symmetry planes: the boundaries of type "symmetry", and the displacement
    boundaries that hold a plane's normal component at 0 and leave the others free, which are the same condition
    (collective)."""
    planes = []
    for bc in scene.boundary:
        if bc.type == "displacement":
            values = (bc.ux, bc.uy, bc.uz)
            held = [k for k, value in enumerate(values) if value is not None]
            if len(held) != 1 or values[held[0]] != 0.0:
                continue
        elif bc.type != "symmetry":
            continue
        axis = assembly.plane_axis(mesh, bc.surface)
        if axis is None or (bc.type == "displacement" and axis != held[0]):
            continue
        v = mesh.surface_vertices(bc.surface)
        total, count = mesh.comm.allreduce(np.array([mesh.coords[v, axis].sum(), len(v)]), op=MPI.SUM)
        planes.append((axis, total / max(count, 1.0)))
    return planes


def symmetry_components(mesh, scene):
    """(local vertices, 3) bools: the components normal to the symmetry planes (symmetry_planes) that each vertex
    lies on (collective)."""
    on = np.zeros((len(mesh.coords), 3), dtype=bool)
    extent = mesh.comm.allreduce(float(np.abs(mesh.coords).max(initial=0.0)), op=MPI.MAX)
    for axis, plane in symmetry_planes(mesh, scene):
        on[:, axis] |= np.abs(mesh.coords[:, axis] - plane) <= 1e-9 * max(extent, 1e-300)
    return on


def ridge_tilts(mesh, S, mirrored=None):
    """Per owned node of S, how far (radians) S folds convexly there in the reference configuration; 0 where it is
    flat or folds the other way (a valley). Those above contact[].feature_angle are the feature nodes, the sharp
    edges and corners that weighted gaps let through. A node's
    faces tilt from its angle-weighted normal m by arccos(|sum w n_f| / sum w) on average (w: the faces' angles at
    the node, n_f their centroid normals): 45 degrees on a box's edge, 54.7 at its corner, a knife's faces' tilt
    from its edge's normal; the fold is convex when the faces' centroids lie behind the node along m, as on a
    ridge, not in a valley. mirrored (symmetry_components): on a symmetry plane the faces' mirror images count
    too, so the components normal to it drop out of both sums (a half knife's edge, with one face of its own, read
    no fold at all; hunt30_3). Sums over ranks, so the same nodes on any number of them. Collective."""
    xf = mesh.coords[S.faces]
    nv = S.faces.shape[1]
    values = np.zeros((len(S.faces), nv, 3, 3))      # per face node: w n_f, w (c_f - x_k), (w, 0, 0)
    if len(S.faces):
        w = _corner_angles(xf)
        values[..., 0, :] = w[:, :, None] * fem.centroid_normals(mesh.face_type, xf)[:, None, :]
        values[..., 1, :] = w[:, :, None] * (xf.mean(axis=1)[:, None, :] - xf)
        values[..., 2, 0] = w
        if mirrored is not None:
            values[..., :2, :] *= ~mirrored[S.faces][:, :, None, :]
    m, behind, total = (_nodal_sums(mesh, S.faces, values[..., j, :], S.nodes, S.template) for j in range(3))
    total = total[:, 0]
    size = np.linalg.norm(m, axis=1)
    tilt = np.arccos(np.clip(size / np.where(total > 0, total, 1.0), -1.0, 1.0))
    ridge = np.einsum("ki,ki->k", behind, m) < 0.0
    return np.where(ridge & (total > 0), tilt, 0.0)


def exchange_faces(mesh, faces, X, U, sizes, need_lo, need_hi):
    """Every rank's faces (local vertex lists) whose boxes meet another rank's need box go there.

    need_lo/need_hi: this rank's box of points, already inflated by the search radius.
    Returns (face_gvert, face_orig, face_X, face_U, face_size) of local and received faces."""
    comm = mesh.comm
    nv = faces.shape[1]
    boxes = comm.allgather((need_lo, need_hi))
    xyz = X[faces] + U[faces]
    fmin, fmax = (xyz.min(axis=1), xyz.max(axis=1)) if len(faces) else (np.zeros((0, 3)), np.zeros((0, 3)))
    packet = np.concatenate([mesh.gvert[faces], mesh.vert_orig[faces], X[faces].reshape(-1, 3 * nv),
                             U[faces].reshape(-1, 3 * nv), sizes[:, None]], axis=1).astype(float)
    send, counts = [], np.zeros(comm.size, dtype=np.int64)
    for r, (lo, hi) in enumerate(boxes):
        if r == comm.rank or lo is None:
            continue
        hit = np.all((fmax >= lo) & (fmin <= hi), axis=1)
        send.append(packet[hit])
        counts[r] = hit.sum()
    width = packet.shape[1]
    sendbuf = np.concatenate(send) if send else np.zeros((0, width))
    rcounts = np.empty_like(counts)
    comm.Alltoall(counts, rcounts)
    recv = np.empty((int(rcounts.sum()), width))
    comm.Alltoallv([sendbuf, (counts * width, None), MPI.DOUBLE], [recv, (rcounts * width, None), MPI.DOUBLE])
    allp = np.concatenate([packet, recv])
    gv = allp[:, :nv].astype(np.int64)
    orig = allp[:, nv:2 * nv].astype(np.int64)
    fx = allp[:, 2 * nv:5 * nv].reshape(-1, nv, 3)
    fu = allp[:, 5 * nv:8 * nv].reshape(-1, nv, 3)
    return gv, orig, fx, fu, allp[:, -1]


def _need_box(pts, radius):
    return (pts.min(axis=0) - radius, pts.max(axis=0) + radius) if len(pts) else (None, None)


def _target_faces(mesh, T, X, U, points, radius):
    """T's faces (local and received) that may meet points (p, 3) within radius: global ids, keys, X, U, sizes."""
    tsize = fem.face_size(mesh.coords[T.faces]) if len(T.faces) else np.zeros(0)
    gv, orig, fx, fu, fsize = exchange_faces(mesh, T.faces, X, U, tsize, *_need_box(points, radius))
    return gv, np.sort(orig, axis=1), fx, fu, fsize


def _search_pass(mesh, T, X, U, radius, points, memo=None, weigh=None):
    """Points (a quadrature.gauss_points-like dict) projected on T's faces: a rows.Pass, the found mask and dict.

    memo (a dict, or None): the faces the same points took at the pass's last search in this increment, kept while
    within KEEP_TOL x their size of the nearest (search.closest_faces' keep), and this search's, for the next.
    weigh (None, or a function of the search's dict): the points' weights, known once their faces are."""
    gv, key, fx, fu, fsize = _target_faces(mesh, T, X, U, points["x_cur"], radius)
    keep = memo.get("key") if memo is not None else None
    if keep is not None and len(keep) != len(points["x_cur"]):
        keep = None
    found = closest_faces(points["x_cur"], fx + fu, mesh.face_type, key, radius, EDGE_BAND * points["size"],
                          keep, KEEP_TOL * points["size"], points["normal"])
    if memo is not None:
        memo["key"] = found["key"]
    # the T material point each point faces, in the reference configuration (also ContactModel.report's slip)
    found["target_ref"] = quadrature.faced_points(found, fx)
    if weigh is not None:
        points = dict(points, weight=weigh(found))
    return quadrature.found_pass(points, found, gv, fx, fsize), found["face"] >= 0, found


def project_pass(mesh, S, T, X, U, radius, memo=None, which=None, weighted=True):
    """Owned nodes of S (those of the mask `which`, if given) projected on faces of T (local and gathered): a
    rows.Pass, the found mask, the search. Each node weighs its tributary area on the faces turned towards the face
    it found (facing_areas); weighted=False leaves the Pass's weights S's areas, for callers that read the search
    alone."""
    which = slice(None) if which is None else which
    v = S.nodes[which]
    points = {"x_cur": X[v] + U[v], "x_ref": X[v], "node": mesh.gvert[v], "size": S.size[which],
              "weight": S.area[which], "normal": nodal_normals(mesh, S, X + U, by="angle")[which]}
    weigh = (lambda found: facing_areas(mesh, S, X, U, which, found)[0]) if weighted else None
    return _search_pass(mesh, T, X, U, radius, points, memo, weigh)


def facing_areas(mesh, S, X, U, which, found):
    """The tributary areas and area-weighted normals (the reference configuration's) of S's owned nodes `which`
    over the faces around each turned towards the T face it found (search.FACING, centroid normals now); a node
    that found none keeps its own, S.area and S.normal, as does one all of whose faces are turned (the very same
    numbers). A surface that holds faces beside the contact (a punch's whole skin: its sides) gave its edge nodes
    the sides' areas too: their nodal rows, tractions and the contact area counted them (a punch's contact area
    0.54 against 0.36 m2; hunt28_3). Collective."""
    _, ref, nodal, away = _turned_faces(mesh, S, X, U, which, found)
    values = np.zeros(nodal.shape + (3,))
    values[..., 0] = nodal * away
    away_area = _nodal_sums(mesh, S.faces, values, S.nodes[which], S.template)[:, 0]
    turned = _nodal_sums(mesh, S.faces, (nodal * ~away)[:, :, None] * ref[:, None, :], S.nodes[which], S.template)
    area, normal = S.area[which].copy(), S.normal[which].copy()
    part = (away_area > 0) & (away_area < (1.0 - 1e-9) * area)     # a node with no face turned keeps its own
    area[part] -= away_area[part]
    size = np.linalg.norm(turned[part], axis=1)
    normal[part] = turned[part] / np.where(size > 0, size, 1.0)[:, None]
    return area, normal


def _turned_faces(mesh, S, X, U, which, found):
    """Per face node of S's local faces (k, nv): the outward normal of the T face that node found (zero: none or
    not among `which`), the faces' reference centroid normals (k, 3), their reference nodal areas, and whether
    the face is turned away (now) from the T face its node found (search.FACING). Collective."""
    ok = found["face"] >= 0
    target = S.template.duplicate()
    target.set(0.0)
    target.getArray().reshape(-1, 3)[_owned_rows(mesh, S.nodes[which])[ok]] = found["normal"][ok]
    faced = mesh.local_vectors(target)[S.faces]                  # (k, nv, 3): the T normal each face node found
    target.destroy()
    if len(S.faces):
        now = fem.centroid_normals(mesh.face_type, (X + U)[S.faces])
        ref = fem.centroid_normals(mesh.face_type, X[S.faces])
        nodal = fem.face_nodal_areas(mesh.face_type, X[S.faces])
    else:
        now = ref = np.zeros((0, 3))
        nodal = np.zeros((0, S.faces.shape[1]))
    away = (np.abs(faced).sum(axis=2) > 0) & ~facing_pairs(faced, np.broadcast_to(now[:, None, :], faced.shape))
    return faced, ref, nodal, away


def facing_lean(mesh, S, X, U, which, found):
    """For S's owned nodes `which`: the mean, over the node's faces turned towards the T face it found (weighted
    by the node's reference areas on them), of the cosine between a face's reference normal and that T face's
    inward normal -n_T: 1 where a face around the node lies parallel to the other surface, cos(theta) on a knife's
    edge whose faces stand theta from it (1: a node that found no face). The reference normals: an edge that its
    nodal row held up flattened its faces below the angle, lost its row and sank at every other step (hunt30_3).
    Collective."""
    faced, ref, nodal, away = _turned_faces(mesh, S, X, U, which, found)
    turned = nodal * ((np.abs(faced).sum(axis=2) > 0) & ~away)
    values = np.zeros(nodal.shape + (3,))
    values[..., 0] = turned
    values[..., 1] = turned * -np.einsum("ki,kvi->kv", ref, faced)
    sums = _nodal_sums(mesh, S.faces, values, S.nodes[which], S.template)
    return np.where(sums[:, 0] > 0, sums[:, 1] / np.where(sums[:, 0] > 0, sums[:, 0], 1.0), 1.0)


def gauss_pass(mesh, S, T, X, U, radius, n, memo=None):
    """n x n Gauss points of this rank's S faces projected on faces of T: a rows.Pass."""
    f = S.faces
    points = quadrature.gauss_points(mesh.face_type, X[f], X[f] + U[f], mesh.gvert[f], n)
    return _search_pass(mesh, T, X, U, radius, points, memo)[0]


def segment_pass(mesh, S, T, X, U, radius, degree=4):
    """Exact (segment) integration of this rank's S faces against T's faces (local and gathered): a rows.Pass."""
    f = S.faces
    xs_cur = X[f] + U[f]
    gv, _, fx, fu, fsize = _target_faces(mesh, T, X, U, xs_cur.reshape(-1, 3), radius)
    # a folded or non-convex face raises MeshError on the rank that meets it: all ranks stop together
    return on_all(mesh.comm, lambda: quadrature.segment_pass(mesh.face_type, X[f], xs_cur, mesh.gvert[f], fx,
                                                             fx + fu, gv, fsize, radius, degree))


def integration_pass(mesh, spec, S, T, X, U, radius, memo=None):
    """The pass "integrate S against T" with the pair's integration rule (memo: _search_pass's; segment
    integration clips faces and has no faces to keep)."""
    if spec.integration == "gauss":
        return gauss_pass(mesh, S, T, X, U, radius, spec.gauss_points, memo)
    if spec.integration == "segment":
        return segment_pass(mesh, S, T, X, U, radius)
    return project_pass(mesh, S, T, X, U, radius, memo)[0]


def _face_geometry(mesh, S):
    """Per local face of S in the reference configuration (k, 13): centroid, outward unit normal there, size,
    box corners (low, high)."""
    xf = mesh.coords[S.faces]
    if not len(xf):
        return np.zeros((0, 13))
    return np.hstack([xf.mean(axis=1), fem.centroid_normals(mesh.face_type, xf), fem.face_size(xf)[:, None],
                      xf.min(axis=1), xf.max(axis=1)])


def _mean_over(comm, sizes, fallback):
    """The mean of sizes over all ranks, or fallback where no rank has any (collective)."""
    count = comm.allreduce(len(sizes), op=MPI.SUM)
    return comm.allreduce(float(np.sum(sizes)), op=MPI.SUM) / count if count else fallback


def _ahead(faces, lo, hi, tol):
    """Which faces have part of the box [lo, hi] in front of them (their centroid's tangent plane, within tol)."""
    corners = np.stack(np.meshgrid(*zip(lo, hi), indexing="ij"), axis=-1).reshape(-1, 3)
    return np.einsum("kci,ki->kc", corners[None, :, :] - faces[:, None, :3], faces[:, 3:6]).max(axis=1) >= -tol


def _pairs_touch(a, b):
    """Per pair (a row, b row) of _face_geometry rows: turned towards each other (search.FACING) and each centroid
    in front of the other's face, within the larger face's size (a conforming or slightly overlapping pair)."""
    tol = np.maximum(a[..., 6], b[..., 6])
    return ((_dot(a[..., 3:6], b[..., 3:6]) <= FACING) & (_dot(b[..., :3] - a[..., :3], a[..., 3:6]) >= -tol)
            & (_dot(a[..., :3] - b[..., :3], b[..., 3:6]) >= -tol))


def _touching(own, them, chunk=1 << 18):
    """Which of own's faces (rows of _face_geometry) can touch one of them's (_pairs_touch). First each face
    against those of them within the largest face's size (the faces that touch find each other there), then
    the rest against them grouped by their normals' direction: a group none of whose normals can face the face
    (its mean normal and spread), or whose faces' box lies wholly behind it, is passed over. Every pair tested
    took 17 s for two stacked cubes' whole skins of 38,400 faces each (hunt29_2); the answer is the same."""
    out = np.zeros(len(own), dtype=bool)
    if not len(own) or not len(them):
        return out
    reach = max(float(own[:, 6].max()), float(them[:, 6].max()))
    p, f = candidate_pairs(own[:, :3], them[:, 7:10], them[:, 10:13], reach)
    out[np.unique(p[_pairs_touch(own[p], them[f])])] = True
    key = np.round(2.0 * them[:, 3:6]).astype(np.int64) @ np.array([25, 5, 1])
    for group in np.split(np.argsort(key, kind="stable"), np.flatnonzero(np.diff(np.sort(key))) + 1):
        rest = np.flatnonzero(~out)
        if not len(rest):
            break
        b = them[group]
        mean = b[:, 3:6].sum(axis=0)
        mean /= np.linalg.norm(mean)
        spread = float(np.linalg.norm(b[:, 3:6] - mean, axis=1).max())
        a = own[rest]
        hope = (a[:, 3:6] @ mean - spread <= FACING) & _ahead(a, b[:, 7:10].min(axis=0), b[:, 10:13].max(axis=0),
                                                               a[:, 6] + b[:, 6].max())
        rest = rest[hope]
        step = max(1, chunk // len(group))
        for first in range(0, len(rest), step):
            some = rest[first:first + step]
            out[some] = _pairs_touch(own[some, None, :], b[None, :, :]).any(axis=1)
    return out


def touching_sizes(mesh, S, M):
    """The mean sizes of the faces of S and of M that can touch the other surface (_touching; collective). A
    surface that holds more than its touching faces (a body's whole skin: a punch's thin side faces, a plate's
    far side) sets the penalty and the search's reach by the faces that touch, not by all of them (hunt28_6 F2: a
    punch's thin sides took the reach below the gap); one with none such (a knife's edge) by all its faces."""
    comm = mesh.comm
    own = [_face_geometry(mesh, S), _face_geometry(mesh, M)]
    every = [np.concatenate(comm.allgather(g)) for g in own]
    return [_mean_over(comm, own[i][_touching(own[i], every[1 - i]), 6], surface.mean_size)
            for i, surface in enumerate((S, M))]


def _refuse_not_convex(mesh, index, S, M):
    """A MeshError on every rank when a face of pair `index`'s surfaces is not strictly convex in its own plane
    (a quad with a reflex or straight corner passes the cell check, which reads det J at the Gauss points):
    segment rows dropped such a master face in silence, the patch test 2-3 % off, "ok", and refused a slave one
    with "S face of pair 57 is degenerate or not convex", naming no surface or place (hunt35_4). The face named
    is the first by x, y, z of its centre, on any number of ranks (collective)."""
    from .clipping import not_convex
    for side, surface in (("slave", S), ("master", M)):
        xf = mesh.coords[surface.faces]
        bad = xf[not_convex(mesh.face_type, xf)].mean(axis=1) if len(xf) else np.zeros((0, 3))
        found = np.concatenate(mesh.comm.allgather(bad))
        if len(found):
            first = found[np.lexsort(found.T[::-1])[0]]
            raise MeshError(f"contact[{index}].{side} ({surface.name}): {len(found)} face(s) not strictly convex in "
                            f"their own plane (a reflex or straight corner), the first centred at x, y, z = "
                            f"{', '.join(f'{v:.4g}' for v in first)}: segment rows cannot clip them; mend the mesh "
                            f"there, or use integration = \"gauss\" or \"nodal\"")


def contact_pairs_data(mesh, scene, template, mirrored=None):
    """Surfaces, penalty scale and search radius of every contact pair."""
    pairs = []
    mirrored = symmetry_components(mesh, scene) if mirrored is None else mirrored
    for i, pair in enumerate(scene.contact):
        S = surface_data(mesh, pair.slave, template)
        M = surface_data(mesh, pair.master, template)
        E = min(scene.bodies[S.body].material.youngs_modulus, scene.bodies[M.body].material.youngs_modulus)
        if pair.integration == "segment":
            _refuse_not_convex(mesh, i, S, M)
        sizes = touching_sizes(mesh, S, M)
        h_eff = min(sizes)
        # each side's convex folds (the unforced warning says the deepest sunk node's), and with feature_angle its
        # feature nodes
        folds = {"slave": ridge_tilts(mesh, S, mirrored), "master": ridge_tilts(mesh, M, mirrored)}
        features = None
        if pair.feature_angle is not None:
            angle = np.radians(pair.feature_angle)
            features = {"slave": folds["slave"] > angle, "master": folds["master"] > angle,
                        "sharp": {"slave": np.zeros(len(S.nodes), dtype=bool),
                                  "master": np.zeros(len(M.nodes), dtype=bool)}}
        pairs.append({"index": i, "spec": pair, "slave": S, "master": M, "h_eff": h_eff, "sizes": sizes,
                      "eps_n": pair.penalty * E / h_eff,
                      "radius": pair.search_distance * h_eff * (1.0 + REACH_SLACK),
                      "features": features, "folds": folds,
                      "memo": {"slave": {}, "master": {}, "master_nodes": {}, "features_slave": {},
                               "features_master": {}, "facing_slave": {}, "facing_master": {}}})     # _search_pass
    return pairs


def die_data(mesh, scene, template):
    dies = []
    for i, die in enumerate(scene.die):
        surfaces = [surface_data(mesh, s, template) for s in die.surfaces]
        # the die's surfaces as one: a node on two of them (a face split into groups) has its whole area, not
        # the first-listed one's (the seam read twice the pressure)
        whole = surfaces[0] if len(surfaces) == 1 else surface_data(mesh, die.surfaces, template)
        # the faces of them all turned towards the die (search.FACING) set its element size, as a pair's touching
        # faces do (each listed surface on its own let a side with none turned give all its thin faces; hunt29_2)
        n = np.asarray(die.normal, dtype=float) / np.linalg.norm(die.normal)
        g = _face_geometry(mesh, whole)
        h = _mean_over(mesh.comm, g[facing_pairs(g[:, 3:6], n[None, :]), 6], whole.mean_size)
        E = min(scene.bodies[s.body].material.youngs_modulus for s in surfaces)   # one E: scene.py checks it
        dies.append({"index": i, "spec": die, "surface": whole, "nodes": whole.nodes, "area": whole.area, "h": h,
                     "eps_n": die.penalty * E / h,
                     "radius": die.search_distance * h * (1.0 + REACH_SLACK),
                     "total_area": whole.total_area, "surfaces": [(s.name, s.nodes) for s in surfaces],
                     "bodies": sorted({s.body for s in surfaces})})
    return dies


# feature rows (ContactModel._facing_features): a node of the other surface whose closest point lies this near a
# feature node's ridge (the shape functions of the face's feature nodes summing to at least this) takes a nodal
# row beside its own. Put in place of its own, a shallow knife's plate nodes pressed deep lost their segment
# rows, and the force fell from nodal two_pass's to 4 % under it
FACING_RIDGE = 0.5
# the unforced warning calls a sunk node's surface flat below this fold (degrees; ridge_tilts)
FLAT_FOLD = 1.0
# a pair's or die's gaps are differences of coordinates, known to eps |x|: far from the origin they are round-off
# below that, and a penalty's penetrations (~1e-7 h at alpha 1e4) are lost in it. Said (precision_warnings) when
# eps |x| passes this share of the pair's h_eff: the two cubes moved 1e6 m (eps |x| 3.4e-9 h) kept their answer,
# 1e9 m (3.4e-6 h) read penetrations 2-15x off, 1e14 m 97 % off in displacement, each "ok" with no word (hunt30_4)
COORDINATE_PRECISION = 1e-8
# _gap_change's floor on the penetration it measures against: this times eps |x| (x: the pair's nodes) over
# reuse_tolerance. Two searches of the same state moved the gaps by 0.1-0.15 eps |x| (the sliding cubes at alpha
# 1e8 under a 2e-6 press: 3-6e-17 m against penetrations of 4e-15 m, which never settled; hunt30_7)
GAP_ROUND_OFF = 0.3
# large sliding (ContactModel._relaxation): the bounds of Aitken's relaxation of the search configuration (1.5
# before the edge band: two_pass with nodal rows in 16 steps on the sliding cubes crept by 0.87 a search at 1.5
# and did not settle in 20; at 5 and 10 every slide of sliding_cubes, 3 formulations x 3 rules x 1 / 2 / 16
# steps, took the same searches as at 1.5, that one settling)
MIN_RELAXATION = 0.1
MAX_RELAXATION = 5.0
# sliding = "small" is said to be out of its range once a pressed node faces an opposite material point
# this many h_eff from the one it faced at u = 0, and finite sliding once it has in one step (ContactModel.slip_warnings)
SLIP_WARNING = 0.5
# finite sliding is also said to be out of its range when nodes facing nothing of the other surface carry this share
# of a pair's normal force (0.04-0.07 where large sliding settled on configs/sliding_cubes.toml: master nodes past
# the slave's edge that its rows press; 0.61-1.0 where a 1.2 m slide in two steps had left the lower cube)
UNFACED_WARNING = 0.5
# ... once the step slid the contact by more than this many h_eff (slip_warnings; hunt32_1: a punch on a coarser
# block, 0.007 h_eff a step)
UNFACED_SLIP = 0.05
# finite sliding is said to overshoot when its slip per step grew at every other step for SLIP_GROWTH_STEPS steps,
# SLIP_GROWTH times in all, to more than SLIP_GROWTH_FLOOR x h_eff: rows searched at each step's start that
# overshoot (a tilted block's edge in the dent it presses: 0.0037 -> 0.024 m over steps 41-47 of 64, then 0.43 m a
# step, the answer 25 % off large sliding's and worse with more steps; 1-2x on configs/ scenes' constant slips)
SLIP_GROWTH_STEPS = 6
SLIP_GROWTH = 4.0
SLIP_GROWTH_FLOOR = 0.05
# a pair is said to let nodes through when a node that carries no contact force penetrates the other surface by
# more than UNFORCED_WARNING x h_eff and UNFORCED_RATIO x the deepest pressed node (ContactModel.slip_warnings): a
# chisel's 60-degree edge under segment or Gauss rows sank the whole stroke with no force (weighted gaps spread it
# over the edge's faces, open beside it; hunt28_5 F4), while at a contact zone's rim, where rows open, a node is
# shallower than the pressed ones
UNFORCED_WARNING = 1e-3
UNFORCED_RATIO = 10.0
# penalty rows (ContactModel.slip_warnings): pressed nodes deeper than DEEP_PENETRATION x h_eff are a penalty too soft
# for the load (alpha 1 on the patch test at p = 0.5 E: 0.5 h_eff, no word; flat_punch at alpha 1: its force 11 %
# low; hunt33_3), and penetrations p / eps_n (the slave's pressed nodes' mean pressure) below ROUND_OFF_PENETRATION x
# eps |x| (x: the farthest node of the pair's surfaces) are round-off: alpha 1e10 at a strain of 1e-6 left 1.4e-17 m
# (0.06 eps |x|), and the nodes read -2.5 to -6.2 times that (hunt33_3), while at 64 eps |x| (alpha 1e10, p = 1e-3 E)
# they read p / eps_n to 0.1 % (hunt33_6); a faceted sphere's nodes read 1000x their p / eps_n off by its facets'
# sagitta, which no rule on their sign could tell from round-off
DEEP_PENETRATION = 0.1
# ... and pressed nodes that sink this many times their own pressure's p / eps_n are not the penalty's doing: their
# rows do not hold them (quasi_symmetric's nodal rows, coarse slave, 10x mesh ratio; hunt32_2)
UNHELD_DEPTH = 100.0
# ... for a pair whose pressure strains the bodies more than this (p / E): a floating stack's pairs at a strain of
# 1e-14 had round-off depths (hunt35_2), steel under 1 kPa (5e-9) a soft penalty 14 % off (hunt35_3)
LOADED_STRAIN = 1e-12
COARSER = 1.2            # a surface whose touching faces are this much larger than the other's is the coarser
ROUND_OFF_PENETRATION = 10.0
# ... and pressed nodes (of a pair or a die) deeper than SOFT_PENALTY x the largest displacement of the bodies they
# belong to: flat_punch (coarse) at alpha 1 was 11 % low with its deepest node at 0.024 h_eff and 0.18 of the
# punch's travel; a die at alpha 0.1 left the punch's force 45 % low (hunt33_6)
SOFT_PENALTY = 0.05


class ContactModel:
    """Builds the constraint terms of every contact pair and die at each search, and reports on them."""

    def __init__(self, mesh, scene, template, phases=None):
        self.mesh, self.scene, self.comm = mesh, scene, mesh.comm
        self.template = template
        self.phases = phases
        # the components normal to the symmetry planes each vertex lies on (the folds' and tractions' mirror images)
        self.mirrored = symmetry_components(mesh, scene) if scene.contact else None
        self.pairs = contact_pairs_data(mesh, scene, template, self.mirrored)
        self.dies = die_data(mesh, scene, template)
        self.current = []
        self.faced_at_start = {}   # (pair, side): the opposite material point each node faced at u = 0 (report)
        self.faced_last = {}       # (pair, side): the same at the last report
        self.slip_warned = set()
        self.step_slips = {}           # finite-sliding pairs' max_slip_step, step by step (slip_warnings)
        self.met = set()           # the pairs whose surfaces a search has found within reach (_check_found)
        self.apart = set()         # the pairs last said to have no rows (slip_warnings)
        self.unforced = {}         # per pair: the sides whose nodes its last report found sunk in with no force
        # per pair: (deepest pressed node, slave's pressed mean, their p / eps_n, |x|, the bodies' deformation) [m]
        self.pressed_depth = {}
        # per die: (deepest node that carries force, its bodies' deformation, its farthest node from the origin) [m]
        self.die_depth = {}
        self.through_die = {}      # per die pressing none of its surfaces: its bodies' nodes past its plane (_through_die)
        # per pair (report): the load factor of the search that made its rows, whether the last search kept an
        # earlier search's, the last search's _gap_change, and the searches of the last increment
        self.searches = {f"contact[{pd['index']}]": {"load_factor": 0.0, "gap_change": None, "kept": False, "count": 0}
                         for pd in self.pairs}
        self.t = 0.0
        self.prepared = None       # (load factor, {name: term}) of prepare(), until the search it was made for
        # per large-sliding pair, over an increment's searches (settle, _relaxation): the configuration U last
        # searched at ("at"), the last residual U - at on the pair's surface nodes ("r") and its relaxation ("w")
        self.settling = {}

    def hold_warnings(self, dofs, values, per_boundary):
        """Warning lines for each die whose rows fight a displacement or symmetry boundary (dofs: the owned held
        dofs, sorted; values at full load; per_boundary: each boundary's, as assembly.dirichlet_dofs gives them),
        with the motions at full load, the held components of a node moving with their values and its others
        left still: a die whose motion drives into nodes held along its whole normal (frictionless too), and a
        sticking die that moves the nodes it touches (at the start, or at the end of its motion) in a component
        that a boundary holds at another value, unless their hold lifts them off it. Either way the die's force
        grows with its penalty (a sticking die dragged across a symmetry plane: 5e4 N, said by nothing; hunt31_2;
        a frictionless die onto a clamped face, and a sticking one reaching its nodes later, were not said; a
        support lifting a floor's edge off a sticking floor was said to fight it: hunt31_3; an inclined die's drag
        was missed: hunt31_5). Collective."""
        mesh, lines = self.mesh, []
        tol = self.scene.solver.active_set_tolerance
        for dd in self.dies:
            spec = dd["spec"]
            own = mesh.owned[dd["nodes"]]
            v = dd["nodes"][own]
            n, motion = np.asarray(spec.normal, dtype=float), np.asarray(spec.motion, dtype=float)
            wanted = 3 * mesh.gvert[v][:, None] + np.arange(3)
            at = np.minimum(np.searchsorted(dofs, wanted), max(len(dofs) - 1, 0))
            # a rank may hold no held dof
            held, value = ((dofs[at] == wanted, values[at]) if len(dofs) else
                           (np.zeros(wanted.shape, dtype=bool), np.zeros(wanted.shape)))
            moved = np.where(held, value, 0.0)
            across = np.abs(n) > 1e-12                       # the components along the die's normal
            normal_held = held[:, across].all(axis=1)
            U = np.zeros_like(mesh.coords)
            start = _on_die(dd, _die_depth(dd, mesh.coords, U, 0.0)[own], tol)
            U[v] = moved
            end = _die_depth(dd, mesh.coords, U, 1.0)[own]   # the depth at full load
            # the hold lifts the node off the die (or the die moves off a node held along its normal; a node free
            # along it may follow the die, pressed by the body: such a die was taken to move off; hunt31_6)
            apart = normal_held & ((moved - motion) @ n > 1e-12 * max(np.abs(motion).max(initial=0.0),
                                                                       np.abs(moved).max(initial=0.0)))
            push = normal_held & (end > 1e-9 * dd["h"])
            pushing = push[:, None] & across[None, :] & held
            fights = [("pushes", pushing)]
            if spec.condition == "sticking":
                # a node stuck to the die moves with it in every component (an inclined die's too; hunt31_5)
                touches = (start | _on_die(dd, end, tol)) & ~apart
                other = np.abs(value - motion) > 1e-12 * np.maximum(np.abs(motion), np.abs(value))
                fights.append(("drags", touches[:, None] & held & other & ~pushing))
            for how, mask in fights:
                bad = wanted[mask]
                for i, own in enumerate(per_boundary):
                    mine = np.isin(bad, own)
                    count = self.comm.allreduce(len(np.unique(bad[mine] // 3)), op=MPI.SUM)
                    if not count:
                        continue
                    comps = sorted(set().union(*self.comm.allgather({int(c) for c in bad[mine] % 3})))
                    bc = self.scene.boundary[i]
                    what = ("moves onto" if how == "pushes" else "sticks to and moves")
                    lines.append(f"die[{dd['index']}] {spec.name} ({spec.condition}, moving "
                                 f"{', '.join(f'{m:g}' for m in motion)} m) {what} {count} node(s) whose "
                                 f"{', '.join('u' + 'xyz'[c] for c in comps)} boundary[{i}] ({bc.surface}, "
                                 f"{bc.type}) holds otherwise: the die's rows and the hold fight, and the die's force "
                                 f"grows with its penalty")
        return lines

    def die_away_warnings(self):
        """Lines naming the dies with nodes of their surfaces on or past their plane, at u = 0, whose faces turn away
        from them and which no row holds: the die would go through them (a normal the wrong way round, or a die on
        an edge of a surface that does not face it; hunt31_2). `qsc check` and a run's start say them (the run
        said nothing, its die's force 0; hunt33_5). Collective."""
        lines = []
        X = self.mesh.coords
        for dd in self.dies:
            depth = _die_depth(dd, X, 0.0 * X, 0.0)
            on = _on_die(dd, depth, self.scene.solver.active_set_tolerance)
            turned = _turned_to_die(self.mesh, dd, X)
            away = self.comm.allreduce(int((~turned & on & self.mesh.owned[dd["nodes"]]).sum()), op=MPI.SUM)
            if not away:
                continue
            # nodes of faces turned towards the die past its plane too: the die starts inside the body, whose
            # sides' nodes are past it by that overlap, not by a wrong normal (a whole skin 0.15 m into the die
            # was told to check its normal; hunt33_6)
            inside = self.comm.allreduce(float(depth[turned].max(initial=0.0)), op=MPI.MAX)
            why = (f"the die starts {inside:.3g} m = {inside / dd['h']:.2g} element sizes into the body (nodes of "
                   f"faces turned towards it lie that far past its plane, and its rows push them out in the first "
                   f"increment): start its plane at the surface it presses, or list only the surfaces that face it"
                   if inside > UNFORCED_WARNING * dd["h"] else DIE_AWAY)
            lines.append(f"die[{dd['index']}] {dd['spec'].name}: {away} node(s) of its surfaces lie on or past its "
                         f"plane with faces turned away from it, and no row: {why}")
        return lines

    def precision_warnings(self):
        """A line (in a list; none if all is well) naming the pairs and dies whose element size is within
        1 / COORDINATE_PRECISION of their coordinates' precision, eps |x| (x: the farthest node of the pair's
        surfaces, or of the die's with its plane's offset) (collective). A body or a die's point far from a
        contact that lies near the origin raised it at first (hunt30_7)."""
        X = self.mesh.coords

        def farthest(nodes):
            return self.comm.allreduce(float(np.abs(X[nodes]).max(initial=0.0)), op=MPI.MAX)

        entries = [(f"contact[{pd['index']}]", pd["h_eff"], max(farthest(pd["slave"].nodes), farthest(pd["master"].nodes)))
                   for pd in self.pairs]
        for dd in self.dies:
            n = np.asarray(dd["spec"].normal, dtype=float) / np.linalg.norm(dd["spec"].normal)
            offset = float(np.abs(np.asarray(dd["spec"].point, dtype=float) * n).max())   # the gaps' (x - p) . n
            entries.append((f"die[{dd['index']}]", dd["h"], max(farthest(dd["nodes"]), offset)))
        eps = np.finfo(float).eps
        near = [(name, h, reach) for name, h, reach in entries if eps * reach > COORDINATE_PRECISION * h]
        if not near:
            return []
        listed = ", ".join(f"{name} ({reach:.3g} m out, known to {eps * reach:.2g} m, {eps * reach / h:.2g} of its "
                           f"element size {h:.3g} m)" for name, h, reach in near)
        line = (f"far from the origin: {listed}: gaps and penetrations are round-off below that (a penalty's are "
                f"~1e-7 of the element size at alpha 1e4), and the answer may be off with no other sign; move the "
                f"scene nearer the origin")
        return [line]

    def _phase(self, name):
        from contextlib import nullcontext
        return self.phases(name) if self.phases else nullcontext()

    def _term(self, name, rows, eps_n, h, augmented, node_local=False, alpha=None):
        mesh = self.mesh
        G = assembly.triplet_matrix(mesh, rows.G_rows, rows.G_cols, rows.G_vals)
        g = assembly.row_vector(mesh, rows.g_rows, rows.g_vals, self.template)
        W = assembly.row_vector(mesh, rows.W_rows, rows.W_vals, self.template)
        r0 = self.template.getOwnershipRange()[0]
        w = W.getArray()
        exists = w > 0                     # the term works on the rows that exist
        closed = self.scene.solver.active_set_tolerance * w[exists] * h
        gate = None
        if len(rows.gate_rows):
            gate = gate_positions(np.flatnonzero(exists) + r0, rows.gate_rows, rows.gate_of)
        # the triplets make G and W: the same triplets on every rank, the same rows (a digest of G's CSR read
        # all of G's rows, every dof's: 0.07 s a search at 212k dofs)
        digest = array_digest(rows.G_rows, rows.G_cols, rows.G_vals, rows.W_rows, rows.W_vals)
        return ConstraintTerm(name, G, g, W, rows.phi, eps_n, closed, gate, augmented, node_local, alpha,
                              digest=digest)

    def terms(self, u, t, t0=0.0, before=None):
        """New search at the current displacement u, the converged state at load factor t0, for the increment to
        load factor t (before: None, or (t_a, u_a), the converged state before u, whose path to u sticking dies
        extend to find where their nodes meet them): one ConstraintTerm per pair and die. A pair
        with small sliding keeps the term of its first search (its rows and, with the augmented Lagrangian,
        its multipliers); one with finite or large sliding keeps its last term when the new search's rows are
        those rows with gaps within reuse_tolerance of them (_gap_change)."""
        small = {f"contact[{pd['index']}]" for pd in self.pairs if pd["spec"].sliding == "small"}
        reusable = {f"contact[{pd['index']}]" for pd in self.pairs
                    if pd["spec"].sliding != "small" and pd["spec"].reuse_tolerance > 0}
        kept = {term.name: term for term in self.current if term.name in small}
        last = {term.name: term for term in self.current if term.name in reusable}
        for term in self.current:
            if term.name not in kept and term.name not in last:
                term.destroy()
        mesh = self.mesh
        U, X = mesh.local_vectors(u), mesh.coords
        prepared = self._take_prepared(U, t)
        self.t = t
        out = []
        for pd in self.pairs:
            name = f"contact[{pd['index']}]"
            if name in kept:
                out.append(kept[name])
                self.searches[name] = dict(self.searches[name], gap_change=None, kept=True, count=0)
                continue
            if name not in prepared:
                for memo in pd["memo"].values():     # an increment's first search takes the nearest faces
                    memo.clear()
            out.append(prepared.pop(name) if name in prepared else self._search(pd, U, u, t, last.get(name)))
            self.searches[name]["count"] = 1
            if pd["spec"].sliding == "large":
                self.settling[name] = {"at": U, "r": None, "w": 1.0}
        rate = None          # the nodes' displacement per unit load factor on the path to u (_stick_anchors)
        if before is not None and t0 > before[0] and any(dd["spec"].condition == "sticking" for dd in self.dies):
            rate = (U - mesh.local_vectors(before[1])) / (t0 - before[0])
        for dd in self.dies:
            spec = dd["spec"]
            with self._phase("rows"):
                n = np.asarray(spec.normal, dtype=float)
                u_die = t * np.asarray(spec.motion, dtype=float)
                v = dd["nodes"]
                # the nodes within reach whose surface is turned towards the die (search.FACING, the die's normal
                # as the other surface's), each with its area on the faces turned towards it (facing_areas): a
                # body's whole skin as the die's surface gave the nodes of its sides rows and the edge nodes the
                # sides' areas (the contact area 1.5 for a 1 m2 face)
                S = dd["surface"]
                turned = _turned_to_die(mesh, dd, X + U)
                # within reach of the die where it stands at the increment's start or end: one that moves away
                # dropped, from its end, every node it held at the start (OUT_OF_REACH after cutbacks; hunt35_1)
                within = -np.maximum(_die_depth(dd, X, U, t0), _die_depth(dd, X, U, t)) <= dd["radius"]
                near = within & turned
                dd["near"] = near                   # the nodes with rows (missed)
                dd["away"] = within & ~turned       # within reach, of faces turned away (missed, contact_plan)
                toward = {"face": np.zeros(len(v), dtype=np.int64), "normal": np.tile(n, (len(v), 1))}
                dd["area"] = facing_areas(mesh, S, X, U, slice(None), toward)[0]
                anchor = self._stick_anchors(dd, X, U, t, t0, rate)[near] if spec.condition == "sticking" else None
                rows = row_builders.die_rows(mesh.gvert[v[near]], dd["area"][near], X[v[near]], spec.point, n,
                                             u_die, spec.condition == "sticking", anchor)
                term = self._term(f"die[{dd['index']}]", rows, dd["eps_n"], dd["h"], False, node_local=True)
                term.pressure_floor = FLOOR_STRAIN * dd["eps_n"] * dd["h"] / spec.penalty   # E FLOOR_STRAIN
                out.append(term)
        self.current = out
        return out

    def _stick_anchors(self, dd, X, U, t, t0, rate=None):
        """A sticking die's anchors (die_rows): where on the die, in its tangents, each of its nodes sticks during
        the increment from the converged state U at load factor t0 to t. A node that touched the die at t0 keeps
        the anchor it was held at; one apart from it sticks where it would meet the die, both going on as they
        came: the die along its motion, the node at `rate` (its displacement per unit load factor on the path to
        U, or none), until the gap it had at t0 is closed (at t0 when they do not approach each other). The
        anchors measured the slip from the undeformed state: a block that a die reached after moving sideways
        0.025 was sheared by the die's whole travel, 2x the force (hunt31_2); a body lifted onto a die that
        slides met it where the die's approach alone said (up to 2x again at 1-4 steps; hunt31_3). A try from
        the same t0 (after a cutback) starts from the same anchors."""
        spec, v = dd["spec"], dd["nodes"]
        n, motion = np.asarray(spec.normal, dtype=float), np.asarray(spec.motion, dtype=float)
        T = row_builders.die_tangents(n)
        state = dd.setdefault("stick", {"t0": 0.0, "held": np.zeros((len(v), 2)), "t": None, "used": None})
        depth = _die_depth(dd, X, U, t0)
        touching = _on_die(dd, depth, self.scene.solver.active_set_tolerance)
        if state["t"] is not None and abs(t0 - state["t"]) <= 1e-12 and abs(t0 - state["t0"]) > 1e-12:
            # the last try converged (its state is u): the nodes that touch the die at t0 keep its anchors
            state["held"] = np.where(touching[:, None], state["used"], 0.0)
            state["t0"] = t0
        elif abs(t0 - state["t0"]) > 1e-12:
            raise RuntimeError(f"die[{dd['index']}]: an increment from load factor {t0} after tries at "
                               f"{state['t0']} to {state['t']}")
        # each node's relative velocity (per unit load factor) against the die, and its approach over the increment
        relative = -motion if rate is None else rate[v] - motion
        approach = -(t - t0) * (relative @ n)
        meet = np.where(approach > 0, np.clip(-depth / np.where(approach > 0, approach, 1.0), 0.0, 1.0), 0.0)
        fresh = (U[v] - t0 * motion + (meet * (t - t0))[:, None] * relative) @ T.T
        used = np.where(touching[:, None], state["held"], fresh)
        # the nodes apart when no path was known (the run's first increment): pathless_met counts those that met it
        state["t"], state["used"], state["pathless"] = t, used, ~touching if rate is None else None
        return used

    def missed(self, u):
        """After a converged solve: the first die or finite-sliding pair with nodes that had no row (out of its
        reach at the increment's search) and penetrate at u, as ("die[i] (name): n node(s)" or "contact[i]
        (slave / master): n node(s)", cause), or None (collective). The cause is "reach", or "away" for a die's
        nodes within its reach whose faces turn away from it (a normal given the wrong way round, or a surface
        that does not face the die: its message said to raise the reach, which changed nothing; hunt31_2). A node
        farther than the search distance at an increment's start went through the die, or into the other surface,
        unheld (exit 0, no force).

        A pair's nodes are those of the sides that hold rows (the slave's; two_pass: the master's too): one
        without a row that now faces the other surface fully (edge_factor 1: not merely beside its edge) and
        penetrates it. Large sliding needs no check (its searches settle at the converged state), small
        sliding's rows are the run's by choice."""
        mesh = self.mesh
        U, X = mesh.local_vectors(u), mesh.coords
        for dd in self.dies:             # dd["near"]: the nodes the increment's search (terms) gave rows
            through = ~dd["near"] & (_die_depth(dd, X, U, self.t) > 0)
            count, away = (self.comm.allreduce(int(x.sum()), op=MPI.SUM) for x in (through, through & dd["away"]))
            if away:
                return f"die[{dd['index']}] ({dd['spec'].name}): {away} node(s)", "away"
            if count:
                return f"die[{dd['index']}] ({dd['spec'].name}): {count} node(s)", "reach"
        terms = {t.name: t for t in self.current}
        for pd in self.pairs:
            if pd["spec"].sliding != "finite":
                continue
            W = terms[f"contact[{pd['index']}]"].W.getArray().reshape(-1, 3)[:, 0]
            count = 0
            for S, T in ((pd["slave"], pd["master"]), (pd["master"], pd["slave"])):
                if S is pd["slave"] and _no_own_weight(pd["spec"]):
                    continue                 # quasi_symmetric's slave at weight 0: its rows are the master's points'
                if S is pd["master"] and pd["spec"].formulation != "two_pass":
                    continue                 # its nodes are not held, but for feature rows (a sharp master's
                    # others went on penetrating the slave, as master_slave lets them: OUT_OF_REACH; hunt30_3)
                held = W[_owned_rows(mesh, S.nodes)] > 0
                if not self.comm.allreduce(bool(held.any()), op=MPI.LOR):
                    continue                 # a side without rows (master_slave's master)
                found = project_pass(mesh, S, T, X, U, pd["radius"], which=~held, weighted=False)[2]
                tol = self.scene.solver.active_set_tolerance * pd["h_eff"]
                count += int(((found["edge_factor"] == 1.0) & (-found["signed_gap"] > tol)).sum())
            count = self.comm.allreduce(count, op=MPI.SUM)
            if count:
                return f"contact[{pd['index']}] ({pd['spec'].slave} / {pd['spec'].master}): {count} node(s)", "reach"
        return None

    def prepare(self, t):
        """The first increment's search of every pair (at u = 0, load factor t), made before K is assembled so
        that K's pattern can hold the pairs' contact stencil and J need not be made anew with a wider one
        (set_terms; MatAXPY with a new pattern re-inserted every entry of K, 0.42 s at 212k dofs). Returns the
        stencil's entries by 3x3 block (K's `extra`: rows owned here) and the digests of the pairs' stencils
        (ConstraintTerm.stencil_digest); the first terms() call, at u = 0 and t, takes these terms instead of
        searching again (collective)."""
        u = self.template.duplicate()
        u.set(0.0)
        U = self.mesh.local_vectors(u)
        self.prepared = (t, {f"contact[{pd['index']}]": self._search(pd, U, u, t, None) for pd in self.pairs})
        u.destroy()
        rows, cols, digests = [], [], []
        r0 = self.template.getOwnershipRange()[0]          # G^T G's rows are the dofs'
        with self._phase("rows"):
            for term in self.prepared[1].values():
                ia, ja = term.stencil_pattern()
                rows.append(np.repeat(np.arange(len(ia) - 1), np.diff(ia)) + r0)
                cols.append(ja)
                digests.append(term.stencil_digest())
        if not digests:
            return None, []
        rows, cols = np.concatenate(rows).astype(np.int64), np.concatenate(cols).astype(np.int64)
        bits = np.left_shift(1, 3 * (rows % 3) + cols % 3)       # the entry's place in its 3x3 block
        return (rows // 3, cols // 3, bits), digests

    def _take_prepared(self, U, t):
        """The terms prepare() made, {name: term}, if this search is the one they were made for (at u = 0, load
        factor t; collective); {} otherwise, and they are destroyed. Either way only once."""
        if self.prepared is None:
            return {}
        at, terms = self.prepared
        self.prepared = None
        if at == t and self.comm.allreduce(not U.any(), op=MPI.LAND):
            return terms
        for term in terms.values():
            term.destroy()
        return {}

    def _search(self, pd, U, u, t, last):
        """Pair pd's term from a new search at local displacements U (u: the same as a Vec), load factor t:
        `last` (the pair's last term, or None) instead when the new rows are its rows with gaps within
        reuse_tolerance of theirs at u; the term not returned is destroyed."""
        mesh, spec, X = self.mesh, pd["spec"], self.mesh.coords
        name = f"contact[{pd['index']}]"
        with self._phase("search"):
            memo = pd["memo"]
            sp = integration_pass(mesh, spec, pd["slave"], pd["master"], X, U, pd["radius"], memo["slave"])
            mp = None
            if spec.formulation != "master_slave":
                mp = integration_pass(mesh, spec, pd["master"], pd["slave"], X, U, pd["radius"], memo["master"])
        points = self._check_found(pd, sp, mp)
        with self._phase("rows"):
            if spec.formulation == "master_slave":
                rows = row_builders.master_slave(sp)
            elif spec.formulation == "two_pass":
                rows = row_builders.two_pass(sp, mp)
            else:
                weight = spec.weight.to_dict() if hasattr(spec.weight, "to_dict") else spec.weight
                if spec.master_multiplier == "master_nodes" and spec.integration != "nodal":
                    with self._phase("search"):
                        node_pass = project_pass(mesh, pd["master"], pd["slave"], X, U, pd["radius"],
                                                 memo["master_nodes"])[0]
                    rows = row_builders.quasi_symmetric_master_nodes(sp, mp, node_pass, weight,
                                                                     move=self._to_row_owners)
                else:
                    rows = row_builders.quasi_symmetric(sp, mp, weight)
            feature_rows = 0
            if pd["features"] is not None:
                with self._phase("search"):
                    passes, feature_ids, extra = self._feature_passes(pd, X, U)
                rows = row_builders.with_nodal_rows(rows, passes, feature_ids, extra)
                feature_rows = len(feature_ids) + self.comm.allreduce(
                    sum(len(np.unique(pss.node)) for pss in extra), op=MPI.SUM)
            term = self._term(name, rows, pd["eps_n"], pd["h_eff"], spec.enforcement == "augmented_lagrangian",
                              alpha=spec.penalty)
            term.feature_rows = feature_rows
            term.points = points
            term.augmented_tolerance = spec.augmented_tolerance
            # the pressure of a strain of FLOOR_STRAIN: E_eff FLOOR_STRAIN, E_eff = eps_n h_eff / alpha
            term.pressure_floor = FLOOR_STRAIN * pd["eps_n"] * pd["h_eff"] / spec.penalty
            change, reused = None, False
            if last is not None:
                nodes = np.concatenate([pd["slave"].nodes, pd["master"].nodes])
                reach = self.comm.allreduce(float(np.abs(X[nodes] + U[nodes]).max(initial=0.0)), op=MPI.MAX)
                # the depth no smaller than what the coordinates resolve at the pair's tolerance (GAP_ROUND_OFF)
                floor = (GAP_ROUND_OFF * np.finfo(float).eps * reach / spec.reuse_tolerance
                         if spec.reuse_tolerance > 0 else 0.0)
                change = _gap_change(last, term, u, floor)
                reused = change <= spec.reuse_tolerance
                if not reused and term.lmbda is not None and last.lmbda is not None and self.comm.allreduce(
                        np.array_equal(last.rows, term.rows), op=MPI.LAND):
                    term.lmbda = last.lmbda.copy()     # the same rows: the Uzawa loop starts on their multipliers
                (term if reused else last).destroy()
                term = last if reused else term
            searched_for = self.searches[name]["load_factor"] if reused else t
            self.searches[name] = dict(self.searches[name], load_factor=searched_for, gap_change=change, kept=reused)
        return term

    def _feature_passes(self, pd, X, U):
        """The nodal passes against the other surface of the feature nodes (ridge_tilts), the global row ids of
        those that found a face (every rank's), whose rows are to be these, and the nodal passes of the nodes that
        face one (_facing_features), whose rows are added (rows.with_nodal_rows). Collective."""
        passes, ids, sharp, extra = [], [], {}, []
        lean = np.cos(np.radians(pd["spec"].feature_angle))
        sides = (("slave", pd["slave"], pd["master"]), ("master", pd["master"], pd["slave"]))
        for side, S, T in sides:
            which = pd["features"][side]
            sharp[side] = np.zeros(len(S.nodes), dtype=bool)
            if not self.comm.allreduce(bool(which.any()), op=MPI.LOR):
                continue
            fp, ok, found = project_pass(self.mesh, S, T, X, U, pd["radius"], pd["memo"][f"features_{side}"],
                                         which)
            # the ridge's faces that can meet the other surface lean away from it: a box's edge whose face lies
            # on the other surface is held by that face's rows. A node found so keeps its row for the run: at a
            # threshold, rows that came and went made large sliding's searches cycle (hunt30_3)
            held = pd["features"]["sharp"][side]
            held[which] |= ok & (facing_lean(self.mesh, S, X, U, which, found) < lean)
            sharp[side][which] = ok & held[which]
            passes.append(fp.subset(np.isin(fp.node, self.mesh.gvert[S.nodes[sharp[side]]])))
            ids.append(3 * self.mesh.gvert[S.nodes[sharp[side]]])
        for (side, S, T), (other, _, _) in zip(sides, sides[::-1]):
            facing = self._facing_features(pd, side, S, T, sharp[other], sharp[side], X, U)
            if facing is not None:
                extra.append(facing)
        ids = np.concatenate(ids) if ids else np.zeros(0, dtype=np.int64)
        return passes, np.concatenate(self.comm.allgather(ids)).astype(np.int64), extra

    def _facing_features(self, pd, side, S, T, T_sharp, S_sharp, X, U):
        """The nodal pass of S's nodes (not feature nodes themselves) whose closest point on T lies near a feature
        node of T (T_sharp, a mask over T's owned nodes; FACING_RIDGE), or None when T has none: a row beside
        their own. A flat surface's weighted rows let a knife's edge in as the edge's own let it through, and
        master_slave holds no master node: the plate's nodes between the edge's, or on a half model's plane under
        it, went 40 % of the stroke into the edge, the force 21-24 % low against nodal two_pass rows and a refined
        edge (hunt30_5). Collective."""
        mesh = self.mesh
        gids = np.concatenate(self.comm.allgather(mesh.gvert[T.nodes[T_sharp]]))
        if not len(gids):
            return None
        at = np.concatenate(self.comm.allgather((X + U)[T.nodes[T_sharp]]))
        reach = pd["radius"] + self.comm.allreduce(float(T.size[T_sharp].max(initial=0.0)), op=MPI.MAX)
        near = np.zeros(len(S.nodes), dtype=bool)
        points = candidate_pairs((X + U)[S.nodes], at, at, reach)[0]
        near[points] = True
        near &= ~S_sharp
        fp, _, _ = project_pass(mesh, S, T, X, U, pd["radius"], pd["memo"][f"facing_{side}"], near)
        # on the ridge's half of the face: its feature nodes' shape functions sum to at least FACING_RIDGE there
        keep = (fp.shape * np.isin(fp.target_nodes, gids)).sum(axis=1) >= FACING_RIDGE
        nodes = np.unique(fp.node[keep])
        return fp.subset(np.isin(fp.node, nodes))

    def settle(self, u):
        """Large sliding, after a converged solve at the current load factor: each large-sliding pair searched
        again, at the converged u or part-way to it (_relaxation), against the term it was solved with
        (_search). Returns (terms, settled): the
        current terms with those pairs' kept or new, and whether every one kept its term (then the answer's
        rows are its own configuration's and nothing changed); (None, True) without such pairs (collective)."""
        large = [(i, pd) for i, pd in enumerate(self.pairs) if pd["spec"].sliding == "large"]
        if not large:
            return None, True
        U = self.mesh.local_vectors(u)
        settled = True
        for i, pd in large:               # the pairs' terms lead self.current, in the pairs' order
            name = f"contact[{pd['index']}]"
            state = self.settling[name]
            w = self._relaxation(pd, state, U)
            at = U if w == 1.0 else state["at"] + w * (U - state["at"])
            self.current[i] = self._search(pd, at, u, self.t, self.current[i])
            state["at"] = at
            self.searches[name]["count"] += 1
            settled = settled and self.searches[name]["kept"]
        return list(self.current), settled

    def _relaxation(self, pd, state, U):
        """Aitken's relaxation of large sliding's searches (collective): the search after a solve takes place at
        at + w (U - at), `at` the configuration the rows solved with were searched at, U the answer, with
        w = -w_last r_last . (r - r_last) / |r - r_last|^2 from the residuals r = U - at on the pair's owned
        surface nodes, within [MIN_RELAXATION, MAX_RELAXATION] (the first search after the increment's start:
        w = 1). Plain searches settle slowly where the rows creep (by 0.1-0.35 a search on segment rows, 0.9
        with nodal rows fading past an edge)."""
        nodes = np.concatenate([pd["slave"].nodes, pd["master"].nodes])
        r = (U - state["at"])[nodes].ravel()
        w = 1.0
        if state["r"] is not None:
            dr = r - state["r"]
            num, den = self.comm.allreduce(np.array([state["r"] @ dr, dr @ dr]), op=MPI.SUM)
            if den > 0.0:
                w = float(np.clip(-state["w"] * num / den, MIN_RELAXATION, MAX_RELAXATION))
        state["r"], state["w"] = r, w
        return w

    def _to_row_owners(self, parts):
        """Row triplets (G_rows, G_cols, G_vals, g_rows, g_vals, W_rows, W_vals) moved to their rows' owners."""
        comm = self.comm
        starts = 3 * assembly.ownership_starts(comm, self.mesh.owned.sum())
        G_r, G_c, G_v, g_r, g_v, W_r, W_v = parts
        G = assembly.send_to_owners(comm, starts, np.asarray(G_r, np.int64), np.asarray(G_c, np.int64),
                                    np.asarray(G_v, float))
        g = assembly.send_to_owners(comm, starts, np.asarray(g_r, np.int64), np.asarray(g_v, float))
        W = assembly.send_to_owners(comm, starts, np.asarray(W_r, np.int64), np.asarray(W_v, float))
        return (*G, *g, *W)

    def _check_found(self, pd, sp, mp):
        """Surfaces declared in contact must meet within the search distance somewhere at the pair's first search
        (all ranks agree); a later search that finds nothing has surfaces that came apart (no rows).

        Returns the number of points projected (both passes, all ranks)."""
        found = self.comm.allreduce(len(sp.node) + (len(mp.node) if mp is not None else 0), op=MPI.SUM)
        if found:
            self.met.add(pd["index"])
        elif pd["index"] not in self.met:
            spec = pd["spec"]
            raise SceneError(f"contact[{pd['index']}]: no node of {spec.slave!r} or {spec.master!r} is within the "
                             f"search distance ({pd['radius']:.3g} m = search_distance x element size) of the "
                             f"other surface and turned towards it (outward normals within 70 degrees of facing "
                             f"each other){self._apart(pd)}; increase contact[{pd['index']}].search_distance or "
                             f"check the geometry and the surfaces' faces")
        return found

    def _apart(self, pd):
        """For _check_found's error: how far the slave surface's centre lies from the master's along the master's
        mean outward normal, saying when that is an overlap (the bodies pushed into each other beyond the reach
        read only "not within the search distance"; hunt33_3 F7). Collective."""
        def centre_and_normal(S):
            a = S.area[:, None]
            sums = self.comm.allreduce(np.concatenate([(a * self.mesh.coords[S.nodes]).sum(axis=0),
                                                       (a * S.normal).sum(axis=0), [S.area.sum()]]), op=MPI.SUM)
            return sums[:3] / max(sums[6], 1e-300), sums[3:6]
        slave, _ = centre_and_normal(pd["slave"])
        master, normal = centre_and_normal(pd["master"])
        size = np.linalg.norm(normal)
        if size < 0.5 * pd["master"].total_area:      # a curved or closed master has no direction to measure along
            return ""
        d = float((slave - master) @ normal / size)
        if d < -pd["radius"]:
            return (f"; the slave surface's centre lies {-d:.3g} m behind the master surface along its mean outward "
                    f"normal: the bodies overlap by more than the search distance")
        return f"; the slave surface's centre lies {d:.3g} m from the master surface along its mean outward normal"

    def add_forces(self, u, r):
        """r += sum of G^T m over all terms at u (for reactions)."""
        for term in self.current:
            term.evaluate(u)
            term.add_force(r)

    def report(self, u, U):
        """Point fields (traction, penetration, status on contact nodes) and per pair/die summaries."""
        mesh = self.mesh
        nvl = len(mesh.coords)
        # each body's largest displacement from its mean (its deformation, not its travel): the scale a penalty's
        # penetration is read against (slip_warnings). Its largest displacement hid a penalty 18 % soft under a
        # stack slid 0.3 m, and dies 45 % soft that carried a stack 0.5 m (hunt34_2)
        nb = len(self.scene.bodies)
        mine = mesh.owned & (mesh.vertex_body >= 0)
        body, owned = mesh.vertex_body[mine], U[mine]
        sums = np.stack([np.bincount(body, weights=owned[:, c], minlength=nb) for c in range(3)]
                        + [np.bincount(body, minlength=nb).astype(float)], axis=1)
        self.comm.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
        mean = sums[:, :3] / np.maximum(sums[:, 3:], 1.0)
        moved = np.array([float(np.linalg.norm(U[mesh.vertex_body == b] - mean[b], axis=1).max(initial=0.0))
                          for b in range(nb)])
        self.comm.Allreduce(MPI.IN_PLACE, moved, op=MPI.MAX)
        # a node on several pairs' or dies' surfaces: the tractions of one surface add up (a surface pressed by two
        # pairs), of different surfaces the largest stands; the largest penetration, the highest status
        tractions = {}
        penetration = np.full((nvl, 1), -np.inf)
        status = np.full((nvl, 1), -1.0)
        X = mesh.coords
        summaries = {}
        terms = {t.name: t for t in self.current}
        for pd in self.pairs:
            term = terms[f"contact[{pd['index']}]"]
            F = _term_force(term, u)
            entry = {"rows": self.comm.allreduce(len(term.rows), op=MPI.SUM),
                     "active_rows": self.comm.allreduce(int(term.active.sum()), op=MPI.SUM),
                     "eps_n": pd["eps_n"], "h_eff": pd["h_eff"], "integration": pd["spec"].integration,
                     "quadrature_points": term.points, "feature_rows": term.feature_rows,
                     "G_nonzeros": _nonzeros(term.G, self.comm),
                     "rows_searched_for": self.searches[term.name]["load_factor"],
                     "rows_kept": self.searches[term.name]["kept"], "searches": self.searches[term.name]["count"],
                     "gap_change": _finite_or_none(self.searches[term.name]["gap_change"])}
            mean_pen, pressed_unfaced, unfaced_force, step_slip, depth, fold = {}, 0, {}, 0.0, {}, {}
            for side, S, T in (("slave", pd["slave"], pd["master"]), ("master", pd["master"], pd["slave"])):
                _, ok, found = project_pass(mesh, S, T, X, U, pd["radius"], weighted=False)
                area, normal = self._pressed_areas(S, X, U, found, F[_owned_rows(mesh, S.nodes)])
                v = S.nodes[ok]
                h = -found["signed_gap"][ok]          # penetration in the current configuration
                p_own = np.einsum("pi,pi->p", F[_owned_rows(mesh, S.nodes)], normal) / area
                # a node presses with more than round-off: a point shared by faces it is as near to spreads the
                # round-off of its rows over their nodes (8e-17 Pa beside a symmetric punch, which made
                # pressed_unfaced_nodes depend on the number of ranks; hunt27_4)
                top = self.comm.allreduce(float(np.abs(p_own).max(initial=0.0)), op=MPI.MAX)
                presses = p_own > PRESSED_SHARE * top
                pressed = ok & presses
                entry[f"max_slip_{side}"] = self._max_slip(pd, side, S, T, pressed, found)
                step_slip = max(step_slip, self._max_slip(pd, side, S, T, pressed, found, since="report"))
                tractions.setdefault(S.name, np.zeros(nvl))[S.nodes] += p_own
                penetration[v, 0] = np.maximum(penetration[v, 0], h)
                # touching: penetrating, or carrying contact force (rows linearised at an increment's start can
                # hold a node that the increment's sliding has since lifted off the opposite facets)
                touching = (h >= -self.scene.solver.active_set_tolerance * pd["h_eff"]) | presses[ok]
                status[v, 0] = np.maximum(status[v, 0], touching.astype(float))
                # a node beyond the opposite surface's edge that its neighbours' rows still press carries force too
                unfaced = ~ok & presses
                status[S.nodes[unfaced], 0] = 1.0
                pressed_unfaced += self.comm.allreduce(int(unfaced.sum()), op=MPI.SUM)
                for with_force in (True, False):     # the deepest nodes with and without contact force
                    depth[side, with_force] = self.comm.allreduce(float(h[presses[ok] == with_force].max(initial=0.0)),
                                                                  op=MPI.MAX)
                # ... and of those with force, the deepest that sinks UNHELD_DEPTH times what its own pressure explains
                # (p / eps_n): its rows do not hold it (slip_warnings)
                unexplained = presses[ok] & (h > UNHELD_DEPTH * p_own[ok] / pd["eps_n"])
                depth[side, "unheld"] = self.comm.allreduce(float(h[unexplained].max(initial=0.0)), op=MPI.MAX)
                # the fold of the deepest node without force (the warning's advice): the largest of those as deep
                unforced = np.flatnonzero(~presses[ok] & (h >= depth[side, False]) & (h > 0))
                fold[side] = self.comm.allreduce(float(pd["folds"][side][ok][unforced].max(initial=0.0)), op=MPI.MAX)
                unfaced_force[side] = self.comm.allreduce(float((p_own * area)[unfaced].sum()), op=MPI.SUM)
                force = self.comm.allreduce(-F[_owned_rows(mesh, S.nodes)].sum(axis=0), op=MPI.SUM)
                entry[f"max_penetration_{side}"] = _finite_or_none(
                    self.comm.allreduce(float(h.max(initial=-np.inf)), op=MPI.MAX))     # None: no node faces T
                a = area[ok]
                held = presses[ok]           # the swap indicator's nodes: those that carry force, with their pressure
                mean_pen[side] = tuple(self.comm.allreduce(np.array([
                    (a * h).sum(), a.sum(), (a * h)[held].sum(), a[held].sum(), (a * p_own[ok])[held].sum()]),
                    op=MPI.SUM))
                entry[f"force_on_{side}"] = force.tolist()
                # the area that carries contact force: the pressed nodes' tributary areas. The closed rows' sum phi W
                # is that area only while every row holds: two_pass opens one side's rows where both cannot close
                # (a punch fully pressed over 0.16 m2 read 0.080, a patch under uneven pressure 0.834 of 1 m2)
                entry["contact_area" if side == "slave" else "contact_area_master"] = self.comm.allreduce(
                    float(area[presses].sum()), op=MPI.SUM)
                if side == "slave":
                    entry["total_normal_force"] = self.comm.allreduce(float((p_own * area).sum()), op=MPI.SUM)
            ms = mean_pen["slave"][0] / max(mean_pen["slave"][1], 1e-300)
            mm = mean_pen["master"][0] / max(mean_pen["master"][1], 1e-300)
            entry["mean_penetration_slave"], entry["mean_penetration_master"] = ms, mm
            # the pressed nodes' deepest penetration, and the slave's pressed nodes' mean penetration against
            # their mean pressure's p / eps_n (slip_warnings)
            pressed_area = max(mean_pen["slave"][3], 1e-300)
            if "far" not in pd:
                pd["far"] = self.comm.allreduce(float(np.abs(mesh.coords[np.concatenate([
                    pd["slave"].nodes, pd["master"].nodes])]).max(initial=0.0)), op=MPI.MAX)
            self.pressed_depth[pd["index"]] = (max(depth["slave", True], depth["master", True]),
                                               mean_pen["slave"][2] / pressed_area,
                                               mean_pen["slave"][4] / pressed_area / pd["eps_n"], pd["far"],
                                               max(moved[pd["slave"].body], moved[pd["master"].body]),
                                               max(depth["slave", "unheld"], depth["master", "unheld"]))
            entry["swap_indicator"] = _swap_indicator(mean_pen["slave"][2:], mean_pen["master"][2:], pd["eps_n"])
            entry["max_slip_step"] = step_slip
            entry["pressed_unfaced_nodes"] = pressed_unfaced
            bound = max(UNFORCED_WARNING * pd["h_eff"], UNFORCED_RATIO * max(depth["slave", True], depth["master", True]))
            for side in ("slave", "master"):
                entry[f"max_penetration_unforced_{side}"] = depth[side, False]
            self.unforced[pd["index"]] = {side: np.degrees(fold[side]) for side in ("slave", "master")
                                          if depth[side, False] > bound}
            # the share of the slave's normal force those nodes carry (on the side where it is larger)
            entry["pressed_unfaced_share"] = max(unfaced_force.values()) / max(entry["total_normal_force"], 1e-300)
            summaries[f"contact[{pd['index']}] {pd['spec'].slave} / {pd['spec'].master}"] = entry
        for dd in self.dies:
            term = terms[f"die[{dd['index']}]"]
            F = _term_force(term, u)
            force = self.comm.allreduce(-F[_owned_rows(mesh, dd["nodes"])].sum(axis=0), op=MPI.SUM)
            spec = dd["spec"]
            n = np.asarray(spec.normal)
            v = dd["nodes"]
            h = _die_depth(dd, X, U, self.t)
            penetration[v, 0] = np.maximum(penetration[v, 0], h)
            on = _on_die(dd, h, self.scene.solver.active_set_tolerance)
            status[v, 0] = np.maximum(status[v, 0], on)
            pressure = np.zeros(nvl)
            pressure[v] = (F[_owned_rows(mesh, v)] @ -n) / dd["area"]
            pressed = pressure[v] > 0
            if "far" not in dd:
                dd["far"] = self.comm.allreduce(float(np.abs(mesh.coords[v]).max(initial=0.0)), op=MPI.MAX)
            self.die_depth[dd["index"]] = (self.comm.allreduce(float(h[pressed].max(initial=0.0)), op=MPI.MAX),
                                           float(moved[dd["bodies"]].max()), dd["far"])
            for name, nodes in dd["surfaces"]:       # a die adds to the pressure of the surfaces it presses
                tractions.setdefault(name, np.zeros(nvl))[nodes] += pressure[nodes]
            # a node's area once: a sticking die's tangential rows (gated by its normal row) carry it too; the area
            # that carries contact force, as a pair's: a closed row at zero force (a die just touching) read 1 m2
            # at 0 N (hunt31_2)
            normal = (term.active & (term.gate_of < 0 if term.gate_of is not None else True)
                      & (term.m.getArray(readonly=True)[term.rows] > 0))
            if dd["index"] not in self.through_die:
                presses = self.comm.allreduce(bool(normal.any()), op=MPI.LOR)
                through = self._through_die(dd, X, U, self.die_depth[dd["index"]][0] if presses else None)
                if through:
                    self.through_die[dd["index"]] = (*through, presses)
            summaries[f"die[{dd['index']}] {spec.name}"] = {
                "rows": self.comm.allreduce(len(term.rows), op=MPI.SUM),
                "active_rows": self.comm.allreduce(int(term.active.sum()), op=MPI.SUM),
                "eps_n": dd["eps_n"], "force_on_bodies": force.tolist(),
                "max_penetration": _finite_or_none(self.comm.allreduce(float(h.max(initial=-np.inf)), op=MPI.MAX)),
                "contact_area": self.comm.allreduce(float(term.W.getArray()[term.rows][normal].sum()),
                                                    op=MPI.SUM)}
        traction = np.zeros((nvl, 1))
        if tractions:
            stack = np.stack(list(tractions.values()))
            traction[:, 0] = stack[np.argmax(np.abs(stack), axis=0), np.arange(nvl)]
        penetration[np.isinf(penetration)] = 0.0            # a node that faces nothing
        fields = {"contact_traction": traction, "contact_penetration": penetration, "contact_status": status}
        return fields, summaries

    def _through_die(self, dd, X, U, pressed=None):
        """How far nodes of a die's bodies that were not past its plane at the start lie past it at the load factor
        of the report, with the deepest node's place and surfaces, if more than UNFORCED_WARNING x its element
        size; else None (collective). A die that presses none of its surfaces counts every other node of its
        bodies (a sphere's floor given the sphere's top instead of its contact cap let the pole 9.5 mm through, the
        die's force 0, no word; hunt33_6); one whose deepest pressed node sinks `pressed` counts the nodes off its
        surfaces, within their footprint on its plane (_footprint), deeper than UNFORCED_RATIO x that (the floor
        given the sphere's outer skin pressed the ring where it meets the cap, the pole 13 mm through, the force
        59 % low, no word; hunt34_2). Nodes outside the footprint are left: a die on a patch of a face is a punch
        of that patch's shape."""
        mesh = self.mesh
        if "before" not in dd:
            nodes = np.flatnonzero(np.isin(mesh.vertex_body, dd["bodies"]) & mesh.owned)
            # ... of the nodes not past it at the start: a punch that approaches a stepped body's shoulder has the
            # body's tall part past its plane by design (hunt34_2)
            dd["before"] = nodes[_die_depth(dict(dd, nodes=nodes), X, 0.0 * X, 0.0) <= UNFORCED_WARNING * dd["h"]]
        nodes = dd["before"]
        depth = _die_depth(dict(dd, nodes=nodes), X, U, self.t)
        floor = UNFORCED_WARNING * dd["h"]
        if pressed is not None:
            floor = max(floor, UNFORCED_RATIO * pressed)
            deep = np.flatnonzero((depth > floor) & ~np.isin(nodes, dd["nodes"]))
            if not self.comm.allreduce(len(deep) > 0, op=MPI.LOR):
                return None           # the footprint (a hull) only when some node off the surfaces sank that deep
            frame, hull = self._footprint(dd)
            deep = deep[_inside(hull, X[nodes[deep]] @ frame.T, 1e-6 * dd["h"])]
            nodes, depth = nodes[deep], depth[deep]
        bodies = {self.scene.bodies[b].name for b in dd["bodies"]}

        def surfaces(k):
            named = [name for name in mesh.surface_names if name.split(".", 1)[0] in bodies
                     and np.isin(nodes[k], mesh.surface_vertices(name))]
            # a mesh file's "boundary" (every boundary face) beside the groups that name the place says nothing
            return [name for name in named if not name.endswith(".boundary")] or named
        # of nodes as deep, the first by x, y, z: the same on any number of ranks
        deepest, where, named = first_largest(self.comm, depth, X[nodes], tie=1e-9 * dd["h"], detail=surfaces)
        return (deepest, where, named) if deepest > floor else None

    def _footprint(self, dd):
        """A frame (2, 3) of the die's plane and the convex hull (k, 2), counter-clockwise, of its surfaces' nodes
        projected on it in that frame (none: fewer than 3 corners), made once (collective)."""
        if "hull" not in dd:
            n = np.asarray(dd["spec"].normal, dtype=float)
            t1 = np.cross(n, np.eye(3)[int(np.argmin(np.abs(n)))])
            t1 /= np.linalg.norm(t1)
            frame = np.array([t1, np.cross(n, t1)])
            x = self.mesh.coords[dd["nodes"][self.mesh.owned[dd["nodes"]]]]
            # with the surfaces' mirror images in the symmetry planes: a quarter sphere's outer skin, a quarter ring
            # whose hull left its pole out
            for axis, plane in symmetry_planes(self.mesh, self.scene):
                image = x.copy()
                image[:, axis] = 2.0 * plane - image[:, axis]
                x = np.vstack([x, image])
            # each rank's hull, then the hull of their corners
            corners = self.comm.allgather(_convex_hull(x @ frame.T))
            dd["frame"], dd["hull"] = frame, _convex_hull(np.vstack(corners))
        return dd["frame"], dd["hull"]

    def _pressed_areas(self, S, X, U, found, F):
        """The areas and normals of S's owned nodes on the faces turned towards the other surface (facing_areas):
        towards the face a node found, or, for one that found none, against the contact force F on it (its rows
        hold it from the other surface's side: a node past the other's edge that its neighbours' rows press). Such a
        node kept its whole skin's area and normal: a tall punch's edge nodes past the block's edge made the
        reported normal force 26 % low and the contact area 3x (hunt28_4). Collective."""
        size = np.linalg.norm(F, axis=1)
        pushed = (found["face"] < 0) & (size > 0)
        toward = {"face": np.where(pushed, 0, found["face"]), "normal": found["normal"].copy()}
        toward["normal"][pushed] = -F[pushed] / size[pushed, None]
        area, normal = facing_areas(self.mesh, S, X, U, slice(None), toward)
        # on a symmetry plane the faces' mirror images count: the normal loses its component across the plane (a
        # half knife's total normal force read 0.149 against its force 0.210 N; hunt30_5 D)
        mirrored = self.mirrored[S.nodes]
        if mirrored.any():
            flat = np.where(mirrored, 0.0, normal)
            length = np.linalg.norm(flat, axis=1)
            normal = np.where(length[:, None] > 0, flat / np.where(length > 0, length, 1.0)[:, None], normal)
        return area, normal

    def _unheld(self, pd, deepest):
        """The warning line for a pair whose deepest pressed nodes sink UNHELD_DEPTH times deeper than their own
        pressure's p / eps_n: no penalty explains that, so its rows do not hold them (quasi_symmetric's nodal rows
        with the coarse surface as the slave at a 10x mesh ratio: the fine master's nodes sank 1e5 p / eps_n, the
        stresses 3-4x off, and the soft-penalty warning sent the user to raise the penalty; hunt32_2). Read against
        the pair's mean pressure it fired on a soft penalty under a concentrated load (hunt35_3)."""
        spec = pd["spec"]
        name = f"contact[{pd['index']}]"
        if spec.integration == "nodal" and spec.formulation != "two_pass":
            qs = spec.formulation == "quasi_symmetric"
            cure = ("quasi_symmetric's nodal rows hold the master's nodes through the slave's multipliers" if qs else
                    "master_slave's nodal rows hold the master's nodes only where slave nodes press them")
            if pd["sizes"][0] > COARSER * pd["sizes"][1]:        # the slave's faces are the larger
                cure += (", which a coarser slave spreads over many of them" if qs else ", and a coarser slave has few")
                cure += ": make the finer surface the slave" + (", or set weight = \"finer\"" if qs else "") + ", or"
            else:
                cure += ":"
            cure += " use two_pass or integration = \"segment\""
        else:
            # not the run's own settings: a faceted ring's two_pass segment run was told to use two_pass with segment
            # rows, while feature_angle, which held it, went unnamed (hunt35_4)
            cures = ["refine the coarser surface (a curved one's facets)"]
            if spec.feature_angle is None:
                cures.append("give the pair a feature_angle below the fold between its facets (their edges' and "
                             "corners' own nodal rows)")
            if spec.formulation != "two_pass" or spec.integration != "segment":
                cures.append("use two_pass with integration = \"segment\"")
            cure = ", or ".join(cures)
        return (f"{name}: pressed nodes penetrate the other surface by up to {deepest:.3g} m = "
                f"{deepest / pd['h_eff']:.2g} h_eff, more than {UNHELD_DEPTH:g} times the penetration of their own "
                f"contact pressure (p / eps_n): no penalty explains that, so the rows do not hold those nodes, and "
                f"the stresses and displacements near them are off by about as much; a larger penalty does not "
                f"help: {cure}")

    def _feature_advice(self, pd, fold, sides):
        """What feature_angle can do for the sunk nodes of `sides` whose surface folds `fold` degrees there
        (ridge_tilts)."""
        angle, key = pd["spec"].feature_angle, f"contact[{pd['index']}].feature_angle"
        if fold < FLAT_FOLD:
            # a knife's edge pressing into a plate: the plate's nodes (hunt30_5 A), held by feature_angle below the
            # knife's fold (hunt30_7 F2: with the angle above it the advice said nothing could)
            other = [self.comm.allreduce(float(pd["folds"][s].max(initial=0.0)), op=MPI.MAX)
                     for s in ("slave", "master") if s not in sides] or [0.0]
            sharpest = np.degrees(max(other))
            what = "; they lie where their surface is flat: a sharp edge or corner of the other surface presses into them"
            if sharpest < FLAT_FOLD:
                return what
            if angle is None or angle >= sharpest:
                return (what + f", whose sharpest fold is {sharpest:.0f} degrees: {key} below that gives its nodes, "
                        f"and the nodes they press, nodal rows of their own")
            return what
        if angle is None:
            return (f"; or set {key} below {fold:.0f} degrees (their fold), which gives such nodes nodal rows of their "
                    f"own with any formulation and rule")
        if angle >= fold:
            return f"; feature_angle = {angle:g} is above their fold ({fold:.0f} degrees): lower it below that"
        return (f"; feature_angle = {angle:g} took in their fold ({fold:.0f} degrees), but their faces lean from the "
                f"other surface by less than that where they meet it")

    def pathless_met(self, u):
        """After a converged try: how many nodes met a sticking die in it (apart at its start, on the die at u)
        when no earlier state gave their path (_stick_anchors: the run's first increment), over all dies
        (collective)."""
        if not any(dd.get("stick", {}).get("pathless") is not None for dd in self.dies):
            return 0
        U, X = self.mesh.local_vectors(u), self.mesh.coords
        count = 0
        for dd in self.dies:
            pathless = dd.get("stick", {}).get("pathless")
            if pathless is not None:
                on = _on_die(dd, _die_depth(dd, X, U, self.t), self.scene.solver.active_set_tolerance)
                count += int((pathless & on & self.mesh.owned[dd["nodes"]]).sum())
        return self.comm.allreduce(count, op=MPI.SUM)

    def slip_warnings(self, summaries):
        """Lines on the pairs' state after a step (report's summaries): a small-sliding pair whose contact slid
        farther than SLIP_WARNING x h_eff (max_slip_*), a pair whose pressed nodes face nothing of the other
        surface (the rows of an earlier configuration hold them: small or finite sliding), each the first time;
        a pair whose search found the surfaces out of reach (no rows), when it starts to."""
        lines = []
        for pd, entry in zip(self.pairs, summaries.values()):
            spec, name = pd["spec"], f"contact[{pd['index']}]"
            if entry["rows"] == 0 and name not in self.apart:
                lines.append(f"{name}: no point of either surface is within the search distance "
                             f"({pd['radius']:.3g} m) of the other: the surfaces have come apart (no rows, no force)")
            (self.apart.add if entry["rows"] == 0 else self.apart.discard)(name)
            share, slid = entry["pressed_unfaced_share"], entry["max_slip_step"]
            slips = self.step_slips.setdefault(name, [])
            slips.append(slid)
            if spec.sliding == "finite" and (name, "growth") not in self.slip_warned and _overshooting(
                    slips, pd["h_eff"]):
                self.slip_warned.add((name, "growth"))
                lines.append(f"{name}: its slip per step grew from {slips[-1 - SLIP_GROWTH_STEPS]:.3g} to "
                             f"{slid:.3g} m over the last {SLIP_GROWTH_STEPS} steps: finite "
                             f"sliding's rows, searched at each step's start, overshoot here, and its answer may drift "
                             f"from step to step (more load steps make that worse): use sliding = \"large\", whose "
                             f"searches settle the rows at each step's answer")
            # nodes past the other surface's edge that its rows press through their shape functions (a punch
            # narrower than two elements of the other surface: 70 % of the force at step 1 of 1 or 8, large
            # sliding alike) are no fault of the rows' age: only a step that slid can leave its rows behind
            unfaced = share > UNFACED_WARNING and slid > UNFACED_SLIP * pd["h_eff"]
            if spec.sliding == "finite" and (name, "step") not in self.slip_warned and (
                    slid > SLIP_WARNING * pd["h_eff"] or unfaced):
                self.slip_warned.add((name, "step"))
                what = (f"slid {slid:.3g} m = {slid / pd['h_eff']:.2g} h_eff in this step" if not unfaced
                        else f"left nodes that carry {share:.0%} of its normal force facing no part of the other "
                             f"surface")
                # a knife's edge whose faces turn more than 70 degrees from the other surface faces none of it
                # (search.FACING) however it slides (hunt28_5)
                shape = ("" if not unfaced else
                         " (or the surfaces meet at an edge whose faces turn more than 70 degrees from the other "
                         "surface, which no search pairs: then the rows of the edge's own nodes hold it)")
                lines.append(f"{name}: the contact {what}; finite sliding keeps the rows searched at the step's "
                             f"start, whose error grows with that: use more load steps or sliding = \"large\""
                             f"{shape}")
            sunk = self.unforced.get(pd["index"])
            if sunk and (name, "unforced") not in self.slip_warned:
                self.slip_warned.add((name, "unforced"))
                depth = max(entry[f"max_penetration_unforced_{side}"] for side in sunk)
                cure = ("nodal rows of master_slave or two_pass hold it" if list(sunk) == ["slave"] else
                        "master_slave never holds the master's nodes: make the sharp (or finer) surface the slave with "
                        "nodal rows of master_slave, or use two_pass with nodal rows")
                cure += self._feature_advice(pd, max(sunk.values()), list(sunk))
                lines.append(
                    f"{name}: {' and '.join(sunk)} nodes with no contact force penetrate the other surface by up to "
                    f"{depth:.3g} m = {depth / pd['h_eff']:.2g} h_eff: no row holds them. A sharp edge or corner (or a "
                    f"coarse curved tip) passes through segment and Gauss rows, whose weighted gaps spread its "
                    f"penetration over the faces beside it, open there, and through quasi_symmetric's nodal rows: "
                    f"{cure}. Or their rows were searched before they slid there: use more load steps or sliding = "
                    f"\"large\"")
            deepest, mean, expected, far, scale, unheld = self.pressed_depth.get(pd["index"], (0.0,) * 6)
            precision = ROUND_OFF_PENETRATION * np.finfo(float).eps * far
            # a pair that carries no load to speak of has no penalty soft for it: a stack's pairs at 1e-11 N (a strain
            # of 1e-14), their depths the solve's round-off (1e-15 to 8e-14 m), were said soft, other pairs on
            # other numbers of ranks (hunt35_2)
            strain = expected * spec.penalty / pd["h_eff"]
            if spec.enforcement == "penalty" and strain > LOADED_STRAIN and (name, "deep") not in self.slip_warned:
                line = _soft_penalty(name, deepest, pd["h_eff"], scale, spec.penalty, pd["eps_n"], "the other surface",
                                     precision)
                if line and unheld >= 0.5 * deepest:
                    line = self._unheld(pd, unheld)
                if line:
                    self.slip_warned.add((name, "deep"))
                    lines.append(line)
            # a pressure of a strain below 1e-10 (p / E = alpha p / (eps_n h_eff)) is itself round-off: rows that hold
            # a loose stack with no load carry 1e-11 Pa
            if spec.enforcement == "penalty" and 0 < expected < precision and strain > 1e-10 and \
                    (name, "round-off") not in self.slip_warned:
                self.slip_warned.add((name, "round-off"))
                lines.append(f"{name}: its pressure's penetration p / eps_n = {expected:.3g} m lies within "
                             f"{ROUND_OFF_PENETRATION:g} x the coordinates' precision (eps |x| = "
                             f"{precision / ROUND_OFF_PENETRATION:.3g} m; eps_n {pd['eps_n']:.3g} Pa/m): the reported "
                             f"penetrations (contact_penetration, max/mean_penetration_*; the pressed slave nodes' mean "
                             f"{mean:.3g} m) are round-off; a lower penalty reads them")
            slip = max(entry["max_slip_slave"], entry["max_slip_master"])
            if spec.sliding == "small" and slip > SLIP_WARNING * pd["h_eff"] and name not in self.slip_warned:
                self.slip_warned.add(name)
                lines.append(f"{name}: the contact slid {slip:.3g} m = {slip / pd['h_eff']:.2g} h_eff, more than "
                             f"{SLIP_WARNING} h_eff; sliding = \"small\" keeps the rows of the undeformed "
                             f"configuration: use sliding = \"finite\" for this scene")
        for dd in self.dies:
            name, spec = f"die[{dd['index']}]", dd["spec"]
            through = self.through_die.get(dd["index"])
            if through and (name, "through") not in self.slip_warned:
                self.slip_warned.add((name, "through"))
                deepest, where, named, presses = through
                listed = ", ".join(s for s, _ in dd["surfaces"])
                what = f"it presses its surfaces ({listed})" if presses else f"it presses none of its surfaces ({listed})"
                lines.append(f"{name} {spec.name}: {what} while other nodes of its bodies"
                             + (" within their footprint" if presses else "") + f" lie up to {deepest:.3g} m = "
                             f"{deepest / dd['h']:.2g} of its surfaces' element size past its plane (the deepest at "
                             f"x, y, z = {', '.join(f'{v:.4g}' for v in where)} before the load"
                             + (f", on {', '.join(named)}" if named else "") + "): a die acts on the surfaces it lists "
                             "only, and the others go through it; list the surface that faces it")
            deepest, scale, far = self.die_depth.get(dd["index"], (0.0,) * 3)
            line = _soft_penalty(name, deepest, dd["h"], scale, spec.penalty, dd["eps_n"], "the die",
                                 ROUND_OFF_PENETRATION * np.finfo(float).eps * far)
            if line and (name, "deep") not in self.slip_warned:
                self.slip_warned.add((name, "deep"))
                lines.append(line)
        return lines

    def _max_slip(self, pd, side, S, T, pressed, found, since="start"):
        """The largest distance, over S's pressed nodes (found on T now, with a positive contact traction), between
        the T material point a node faces now and the one it faced at u = 0 (since="start"), or at the last
        report (since="report": the last step's end, where finite sliding searched the rows of this one; u = 0
        at the first), both in T's reference configuration: how far the contact slid [m]; all ranks."""
        key = (pd["index"], side)
        if key not in self.faced_at_start:
            _, ok0, found0 = project_pass(self.mesh, S, T, self.mesh.coords, np.zeros_like(self.mesh.coords),
                                          pd["radius"], weighted=False)
            self.faced_at_start[key] = (ok0, found0["target_ref"])
        if since == "report":
            ok0, start = self.faced_last.get(key, self.faced_at_start[key])
            self.faced_last[key] = (found["face"] >= 0, found["target_ref"])
        else:
            ok0, start = self.faced_at_start[key]
        both = pressed & ok0
        slip = np.linalg.norm(found["target_ref"][both] - start[both], axis=1)
        return self.comm.allreduce(float(slip.max(initial=0.0)), op=MPI.MAX)

    def destroy(self):
        self._take_prepared(None, None)
        for term in self.current:
            term.destroy()
        self.current = []


def _turned_to_die(mesh, dd, x):
    """Which of a die's nodes (dd["nodes"]) have a surface turned towards the die at positions x (search.FACING, the
    die's normal as the other surface's): the nodes a die's rows may hold."""
    return facing_pairs(nodal_normals(mesh, dd["surface"], x, by="angle"), np.asarray(dd["spec"].normal, dtype=float))


def _convex_hull(points):
    """The convex hull of 2-D points (n, 2), counter-clockwise from the lowest-leftmost (Andrew's monotone chain),
    none (0, 2) for fewer than 3 corners."""
    p = np.unique(np.asarray(points, dtype=float).reshape(-1, 2), axis=0)

    def chain(seq):
        out = []
        for q in seq:
            while len(out) >= 2 and ((out[-1][0] - out[-2][0]) * (q[1] - out[-2][1])
                                     - (out[-1][1] - out[-2][1]) * (q[0] - out[-2][0])) <= 0:
                out.pop()
            out.append(q)
        return out
    if len(p) < 3:
        return np.zeros((0, 2))
    hull = chain(p)[:-1] + chain(p[::-1])[:-1]
    return np.array(hull) if len(hull) >= 3 else np.zeros((0, 2))


def _inside(hull, points, tol):
    """Which 2-D points (m, 2) lie inside a counter-clockwise convex hull (k, 2), or within tol of it."""
    if len(hull) < 3 or not len(points):
        return np.zeros(len(points), dtype=bool)
    edges = np.roll(hull, -1, axis=0) - hull
    rel = points[:, None, :] - hull[None, :, :]
    cross = (edges[None, :, 0] * rel[:, :, 1] - edges[None, :, 1] * rel[:, :, 0]) / np.linalg.norm(edges, axis=1)
    return (cross >= -tol).all(axis=1)


def _soft_penalty(name, deepest, h, scale, alpha, eps_n, other, precision):
    """The warning line for a pair's or die's penalty rows whose pressed nodes sink deeper than DEEP_PENETRATION x
    their element size or SOFT_PENALTY x their bodies' deformation (scale: the largest displacement from their
    mean), else None; none within `precision` (m: ROUND_OFF_PENETRATION x eps |x|), where the depths are round-off
    (a load straining the patch pair 1e-15 read 0.099 of its displacement as a soft penalty)."""
    if deepest <= precision or not (deepest > DEEP_PENETRATION * h or deepest > SOFT_PENALTY * scale > 0):
        return None
    return (f"{name}: pressed nodes penetrate {other} by up to {deepest:.3g} m = {deepest / h:.2g} element sizes and "
            f"{deepest / max(scale, 1e-300):.2g} of the bodies' deformation (their largest displacement from their "
            f"mean): its penalty (alpha {alpha:g}, eps_n {eps_n:.3g} Pa/m) is soft for this load, and the answer is off "
            f"by about as much (the force under a prescribed motion, the displacements under a prescribed load): raise "
            f"{name}.penalty" + (", or use enforcement = \"augmented_lagrangian\"" if name.startswith("contact") else ""))


def _overshooting(slips, h_eff):
    """Whether a finite-sliding pair's slip per step (slips, step by step) grew at every other step over the last
    SLIP_GROWTH_STEPS, SLIP_GROWTH times in all, to more than SLIP_GROWTH_FLOOR x h_eff (the overshoot may
    alternate from step to step), every one of them sliding."""
    window = slips[-1 - SLIP_GROWTH_STEPS:]
    if len(window) <= SLIP_GROWTH_STEPS or min(window) <= 0.0:
        return False          # steps before the contact slid at all are no growth (a 30-degree tilt; hunt31_4)
    every_other = window[::2]
    return (slips[-1] > SLIP_GROWTH_FLOOR * h_eff and slips[-1] > SLIP_GROWTH * window[0]
            and all(b > a for a, b in itertools.pairwise(every_other)))


def _gap_change(last, new, u, floor=0.0):
    """How far the rows of a pair's last term are from a new search's at u (collective): the largest difference
    of their gaps c / w over the rows, relative to the largest penetration of the new rows, a / eps_n with the
    row pressure a = lmbda + eps_n c / w of penalty.row_response (the augmented Lagrangian's multipliers
    lmbda, the last term's, count: its pressure is carried at a near-zero gap); inf when the two searches made
    different rows, or nothing presses on the new rows but something did on the last; 0 when nothing presses on
    either. The penetration it is measured against is at least `floor` (m: the coordinates' round-off over the
    pair's reuse_tolerance: a press so light that the penetrations are 4e-15 m stands within 1 % of the gaps'
    round-off, by which large sliding at alpha 1e8 moved them at every search, and never settled; hunt30_7).
    eps_n x this is the pressure error that keeping the last rows makes at u, relative to the largest contact
    pressure."""
    comm = new.G.getComm().tompi4py()
    if not comm.allreduce(np.array_equal(last.rows, new.rows), op=MPI.LAND):
        return np.inf
    gaps = [term.row_values(u) / term.W.getArray()[term.rows] for term in (last, new)]
    change = comm.allreduce(float(np.abs(gaps[0] - gaps[1]).max(initial=0.0)), op=MPI.MAX)
    carried = last.lmbda / new.eps_n if last.lmbda is not None else 0.0
    held = gaps[1] + carried
    depth = comm.allreduce(float(held.max(initial=0.0)), op=MPI.MAX)
    if change == 0.0:
        return 0.0
    if depth > 0:
        return change / max(depth, floor)
    # nothing presses on the new rows: keeping the last ones makes no pressure error if nothing presses on them
    # either (an open gap's rows changed by round-off, or the surfaces lifted off)
    pressed_last = comm.allreduce(float((gaps[0] + carried).max(initial=0.0)), op=MPI.MAX)
    return 0.0 if pressed_last <= 0 else np.inf


def _searched(spec):
    """How a pair is searched, for `qsc check`."""
    if spec.sliding == "small":
        return "searched once"
    if spec.sliding == "large":
        return (f"searched at every load step and again after every converged solve until a search finds the "
                f"rows within {spec.reuse_tolerance:g} of the largest penetration, at most {spec.max_searches} "
                f"searches an increment")
    if spec.reuse_tolerance > 0:
        return (f"searched at every load step; rows kept while a search finds them within {spec.reuse_tolerance:g} "
                f"of the largest penetration")
    return "searched at every load step"


def _swap_indicator(slave, master, eps_n):
    """|ms - mm| / max(|ms|, |mm|, p / eps_n): ms, mm the mean penetrations of each side's nodes that carry
    force, p their mean pressure (slave, master: (sum of area x penetration, area, area x pressure) over them).
    Over every node that faced the other surface, open ones counted, it read the footprints' difference (0.065
    on Hertz for every formulation), and with no floor two round-off means of an augmented Lagrangian's exact
    answer read 1.2-2.0 (hunt32_2)."""
    means = [pen / area if area > 0 else 0.0 for pen, area, _ in (slave, master)]
    area = slave[1] + master[1]
    floor = (slave[2] + master[2]) / area / eps_n if area > 0 and eps_n > 0 else 0.0
    scale = max(abs(means[0]), abs(means[1]), floor)
    return abs(means[0] - means[1]) / scale if scale > 0 else 0.0


def _finite_or_none(x):
    return None if x is None or not np.isfinite(x) else float(x)


def _no_own_weight(spec):
    """Whether a pair's slave nodes hold no row of their own: quasi_symmetric at weight 0, where a slave node has a
    row only under the master's points and may pass into the master elsewhere, as master_slave's master may
    into the slave (missed() read those nodes as out of reach: exit 3 after every cutback; hunt28_2)."""
    w = spec.weight
    return spec.formulation == "quasi_symmetric" and isinstance(w, (int, float)) and w == 0


def _nonzeros(G, comm):
    """G's entries above 1e-14 of its largest (collective): the count of stored entries (MatGetInfo) held explicit
    zeros and round-off that cancelled to zero on some partitions only (Hertz, master_nodes: 3849-3861 on 1-4 ranks)."""
    values = np.abs(G.getValuesCSR()[2])
    top = comm.allreduce(float(values.max(initial=0.0)), op=MPI.MAX)
    return comm.allreduce(int(np.count_nonzero(values > 1e-14 * top)), op=MPI.SUM)


def _die_depth(dd, X, U, t):
    """How far each of a die's nodes (dd["nodes"]) lies past its plane at load factor t (positive: penetrating),
    X and U the local coordinates and displacements."""
    spec, v = dd["spec"], dd["nodes"]
    u_die = t * np.asarray(spec.motion, dtype=float)
    return -((X[v] + U[v] - np.asarray(spec.point)) - u_die) @ np.asarray(spec.normal, dtype=float)


def _on_die(dd, depth, tolerance):
    """Which of a die's nodes touch it: their depth past its plane (_die_depth) at least -tolerance x the die's h
    (solver.active_set_tolerance, as its rows close)."""
    return depth >= -tolerance * dd["h"]


def _term_force(term, u):
    """This term's contact force G^T m at u, as owned (n, 3) rows."""
    term.evaluate(u)
    fc = u.duplicate()
    fc.set(0.0)
    term.add_force(fc)
    F = fc.getArray().reshape(-1, 3).copy()
    fc.destroy()
    return F


def contact_plan(mesh, scene, held=None, fixed=None):
    """Lines for `qsc check`: what each contact pair and die will model (the rows of the first increment's search,
    at u = 0, as a run makes them); held(terms), if given, is called with those terms (the free-motion check);
    fixed: assembly.dirichlet_dofs' answer, for the sticking dies' hold warnings."""
    if not (scene.contact or scene.die):
        if held is not None:
            held([])
        return ["contact: none (no contact search)"]
    template = mesh.dof_vector()
    model = ContactModel(mesh, scene, template)
    terms = model.terms(template, 1.0 / scene.load.steps)
    away = model.die_away_warnings()
    if held is not None:
        try:
            held(terms)
        except SceneError as exc:
            # a body a die was to hold, free because the die's normal is the wrong way round: the message sent the
            # user to the boundaries (hunt33_5)
            if not away:
                raise
            raise SceneError(f"{exc}; and {'; '.join(away)}") from None
    lines = []
    for pd, term in zip(model.pairs, terms):
        spec = pd["spec"]
        rows = mesh.comm.allreduce(len(term.rows), op=MPI.SUM)
        features = ""
        if pd["features"] is not None:
            ridges = [mesh.comm.allreduce(int(pd["features"][side].sum()), op=MPI.SUM) for side in ("slave", "master")]
            features = (f", {term.feature_rows} of them feature rows (feature_angle {spec.feature_angle:g}: "
                        f"{ridges[0]} slave and {ridges[1]} master nodes on ridges that sharp)")
        lines.append(f"contact[{pd['index']}]: {spec.slave} (slave) / {spec.master} (master), {spec.formulation}, "
                     f"{spec.enforcement}; h_eff {pd['h_eff']:.4g} m, eps_n {pd['eps_n']:.4g} Pa/m, "
                     f"search radius {pd['radius']:.4g} m, {spec.sliding} sliding ({_searched(spec)}); {rows} "
                     f"candidate rows at the first search{features}")
    for dd, term in zip(model.dies, terms[len(model.pairs):]):
        spec = dd["spec"]
        rows = mesh.comm.allreduce(len(term.rows), op=MPI.SUM)
        lines.append(f"die[{dd['index']}] {spec.name}: rigid plane, {spec.condition}, on {', '.join(spec.surfaces)}; "
                     f"eps_n {dd['eps_n']:.4g} Pa/m; {rows} candidate rows at the first search")
    lines += [f"warning: {line}" for line in away + model.precision_warnings()]
    if fixed is not None:
        lines += [f"warning: {line}" for line in model.hold_warnings(*fixed)]
    model.destroy()
    template.destroy()
    return lines
