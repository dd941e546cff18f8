"""Model only what a scene requires (issue 5, part 4): the quarter two-cube model with symmetry planes gives the
full model's reactions, and `qsc check` says what each will model; a mirror-symmetric scene keeps its symmetry."""

import pytest
from conftest import CONFIGS, run_scene

FULL = ["bodies.0.mesh.cells=[4,4,4]", "bodies.1.mesh.cells=[6,6,6]"]
QUARTER = ["bodies.0.mesh.cells=[2,2,4]", "bodies.1.mesh.cells=[3,3,6]"]


def forces(comm, tmp, name, sets):
    """z forces [N] of the two dies on the bodies and the pair's total normal contact force, last load step."""
    run, summary = run_scene(CONFIGS / name, tmp, sets + ["output.xdmf=false"], comm)
    run.destroy()
    assert summary["status"] == "ok"
    step = summary["steps"][-1]
    contact = step["contact"]
    pair = next(v for k, v in contact.items() if k.startswith("contact[0]"))
    return (contact["die[0] bottom"]["force_on_bodies"][2], contact["die[1] top"]["force_on_bodies"][2],
            pair["total_normal_force"])


@pytest.mark.parametrize("formulation", ["master_slave", "two_pass", "quasi_symmetric"])
def test_quarter_model_gives_the_full_reactions(comm, mpi_tmp, formulation):
    """The quarter [0.5, 1]^2 of the two cubes with symmetry planes x = 0.5 and y = 0.5 shall give 1/4 of the
    full model's die reactions and contact force, to 1e-6 relative, for every formulation."""
    sets = [f"contact.0.formulation={formulation}"]
    full = forces(comm, mpi_tmp / "full", "two_cubes_full.toml", FULL + sets)
    quarter = forces(comm, mpi_tmp / "quarter", "two_cubes_quarter.toml", QUARTER + sets)
    assert full[1] < 0.0 < full[0]                 # the top die pushes down, the bottom one up
    for f, q in zip(full, quarter):
        assert 4.0 * q == pytest.approx(f, rel=1e-6)


def test_check_reports_what_will_be_modelled(comm):
    """`qsc check` on the quarter scene shall report the bodies, the dofs, the four symmetry boundaries and the
    candidate contact rows of the pair and the dies, a quarter of the full model's dofs or fewer."""
    from qsc_petsc.check import check
    from qsc_petsc.scene import load_scene
    text = {}
    for name in ("full", "quarter"):
        text[name] = check(load_scene(CONFIGS / f"two_cubes_{name}.toml"), comm)
    if comm.rank == 0:
        quarter = text["quarter"]
        assert "bodies: lower (128 cells), upper (432 cells)" in quarter
        assert "mesh: 560 hex cells, 862 vertices, 2586 dofs" in quarter
        assert "boundary conditions: 4" in quarter
        assert "contact[0]: upper.zmin (slave) / lower.zmax (master), quasi_symmetric" in quarter
        assert "49 candidate rows at the first search" in quarter      # 7 x 7 slave nodes of the quarter's 6 x 6 faces
        assert "169 candidate rows at the first search" in text["full"]   # 13 x 13 of the full 12 x 12
        assert "8778 dofs" in text["full"] and 4 * 2586 < 1.2 * 8778


@pytest.mark.parametrize("name, cells, condition, area", [("two_cubes_full.toml", FULL, "sticking", 1.0),
                                                         ("two_cubes_quarter.toml", QUARTER, "frictionless", 0.25)])
def test_die_contact_area_is_the_pressed_face(comm, mpi_tmp, name, cells, condition, area):
    """A die pressing a whole face reports that face's area, sticking or not (a sticking die's two tangential
    rows per node once counted the node's area again: 3 m^2 for a unit face). The quarter's symmetry planes
    hold what frictionless dies leave free."""
    sets = cells + ["output.xdmf=false"] + [f"die.{i}.condition={condition}" for i in (0, 1)]
    run, summary = run_scene(CONFIGS / name, mpi_tmp, sets, comm)
    run.destroy()
    assert summary["status"] == "ok"
    contact = summary["steps"][-1]["contact"]
    for die in ("die[0] bottom", "die[1] top"):
        assert contact[die]["contact_area"] == pytest.approx(area, rel=1e-12)


@pytest.mark.parametrize("integration", ["gauss", "nodal"])
def test_a_centred_punch_is_not_pushed_sideways(tmp_path, integration):
    """configs/flat_punch.toml is mirror-symmetric about x = 0.5 and y = 0.5: its contact force shall have no
    sideways part beyond round-off. The punch's Gauss points on its central lines lie on the block's edges,
    where the tie rule had given each to one face and its normal: Fx = Fy = 9.0e-5 of the normal force (Gauss,
    master_slave, these meshes); now shared between the faces (search.closest_faces)."""
    sets = ["bodies.0.mesh.cells=[8,8,4]", "bodies.1.mesh.cells=[5,5,5]", "output.xdmf=false",
            "contact.0.formulation=master_slave", f"contact.0.integration={integration}"]
    run, summary = run_scene(CONFIGS / "flat_punch.toml", tmp_path / "out", sets)
    run.destroy()
    assert summary["status"] == "ok"
    force = next(iter(summary["steps"][-1]["contact"].values()))["force_on_slave"]
    assert abs(force[0]) < 1e-12 * force[2] and abs(force[1]) < 1e-12 * force[2]
