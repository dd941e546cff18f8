#!/usr/bin/env python3
"""The speed/accuracy trade (issue 5, part 2): reruns every `qsc sweep` of docs/tradeoff.md and rewrites its tables.

Three scenes, each measured with qsc sweep (qsc_petsc/sweep.py: every run its own `qsc run` on 1 rank,
compared with a reference run by qsc_petsc/compare.py); sweeps go to results/tradeoff/<name>/:
  * patch: configs/patch_test.toml (non-matching 4x4 / 7x7), formulation x alpha x integration, and
    quasi_symmetric's weight {power = 4} against the paper's 0.5; reference: the matching 4x4 / 4x4 mesh
    at alpha 1e8, which is exact for this problem (linear displacement; the penalty's rigid shift of
    the upper block is p/eps_n = 2.5e-12 m); plus max |sigma_zz + p| / p from each run's cell stresses.
  * cubes: configs/two_cubes_quarter.toml (sticking dies), formulation x refinement (lower n x n x 2n,
    upper 1.5n x 1.5n x 3n) x solver. The solver is one key, petsc.pc_type = lu | gamg, with
    petsc.ksp_type = cg for both: CG preconditioned by the exact MUMPS factorisation converges in one
    iteration per Newton step (the same answer and time as the scene's preonly, checked in the doc), so
    no nonsense (preonly, gamg) pair is made; nodal rows with both solvers, segment integration with
    LU. Sweeps per level (the two cell counts move together) share one reference run, matching
    24 x 24 x 48 cells on both bodies, solved once; its own error is estimated from the matching 12
    and 16 runs (two more sweeps against it).
  * hertz: configs/hertz_{coarse,medium}.toml, formulation x integration x sliding; reference: Hertz's
    analytical peak pressure and contact radius at each run's measured force (scripts/hertz.py's
    measures). The sweep's own error columns there compare with its first run and are not used.
Writes the tables into docs/tradeoff.md (sections replaced, the rest of the file kept) and
docs/tradeoff_patch.png, docs/tradeoff_cubes.png. Usage:
  .venv/bin/python scripts/tradeoff.py [--parts patch cubes hertz] [--no-run]      (about 15 minutes)
"""

import argparse
import csv
import json
import math
import os
import shlex
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))
sys.path.insert(0, str(ROOT))
from benchlib import ENV, write_table

DOC = ROOT / "docs" / "tradeoff.md"
RESULTS = ROOT / "results" / "tradeoff"
PATCH = "configs/patch_test.toml"
CUBES = "configs/two_cubes_quarter.toml"
FORMULATIONS = ("master_slave", "two_pass", "quasi_symmetric")
ALPHAS = ("1e2", "1e4", "1e6")
WEIGHTS = ("0.5", "{power=4}")
CUBE_LEVELS = (4, 6, 8, 12)          # n: quarter lower n x n x 2n cells, upper 1.5n x 1.5n x 3n
CUBE_REFERENCE = 24                  # matching m x m x 2m cells on both bodies
CUBE_CHECKS = (12, 16)               # matching runs that measure the reference's own error
SOLVERS = {"lu": "MUMPS LU", "gamg": "CG + GAMG"}
HERTZ_LEVELS = ("coarse", "medium")
SLIDINGS = ("finite", "small")       # a new search every load step, or one in the undeformed configuration
# Gauss and segment points change the active set by a few points per Newton step (scripts/hertz.py)
HERTZ_ITERATIONS = 80


def integrations():
    """nodal and gauss; segment too when exact (clipped) integration is available."""
    try:
        import qsc_petsc.contact.clipping  # noqa: F401
    except ImportError:
        return ("nodal", "gauss")
    return ("nodal", "gauss", "segment")


def load_note():
    """The 1, 5 and 15 minute load averages and the core count, as `uptime` and nproc report them."""
    one, five, fifteen = os.getloadavg()
    return f"load average {one:.2f} / {five:.2f} / {fifteen:.2f} on {os.cpu_count()} cores"


# ---------------------------------------------------------------- running the sweeps

def sweep(name, argv, no_run=False, reference=None):
    """Run `qsc sweep <argv> --out results/tradeoff/<name>` (or, with no_run, read its last CSV).

    Returns (the sweep's reference record or None, the rows of its sweep.csv as dicts)."""
    from qsc_petsc import sweep as qsweep
    out = RESULTS / name
    argv = [*argv, "--out", str(out.relative_to(ROOT))]
    print(f"$ qsc sweep {shlex.join(argv)}" + ("  (reference reused)" if reference else ""), flush=True)
    ref = None
    if not no_run:
        rows = qsweep.sweep(qsweep.make_plan(argv), reference=reference)
        ref = rows[0]
        if ref["status"] != "ok":
            raise RuntimeError(f"{name}: the reference run failed: {ref['message']}")
    with open(out / "sweep.csv", newline="") as f:
        return ref, list(csv.DictReader(f))


NOT_OK = []        # runs that failed or did not converge, named in their section's description


def runs(rows):
    """The combinations' rows (not the reference row) that succeeded; the others go to NOT_OK."""
    kept = []
    for r in rows[1:]:
        if r["status"] != "ok":
            NOT_OK.append(f"{Path(r['folder']).parent.name}/{r['run']}: {r['status']} ({r['message']})")
            print(f"  not ok: {NOT_OK[-1]}", flush=True)
            continue
        kept.append(r)
    return kept


def timing_note(args, count, before, elapsed):
    """How long the part's runs took and the machine's load around them (or that nothing was rerun)."""
    if args.no_run:
        return (f"{count}; tables rebuilt with --no-run from the sweeps already in results/tradeoff, whose "
                f"load averages are not recorded here")
    return f"{count} in {elapsed:.0f} s; {before} before, {load_note()} after"


def not_ok_note():
    """'; not ok: ...' for the runs that failed since the last call, or '' if none did."""
    note = f"; NOT OK (left out of the table): {'; '.join(NOT_OK)}" if NOT_OK else "; every run converged"
    NOT_OK.clear()
    return note


def summary(row):
    return json.loads((ROOT / row["folder"] / "summary.json").read_text())


def pair_stats(row):
    """(quadrature points, nonzeros of G) of the run's first contact pair at its last load step."""
    pair = next(iter(summary(row)["steps"][-1]["contact"].values()))
    return pair["quadrature_points"], pair["G_nonzeros"]


def stress_error(row):
    """max |sigma_zz + p| / p over the cells (cell-centre stresses of the last step); p from the scene."""
    import tomllib

    import h5py

    from qsc_petsc.output import VOIGT_TO_TENSOR6
    folder = ROOT / row["folder"]
    scene = tomllib.loads((folder / "scene.resolved.toml").read_text())
    p = next(b["value"] for b in scene["boundary"] if b["type"] == "pressure")
    with h5py.File(folder / "solution.h5", "r") as h5:
        last = max(k for k in h5 if k.startswith("step_"))
        szz = h5[f"{last}/stress"][:, VOIGT_TO_TENSOR6.index(2)]      # the file's order is XDMF's Tensor6
    return float(np.abs(szz + p).max() / p)


def fmt(x, spec=".2e"):
    return "-" if x is None or x == "" else format(float(x), spec)


def seconds(row):
    return float(row["run_time_s"])


def krylov_per_newton(row):
    return int(row["krylov_iterations"]) / int(row["newton_iterations"])


# ---------------------------------------------------------------- 1. patch test

def patch(args):
    common = [PATCH, "--vary", f"contact.0.penalty={','.join(ALPHAS)}",
              "--vary", f"contact.0.integration={','.join(integrations())}",
              "--reference", "bodies.1.mesh.cells=[4,4,2]", "--reference", "contact.0.penalty=1e8",
              "--reference", "contact.0.integration=nodal"]
    before = load_note()
    t0 = time.perf_counter()
    # quasi_symmetric's weight only exists for quasi_symmetric: two sweeps instead of a product with
    # duplicated master_slave/two_pass runs
    _, rows_f = sweep("patch_formulations", [*common, "--vary", f"contact.0.formulation={','.join(FORMULATIONS)}"],
                      args.no_run)
    _, rows_w = sweep("patch_weight", [*common, "--vary", "contact.0.weight={power=4}",
                                       "--set", "contact.0.formulation=quasi_symmetric"], args.no_run)
    elapsed = time.perf_counter() - t0
    records = []
    for r in runs(rows_f):
        weight = "0.5" if r["contact.0.formulation"] == "quasi_symmetric" else ""
        records.append(dict(r, formulation=r["contact.0.formulation"], weight=weight))
    for r in runs(rows_w):
        records.append(dict(r, formulation="quasi_symmetric", weight="{power=4}"))
    order = {f: i for i, f in enumerate(integrations())}
    records.sort(key=lambda r: (order[r["contact.0.integration"]], FORMULATIONS.index(r["formulation"]),
                                r["weight"], float(r["contact.0.penalty"])))
    table = []
    for r in records:
        r["szz"] = stress_error(r)
        points, nnz = pair_stats(r)
        table.append("| " + " | ".join([
            r["formulation"], r["weight"] or "-", r["contact.0.integration"], r["contact.0.penalty"],
            r["newton_iterations"], str(points), str(nnz), fmt(r["run_time_s"], ".3f"), fmt(r["displacement_l2"]),
            fmt(r["energy"]), fmt(r["traction"]), fmt(r["szz"])]) + " |")
    columns = ["formulation", "weight", "integration", "alpha", "Newton", "quad points", "G nnz", "run s",
               "u L2", "energy", "traction", "max\\|szz+p\\|/p"]
    description = (
        f"configs/patch_test.toml: lower 4 x 4 x 2, upper 7 x 7 x 2 cells (slave = upper), p = 1 Pa, "
        f"801 dofs, MUMPS, 1 rank; sweeps `qsc sweep {PATCH} --vary contact.0.formulation="
        f"{','.join(FORMULATIONS)} --vary contact.0.penalty={','.join(ALPHAS)} --vary contact.0.integration="
        f"{','.join(integrations())} --reference bodies.1.mesh.cells=[4,4,2] --reference contact.0.penalty=1e8 "
        f"--reference contact.0.integration=nodal` and the same with `--set contact.0.formulation="
        f"quasi_symmetric --vary contact.0.weight={{power=4}}` (results/tradeoff/patch_*). Reference: the "
        f"matching 4 x 4 mesh at alpha 1e8, exact for this problem (every formulation reproduces the linear "
        f"solution on matching meshes; its penalty shift is 2.5e-12 m against displacements of 1e-3 m). "
        f"gauss: 3 x 3 points per face (the default contact.0.gauss_points); segment: exact integration over "
        f"the overlaps of the two surfaces' faces. u L2, energy: relative displacement errors in the L2 and energy norms; traction: relative RMS "
        f"error of the nodal contact traction at the run's contact nodes; max\\|szz+p\\|/p: the exact "
        f"answer's own test, over the cell-centre stresses; quad points: points projected (both passes); "
        f"G nnz: nonzeros of the constraint matrix; run s: sum of the phases, 1 rank. "
        f"{timing_note(args, f'{len(records)} runs', before, elapsed)}{not_ok_note()}")
    write_table(DOC, "Patch test", "tradeoff.py", description, columns, table)
    plot_patch(records, ROOT / "docs" / "tradeoff_patch.png")


def plot_patch(records, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rules = integrations()
    fig, axes = plt.subplots(1, len(rules), figsize=(4.2 * len(rules), 4), sharey=True)
    floor = 1e-16                      # exact runs drawn at the floor of the log axis
    for ax, rule in zip(np.atleast_1d(axes), rules):
        for (f, w), style in zip([(f, "0.5" if f == "quasi_symmetric" else "") for f in FORMULATIONS]
                                 + [("quasi_symmetric", "{power=4}")], ("s-", "o-", "^-", "v--")):
            rs = [r for r in records if r["contact.0.integration"] == rule and (r["formulation"], r["weight"]) == (f, w)]
            if rs:
                ax.plot([float(r["contact.0.penalty"]) for r in rs], [max(r["szz"], floor) for r in rs], style,
                        label=f + (f", w={w}" if w else ""))
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(f"integration = {rule}", fontsize=10)
        ax.set_xlabel("penalty alpha")
        ax.grid(alpha=0.3, which="both")
    np.atleast_1d(axes)[0].set_ylabel("max |sigma_zz + p| / p")
    np.atleast_1d(axes)[0].legend(fontsize=8)
    fig.suptitle("Patch test, non-matching 4x4 / 7x7 (exact answer: 0)", fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


# ---------------------------------------------------------------- 2. two cubes

def cube_cells(n):
    return f"[{n},{n},{2 * n}]", f"[{3 * n // 2},{3 * n // 2},{3 * n}]"


def cube_reference_args():
    m = f"[{CUBE_REFERENCE},{CUBE_REFERENCE},{2 * CUBE_REFERENCE}]"
    return ["--reference", f"bodies.0.mesh.cells={m}", "--reference", f"bodies.1.mesh.cells={m}",
            "--reference", "contact.0.formulation=master_slave", "--reference", "petsc.pc_type=lu",
            "--reference", "contact.0.integration=nodal"]


def cube_integrations():
    """nodal, and segment when it is available (Gauss points are left to the patch test and Hertz)."""
    return tuple(i for i in integrations() if i != "gauss")


def cube_argv(lower, upper, formulations, pc_types, integration):
    """A two-cube sweep: the same varied keys in the same order in every one, so that they share a reference."""
    return [CUBES, "--vary", f"bodies.0.mesh.cells={lower}", "--vary", f"bodies.1.mesh.cells={upper}",
            "--vary", f"contact.0.formulation={','.join(formulations)}", "--vary", f"petsc.pc_type={','.join(pc_types)}",
            "--vary", f"contact.0.integration={integration}", "--set", "petsc.ksp_type=cg", *cube_reference_args()]


def richardson(h, f):
    """f(h) = f0 + C h^r through three (h, f) points: returns (f0, r), or (None, None) if not monotone."""
    (h1, f1), (h2, f2), (h3, f3) = sorted(zip(h, f), reverse=True)
    ratio = (f1 - f3) / (f2 - f3)
    if not ratio > 1.0:
        return None, None

    def g(r):
        return (h1 ** r - h3 ** r) / (h2 ** r - h3 ** r) - ratio
    lo, hi = 0.05, 8.0
    if g(lo) * g(hi) > 0:
        return None, None
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if g(lo) * g(mid) > 0 else (lo, mid)
    r = 0.5 * (lo + hi)
    return f3 - (f2 - f3) / ((h2 / h3) ** r - 1.0), r


def top_die_fz(row):
    dies = summary(row)["steps"][-1]["contact"]
    return next(v for k, v in dies.items() if k.startswith("die[1]"))["force_on_bodies"][2]


def fit_exponent(dofs, values):
    """k and c of values ~ c dofs^k by least squares in log-log."""
    k, logc = np.polyfit(np.log(np.asarray(dofs, float)), np.log(np.asarray(values, float)), 1)
    return float(k), float(math.exp(logc))


def cubes(args):
    before = load_note()
    t0 = time.perf_counter()
    ref = None
    rows = []
    for n in CUBE_LEVELS:
        lower, upper = cube_cells(n)
        # nodal rows with both solvers; segment integration with LU only (the solver does not change the answer)
        for name, pcs, integration in ((f"cubes_n{n}", ("lu", "gamg"), "nodal"),
                                       (f"cubes_n{n}_segment", ("lu",), "segment"))[:len(cube_integrations())]:
            r, level_rows = sweep(name, cube_argv(lower, upper, FORMULATIONS, pcs, integration), args.no_run, ref)
            ref = ref or r
            rows += [dict(x, level=n) for x in runs(level_rows)]
            reference_row = level_rows[0]
    checks = []
    for m in CUBE_CHECKS:
        cells = f"[{m},{m},{2 * m}]"
        _, check_rows = sweep(f"cubes_check_m{m}", cube_argv(cells, cells, ("master_slave",), ("lu",), "nodal"),
                              args.no_run, ref)
        checks += [dict(x, m=m) for x in runs(check_rows)]
    # the scene's own solver (preonly + LU) against the sweep's CG + LU, on one level
    _, same = sweep("cubes_preonly", [CUBES, "--vary", "petsc.ksp_type=preonly,cg", "--set", "contact.0.integration=nodal",
                                      *cube_cells_args(8)], args.no_run)
    elapsed = time.perf_counter() - t0

    # reference: its own error, from the matching runs (differences against it) and a Richardson fit
    h = {m: 0.5 / m for m in (*CUBE_CHECKS, CUBE_REFERENCE)}
    fz = {c["m"]: top_die_fz(c) for c in checks}
    fz[CUBE_REFERENCE] = top_die_fz(reference_row)
    f0, rate = richardson([h[m] for m in fz], list(fz.values()))
    d = {c["m"]: float(c["displacement_l2"]) for c in checks}
    m1, m2 = CUBE_CHECKS
    # e(m) = C h^r: the two differences against the reference give r, then the reference's own e
    u_rate = _difference_rate(d[m1], d[m2], h[m1], h[m2], h[CUBE_REFERENCE])
    u_own = (d[m2] / ((h[m2] / h[CUBE_REFERENCE]) ** u_rate - 1.0)) if u_rate else None
    fz_own = abs(fz[CUBE_REFERENCE] - f0) / abs(f0) if f0 is not None else None
    check_table = []
    for c in sorted(checks, key=lambda c: c["m"]) + [dict(reference_row, m=CUBE_REFERENCE)]:
        is_ref = c["m"] == CUBE_REFERENCE
        check_table.append("| " + " | ".join([
            f"{c['m']} x {c['m']} x {2 * c['m']}" + (" (reference)" if is_ref else ""), c["dofs"],
            fmt(c["run_time_s"], ".1f"), fmt(c["peak_memory_total_mib"], ".0f"),
            "0" if is_ref else fmt(c["displacement_l2"]), "0" if is_ref else fmt(c["energy"]),
            "0" if is_ref else fmt(c["traction"]), f"{fz[c['m']]:.6f}",
            fmt(abs(fz[c["m"]] - f0) / abs(f0)) if f0 is not None else "-"]) + " |")
    same_rows = runs(same)
    pre = next(r for r in same_rows if r["petsc.ksp_type"] == "preonly")
    cg = next(r for r in same_rows if r["petsc.ksp_type"] == "cg")
    check_desc = (
        f"configs/two_cubes_quarter.toml with matching meshes, m x m x 2m cells on both bodies, MUMPS, 1 rank "
        f"(results/tradeoff/cubes_check_m*, compared with the reference run of results/tradeoff/cubes_n"
        f"{CUBE_LEVELS[0]}). Columns: differences against the reference (relative, as in the table below); "
        f"top die Fz: the top die's z force on the bodies [N] (quarter model), and its difference from the "
        f"Richardson extrapolation Fz(h) = Fz0 + C h^r through the three matching runs: Fz0 = "
        f"{f0:.6f} N, r = {rate:.2f}. The u L2 differences fall like h^{u_rate:.2f}, which puts the "
        f"reference's own u L2 error at about {fmt(u_own)}; its Fz error is {fmt(fz_own)}. The energy-norm "
        f"and traction differences hardly fall (the sticking dies and the interface perimeter make stress "
        f"singularities at the cube edges): they are not converged here and the table below does not use "
        f"them. The scene's own solver, preonly + LU, against the sweep's CG + LU (results/tradeoff/"
        f"cubes_preonly, n = 8, {pre['dofs']} dofs): u L2 difference {fmt(cg['displacement_l2'])}, "
        f"Newton {pre['newton_iterations']} / {cg['newton_iterations']}, Krylov {pre['krylov_iterations']} / "
        f"{cg['krylov_iterations']}, run {fmt(pre['run_time_s'], '.2f')} / {fmt(cg['run_time_s'], '.2f')} s")
    write_table(DOC, "Two cubes: the reference", "tradeoff.py", check_desc,
                ["matching cells", "dofs", "run s", "memory MiB", "u L2 diff", "energy diff", "traction diff",
                 "top die Fz [N]", "Fz vs Fz0"], check_table)

    rows.sort(key=lambda r: (list(SOLVERS).index(r["petsc.pc_type"]), r["contact.0.integration"] != "nodal",
                             FORMULATIONS.index(r["contact.0.formulation"]), r["level"]))
    table = []
    for r in rows:
        r["fz_error"] = abs(top_die_fz(r) - f0) / abs(f0) if f0 is not None else None
        table.append("| " + " | ".join([
            SOLVERS[r["petsc.pc_type"]], r["contact.0.integration"], r["contact.0.formulation"], str(r["level"]),
            r["dofs"],
            r["newton_iterations"], r["krylov_iterations"], fmt(r["run_time_s"], ".2f"), fmt(r["time_solve_s"], ".2f"),
            fmt(r["peak_memory_total_mib"], ".0f"), fmt(r["displacement_l2"]), fmt(r["force"]),
            fmt(r["force[contact[0]]"]), fmt(r["fz_error"])]) + " |")
    description = (
        f"configs/two_cubes_quarter.toml (quarter of two unit cubes between sticking dies, top die down "
        f"0.02 m in 2 load steps, alpha 1e4), level n: lower n x n x 2n, upper 1.5n x 1.5n x 3n cells; "
        f"1 rank. Per level, nodal rows with both solvers, e.g. `qsc sweep "
        f"{shlex.join(cube_argv(*cube_cells(8), FORMULATIONS, ('lu', 'gamg'), 'nodal'))}` "
        f"(results/tradeoff/cubes_n*), and segment integration with LU (`--vary petsc.pc_type=lu --vary "
        f"contact.0.integration=segment`, results/tradeoff/cubes_n*_segment); the script solves the shared "
        f"reference once. Solvers: MUMPS LU "
        f"(pc_type = lu, the scene's pc_factor_mat_solver_type = mumps) and CG + GAMG (pc_type = gamg; "
        f"solver.contact_preconditioner = auto adds the exact solve on the contact band). Reference: matching "
        f"{CUBE_REFERENCE} x {CUBE_REFERENCE} x {2 * CUBE_REFERENCE} cells on both bodies (table above). "
        f"u L2: relative displacement error against it; force: largest relative error of the contact and die "
        f"force vectors; contact F: the pair's force vector; Fz vs Fz0: the top die's z force against the "
        f"extrapolated Fz0. run s: sum of the phases; memory: peak resident set. "
        f"{timing_note(args, f'{len(rows)} runs and {len(checks) + 3} checks', before, elapsed)}{not_ok_note()}")
    write_table(DOC, "Two cubes", "tradeoff.py", description,
                ["solver", "integration", "formulation", "n", "dofs", "Newton", "Krylov", "run s", "solve s",
                 "memory MiB",
                 "u L2", "force", "contact F", "Fz vs Fz0"], table)

    fits = []
    for pc, integration in solver_groups(rows):
        for f in (*FORMULATIONS, None):
            rs = [r for r in rows if (r["petsc.pc_type"], r["contact.0.integration"]) == (pc, integration)
                  and (f is None or r["contact.0.formulation"] == f)]
            if len({r["level"] for r in rs}) < 2:
                continue
            dofs = [int(r["dofs"]) for r in rs]
            k_all, _ = fit_exponent(dofs, [seconds(r) for r in rs])
            k_solve, _ = fit_exponent(dofs, [float(r["time_solve_s"]) for r in rs])
            top = sorted({r["level"] for r in rs})[-2:]
            rt = [r for r in rs if r["level"] in top]
            k_top, _ = fit_exponent([int(r["dofs"]) for r in rt], [seconds(r) for r in rt])
            k_mem, _ = fit_exponent(dofs, [float(r["peak_memory_total_mib"]) for r in rs])
            k_its, _ = fit_exponent(dofs, [krylov_per_newton(r) for r in rs])
            fits.append("| " + " | ".join([SOLVERS[pc], integration, f or "all three", f"{min(dofs)}-{max(dofs)}", f"{k_all:.2f}",
                                           f"{k_top:.2f}", f"{k_solve:.2f}", f"{k_its:.2f}", f"{k_mem:.2f}"]) + " |")
    write_table(DOC, "Two cubes: cost against dofs", "tradeoff.py",
                "least-squares fits of y ~ c dofs^k in log-log over the levels of the table above, per solver and "
                "integration and formulation and pooled; k run: run time (sum of phases) over all levels; k run, 2 finest: the "
                "same through the two finest levels only; k solve: the solve phase; k Krylov/Newton: Krylov "
                "iterations per Newton iteration (1 for LU); k memory: peak resident set",
                ["solver", "integration", "formulation", "dofs", "k run", "k run, 2 finest", "k solve", "k Krylov/Newton",
                 "k memory"], fits)
    plot_cubes(rows, u_own, ROOT / "docs" / "tradeoff_cubes.png")


def solver_groups(rows):
    """The (pc_type, integration) pairs present, in table order."""
    return sorted({(r["petsc.pc_type"], r["contact.0.integration"]) for r in rows},
                  key=lambda g: (list(SOLVERS).index(g[0]), g[1] != "nodal"))


def cube_cells_args(n):
    lower, upper = cube_cells(n)
    return ["--set", f"bodies.0.mesh.cells={lower}", "--set", f"bodies.1.mesh.cells={upper}"]


def _difference_rate(d1, d2, h1, h2, h_ref):
    """r of e(h) = C h^r from d_i = e(h_i) - e(h_ref), the differences of two coarser runs against the reference."""
    if not d1 > d2 > 0:
        return None

    def g(r):
        return (h1 ** r - h_ref ** r) / (h2 ** r - h_ref ** r) - d1 / d2
    lo, hi = 0.05, 8.0
    if g(lo) * g(hi) > 0:
        return None
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if g(lo) * g(mid) > 0 else (lo, mid)
    return 0.5 * (lo + hi)


def plot_cubes(rows, u_own, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.3))
    colors = dict(zip(FORMULATIONS, ("tab:blue", "tab:orange", "tab:green")))
    markers = {("lu", "nodal"): "o", ("gamg", "nodal"): "s", ("lu", "segment"): "^"}
    lines = {("lu", "nodal"): "k--", ("gamg", "nodal"): "k:", ("lu", "segment"): "k-."}
    for group in solver_groups(rows):
        label = f"{SOLVERS[group[0]]}, {group[1]}"
        rs = [r for r in rows if (r["petsc.pc_type"], r["contact.0.integration"]) == group]
        for f in FORMULATIONS:
            rf = [r for r in rs if r["contact.0.formulation"] == f]
            ax1.plot([int(r["dofs"]) for r in rf], [seconds(r) for r in rf], markers[group], color=colors[f], ms=5)
            ax2.plot([seconds(r) for r in rf], [float(r["displacement_l2"]) for r in rf], markers[group] + "-",
                     color=colors[f], ms=5, lw=0.8, label=f"{f}, {label}")
        dofs = np.array([int(r["dofs"]) for r in rs], float)
        k, c = fit_exponent(dofs, [seconds(r) for r in rs])
        x = np.geomspace(dofs.min(), dofs.max(), 20)
        ax1.plot(x, c * x ** k, lines[group], lw=1, label=f"{label}: time ~ dofs^{k:.2f}")
    if u_own:
        ax2.axhline(u_own, color="0.5", lw=1, ls="--", label="reference's own error (estimate)")
    for ax in (ax1, ax2):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.grid(alpha=0.3, which="both")
    ax1.set_xlabel("dofs")
    ax1.set_ylabel("run time [s] (1 rank, shared machine)")
    ax1.legend(fontsize=8)
    ax1.set_title("cost (o: MUMPS LU, s: CG + GAMG, ^: MUMPS LU + segment)", fontsize=10)
    ax2.set_xlabel("run time [s]")
    ax2.set_ylabel("relative displacement L2 error")
    ax2.set_title("accuracy against time (levels n = " + ", ".join(map(str, CUBE_LEVELS)) + ")", fontsize=10)
    ax2.legend(fontsize=7)
    fig.suptitle("Two cubes between sticking dies (quarter model)", fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


# ---------------------------------------------------------------- 3. Hertz

def hertz_measures(row):
    """scripts/hertz.py's measures (Hertz's a and p0 at the measured force; per surface fit p(0), max t, a)."""
    import h5py
    import hertz as hertz_script

    from qsc_petsc.scene import load_scene
    folder = ROOT / row["folder"]
    s = summary(row)
    scene = load_scene(folder / "scene.resolved.toml")
    pair = next(iter(s["steps"][-1]["contact"].values()))
    with h5py.File(folder / "solution.h5", "r") as h5:
        points = h5["mesh/geometry"][:]
        traction = h5[f"step_{len(s['steps']):04d}/contact_traction"][:, 0]
    measured, _ = hertz_script.measure(scene, points, traction, pair["total_normal_force"])
    return measured


def hertz(args):
    before = load_note()
    t0 = time.perf_counter()
    rows = []
    for level in HERTZ_LEVELS:
        argv = [f"configs/hertz_{level}.toml", "--vary", f"contact.0.formulation={','.join(FORMULATIONS)}",
                "--vary", f"contact.0.integration={','.join(integrations())}",
                "--vary", f"contact.0.sliding={','.join(SLIDINGS)}",
                "--set", f"solver.max_active_set_iterations={HERTZ_ITERATIONS}"]
        _, level_rows = sweep(f"hertz_{level}", argv, args.no_run)
        rows += [dict(r, level=level) for r in runs(level_rows)]
    elapsed = time.perf_counter() - t0
    table = []
    for r in rows:
        m = hertz_measures(r)
        r.update(m)
        points, _ = pair_stats(r)
        p0, a = m["p0_hertz"], m["a_hertz"]
        table.append("| " + " | ".join([
            r["level"], r["contact.0.formulation"], r["contact.0.integration"], r["contact.0.sliding"], r["dofs"],
            r["newton_iterations"],
            str(points), fmt(r["run_time_s"], ".2f"), f"{m['force']:.4f}",
            f"{m['fit_p0_sphere'] / p0 - 1:+.3f} / {m['fit_p0_block'] / p0 - 1:+.3f}",
            f"{m['max_t_sphere'] / p0 - 1:+.3f} / {m['max_t_block'] / p0 - 1:+.3f}",
            f"{m['a_sphere'] / a - 1:+.3f} / {m['a_block'] / a - 1:+.3f}",
            f"{m['h_sphere'] / a:.2f} / {m['h_block'] / a:.2f}"]) + " |")
    description = (
        f"configs/hertz_{{coarse,medium}}.toml (quarter sphere R = 1 m, E = 2000 Pa, on a block, E = 1000 Pa, "
        f"nu = 0.3; sphere = slave; gmsh tets, non-matching contact meshes; alpha 1e4, MUMPS, 1 rank); sweeps "
        f"`qsc sweep configs/hertz_<level>.toml --vary contact.0.formulation={','.join(FORMULATIONS)} --vary "
        f"contact.0.integration={','.join(integrations())} --vary contact.0.sliding={','.join(SLIDINGS)} --set "
        f"solver.max_active_set_iterations={HERTZ_ITERATIONS}` (results/tradeoff/hertz_*); gauss: gauss_points = 3 "
        f"(a symmetric 12-point rule on each triangle); sliding: finite = a new search at each of the 2 load steps, "
        f"small = one search in the undeformed configuration. Against Hertz at each run's measured force F "
        f"(4 x the quarter's): p(0): the centre traction from a fit t = c0 + c2 r^2 over r < a_H/2, relative "
        f"to p0_H; max t: the largest nodal traction relative to p0_H; a: the radius where the nodal traction "
        f"drops to zero (qsc_petsc.hertz.loaded_radius) relative to a_H -- it moves in steps of the node "
        f"spacing, h/a_H the mean face size there. Each pair: sphere surface / block surface (scripts/hertz.py's "
        f"measures). {timing_note(args, f'{len(rows)} runs', before, elapsed)}{not_ok_note()}")
    write_table(DOC, "Hertz", "tradeoff.py", description,
                ["level", "formulation", "integration", "sliding", "dofs", "Newton", "quad points", "run s", "F [N]",
                 "p(0) err", "max t err", "a err", "h/a_H"], table)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--parts", nargs="+", default=["patch", "cubes", "hertz"], choices=["patch", "cubes", "hertz"])
    ap.add_argument("--no-run", action="store_true",
                    help="rebuild the tables from the sweeps already in results/tradeoff (no run)")
    args = ap.parse_args()
    os.chdir(ROOT)                      # scene paths, results/ and the Hertz mesh cache are relative to it
    os.environ.update({k: ENV[k] for k in ("OMPI_ALLOW_RUN_AS_ROOT", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM",
                                           "OMP_NUM_THREADS")})
    uptime = subprocess.run(["uptime"], capture_output=True, text=True, check=False).stdout.strip()
    print(f"uptime: {uptime}", flush=True)
    for part in args.parts:
        {"patch": patch, "cubes": cubes, "hertz": hertz}[part](args)


if __name__ == "__main__":
    main()
