"""Small-strain isotropic linear elasticity kernels: B matrices, stiffness, energy and stress of hex and tet cells.

Pure NumPy. Dofs within a cell are node-major (node 0 x, y, z, node 1 x, y, z, ...), the
global interleaved layout. Voigt order is xx, yy, zz, yz, xz, xy with engineering shear
strains (gamma = 2 eps). Units follow the caller: coordinates in m and moduli in Pa give
stiffness in N/m, energy in J and stress in Pa.
"""

import numpy as np

from qsc_petsc import fem
from qsc_petsc.errors import MeshError

# 2x2x2 Gauss integrates the trilinear hex stiffness fully; one point is exact for linear tets.
# (fem.gauss_tet(1) is a collapsed rule whose weight is 1/8, not 1/6, so the tet rule is written here.)
QUADRATURE = {"hex": fem.gauss_hex(2), "tet": (fem.CENTROID["tet"][None, :], np.array([1.0 / 6.0]))}

# a cell whose det J is not above this fraction of its Jacobian's longest column cubed at a quadrature point is flat
# or inverted (an element stretched 1000:1 stands at 1e-6): a flattened hex's det J came out +4.5e-19 (round-off)
# and passed a plain det J <= 0 test
MIN_RELATIVE_DET = 1e-10

CHUNK = 2048  # cells per vectorised batch: temporaries stay in cache (~10 MB for hexes)

# _VOIGT[i, j, k] = 1 where strain component i gets d u_j / d x_k
_VOIGT = np.zeros((6, 3, 3))
for _i, (_j, _k) in enumerate([(0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1)]):
    _VOIGT[_i, _j, _k] = _VOIGT[_i, _k, _j] = 1.0
_VOIGT_OF_GRADIENT = _VOIGT.transpose(0, 2, 1).reshape(6, 9).T     # (9, 6): H.ravel() (H_kj = d u_j / d x_k) -> eps


# the rigid-body motions, the strain's null space, in the order every caller numbers them (near-nullspace, slip modes,
# the free-motion check and its messages)
RIGID_MODES = ("translation x", "translation y", "translation z", "rotation about x", "rotation about y",
               "rotation about z")


def write_rigid_motion(a, rows, k, r):
    """Rigid motion k (RIGID_MODES' order: unit translations, then unit-rate rotations e_axis x r) at points r (m, 3)
    taken from the rotations' centre into rows `rows` of a (n, 3), whose other entries it leaves."""
    if k < 3:
        a[rows, k] = 1.0
    else:
        # e_axis x r: two components of r, one negated (no products; np.cross took twice the time)
        i, j = (k - 2) % 3, (k - 1) % 3
        a[rows, i] = -r[:, j]
        a[rows, j] = r[:, i]


def rigid_motions(r):
    """The six rigid motions (6, m, 3) at points r (m, 3) taken from the rotations' centre (RIGID_MODES' order)."""
    r = np.asarray(r, dtype=float).reshape(-1, 3)
    fields = np.zeros((6, len(r), 3))
    for k in range(6):
        write_rigid_motion(fields[k], slice(None), k, r)
    return fields


def lame(youngs_modulus, poissons_ratio):
    """Lame parameters (lmbda, mu) from Young's modulus E (Pa) and Poisson's ratio nu (-)."""
    E, nu = np.asarray(youngs_modulus, float), np.asarray(poissons_ratio, float)
    return E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), E / (2.0 * (1.0 + nu))


def mean_dilatation_bulk(youngs_modulus, poissons_ratio, volumetric):
    """The bulk modulus lmbda + 2 mu / 3 [Pa] a material takes with each cell's mean dilatation (its volumetric =
    "mean_dilatation": B-bar), else 0 (integrated fully)."""
    if volumetric != "mean_dilatation":
        return 0.0
    lmbda, mu = lame(youngs_modulus, poissons_ratio)
    return float(lmbda + 2.0 * mu / 3.0)


def elasticity_matrix(lmbda, mu):
    """Isotropic elasticity matrix D (..., 6, 6) in Voigt order, for scalar or (m,) Lame parameters."""
    lmbda, mu = np.asarray(lmbda, float)[..., None, None], np.asarray(mu, float)[..., None, None]
    one = np.zeros((6, 6))
    one[:3, :3] = 1.0
    return lmbda * one + mu * np.diag([2.0, 2.0, 2.0, 1.0, 1.0, 1.0])


class DegenerateCell(MeshError):
    """A cell whose Jacobian is not positive: .cell its id (the ids given, else its row), .detail what was found."""

    def __init__(self, cell_type, cell, detail):
        super().__init__(f"{cell_type} cell {cell} is inverted or degenerate: {detail}")
        self.cell, self.detail = cell, detail


def _jacobians(xe, dN):
    """The Jacobians of cells xe (m, n, 3) at the points of shape-function derivatives dN (nq, n, 3), in one GEMM,
    as 3x3 components of (m, nq) arrays (so that cofactors are plain vector arithmetic): J[i, k] = d x_i / d xi_k."""
    m, n = xe.shape[:2]
    nq = len(dN)
    J = xe.transpose(2, 0, 1).reshape(3 * m, n) @ dN.transpose(1, 2, 0).reshape(n, 3 * nq)
    return J.reshape(3, m, 3, nq).transpose(0, 2, 1, 3)


def _refuse_degenerate(cell_type, J, detJ, ids=None):
    """Raise DegenerateCell for the first cell whose det J (m, nq) is not above MIN_RELATIVE_DET of the cube of its
    Jacobian's (J: _jacobians) longest column at a point (1 for a cube, 0 flat, < 0 inverted: a flat cell's det J is
    round-off of either sign, so det J <= 0 alone lets some through), naming it ids[row] (default: row)."""
    longest = np.maximum.reduce([J[0, k] ** 2 + J[1, k] ** 2 + J[2, k] ** 2 for k in range(3)])
    with np.errstate(divide="ignore", invalid="ignore"):        # a cell collapsed to a point: NaN, caught below
        relative = detJ / longest ** 1.5
    bad = np.flatnonzero((~(relative > MIN_RELATIVE_DET)).any(axis=1))
    if len(bad):
        c = bad[0]
        raise DegenerateCell(cell_type, int(c if ids is None else ids[c]),
                             f"det J = {detJ[c].min():.3g} at a quadrature point, {relative[c].min():.3g} relative "
                             f"to the cell's size (not above {MIN_RELATIVE_DET:g})")


def _gradients(cell_type, xe, xi, ids=None, weights=None):
    """Physical shape-function gradients G (m, nq, n, 3) and det J (m, nq) at reference points xi (nq, 3).

    With quadrature weights (nq,), G is scaled by sqrt(w det J) so that sum_q G G^T is the
    integral int G G^T dV. Raises MeshError if det J is not positive beyond round-off (MIN_RELATIVE_DET), naming
    the cell ids[row] (default: row).
    """
    _, dN = fem.SHAPE[cell_type](xi)                               # (nq, n, 3) d N_a / d xi_k
    m, n = xe.shape[:2]
    nq = len(dN)
    J = _jacobians(xe, dN)
    cof = [[J[(i + 1) % 3, (k + 1) % 3] * J[(i + 2) % 3, (k + 2) % 3]
            - J[(i + 1) % 3, (k + 2) % 3] * J[(i + 2) % 3, (k + 1) % 3] for k in range(3)] for i in range(3)]
    detJ = J[0, 0] * cof[0][0] + J[0, 1] * cof[0][1] + J[0, 2] * cof[0][2]
    _refuse_degenerate(cell_type, J, detJ, ids)
    scale = 1.0 / detJ if weights is None else np.sqrt(weights / detJ)
    # G_ai = dN_ak (J^-1)_ki with J^-1 = cof^T / det J: one (n, 3) x (3, 3m) GEMM per quadrature point
    Jinv = (np.array(cof) * scale).transpose(3, 1, 2, 0).reshape(nq, 3, 3 * m)   # [q, k, (m, i)]
    G = (dN @ Jinv).reshape(nq, n, m, 3).transpose(2, 0, 1, 3)
    return np.ascontiguousarray(G), detJ


def check_cells(cell_type, coords, cells, ids, batch=20000):
    """Raise DegenerateCell for the first of cells (m, n) over coords whose det J is not above MIN_RELATIVE_DET of
    its Jacobian's longest column cubed at a quadrature point: the assembly's test (_gradients), without the
    gradients (0.33 s for 328k hexes on one core, 1.9 s through _gradients)."""
    _, dN = fem.SHAPE[cell_type](QUADRATURE[cell_type][0])
    for a in range(0, len(cells), batch):
        J = _jacobians(coords[cells[a:a + batch]], dN)
        det = (J[0, 0] * (J[1, 1] * J[2, 2] - J[1, 2] * J[2, 1]) - J[0, 1] * (J[1, 0] * J[2, 2] - J[1, 2] * J[2, 0])
               + J[0, 2] * (J[1, 0] * J[2, 1] - J[1, 1] * J[2, 0]))
        _refuse_degenerate(cell_type, J, det, ids[a:a + batch])


def strain_displacement(cell_type, xe, xi):
    """Strain-displacement matrices B (m, nq, 6, 3n), eps = B u_e, and det J (m, nq) at reference points xi (nq, 3)."""
    xe = np.asarray(xe, float)
    G, detJ = _gradients(cell_type, xe, np.atleast_2d(xi))
    m, nq, n, _ = G.shape
    B = np.einsum("ijk,mqak->mqiaj", _VOIGT, G, optimize=True)
    return B.reshape(m, nq, 6, 3 * n), detJ


def _stiffness_into(cell_type, xe, lmbda, mu, K, ids, kappa=None):
    """Write the stiffness of cells xe (c, n, 3) with Lame parameters lmbda, mu (c,) into K (c, 3n, 3n); kappa (c,) or
    None: the bulk modulus whose energy a cell takes with its mean dilatation (0: at every point, full integration).

    With G_ai = d N_a / d x_i and H_aibj = int G_ai G_bj dV, the isotropic stiffness is
    K_aibj = lmbda H_aibj + mu (H_ajbi + delta_ij H_akbk): one rank-nq product per cell, a
    sixth of the work of B^T D B.
    """
    xi, w = QUADRATURE[cell_type]
    Gw, detJ = _gradients(cell_type, xe, xi, ids, weights=w)
    c, nq, n, _ = Gw.shape
    Gw = Gw.reshape(c, nq, 3 * n)
    H = np.matmul(Gw.transpose(0, 2, 1), Gw)
    K_m = np.take(H.reshape(c, -1), _swap_ij(n), axis=1).reshape(H.shape)  # H_ajbi, a gather is the fastest transpose
    np.multiply(mu[:, None, None], K_m, out=K_m)
    np.multiply(lmbda[:, None, None], H, out=K)
    K += K_m
    trace = mu[:, None, None] * np.einsum("makbk->mab", H.reshape(c, n, 3, n, 3))
    K5 = K.reshape(c, n, 3, n, 3)
    for i in range(3):
        K5[:, :, i, :, i] += trace
    if kappa is not None and kappa.any():
        # mean dilatation (B-bar): the volumetric energy kappa (div u)^2 / 2 taken with the cell's mean div u, b u / V,
        # instead of at each point (H_aibj is the integral of d N_a/d x_i d N_b/d x_j: div u's own term)
        b, volume = _mean_divergence(Gw, detJ, w)
        K += (kappa / volume)[:, None, None] * (b[:, :, None] * b[:, None, :]) - kappa[:, None, None] * H


def _mean_divergence(Gw, detJ, w):
    """b (c, 3n), the integral of d N_a / d x_i over each cell (so that the cell's mean div u is b u / V), and V (c,),
    from the weighted gradients Gw (c, nq, 3n) = G sqrt(w det J) and det J (c, nq)."""
    root = np.sqrt(w * detJ)
    return np.einsum("cqk,cq->ck", Gw, root), (w * detJ).sum(axis=1)


def _swap_ij(n):
    """Flat indices taking H_aibj to H_ajbi in a (3n, 3n) matrix."""
    return np.arange(9 * n * n).reshape(n, 3, n, 3).transpose(0, 3, 2, 1).ravel()


def congruent_groups(xe, lmbda, mu, kappa=None):
    """Group cells (m, n, 3) that are translates of one another and have the same lmbda, mu (and kappa) (m,) [Pa].

    Returns (first, group): one representative cell per group and the group of every cell. Node
    offsets from node 0 are rounded to 2^-40 of the power of two just above the cell's extent,
    and that power is part of the key, so cells share a group only if their offsets agree to
    ~1e-12 of their size: round-off may split one shape over two groups, never merge two shapes.
    """
    m = len(xe)
    rel = (xe[:, 1:] - xe[:, :1]).reshape(m, 3 * (xe.shape[1] - 1))
    _, exponent = np.frexp(np.abs(rel).max(axis=1, initial=0.0))
    moduli = (lmbda, mu) if kappa is None else (lmbda, mu, kappa)
    keys = np.empty((m, rel.shape[1] + 1 + len(moduli)), np.int64)
    np.rint(rel / np.ldexp(1.0, exponent - 40)[:, None], out=rel)
    keys[:, :rel.shape[1]] = rel
    keys[:, rel.shape[1]] = exponent
    for j, p in enumerate(moduli, start=rel.shape[1] + 1):      # the bits: equal keys mean equal moduli
        keys[:, j] = np.ascontiguousarray(np.broadcast_to(np.asarray(p, float), (m,))).view(np.int64)
    # hash rows to one integer (wrapping multiply-add), then verify: a collision falls back to a row-wise unique
    mult = np.random.default_rng(12345).integers(1, 2**62, keys.shape[1], dtype=np.int64)
    _, first, group = np.unique(keys @ mult, return_index=True, return_inverse=True)
    if not (keys == keys[first[group]]).all():
        _, first, group = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    return first, group.reshape(-1)


def stiffness(cell_type, xe, lmbda, mu, share_translates=True, ids=None, kappa=None):
    """Element stiffness matrices (m, 3n, 3n) of cells with node coordinates xe (m, n, 3).

    lmbda, mu: Lame parameters (Pa), scalars or (m,); kappa: None, or the bulk modulus (Pa, scalar or (m,)) that a
    cell takes with its mean dilatation (B-bar; 0 for a cell integrated fully). Cells that are translates of one
    another (congruent_groups) with the same moduli share one computed K unless share_translates is False. Raises
    MeshError naming the first cell with det J <= 0: ids[row] (default: its row).
    """
    xe = np.asarray(xe, float)
    m, n = xe.shape[:2]
    lmbda, mu = (np.ascontiguousarray(np.broadcast_to(np.asarray(p, float), (m,))) for p in (lmbda, mu))
    if kappa is not None:
        kappa = np.ascontiguousarray(np.broadcast_to(np.asarray(kappa, float), (m,)))
    ids = np.arange(m) if ids is None else np.asarray(ids)
    K = np.empty((m, 3 * n, 3 * n))
    if share_translates and m > 1:
        first, group = congruent_groups(xe, lmbda, mu, kappa)
        if len(first) <= m // 2:
            K_distinct = np.empty((len(first),) + K.shape[1:])
            for s in range(0, len(first), CHUNK):
                c = first[s:s + CHUNK]
                _stiffness_into(cell_type, xe[c], lmbda[c], mu[c], K_distinct[s:s + CHUNK], ids[c],
                                None if kappa is None else kappa[c])
            return np.take(K_distinct, group, axis=0, out=K, mode="clip")  # "raise" would buffer out
    for s in range(0, m, CHUNK):
        c = np.arange(s, min(s + CHUNK, m))
        _stiffness_into(cell_type, xe[c], lmbda[c], mu[c], K[s:s + CHUNK], ids[c], None if kappa is None else kappa[c])
    return K


def mean_dilatation(cell_type, xe, ue):
    """Each cell's mean dilatation (m,): the integral of div u over the cell over its volume, for displacements ue
    (m, 3n) (the volumetric strain a mean-dilatation cell takes everywhere: _stiffness_into's kappa)."""
    xe = np.asarray(xe, float)
    xi, w = QUADRATURE[cell_type]
    Gw, detJ = _gradients(cell_type, xe, xi, weights=w)
    b, volume = _mean_divergence(Gw.reshape(len(xe), len(xi), -1), detJ, w)
    return np.einsum("ck,ck->c", b, np.asarray(ue, float)) / volume


def with_mean_dilatation(eps, theta):
    """Voigt strains (n, 6) whose volumetric part is theta (n,) in place of their own trace: B-bar's strain."""
    out = np.array(eps, dtype=float)
    out[:, :3] += ((theta - out[:, :3].sum(axis=1)) / 3.0)[:, None]
    return out


def strain_energy(cell_type, xe, ue, lmbda, mu, kappa=None):
    """Strain energy 1/2 int eps : D eps dV (m,) of displacements ue (m, 3n), integrated with the stiffness rule;
    a cell with kappa > 0 (stiffness) takes its volumetric strain from its mean dilatation, as its stiffness does."""
    xi, w = QUADRATURE[cell_type]
    B, detJ = strain_displacement(cell_type, xe, xi)
    eps = B @ np.asarray(ue, float)[:, None, :, None]              # (m, nq, 6, 1)
    if kappa is not None and np.any(np.asarray(kappa) > 0):
        mean = np.broadcast_to(np.asarray(kappa, float), (len(eps),)) > 0
        # the mean dilatation from the same points' strains: the integral of div u over the volume
        theta = np.einsum("mq,mq->m", eps[mean][:, :, :3, 0].sum(axis=2), detJ[mean] * w) / (detJ[mean] @ w)
        nq = eps.shape[1]
        eps[mean] = with_mean_dilatation(eps[mean][..., 0].reshape(-1, 6), np.repeat(theta, nq)).reshape(
            -1, nq, 6, 1)
    D = elasticity_matrix(lmbda, mu)
    D = D[:, None] if D.ndim == 3 else D
    sigma = D @ eps
    return 0.5 * np.einsum("mqi,mqi,mq,q->m", eps[..., 0], sigma[..., 0], detJ, w)


def cell_stress(cell_type, xe, ue, lmbda, mu, chunk=16384, kappa=None, rotation=None):
    """Cauchy stress (m, 6), Voigt order, at each cell's reference centroid; kappa (stiffness): a cell with kappa > 0
    takes its mean dilatation's pressure (kappa times the cell's mean div u in place of div u there); rotation: None,
    or an array (m,) that takes each cell's largest infinitesimal rotation there (the skew part of grad u), rad.

    Computed from the displacement gradient H = G^T u_e (G the shape-function gradients there) and the Voigt
    table, not from the strain-displacement matrix B (6 x 3n per cell): 100k distorted hexes, both chunked,
    51-58 ms against 126-139 ms (docs/performance.md, session 14). Chunks bound the temporaries."""
    xe, ue = np.asarray(xe, float), np.asarray(ue, float)
    m, n = xe.shape[:2]
    lmbda, mu = (np.broadcast_to(np.asarray(p, float), (m,)) for p in (lmbda, mu))
    out = np.empty((m, 6))
    for s in range(0, m, chunk):
        c = slice(s, s + chunk)
        G, _ = _gradients(cell_type, xe[c], np.atleast_2d(fem.CENTROID[cell_type]))
        H = np.matmul(G[:, 0].transpose(0, 2, 1), ue[c].reshape(-1, n, 3))      # H_kj = d u_j / d x_k
        eps = H.reshape(len(H), 9) @ _VOIGT_OF_GRADIENT                           # Voigt strain, as B u gives it
        if kappa is not None:
            mean = np.flatnonzero(np.broadcast_to(np.asarray(kappa, float), (m,))[c] > 0)
            eps[mean] = with_mean_dilatation(eps[mean], mean_dilatation(cell_type, xe[c][mean], ue[c][mean]))
        out[c] = (elasticity_matrix(lmbda[c], mu[c]) @ eps[..., None])[..., 0]
        if rotation is not None:
            rotation[c] = 0.5 * np.abs(H - H.transpose(0, 2, 1)).reshape(len(H), 9).max(axis=1)
    return out


def von_mises(stress):
    """Von Mises equivalent stress (m,) of Voigt stresses (m, 6)."""
    s = np.asarray(stress, float)
    xx, yy, zz, yz, xz, xy = s.T
    return np.sqrt(0.5 * ((xx - yy) ** 2 + (yy - zz) ** 2 + (zz - xx) ** 2) + 3.0 * (yz**2 + xz**2 + xy**2))
