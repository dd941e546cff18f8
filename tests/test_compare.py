"""compare.py: run folders against a reference on other meshes (other refinement, hex against tet).

Manufactured result folders are written with the real ResultWriter (on COMM_SELF), so the tests
read the layout output.py writes; one test also compares real runs of the patch test.
"""

import json
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import CONFIGS, run_scene
from mpi4py import MPI

from qsc_petsc import compare
from qsc_petsc.errors import QscError
from qsc_petsc.meshgen import box_mesh
from qsc_petsc.output import ResultWriter

E, NU = 200.0, 0.25          # Pa, -


def _linear(x):
    A = np.array([[0.3, -0.1, 0.2], [0.05, 0.4, -0.2], [0.1, 0.2, -0.3]])
    return x @ A.T + np.array([0.01, -0.02, 0.03])


def _quadratic(x):
    return np.column_stack([x[:, 0] ** 2 + x[:, 1] * x[:, 2], 0.5 * x[:, 1] ** 2 - x[:, 0] * x[:, 2],
                            x[:, 2] ** 2 + 0.3 * x[:, 0] * x[:, 1]])


def _bodies(specs):
    """One mesh of several box bodies: specs = [(origin, size, cells, element)]; returns points, cells, body."""
    pts, cells, body = [], [], []
    offset = 0
    for b, (origin, size, n, element) in enumerate(specs):
        m = box_mesh(origin, size, n, element)
        pts.append(m.points)
        cells.append(m.cells + offset)
        body.append(np.full(len(m.cells), b))
        offset += len(m.points)
    return np.vstack(pts), np.vstack(cells), np.concatenate(body)


def write_result(folder, specs, field, names=("a", "b"), point_extra=None, summary_steps=None):
    """A result folder holding field(points) as the displacement of load step 1."""
    points, cells, body = _bodies(specs)
    folder.mkdir(parents=True, exist_ok=True)
    nv, nc = len(points), len(cells)
    mesh = SimpleNamespace(comm=MPI.COMM_SELF, vert_orig=np.arange(nv), coords=points, owned=np.ones(nv, bool),
                           cells=cells, cell_orig=np.arange(nc), n_vertices=nv, n_cells=nc,
                           cell_type="hex" if cells.shape[1] == 8 else "tet")
    writer = ResultWriter(mesh, folder)
    point = {"displacement": field(points), **(point_extra(points) if point_extra else {})}
    writer.write_step(1, 1.0, point, {"body": body[:, None].astype(float)})
    lines = []
    for name in names[:len(specs)]:
        lines += ["[[bodies]]", f'name = "{name}"', f"material = {{ youngs_modulus = {E}, poissons_ratio = {NU} }}", ""]
    (folder / "scene.resolved.toml").write_text("\n".join(lines))
    (folder / "summary.json").write_text(json.dumps({"status": "ok", "steps": summary_steps or [{"step": 1}]}))
    return folder


def test_identical_folders_give_zero(tmp_path):
    spec = [((0, 0, 0), (1, 1, 1), (3, 2, 2), "hex")]
    a = write_result(tmp_path / "a", spec, _quadratic)
    e = compare.errors(a, a)
    assert e["displacement_l2"] == 0.0 and e["energy"] == 0.0
    assert e["outside_points"] == 0


@pytest.mark.parametrize("run_el, ref_el", [("hex", "tet"), ("tet", "hex"), ("hex", "hex")])
def test_linear_field_exact_on_other_mesh(tmp_path, run_el, ref_el):
    """Q1 and P1 reproduce a linear field: the run differs from the reference only by round-off."""
    # two bodies sharing the plane z = 0.5: interface points must be found in their own body
    run = write_result(tmp_path / "run", [((0, 0, 0), (1, 1, 0.5), (3, 2, 2), run_el),
                                          ((0, 0, 0.5), (1, 1, 0.5), (2, 3, 1), run_el)], _linear)
    ref = write_result(tmp_path / "ref", [((0, 0, 0), (1, 1, 0.5), (5, 4, 3), ref_el),
                                          ((0, 0, 0.5), (1, 1, 0.5), (4, 5, 2), ref_el)], _linear)
    e = compare.errors(run, ref)
    assert e["displacement_l2"] < 1e-12
    assert e["energy"] < 1e-12
    assert e["outside_points"] == 0
    assert e["strain_energy"] == pytest.approx(e["strain_energy_reference"], rel=1e-12)


def test_interface_points_use_their_own_body(tmp_path):
    """A field that jumps across the interface: located in the other body, interface points would see the jump."""
    spec_run = [((0, 0, 0), (1, 1, 0.5), (2, 2, 2), "hex"), ((0, 0, 0.5), (1, 1, 0.5), (3, 3, 2), "hex")]
    spec_ref = [((0, 0, 0), (1, 1, 0.5), (3, 3, 3), "tet"), ((0, 0, 0.5), (1, 1, 0.5), (2, 2, 2), "tet")]

    def field_by_body(specs):
        _, cells, body = _bodies(specs)

        def f(points):
            pb = np.zeros(len(points), int)
            pb[cells] = body[:, None]
            return _linear(points) + pb[:, None] * np.ones((1, 3))     # body 1 is shifted by 1 m
        return f
    run = write_result(tmp_path / "run", spec_run, field_by_body(spec_run))
    ref = write_result(tmp_path / "ref", spec_ref, field_by_body(spec_ref))
    assert compare.errors(run, ref)["displacement_l2"] < 1e-12


def test_quadratic_field_converges_at_order_two(tmp_path):
    """Tet interpolants of a quadratic field against a fine hex reference: L2 slope 2, energy slope 1 (fitted)."""
    ref = write_result(tmp_path / "ref", [((0, 0, 0), (1, 1, 1), (16, 16, 16), "hex")], _quadratic)
    hs, l2, energy = [], [], []
    for n in (2, 4, 8):
        run = write_result(tmp_path / f"run{n}", [((0, 0, 0), (1, 1, 1), (n, n, n), "tet")], _quadratic)
        e = compare.errors(run, ref)
        hs.append(1.0 / n)
        l2.append(e["displacement_l2"])
        energy.append(e["energy"])
    slope = np.polyfit(np.log(hs), np.log(l2), 1)[0]
    assert 1.9 < slope < 2.2, (l2, slope)          # measured 2.11: the reference's own error is 1/4 of the finest
    slope = np.polyfit(np.log(hs), np.log(energy), 1)[0]
    assert 0.9 < slope < 1.2, (energy, slope)      # measured 1.10


def test_points_outside_the_reference_are_clamped_or_refused(tmp_path):
    """A run slightly larger than the reference is compared at the nearest reference points; a far one is refused."""
    ref = write_result(tmp_path / "ref", [((0, 0, 0), (1, 1, 1), (4, 4, 4), "hex")], _linear)
    near = write_result(tmp_path / "near", [((0, 0, 0), (1.1, 1, 1), (4, 4, 4), "hex")], _linear)
    e = compare.errors(near, ref)
    assert e["outside_points"] > 0 and 0 < e["max_outside_distance"] <= 0.1
    far = write_result(tmp_path / "far", [((3, 0, 0), (1, 1, 1), (2, 2, 2), "hex")], _linear)
    with pytest.raises(QscError, match="not within a cell of the same body"):
        compare.errors(far, ref)


def test_traction_and_contact_errors(tmp_path):
    """Traction sampled at the run's contact nodes (status >= 0); force and penetration from the summaries."""
    def contact_fields(scale):
        def f(points):
            on = np.isclose(points[:, 2], 0.5)
            t = np.where(on, scale * (1.0 + points[:, 0]), 0.0)[:, None]
            status = np.where(on, 1.0, -1.0)[:, None]
            return {"contact_traction": t, "contact_traction_unused": t, "contact_status": status}
        return f

    def steps(force, pen):
        return [{"step": 1, "contact": {"contact[0] a.zmax / b.zmin": {
            "force_on_slave": [0.0, 0.0, force], "max_penetration_slave": pen, "max_penetration_master": pen / 2}}}]
    spec = [((0, 0, 0), (1, 1, 0.5), (2, 2, 1), "hex")]
    ref = write_result(tmp_path / "ref", [((0, 0, 0), (1, 1, 0.5), (4, 4, 2), "tet")], _linear,
                       point_extra=contact_fields(1.0), summary_steps=steps(2.0, 1e-3))
    run = write_result(tmp_path / "run", spec, _linear, point_extra=contact_fields(1.1),
                       summary_steps=steps(2.2, 1.5e-3))
    e = compare.errors(run, ref)
    assert e["traction"] == pytest.approx(0.1, rel=1e-12)       # linear traction: interpolation is exact
    assert e["contact"]["contact[0]"]["force"] == pytest.approx(0.1)
    assert e["max_penetration"] == pytest.approx(0.5)
    assert e["force"] == pytest.approx(0.1)


def test_load_result_steps_and_bad_folders(tmp_path):
    a = write_result(tmp_path / "a", [((0, 0, 0), (1, 1, 1), (1, 1, 1), "hex")], _linear)
    assert compare.load_result(a).step == 1
    with pytest.raises(QscError, match="no load step 2"):
        compare.load_result(a, step=2)
    with pytest.raises(QscError, match="no solution.h5"):
        compare.load_result(tmp_path)


def test_real_runs_of_the_patch_test(tmp_path):
    """Real output folders: a run against itself is exact; a coarser upper mesh gives small, finite errors."""
    small = ["bodies.0.mesh.cells=[2,2,1]", "bodies.1.mesh.cells=[3,3,1]", "contact.0.formulation=two_pass"]
    run_scene(CONFIGS / "patch_test.toml", tmp_path / "a", small)[0].destroy()
    run_scene(CONFIGS / "patch_test.toml", tmp_path / "b", small[:1] + ["bodies.1.mesh.cells=[2,2,1]"]
              + small[2:])[0].destroy()
    same = compare.errors(tmp_path / "a", tmp_path / "a")
    assert same["displacement_l2"] == 0 and same["energy"] == 0 and same["traction"] == 0
    assert same["force"] == 0 and same["max_penetration"] == 0
    e = compare.errors(tmp_path / "b", tmp_path / "a")
    # the patch test's exact solution is uniaxial: both runs are close to it, hence to each other
    assert 0 < e["displacement_l2"] < 1e-2 and 0 < e["energy"] < 0.1
    assert e["force"] < 1e-6 and e["traction"] is not None


def test_a_pair_that_faces_nothing_has_no_penetration_error():
    """A pair or die whose nodes face nothing has max penetrations null in summary.json (no longer -Infinity,
    session 25): the comparison takes them as absent instead of failing on them."""
    record = {"contact": {"contact[0] a.s / b.s": {"force_on_slave": [0.0, 0.0, 0.0], "max_penetration_slave": None,
                                                   "max_penetration_master": 1e-3},
                          "contact[1] c.s / d.s": {"force_on_slave": [0.0, 0.0, 0.0], "max_penetration_slave": None,
                                                   "max_penetration_master": None},
                          "die[0] floor": {"force_on_bodies": [0.0, 0.0, 2.0], "max_penetration": None}}}

    class Step:
        def step_record(self):
            return record

    out = compare.contact_errors(Step(), Step())
    assert out["contact[0]"]["max_penetration"] == 0.0 and out["contact[0]"]["max_penetration_value"] == 1e-3
    assert out["contact[1]"]["max_penetration"] is None and out["die[0]"]["max_penetration"] is None
    assert out["die[0]"]["force"] == 0.0


def test_a_pair_with_slave_and_master_swapped_compares_the_same_force():
    """The pair's force is on its slave: with the roles swapped against the reference it is the reference's force
    on the other body, reversed. compare read it as a 200 % force error on the same answer (hunt32_3)."""
    def step(key, fz):
        record = {"contact": {key: {"force_on_slave": [0.0, 0.0, fz], "max_penetration_slave": 1e-3,
                                    "max_penetration_master": None}}}
        return type("Step", (), {"step_record": lambda self: record})()

    swapped = compare.contact_errors(step("contact[0] lower.zmax / upper.zmin", 1.0 + 1e-3),
                                     step("contact[0] upper.zmin / lower.zmax", -1.0))
    assert swapped["contact[0]"]["force"] == pytest.approx(1e-3)
    same = compare.contact_errors(step("contact[0] upper.zmin / lower.zmax", 1.0 + 1e-3),
                                  step("contact[0] upper.zmin / lower.zmax", 1.0))
    assert same["contact[0]"]["force"] == pytest.approx(1e-3)
    other = compare.contact_errors(step("contact[0] a.s / b.s", 1.0), step("contact[0] c.s / d.s", -1.0))
    assert other["contact[0]"]["force"] == pytest.approx(2.0)      # another pair: no swap to undo


def test_mean_dilatation_runs_compare_in_their_own_energy(tmp_path):
    """A mean-dilatation body's energy takes each cell's mean dilatation as its volumetric strain, as its stiffness
    does: compare weighted the pointwise one by a nearly incompressible body's bulk modulus, and read a run 0.06 %
    off as 78 % off in energy, its strain energy 16x the run's (hunt33_4). A block clamped at its base under an
    uneven pressure, nu 0.4999: the energy error shrinks with h, and the strain energy is 1/2 u^T K u."""
    scene = tmp_path / "block.toml"
    scene.write_text('''name = "block"
[[bodies]]
name = "block"
mesh = { type = "box", origin = [0.0, 0.0, 0.0], size = [1.0, 1.0, 1.0], cells = [2, 2, 2] }
material = { youngs_modulus = 1000.0, poissons_ratio = 0.4999, volumetric = "mean_dilatation" }
[[boundary]]
surface = "block.zmin"
type = "displacement"
ux = 0.0
uy = 0.0
uz = 0.0
[[boundary]]
surface = "block.zmax"
type = "pressure"
value = "1 + x"
[petsc]
ksp_type = "preonly"
pc_type = "lu"
''')
    for n in (2, 4, 8):
        run_scene(scene, tmp_path / str(n), [f"bodies.0.mesh.cells=[{n},{n},{n}]"])[0].destroy()
    coarse, fine = (compare.errors(tmp_path / str(n), tmp_path / "8") for n in (2, 4))
    assert coarse["energy"] < 0.5 and fine["energy"] < 0.7 * coarse["energy"]
    assert fine["displacement_l2"] < 0.5 * coarse["displacement_l2"]
    result = compare.load_result(tmp_path / "2")
    from qsc_petsc import elasticity
    lm, mu = result.lame()
    xe = result.points[result.cells]
    ue = result.point_data["displacement"][result.cells].reshape(len(xe), -1)
    K = elasticity.stiffness("hex", xe, lm, mu, kappa=lm + 2 * mu / 3)
    assert compare.strain_energy(result) == pytest.approx(0.5 * np.einsum("ma,mab,mb->", ue, K, ue), rel=1e-10)
