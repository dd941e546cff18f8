#!/usr/bin/env python3
"""Finite against large sliding on a slide of several elements: the error of each against the load-step count.

configs/two_cubes_dies.toml (lower cube 6^3, upper 9^3 hexes, quasi_symmetric, MUMPS) with the top (sticking)
die also moving 0.3 m sideways: the upper cube slides 2.7 h_eff over the lower one on the frictionless interface,
an elastic answer that does not depend on the load path. Finite sliding linearises each increment's rows at its
start; large sliding searches again after every converged solve until the rows settle. The reference is large
sliding with 16 load steps. Errors from qsc_petsc.compare at the last step: displacement L2 and interface
traction (relative), total normal force (relative). Writes a table into docs/tradeoff.md. Usage (~1 min):
.venv/bin/python scripts/sliding_table.py [--ranks 2]
"""

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))
from benchlib import ENV, QSC, add_docs_args, write_table

from qsc_petsc.compare import errors

SLIDE = ["die.1.motion=[0.3,0,-0.02]"]
RUNS = [("finite", 1), ("finite", 2), ("finite", 4), ("finite", 8), ("finite", 16), ("finite", 64),
        ("large", 1), ("large", 2), ("large", 4)]
REFERENCE = ("large", 16)
OUT = ROOT / "results" / "sliding"


def run(sliding, steps, ranks):
    """One run of the slide; returns (output folder, summary, wall seconds)."""
    out = OUT / f"{sliding}_{steps}"
    sets = SLIDE + [f"load.steps={steps}", f'contact.0.sliding="{sliding}"']
    cmd = ["mpirun", "--oversubscribe", "-n", str(ranks), str(QSC), "run", str(ROOT / "configs" / "two_cubes_dies.toml"),
           "--out", str(out)] + [a for s in sets for a in ("--set", s)]
    t0 = time.perf_counter()
    subprocess.run(cmd, env=ENV, check=True, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    return out, json.loads((out / "summary.json").read_text()), wall


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--ranks", type=int, default=2)
    add_docs_args(ap, "Finite and large sliding: a slide of 2.7 elements", petsc=False)
    args = ap.parse_args()
    ref, ref_summary, _ = run(*REFERENCE, args.ranks)
    ref_pair = next(iter(ref_summary["steps"][-1]["contact"].values()))
    rows = []
    for sliding, steps in RUNS:
        out, s, wall = run(sliding, steps, args.ranks)
        e = errors(out, ref)
        pairs = [next(iter(step["contact"].values())) for step in s["steps"]]
        force = pairs[-1]["total_normal_force"]
        rows.append(f"| {sliding} | {steps} | {sum(p['searches'] for p in pairs)} | "
                    f"{sum(step['snes_iterations'] for step in s['steps'])} | {e['displacement_l2']:.1e} | "
                    f"{e['traction']:.1e} | {force:.4f} | {abs(force / ref_pair['total_normal_force'] - 1):.1e} | "
                    f"{sum(s['time'].values()):.2f} | {wall:.2f} |")
        print(rows[-1], flush=True)
    write_table(ROOT / "docs" / "tradeoff.md", args.title, "sliding_table.py",
                f"{args.ranks} ranks; configs/two_cubes_dies.toml with `die.1.motion = [0.3, 0, -0.02]`: the upper "
                "cube dragged 0.3 m = 2.7 h_eff sideways over the lower one; reference: large sliding in "
                f"{REFERENCE[1]} load steps (total normal force {ref_pair['total_normal_force']:.4f} N); errors at "
                "the last step (qsc_petsc.compare): displacement L2 and interface traction relative to the "
                "reference's, total normal force's relative difference; searches and Newton iterations summed "
                "over the load steps; seconds: total = the sum of the phases, wall = the whole `mpirun qsc run`",
                ["sliding", "load steps", "searches", "Newton its", "u L2 error", "traction error",
                 "normal force [N]", "force error", "total", "wall"], rows)


if __name__ == "__main__":
    main()
