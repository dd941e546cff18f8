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
BoomerAMG's settings (HMIS coarsening, ext+i interpolation, at most 4 weights per row, strength
threshold 0.5, one level of aggressive coarsening: the usual 3-D elasticity choices; one forward
l1-Gauss-Seidel sweep down and one backward sweep up, in the rows' order) are defaults that any `-qsc_pc_hypre_*` option overrides. The multigrid reads the system's own
options (`-qsc_pc_*`); the band is one submatrix across all ranks, factored once per new Jacobian
(`-qsc_band_*`: default preonly + Cholesky with MUMPS). Both parts are Python contexts in a PETSc composite
sharing a Parts flag, so that System can keep their setups across a new search that moved only the
projections.

Under GMRES the band's part starts with a Galerkin correction on the slip modes (SlipCorrection,
assembly.slip_modes; scene key solver.contact_slip_modes): bodies in frictionless contact slide on each other
at little cost in energy, a global motion the multigrid leaves to the Krylov method (two cubes, 70k dofs: 68
-> 55 Krylov iterations, docs/performance.md). Before the multigrid instead of after it: the same counts.
"""

from contextlib import nullcontext

import numpy as np
from petsc4py import PETSc

from .options import insert_options, option_value, remove_options, set_from_options

AMG_TYPES = ("hypre", "gamg")        # the band's partner: the first is the default
# BoomerAMG: cheaper V-cycles than hypre's defaults (about half the operator complexity, measured) at the
# same or a slightly larger iteration count. Smoothing: one forward l1-Gauss-Seidel sweep down and one
# backward sweep up, a symmetric V-cycle (so CG stays valid) at half the work of hypre's default
# symmetric hybrid Gauss-Seidel sweeps; the l1 form converges where penalty rows couple across ranks, where
# hybrid Gauss-Seidel (Jacobi between ranks) need not (plain CG + BoomerAMG stopped with an indefinite
# preconditioner on 3 ranks, patch test). Two cubes, 212k dofs: 22.7 s against 27.4 s (docs/performance.md).
# The sweeps take the rows in their order (no_CF), not hypre's C-points-then-F-points: the same Krylov counts
# (+-1, Hertz +2 %) at 10-14 % less time per V-cycle (docs/performance.md, session 14).
HYPRE_DEFAULTS = {"pc_hypre_boomeramg_coarsen_type": "HMIS", "pc_hypre_boomeramg_interp_type": "ext+i",
                  "pc_hypre_boomeramg_P_max": "4", "pc_hypre_boomeramg_strong_threshold": "0.5",
                  "pc_hypre_boomeramg_agg_nl": "1",
                  "pc_hypre_boomeramg_relax_type_down": "l1-Gauss-Seidel",
                  "pc_hypre_boomeramg_relax_type_up": "backward-l1-Gauss-Seidel",
                  "pc_hypre_boomeramg_no_CF": "true"}
GMRES_RESTART = 100        # above the iteration counts measured (docs/performance.md): no restarts
COARSE_CUTOFF = 1e-12      # eigenvalues of Z^T J Z below this fraction of its largest: directions dropped
RUN_GAP = 4096             # the slip correction's dense slices bridge gaps of up to this many dofs


def _owned_marked(template, dofs):
    """The owned dofs (global, sorted) that any rank lists in `dofs` (collective)."""
    mark = template.duplicate()
    mark.set(0.0)
    mark.setValues(np.asarray(dofs, dtype=PETSc.IntType), np.ones(len(dofs)))
    mark.assemble()
    owned = np.flatnonzero(mark.getArray() > 0) + mark.getOwnershipRange()[0]
    mark.destroy()
    return owned


def band_dofs(K, couplings, layers=1):
    """This rank's owned dofs (global, sorted) of the contact band: every row the contact couplings (Mats
    with K's row layout, e.g. G^T G) touch and its coupling partners, grown by `layers` rings of K's
    sparsity; each dof is listed once, by its owner, whichever rank found it (collective)."""
    r0, r1 = K.getOwnershipRange()
    touched = np.zeros(r1 - r0, dtype=bool)
    partners = []
    for C in couplings:
        ia, ja, _ = C.getValuesCSR()
        touched |= np.diff(ia) > 1          # a row coupled to more than itself
        partners.append(ja)                 # its partners may live on other ranks
    template = K.createVecRight()
    band = _owned_marked(template, np.union1d(np.flatnonzero(touched) + r0,
                                              np.concatenate(partners) if partners else []))
    if layers > 0:
        ia, ja, _ = K.getValuesCSR()
        for _ in range(layers):
            loc = band - r0
            counts = ia[loc + 1] - ia[loc]
            idx = np.repeat(ia[loc], counts) + (np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts))
            band = _owned_marked(template, np.union1d(band, ja[idx]))
    template.destroy()
    return np.asarray(band, dtype=PETSc.IntType)


class Parts:
    """What the two parts of a band composite share: keep = True leaves their setups as they are however the
    operator changes (System decides: a new search that moved only the projections). PETSc's own reuse flag
    cannot say it: the composite passes it down to its parts at every application, and SNES resets it after
    every Jacobian."""

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
    owned dofs): c = (Z^T P Z)^-1 Z^T r, then the rest r - P Z c goes on to the next solver and Z c is added
    to its answer. Z and P Z are kept dense on a few slices of the local dofs (P Z from the setup, where it is
    nonzero: the body and, through the contact rows, the dofs facing it): an application costs no product
    with the operator and one reduction."""

    def __init__(self, blocks):
        self.n_modes = [len(values) for _, values in blocks]
        self.Z = [self._dense(cols, values) for cols, values in blocks]   # per block: [(slice, values there)]
        self.PZ = self.E_inv = self.rest = None

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

    def set_up(self, P):
        z, pz = P.createVecs()
        products = []
        for pieces, m in zip(self.Z, self.n_modes):
            PZ = np.empty((m, pz.getLocalSize()))
            for k in range(m):
                za = z.getArray()
                za[:] = 0.0
                for run, values in pieces:
                    za[run] = values[k]
                P.mult(z, pz)
                PZ[k] = pz.getArray()
            products.append(PZ)
        z.destroy()
        self.PZ = []
        for PZ in products:
            nonzero = np.flatnonzero(np.any(PZ != 0.0, axis=0))
            self.PZ.append(self._dense(nonzero, PZ[:, nonzero]))
        self.comm = pz.getComm().tompi4py()
        # a rank may hold none of a body's dofs: its blocks start from zeros
        E = self.comm.allreduce(np.block([[sum((values @ PZ[:, run].T for run, values in pieces),
                                               np.zeros((m, len(PZ)))) for PZ in products]
                                          for pieces, m in zip(self.Z, self.n_modes)]))
        lam, Q = np.linalg.eigh(0.5 * (E + E.T))
        # a direction the operator leaves (nearly) free, or a mode zero on this body's supports alone, is dropped
        keep = lam > COARSE_CUTOFF * lam.max()
        self.E_inv = (Q[:, keep] / lam[keep]) @ Q[:, keep].T
        if self.rest is not None:
            self.rest.destroy()
        self.rest = pz

    def split(self, r):
        """(c, the rest r - P Z c as a Vec this object owns) for a residual Vec r (collective)."""
        ra = r.getArray(readonly=True)
        zr = np.concatenate([sum((values @ ra[run] for run, values in pieces), np.zeros(m))
                             for pieces, m in zip(self.Z, self.n_modes)])
        c = np.split(self.E_inv @ self.comm.allreduce(zr), np.cumsum(self.n_modes)[:-1])
        rest = self.rest.getArray()
        rest[:] = ra
        for ck, pieces in zip(c, self.PZ):
            for run, values in pieces:
                rest[run] -= ck @ values
        return c, self.rest

    def add(self, c, y):
        """y += Z c."""
        ya = y.getArray()
        for ck, pieces in zip(c, self.Z):
            for run, values in pieces:
                ya[run] += ck @ values

    def modes(self):
        return sum(self.n_modes)

    def destroy(self):
        if self.rest is not None:
            self.rest.destroy()


class MultigridPart:
    """PCPYTHON context: the band composite's multigrid (hypre or gamg, tuned by -qsc_pc_*), set up again
    unless parts.keep; `soften(P)`, if given, is a context in which P is the operator BoomerAMG is to be set
    up on (System.softened)."""

    def __init__(self, inner, parts, soften=None):
        self.inner, self.parts = inner, parts
        self.soften = soften
        self.ready = False

    def setUp(self, pc):
        keep = self.parts.keep and self.ready
        self.inner.setReusePreconditioner(keep)
        if keep:
            return
        A, P = pc.getOperators()
        self.inner.setOperators(A, P)
        with self.soften(P) if self.soften else nullcontext():
            self.inner.setUp()
        # set up on the softened operator: P's values changed and changed back, so the inner PC, which records
        # P's state, must not redo its setup at its next application
        self.inner.setReusePreconditioner(self.soften is not None)
        self.ready = True

    def apply(self, pc, x, y):
        self.inner.apply(x, y)

    def view(self, pc, viewer):
        self.inner.view(viewer)

    def destroy(self, pc=None):
        try:
            self.inner.destroy()
        except PETSc.Error:
            # after a failed setup hypre's error flag stays set and every later hypre call fails, its destroy
            # included (a failed run is released before exit: cli.release); the process ends without it
            pass


class BandSolve:
    """PCPYTHON context: the exact solve on the band, y = J_bb^-1 x on the band dofs and 0 elsewhere.

    One factorization of the band's submatrix across all ranks (MUMPS Cholesky by default, options
    -qsc_band_*): where the partition cuts the contact interface, overlapping per-rank blocks summed
    their corrections and cost a third more iterations (two cubes, 70k dofs: 123 against 83). Not
    factored again while parts.keep."""

    def __init__(self, band, comm, parts=None, slip=None):
        self.parts = parts or Parts()
        self.slip = slip                 # a SlipCorrection made before the band's solve, or None
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
        self.sub = self.scatter = self.xb = self.yb = None

    def setUp(self, pc):
        if self.parts.keep and self.sub is not None:
            return
        _, P = pc.getOperators()
        self.sub = P.createSubMatrix(self.iset, self.iset, submat=self.sub)
        self.ksp.setOperators(self.sub)
        if self.scatter is None:
            self.xb, self.yb = self.sub.createVecs()
            whole = P.createVecRight()
            self.scatter = PETSc.Scatter().create(whole, self.iset, self.xb, None)
            whole.destroy()
        self.ksp.setUp()
        if self.slip is not None:
            self.slip.set_up(P)

    def apply(self, pc, x, y):
        if self.slip is not None:
            c, x = self.slip.split(x)
        self.scatter.scatter(x, self.xb, PETSc.InsertMode.INSERT, PETSc.ScatterMode.FORWARD)
        self.ksp.solve(self.xb, self.yb)
        y.set(0.0)
        self.scatter.scatter(self.yb, y, PETSc.InsertMode.INSERT, PETSc.ScatterMode.REVERSE)
        if self.slip is not None:
            self.slip.add(c, y)

    def view(self, pc, viewer):
        if self.slip is not None:
            viewer.printfASCII(f"Galerkin correction on {self.slip.modes()} slip modes, then the band's solve "
                               "(qsc_petsc.assembly.slip_modes)\n")
        self.ksp.view(viewer)

    def destroy(self, pc=None):
        for obj in (self.ksp, self.sub, self.scatter, self.xb, self.yb, self.iset, self.slip):
            if obj is not None:
                obj.destroy()


def amg_type():
    """The band's partner: the preconditioner type the options name, else BoomerAMG."""
    return option_value("pc_type", AMG_TYPES[0])


def wants_band(mode, has_pairs):
    """Whether to use the band preconditioner: mode "band" always (with contact pairs), "auto" unless the
    options name a preconditioner other than an algebraic multigrid (hypre, gamg), "none" never."""
    if not has_pairs or mode == "none":
        return False
    return mode == "band" or amg_type() in AMG_TYPES


def install_band_pc(ksp, band, comm, coarse=None, soften=None):
    """Give ksp a fresh composite PC: the multigrid, then the exact solve on the contact band (BandSolve), whose
    dofs (this rank's, from band_dofs) are `band`; `coarse` (assembly.slip_modes' blocks, or None) gives the
    band's solve a Galerkin correction first (SlipCorrection), except under a named CG (the correction is not
    symmetric); `soften` (a context, System.softened) is where BoomerAMG is set up (the multigrid must be hypre).

    When the options name no KSP, it becomes GMRES (right-preconditioned, as the true-residual test
    needs) with the multiplicative composite, one V-cycle per iteration; a named CG gets the
    symmetric-multiplicative one (so CG stays valid, at two V-cycles per iteration), any other KSP the
    multiplicative one. Returns the global number of band dofs and the Parts the two share (None without a
    band). A search whose band and Jacobian pattern are the last one's keeps the PC it has
    (System.set_terms); any other gets a fresh one: the band follows the new rows."""
    if comm.allreduce(len(band)) == 0:
        return 0, None                  # no row within reach: nothing stiff to take out, plain options
    krylov = option_value("ksp_type")
    added = insert_options(HYPRE_DEFAULTS) if amg_type() == "hypre" else {}   # read once below, then removed
    pc = PETSc.PC().create(comm=comm)
    pc.setOptionsPrefix("qsc_")
    pc.setType("composite")
    if krylov is None:
        ksp.setType("gmres")             # one V-cycle per iteration (CG needs the symmetric form: two)
        ksp.setGMRESRestart(GMRES_RESTART)
        ksp.setPCSide(PETSc.PC.Side.RIGHT)   # left-preconditioned GMRES cannot test the true residual
    pc.setCompositeType(PETSc.PC.CompositeType.SYMMETRIC_MULTIPLICATIVE if krylov == "cg"
                        else PETSc.PC.CompositeType.MULTIPLICATIVE)
    pc.addCompositePCType("python")
    pc.addCompositePCType("python")
    amg = PETSc.PC().create(comm=comm)
    amg.setType(amg_type())
    amg.setOptionsPrefix("qsc_")         # -qsc_pc_hypre_* / -qsc_pc_gamg_* tune it as they tune a plain PC
    set_from_options(amg, "contact band's multigrid (-qsc_pc_*)")
    remove_options(added)               # BoomerAMG has read them
    parts = Parts()
    slip = SlipCorrection(coarse) if coarse and krylov != "cg" else None
    pc.getCompositePC(0).setPythonContext(MultigridPart(amg, parts, soften))
    pc.getCompositePC(1).setPythonContext(BandSolve(band, comm, parts, slip))
    ksp.setPC(pc)
    return comm.allreduce(len(band)), parts


def multigrid(pc):
    """The multigrid PC of a band composite (install_band_pc), else None."""
    if pc.getType() != "composite":
        return None
    return pc.getCompositePC(0).getPythonContext().inner
