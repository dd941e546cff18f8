"""The run: validated scene -> distributed mesh -> operators -> load steps -> output folder."""

import atexit
import resource
import signal
import threading
import time
import weakref
from contextlib import contextmanager
from functools import cached_property
from pathlib import Path

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from . import __version__, assembly, elasticity, fem, lattice, options, preconditioner
from .errors import OutputError, QscError, SceneError, folder_error
from .mesh import check_cells, distribute_mesh, first_largest, on_root
from .output import ResultWriter, check_output_folder, clear_results, write_json, write_on_root
from .restraint import Restraint, describe
from .scene import PETSC_DEFAULTS
from .solver import (
    AUGMENTED_ROUND_OFF,
    AUGMENTED_SLIVER,
    FLOOR_STRAIN,
    ROUND_OFF_WARNING,
    System,
    check_solver_options,
    solve_load_step,
)

# Runs built and not yet destroyed, as weak references in creation order (the same order on every rank).
_LIVE_RUNS = []
# a step whose largest strain passes this is said once: the elasticity is linear (small strains). A 2 m stack pressed
# 2.5 m by its top die ended "ok" with 178 of its 189 cells inside out, and 20 % and 50 % strokes without a word
# (hunt33_3)
LARGE_STRAIN = 0.05
LARGE_ROTATION = 0.1       # rad
# ... passed by more than round-off: a block pressed to exactly 5 % (uniform strain) warned at step 1 on 1 rank, by
# its round-off, and at step 2 on 2 and 3 (hunt34_2)
THRESHOLD_MARGIN = 1.0 + 1e-9
# an answer that stands on round-off to more than this share of its loads is said once (Run._round_off_line): loads
# that strain the bodies ~1e-12 or less were solved to an absolute floor with no word, the patch pair's two_pass
# contact force 5e-4 off at a strain of 1e-12 and 30x at 1e-15 (hunt33_3)
ROUND_OFF_ANSWER = 1e-6
# ... the Newton test's part of it, only for loads whose own forces are below this share of its floor (a stiff
# penalty's round-off at a strain near the floor is solver.ROUND_OFF_WARNING's)
FLOOR_SHARE = 1e-2


@atexit.register      # registered after petsc4py's import, so it runs before petsc4py finalizes PETSc
def _destroy_live_runs():
    """Destroy the runs an in-process caller left alive: at PetscFinalize, PETSc's own cleanup of their
    solver objects (the contact band's Python preconditioner) crashed with SEGV after the results
    were written."""
    for ref in _LIVE_RUNS:
        run = ref()
        if run is not None:
            run.destroy()
    _LIVE_RUNS.clear()


def _kept_rows(contact):
    """The step line's note on pairs whose new search kept the last rows (reuse_tolerance): finite sliding's
    search at the increment's start, large sliding's after the increment's last solve (its rows settled)."""
    settled = [f"{name.split()[0]} after {e['searches']} searches (gap change {e['gap_change']:.2g})"
               for name, e in contact.items() if e.get("searches", 0) > 1 and e.get("rows_kept")]
    kept = [f"{name.split()[0]} (gap change {e['gap_change']:.2g}, searched for load factor {e['rows_searched_for']:.4g})"
            for name, e in contact.items() if e.get("rows_kept") and e.get("gap_change") is not None
            and e.get("searches", 0) <= 1]
    return (("; kept the last search's rows: " + ", ".join(kept) if kept else "")
            + ("; rows settled: " + ", ".join(settled) if settled else ""))


class Phases:
    """Wall time per phase (max over ranks) and a PETSc log event per phase, for -log_view.

    A phase entered inside another (search and rows inside a load step's solve) is timed on its own
    and left out of the enclosing one, so the phases add up to the run's time; the PETSc events
    stay inclusive, as -log_view reports every event."""

    def __init__(self, comm):
        self.comm, self.seconds, self.events = comm, {}, {}
        self.open = []                 # names of the phases entered and not left, outermost first

    @contextmanager
    def __call__(self, name):
        event = self.events.setdefault(name, PETSc.Log.Event(f"qsc:{name}"))
        event.begin()
        self.open.append(name)
        t0 = time.perf_counter()
        try:
            yield
        finally:
            elapsed = time.perf_counter() - t0
            event.end()
            self.open.pop()
            self.seconds[name] = self.seconds.get(name, 0.0) + elapsed
            if self.open:
                self.seconds[self.open[-1]] = self.seconds.get(self.open[-1], 0.0) - elapsed

    def summary(self):
        names = sorted(set().union(*self.comm.allgather(set(self.seconds))))
        local = np.array([self.seconds.get(n, 0.0) for n in names])
        worst = np.zeros_like(local)
        self.comm.Allreduce(local, worst, op=MPI.MAX)
        return dict(zip(names, worst.tolist()))


def peak_rss_mib():
    """This process's peak resident set [MiB]: VmHWM where /proc has it. getrusage's ru_maxrss is not the
    process's own on Linux: exec keeps the high-water mark of the image it replaced, so a run started from a
    large Python process (qsc sweep after loading its reference solution) reported that process's size
    (1547 MiB for a run that peaks at 1012)."""
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0          # kB
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0     # KiB on Linux


def peak_memory_mib(comm):
    per_rank = comm.allgather(peak_rss_mib())
    return {"max_rank": max(per_rank), "total": sum(per_rank), "per_rank": per_rank}


def prepare_output(scene, out_dir, comm):
    if isinstance(out_dir, str) and not out_dir.strip():
        raise SceneError("--out: an empty folder name (omit --out for the scene's output.directory)")
    directory = Path(out_dir if out_dir else scene.output.directory.replace("{name}", scene.name))

    def make():
        try:
            directory.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise SceneError(folder_error("--out" if out_dir else "output.directory", directory, exc)) from None
        check_output_folder(directory)
    on_root(comm, make)
    return directory


@contextmanager
def held_interrupts():
    """Ctrl-C or SIGTERM (whichever raises KeyboardInterrupt here) held while a step's results are written, its
    fields and then summary.json, and raised after: one that came between them left solution.xdmf a step ahead
    of the summary, and a step file half written (hunt33_2). A second one goes through at once."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught, saved = [], {}

    def hold(signum, frame):
        if caught:
            raise KeyboardInterrupt
        caught.append(signum)

    for number in (signal.SIGINT, signal.SIGTERM):
        handler = signal.getsignal(number)
        if callable(handler):         # a Python handler (Ctrl-C's, the CLI's SIGTERM), not the system's
            saved[number] = handler
            signal.signal(number, hold)
    try:
        yield
    finally:
        for number, handler in saved.items():
            signal.signal(number, handler)
    if caught:
        raise KeyboardInterrupt


def replace_results(directory, comm):
    """An earlier run's results in directory removed, once the run's set-up has passed (collective): a run
    refused for its input (a mistyped PETSc option, a truncated mesh file) removed them first (hunt34_3)."""
    def clear():
        try:
            clear_results(directory)
        except OSError as exc:
            raise OutputError(f"output: cannot remove the earlier run's {str(exc.filename)!r}: {exc.strerror}") from None
    on_root(comm, clear)


class Run:
    """Everything one solve needs, built in order; `execute` runs the load steps."""

    def __init__(self, scene, comm, out_dir=None, log=print):
        self.scene, self.comm = scene, comm
        self.log = log if comm.rank == 0 else (lambda *a, **k: None)
        self.phases = Phases(comm)
        self.out = prepare_output(scene, out_dir, comm)
        self.from_scene = options.insert_options(scene.petsc)
        self.destroyed = False
        self.round_off_said = set()      # pairs whose augmented Lagrangian ended on its round-off, said once
        try:
            self._build(scene, comm)
        except BaseException as exc:
            if isinstance(exc, QscError):
                self._set_up_failed(exc)
            options.remove_options(self.from_scene)   # a failed set-up leaks no options to the next run
            raise
        _LIVE_RUNS[:] = [ref for ref in _LIVE_RUNS if ref() is not None] + [weakref.ref(self)]

    def _set_up_failed(self, exc):
        """A set-up that stopped on bad input (a refused PETSc option, a bad mesh) says so in its folder when it
        holds no earlier run's results: summary.json with status "failed" and the error, and petsc_options.txt.
        An earlier run's results stay as they were (its summary says its own status), and the error says so.
        Collective; a folder that cannot take them adds nothing to the error."""
        earlier = self.comm.bcast((self.out / "summary.json").exists() if self.comm.rank == 0 else None, root=0)
        if earlier:
            exc.args = (f"{exc.args[0]} (the earlier results in {str(self.out)!r} are left as they were)",
                        *exc.args[1:])
            return
        summary = {"scene": self.scene.name, "status": "failed", "error": str(exc), "qsc_petsc": __version__,
                   "ranks": self.comm.size, "petsc_options": options.options_in_effect()}
        try:
            path = self.out / "summary.json"
            write_on_root(self.comm, path, lambda: write_json(path, summary))
            self._write_options(summary["petsc_options"])
        except QscError:
            pass

    def _build(self, scene, comm):
        """Mesh, contact model and its first search, operators, solver and output writer, in that order."""
        options.check_options()
        # the solver set up on a model matrix, as `qsc check` does: an option a factorization package refuses
        # (-qsc_mat_mumps_icntl_7 99) is an input error before the folder is touched, not a failed solve
        # (the band's part not where SuperLU_DIST factors it: a second band set-up in one process freed a
        # communicator twice at PetscFinalize, "corrupted double-linked list" and exit 134 after an "ok" run;
        # PETSc 3.18, hunt35_3)
        band = options.option_value("band_pc_factor_mat_solver_type") != "superlu_dist"
        check_solver_options(comm, scene.solver.contact_preconditioner if scene.contact and band else None)
        with self.phases("mesh"):
            self.mesh = distribute_mesh(scene, comm)
            check_cells(self.mesh, scene)
        mesh = self.mesh
        for line in assembly.locking_warnings(scene, mesh.cell_type):
            self.log(f"warning: {line}")
        self.contact, extra, stencil_digests = None, None, []
        if scene.contact or scene.die:
            from .contact.model import ContactModel
            self.contact = ContactModel(mesh, scene, mesh.dof_vector(), self.phases)
            for line in self.contact.precision_warnings():
                self.log(f"warning: {line}")
            # the first increment's search comes first: K's pattern holds its contact stencil (set_terms)
            extra, stencil_digests = self.contact.prepare(1.0 / scene.load.steps)
            for line in self.contact.die_away_warnings():        # from the first search's reach
                self.log(f"warning: {line}")
        with self.phases("assembly"):
            self.lmbda, self.mu = assembly.cell_materials(mesh, scene)
            self.kappa = assembly.cell_mean_bulk(mesh, scene)
            # generated hex boxes read their rows from stencil templates; other meshes sum element blocks
            lattices = lattice.box_lattices(scene)
            self.stiffness_path = "box stencils" if lattices else "element blocks"
            self.bc_dofs, bc_values, self.bc_per_boundary = assembly.dirichlet_dofs(mesh, scene)
            if self.contact is not None:
                for line in self.contact.hold_warnings(self.bc_dofs, bc_values, self.bc_per_boundary):
                    self.log(f"warning: {line}")
            # K arrives as K0 with its lifting: the Dirichlet rows and columns go while its arrays are ours
            fixed = (self.bc_dofs, bc_values)
            K, lifting = (assembly.lattice_stiffness_matrix(mesh, lattices, extra, fixed) if lattices
                          else assembly.stiffness_matrix(mesh, self.lmbda, self.mu, extra, fixed, self.kappa))
            u = K.createVecRight()
            self.f_ext = assembly.surface_load(mesh, scene, u)
            held = [(surface, None if die.condition == "sticking" else np.asarray(die.normal, float))
                    for die in scene.die for surface in die.surfaces]
            nullspace = assembly.rigid_body_modes(mesh, u, held)
            surfaces = sorted({name for pair in scene.contact for name in (pair.slave, pair.master)})
            slip = (assembly.slip_modes(mesh, u, surfaces, self.bc_dofs)
                    if surfaces and scene.solver.contact_slip_modes else None)
            soft = scene.solver.contact_multigrid_alpha
            preconditioner.check_multigrid_alpha(scene)
            strain = assembly.dilatations(mesh, u)
            self.system = System(K, self.f_ext, self.bc_dofs, bc_values, nullspace, comm,
                                 scene.solver.max_active_set_iterations, scene.solver.contact_preconditioner,
                                 scene.solver.contact_band_layers, slip, soft, stencil_digests, lifting, strain)
            for vec in strain:
                vec.destroy()
            self.n_constrained = comm.allreduce(len(self.bc_dofs), op=MPI.SUM)
            self.restraint = Restraint(mesh, self.bc_dofs, u)
            self.system.free_motions = lambda terms, active: describe(self.restraint.free(terms, active))
            self.system.free_load = self.restraint.free_load
        replace_results(self.out, comm)
        self.writer = ResultWriter(mesh, self.out, scene.output.xdmf)
        path = self.out / "scene.resolved.toml"
        write_on_root(comm, path, lambda: path.write_text(scene.to_toml()))
        self.summary = self._summary_header()
        self.steps_written = []     # summary.json's steps, encoded (output.write_json)
        self.write_summary()          # "running", from the end of the set-up on

    def _summary_header(self):
        mesh = self.mesh
        return {
            "scene": self.scene.name, "status": "running", "qsc_petsc": __version__,
            "petsc": ".".join(map(str, PETSc.Sys.getVersion())), "ranks": self.comm.size,
            "mesh": {"cell_type": mesh.cell_type, "cells": mesh.n_cells, "vertices": mesh.n_vertices,
                     "dofs": 3 * mesh.n_vertices, "constrained_dofs": self.n_constrained,
                     "stiffness_assembly": self.stiffness_path, "partitioner": mesh.partitioner,
                     "bodies": mesh.body_names,
                     "cells_per_rank": self.comm.allgather(len(mesh.cells)),
                     "dofs_per_rank": self.comm.allgather(3 * int(mesh.owned.sum()))},
            "steps": [],
        }

    def local_displacement(self, u):
        """Ghosted local displacement array (nv, 3) from the global Vec."""
        return self.mesh.local_vectors(u)

    @cached_property
    def held_boundaries(self):
        """(index, boundary) of the displacement and symmetry boundaries: those with a reaction."""
        return [(i, bc) for i, bc in enumerate(self.scene.boundary) if bc.type != "pressure"]

    @cached_property
    def reaction_cells(self):
        """The local cells at a displacement or symmetry surface's vertices, whose element forces the reactions sum."""
        at = np.zeros(len(self.mesh.coords), bool)
        for _, bc in self.held_boundaries:
            at[self.mesh.surface_vertices(bc.surface)] = True
        return np.flatnonzero(at[self.mesh.cells].any(axis=1))

    def reactions(self, u, t):
        """Net force [N] that each displacement/symmetry boundary exerts on the body (its constrained components).

        K u - f is read on the constrained dofs only, so the element forces are summed over the cells at their
        surfaces' vertices (985k-dof box, 2 ranks: 0.25-0.34 s over every cell); none without such boundaries."""
        mesh = self.mesh
        dm = mesh.dm
        held = self.held_boundaries
        if not held:
            return {}
        ul = self.local_displacement(u).ravel()
        fl = dm.createLocalVec()
        fl.getArray()[:] = assembly.internal_force(mesh, ul, self.lmbda, self.mu, self.reaction_cells, self.kappa)
        r = u.duplicate()
        r.set(0.0)
        dm.localToGlobal(fl, r, addv=PETSc.InsertMode.ADD_VALUES)
        r.axpy(-t, self.f_ext)
        if self.contact is not None:
            self.contact.add_forces(u, r)
        rarr = r.getArray()
        r0 = u.getOwnershipRange()[0]
        out = {}
        for i, bc in held:
            # only the components this boundary holds: on an edge shared with another boundary the
            # other components are that boundary's reaction, and one that both hold the first's (dirichlet_dofs)
            dofs = self.bc_per_boundary[i]
            local = np.bincount(dofs % 3, weights=rarr[dofs - r0], minlength=3)
            total = self.comm.allreduce(local, op=MPI.SUM)
            out[f"boundary[{i}] {bc.surface}"] = total.tolist()     # K u - f: the force it applies to the body
        r.destroy()
        fl.destroy()
        return out

    def fields(self, u, rotation=None):
        mesh = self.mesh
        ul = self.local_displacement(u)
        k = mesh.cells.shape[1]
        ue = ul[mesh.cells].reshape(len(mesh.cells), 3 * k)
        stress = elasticity.cell_stress(mesh.cell_type, mesh.coords[mesh.cells], ue, self.lmbda, self.mu,
                                        kappa=self.kappa, rotation=rotation)
        point = {"displacement": ul}
        cell = {"stress": stress, "von_mises": elasticity.von_mises(stress)[:, None],
                "body": mesh.cell_body[:, None].astype(float),
                "rank": np.full((len(mesh.cells), 1), float(self.comm.rank))}
        return point, cell, ul

    def _largest_strain(self, stress, rotation, ul):
        """The largest strain component over the cells (normal strains and half the engineering shears, from the
        cells' stresses through the compliance of their materials, and the stretch of their edges) and where (a
        cell's centroid), then the largest of each cell's rotation (rotation: as fields fills it) and where: the
        same on every rank. A cantilever turned 0.42 rad, whose linear answer stretched it 5.2 %, had strains of
        0.0044 (hunt33_6). ul: the local nodes' displacements."""
        lm, mu = self.lmbda[:, None], self.mu[:, None]
        normal = stress[:, :3] / (2 * mu) - lm * stress[:, :3].sum(axis=1, keepdims=True) / (2 * mu * (3 * lm + 2 * mu))
        size = np.abs(np.hstack([normal, stress[:, 3:] / (2 * mu)])).max(axis=1, initial=0.0)
        # the edges' stretch (du . e / |e|^2, the linear normal strain along each edge; rotations add nothing): a
        # beam bent two cells thick has its centroids at a quarter of its depth, where the strain is half its
        # fibres' (0.034 read against 0.061-0.070 at its root; hunt33_6)
        a, b = (self.mesh.cells[:, list(end)] for end in zip(*fem.CELL_EDGES[self.mesh.cell_type]))
        edge = self.mesh.coords[b] - self.mesh.coords[a]
        stretch = np.abs(np.einsum("cek,cek->ce", ul[b] - ul[a], edge)) / np.einsum("cek,cek->ce", edge, edge)
        size = np.maximum(size, stretch.max(axis=1, initial=0.0))

        def largest(values):
            # of cells as large (to 1e-9), the first by x, y, z of its centre: a uniform strain named a different
            # cell on 1 and 2 ranks (hunt34_2)
            value, where, _ = first_largest(self.comm, values, self._centres, relative=1e-9)
            return (value, where) if where is not None else (0.0, [0.0] * 3)
        return (*largest(size), *largest(rotation))

    @cached_property
    def _centres(self):
        """The local cells' centroids (the mean of their nodes) [m], where _largest_strain places its cells."""
        return self.mesh.coords[self.mesh.cells].mean(axis=1)

    @cached_property
    def _reach(self):
        """The model's farthest node from the origin and from the centre of its bounding box [m] (collective)."""
        X = self.mesh.coords
        low = np.min(self.comm.allgather(X.min(axis=0, initial=np.inf)), axis=0)
        high = np.max(self.comm.allgather(X.max(axis=0, initial=-np.inf)), axis=0)
        far = self.comm.allreduce(float(np.abs(X).max(initial=0.0)), op=MPI.MAX)
        return far, self.comm.allreduce(float(np.abs(X - 0.5 * (low + high)).max(initial=0.0)), op=MPI.MAX)

    def _round_off_line(self, u, ul, t, contact):
        """The warning for an answer at load factor t that stands on round-off, not on the tolerance, else None
        (hunt33_3, hunt34_2): applied loads (pressures, prescribed displacements) whose own forces are below
        FLOOR_SHARE of the Newton test's floor (those of a strain of FLOOR_STRAIN), solved to rtol of the floor or
        to its round-off floor, whose last residual stands above max(ROUND_OFF_ANSWER, 10 rtol) of the loads' own
        forces (a direct solve's exact step stands at round-off); and contact gaps whose precision eps |x| stands
        above ROUND_OFF_ANSWER of the loads' displacements: the bodies' largest, the travel of the dies whose rows
        close, and the pressures' and prescribed displacements' forces as a strain over the model's half-extent (a
        die that travelled just to touch leaves |u| round-off under loads that are not). contact: the step's
        report (collective)."""
        system, parts, cures = self.system, [], []
        rtol = system.snes.getTolerances()[0]
        own = system.own_force_scale(u)
        # applied loads only: a die that travelled just to touch leaves |K u| round-off, and no load to be off
        if system.t * system.b_norm > 0 and own < FLOOR_SHARE * system.force_floor and system.last_fnorm is not None:
            share = system.last_fnorm / own
            if share > max(ROUND_OFF_ANSWER, 10 * rtol):
                parts.append(f"the Newton test stopped at {share:.2g} of their own forces ({own:.3g} N: it solves to "
                             f"rtol {rtol:g} of the forces of a {FLOOR_STRAIN:g} strain at least, or to its round-off "
                             f"floor)")
                cures.append("lower -qsc_snes_rtol")
        if self.contact is not None:
            far, extent = self._reach
            precision = np.finfo(float).eps * far
            moved = self.comm.allreduce(float(np.abs(ul).max(initial=0.0)), op=MPI.MAX)
            travel = max((t * float(np.linalg.norm(die.motion)) for i, die in enumerate(self.scene.die)
                          if contact.get(f"die[{i}] {die.name}", {}).get("active_rows")), default=0.0)
            forced = t * system.b_norm / system.force_floor * FLOOR_STRAIN * extent if system.force_floor > 0 else 0.0
            loads = max(moved, travel, forced)
            if loads > 0 and precision > ROUND_OFF_ANSWER * loads:
                parts.append(f"the coordinates' precision eps |x| ({precision:.3g} m), which the contact gaps stand "
                             f"on, stands at {precision / loads:.2g} of their displacements (the largest {moved:.3g} m)")
        if not parts:
            return None
        return (f"the loads strain the bodies too little for their answer: {'; '.join(parts)}. The answer may be off "
                f"by about as much or more (contact forces, stresses): pose the scene with larger loads (with no "
                f"initial gaps the linear answer scales with them)" + "".join(f", or {c}" for c in cures))

    def write_summary(self):
        self.summary["time"] = self.phases.summary()
        self.summary["peak_memory_mib"] = peak_memory_mib(self.comm)
        path = self.out / "summary.json"
        write_on_root(self.comm, path, lambda: write_json(path, self.summary, self.steps_written))

    def execute(self):
        """Run every load step and return the summary; the scene's PETSc options leave the database when it
        ends, failed or not (an in-process caller's next run must not inherit them)."""
        try:
            return self._load_steps()
        finally:
            options.remove_options(self.from_scene)

    def _load_steps(self):
        scene, system = self.scene, self.system
        n_steps = scene.load.steps
        u = system.u.copy()
        update = self.contact.terms if self.contact else (lambda u, t, t0, before: [])
        large = [pair for pair in scene.contact if pair.sliding == "large"]
        settle = self.contact.settle if large else None
        max_searches = max((pair.max_searches for pair in large), default=2)
        augmented_max = max((pair.augmented_max_iterations for pair in scene.contact
                             if pair.enforcement == "augmented_lagrangian"), default=25)
        # dies and finite-sliding pairs: nodes out of reach at an increment's start that went through (missed)
        guarded = bool(scene.die) or any(pair.sliding == "finite" for pair in scene.contact)
        sticking = any(die.condition == "sticking" for die in scene.die)
        before = None         # the converged state before u, (t, Vec): the predictor's path, the sticking dies' too
        last_loose = ""       # the last step's loose motions (Restraint.loose), warned when they change
        strained = False      # the large-strain warning said
        coarse = False        # the round-off warning said
        try:
            for step in range(1, n_steps + 1):
                t_prev, t = (step - 1) / n_steps, step / n_steps
                with self.phases("solve"):
                    u, stats, before = solve_load_step(
                        system, step, t_prev, t, u, update, scene.solver.max_cutbacks,
                        augmented_max=augmented_max, log=self.log,
                        before=before, predict=scene.solver.predictor == "extrapolate", settle=settle,
                        max_searches=max_searches, missed=self.contact.missed if guarded else None,
                        split=self.contact.pathless_met if sticking else None)
                with self.phases("output"):
                    rotation = np.empty(len(self.mesh.cells))
                    point, cell, ul = self.fields(u, rotation)
                    record = self._step_record(step, t, stats, u, ul)
                    strain, where, turn, turned_at = self._largest_strain(cell["stress"], rotation, ul)
                    large = strain > LARGE_STRAIN * THRESHOLD_MARGIN
                    if (large or turn > LARGE_ROTATION * THRESHOLD_MARGIN) and not strained:
                        strained = True
                        what = (f"strains reach {strain:.2g} (a cell near x, y, z = "
                                f"{', '.join(f'{v:.4g}' for v in where)})" if large else
                                f"rotations reach {turn:.2g} rad (a cell near x, y, z = "
                                f"{', '.join(f'{v:.4g}' for v in turned_at)})")
                        self.log(f"step {step}: warning: {what}: the elasticity is linear, for small strains and "
                                 f"rotations; past a few % (or 0.1 rad) its answer departs from a finite-strain "
                                 f"one's (a rotation stretches it by about its square over 2), and past 100 % "
                                 f"cells turn inside out. Read at the cells' centres and along their edges")
                    if self.contact is not None:
                        cpoint, record["contact"] = self.contact.report(u, ul)
                        point.update(cpoint)
                        for line in self.contact.slip_warnings(record["contact"]):
                            self.log(f"step {step}: warning: {line}")
                        loose = describe(self.restraint.loose(system.terms, u))
                        if loose:
                            record["loose"] = loose
                        if loose and loose != last_loose:
                            self.log(f"step {step}: warning: {loose}: held there by no boundary and only by "
                                     f"contact rows that carry no force, if any, so the scene does not set its "
                                     f"position along that motion (this answer is one of many); hold it with a "
                                     f"boundary condition, or a die or contact within reach that presses on it "
                                     f"(summary: loose)")
                        last_loose = loose
                    line = self._round_off_line(u, ul, t, record.get("contact", {}))
                    if line and not coarse:
                        coarse = True
                        self.log(f"step {step}: warning: {line}")
                    with held_interrupts():
                        self.writer.write_step(step, t, point, cell)
                        self.summary["steps"].append(record)
                        self.write_summary()
                last = stats["solves"][-1]
                floor = last.get("round_off_floor")
                if floor is not None and floor > ROUND_OFF_WARNING:
                    eps, name = max(((term.eps_n, term.name) for term in system.terms), default=(0.0, ""))
                    why = (f"the round-off of the penalty rows (eps_n times the coordinates' precision) lies there, "
                           f"and the contact forces and tractions may be off by as much; lower the penalty of the "
                           f"stiffest, {name} (eps_n {eps:.3g} Pa/m)" if name else
                           "the linear solves' round-off lies there, and the reactions may be off by as much")
                    self.log(f"step {step}: warning: the solve stopped on its Newton steps (below stol x |u|) with "
                             f"the residual at {floor:.2g} of its force scale: {why}")
                settled = last.get("multipliers_at_round_off")
                if settled and settled[0] not in self.round_off_said:
                    self.round_off_said.add(settled[0])
                    name, change, tol, bound = settled
                    self.log(f"step {step}: warning: the augmented Lagrangian's updates of {name} ended on their "
                             f"round-off: they still changed its multipliers by {change:.2g} (relative), above its "
                             f"augmented_tolerance {tol:g} but within {AUGMENTED_ROUND_OFF:g}x the multipliers' "
                             f"round-off (eps_n times the rows' precision: {bound / AUGMENTED_ROUND_OFF:.2g}), below which no update can go; the answer "
                             f"holds to that. A lower penalty meets the tolerance: the augmented Lagrangian needs no "
                             f"stiff one")
                for name, rows, share, tol in last.get("augmented_penalty_rows") or ():
                    if (name, "penalty rows") not in self.round_off_said:
                        self.round_off_said.add((name, "penalty rows"))
                        self.log(f"step {step}: warning: {rows} row(s) of {name} keep no augmented multiplier (their "
                                 f"stiffness on their own nodes below {AUGMENTED_SLIVER:g} of the largest: slivers "
                                 f"past an edge, whose multipliers the updates would grow without moving their gaps) "
                                 f"and carry {share:.2g} of its normal force, above its augmented_tolerance {tol:g}: "
                                 f"there the answer is the penalty's, off the stiff limit by about their share of its "
                                 f"compliance; a larger penalty narrows it (summary: augmented_penalty_rows)")
                # both counts over every try of the step, cut back or not (the summary's snes/ksp_iterations)
                # the augmented Lagrangian's updates too: its step line gave "130 Newton / 130 Krylov" alone (hunt35_1)
                updates = sum(solve.get("augmented_iterations", 0) for solve in stats["solves"])
                self.log(f"step {step}/{n_steps}: load factor {t:.4g}, {record['snes_iterations']} Newton / "
                         f"{record['ksp_iterations']} Krylov iterations"
                         + (f" / {updates} augmented updates" if updates else "") + ", "
                         f"{last['snes_reason']}{_kept_rows(record.get('contact', {}))}")
                if last.get("tied_in_tension"):
                    self.log(f"step {step}: note: {last['tied_in_tension']} sticking die node(s) held in slight "
                             f"tension: their pressure is about zero, and letting them go made the Newton "
                             f"iterations cycle (summary: tied_rows, tied_in_tension)")
        except QscError as exc:
            self.summary["status"] = "failed"
            self.summary["error"] = str(exc)
            self._finish()
            raise
        except KeyboardInterrupt:
            # Ctrl-C: serially the folder can still say so (summary.json read "running" for ever); in parallel the
            # ranks stop wherever the signal found them, so rank 0, if the signal reached it, writes the summary it
            # holds (the finished steps) alone, with no collective call (the CLI then ends the job)
            self.summary["status"] = "interrupted"
            if self.comm.size == 1:
                self._finish()
            elif self.comm.rank == 0:
                try:
                    write_json(self.out / "summary.json", self.summary)
                except OSError:
                    pass              # interrupted all the same; the folder keeps the last step's summary
            raise
        self.summary["status"] = "ok"
        self._finish()
        self.u = u
        return self.summary

    def _finish(self):
        """summary.json and petsc_options.txt at the end of the run, failed or not: the options a failed run ran
        with are what its user changes next (collective)."""
        in_effect = self.summary["petsc_options"] = options.options_in_effect()
        self.write_summary()
        self._write_options(in_effect, self.system.settings())   # execute runs only on a built Run: it has a system

    def _write_options(self, in_effect, settings=()):
        """petsc_options.txt (collective)."""
        path = self.out / "petsc_options.txt"
        write_on_root(self.comm, path,
                      lambda: path.write_text(options.options_text(in_effect, self.from_scene, settings,
                                                                   PETSC_DEFAULTS)))

    def _step_record(self, step, t, stats, u, ul):
        last = stats["solves"][-1]
        umax = self.comm.allreduce(float(np.abs(ul[self.mesh.owned]).max(initial=0.0)), op=MPI.MAX)
        return {
            "step": step, "load_factor": t, "cutbacks": stats["cutbacks"],
            "snes_iterations": sum(s["snes_iterations"] for s in stats["solves"]),
            "ksp_iterations": sum(s["ksp_iterations"] for s in stats["solves"]),
            "snes_reason": last["snes_reason"], "ksp_reason": last["ksp_reason"],
            "solves": stats["solves"], "max_abs_displacement": umax,
            "reactions": self.reactions(u, t),
        }

    def destroy(self):
        """Release the run's PETSc objects (collective); a second call does nothing."""
        if self.destroyed:
            return
        self.destroyed = True
        options.remove_options(self.from_scene)   # scene options live only while their run does
        self.system.destroy()
        self.restraint.destroy()
        if self.contact is not None:
            self.contact.destroy()
