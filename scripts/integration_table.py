#!/usr/bin/env python3
"""Contact integration options on the patch test: error, swap difference, Newton iterations, points, nonzeros, time.

configs/patch_test.toml (p = 1, exact sigma_zz = -p) with lower/upper in-plane cells (4,5), (4,7), (2,8),
(8,2), (3,10), (5,16) and matching (4,4), each option with the upper and with the lower block as slave,
alpha = 1e4. Writes docs/integration_table.csv (every run) and, into docs/verification.md, a table per
option (worst over the non-matching pairs and both slave choices). Usage (serial, about 2 min):
.venv/bin/python scripts/integration_table.py
"""

import argparse
import csv
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))
from benchlib import add_docs_args, write_table
from patch_table import SIDES, solve

PAIRS = [(4, 5), (4, 7), (2, 8), (8, 2), (3, 10), (5, 16), (4, 4)]
GAUSS = "contact.0.integration=gauss"
SEGMENT = "contact.0.integration=segment"
H4 = "{power=4}"
# (label, formulation, weight, extra overrides)
OPTIONS = [
    ("master_slave, nodal", "master_slave", None, []),
    ("two_pass, nodal", "two_pass", None, []),
    ("quasi_symmetric 0.5, nodal (paper)", "quasi_symmetric", 0.5, []),
    ("quasi_symmetric h^4, nodal", "quasi_symmetric", H4, []),
    ("master_slave, gauss 3", "master_slave", None, [GAUSS, "contact.0.gauss_points=3"]),
    ("two_pass, gauss 3", "two_pass", None, [GAUSS, "contact.0.gauss_points=3"]),
    ("quasi_symmetric 0.5, gauss 5", "quasi_symmetric", 0.5, [GAUSS, "contact.0.gauss_points=5"]),
    ("quasi_symmetric h^4, gauss 2", "quasi_symmetric", H4, [GAUSS, "contact.0.gauss_points=2"]),
    ("quasi_symmetric h^4, gauss 3", "quasi_symmetric", H4, [GAUSS, "contact.0.gauss_points=3"]),
    ("quasi_symmetric h^4, gauss 5", "quasi_symmetric", H4, [GAUSS, "contact.0.gauss_points=5"]),
    ("quasi_symmetric h^4, gauss 5, master nodes", "quasi_symmetric", H4,
     [GAUSS, "contact.0.gauss_points=5", "contact.0.master_multiplier=master_nodes"]),
    ("master_slave, segment", "master_slave", None, [SEGMENT]),
    ("two_pass, segment", "two_pass", None, [SEGMENT]),
    ("quasi_symmetric 0.5, segment", "quasi_symmetric", 0.5, [SEGMENT]),
    ("quasi_symmetric h^4, segment", "quasi_symmetric", H4, [SEGMENT]),
]
COLUMNS = ["option", "lower", "upper", "slave", "max_stress_error", "rms_stress_error", "max_traction_error",
           "max_pen_slave", "max_pen_master", "newton", "points", "G_nonzeros", "search_rows_s", "solve_s",
           "swap_difference"]


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--alpha", default="1e4")
    ap.add_argument("--only", nargs="*", default=None, help="labels of the options to run (default: all)")
    add_docs_args(ap, "Contact integration options on the patch test", petsc=False)
    args = ap.parse_args()
    unknown = sorted(set(args.only or []) - {label for label, *_ in OPTIONS})
    if unknown:
        ap.error(f"--only: unknown label(s) {', '.join(unknown)}; the labels are "
                 + "; ".join(label for label, *_ in OPTIONS))
    rows = []
    for label, formulation, weight, extra in OPTIONS:
        if args.only and label not in args.only:
            continue
        for lower, upper in PAIRS:
            res = {side: solve(lower, upper, formulation, weight, side, args.alpha, extra) for side in SIDES}
            ua, ub = res["upper"][1], res["lower"][1]
            swap = float(np.linalg.norm(ua - ub) / np.linalg.norm(ua))
            for side in SIDES:
                m = res[side][0]
                t = m.pop("time")
                rows.append({"option": label, "lower": lower, "upper": upper, "slave": side, **m,
                             "search_rows_s": t.get("search", 0.0) + t.get("rows", 0.0), "solve_s": t["solve"],
                             "swap_difference": swap})
            print(f"{label} ({lower},{upper}): err {rows[-2]['max_stress_error']:.2e} / "
                  f"{rows[-1]['max_stress_error']:.2e}, swap {swap:.1e}", flush=True)
    docs = ROOT / "docs"
    # the table's columns only, written whole or not at all (a failed write left the header alone)
    tmp = docs / "integration_table.csv.tmp"
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    tmp.replace(docs / "integration_table.csv")
    table = []
    for label, *_ in OPTIONS:
        mine = [r for r in rows if r["option"] == label and r["lower"] != r["upper"]]
        if not mine:
            continue
        same = [r for r in rows if r["option"] == label and r["lower"] == r["upper"]]
        worst = {key: max(r[key] for r in mine) for key in COLUMNS[4:]}
        mean = {key: float(np.mean([r[key] for r in mine])) for key in COLUMNS[4:]}
        table.append(f"| {label} | {worst['max_stress_error']:.2e} | {worst['rms_stress_error']:.2e} | "
                     f"{worst['max_traction_error']:.2e} | {worst['swap_difference']:.1e} | "
                     f"{max(r['max_stress_error'] for r in same):.1e} | {mean['newton']:.1f} | "
                     f"{max(r['newton'] for r in mine)} | {mean['points']:.0f} | {mean['G_nonzeros']:.0f} | "
                     f"{1e3 * mean['search_rows_s']:.1f} |")
    description = (f"serial, MUMPS, alpha = {args.alpha}; worst over the six non-matching pairs (4,5), (4,7), "
                   "(2,8), (8,2), (3,10), (5,16) and both slave choices, except 'matching' = the (4,4) pair; "
                   "points = quadrature points projected (both passes; a point as near to several faces counts once "
                   "a face), nonzeros of G, search + rows time per search in ms (means over the non-matching runs); "
                   "every run: docs/integration_table.csv")
    write_table(docs / "verification.md", args.title, "integration_table.py", description,
                ["option", "max \\|szz+p\\|/p", "rms", "max traction err", "swap diff", "matching", "Newton mean",
                 "Newton max", "points", "G nonzeros", "search+rows ms"], table)


if __name__ == "__main__":
    main()
