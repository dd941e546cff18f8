"""The Newton loop's economy: an unchanged active set keeps the Jacobian and its preconditioner, and the
Krylov solve stops where the Newton test needs it (solver.System). Small two-cube scene between sticking
dies, serial, the iterative defaults."""

import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import CONFIGS, ROOT, run_scene, scene_without_petsc
from mpi4py import MPI
from petsc4py import PETSc

sys.path.insert(0, str(ROOT / "scripts"))
import bench_contact

from qsc_petsc import solver
from qsc_petsc.errors import ConvergenceError
from qsc_petsc.run import Run
from qsc_petsc.scene import load_scene
from qsc_petsc.solver import FLOOR_SPAN, KRYLOV_MARGIN, STALL_WINDOW, START_REACH, START_TOUCHING, System

SMALL = ["bodies.0.mesh.cells=[3,3,3]", "bodies.1.mesh.cells=[4,4,4]"]


def _solves(summary):
    """Every SNES solve of a run's summary, increment by increment."""
    return [s for step in summary["steps"] for s in step["solves"]]


def test_unchanged_active_set_keeps_the_jacobian(tmp_path):
    """Every increment's second Newton step sees the active set of the first: it shall reuse the Jacobian
    (one assembly per increment) and still give the direct solver's answer. Each increment starts from the
    previous state (the extrapolating predictor would make the second increment's first step exact)."""
    run, summary = run_scene(scene_without_petsc(tmp_path), tmp_path / "iterative",
                             SMALL + ['solver.predictor="previous"', "contact.0.reuse_tolerance=0"])
    solves = _solves(summary)
    assert all(s["snes_iterations"] == 2 and s["jacobian_assemblies"] == 1 for s in solves)
    u = run.u.getArray().copy()
    direct, _ = run_scene(CONFIGS / "two_cubes_dies.toml", tmp_path / "direct", SMALL + ["contact.0.reuse_tolerance=0"])
    ref = direct.u.getArray()
    assert np.abs(u - ref).max() <= 1e-8 * np.abs(ref).max()


def test_search_with_the_same_coupling_keeps_jacobian_and_band(tmp_path, monkeypatch):
    """The second increment's search of the flat two-cube contact couples the same dofs: J keeps its pattern
    (the same matrix, reset to K) and the band's preconditioner objects stay, and with the same rows active
    its setup too (only the projections moved); the answer is MUMPS's. A contact pair's G^T G lies outside
    K's pattern, the dies' inside it (node_local)."""
    seen = []
    original = System.set_terms

    def spy(self, terms):
        original(self, terms)
        pc = self.snes.getKSP().getPC()
        seen.append((self.J.handle, pc.handle, pc.getType(), [t.node_local for t in terms]))

    monkeypatch.setattr(System, "set_terms", spy)
    run, summary = run_scene(scene_without_petsc(tmp_path), tmp_path / "iterative",
                             SMALL + ["contact.0.reuse_tolerance=0"])
    assert summary["status"] == "ok" and len(seen) == 2
    (j1, pc1, kind, local), (j2, pc2, _, _) = seen
    assert kind == "python" and (j1, pc1) == (j2, pc2)
    assert local == [False, True, True]                 # contact[0], die[0], die[1]
    assert run.system.band_parts.keep                   # the second increment kept the first one's setup
    u = run.u.getArray().copy()
    direct, _ = run_scene(CONFIGS / "two_cubes_dies.toml", tmp_path / "direct", SMALL + ["contact.0.reuse_tolerance=0"])
    ref = direct.u.getArray()
    assert np.abs(u - ref).max() <= 1e-8 * np.abs(ref).max()


@pytest.mark.parametrize("reuse", ["0", "1e-3"])
def test_a_kept_search_does_not_redo_the_band(tmp_path, monkeypatch, reuse):
    """The band follows the contact stencil's pattern: a later search with the same pattern (new rows,
    reuse_tolerance = 0) or the very same term (the default tolerance keeps it) keeps J, the composite and
    the band without computing the band again, and the kept term's search leaves J's stiffnesses as they
    were (no Jacobian assembled in that increment)."""
    from qsc_petsc import preconditioner
    calls = []
    original = preconditioner.band_dofs
    monkeypatch.setattr(preconditioner, "band_dofs", lambda *a, **k: calls.append(1) or original(*a, **k))
    seen = []
    set_terms = System.set_terms

    def spy(self, terms):
        set_terms(self, terms)
        seen.append((self.J.handle, self.snes.getKSP().getPC().handle, self.band))

    monkeypatch.setattr(System, "set_terms", spy)
    _, summary = run_scene(scene_without_petsc(tmp_path), tmp_path / "out",
                           SMALL + [f"contact.0.reuse_tolerance={reuse}", "load.steps=3"])
    assert summary["status"] == "ok" and len(seen) == 3 and len(calls) == 1
    assert len({(j, pc) for j, pc, _ in seen}) == 1 and all(band is seen[0][2] for _, _, band in seen)
    kept = [next(iter(step["contact"].values()))["rows_kept"] for step in summary["steps"]]
    assert kept == ([False] * 3 if reuse == "0" else [False, True, True])
    if reuse != "0":
        assert [s["jacobian_assemblies"] for s in _solves(summary)][1:] == [0, 0]


def test_search_with_the_same_rows_keeps_the_jacobian_as_it_is(tmp_path):
    """A block between two dies: every search finds the same die rows, so J keeps its stiffnesses and, the
    active set unchanged, no increment after the first assembles a Jacobian or rebuilds its preconditioner;
    the answer is the direct solver's."""
    scene = tmp_path / "die_block.toml"
    scene.write_text(bench_contact.scene(2, "merged"))        # a 3 x 3 x 6 block between sticking dies
    run, summary = run_scene(scene, tmp_path / "iterative", ["load.steps=3"])
    assert [s["jacobian_assemblies"] for s in _solves(summary)] == [1, 0, 0]
    u = run.u.getArray().copy()
    direct, _ = run_scene(scene, tmp_path / "direct", ["load.steps=3", "petsc.ksp_type=preonly", "petsc.pc_type=lu"])
    ref = direct.u.getArray()
    assert np.abs(u - ref).max() <= 1e-8 * np.abs(ref).max()


def test_krylov_stops_at_the_newton_target(tmp_path):
    """With the true-residual norm the KSP's absolute tolerance is KRYLOV_MARGIN x snes_rtol x the force
    scale of the current iterate (the last Newton step's, within 1e-6 of the final one); a ksp_atol the user sets stays."""
    run, _ = run_scene(scene_without_petsc(tmp_path), tmp_path / "auto", SMALL)
    snes = run.system.snes
    atol = snes.getKSP().getTolerances()[1]
    assert atol == pytest.approx(KRYLOV_MARGIN * snes.getTolerances()[0] * run.system.force_scale, rel=1e-6)
    assert atol > 1e-40
    run, _ = run_scene(scene_without_petsc(tmp_path, 'ksp_atol = "1e-40"'), tmp_path / "user", SMALL)
    assert run.system.snes.getKSP().getTolerances()[1] == 1e-40
    assert not PETSc.Options().hasName("qsc_ksp_atol")      # the scene's option left with its run


def test_named_boomeramg_gets_the_tuned_defaults(tmp_path):
    """-qsc_pc_type hypre without contact pairs gets the band's BoomerAMG defaults (PMIS, l1-Gauss-Seidel),
    which leave the options database once read; an option the user sets wins."""
    from qsc_petsc.preconditioner import HYPRE_DEFAULTS

    def pc_view(sets):
        run, _ = run_scene(CONFIGS / "block_compression.toml", tmp_path / "out", sets)
        path = tmp_path / "pc.txt"
        viewer = PETSc.Viewer().createASCII(str(path))
        run.system.snes.getKSP().getPC().view(viewer)
        viewer.destroy()
        run.destroy()
        return path.read_text()

    text = pc_view(["petsc.pc_type=hypre"])
    assert "PMIS" in text and "l1-Gauss-Seidel" in text
    assert not any(PETSc.Options().hasName("qsc_" + key) for key in HYPRE_DEFAULTS)
    assert "HMIS" in pc_view(["petsc.pc_type=hypre", "petsc.pc_hypre_boomeramg_coarsen_type=HMIS"])


def test_no_solve_ends_in_the_closed_start(tmp_path):
    """The closed start (every row within reach closed, either sign) is the first iterate's only: a kept
    Jacobian (augmented Lagrangian re-solves start from the set they ended with) must not keep it, or the
    re-solve would converge to the glued problem."""
    run, summary = run_scene(CONFIGS / "patch_test.toml", tmp_path / "out",
                             ['contact.0.enforcement="augmented_lagrangian"'])
    assert summary["status"] == "ok"
    assert any(s["augmented_iterations"] > 0 for s in _solves(summary))
    assert not any(term.start for term in run.system.terms)


def test_increment_starts_from_the_touching_rows(tmp_path, monkeypatch):
    """A curved contact (hertz_coarse, two increments) starts each increment with the rows that touch or
    penetrate closed, not every row within reach: the same answer in fewer Newton iterations (measured
    9 + 8 against 6 + 4 here, 36 + 24 against 20 + 15 on hertz_fine (session 10) with two_pass)."""
    run, summary = run_scene(CONFIGS / "hertz_coarse.toml", tmp_path / "touching")
    assert all(s["closed_start"] == START_TOUCHING for s in _solves(summary))
    u = run.u.getArray().copy()
    monkeypatch.setattr(System, "_start_mode", lambda self, u: START_REACH)
    reach, reach_summary = run_scene(CONFIGS / "hertz_coarse.toml", tmp_path / "reach")
    assert all(s["closed_start"] == START_REACH for s in _solves(reach_summary))
    ref = reach.u.getArray()
    assert np.abs(u - ref).max() <= 1e-8 * np.abs(ref).max()
    newton = [sum(s["snes_iterations"] for s in _solves(x)) for x in (summary, reach_summary)]
    assert newton[0] < newton[1]


def test_increment_starts_with_the_rows_the_last_one_ended_closed(tmp_path, monkeypatch):
    """The stiff plate's interface slides and tilts between increments: the new search finds gaps about 1e-6 m
    apart from those the last increment converged to, so the touching rows alone were a few of the closed ones
    (168 of 676 at 25 x 25 x 5 cells pressed 2 %) and the second increment took 4 Newton steps here; with the
    rows the first ended closed held closed too it takes 1, to the same answer."""
    sets = ["bodies.0.mesh.cells=[4,4,4]", "bodies.1.mesh.cells=[6,6,2]", "output.xdmf=false"]
    run, summary = run_scene(CONFIGS / "stiff_plate.toml", tmp_path / "held", sets)
    u = run.u.getArray().copy()
    start_mode = System._start_mode

    def touching_only(self, u):
        self.closed_rows = {}
        return start_mode(self, u)
    monkeypatch.setattr(System, "_start_mode", touching_only)
    touching, touching_summary = run_scene(CONFIGS / "stiff_plate.toml", tmp_path / "touching", sets)
    newton = [[s["snes_iterations"] for s in _solves(x)] for x in (summary, touching_summary)]
    assert newton[0][1] == 1 and newton[1][1] >= 3, newton
    ref = touching.u.getArray()
    assert np.abs(u - ref).max() <= 1e-8 * np.abs(ref).max()


def test_body_held_only_across_a_gap_starts_within_reach(tmp_path):
    """The patch test's upper block 0.01 m above the lower, held only by contact: no row touches, so the
    touching start would leave it free (a singular first Newton step); it starts with every row within reach
    closed (test_extremes.test_gap_closed_by_the_load checks that its answer is the touching one)."""
    _, summary = run_scene(CONFIGS / "patch_test.toml", tmp_path / "gap", ["bodies.1.mesh.origin=[0,0,0.51]"])
    assert summary["status"] == "ok"
    assert _solves(summary)[0]["closed_start"] == START_REACH


def test_extrapolated_increment_of_a_linear_response_takes_one_newton_step(tmp_path):
    """The two cubes between sticking dies respond linearly once the active set holds: from the extrapolation
    of the converged states at t = 0 and 1/3, the increments to 2/3 and 1 start within the Newton target of
    their answers and take one Newton step each, fewer Krylov iterations than from the previous state,
    and the same answer."""
    sets = SMALL + ["load.steps=3"]
    run, summary = run_scene(scene_without_petsc(tmp_path), tmp_path / "extrapolate", sets)
    solves = _solves(summary)
    assert [s["predictor"] for s in solves] == ["previous", "extrapolated", "extrapolated"]
    assert [s["snes_iterations"] for s in solves[1:]] == [1, 1]
    prev, prev_summary = run_scene(scene_without_petsc(tmp_path), tmp_path / "previous",
                                   sets + ['solver.predictor="previous"'])
    assert all(s["predictor"] == "previous" for s in _solves(prev_summary))
    krylov = [sum(s["ksp_iterations"] for s in _solves(x)[1:]) for x in (summary, prev_summary)]
    assert krylov[0] < krylov[1]
    u, ref = run.u.getArray(), prev.u.getArray()
    assert np.abs(u - ref).max() <= 1e-8 * np.abs(ref).max()


def test_cycle_watch_damps_from_a_returning_active_set():
    """An active set met again two or more iterations later is a cycle: steps are damped from there on. The
    same set at consecutive iterations is an iteration converging, not a cycle."""
    A, B, C = (np.array(v, bool) for v in ([1, 0, 1], [1, 1, 1], [0, 0, 1]))

    def watch(sets, fnorms=None):
        ns = SimpleNamespace(comm=MPI.COMM_SELF)
        for it, active in enumerate(sets):
            System._watch_cycles(ns, it, active, 1.0 / (it + 1) if fnorms is None else fnorms[it])
        return ns.damped_from

    assert watch([A, A, A]) is None
    assert watch([A, B, C, B]) == 3
    assert watch([A, B, A]) == 2
    assert watch([A, B, C, C, B]) == 4
    assert watch([A, B, A, B, A]) == 2       # the first return damps; later ones do not move it
    # wandering without a repeat: damped once STALL_WINDOW iterations bring no new lowest residual
    wander = [np.array([(k >> b) & 1 for b in range(5)], bool) for k in range(20)]
    norms = [1.0, 0.5] + [0.6 + 0.1 * (k % 3) for k in range(18)]
    assert watch(wander, norms) == STALL_WINDOW + 1
    assert watch(wander) is None                         # a residual falling every iteration is never damped


def test_round_off_floor_rule():
    """A step taken with the final active set and a converged Krylov solve that does not halve the residual,
    near the target, is the round-off floor; a residual that halves, one far above the target (a stalled
    Newton method), a failed Krylov solve, the first step or a direct solve's single step are not (two in a
    row are)."""
    def floor(it, fnorm, last, target=1e-12, ksp_reason=2, ksp_type="cg", before=None):
        ksp = SimpleNamespace(getConvergedReason=lambda: ksp_reason, getType=lambda: ksp_type)
        ns = SimpleNamespace(snes=SimpleNamespace(getKSP=lambda: ksp))
        return System._on_floor(ns, it, fnorm, last, target, before)

    assert floor(2, 6.1e-13 * 16, 9.5e-13 * 16)
    assert not floor(2, 4e-13 * 16, 9.5e-13 * 16)                 # halved: Newton still gaining
    assert not floor(2, 2 * FLOOR_SPAN * 1e-12, 2.1 * FLOOR_SPAN * 1e-12)   # stalled far above the target
    assert not floor(2, 9e-12, 1e-11, ksp_reason=-3)              # the Krylov solve failed
    assert not floor(1, 9e-12, 1e-11)                             # the first step is measured from F(u0)
    assert not floor(2, 9e-12, 1e-11, ksp_type="preonly")         # a direct solve's next step may still refine
    assert not floor(3, 9e-12, 1e-11, ksp_type="preonly", before=3e-11)     # ... it did: the step before halved
    assert floor(3, 9e-12, 1e-11, ksp_type="preonly", before=1.1e-11)       # two steps in a row: the floor


def test_damped_steps_reach_the_same_answer(tmp_path, monkeypatch):
    """With damping on from the first iteration (as after a cycle), every step goes through the backtracking
    pre-check (System._damp): hertz_coarse converges to the undamped answer."""
    run, _ = run_scene(CONFIGS / "hertz_coarse.toml", tmp_path / "full")
    u = run.u.getArray().copy()

    def always(self, it, active, fnorm):
        self.damped_from, self.cycled = 0, False

    monkeypatch.setattr(System, "_watch_cycles", always)
    damped, summary = run_scene(CONFIGS / "hertz_coarse.toml", tmp_path / "damped")
    assert summary["status"] == "ok"
    assert all(s["damped_from"] == 0 for s in _solves(summary))
    ref = damped.u.getArray()
    assert np.abs(u - ref).max() <= 1e-8 * np.abs(ref).max()


def test_run_left_alive_in_process_exits_cleanly(tmp_path):
    """A Run used from Python and never destroyed (the contact band's composite preconditioner, with its
    Python part, alive at exit) is destroyed before PETSc finalizes: the interpreter exits 0, no SEGV."""
    scene = scene_without_petsc(tmp_path)
    code = (f"from mpi4py import MPI\n"
            f"from qsc_petsc.run import Run\nfrom qsc_petsc.scene import load_scene\n"
            f"run = Run(load_scene({str(scene)!r}, {SMALL!r}), MPI.COMM_WORLD, {str(tmp_path / 'out')!r},"
            f" log=lambda *a, **k: None)\n"
            f"assert run.execute()['status'] == 'ok'\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                          check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "SEGV" not in proc.stderr


def test_a_try_reports_the_failure_of_its_last_solve():
    """An increment's try merges the counts of its solves (augmented Lagrangian updates, large sliding's
    searches) and takes the outcome of the last: an augmented Lagrangian loop that failed in a later solve
    reports which pair's multipliers were still moving (a large-sliding slide with an augmented pair at alpha
    1e2 stopped with a KeyError instead of that message before session 17)."""
    from qsc_petsc.solver import _merge
    first = {"snes_iterations": 3, "ksp_iterations": 3, "jacobian_assemblies": 2, "damped_steps": 0,
             "tied_rows": 0, "damped_from": None, "snes_reason": "CONVERGED_FNORM_RELATIVE",
             "ksp_reason": "CONVERGED_ITS", "active_rows": 10, "tied_in_tension": 0, "round_off_floor": 3e-2,
             "linear_short": False}
    later = dict(first, snes_iterations=5, damped_from=4, tied_rows=2, snes_reason="AUGMENTED_LAGRANGIAN_MAX_IT",
                 multipliers_unsettled=("contact[1]", 1.6e-5, 1e-6, 1e-12), round_off_floor=None)
    _merge(first, later)
    assert first["round_off_floor"] is None      # the last solve's stop: no warning for an earlier solve's floor
    assert first["snes_iterations"] == 8 and first["ksp_iterations"] == 6 and first["jacobian_assemblies"] == 4
    assert (first["damped_from"], first["tied_rows"]) == (4, 2)
    assert first["snes_reason"] == "AUGMENTED_LAGRANGIAN_MAX_IT"
    assert first["multipliers_unsettled"] == ("contact[1]", 1.6e-5, 1e-6, 1e-12)


@pytest.mark.parametrize("free, cap", [(2e6, 1), (None, None), (4e9, 3600)])
def test_mumps_memory_cap_from_the_available_memory(tmp_path, monkeypatch, free, cap):
    """A run solving with MUMPS shall cap its factorization at MUMPS_MEMORY_SHARE of the rank's share of the
    node's available memory (ICNTL(23), in MB; each solve's summary says it): with 2 MB available the
    2187-dof block needs more and the run fails at once, naming the cap; where the kernel does not say what
    is available, no cap. The cap is in the options database only while a solve runs. A run without MUMPS
    sets none."""
    monkeypatch.setattr(solver, "available_memory", lambda: free)
    scene = tmp_path / "block.toml"
    scene.write_text(
        'name = "block"\n[[bodies]]\nname = "blk"\n'
        'mesh = { type = "box", size = [1.0, 1.0, 1.0], cells = [8, 8, 8] }\n'
        'material = { youngs_modulus = 1000.0 }\n'
        '[[boundary]]\nsurface = "blk.zmin"\ntype = "displacement"\nux = 0.0\nuy = 0.0\nuz = 0.0\n'
        '[[boundary]]\nsurface = "blk.zmax"\ntype = "pressure"\nvalue = 1.0\n'
        '[petsc]\nksp_type = "preonly"\npc = { type = "lu", factor_mat_solver_type = "mumps" }\n')
    run = Run(load_scene(scene), MPI.COMM_WORLD, tmp_path / "out", log=lambda *a, **k: None)
    try:
        if cap == 1:
            with pytest.raises(ConvergenceError, match=r"it needs more memory than its cap of 1 MB a rank "
                                                       r"\(90% of a rank's share of its node's available memory\)"):
                run.execute()
            assert run.summary["status"] == "failed"
        else:
            summary = run.execute()
            assert [s.get("mumps_icntl_23") for s in _solves(summary)] == [cap]
        assert not PETSc.Options().hasName("qsc_mat_mumps_icntl_23")
    finally:
        run.destroy()
    _, summary = run_scene(CONFIGS / "block_compression.toml", tmp_path / "default")
    assert all("mumps_icntl_23" not in s for s in _solves(summary))


@pytest.mark.parametrize("sets, mumps", [(["die.1.motion=[0,0,0]"], False),
                                         (["die.1.motion=[0,0,0]", "contact.0.sliding=\"small\""], False),
                                         (["die.1.motion=[0,0,0]", "contact.0.formulation=two_pass",
                                           "contact.0.integration=nodal"], True)],
                         ids=["finite", "small", "two_pass_mumps"])
def test_a_scene_with_no_load_converges_at_rest(tmp_path, sets, mumps):
    """Two cubes between dies of which neither moves: nothing loads them, and the answer is u = 0. With no load
    |K u| and t |b| are round-off, and the coinciding faces' segment rows have round-off gaps: the residual sat
    at 6.5e-14 N against a target of ~1e-24 for 60 Newton iterations at every cutback and the run failed. The
    Newton test's scale is now at least the elastic forces of a strain of FLOOR_STRAIN. two_pass under MUMPS
    stood at 2e-13 against that floor's 6.4e-14, and stops now on the round-off floor (two direct steps that
    do not halve the residual)."""
    scene = CONFIGS / "two_cubes_dies.toml" if mumps else scene_without_petsc(tmp_path)
    run, summary = run_scene(scene, tmp_path / "out", SMALL + sets)
    u = np.abs(run.u.getArray()).max()
    run.destroy()
    assert summary["status"] == "ok"
    assert u < 1e-12 and all(s["snes_iterations"] <= (10 if mumps else 2) for s in summary["steps"])
    assert abs(next(iter(summary["steps"][-1]["contact"].values()))["total_normal_force"]) < 1e-9


TOUCH = """\
name = "touch"
[[bodies]]
name = "lower"
mesh = { type = "box", origin = [0.0, 0.0, 0.0], size = [1.0, 1.0, 0.5], cells = [4, 4, 2] }
material = { youngs_modulus = 1000.0, poissons_ratio = 0.3 }
[[bodies]]
name = "upper"
mesh = { type = "box", origin = [0.0, 0.0, 0.51], size = [1.0, 1.0, 0.5], cells = [5, 5, 3] }
material = { youngs_modulus = 1000.0, poissons_ratio = 0.3 }
[[boundary]]
surface = "lower.zmin"
type = "displacement"
uz = 0.0
[[boundary]]
surface = "upper.zmax"
type = "displacement"
uz = -0.01
[[boundary]]
surface = "lower.xmin"
type = "symmetry"
[[boundary]]
surface = "lower.ymin"
type = "symmetry"
[[boundary]]
surface = "upper.xmin"
type = "symmetry"
[[boundary]]
surface = "upper.ymin"
type = "symmetry"
[[contact]]
slave = "upper.zmin"
master = "lower.zmax"
enforcement = "augmented_lagrangian"
[load]
steps = 2
[petsc]
ksp_type = "preonly"
pc_type = "lu"
pc_factor_mat_solver_type = "mumps"
"""


def test_augmented_lagrangian_settles_on_a_contact_without_force(tmp_path):
    """A gap of 0.01 m closed by a motion of 0.01 m: the bodies end touching with no force, and the augmented
    Lagrangian's multipliers are round-off, whose change relative to themselves stayed at 0.2-1.6 for 200 updates
    (AUGMENTED_LAGRANGIAN_MAX_IT at every cutback; a helper's test pass). The change is now measured against the
    pressure of a strain of FLOOR_STRAIN where the multipliers are smaller."""
    path = tmp_path / "touch.toml"
    path.write_text(TOUCH)
    run, summary = run_scene(path, tmp_path / "out")
    run.destroy()
    assert summary["status"] == "ok"
    assert all(step["cutbacks"] == 0 for step in summary["steps"])
    pair = next(iter(summary["steps"][-1]["contact"].values()))
    assert abs(pair["total_normal_force"]) < 1e-6 * 1000.0 * 1.0


def test_the_force_floor_is_the_softest_bodys(tmp_path):
    """A cube of E = 1e3 pressed 1 % on one of E = 1e12, iterative defaults: the Newton test's floor, from a strain
    of FLOOR_STRAIN of both bodies, was the stiff one's and left the die force 2.5e-7 off MUMPS's (hunt27_4);
    from the softest body's it is within 1e-9."""
    scene = scene_without_petsc(tmp_path)
    sets = SMALL + ["bodies.0.material.youngs_modulus=1e12", "output.xdmf=false"]
    forces = []
    for name, petsc in (("iterative", []), ("mumps", ["petsc.ksp_type=\"preonly\"", "petsc.pc_type=\"lu\"",
                                                      "petsc.pc_factor_mat_solver_type=\"mumps\""])):
        run, summary = run_scene(scene, tmp_path / name, sets + petsc)
        run.destroy()
        assert summary["status"] == "ok"
        forces.append(summary["steps"][-1]["contact"]["die[1] top"]["force_on_bodies"][2])
    assert forces[0] == pytest.approx(forces[1], rel=1e-9)


def test_a_mumps_pc_before_its_first_factorization():
    """A try that failed before its first linear solve leaves a MUMPS PC without a factor, whose
    PCFactorGetMatrix is PETSc error 58: the workspace and reset checks after a failed try read it as no failure."""
    from qsc_petsc import options
    ksp = PETSc.KSP().create(comm=PETSc.COMM_SELF)
    ksp.setType("preonly")
    pc = ksp.getPC()
    pc.setType("lu")
    pc.setFactorSolverType("mumps")
    assert options.factored_by_mumps(pc)
    assert options.mumps_factor(pc) is None
    assert options.more_mumps_workspace(pc, options.PREFIX, set()) is None
    assert not options.reset_failed_mumps(pc)
    ksp.destroy()


def test_a_failed_mumps_factor_is_made_anew():
    """PETSc skips the numeric factorization of a MUMPS factor whose last factorization failed, so the next solve
    called MUMPS with no factors (PETSc error 76, INFOG(1) = -3): a body pulled off the contact that held it ended
    its 2-rank run on that error instead of its cutbacks on a machine where MUMPS met the singular iterate's null
    pivot. options.reset_failed_mumps (System.solve_at, after a failed try) makes the next setup factor anew."""
    from qsc_petsc import options

    def solve(values, reset):
        A.setValues(range(3), range(3), values)
        A.assemble()
        if reset:
            options.reset_failed_mumps(pc)       # as solve_at after a failed try: SNES then sets the operators
        ksp.setOperators(A)
        ksp.solve(b, x)
        return ksp.getConvergedReason()

    for reset in (False, True):
        A = PETSc.Mat().createAIJ((3, 3), nnz=3, comm=PETSc.COMM_SELF)
        ksp = PETSc.KSP().create(comm=PETSc.COMM_SELF)
        ksp.setType("preonly")
        pc = ksp.getPC()
        pc.setType("lu")
        pc.setFactorSolverType("mumps")
        b, x = A.createVecs()
        b.set(1.0)
        assert solve([2, 1, 0, 1, 2, 0, 0, 0, 0], reset) < 0               # singular: INFOG(1) = -10
        assert pc.getFactorMatrix().getMumpsInfog(1) == -10
        if reset:
            assert solve([2, 1, 0, 1, 2, 0, 0, 0, 3], reset) > 0          # made anew
            assert not options.reset_failed_mumps(pc)                      # a good factor stays
            assert np.allclose(x.getArray(), 1.0 / 3.0)
        else:
            with pytest.raises(PETSc.Error) as failed:
                solve([2, 1, 0, 1, 2, 0, 0, 0, 3], reset)
            assert failed.value.ierr == 76
        for obj in (A, ksp, b, x):
            obj.destroy()
