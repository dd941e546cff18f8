"""Quadratures of a contact pass "integrate S against T": nodal, Gauss points or segments, turned into rows.Pass.

Pure NumPy (formulation.md section 8). Every rule yields points x_q of S faces
with area weights w_q on the reference S surface, S's shape values there, and
the T face each point meets, its natural coordinates, normal and initial gap.
The search runs on the current configuration; the rows are linear in the total
displacement, so the initial gap is measured between the reference positions
of the same material points.
"""

import numpy as np

from .. import fem
from . import geometry
from .rows import Pass
from .search import FACING, found_entries


def gauss_points(face_type, xs_ref, xs_cur, s_gids, n):
    """Gauss points of S faces (reference xs_ref and current xs_cur (m, nv, 3), global ids s_gids (m, nv)): n x n
    on quads, fem.contact_face_rule's symmetric rule on triangles.

    Returns a dict over the points: x_ref, x_cur (q, 3), weight (q,) [m^2 on the
    reference S], normal (q, 3) (S's outward normal at the point, current configuration), source_nodes (q, nv), source_shape (q, nv), node (q,) (the face node
    nearest the point), size (q,) (the S face's size) [m].
    """
    xi, w = fem.contact_face_rule(face_type, n)
    N, _ = fem.SHAPE[face_type](xi)                                   # (nq, nv)
    m, nq, nv = len(xs_ref), len(w), N.shape[1]
    if m == 0:
        z = np.zeros(0)
        return {"x_ref": np.zeros((0, 3)), "x_cur": np.zeros((0, 3)), "normal": np.zeros((0, 3)), "weight": z,
                "size": z, "source_nodes": np.zeros((0, nv), dtype=np.int64), "source_shape": np.zeros((0, nv)),
                "node": np.zeros(0, dtype=np.int64)}
    _, jac = fem.face_normals(face_type, xs_ref, xi)
    src = np.repeat(np.asarray(s_gids, dtype=np.int64), nq, axis=0)
    shp = np.tile(N, (m, 1))
    return {"x_ref": np.einsum("qv,mvi->mqi", N, xs_ref).reshape(-1, 3),
            "x_cur": np.einsum("qv,mvi->mqi", N, xs_cur).reshape(-1, 3),
            "normal": fem.face_normals(face_type, xs_cur, xi)[0].reshape(-1, 3),
            "weight": (jac * w).reshape(-1), "size": np.repeat(fem.face_size(xs_ref), nq),
            "source_nodes": src, "source_shape": shp, "node": src[np.arange(len(src)), np.argmax(shp, axis=1)]}


def faced_points(found, t_xref):
    """(p, 3): the reference position of the T point each point faces (zeros where it found no face); found is
    search.closest_faces' dict, t_xref (k, nv, 3) the reference coordinates of the T faces given to it."""
    ok = found["face"] >= 0
    out = np.zeros((len(ok), 3))
    out[ok] = np.einsum("pv,pvi->pi", found["shape"][ok], t_xref[found["face"][ok]])
    return out


def found_pass(points, found, t_gids, t_xref, t_size):
    """The Pass of the points that found a T face; found is search.closest_faces' dict for points["x_cur"].

    points: dict with x_ref, weight, size, node and optionally source_nodes, source_shape
    (nodal quadrature when absent); a point's weight is scaled by its edge_factor (search.closest_faces) and
    shared among the faces at the same distance (search.found_entries: one entry each).
    t_gids (k, nv), t_xref (k, nv, 3), t_size (k,): the T faces given to the search.
    """
    q, e, part = found_entries(found, ("face", "shape", "normal"))
    f = e["face"]
    x_target = np.einsum("pv,pvi->pi", e["shape"], t_xref[f])
    delta0 = np.einsum("pi,pi->p", points["x_ref"][q] - x_target, e["normal"])
    src = points.get("source_nodes")
    return Pass(node=points["node"][q], area=points["weight"][q] * part, size=points["size"][q],
                target_nodes=np.asarray(t_gids)[f], shape=e["shape"], normal=e["normal"], delta0=delta0,
                target_size=np.asarray(t_size)[f], source_nodes=None if src is None else src[q],
                source_shape=None if src is None else points["source_shape"][q])


def segment_pass(face_type, xs_ref, xs_cur, s_gids, xt_ref, xt_cur, t_gids, t_size, radius, degree=4):
    """Exact (segment) integration of S faces against T faces: the overlaps cut into quadrature points, a Pass.

    face_type: "tri"/"quad", or a pair (S type, T type). The faces are clipped in their current configuration
    (which decides what meets what); a T face not turned towards the S face (search.FACING) meets none of it;
    points farther than radius [m] from T along its normal are dropped; weights are areas on
    the reference S surface, like the nodal areas.
    """
    from .clipping import candidate_pairs, segment_quadrature
    type_s, type_t = (face_type, face_type) if isinstance(face_type, str) else face_type
    nv_s, nv_t = fem.FACE_NODES[type_s], fem.FACE_NODES[type_t]
    if len(xs_cur) == 0 or len(xt_cur) == 0:
        return Pass.empty(nv_s, nv_t)
    i, j = candidate_pairs(xs_cur, xt_cur, radius)
    if len(i) == 0:
        return Pass.empty(nv_s, nv_t)
    q = segment_quadrature(type_s, xs_cur[i], type_t, xt_cur[j], degree=degree, max_normal_dot=FACING)
    si, tj = i[q["pair"]], j[q["pair"]]
    Ns, _ = fem.SHAPE[type_s](q["xi_s"])
    Nt, _ = fem.SHAPE[type_t](q["xi_t"])
    normal = geometry.face_normal_at(type_t, xt_cur[tj], q["xi_t"])
    gap = np.einsum("pi,pi->p", q["x"] - np.einsum("pv,pvi->pi", Nt, xt_cur[tj]), normal)
    k = np.abs(gap) <= radius
    si, tj, Ns, Nt, normal = si[k], tj[k], Ns[k], Nt[k], normal[k]
    xi_s = q["xi_s"][k]

    weight = (q["weight"][k] * geometry.face_area_density_at(type_s, xs_ref[si], xi_s)
              / geometry.face_area_density_at(type_s, xs_cur[si], xi_s))
    x_ref = np.einsum("pv,pvi->pi", Ns, xs_ref[si])
    delta0 = np.einsum("pi,pi->p", x_ref - np.einsum("pv,pvi->pi", Nt, xt_ref[tj]), normal)
    src = np.asarray(s_gids, dtype=np.int64)[si]
    return Pass(node=src[np.arange(len(src)), np.argmax(Ns, axis=1)], area=weight, size=fem.face_size(xs_ref[si]),
                target_nodes=np.asarray(t_gids)[tj], shape=Nt, normal=normal, delta0=delta0,
                target_size=np.asarray(t_size)[tj], source_nodes=src, source_shape=Ns)
