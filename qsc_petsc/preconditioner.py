"""The contact-band preconditioner: algebraic multigrid composed with an exact solve on the band of dofs the contact rows couple.

Penalty rows between bodies add eps_n G^T D G, a coupling 1e2-1e6 times stiffer than the elements
around it and not diagonal (a slave node against a master face): multigrid's coarse spaces and
smoothers do not resolve it, and CG + GAMG needed 9-11x the iterations of the same mesh merged into
one body (docs/performance.md). Composing the multigrid multiplicatively with a sparse Cholesky on
the rows the contact stencil touches (plus `layers` rings of element neighbours) removes that stiff
part exactly: the band is two-dimensional, so its factor is cheap next to the 3-D solve.

The multigrid is hypre's BoomerAMG unless `-qsc_pc_type` names another (gamg), and the Krylov method
GMRES unless `-qsc_ksp_type` names one. BoomerAMG's classical coarsening follows the strong penalty
couplings across the interface: on the two cubes (70k dofs), CG with the band needed 17 iterations
per Newton step with BoomerAMG and 54-79 with GAMG (docs/performance.md).
GMRES takes the multiplicative composite, one V-cycle per iteration; CG needs the symmetric one, two.
BoomerAMG's settings (PMIS coarsening, ext+i interpolation, at most 4 weights per row, strength
threshold 0.5, one level of aggressive coarsening: the usual 3-D elasticity choices; one forward
l1-Gauss-Seidel sweep down and one backward sweep up, in the rows' order) are defaults that any `-qsc_pc_hypre_*` option overrides. The multigrid reads the system's own
options (`-qsc_pc_*`); the band is one submatrix across all ranks, factored once per new Jacobian
(`-qsc_band_*`: default preonly + Cholesky with MUMPS). Both parts sit in one Python preconditioner
(BandComposite), which forms the residual between them on the band's rows only, and reads a Parts flag, so
that System can keep their setups across a new search that moved only the projections.

Under GMRES the band's part starts with a Galerkin correction on the slip modes (SlipCorrection,
assembly.slip_modes; scene key solver.contact_slip_modes): bodies in frictionless contact slide on each other
at little cost in energy, a global motion the multigrid leaves to the Krylov method (two cubes, 70k dofs: 68
-> 55 Krylov iterations, docs/performance.md). Before the multigrid instead of after it: the same counts.
"""

from contextlib import nullcontext

import numpy as np
from petsc4py import PETSc

from .errors import ConvergenceError
from .options import (
    factored_by_mumps,
    insert_options,
    more_mumps_workspace,
    option_value,
    remove_options,
    set_from_options,
)

AMG_TYPES = ("hypre", "gamg")        # the band's partner: the first is the default
# BoomerAMG: cheaper V-cycles than hypre's defaults (about half the operator complexity, measured) at the
# same or a slightly larger iteration count. Smoothing: one forward l1-Gauss-Seidel sweep down and one
# backward sweep up, a symmetric V-cycle (so CG stays valid) at half the work of hypre's default
# symmetric hybrid Gauss-Seidel sweeps; the l1 form converges where penalty rows couple across ranks, where
# hybrid Gauss-Seidel (Jacobi between ranks) need not (plain CG + BoomerAMG stopped with an indefinite
# preconditioner on 3 ranks, patch test). Two cubes, 212k dofs: 22.7 s against 27.4 s (docs/performance.md).
# The sweeps take the rows in their order (no_CF), not hypre's C-points-then-F-points: the same Krylov counts
# (+-1, Hertz +2 %) at 10-14 % less time per V-cycle (docs/performance.md, session 14). PMIS coarsening, not
# HMIS: coarser grids (operator complexity 1.29 against 1.42 at 212k dofs) at the same Krylov counts (+-3 on
# every scene measured), 8-12 % less time in the preconditioner at 212k and 808k (session 15).
HYPRE_DEFAULTS = {"pc_hypre_boomeramg_coarsen_type": "PMIS", "pc_hypre_boomeramg_interp_type": "ext+i",
                  "pc_hypre_boomeramg_P_max": "4", "pc_hypre_boomeramg_strong_threshold": "0.5",
                  "pc_hypre_boomeramg_agg_nl": "1",
                  "pc_hypre_boomeramg_relax_type_down": "l1-Gauss-Seidel",
                  "pc_hypre_boomeramg_relax_type_up": "backward-l1-Gauss-Seidel",
                  "pc_hypre_boomeramg_no_CF": "true"}
GMRES_RESTART = 100        # above the iteration counts measured (docs/performance.md): no restarts
COARSE_CUTOFF = 1e-12      # eigenvalues of Z^T J Z below this fraction of its largest: directions dropped
RUN_GAP = 4096             # the slip correction's dense slices bridge gaps of up to this many dofs


def _distinct(dofs, r0, r1):
    """The distinct entries of dofs (global numbers): those in [r0, r1) through a mask of that range, the others
    (a few: partners on other ranks) by a sort."""
    dofs = np.asarray(dofs, dtype=np.int64)
    inside = (dofs >= r0) & (dofs < r1)
    seen = np.zeros(r1 - r0, dtype=bool)
    seen[dofs[inside] - r0] = True
    return np.concatenate([np.flatnonzero(seen) + r0, np.unique(dofs[~inside])])


def _owned_marked(template, dofs):
    """The owned dofs (global, sorted) that any rank lists in `dofs` (collective)."""
    r0, r1 = template.getOwnershipRange()
    dofs = _distinct(dofs, r0, r1)
    mark = template.duplicate()
    mark.set(0.0)
    mark.setValues(dofs.astype(PETSc.IntType), np.ones(len(dofs)))
    mark.assemble()
    owned = np.flatnonzero(mark.getArray() > 0) + r0
    mark.destroy()
    return owned


def band_dofs(K, patterns, layers=1):
    """This rank's owned dofs (global, sorted) of the contact band: every row the contact couplings touch (their
    patterns, this rank's rows of Mats with K's row layout, e.g. G^T G: local row pointers and global columns)
    and its coupling partners, grown by `layers` rings of K's sparsity; each dof is listed once, by its owner,
    whichever rank found it (collective)."""
    r0, r1 = K.getOwnershipRange()
    touched = np.zeros(r1 - r0, dtype=bool)
    partners = []
    for ia, ja in patterns:
        touched |= np.diff(ia) > 1          # a row coupled to more than itself
        partners.append(ja)                 # its partners may live on other ranks
    template = K.createVecRight()
    band = _owned_marked(template, np.concatenate([np.flatnonzero(touched) + r0, *partners]))
    columns = PETSc.IS().createStride(r1 - r0, r0, 1, comm=K.getComm())
    for _ in range(layers):
        # the band's rows of K alone: a copy of all of K's pattern (getValuesCSR) took fresh memory of K's size
        rows = PETSc.IS().createGeneral(np.asarray(band, dtype=PETSc.IntType), comm=K.getComm())
        sub = K.createSubMatrix(rows, columns)
        band = _owned_marked(template, np.concatenate([band, sub.getValuesCSR()[1]]))
        sub.destroy()
        rows.destroy()
    columns.destroy()
    template.destroy()
    return np.asarray(band, dtype=PETSc.IntType)


class Parts:
    """What System tells a band composite: keep = True leaves the setups of its multigrid and band as they are
    however the operator changes (a new search that moved only the projections). PETSc's own reuse flag
    cannot say it: SNES resets it after every Jacobian."""

    def __init__(self):
        self.keep = False


def _runs(positions, gap=RUN_GAP):
    """Sorted positions as a few slices that cover them: consecutive runs, joined across gaps of at most `gap`
    positions (a body's dofs are a few long runs in PETSc's numbering: dense slices beat indexed access)."""
    if len(positions) == 0:
        return []
    breaks = np.flatnonzero(np.diff(positions) > gap + 1)
    starts = np.concatenate([[positions[0]], positions[breaks + 1]])
    stops = np.concatenate([positions[breaks], [positions[-1]]]) + 1
    return [slice(int(a), int(b)) for a, b in zip(starts, stops)]


class SlipCorrection:
    """A Galerkin correction on a coarse space Z (assembly.slip_modes: blocks of modes, each on its body's
    owned dofs): c = (Z^T P Z)^-1 Z^T r, after which the band's solve takes r - P Z c and Z c is added to its
    answer. Z and P Z are kept dense on a few slices of the local dofs (P Z from the setup, where it is
    nonzero: the body and, through the contact rows, the dofs facing it), P Z also on the band's rows: an
    application costs no product with the operator and one reduction."""

    def __init__(self, blocks):
        self.n_modes = [len(values) for _, values in blocks]
        self.Z = [self._dense(cols, values) for cols, values in blocks]   # per block: [(slice, values there)]
        self.PZ = self.PZ_band = self.E_inv = self.Zd = None

    @staticmethod
    def _dense(positions, values):
        """[(slice, values on it)] for values (modes, len(positions)) given at sorted positions."""
        pieces = []
        for run in _runs(positions):
            dense = np.zeros((len(values), run.stop - run.start))
            inside = (positions >= run.start) & (positions < run.stop)
            dense[:, positions[inside] - run.start] = values[:, inside]
            pieces.append((run, dense))
        return pieces

    def set_up(self, P, band_rows):
        """P Z and the coarse matrix Z^T P Z for the operator P; `band_rows`: the band's local positions."""
        n = P.getLocalSize()[1]
        if self.Zd is None:
            # Z as one dense matrix (its values never change: made once), so that P Z is one product (P read
            # once, not once per mode)
            self.Z_dense = np.zeros((n, self.modes()), order="F")
            for pieces, first in zip(self.Z, np.cumsum([0] + self.n_modes[:-1])):
                for run, values in pieces:
                    self.Z_dense[run, first:first + len(values)] = values.T
            self.Zd = PETSc.Mat().createDense([(n, P.getSize()[1]), (PETSc.DECIDE, self.modes())],
                                              array=self.Z_dense.ravel(order="F"), comm=P.getComm())
            self.Zd.assemble()
        PZd = P.matMult(self.Zd)
        PZ = np.empty((self.modes(), n))
        for k in range(self.modes()):
            PZ[k] = PZd.getDenseColumnVec(k).getArray(readonly=True)
            PZd.restoreDenseColumnVec(k)
        PZd.destroy()
        self.PZ = []
        for block in np.split(PZ, np.cumsum(self.n_modes)[:-1]):
            nonzero = np.flatnonzero(np.any(block != 0.0, axis=0))
            self.PZ.append(self._dense(nonzero, block[:, nonzero]))
        self.PZ_band = PZ[:, band_rows]
        self.comm = P.getComm().tompi4py()
        E = self.comm.allreduce(self.Z_dense.T @ PZ.T)           # Z^T P Z
        lam, Q = np.linalg.eigh(0.5 * (E + E.T))
        # a direction the operator leaves (nearly) free, or a mode zero on this body's supports alone, is dropped
        keep = lam > COARSE_CUTOFF * lam.max()
        self.E_inv = (Q[:, keep] / lam[keep]) @ Q[:, keep].T

    def coefficients(self, x, y):
        """c = (Z^T P Z)^-1 Z^T (x - P y) for Vecs x, y (collective), with Z^T P y = (P Z)^T y: P is symmetric
        (K + G^T D G), so the residual x - P y itself is never formed."""
        xa, ya = x.getArray(readonly=True), y.getArray(readonly=True)
        zr = np.concatenate([sum((values @ xa[run] for run, values in Z), np.zeros(m))
                             - sum((values @ ya[run] for run, values in PZ), np.zeros(m))
                             for Z, PZ, m in zip(self.Z, self.PZ, self.n_modes)])
        return self.E_inv @ self.comm.allreduce(zr)

    def add(self, c, y):
        """y += Z c."""
        ya = y.getArray()
        for ck, pieces in zip(np.split(c, np.cumsum(self.n_modes)[:-1]), self.Z):
            for run, values in pieces:
                ya[run] += ck @ values

    def modes(self):
        return sum(self.n_modes)

    def destroy(self):
        if self.Zd is not None:
            self.Zd.destroy()


class BandSolve:
    """The exact solve on the band: y_b = J_bb^-1 x_b on this rank's band dofs (all owned, so the band's Vecs
    are slices of the whole ones).

    One factorization of the band's submatrix across all ranks (MUMPS Cholesky by default, options
    -qsc_band_*): where the partition cuts the contact interface, overlapping per-rank blocks summed
    their corrections and cost a third more iterations (two cubes, 70k dofs: 123 against 83)."""

    def __init__(self, band, comm):
        self.iset = PETSc.IS().createGeneral(band, comm=comm)
        ksp = PETSc.KSP().create(comm=comm)
        ksp.setOptionsPrefix("qsc_band_")
        ksp.setType("preonly")
        ksp.getPC().setType("cholesky")
        ksp.getPC().setFactorSolverType("mumps")
        # read here, at the search, not in setUp: an error inside PETSc's solve callbacks would reach one
        # rank's Python while the others wait in the factorization
        set_from_options(ksp, "contact band's solve (-qsc_band_*)")
        self.ksp = ksp
        self.sub = self.xb = self.yb = self.rows = None
        self.own_options = set()          # options set here (more MUMPS workspace), removed by destroy

    def set_up(self, P):
        self.sub = P.createSubMatrix(self.iset, self.iset, submat=self.sub)
        # a principal submatrix of J = K + G^T D G (D >= 0): symmetric positive definite, so MUMPS factors it
        # without pivoting. Its symmetric-indefinite mode (PETSc's default for Cholesky) returned NaN now
        # and then on the same matrix: two cubes, 212k dofs, contact_band_layers = 0, 4 runs of 6 (none of 4
        # with this flag, docs/performance.md session 15)
        self.sub.setOption(PETSc.Mat.Option.SPD, True)
        self.ksp.setOperators(self.sub)
        if self.xb is None:
            self.xb, self.yb = self.sub.createVecs()
            self.rows = self.iset.getIndices() - P.getOwnershipRange()[0]   # local positions
        self.ksp.setUp()
        pc = self.ksp.getPC()
        # MUMPS's workspace estimate can fall short on several ranks (configs/stiff_plate.toml with Gauss rows,
        # 2 ranks: INFOG(1) = -9 from the AMF ordering's factors, and the band's solve gave inf): relaxed and
        # factored again, as System does for its own factors
        if not factored_by_mumps(pc):
            return
        while more_mumps_workspace(pc, "qsc_band_", self.own_options) is not None:
            self.ksp.setOperators(self.sub)
            self.ksp.setUp()
        F = pc.getFactorMatrix()
        if F.getMumpsInfog(1) < 0:
            # its solve would return inf or NaN, which the Krylov method reported as DIVERGED_NANORINF at every
            # cutback; a smaller increment has the same band (collective: INFOG is global)
            raise ConvergenceError(
                f"the contact band's MUMPS factorization failed: INFOG(1) = {F.getMumpsInfog(1)}, INFOG(2) = "
                f"{F.getMumpsInfog(2)} (MUMPS's manual names them; memory relaxation ICNTL(14) = "
                f"{F.getMumpsIcntl(14)} %, cap ICNTL(23) = {F.getMumpsIcntl(23)} MB, 0: none): check the "
                f"-qsc_band_mat_mumps_* options, or -qsc_band_pc_factor_mat_solver_type")

    def solve(self, rhs):
        """The band's solve of rhs (this rank's band entries, an array, in the order of `rows`); returns the
        answer's array (the band's own: read it before the next solve)."""
        self.xb.getArray()[:] = rhs
        self.ksp.solve(self.xb, self.yb)
        return self.yb.getArray(readonly=True)

    def destroy(self):
        remove_options(self.own_options)
        for obj in (self.ksp, self.sub, self.xb, self.yb, self.iset):
            if obj is not None:
                obj.destroy()


class BandComposite:
    """PCPYTHON context: the multigrid M (hypre or gamg, tuned by -qsc_pc_*), then the band's solve B,
    multiplicatively: y = M x, then y += B (x - J y), the slip correction (if any) first in the second part;
    `symmetric` (for CG) adds M (x - J y) again.

    The residual x - J y between the two parts is read only on the band's rows (J's band rows times y, one
    band-sized product) and, for the slip correction, through Z^T (x - J y) = Z^T x - (J Z)^T y: no product
    with the whole J, which PETSc's multiplicative composite made at every application (212k dofs, one
    -log_view pair: MatMult 1.23 -> 0.80 s over the run's 293 calls, SNESSolve 7.01 -> 6.50 s; docs/performance.md,
    session 15).

    Set up again unless parts.keep: System keeps the setup across a new search that moved only the
    projections. The band's rows of J are taken again all the same (a cheap copy), so that the residual is the
    current J's, as the composite's was; the slip correction's J Z stays the setup's. `soften(P)`, if given, is
    a context in which P is the operator BoomerAMG is to be set up on (System.softened)."""

    def __init__(self, inner, band, parts, slip=None, soften=None, symmetric=False, defaults=None):
        self.inner, self.band, self.parts = inner, band, parts
        self.slip, self.soften, self.symmetric = slip, soften, symmetric
        # {option: value} qsc put in the database for the multigrid's setup alone (petsc_options.txt says them)
        self.defaults = defaults or {}
        self.ready = False
        self.columns = self.band_rows = self.jy = self.work = None

    def setUp(self, pc):
        _, P = pc.getOperators()
        if self.columns is None:
            r0, r1 = P.getOwnershipRange()
            self.columns = PETSc.IS().createStride(r1 - r0, first=r0, step=1, comm=P.getComm())
        keep = self.parts.keep and self.ready
        # J y on the band's rows: taken from the operator at hand, as the whole residual was
        self.band_rows = P.createSubMatrix(self.band.iset, self.columns, submat=self.band_rows)
        if self.jy is None:
            self.jy = self.band_rows.createVecLeft()
        self.inner.setReusePreconditioner(keep)
        if keep:
            return
        self.inner.setOperators(P, P)
        with self.soften(P) if self.soften else nullcontext():
            self.inner.setUp()
        # set up on the softened operator: P's values changed and changed back, so the inner PC, which records
        # P's state, must not redo its setup at its next application
        self.inner.setReusePreconditioner(self.soften is not None)
        self.band.set_up(P)
        if self.slip is not None:
            self.slip.set_up(P, self.band.rows)
        self.ready = True

    def apply(self, pc, x, y):
        self.inner.apply(x, y)
        self.band_rows.mult(y, self.jy)
        rb = x.getArray(readonly=True)[self.band.rows] - self.jy.getArray(readonly=True)
        c = None
        if self.slip is not None:
            c = self.slip.coefficients(x, y)
            rb -= c @ self.slip.PZ_band
        y.getArray()[self.band.rows] += self.band.solve(rb)
        if c is not None:
            self.slip.add(c, y)
        if self.symmetric:
            if self.work is None:
                self.work = (y.duplicate(), y.duplicate())
            r, t = self.work
            pc.getOperators()[1].mult(y, r)
            r.aypx(-1.0, x)
            self.inner.apply(r, t)
            y.axpy(1.0, t)

    def view(self, pc, viewer):
        viewer.printfASCII(f"qsc_petsc band composite ({'symmetric ' if self.symmetric else ''}multiplicative): "
                           "the multigrid, then" + (f" a Galerkin correction on {self.slip.modes()} slip modes and"
                                                    if self.slip is not None else "") + " the band's solve\n")
        self.inner.view(viewer)
        self.band.ksp.view(viewer)

    def destroy(self, pc=None):
        for obj in (self.columns, self.band_rows, self.jy, *(self.work or ())):
            if obj is not None:
                obj.destroy()
        self.band.destroy()
        if self.slip is not None:
            self.slip.destroy()
        try:
            self.inner.destroy()
        except PETSc.Error:
            # after a failed setup hypre's error flag stays set and every later hypre call fails, its destroy
            # included (a failed run is released before exit: cli.release); the process ends without it
            pass


def amg_type():
    """The band's partner: the preconditioner type the options name, else BoomerAMG."""
    return option_value("pc_type", AMG_TYPES[0])


def check_multigrid_alpha(scene):
    """A SceneError when solver.contact_multigrid_alpha is set for a multigrid other than BoomerAMG (run and
    check: `qsc check` passed it, hunt32_3)."""
    if scene.solver.contact_multigrid_alpha is not None and scene.contact and amg_type() != "hypre":
        from .errors import SceneError
        raise SceneError(f"solver.contact_multigrid_alpha: softens the interface for BoomerAMG only, and pc_type is "
                         f"{amg_type()!r}")


def wants_band(mode, has_pairs):
    """Whether to use the band preconditioner: mode "band" always (with contact pairs), "auto" unless the
    options name a preconditioner other than an algebraic multigrid (hypre, gamg), "none" never."""
    if not has_pairs or mode == "none":
        return False
    return mode == "band" or amg_type() in AMG_TYPES


def install_band_pc(ksp, band, comm, coarse=None, soften=None):
    """Give ksp a fresh band composite (BandComposite): the multigrid, then the exact solve on the contact band
    (BandSolve), whose dofs (this rank's, from band_dofs) are `band`; `coarse` (assembly.slip_modes' blocks,
    or None) gives the band's solve a Galerkin correction first (SlipCorrection), except under a named CG (the
    correction is not symmetric); `soften` (a context, System.softened) is where BoomerAMG is set up (the
    multigrid must be hypre).

    When the options name no KSP, it becomes GMRES (right-preconditioned, as the true-residual test
    needs) with the multiplicative composite, one V-cycle per iteration; a named CG gets the
    symmetric-multiplicative one (so CG stays valid, at two V-cycles per iteration), any other KSP the
    multiplicative one. Returns the global number of band dofs and the Parts the composite reads (None without a
    band). A search whose band and Jacobian pattern are the last one's keeps the PC it has
    (System.set_terms); any other gets a fresh one: the band follows the new rows."""
    n_band = comm.allreduce(len(band))
    if n_band == 0:
        return 0, None                  # no row within reach: nothing stiff to take out, plain options
    krylov = option_value("ksp_type")
    added = insert_options(HYPRE_DEFAULTS) if amg_type() == "hypre" else {}   # read once below, then removed
    if krylov is None:
        ksp.setType("gmres")             # one V-cycle per iteration (CG needs the symmetric form: two)
        ksp.setGMRESRestart(GMRES_RESTART)
        ksp.setPCSide(PETSc.PC.Side.RIGHT)   # left-preconditioned GMRES cannot test the true residual
    amg = PETSc.PC().create(comm=comm)
    amg.setType(amg_type())
    amg.setOptionsPrefix("qsc_")         # -qsc_pc_hypre_* / -qsc_pc_gamg_* tune it as they tune a plain PC
    set_from_options(amg, "contact band's multigrid (-qsc_pc_*)")
    remove_options(added)               # BoomerAMG has read them
    parts = Parts()
    slip = SlipCorrection(coarse) if coarse and krylov != "cg" else None
    pc = PETSc.PC().create(comm=comm)
    pc.setOptionsPrefix("qsc_")
    pc.setType("python")
    pc.setPythonContext(BandComposite(amg, BandSolve(band, comm), parts, slip, soften, symmetric=krylov == "cg",
                                      defaults=added))
    ksp.setPC(pc)
    return n_band, parts


def multigrid(pc):
    """The multigrid PC of a band composite (install_band_pc), else None."""
    if pc.getType() != "python" or not isinstance(pc.getPythonContext(), BandComposite):
        return None
    return pc.getPythonContext().inner
