#!/usr/bin/env python3
"""Cost of each contact integration option on the two-cube scene (issue 7): points projected, nonzeros, time per phase.

The scene of bench_contact.py (two unit cubes between sticking rigid dies, upper mesh 1.5x finer, alpha 1e4,
2 load steps), quasi_symmetric (and master_slave for reference) with nodal, Gauss-point and segment
integration. Writes the table into docs/performance.md. Usage:
.venv/bin/python scripts/bench_integration.py [--cells 28] [--ranks 2] [--petsc "..."]
"""

import argparse

from bench_contact import scene
from benchlib import add_docs_args, run, write_table

# (label, formulation, lines added to the [[contact]] table)
OPTIONS = [
    ("master_slave, nodal", "master_slave", 'integration = "nodal"\n'),
    ("master_slave, segment", "master_slave", 'integration = "segment"\n'),
    ("quasi_symmetric 0.5, nodal", "quasi_symmetric", 'integration = "nodal"\n'),
    ("quasi_symmetric h^4, gauss 2", "quasi_symmetric", 'integration = "gauss"\ngauss_points = 2\nweight = {power = 4}\n'),
    ("quasi_symmetric h^4, gauss 3", "quasi_symmetric", 'integration = "gauss"\ngauss_points = 3\nweight = {power = 4}\n'),
    ("quasi_symmetric h^4, gauss 5", "quasi_symmetric", 'integration = "gauss"\ngauss_points = 5\nweight = {power = 4}\n'),
    ("quasi_symmetric h^4, segment", "quasi_symmetric", 'integration = "segment"\nweight = {power = 4}\n'),
]


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--cells", type=int, default=28, help="lower cube cells per direction (28: about 0.3M dofs)")
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--only", nargs="*", default=None)
    add_docs_args(ap, "Contact integration options: cost on the two-cube scene")
    args = ap.parse_args()
    rows = []
    for label, formulation, lines in OPTIONS:
        if args.only and label not in args.only:
            continue
        text = scene(args.cells, formulation).replace("penalty = 1e4\n", "penalty = 1e4\n" + lines, 1)
        s, _ = run(text, args.ranks, args.petsc.split())
        t = s["time"]
        pair = next(iter(s["steps"][-1]["contact"].values()))
        rows.append(f"| {label} | {s['mesh']['dofs']} | {pair['quadrature_points']} | {pair['G_nonzeros']} | "
                    f"{t.get('search', 0):.2f} | {t.get('rows', 0):.2f} | {t['solve']:.2f} | {sum(t.values()):.2f} | "
                    f"{sum(x['snes_iterations'] for x in s['steps'])} | {sum(x['ksp_iterations'] for x in s['steps'])} | "
                    f"{s['peak_memory_mib']['total']:.0f} |")
        print(rows[-1], flush=True)
    description = (f"two cubes ({args.cells}^3 and {3 * args.cells // 2}^3 hexes), sticking dies, 2 load steps, "
                   f"alpha 1e4, {args.ranks} ranks, PETSc options `{args.petsc or '(defaults: CG + GAMG + contact band)'}`; "
                   "points = quadrature points projected per search (both passes), G nonzeros at the last search; "
                   "seconds summed over the 2 steps (search and rows run once per step), max over ranks; memory "
                   "= peak resident set over all ranks, MiB")
    write_table(__import__("benchlib").ROOT / "docs" / "performance.md", args.title, "bench_integration.py",
                description, ["option", "dofs", "points", "G nonzeros", "search", "rows", "solve", "total",
                              "Newton its", "KSP its", "mem total"], rows)


if __name__ == "__main__":
    main()
