"""Unit tests of the pure-NumPy contact kernels: projection, search, rows of each formulation, penalty response."""

import numpy as np
import pytest

from qsc_petsc import fem
from qsc_petsc.contact.geometry import project_on_faces
from qsc_petsc.contact.penalty import gate_positions, multipliers_update, row_response
from qsc_petsc.contact.rows import Pass, Rows, die_rows, master_slave, quasi_symmetric, two_pass, weights
from qsc_petsc.contact.search import candidate_pairs, closest_faces

EPS_N = 1.0e3


# ---------------------------------------------------------------- fixtures: surfaces, passes, dense G

def warp(x, y):
    return 0.05 * np.sin(np.pi * x) * np.sin(np.pi * y) + 0.02 * np.sin(2.3 * x + 0.4) * np.sin(1.9 * y + 0.1)


def flat(x, y):
    return np.zeros_like(x)


class Surface:
    """A structured n x n patch of [0, 1]^2 lifted to z = zfun(x, y) + offset, outward normal +z (or -z if down)."""

    def __init__(self, n, face_type, zfun, first_id, down=False, offset=0.0, tilt=None):
        t = np.linspace(0.0, 1.0, n + 1)
        X, Y = np.meshgrid(t, t, indexing="ij")
        x, y = X.ravel(), Y.ravel()
        self.xyz = np.column_stack([x, y, zfun(x, y) + offset])
        if tilt is not None:                     # a rigid rotation of the whole patch
            self.xyz = self.xyz @ tilt.T
        v = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)          # v[i, j]: node at (x_i, y_j)
        quads = np.column_stack([v[:-1, :-1].ravel(), v[1:, :-1].ravel(), v[1:, 1:].ravel(), v[:-1, 1:].ravel()])
        if face_type == "quad":
            faces = quads
        else:
            faces = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
        if down:
            faces = faces[:, ::-1]
        self.type = face_type
        self.faces = faces
        self.ids = first_id + np.arange(len(x), dtype=np.int64)
        self.gfaces = self.ids[faces]
        xf = self.xyz[faces]
        self.face_size = fem.face_size(xf)
        self.area = np.zeros(len(x))
        np.add.at(self.area, faces, fem.face_nodal_areas(face_type, xf))
        cnt = np.zeros(len(x))
        np.add.at(cnt, faces, 1.0)
        self.size = np.zeros(len(x))
        np.add.at(self.size, faces, np.repeat(self.face_size[:, None], faces.shape[1], axis=1))
        self.size /= cnt


def make_pass(S, T, radius=0.2):
    found = closest_faces(S.xyz, T.xyz[T.faces], T.type, np.sort(T.gfaces, axis=1), radius)
    return Pass.from_search(S.ids, S.area, S.size, found, T.gfaces, T.face_size)


def pair(nA, tA, nB, tB, zfun=warp, gap=0.0, tilt=None):
    A = Surface(nA, tA, zfun, 0, down=False, tilt=tilt)
    B = Surface(nB, tB, zfun, len(A.ids), down=True, offset=gap, tilt=tilt)
    return A, B, 3 * (len(A.ids) + len(B.ids))


def dense(rows, ndof):
    G = np.zeros((ndof, ndof))
    np.add.at(G, (rows.G_rows, rows.G_cols), rows.G_vals)
    g = np.zeros(ndof)
    np.add.at(g, rows.g_rows, rows.g_vals)
    W = np.zeros(ndof)
    np.add.at(W, rows.W_rows, rows.W_vals)
    r = np.flatnonzero(W > 0)
    gate = gate_positions(r, rows.gate_rows, rows.gate_of) if len(rows.gate_rows) else None
    return G[r], g[r], W[r], r, gate


def response(rows, ndof, u, **kw):
    G, g, W, _, gate = dense(rows, ndof)
    e, m, d, act = row_response(G @ u - g, W, EPS_N, rows.phi, gate_of=gate, **kw)
    return e, G.T @ m, G.T @ (d[:, None] * G), act


def away_from_kinks(rows, ndof, scale, seed, lmbda=None, margin=2e-4):
    """A random u (ndof,) with every row multiplier at least margin away from its kink, some rows open and some closed."""
    G, g, W, _, _ = dense(rows, ndof)
    for s in range(seed, seed + 500):
        u = scale * np.random.default_rng(s).standard_normal(ndof)
        a = (G @ u - g) / W + (0.0 if lmbda is None else lmbda / EPS_N)
        if np.abs(a).min() > margin and (a > 0).any() and (a < 0).any():
            return u
    raise AssertionError("no u away from the kinks")


def check_derivatives(rows, ndof, u, **kw):
    _, F, J, _ = response(rows, ndof, u, **kw)
    h = 1e-6
    Ffd = np.empty(ndof)
    Jfd = np.empty((ndof, ndof))
    for i in range(ndof):
        up, um = u.copy(), u.copy()
        up[i] += h
        um[i] -= h
        ep, Fp, _, _ = response(rows, ndof, up, **kw)
        em, Fm, _, _ = response(rows, ndof, um, **kw)
        Ffd[i] = (ep - em) / (2 * h)
        Jfd[:, i] = (Fp - Fm) / (2 * h)
    assert np.abs(F).max() > 0 and np.abs(J).max() > 0
    np.testing.assert_allclose(Ffd, F, rtol=0, atol=1e-7 * np.abs(F).max())
    np.testing.assert_allclose(Jfd, J, rtol=0, atol=1e-7 * np.abs(J).max())
    np.testing.assert_allclose(J, J.T, atol=1e-12 * np.abs(J).max())


FORMULATIONS = {
    "master_slave": lambda sp, mp: master_slave(sp),
    "two_pass": two_pass,
    "quasi_symmetric_0.5": lambda sp, mp: quasi_symmetric(sp, mp, 0.5),
    "quasi_symmetric_finer": lambda sp, mp: quasi_symmetric(sp, mp, "finer"),
    "quasi_symmetric_0.2": lambda sp, mp: quasi_symmetric(sp, mp, 0.2),
}
MESH_PAIRS = [(3, "quad", 4, "quad"), (4, "quad", 3, "tri"), (3, "tri", 4, "tri")]


# ---------------------------------------------------------------- geometry

def random_warped_quad(rng):
    x = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
    x[:, :2] += 0.15 * rng.uniform(-1, 1, (4, 2))
    x[:, 2] += 0.25 * rng.uniform(-1, 1, 4)
    return x


def warped_quads_and_points(rng, count=200):
    """count random warped quads, natural coordinates xi inside each, the shape values, points and normals there."""
    faces = np.array([random_warped_quad(rng) for _ in range(count)])
    xi = rng.uniform(-0.95, 0.95, (count, 2))
    N, _ = fem.shape_quad(xi)
    on = np.einsum("pv,pvi->pi", N, faces)
    n = np.array([fem.face_normals("quad", f[None], x[None])[0][0, 0] for f, x in zip(faces, xi)])
    return faces, xi, N, on, n


def test_projection_recovers_xi_on_warped_quads():
    """Points off a warped quad along its normal at xi shall project back to xi, at distance |t|, inside."""
    rng = np.random.default_rng(1)
    faces, xi, N, on, n = warped_quads_and_points(rng)
    t = rng.uniform(-0.05, 0.05, 200)
    pr = project_on_faces(on + t[:, None] * n, faces, "quad")
    np.testing.assert_allclose(pr.xi, xi, atol=1e-11)
    np.testing.assert_allclose(pr.distance, np.abs(t), atol=1e-13)
    np.testing.assert_allclose(pr.normal, n, atol=1e-12)
    np.testing.assert_allclose(pr.closest, on, atol=1e-13)
    np.testing.assert_allclose(pr.shape, N, atol=1e-11)
    assert pr.inside.all()


@pytest.mark.parametrize("offset", [1e3, 1e6])
def test_projection_on_quads_far_from_the_origin(offset):
    """The same warped quads and points moved offset away (the faces 1 m wide): the same xi, inside, to the
    coordinates' own round-off (eps x offset). The Newton residual read x(xi) - p from the coordinates, whose
    round-off (eps |x| / h in xi) kept its steps above NEWTON_TOL at |x| / h ~ 500 and more: the points went to the
    edges, and their rows away (a body 1000 m off lost 16 % of its rows; hunt30_1)."""
    faces, xi, _, on, n = warped_quads_and_points(np.random.default_rng(3))
    shift = offset * np.array([1.0, -0.6, 0.3])
    pr = project_on_faces(on + 0.03 * n + shift, faces + shift, "quad")
    assert pr.inside.all()
    np.testing.assert_allclose(pr.xi, xi, atol=50 * np.finfo(float).eps * offset)
    np.testing.assert_allclose(pr.distance, 0.03, atol=50 * np.finfo(float).eps * offset)


def brute_force_distance(point, face, face_type, k=601):
    s = np.linspace(-1, 1, k) if face_type == "quad" else np.linspace(0, 1, k)
    X, Y = np.meshgrid(s, s, indexing="ij")
    xi = np.column_stack([X.ravel(), Y.ravel()])
    if face_type == "tri":
        xi = xi[xi.sum(axis=1) <= 1.0]
    N, _ = fem.SHAPE[face_type](xi)
    return np.linalg.norm(N @ face - point, axis=1).min()


@pytest.mark.parametrize("face_type", ["quad", "tri"])
def test_projection_outside_points_match_brute_force(face_type):
    """Points anywhere around a face shall get its true closest point (checked against dense sampling)."""
    rng = np.random.default_rng(2)
    faces = np.array([random_warped_quad(rng) for _ in range(40)])
    if face_type == "tri":
        faces = faces[:, :3]
    pts = rng.uniform(-0.8, 1.8, (40, 3))
    pr = project_on_faces(pts, faces, face_type)
    N, _ = fem.SHAPE[face_type](pr.xi)
    np.testing.assert_allclose(np.einsum("pv,pvi->pi", N, faces), pr.closest, atol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(pts - pr.closest, axis=1), pr.distance, atol=1e-14)
    for p, f, d in zip(pts, faces, pr.distance):
        b = brute_force_distance(p, f, face_type)
        assert d <= b + 1e-12
        assert b - d < 2e-5
    assert (~pr.inside).any()


def test_projection_triangle_edges_and_vertices():
    """Points in the vertex and edge regions of a triangle shall be clamped to that vertex or edge in closed form."""
    tri = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    pts = np.array([[-1.0, -1.0, 0.5],     # vertex 0
                    [2.0, -0.5, 0.1],      # vertex 1
                    [-0.3, 1.5, -0.2],     # vertex 2
                    [0.5, -1.0, 0.3],      # edge 0-1
                    [1.0, 1.0, 0.2],       # edge 1-2
                    [-0.7, 0.25, 0.0],     # edge 2-0
                    [0.2, 0.3, -0.4],      # interior
                    [0.5, 0.5, 0.0]])      # exactly on edge 1-2
    xi = np.array([[0, 0], [1, 0], [0, 1], [0.5, 0], [0.5, 0.5], [0, 0.25], [0.2, 0.3], [0.5, 0.5]])
    inside = [False, False, False, False, False, False, True, True]
    pr = project_on_faces(pts, np.repeat(tri[None], len(pts), axis=0), "tri")
    np.testing.assert_allclose(pr.xi, xi, atol=1e-15)
    np.testing.assert_array_equal(pr.inside, inside)
    np.testing.assert_allclose(pr.normal, np.tile([0, 0, 1.0], (len(pts), 1)))
    np.testing.assert_allclose(pr.distance, np.linalg.norm(pts - np.column_stack([xi, 0 * xi[:, 0]]), axis=1))


def test_projection_quad_edge_and_vertex_clamping():
    """Points beyond a quad's edges or corners shall project on the edge point or corner exactly."""
    quad = np.array([[0.0, 0, 0], [2, 0, 0], [2, 1, 0.3], [0, 1, 0.3]])      # a plane quad, sloped
    pts = np.array([[1.0, -1.0, 0.0], [3.0, -1.0, 0.0], [-1.0, 2.0, 1.0], [3.0, 0.5, -0.5]])
    pr = project_on_faces(pts, np.repeat(quad[None], 4, axis=0), "quad")
    np.testing.assert_allclose(pr.xi[:3], [[0, -1], [1, -1], [-1, 1]], atol=1e-15)
    assert pr.xi[3, 0] == 1.0 and not pr.inside.any()


# ---------------------------------------------------------------- search

def dense_pairs(points, lo, hi, radius):
    inside = ((points[:, None] >= lo[None] - radius) & (points[:, None] <= hi[None] + radius)).all(axis=2)
    return set(zip(*np.nonzero(inside)))


@pytest.mark.parametrize("radius", [0.0, 0.03, 0.4])
def test_candidate_pairs_equal_brute_force(radius):
    """The bucket grid shall return exactly the (point, face) pairs of the all-pairs box test, sorted."""
    rng = np.random.default_rng(3)
    lo = rng.uniform(-1, 1, (300, 3))
    hi = lo + rng.uniform(0, 0.3, (300, 3)) * rng.choice([0.1, 1, 5], (300, 1))
    pts = rng.uniform(-1.5, 1.5, (700, 3))
    pts[:50] = lo[:50]                     # points on box corners and faces
    pts[50:100, 0] = hi[50:100, 0] + radius
    pi, fi = candidate_pairs(pts, lo, hi, radius)
    assert set(zip(pi, fi)) == dense_pairs(pts, lo, hi, radius)
    assert len(set(zip(pi, fi))) == len(pi)
    assert (np.diff(pi) >= 0).all()
    # integer data: many points exactly on box boundaries
    lo = rng.integers(0, 10, (200, 3)).astype(float)
    hi = lo + rng.integers(0, 3, (200, 3))
    pts = rng.integers(-1, 13, (500, 3)).astype(float)
    pi, fi = candidate_pairs(pts, lo, hi, radius)
    assert set(zip(pi, fi)) == dense_pairs(pts, lo, hi, radius)


def test_candidate_pairs_empty():
    z = np.zeros((0, 3))
    for args in [(z, np.ones((2, 3)), np.ones((2, 3))), (np.ones((2, 3)), z, z)]:
        pi, fi = candidate_pairs(*args, 0.1)
        assert len(pi) == len(fi) == 0
    pi, fi = candidate_pairs(np.full((3, 3), 100.0), np.zeros((2, 3)), np.ones((2, 3)), 0.1)
    assert len(pi) == 0


def tie_points(S):
    """Grid nodes, edge midpoints and points hovering over them: every one ties between several faces."""
    xf = S.xyz[S.faces]
    mids = 0.5 * (xf + np.roll(xf, -1, axis=1)).reshape(-1, 3)
    return np.concatenate([S.xyz, mids, S.xyz + [0, 0, 0.01], mids - [0, 0, 0.01]])


@pytest.mark.parametrize("face_type", ["quad", "tri"])
def test_tie_rule_is_independent_of_face_order_and_subset(face_type):
    """Points on shared edges and vertices shall pick the same face (smallest key) for any order or superset of faces."""
    S = Surface(4, face_type, warp, 100, down=True)
    pts = tie_points(S)
    key = np.sort(S.gfaces, axis=1)
    xf = S.xyz[S.faces]
    ref = closest_faces(pts, xf, face_type, key, 0.2)
    assert (ref["face"] >= 0).all()
    # genuinely ties: several faces at (nearly) the same distance
    pi, fi = candidate_pairs(pts, xf.min(axis=1), xf.max(axis=1), 0.2)
    pr = project_on_faces(pts[pi], xf[fi], face_type)
    close = pr.distance <= ref["distance"][pi] + 1e-9 * S.face_size[fi]
    nties = np.bincount(pi[close], minlength=len(pts))
    assert (nties >= 2).sum() > len(S.xyz)
    # the winner has the smallest key among its ties
    for i in np.flatnonzero(nties >= 2)[:50]:
        tied = fi[close & (pi == i)]
        best = min(tuple(k) for k in key[tied])
        assert tuple(key[ref["face"][i]]) == best
    rng = np.random.default_rng(4)
    for trial in range(5):
        perm = rng.permutation(len(xf))
        if trial >= 3:          # a rank that holds only some faces (all those within radius of its points)
            perm = perm[: 3 * len(perm) // 4]
        sub = np.flatnonzero(np.isin(ref["face"], perm))
        got = closest_faces(pts[sub], xf[perm], face_type, key[perm], 0.2)
        if trial < 3:
            assert len(sub) == len(pts)
        np.testing.assert_array_equal(perm[got["face"]], ref["face"][sub])
        for k in ["xi", "shape", "normal", "distance", "signed_gap", "inside"]:
            np.testing.assert_array_equal(got[k], ref[k][sub])



@pytest.mark.parametrize("face_type", ["quad", "tri"])
def test_a_wide_search_projects_only_the_faces_that_may_be_nearest(face_type, monkeypatch):
    """Within a radius of many face sizes the search projects only the faces whose box lies within a point's
    nearest vertex distance (plus the tie and keep margins), found by radii doubling from the faces' size; the
    answer shall be that of projecting every face within the radius, bit for bit, for points on, over, under
    and far from a warped surface, with ties, an edge band and kept faces (it projected all: search_distance
    10, 11 M pairs, 40 s; now 0.3 s)."""
    from qsc_petsc.contact import search
    S = Surface(6, face_type, warp, 100, down=True)
    key = np.sort(S.gfaces, axis=1)
    xf = S.xyz[S.faces]
    rng = np.random.default_rng(11)
    pts = np.concatenate([tie_points(S), S.xyz + rng.uniform(-0.3, 0.3, S.xyz.shape) * [1, 1, 0.5],
                          S.xyz[:5] + [0, 0, 0.9]])
    band = np.full(len(pts), 0.05)
    keep = key[rng.integers(0, len(key), len(pts))]
    calls = []

    def every_face(points, face_xyz, radius, margin, facing=None):
        calls.append(len(points))
        pi, fi = candidate_pairs(points, face_xyz.min(axis=1), face_xyz.max(axis=1), radius)
        if facing is None:
            return pi, fi
        turned = search.facing_pairs(facing[0][pi], facing[1][fi])
        return pi[turned], fi[turned]

    # points facing the surface (up), and some turned away from it, whose faces none is turned towards
    normal = np.where((np.arange(len(pts)) % 7 == 3)[:, None], [0.0, 0.0, -1.0], [0.0, 0.0, 1.0])
    for kwargs in ({}, {"band": band}, {"keep": keep, "keep_within": np.full(len(pts), 0.02)}, {"normal": normal}):
        got = closest_faces(pts, xf, face_type, key, 1.0, **kwargs)
        with monkeypatch.context() as m:
            m.setattr(search, "_nearest_candidates", every_face)
            ref = closest_faces(pts, xf, face_type, key, 1.0, **kwargs)
        for k in ["face", "xi", "normal", "signed_gap", "edge_factor", "share", "key"]:
            np.testing.assert_array_equal(got[k], ref[k], err_msg=k)
        np.testing.assert_array_equal(got["extra"]["face"], ref["extra"]["face"])
    assert calls and (got["face"] >= 0).sum() == (normal[:, 2] > 0).sum() and (got["share"] > 1).any()

def test_a_point_in_front_of_a_face_turned_away_meets_none():
    """A chisel over a plate: its vertical face (x = 0, outward -x) and its bevel (outward down and +x) meet at the
    edge x = z = 0. A plate node beside the edge (outward +z) is as near to both faces; it is in front of the
    vertical face, turned away from it, so outside the chisel: no face (the bevel's plane alone read it as
    penetrating, and two_pass pushed the chisel off; hunt28_5). A node under the edge line of a block's bottom and
    side (on the side face's plane) takes the bottom face, whole (it took a sideways share; hunt28_3)."""
    t = np.tan(np.radians(30.0))
    chisel = np.array([[[0, 0, 0], [0, 0, 1], [0, 1, 1], [0, 1, 0]],            # vertical face, outward -x
                       [[0, 0, 0], [0, 1, 0], [1, 1, 1 / t], [1, 0, 1 / t]]], dtype=float)  # bevel, 60 degrees
    key = np.array([[0, 1, 2, 3], [0, 1, 4, 5]])
    up = np.array([[0.0, 0.0, 1.0]])
    beside = np.array([[-0.03, 0.5, 0.0]])
    plain = closest_faces(beside, chisel, "quad", key, 0.2)
    assert plain["face"][0] >= 0 and plain["share"][0] == 2          # the tie of the two faces, without normals
    assert closest_faces(beside, chisel, "quad", key, 0.2, normal=up)["face"][0] == -1
    # with an edge band the weight fades as past an edge: whole up to a tenth of it, none beyond it
    for band, weight in ((0.02, 0.0), (0.3, 1.0), (0.1, (0.1 - 0.03) / 0.09)):
        out = closest_faces(beside, chisel, "quad", key, 0.2, band=np.array([band]), normal=up)
        assert out["edge_factor"][0] == pytest.approx(weight, abs=1e-6) and (out["face"][0] >= 0) == (weight > 0)
    block = np.array([[[0, 0, 0], [0, 1, 0], [1, 1, 0], [1, 0, 0]],               # bottom, outward -z
                      [[0, 0, 0], [0, 0, 1], [0, 1, 1], [0, 1, 0]]], dtype=float)  # side x = 0, outward -x
    edge = closest_faces(np.array([[0.0, 0.5, 0.0]]), block, "quad", key, 0.2, normal=up)
    assert edge["face"][0] == 0 and edge["share"][0] == 1 and len(edge["extra"]["point"]) == 0


def test_a_side_face_meets_no_plate_tilted_below_the_facing_angle():
    """A Gauss point on a punch's side (outward +x) just above a plate tilted 10 degrees towards it (outward normal
    10 degrees off +z, towards -x): their normals are 80 degrees from facing, so the point meets no face. At 84
    degrees (FACING -0.1) it did: a plate bent 6 degrees beside a punch opened the punch's edge rows through its
    sides' points (6.6 % of the force; hunt28_6)."""
    a = np.radians(10.0)
    plate = np.array([[[-0.5, 0, 0], [0.5, 0, 0], [0.5, 1, 0], [-0.5, 1, 0]]], dtype=float)      # outward +z
    plate = plate @ np.array([[np.cos(a), 0, -np.sin(a)], [0, 1, 0], [np.sin(a), 0, np.cos(a)]]).T   # tilted
    from qsc_petsc.contact.geometry import face_normal_at
    n = face_normal_at("quad", plate, np.zeros((1, 2)))[0]
    assert n[2] == pytest.approx(np.cos(a)) and n[0] < 0
    side = np.array([[0.0, 0.5, 0.02]])
    assert closest_faces(side, plate, "quad", np.array([[0, 1, 2, 3]]), 0.2)["face"][0] == 0
    assert closest_faces(side, plate, "quad", np.array([[0, 1, 2, 3]]), 0.2, normal=np.array([[1.0, 0, 0]]))[
        "face"][0] == -1


def test_tie_rule_on_a_kinked_ridge():
    """Over the ridge of a roof, the normal shall come from the face with the smallest key, whatever the order."""
    x = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [-1, 0, -1], [-1, 1, -1], [2, 0, -1], [2, 1, -1]],
                 dtype=float)
    faces = np.array([[4, 0, 3, 5], [0, 1, 2, 3], [1, 6, 7, 2]])            # left slope, flat top, right slope
    ids = np.array([7, 3, 9, 1, 8, 2, 5, 6])
    key = np.sort(ids[faces], axis=1)
    pts = np.array([[-0.3, 0.5, 0.3], [1.3, 0.5, 0.3], [0.0, 0.5, 0.0], [1.0, 0.2, 0.0]])
    ref = closest_faces(pts, x[faces], "quad", key, 2.0)
    for perm in [[2, 1, 0], [1, 2, 0], [0, 2, 1]]:
        got = closest_faces(pts, x[faces][perm], "quad", key[perm], 2.0)
        np.testing.assert_array_equal(np.array(perm)[got["face"]], ref["face"])
        np.testing.assert_array_equal(got["normal"], ref["normal"])
    # the point over the left ridge is equidistant to the left slope and the top: smallest key wins
    k0, k1 = tuple(key[0]), tuple(key[1])
    assert ref["face"][0] == (0 if k0 < k1 else 1)
    assert ref["signed_gap"][0] > 0


def test_closest_faces_radius_and_signed_gap():
    """Points beyond the radius find no face; signed_gap is + when apart and - when penetrating."""
    S = Surface(3, "quad", flat, 0)
    pts = np.array([[0.5, 0.5, 0.1], [0.5, 0.5, -0.05], [0.5, 0.5, 0.5]])
    out = closest_faces(pts, S.xyz[S.faces], "quad", np.sort(S.gfaces, axis=1), 0.2)
    np.testing.assert_array_equal(out["face"] >= 0, [True, True, False])
    np.testing.assert_allclose(out["signed_gap"][:2], [0.1, -0.05])


def test_closest_faces_fades_points_past_the_surface_edge():
    """With an edge band, a point whose closest point is on an edge it lies beyond is d_p past the edge in the
    face's plane and d_n off the plane; with d = max(d_p - d_n, 0) its edge_factor is 1 up to d = 0.1 band, then
    falls linearly to 0 at d = band, and it has no face from d >= band. Points over a face keep all their
    weight, and so does a point over a convex ridge of two faces at any gap (d_p = d_n sin / cos of the half
    angle: small sliding's first search, with a gap, dropped the ridge's rows and let it through a body)."""
    S = Surface(2, "quad", flat, 0)
    pts = np.array([[0.5, 0.5, -0.01],                  # over the surface
                    [1.02, 0.5, 0.0],                   # 0.02 beside the edge x = 1
                    [1.06, 0.5, 0.0],                   # 0.06 beside it: beyond a band of 0.05
                    [0.5, -0.03, 0.0],                  # 0.03 beside the edge y = 0
                    [1.03, 0.5, 0.01]])                 # 0.03 past the edge, 0.01 above: d = 0.02
    key = np.sort(S.gfaces, axis=1)
    band = np.full(len(pts), 0.05)
    out = closest_faces(pts, S.xyz[S.faces], "quad", key, 0.2, band)
    np.testing.assert_array_equal(out["face"] >= 0, [True, True, False, True, True])
    fade = (0.05 - np.array([0.02, 0.03, 0.02])) / (0.9 * 0.05)
    np.testing.assert_allclose(out["edge_factor"], [1.0, fade[0], 0.0, fade[1], fade[2]])
    near = closest_faces(np.array([[1.004, 0.5, 0.0]]), S.xyz[S.faces], "quad", key, 0.2, np.array([0.05]))
    assert near["edge_factor"][0] == 1.0                # within EDGE_FULL of the band
    plain = closest_faces(pts, S.xyz[S.faces], "quad", key, 0.2)
    np.testing.assert_array_equal(plain["edge_factor"], [1.0] * 5)
    # a ridge: two faces meeting at x = 0.5 at a right angle, points over it at gaps 1e-3 and 0.1
    xyz = np.array([[0.0, 0, -0.5], [0.5, 0, 0], [0.5, 1, 0], [0.0, 1, -0.5], [1.0, 0, -0.5], [1.0, 1, -0.5]])
    faces = np.array([[0, 1, 2, 3], [1, 4, 5, 2]])
    ridge = closest_faces(np.array([[0.5, 0.5, 1e-3], [0.5, 0.5, 0.1]]), xyz[faces], "quad",
                          np.sort(faces, axis=1), 0.2, np.array([0.05, 0.05]))
    assert not ridge["inside"].any() and (ridge["face"] >= 0).all()
    np.testing.assert_allclose(ridge["edge_factor"], [1.0, 1.0])


def test_a_point_keeps_its_face_at_a_kink_within_the_keep_distance():
    """Two faces meeting at x = 0.5 with a slight kink (a roof of slope 0.01): a point just over the left face
    is nearest to it; given the right face as the face it took at the last search, it keeps that face while the
    right face lies within keep_within of the nearest, and takes the nearest beyond. Large sliding's searches
    had swung such points between the two faces for ever (session 26). The keys of the faces taken come back."""
    xyz = np.array([[0.0, 0, -0.005], [0.5, 0, 0], [0.5, 1, 0], [0.0, 1, -0.005], [1.0, 0, -0.005],
                    [1.0, 1, -0.005]])
    faces = np.array([[0, 1, 2, 3], [1, 4, 5, 2]])
    key = np.sort(faces, axis=1)
    pts = np.array([[0.4999, 0.5, 1e-4], [0.49, 0.5, 1e-4]])
    plain = closest_faces(pts, xyz[faces], "quad", key, 0.2)
    np.testing.assert_array_equal(plain["face"], [0, 0])
    np.testing.assert_array_equal(plain["key"], key[[0, 0]])
    right = np.repeat(key[1:2], 2, axis=0)
    kept = closest_faces(pts, xyz[faces], "quad", key, 0.2, keep=right, keep_within=np.full(2, 1e-3))
    np.testing.assert_array_equal(kept["face"], [1, 0])        # the second lies 1e-2 into the left face
    np.testing.assert_array_equal(kept["key"], key[[1, 0]])
    gap = kept["signed_gap"][0]
    assert abs(gap - plain["signed_gap"][0]) < 0.03 * gap   # the kept face's gap: the nearest's, to the kink's order
    none = closest_faces(pts, xyz[faces], "quad", key, 0.2, keep=np.full((2, 4), -1), keep_within=np.full(2, 1e-3))
    np.testing.assert_array_equal(none["face"], [0, 0])
    far = closest_faces(pts + [0, 0, 5], xyz[faces], "quad", key, 0.2, keep=right, keep_within=np.full(2, 1e-3))
    np.testing.assert_array_equal(far["key"], np.full((2, 4), -1))


def test_a_point_as_near_to_two_faces_is_shared_between_them():
    """A valley of two faces meeting at x = 0.5 (slopes -+0.01) and a point under its bottom line: as near to
    both, each face takes half of its weight with its own projection and normal, so that its pair of rows
    pushes nothing sideways. The tie rule alone gave it whole to the face of smaller key, whose normal leaned
    it toward that face (Gauss rows, whose points fall on the other surface's edges, left configs/flat_punch.toml
    1.1e-5 of its normal force sideways). A shared point keeps no face for the next search; a point nearer to
    one face goes to it whole."""
    xyz = np.array([[0.0, 0, 0.005], [0.5, 0, 0], [0.5, 1, 0], [0.0, 1, 0.005], [1.0, 0, 0.005], [1.0, 1, 0.005]])
    faces = np.array([[0, 1, 2, 3], [1, 4, 5, 2]])
    key = np.sort(faces, axis=1)
    pts = np.array([[0.5, 0.3, -1e-3], [0.45, 0.5, -1e-3]])
    out = closest_faces(pts, xyz[faces], "quad", key, 0.2)
    np.testing.assert_array_equal(out["face"], [0, 0])          # the winner: the smaller key
    np.testing.assert_array_equal(out["share"], [2.0, 1.0])
    np.testing.assert_array_equal(out["extra"]["point"], [0])
    np.testing.assert_array_equal(out["extra"]["face"], [1])
    np.testing.assert_allclose(out["extra"]["signed_gap"], out["signed_gap"][:1], rtol=1e-12)
    assert out["normal"][0, 0] == pytest.approx(-out["extra"]["normal"][0, 0], rel=1e-12) != 0.0
    np.testing.assert_array_equal(out["key"], [[-1] * 4, key[0]])
    pss = Pass.from_search(np.array([10, 11]), np.ones(2), np.full(2, 0.5), out, faces, np.full(2, 0.5))
    np.testing.assert_array_equal(pss.node, [10, 11, 10])
    np.testing.assert_allclose(pss.area, [0.5, 1.0, 0.5])
    shared = pss.node == 10
    sideways = (pss.area[shared, None] * pss.delta0[shared, None] * pss.normal[shared]).sum(axis=0)
    assert abs(sideways[0]) < 1e-15 and abs(sideways[2]) > 1e-4


# ---------------------------------------------------------------- rows

def linearisation_error(S, T, ndof, scale):
    """max |C_r / W_r + signed gap after moving the nodes by u| over nodes projecting well inside a face."""
    u = scale * np.random.default_rng(5).standard_normal((ndof // 3, 3))
    G, g, W, r, _ = dense(master_slave(make_pass(S, T)), ndof)
    h = (G @ u.ravel() - g) / W
    moved = closest_faces(S.xyz + u[S.ids], (T.xyz + u[T.ids])[T.faces], T.type, np.sort(T.gfaces, axis=1), 0.2)
    k = r // 3 - S.ids[0]
    xi = moved["xi"][k]
    lo = 0.0 if T.type == "tri" else -1.0
    ok = (xi > lo + 0.02).all(axis=1) & (xi < 0.98).all(axis=1)
    if T.type == "tri":
        ok &= xi.sum(axis=1) < 0.98
    assert ok.sum() >= 2
    return np.abs(h[ok] + moved["signed_gap"][k][ok]).max()


@pytest.mark.parametrize("mesh", MESH_PAIRS)
def test_penetration_is_the_linearised_signed_gap(mesh):
    """C_r / W_r of a pass shall be minus the signed gap recomputed after a displacement u, up to O(|u|^2)."""
    A, B, ndof = pair(*mesh, gap=0.01)
    for S, T in [(A, B), (B, A)]:
        e5, e6 = linearisation_error(S, T, ndof, 1e-5), linearisation_error(S, T, ndof, 1e-6)
        assert e6 < 1e-10
        assert 50 < e5 / e6 < 200          # second order: the first-order terms are exact


@pytest.mark.parametrize("mesh", MESH_PAIRS)
@pytest.mark.parametrize("name", FORMULATIONS)
def test_force_and_jacobian_are_derivatives(name, mesh):
    """For every formulation, G^T m shall be the gradient of the energy and G^T diag(d) G the gradient of the force."""
    A, B, ndof = pair(*mesh)
    rows = FORMULATIONS[name](make_pass(A, B), make_pass(B, A))
    u = away_from_kinks(rows, ndof, 0.01, seed=10)
    check_derivatives(rows, ndof, u)


def test_augmented_lagrangian_derivatives_and_uzawa():
    """With multipliers, force and Jacobian shall still be the derivatives; Uzawa shall clamp at zero."""
    A, B, ndof = pair(3, "quad", 4, "tri")
    rows = quasi_symmetric(make_pass(A, B), make_pass(B, A), "finer")
    r = len(dense(rows, ndof)[3])
    lmbda = np.abs(np.random.default_rng(6).standard_normal(r)) * EPS_N * 0.005
    u = away_from_kinks(rows, ndof, 0.01, seed=20, lmbda=lmbda)
    check_derivatives(rows, ndof, u, lmbda=lmbda)
    np.testing.assert_allclose(multipliers_update([1.0, 1.0, 0.0, 2.0], [0.5, -2.0, 1.0, 1.0], [1.0, 1.0, 2.0, 0.0],
                                                  2.0), [2.0, 0.0, 1.0, 0.0])


def test_closed_set_start_and_missing_rows():
    """Rows at c = -tol shall be active with zero force; rows with W = 0 shall not exist."""
    e, m, d, act = row_response([-1e-14, -1e-3, 0.2, 5.0], [1.0, 1.0, 2.0, 0.0], 10.0, 0.5, closed_tol=1e-12)
    np.testing.assert_array_equal(act, [True, False, True, False])
    np.testing.assert_allclose(m, [0.0, 0.0, 0.5 * 10 * 0.1, 0.0])
    np.testing.assert_allclose(d, [5.0, 0.0, 2.5, 0.0])
    np.testing.assert_allclose(e, 0.5 * 10 / 4 * 0.04)
    _, _, _, act = row_response([-1e-14], [1.0], 10.0, 1.0)
    assert not act[0]


@pytest.mark.parametrize("slave_type,master_type", [("quad", "quad"), ("tri", "quad"), ("quad", "tri")])
def test_sum_phi_W_is_the_contact_area(slave_type, master_type):
    """On flat interfaces fully in contact, sum_r phi W_r shall be the contact area for every formulation."""
    for nA, nB in [(3, 4), (4, 3), (2, 7)]:
        A, B, _ = pair(nA, slave_type, nB, master_type, zfun=flat)
        sp, mp = make_pass(A, B), make_pass(B, A)
        # every node found a face (a node on an edge of the other mesh is shared by its faces: more entries)
        assert set(sp.node) == set(A.ids) and set(mp.node) == set(B.ids)
        for name, build in FORMULATIONS.items():
            rows = build(sp, mp)
            assert rows.phi * rows.W_vals.sum() == pytest.approx(1.0, rel=1e-13), name


def tilt_matrix():
    a, b = 0.3, -0.2
    Rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    Ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    return Ry @ Rx


@pytest.mark.parametrize("face_type", ["quad", "tri"])
def test_matching_meshes_give_identical_rows(face_type):
    """On matching meshes the three formulations shall give identical C_r / W_r (and energies)."""
    A, B, ndof = pair(3, face_type, 3, face_type, zfun=flat, gap=0.003, tilt=tilt_matrix())
    sp, mp = make_pass(A, B), make_pass(B, A)
    u = 0.01 * np.random.default_rng(7).standard_normal(ndof)
    mean = {}
    for name, build in FORMULATIONS.items():
        G, g, W, r, _ = dense(build(sp, mp), ndof)
        mean[name] = dict(zip(r // 3, (G @ u - g) / W))
    ref = mean["master_slave"]
    assert sorted(ref) == list(A.ids)
    for name, rows_mean in mean.items():
        for v, h in rows_mean.items():
            partner = v if v in ref else v - len(A.ids)          # B node v sits on A node v - nA
            assert h == pytest.approx(ref[partner], abs=1e-14), (name, v)
    energies = [response(build(sp, mp), ndof, u)[0] for build in FORMULATIONS.values()]
    np.testing.assert_allclose(energies, energies[0], rtol=1e-12)


def test_quasi_symmetric_weight_one_is_master_slave():
    """quasi_symmetric with w_a = 1 shall reproduce master_slave's C/W, energy, force and Jacobian."""
    A, B, ndof = pair(3, "quad", 4, "tri")
    sp, mp = make_pass(A, B), make_pass(B, A)
    u = away_from_kinks(master_slave(sp), ndof, 0.01, seed=30)
    ms, qs = master_slave(sp), quasi_symmetric(sp, mp, 1.0)
    Gm, gm, Wm, rm, _ = dense(ms, ndof)
    Gq, gq, Wq, rq, _ = dense(qs, ndof)
    np.testing.assert_array_equal(rm, rq)
    np.testing.assert_allclose((Gq @ u - gq) / Wq, (Gm @ u - gm) / Wm, atol=1e-15)
    for a, b in zip(response(ms, ndof, u)[:3], response(qs, ndof, u)[:3]):
        np.testing.assert_allclose(a, b, rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize("weight", [0.5, 0.0, "finer"])
def test_quasi_symmetric_equals_paper_formula(weight):
    """Each slave row shall be 2 w_a A_k h_k + 2 w_b sum_l N_a^k(xi_a^l) B_l h_l, computed here node by node."""
    A, B, ndof = pair(4, "tri", 3, "quad", gap=0.002)         # the slave (A) finer than the master
    sp, mp = make_pass(A, B), make_pass(B, A)
    u = 0.01 * np.random.default_rng(8).standard_normal((ndof // 3, 3))
    C = np.zeros(ndof // 3)
    Wref = np.zeros(ndof // 3)
    for k in range(len(sp.node)):
        h = -(u[sp.node[k]] - sp.shape[k] @ u[sp.target_nodes[k]]) @ sp.normal[k] - sp.delta0[k]
        w_a = weights(weight, sp.size[k], sp.target_size[k])
        C[sp.node[k]] += 2 * w_a * sp.area[k] * h
        Wref[sp.node[k]] += 2 * w_a * sp.area[k]
    for l in range(len(mp.node)):
        h = -(u[mp.node[l]] - mp.shape[l] @ u[mp.target_nodes[l]]) @ mp.normal[l] - mp.delta0[l]
        w_b = 1 - weights(weight, mp.target_size[l], mp.size[l])
        for k, N in zip(mp.target_nodes[l], mp.shape[l]):
            C[k] += 2 * w_b * N * mp.area[l] * h
            Wref[k] += 2 * w_b * N * mp.area[l]
    rows = quasi_symmetric(sp, mp, weight)
    G, g, W, r, _ = dense(rows, ndof)
    assert set(r // 3) <= set(A.ids)
    np.testing.assert_array_equal(r // 3, np.flatnonzero(Wref > 0))
    np.testing.assert_allclose(G @ u.ravel() - g, C[r // 3], atol=1e-15)
    np.testing.assert_allclose(W, Wref[r // 3], rtol=1e-14)


def test_finer_weight_rule():
    """The "finer" rule shall weight the finer side and be symmetric under swapping slave and master."""
    assert weights("finer", 1.0, 1.0) == 0.5
    assert weights("finer", 0.1, 1.0) > 0.999 and weights("finer", 1.0, 0.1) < 1e-3
    np.testing.assert_allclose(weights("finer", [0.3, 2.0], [0.7, 1.0]) + weights("finer", [0.7, 1.0], [0.3, 2.0]), 1)
    np.testing.assert_array_equal(weights(0.25, np.ones(3), np.ones(3)), 0.25)
    for bad in [1.5, -0.1, "coarser"]:
        with pytest.raises(ValueError):
            weights(bad, 1.0, 1.0)


# ---------------------------------------------------------------- die

DIE = {"point": np.array([0.1, -0.2, 0.12]), "normal": np.array([0.1, -0.2, -1.0]) / np.sqrt(1.05),
       "u_die": np.array([0.01, -0.02, -0.1])}


def die_setup(sticking):
    S = Surface(3, "quad", warp, 0)
    return S, die_rows(S.ids, S.area, S.xyz, DIE["point"], DIE["normal"], DIE["u_die"], sticking), 3 * len(S.ids)


def test_die_penetration_is_exact():
    """A die row's C/W shall be the penetration of the moved node through the moved plane."""
    S, rows, ndof = die_setup(False)
    u = 0.02 * np.random.default_rng(9).standard_normal((len(S.ids), 3))
    G, g, W, r, _ = dense(rows, ndof)
    pen = -((S.xyz + u - DIE["point"] - DIE["u_die"]) @ DIE["normal"])
    np.testing.assert_allclose((G @ u.ravel() - g) / W, pen, atol=1e-15)
    np.testing.assert_allclose(W, S.area)
    assert rows.phi == 1.0 and len(rows.gate_rows) == 0
    # sticking adds rows 3v+1, 3v+2 measuring the tangential slip relative to the die, gated by row 3v
    _, stick, _ = die_setup(True)
    G, g, W, r, gate = dense(stick, ndof)
    c = (G @ u.ravel() - g) / W
    np.testing.assert_array_equal(r[gate >= 0] // 3, r[gate[gate >= 0]] // 3)
    np.testing.assert_array_equal(r[gate < 0] % 3, 0)
    rel = u - DIE["u_die"]
    slip = rel - np.outer(rel @ DIE["normal"], DIE["normal"])
    np.testing.assert_allclose(np.hypot(c[r % 3 == 1], c[r % 3 == 2]), np.linalg.norm(slip, axis=1), atol=1e-15)


@pytest.mark.parametrize("sticking", [False, True])
def test_die_force_and_jacobian_are_derivatives(sticking):
    """Die rows (frictionless and sticking) shall have consistent energy, force and Jacobian."""
    _, rows, ndof = die_setup(sticking)
    G, g, W, _, gate = dense(rows, ndof)
    u = away_from_kinks(_normal_rows(rows), ndof, 0.02, seed=40)
    act = response(rows, ndof, u)[3]
    if sticking:
        np.testing.assert_array_equal(act[gate >= 0], act[gate[gate >= 0]])
    check_derivatives(rows, ndof, u)
    if sticking:
        # an active sticking node is held tangentially: the row force is along t and of either sign
        m = row_response(G @ u - g, W, EPS_N, 1.0, gate_of=gate)[1]
        eq = gate >= 0
        assert (m[eq][act[eq]] != 0).all() and (m[eq][~act[eq]] == 0).all()
        assert (m[eq] < 0).any() and (m[eq] > 0).any()


def _normal_rows(rows):
    """The die rows without their gated tangential rows (the kinks live only in the normal rows)."""
    keep = rows.G_rows % 3 == 0
    kg, kw = rows.g_rows % 3 == 0, rows.W_rows % 3 == 0
    return Rows(rows.G_rows[keep], rows.G_cols[keep], rows.G_vals[keep], rows.g_rows[kg], rows.g_vals[kg],
                rows.W_rows[kw], rows.W_vals[kw], rows.phi)


def test_concat_folds_phi():
    """Concatenating rows with different phi shall keep every energy, force and Jacobian."""
    A, B, ndof = pair(3, "quad", 4, "quad")
    qs = quasi_symmetric(make_pass(A, B), make_pass(B, A))
    die = die_rows(B.ids, B.area, B.xyz, [0, 0, 0.2], [0, 0, 1.0], [0, 0, 0.15], sticking=True)
    both = Rows.concat(qs, die)
    assert both.phi == 1.0
    u = 0.01 * np.random.default_rng(11).standard_normal(ndof)
    a, b, c = response(qs, ndof, u), response(die, ndof, u), response(both, ndof, u)
    assert c[0] == pytest.approx(a[0] + b[0], rel=1e-13)
    np.testing.assert_allclose(c[1], a[1] + b[1], atol=1e-12)
    np.testing.assert_allclose(c[2], a[2] + b[2], atol=1e-9)
    assert (both.phi * both.W_vals).sum() == pytest.approx(qs.phi * qs.W_vals.sum() + die.W_vals.sum())


def test_empty_inputs():
    """A rank with no contact nodes or no opposite faces shall get empty, well-typed results."""
    A, B, _ = pair(3, "quad", 4, "quad")
    found = closest_faces(np.zeros((0, 3)), B.xyz[B.faces], "quad", np.sort(B.gfaces, axis=1), 0.1)
    none = Pass.from_search(A.ids[:0], A.area[:0], A.size[:0], found, B.gfaces, B.face_size)
    far = closest_faces(A.xyz + [0, 0, 5], B.xyz[B.faces], "quad", np.sort(B.gfaces, axis=1), 0.1)
    assert (far["face"] == -1).all()
    assert len(Pass.from_search(A.ids, A.area, A.size, far, B.gfaces, B.face_size).node) == 0
    mp = make_pass(B, A)
    for build in FORMULATIONS.values():
        rows = build(none, none)
        assert len(rows.G_rows) == len(rows.W_rows) == 0 and rows.G_rows.dtype == np.int64
    # master nodes only: the slave rows of quasi_symmetric come from the second term alone
    rows = quasi_symmetric(none, mp, 0.5)
    assert set(rows.W_rows // 3) <= set(A.ids) and rows.phi * rows.W_vals.sum() == pytest.approx(0.5 * mp.area.sum(), rel=1e-13)
    e, m, d, act = row_response(np.zeros(0), np.zeros(0), EPS_N, 0.5, closed_tol=0.0, lmbda=np.zeros(0),
                                gate_of=np.zeros(0, dtype=np.int64))
    assert e == 0.0 and len(m) == len(d) == len(act) == 0


def test_gate_positions():
    rows = np.array([30, 31, 32, 7, 3, 4, 5])
    got = gate_positions(rows, [31, 32, 4, 5, 100], [30, 30, 3, 3, 99])
    np.testing.assert_array_equal(got, [-1, 0, 0, -1, -1, 4, 4])
    with pytest.raises(ValueError):
        gate_positions(np.array([31, 7]), [31], [30])


def test_swap_indicator_has_the_penalty_as_its_floor():
    """summary.json's swap_indicator compares the two sides' mean penetrations over the nodes that carry force,
    against p / eps_n at least: an augmented Lagrangian's exact answer (two round-off means) read 1.2-2.0, and
    open nodes within reach made it the footprints' difference (hunt32_2)."""
    from qsc_petsc.contact.model import _swap_indicator
    eps_n, p, area = 1e8, 2.0, 0.5               # (area x penetration, area, area x pressure) per side
    assert _swap_indicator((area * 2e-17, area, area * p), (area * -1e-17, area, area * p), eps_n) < 1e-8
    assert _swap_indicator((area * 2e-8, area, area * p), (area * 2e-8, area, area * p), eps_n) == 0.0
    assert _swap_indicator((area * 2e-8, area, area * p), (0.0, area, area * p), eps_n) == pytest.approx(1.0)
    assert _swap_indicator((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), eps_n) == 0.0           # nothing presses
