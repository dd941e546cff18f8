"""Tests of the linear elasticity element kernels: energy derivatives, rigid modes, patch tests, fast path."""

import warnings

import numpy as np
import pytest

from qsc_petsc import elasticity as el
from qsc_petsc import fem
from qsc_petsc.errors import MeshError

E, NU = 210e9, 0.3                     # Pa, -
LMBDA, MU = el.lame(E, NU)
HEX_REF = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                    [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]])  # unit cube in VTK order
TET_REF = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])


def _rotation(rng):
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q *= np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def distorted_cells(cell_type, m, seed=0):
    """m randomly distorted, rotated, scaled (mm-sized) and shifted cells with positive volume."""
    rng = np.random.default_rng(seed)
    ref = HEX_REF if cell_type == "hex" else TET_REF
    x = ref[None] + 0.15 * rng.uniform(-1, 1, (m,) + ref.shape)
    x = np.einsum("mai,mji->maj", x, np.stack([_rotation(rng) for _ in range(m)]))
    return 1e-3 * (x * rng.uniform(0.5, 2.0, (m, 1, 1)) + rng.uniform(-5, 5, (m, 1, 3)))


def affine_displacement(xe, A, c=None):
    """Nodal displacements (m, 3n) of u(x) = A x + c."""
    u = xe @ A.T + (0.0 if c is None else c)
    return u.reshape(len(xe), -1)


def voigt_strain(A):
    eps = 0.5 * (A + A.T)
    return np.array([eps[0, 0], eps[1, 1], eps[2, 2], 2 * eps[1, 2], 2 * eps[0, 2], 2 * eps[0, 1]])


def test_lame_and_uniaxial_compliance():
    D = el.elasticity_matrix(LMBDA, MU)
    eps = np.linalg.solve(D, [1e6, 0, 0, 0, 0, 0])
    assert eps[0] == pytest.approx(1e6 / E)
    assert eps[1] == pytest.approx(-NU * 1e6 / E) and eps[2] == pytest.approx(-NU * 1e6 / E)
    assert np.allclose(eps[3:], 0.0)


@pytest.mark.parametrize("cell_type", ["hex", "tet"])
def test_stiffness_is_hessian_of_strain_energy(cell_type):
    xe = distorted_cells(cell_type, 2, seed=1)
    nd = 3 * xe.shape[1]
    K = el.stiffness(cell_type, xe, LMBDA, MU)
    rng = np.random.default_rng(2)
    u0 = 1e-6 * rng.standard_normal((2, nd))
    h = 1e-6
    # central second differences are exact for a quadratic energy up to round-off
    e = h * np.eye(nd)
    for c in range(2):
        up = u0[c] + e[:, None, :] + e[None, :, :]
        um = u0[c] - e[:, None, :] - e[None, :, :]
        pm = u0[c] + e[:, None, :] - e[None, :, :]
        mp = u0[c] - e[:, None, :] + e[None, :, :]
        u = np.concatenate([a.reshape(-1, nd) for a in (up, um, pm, mp)])
        W = el.strain_energy(cell_type, np.repeat(xe[c:c + 1], len(u), axis=0), u, LMBDA, MU)
        W = W.reshape(4, nd, nd)
        K_fd = (W[0] + W[1] - W[2] - W[3]) / (4 * h * h)
        assert np.allclose(K[c], K_fd, rtol=1e-5, atol=1e-6 * np.abs(K[c]).max())


@pytest.mark.parametrize("cell_type", ["hex", "tet"])
def test_stiffness_symmetric_with_rigid_body_kernel(cell_type):
    xe = distorted_cells(cell_type, 5, seed=3)
    K = el.stiffness(cell_type, xe, LMBDA, MU)
    scale = np.abs(K).max(axis=(1, 2))[:, None]
    assert np.allclose(K, K.transpose(0, 2, 1), atol=1e-13 * scale.max())
    rng = np.random.default_rng(4)
    for _ in range(3):
        omega, c = rng.standard_normal(3), rng.standard_normal(3)
        W = np.array([[0, -omega[2], omega[1]], [omega[2], 0, -omega[0]], [-omega[1], omega[0], 0]])
        r = affine_displacement(xe, W, c)                  # u = omega x x + c
        f = np.einsum("mab,mb->ma", K, r)
        assert np.abs(f).max(axis=1) == pytest.approx(0.0, abs=1e-12 * scale.max())
    # exactly six zero eigenvalues per cell
    ev = np.linalg.eigvalsh(K) / scale
    assert ((np.abs(ev) < 1e-10).sum(axis=1) == 6).all()


@pytest.mark.parametrize("cell_type", ["hex", "tet"])
def test_cell_stress_is_d_b_u_at_the_centroid(cell_type):
    """cell_stress (from the displacement gradient) shall equal D B u at the reference centroid for any nodal
    displacements and per-cell Lame parameters, in one chunk or several."""
    xe = distorted_cells(cell_type, 7, seed=8)
    rng = np.random.default_rng(9)
    ue = rng.standard_normal((7, 3 * xe.shape[1]))
    lmbda, mu = LMBDA * rng.uniform(0.5, 2.0, 7), MU * rng.uniform(0.5, 2.0, 7)
    B, _ = el.strain_displacement(cell_type, xe, fem.CENTROID[cell_type])
    expected = (el.elasticity_matrix(lmbda, mu) @ (B[:, 0] @ ue[..., None]))[..., 0]
    for chunk in (16384, 3):
        got = el.cell_stress(cell_type, xe, ue, lmbda, mu, chunk=chunk)
        assert np.abs(got - expected).max() <= 1e-12 * np.abs(expected).max()


@pytest.mark.parametrize("cell_type", ["hex", "tet"])
def test_uniform_strain_gives_exact_stress(cell_type):
    xe = distorted_cells(cell_type, 6, seed=5)
    rng = np.random.default_rng(6)
    A = 1e-3 * rng.standard_normal((3, 3))
    ue = affine_displacement(xe, A, rng.standard_normal(3))
    eps = voigt_strain(A)
    sigma = el.elasticity_matrix(LMBDA, MU) @ eps
    assert np.allclose(el.cell_stress(cell_type, xe, ue, LMBDA, MU), sigma, rtol=1e-9, atol=1e-9 * abs(sigma).max())
    xi, w = el.QUADRATURE[cell_type]
    B, detJ = el.strain_displacement(cell_type, xe, xi)
    assert np.allclose(B @ ue[:, None, :, None], eps[:, None], atol=1e-12)
    volume = detJ @ w
    assert np.allclose(el.strain_energy(cell_type, xe, ue, LMBDA, MU), 0.5 * eps @ sigma * volume, rtol=1e-10)


@pytest.mark.parametrize("cell_type", ["hex", "tet"])
def test_fast_path_equals_general_path(cell_type):
    rng = np.random.default_rng(7)
    shapes = distorted_cells(cell_type, 3, seed=8)
    which = rng.integers(0, 3, 200)
    xe = shapes[which] + rng.uniform(-1, 1, (200, 1, 3))          # translates of 3 shapes
    lmbda = np.where(rng.random(200) < 0.5, LMBDA, 2 * LMBDA)   # two materials
    first, _ = el.congruent_groups(xe, lmbda, np.full(200, MU))
    assert len(first) < 20      # round-off may split a shape in two bins, never merge two shapes
    K_fast = el.stiffness(cell_type, xe, lmbda, MU)
    K_gen = el.stiffness(cell_type, xe, lmbda, MU, share_translates=False)
    assert np.allclose(K_fast, K_gen, rtol=1e-9, atol=1e-9 * np.abs(K_gen).max())


def test_congruent_groups_detects_and_never_merges():
    """Translates of one cell shall share a group; a scaled, rotated or re-materialled copy never."""
    xe = np.rint(distorted_cells("hex", 1, seed=11)[0] * 2**30) / 2**30    # dyadic: translates stay exact

    theta = 1e-6
    rot = np.array([[np.cos(theta), -np.sin(theta), 0], [np.sin(theta), np.cos(theta), 0], [0, 0, 1]])
    cells = np.array([xe, xe + [5.0, -2.0, 7.0], xe + [1024.0, 0, 0], xe * (1 + 1e-9), xe @ rot.T, xe])
    lmbda = np.array([LMBDA] * 5 + [2 * LMBDA])
    _, group = el.congruent_groups(cells, lmbda, np.full(6, MU))
    assert group[0] == group[1] == group[2]
    assert len(set(group[[0, 3, 4, 5]])) == 4
    x = np.linspace(0.0, 1.0, 21)                                    # a box of 20^3 hexes: one shape
    grid = np.stack(np.meshgrid(x, x, x, indexing="ij"), -1)
    corners = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
    box = np.stack([grid[i:i + 20, j:j + 20, k:k + 20] for i, j, k in corners], 3).reshape(-1, 8, 3)
    first, group = el.congruent_groups(box, LMBDA, MU)
    assert len(first) <= 8                          # round-off of the grid may split the shape, rarely
    K = el.stiffness("hex", box, LMBDA, MU, share_translates=False)
    assert np.allclose(K, K[first[group]], rtol=0, atol=1e-12 * np.abs(K).max())


@pytest.mark.parametrize("cell_type", ["hex", "tet"])
@pytest.mark.parametrize("share", [True, False])
def test_inverted_cell_raises(cell_type, share):
    xe = np.repeat(distorted_cells(cell_type, 1, seed=9), 5, axis=0) + np.arange(5)[:, None, None]
    xe[3] = xe[3][[1, 0] + list(range(2, xe.shape[1]))] if cell_type == "tet" else xe[3][[4, 5, 6, 7, 0, 1, 2, 3]]
    with pytest.raises(MeshError, match=f"{cell_type} cell 3 "):
        el.stiffness(cell_type, xe, LMBDA, MU, share_translates=share)


def test_flat_cell_raises_whatever_the_sign_of_its_round_off():
    """A hex flattened onto its bottom face (0.25 x 1/3 at z = 0.6: det J = +4.5e-19, round-off) and a tet with a
    vertex moved onto its opposite face shall raise MeshError, as a hex collapsed to a point shall (without a NumPy
    warning first); a cell stretched 1000:1 shall not."""
    hexa = np.array([[0, 0], [0.25, 0], [0.25, 1 / 3], [0, 1 / 3]] * 2)
    flat = np.column_stack([hexa, np.full(8, 0.6)])[None]
    with pytest.raises(MeshError, match="hex cell 0 is inverted or degenerate"):
        el.stiffness("hex", flat, LMBDA, MU)
    tet = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.3, 0.3, 0]]], float)
    with pytest.raises(MeshError, match="tet cell 0 is inverted or degenerate"):
        el.stiffness("tet", tet, LMBDA, MU)
    with warnings.catch_warnings():                  # a cell collapsed to a point: the error, not a NumPy warning
        warnings.simplefilter("error")
        with pytest.raises(MeshError, match="hex cell 0 is inverted or degenerate"):
            el.stiffness("hex", np.ones((1, 8, 3)), LMBDA, MU)
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]] * 2, float)
    long = np.column_stack([1000.0 * square[:, 0], square[:, 1], np.repeat([0.0, 1.0], 4)])[None]
    K = el.stiffness("hex", long, LMBDA, MU)
    assert np.isfinite(K).all() and np.allclose(K @ np.tile([1.0, 0, 0], 8), 0, atol=1e-9 * np.abs(K).max())


def test_von_mises():
    s = np.array([[-3e6, 0, 0, 0, 0, 0], [0, 0, 2e6, 0, 0, 0], [1e6, 1e6, 1e6, 0, 0, 0], [0, 0, 0, 0, 0, 1e6]])
    assert np.allclose(el.von_mises(s), [3e6, 2e6, 0.0, np.sqrt(3) * 1e6])


@pytest.mark.parametrize("cell_type", ["hex", "tet"])
def test_rigid_motions_strain_nothing(cell_type):
    """The six rigid motions are unit translations and unit-rate rotations e_axis x r about the given centre, in
    RIGID_MODES' order, and a distorted cell's stiffness takes none of them to any force."""
    r = np.array([[0.0, 0.0, 0.0], [0.5, -1.0, 1.5]])
    v = el.rigid_motions(r)
    assert np.array_equal(v[:3], np.broadcast_to(np.eye(3)[:, None, :], (3, 2, 3)))
    assert np.allclose(v[3:, 0], 0.0)                                 # the centre does not move in rotation
    for axis, name in enumerate(("x", "y", "z")):
        assert el.RIGID_MODES[3 + axis] == f"rotation about {name}"
        assert np.allclose(v[3 + axis, 1], np.cross(np.eye(3)[axis], r[1]))
    xe = distorted_cells(cell_type, 3, seed=5)
    K = el.stiffness(cell_type, xe, LMBDA, MU)
    for m in range(len(xe)):
        u = el.rigid_motions(xe[m] - [0.3, -0.2, 0.7]).reshape(6, -1)
        assert np.abs(K[m] @ u.T).max() <= 1e-12 * np.abs(K[m]).max()


# ---------------------------------------------------------------- mean dilatation (B-bar)

def test_mean_dilatation_keeps_the_patch_test_and_the_rigid_modes():
    """B-bar changes nothing where the strain is uniform (the patch test: energy and stress as full integration),
    keeps K symmetric with exactly the six rigid modes in its kernel, and shares translates as the full kernel does."""
    xe = distorted_cells("hex", 6, seed=11)
    kappa = LMBDA + 2.0 * MU / 3.0
    K_full, K_mean = el.stiffness("hex", xe, LMBDA, MU), el.stiffness("hex", xe, LMBDA, MU, kappa=kappa)
    rng = np.random.default_rng(12)
    A = 1e-3 * rng.standard_normal((3, 3))
    ue = affine_displacement(xe, A)     # no translation: its round-off in K u would be 1e-5 of the strain's energy
    energy = [np.einsum("ma,mab,mb->m", ue, K, ue) for K in (K_full, K_mean)]
    assert np.allclose(energy[1], energy[0], rtol=1e-10)
    assert np.allclose(el.cell_stress("hex", xe, ue, LMBDA, MU, kappa=kappa), el.cell_stress("hex", xe, ue, LMBDA, MU),
                       rtol=1e-9, atol=1e-9 * np.abs(el.cell_stress("hex", xe, ue, LMBDA, MU)).max())
    scale = np.abs(K_mean).max()
    assert np.allclose(K_mean, K_mean.transpose(0, 2, 1), atol=1e-13 * scale)
    assert ((np.abs(np.linalg.eigvalsh(K_mean) / scale) < 1e-10).sum(axis=1) == 6).all()
    translates = np.concatenate([xe[:1], xe[:1] + 1e-3])
    assert np.allclose(el.stiffness("hex", translates, LMBDA, MU, kappa=kappa),
                       el.stiffness("hex", translates, LMBDA, MU, kappa=kappa, share_translates=False), rtol=1e-12)


def test_mean_dilatation_does_not_lock():
    """A hex bent in its plane, u = (x z, 0, -x^2 / 2) about its centre: its divergence z averages to 0 over the cell.
    Fully integrated, its energy grows with the bulk modulus as nu nears 0.5 (volumetric locking); with the cell's
    mean dilatation it stays the shear energy, and the stress's pressure part is the mean dilatation's (0)."""
    xe = (HEX_REF - 0.5)[None]
    x, z = xe[0, :, 0], xe[0, :, 2]
    ue = np.stack([x * z, 0 * x, -0.5 * x**2], axis=1).reshape(1, -1)
    energies = {}
    for nu in (0.3, 0.49, 0.4999):
        lmbda, mu = el.lame(1.0, nu)
        kappa = lmbda + 2.0 * mu / 3.0
        for name, k in (("full", None), ("mean", kappa)):
            K = el.stiffness("hex", xe, lmbda, mu, kappa=k)[0]
            energies[name, nu] = 0.5 * ue[0] @ K @ ue[0]
        sigma = el.cell_stress("hex", xe, ue, lmbda, mu, kappa=kappa)[0]
        assert abs(sigma[:3].sum()) <= 1e-12 * np.abs(sigma).max(initial=1.0)
    assert energies["full", 0.4999] > 100 * energies["full", 0.3]
    assert energies["mean", 0.4999] < 1.5 * energies["mean", 0.3]
