"""Rigid dies: nodes out of reach that go through, a die over bodies of different moduli, a die's surfaces taken
as one, and the pressure field where a die and a pair press one surface (a helper's test pass, session 25)."""

import meshio
import numpy as np
import pytest
from conftest import CONFIGS, block_and_cube, die, run_scene, write_gmsh
from mpi4py import MPI

from qsc_petsc import fem, solver
from qsc_petsc.contact.model import contact_plan
from qsc_petsc.errors import ConvergenceError
from qsc_petsc.mesh import distribute_mesh
from qsc_petsc.meshgen import box_mesh
from qsc_petsc.scene import SceneError, load_scene

THROUGH = """\
name = "through"
[[bodies]]
name = "b"
mesh = { type = "box", origin = [0.0, 0.0, 0.0], size = [1.0, 1.0, 1.0], cells = [4, 4, 4] }
material = { youngs_modulus = 1000.0, poissons_ratio = 0.3 }
[[boundary]]
surface = "b.zmax"
type = "displacement"
ux = 0.0
uy = 0.0
uz = -0.5
[[die]]
name = "floor"
point = [0.0, 0.0, -0.3]
normal = [0.0, 0.0, 1.0]
surfaces = ["b.zmin"]
[load]
steps = 1
[petsc]
ksp_type = "preonly"
pc_type = "lu"
pc_factor_mat_solver_type = "mumps"
"""

STOP = """\
name = "stop"
[[bodies]]
name = "lower"
mesh = { type = "box", origin = [0.0, 0.0, 0.0], size = [1.0, 1.0, 1.0], cells = [4, 4, 4] }
material = { youngs_modulus = 500.0, poissons_ratio = 0.3 }
[[bodies]]
name = "upper"
mesh = { type = "box", origin = [0.0, 0.0, 1.0], size = [1.0, 1.0, 0.5], cells = [5, 5, 2] }
material = { youngs_modulus = 1000.0, poissons_ratio = 0.3 }
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
[[boundary]]
surface = "upper.zmax"
type = "pressure"
value = 10.0
[[contact]]
slave = "upper.zmin"
master = "lower.zmax"
formulation = "quasi_symmetric"
penalty = 1e4
[[die]]
name = "floor"
point = [0.0, 0.0, 0.0]
normal = [0.0, 0.0, 1.0]
surfaces = ["lower.zmin"]
condition = "frictionless"
[[die]]
name = "stop"
point = [0.0, 0.0, 0.995]
normal = [0.0, 0.0, 1.0]
surfaces = ["upper.zmin"]
condition = "frictionless"
[load]
steps = 2
[petsc]
ksp_type = "preonly"
pc_type = "lu"
pc_factor_mat_solver_type = "mumps"
"""


def _write(tmp_path, name, text):
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return path


def test_a_body_cannot_pass_through_a_die_from_out_of_reach(tmp_path):
    """A block 0.3 m above a floor die (search distance 0.25 m) pushed down 0.5 m in one step: the die's rows
    were made at the step's start for the nodes within reach, none, and the block went through with no force,
    exit 0. A converged try that leaves out-of-reach nodes through a die fails (OUT_OF_REACH) and is halved:
    the die carries the block's 208 N (the answer of 2 load steps, or of a larger search distance)."""
    _, summary = run_scene(_write(tmp_path, "through", THROUGH), tmp_path / "one")
    step = summary["steps"][0]
    assert summary["status"] == "ok" and step["cutbacks"] >= 1
    assert step["solves"][0]["snes_reason"] == "OUT_OF_REACH"
    force = next(iter(step["contact"].values()))["force_on_bodies"][2]
    _, ref = run_scene(_write(tmp_path, "through", THROUGH), tmp_path / "two", ["load.steps=2"])
    assert force == pytest.approx(next(iter(ref["steps"][-1]["contact"].values()))["force_on_bodies"][2], rel=1e-8)
    assert force == pytest.approx(208.365, rel=1e-4)


def test_a_die_over_bodies_of_different_moduli_is_refused(tmp_path):
    """The die's penalty alpha E / h took the smallest E for every body it pressed: a body 1e3 x stiffer was held
    2.5 % low, 1e5 x 72 % low. A die over bodies of different Young's moduli is now an input error."""
    text = STOP.replace('surfaces = ["lower.zmin"]', 'surfaces = ["lower.zmin", "upper.zmax"]')
    with pytest.raises(SceneError, match=r"die\[0\]\.surfaces: the die presses bodies of different Young's "
                                         r"moduli \(lower 500 Pa, upper 1000 Pa\)"):
        load_scene(_write(tmp_path, "two_e", text))


def test_a_die_takes_its_surfaces_as_one(tmp_path):
    """A floor face split into two groups (bot_a, bot_b) in a mesh file: the seam nodes had the first-listed
    group's area only and read twice the pressure (20 Pa under 10), the die's area 0.93. The die's surfaces are
    now one surface: the same answer as the unsplit face."""
    box = box_mesh((0.0, 0.0, 0.0), (1.0, 1.0, 1.0), (4, 4, 4), "tet")
    bottom = fem.cell_faces("tet", box.cells[box.surfaces["zmin"][:, 0]], box.surfaces["zmin"][:, 1])
    left = box.points[bottom].mean(axis=1)[:, 0] < 0.5
    groups = {"bot_a": bottom[left], "bot_b": bottom[~left], "bottom": bottom}
    for side in ("xmin", "ymin", "zmax"):
        rows = box.surfaces[side]
        groups[side] = fem.cell_faces("tet", box.cells[rows[:, 0]], rows[:, 1])
    write_gmsh(tmp_path / "split.msh", box.points, box.cells, "tet", groups)
    text = """name = "split"
[[bodies]]
name = "b"
mesh = { type = "file", path = "split.msh" }
material = { youngs_modulus = 1000.0, poissons_ratio = 0.3 }
[[boundary]]
surface = "b.xmin"
type = "symmetry"
[[boundary]]
surface = "b.ymin"
type = "symmetry"
[[boundary]]
surface = "b.zmax"
type = "pressure"
value = 10.0
[[die]]
name = "floor"
point = [0.0, 0.0, 0.0]
normal = [0.0, 0.0, 1.0]
surfaces = ["b.bot_a", "b.bot_b"]
[load]
steps = 1
[petsc]
ksp_type = "preonly"
pc_type = "lu"
"""
    _, summary = run_scene(_write(tmp_path, "split", text), tmp_path / "out")
    die = next(iter(summary["steps"][0]["contact"].values()))
    assert die["contact_area"] == pytest.approx(1.0, rel=1e-12)
    traction = meshio.read(tmp_path / "out" / "steps" / "step_0001.xdmf").point_data["contact_traction"][:, 0]
    assert np.allclose(traction[traction > 0], 10.0, rtol=1e-8)


def test_a_die_and_a_pair_on_one_surface_add_up(tmp_path):
    """A stop die and a contact pair share the upper block's bottom (the die 5 mm below the lower block's top):
    the field showed the larger of the two (7.5 Pa) where their sum, 10 Pa, is the pressure."""
    _, summary = run_scene(_write(tmp_path, "stop", STOP), tmp_path / "out")
    assert summary["status"] == "ok"
    result = meshio.read(tmp_path / "out" / "steps" / "step_0002.xdmf")
    traction, x = result.point_data["contact_traction"][:, 0], result.points
    bottom = np.isclose(x[:, 2], 1.0) & (traction > 0)
    assert bottom.sum() > 0 and traction.max() == pytest.approx(10.0, rel=1e-6)


STACK_WITH_A_GAP = """\
name = "stack4"
[[bodies]]
name = "b0"
mesh = { type = "box", origin = [0.0, 0.0, 0.0], size = [1.0, 1.0, 0.1], cells = [4, 4, 1] }
material = { youngs_modulus = 1000.0 }
[[boundary]]
surface = "b0.xmin"
type = "symmetry"
[[boundary]]
surface = "b0.ymin"
type = "symmetry"
[[bodies]]
name = "b1"
mesh = { type = "box", origin = [0.0, 0.0, 0.1], size = [1.0, 1.0, 0.1], cells = [4, 4, 1] }
material = { youngs_modulus = 1000.0 }
[[boundary]]
surface = "b1.xmin"
type = "symmetry"
[[boundary]]
surface = "b1.ymin"
type = "symmetry"
[[bodies]]
name = "b2"
mesh = { type = "box", origin = [0.0, 0.0, 0.2], size = [1.0, 1.0, 0.1], cells = [4, 4, 1] }
material = { youngs_modulus = 1000.0 }
[[boundary]]
surface = "b2.xmin"
type = "symmetry"
[[boundary]]
surface = "b2.ymin"
type = "symmetry"
[[bodies]]
name = "b3"
mesh = { type = "box", origin = [0.0, 0.0, 0.7], size = [1.0, 1.0, 0.1], cells = [4, 4, 1] }
material = { youngs_modulus = 1000.0 }
[[boundary]]
surface = "b3.xmin"
type = "symmetry"
[[boundary]]
surface = "b3.ymin"
type = "symmetry"
[[contact]]
slave = "b1.zmin"
master = "b0.zmax"
[[contact]]
slave = "b2.zmin"
master = "b1.zmax"
[[contact]]
slave = "b3.zmin"
master = "b2.zmax"
search_distance = 2.0
[[die]]
name = "bottom"
point = [0, 0, 0]
normal = [0, 0, 1]
motion = [0, 0, 0]
surfaces = ["b0.zmin"]
condition = "frictionless"
[[die]]
name = "top"
point = [0, 0, 0.8]
normal = [0, 0, -1]
motion = [0, 0, -0.01]
surfaces = ["b3.zmax"]
condition = "frictionless"
[load]
steps = 1
[petsc]
ksp_type = "preonly"
pc_type = "lu"
pc_factor_mat_solver_type = "mumps"
"""


def test_every_loose_body_is_named_when_no_force_is_carried(tmp_path):
    """Three blocks on a frictionless die and a fourth 0.4 m above them under a frictionless die that pushes it
    into the gap: nothing carries force, and each block could rise or sink with the rest. All four are loose;
    with every row force round-off (3e-15 N at most) round-off rows counted as pressing against a share of
    the largest, and only the top block was named (hunt27_2 F4). The share is now of the force floor at least."""
    path = tmp_path / "stack.toml"
    path.write_text(STACK_WITH_A_GAP)
    run, summary = run_scene(path, tmp_path / "out")
    run.destroy()
    assert summary["status"] == "ok"
    assert summary["steps"][-1]["loose"] == ("b0 (translation z); b1 (translation z); b2 (translation z); "
                                             "b3 (translation z)")


FLOATING_STACK = """\
name = "floating"

[[bodies]]
name = "b0"
mesh = { type = "box", origin = [0.0, 0.0, 0.0], size = [1.0, 1.0, 0.5], cells = [3, 3, 2], element = "hex" }
material = { youngs_modulus = 1000.0, poissons_ratio = 0.3 }

[[bodies]]
name = "b1"
mesh = { type = "box", origin = [0.0, 0.0, 0.51], size = [1.0, 1.0, 0.5], cells = [5, 5, 2], element = "hex" }
material = { youngs_modulus = 1000.0, poissons_ratio = 0.3 }

[[bodies]]
name = "b2"
mesh = { type = "box", origin = [0.0, 0.0, 1.02], size = [1.0, 1.0, 0.5], cells = [4, 4, 3], element = "hex" }
material = { youngs_modulus = 1000.0, poissons_ratio = 0.3 }

[[bodies]]
name = "b3"
mesh = { type = "box", origin = [0.0, 0.0, 1.53], size = [1.0, 1.0, 0.5], cells = [7, 7, 2], element = "hex" }
material = { youngs_modulus = 1000.0, poissons_ratio = 0.3 }

[[boundary]]
surface = "b0.zmin"
type = "displacement"
uz = 0.0

[[boundary]]
surface = "b0.xmin"
type = "symmetry"

[[boundary]]
surface = "b0.ymin"
type = "symmetry"

[[boundary]]
surface = "b1.xmin"
type = "symmetry"

[[boundary]]
surface = "b1.ymin"
type = "symmetry"

[[boundary]]
surface = "b2.xmin"
type = "symmetry"

[[boundary]]
surface = "b2.ymin"
type = "symmetry"

[[boundary]]
surface = "b3.xmin"
type = "symmetry"

[[boundary]]
surface = "b3.ymin"
type = "symmetry"

[[die]]
name = "top"
point = [0.0, 0.0, 2.0300000000000002]
normal = [0.0, 0.0, -1.0]
motion = [0.0, 0.0, -0.04]
surfaces = ["b3.zmax"]
condition = "frictionless"

[[contact]]
slave = "b1.zmin"
master = "b0.zmax"
formulation = "master_slave"

[[contact]]
slave = "b2.zmin"
master = "b1.zmax"
formulation = "master_slave"

[[contact]]
slave = "b3.zmin"
master = "b2.zmax"
formulation = "master_slave"

[load]
steps = 3

[petsc]
ksp_type = "preonly"
pc_type = "lu"
pc_factor_mat_solver_type = "mumps"
"""


def test_rows_at_their_round_off_hold_no_body(tmp_path):
    """Four blocks with gaps of 0.01 m between them, rollers, the bottom one clamped, a die moving down 0.04 m in 3
    steps: at step 1 the die has closed 0.013 of the 0.03 m of gaps, b1 and b2 lie on b0 with rows at round-off
    (7e-12 and 2e-11 N) and b3 under the die. Only b3 was named loose (hunt32_1): those rows passed the share of
    the force floor. A row within LOOSE_ROUND_OFF of its own round-off carries no force."""
    path = tmp_path / "floating.toml"
    path.write_text(FLOATING_STACK)
    run, summary = run_scene(path, tmp_path / "out")
    run.destroy()
    assert summary["status"] == "ok"
    assert summary["steps"][0]["loose"] == "b1 (translation z); b2 (translation z); b3 (translation z)"
    assert "loose" not in summary["steps"][-1]


STICK = """\
name = "stick"
[[bodies]]
name = "blk"
mesh = {{ type = "box", origin = [0, 0, 0], size = [1, 1, 1], cells = [4, 4, 4] }}
material = {{ youngs_modulus = 1000.0, poissons_ratio = 0.3 }}
{support}
[[die]]
name = "top"
point = [0, 0, {top}]
normal = [0, 0, -1]
motion = {motion}
surfaces = ["blk.zmax"]
condition = "sticking"
[load]
steps = {steps}
[petsc]
ksp_type = "preonly"
pc_type = "lu"
pc_factor_mat_solver_type = "mumps"
"""
FLOOR = """[[die]]
name = "bottom"
point = [0, 0, 0]
normal = [0, 0, 1]
surfaces = ["blk.zmin"]
condition = "sticking\""""


def _top_force(summary, step=-1):
    return np.array(summary["steps"][step]["contact"]["die[1] top"]["force_on_bodies"])


@pytest.mark.parametrize("cut", [False, True])
def test_a_sticking_die_holds_a_node_where_it_met_it(tmp_path, monkeypatch, cut):
    """A sticking die measured the slip from the undeformed state: a die that reached a block 0.05 m below it
    after moving 0.025 m sideways sheared it by its whole travel, 14.0 N against 7.0 (hunt31_2). Its nodes
    stick where they meet the die: here 0.045 m below, met halfway through the 5th step, the answer of the die
    that starts on the block and moves the rest of the way, and no force before; also when that step's first
    try fails and is cut back into one that ends on the die and one that starts there."""
    if cut:
        real, failed = solver._solve_enforced, []

        def fail_once(system, step, t_try, *args):
            ok, u, stats = real(system, step, t_try, *args)
            if step == 5 and not failed:
                failed.append(t_try)
                return False, u, stats
            return ok, u, stats
        monkeypatch.setattr(solver, "_solve_enforced", fail_once)
    gap = STICK.format(support=FLOOR, top=1.045, motion="[0.05, 0, -0.1]", steps=10)
    _, summary = run_scene(_write(tmp_path, "gap", gap), tmp_path / "gap")
    monkeypatch.undo()
    ref = STICK.format(support=FLOOR, top=1.0, motion="[0.0275, 0, -0.055]", steps=5)
    _, reference = run_scene(_write(tmp_path, "ref", ref), tmp_path / "ref")
    assert summary["status"] == "ok" and summary["steps"][4]["cutbacks"] == int(cut)
    assert np.abs(_top_force(summary, 3)).max() < 1e-9
    # the floor carries the block from the start, with no force until the die comes: no contact area till then
    # (the closed rows' area read 1 m2 at 0 N; hunt31_2)
    floor = [step["contact"]["die[0] bottom"]["contact_area"] for step in summary["steps"]]
    assert floor[3] == 0.0 and floor[-1] == pytest.approx(1.0, rel=1e-12), floor
    assert _top_force(summary) == pytest.approx(_top_force(reference), rel=1e-8, abs=1e-8)
    assert _top_force(summary)[0] == pytest.approx(7.702, abs=1e-3)      # 7.002 N a 0.025 m shear (hunt31_2)


def test_a_sticking_die_does_not_pull_a_carried_body_back(tmp_path):
    """A block carried 0.05 m sideways by its support, a sticking die coming straight down onto it: on touching
    the die pulled its top back to where it started (ux 0.02 -> 0, hunt31_2). The top now stays where the die met
    it, to within its own travel over the touching increment (0.005 m), while the support goes on."""
    support = '[[boundary]]\nsurface = "blk.zmin"\ntype = "displacement"\nux = 0.05\nuy = 0.0\nuz = 0.0'
    scene = STICK.format(support=support, top=1.05, motion="[0, 0, -0.1]", steps=10)
    _, summary = run_scene(_write(tmp_path, "carried", scene), tmp_path / "out")
    assert summary["status"] == "ok"
    u = meshio.read(tmp_path / "out" / "steps" / "step_0010.xdmf")
    top = u.points[:, 2] > 1.0 - 1e-9
    ux = u.point_data["displacement"][top, 0]
    assert ux.min() > 0.02 - 1e-3 and ux.max() < 0.025 + 1e-3, ux


def test_a_die_turned_away_from_its_surface_says_so(tmp_path):
    """A die whose normal points away from the bodies (or that lies on an edge of a surface that does not face
    it) holds nothing: its nodes went through it and the run stopped saying they were out of the die's reach, to
    raise search_distance, which changed nothing; `qsc check` said only "0 candidate rows" (hunt31_2). Both now
    say that the nodes' faces turn away from the die, and what to check."""
    scene_text = STICK.format(support=FLOOR, top=1.0, motion="[0, 0, 0.01]", steps=2).replace(
        "normal = [0, 0, -1]", "normal = [0, 0, 1]")
    path = _write(tmp_path, "turned", scene_text)
    scene = load_scene(path)
    lines = contact_plan(distribute_mesh(scene, MPI.COMM_WORLD), scene)
    assert any(line.startswith("warning: die[1] top: 25 node(s) of its surfaces lie on or past its plane with faces "
                               "turned away from it, and no row: a die holds only the nodes of faces turned towards "
                               "it; check the sign of its normal") for line in lines), lines
    right = load_scene(_write(tmp_path, "right", STICK.format(support=FLOOR, top=1.0, motion="[0, 0, -0.01]",
                                                              steps=2)))
    assert not any(line.startswith("warning") for line in contact_plan(distribute_mesh(right, MPI.COMM_WORLD), right))
    with pytest.raises(ConvergenceError, match=r"die\[1\] \(top\): 25 node\(s\) within the die's reach, of faces "
                                               r"turned away from it, went through it: a die holds only"):
        run_scene(path, tmp_path / "out", ["solver.max_cutbacks=1"])


def test_a_die_on_surfaces_that_never_reach_it_says_where_the_body_went_through(tmp_path):
    """A die acts on the surfaces it lists only: a floor given a body's top instead of its bottom let the body
    through it with the die's force 0 and no word (hunt33_6: a sphere's pole 9.5 mm through). The run says how far
    and on which surfaces the deepest node lies; the floor on the bottom presses it and says nothing."""
    text = ('name = "through"\n[[bodies]]\nname = "b"\nmesh = { type = "box", origin = [0.0, 0.0, 0.0], size = '
            '[1.0, 1.0, 1.0], cells = [3, 3, 3] }\nmaterial = { youngs_modulus = 1000.0 }\n[[boundary]]\n'
            'surface = "b.zmax"\ntype = "displacement"\nux = 0.0\nuy = 0.0\nuz = -0.02\n[[die]]\nname = "floor"\n'
            'point = [0.0, 0.0, 0.0]\nnormal = [0.0, 0.0, 1.0]\nsurfaces = ["b.{face}"]\n')
    for face, said in (("zmax", [("die[0] floor: it presses none of its surfaces (b.zmax) while other nodes of its "
                                 "bodies lie up to 0.02 m = 0.06 of its surfaces' element size past its plane (the deepest at x, y, z "
                                 "= 0, 0, 0 before the load, on b.xmin, b.ymin, b.zmin): a die acts on the surfaces it lists only")]),
                       ("zmin", [])):
        lines = []
        run, summary = run_scene(_write(tmp_path, face, text.replace("{face}", face)), tmp_path / face,
                                 log=lines.append)
        run.destroy()
        warnings = [line for line in lines if "warning" in line]
        assert summary["status"] == "ok" and len(warnings) == len(said), lines
        assert all(any(s in w for w in warnings) for s in said), lines


def test_a_die_that_lets_nodes_through_within_its_surfaces_footprint_says_so(tmp_path):
    """A floor die given the outer ring of a block's bottom and not its core: the ring is pressed and the core goes
    through the floor with no word (hunt34_2: a sphere's floor given its outer skin, the pole 13 mm through, the
    force 59 % low). Nodes off the die's surfaces, within their footprint, sunk past 10 x its pressed nodes are
    said; the die on both, or on a patch of a face (a punch of that shape), is not."""
    from qsc_petsc import fem
    from qsc_petsc.meshgen import box_mesh
    box = box_mesh((0.0, 0.0, 0.0), (1.0, 1.0, 0.5), (8, 8, 4), "hex")

    def faces(side):
        return fem.cell_faces("hex", box.cells[box.surfaces[side][:, 0]], box.surfaces[side][:, 1])
    bottom, top = faces("zmin"), faces("zmax")
    core = (np.abs(box.points[bottom].mean(axis=1)[:, :2] - 0.5) < 0.25).all(axis=1)
    patch = (np.abs(box.points[top].mean(axis=1)[:, :2] - 0.5) < 0.25).all(axis=1)
    write_gmsh(tmp_path / "b.msh", box.points, box.cells, "hex",
               {"ring": bottom[~core], "core": bottom[core], "top": top, "patch": top[patch]})
    text = ('name = "ring"\n[[bodies]]\nname = "b"\nmesh = { type = "file", path = "b.msh" }\nmaterial = { '
            'youngs_modulus = 1000.0 }\n[[boundary]]\nsurface = "b.top"\ntype = "displacement"\nux = 0.0\n'
            'uy = 0.0\nuz = -0.01\n[[die]]\nname = "floor"\npoint = [0.0, 0.0, 0.0]\nnormal = [0.0, 0.0, 1.0]\n'
            'surfaces = {surfaces}\ncondition = "sticking"\n')
    punch = ('name = "punch"\n[[bodies]]\nname = "b"\nmesh = { type = "file", path = "b.msh" }\nmaterial = { '
             'youngs_modulus = 1000.0 }\n[[boundary]]\nsurface = "b.ring"\ntype = "displacement"\nux = 0.0\n'
             'uy = 0.0\nuz = 0.0\n[[boundary]]\nsurface = "b.core"\ntype = "displacement"\nux = 0.0\n'
             'uy = 0.0\nuz = 0.0\n[[die]]\nname = "punch"\npoint = [0.0, 0.0, 0.5]\nnormal = [0.0, 0.0, -1.0]\n'
             'motion = [0.0, 0.0, -0.01]\nsurfaces = ["b.patch"]\ncondition = "sticking"\n')
    for name, scene, said in (("ring", text.replace("{surfaces}", '["b.ring"]'), True),
                              ("both", text.replace("{surfaces}", '["b.ring", "b.core"]'), False),
                              ("patch", punch, False)):
        lines = []
        run, summary = run_scene(_write(tmp_path, name, scene), tmp_path / name, log=lines.append)
        run.destroy()
        warnings = [line for line in lines if "warning" in line]
        assert summary["status"] == "ok" and len(warnings) == said, lines
        assert not said or ("die[0] floor: it presses its surfaces (b.ring) while other nodes of its bodies within "
                            "their footprint lie up to" in warnings[0] and "on b.core" in warnings[0]), lines


def test_a_punch_approaching_a_shoulder_is_not_said_to_let_the_body_through(tmp_path):
    """A die on an L-shaped body's shoulder, approaching across a gap: its plane has the body's tall part past it
    from the start, by design, and the through-die warning named those nodes while the die approached, its advice
    (list the surface that faces it) crushing the tall part (hunt34_2). Nodes past the plane at the start are not
    counted; the die presses the shoulder at step 2 with no word."""
    points = np.array([[i, j, k] for k in range(3) for j in range(2) for i in range(3)], dtype=float)

    def at(i, j, k):
        return i + 3 * j + 6 * k
    cells = np.array([[at(i, 0, k), at(i + 1, 0, k), at(i + 1, 1, k), at(i, 1, k),
                       at(i, 0, k + 1), at(i + 1, 0, k + 1), at(i + 1, 1, k + 1), at(i, 1, k + 1)]
                      for i, k in ((0, 0), (1, 0), (0, 1))])
    surfaces = {"shoulder": np.array([[at(1, 0, 1), at(2, 0, 1), at(2, 1, 1), at(1, 1, 1)]]),
                "bottom": np.array([[at(i, 0, 0), at(i, 1, 0), at(i + 1, 1, 0), at(i + 1, 0, 0)] for i in (0, 1)])}
    write_gmsh(tmp_path / "l.msh", points, cells, "hex", surfaces)
    path = _write(tmp_path, "shoulder", 'name = "shoulder"\n[[bodies]]\nname = "l"\nmesh = { type = "file", path = '
                  '"l.msh" }\nmaterial = { youngs_modulus = 1000.0 }\n[[boundary]]\nsurface = "l.bottom"\ntype = '
                  '"displacement"\nux = 0.0\nuy = 0.0\nuz = 0.0\n[[die]]\nname = "punch"\npoint = [0.0, 0.0, '
                  '1.02]\nnormal = [0.0, 0.0, -1.0]\nmotion = [0.0, 0.0, -0.03]\nsurfaces = ["l.shoulder"]\n'
                  '[load]\nsteps = 2\n')
    lines = []
    run, summary = run_scene(path, tmp_path / "out", log=lines.append)
    run.destroy()
    assert summary["status"] == "ok" and not [line for line in lines if "warning" in line], lines
    force = summary["steps"][-1]["contact"]["die[0] punch"]["force_on_bodies"][2]
    assert summary["steps"][0]["contact"]["die[0] punch"]["active_rows"] == 0 and force < 0


def test_a_die_started_inside_its_body_says_so_not_its_normal():
    """configs/two_cubes_dies.toml's top die on the upper cube's whole skin, started 0.15 m (1.3 elements) into it:
    the sides' nodes past its plane were said to need the normal's sign checked; the normal is right, the die
    starts inside (hunt33_6). The answer is the top face's alone."""
    skin = '["upper.xmin","upper.xmax","upper.ymin","upper.ymax","upper.zmin","upper.zmax"]'
    scene = load_scene(CONFIGS / "two_cubes_dies.toml", [f"die.1.surfaces={skin}", "die.1.point=[0,0,1.85]"])
    lines = contact_plan(distribute_mesh(scene, MPI.COMM_WORLD), scene)
    assert any(line.startswith("warning: die[1] top: 36 node(s) of its surfaces lie on or past its plane with faces "
                               "turned away from it, and no row: the die starts 0.15 m = 1.3 element sizes into the "
                               "body") for line in lines), lines
    assert not any("sign of its normal" in line for line in lines), lines


def test_a_body_a_turned_die_leaves_free_names_the_die(tmp_path):
    """configs/two_cubes_dies.toml with its top die's normal the wrong way round: `qsc check` and the run stopped on
    "free rigid-body motion of upper ...: add a boundary condition", the die's warning never said (hunt33_5).
    check's error now names the die and its normal; the run says the warning before it stops. A body held
    otherwise: the run says it too, where it said nothing and its die's force was 0."""
    flip = ["die.1.normal=[0,0,1]"]
    scene = load_scene(CONFIGS / "two_cubes_dies.toml", flip)
    with pytest.raises(SceneError, match=r"free rigid-body motion of upper .*; and die\[1\] top: 100 node\(s\) .* "
                                         r"check the sign of its normal"):
        from qsc_petsc.check import check
        check(scene, MPI.COMM_WORLD)
    lines = []
    with pytest.raises(SceneError, match="free rigid-body motion of upper"):
        run_scene(CONFIGS / "two_cubes_dies.toml", tmp_path / "run", flip, log=lines.append)
    assert any(line.startswith("warning: die[1] top: 100 node(s)") for line in lines), lines


def test_a_die_that_fights_a_boundary_is_said(tmp_path):
    """A sticking die moving 0.01 m in x across a symmetry plane that holds ux on the nodes it drags: the die's
    rows fight the hold, and its force, 5e4 N, grows with the penalty; nothing said so (hunt31_2). Nor when the die
    starts apart and reaches them, or when a frictionless die moves onto a clamped face (hunt31_3). `qsc check` and
    the run warn, naming the die, the boundary and the component; not the quarter model, whose dies move along its
    symmetry planes, nor a support that lifts a sticking floor's edge off it (which was warned; hunt31_3)."""
    from conftest import CONFIGS

    from qsc_petsc.assembly import dirichlet_dofs

    def warnings(path):
        scene = load_scene(path)
        mesh = distribute_mesh(scene, MPI.COMM_WORLD)
        return [line for line in contact_plan(mesh, scene, None, dirichlet_dofs(mesh, scene))
                if line.startswith("warning")]
    sym = '[[boundary]]\nsurface = "blk.xmin"\ntype = "symmetry"\n' + FLOOR
    drag = ("warning: die[1] top (sticking, moving 0.01, 0, -0.005 m) sticks to and moves 5 node(s) whose ux "
            "boundary[0] (blk.xmin, symmetry) holds otherwise: the die's rows and the hold fight")
    for top in (1.0, 1.004):             # on the block from the start, or reaching it
        path = _write(tmp_path, f"drag{top}", STICK.format(support=sym, top=top, motion="[0.01, 0, -0.005]",
                                                            steps=1))
        assert [line[:len(drag)] for line in warnings(path)] == [drag]
    logged = []
    run_scene(path, tmp_path / "out", log=logged.append)
    assert any(line.startswith(drag[len("warning: "):], len("warning: ")) for line in logged), logged
    clamp = ('[[boundary]]\nsurface = "blk.xmin"\ntype = "displacement"\nux = 0.0\nuy = 0.0\nuz = 0.0\n'
             + FLOOR.replace("sticking", "frictionless"))
    onto = STICK.format(support=clamp, top=1.0, motion="[0, 0, -0.01]", steps=1).replace(
        'condition = "sticking"\n[load]', 'condition = "frictionless"\n[load]')
    said = "warning: die[1] top (frictionless, moving 0, 0, -0.01 m) moves onto 5 node(s) whose uz boundary[0] (blk."
    assert [line[:len(said)] for line in warnings(_write(tmp_path, "onto", onto))] == [said]
    lift = ('[[boundary]]\nsurface = "blk.xmin"\ntype = "displacement"\nuz = 0.05\n'
            '[[boundary]]\nsurface = "blk.zmax"\ntype = "pressure"\nvalue = 1.0\n' + FLOOR)
    lifted = STICK.format(support=lift, top=1.5, motion="[0, 0, 0]", steps=1)
    assert warnings(_write(tmp_path, "lift", lifted)) == []
    # an inclined sticking die dragging held nodes along its plane (was not warned; hunt31_5)
    side = '[[boundary]]\nsurface = "blk.xmax"\ntype = "symmetry"\n' + FLOOR
    slope = STICK.format(support=side, top=1.0, motion="[-0.01, 0, -0.01]", steps=1).replace(
        "normal = [0, 0, -1]", "normal = [-0.5, 0, -0.8660254037844386]").replace(
        "point = [0, 0, 1.0]", "point = [1, 0, 1]")
    said = ("warning: die[1] top (sticking, moving -0.01, 0, -0.01 m) sticks to and moves 5 node(s) whose ux "
            "boundary[0] (blk.xmax, symmetry)")
    assert [line[:len(said)] for line in warnings(_write(tmp_path, "slope", slope))] == [said]
    assert warnings(CONFIGS / "two_cubes_quarter.toml") == []


@pytest.mark.parametrize("steps, predictor", [(7, "extrapolate"), (4, "previous")])
def test_a_body_carried_onto_a_sliding_die_sticks_where_it_meets_it(tmp_path, steps, predictor):
    """A block lifted 0.1 m by its support onto a sticking die 0.05 m above that only slides 0.05 m sideways: the
    anchors counted the die's approach alone, so the top stuck where the increment began (Fx 8.0 N at 7 steps,
    10.1 at 4, 14.0 at 1, against 7.0; hunt31_3). The nodes' own path to the increment's start, extended, finds
    where they meet the die: the answer of the die that starts on the block and moves the rest of the way, with
    either predictor. In the first increment no path is known: a try in which nodes meet the die is halved until
    they meet it in one with a path (at 1 and 2 steps 14.0 N, no word; hunt31_5)."""
    lift = '[[boundary]]\nsurface = "blk.zmin"\ntype = "displacement"\nux = 0.0\nuy = 0.0\nuz = {uz}'
    scene = STICK.format(support=lift.format(uz=0.1), top=1.05, motion="[0.05, 0, 0]", steps=steps)
    _, summary = run_scene(_write(tmp_path, "lift", scene), tmp_path / "lift", [f"solver.predictor={predictor}"])
    ref = STICK.format(support=lift.format(uz=0.0), top=1.0, motion="[0.025, 0, -0.05]", steps=2)
    _, reference = run_scene(_write(tmp_path, "ref", ref), tmp_path / "ref")
    force = np.array(summary["steps"][-1]["contact"]["die[0] top"]["force_on_bodies"])
    assert force == pytest.approx(np.array(reference["steps"][-1]["contact"]["die[0] top"]["force_on_bodies"]),
                                  rel=1e-8, abs=1e-8)
    assert force[0] == pytest.approx(7.002, abs=1e-3)
    for few in (1, 2):
        logged = []
        _, first = run_scene(_write(tmp_path, "one", scene), tmp_path / f"few{few}", [f"load.steps={few}"],
                             log=logged.append)
        assert first["steps"][-1]["contact"]["die[0] top"]["force_on_bodies"] == pytest.approx(
            list(force), rel=1e-8, abs=1e-8)
        assert any("met a sticking die in the increment to load factor" in line and "halving it" in line
                   for line in logged), logged
        assert "STICKING_PATH_UNKNOWN" in [solve["snes_reason"] for solve in first["steps"][0]["solves"]]
        assert first["steps"][0]["cutbacks"] == 0
        # the halvings end once the path is known: the step's rest is one try (it was 63 more; hunt31_6)
        assert len(first["steps"][0]["solves"]) <= 4, first["steps"][0]["solves"]
    # met within 1/128 of the only step: past the 6 halvings, where the die's approach alone places the nodes,
    # the log says so (it read the step's last try, which had a path: never; hunt31_6)
    tiny = STICK.format(support=lift.format(uz=0.1), top=1.00078125, motion="[0.05, 0, 0]", steps=1)
    logged = []
    _, summary = run_scene(_write(tmp_path, "tiny", tiny), tmp_path / "tiny", log=logged.append)
    assert summary["status"] == "ok"
    assert any("met a sticking die within the first 1/64 of the run's first increment" in line for line in logged)


CARRIED = block_and_cube(
    "carried", [2.0, 1.0, 0.5], [10, 5, 3], [4, 4, 4],
    '[[boundary]]\nsurface = "lower.zmin"\ntype = "displacement"\nux = 0.0\nuy = 0.0\nuz = 0.0\n[[boundary]]\n'
    'surface = "upper.ymin"\ntype = "symmetry"\n[[contact]]\nslave = "upper.zmin"\nmaster = "lower.zmax"\n'
    'formulation = "quasi_symmetric"\n'
    + die("push", [0.25, 0.0, 0.0], [1.0, 0.0, 0.0], ["upper.xmin"], [1.0, 0.0, 0.0])
    + die("front", [0.75, 0.0, 0.0], [-1.0, 0.0, 0.0], ["upper.xmax"], [0.9975, 0.0, 0.0])
    + die("top", [0.0, 0.0, 1.0], [0.0, 0.0, -1.0], ["upper.zmax"], [0.0, 0.0, -0.005]), lower_modulus=1e7)


def test_a_die_that_moves_away_keeps_the_nodes_it_holds(tmp_path):
    """A block carried 1 m between a pushing die and one in front moving away along its normal (0.5 % squeeze): the
    front die's reach was measured from where it stands at the increment's end, so every node it held dropped its
    row, and the solve failed OUT_OF_REACH saying they were out of reach at the increment's start (cutbacks, or
    exit 3; hunt35_1). Its reach covers where it stands at the start too: 2 increments, no cutback, the squeeze's
    force on both dies."""
    path = tmp_path / "carried.toml"
    path.write_text(CARRIED)
    run, summary = run_scene(path, tmp_path / "out", ["load.steps=2", "solver.max_cutbacks=0"])
    run.destroy()
    assert summary["status"] == "ok"
    last = summary["steps"][-1]["contact"]
    push, front = last["die[0] push"]["force_on_bodies"][0], last["die[1] front"]["force_on_bodies"][0]
    assert push > 1.0 and front == pytest.approx(-push, rel=1e-6)


def test_a_body_the_earlier_steps_left_free_is_a_failed_solve_not_bad_input():
    """A block pushed by one die along frictionless supports slid clear of them at step 17 of 20; step 18's check
    that the rows within reach hold every body stopped the run with "add a boundary condition", exit 2, as if the
    scene were wrong (hunt35_1). After the first step it is the earlier steps' outcome: a failed solve (exit 3)."""
    from qsc_petsc.errors import ConvergenceError
    assert isinstance(solver.free_motion_error(1, "upper (translation x)"), SceneError)
    late = solver.free_motion_error(18, "upper (translation x)")
    assert isinstance(late, ConvergenceError) and "the earlier steps moved it out of the reach" in str(late)


def test_bodies_sticking_dies_hold_without_tangential_force_are_not_loose(tmp_path):
    """A block and a plate of nu = 0 between two sticking dies: the dies' tangential rows carry no force (no Poisson
    expansion to hold), and the bodies were said loose, "one of many", though the dies hold them where they are
    (hunt35_4; the uniaxial answer to 1e-11). A tangential row holds wherever its normal row presses."""
    body = ('[[bodies]]\nname = "{}"\nmesh = {{ type = "box", origin = [0.0, 0.0, {}], size = [1.0, 1.0, {}], '
            'cells = {} }}\nmaterial = {{ youngs_modulus = 1000.0, poissons_ratio = 0.0 }}\n')
    path = tmp_path / "sandwich.toml"
    path.write_text('name = "sandwich"\n' + body.format("block", 0.0, 0.5, [4, 4, 3])
                    + body.format("plate", 0.5, 0.02, [10, 10, 1])
                    + die("bottom", [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], ["block.zmin"], condition="sticking")
                    + die("top", [0.0, 0.0, 0.52], [0.0, 0.0, -1.0], ["plate.zmax"], [0.0, 0.0, -0.0052], "sticking")
                    + '[[contact]]\nslave = "plate.zmin"\nmaster = "block.zmax"\n')
    lines = []
    run, summary = run_scene(path, tmp_path / "out", log=lines.append)
    run.destroy()
    assert summary["status"] == "ok" and "loose" not in summary["steps"][-1], lines
    assert not [line for line in lines if "warning" in line], lines
