"""Every scene in configs/ as a test: it loads as written and runs, on a coarsened mesh, to status "ok".

Runs serially in the suite; collective (every rank calls run_scene), so it also runs under mpirun.
"""

import tomllib

import pytest
from conftest import CONFIGS, run_scene

from qsc_petsc.scene import load_scene

SCENES = sorted(CONFIGS.glob("*.toml"))


def coarse(path):
    """--set overrides halving the cells of every generated box (at least one cell per direction), and
    the coarse level for every Hertz part.

    Halving keeps what a scene is about (non-matching interfaces stay non-matching) at an eighth
    of the cells, so that every scene added to configs/ is tested without a hand-made override."""
    data = tomllib.loads(path.read_text())
    bodies = list(enumerate(data.get("bodies", [])))
    return [f"bodies.{i}.mesh.cells=[{','.join(str(max(1, n // 2)) for n in body['mesh']['cells'])}]"
            for i, body in bodies if body.get("mesh", {}).get("type") == "box"] + [
            f"bodies.{i}.mesh.level=coarse" for i, body in bodies if body.get("mesh", {}).get("type") == "hertz"]


def test_configs_folder_has_scenes():
    """configs/ shall hold the demo scenes, so that the tests below test something."""
    assert {p.stem for p in SCENES} >= {"block_compression", "patch_test", "two_cubes_dies"}


@pytest.mark.parametrize("path", SCENES, ids=lambda p: p.stem)
def test_scene_is_valid_as_written(path):
    """Every scene in configs/ shall load and validate as written, named after its file."""
    scene = load_scene(path)
    assert scene.name == path.stem


@pytest.mark.parametrize("path", SCENES, ids=lambda p: p.stem)
def test_scene_runs(comm, mpi_tmp, path):
    """Every scene in configs/ shall run on a coarse mesh to status "ok", converging in every load step
    and writing its results."""
    overrides = coarse(path)
    steps = load_scene(path, overrides).load.steps
    run, summary = run_scene(path, mpi_tmp, overrides, comm)
    run.destroy()
    assert summary["status"] == "ok"
    assert [s["step"] for s in summary["steps"]] == list(range(1, steps + 1))
    assert summary["steps"][-1]["load_factor"] == 1.0
    for step in summary["steps"]:
        assert step["snes_reason"].startswith("CONVERGED"), step
        assert step["max_abs_displacement"] > 0.0
        assert "loose" not in step, step          # every body held by a boundary or by rows that press
    names = ("summary.json", "scene.resolved.toml", "petsc_options.txt", "solution.xdmf", "solution.h5")
    written = [name for name in names if (mpi_tmp / name).is_file()] if comm.rank == 0 else None
    assert comm.bcast(written, root=0) == list(names)        # rank 0 writes them, and has by now


def test_readme_scene_runs(tmp_path):
    """The README's scene in brief shall run as printed there (it left the lower body free in x, y and about z
    under its frictionless contact, so it stopped at load step 1)."""
    readme = (CONFIGS.parent / "README.md").read_text()
    start = readme.index("```toml\n", readme.index("A scene in brief:")) + len("```toml\n")
    path = tmp_path / "readme_scene.toml"
    path.write_text(readme[start:readme.index("```", start)])
    run, summary = run_scene(path, tmp_path / "out")
    run.destroy()
    assert summary["status"] == "ok" and len(summary["steps"]) == 2
    assert all(step["snes_reason"].startswith("CONVERGED") for step in summary["steps"])
