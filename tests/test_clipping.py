"""Segment-integration geometry (qsc_petsc.contact.clipping): candidate pairs, clipped overlaps and their quadrature
checked against independent computations (tensor-product mortar matrices, vertex-enumeration polygon moments,
brute-force box tests) on flat tilted, warped and curved faces."""

from math import factorial

import numpy as np
import pytest

from qsc_petsc import fem
from qsc_petsc.contact.clipping import _inverse_map, _monomials, candidate_pairs, segment_quadrature, triangle_rule
from qsc_petsc.errors import MeshError


def rotation(seed):
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def grid(nx, ny, face_type="quad", reverse=False):
    """Nodes (n, 2) and faces of a structured nx x ny mesh of [0, 1]^2; node (a, b) has id a + (nx + 1) b."""
    X, Y = np.meshgrid(np.linspace(0, 1, nx + 1), np.linspace(0, 1, ny + 1), indexing="xy")
    nodes = np.column_stack([X.ravel(), Y.ravel()])
    a, b = np.meshgrid(np.arange(nx), np.arange(ny), indexing="xy")
    n0 = (a + (nx + 1) * b).ravel()
    quads = np.column_stack([n0, n0 + 1, n0 + nx + 2, n0 + nx + 1])
    faces = quads if face_type == "quad" else np.vstack([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    return nodes, (faces[:, ::-1] if reverse else faces)


def place(p2, R, shift, z=0.0):
    """Plane points (n, 2) at height z, rotated by R and shifted: (n, 3)."""
    p = np.column_stack([p2, np.full(len(p2), z)])
    return p @ R.T + shift


def hat_mass_1d(n_a, n_b):
    """int_0^1 phi_a psi_c dx for the hat functions of uniform meshes with n_a and n_b cells (exact: 2-point Gauss per piece)."""
    xa, xb = np.linspace(0, 1, n_a + 1), np.linspace(0, 1, n_b + 1)
    cuts = np.unique(np.concatenate([xa, xb]))
    g, w = np.polynomial.legendre.leggauss(2)
    mid, half = 0.5 * (cuts[1:] + cuts[:-1]), 0.5 * (cuts[1:] - cuts[:-1])
    x = (mid[:, None] + half[:, None] * g[None, :]).ravel()
    wx = (half[:, None] * w[None, :]).ravel()

    def hats(nodes):
        return np.maximum(0.0, 1.0 - np.abs(x[None, :] - nodes[:, None]) * (len(nodes) - 1))
    return np.einsum("q,aq,cq->ac", wx, hats(xa), hats(xb))


def overlap_quadrature(ts, xs, tt, xt, distance):
    i, j = candidate_pairs(xs, xt, distance)
    return i, j, segment_quadrature(ts, xs[i], tt, xt[j])


@pytest.mark.parametrize("ns, nt, reverse, seed", [((4, 4), (7, 7), True, 1), ((3, 10), (5, 16), False, 2)])
def test_tilted_flat_grids_give_face_areas_and_the_mortar_matrix(ns, nt, reverse, seed):
    """On tilted non-matching flat grids (T 0.05 away along the normal) the weights of each S face shall sum to its
    area and sum_q w N_S^I N_T^J shall equal the tensor-product mortar matrix to 1e-12."""
    R, shift = rotation(seed), np.array([0.3, -1.2, 2.0])
    ps, fs = grid(*ns)
    pt, ft = grid(*nt, reverse=reverse)
    xs, xt = place(ps, R, shift)[fs], place(pt, R, shift, z=0.05)[ft]
    i, j, q = overlap_quadrature("quad", xs, "quad", xt, 0.06)

    area = np.zeros(len(fs))
    np.add.at(area, i[q["pair"]], q["weight"])
    np.testing.assert_allclose(area, 1.0 / (ns[0] * ns[1]), rtol=1e-13)

    Ns, _ = fem.SHAPE["quad"](q["xi_s"])
    Nt, _ = fem.SHAPE["quad"](q["xi_t"])
    M = np.zeros((len(ps), len(pt)))
    rows = fs[i[q["pair"]]][:, :, None]
    cols = ft[j[q["pair"]]][:, None, :]
    np.add.at(M, (np.broadcast_to(rows, (len(rows), 4, 4)), np.broadcast_to(cols, (len(cols), 4, 4))),
              q["weight"][:, None, None] * Ns[:, :, None] * Nt[:, None, :])
    # node (a, b) of a grid is phi_a(x) phi_b(y): the mortar matrix is a Kronecker product of 1-D ones
    exact = np.kron(hat_mass_1d(ns[1], nt[1]), hat_mass_1d(ns[0], nt[0]))
    assert np.abs(M - exact).max() < 1e-12
    assert abs(M.sum() - 1.0) < 1e-13


def convex_polygon(rng, nv, centre, radius):
    """A random strictly convex ccw polygon with nv vertices."""
    while True:
        ang = np.sort(rng.uniform(0, 2 * np.pi, nv))
        r = radius * rng.uniform(0.7, 1.0, nv)
        P = np.column_stack([r * np.cos(ang), r * np.sin(ang)])
        e = np.roll(P, -1, axis=0) - P
        turn = e[:, 0] * np.roll(e, -1, axis=0)[:, 1] - e[:, 1] * np.roll(e, -1, axis=0)[:, 0]
        if turn.min() > 0.05 * radius ** 2:
            return centre + P


def overlap_moments(A, B):
    """Integrals of 1, x, y, xy over the intersection of convex ccw polygons A, B by vertex enumeration and Green's theorem."""
    def inside(p, P):
        e = np.roll(P, -1, axis=0) - P
        return (e[:, 0] * (p[1] - P[:, 1]) - e[:, 1] * (p[0] - P[:, 0]) >= -1e-14).all()
    pts = [p for p in A if inside(p, B)] + [p for p in B if inside(p, A)]
    for a0, a1 in zip(A, np.roll(A, -1, axis=0)):
        for b0, b1 in zip(B, np.roll(B, -1, axis=0)):
            M = np.column_stack([a1 - a0, b0 - b1])
            if abs(np.linalg.det(M)) < 1e-14:
                continue
            s, t = np.linalg.solve(M, b0 - a0)
            if -1e-14 <= s <= 1 + 1e-14 and -1e-14 <= t <= 1 + 1e-14:
                pts.append(a0 + s * (a1 - a0))
    if len(pts) < 3:
        return np.zeros(4)
    P = np.array(pts)
    c = P.mean(axis=0)
    P = P[np.argsort(np.arctan2(P[:, 1] - c[1], P[:, 0] - c[0]))]
    x, y = P[:, 0], P[:, 1]
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    cr = x * y1 - x1 * y
    return np.array([cr.sum() / 2, ((x + x1) * cr).sum() / 6, ((y + y1) * cr).sum() / 6,
                     (cr * (x * y1 + 2 * x * y + 2 * x1 * y1 + x1 * y)).sum() / 24])


@pytest.mark.parametrize("ts, tt", [("quad", "tri"), ("tri", "tri"), ("tri", "quad"), ("quad", "quad")])
def test_polygon_moments_match_vertex_enumeration(ts, tt):
    """Integrals of 1, x, y, xy over the overlap of random convex faces (tilted plane, T offset and turned the other
    way) shall equal the exact moments of the overlap polygon found by vertex enumeration, to 1e-13."""
    rng = np.random.default_rng(7)
    R, shift = rotation(11), np.array([5.0, 1.0, -3.0])
    nvs, nvt = fem.FACE_NODES[ts], fem.FACE_NODES[tt]
    A = [convex_polygon(rng, nvs, np.zeros(2), 1.0) for _ in range(60)]
    B = [convex_polygon(rng, nvt, rng.uniform(-1, 1, 2), rng.uniform(0.3, 1.5)) for _ in range(60)]
    xs = np.array([place(a, R, shift) for a in A])
    xt = np.array([place(b[::-1], R, shift, z=-0.02) for b in B])          # T's normal faces S
    q = segment_quadrature(ts, xs, tt, xt)
    local = ((q["x"] - shift) @ R)                                          # back to the plane's coordinates
    np.testing.assert_allclose(local[:, 2], 0.0, atol=1e-14)
    f = np.column_stack([np.ones(len(local)), local[:, 0], local[:, 1], local[:, 0] * local[:, 1]])
    got = np.zeros((len(A), 4))
    np.add.at(got, q["pair"], q["weight"][:, None] * f)
    want = np.array([overlap_moments(a, b) for a, b in zip(A, B)])
    assert (want[:, 0] > 1e-3).sum() >= 20 and (want[:, 0] == 0).sum() >= 1  # overlapping and separate pairs
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-13)
    assert set(np.unique(q["pair"])) == set(np.flatnonzero(want[:, 0] > 0))


def warped_quad(rng, centre, size, warp):
    p = centre + size * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * rng.uniform(0.8, 1.2, (4, 2))
    return np.column_stack([p, warp * rng.uniform(-1, 1, 4)])


@pytest.mark.parametrize("ts, tt", [("quad", "quad"), ("quad", "tri"), ("tri", "quad")])
def test_points_map_back_to_s_and_along_the_normal_to_t(ts, tt):
    """On warped, tilted faces x shall be N_S(xi_s) x_S with xi_s in S, and N_T(xi_t) x_T shall lie on the line through
    x along S's centroid normal with xi_t in T."""
    rng = np.random.default_rng(3)
    R = rotation(5)
    xs, xt = [], []
    for _ in range(30):
        s = warped_quad(rng, np.zeros(2), 1.0, 0.15)
        t = warped_quad(rng, rng.uniform(-1, 1, 2), rng.uniform(0.4, 1.2), 0.15) + [0, 0, 0.3]
        xs.append(s[:3] if ts == "tri" else s)
        xt.append(t[[0, 2, 1]] if tt == "tri" else t[::-1])
    xs, xt = np.array(xs) @ R.T, np.array(xt) @ R.T
    q = segment_quadrature(ts, xs, tt, xt)
    assert len(q["pair"]) > 100
    Ns, _ = fem.SHAPE[ts](q["xi_s"])
    Nt, _ = fem.SHAPE[tt](q["xi_t"])
    np.testing.assert_allclose(np.einsum("qv,qvi->qi", Ns, xs[q["pair"]]), q["x"], atol=1e-14)
    n, _ = fem.face_normals(ts, xs, fem.CENTROID[ts][None, :])
    d = np.einsum("qv,qvi->qi", Nt, xt[q["pair"]]) - q["x"]
    assert np.linalg.norm(np.cross(d, n[q["pair"], 0]), axis=1).max() < 1e-13
    assert np.abs(np.einsum("qi,qi->q", d, n[q["pair"], 0])).min() > 0.0
    for ft, xi in ((ts, q["xi_s"]), (tt, q["xi_t"])):
        if ft == "quad":
            assert np.abs(xi).max() <= 1 + 1e-12
        else:
            assert xi.min() >= -1e-12 and xi.sum(axis=1).max() <= 1 + 1e-12
    assert (q["weight"] > 0).all()


def cylinder(n_theta, n_z, theta, z, radius, face_type="quad", shear=0.0):
    """A structured mesh (node coordinates (m, nv, 3) per face) of the cylinder x^2 + y^2 = radius^2."""
    u, v = np.meshgrid(np.linspace(*theta, n_theta + 1), np.linspace(*z, n_z + 1), indexing="xy")
    th = u + shear * (v - np.mean(z))
    nodes = np.column_stack([radius * np.cos(th.ravel()), radius * np.sin(th.ravel()), v.ravel()])
    _, faces = grid(n_theta, n_z, face_type)
    return nodes[faces]


def deviation(face_type, xf, radius):
    """Largest distance from the cylinder of points of the faces (sampled on a fine reference grid)."""
    s = np.linspace(-1, 1, 21) if face_type == "quad" else np.linspace(0, 1, 21)
    X, Y = np.meshgrid(s, s)
    xi = np.column_stack([X.ravel(), Y.ravel()])
    if face_type == "tri":
        xi = xi[xi.sum(axis=1) <= 1]
    N, _ = fem.SHAPE[face_type](xi)
    p = np.einsum("qv,mvi->mqi", N, xf)
    return np.abs(radius - np.hypot(p[..., 0], p[..., 1])).max()


@pytest.mark.parametrize("tt", ["quad", "tri"])
def test_cylinder_meshed_twice_total_weight_and_distance(tt):
    """Warped (sheared) quads of a cylinder against a different mesh of it: each S face's weights shall sum to its area
    (1e-11), the total to the exact cylinder area up to the chord error, and the points on T shall lie within the two
    meshes' distance from the cylinder."""
    radius = 1.0
    xs = cylinder(9, 6, (0.3, 1.2), (0.2, 0.8), radius, "quad", shear=0.4)   # warped quads
    xt = cylinder(17, 11, (0.0, np.pi / 2), (0.0, 1.0), radius, tt)[:, ::-1]   # T faces S
    dev = deviation("quad", xs, radius) + deviation(tt, xt, radius)
    i, j, q = overlap_quadrature("quad", xs, tt, xt, 2 * dev)
    area = np.zeros(len(xs))
    np.add.at(area, i[q["pair"]], q["weight"])
    np.testing.assert_allclose(area, fem.face_nodal_areas("quad", xs, n_gauss=8).sum(axis=1), rtol=1e-11)
    exact = radius * 0.9 * 0.6
    dtheta = 0.9 / 9 * 1.5                          # the sheared faces' largest angular span
    assert abs(area.sum() - exact) < dtheta ** 2 / 12 * exact
    Nt, _ = fem.SHAPE[tt](q["xi_t"])
    on_t = np.einsum("qv,qvi->qi", Nt, xt[j[q["pair"]]])
    gap = np.linalg.norm(on_t - q["x"], axis=1)
    assert gap.max() <= 1.1 * dev
    assert gap.max() > 0.1 * dev                    # the meshes do differ: the test measures something
    r = np.hypot(on_t[:, 0], on_t[:, 1])
    assert (r <= radius + 1e-14).all() and (r >= radius - deviation(tt, xt, radius) - 1e-14).all()


def test_touching_and_separate_faces_give_no_points():
    """Faces sharing only an edge or a vertex, apart in the plane, overlapping by less than area_tol, or seen edge-on
    shall give no points; neither shall T faces turned the same way as S when max_normal_dot asks for opposing faces."""
    sq = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    R = rotation(4)
    xt = np.array([sq + [1, 0, 0], sq + [1, 1, 0], sq + [0, -1, 0.01], sq + [2, 0, 0],
                   sq + [1 - 1e-14, 0.5, 0]])                         # a sliver below area_tol
    xs = np.repeat(sq[None], len(xt), axis=0)
    q = segment_quadrature("quad", xs @ R.T, "quad", xt @ R.T)
    assert len(q["pair"]) == 0
    edge_on = np.array([[[0.2, 0.5, -0.3], [0.8, 0.5, -0.3], [0.8, 0.5, 0.3], [0.2, 0.5, 0.3]]])
    assert len(segment_quadrature("quad", sq[None], "quad", edge_on)["pair"]) == 0
    tri = np.array([[[0.1, 0.1, 0.2], [0.9, 0.1, 0.2], [0.1, 0.9, 0.2]]])
    same_way = segment_quadrature("quad", sq[None], "tri", tri, max_normal_dot=-0.1)
    assert len(same_way["pair"]) == 0
    opposing = segment_quadrature("quad", sq[None], "tri", tri[:, ::-1], max_normal_dot=-0.1)
    assert abs(opposing["weight"].sum() - 0.32) < 1e-15
    assert len(segment_quadrature("quad", np.zeros((0, 4, 3)), "tri", np.zeros((0, 3, 3)))["pair"]) == 0


def test_bad_s_face_and_shapes_are_errors():
    """A non-convex S quad shall raise MeshError naming its pair; mismatched arrays a ValueError."""
    good = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    dart = np.array([[0, 0, 0], [1, 0, 0], [0.3, 0.3, 0], [0, 1, 0]], float)
    with pytest.raises(MeshError, match="pair 1"):
        segment_quadrature("quad", np.array([good, dart]), "quad", np.array([good, good]))
    with pytest.raises(ValueError, match="xt"):
        segment_quadrature("quad", good[None], "tri", good[None])


@pytest.mark.parametrize("split", [1, 8])
def test_inverse_bilinear_map_of_distorted_quads(split):
    """Newton shall recover the natural coordinates of points of strongly distorted quads to 1e-13, whether the
    stragglers are split off early or late, and an affine map (triangle) shall be inverted directly."""
    rng = np.random.default_rng(8)
    t = 3000
    P = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float)[None] + 0.45 * rng.uniform(-1, 1, (t, 4, 2))
    xi = rng.uniform(-0.999, 0.999, (t, 6, 2))
    N, _ = fem.SHAPE["quad"](xi.reshape(-1, 2))
    p = np.einsum("qv,qvd->qd", N, np.repeat(P, 6, axis=0)).reshape(t, 6, 2)
    got = _inverse_map(_monomials("quad") @ P, p, "S", split=split)
    assert np.abs(got - xi).max() < 1e-13
    tri = P[:, :3]
    eta = rng.uniform(0, 0.5, (t, 6, 2))
    N, _ = fem.SHAPE["tri"](eta.reshape(-1, 2))
    p = np.einsum("qv,qvd->qd", N, np.repeat(tri, 6, axis=0)).reshape(t, 6, 2)
    assert np.abs(_inverse_map(_monomials("tri") @ tri, p, "T") - eta).max() < 1e-13


@pytest.mark.parametrize("degree", range(13))
def test_triangle_rules_are_exact_to_their_degree(degree):
    """triangle_rule(d) shall integrate every monomial xi^i eta^j, i + j <= d, exactly, with positive weights
    (Dunavant's tabulated degree 6 and 8 rules carry 15 digits), and be symmetric in the three vertices: the same
    points and weights whatever the order of the barycentric coordinates."""
    b, w = triangle_rule(degree)
    assert (w > 0).all() and (b >= 0).all() and abs(w.sum() - 1) < 1e-15
    for i in range(degree + 1):
        for j in range(degree + 1 - i):
            exact = factorial(i) * factorial(j) / factorial(i + j + 2)
            assert abs(0.5 * np.sum(w * b[:, 1] ** i * b[:, 2] ** j) - exact) < 5e-15
    key = np.round(np.column_stack([b, w]), 12)
    for perm in ([1, 0, 2], [0, 2, 1], [2, 0, 1]):
        permuted = np.round(np.column_stack([b[:, perm], w]), 12)
        np.testing.assert_array_equal(np.unique(permuted, axis=0), np.unique(key, axis=0))


def brute_force_pairs(xs, xt, distance):
    lo_s, hi_s = xs.min(axis=1) - distance, xs.max(axis=1) + distance
    lo_t, hi_t = xt.min(axis=1), xt.max(axis=1)
    hit = ((lo_s[:, None] <= hi_t[None]) & (lo_t[None] <= hi_s[:, None])).all(axis=2)
    return np.nonzero(hit)


@pytest.mark.parametrize("distance", [0.0, 0.03, 0.5])
def test_candidate_pairs_equal_brute_force(distance):
    """candidate_pairs shall list exactly the pairs of the m x n box test, sorted, once each, for faces of mixed sizes."""
    rng = np.random.default_rng(int(distance * 100))
    size_s = np.where(rng.random(400) < 0.05, 0.5, 0.05)[:, None, None]
    size_t = np.where(rng.random(300) < 0.05, 0.8, 0.08)[:, None, None]
    xs = rng.uniform(0, 2, (400, 1, 3)) + size_s * rng.uniform(-1, 1, (400, 4, 3))
    xt = rng.uniform(0.5, 3, (300, 1, 3)) + size_t * rng.uniform(-1, 1, (300, 3, 3))
    xt[:100, :, 2] = 1.0                                     # flat faces: boxes of zero thickness
    i, j = candidate_pairs(xs, xt, distance)
    bi, bj = brute_force_pairs(xs, xt, distance)
    assert len(bi) > 0
    np.testing.assert_array_equal(i, bi)
    np.testing.assert_array_equal(j, bj)
    assert candidate_pairs(xs[:0], xt, distance)[0].shape == (0,)
    assert len(candidate_pairs(xs, xt + 10.0, distance)[0]) == 0
