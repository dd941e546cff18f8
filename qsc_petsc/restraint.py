"""Which rigid-body motions of the bodies no displacement boundary and no contact row holds (every body must be held;
a body read from a file in several unconnected pieces, every piece).

A body that nothing holds in some direction makes the Jacobian singular. A direct solver
then returns one of infinitely many answers, picked by round-off (a silent wrong
displacement), and an iterative one stalls with a reason that does not say why. So the
constraints are checked against the rigid-body motions themselves: with B the matrix whose
rows are the held dofs' components of every body's six rigid motions and, for each contact
row r, (G_r v) / W_r (the row's weighted normal velocity, dimensionless), a motion v is free
iff B v = 0; the null space of the Gram matrix B^T B (6 per body, all-reduced) names them.
"""

import weakref

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from .elasticity import RIGID_MODES, rigid_motions

# B^T B eigenvalues below this fraction of the largest are a null space: a held direction
# contributes O(1) per held dof or row, an unheld one round-off (1e-16 relative)
FREE_TOL = 1e-9
# a mode is reported when at least this share of it lies in the free space
SHOW_TOL = 0.3
# Restraint.loose: a row whose force is at most this share of the largest row force carries none
LOOSE_SHARE = 1e-9
# ... or at most this many times its own round-off (Restraint.loose)
LOOSE_ROUND_OFF = 100.0


def null_motions(gram):
    """An orthonormal basis (6 nb, k) of the motions a Gram matrix B^T B (6 nb, 6 nb) leaves free."""
    gram = np.asarray(gram, dtype=float)
    w, vec = np.linalg.eigh(0.5 * (gram + gram.T))
    top = max(float(w.max(initial=0.0)), 0.0)
    return vec[:, w <= FREE_TOL * top] if top > 0 else np.eye(len(gram))


def free_motions(gram, body_names):
    """The free motions of a Gram matrix B^T B (6 nb, 6 nb): {body name: [mode names]}, empty if all are held."""
    null = null_motions(gram)
    if null.shape[1] == 0:
        return {}
    share = np.linalg.norm(null, axis=1).reshape(len(body_names), 6)
    out = {}
    for b, name in enumerate(body_names):
        modes = [RIGID_MODES[k] for k in range(6) if share[b, k] >= SHOW_TOL]
        if modes:
            out[name] = modes
    if not out:    # a free combination spread thin over many modes: name its largest parts
        b, k = np.unravel_index(int(np.argmax(share)), share.shape)
        out[body_names[b]] = [RIGID_MODES[k]]
    return out


def describe(free):
    """One line naming the free motions: 'upper (translation x, rotation about z)'."""
    return "; ".join(f"{name} ({', '.join(modes)})" for name, modes in free.items())


class Restraint:
    """The rigid motions of every body on this rank's owned dofs, and the check of a set of constraints against them."""

    def __init__(self, mesh, bc_dofs, template):
        comm = mesh.comm
        # one rigid body per connected piece: a body read from a file may come in several (LocalMesh.vertex_piece)
        self.comm, self.names = comm, list(mesh.piece_names)
        self.mesh, self.sizes = mesh, template.getSizes()
        owned = mesh.owned_rows              # dof 3 r + c of this rank is component c of vertex owned[r]
        self.frames = []            # per body: the centre [m] and length [m] its rotations are taken with
        for b in range(len(self.names)):
            x = mesh.coords[owned[mesh.vertex_piece[owned] == b]]
            lo, hi = np.empty(3), np.empty(3)
            comm.Allreduce(x.min(axis=0) if len(x) else np.full(3, np.inf), lo, op=MPI.MIN)
            comm.Allreduce(x.max(axis=0) if len(x) else np.full(3, -np.inf), hi, op=MPI.MAX)
            self.frames.append((0.5 * (lo + hi), float(np.linalg.norm(hi - lo)) or 1.0))
        # the boundary conditions' rows of the motions: only their vertices' velocities are needed
        dofs = np.asarray(bc_dofs, dtype=np.int64) - template.getOwnershipRange()[0]
        held = self._velocities(owned[dofs // 3], dofs % 3)
        self.gram_bc = held.T @ held
        self.Rmat = None            # every owned dof's motions, made for the first contact term (_motion_matrix)
        self.seen = weakref.WeakKeyDictionary()        # per term, its rows' motions (_motions): G does not change

    def _velocities(self, vertices, components):
        """Rows (k, 6 nb) of the motions at the given components of local vertices: each body's six, zero elsewhere."""
        out = np.zeros((len(vertices), 6 * len(self.names)))
        body = self.mesh.vertex_piece[vertices]
        for b, (centre, length) in enumerate(self.frames):
            sel = np.flatnonzero(body == b)
            # rotations at unit speed at distance `length` from the centre: every motion's rows of one size
            v = rigid_motions((self.mesh.coords[vertices[sel]] - centre) / length)
            out[sel, 6 * b:6 * b + 6] = v[:, np.arange(len(sel)), components[sel]].T
        return out

    def _motion_matrix(self):
        """The motions of every owned dof (owned dofs, 6 nb) as one dense Mat: a term's G R is one product, not a
        G.mult per motion (collective the first time)."""
        if self.Rmat is None:
            owned = self.mesh.owned_rows
            # column-major: PETSc's dense layout
            R = np.asfortranarray(self._velocities(np.repeat(owned, 3), np.tile(np.arange(3), len(owned))))
            self.Rmat = PETSc.Mat().createDense((self.sizes, (None, R.shape[1])), array=R.ravel(order="F"),
                                                comm=self.comm)
            self.Rmat.assemble()
        return self.Rmat

    def _gram(self, terms, active_only, masks=None):
        """B^T B of the boundary conditions' and the terms' rows (all existing rows, only the active ones, or per
        term those a boolean mask over its rows keeps), over all ranks (collective)."""
        gram = self.gram_bc.copy()
        for i, term in enumerate(terms):
            keep = (masks[i] if masks is not None else term.active if active_only
                    else np.ones(len(term.rows), dtype=bool))
            block = self._motions(term)[keep]
            gram += block.T @ block
        total = np.empty_like(gram)
        self.comm.Allreduce(gram, total, op=MPI.SUM)
        return total

    def free(self, terms, active_only, masks=None):
        """Free motions under the boundary conditions and the terms' rows (_gram): {body name: [mode names]}, the
        same on every rank (collective)."""
        return free_motions(self._gram(terms, active_only, masks), self.names)

    def free_load(self, terms, r):
        """The largest force [N] that r (a residual Vec) puts on a motion the boundary conditions and the terms'
        active rows leave free, 0 if none is (collective). A body pulled off its only support carries the pull
        there; one floating between open rows with no load on it, round-off: an equilibrium, one of many
        (Restraint.loose names it), which a solve on 2 ranks failed and on 1 rank converged to (hunt32_1)."""
        null = null_motions(self._gram(terms, True))
        if null.shape[1] == 0:
            return 0.0
        R = self._motion_matrix().getDenseArray()          # this rank's owned dofs, every body's motions
        q = R.T @ r.getArray(readonly=True)
        self.comm.Allreduce(MPI.IN_PLACE, q, op=MPI.SUM)
        return float(np.abs(null.T @ q).max())

    def _motions(self, term):
        """(G_r v) / W_r of the term's existing rows r for every motion v: (rows, 6 nb), made once per term
        (collective the first time)."""
        if term not in self.seen:
            GR = term.G.matMult(self._motion_matrix())
            self.seen[term] = GR.getDenseArray()[term.rows] / term.W.getArray()[term.rows, None]
            GR.destroy()
        return self.seen[term]

    def loose(self, terms, u=None):
        """The motions that no boundary and no active row carrying force holds (a row's pressure at most LOOSE_SHARE of
        the largest row pressure of all terms, or of the term's pressure_floor, that of a strain of FLOOR_STRAIN, if
        that is larger, carries none): {body name: [mode names]}, empty if the boundary conditions and the rows that
        press hold every body (collective). Such a body sits where the Newton iterations left it: any position along
        those motions that keeps its rows open is an equilibrium too. Without the floor, when every force was
        round-off (a stack not loaded yet, 3e-15 N at most) round-off rows counted as pressing and only some of the
        loose bodies were named. The floor was the Newton test's force floor (N) until session 34, against pressures
        (Pa): 100 km blocks pressed to a strain of 1e-5 were said loose, all 64 rows carrying the load (hunt34_1)."""
        forces = [np.abs(term.m.getArray()[term.rows]) for term in terms]
        largest = self.comm.allreduce(max((float(f.max(initial=0.0)) for f in forces), default=0.0), op=MPI.MAX)
        pressing = [term.active & (f > LOOSE_SHARE * max(largest, term.pressure_floor))
                    for term, f in zip(terms, forces)]
        if u is not None:
            # ... nor one whose force is its own round-off (ConstraintTerm.round_off): rows whose gap closed to
            # round-off held the bodies of a floating stack, of which only the top one was named (hunt32_1)
            pressing = [p & (f > LOOSE_ROUND_OFF * term.round_off(u)) for p, f, term in zip(pressing, forces, terms)]
        for term, held in zip(terms, pressing):
            if term.gate_of is not None:
                # a sticking die's tangential row holds its node wherever the node's normal row presses, with force
                # or none: blocks of nu = 0 between sticking dies, whose tangential rows carry nothing, were said
                # loose, "one of many", though held (hunt35_4)
                tangential = np.flatnonzero(term.gate_of >= 0)
                held[tangential] = term.active[tangential] & held[term.gate_of[tangential]]
        # every active row may carry force and a body still be free: a solve converges with a body held by no row
        # when the residual does not load it (free_load); three blocks between open gaps ended "ok" with no word on
        # 2 ranks, every row open (hunt35_2)
        return self.free(terms, True, pressing)

    def destroy(self):
        if self.Rmat is not None:
            self.Rmat.destroy()
