"""Several contact pairs in one scene: three cubes stacked between sticking dies (two non-matching interfaces,
the middle cube held in its plane by two symmetry planes), each pair with its own enforcement and settings.
Runs serially in the suite and under mpirun -n 2 and -n 3."""

import pytest
from conftest import run_scene

BODY = """
[[bodies]]
name = "{name}"
mesh = {{ type = "box", origin = [0.0, 0.0, {z0}], size = [1.0, 1.0, 1.0], cells = [{n}, {n}, {n}] }}
material = {{ youngs_modulus = 1000.0, poissons_ratio = 0.3 }}
"""
DIE = """
[[die]]
name = "{name}"
point = [0.0, 0.0, {z}]
normal = [0.0, 0.0, {nz}]
motion = [0.0, 0.0, {dz}]
surfaces = ["{surface}"]
condition = "sticking"
"""
PAIRS_AND_SOLVER = """
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
[petsc]
ksp_type = "preonly"
pc_type = "lu"
pc_factor_mat_solver_type = "mumps"
"""


def scene_text(tolerance):
    """Three unit cubes a, b, c (3, 4, 3 cells a side) stacked along z between a fixed and a descending die."""
    return ('name = "three_cubes"\n' + "".join(BODY.format(name=name, z0=z0, n=n)
                                               for name, z0, n in (("a", 0.0, 3), ("b", 1.0, 4), ("c", 2.0, 3)))
            + DIE.format(name="bottom", z=0.0, nz=1.0, dz=0.0, surface="a.zmin")
            + DIE.format(name="top", z=3.0, nz=-1.0, dz=-0.03, surface="c.zmax")
            + PAIRS_AND_SOLVER.format(tolerance=tolerance))


def _run(comm, folder, tolerance):
    path = folder / f"scene_{tolerance:g}.toml"
    if comm.rank == 0:
        path.write_text(scene_text(tolerance))
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
