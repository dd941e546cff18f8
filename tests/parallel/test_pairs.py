"""Several contact pairs in one scene: three cubes stacked between sticking dies (two non-matching interfaces,
the middle cube held in its plane by two symmetry planes), each pair with its own enforcement and settings.
Runs serially in the suite and under mpirun -n 2 and -n 3."""

import pytest
from conftest import run_scene

SCENE = """
name = "three_cubes"
[[bodies]]
name = "a"
mesh = {{ type = "box", origin = [0.0, 0.0, 0.0], size = [1.0, 1.0, 1.0], cells = [3, 3, 3] }}
material = {{ youngs_modulus = 1000.0, poissons_ratio = 0.3 }}
[[bodies]]
name = "b"
mesh = {{ type = "box", origin = [0.0, 0.0, 1.0], size = [1.0, 1.0, 1.0], cells = [4, 4, 4] }}
material = {{ youngs_modulus = 1000.0, poissons_ratio = 0.3 }}
[[bodies]]
name = "c"
mesh = {{ type = "box", origin = [0.0, 0.0, 2.0], size = [1.0, 1.0, 1.0], cells = [3, 3, 3] }}
material = {{ youngs_modulus = 1000.0, poissons_ratio = 0.3 }}
[[boundary]]
surface = "b.xmin"
type = "symmetry"
[[boundary]]
surface = "b.ymin"
type = "symmetry"
[[contact]]
slave = "b.zmin"
master = "a.zmax"
formulation = "master_slave"
[[contact]]
slave = "b.zmax"
master = "c.zmin"
enforcement = "augmented_lagrangian"
penalty = 1e2
augmented_tolerance = {tolerance}
[[die]]
name = "bottom"
point = [0.0, 0.0, 0.0]
normal = [0.0, 0.0, 1.0]
surfaces = ["a.zmin"]
condition = "sticking"
[[die]]
name = "top"
point = [0.0, 0.0, 3.0]
normal = [0.0, 0.0, -1.0]
motion = [0.0, 0.0, -0.03]
surfaces = ["c.zmax"]
condition = "sticking"
[petsc]
ksp_type = "preonly"
pc_type = "lu"
pc_factor_mat_solver_type = "mumps"
"""


def _run(comm, folder, tolerance):
    path = folder / f"scene_{tolerance:g}.toml"
    if comm.rank == 0:
        path.write_text(SCENE.format(tolerance=tolerance))
    comm.barrier()
    run, summary = run_scene(path, folder / f"out_{tolerance:g}", comm=comm)
    run.destroy()
    return summary


def test_each_pair_keeps_its_own_settings(comm, mpi_tmp):
    """The top interface, augmented, stops its Uzawa loop at its own augmented_tolerance (the other pair is plain
    penalty, with the default 1e-6 that the loop read before session 17): 2 updates at 1e-3, 10 at 1e-9. Both
    interfaces carry the same normal force whatever the tolerance (the middle cube's equilibrium): the answer
    keeps the multipliers it was solved with (an update applied after the last solve put the loose run's two
    forces 9e-4 apart)."""
    loose, tight = (_run(comm, mpi_tmp, tol) for tol in (1e-3, 1e-9))
    for summary in (loose, tight):
        assert summary["status"] == "ok"
        pairs = [entry for name, entry in summary["steps"][-1]["contact"].items() if name.startswith("contact")]
        assert pairs[0]["total_normal_force"] == pytest.approx(pairs[1]["total_normal_force"], rel=1e-9)
    updates = [[solve["augmented_iterations"] for step in s["steps"] for solve in step["solves"]]
               for s in (loose, tight)]
    assert updates == [[2], [10]]
