"""Load-stepped SNES solve of K u + F_c(u) = f: semi-smooth Newton on the penalised contact rows.

The elastic part is linear and assembled once (Dirichlet rows and columns eliminated with a
lifting vector); every contact term contributes G^T m to the residual and G^T D G to the
Jacobian (formulation.md section 4). Between two contact searches G is frozen, so a step
converges when the active set stops changing and the residual (or the step) is small.
"""

import hashlib
import time
from contextlib import contextmanager

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from . import assembly, options, preconditioner
from .contact.penalty import multipliers_update, row_response
from .errors import ConvergenceError, SceneError, petsc_detail
from .mesh import available_memory, node_memory

SNES_REASONS = {v: k for k, v in vars(PETSc.SNES.ConvergedReason).items() if not k.startswith("_")}
KSP_REASONS = {v: k for k, v in vars(PETSc.KSP.ConvergedReason).items() if not k.startswith("_")}
SUBSET = PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN
PETSC_ERR_NOT_CONVERGED = 91   # raised instead of a reason under -qsc_ksp/snes_error_if_not_converged
PETSC_ERR_MISSING_FACTOR = 92  # MatGetFactor: no package provides that factorization of that matrix type
# MUMPS INFOG(1) when its factorization would take more memory than it may: over the ICNTL(23) cap (-19), or an
# allocation the system refused (-13); with a cap set, a work array too small within it (-9) is the same want
MUMPS_MEMORY_ERRORS = (-19, -13)
# the part of a rank's share of its node's available memory that a MUMPS factorization may take by default
# (ICNTL(23), System._mumps_memory_cap): the rest is for the matrix, vectors and the solve's own arrays
MUMPS_MEMORY_SHARE = 0.9
# the augmented Lagrangian's updates end when they change the multipliers by at most a pair's augmented_tolerance or
# by this many times their round-off (the rms over the rows that hold a multiplier of eps_n eps (|G| |u| + |g|) / W,
# relative to the multipliers': ConstraintTerm.next_multipliers), whichever is larger. The changes stood at
# 0.5-1.2x that estimate for ever (patch test at alpha 1e4 / 1e8 / 1e10: 0.8-1.9e-11 / 0.8-1.0e-7 / 0.9-1.2e-5
# against 1.55e-11 / 1.55e-7 / 1.55e-5; hertz_coarse at 1e6-1e10 and Gauss and nodal rows at 1e9 alike), and a run
# at alpha 1e10 stopped with AUGMENTED_LAGRANGIAN_MAX_IT at the default tolerance 1e-6 (hunt30_2)
AUGMENTED_ROUND_OFF = 10.0
# ... but no higher than this: a round-off that large leaves the updates nothing to do (the multipliers are
# their penalty's), and the loop runs on to augmented_max_iterations and says so. The rows' own displacements
# set it, not another body's (hunt30_4: a free body moved 1e12 m set the first bound at 1.2 and the loop stopped
# at the penalty's answer, 9.4 % off)
AUGMENTED_ROUND_OFF_CAP = 1e-3
# ... and a run whose updates a halved increment left as far says they stand on their round-off (lower the penalty)
# when they change by at most this many times it: two_pass's over-constrained rows at alpha 1e8 stood at 250-400x
# the estimate, beyond AUGMENTED_ROUND_OFF, and the message sent the user to more updates or a stiffer penalty,
# which did nothing or worse (hunt33_3); a soft penalty's slow updates stand 1e6x and more above theirs
AUGMENTED_STALL_NOISE = 1e4
# the augmented Lagrangian: rows whose stiffness on their own node, against the elements' there, is below this
# fraction of the term's largest keep no multiplier (ConstraintTerm.own_stiffness). Slivers of area past an edge
# stand at 5e-7-5e-6 of the largest, every other row of the sliding cubes at 9e-4 or more (1e-2 or more but in
# one increment; a row of a mesh 10x finer than the pair's coarser side at ~0.1)
AUGMENTED_SLIVER = 1e-4
# a try that ends on AUGMENTED_LAGRANGIAN_MAX_IT after a halving, its multipliers' change above this share of the
# try before's, ends the cutbacks (solve_load_step)
AUGMENTED_CUTBACK_GAIN = 0.5
KSP_MAX_IT = 2000              # Krylov iterations per linear solve unless -qsc_ksp_max_it says otherwise
# SNES types that take Newton steps with the Jacobian and stop by System._converged (the active set and the force
# residual): the others stop by tests of their own (ksponly after one linear solve, ngmres on a step norm it never
# formed, the VI solvers by theirs) and ended "converged" with the contact force off by orders of magnitude
NEWTON_TYPES = ("newtonls", "newtontr")
START_TOUCHING, START_REACH = "touching", "reach"   # ConstraintTerm.start: an increment's first closed set
DAMPING_HALVINGS = 8           # smallest damped Newton step 1/2^7 (System._damp)
# Newton iterations without a new lowest residual after which steps are damped (System._watch_cycles): 8 damped
# hertz_fine's two_pass (peeling its over-closed edge ring by ring) into 27 + 16 iterations against 20 + 15
STALL_WINDOW = 15
# System.softened: the multigrid's contact rows are at most this much softer than the pair's own. Softer, its
# corrections at the interface outgrew what the band's solve puts right: two cubes (70k dofs), alpha 1e6 with
# contact_multigrid_alpha 1 (1e-6) stopped at 2000 Krylov iterations; at 1e-4 (alpha_mg 100) 55-56 against 61.
# Pairs stiffer than SOFTENED_UP_TO keep their own penalty: at alpha 1e8 the second increment stopped at 2000
# iterations with 1e-4, and with 1e-3 the run took 219 (43 + 176) against 70
SOFTEST = 1e-4
SOFTENED_UP_TO = 1e6
# _keep_or_rebuild_pc: a new search keeps the last search's preconditioner only if, for every contact pair,
# alpha x ||G^T G - G0^T G0||_inf / ||G0^T G0||_inf (G0: the rows it was set up for) is at most this: the change
# in the interface's stiffness against the elements'. A punch (0.4 m cube on a 1 m block, 13k dofs, alpha 1e4)
# slid 1.7e-2 of it between its two increments: 116 Krylov iterations kept against 24 set up again; at alpha
# 1e3 49 against 23, at 1e2 23 / 22, at 10 20 / 20. Two cubes between dies (70k): 2.3e-6, kept (alpha 1e4: 0.023)
STALE_CHANGE = 1.0
# the Newton test's force scale is at least the elastic forces of this strain (System.force_floor): a load
# that strains the bodies less is solved to rtol of that, not of itself
FLOOR_STRAIN = 1e-6
KRYLOV_MARGIN = 0.1            # the Krylov residual's stop below the Newton target (System._match_krylov_to_newton)
# round-off floor (System._converged): a Newton step taken with the final active set that did not halve the
# residual, which is within FLOOR_SPAN of the target, ends the solve (the linear solves cannot go lower)
FLOOR_REDUCTION, FLOOR_SPAN = 0.5, 1e3
# a solve that stops on its Newton steps (below stol x |u|: the rows' round-off moves u no more) with the residual
# above this share of its force scale is said (Run: a warning; round_off_floor in the summary). flat_punch at
# alpha 1e8 / 1e9 / 1e10 stopped at 2-6e-8 / 2-5e-7 / 2-5e-6 with every formulation and rule, but two_pass with
# Gauss or segment rows at 1e10 at 1-3e-2, its contact force 1-2 % off the dies' and its traction 5.6 %, with
# no word (hunt29_1). Not a failure: large sliding's Gauss rows at 1e10 stopped at 3.5e-2 on some searches and
# balanced the dies to 2e-6 (hunt29_3): the residual alone does not tell a wrong answer from round-off tractions
ROUND_OFF_WARNING = 1e-4
# a PETSc error inside the solve (System.solve_at): how long the failed rank waits for every other rank to fail
# too before the error is treated as one rank's (re-raised: the CLI aborts the job rather than hang)
AGREE_SECONDS = 20.0
PETSC_ERRORS = {55: "out of memory", 56: "an operation the matrix or solver type does not support",
                71: "a zero pivot in an LU factorization", 76: "an error in an external library (hypre, MUMPS, ...)",
                77: "an error in an external library (hypre, MUMPS, ...)",
                81: "a zero pivot in a Cholesky factorization (the matrix is not positive definite)",
                82: "a failed inner iteration", 84: "an integer overflow (too many nonzeros for 32-bit indices)"}


class ConstraintTerm:
    """One set of penalised constraint rows C = G u - g with weights W (a contact pair or a die)."""

    def __init__(self, name, G, g, W, phi, eps_n, closed_tol, gate_of=None, augmented=False, node_local=False,
                 alpha=None, *, digest):
        self.name, self.G, self.g, self.W, self.phi, self.eps_n = name, G, g, W, phi, eps_n
        # a digest of what made this rank's part of G and W (e.g. their triplets): equal digests on every rank,
        # the same rows (System.set_terms keeps J as it is)
        self.digest = digest
        # node_local: every row acts on one node's dofs (a die), so G^T D G lies inside K's 3 x 3 node blocks
        self.node_local = node_local
        self.alpha = alpha         # a contact pair's dimensionless penalty (dies: None)
        # G scaled by the rows' stiffnesses and G^T diag(d) G, kept so that each Jacobian redoes only the
        # product's numeric part (System._jacobian)
        self.DG = self.product = None
        self.G_abs = None        # |G|, for the augmented Lagrangian's round-off (_row_scale)
        self.own = None          # the rows' stiffness on their own nodes (own_stiffness)
        self.sliver = None       # the rows the last Uzawa step kept as penalty rows (next_multipliers)
        # the d the product holds (None once it is changed in place); its pattern (G^T G's) and the pattern's digest
        self.product_d = self.pattern = self.pattern_digest = None
        w = W.getArray()
        self.rows = np.flatnonzero(w > 0)                 # local indices of rows that exist
        self.closed_tol = closed_tol
        self.gate_of = gate_of                            # per existing row: position of its gate row, or -1
        self.augmented = augmented
        self.augmented_tolerance = None         # the Uzawa loop's end: its pair's (set by the contact model)
        # the pressure of a strain of FLOOR_STRAIN on its bodies (set by the contact model): next_multipliers' smallest
        # pressure scale, and Restraint.loose's
        self.pressure_floor = 0.0
        self.lmbda = np.zeros(len(self.rows)) if augmented else None
        self.c = G.createVecLeft()
        self.m = G.createVecLeft()
        self.active = np.zeros(len(self.rows), dtype=bool)
        self.d = np.zeros(len(self.rows))
        self.energy = 0.0
        # first iteration of an increment (formulation.md section 4, zero-gap start): START_TOUCHING closes
        # the rows that touch or penetrate at the start (c >= -closed_tol), START_REACH every row within
        # reach; either way with force of either sign, so the first Newton step solves that glued problem
        # and the semi-smooth iterations open what must open. System.solve_at picks the mode. held_closed (per
        # existing row, or None): rows the last converged increment ended closed, which START_TOUCHING closes too
        self.start = None
        self.held_closed = None
        # per existing row, or None: gate rows (a sticking die's normal rows) that this solve keeps closed, with
        # force of either sign, since its active sets cycled (System._tie_gates)
        self.tied = None

    def row_values(self, u):
        """c = G u - g at u, kept in self.c; returns its existing rows (collective)."""
        self.G.mult(u, self.c)
        self.c.axpy(-1.0, self.g)
        return self.c.getArray()[self.rows]

    def _row_scale(self, u):
        """|G| |u| + |g| on the existing rows: the size of the terms whose sum C is (collective)."""
        if self.G_abs is None:
            self.G_abs = self.G.copy()
            ia, ja, a = self.G_abs.getValuesCSR()
            self.G_abs.setValuesCSR(ia, ja, np.abs(a))
            self.G_abs.assemble()
        ua = u.copy()
        ua.abs()
        out = self.G.createVecLeft()
        self.G_abs.mult(ua, out)
        scale = out.getArray()[self.rows] + np.abs(self.g.getArray()[self.rows])
        for v in (ua, out):
            v.destroy()
        return scale

    def round_off(self, u):
        """Per existing row, the round-off of its multiplier (force per area) at u: the rows' round-off
        eps (|G| |u| + |g|) in C is eps_n eps (|G| |u| + |g|) / W in a multiplier (collective)."""
        return self.eps_n * np.finfo(float).eps * self._row_scale(u) / self.W.getArray()[self.rows]

    def evaluate(self, u):
        """Row values, multipliers and active set at u (collective)."""
        c = self.row_values(u)
        tol = self.closed_tol
        if self.start == START_REACH:
            tol = np.full(len(c), np.inf)
        elif self.start == START_TOUCHING and self.held_closed is not None:
            tol = np.where(self.held_closed, np.inf, tol)
        bilateral = self.start is not None
        if self.tied is not None:
            tol = np.where(self.tied, np.inf, tol)
            bilateral = bilateral | self.tied
        self.energy, m, self.d, self.active = row_response(
            c, self.W.getArray()[self.rows], self.eps_n, self.phi, tol, self.lmbda, self.gate_of, bilateral)
        marr = self.m.getArray()
        marr[:] = 0.0
        marr[self.rows] = m

    def add_force(self, f):
        """f += G^T m: the scatter of G^T is where slave multipliers cross ranks."""
        self.G.multTransposeAdd(self.m, f, f)

    def jacobian(self, d=None):
        """G^T diag(d) G (d: per existing row, default the rows' stiffnesses at the last evaluate), in a matrix the
        term owns and reuses: the product's symbolic part (two thirds of its cost, 212k dofs) is done once
        per search, and the numeric part again only for another d. The matrix is overwritten by the next call
        (whoever changes it in place sets product_d to None); its pattern is G^T G's whatever d."""
        d = self.d if d is None else d
        # product_d is None on every rank or on none; whether d is the same must be too (the product is collective)
        if self.product_d is not None and self.G.getComm().tompi4py().allreduce(np.array_equal(d, self.product_d),
                                                                              op=MPI.LAND):
            return self.product
        dvec = self.G.createVecLeft()
        dvec.set(0.0)
        dvec.getArray()[self.rows] = d
        if self.DG is None:
            self.DG = self.G.copy()
        else:
            self.G.copy(self.DG, PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        self.DG.diagonalScale(L=dvec)
        dvec.destroy()
        self.product = self.G.transposeMatMult(self.DG, self.product)
        self.product_d = np.array(d, dtype=float)
        return self.product

    def stencil(self):
        """G^T G (the product with d = 1): the coupling stencil the Jacobian holds."""
        return self.jacobian(np.ones_like(self.d))

    def stencil_pattern(self):
        """This rank's rows of the stencil's pattern (local row pointers, global columns), the product's whatever
        d: read once, kept with its digest (stencil_digest)."""
        if self.pattern is None:
            ia, ja, _ = self.stencil().getValuesCSR()
            self.pattern, self.pattern_digest = (ia, ja), array_digest(ia, ja)
        return self.pattern

    def stencil_digest(self):
        """A digest of this rank's rows of the stencil's pattern: equal on every rank, the same coupled dofs."""
        self.stencil_pattern()
        return self.pattern_digest

    def destroy(self):
        for mat in (self.G, self.DG, self.product, self.G_abs):
            if mat is not None:
                mat.destroy()

    def own_stiffness(self, stiffness):
        """Per existing row, its penalty's stiffness on the node it belongs to (row 3 k: node k) against the
        elements' there: |G_k|^2 / (W k_n), G_k the row's entries on node k's dofs (W a n, a the mean of node k's
        shape function over the row's points, weighted by it) and k_n the diagonal of K along G_k over the node's
        free dofs (stiffness: K's diagonal on this rank's dofs, NaN on fixed ones); NaN where the node is held all
        along G_k, 0 without entries on it. Uzawa moves a row's gap by its own node: a row whose node barely moves
        its gap (a sliver past an edge: a ~ 0.02 against 0.44) or whose area is a sliver converges by a fixed step
        an update. Kept per term (G does not change)."""
        if self.own is None:
            ia, ja, a = self.G.getValuesCSR()
            row = np.repeat(np.arange(len(ia) - 1), np.diff(ia))
            mine = ja // 3 == (row + self.G.getOwnershipRange()[0]) // 3
            Gk = np.zeros((len(ia) - 1, 3))
            Gk[row[mine], ja[mine] % 3] = a[mine]
            n2 = Gk[self.rows] ** 2
            k = np.asarray(stiffness).reshape(-1, 3)[self.rows // 3]     # G's rows are laid out as the dofs
            free = np.where(np.isnan(k), 0.0, n2)
            size, free_size = n2.sum(axis=1), free.sum(axis=1)
            k_n = np.divide((free * np.nan_to_num(k)).sum(axis=1), free_size, out=np.full(len(k), np.nan),
                            where=free_size > 1e-12 * size)
            self.own = np.divide(size, self.W.getArray()[self.rows] * k_n, out=np.zeros(len(k)), where=size > 0)
        return self.own

    def penalty_share(self):
        """(rows, share): the rows the last next_multipliers kept as penalty rows (slivers) that carry force, and
        their share of the term's normal force (collective). There the answer is the penalty's: an overhang's edge
        rows left the augmented Lagrangian 7.6e-4 from the stiff limit at alpha 1e4, tolerance 1e-6 (hunt35_1)."""
        force = np.abs(self.m.getArray()[self.rows] * self.W.getArray()[self.rows])
        sliver = self.sliver if self.sliver is not None else np.zeros(len(force), dtype=bool)
        comm = self.G.getComm().tompi4py()
        rows, part, total = comm.allreduce(
            np.array([np.sum(sliver & (force > 0)), force[sliver].sum(), force.sum()]), op=MPI.SUM)
        return int(rows), (part / total if total > 0 else 0.0)

    def next_multipliers(self, u, stiffness):
        """The augmented Lagrangian's Uzawa step from the last evaluate, at u, not applied: (new multipliers, their
        relative change, the change's round-off bound, AUGMENTED_ROUND_OFF) (collective). Left unapplied once every
        term has settled, the answer keeps the multipliers it was solved with, so that its contact forces balance
        the bodies' (an applied update would add its change to the forces reported at the same displacement).
        stiffness: System.dof_stiffness()."""
        c = self.c.getArray()[self.rows]
        W = self.W.getArray()[self.rows]
        new = multipliers_update(self.lmbda, c, W, self.eps_n, self.gate_of)
        comm = self.G.getComm().tompi4py()
        # a row whose own stiffness is a sliver of the others' stays a penalty row (no multiplier): Uzawa's step
        # barely moves its gap, and its multiplier grew by the same step at every update. A slave node 1 mm past
        # the other cube's edge (W 3.8e-5 of the largest: 1200 Pa an update, 2 % change after 25 updates); slave
        # nodes 0.05 element past it (W 1.6e-3 of the largest, a ~ 0.024): 43 Pa an update to 1100 Pa, 100x the
        # contact's pressure, and the sliding cubes at alpha 1e2 stopped in 4-64 load steps; at alpha 1e4 they
        # converged holding 5500 Pa (hunt31_4)
        own = self.own_stiffness(stiffness)
        top = comm.allreduce(float(np.nanmax(own, initial=0.0)), op=MPI.MAX)
        sliver = np.nan_to_num(own, nan=np.inf) < AUGMENTED_SLIVER * top
        new[sliver] = 0.0
        self.sliver = sliver
        # the multipliers' round-off (round_off), on the rows that hold one: the floor of the updates' change
        # (AUGMENTED_ROUND_OFF)
        held = ~sliver & ((new > 0) | (self.lmbda > 0))
        noise = np.sum(self.round_off(u)[held] ** 2)
        change, size, count, noise = comm.allreduce(
            np.array([np.sum((new - self.lmbda) ** 2), np.sum(new ** 2), len(new), noise], dtype=float), op=MPI.SUM)
        # relative to the multipliers, or to pressure_floor on every row where they are smaller: a contact that
        # ends touching with no force (unloaded, or a gap closed exactly) has round-off multipliers, whose
        # relative change stayed at 0.2-1.6 for 200 updates (a pair pulled apart, every formulation and rule)
        size = max(size, count * self.pressure_floor ** 2)
        if size == 0:
            return new, 0.0, 0.0
        bound = min(AUGMENTED_ROUND_OFF * np.sqrt(noise / size), AUGMENTED_ROUND_OFF_CAP)
        return new, np.sqrt(change / size), bound


def new_snes(comm, max_it):
    """The run's SNES with qsc's defaults, before the options database has its say (configure_snes)."""
    snes = PETSc.SNES().create(comm=comm)
    snes.setOptionsPrefix("qsc_")
    snes.setType("newtonls")
    options.insert_options({
        "snes_linesearch_type": "basic",          # full semi-smooth Newton steps
        # CG stops on the true residual, so one exact linear solve meets the SNES tolerance
        # (the preconditioned norm left a second Newton step on every linear increment)
        "ksp_norm_type": "unpreconditioned",
    })
    # no absolute floor: the forces scale with the lengths and moduli (a patch test 1e-25 m wide carries 1e-50 N,
    # and an atol of 1e-50 N ended its solve "converged" at u = 0); only an exactly zero residual converges at once
    snes.setTolerances(rtol=1e-10, atol=0.0, stol=1e-10, max_it=max_it)
    ksp = snes.getKSP()
    ksp.setType("cg")
    ksp.getPC().setType("gamg")
    # PETSc's 10000 let a stagnating solve run for many minutes before it said so; the most measured
    # here is ~400 per linear solve (plain CG + GAMG, contact at alpha 1e4, docs/performance.md)
    ksp.setTolerances(rtol=1e-10, max_it=KSP_MAX_IT)
    return snes


def configure_snes(snes):
    """The options database's say on the run's SNES, its KSP and PC: a refused option or a SNES type whose
    stops qsc cannot check is a SceneError (also `qsc check`'s, through check_solver_options)."""
    # a named BoomerAMG gets the tuned defaults too (two cubes merged, 212k dofs, CG: 11.3 s against 33 s
    # with hypre's own and 17-22 s with GAMG, docs/performance.md)
    named_hypre = options.option_value("pc_type") == "hypre"
    added = options.insert_options(preconditioner.HYPRE_DEFAULTS) if named_hypre else {}
    try:
        options.set_from_options(snes, "solver (-qsc_snes_*, -qsc_ksp_*, -qsc_pc_*)")
    finally:
        options.remove_options(added)
    if snes.getType() not in NEWTON_TYPES:
        raise SceneError(f"-qsc_snes_type {snes.getType()}: not a Newton method this solver can check "
                         f"(the active set and the force residual); use one of {', '.join(NEWTON_TYPES)}")


def missing_factor_error(exc):
    """The SceneError for PETSc error 92 (MatGetFactor: no installed package provides the factorization asked
    for), met at a preconditioner's first set-up on every rank."""
    return SceneError("the PETSc options ask for a factorization that no installed package provides (PETSc error "
                      f"92 in {petsc_detail(exc)}): check -qsc_pc_factor_mat_solver_type and "
                      "-qsc_band_pc_factor_mat_solver_type")


def _model_matrix(comm):
    """A small SPD matrix on comm (two nodes of three dofs a rank: a chain of springs held at both ends), for
    `qsc check` to set the run's preconditioner up on."""
    n = 6
    A = PETSc.Mat().createAIJ(((n, None), (n, None)), bsize=3, nnz=(3, 1), comm=comm)
    r0, r1 = A.getOwnershipRange()
    size = A.getSize()[0]
    for i in range(r0, r1):
        A.setValue(i, i, 2.0)
        for j in (i - 3, i + 3):
            if 0 <= j < size:
                A.setValue(i, j, -1.0)
    A.assemble()
    return A


class _ErrorText:
    """A PETSc error as one rank saw it (its code and text), for petsc_detail on every rank."""

    def __init__(self, ierr, text):
        self.ierr, self.text = ierr, text

    def __str__(self):
        return self.text


def _set_up_model(comm, contact_preconditioner):
    """The run's solver set up on the model matrix (check_solver_options): the PETSc.Error its set-up raised,
    or None. A refused option of the solver objects' own is a SceneError already (configure_snes)."""
    snes = new_snes(comm, 50)
    A = None
    try:
        configure_snes(snes)
        A = _model_matrix(comm)
        ksp = snes.getKSP()
        if contact_preconditioner is not None and preconditioner.wants_band(contact_preconditioner, True):
            preconditioner.install_band_pc(ksp, np.arange(*A.getOwnershipRange(), dtype=PETSc.IntType), comm)
        ksp.setOperators(A, A)
        try:
            ksp.setUp()
        except PETSc.Error as exc:
            return exc
        return None
    finally:
        snes.destroy()
        if A is not None:
            A.destroy()


def _options_at_fault(comm, contact_preconditioner):
    """The -qsc_ options without which the model's set-up passes, one left out at a time (collective: every
    rank holds the same database), as "-name value". A factorization package reads its options
    (-qsc_mat_mumps_icntl_7 99) only when it factors, and its message names neither the option nor always the
    value."""
    database = PETSc.Options()
    at_fault = []
    for name, value in options.options_in_effect().items():
        if not name.startswith(options.PREFIX):
            continue
        database.delValue(name)
        try:
            passes = _set_up_model(comm, contact_preconditioner) is None
        except SceneError:
            passes = False
        finally:
            database.setValue(name, value)
        if passes:
            at_fault.append((name.endswith("_type"), f"-{name}" + (f" {value}" if value else "")))
    # a type option passes by choosing an object that reads no such option (-qsc_pc_type lu): named only alone
    return [named for chooses, named in at_fault if not chooses] or [named for _, named in at_fault]


def check_solver_options(comm, contact_preconditioner=None):
    """What the run's solver set-up would say of the options database (collective): `qsc check`'s, and the run's
    before it touches its folder. The preconditioner is also set up, on a small model matrix (_model_matrix), as
    the run would set it up: with contact_preconditioner (a scene's solver.contact_preconditioner, given when it
    has contact pairs) the band composite where the run would use it, so that a factorization package
    (-qsc_pc_factor_*, -qsc_band_pc_factor_*), the options it reads when it factors (-qsc_mat_mumps_*,
    -qsc_band_mat_mumps_*) and the contact band's own options (-qsc_band_*) are met before the run: the run
    failed on them at its first factorization, exit 3, "solve failed" (hunt34_3). A set-up that fails there
    for another reason is left to the run (a model matrix is not the run's)."""
    exc = _set_up_model(comm, contact_preconditioner)
    # the first rank's error that met one (an option's is every rank's: they hold the same database)
    errors = comm.allgather(None if exc is None else (exc.ierr, str(exc)))
    ierr, text = next((e for e in errors if e is not None), (0, ""))
    exc = _ErrorText(ierr, text)      # a PETSc.Error's text is its own rank's PETSc traceback
    if ierr == PETSC_ERR_MISSING_FACTOR:
        raise missing_factor_error(exc)
    if ierr not in options.OPTION_ERRORS:
        return
    at_fault = _options_at_fault(comm, contact_preconditioner)
    if not at_fault:
        raise SceneError(f"PETSc options: {options.refused_option(exc)}")
    raise SceneError(f"PETSc options: the solver's set-up refuses {', '.join(at_fault)} (PETSc error {ierr} in "
                     f"{petsc_detail(exc)})")


class System:
    """K0 u - t b + sum_terms G^T m with Dirichlet rows u_i - t ubar_i, solved by SNES.

    K: the stiffness, whose Dirichlet rows and columns are taken out here (MatZeroRowsColumns), or K0 already
    when `lifting` (what its fixed columns took from the load, elimination.py) is given."""

    def __init__(self, K, f_ext, bc_dofs, bc_values, nullspace, comm, max_it=50, contact_pc="auto", band_layers=1,
                 slip_modes=None, multigrid_alpha=None, k_stencil_digests=(), lifting=None, strain_fields=None):
        self.comm = comm
        # kept for _all_failed alone: no other collective ever runs on it, whatever the ranks were doing
        self.agree_comm = comm.Dup()
        # contact_pc: "auto" | "band" | "none" (see preconditioner.py); band_dofs: size of the last band
        self.contact_pc, self.band_layers, self.band_dofs = contact_pc, band_layers, 0
        # the band preconditioner's coarse space (assembly.slip_modes: blocks of modes on owned dofs) or None
        self.slip_modes = slip_modes
        # the contact pairs' dimensionless penalty in the operator BoomerAMG is set up on (None: their own)
        self.multigrid_alpha = multigrid_alpha
        self.u = K.createVecRight()
        self.u.set(0.0)
        ubar = self.u.duplicate()
        ubar.set(0.0)
        ubar.setValues(bc_dofs.astype(PETSc.IntType), bc_values)
        ubar.assemble()
        self.ubar = ubar
        self.b = f_ext.copy()
        if lifting is None:
            K.zeroRowsColumns(bc_dofs.astype(PETSc.IntType), 1.0, ubar, self.b)   # K0 and its lifting
        else:                      # K is K0 already (elimination.py): b as zeroRowsColumns would leave it
            b = self.b.getArray()
            b -= lifting
            b[bc_dofs - self.u.getOwnershipRange()[0]] = bc_values
        # the Newton test's force scale leaves the Dirichlet rows out: they hold u_i - t ubar_i (metres, diagonal 1),
        # which outweighed every force in a soft or small body (E = 1e-12 Pa, or a box 1e-20 m wide, driven by a
        # prescribed displacement: "converged" at once with every free node at rest)
        self.bc_local = (bc_dofs - self.u.getOwnershipRange()[0]).astype(np.int64)
        self.stiffness = None        # K's diagonal, NaN on fixed dofs (dof_stiffness)
        self.free_local = np.ones(self.u.getLocalSize(), dtype=bool)
        self.free_local[self.bc_local] = False
        self.b_norm = self._free_norm(self.b)
        # the Newton test's scale is never below the elastic forces of a strain of FLOOR_STRAIN of the softest
        # body (strain_fields: assembly.dilatations): with no load at all, |K u| and t |b| are round-off
        # themselves, and a contact scene whose gaps are round-off (coinciding faces, a die that does not move)
        # sat at a residual of 6.5e-14 N for 60 Newton iterations against a target of ~1e-24 and failed. The
        # softest, not all: a cube of E = 1e3 pressed 1 % on one of 1e12 was solved to 2.5e-7 in force under a
        # floor from both (hunt27_4)
        forces = K.createVecLeft()
        scales = []
        for field in strain_fields or ():
            K.mult(field, forces)
            scales.append(self._free_norm(forces))
        forces.destroy()
        self.force_floor = FLOOR_STRAIN * min((f for f in scales if f > 0), default=0.0)
        K.setNearNullSpace(nullspace)
        self.K = K
        self.bc_dofs = bc_dofs.astype(PETSc.IntType)
        self.terms = []
        self.J = K
        self.t = 0.0
        self.force_scale = 0.0     # max(|K u|, t |b|, force_floor) on the free dofs at the last residual: the Newton test's scale
        self.prev_active = None
        # free_motions(terms, active_only) -> "" or the rigid motions the boundaries and rows leave free
        # (restraint.Restraint); a solve never converges to an active set that leaves a body free with a load on
        # it: free_load(terms, r) -> the largest force the residual r puts on those motions (None: any is loaded)
        self.free_motions = self.free_load = None
        self.free_now = self.free_seen = ""
        # active-set cycling guard (_converged, _damp): the active sets this solve has met, {signature: last
        # iteration}, and the iteration from which Newton steps are damped (None: full steps)
        self.sets_seen = {}
        self.damped_from = None
        self.cycled = False         # an active set came back (_watch_cycles): sticking-die rows are tied
        self.fnorms = []
        self.damped_steps = 0
        self.step_scale = 1.0
        self.tied_rows = 0
        # the residual norm of the previous iteration, and the relative residual at which a solve stopped on the
        # round-off floor (None: it met the target)
        self.last_fnorm = None
        self.floor = None
        self.linear_short = False      # the last solve stopped on a linear solve that ended far above the target
        self.own_options = set()       # options this system set (removed by destroy)
        # the rows' stiffnesses d the Jacobian holds: between two searches J = K + sum G^T diag(d) G depends
        # on u through d only, so an unchanged d keeps J, and the preconditioner built on it, as they are
        self.jacobian_d = None
        # per term that couples nodes (not node_local), a digest of this rank's G^T G pattern at the last search:
        # a search whose rows couple the same dofs keeps J's pattern (set_terms)
        self.stencil_signature = None
        # the same for the contact stencils K's pattern was assembled with (ContactModel.prepare): a search with
        # those makes J as K's copy, without widening its pattern; and whether J's pattern is K's
        self.k_stencil_signature = list(k_stencil_digests)
        self.j_pattern_is_k = True
        # per term, a digest of this rank's rows (G's pattern and values, the rows that exist): a search that
        # finds the very same rows keeps J with its stiffnesses
        self.rows_signature = None
        # the contact band's preconditioner: this rank's band dofs (None: no band), the Parts its two halves share,
        # a digest of the rows active when it was last set up, whether the next Jacobian may keep it as it is
        # (a new search that kept J's pattern and the band) and whether it is kept while J changed
        self.band = self.band_parts = self.pc_rows = None
        self.search_stencils = self.pc_stencils = None   # the pairs' G^T G: this search's, the preconditioner's
        self.pc_candidate = self.pc_stale = False
        self.jacobian_rebuilds = 0
        # the Krylov stop follows the Newton test (KSP atol = KRYLOV_MARGIN x SNES target) unless the user set one
        self.ksp_atol_auto = options.option_value("ksp_atol") is None
        self.mumps_relaxation = None   # MUMPS ICNTL(14) [%] once raised after a workspace failure
        # per term name: which of this rank's rows (G's local row range, 3 per owned node: the same at every
        # search) the last converged solve ended closed; the next increment starts with them closed
        self.closed_rows = {}

        self.snes = new_snes(comm, max_it)
        self.r = self.u.duplicate()
        self.snes.setFunction(self._residual, self.r)
        self.snes.setJacobian(self._jacobian, self.J, self.J)
        self.snes.setConvergenceTest(self._converged)
        self.snes.setLineSearchPreCheck(self._damp)
        configure_snes(self.snes)
        self.test_reason = 0           # what _converged last answered: a solve converges by it alone
        self.mumps_cap = self._mumps_memory_cap(available_memory)

    def _mumps_memory_cap(self, available):
        """The MB a MUMPS factorization solving the system (-qsc_pc_type lu or cholesky with MUMPS, named or PETSc's
        own choice on several ranks) may take on each rank, its ICNTL(23): -qsc_mat_mumps_icntl_23 if set, else
        MUMPS_MEMORY_SHARE of each rank's share of its node's available memory, the least over the nodes
        (collective; set around each solve by _mumps_options). (cap, where it comes from) or None.

        Past the cap MUMPS stops after its analysis (INFOG(1) = -19), which _more_mumps_workspace turns into an
        error naming the memory; without it the kernel refuses the allocation or ends the run midway through
        the factorization, without a word. MUMPS sizes its main work array within the cap but touches only what
        the factors use (70k dofs, 2 ranks: peak memory 1.93 -> 1.99 GB with a cap of 8000 MB)."""
        if not self._factors_with_mumps():
            return None
        own = options.option_value("mat_mumps_icntl_23")
        if own is not None:         # the user's (PETSc itself refuses a value that is not an integer)
            try:
                return (int(own), "-qsc_mat_mumps_icntl_23") if int(own) > 0 else None
            except ValueError:
                return None
        ranks, free = node_memory(self.comm, available)
        share = self.comm.allreduce(np.inf if free is None else free / ranks, op=MPI.MIN)
        if not np.isfinite(share):
            return None
        return (max(int(MUMPS_MEMORY_SHARE * share / 1e6), 1),
                f"{MUMPS_MEMORY_SHARE:.0%} of a rank's share of its node's available memory")

    def dof_stiffness(self):
        """K's diagonal on this rank's dofs, NaN on the fixed ones (whose rows hold 1): the elements' stiffness at
        each free dof (ConstraintTerm.own_stiffness). Kept: K does not change."""
        if self.stiffness is None:
            diagonal = self.K.getDiagonal()
            self.stiffness = diagonal.getArray().copy()
            diagonal.destroy()
            self.stiffness[self.bc_local] = np.nan
        return self.stiffness

    def _factors_with_mumps(self):
        """Whether the solver's PC is a MUMPS factorization (options.factored_by_mumps)."""
        return options.factored_by_mumps(self.snes.getKSP().getPC())

    @contextmanager
    def _mumps_options(self):
        """The memory cap in the options database while a solve may make a MUMPS factor (it reads its options
        then), and out of it after: a run that is not destroyed leaves no cap for the next run to take as the
        user's."""
        name = "qsc_mat_mumps_icntl_23"
        ours = self.mumps_cap is not None and self.mumps_cap[1] != "-" + name
        if ours:
            PETSc.Options().setValue(name, self.mumps_cap[0])
        try:
            yield
        finally:
            if ours:
                PETSc.Options().delValue(name)

    def set_terms(self, terms):
        """Install the constraint terms of a new search, keeping what it did not change (collective).

        J holds the union of K's pattern and every term's G^T G, with the rows' stiffnesses jacobian_d;
        _jacobian then adds only what the active set changes. The very same rows as the last search keep J
        and its stiffnesses; a coupling stencil with the last one's pattern keeps J's pattern (values reset
        to K); any other search builds J anew: as K's copy if K's pattern holds the stencil already (the first
        search, made before K: ContactModel.prepare), else widened by MatAXPY, which re-inserts every entry
        of K row by row (0.42 s at 212k dofs). The contact band's preconditioner objects stay when J's
        pattern and the band do (_keep_or_rebuild_pc may then keep its setup too)."""
        self.terms = terms
        self.prev_active = None
        rows = [term.digest for term in terms]
        if terms and self.J is not self.K and self.comm.allreduce(rows == self.rows_signature, op=MPI.LAND):
            # every row as the last search's (a die with nothing else, a pair's kept term): J = K + sum G^T
            # diag(d) G as it is, with the stiffnesses it holds, and the band and the preconditioner objects it
            # had; an unchanged active set keeps them all untouched (the terms make their products when asked)
            self.pc_candidate = False
            return
        # G^T G of every term (the terms keep the product for their Jacobians): the Jacobian's contact stencil,
        # and the contact pairs' band for the preconditioner
        stencils = [term.stencil() for term in terms]
        # a die's rows act on one node each: its stencil is inside K's pattern already; a pair whose search found
        # nothing (its surfaces came apart) couples nothing (and MatAXPY of its empty stencil into J left J
        # with values PETSc's LU read as a zero pivot)
        counts = self.comm.allreduce(np.array([len(term.rows) for term in terms], dtype=np.int64), op=MPI.SUM)
        pairs = [term for term, n in zip(terms, counts) if not term.node_local and n]
        coupling = [GtG for term, GtG, n in zip(terms, stencils, counts) if not term.node_local and n]
        signature = [term.stencil_digest() for term in pairs]
        kept = bool(terms) and self.J is not self.K and self.comm.allreduce(signature == self.stencil_signature,
                                                                             op=MPI.LAND)
        if not terms:
            self.J = self.K
        elif kept:
            # the new rows couple the same dofs as the last search's (a flat contact): J keeps its pattern
            self._reset_to_stiffness(self.J)
        else:
            J = self.K.copy()
            in_k = self.comm.allreduce(signature == self.k_stencil_signature, op=MPI.LAND)
            self.j_pattern_is_k = in_k or not coupling
            if not self.j_pattern_is_k:
                pattern = coupling[0].copy()
                for GtG in coupling[1:]:      # summed first: one pass over K's rows, not one per term
                    pattern.axpy(1.0, GtG, PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
                pattern.zeroEntries()
                J.axpy(1.0, pattern, PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
                pattern.destroy()
            assembly.plain_rows(J)         # a new pattern's matrix is PETSc's, with its defaults
            J.setNearNullSpace(self.K.getNearNullSpace())
            if self.J is not self.K:
                self.J.destroy()
            self.J = J
        self.stencil_signature, self.rows_signature = signature, rows
        self.snes.setJacobian(self._jacobian, self.J, self.J)
        self.jacobian_d = [np.zeros_like(term.d) for term in terms]
        # the stencils that couple nodes are the contact pairs' (dies are node-local): the band follows them
        if preconditioner.wants_band(self.contact_pc, bool(coupling)):
            # J's pattern and the band of the last search keep its preconditioner objects: the next setup is
            # numeric only (the band's symbolic factorization and the composite's construction are not redone).
            # The band is a function of the stencils' pattern, so a kept pattern keeps it
            same = kept and self.band is not None
            band = self.band if same else preconditioner.band_dofs(
                self.K, [term.stencil_pattern() for term in pairs], self.band_layers)
            if not same:
                self.band_dofs, self.band_parts = preconditioner.install_band_pc(
                    self.snes.getKSP(), band, self.comm, self.slip_modes,
                    self.softened if self.multigrid_alpha is not None else None)
                self.band, self.pc_rows = band, None
            # the first Jacobian may keep the preconditioner as it is (_keep_or_rebuild_pc) if the rows barely moved
            self.pc_candidate = same and self._stencils_close(pairs, coupling)
            self.search_stencils = [GtG.copy() for GtG in coupling]

    def _residual(self, snes, u, f):
        self.K.mult(u, f)
        # the residual is measured against the elastic force scale, not F(u0): a prescribed die
        # motion starts with penalty forces many orders above the loads the solution carries
        self.force_scale = max(self._free_norm(f), self.t * self.b_norm, self.force_floor)
        f.axpy(-self.t, self.b)
        for term in self.terms:
            term.evaluate(u)
        if self.terms:
            fc = f.duplicate()
            fc.set(0.0)
            for term in self.terms:
                term.add_force(fc)
            fc.getArray()[self.bc_local] = 0.0
            f.axpy(1.0, fc)
            fc.destroy()

    def own_force_scale(self, u):
        """max(|K u|, t |b|) on the free dofs at u: the Newton test's force scale without its floor (collective)."""
        f = self.K.createVecLeft()
        self.K.mult(u, f)
        scale = max(self._free_norm(f), self.t * self.b_norm)
        f.destroy()
        return scale

    def _free_norm(self, v):
        """The 2-norm of v's entries on the free (not Dirichlet) dofs (collective)."""
        a = v.getArray(readonly=True)[self.free_local]
        top = self.comm.allreduce(float(np.abs(a).max(initial=0.0)), op=MPI.MAX)
        if top == 0.0:
            return 0.0
        return top * np.sqrt(self.comm.allreduce(float(np.sum((a / top) ** 2)), op=MPI.SUM))  # no underflow

    def _jacobian(self, snes, u, J, P):
        self._match_krylov_to_newton(snes)
        if not self.terms:
            return
        # per term: 1 if its rows' stiffnesses changed, 2 if some row opened (a stiffness fell)
        mine = np.array([0 if np.array_equal(term.d, held) else 2 if np.any(term.d < held) else 1
                         for term, held in zip(self.terms, self.jacobian_d)], dtype=np.int64)
        changed = np.zeros_like(mine)
        self.comm.Allreduce(mine, changed, op=MPI.MAX)
        for term in self.terms:
            term.start = None       # the closed start was this iterate's; the next residual sees the true set
        self._keep_or_rebuild_pc(changed.any())
        if not changed.any():
            return        # J untouched: its state is unchanged, so PCSetUp keeps the preconditioner too
        self.jacobian_rebuilds += 1
        if changed.max() == 2:
            # a row opened: subtracting its penalty (1e2-1e10 x K) would leave round-off of that size in J,
            # enough to make a free body's singular J solvable and its iterates jump; rebuild from K instead
            self._reset_to_stiffness(J)
            held = [np.zeros_like(term.d) for term in self.terms]
            changed = np.ones_like(changed)
        else:
            held = self.jacobian_d
        for i in np.flatnonzero(changed):
            term = self.terms[i]
            J.axpy(1.0, self._jacobian_part(term, term.d - held[i]), SUBSET)      # J += G^T diag(d - d_held) G
        self.jacobian_d = [term.d.copy() for term in self.terms]

    @contextmanager
    def softened(self, P):
        """P (the Jacobian) with each contact pair's rows at the penalty multigrid_alpha instead of the pair's
        own while the block is open, then P as it was (collective): P += (s - 1) G^T diag(d) G per pair with
        alpha up to SOFTENED_UP_TO, s = max(multigrid_alpha / alpha, SOFTEST), d the stiffnesses P holds, held
        dofs left out, and taken off again after. BoomerAMG copies the operator at its setup, so only its
        coarse spaces and smoothers see the softer interface. P's object state is put back too: its values
        are its own again (to round-off), and a changed state would make every PC on it set itself up anew at
        the next solve."""
        parts = []
        for term, d in zip(self.terms, self.jacobian_d or []):
            if (term.node_local or term.alpha is None or term.alpha <= self.multigrid_alpha
                    or term.alpha > SOFTENED_UP_TO):
                continue
            parts.append((max(self.multigrid_alpha / term.alpha, SOFTEST) - 1.0, self._jacobian_part(term, d)))
        state = P.stateGet()
        for factor, C in parts:
            P.axpy(factor, C, SUBSET)
        try:
            yield
        finally:
            for factor, C in parts:
                P.axpy(-factor, C, SUBSET)
            P.stateSet(state)

    def _jacobian_part(self, term, d):
        """G^T diag(d) G of a term as J takes it: held dofs' rows and columns left out (K's are already identity).
        The term's own product matrix, overwritten by its next jacobian call."""
        C = term.jacobian(d)
        C.zeroRowsColumns(self.bc_dofs, 0.0)
        term.product_d = None
        return C

    def _reset_to_stiffness(self, J):
        """J's values set to K's, its pattern (K's and the contact stencil's) kept: a copy when the patterns are
        one (MatAXPY into a wider pattern goes row by row)."""
        if self.j_pattern_is_k:
            self.K.copy(J, PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
            return
        J.zeroEntries()
        J.axpy(1.0, self.K, SUBSET)

    def _keep_or_rebuild_pc(self, j_changes):
        """Whether the band preconditioner stays as it is for the next linear solves (collective). The first
        Jacobian of a search that kept J's pattern and the band (set_terms) keeps it when the rows active now
        are the rows it was set up for: between the two searches only the projections moved (two cubes between
        dies, 212k dofs: the second increment's multigrid setup and band factorization, 0.6-0.8 s of 16 s,
        saved at the same Krylov count). It stays until J changes again."""
        if self.band_parts is None:
            return
        digest = None
        if self.pc_candidate or j_changes:     # the global ids of the active rows, term by term
            digest = array_digest(*[np.append(term.c.getOwnershipRange()[0] + term.rows[term.active], -1)
                               for term in self.terms])
        if self.pc_candidate:
            self.pc_candidate = False
            self.pc_stale = self.comm.allreduce(digest == self.pc_rows, op=MPI.LAND)
        elif j_changes:
            self.pc_stale = False
        if j_changes and not self.pc_stale:
            self.pc_rows = digest             # the rows the preconditioner is set up again for
            self.pc_stencils = self.search_stencils
        self.band_parts.keep = self.pc_stale

    def _stencils_close(self, pairs, stencils):
        """Whether each contact pair's G^T G moved by at most STALE_CHANGE / alpha of the one the preconditioner
        was set up with (collective; same pattern). alpha x that relative change is the change in the interface's
        stiffness against the elements' own: the rows of a body sliding on another change every search."""
        if self.pc_stencils is None or len(self.pc_stencils) != len(stencils):
            return False
        for term, new, old in zip(pairs, stencils, self.pc_stencils):
            if term.alpha is None:
                return False
            change = new.copy()
            change.axpy(-1.0, old, PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
            moved, scale = change.norm(PETSc.NormType.INFINITY), old.norm(PETSc.NormType.INFINITY)
            change.destroy()
            if term.alpha * moved > STALE_CHANGE * scale:
                return False
        return True

    def _match_krylov_to_newton(self, snes):
        """Stop the linear solve once its residual, the next Newton residual while the active set holds, is
        KRYLOV_MARGIN below the Newton target rtol x force scale: the KSP rtol alone, relative to a residual
        already near the target, over-solved the last Newton step of every increment by 6-7 orders."""
        ksp = snes.getKSP()
        if not self.ksp_atol_auto or ksp.getNormType() != PETSc.KSP.NormType.UNPRECONDITIONED:
            return
        target = KRYLOV_MARGIN * snes.getTolerances()[0] * self.force_scale
        ksp.setTolerances(atol=target)       # rtol, divtol, max_it as they are

    def active_count(self):
        return self.comm.allreduce(int(sum(t.active.sum() for t in self.terms)), op=MPI.SUM)

    def _converged(self, snes, it, norms):
        """SNES's convergence test (_newton_test), its answer kept: a positive reason SNES sets by itself (a trust
        region's own stop) is no convergence (solve_at)."""
        self.test_reason = self._newton_test(snes, it, norms)
        return self.test_reason

    def _newton_test(self, snes, it, norms):
        xnorm, ynorm, fnorm = norms
        active = np.concatenate([t.active for t in self.terms]) if self.terms else np.zeros(0, bool)
        changed = 0 if self.prev_active is None else int(np.sum(active != self.prev_active))
        changed = self.comm.allreduce(changed, op=MPI.SUM)
        first = self.prev_active is None
        self.prev_active = active.copy()
        rtol, atol, stol, max_it = snes.getTolerances()
        self._watch_cycles(it, active, fnorm)
        if self.cycled:
            self._tie_gates()
        last_fnorm, self.last_fnorm = self.last_fnorm, fnorm
        if it == 0:
            self.floor, self.linear_short = None, False
            # only with nothing to solve: a -qsc_snes_atol above the first residual ended the solve before its
            # first step, the bodies at rest and "ok" (hunt34_3); after a step it stops as it says
            return PETSc.SNES.ConvergedReason.CONVERGED_FNORM_ABS if fnorm == 0.0 else 0
        if not np.isfinite(fnorm):
            return PETSc.SNES.ConvergedReason.DIVERGED_FNORM_NAN
        if self.free_motions is not None and self.terms and (changed or first):
            # with a body free the Jacobian is singular: a direct solver's answer is round-off in that motion
            self.free_now = self.free_motions(self.terms, True)
            self.free_seen = self.free_now or self.free_seen
        if changed == 0 and not first:
            # ... but a body floating with nothing on it between open rows is an equilibrium (one of many, said by
            # the run): its iterations go on, the Jacobian singular along a motion the residual does not load
            if self.free_now and (self.free_load is None or
                                  self.free_load(self.terms, snes.getFunction()[0]) > rtol * self.force_scale):
                return PETSc.SNES.ConvergedReason.DIVERGED_JACOBIAN_DOMAIN
            if fnorm <= atol:
                return PETSc.SNES.ConvergedReason.CONVERGED_FNORM_ABS
            if fnorm <= rtol * self.force_scale:
                return PETSc.SNES.ConvergedReason.CONVERGED_FNORM_RELATIVE
            if ynorm <= stol * xnorm * self.step_scale:
                if not self._krylov_reached(rtol * self.force_scale):
                    # the linear solve stopped before its first iteration, far above the target (a -qsc_ksp_atol
                    # above the residual): its zero step is no round-off floor (reactions 9 % off, exit 0; hunt30_6)
                    self.linear_short = True
                    return PETSc.SNES.ConvergedReason.DIVERGED_LINEAR_SOLVE
                self.floor = fnorm / self.force_scale
                return PETSc.SNES.ConvergedReason.CONVERGED_SNORM_RELATIVE
            before = self.fnorms[-3] if len(self.fnorms) >= 3 else None
            if self._on_floor(it, fnorm, last_fnorm, rtol * self.force_scale, before):
                self.floor = fnorm / self.force_scale
                return PETSc.SNES.ConvergedReason.CONVERGED_SNORM_RELATIVE
        if it >= max_it:
            return PETSc.SNES.ConvergedReason.DIVERGED_MAX_IT
        return 0

    def _krylov_reached(self, target):
        """Whether the last linear solve's step may be taken for the answer's last correction: a direct solve's,
        one that iterated (at a round-off floor its iterations stop on the rows' round-off, far above the target:
        the sliding cubes at alpha 1e8-1e10, hunt29_3), or one whose residual was already within FLOOR_SPAN of the
        target. A solve that stopped before its first iteration above that made no step at all (a -qsc_ksp_atol
        above the residual)."""
        ksp = self.snes.getKSP()
        if ksp.getType() == PETSc.KSP.Type.PREONLY or ksp.getIterationNumber() > 0:
            return True
        try:
            if ksp.getNormType() != PETSc.KSP.NormType.UNPRECONDITIONED:
                return True
        except PETSc.Error:
            return True
        return ksp.getResidualNorm() <= FLOOR_SPAN * target

    def _on_floor(self, it, fnorm, last_fnorm, target, before=None):
        """Whether the residual sits on the linear solves' round-off floor: the last step was taken with the
        active set it ended with (an exact linearisation) and a converged Krylov solve aimed below
        KRYLOV_MARGIN x target, yet the residual fell by less than FLOOR_REDUCTION; and it is within FLOOR_SPAN
        of the target (a Newton method that stalls far above it, e.g. on a wrong Jacobian, is not
        converged). A slender cantilever (20 x 1 x 1, 160 x 8 x 8 hexes, CG + GAMG, 2 ranks) stood at 1.8e-9 of
        its force scale after its first Newton step, for a target of 1e-10; two more steps of 14 and 13
        Krylov iterations left it at 1.1e-9. A direct solve (KSP preonly) needs two such steps in a row (`before`:
        the residual before last_fnorm): its next step costs a triangular solve with the factors it has, and
        may still refine (patch test 4/7, alpha 1e8, MUMPS: the third step took the force balance from 7.8e-9 to
        1.3e-9 of p A); two_pass with no load (round-off gaps, MUMPS) stood at 2.2e-13, 1.95e-13, ... down to
        1.7e-13 for 60 steps against a target of 6.4e-14 (hunt27_4)."""
        ksp = self.snes.getKSP()
        stalled = (it >= 2 and last_fnorm is not None and fnorm > FLOOR_REDUCTION * last_fnorm
                   and fnorm <= FLOOR_SPAN * target and ksp.getConvergedReason() > 0)
        if ksp.getType() != PETSc.KSP.Type.PREONLY:
            return stalled
        return stalled and it >= 3 and before is not None and last_fnorm > FLOOR_REDUCTION * before

    def _watch_cycles(self, it, active, fnorm):
        """Damp the Newton steps from the iteration at which the active set returns to one it had two or more
        iterations before (collective). Full semi-smooth steps can cycle among a few sets whose rows sit at
        the contact edge: hertz_xfine with two_pass, started from the previous state, repeated the same six
        residual norms from its 31st iteration (the 31st set came back at the 37th) and did not settle
        within 50 or 120; damped from the 37th it converged at the 41st. Also from the iteration that ends
        STALL_WINDOW iterations without a new lowest residual (fnorm). `cycled`: a set came back."""
        if it == 0:
            self.sets_seen, self.damped_from, self.cycled, self.fnorms = {}, None, False, []
        self.fnorms.append(fnorm)
        digest = array_digest(np.packbits(active))
        signature = tuple(self.comm.allgather(digest))
        if self.sets_seen.get(signature, it) < it - 1:
            self.cycled = True
        # or wandering: no new lowest residual in STALL_WINDOW iterations, the sets never quite repeating (two_pass,
        # a cube dragged 0.4 m by a sticking die, large sliding: residuals 1e2-1e3 over 50 iterations, twice)
        stalled = it > STALL_WINDOW and min(self.fnorms[-STALL_WINDOW:]) > min(self.fnorms[:-STALL_WINDOW])
        if self.damped_from is None and (self.cycled or stalled):
            self.damped_from = it
        self.sets_seen[signature] = it

    def _tie_gates(self):
        """Once the active sets cycle (_watch_cycles), every closed gate row (a sticking die's normal row) stays
        closed, with force of either sign, for the rest of the solve (collective). A sticking node's tangential
        rows act only while its normal row is closed, so its force jumps when that row opens: a node whose
        pressure would be about zero either way has no answer, and no damping finds one (a cube dragged 0.5 m
        sideways by a sticking die, large sliding: full steps from the 3rd Newton iteration alternated between
        residuals 1.6e-2 and 1.06, one die node stuck and let go, until the 50th). Tied, it keeps the small
        tension it needs; the summary counts these rows (tied_rows). Rows closed now only: F and J at the
        current iterate do not change."""
        tied = 0
        for term in self.terms:
            if term.gate_of is None:
                continue
            gates = np.zeros(len(term.rows), dtype=bool)
            gates[term.gate_of[term.gate_of >= 0]] = True
            closed = gates & term.active
            term.tied = closed if term.tied is None else term.tied | closed
            tied += int(term.tied.sum())
        self.tied_rows = self.comm.allreduce(tied, op=MPI.SUM)

    def _tied_in_tension(self):
        """How many tied gate rows carry a tensile force at the last evaluate (collective)."""
        count = sum(int(np.sum(term.tied & (term.m.getArray()[term.rows] < 0.0)))
                    for term in self.terms if term.tied is not None)
        return self.comm.allreduce(count, op=MPI.SUM)

    def _damp(self, x, y):
        """Line-search pre-check (the step is x - y): once cycling was seen (_watch_cycles), halve y until the
        residual norm falls below (1 - 1e-4 lambda) of the current one, at most DAMPING_HALVINGS times
        (a backtracking line search on |F|; the semi-smooth Newton direction descends |F|^2). Returns
        whether y changed."""
        self.step_scale = 1.0
        if self.damped_from is None:
            return False
        f0 = self.snes.getFunctionNorm()
        trial, r = x.duplicate(), x.duplicate()
        lam = 1.0
        try:
            for halving in range(DAMPING_HALVINGS):
                trial.waxpy(-lam, y, x)
                self._residual(self.snes, trial, r)
                if r.norm() <= (1.0 - 1e-4 * lam) * f0 or halving == DAMPING_HALVINGS - 1:
                    break           # the last one tried, not a half of it that was not
                lam *= 0.5
        finally:
            trial.destroy()
            r.destroy()
        if lam == 1.0:
            return False
        y.scale(lam)
        # the Newton test's step size reads the undamped step: a step shrunk to 1/256 where no halving lowered the
        # residual passed stol x |u|, the residual at 1.4 of its force scale, a body out of balance by 70 % of the
        # normal force, "ok" (hunt35_1)
        self.step_scale = lam
        self.damped_steps += 1
        return True

    def solve_at(self, t, u0):
        """One SNES solve at load factor t from initial guess u0; returns (ok, stats)."""
        self.t = t
        self.prev_active = None
        self.free_now = self.free_seen = ""
        rebuilds = self.jacobian_rebuilds
        self.damped_steps = 0
        self.step_scale = 1.0         # the last Newton step's share of its undamped length (_damp)
        self.tied_rows = 0
        for term in self.terms:
            term.tied = None
        start = None
        while True:
            u = u0.copy()
            u.getArray()[self.bc_local] = t * self.ubar.getArray()[self.bc_local]
            if start is None:
                start = self._start_mode(u)
            for term in self.terms:
                term.start = start
            self.test_reason = 0
            try:
                with self._mumps_options():
                    self.snes.solve(None, u)
            except PETSc.Error as exc:     # on every rank: the reason is collective; a failed solve like any other
                if exc.ierr == PETSC_ERR_MISSING_FACTOR:     # met at the first factorization, on every rank
                    raise missing_factor_error(exc) from None
                if exc.ierr in (56, 65) and "iewer" in petsc_detail(exc) and _all_failed(self.agree_comm):
                    # a viewer option read at the solve's end (-qsc_ksp_converged_reason true): the options'
                    # fault, as at set-up (options.set_from_options)
                    raise SceneError(f"PETSc options: {options.refused_option(exc)}") from None
                if exc.ierr != PETSC_ERR_NOT_CONVERGED:
                    if not _all_failed(self.agree_comm):
                        raise
                    raise ConvergenceError(
                        f"PETSc error {exc.ierr} ({PETSC_ERRORS.get(exc.ierr, 'see its message')}) on every rank "
                        f"inside the solve at load factor {t:.6g}, in {petsc_detail(exc)} (a solver option the "
                        f"library rejects, e.g. one of -qsc_pc_hypre_*, is a usual cause)") from None
            if self.snes.getConvergedReason() > 0 or not self._more_mumps_workspace():
                break
            u.destroy()
        if self.snes.getConvergedReason() <= 0:
            # a try that met a singular matrix (an iterate that left a body free): the next one makes new factors
            options.reset_failed_mumps(self.snes.getKSP().getPC())
        # held dofs stay at their values up to the Krylov tolerance: put them back exactly
        u.getArray()[self.bc_local] = t * self.ubar.getArray()[self.bc_local]
        reason = self.snes.getConvergedReason()
        ksp_reason = self.snes.getKSP().getConvergedReason()
        if reason == 0 and ksp_reason < 0:      # stopped inside the linear solve, before SNES set its reason
            reason = PETSc.SNES.ConvergedReason.DIVERGED_LINEAR_SOLVE
        shown = SNES_REASONS.get(reason, str(reason))
        if reason > 0 and reason != self.test_reason:
            shown += " (set by SNES itself; the Newton test had not passed)"
            reason = -reason
        stats = {
            "snes_iterations": self.snes.getIterationNumber(),
            "ksp_iterations": self.snes.getLinearSolveIterations(),
            "snes_reason": shown,
            "ksp_reason": KSP_REASONS.get(ksp_reason, str(ksp_reason)),
            "active_rows": self.active_count(),
            "closed_start": start,          # the rows the increment started closed (None without rows)
            "damped_from": self.damped_from,   # the Newton iteration from which steps were damped (cycle or stall)
            "damped_steps": self.damped_steps,
            "tied_rows": self.tied_rows,       # sticking die rows kept closed after cycling (_tie_gates)
            "tied_in_tension": self._tied_in_tension(),   # of those, the ones the answer pulls on
            "round_off_floor": self.floor,     # the relative residual it stopped at on the floor, or None
            "linear_short": self.linear_short,
            "jacobian_assemblies": self.jacobian_rebuilds - rebuilds,   # with rows: one per new active set
        }
        if reason > 0:
            self.closed_rows = {}
            for term in self.terms:
                closed = np.zeros(term.c.getLocalSize(), dtype=bool)
                closed[term.rows[term.active]] = True
                self.closed_rows[term.name] = closed
        if reason <= 0 and self.free_seen:
            stats["free_motion"] = self.free_seen
            if self.free_now and self.free_load is not None:
                # whether the last residual loads the free motion: a body pulled off its only support has no
                # equilibrium; one floating between open gaps has many, and only its singular Jacobian failed an
                # iterative solve (a stack with gaps under the defaults: exit 3 on 1 and 2 ranks saying "no
                # equilibrium", ok on 3; hunt35_2)
                loaded = self.free_load(self.terms, self.snes.getFunction()[0])
                stats["free_loaded"] = bool(loaded > self.snes.getTolerances()[0] * self.force_scale)
        if self.mumps_relaxation is not None:
            stats["mumps_icntl_14"] = self.mumps_relaxation
        if self.mumps_cap is not None:
            stats["mumps_icntl_23"] = self.mumps_cap[0]
        return reason > 0, u, stats

    def _start_mode(self, u):
        """The closed set an increment starts from (collective): the rows touching or penetrating at u, and those
        the last converged increment ended closed (START_TOUCHING), unless those leave a body free, then every
        row within reach (START_REACH).

        The ended-closed rows too: with finite sliding the new search's gaps differ at second order from the
        ones the last increment converged to (the faces slide and tilt), and a contact pressed over its whole
        face can find itself a micrometre apart: the stiff plate (configs/stiff_plate.toml, 2 ranks) took 4 Newton
        steps and 62 Krylov iterations in its second increment from the touching rows alone, 2 and 20 holding
        the ended-closed rows (pressed 2 % instead of 1 %, 168 of its 676 rows touched at that start).

        Touching first: a start that glued every row within reach made a curved contact peel the rows outside
        its zone off over tens of Newton iterations, in every increment (Hertz, fine level, two_pass: 36 + 24
        iterations with 899 rows glued for 75 in contact; 20 + 15 from the touching rows (session 10), same answer).
        Within reach when the touching rows hold too little: a body held only by contact across a gap would
        be singular in the first Newton step."""
        if not self.terms:
            return None
        if self.free_motions is None:        # no restraint check to ask (a bare System): the start that is safe
            return START_REACH
        for term in self.terms:
            closed = self.closed_rows.get(term.name)
            term.held_closed = closed[term.rows] if closed is not None else None
            term.start = START_TOUCHING
            term.evaluate(u)
        return START_REACH if self.free_motions(self.terms, True) else START_TOUCHING

    def _more_mumps_workspace(self):
        """After a MUMPS factorization that ran out of workspace, double its memory relaxation ICNTL(14) for the
        next factors (collective: INFOG is global); False if that was not the failure or it is spent. One that
        wanted more memory than it may take (past its ICNTL(23) cap, or an allocation the kernel refused) ends
        the solve at once with a ConvergenceError naming the memory: a smaller increment needs the same factors
        (the 835k-dof merged two-cube body on 2 ranks, MUMPS LU: four cutbacks, each failing the same way, and
        "KSP DIVERGED_PCSETUP_FAILED")."""
        if not self._factors_with_mumps():
            return False
        pc = self.snes.getKSP().getPC()
        F = options.mumps_factor(pc)
        if F is None:               # the try failed before its first factorization
            return False
        error = F.getMumpsInfog(1)
        if error in MUMPS_MEMORY_ERRORS or (error in options.MUMPS_WORKSPACE_ERRORS and self.mumps_cap is not None):
            cap, lift = "", ""
            if self.mumps_cap is not None:
                cap = f"{self.mumps_cap[0]} MB a rank ({self.mumps_cap[1]})"
                lift = "; -qsc_mat_mumps_icntl_23 0 lifts the cap"
            want = (f"the system refused an allocation it asked for{' within its cap of ' + cap if cap else ''}"
                    if error == -13 else f"it needs more memory than its cap of {cap}")
            raise ConvergenceError(
                f"MUMPS's factorization: {want}; its estimate after the analysis was {F.getMumpsInfog(16)} MB on "
                f"its largest rank, {F.getMumpsInfog(17)} MB in all (INFOG(1) = {error}; INFOG(16), INFOG(17)). "
                f"Use the iterative default (no -qsc_pc_type lu) or more nodes{lift}")
        relax = options.more_mumps_workspace(pc, options.PREFIX, self.own_options)
        if relax is None:
            return False
        self.mumps_relaxation = relax
        return True

    def settings(self):
        """Lines naming what the SNES, its KSP and PC hold (petsc_options.txt): what qsc set through the API and
        PETSc's defaults, which the options database does not list. The KSP's atol is the last Newton step's."""
        snes, ksp = self.snes, self.snes.getKSP()
        rtol, atol, stol, max_it = snes.getTolerances()
        krtol, katol, _, kmax = ksp.getTolerances()
        try:
            norm = {v: k for k, v in vars(PETSc.KSP.NormType).items() if not k.startswith("_")}[ksp.getNormType()]
            side = {0: "left", 1: "right", 2: "symmetric"}[ksp.getPCSide()]
        except PETSc.Error:        # a norm or side the KSP type does not support (its solve failed on it already)
            norm, side = "unsupported", "unsupported"
        lines = [f"# snes: {snes.getType()}, rtol {rtol:g}, atol {atol:g}, stol {stol:g}, max_it {max_it}",
                 (f"# ksp: {ksp.getType()}, {side} preconditioning, {norm.lower()} norm, rtol {krtol:g}, "
                  f"atol {katol:g}, max_it {kmax}")]
        pc = ksp.getPC()
        context = pc.getPythonContext() if pc.getType() == "python" else None
        if isinstance(context, preconditioner.BandComposite):
            band = context.band.ksp.getPC()
            lines.append(f"# pc: band composite: {context.inner.getType()}, then"
                         + (f" a Galerkin correction on {context.slip.modes()} slip modes and" if context.slip else "")
                         + f" the band's {band.getType()} ({band.getFactorSolverType()}) on {self.band_dofs} dofs"
                         + (" (symmetric: the multigrid again)" if context.symmetric else ""))
            if context.defaults:
                # inserted for the multigrid's setup and taken out again, so the database above does not hold them
                lines.append("# the multigrid read qsc's defaults: "
                             + " ".join(f"-{name} {value}" for name, value in context.defaults.items()))
        else:
            factor = pc.getFactorSolverType() if pc.getType() in ("lu", "cholesky") else None
            lines.append(f"# pc: {pc.getType()}" + (f" ({factor})" if factor else ""))
        return lines

    def destroy(self):
        for name in self.own_options:
            PETSc.Options().delValue(name)
        self.agree_comm.Free()
        self.snes.destroy()
        if self.J is not self.K:
            self.J.destroy()


def array_digest(*arrays):
    """A SHA-256 digest of the arrays' contents (this rank's: compare them with an allreduce). SHA-256, not
    BLAKE2b: 12 MB in 8.0 against 28 ms on this project's machines, and a search digests its triplets and its
    stencil's pattern (tens of MB at 212k dofs)."""
    h = hashlib.sha256()
    for arr in arrays:
        h.update(memoryview(np.ascontiguousarray(arr)).cast("B"))
    return h.digest()


def _all_failed(comm, seconds=AGREE_SECONDS):
    """True once every rank of comm (a communicator used for nothing else) has called this within `seconds`
    of each other: an error every rank met, e.g. in a collective setup; False when some rank does not come
    (it is still inside a PETSc collective the failed rank left): the caller cannot end the run cleanly."""
    request = comm.Ibarrier()
    deadline = time.monotonic() + seconds
    while not request.Test():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.002)
    return True


def extrapolate(before, t_b, u_b, t):
    """A new Vec: the load path through the converged states before = (t_a, u_a) and (t_b, u_b), extended
    linearly to t; u_b itself when there is no earlier state."""
    start = u_b.copy()
    if before is not None and t_b > before[0]:
        w = (t - t_b) / (t_b - before[0])
        start.axpy(w, u_b)
        start.axpy(-w, before[1])
    return start


def _solve_at(system, step, t, u0):
    """system.solve_at, its errors naming the load step."""
    try:
        return system.solve_at(t, u0)
    except ConvergenceError as exc:
        raise ConvergenceError(f"load step {step}: {exc}") from None


def _merge(stats, more):
    """Add a further solve's counts to an increment's try and take its outcome."""
    for key in ("snes_iterations", "ksp_iterations", "jacobian_assemblies", "damped_steps"):
        stats[key] += more[key]
    stats["tied_rows"] = max(stats["tied_rows"], more["tied_rows"])
    if stats["damped_from"] is None:        # the Newton iteration of the first solve that met cycling
        stats["damped_from"] = more["damped_from"]
    stats.update({k: more[k] for k in ("snes_reason", "ksp_reason", "active_rows", "tied_in_tension",
                                       "round_off_floor", "linear_short")})
    if "multipliers_unsettled" in more:     # the outcome's: why a later solve of the try failed
        stats["multipliers_unsettled"] = more["multipliers_unsettled"]
    stats["multipliers_at_round_off"] = more.get("multipliers_at_round_off")     # the answer's multipliers'
    stats["augmented_penalty_rows"] = more.get("augmented_penalty_rows", [])


def _solve_enforced(system, step, t, start, augmented_max):
    """One solve at load factor t from `start`, then, with augmented Lagrangian terms, multiplier updates and
    solves until the next update would change every term's multipliers by at most its augmented_tolerance
    (that update is left unapplied: ConstraintTerm.next_multipliers), at most augmented_max updates applied;
    returns (ok, u, stats), stats["augmented_iterations"] the updates computed (the applied ones and the test),
    stats["multipliers_at_round_off"] (name, change, tolerance, round-off bound) of the pair furthest above its
    tolerance when the updates ended on their round-off instead (AUGMENTED_ROUND_OFF), else None."""
    ok, u_new, stats = _solve_at(system, step, t, start)
    augmented = [term for term in system.terms if term.augmented]
    stats["multipliers_at_round_off"] = None
    outer = 0
    while ok and augmented:
        steps = [(term, *term.next_multipliers(u_new, system.dof_stiffness())) for term in augmented]
        outer += 1
        if all(change <= max(term.augmented_tolerance, bound) for term, _, change, bound in steps):
            # a tolerance under the multipliers' round-off is met at that round-off, and said (Run)
            over = [(term.name, change, term.augmented_tolerance, bound) for term, _, change, bound in steps
                    if change > term.augmented_tolerance]
            if over:
                stats["multipliers_at_round_off"] = max(over, key=lambda entry: entry[1] / entry[2])
            # the rows that kept no multiplier, where they carry more of the force than the tolerance (Run)
            shares = [(term.name, *term.penalty_share(), term.augmented_tolerance) for term in augmented]
            stats["augmented_penalty_rows"] = [entry for entry in shares if entry[2] > entry[3]]
            break
        if outer > augmented_max:          # augmented_max updates applied, and this one's test not met
            ok = False
            stats["snes_reason"] = "AUGMENTED_LAGRANGIAN_MAX_IT"
            term, _, change, bound = max(steps, key=lambda step: step[2] / step[0].augmented_tolerance)
            # the round-off estimate itself (bound is AUGMENTED_ROUND_OFF times it, capped)
            stats["multipliers_unsettled"] = (term.name, change, term.augmented_tolerance,
                                              bound / AUGMENTED_ROUND_OFF)
            break
        for term, new, _, _ in steps:
            term.lmbda = new
        ok, u_new, more = _solve_at(system, step, t, u_new)
        _merge(stats, more)
    stats["augmented_iterations"] = outer
    return ok, u_new, stats


def solve_load_step(system, step, t_prev, t_target, u, update_terms, max_cutbacks,
                    augmented_max=25, log=None, before=None, predict=True, settle=None,
                    max_searches=20, missed=None, split=None):
    """Advance from t_prev to t_target, halving the increment on failure; returns (u, stats, before).

    predict: each try starts from the linear extrapolation of the last two converged states along the load
    (exact for a linear response: the increment needs one Newton step), except the first try of a run and a
    try after a failed one, which start from the converged state; False: always from the converged state.
    before: None, or (t_a, u_a), the converged state before (t_prev, u); the returned before is the state
    before the returned u, for the next call. update_terms(u, t_try, t, before) makes the terms of a try.
    settle (large sliding; ContactModel.settle): after each converged solve, settle(u) searches again at the
    converged u and returns (terms, settled); while not settled the try is solved again from u on those terms,
    and a try whose searches (update_terms' included) reach max_searches unsettled fails (SEARCH_NOT_SETTLED),
    so its increment is halved like any failed one.
    missed (dies, finite-sliding pairs; ContactModel.missed): after a converged try, the nodes that were out of a
    die's or pair's reach at the increment's start and went through it, or None; a try with some fails
    (OUT_OF_REACH) and is halved.
    split (sticking dies; ContactModel.pathless_met): after a converged try, how many nodes met a sticking die
    in it with no earlier state to give their path (the run's first increment); such a try is halved, up to
    MAX_PATH_SPLITS times, and not counted as a cutback (STICKING_PATH_UNKNOWN in its record).
    A body that the boundary conditions and every contact row within reach leave free is a scene
    error (System.free_motions); a failed solve names what its iterates left free."""
    dt = t_target - t_prev
    t = t_prev
    resume = None         # the increment before the first halving for a sticking die's unknown path
    cutbacks, records = 0, []
    failed, cause, splits = False, None, 0
    unsettled = []        # the multipliers' last change of each try that ended on AUGMENTED_LAGRANGIAN_MAX_IT
    while t < t_target - 1e-14:
        t_try = min(t + dt, t_target)
        system.set_terms(update_terms(u, t_try, t, before))
        _check_held(system, step)
        # a try after a failed one starts from the converged state, as every try does without the predictor
        path = None if failed or not predict else before
        start = extrapolate(path, t, u, t_try)
        ok, u_new, stats = _solve_enforced(system, step, t_try, start, augmented_max)
        stats["predictor"] = "previous" if path is None else "extrapolated"
        start.destroy()
        searches = 1
        while ok and settle is not None:
            terms, settled = settle(u_new)
            searches += 1
            if settled:
                break
            if searches >= max_searches:
                ok = False
                stats["snes_reason"] = "SEARCH_NOT_SETTLED"
                break
            system.set_terms(terms)
            _check_held(system, step)
            ok, u_next, more = _solve_enforced(system, step, t_try, u_new, augmented_max)
            u_new.destroy()
            u_new = u_next
            updates = stats["augmented_iterations"] + more["augmented_iterations"]
            _merge(stats, more)
            stats["augmented_iterations"] = updates
        if ok and missed is not None:
            through = missed(u_new)
            if through:
                ok = False
                stats["snes_reason"], (stats["out_of_reach"], cause) = "OUT_OF_REACH", through
        met = split(u_new) if ok and split is not None else 0
        if met and splits < MAX_PATH_SPLITS:
            ok = False
            stats["snes_reason"] = "STICKING_PATH_UNKNOWN"
        elif met:
            stats["met_without_path"] = met
            if log:
                log(f"step {step}: warning: {met} node(s) met a sticking die within the first 1/{2 ** splits} of "
                    f"the run's first increment, where no earlier state gives their path: they stick where the "
                    f"die's own approach places them, which errs by up to their own travel along the die before "
                    f"they meet it (a body lifted onto a sliding die in one step: twice the shear force)")
        stats.update(load_factor=t_try, searches=searches)
        records.append(stats)
        if ok:
            if before is not None:
                before[1].destroy()
            before = (t, u)            # the predictor's path, and the sticking dies' (update_terms)
            u, t, failed = u_new, t_try, False
            if resume is not None and not met:
                dt, resume = resume, None     # the path is known now: the halvings for it end (70 solves in 1 step)
            continue
        u_new.destroy()
        failed = True
        if met:
            # no failure: the try is halved until the nodes meet the die in an increment with a known path
            resume = dt if resume is None else resume
            splits += 1
            if log:
                log(f"step {step}: {met} node(s) met a sticking die in the increment to load factor {t_try:.6g}, "
                    f"where no earlier state gives their path: halving it, so that they meet it in one that does")
            dt *= 0.5
            continue
        cutbacks += 1
        # a die's nodes whose faces turn away from it go through it at any increment: no cutback helps (hunt31_3)
        away = stats["snes_reason"] == "OUT_OF_REACH" and cause == "away"
        # Uzawa's rate does not depend on the increment: a halved try whose multipliers still changed by more than
        # AUGMENTED_CUTBACK_GAIN of the last try's will not settle at any size either (two_pass at alpha 1e2 on the
        # two cubes: 1e-4 after 25 updates at every one of 4 cutbacks, ~100 solves; hunt32_2)
        if stats["snes_reason"] == "AUGMENTED_LAGRANGIAN_MAX_IT":
            unsettled.append(stats["multipliers_unsettled"][1])
        stalled = len(unsettled) > 1 and unsettled[-1] > AUGMENTED_CUTBACK_GAIN * unsettled[-2] and \
            stats["snes_reason"] == "AUGMENTED_LAGRANGIAN_MAX_IT"
        if log and cutbacks <= max_cutbacks and not (away or stalled):
            log(f"step {step}: solve at load factor {t_try:.6g} failed "
                f"({stats['snes_reason']}, KSP {stats['ksp_reason']}); cutting the increment in half")
        if cutbacks > max_cutbacks or away or stalled:
            free = stats.get("free_motion", "")
            why = (f"; an iterate left {free} held by no boundary and no closed contact row (a body held only "
                   f"by contact that separates has no equilibrium)") if free else ""
            if free and stats.get("free_loaded") is False and not _single_application(system):
                ksp = system.snes.getKSP()
                pc = ksp.getPC().getType()
                solve = f"{ksp.getType()} + {'the contact band preconditioner' if pc == 'python' else pc}"
                why = (f"; an iterate left {free} held by no boundary and no closed contact row and no load on it "
                       f"(bodies between open gaps: an equilibrium, one of many), its Jacobian singular, which the "
                       f"linear solve ({solve}) could not take: a direct "
                       f"solver does (-qsc_ksp_type preonly -qsc_pc_type lu -qsc_pc_factor_mat_solver_type mumps), "
                       f"or hold the bodies (a boundary, or a die that presses them)")
            single = _single_application(system)
            if single:
                # its Newton steps are not the Jacobian's: wrong iterates open rows that hold, so the free
                # motion above would send the user to the boundaries
                why = (f"; each linear solve was one application of pc_type {single} (ksp_type preonly), not a "
                       f"solve: the Newton steps were not the Jacobian's (preonly needs an exact factorization, "
                       f"-qsc_pc_type lu or cholesky; or leave ksp_type to qsc)")
            if stats["snes_reason"] == "DIVERGED_INNER" and not system.ksp_atol_auto:
                # newtontr's step from a linear solve that -qsc_ksp_atol stopped at once (the residual below it):
                # no step the trust region can take; each option alone converges (hunt33_5)
                why = ("; the trust region's linear solve stopped on -qsc_ksp_atol, which its residual was below "
                       "already, and left it no step to take: lower -qsc_ksp_atol, or leave it to qsc, which sets "
                       "the Krylov stop below the Newton target")
            if stats.get("linear_short"):
                why = ("; a linear solve stopped with its residual far above the Newton target and its step no "
                       "correction (-qsc_ksp_atol above the residual, or -qsc_ksp_rtol near 1): lower them, or "
                       "leave them to qsc, which sets the Krylov stop below the Newton target")
            if stats["snes_reason"] == "AUGMENTED_LAGRANGIAN_MAX_IT":
                name, change, tol, noise = stats["multipliers_unsettled"]
                halving = (f"; a halved increment left them as far ({unsettled[-2]:.2g} before), so no more were "
                           f"tried" if stalled else "")
                if stalled and change <= AUGMENTED_STALL_NOISE * noise:
                    # a stiff penalty's updates that stand on their round-off (two_pass's over-constrained rows at
                    # 25-40x the allowance, alpha 1e8 on the patch test): more updates or a stiffer penalty cannot
                    # help, a softer one does (hunt33_3)
                    cure = (f"they stand at {change / noise:.3g} x their round-off ({noise:.2g}: eps_n times the rows' "
                            f"precision), which the updates cannot go below: lower {name}.penalty (the augmented "
                            f"Lagrangian needs no stiff one), or use the penalty alone")
                else:
                    cure = (f"raise {name}.augmented_max_iterations, or its penalty (the updates converge the faster "
                            f"the stiffer it is)")
                why = (f"; the multipliers of {name} still changed by {change:.2g} (relative; its "
                       f"augmented_tolerance {tol:g}) after {augmented_max} updates{halving}: {cure}")
            if away:
                why = (f"; {stats['out_of_reach']} within the die's reach, of faces turned away from it, went "
                       f"through it: {DIE_AWAY}")
            elif stats["snes_reason"] == "OUT_OF_REACH":
                what = stats["out_of_reach"]
                why = (f"; {what} out of the die's reach at the increment's start went through it "
                       f"(raise die[i].search_distance, or use more load steps)" if what.startswith("die") else
                       f"; {what} without a row at the increment's start (farther than contact[i].search_distance "
                       f"from the other surface, or beside its edge) penetrate it: use more load steps or sliding = "
                       f"\"large\" (whose searches follow the nodes), or raise search_distance if they came from "
                       f"above the surface")
            if stats["snes_reason"] == "SEARCH_NOT_SETTLED":
                why = (f"; the rows of the large-sliding pairs had not settled after {max_searches} searches "
                       f"(contact[i].max_searches; more load steps slide less per increment)")
            if stats["snes_reason"] == "DIVERGED_MAX_IT" and not why:
                # the active set still wandering at the limit: a 1/500 plate between a punch and a block converged
                # in 114 Newton iterations with the key raised, which the message did not name (hunt35_4)
                key = ("-qsc_snes_max_it" if options.option_value("snes_max_it") is not None else
                       "solver.max_active_set_iterations")
                why = (f"; the Newton iterations (their active sets) had not settled within "
                       f"{system.snes.getTolerances()[3]}: raise {key}, or use more load steps")
            raise ConvergenceError(
                f"load step {step} (load factor {t_try:.6g}) did not converge after {cutbacks - 1} "
                f"cutbacks: SNES {stats['snes_reason']} after {stats['snes_iterations']} iterations, "
                f"KSP {stats['ksp_reason']}{why}")
        dt *= 0.5
    return u, {"cutbacks": cutbacks, "solves": records}, before


DIE_AWAY = ("a die holds only the nodes of faces turned towards it; check the sign of its normal (from the die "
            "toward the bodies), or list the surfaces that face it")
# the run's first increment is halved up to this many times while nodes meet a sticking die in it, whose path to
# the die no earlier state gives (solve_load_step's split): a block lifted onto a sliding die in 2 steps met it at
# the first step's end with the anchor of the die's start, 2x the shear force (hunt31_5)
MAX_PATH_SPLITS = 6
EXACT_PCS = ("lu", "cholesky", "qr", "svd", "redundant", "telescope", "fieldsplit", "composite", "ksp", "shell")


def _single_application(system):
    """The PC type when the linear solver is preonly with a preconditioner that is no exact solve (jacobi, ilu,
    hypre...; a PC type that may be exact, as a redundant or fieldsplit one, is given the benefit), else None."""
    ksp = system.snes.getKSP()
    pc = ksp.getPC().getType()
    if ksp.getType() != "preonly" or pc in EXACT_PCS:
        return None
    return "python (the contact band composite: a V-cycle and the band's solve)" if pc == "python" else pc


def _check_held(system, step):
    """A scene error when the terms just set leave a body free (System.free_motions)."""
    free = system.free_motions(system.terms, False) if system.free_motions else ""
    if free:
        raise free_motion_error(step, free)


def free_motion_error(step, free):
    """The error for a load step whose boundaries and rows within reach leave the motions `free` (restraint.describe)
    free: the scene's at the first step (SceneError; `qsc check` raises it too), the earlier steps' outcome after it
    (ConvergenceError: a block pushed off its support ended 17 steps with "add a boundary condition", exit 2, as if
    the scene were wrong; hunt35_1)."""
    if step > 1:
        return ConvergenceError(
            f"load step {step}: free rigid-body motion of {free}: the earlier steps moved it out of the reach of "
            f"every contact row and die that held it, and no displacement or symmetry boundary holds it (frictionless "
            f"contact holds the normal direction only), so it has no equilibrium past there; hold it with a "
            f"boundary condition, or raise the search_distance of the pair or die that should still reach it")
    return SceneError(f"load step {step}: free rigid-body motion of {free}: no displacement or symmetry boundary holds "
                      f"it and no contact row or die within reach does (frictionless contact holds the normal "
                      f"direction only); add a boundary condition")
