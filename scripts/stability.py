#!/usr/bin/env python3
"""Stability at the extremes (issue 5, part 3): measures every case of docs/stability.md and writes it.

Small patch-test scenes (configs/patch_test.toml: two stacked blocks, pressure p = 1 Pa on top; exact
answer sigma_zz = -p everywhere and, on matching meshes, a row penetration p / eps_n) pushed to the
extremes: penalty alpha 1e0-1e10, slave/master element size 1:16-16:1, Young's modulus ratio 1e-4-1e4,
Poisson's ratio up to 0.499, lengths in units from 1e-28 to 1e28, gaps, initial penetration, slave
nodes on master edges and vertices, bodies held only by contact, and the interface on one rank or
split across ranks. tests/test_extremes.py and tests/parallel/test_extremes_parallel.py assert on the
same functions. Usage: .venv/bin/python scripts/stability.py [--ranks 2 3] [--tables units ...] (about a minute, serial
runs in-process, the parallel table under mpirun).
"""

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))
from benchlib import ENV, write_table

PATCH = ROOT / "configs" / "patch_test.toml"
CUBES = ROOT / "configs" / "two_cubes_dies.toml"
DOCS = ROOT / "docs" / "stability.md"
FORMULATIONS = ("master_slave", "two_pass", "quasi_symmetric")
MUMPS = {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}
GAMG = {"ksp_type": "cg", "pc_type": "gamg", "ksp_rtol": "1e-10"}


# ---------------------------------------------------------------- scenes

def scene(path=PATCH, sets=(), edit=None):
    """A validated scene: the file with --set overrides (one load step, no XDMF), then edit(data) on its dict."""
    from qsc_petsc.scene import load_scene, parse_scene
    base = load_scene(path, ["load.steps=1", "output.xdmf=false", *sets])
    if base.contact and not any(s.startswith("contact.0.integration=") for s in sets):
        # these tables measure the node-to-segment rows unless a case names its integration
        base = load_scene(path, ["load.steps=1", "output.xdmf=false", "contact.0.integration=nodal", *sets])
    if edit is None:
        return base
    data = base.to_dict()
    edit(data)
    return parse_scene(data, path.parent, base.name)


def cells(lower, upper, layers=1):
    """--set overrides for the patch test's in-plane cell counts (lower, upper) and layers along z."""
    return [f"bodies.0.mesh.cells=[{lower},{lower},{layers}]", f"bodies.1.mesh.cells=[{upper},{upper},{layers}]"]


def scaled(s):
    """An edit: every length of the scene times s (box origins and sizes, dies, prescribed displacements)."""
    def edit(data):
        for body in data["bodies"]:
            body["mesh"]["origin"] = [s * x for x in body["mesh"]["origin"]]
            body["mesh"]["size"] = [s * x for x in body["mesh"]["size"]]
        for die in data["die"]:
            die["point"] = [s * x for x in die["point"]]
            die["motion"] = [s * x for x in die["motion"]]
        for bc in data["boundary"]:
            for k in ("ux", "uy", "uz"):
                if bc.get(k) is not None:
                    bc[k] *= s
    return edit


def petsc(options):
    """An edit: replace the scene's PETSc options."""
    def edit(data):
        data["petsc"] = dict(options)
    return edit


def chain(*edits):
    def edit(data):
        for e in edits:
            if e is not None:
                e(data)
    return edit


def without_upper_holds(data):
    """An edit: the upper block keeps only its pressure (no displacement boundary at all)."""
    data["boundary"] = [b for b in data["boundary"] if not b["surface"].startswith("upper.") or b["type"] == "pressure"]


def pressure(value):
    def edit(data):
        for b in data["boundary"]:
            if b["type"] == "pressure":
                b["value"] = value
    return edit


def clamp_upper(uz):
    """An edit: no pressure; the upper block's top face held at uz [m]."""
    def edit(data):
        data["boundary"] = [b for b in data["boundary"] if b["type"] != "pressure"]
        data["boundary"].append({"surface": "upper.zmax", "type": "displacement", "uz": uz})
    return edit


def block_on_die(condition):
    """An edit: the upper block removed; the lower block has no boundary but a pressure on top and a rigid die
    under it (sticking or frictionless): held only by contact."""
    def edit(data):
        data["bodies"] = data["bodies"][:1]
        data["contact"] = []
        data["boundary"] = [{"surface": "lower.zmax", "type": "pressure", "value": 1.0}]
        data["die"] = [{"name": "base", "point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0],
                        "surfaces": ["lower.zmin"], "condition": condition, "penalty": 1e4}]
    return edit


# ---------------------------------------------------------------- one run, measured

def _gather_rows(comm, ids, values):
    """Rows of values (n, k) by rank-independent ids, gathered in id order on every rank."""
    parts = comm.allgather((np.asarray(ids), np.asarray(values)))
    ids = np.concatenate([p[0] for p in parts])
    vals = np.concatenate([p[1] for p in parts])
    return vals[np.argsort(ids, kind="stable")]


def dense_condition(run):
    """2-norm condition number of the final Jacobian on the free dofs (dense SVD; serial, small meshes only)."""
    J = run.system.J.convert("dense")
    A = J.getDenseArray().copy()
    J.destroy()
    free = np.setdiff1d(np.arange(A.shape[0]), run.system.bc_dofs)
    s = np.linalg.svd(A[np.ix_(free, free)], compute_uv=False)
    return float(s[0] / s[-1])


def measure(sc, comm=MPI.COMM_SELF, out=None, p=1.0, length=1.0, lanczos=False, condition=False):
    """Run scene sc (collective) and return its measures, equal on every rank.

    p: the pressure scale of the stresses [Pa]; length: the length unit (u / length is compared).
    lanczos: record CG's extreme singular value estimates of the preconditioned operator (last solve);
    condition: the dense 2-norm condition number of the final Jacobian (serial only).
    A QscError (bad input, failed solve) is a result: status = the error class, message = its text."""
    from qsc_petsc.errors import QscError
    from qsc_petsc.run import Run
    tmp = None
    if out is None:
        tmp = comm.bcast(tempfile.mkdtemp(prefix="qsc_stab_") if comm.rank == 0 else None, root=0)
        out = tmp
    t0 = time.perf_counter()
    run = None
    try:
        run = Run(sc, comm, out, log=lambda *a, **k: None)
        ksp = run.system.snes.getKSP()
        if lanczos:
            ksp.setComputeSingularValues(True)
        summary = run.execute()
    except QscError as exc:
        if run is not None:
            run.destroy()
        return {"status": type(exc).__name__, "message": str(exc), "seconds": time.perf_counter() - t0}
    finally:
        if tmp is not None and comm.rank == 0:
            shutil.rmtree(tmp, ignore_errors=True)
    res = {"status": "ok", "seconds": time.perf_counter() - t0,
           "newton": sum(s["snes_iterations"] for s in summary["steps"]),
           "krylov": sum(s["ksp_iterations"] for s in summary["steps"]),
           "reason": summary["steps"][-1]["snes_reason"], "dofs": summary["mesh"]["dofs"],
           "mumps_icntl_14": max((s.get("mumps_icntl_14") or 0 for step in summary["steps"] for s in step["solves"]),
                                 default=0) or None,
           "jacobian_nonzeros": int(run.system.J.getInfo()["nz_used"])}
    mesh = run.mesh
    _, cell, ul = run.fields(run.u)
    res["finite"] = comm.allreduce(bool(np.isfinite(ul).all() and np.isfinite(cell["stress"]).all()), op=MPI.LAND)
    szz = cell["stress"][:, 2]
    res["stress_error"] = comm.allreduce(float(np.abs(szz + p).max(initial=0.0)) / p, op=MPI.MAX)
    owned = mesh.owned
    res["u"] = _gather_rows(comm, mesh.vert_orig[owned], ul[owned] / length)
    res["stress"] = _gather_rows(comm, mesh.cell_orig, cell["stress"] / p)
    step = summary["steps"][-1]
    res["reactions"] = step["reactions"]
    for name, entry in step.get("contact", {}).items():
        if name.startswith("contact[0]"):
            res["pair"] = entry
        elif name.startswith("die["):
            res.setdefault("dies", {})[name] = entry
    if lanczos and res["krylov"] > 0:
        res["singular_values"] = ksp.computeExtremeSingularValues()
    if condition and comm.size == 1:
        res["condition"] = dense_condition(run)
    run.destroy()
    return res


def penetration_ratio(res, p=1.0):
    """Mean slave-row penetration over p / eps_n (1 on matching meshes)."""
    pair = res["pair"]
    return pair["mean_penetration_slave"] * pair["eps_n"] / p


def force_error(res, p=1.0, area=1.0):
    """|total normal contact force - p A| / (p A)."""
    return abs(res["pair"]["total_normal_force"] - p * area) / (p * area)


def relative_difference(a, b):
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))


# ---------------------------------------------------------------- the cases

ALPHAS = ("1e0", "1e2", "1e4", "1e6", "1e8", "1e10")
# nested pairs (one mesh refines the other) and non-nested ones about 10x apart (nodes of one fall anywhere on the
# other's faces: the nodal rules' error is 1e-3, not the nested pairs' 1e-5)
RATIO_PAIRS = [(1, 1), (1, 2), (1, 4), (1, 8), (1, 16), (2, 1), (4, 1), (8, 1), (16, 1)]
NON_NESTED_PAIRS = [(2, 19), (19, 2), (3, 29), (29, 3)]
RATIO_RULES = {
    "master_slave": ["contact.0.formulation=master_slave"],
    "two_pass": ["contact.0.formulation=two_pass"],
    "quasi_symmetric": ["contact.0.formulation=quasi_symmetric"],
    "quasi_symmetric, finer": ["contact.0.formulation=quasi_symmetric", "contact.0.weight=finer"],
    "quasi_symmetric, Gauss 5x5, {power=4}": ["contact.0.formulation=quasi_symmetric", "contact.0.integration=gauss",
                                             "contact.0.gauss_points=5", "contact.0.weight={power=4}"],
}
E_RATIOS = (1e-4, 1e-2, 1.0, 1e2, 1e4)
NUS = (0.0, 0.3, 0.45, 0.49, 0.499)
SCALES = (1e-28, 1e-6, 1e-3, 1.0, 1e3, 1e28)     # to near the limits of a body's extent (mesh.MIN_EXTENT, MAX_EXTENT)


def moduli(ratio, soft=1000.0):
    """--set overrides: E_upper / E_lower = ratio, the softer body at `soft` Pa (so eps_n stays the same)."""
    lower, upper = (soft, soft * ratio) if ratio >= 1 else (soft / ratio, soft)
    return [f"bodies.0.material.youngs_modulus={lower!r}", f"bodies.1.material.youngs_modulus={upper!r}"]


def special_cases():
    """(name, expected, scene, check) of the gap / penetration / tie / holding cases; check(res) -> measured text."""
    base = cells(2, 2)
    d, eps = 0.01, 1e4 * 1000.0 / 0.5        # overlap [m]; eps_n = alpha E / h for 2 x 2 cells of 0.5 m
    sigma_fit = d / (1.0 / 1000.0 + 1.0 / eps)  # both blocks clamped: d = |sigma| (L / E + 1 / eps_n), L = 1 m
    return [
        ("gap 0.01 m, upper held only by contact, pressure closes it", "contact closes: sigma_zz = -p, pen = p/eps_n",
         scene(sets=base + ["bodies.1.mesh.origin=[0,0,0.51]"])),
        ("gap 0.01 m, upper held by uz = -0.005 m on its top, no pressure", "no contact: zero contact force, no stress",
         scene(sets=base + ["bodies.1.mesh.origin=[0,0,0.51]"], edit=clamp_upper(-0.005))),
        ("gap 0.01 m, upper held only by contact, pulled away (p = -1)", "no equilibrium: ConvergenceError naming it",
         scene(sets=base + ["bodies.1.mesh.origin=[0,0,0.51]"], edit=pressure(-1.0))),
        ("touching, upper held only by contact, pulled away (p = -1)", "no equilibrium: ConvergenceError naming it",
         scene(sets=base, edit=pressure(-1.0))),
        ("initial penetration 0.01 m, upper held only by contact", "pushed out: sigma_zz = -p, pen = p/eps_n",
         scene(sets=base + ["bodies.1.mesh.origin=[0,0,0.49]"])),
        ("initial penetration 0.01 m, both blocks clamped", f"sigma_zz = -d/(L/E + 1/eps_n) = {-sigma_fit:.6g} Pa",
         scene(sets=base + ["bodies.1.mesh.origin=[0,0,0.49]"], edit=clamp_upper(0.0))),
        ("upper with no displacement boundary (pressure + frictionless contact)",
         "not held in x, y, rot z: SceneError naming them", scene(sets=cells(2, 3), edit=without_upper_holds)),
        ("one block on a sticking die, no displacement boundary", "held by the die: converges, die force = p A",
         scene(sets=cells(2, 2), edit=block_on_die("sticking"))),
        ("one block on a frictionless die, no displacement boundary", "not held in x, y, rot z: SceneError",
         scene(sets=cells(2, 2), edit=block_on_die("frictionless"))),
    ], sigma_fit


TIE_CASES = [  # slave (upper) nodes on master (lower) vertices and edges, and master nodes on slave edges
    ("hex", 2, 4), ("hex", 3, 6), ("hex", 4, 2), ("tet", 2, 4), ("tet", 4, 2),
]


def tie_sets(element, lower, upper, formulation, shift=0.0):
    return cells(lower, upper) + [f"bodies.0.mesh.element={element}", f"bodies.1.mesh.element={element}",
                                  f"contact.0.formulation={formulation}",
                                  f"bodies.1.mesh.origin=[{shift!r},{shift!r},0.5]"]


# ---------------------------------------------------------------- parallel layouts

def layout_scene(layout, formulation="quasi_symmetric", extra=()):
    """The patch test laid out so that the simple partitioner (cells in order) puts the whole interface on rank 0
    ("one_rank": a bystander body holds most cells) or spreads it over every rank ("split": thin blocks)."""
    if layout == "split":
        return scene(sets=cells(5, 7) + [f"contact.0.formulation={formulation}", *extra])

    def bystander(data):
        data["bodies"].append({"name": "bystander", "mesh": {"type": "box", "origin": [3.0, 0.0, 0.0],
                                                             "size": [1.0, 1.0, 1.0], "cells": [8, 8, 4]},
                               "material": {"youngs_modulus": 500.0, "poissons_ratio": 0.2}})
        # on rollers under the blocks' pressure: the same exact uniaxial answer, sigma_zz = -p everywhere
        data["boundary"] += [{"surface": f"bystander.{face}", "type": "symmetry"} for face in ("xmin", "ymin", "zmin")]
        data["boundary"].append({"surface": "bystander.zmax", "type": "pressure", "value": 1.0})
    return scene(sets=cells(4, 6) + [f"contact.0.formulation={formulation}", *extra], edit=bystander)


def interface_ranks(comm, sc):
    """(ranks owning slave faces, ranks owning master faces) of contact[0] under the current partitioner."""
    from qsc_petsc.mesh import distribute_mesh
    mesh = distribute_mesh(sc, comm)
    pair = sc.contact[0]
    has = [len(mesh.surface_faces(s)[0]) > 0 for s in (pair.slave, pair.master)]
    mesh.dm.destroy()
    owners = comm.allgather(has)
    return [r for r, h in enumerate(owners) if h[0]], [r for r, h in enumerate(owners) if h[1]]


class simple_partitioner:
    """Context: the simple partitioner (contiguous cell ranges in cell order) for the runs inside."""

    def __enter__(self):
        from petsc4py import PETSc
        PETSc.Options().setValue("qsc_petscpartitioner_type", "simple")

    def __exit__(self, *exc):
        from petsc4py import PETSc
        PETSc.Options().delValue("qsc_petscpartitioner_type")


PARALLEL_CASES = {
    "alpha 1e4": [],
    "alpha 1e8": ["contact.0.penalty=1e8"],
    "initial penetration 0.01 m": ["bodies.1.mesh.origin=[0,0,0.49]"],
}


def parallel_table(comm, tmp):
    """Every layout, formulation and case on comm and on one rank: differences of the results (collective)."""
    rows = []
    with simple_partitioner():
        for layout in ("one_rank", "split"):
            for formulation in FORMULATIONS:
                for case, extra in PARALLEL_CASES.items():
                    sc = layout_scene(layout, formulation, extra)
                    slave_ranks, master_ranks = interface_ranks(comm, sc)
                    par = measure(sc, comm, Path(tmp) / "w")
                    ser = measure(sc, MPI.COMM_SELF, Path(tmp) / f"s{comm.rank}")
                    row = {"layout": layout, "formulation": formulation, "case": case, "ranks": comm.size,
                           "slave_ranks": slave_ranks, "master_ranks": master_ranks,
                           "status": par["status"] if ser["status"] == "ok" else f"serial: {ser['status']}",
                           "message": par.get("message", ser.get("message", ""))}
                    if par["status"] == ser["status"] == "ok":
                        row.update(newton=par["newton"], serial_newton=ser["newton"],
                                   u_difference=comm.allreduce(relative_difference(par["u"], ser["u"]), op=MPI.MAX),
                                   force_difference=abs(par["pair"]["total_normal_force"]
                                                        - ser["pair"]["total_normal_force"]),
                                   stress_error=par["stress_error"],
                                   mumps_icntl_14=par["mumps_icntl_14"])
                    rows.append(row)
    return rows


# ---------------------------------------------------------------- the document

def fmt(x, spec=".2e"):
    return "-" if x is None else format(x, spec)


def table_alpha(args):
    rows = []
    for lower, upper in ((4, 4), (4, 7)):
        for alpha in ALPHAS:
            sets = cells(lower, upper, 2) + [f"contact.0.penalty={alpha}"]
            direct = measure(scene(sets=sets, edit=petsc(MUMPS)), condition=True)
            gamg = measure(scene(sets=sets, edit=petsc(GAMG)), lanczos=True)
            sv = gamg.get("singular_values")
            rows.append("| " + " | ".join([
                f"{lower}/{upper}", alpha, fmt(direct["pair"]["eps_n"]), str(direct["newton"]), str(direct["krylov"]),
                fmt(direct["stress_error"]), fmt(abs(penetration_ratio(direct) - 1.0)) if lower == upper else "-",
                fmt(force_error(direct)), fmt(direct["condition"]),
                str(gamg.get("newton", "-")), str(gamg.get("krylov", "-")),
                gamg["reason"] if gamg["status"] == "ok" else gamg["message"].split(": ", 1)[-1],
                fmt(relative_difference(gamg["u"], direct["u"])) if gamg["status"] == "ok" else "-",
                fmt(sv[0] / sv[1]) if sv else "-"]) + " |")
            print(f"alpha {alpha} {lower}/{upper}: MUMPS {direct['newton']} its, cond {direct['condition']:.2e}; "
                  f"GAMG {gamg['status']}", flush=True)
    write_table(DOCS, "Penalty: iterations and conditioning against alpha", "stability.py",
                "patch test, 2 layers per block, lower/upper in-plane cells 4/4 (matching) and 4/7, "
                "quasi_symmetric, one load step, serial. MUMPS: `preonly` + LU. cond2(J): the 2-norm "
                "condition number of the final Jacobian restricted to the free dofs, from a dense SVD "
                "(numpy) -- exact, not an estimate. CG + GAMG (rtol 1e-10; composed with the exact solve on the contact band, the default when gamg "
                "is named with contact pairs): Newton and Krylov iterations, "
                "the outcome, du = max \\|u_GAMG - u_MUMPS\\| / max \\|u_MUMPS\\|, and sigma_max/sigma_min of the "
                "GAMG-preconditioned operator estimated by CG's Lanczos process (`KSPComputeExtremeSingularValues`, last linear solve). pen: |mean slave "
                "row penetration / (p/eps_n) - 1| (matching meshes only); force: |total contact force - pA|/pA",
                ["lower/upper", "alpha", "eps_n [Pa/m]", "MUMPS Newton", "MUMPS Krylov", "max\\|szz+p\\|/p",
                 "pen", "force", "cond2(J)", "GAMG Newton", "GAMG Krylov", "GAMG outcome", "GAMG du",
                 "GAMG Lanczos smax/smin"], rows)


def table_ratio(args):
    rows = []
    for lower, upper in RATIO_PAIRS + NON_NESTED_PAIRS:
        for rule, sets in RATIO_RULES.items():
            r = measure(scene(sets=cells(lower, upper) + sets))
            pair = r["pair"]
            rows.append("| " + " | ".join([
                f"{lower}:{upper}", f"{lower / upper:.4g}", rule, str(r["newton"]), fmt(r["stress_error"]),
                fmt(force_error(r)), fmt(pair["max_penetration_master"] * pair["eps_n"]),
                str(r["jacobian_nonzeros"]), f"{r['seconds']:.2f}"]) + " |")
        print(f"mesh ratio {lower}:{upper} done", flush=True)
    write_table(DOCS, "Slave/master mesh ratio", "stability.py",
                "patch test, one layer per block, upper = slave with `upper` x `upper` cells on the lower "
                "block's `lower` x `lower`; h_s/h_m = slave/master element size; alpha 1e4, MUMPS, serial. "
                "Every run converged; the stress error is the nodal rules' integration error (exact with matching "
                "meshes); force: |total contact force - pA|/pA (equilibrium); master pen: the largest "
                "penetration of a master node in units of p/eps_n -- where it is large, master nodes poke "
                "through a coarse slave and the summary says so (`max_penetration_master`); J nnz: nonzeros of "
                "the Jacobian (the wider quasi-symmetric stencil with a coarse slave); s: wall seconds",
                ["lower:upper cells", "h_s/h_m", "rule", "Newton", "max\\|szz+p\\|/p", "force", "master pen",
                 "J nnz", "s"], rows)


def table_materials(args):
    rows = []
    for ratio in E_RATIOS:
        for lower, upper in ((2, 2), (2, 3)):
            for formulation in FORMULATIONS:
                r = measure(scene(sets=cells(lower, upper) + moduli(ratio) + [f"contact.0.formulation={formulation}"]))
                rows.append("| " + " | ".join([
                    f"E ratio {ratio:g}", f"{lower}/{upper}", formulation, str(r["newton"]), fmt(r["stress_error"]),
                    fmt(abs(penetration_ratio(r) - 1.0)) if lower == upper else "-", fmt(force_error(r))]) + " |")
    for nu in NUS:
        for nu_lower, label in ((nu, "both"), (0.0, "upper only"))[:2 if nu else 1]:
            for lower, upper in ((2, 2), (2, 3)):
                sets = cells(lower, upper) + [f"bodies.0.material.poissons_ratio={nu_lower}",
                                              f"bodies.1.material.poissons_ratio={nu}"]
                for formulation in FORMULATIONS:
                    r = measure(scene(sets=sets + [f"contact.0.formulation={formulation}"]))
                    rows.append("| " + " | ".join([
                        f"nu {nu} ({label})", f"{lower}/{upper}", formulation, str(r["newton"]),
                        fmt(r["stress_error"]), fmt(abs(penetration_ratio(r) - 1.0)) if lower == upper else "-",
                        fmt(force_error(r))]) + " |")
    print("materials done", flush=True)
    write_table(DOCS, "Stiffness and Poisson's ratio", "stability.py",
                "patch test, one layer per block, matching (2/2) and non-matching (2/3) in-plane cells, "
                "alpha 1e4, MUMPS, serial. E ratio = E_upper/E_lower with the softer body at 1000 Pa (eps_n "
                "uses the smaller E); nu on both blocks, or on the upper block with nu = 0 below (the "
                "interface then slides). pen: |mean slave row penetration/(p/eps_n) - 1| (matching only); "
                "force: |total contact force - pA|/pA",
                ["case", "lower/upper", "formulation", "Newton", "max\\|szz+p\\|/p", "pen", "force"], rows)


def table_units(args):
    rows = []
    cases = [(f"patch 2/3, {f}", PATCH, cells(2, 3) + [f"contact.0.formulation={f}"], 1.0) for f in FORMULATIONS]
    cases.append(("two cubes between sticking dies, 2^3/3^3", CUBES,
                  ["bodies.0.mesh.cells=[2,2,2]", "bodies.1.mesh.cells=[3,3,3]"], 1.0))
    for label, path, sets, p in cases:
        ref = measure(scene(path, sets), p=p)
        for s in SCALES:
            r = measure(scene(path, sets, edit=scaled(s)), p=p, length=s)
            rows.append("| " + " | ".join([
                label, f"{s:g}", r["status"], str(r["newton"]), fmt(float(np.abs(r["u"]).max())),
                fmt(relative_difference(r["u"], ref["u"])), fmt(float(np.abs(r["stress"] - ref["stress"]).max()))])
                + " |")
    print("units done", flush=True)
    write_table(DOCS, "Length units", "stability.py",
                "the same physical scene with every length times s (boxes, die points and motions; pressures "
                "and moduli unchanged, so strains and stresses are the same and displacements scale with s); "
                "alpha 1e4, MUMPS, serial. u/s: the largest displacement in units of s; du: max |u/s - u_ref| "
                "/ max |u_ref| against s = 1; dsigma: max |sigma - sigma_ref| / p (p = 1 Pa for the patch test, "
                "1 Pa scale for the cubes)",
                ["scene", "s", "status", "Newton", "max \\|u\\|/s", "du", "dsigma"], rows)


def table_special(args):
    rows = []
    cases, sigma_fit = special_cases()
    for name, expected, sc in cases:
        r = measure(sc)
        if r["status"] != "ok":
            measured = r["message"]
        elif "held by uz" in name:
            measured = (f"contact force {r['pair']['total_normal_force']:.3g} N, active rows "
                        f"{r['pair']['active_rows']} of {r['pair']['rows']}, max \\|sigma\\| "
                        f"{np.abs(r['stress']).max():.1e} Pa, gap left {-r['pair']['max_penetration_slave']:.6g} m")
        elif "clamped" in name:
            szz = r["stress"][:, 2]
            measured = (f"szz from {szz.min():.8g} to {szz.max():.8g} Pa: max \\|szz/sigma_fit + 1\\| "
                        f"{np.abs(szz / sigma_fit + 1.0).max():.1e}")
        elif "pair" in r:
            measured = (f"max\\|szz+p\\|/p {r['stress_error']:.2e}, contact force {r['pair']['total_normal_force']:.6g}"
                        f" N, pen/(p/eps_n) {penetration_ratio(r):.6g}")
        else:
            die = next(iter(r["dies"].values()))
            measured = f"max\\|szz+p\\|/p {r['stress_error']:.2e}, die force z {die['force_on_bodies'][2]:.6g} N"
        rows.append(f"| {name} | {expected} | {r['status']} | {r.get('newton', '-')} | {measured} |")
    for element, lower, upper in TIE_CASES:
        for formulation in FORMULATIONS:
            ref = measure(scene(sets=tie_sets(element, lower, upper, formulation)))
            shifted = [measure(scene(sets=tie_sets(element, lower, upper, formulation, d))) for d in (1e-12, -1e-12)]
            jump = max(relative_difference(s["u"], ref["u"]) for s in shifted)
            rows.append(f"| nodes on edges and vertices: {element} {lower}/{upper}, {formulation} | converges; "
                        f"continuous under a 1e-12 m shift | {ref['status']} | {ref['newton']} | "
                        f"max\\|szz+p\\|/p {ref['stress_error']:.2e}, u change under +-1e-12 m shift {jump:.1e} |")
    print("special cases done", flush=True)
    write_table(DOCS, "Gaps, penetration, ties and holding", "stability.py",
                "patch-test blocks (2 x 2 x 1 cells unless said), p = 1 Pa, alpha 1e4, MUMPS, serial. "
                "'held only by contact': the upper block has no displacement boundary along z; a body that the "
                "boundaries and the contact rows within reach leave free is a SceneError before any solve, and a "
                "solve whose iterate leaves a body free (all its rows open) stops with a ConvergenceError naming "
                "the body and motion (qsc_petsc/restraint.py)",
                ["case", "expected", "outcome", "Newton", "measured"], rows)
    return sigma_fit


def table_parallel(args):
    rows = []
    for n in args.ranks:
        with tempfile.TemporaryDirectory(prefix="qsc_stab_par_") as tmp:
            path = Path(tmp) / "rows.json"
            cmd = ["mpirun", "--oversubscribe", "-n", str(n), sys.executable, __file__, "--parallel-json", str(path)]
            subprocess.run(cmd, env=ENV, check=True, timeout=1800)
            for r in json.loads(path.read_text()):
                head = [str(r["ranks"]), r["layout"], ",".join(map(str, r["slave_ranks"])),
                        ",".join(map(str, r["master_ranks"])), r["formulation"], r["case"]]
                if r["status"] != "ok":
                    rows.append("| " + " | ".join(head + [r["status"], "-", "-", "-", r["message"]]) + " |")
                    continue
                relax = r["mumps_icntl_14"]
                rows.append("| " + " | ".join(head + [
                    "ok", f"{r['newton']} ({r['serial_newton']})", fmt(r["u_difference"]), fmt(r["force_difference"]),
                    fmt(r["stress_error"]) + (f"; MUMPS ICNTL(14) raised to {relax}" if relax else "")]) + " |")
        print(f"parallel {n} ranks done", flush=True)
    write_table(DOCS, "Interface on one rank or split across ranks", "stability.py",
                "patch test under the simple partitioner (cells in order): 'one_rank' adds a bystander body "
                "(8 x 8 x 4 cells, on rollers under the same pressure) after the blocks (4/6 cells) so that rank 0 "
                "owns the whole interface; 'split' "
                "uses thin blocks (5/7 cells, one layer) so that the slave surface is cut between ranks and every "
                "rank owns interface faces. Each run is compared with the same scene on one rank: du = max "
                "\\|u_N - u_1\\| / max \\|u_1\\|, dF = \\|total contact force N - 1\\| [N]",
                ["ranks", "layout", "slave on ranks", "master on ranks", "formulation", "case", "outcome",
                 "Newton N (1)", "du", "dF", "max\\|szz+p\\|/p; notes"], rows)


TABLES = {"alpha": table_alpha, "ratio": table_ratio, "materials": table_materials, "units": table_units,
          "special": table_special, "parallel": table_parallel}


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--ranks", type=int, nargs="*", default=[2, 3], help="rank counts of the parallel table")
    ap.add_argument("--parallel-json", help=argparse.SUPPRESS)   # internal: the parallel table's worker
    ap.add_argument("--tables", nargs="+", choices=sorted(TABLES), default=sorted(TABLES),
                    help="the tables to (re)write (default: all)")
    args = ap.parse_args()
    if args.parallel_json:
        comm = MPI.COMM_WORLD
        tmp = comm.bcast(tempfile.mkdtemp(prefix="qsc_stab_") if comm.rank == 0 else None, root=0)
        rows = parallel_table(comm, tmp)
        comm.Barrier()
        if comm.rank == 0:
            Path(args.parallel_json).write_text(json.dumps(rows))
            shutil.rmtree(tmp, ignore_errors=True)
        return
    if not DOCS.exists():
        DOCS.write_text("# Stability at the extremes\n\nMeasured on this project's machines (2 cores, shared); "
                        "every table says the command that made it. Tests: tests/test_extremes.py, "
                        "tests/parallel/test_extremes_parallel.py.\n")
    os.chdir(ROOT)
    for name, table in TABLES.items():
        if name in args.tables and (name != "parallel" or args.ranks):
            table(args)


if __name__ == "__main__":
    main()
