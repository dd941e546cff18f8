"""The output folder: XDMF/HDF5 fields per load step, summary.json, the resolved scene, and their rank independence.

The patch test (two bodies, non-matching meshes, two load steps) runs once on 1 rank and once on
2 ranks through the qsc command; the tests read what those runs wrote. The file-mesh body runs
in-process. These tests start MPI jobs themselves and therefore run only in the serial suite.
"""

import json
from pathlib import Path

import h5py
import meshio
import numpy as np
import pytest
from conftest import CONFIGS, run_scene, write_gmsh_box
from test_cli import MPIRUN, qsc

from qsc_petsc.scene import load_scene

PATCH = CONFIGS / "patch_test.toml"
OVERRIDES = ["bodies.0.mesh.cells=[2,2,1]", "bodies.1.mesh.cells=[3,3,1]", "load.steps=2"]
PRESSURE = 1.0          # Pa on upper.zmax, area 1 m^2 (configs/patch_test.toml)
# A direct solve, so that comparing ranks measures the parallel assembly and output, not the Krylov tolerance.
DIRECT = ["-qsc_ksp_type", "preonly", "-qsc_pc_type", "redundant", "-qsc_redundant_pc_type", "lu"]


def _patch_args(folder, *sets):
    """qsc's arguments for the patch test into `folder`, with OVERRIDES and then `sets`."""
    args = ["run", PATCH, "--out", folder, *DIRECT]
    for text in (*OVERRIDES, *sets):
        args += ["--set", text]
    return args


def _run_patch(folder, ranks):
    code, out = qsc(_patch_args(folder), ranks)
    assert code == 0, out
    return folder


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    """Output folder of the patch test on 1 rank."""
    return _run_patch(tmp_path_factory.mktemp("serial"), 1)


@pytest.fixture(scope="module")
def parallel(tmp_path_factory):
    """Output folder of the patch test on 2 ranks."""
    if MPIRUN is None:
        pytest.skip("mpirun not found")
    return _run_patch(tmp_path_factory.mktemp("parallel"), 2)


def summary_of(folder):
    return json.loads((folder / "summary.json").read_text())


# ---------------------------------------------------------------- fields

def test_step_file_has_the_fields(serial):
    """steps/step_0001.xdmf shall read with meshio.read, with point data displacement and cell data
    stress (6 components), von_mises, body and rank on every cell."""
    mesh = meshio.read(serial / "steps" / "step_0001.xdmf")
    summary = summary_of(serial)
    n_points, n_cells = summary["mesh"]["vertices"], summary["mesh"]["cells"]
    assert mesh.points.shape == (n_points, 3)
    assert [block.type for block in mesh.cells] == ["hexahedron"] and len(mesh.cells[0].data) == n_cells
    assert mesh.point_data["displacement"].shape == (n_points, 3)
    assert np.abs(mesh.point_data["displacement"]).max() == pytest.approx(
        summary["steps"][0]["max_abs_displacement"], rel=1e-12)
    stress = mesh.cell_data["stress"][0]           # XDMF's Tensor6 order: xx, xy, xz, yy, yz, zz
    assert stress.shape == (n_cells, 6)
    shapes = {name: np.shape(mesh.cell_data[name][0]) for name in ("von_mises", "body", "rank")}
    assert all(shape in ((n_cells,), (n_cells, 1)) for shape in shapes.values()), shapes
    body = np.ravel(mesh.cell_data["body"][0])
    assert np.array_equal(np.unique(body), [0, 1])
    assert np.all(np.ravel(mesh.cell_data["rank"][0]) == 0)
    # uniaxial pressure at half load: sigma_zz about -p/2, von Mises about p/2 (non-matching meshes: not exact)
    assert np.median(stress[:, 5]) == pytest.approx(-0.5 * PRESSURE, rel=0.05)
    assert np.median(np.ravel(mesh.cell_data["von_mises"][0])) == pytest.approx(0.5 * PRESSURE, rel=0.05)


def test_stress_is_written_in_xdmf_tensor6_order(tmp_path):
    """A symmetric tensor field (Voigt order xx, yy, zz, yz, xz, xy in the program) shall be written in XDMF's
    Tensor6 order xx, xy, xz, yy, yz, zz, the order in which VTK's XDMF reader (ParaView's) expands it: the
    Voigt order showed zz as xz there."""
    run, summary = run_scene(CONFIGS / "block_compression.toml", tmp_path / "out")
    try:
        cells = len(run.mesh.cells)
        voigt = np.tile(np.arange(1.0, 7.0), (cells, 1))            # xx=1 yy=2 zz=3 yz=4 xz=5 xy=6
        run.writer.write_step(9, 9.0, {}, {"stress": voigt})
    finally:
        run.destroy()
    written = meshio.read(tmp_path / "out" / "steps" / "step_0009.xdmf").cell_data["stress"][0]
    assert np.array_equal(written, np.tile([1.0, 6.0, 5.0, 2.0, 4.0, 3.0], (summary["mesh"]["cells"], 1)))
    # the program's own uniaxial answer: sigma_zz in the last place, the shear entries zero
    step = meshio.read(tmp_path / "out" / "steps" / "step_0001.xdmf").cell_data["stress"][0]
    assert np.allclose(step[:, [1, 2, 4]], 0.0, atol=1e-8 * np.abs(step[:, 5]).max())
    assert np.all(step[:, 5] < 0.0)


def test_time_series_has_one_entry_per_load_step(serial):
    """solution.xdmf shall read with meshio's TimeSeriesReader: one entry per load step, at increasing times."""
    with meshio.xdmf.TimeSeriesReader(serial / "solution.xdmf") as series:
        points, cells = series.read_points_cells()
        entries = [series.read_data(k) for k in range(series.num_steps)]
    assert len(entries) == 2
    times = [t for t, _, _ in entries]
    assert times == [0.5, 1.0]
    for k, (t, point_data, cell_data) in enumerate(entries, start=1):
        step = meshio.read(serial / "steps" / f"step_{k:04d}.xdmf")      # the same data, one step per file
        assert np.array_equal(points, step.points)
        assert np.array_equal(point_data["displacement"], step.point_data["displacement"])
        assert np.array_equal(cell_data["stress"][0], step.cell_data["stress"][0])
        assert cell_data["stress"][0].shape == (len(cells[0].data), 6)
    assert np.abs(entries[1][1]["displacement"]).max() > np.abs(entries[0][1]["displacement"]).max() > 0.0


def test_a_step_writes_its_own_files_only(tmp_path):
    """Each load step rewrote every earlier step's file and re-encoded every earlier step's summary (250 steps of an
    8-cell block: 122 s writing against 0.46 s solving; hunt33_2): an earlier step's file stays as written, and
    summary.json is the plain JSON of the summary."""
    import os

    from qsc_petsc.output import write_json
    folder = tmp_path / "out"
    code, out = qsc(["run", CONFIGS / "block_compression.toml", "--out", folder, "--set", "load.steps=3",
                     "--set", "bodies.0.mesh.cells=[2,2,2]"])
    assert code == 0, out
    def written(name):
        return os.stat(folder / name).st_mtime_ns
    # each step file written at its own step, never again: before the last step's collection
    assert written("steps/step_0001.xdmf") < written("steps/step_0002.xdmf") < written("solution.xdmf")
    summary = summary_of(folder)
    assert len(summary["steps"]) == 3
    assert (folder / "summary.json").read_text() == json.dumps(summary, indent=2) + "\n"
    cache = []
    for k in range(4):          # the cached steps' text is the plain encoding's, also as steps come and go
        data = {"head": 1, "steps": summary["steps"][:k] if k < 3 else summary["steps"][:1], "tail": [None]}
        write_json(tmp_path / "s.json", data, cache)
        assert (tmp_path / "s.json").read_text() == json.dumps(data, indent=2) + "\n"


# ---------------------------------------------------------------- summary.json and the resolved scene

def test_summary_contents(serial):
    """summary.json shall hold the scene, ranks, dofs, per-step iterations and reasons, time per phase,
    a reaction per Dirichlet boundary and the peak memory."""
    summary = summary_of(serial)
    scene = load_scene(PATCH, OVERRIDES)
    assert summary["scene"] == "patch_test" and summary["status"] == "ok" and summary["ranks"] == 1
    assert summary["mesh"]["dofs"] == 3 * summary["mesh"]["vertices"] == sum(summary["mesh"]["dofs_per_rank"])
    assert summary["mesh"]["stiffness_assembly"] == "box stencils" and summary["mesh"]["partitioner"] == "none"
    assert [s["step"] for s in summary["steps"]] == [1, 2]
    assert [s["load_factor"] for s in summary["steps"]] == [0.5, 1.0]
    for step in summary["steps"]:
        assert step["snes_iterations"] >= 1 and step["ksp_iterations"] >= 1
        assert step["snes_reason"].startswith("CONVERGED") and step["ksp_reason"].startswith("CONVERGED")
        assert step["solves"] and all("snes_reason" in s and "ksp_reason" in s for s in step["solves"])
    assert {"mesh", "assembly", "solve", "output"} <= set(summary["time"])
    assert all(isinstance(t, float) and t >= 0.0 for t in summary["time"].values())
    memory = summary["peak_memory_mib"]
    assert memory["max_rank"] > 0 and len(memory["per_rank"]) == 1
    # reactions: one per displacement boundary (the pressure is a load, not a reaction)
    dirichlet = [f"boundary[{i}] {bc.surface}" for i, bc in enumerate(scene.boundary) if bc.type != "pressure"]
    for step in summary["steps"]:
        reactions = step["reactions"]
        assert sorted(reactions) == sorted(dirichlet)
        assert all(len(force) == 3 for force in reactions.values())
        # a roller holds one component only, and the supports carry the pressure load p A t
        assert reactions["boundary[1] lower.xmin"][1:] == [0.0, 0.0]
        total = np.sum(list(reactions.values()), axis=0)
        assert total == pytest.approx([0.0, 0.0, PRESSURE * step["load_factor"]], abs=1e-8)


def test_resolved_scene_loads_back_equal(serial):
    """scene.resolved.toml shall load back to a scene equal to the one that ran."""
    ran = load_scene(PATCH, OVERRIDES)
    again = load_scene(serial / "scene.resolved.toml")
    assert again.to_dict() == ran.to_dict()


def test_a_run_into_an_earlier_runs_folder_leaves_only_its_own_steps(serial, tmp_path):
    """A run into a folder that holds an earlier run's results (two steps) with one step shall leave that one
    step's files only: the earlier step files pointed into the solution.h5 the new run rewrote."""
    import shutil
    folder = tmp_path / "out"
    shutil.copytree(serial, folder)
    code, out = qsc(_patch_args(folder, "load.steps=1"), 1)
    assert code == 0, out
    assert sorted(p.name for p in (folder / "steps").iterdir()) == ["step_0001.xdmf"]
    assert meshio.read(folder / "steps" / "step_0001.xdmf").point_data["displacement"].shape[1] == 3
    with meshio.xdmf.TimeSeriesReader(folder / "solution.xdmf") as series:
        assert series.num_steps == 1


def test_a_folder_where_a_step_file_goes_is_named(tmp_path):
    """A folder in place of a step's XDMF file shall end the run with exit 2 and one line naming that file (not
    the temporary file written beside it), and leave no temporary file."""
    folder = tmp_path / "out"
    (folder / "steps" / "step_0002.xdmf").mkdir(parents=True)
    code, out = qsc(_patch_args(folder), 1)
    assert code == 2, out
    assert "step_0002.xdmf'" in out and "Is a directory" in out and ".tmp" not in out, out
    assert not list((folder / "steps").glob("*.tmp"))


SHARED_EDGE = """
name = "shared_edge"
[[bodies]]
name = "block"
mesh = { type = "box", size = [1.0, 1.0, 1.0], cells = [4, 4, 4] }
material = { youngs_modulus = 1000.0, poissons_ratio = 0.3 }
[[boundary]]
surface = "block.zmin"
type = "displacement"
ux = 0.0
uy = 0.0
uz = 0.0
[[boundary]]
surface = "block.xmin"
type = "symmetry"
[[boundary]]
surface = "block.zmax"
type = "pressure"
value = 1.0
"""


def test_reactions_balance_where_boundaries_hold_one_dof(tmp_path):
    """A clamped face and a symmetry plane both hold u_x on their common edge: the edge's x-reaction shall count
    once, in the first boundary's (scene order), so that the reactions balance the load (it was in both: their
    x-components summed to 4 % of the load)."""
    path = tmp_path / "shared_edge.toml"
    path.write_text(SHARED_EDGE)
    run, summary = run_scene(path, tmp_path / "out")
    run.destroy()
    reactions = summary["steps"][-1]["reactions"]
    assert np.sum(list(reactions.values()), axis=0) == pytest.approx([0.0, 0.0, PRESSURE], abs=1e-9)
    assert reactions["boundary[1] block.xmin"][0] != 0.0        # the plane's other nodes still push back


def test_nodes_that_carry_contact_force_are_touching(tmp_path):
    """contact_status shall be 1 on every node with contact traction, including block nodes just beyond the punch's
    edge, which no punch facet faces but the punch's rows still press (they read -1: no projection)."""
    sets = ["bodies.0.mesh.cells=[10,10,5]", "bodies.1.mesh.cells=[6,6,6]"]
    run, summary = run_scene(CONFIGS / "flat_punch.toml", tmp_path / "out", sets)
    run.destroy()
    assert summary["status"] == "ok"
    result = meshio.read(tmp_path / "out" / "steps" / f"step_{len(summary['steps']):04d}.xdmf")
    traction, status = result.point_data["contact_traction"][:, 0], result.point_data["contact_status"][:, 0]
    pressed = traction > 0
    assert pressed.sum() > 0 and np.all(status[pressed] == 1.0)
    assert np.any(status == -1.0)          # nodes of the block's top that face nothing and carry nothing


SPLIT = """\
name = "split"
[[bodies]]
name = "l1"
mesh = { type = "box", origin = [0, 0, 0], size = [0.5, 1, 1], cells = [2, 4, 4] }
material = { youngs_modulus = 1000.0 }
[[bodies]]
name = "l2"
mesh = { type = "box", origin = [0.5, 0, 0], size = [0.5, 1, 1], cells = [3, 4, 4] }
material = { youngs_modulus = 1000.0 }
[[bodies]]
name = "up"
mesh = { type = "box", origin = [0, 0, 1], size = [1, 1, 0.5], cells = [5, 5, 2] }
material = { youngs_modulus = 1000.0 }
[[boundary]]
surface = "l1.zmin"
type = "symmetry"
[[boundary]]
surface = "l2.zmin"
type = "symmetry"
[[boundary]]
surface = "l1.xmin"
type = "symmetry"
[[boundary]]
surface = "l1.ymin"
type = "symmetry"
[[boundary]]
surface = "l2.ymin"
type = "symmetry"
[[boundary]]
surface = "up.xmin"
type = "symmetry"
[[boundary]]
surface = "up.ymin"
type = "symmetry"
[[boundary]]
surface = "up.zmax"
type = "pressure"
value = 10.0
[[contact]]
slave = "up.zmin"
master = "l1.zmax"
[[contact]]
slave = "up.zmin"
master = "l2.zmax"
[[contact]]
slave = "l2.xmin"
master = "l1.xmax"
[petsc]
ksp_type = "preonly"
pc_type = "lu"
pc_factor_mat_solver_type = "mumps"
"""


def test_a_node_on_several_pairs_keeps_its_traction(tmp_path):
    """A block on two side-by-side blocks (pairs up.zmin / l1.zmax, up.zmin / l2.zmax, l2.xmin / l1.xmax) under
    10 Pa: the fields were written pair by pair, so a node on two pairs kept the last one's value (0 on the upper
    block's bottom over l1, 1e-11 on l1's top edge at x = 0.5; helper pass, session 25). A surface's tractions
    from several pairs add up, and of different surfaces the largest stands: 10 Pa on every node of up.zmin and
    of the lower blocks' tops, the uniaxial answer."""
    path = tmp_path / "split.toml"
    path.write_text(SPLIT)
    run, summary = run_scene(path, tmp_path / "out")
    run.destroy()
    assert summary["status"] == "ok"
    result = meshio.read(tmp_path / "out" / "steps" / "step_0001.xdmf")
    traction, x = result.point_data["contact_traction"][:, 0], result.points
    tops = np.isclose(x[:, 2], 1.0)                 # up.zmin, l1.zmax and l2.zmax
    assert tops.sum() > 0 and np.allclose(traction[tops], 10.0, rtol=1e-8)


def test_an_interrupted_run_says_so(tmp_path, monkeypatch):
    """Ctrl-C during a run left summary.json at "running" for ever and no petsc_options.txt (helper pass, session
    25): serially the run now writes status "interrupted" with the steps it finished, then stops."""
    from qsc_petsc import run as run_module
    calls = []
    original = run_module.solve_load_step

    def interrupted_at_step_2(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return original(*args, **kwargs)

    monkeypatch.setattr(run_module, "solve_load_step", interrupted_at_step_2)
    with pytest.raises(KeyboardInterrupt):
        run_scene(CONFIGS / "patch_test.toml", tmp_path / "out", ["load.steps=3"])
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["status"] == "interrupted" and len(summary["steps"]) == 1
    assert (tmp_path / "out" / "petsc_options.txt").is_file()


def test_a_run_clears_an_earlier_runs_results_from_its_folder(tmp_path):
    """A run into a used folder (a helper's test pass, session 26): with output.xdmf = false it left the earlier
    run's solution.h5, solution.xdmf and steps/ (another scene's mesh and fields beside this run's summary); a
    set-up stopped by bad input left them and the old scene.resolved.toml; while step 1 ran, and for ever if
    the run died there, the folder showed the old summary.json as "ok". A run now removes the results a run
    writes (and nothing else) once its set-up has passed, and writes a "running" summary then."""
    from qsc_petsc.errors import QscError
    from qsc_petsc.run import Run
    out = tmp_path / "out"
    run, _ = run_scene(CONFIGS / "two_cubes_dies.toml", out)
    run.destroy()
    (out / "notes.txt").write_text("the user's")
    assert (out / "steps" / "step_0002.xdmf").is_file()
    run, summary = run_scene(CONFIGS / "patch_test.toml", out, ["output.xdmf=false"])
    run.destroy()
    assert summary["status"] == "ok"
    left = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    assert left == ["notes.txt", "petsc_options.txt", "scene.resolved.toml", "summary.json"]
    assert 'name = "patch_test"' in (out / "scene.resolved.toml").read_text()
    run, _ = run_scene(CONFIGS / "two_cubes_dies.toml", out)
    run.destroy()
    before = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    # a run refused for its input leaves them as they were (it removed them first: a mistyped PETSc option cost
    # the earlier solution; hunt34_3), and says so
    with pytest.raises(QscError, match="the earlier results in .* are left as they were"):
        run_scene(CONFIGS / "patch_test.toml", out, ["petsc.pc_type=bogus"])
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()) == before
    assert json.loads((out / "summary.json").read_text())["scene"] == "two_cubes_dies"
    fresh = tmp_path / "fresh"           # a folder with no earlier results says the failure
    with pytest.raises(QscError):
        run_scene(CONFIGS / "patch_test.toml", fresh, ["petsc.pc_type=bogus"])
    left = sorted(p.relative_to(fresh).as_posix() for p in fresh.rglob("*") if p.is_file())
    assert left == ["petsc_options.txt", "summary.json"]
    assert json.loads((fresh / "summary.json").read_text())["status"] == "failed"
    from mpi4py import MPI
    run = Run(load_scene(CONFIGS / "patch_test.toml"), MPI.COMM_WORLD, out, log=lambda *a: None)
    summary = json.loads((out / "summary.json").read_text())
    run.destroy()
    assert (summary["scene"], summary["status"], summary["steps"]) == ("patch_test", "running", [])


def test_a_folder_it_cannot_clear_keeps_the_earlier_results(tmp_path, monkeypatch):
    """An earlier run's steps/ this process may not change (another user's): the run stopped naming it (exit 2), but
    had removed the earlier run's other results first (hunt33_2). Nothing goes unless everything can."""
    from qsc_petsc import output
    from qsc_petsc.errors import OutputError
    out = tmp_path / "out"
    run, _ = run_scene(CONFIGS / "patch_test.toml", out)
    run.destroy()
    before = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    real = output.os.access
    monkeypatch.setattr(output.os, "access", lambda path, mode: Path(path).name != "steps" and real(path, mode))
    with pytest.raises(OutputError, match=r"cannot remove the earlier run's '.*step_0001.xdmf': Permission denied"):
        run_scene(CONFIGS / "patch_test.toml", out)
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()) == before


def test_a_file_it_cannot_remove_keeps_the_earlier_results(tmp_path, monkeypatch):
    """A file that cannot go though its folder may be written (immutable, another user's in a sticky folder):
    summary.json had gone first, then the run stopped naming the file (hunt34_3). Each is renamed aside first and
    back if one cannot be; a clearing cut short leaves files aside that the next run removes."""
    from qsc_petsc import output
    from qsc_petsc.errors import OutputError
    out = tmp_path / "out"
    run, _ = run_scene(CONFIGS / "two_cubes_dies.toml", out)
    run.destroy()
    before = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    real = Path.rename

    def rename(self, target):
        if self.name == "solution.h5":
            raise PermissionError(1, "Operation not permitted", str(self))
        return real(self, target)

    monkeypatch.setattr(output.Path, "rename", rename)
    with pytest.raises(OutputError, match=r"cannot remove the earlier run's '.*solution.h5': Operation not permitted"):
        run_scene(CONFIGS / "patch_test.toml", out)
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()) == before
    monkeypatch.undo()
    (out / "summary.json").rename(out / ("summary.json" + output.ASIDE))    # a clearing cut short
    (out / "steps" / "step_0001.xdmf").rename(out / "steps" / ("step_0001.xdmf" + output.ASIDE))
    (out / "notes.json.cleared").write_text("the user's")
    # a leftover twin beside its file: listed twice, the second unlink failed after the others went (hunt35_3)
    (out / ("petsc_options.txt" + output.ASIDE)).write_text("left by a clearing cut short")
    run, _ = run_scene(CONFIGS / "patch_test.toml", out, ["output.xdmf=false"])
    run.destroy()
    left = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    assert left == ["notes.json.cleared", "petsc_options.txt", "scene.resolved.toml", "summary.json"]


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="no /dev/full")
def test_a_full_disk_is_said_in_one_line(tmp_path):
    """HDF5's account of a failed write runs over two lines (a time stamp, then descriptors and sizes; hunt34_3):
    the error is one line with the system's reason."""
    from qsc_petsc.errors import OutputError
    out = tmp_path / "out"
    out.mkdir()
    (out / "solution.h5").symlink_to("/dev/full")
    with pytest.raises(OutputError) as caught:
        run_scene(CONFIGS / "patch_test.toml", out)
    message = str(caught.value)
    assert "\n" not in message and message.endswith("solution.h5': Unable to create file (No space left on device)")


def test_an_interrupt_while_a_step_is_written_waits_for_its_summary(tmp_path, monkeypatch):
    """Ctrl-C after a step's fields were written and before its summary: solution.xdmf held a step more than
    summary.json (hunt33_2). The interrupt is held until the step's results are all written; a second one goes
    through at once."""
    import os
    import signal

    from qsc_petsc import output
    real = output.ResultWriter.write_step

    def write_step(self, step, *args):
        real(self, step, *args)
        if step == 2:
            os.kill(os.getpid(), signal.SIGINT)

    monkeypatch.setattr(output.ResultWriter, "write_step", write_step)
    # Ctrl-C's own handler, whatever an earlier test or library left (the suite once ran this with SIGINT at the
    # system's default, which ended the process)
    earlier = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        _interrupt_while_writing(tmp_path / "out")
    finally:
        signal.signal(signal.SIGINT, earlier)


def _interrupt_while_writing(out):
    import os
    import signal

    import meshio

    from qsc_petsc.run import held_interrupts
    with pytest.raises(KeyboardInterrupt):
        run_scene(CONFIGS / "patch_test.toml", out, ["load.steps=4"])
    summary = summary_of(out)
    assert summary["status"] == "interrupted" and [s["step"] for s in summary["steps"]] == [1, 2]
    with meshio.xdmf.TimeSeriesReader(str(out / "solution.xdmf")) as reader:
        reader.read_points_cells()
        assert reader.num_steps == 2
    assert sorted(p.name for p in (out / "steps").iterdir()) == ["step_0001.xdmf", "step_0002.xdmf"]
    reached = []
    with pytest.raises(KeyboardInterrupt), held_interrupts():
        os.kill(os.getpid(), signal.SIGINT)
        reached.append("first held")
        os.kill(os.getpid(), signal.SIGINT)
        reached.append("second held")
    assert reached == ["first held"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


# ---------------------------------------------------------------- rank independence

def test_two_ranks_write_the_same_results(serial, parallel):
    """Results written on 2 ranks shall equal those written on 1 rank entry by entry (1e-10 relative),
    except the rank field."""
    assert summary_of(parallel)["ranks"] == 2
    with h5py.File(serial / "solution.h5", "r") as one, h5py.File(parallel / "solution.h5", "r") as two:
        assert np.array_equal(one["mesh/geometry"][()], two["mesh/geometry"][()])
        assert np.array_equal(one["mesh/topology"][()], two["mesh/topology"][()])
        assert sorted(one) == sorted(two) == ["mesh", "step_0001", "step_0002"]
        for step in ("step_0001", "step_0002"):
            assert sorted(one[step]) == sorted(two[step])
            for name in one[step]:
                a, b = one[step][name][()], two[step][name][()]
                assert a.shape == b.shape, (step, name)
                if name == "rank":
                    assert set(np.unique(b)) == {0.0, 1.0}
                    continue
                scale = max(np.abs(a).max(), np.finfo(float).tiny)
                # penetrations are differences of O(1 m) coordinates: their round-off is ~1e-16 m absolute
                floor = 1e-14 if name == "contact_penetration" else 0.0
                assert np.abs(a - b).max() <= 1e-10 * scale + floor, (step, name, np.abs(a - b).max(), scale)
    s1, s2 = summary_of(serial), summary_of(parallel)
    for a, b in zip(s1["steps"], s2["steps"]):
        for key, force in a["reactions"].items():
            assert b["reactions"][key] == pytest.approx(force, rel=1e-8, abs=1e-10)


# ---------------------------------------------------------------- a body read from a mesh file

def test_file_mesh_body(comm, mpi_tmp):
    """A body meshed in a gmsh 2.2 file shall run with displacement conditions on its named physical groups,
    and its resolved scene shall load back equal."""
    if comm.rank == 0:
        write_gmsh_box(mpi_tmp / "cube.msh", {"base": "zmin", "lid": "zmax", "side": "xmin"})
    comm.Barrier()
    scene = mpi_tmp / "file_body.toml"
    if comm.rank == 0:
        scene.write_text(
            'name = "file_body"\n\n'
            '[[bodies]]\nname = "cube"\nmesh = { type = "file", path = "cube.msh" }\n'
            'material = { youngs_modulus = 1000.0, poissons_ratio = 0.3 }\n\n'
            '[[boundary]]\nsurface = "cube.base"\ntype = "displacement"\nux = 0.0\nuy = 0.0\nuz = 0.0\n\n'
            '[[boundary]]\nsurface = "cube.lid"\ntype = "displacement"\nuz = -0.01\n')
    comm.Barrier()
    out = mpi_tmp / "out"
    run, summary = run_scene(scene, out, (), comm)
    run.destroy()
    assert summary["status"] == "ok"
    assert summary["mesh"]["cell_type"] == "tet" and summary["mesh"]["cells"] == 6 * 8
    assert summary["mesh"]["stiffness_assembly"] == "element blocks"
    reactions = summary["steps"][-1]["reactions"]
    base, lid = reactions["boundary[0] cube.base"], reactions["boundary[1] cube.lid"]
    assert lid[:2] == [0.0, 0.0] and lid[2] < 0.0                    # the lid holds uz only, pushing down
    assert np.add(base, lid) == pytest.approx([0.0, 0.0, 0.0], abs=1e-9 * abs(lid[2]))
    if comm.rank == 0:
        result = meshio.read(out / "steps" / "step_0001.xdmf")
        u, z = result.point_data["displacement"], result.points[:, 2]
        # prescribed values hold to the Krylov tolerance (the Newton update of a held dof is a CG iterate)
        assert np.allclose(u[z == 1.0, 2], -0.01, rtol=0, atol=1e-9 * 0.01)
        assert np.allclose(u[z == 0.0], 0.0, rtol=0, atol=1e-9 * 0.01)
        resolved = load_scene(out / "scene.resolved.toml")
        assert resolved.to_dict() == load_scene(scene).to_dict()
        assert resolved.bodies[0].mesh.path == str(mpi_tmp / "cube.msh")


def test_nested_phases_add_up_to_the_run():
    """A phase inside another (search and rows inside a load step's solve) is timed once: the enclosing
    phase leaves it out, so the phases add up to the wall time."""
    import time

    from mpi4py import MPI

    from qsc_petsc.run import Phases

    phases = Phases(MPI.COMM_SELF)
    t0 = time.perf_counter()
    with phases("solve"):
        time.sleep(0.02)
        with phases("rows"):
            time.sleep(0.05)
        time.sleep(0.02)
    wall = time.perf_counter() - t0
    seconds = phases.summary()
    assert seconds["rows"] >= 0.05
    assert seconds["solve"] >= 0.04
    assert seconds["solve"] == pytest.approx(wall - seconds["rows"], abs=5e-3)   # without the rows' time


def test_peak_memory_is_the_run_process_own():
    """A run started from a large process reports its own peak resident set, not its parent's: exec keeps the
    replaced image's high-water mark in getrusage's ru_maxrss (qsc sweep's runs reported the sweep's size)."""
    import subprocess
    import sys
    ballast = np.ones(60_000_000)                   # 480 MB touched in this process, the child's parent
    code = ("import resource; from qsc_petsc.run import peak_rss_mib; "
            "print(peak_rss_mib(), resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)")
    own, inherited = map(float, subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                               check=True).stdout.split())
    assert ballast.sum() > 0
    assert own < 300 and inherited > 450
