"""The qsc command as a user meets it: one-line input errors on 1 and 2 ranks, versions, check, failed solves, options.

Every case starts the real program in a subprocess (through mpirun for 2 ranks) with a time limit,
so a rank left waiting in a collective call fails the test instead of hanging the suite. These
tests start MPI jobs themselves and therefore run only in the serial suite.
"""

import json
import os
import re
import shutil
import signal
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import meshio
import numpy as np
import pytest
from conftest import write_gmsh, write_gmsh_box
from mpi4py import MPI

from qsc_petsc import fem
from qsc_petsc.meshgen import box_mesh

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "configs"
_SCRIPT = Path(sys.executable).with_name("qsc")
QSC = [str(_SCRIPT)] if _SCRIPT.exists() else [sys.executable, "-m", "qsc_petsc.cli"]
MPIRUN = shutil.which("mpirun")
ENV = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1", "OMP_NUM_THREADS": "1"}
TIMEOUT = 60.0          # s; a healthy case takes about one
RANKS = [1, pytest.param(2, marks=[pytest.mark.mpi,
                                   pytest.mark.skipif(MPIRUN is None, reason="mpirun not found")])]

# A block on a clamped base (no rigid-body modes), 2 x 2 x 2 hexes: the smallest scene that solves.
BLOCK = """\
name = "block"

[[bodies]]
name = "blk"
mesh = {{ {mesh} }}
material = {{ youngs_modulus = {E} }}

[[boundary]]
surface = "blk.{fixed}"
type = "displacement"
ux = 0.0
uy = 0.0
uz = 0.0
"""
BOX = 'type = "box", size = [1.0, 1.0, 1.0], cells = [2, 2, 2]'
PRESSED = '\n[[boundary]]\nsurface = "blk.zmax"\ntype = "pressure"\nvalue = 1.0\n'     # 1 Pa on the top face

# Two blocks on a clamped base, the upper one pushed down by its top face across a gap of 0.03 m:
# the gap stays open in load step 1 and closes in load step 2 (contact rows exist in both).
GAP = """\
name = "gap"

[[bodies]]
name = "lower"
mesh = { type = "box", size = [1.0, 1.0, 0.5], cells = [2, 2, 1] }
material = { youngs_modulus = 1000.0 }

[[bodies]]
name = "upper"
mesh = { type = "box", origin = [0.0, 0.0, 0.47], size = [1.0, 1.0, 0.5], cells = [3, 3, 1] }
material = { youngs_modulus = 1000.0 }

[[boundary]]
surface = "lower.zmin"
type = "displacement"
ux = 0.0
uy = 0.0
uz = 0.0

[[boundary]]
surface = "upper.zmax"
type = "displacement"
ux = 0.0
uy = 0.0
uz = 0.05

[[contact]]
slave = "upper.zmin"
master = "lower.zmax"

[load]
steps = 2

[solver]
predictor = "previous"

[petsc]
ksp_type = "preonly"
pc_type = "lu"
pc_factor_mat_solver_type = "mumps"
"""


def block_scene(folder, *, mesh=BOX, E="1000.0", fixed="zmin", extra=""):
    """Write the block scene (with parts replaced) to folder/block.toml and return its path."""
    path = Path(folder) / "block.toml"
    path.write_text(BLOCK.format(mesh=mesh, E=E, fixed=fixed) + extra)
    return path


def serial_only():
    """Skip a test that starts MPI jobs when the suite itself runs under mpirun."""
    if MPI.COMM_WORLD.size > 1:
        pytest.skip("starts MPI jobs itself: serial suite only")


def run_qsc(args, ranks=1, cwd=None, timeout=TIMEOUT):
    """Run qsc on `ranks` processes; returns (exit code, stdout + stderr), exit code None after the time limit."""
    cmd = QSC + [str(a) for a in args]
    if ranks > 1:
        cmd = [MPIRUN, "--oversubscribe", "-n", str(ranks)] + cmd
    # a session of its own, so that a hang is ended together with every rank mpirun started
    proc = subprocess.Popen(cmd, cwd=cwd, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True)
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, _ = proc.communicate()
        return None, out
    return proc.returncode, out


def qsc(args, ranks=1, cwd=None, timeout=TIMEOUT):
    """run_qsc, failing the test if the run is still going after the time limit."""
    serial_only()
    code, out = run_qsc(args, ranks, cwd, timeout)
    if code is None:
        pytest.fail(f"qsc {' '.join(map(str, args))} on {ranks} rank(s) still running after {timeout} s:\n{out}")
    return code, out


def own_lines(output):
    """The program's non-empty output lines, without Open MPI's boxed notices (between lines of dashes)."""
    lines, in_notice = [], False
    for line in output.splitlines():
        if set(line.strip()) == {"-"}:
            in_notice = not in_notice
        elif not in_notice and line.strip() and "ORTE_ERROR_LOG" not in line:
            lines.append(line)
    return lines


# ---------------------------------------------------------------- bad input

def _unknown_key(tmp):
    return [block_scene(tmp, extra='\n[load]\nsteps = 1\nstepz = 2\n')], ["load.stepz", "unknown key"]


def _wrong_type(tmp):
    return [block_scene(tmp, E='"stiff"')], ["bodies[0].material.youngs_modulus", "expected a number", '"stiff"']


def _negative_modulus(tmp):
    return [block_scene(tmp, E="-1000.0")], ["bodies[0].material.youngs_modulus", "must be > 0", "-1000.0"]


def _missing_mesh_file(tmp):
    return [block_scene(tmp, mesh='type = "file", path = "nowhere.msh"')], ["bodies[0].mesh.path", "nowhere.msh",
                                                                            "not found"]


def _unknown_box_surface(tmp):
    return [block_scene(tmp, fixed="bottom")], ["boundary[0].surface", '"bottom"', "xmin"]


def _unknown_file_surface(tmp):
    # only known once rank 0 has read the mesh: every rank must fail with it
    write_gmsh_box(tmp / "cube.msh", {"base": "zmin", "lid": "zmax"})
    return [block_scene(tmp, mesh='type = "file", path = "cube.msh"', fixed="bottom")], [
        "boundary[0].surface", "blk.bottom", "base", "lid"]


def _not_a_mesh(tmp):
    (tmp / "bad.msh").write_text("this is not a mesh\n$MeshFormat\ngarbage\n")
    return [block_scene(tmp, mesh='type = "file", path = "bad.msh"')], ["cannot read mesh file", "bad.msh"]


def _degenerate_file_cell(tmp):
    # a flat tet in a file body: the message named "tet cell N", N counted over every body's cells
    box = write_gmsh_box(tmp / "cube.msh", {"base": "zmin"})
    text = (tmp / "cube.msh").read_text()
    head, elements = text.split("$Elements\n", 1)
    lines = elements.split("\n")
    count, first = int(lines[0]), 1
    tets = [i for i in range(first, first + count) if lines[i].split()[1] == "4"]
    fields = lines[tets[3]].split()
    fields[-1] = fields[-2]                                    # tet 3 of the file: two equal nodes
    lines[tets[3]] = " ".join(fields)
    (tmp / "cube.msh").write_text(head + "$Elements\n" + "\n".join(lines))
    assert len(box.cells) > 3
    return [block_scene(tmp, mesh='type = "file", path = "cube.msh"', fixed="base")], [
        "bodies[0] (blk, mesh file ", "cube.msh): tet 3 (0-based", "degenerate"]


def _interior_file_surface(tmp):
    # a group with a face inside the body is set aside when read, an error where a scene names it (hunt33_1)
    box = box_mesh((0.0, 0.0, 0.0), (1.0, 1.0, 1.0), (2, 2, 2), "tet")
    base = fem.cell_faces("tet", box.cells[box.surfaces["zmin"][:, 0]], box.surfaces["zmin"][:, 1])
    write_gmsh(tmp / "cube.msh", box.points, box.cells, "tet", {"base": base, "mid": box.cells[:1, [1, 2, 3]]})
    return [block_scene(tmp, mesh='type = "file", path = "cube.msh"', fixed="mid")], [
        ("boundary[0].surface: surface 'blk.mid' of the mesh file cannot be used: 1 of 1 of its facets are not "
         "boundary faces of the tetra cells")]


def _contact_boxes_lost_in_round_off(tmp):
    # 1 m boxes 1e16 m out: their cells flat by round-off, which the contact search met first (ZeroDivisionError,
    # exit 1; hunt33_5)
    return [CONFIGS / "patch_test.toml", "--set", "bodies.0.mesh.origin=[1e16,0,0]", "--set",
            "bodies.1.mesh.origin=[1e16,0,0.5]"], ["bodies[0] (lower, generated box): hex 0", "inverted or degenerate"]


def _unknown_set_path(tmp):
    return [block_scene(tmp), "--set", "solver.max_cutback=2"], ["solver.max_cutback", "unknown key"]


def _set_missing_entry(tmp):
    return [block_scene(tmp), "--set", "bodies.3.name=x"], ["bodies[3]", "no such entry"]


def _unavailable_partitioner(tmp):
    # Debian's PETSc has no ParMETIS; serially nothing is partitioned, so this is checked on 2 ranks
    return [block_scene(tmp), "-qsc_petscpartitioner_type", "parmetis"], ["-qsc_petscpartitioner_type",
                                                                          "parmetis", "not available"]


def _shell_partitioner(tmp):
    # takes its partition through the API: PETSc stopped inside DMPlexDistribute with a traceback per rank
    return [block_scene(tmp), "-qsc_petscpartitioner_type", "shell"], ["-qsc_petscpartitioner_type", "'shell'",
                                                                       "coordinate bisection"]


def _huge_box(tmp):
    # refused before any array is made (the box would not fit in memory either)
    return [block_scene(tmp, mesh='type = "box", size = [1.0, 1.0, 1.0], cells = [2000, 2000, 2000]')], [
        "bodies[0].mesh.cells", "[2000, 2000, 2000]", "24036018003 dofs", "32-bit"]


def _body_too_small(tmp):
    # lengths are raised to powers downstream: a patch test 1e-80 wide failed its contact quadrature
    return [block_scene(tmp, mesh='type = "box", size = [1e-40, 1e-40, 1e-40], cells = [2, 2, 2]')], [
        "bodies[0].mesh.size", "1e-40 across", "between 1e-30 and 1e+30"]


def _pressure_not_finite(tmp):
    return [block_scene(tmp, extra=PRESSED.replace("value = 1.0", 'value = "1 / (z - 1)"'))], [
        "boundary[1].value", "'1 / (z - 1)'", "blk.zmax", "not finite"]


def _pressure_out_of_range(tmp):
    # finite, but squared downstream it overflowed: the run "converged" with displacements of 1e147 m
    return [block_scene(tmp, extra=PRESSED.replace("value = 1.0", 'value = "1e150 * (1 + x)"'))], [
        "boundary[1].value", "'1e150 * (1 + x)'", "blk.zmax", "of magnitude between 1e-100 and 1e+100"]


def _conflicting_boundaries(tmp):
    extra = '\n[[boundary]]\nsurface = "blk.zmin"\ntype = "displacement"\nuz = 0.1\n'
    return [block_scene(tmp, extra=extra)], [
        ("boundary[1]: uz = 0.1 m on blk.zmin where boundary[0] holds uz = 0 m (blk.zmin), on 9 node(s), the first "
         "at x, y, z = 0, 0, 0")]


def _negative_tolerance(tmp):
    return [block_scene(tmp), "-qsc_ksp_rtol", "-1"], ["-qsc_ksp_rtol: must be a finite number >= 0, got '-1'"]


def _snes_without_newton_test(tmp):
    # ksponly stops after one linear solve, whatever the contact rows or the residual: it reported success with
    # the contact force off by orders of magnitude
    return [block_scene(tmp), "-qsc_snes_type", "ksponly"], ["-qsc_snes_type ksponly", "not a Newton method",
                                                             "newtonls, newtontr"]


def _result_name_taken(tmp):
    (tmp / "out" / "solution.h5").mkdir(parents=True)      # where the run would write its fields
    return [block_scene(tmp)], ["output:", "solution.h5", "is a folder"]


BAD_INPUT = [_unknown_key, _wrong_type, _negative_modulus, _missing_mesh_file, _unknown_box_surface,
             _unknown_file_surface, _interior_file_surface, _not_a_mesh, _degenerate_file_cell,
             _contact_boxes_lost_in_round_off, _unknown_set_path, _set_missing_entry, _unavailable_partitioner,
             _shell_partitioner, _huge_box, _body_too_small, _pressure_not_finite, _pressure_out_of_range,
             _conflicting_boundaries, _negative_tolerance, _snes_without_newton_test, _result_name_taken]
SERIAL_OK = {_unavailable_partitioner}     # cases that only fail in parallel


@pytest.fixture(scope="module")
def bad_input_runs(tmp_path_factory):
    """Every bad-input case on 1 and 2 ranks, run side by side (an mpirun error exit is mostly waiting)."""
    serial_only()
    jobs = {}
    for case in BAD_INPUT:
        for ranks in (1, 2) if MPIRUN else (1,):
            if ranks == 1 and case in SERIAL_OK:
                continue
            folder = tmp_path_factory.mktemp(f"{case.__name__.strip('_')}_{ranks}")
            args, expected = case(folder)
            jobs[case, ranks] = (["run", *args, "--out", folder / "out"], ranks, folder, expected)
    with ThreadPoolExecutor(max_workers=4) as pool:
        runs = {key: pool.submit(run_qsc, args, ranks, folder, 30.0) for key, (args, ranks, folder, _) in jobs.items()}
        return {key: (*run.result(), jobs[key][3]) for key, run in runs.items()}


@pytest.mark.parametrize("ranks", RANKS)
@pytest.mark.parametrize("case", BAD_INPUT, ids=lambda f: f.__name__.strip("_"))
def test_bad_input_is_one_line_and_exit_2(bad_input_runs, case, ranks):
    """A bad scene, mesh or override shall end the run on every rank within seconds, with exit code 2
    and one line naming the problem."""
    if (case, ranks) not in bad_input_runs:
        pytest.skip("fails only in parallel (nothing is partitioned on one rank)")
    code, out, expected = bad_input_runs[case, ranks]
    assert code is not None, "still running after 30 s:\n" + out
    assert "Traceback" not in out and "internal error" not in out, out
    lines = own_lines(out)
    assert code == 2, out
    assert len(lines) == 1, out
    assert lines[0].startswith("qsc: error: "), out
    for text in expected:
        assert text in lines[0], (text, lines[0])


@pytest.mark.parametrize("ranks", RANKS)
def test_argument_errors_print_once(tmp_path, ranks):
    """An unknown command and an empty --out shall be one line however many ranks parse them."""
    code, out = qsc(["frobnicate"], ranks, cwd=tmp_path)
    assert code == 2 and [line for line in own_lines(out) if "error" in line] == [
        "qsc: error: argument command: invalid choice: 'frobnicate' (choose from 'run', 'check', 'sweep')"], out
    code, out = qsc(["run", CONFIGS / "patch_test.toml", "--out", ""], ranks, cwd=tmp_path)
    assert code == 2 and own_lines(out) == [
        "qsc: error: --out: an empty folder name (omit --out for the scene's output.directory)"], out


def test_check_refuses_a_softened_interface_for_gamg(tmp_path):
    """solver.contact_multigrid_alpha softens the interface for BoomerAMG only: run refused it under pc_type gamg
    (exit 2), check said the scene was valid (hunt32_3)."""
    code, out = qsc(["check", CONFIGS / "two_cubes_dies.toml", "--set", "solver.contact_multigrid_alpha=1",
                     "-qsc_pc_type", "gamg"], cwd=tmp_path)
    said = "qsc: error: solver.contact_multigrid_alpha: softens the interface for BoomerAMG only, and pc_type is 'gamg'"
    assert code == 2 and own_lines(out) == [said], out


def test_missing_scene_file(tmp_path):
    """A scene path that does not exist shall be exit code 2 with one line naming the path."""
    code, out = qsc(["check", tmp_path / "nothing.toml"])
    assert code == 2 and own_lines(out) == [f"qsc: error: {tmp_path / 'nothing.toml'}: scene file not found"], out


# ---------------------------------------------------------------- version and check

def test_version():
    """qsc --version shall print the qsc_petsc, PETSc, petsc4py and MPI versions, one per line."""
    import petsc4py
    from petsc4py import PETSc

    import qsc_petsc
    code, out = qsc(["--version"])
    lines = own_lines(out)
    assert code == 0, out
    assert [line.split()[0] for line in lines] == ["qsc_petsc", "PETSc", "petsc4py", "MPI"], out
    assert lines[0] == f"qsc_petsc {qsc_petsc.__version__}"
    assert lines[1] == "PETSc " + ".".join(map(str, PETSc.Sys.getVersion()))
    assert lines[2] == f"petsc4py {petsc4py.__version__}"
    assert len(lines[3].split()) > 1 and "\x00" not in out        # Open MPI's version string ends in a NUL


def test_dash_h_is_the_help():
    """-h is argparse's help (every usage line shows it), not a PETSc option: `qsc run -h` said the scene was
    missing, `qsc run SCENE -h` ran the scene (helper pass, session 25)."""
    for args in (["-h"], ["run", "-h"], ["check", "-h"], ["run", CONFIGS / "patch_test.toml", "-h"]):
        code, out = qsc(args)
        assert code == 0 and "usage: qsc" in out and "results in" not in out, out


def test_check_and_run_say_a_scene_too_far_from_the_origin(tmp_path):
    """The two cubes moved 1e9 m (their elements 0.11-0.17 m): coordinates known to 2.2e-7 m, 2e-6 of an element,
    where a penalty's penetrations (~1e-7 of it) are round-off; far enough and the answer went 97 % off, exit 0 with
    no word (hunt30_4). check and run say it in one line naming the pair and the dies; at 1e6 m nothing, nor for
    a scene near the origin with a body or a die's point far off (hunt30_7)."""
    cells = ["--set", "bodies.0.mesh.cells=[2,2,2]", "--set", "bodies.1.mesh.cells=[3,3,3]"]
    code, out = qsc(["check", CONFIGS / "two_cubes_dies.toml", *cells, "--set", "die.0.point=[1e9,-3e9,0]"],
                    cwd=tmp_path)
    assert code == 0 and "far from the origin" not in out, out      # the die's plane is z = 0 all the same
    for offset, warned in ((1e9, True), (1e6, False)):
        moved = ["--set", f"bodies.0.mesh.origin=[{offset},0,0]", "--set", f"bodies.1.mesh.origin=[{offset},0,1]",
                 *cells]
        for command in (["check"], ["run", "--out", tmp_path / f"o{offset:g}"]):
            code, out = qsc([command[0], CONFIGS / "two_cubes_dies.toml", *command[1:], *moved], cwd=tmp_path)
            assert code == 0, out
            said = [line for line in own_lines(out) if "far from the origin: " in line]
            assert len(said) == warned, out
            if warned:
                assert ("contact[0] (1e+09 m out, known to 2.2e-07 m, 6.7e-07 of its element size 0.333 m), die[0] "
                        "(1e+09 m out, known to 2.2e-07 m, 4.4e-07 of its element size 0.5 m), die[1]") in said[0]


def test_a_cell_degenerate_by_round_off_says_it_is_far(tmp_path):
    """Boxes 1e16 m out: their corners, known to 2 m, invert a 0.25 m hex; the cell check said so with no cause,
    before the far-from-origin line could (hunt34_3). At 1e15 m the run goes on."""
    moved = ["--set", "bodies.0.mesh.origin=[1e16,0,0]", "--set", "bodies.1.mesh.origin=[1e16,0,0.5]"]
    code, out = qsc(["check", CONFIGS / "patch_test.toml", *moved], cwd=tmp_path)
    assert code == 2, out
    assert own_lines(out)[-1].endswith("its corners lie 1e+16 m from the origin, where coordinates are known to 2 m "
                                       "against its size 0.25 m: move the scene nearer to the origin"), out


@pytest.mark.parametrize("ranks", RANKS)
def test_check_reports_mesh_partition_and_contact(tmp_path, ranks):
    """qsc check shall print mesh and partition statistics and the contact pair, once, and write nothing."""
    code, out = qsc(["check", CONFIGS / "patch_test.toml"], ranks, cwd=tmp_path)
    lines = own_lines(out)
    assert code == 0, out
    assert lines[0] == "scene patch_test: valid"
    assert "mesh: 130 hex cells, 267 vertices, 801 dofs" in lines          # 4x4x2 + 7x7x2 hexes
    assert "bodies: lower (32 cells), upper (98 cells)" in lines
    assert ("partition over 1 rank(s):" if ranks == 1 else
            f"partition over {ranks} rank(s) (coordinate bisection):") in lines      # the default partitioner
    ranks_lines = [line for line in lines if line.strip().startswith("rank ")]
    assert len(ranks_lines) == ranks
    assert sum(int(line.split()[2]) for line in ranks_lines) == 130                  # "rank r: N cells, ..."
    assert sum(int(line.split(",")[1].split()[0]) for line in ranks_lines) == 801   # "..., D owned dofs, ..."
    assert any(line.strip().startswith("balance (max/mean owned dofs):") for line in lines)
    contact = [line for line in lines if line.startswith("contact[0]:")]
    assert len(contact) == 1 and "upper.zmin (slave) / lower.zmax (master), quasi_symmetric" in contact[0], out
    assert len(lines) == len(set(lines)), "a line printed by more than one rank:\n" + out
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("ranks", RANKS)
def test_check_finds_a_free_body(tmp_path, ranks):
    """qsc check shall end as the run would before its first solve (exit 2, the free motions named) when the
    boundaries and the rows within reach leave a body free: the patch test without its rollers, whose frictionless
    contact holds the normal only."""
    scene = (CONFIGS / "patch_test.toml").read_text()
    for roller in ('surface = "lower.xmin"', 'surface = "lower.ymin"'):
        scene = scene.replace(roller, roller.replace("lower", "upper"), 1)     # the upper block held twice
    path = tmp_path / "free.toml"
    path.write_text(scene)
    code, out = qsc(["check", path], ranks, cwd=tmp_path)
    assert code == 2, out
    assert own_lines(out)[-1].startswith("qsc: error: load step 1: free rigid-body motion of lower (translation x, "
                                         "translation y, rotation about z)"), out


@pytest.mark.parametrize("ranks", RANKS)
def test_a_body_in_unconnected_pieces_must_hold_each(tmp_path, ranks):
    """A body read from a file in two unconnected pieces (two unit cubes 1 m apart), only the first one's base
    clamped: the hold check took the six rigid motions per body, so check said valid and direct solvers returned
    an arbitrary position for the free cube with exit 0 (helper pass, session 25). Each piece is held on its own
    now: the second is named (with where it is) in the run's exit-2 line, and clamping both bases solves."""
    cube = box_mesh((0.0, 0.0, 0.0), (1.0, 1.0, 1.0), (2, 2, 2), "tet")
    points = np.vstack([cube.points, cube.points + [2.0, 0.0, 0.0]])
    cells = np.vstack([cube.cells, cube.cells + len(cube.points)])
    rows = cube.surfaces["zmin"]
    bottoms = fem.cell_faces("tet", cube.cells[rows[:, 0]], rows[:, 1])
    write_gmsh(tmp_path / "two.msh", points, cells, "tet", {"base": bottoms, "base2": bottoms + len(cube.points)})
    one = block_scene(tmp_path, mesh='type = "file", path = "two.msh"', fixed="base", extra=PRESSED.replace(
        "blk.zmax", "blk.boundary"))
    code, out = qsc(["check", one], ranks, cwd=tmp_path)
    assert code == 2 and own_lines(out)[-1].startswith(
        "qsc: error: load step 1: free rigid-body motion of blk piece 2 of 2 (around 2.5, 0.5, 0.5)"), out
    both = block_scene(tmp_path, mesh='type = "file", path = "two.msh"', fixed="base", extra=PRESSED.replace(
        "blk.zmax", "blk.boundary") + '\n[[boundary]]\nsurface = "blk.base2"\ntype = "displacement"\nux = 0.0\n'
        'uy = 0.0\nuz = 0.0\n')
    code, out = qsc(["run", both, "--out", "out"], ranks, cwd=tmp_path)
    assert code == 0, out


def test_check_tries_the_solver_options(tmp_path):
    """qsc check said valid for PETSc options the run refuses at set-up (an unknown PC type, a SNES type whose
    stops qsc cannot check, from the command line or the scene; helper pass, session 25): it sets up the run's
    solver from the options and ends as the run would (exit 2, the same line)."""
    for args in (["-qsc_pc_type", "bogus"], ["--set", "petsc.snes_type=ksponly"],
                 # met at the preconditioner's set-up: on a model matrix (session 33)
                 ["-qsc_pc_type", "cholesky", "-qsc_pc_factor_mat_solver_type", "superlu"]):
        code, out = qsc(["check", CONFIGS / "patch_test.toml", *args])
        assert code == 2 and own_lines(out)[-1].startswith("qsc: error: ") and (
            "bogus" in out or "-qsc_snes_type ksponly" in out or "no installed package provides" in out), out
    code, out = qsc(["check", CONFIGS / "patch_test.toml", "-qsc_pc_type", "lu"])
    assert code == 0, out


def test_check_evaluates_the_pressure_fields(tmp_path):
    """qsc check said "valid" for a pressure field the run refuses (not finite on some face; hunt34_3)."""
    code, out = qsc(["check", CONFIGS / "patch_test.toml", "--set", 'boundary.5.value="sqrt(0.9-x)"'])
    assert code == 2 and own_lines(out)[-1].startswith("qsc: error: boundary[5].value: the pressure 'sqrt(0.9-x)' "
                                                       "on upper.zmax is not finite on the face near"), out
    # infinite on the surface's edge x = 0 only, which no quadrature point meets: its load grew by ln 2 a refinement
    code, out = qsc(["check", CONFIGS / "patch_test.toml", "--set", 'boundary.5.value="1/x"'])
    assert code == 2 and "the pressure '1/x' on upper.zmax is not finite on the face near x, y, z = 0.07143" in out


def test_check_finds_a_degenerate_cell(tmp_path):
    """qsc check called a mesh with a flat tet valid, which the run refuses (the assembly's test; hunt33_1): it makes
    the same test, with the run's line."""
    args, expected = _degenerate_file_cell(tmp_path)
    code, out = qsc(["check", *args])
    assert code == 2 and all(e in own_lines(out)[-1] for e in expected), out


# ---------------------------------------------------------------- failed solves

def _summary(out_dir):
    return json.loads((out_dir / "summary.json").read_text())


@pytest.mark.parametrize("ranks", RANKS)
def test_failed_load_step_exits_3_and_keeps_earlier_steps(tmp_path, ranks):
    """A load step that does not converge shall exit 3 with a message naming the SNES reason and the step;
    summary.json shall say "failed" and the results of the steps before it shall stay readable."""
    scene = tmp_path / "gap.toml"
    scene.write_text(GAP)
    # Calibrate on a free run: the blocks start 0.03 m into each other and the upper one is pulled up by
    # 0.05 m; step 2 (they separate: its glued first iterate must open) needs more Newton iterations than step 1
    # when it starts from step 1's state (the scene's predictor; an extrapolated start is already separated).
    code, out = qsc(["run", scene, "--out", tmp_path / "free"], ranks)
    assert code == 0, out
    steps = _summary(tmp_path / "free")["steps"]
    newton = [max(s["snes_iterations"] for s in step["solves"]) for step in steps]
    assert newton[1] > newton[0], newton
    code, out = qsc(["run", scene, "--out", tmp_path / "out", "--set", "solver.max_cutbacks=1",
                     "-qsc_snes_max_it", newton[0]], ranks)
    lines = own_lines(out)
    assert code == 3, out
    assert "Traceback" not in out
    assert lines[-1].startswith("qsc: solve failed: load step 2 "), out
    assert "SNES DIVERGED_MAX_IT" in lines[-1], out
    # the limit named, as the user set it (a 1/500 plate converged with it raised, unnamed; hunt35_4)
    assert lines[-1].endswith(f"had not settled within {newton[0]}: raise -qsc_snes_max_it, or use more load steps"), out
    assert any(line.startswith("step 1/2: ") for line in lines), out
    assert sum("cutting the increment in half" in line for line in lines) == 1, out    # max_cutbacks = 1
    summary = _summary(tmp_path / "out")
    assert summary["status"] == "failed"
    assert summary["error"] in lines[-1]
    assert "-qsc_snes_max_it" in (tmp_path / "out" / "petsc_options.txt").read_text()   # what to change next
    assert [s["step"] for s in summary["steps"]] == [1]
    assert not (tmp_path / "out" / "steps" / "step_0002.xdmf").exists()
    step1 = meshio.read(tmp_path / "out" / "steps" / "step_0001.xdmf")
    assert step1.point_data["displacement"].shape == (len(step1.points), 3)
    assert np.abs(step1.point_data["displacement"]).max() == pytest.approx(summary["steps"][0]["max_abs_displacement"])
    with meshio.xdmf.TimeSeriesReader(tmp_path / "out" / "solution.xdmf") as series:
        series.read_points_cells()
        assert series.num_steps == 1


@pytest.mark.parametrize("ranks", RANKS)
def test_result_that_cannot_be_written_stops_every_rank(tmp_path, ranks):
    """A result file that cannot be written mid-run (here: a folder in the way of step 2's file) shall stop
    every rank with exit 2 and one line naming the path, summary.json saying "failed" and step 1 kept."""
    out = tmp_path / "out"
    (out / "steps" / "step_0002.xdmf.tmp").mkdir(parents=True)
    code, text = qsc(["run", block_scene(tmp_path, extra=PRESSED), "--out", out, "--set", "load.steps=2"], ranks)
    lines = own_lines(text)
    assert code == 2 and "Traceback" not in text, text
    assert lines[-1] == f"qsc: error: output: cannot write {str(out / 'steps' / 'step_0002.xdmf.tmp')!r}: Is a directory"
    summary = _summary(out)
    assert summary["status"] == "failed" and summary["error"] in lines[-1]
    assert meshio.read(out / "steps" / "step_0001.xdmf").point_data["displacement"].shape == (27, 3)


@pytest.mark.parametrize("ranks", RANKS)
def test_body_held_only_by_rows_without_force_is_warned(tmp_path, ranks):
    """The quarter two-cube stack with its bottom die out of reach: the top die moves both cubes down as one
    rigid body, held only by contact rows that press with no force. The answer is an equilibrium, one of many:
    the run succeeds, and warns once, naming the bodies and motion (summary: loose)."""
    code, text = qsc(["run", CONFIGS / "two_cubes_quarter.toml", "--out", tmp_path, "--set", "die.0.point=[0, 0, -10]",
                      "--set", "bodies.1.mesh.cells=[3, 3, 6]"], ranks)
    assert code == 0, text
    warnings = [line for line in own_lines(text) if "warning" in line]
    assert len(warnings) == 1 and warnings[0].startswith(
        "step 1: warning: lower (translation z); upper (translation z): held there by no boundary and only by "
        "contact rows that carry no force, if any"), text
    assert [step.get("loose") for step in _summary(tmp_path)["steps"]] == [
        "lower (translation z); upper (translation z)"] * 2


@pytest.mark.parametrize("ranks", RANKS)
def test_linear_solver_error_is_a_failed_solve(tmp_path, ranks):
    """With -ksp_error_if_not_converged a Krylov failure shall be a failed solve (exit 3, KSP reason named),
    not an internal error."""
    args = ["run", block_scene(tmp_path, extra=PRESSED), "--out", tmp_path / "out", "--set", "solver.max_cutbacks=0"]
    code, out = qsc(args + ["-qsc_ksp_max_it", "1", "-qsc_ksp_error_if_not_converged"], ranks)
    lines = own_lines(out)
    assert "Traceback" not in out and "internal error" not in out, out
    assert code == 3, out
    assert lines[-1].startswith("qsc: solve failed: load step 1 "), out
    # DIVERGED_ITS and DIVERGED_MAX_IT are two PETSc names of one KSP reason
    assert re.search(r"SNES DIVERGED_LINEAR_SOLVE .*KSP (DIVERGED_ITS|DIVERGED_MAX_IT)$", lines[-1]), out
    assert _summary(tmp_path / "out")["status"] == "failed"


MUMPS = ["-qsc_ksp_type", "preonly", "-qsc_pc_type", "lu", "-qsc_pc_factor_mat_solver_type", "mumps"]


@pytest.mark.parametrize("ranks", RANKS)
def test_mumps_over_its_memory_cap_fails_at_once(tmp_path, ranks):
    """A MUMPS factorization that needs more than its memory cap (ICNTL(23), here the user's 1 MB) shall end the
    run at the first factorization with one line naming the memory, MUMPS's estimate and what to do: exit 3,
    no cutbacks (a smaller increment needs the same factors), summary.json "failed". The cap a run sets by
    itself is tested in-process (test_newton)."""
    mesh = 'type = "box", size = [1.0, 1.0, 1.0], cells = [8, 8, 8]'      # 2187 dofs: ~2 MB of MUMPS data
    args = ["run", block_scene(tmp_path, mesh=mesh, extra=PRESSED), "--out", tmp_path / "out"]
    code, out = qsc(args + MUMPS + ["-qsc_mat_mumps_icntl_23", "1"], ranks)
    lines = own_lines(out)
    assert code == 3, out
    assert "Traceback" not in out and not any("cutting the increment" in line for line in lines), out
    assert lines[-1].startswith("qsc: solve failed: load step 1: MUMPS's factorization: it needs more memory than "
                                "its cap of 1 MB a rank (-qsc_mat_mumps_icntl_23); its estimate after the analysis "
                                "was "), out
    assert "(INFOG(1) = -19; INFOG(16), INFOG(17))" in lines[-1] and lines[-1].endswith("lifts the cap"), out
    assert _summary(tmp_path / "out")["status"] == "failed"


@pytest.mark.parametrize("ranks", RANKS)
def test_library_error_in_the_solve_is_a_failed_solve(tmp_path, ranks):
    """An option combination hypre accepts as options but rejects at its setup (nodal coarsening with vector
    interpolation variant 2, hypre 2.26) fails inside the solve on every rank: exit 3 on all of them with one
    line naming the PETSc error and the load step, summary.json "failed"; not an internal error, no abort."""
    args = ["run", CONFIGS / "two_cubes_dies.toml", "--out", tmp_path / "out", "-qsc_ksp_type", "gmres",
            "-qsc_pc_type", "hypre", "-qsc_pc_hypre_boomeramg_nodal_coarsen", "6",
            "-qsc_pc_hypre_boomeramg_vec_interp_variant", "2"]
    code, out = qsc(args, ranks)
    assert code == 3, out
    assert "Traceback" not in out and "internal error" not in out and "MPI_ABORT" not in out, out
    failed = [line for line in own_lines(out) if line.startswith("qsc: solve failed: ")]
    assert len(failed) == 1 and failed[0].startswith("qsc: solve failed: load step 1: PETSc error 76 "), out
    assert "in PCSetUp_HYPRE(): Error in jac->setup()" in failed[0], out    # PETSc's message, quoted
    summary = _summary(tmp_path / "out")
    assert summary["status"] == "failed" and summary["error"] in failed[0]


# ---------------------------------------------------------------- PETSc options

def test_command_line_options_win_over_the_scene(tmp_path):
    """PETSc options on the command line shall override the scene's [petsc] table, and
    petsc_options.txt shall say where each option came from."""
    petsc = '\n[petsc]\nksp_type = "cg"\nksp_rtol = 1e-9\npc = { type = "jacobi" }\n'
    scene = block_scene(tmp_path, extra=PRESSED + petsc)
    code, out = qsc(["run", scene, "--out", tmp_path / "out", "-qsc_ksp_type", "preonly", "-qsc_pc_type", "lu",
                     "-qsc_ksp_converged_reason"])
    assert code == 0, out
    text = (tmp_path / "out" / "petsc_options.txt").read_text()
    source = {}
    for line in text.splitlines():
        if not line.startswith("#"):
            option, _, where = line.partition("#")
            name, *value = option.split()
            source[name] = (" ".join(value), where.strip())
    assert source["-qsc_ksp_type"] == ("preonly", "command line"), text
    assert source["-qsc_pc_type"] == ("lu", "command line"), text
    assert source["-qsc_ksp_rtol"] == ("1e-09", "scene"), text
    assert source["-qsc_ksp_converged_reason"] == ("", "command line"), text      # a flag: no value written
    # options the program sets itself are not the user's command line
    assert all(where != "command line" for name, (_, where) in source.items()
               if name not in ("-qsc_ksp_type", "-qsc_pc_type", "-qsc_ksp_converged_reason")), text
    # then, as comments, what the solver objects hold: the options' effect and what qsc set through the API
    assert "# snes: newtonls, rtol 1e-10, atol 0, stol 1e-10, max_it 60" in text, text
    assert "# ksp: preonly, " in text and "max_it 2000" in text and "# pc: lu (" in text, text
    summary = _summary(tmp_path / "out")
    assert summary["status"] == "ok"
    assert summary["petsc_options"]["qsc_ksp_type"] == "preonly"
    # a direct solve: one Krylov "iteration" per Newton iteration
    step = summary["steps"][0]
    assert step["ksp_iterations"] == step["snes_iterations"] >= 1


@pytest.mark.parametrize("option", [["-qsc_pc_type", "nonexistent"], ["-qsc_ksp_rtol", "abc"], ["-qsc_ksp_type"],
                                    ["-qsc_pc_type", "hypre", "-qsc_pc_hypre_boomeramg_relax_type_down", "nonsense"]])
def test_bad_petsc_option_is_an_input_error(tmp_path, option):
    """A PETSc option PETSc refuses (unknown type, value that does not parse, none of its choices) shall exit 2
    with one qsc line that quotes PETSc's message, which names the value."""
    proc = subprocess.run([sys.executable, "-m", "qsc_petsc.cli", "run", str(CONFIGS / "block_compression.toml"),
                           "--out", str(tmp_path), *option], capture_output=True, text=True, timeout=120,
                          check=False)
    assert proc.returncode == 2
    assert "qsc: error: PETSc options of the solver" in proc.stdout
    # PETSc's own message is quoted (petsc4py keeps it in the exception, nothing else prints it)
    assert f"{option[-1]}" in proc.stdout.splitlines()[-1], proc.stdout
    assert "Traceback" not in proc.stderr + proc.stdout
    if option[-1] == "abc":     # PETSc names the value only: qsc names the option that holds it
        assert "a value out of range or not a number in -qsc_ksp_rtol (PETSc error 63" in proc.stdout, proc.stdout
    if option == ["-qsc_ksp_type"]:     # PETSc names an empty type: qsc names the option
        assert "an unknown type in -qsc_ksp_type (no value given) (PETSc error 86" in proc.stdout, proc.stdout
    # the folder says so (it held nothing, or an earlier run's "ok" summary: helper pass, session 25)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["status"] == "failed" and "PETSc options of the solver" in summary["error"]
    assert f"-{option[0].lstrip('-')}" in (tmp_path / "petsc_options.txt").read_text()


@pytest.mark.parametrize("command, option", [("run", ["-ksp_type", "preonly"]), ("check", ["-snes_max_it", "3"]),
                                             ("run", ["-pc_factor_mat_solver_type", "mumps"])])
def test_an_unprefixed_solver_option_is_an_input_error(tmp_path, command, option):
    """qsc's solvers read their options under the qsc_ prefix: an unprefixed -ksp_ / -pc_ / -snes_ option, which
    nothing reads, shall exit 2 naming the prefixed one (-ksp_type preonly ran GMRES without a word)."""
    out = ["--out", str(tmp_path)] if command == "run" else []
    proc = subprocess.run([sys.executable, "-m", "qsc_petsc.cli", command, str(CONFIGS / "block_compression.toml"),
                           *out, *option], capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert f"qsc: error: {option[0]}: " in proc.stdout and f"-qsc_{option[0][1:]}" in proc.stdout, proc.stdout
    assert "Traceback" not in proc.stderr + proc.stdout


def test_an_out_folder_that_is_a_file_names_the_flag(tmp_path):
    """--out naming a file: the error shall name --out (it named the scene key output.directory) and say that a
    file is there (a helper's pass)."""
    path = tmp_path / "afile"
    path.write_text("")
    proc = subprocess.run([sys.executable, "-m", "qsc_petsc.cli", "run", str(CONFIGS / "block_compression.toml"),
                           "--out", str(path)], capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 2
    assert proc.stdout.strip().splitlines()[-1] == (f"qsc: error: --out: cannot create the folder {str(path)!r}: "
                                                    "File exists (a file of that name is there)"), proc.stdout
    # a name too long for the file system: the test for a file there raised again, a traceback and exit 1 (hunt34_3)
    long = tmp_path / ("a" * 300)
    proc = subprocess.run([sys.executable, "-m", "qsc_petsc.cli", "run", str(CONFIGS / "block_compression.toml"),
                           "--out", str(long)], capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 2 and "Traceback" not in proc.stdout + proc.stderr
    assert proc.stdout.strip().splitlines()[-1] == (f"qsc: error: --out: cannot create the folder {str(long)!r}: "
                                                    "File name too long"), proc.stdout


def test_an_unprefixed_option_from_the_environment_is_left_alone(tmp_path):
    """PETSC_OPTIONS (or a .petscrc) may hold options for other programs: an unprefixed solver option there is not
    an error, only on the command line (every run stopped with exit 2; hunt27_4)."""
    env = dict(os.environ, PETSC_OPTIONS="-ksp_converged_reason")
    proc = subprocess.run([sys.executable, "-m", "qsc_petsc.cli", "run", str(CONFIGS / "block_compression.toml"),
                           "--out", str(tmp_path)], capture_output=True, text=True, timeout=120, check=False, env=env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    # petsc_options.txt says where it came from (it read "command line"; hunt30_6), and the [petsc] table's own
    # default is no option the scene wrote (it read "scene")
    text = (tmp_path / "petsc_options.txt").read_text()
    assert "-ksp_converged_reason    # environment" in text and "-qsc_ksp_rtol 1e-10    # scene default" in text


def test_petsc_options_txt_lists_the_multigrids_defaults(tmp_path):
    """qsc's BoomerAMG defaults for the contact band's multigrid are put in the database for its setup and taken
    out again: petsc_options.txt listed neither them nor what BoomerAMG held (hunt30_6); its settings say them,
    less an option the user set."""
    scene = tmp_path / "pt.toml"
    scene.write_text((CONFIGS / "patch_test.toml").read_text().split("[petsc]")[0])
    proc = subprocess.run([sys.executable, "-m", "qsc_petsc.cli", "run", str(scene), "--out", str(tmp_path / "o"),
                           "-qsc_pc_hypre_boomeramg_P_max", "3"], capture_output=True, text=True, timeout=120,
                          check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    text = (tmp_path / "o" / "petsc_options.txt").read_text()
    line = next(x for x in text.splitlines() if x.startswith("# the multigrid read qsc's defaults: "))
    assert "-qsc_pc_hypre_boomeramg_coarsen_type PMIS" in line and "P_max" not in line, text
    assert "-qsc_pc_hypre_boomeramg_P_max 3    # command line" in text, text


@pytest.mark.parametrize("option, holder", [
    (["-qsc_ksp_monitor", "true"], "a value the option does not support"),
    (["-qsc_snes_monitor", "ascii:/nonexistent/dir/x.txt"], "a file that cannot be opened"),
    (["-qsc_ksp_converged_reason", "true"], "a value the option does not support"),
    # PETSc names the format alone (hunt34_3)
    (["-qsc_ksp_monitor", "ascii:monitor.txt:bogusformat"], "a value the option does not support")])
def test_a_viewer_option_with_a_bad_value_is_an_input_error(tmp_path, option, holder):
    """Viewer options given a value they do not take, or a file that cannot be opened, ended in a traceback per
    rank and MPI_Abort (exit 1), or, read at the solve's end, in a failed solve (exit 3; helper pass, session 25):
    exit 2 with one line naming the option. In a scene, `ksp_monitor = true` is the flag itself."""
    # in tmp_path: a viewer's file named relative (monitor.txt) is made where the run starts
    proc = subprocess.run([sys.executable, "-m", "qsc_petsc.cli", "run", str(CONFIGS / "patch_test.toml"),
                           "--out", str(tmp_path / "out"), *option], capture_output=True, text=True, timeout=120,
                          check=False, cwd=tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    last = proc.stdout.splitlines()[-1]
    assert last.startswith("qsc: error: PETSc options") and f"{holder}" in last and f"in {option[0]} (" in last, last
    assert "Traceback" not in proc.stderr + proc.stdout
    proc = subprocess.run([sys.executable, "-m", "qsc_petsc.cli", "run", str(CONFIGS / "patch_test.toml"),
                           "--out", str(tmp_path / "flag"), "--set", "petsc.ksp_converged_reason=true"],
                          capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 0 and "Linear qsc_ solve converged due to" in proc.stdout, proc.stdout + proc.stderr


@pytest.mark.parametrize("case", ["rtol 1", "atol above", "minres", "no cholesky", "value-less", "viewer file",
                                  "preonly jacobi", "no tolerance", "log_view file",
                                  "no newton step", "snes rtol 10", "snes stol 1", "equals", "mumps ordering"])
def test_solver_options_that_cannot_work_end_cleanly(tmp_path, case):
    """Options a PETSc user may try, each of which ended in a wrong answer with exit 0 or a traceback with exit 1
    (hunt30_6): -qsc_ksp_rtol 1 stops every linear solve before its first iteration, and the zero Newton steps
    passed the step test (the two cubes never moved, exit 0): exit 2 naming it; a -qsc_ksp_atol above the residual
    likewise (reactions 9 % off): exit 3 saying why; minres, which cannot take the unpreconditioned norm, failed
    again writing petsc_options.txt (exit 1): it is refused with the file written; a Cholesky no package provides, met
    at set-up (exit 1, no summary): exit 2; a refused value beside a value-less option crashed naming it (exit
    1); an ASCII viewer's file that cannot be written, which rank 0 alone opens, left the others waiting: exit 2
    before the run; preonly with an inexact preconditioner failed naming a body held by no boundary (its wrong
    iterates opened the holding rows): exit 3 naming the one application instead. Options the solver's set-up
    refuses (minres, a MUMPS option read when it factors) are met on a model matrix before the run: exit 2 naming
    them (they failed the first solve, exit 3, hunt34_3)."""
    options, code, said = {
        "rtol 1": (["-qsc_ksp_rtol", "1"], 2, "-qsc_ksp_rtol: must be below 1"),
        "atol above": (["-qsc_ksp_type", "cg", "-qsc_ksp_atol", "1"], 3,
                       "a linear solve stopped with its residual far above the Newton target"),
        "minres": (["-qsc_ksp_type", "minres"], 2, ("the solver's set-up refuses -qsc_ksp_type minres (PETSc error "
                   "56 in KSPSetUpNorms_Private(): KSP minres does not support norm type")),
        "no cholesky": (["-qsc_pc_type", "cholesky", "-qsc_pc_factor_mat_solver_type", "superlu"], 2,
                        "a factorization that no installed package provides"),
        "value-less": (["-qsc_snes_monitor", "-qsc_ksp_monitor", "true"], 2,
                       "a value the option does not support (a viewer option such as -qsc_ksp_monitor takes no value, "
                       + "or ascii:FILE) in -qsc_ksp_monitor ("),
        "viewer file": (["-qsc_snes_converged_reason", "ascii:/nonexistent/f.txt"], 2,
                        "a file that cannot be opened in -qsc_snes_converged_reason ('/nonexistent/f.txt'"),
        "preonly jacobi": (["-qsc_ksp_type", "preonly", "-qsc_pc_type", "jacobi", "-qsc_snes_max_it", "5"], 3,
                           "each linear solve was one application of pc_type jacobi (ksp_type preonly), not a solve"),
        # the value forgotten: a TypeError, a traceback and exit 1 (hunt32_3)
        "no tolerance": (["-qsc_ksp_max_it", "-qsc_ksp_monitor"], 2, "-qsc_ksp_max_it: needs an integer (no value"),
        # PetscFinalize still wrote the report and printed its error stack after the line (hunt32_3)
        "log_view file": (["-log_view", ":/nonexistent/f.txt"], 2, "a file that cannot be opened in -log_view"),
        # every try failed: 4 cutbacks, then "DIVERGED_MAX_IT after 0 iterations", exit 3 (session 33)
        "no newton step": (["-qsc_snes_max_it", "0"], 2, "-qsc_snes_max_it: must be at least 1 (at 0 no Newton step"),
        # the Newton test passed before the answer: the bodies at rest, or 9 % off, "ok" (hunt34_3)
        "snes rtol 10": (["-qsc_snes_rtol", "10"], 2, "-qsc_snes_rtol: must be below 1"),
        "snes stol 1": (["-qsc_snes_stol", "1"], 2, "-qsc_snes_stol: must be below 1"),
        # PETSc reads it as an option "qsc_pc_type=lu" with no value: the defaults ran, exit 0 (hunt34_3)
        "equals": (["-qsc_pc_type=lu"], 2, "-qsc_pc_type=lu: PETSc options take their value after a space"),
        # read by MUMPS when it factors: "solve failed ... PETSc error 63", exit 3, naming no option (hunt34_3)
        "mumps ordering": (["-qsc_ksp_type", "preonly", "-qsc_pc_type", "lu", "-qsc_pc_factor_mat_solver_type",
                            "mumps", "-qsc_mat_mumps_icntl_7", "99"], 2,
                           ("the solver's set-up refuses -qsc_mat_mumps_icntl_7 99 (PETSc error 63 in "
                           "MatSetFromOptions_MUMPS(): Valid values are")),
    }[case]
    proc = subprocess.run([sys.executable, "-m", "qsc_petsc.cli", "run", str(CONFIGS / "block_compression.toml"),
                           "--out", str(tmp_path), *options], capture_output=True, text=True, timeout=120,
                          check=False)
    assert proc.returncode == code, proc.stdout + proc.stderr
    assert said in proc.stdout.splitlines()[-1], proc.stdout
    assert "Traceback" not in proc.stderr + proc.stdout and "PETSC ERROR" not in proc.stderr + proc.stdout
    assert json.loads((tmp_path / "summary.json").read_text())["status"] == "failed"
    assert (tmp_path / "petsc_options.txt").exists()


def test_a_large_snes_atol_still_takes_a_newton_step(tmp_path):
    """-qsc_snes_atol above the first residual ended the solve before its first step: 0 Newton iterations,
    CONVERGED_FNORM_ABS, the block's top reaction -53.8 N against -10, "ok" (hunt34_3). A step is taken first."""
    proc = subprocess.run([sys.executable, "-m", "qsc_petsc.cli", "run", str(CONFIGS / "block_compression.toml"),
                           "--out", str(tmp_path), "-qsc_snes_atol", "100"], capture_output=True, text=True,
                          timeout=120, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert all(step["snes_iterations"] >= 1 for step in summary["steps"])
    assert summary["steps"][-1]["reactions"]["boundary[3] block.zmax"][2] == pytest.approx(-10.0, rel=1e-6)


BAND_OPTIONS = {
    "unknown type": (["-qsc_band_pc_type", "nonexistent"],
                     "qsc: error: PETSc options of the contact band's solve (-qsc_band_*): an unknown type",
                     "in PCSetType(): Unable to find requested PC type nonexistent"),
    "no package": (["-qsc_band_pc_factor_mat_solver_type", "superlu"],
                   "qsc: error: the PETSc options ask for a factorization that no installed package provides",
                   "in MatGetFactor(): MatSolverType superlu does not support"),
    # read when MUMPS factors: the run failed its first solve, exit 3, naming no option (hunt34_3)
    "refused at the factorization": (["-qsc_band_mat_mumps_icntl_4", "abc"],
                                     ("qsc: error: PETSc options: the solver's set-up refuses "
                                     "-qsc_band_mat_mumps_icntl_4 abc (PETSc error 63"),
                                     "in PetscOptionsStringToInt(): Input string abc has no integer value"),
}


@pytest.mark.skipif(MPIRUN is None, reason="mpirun not found")
@pytest.mark.parametrize("case", sorted(BAND_OPTIONS))
def test_bad_band_option_ends_every_rank_with_exit_2(tmp_path, case):
    """A -qsc_band_* option PETSc refuses ends every rank with exit 2 and one error line: an unknown type is read
    at the search (read inside the solve's callbacks it crashed the other rank), a factorization no package
    provides is met at the first factorization (its half-built preconditioner crashed PETSc's finalization
    until the failed run was destroyed before exit). `qsc check` says the same: it sets the preconditioner up on
    a model matrix (it passed them, hunt32_3), and so does the run before it touches its folder."""
    serial_only()
    option, expected, quoted = BAND_OPTIONS[case]
    for command in (["run", CONFIGS / "two_cubes_dies.toml", "--out", tmp_path / "out"],
                    ["check", CONFIGS / "two_cubes_dies.toml"]):
        code, out = run_qsc([*command, "-qsc_ksp_type", "gmres", "-qsc_pc_type", "hypre", *option], 2, tmp_path,
                            60.0)
        assert code == 2, out
        assert "Traceback" not in out and "SEGV" not in out, out
        errors = [line for line in own_lines(out) if line.startswith("qsc: error: ")]
        assert len(errors) == 1 and errors[0].startswith(expected) and quoted in errors[0], out


@pytest.mark.skipif(MPIRUN is None, reason="mpirun not found")
def test_a_band_on_superlu_dist_ends_cleanly(tmp_path):
    """The band factored by SuperLU_DIST on 2 ranks: with the run's model-matrix set-up (session 35) a second band
    set-up in one process freed a communicator twice at PetscFinalize, "corrupted double-linked list" and exit 134
    after the run said "done" (hunt35_3). The run leaves that band out of its model set-up."""
    serial_only()
    code, out = run_qsc(["run", CONFIGS / "two_cubes_dies.toml", "--out", tmp_path / "out", "-qsc_ksp_type", "gmres",
                         "-qsc_pc_type", "hypre", "-qsc_band_pc_type", "lu", "-qsc_band_pc_factor_mat_solver_type",
                         "superlu_dist"], 2, tmp_path, 120.0)
    assert code == 0 and "corrupted" not in out, out


def test_petsc_detail_quotes_the_innermost_routine_and_its_specifics():
    """errors.petsc_detail reads petsc4py's error text: the deepest routine and the lines after PETSc's generic one."""
    from qsc_petsc.errors import petsc_detail

    class Fake(Exception):
        def __init__(self, text):
            self.text = text

        def __str__(self):
            return self.text

    text = ("error code 76\n[0] SNESSolve() at snes.c:4692\n[0] PCSetUp_HYPRE() at hypre.c:419\n"
            "[0] Error in external library\n[0] Error in jac->setup(): error code 12")
    assert petsc_detail(Fake(text)) == "PCSetUp_HYPRE(): Error in jac->setup(): error code 12"
    assert petsc_detail(Fake("error code 55\n[1] MatMult() at matrix.c:2\n[1] Out of memory")) == \
        "MatMult(): Out of memory"
    assert petsc_detail(Fake("error code 76")) == "a routine PETSc did not name"


def _children(pid, count, wait=30.0):
    """The pids of process pid's `count` children (mpirun's ranks), once they are all there (no pgrep in the
    container image)."""
    import time
    deadline = time.time() + wait
    while True:
        found = sorted(int(p) for p in (Path("/proc") / str(pid) / "task" / str(pid) / "children").read_text().split())
        if len(found) >= count or time.time() > deadline:
            assert len(found) == count, found
            return found
        time.sleep(0.01)


@pytest.mark.skipif(MPIRUN is None, reason="mpirun not found")
@pytest.mark.parametrize("delay", [0.0, 0.1, 0.2])
def test_a_signal_to_one_rank_while_it_starts_ends_the_job(tmp_path, delay):
    """SIGTERM to rank 0 while MPI and PETSc start (a helper's test pass, session 26): the handler, installed
    first, raised outside the run's try, and the rank's exit waited in petsc4py's collective clean-up while the
    other waited in set-up, for ever. Before MPI is up the signal now ends the process (mpirun ends the job);
    after, the rank aborts the job. Either way the job ends, non-zero, within seconds."""
    serial_only()
    import time
    cmd = [MPIRUN, "-n", "2"] + QSC + ["run", str(CONFIGS / "sliding_cubes.toml"), "--out", str(tmp_path / "out")]
    proc = subprocess.Popen(cmd, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True)
    try:
        ranks = _children(proc.pid, 2)
        time.sleep(delay)
        os.kill(ranks[0], signal.SIGTERM)
        text, _ = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        pytest.fail(f"the job still ran 30 s after rank 0 was sent SIGTERM {delay} s after it started")
    assert proc.returncode != 0 and "qsc: done" not in text, text


@pytest.mark.skipif(MPIRUN is None, reason="mpirun not found")
@pytest.mark.parametrize("which", [0, 1])
def test_a_signal_to_one_rank_ends_the_job(tmp_path, which):
    """SIGTERM to one rank of a 2-rank run (a kill of one process; a batch system's kill reaches the ranks at
    different points): that rank's clean-up waited in a collective call (MUMPS's destroy, MPI's finalize)
    while the other waited in the solve, for ever (a helper's test pass, session 26). The signalled rank now
    ends the job (MPI_Abort, exit 130); the finished steps stay, and rank 0, when signalled, says
    "interrupted" in summary.json."""
    serial_only()
    import time
    out = tmp_path / "out"
    cmd = [MPIRUN, "-n", "2"] + QSC + ["run", str(CONFIGS / "block_compression.toml"), "--out", str(out),
                                       "--set", "bodies.0.mesh.cells=[24,24,24]", "--set", "load.steps=40",
                                       "--set", "solver.predictor=\"previous\"", "-qsc_ksp_type", "cg",
                                       "-qsc_pc_type", "jacobi"]
    proc = subprocess.Popen(cmd, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True)
    try:
        deadline = time.time() + 60
        summary = out / "summary.json"
        while not (summary.is_file() and json.loads(summary.read_text())["steps"]) and time.time() < deadline:
            time.sleep(0.2)
        ranks = _children(proc.pid, 2)
        os.kill(ranks[which], signal.SIGTERM)
        text, _ = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        pytest.fail(f"the job still ran 30 s after rank {which} was sent SIGTERM")
    assert proc.returncode == 130, text
    assert f"qsc: interrupted (rank {which}); ending the job" in text and "Traceback" not in text, text
    done = json.loads(summary.read_text())
    assert done["steps"] and done["status"] == ("interrupted" if which == 0 else "running")


def test_a_reader_that_leaves_does_not_end_the_run(tmp_path):
    """`qsc run ... | head -1`: PETSc's signal handler ended the run at its next line (SIGPIPE, exit 59, the
    summary left "running" after 1 step of 30; hunt34_3). The rest of the lines go nowhere and the run ends as
    it would have; its lines come as they are made (the first is read while it runs)."""
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "qsc_petsc.cli", "run", str(CONFIGS / "patch_test.toml"),
                             "--out", str(out), "--set", "load.steps=30"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        first = proc.stdout.readline()
        proc.stdout.close()
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert first.startswith("qsc: patch_test: 801 dofs on 1 rank(s)"), first
    assert proc.returncode == 0 and "Traceback" not in err and "PETSC ERROR" not in err, err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "ok" and len(summary["steps"]) == 30
