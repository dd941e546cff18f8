#!/usr/bin/env python3
"""The contact patch test table: every mesh pair, formulation, slave choice and penalty.

configs/patch_test.toml (pressure p = 1 on two stacked blocks; the exact solution is sigma_zz = -p
everywhere) with lower/upper in-plane cells (4,5), (4,7), (2,8), (8,2), (3,10) and matching (4,4);
master_slave, two_pass, quasi_symmetric (w = 0.5) and quasi_symmetric (w = "finer"); the upper or
the lower block as slave; alpha = 1e2, 1e4, 1e6. Writes docs/patch_table.csv and the Markdown table
into docs/verification.md. Usage: .venv/bin/python scripts/patch_table.py [--alphas 1e4] (serial).
"""

import argparse
import csv
import sys
from pathlib import Path

import numpy as np
from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))
from benchlib import add_docs_args, write_table

PAIRS = [(4, 5), (4, 7), (2, 8), (8, 2), (3, 10), (4, 4)]
FORMULATIONS = [("master_slave", None), ("two_pass", None), ("quasi_symmetric", 0.5), ("quasi_symmetric", "finer")]
SIDES = {"upper": ("upper.zmin", "lower.zmax"), "lower": ("lower.zmax", "upper.zmin")}
COLUMNS = ["lower", "upper", "formulation", "weight", "slave", "alpha", "max_stress_error", "rms_stress_error",
           "max_traction_error", "max_pen_slave", "max_pen_master", "newton", "swap_difference"]


def solve(lower, upper, formulation, weight, slave, alpha, extra=()):
    """One patch test; returns the table's measures and the displacement in original vertex order.

    extra: more --set overrides (e.g. contact.0.integration=gauss)."""
    from qsc_petsc.run import Run
    from qsc_petsc.scene import load_scene
    s_ref, m_ref = SIDES[slave]
    sets = [f"bodies.0.mesh.cells=[{lower},{lower},2]", f"bodies.1.mesh.cells=[{upper},{upper},2]",
            f"contact.0.formulation={formulation}", f"contact.0.slave={s_ref}", f"contact.0.master={m_ref}",
            f"contact.0.penalty={alpha}", "load.steps=1", "output.xdmf=false",
            "contact.0.integration=nodal", *extra]      # the table is about node-to-segment rows unless extra says
    if weight is not None:
        sets.append(f"contact.0.weight={weight}")
    scene = load_scene(ROOT / "configs" / "patch_test.toml", sets)
    run = Run(scene, MPI.COMM_SELF, ROOT / "results" / "patch_table", log=lambda *a: None)
    summary = run.execute()
    _, cell, ul = run.fields(run.u)
    contact_fields, _ = run.contact.report(run.u, ul)
    szz = cell["stress"][:, 2]
    err = np.abs(szz + 1.0)                       # p = 1
    mesh = run.mesh
    on_surface = np.zeros(len(mesh.coords), dtype=bool)
    for name in ("upper.zmin", "lower.zmax"):
        on_surface[mesh.surface_vertices(name)] = True
    traction = contact_fields["contact_traction"][on_surface, 0]
    pair = next(iter(summary["steps"][-1]["contact"].values()))
    u = ul[np.argsort(mesh.vert_orig)]
    run.destroy()
    return {"max_stress_error": err.max(), "rms_stress_error": np.sqrt(np.mean(err ** 2)),
            "max_traction_error": np.abs(traction - 1.0).max(), "max_pen_slave": pair["max_penetration_slave"],
            "max_pen_master": pair["max_penetration_master"], "newton": summary["steps"][-1]["snes_iterations"],
            "points": pair["quadrature_points"], "G_nonzeros": pair["G_nonzeros"],
            "time": summary["time"]}, u


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--alphas", nargs="+", default=["1e2", "1e4", "1e6"])
    add_docs_args(ap, "Contact patch test table", petsc=False)
    args = ap.parse_args()
    rows = []
    for lower, upper in PAIRS:
        for formulation, weight in FORMULATIONS:
            for alpha in args.alphas:
                results = {side: solve(lower, upper, formulation, weight, side, alpha) for side in SIDES}
                ua, ub = results["upper"][1], results["lower"][1]
                swap = np.linalg.norm(ua - ub) / np.linalg.norm(ua)
                for side in SIDES:
                    row = {"lower": lower, "upper": upper, "formulation": formulation,
                           "weight": "" if weight is None else weight, "slave": side, "alpha": alpha,
                           **results[side][0], "swap_difference": swap}
                    rows.append(row)
                print(f"({lower},{upper}) {formulation} {weight or ''} alpha {alpha}: max err "
                      f"{rows[-2]['max_stress_error']:.2e} / {rows[-1]['max_stress_error']:.2e}, swap {swap:.1e}",
                      flush=True)
    docs = ROOT / "docs"
    # the table's columns only, written whole or not at all (a failed write left the header alone)
    tmp = docs / "patch_table.csv.tmp"
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    tmp.replace(docs / "patch_table.csv")
    fmt = lambda x: f"{x:.2e}" if isinstance(x, float) else str(x)
    headers = ["lower", "upper", "formulation", "weight", "slave", "alpha", "max \\|szz+p\\|/p", "rms",
               "max traction err", "max pen slave", "max pen master", "Newton", "swap diff"]
    description = ("serial, MUMPS; CSV: docs/patch_table.csv. Stress errors over cells, traction error over the "
                   "nodes of both contact surfaces (force-based nodal traction), penetrations in m, swap diff = "
                   "||u(upper slave) - u(lower slave)|| / ||u(upper slave)|| (same on both rows)")
    write_table(docs / "verification.md", args.title, "patch_table.py", description, headers,
                ["| " + " | ".join(fmt(r[c]) for c in COLUMNS) + " |" for r in rows])


if __name__ == "__main__":
    main()
