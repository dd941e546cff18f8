"""Gauss-point and segment quadratures of a contact pass (formulation.md section 8): rows are exact derivatives,
weights integrate the right areas, and the rules converge to exact integration."""

from math import factorial

import numpy as np
import pytest
from test_contact_kernels import Surface, away_from_kinks, check_derivatives, dense, flat, make_pass, pair, response

from qsc_petsc import fem
from qsc_petsc.contact import quadrature
from qsc_petsc.contact.rows import master_slave, quasi_symmetric, quasi_symmetric_master_nodes, two_pass, weights
from qsc_petsc.contact.search import closest_faces

RULES = {
    "master_slave": lambda sp, mp: master_slave(sp),
    "two_pass": two_pass,
    "quasi_symmetric_0.5": lambda sp, mp: quasi_symmetric(sp, mp, 0.5),
    "quasi_symmetric_power2": lambda sp, mp: quasi_symmetric(sp, mp, {"power": 2.0}),
}


def gauss_pass(S, T, n, radius=0.2):
    xf = S.xyz[S.faces]
    pts = quadrature.gauss_points(S.type, xf, xf, S.gfaces, n)
    found = closest_faces(pts["x_cur"], T.xyz[T.faces], T.type, np.sort(T.gfaces, axis=1), radius)
    return quadrature.found_pass(pts, found, T.gfaces, T.xyz[T.faces], T.face_size)


@pytest.mark.parametrize("mesh", [(3, "quad", 4, "quad"), (4, "tri", 3, "tri")])
@pytest.mark.parametrize("name", RULES)
def test_gauss_rows_force_and_jacobian_are_derivatives(name, mesh):
    """Gauss-point rows on a warped interface: G^T m shall be the energy gradient and G^T D G its Hessian."""
    A, B, ndof = pair(*mesh)
    rows = RULES[name](gauss_pass(A, B, 2), gauss_pass(B, A, 2))
    u = away_from_kinks(rows, ndof, 0.01, seed=3)
    check_derivatives(rows, ndof, u)


@pytest.mark.parametrize("face_type", ["quad", "tri"])
def test_gauss_weights_integrate_the_area_and_shape_functions(face_type):
    """Gauss weights shall sum to the S area and sum_q N_S^k w_q (the row weights W) to the nodal areas."""
    A, B, ndof = pair(3, face_type, 5, face_type)          # warped: the weights include the surface Jacobian
    sp = gauss_pass(A, B, 2)                                # the fixture's nodal areas use the same 2 x 2 rule
    assert len(sp.node) == len(A.faces) * len(fem.contact_face_rule(face_type, 2)[1])
    nodal = np.zeros(len(A.ids))
    np.add.at(nodal, sp.source_nodes.ravel() - A.ids[0], (sp.source_shape * sp.area[:, None]).ravel())
    np.testing.assert_allclose(nodal, A.area, rtol=1e-12)
    rows = master_slave(sp)
    W = np.zeros(ndof)
    np.add.at(W, rows.W_rows, rows.W_vals)
    np.testing.assert_allclose(W[3 * A.ids], A.area, rtol=1e-12)


@pytest.mark.parametrize("n", range(1, 7))
def test_gauss_points_of_a_triangle_do_not_depend_on_its_vertex_order(n):
    """A triangle's contact Gauss points (gauss_points = n) shall be the same physical points with the same weights
    whatever the order its vertices are listed in (a mirror image lists them otherwise: the collapsed n x n rule
    made a symmetric punch on tets asymmetric), at least n^2 of them, exact to degree 2n - 2 as on quads."""
    tri = np.array([[0.1, 0.0, 0.2], [1.3, 0.2, 0.0], [0.4, 0.9, 0.3]])
    ids = np.array([7, 8, 9])

    def points(order):
        pts = quadrature.gauss_points("tri", tri[order][None], tri[order][None], ids[order][None], n)
        return np.unique(np.round(np.column_stack([pts["x_ref"], pts["weight"]]), 12), axis=0)

    first = points([0, 1, 2])
    assert len(first) >= n * n
    for order in ([1, 0, 2], [0, 2, 1], [2, 0, 1], [2, 1, 0]):
        np.testing.assert_array_equal(points(order), first)
    xi, w = fem.contact_face_rule("tri", n)
    degree = 1 if n == 1 else 2 * n - 2
    for i in range(degree + 1):
        for j in range(degree + 1 - i):
            exact = factorial(i) * factorial(j) / factorial(i + j + 2)
            assert np.sum(w * xi[:, 0] ** i * xi[:, 1] ** j) == pytest.approx(exact, rel=1e-13, abs=1e-16)


def test_matching_meshes_gauss_equals_nodal_mean():
    """On matching flat meshes in contact, Gauss rows shall give the same total W and force as nodal rows."""
    A, B, ndof = pair(4, "quad", 4, "quad", zfun=flat, gap=0.0)
    u = np.zeros(ndof)
    u[3 * B.ids + 2] = -1e-3                                # B pushed into A uniformly
    for name, build in RULES.items():
        en, Fn, _, _ = response(build(make_pass(A, B), make_pass(B, A)), ndof, u)
        eg, Fg, _, _ = response(build(gauss_pass(A, B, 3), gauss_pass(B, A, 3)), ndof, u)
        assert eg == pytest.approx(en, rel=1e-12), name
        assert Fg[3 * B.ids + 2].sum() == pytest.approx(Fn[3 * B.ids + 2].sum(), rel=1e-12), name


def mortar_matrix(S, T, rows):
    """The matrix M[k, j] = coefficient of u_T^j . n in row k (the discrete int N_S^k N_T^j ds) of master_slave rows."""
    G, _, _, r, _ = dense(rows, 3 * (len(S.ids) + len(T.ids)))
    return G[:, 3 * T.ids + 2], r


def test_gauss_mortar_integrals_converge_to_exact():
    """On flat non-nested meshes, sum_q w_q N_S^k N_T^j shall converge to int N_S^k N_T^j ds as n grows."""
    A, B, _ = pair(3, "quad", 7, "quad", zfun=flat)
    ref, _ = mortar_matrix(A, B, master_slave(gauss_pass(A, B, 10)))        # 100 points per face
    errs = [np.abs(mortar_matrix(A, B, master_slave(gauss_pass(A, B, n)))[0] - ref).max() for n in (2, 3, 5)]
    assert errs[0] > errs[1] > errs[2]
    # nodal quadrature is the crudest: lumping onto the S node
    nodal, _ = mortar_matrix(A, B, master_slave(make_pass(A, B)))
    assert np.abs(nodal - ref).max() > errs[0]


def test_power_weight_rule():
    """{power: p} shall give w_a = h_b^p / (h_a^p + h_b^p), "finer" p = 4, and be swap-symmetric."""
    np.testing.assert_allclose(weights({"power": 2.0}, 1.0, 2.0), 4.0 / 5.0)
    np.testing.assert_allclose(weights("finer", [0.5, 3.0], [1.0, 1.0]), weights({"power": 4.0}, [0.5, 3.0], [1, 1]))
    h = np.array([0.1, 1.0, 7.0])
    np.testing.assert_allclose(weights({"power": 30.0}, h, h[::-1]) + weights({"power": 30.0}, h[::-1], h), 1.0)
    assert np.isfinite(weights({"power": 500.0}, 1e-3, 1e3)).all()
    with pytest.raises(ValueError):
        weights({"power": -1.0}, 1.0, 1.0)
    with pytest.raises(ValueError):
        weights("coarser", 1.0, 1.0)


@pytest.mark.parametrize("weight", [0.5, "finer"])
def test_master_node_variant_equals_paper_rows_with_nodal_quadrature(weight):
    """With nodal quadrature, the master-node multiplier variant shall give exactly quasi_symmetric's rows."""
    A, B, ndof = pair(3, "quad", 4, "tri")
    sp, mp = make_pass(A, B), make_pass(B, A)
    G1, g1, W1, r1, _ = dense(quasi_symmetric(sp, mp, weight), ndof)
    G2, g2, W2, r2, _ = dense(quasi_symmetric_master_nodes(sp, mp, mp, weight), ndof)
    np.testing.assert_array_equal(r1, r2)
    np.testing.assert_allclose(G2, G1, atol=1e-15)
    np.testing.assert_allclose(g2, g1, atol=1e-15)
    np.testing.assert_allclose(W2, W1, rtol=1e-14)


@pytest.mark.parametrize("mesh", [(3, "quad", 4, "quad"), (4, "tri", 3, "quad")])
def test_master_node_variant_with_gauss_points_is_consistent(mesh):
    """Gauss-point master-node variant on a warped interface: exact derivatives, rows only on slave nodes,
    and sum phi W = the contact area on a flat interface."""
    A, B, ndof = pair(*mesh)
    rows = quasi_symmetric_master_nodes(gauss_pass(A, B, 2), gauss_pass(B, A, 2), make_pass(B, A), {"power": 4.0})
    assert set(np.unique(rows.W_rows) // 3) <= set(A.ids)
    check_derivatives(rows, ndof, away_from_kinks(rows, ndof, 0.01, seed=4))
    A, B, _ = pair(*mesh, zfun=flat)
    rows = quasi_symmetric_master_nodes(gauss_pass(A, B, 3), gauss_pass(B, A, 3), make_pass(B, A), 0.5)
    assert rows.phi * rows.W_vals.sum() == pytest.approx(1.0, rel=1e-12)


def segment(S, T, radius=0.2):
    xs, xt = S.xyz[S.faces], T.xyz[T.faces]
    return quadrature.segment_pass((S.type, T.type), xs, xs, S.gfaces, xt, xt, T.gfaces, T.face_size, radius)


@pytest.mark.parametrize("mesh", [(3, "quad", 4, "quad"), (4, "tri", 3, "quad")])
@pytest.mark.parametrize("name", RULES)
def test_segment_rows_force_and_jacobian_are_derivatives(name, mesh):
    """Segment rows on a warped interface: G^T m shall be the energy gradient and G^T D G its Hessian."""
    A, B, ndof = pair(*mesh)
    rows = RULES[name](segment(A, B), segment(B, A))
    check_derivatives(rows, ndof, away_from_kinks(rows, ndof, 0.01, seed=6))


@pytest.mark.parametrize("face_type", ["quad", "tri"])
def test_segment_pass_takes_no_face_turned_away(face_type):
    """A thin body's whole skin as the T surface: its far side, within reach and turned away from S, shall add
    no point (it read the thickness as penetration); the pass equals the one against the near side alone."""
    S = Surface(3, face_type, flat, 0, down=True)                         # z = 0, facing down
    near = Surface(4, face_type, flat, len(S.ids), offset=0.0)            # z = 0, facing up: in contact
    far = Surface(4, face_type, flat, len(S.ids) + len(near.ids), down=True, offset=-0.1)   # z = -0.1, down

    class Skin:
        type, xyz = face_type, np.concatenate([near.xyz, far.xyz])
        faces = np.concatenate([near.faces, far.faces + len(near.xyz)])
        gfaces = np.concatenate([near.gfaces, far.gfaces])
        face_size = np.concatenate([near.face_size, far.face_size])

    alone, skin = segment(S, near), segment(S, Skin)
    assert len(alone.node) > 0
    for name in ("node", "area", "target_nodes", "shape", "normal", "delta0"):
        np.testing.assert_array_equal(getattr(skin, name), getattr(alone, name), err_msg=name)


@pytest.mark.parametrize("face_type", ["quad", "tri"])
def test_segment_mortar_integrals_are_exact_on_flat_meshes(face_type):
    """On flat non-nested meshes segment integration gives the limit of the Gauss rules: int N_S^k N_T^j ds,
    and W = the nodal areas of S."""
    A, B, ndof = pair(3, face_type, 7, face_type, zfun=flat)
    sp = segment(A, B)
    seg, _ = mortar_matrix(A, B, master_slave(sp))
    fine, _ = mortar_matrix(A, B, master_slave(gauss_pass(A, B, 10)))
    coarse, _ = mortar_matrix(A, B, master_slave(gauss_pass(A, B, 5)))
    assert np.abs(seg - fine).max() < np.abs(coarse - fine).max()       # closer to the limit than 5x5 Gauss
    W = np.zeros(ndof)
    rows = master_slave(sp)
    np.add.at(W, rows.W_rows, rows.W_vals)
    np.testing.assert_allclose(W[3 * A.ids], A.area, rtol=1e-12)
