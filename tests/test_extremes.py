"""Stability at the extremes (issue 5, part 3): every case converges to the known answer or stops with a
clear diagnostic; never NaN, never a silent wrong answer. Tiny patch-test scenes, MUMPS LU, serial.

The measures come from scripts/stability.py, which writes the same cases' numbers into docs/stability.md.
"""

import sys

import numpy as np
import pytest
from conftest import CONFIGS, ROOT, run_scene

sys.path.insert(0, str(ROOT / "scripts"))
import stability as S

from qsc_petsc import assembly, sparsity
from qsc_petsc.contact.penalty import row_response
from qsc_petsc.elasticity import RIGID_MODES as MODES
from qsc_petsc.restraint import free_motions

FORMULATIONS = list(S.FORMULATIONS)


def ok(res):
    """The run converged and every displacement and stress is finite."""
    assert res["status"] == "ok", res.get("message")
    assert res["finite"]
    return res


# ---------------------------------------------------------------- penalty

def test_runs_out_of_the_models_range_say_so(tmp_path):
    """Runs that ended "ok" with no word (hunt33_3): a penalty so soft that the bodies overlap half an element (alpha 1,
    p = 0.5 E; also 50 % strain, past the linear elasticity's range), and one so stiff that p / eps_n lies within
    10 eps |x| (alpha 1e10, p = 1e-6 E), whose reported penetrations are round-off (they read -2.5 to -6.2 p / eps_n).
    The patch test as it stands says none of it."""
    deep = "penetrate the other surface by up to 0.0714 m = 0.5 element sizes"
    cases = {"soft": (["contact.0.penalty=1", "boundary.5.value=500"], [deep, "strains reach 0.5"]),
             "stiff": (["contact.0.penalty=1e10", "boundary.5.value=1e-3"], ["within 10 x the coordinates' precision"]),
             "sound": ([], [])}
    for name, (sets, expected) in cases.items():
        lines = []
        run, summary = run_scene(CONFIGS / "patch_test.toml", tmp_path / name, sets, log=lines.append)
        run.destroy()
        assert summary["status"] == "ok"
        warnings = [line for line in lines if "warning" in line]
        assert len(warnings) == len(expected) and all(any(e in w for w in warnings) for e in expected), lines


def test_loads_at_round_off_say_so(tmp_path):
    """Loads that strain the bodies ~1e-12 or less are solved to round-off (the Newton test's floor, the gaps' eps
    |x|), not to the tolerance: the patch pair's two_pass contact force read 5e-4 off at p = 1e-9 and 30x at 1e-12
    with no word, and quasi_symmetric's round-off depths at 1e-12 read as a soft penalty (hunt33_3). So does a
    block alone under a pressure of 1e-12. A die that travels just to touch its block leaves |u| round-off under a
    load that is not: no word there."""
    block = ('name = "{name}"\n[[bodies]]\nname = "b"\nmesh = {{ type = "box", origin = [0.0, 0.0, 0.0], size = '
             '[1.0, 1.0, 1.0], cells = [3, 3, 3] }}\nmaterial = {{ youngs_modulus = 1000.0 }}\n[[boundary]]\n'
             'surface = "b.zmin"\ntype = "displacement"\nux = 0.0\nuy = 0.0\nuz = 0.0\n{load}')
    tiny, touch = tmp_path / "tiny.toml", tmp_path / "touch.toml"
    tiny.write_text(block.format(name="tiny", load='[[boundary]]\nsurface = "b.zmax"\ntype = "pressure"\n'
                                                   'value = 1e-12\n'))
    touch.write_text(block.format(name="touch", load='[[die]]\nname = "top"\npoint = [0.0, 0.0, 1.1]\nnormal = '
                                                    '[0.0, 0.0, -1.0]\nmotion = [0.0, 0.0, -0.1]\nsurfaces = '
                                                    '["b.zmax"]\n[load]\nsteps = 2\n'))
    said = "the loads strain the bodies too little for their answer"
    cases = {"two_pass": (CONFIGS / "patch_test.toml", ["contact.0.formulation=two_pass", "boundary.5.value=1e-9"]),
             "quasi_symmetric": (CONFIGS / "patch_test.toml", ["boundary.5.value=1e-12"]),
             "block": (tiny, []), "touch": (touch, [])}
    for name, (scene, sets) in cases.items():
        lines = []
        run, summary = run_scene(scene, tmp_path / name, sets, log=lines.append)
        run.destroy()
        warnings = [line for line in lines if "warning" in line]
        assert summary["status"] == "ok", lines
        assert warnings == ([] if name == "touch" else [w for w in warnings if said in w]) and \
            len(warnings) == (name != "touch"), lines


def test_warnings_do_not_depend_on_the_length_unit_or_travel(tmp_path):
    """The loose test read row pressures against a force floor in N: the patch test in lengths x 1e6 (all 64 rows
    carrying the load) said "upper (translation z) ... one of many" (hunt34_1). The soft-penalty test read depths
    against the bodies' largest displacement: the sliding cubes at alpha 0.3 (18 % low) were silent, the 0.3 m
    slide hiding the depth (hunt34_2); against their deformation they say so."""
    big = ["bodies.0.mesh.size=[1e6,1e6,5e5]", "bodies.1.mesh.origin=[0,0,5e5]", "bodies.1.mesh.size=[1e6,1e6,5e5]"]
    for name, (scene, sets, expected) in {
            "big": (CONFIGS / "patch_test.toml", big, []),
            "slid": (CONFIGS / "sliding_cubes.toml", ["contact.0.penalty=0.3"], ["contact[0]: pressed nodes penetrate"]),
    }.items():
        lines = []
        run, summary = run_scene(scene, tmp_path / name, sets, log=lines.append)
        run.destroy()
        warnings = [line for line in lines if "warning" in line]
        assert summary["status"] == "ok" and len(warnings) == len(expected), lines
        assert all(any(e in w for w in warnings) for e in expected) and "loose" not in summary["steps"][-1], lines


def test_soft_dies_and_turned_bodies_say_so(tmp_path):
    """Runs that ended "ok" with no word (hunt33_6): dies at alpha 0.1 under configs/flat_punch.toml (the punch's
    force 45 % low: its nodes sank 0.37 and 0.52 of the bodies' largest displacement), the punch's pair at alpha 1
    (11 % low, 0.18 of it, 0.012 element sizes), a cantilever turned 0.45 rad (its linear answer stretched 5 %,
    its strains 0.004), and a short one bent to 7 % strain at its root, read 3.4 % at its cells' centroids."""
    coarse = ["bodies.0.mesh.cells=[8,8,4]", "bodies.1.mesh.cells=[6,6,6]"]
    beam = tmp_path / "beam.toml"
    beam.write_text('name = "beam"\n[[bodies]]\nname = "b"\nmesh = { type = "box", origin = [0.0, 0.0, 0.0], '
                    'size = [10.0, 0.2, 0.2], cells = [50, 2, 2] }\nmaterial = { youngs_modulus = 1000.0 }\n'
                    '[[boundary]]\nsurface = "b.xmin"\ntype = "displacement"\nux = 0.0\nuy = 0.0\nuz = 0.0\n'
                    '[[boundary]]\nsurface = "b.xmax"\ntype = "displacement"\nuz = -3.0\n')
    cases = {"dies": (CONFIGS / "flat_punch.toml", coarse + ["die.0.penalty=0.1", "die.1.penalty=0.1"],
                      ["die[0]: pressed nodes penetrate the die", "die[1]: pressed nodes penetrate the die"]),
             "pair": (CONFIGS / "flat_punch.toml", coarse + ["contact.0.penalty=1"],
                      ["contact[0]: pressed nodes penetrate the other surface"]),
             "sound": (CONFIGS / "flat_punch.toml", coarse, []),
             "beam": (beam, [], ["rotations reach 0.45 rad"]),
             # bent two cells thick, its centroids at a quarter of its depth read half its fibres' strain: 0.034, no
             # word, against 0.061-0.070 at the root (hunt33_6); its edges' stretch reads the fibres'
             "bent": (beam, ["bodies.0.mesh.size=[2,0.4,0.4]", "bodies.0.mesh.cells=[20,2,2]", "boundary.1.uz=-0.5"],
                      ["strains reach 0.07 (a cell near x, y, z = 0.15, 0.1, 0.1)"])}
    for name, (scene, sets, expected) in cases.items():
        lines = []
        run, summary = run_scene(scene, tmp_path / name, sets, log=lines.append)
        run.destroy()
        warnings = [line for line in lines if "warning" in line]
        assert summary["status"] == "ok" and len(warnings) == len(expected), lines
        assert all(any(e in w for w in warnings) for e in expected), lines


def test_nodes_the_rows_do_not_hold_are_not_sent_to_a_stiffer_penalty(tmp_path):
    """quasi_symmetric's nodal rows with the coarse surface as the slave at a 10x mesh ratio (formulation.md's
    range): the fine master's nodes sank 1e-3 m, 2e5 times the pressure's p / eps_n, the stresses 3-4x off, with no
    word (hunt32_2), then with the soft-penalty warning's advice to raise the penalty, which does not help. They are
    said as not held, with the cures that hold them; with the finer surface as the slave nothing is said."""
    nodal = ["contact.0.integration=nodal", "bodies.0.mesh.cells=[2,2,2]", "bodies.1.mesh.cells=[20,20,2]"]
    coarse_slave = ['contact.0.slave="lower.zmax"', 'contact.0.master="upper.zmin"']
    for name, (sets, expected) in {
            "coarse slave": (nodal + coarse_slave, ("more than 100 times the penetration of their own contact "
                             "pressure (p / eps_n): no penalty explains that")),
            "stiffer": (nodal + coarse_slave + ["contact.0.penalty=1e6"], "no penalty explains that"),
            "fine slave": (nodal, None)}.items():
        lines = []
        run, summary = run_scene(CONFIGS / "patch_test.toml", tmp_path / name.replace(" ", "_"), sets,
                                 log=lines.append)
        run.destroy()
        warnings = [line for line in lines if "warning" in line]
        assert summary["status"] == "ok" and len(warnings) == (expected is not None), (name, lines)
        if expected:
            assert expected in warnings[0] and warnings[0].endswith(
                'make the finer surface the slave, or set weight = "finer", or use two_pass or integration = '
                '"segment"') and "raise contact[0].penalty" not in warnings[0], warnings


def test_augmented_lagrangian_stalled_on_round_off_says_lower_the_penalty(tmp_path):
    """two_pass's augmented Lagrangian at alpha 1e8 on the patch test: its over-constrained rows' updates stand at
    ~26x their round-off estimate (past AUGMENTED_ROUND_OFF), a halved increment alike, and the run stops; the error
    sent the user to more updates or a stiffer penalty, which did nothing or worse (hunt33_3). It says to lower the
    penalty, and alpha 1e4 converges."""
    from qsc_petsc.errors import ConvergenceError
    base = ["contact.0.formulation=two_pass", "contact.0.enforcement=augmented_lagrangian"]
    with pytest.raises(ConvergenceError, match=r"x their round-off .*: lower contact\[0\]\.penalty"):
        run_scene(CONFIGS / "patch_test.toml", tmp_path / "stiff", base + ["contact.0.penalty=1e8"])
    run, summary = run_scene(CONFIGS / "patch_test.toml", tmp_path / "soft", base + ["contact.0.penalty=1e4"])
    run.destroy()
    assert summary["status"] == "ok"


@pytest.mark.parametrize("alpha", S.ALPHAS)
def test_penalty_from_1_to_1e10(alpha):
    """For alpha 1e0 to 1e10 the matching patch test shall give sigma_zz = -p to 1e-8, the row penetration
    p/eps_n (to 1e-6, 1e-3 at 1e10 where it is 4e-14 m on displacements of 1e-3 m) and the contact force pA."""
    res = ok(S.measure(S.scene(sets=S.cells(2, 2) + [f"contact.0.penalty={alpha}"])))
    extreme = float(alpha) > 1e8
    assert res["stress_error"] <= 1e-8
    assert abs(S.penetration_ratio(res) - 1.0) <= (1e-3 if extreme else 1e-6)
    assert S.force_error(res) <= (1e-6 if extreme else 1e-8)
    assert res["newton"] <= 3


def test_a_solve_that_stops_on_its_round_off_says_how_far_off_it_stands(tmp_path):
    """two_pass with Gauss rows at alpha 1e10 on the patch test (4/7 cells): the Newton steps stop moving u
    (below stol x |u|) while the residual stands at 2e-2 of its force scale, the rows' round-off, and the contact
    force is 1.8 % over the load. It ended "converged" by that step test with no word (hunt29_1); the summary
    now gives where it stopped (round_off_floor) and the log a warning naming the stiffest rows. At alpha 1e8 the
    same steps stop at 1e-7 of the scale, without a warning."""
    sets = ["contact.0.formulation=two_pass", "contact.0.integration=gauss"]
    for alpha, warned in (("1e10", True), ("1e8", False)):
        lines = []
        _, summary = run_scene(CONFIGS / "patch_test.toml", tmp_path / alpha, sets + [f"contact.0.penalty={alpha}"],
                               log=lines.append)
        solve = summary["steps"][-1]["solves"][-1]
        assert summary["status"] == "ok" and solve["snes_reason"] == "CONVERGED_SNORM_RELATIVE"
        said = [line for line in lines if "the solve stopped on its Newton steps" in line]
        assert (solve["round_off_floor"] > 1e-4) == warned and len(said) == warned
        assert all("lower the penalty of the stiffest, contact[0] (eps_n 7e+13 Pa/m)" in line for line in said)
        force = next(iter(summary["steps"][-1]["contact"].values()))["total_normal_force"]
        assert abs(force - 1.0) > 1e-2 if warned else force == pytest.approx(1.0, rel=1e-6)


def test_augmented_lagrangian_at_a_stiff_penalty_ends_on_its_round_off(tmp_path):
    """The augmented Lagrangian on the matching patch test: at alpha 1e10 the updates' change stands at ~1e-5 for
    ever (eps_n eps |u|, the rows' round-off), above the default tolerance 1e-6; every cutback repeated them and the
    run stopped with AUGMENTED_LAGRANGIAN_MAX_IT, advising more updates or a stiffer penalty (hunt30_2). The
    updates now end at 10x that round-off, with a warning that names the pair and says so; sigma_zz = -p to the
    penalty run's accuracy. At alpha 1e4 they meet the tolerance, and a tolerance of 1e-14 is met at the
    round-off, said the same way."""
    base = ["contact.0.enforcement=augmented_lagrangian", "bodies.1.mesh.cells=[4,4,2]"]
    for k, (sets, warned) in enumerate(((["contact.0.penalty=1e10"], True), (["contact.0.penalty=1e4"], False),
                                        (["contact.0.augmented_tolerance=1e-14"], True))):
        lines = []
        run, summary = run_scene(CONFIGS / "patch_test.toml", tmp_path / str(k), base + sets, log=lines.append)
        assert summary["status"] == "ok"
        _, cell, _ = run.fields(run.u)
        assert np.abs(cell["stress"][:, 2] + 1.0).max() <= (1e-6 if k == 0 else 1e-10)
        run.destroy()
        solve = summary["steps"][-1]["solves"][-1]
        said = [line for line in lines if "updates of contact[0] ended on their round-off" in line]
        assert len(said) == warned and (solve["multipliers_at_round_off"] is not None) == warned
        if warned:
            name, change, tol, bound = solve["multipliers_at_round_off"]
            assert name == "contact[0]" and tol < change <= bound


def test_conditioning_grows_linearly_with_alpha():
    """The Jacobian's 2-norm condition number (dense SVD on the free dofs) shall grow like alpha: the penalty
    is the stiffest term, and nothing else degrades."""
    cond = {a: S.measure(S.scene(sets=S.cells(2, 2) + [f"contact.0.penalty={a}"]), condition=True)["condition"]
            for a in ("1e4", "1e8")}
    assert 0.5e4 <= cond["1e8"] / cond["1e4"] <= 2e4


def test_iterative_solver_at_extreme_penalty_is_not_silent():
    """With CG + GAMG at alpha = 1e8 the run shall either reach sigma_zz = -p or stop with a ConvergenceError
    naming the KSP reason, never return a wrong answer (measured: with the contact band it converges in
    14-20 Krylov iterations; without the band, plain GAMG stopped with DIVERGED_INDEFINITE_PC)."""
    res = S.measure(S.scene(sets=S.cells(4, 4, 2) + ["contact.0.penalty=1e8"], edit=S.petsc(S.GAMG)))
    if res["status"] == "ok":
        assert res["finite"] and res["stress_error"] <= 1e-6
    else:
        assert res["status"] == "ConvergenceError" and "KSP DIVERGED" in res["message"]


# ---------------------------------------------------------------- mesh ratio

BOUND = {"two_pass": 1e-4, "quasi_symmetric, finer": 2e-2, "quasi_symmetric, Gauss 5x5, {power=4}": 1e-3}


@pytest.mark.parametrize("rule", S.RATIO_RULES)
@pytest.mark.parametrize("lower, upper", S.RATIO_PAIRS, ids=lambda n: str(n))
def test_mesh_ratio(lower, upper, rule):
    """From a 16x finer to a 16x coarser slave every rule shall converge with the contact force in equilibrium
    (1e-8); two_pass, the finer-side and the Gauss rules stay accurate; master_slave and the paper's
    quasi_symmetric are exact or nearly so with a finer slave, and where a coarse slave makes them wrong the
    summary shows it: master nodes penetrate by more than 100 p/eps_n."""
    res = ok(S.measure(S.scene(sets=S.cells(lower, upper) + S.RATIO_RULES[rule])))
    assert S.force_error(res) <= 1e-8
    master_pen = res["pair"]["max_penetration_master"] * res["pair"]["eps_n"]     # in units of p / eps_n
    if rule in BOUND:
        assert res["stress_error"] <= BOUND[rule]
    elif lower <= upper:                          # slave as fine as the master or finer
        assert res["stress_error"] <= (1e-8 if rule == "master_slave" else 1e-4)
    assert res["stress_error"] <= 1e-2 or master_pen >= 100.0


NON_NESTED_BOUND = {"two_pass": 1e-2, "quasi_symmetric, finer": 1e-2, "quasi_symmetric, Gauss 5x5, {power=4}": 1e-3}


@pytest.mark.parametrize("rule", S.RATIO_RULES)
@pytest.mark.parametrize("lower, upper", S.NON_NESTED_PAIRS[:2], ids=lambda n: str(n))
def test_mesh_ratio_non_nested(lower, upper, rule):
    """Meshes about 10x apart whose nodes fall anywhere on the other's faces (2:19, 19:2): the force in
    equilibrium; the nodal rules that hold both ways (two_pass, the finer-side weight) within 1e-2 (measured
    1.9e-3 to 4.1e-3, docs/stability.md), the Gauss rule within 1e-3, master_slave and quasi_symmetric within
    1e-2 with the finer slave, and a coarse slave's error shown by master penetrations."""
    res = ok(S.measure(S.scene(sets=S.cells(lower, upper) + S.RATIO_RULES[rule])))
    assert S.force_error(res) <= 1e-8
    master_pen = res["pair"]["max_penetration_master"] * res["pair"]["eps_n"]
    if rule in NON_NESTED_BOUND:
        assert res["stress_error"] <= NON_NESTED_BOUND[rule]
    elif lower <= upper:
        assert res["stress_error"] <= 1e-2
    assert res["stress_error"] <= 1e-2 or master_pen >= 100.0


# ---------------------------------------------------------------- materials

@pytest.mark.parametrize("formulation", FORMULATIONS)
@pytest.mark.parametrize("ratio", S.E_RATIOS)
def test_youngs_modulus_ratio(ratio, formulation):
    """E_upper / E_lower from 1e-4 to 1e4: matching meshes exact (sigma_zz = -p, penetration p/eps_n with
    eps_n from the softer body); non-matching meshes converge in equilibrium."""
    res = ok(S.measure(S.scene(sets=S.cells(2, 2) + S.moduli(ratio) + [f"contact.0.formulation={formulation}"])))
    assert res["stress_error"] <= 1e-8
    assert abs(S.penetration_ratio(res) - 1.0) <= 1e-6
    res = ok(S.measure(S.scene(sets=S.cells(2, 3) + S.moduli(ratio) + [f"contact.0.formulation={formulation}"])))
    assert S.force_error(res) <= 1e-8


@pytest.mark.parametrize("formulation", FORMULATIONS)
@pytest.mark.parametrize("nu", S.NUS)
def test_poissons_ratio(nu, formulation):
    """Poisson's ratio up to 0.499, on both blocks or on the upper one only (the interface then slides): the
    uniaxial answer stays exact on matching meshes, non-matching meshes converge in equilibrium."""
    for nu_lower in (nu, 0.0):
        mats = [f"bodies.0.material.poissons_ratio={nu_lower}", f"bodies.1.material.poissons_ratio={nu}",
                f"contact.0.formulation={formulation}"]
        res = ok(S.measure(S.scene(sets=S.cells(2, 2) + mats)))
        assert res["stress_error"] <= 1e-8
        res = ok(S.measure(S.scene(sets=S.cells(2, 3) + mats)))
        assert S.force_error(res) <= 1e-8


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_mean_dilatation_keeps_the_patch_test(formulation):
    """B-bar hexes (material.volumetric = "mean_dilatation") at nu 0.4999 on non-matching meshes: the uniaxial
    answer stays exact, as with full integration."""
    mats = [f"bodies.{b}.material.{key}" for b in (0, 1) for key in ("poissons_ratio=0.4999",
                                                                     "volumetric=mean_dilatation")]
    res = ok(S.measure(S.scene(sets=S.cells(2, 3) + mats + [f"contact.0.formulation={formulation}",
                                                            "contact.0.integration=segment"])))
    assert res["stress_error"] <= 1e-8


def test_mean_dilatation_does_not_lock_under_a_punch(tmp_path):
    """configs/flat_punch.toml coarse: fully integrated hexes lock as nu nears 0.5 (the punch's force 2.6x its
    nu = 0.3 value at 0.499, 14x at 0.4999; hunt33_3), which a warning says; with the cells' mean dilatation the
    force tends to the incompressible one (2.70, 2.73, 2.73 N at 0.49, 0.499, 0.4999), with no warning."""
    said = []
    forces = {}
    for nu in (0.3, 0.4999):
        for volumetric in ("full", "mean_dilatation"):
            sets = ["bodies.0.mesh.cells=[8,8,4]", "bodies.1.mesh.cells=[6,6,6]", "load.steps=1",
                    "petsc.ksp_type=preonly", "petsc.pc_type=lu", "petsc.pc_factor_mat_solver_type=mumps"]
            sets += [f"bodies.{b}.material.{key}" for b in (0, 1)
                     for key in (f"poissons_ratio={nu}", f"volumetric={volumetric}")]
            lines = []
            run, summary = run_scene(CONFIGS / "flat_punch.toml", tmp_path / f"{nu}_{volumetric}", sets,
                                     log=lines.append)
            run.destroy()
            forces[nu, volumetric] = summary["steps"][-1]["contact"]["contact[0] punch.zmin / block.zmax"][
                "total_normal_force"]
            said.append(any("lock in volume" in line for line in lines))
    assert said == [False, False, True, False]
    assert forces[0.4999, "full"] > 10 * forces[0.3, "full"]
    assert forces[0.4999, "mean_dilatation"] < 1.2 * forces[0.3, "mean_dilatation"]


def test_mean_dilatation_is_for_hexahedra(tmp_path):
    from qsc_petsc.errors import SceneError
    with pytest.raises(SceneError, match=r"bodies\[0\]\.material\.volumetric: \"mean_dilatation\" is for hexahedra"):
        run_scene(CONFIGS / "block_compression.toml", tmp_path, ["bodies.0.mesh.element=tet",
                                                                 "bodies.0.material.volumetric=mean_dilatation"])


# ---------------------------------------------------------------- length units

@pytest.mark.parametrize("case", FORMULATIONS + ["dies"])
def test_length_units(case):
    """The same physical scene in units from 1e-6 to 1e3 (every length times s) shall give the same u/s and
    sigma/p to 1e-8 (non-matching patch test per formulation; two cubes between sticking dies)."""
    if case == "dies":
        path, sets = S.CUBES, ["bodies.0.mesh.cells=[2,2,2]", "bodies.1.mesh.cells=[3,3,3]"]
    else:
        path, sets = S.PATCH, S.cells(2, 3) + [f"contact.0.formulation={case}"]
    ref = ok(S.measure(S.scene(path, sets)))
    for s in S.SCALES:
        res = ok(S.measure(S.scene(path, sets, edit=S.scaled(s)), length=s))
        assert S.relative_difference(res["u"], ref["u"]) <= 1e-8
        assert np.abs(res["stress"] - ref["stress"]).max() <= 1e-8 * np.abs(ref["stress"]).max()


@pytest.mark.parametrize("integration", ["nodal", "gauss", "segment"])
def test_a_scene_far_from_the_origin(tmp_path, integration):
    """The two cubes between dies (hexes: quad faces) moved 1e3 and 1e6 m along x, y, z (the cubes 1 m): the
    origin's rows, force and area, and its penetrations to the coordinates' own round-off. At 1e3 nodal rows lost 16 % of theirs and Gauss rows sank a node 2.7 mm,
    exit 0 (the quad projection's Newton residual took the coordinates' round-off; hunt30_1)."""
    sets = ["bodies.0.mesh.cells=[3,3,3]", "bodies.1.mesh.cells=[4,4,4]", f"contact.0.integration={integration}"]
    out = []
    for k, d in enumerate((0.0, 1e3, 1e6)):
        shift = np.array([1.0, -2.0, 3.0]) * d
        moved = [f"bodies.0.mesh.origin=[{shift[0]},{shift[1]},{shift[2]}]",
                 f"bodies.1.mesh.origin=[{shift[0]},{shift[1]},{shift[2] + 1.0}]",
                 f"die.0.point=[{shift[0]},{shift[1]},{shift[2]}]",
                 f"die.1.point=[{shift[0]},{shift[1]},{shift[2] + 2.0}]"]
        run, summary = run_scene(CONFIGS / "two_cubes_dies.toml", tmp_path / str(k), sets + moved)
        run.destroy()
        assert summary["status"] == "ok"
        out.append(next(v for key, v in summary["steps"][-1]["contact"].items() if key.startswith("contact[")))
    for d, pair in zip((1e3, 1e6), out[1:]):
        assert (pair["rows"], pair["active_rows"], pair["pressed_unfaced_nodes"]) == (
            out[0]["rows"], out[0]["active_rows"], 0)
        for key in ("total_normal_force", "contact_area"):
            assert pair[key] == pytest.approx(out[0][key], rel=1e-6), key
        # a coordinate 3.7e6 m from the origin is known to eps |x| = 8e-10 m: the penetrations to that
        rounding = 10 * np.finfo(float).eps * np.linalg.norm([1.0, 2.0, 3.0]) * d
        for key in ("max_penetration_slave", "mean_penetration_slave"):
            assert pair[key] == pytest.approx(out[0][key], rel=1e-9, abs=rounding), key


# ---------------------------------------------------------------- gaps, penetration, holding

def special(name):
    cases, sigma_fit = S.special_cases()
    return next(sc for n, _, sc in cases if n.startswith(name)), sigma_fit


def test_gap_closed_by_the_load():
    """An upper block 0.01 m above the lower one, held only by contact and pushed by p: the gap closes and the
    answer is the touching one (sigma_zz = -p, penetration p/eps_n)."""
    res = ok(S.measure(special("gap 0.01 m, upper held only by contact, pressure")[0]))
    assert res["stress_error"] <= 1e-8
    assert abs(S.penetration_ratio(res) - 1.0) <= 1e-6


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_gap_of_exactly_the_search_distance(formulation):
    """An upper block one element (the default search distance) above the lower one, the gap closed in one step:
    round-off kept or dropped each segment point at the reach's edge (24 % off with exit 0 on 1 rank, 12 % on 3,
    none within reach on 2; hunt33_3). The reach is widened by model.REACH_SLACK: the touching answer."""
    sc = S.scene(sets=["bodies.0.mesh.size=[1,1,0.3]", "bodies.0.mesh.cells=[10,10,2]", "bodies.1.mesh.origin=[0,0,0.4]",
                       "bodies.1.mesh.cells=[8,8,2]", "contact.0.integration=segment",
                       f"contact.0.formulation={formulation}"])
    res = ok(S.measure(sc))
    assert res["stress_error"] <= 1e-8


def test_gap_that_stays_open():
    """A gap that the held upper block does not close: no contact force, no stress, the block translated."""
    res = ok(S.measure(special("gap 0.01 m, upper held by uz")[0]))
    assert res["pair"]["active_rows"] == 0 and res["pair"]["total_normal_force"] == 0.0
    assert np.abs(res["stress"]).max() <= 1e-9
    assert res["pair"]["max_penetration_slave"] == pytest.approx(-0.005, rel=1e-9)


@pytest.mark.parametrize("name", ["gap 0.01 m, upper held only by contact, pulled", "touching, upper held only"])
def test_body_pulled_off_its_only_support(name):
    """A body held only by contact and pulled away has no equilibrium: a ConvergenceError naming the body and
    the motion nothing holds, never a converged answer; each attempt stops as soon as the open set is
    confirmed (exact J: a rebuild from K when rows open, not a subtraction of their penalty)."""
    res = S.measure(special(name)[0])
    assert res["status"] == "ConvergenceError"
    assert "upper (translation z)" in res["message"]
    assert "DIVERGED_JACOBIAN_DOMAIN after 2 iterations" in res["message"]


def test_initial_penetration_pushed_out():
    """An upper block overlapping the lower by 0.01 m and held only by contact is pushed out to the touching
    answer: sigma_zz = -p, penetration p/eps_n, moved up by the overlap less the compression."""
    res = ok(S.measure(special("initial penetration 0.01 m, upper held only")[0]))
    assert res["stress_error"] <= 1e-8
    assert abs(S.penetration_ratio(res) - 1.0) <= 1e-6
    # the upper block's bottom moves most: up by the overlap, less the lower block's shortening p L / E
    # (L = 0.5 m) and the penetration p / eps_n
    assert res["u"][:, 2].max() == pytest.approx(0.01 - 0.5e-3 - 1.0 / res["pair"]["eps_n"], rel=1e-8)


def test_initial_penetration_between_clamps():
    """Both blocks clamped with a 0.01 m overlap: the penalty spring and the blocks share it,
    sigma_zz = -d / (L/E + 1/eps_n) in every cell (to 1e-8)."""
    sc, sigma_fit = special("initial penetration 0.01 m, both blocks clamped")
    res = ok(S.measure(sc))
    assert np.abs(res["stress"][:, 2] + sigma_fit).max() <= 1e-8 * sigma_fit


def test_body_not_held_tangentially_is_an_input_error():
    """An upper block with only a pressure and frictionless contact is free in x, y and rotation about z: a
    SceneError names the body and those motions before any solve (a direct solver would return round-off)."""
    res = S.measure(special("upper with no displacement boundary")[0])
    assert res["status"] == "SceneError"
    assert "upper (translation x, translation y, rotation about z)" in res["message"]


def test_block_held_only_by_a_die():
    """A block with no displacement boundary on a sticking die is held by it (sigma_zz = -p, die force pA); on a
    frictionless die it is free in x, y and rotation about z: a SceneError."""
    res = ok(S.measure(special("one block on a sticking die")[0]))
    assert res["stress_error"] <= 1e-8
    assert next(iter(res["dies"].values()))["force_on_bodies"][2] == pytest.approx(1.0, rel=1e-8)
    res = S.measure(special("one block on a frictionless die")[0])
    assert res["status"] == "SceneError" and "lower (translation x, translation y, rotation about z)" in res["message"]


@pytest.mark.parametrize("formulation", FORMULATIONS)
@pytest.mark.parametrize("element, lower, upper", S.TIE_CASES)
def test_nodes_on_edges_and_vertices(element, lower, upper, formulation):
    """Slave nodes exactly on master vertices and edges (and master nodes on slave edges): the run converges,
    a finer nested slave is exact for master_slave, and the answer is continuous: moving the upper block by
    +-1e-12 m in x and y changes the displacements by less than 1e-8 relative."""
    ref = ok(S.measure(S.scene(sets=S.tie_sets(element, lower, upper, formulation))))
    assert S.force_error(ref) <= 1e-8
    if formulation == "master_slave" and upper > lower:
        assert ref["stress_error"] <= 1e-8
    for shift in (1e-12, -1e-12):
        res = ok(S.measure(S.scene(sets=S.tie_sets(element, lower, upper, formulation, shift))))
        assert S.relative_difference(res["u"], ref["u"]) <= 1e-8


# ---------------------------------------------------------------- the restraint kernel

def test_free_motions_names_the_null_space():
    """A Gram matrix holding body a fully and body b in all but translation z and rotation about x reports
    exactly b's two free motions; a fully held one reports none; a body held only relative to another
    reports both bodies."""
    names = ["a", "b"]
    held = np.eye(12)
    assert free_motions(held, names) == {}
    g = held.copy()
    g[8, 8] = g[9, 9] = 0.0                       # b: translation z, rotation about x
    assert free_motions(g, names) == {"b": [MODES[2], MODES[3]]}
    rel = np.eye(12)
    rel[[2, 8], :] = rel[:, [2, 8]] = 0.0
    rel[np.ix_([2, 8], [2, 8])] = [[1.0, -1.0], [-1.0, 1.0]]          # only u_z(a) - u_z(b) is held
    assert free_motions(rel, names) == {"a": [MODES[2]], "b": [MODES[2]]}


def test_bilateral_start_pulls_open_rows_closed():
    """In the first iteration of an increment (bilateral) a row with a gap is active with a negative (pulling)
    force eps_n c / W, so the first Newton step solves the glued problem; otherwise an open row has no force."""
    c, W = np.array([-2e-3, 1e-3]), np.array([0.5, 0.25])
    _, m, d, active = row_response(c, W, 1e6, 1.0, np.inf, bilateral=True)
    assert active.all() and np.allclose(m, 1e6 * c / W) and np.allclose(d, 1e6 / W)
    _, m, _, active = row_response(c, W, 1e6, 1.0, np.inf)
    assert active.all() and m[0] == 0.0 and m[1] == pytest.approx(1e6 * c[1] / W[1])


# ---------------------------------------------------------------- displacement-driven, soft or small

@pytest.mark.parametrize("case", ["E 1e-12 Pa", "1e-20 m"])
def test_prescribed_displacement_on_a_soft_or_small_block(case, tmp_path):
    """Uniaxial compression by a prescribed displacement (configs/block_compression.toml) shall give sigma_zz =
    E eps exactly however soft or small the block: the Dirichlet rows (u_i - ubar_i, in metres) set the Newton
    test's force scale and ended these runs "converged" at once with every free node at rest."""
    from conftest import CONFIGS, run_scene
    if case.startswith("E"):
        sets, E, strain = ["bodies.0.material.youngs_modulus=1e-12"], 1e-12, -0.01
    else:
        sets = ["bodies.0.mesh.size=[1e-20,1e-20,1e-20]", "boundary.3.uz=-1e-22"]
        E, strain = 1000.0, -0.01
    run, summary = run_scene(CONFIGS / "block_compression.toml", tmp_path, sets)
    try:
        _, cell, _ = run.fields(run.u)
    finally:
        run.destroy()
    assert summary["status"] == "ok"
    assert np.abs(cell["stress"][:, 2] - E * strain).max() <= 1e-8 * E * abs(strain)
    reactions = summary["steps"][-1]["reactions"]
    assert reactions["boundary[2] block.zmin"][2] == pytest.approx(-reactions["boundary[3] block.zmax"][2], rel=1e-8)


PLATES = """\
name = "plates"
[[bodies]]
name = "coarse"
mesh = { type = "box", origin = [0.0, 0.0, 0.0], size = [1.0, 1.0, 0.05], cells = [2, 2, 1] }
material = { youngs_modulus = 1000.0 }
[[bodies]]
name = "fine"
mesh = { type = "box", origin = [0.0, 0.0, 0.05], size = [1.0, 1.0, 0.05], cells = [24, 24, 1] }
material = { youngs_modulus = 1000.0 }
[[boundary]]
surface = "coarse.zmin"
type = "displacement"
uz = 0.0
[[boundary]]
surface = "fine.zmax"
type = "pressure"
value = 1.0
[[boundary]]
surface = "coarse.xmin"
type = "symmetry"
[[boundary]]
surface = "coarse.ymin"
type = "symmetry"
[[boundary]]
surface = "fine.xmin"
type = "symmetry"
[[boundary]]
surface = "fine.ymin"
type = "symmetry"
[[contact]]
slave = "fine.zmin"
master = "coarse.zmax"
formulation = "master_slave"
integration = "nodal"
[petsc]
ksp_type = "preonly"
pc_type = "lu"
pc_factor_mat_solver_type = "mumps"
"""


@pytest.mark.parametrize("element", ["hex", "tet"])
def test_a_coarse_face_under_a_fine_surface_widens_only_its_rows(tmp_path, monkeypatch, element):
    """A 2 x 2 plate under a 24 x 24 one: a coarse node's contact row couples hundreds of fine nodes, and the
    stiffness's pattern padded every widened row to it (hex box stencils, _widen_rows; tetrahedra, the element
    blocks' _sort_rows): 60 x 60 took 7.2 s and 2.3 GB (hex) for 22k dofs against 0.14 s and 318 MiB with a 20 x 20
    plate (hunt27_2). Rows are now padded only among rows of about their width: the padded entries stay within
    twice the true ones. The answer: the pressure carried through, p A."""
    padded, true = [], []
    widen, sort_rows = assembly._widen_rows, sparsity._sort_rows

    def widen_spy(key, rows, blocks, v0, v1):
        out = widen(key, rows, blocks, v0, v1)
        padded.append(out[0].size - 27 * len(rows))
        true.append(int(np.isin(blocks[0], rows).sum()))
        return out

    def sort_spy(g, r, k, ncol, cell_cols, ptr, entries, extra_ptr, *rest):
        idx = np.arange(g.start, g.stop) if isinstance(g, slice) else g
        widths = (ptr[r + 1] - ptr[r]) * k + (0 if extra_ptr is None else extra_ptr[idx + 1] - extra_ptr[idx])
        padded.append(int(len(r) * np.max(widths, initial=0)))
        true.append(int(np.sum(widths)))
        return sort_rows(g, r, k, ncol, cell_cols, ptr, entries, extra_ptr, *rest)

    monkeypatch.setattr(assembly, "_widen_rows", widen_spy)
    monkeypatch.setattr(sparsity, "_sort_rows", sort_spy)
    path = tmp_path / "plates.toml"
    text = PLATES if element == "hex" else PLATES.replace("1] }", '1], element = "tet" }')
    path.write_text(text)
    run, summary = run_scene(path, tmp_path / "out")
    run.destroy()
    assert summary["status"] == "ok" and padded
    assert sum(padded) <= 2 * sum(true)
    pair = next(iter(summary["steps"][-1]["contact"].values()))
    assert pair["total_normal_force"] == pytest.approx(1.0, rel=1e-6)


def test_the_rows_do_not_hold_advice_names_no_setting_the_run_has():
    """A faceted ring pressed on a block with two_pass and segment rows: the "rows do not hold those nodes" warning
    was right, and told the run to use two_pass with segment rows, its own settings, while feature_angle, which held
    the ring (0.01226 N against 0.00683), went unnamed (hunt35_4). The cures are those the run does not have."""
    from types import SimpleNamespace

    from qsc_petsc.contact.model import ContactModel

    def advice(**spec):
        keys = {"formulation": "two_pass", "integration": "segment", "feature_angle": None, **spec}
        pd = {"spec": SimpleNamespace(**keys), "index": 0, "h_eff": 0.1, "sizes": [0.1, 0.1]}
        return ContactModel._unheld(None, pd, 1e-3).split("does not help: ")[1]

    assert advice() == ("refine the coarser surface (a curved one's facets), or give the pair a feature_angle below "
                        "the fold between its facets (their edges' and corners' own nodal rows)")
    assert "feature_angle" not in advice(feature_angle=30.0) and "two_pass" not in advice(feature_angle=30.0)
    assert advice(formulation="quasi_symmetric").endswith('or use two_pass with integration = "segment"')


def test_a_contact_face_not_convex_in_its_plane_is_refused_by_name(tmp_path):
    """A hex whose face on the contact surface has a reflex corner (an inner node column moved from 1/3 to 0.52 of a
    3 x 3 face) passes the cell check, which reads det J at the Gauss points. Segment rows dropped it in silence as
    the master (the patch test 2.3 % off, "ok") and refused it as the slave with "S face of pair 57 is degenerate or
    not convex" (hunt35_4). check and run refuse it naming the pair's side, surface and place."""
    from conftest import write_gmsh

    from qsc_petsc import fem
    from qsc_petsc.errors import MeshError
    from qsc_petsc.meshgen import box_mesh
    box = box_mesh((0.0, 0.0, 0.5), (1.0, 1.0, 0.5), (3, 3, 1))
    inner = np.isclose(box.points[:, 0], 1 / 3) & np.isclose(box.points[:, 1], 1 / 3)
    box.points[inner, :2] = 0.52
    write_gmsh(tmp_path / "dart.msh", box.points, box.cells, "hex", {
        side: fem.cell_faces("hex", box.cells[box.surfaces[side][:, 0]], box.surfaces[side][:, 1])
        for side in box.surfaces})
    text = (CONFIGS / "patch_test.toml").read_text().replace(
        'mesh = { type = "box", origin = [0.0, 0.0, 0.5], size = [1.0, 1.0, 0.5], cells = [7, 7, 2] }',
        'mesh = { type = "file", path = "dart.msh" }')
    (tmp_path / "dart.toml").write_text(text)
    for roles in ([], ['contact.0.slave="lower.zmax"', 'contact.0.master="upper.zmin"']):
        with pytest.raises(MeshError, match=r"contact\[0\]\.(slave|master) \(upper.zmin\): 1 face\(s\) not strictly "
                                            r"convex in their own plane .* centred at x, y, z = 0.5467, 0.5467, 0.5"):
            run_scene(tmp_path / "dart.toml", tmp_path / "out", ["contact.0.formulation=\"master_slave\"", *roles])



SPREAD = """name = "spread"
[[bodies]]
name = "block"
mesh = { type = "box", origin = [0.0, 0.0, 0.0], size = [2.0, 2.0, 0.5], cells = [20, 20, 2] }
material = { youngs_modulus = 1000.0, poissons_ratio = 0.3 }
[[bodies]]
name = "plate"
mesh = { type = "box", origin = [0.0, 0.0, 0.5], size = [2.0, 2.0, 0.05], cells = [20, 20, 1] }
material = { youngs_modulus = 1000.0, poissons_ratio = 0.3 }
[[bodies]]
name = "cube"
mesh = { type = "box", origin = [0.0, 0.0, 0.55], size = [0.05, 0.05, 0.05], cells = [2, 2, 2] }
material = { youngs_modulus = 1000.0, poissons_ratio = 0.3 }
[[boundary]]
surface = "block.zmin"
type = "displacement"
uz = 0.0
[[boundary]]
surface = "block.xmin"
type = "symmetry"
[[boundary]]
surface = "block.ymin"
type = "symmetry"
[[boundary]]
surface = "plate.xmin"
type = "symmetry"
[[boundary]]
surface = "plate.ymin"
type = "symmetry"
[[boundary]]
surface = "cube.xmin"
type = "symmetry"
[[boundary]]
surface = "cube.ymin"
type = "symmetry"
[[boundary]]
surface = "plate.zmax"
type = "pressure"
value = 1e-3
[[die]]
name = "top"
point = [0.0, 0.0, 0.6]
normal = [0.0, 0.0, -1.0]
motion = [0.0, 0.0, -0.0005]
surfaces = ["cube.zmax"]
condition = "sticking"
[[contact]]
slave = "cube.zmin"
master = "plate.zmax"
formulation = "quasi_symmetric"
penalty = 1e4
[[contact]]
slave = "plate.zmin"
master = "block.zmax"
formulation = "quasi_symmetric"
penalty = 1.0
[load]
steps = 1
[petsc]
ksp_type = "preonly"
pc_type = "lu"
pc_factor_mat_solver_type = "mumps"
"""


def test_a_soft_penalty_under_a_concentrated_load_is_said_soft(tmp_path):
    """A small cube pressed on a plate lying on a block at alpha 1: the plate's pressure on the block concentrates
    under the cube, and the rows-do-not-hold warning (depth against the pair's mean pressure) said a larger penalty
    would not help, where alpha 10, 100 and 1e4 took the die's force from 24 % low to 5 % and 0.6 % (hunt35_3).
    Read against each node's own pressure it is the soft-penalty warning. So is steel under 1 kPa at alpha 1 (14 %
    off), which a cut at a strain of 1e-8 had left unsaid."""
    (tmp_path / "spread.toml").write_text(SPREAD)
    steel = ["bodies.0.material.youngs_modulus=200e9", "bodies.1.material.youngs_modulus=200e9",
             "boundary.5.value=1000.0", "contact.0.penalty=1"]
    for scene, sets, said in ((tmp_path / "spread.toml", [], "contact[1]: pressed nodes penetrate"),
                              (CONFIGS / "patch_test.toml", steel, "contact[0]: pressed nodes penetrate")):
        lines = []
        run, summary = run_scene(scene, tmp_path / scene.stem, sets, log=lines.append)
        run.destroy()
        warnings = [line for line in lines if "warning" in line]
        assert summary["status"] == "ok" and len(warnings) == 1, lines
        assert said in warnings[0] and "is soft for this load" in warnings[0], warnings
