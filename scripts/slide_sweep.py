#!/usr/bin/env python3
"""Sliding at the extremes: configs/sliding_cubes.toml (a cube dragged sideways over another by a sticking
die, frictionless interface) in one or two load steps, across formulations, sliding modes, element types,
contact integration and penalty, on 1 rank. Records whether each run converged, its cutbacks, searches,
Newton iterations, and the Newton safeguards it needed (damped steps, sticking-die rows tied in tension).
Writes the table "Sliding at the extremes" into docs/stability.md. Usage (about a minute):
.venv/bin/python scripts/slide_sweep.py
"""

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))
from benchlib import ENV, QSC, add_docs_args, write_table

SCENE = ROOT / "configs" / "sliding_cubes.toml"
COARSE = ["bodies.0.mesh.cells=[4,4,4]", "bodies.1.mesh.cells=[6,6,6]"]
MOTIONS = ["[0.3,0.1,-0.03]", "[0.6,0,-0.05]"]
CASES = ([(f, s, e, m, []) for f in ("master_slave", "two_pass", "quasi_symmetric") for s in ("finite", "large")
          for e in ("hex", "tet") for m in MOTIONS]
         + [("quasi_symmetric", "large", "hex", "[0.4,0.1,-0.03]", [extra]) for extra in
            ("contact.0.integration=nodal", "contact.0.integration=gauss", "contact.0.penalty=1e2",
             "contact.0.penalty=1e8", 'contact.0.enforcement="augmented_lagrangian"')])


def run(formulation, sliding, element, motion, extra):
    """One run; returns (converged, summary or None, the error line or "")."""
    sets = COARSE + [f"contact.0.formulation={formulation}", f'contact.0.sliding="{sliding}"',
                     f"bodies.0.mesh.element={element}", f"bodies.1.mesh.element={element}",
                     f"die.1.motion={motion}", *extra]
    with tempfile.TemporaryDirectory(prefix="qsc_sweep_") as tmp:
        cmd = [str(QSC), "run", str(SCENE), "--out", tmp] + [a for s in sets for a in ("--set", s)]
        proc = subprocess.run(cmd, env=ENV, capture_output=True, text=True, timeout=600, check=False)
        summary = json.loads((Path(tmp) / "summary.json").read_text())
    error = next((line for line in proc.stdout.splitlines() + proc.stderr.splitlines() if "failed:" in line), "")
    return proc.returncode == 0, summary, error


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    add_docs_args(ap, "Sliding at the extremes", petsc=False)
    args = ap.parse_args()
    rows = []
    for formulation, sliding, element, motion, extra in CASES:
        ok, s, error = run(formulation, sliding, element, motion, extra)
        steps = s["steps"]
        solves = [x for step in steps for x in step["solves"]]
        pairs = [next(iter(step["contact"].values())) for step in steps]
        rows.append(f"| {formulation} | {sliding} | {element} | {motion} | {' '.join(extra) or '-'} | "
                    f"{'yes' if ok else 'no: ' + error.split('did not converge')[-1][:60]} | "
                    f"{sum(step['cutbacks'] for step in steps)} | "
                    f"{' + '.join(str(p['searches']) for p in pairs)} | "
                    f"{sum(step['snes_iterations'] for step in steps)} | "
                    f"{sum(1 for x in solves if x['damped_from'] is not None)} | "
                    f"{max((x.get('tied_in_tension', 0) for x in solves), default=0)} |")
        print(rows[-1], flush=True)
    write_table(ROOT / "docs" / "stability.md", args.title, "slide_sweep.py",
                "configs/sliding_cubes.toml on 4 / 6 hexes (or the same boxes in tets) a side, 2 load steps, "
                "MUMPS, 1 rank; motion = the sticking top die's, [x, y, z] m at the last step (0.3 m = 1.8 "
                "h_eff here); searches per load step (finite sliding: 1); Newton iterations over the run; "
                "damped = solves whose Newton steps were damped (a returning active set or 15 iterations "
                "without a new lowest residual); tied = sticking-die rows held closed in tension",
                ["formulation", "sliding", "element", "motion", "also", "converged", "cutbacks", "searches",
                 "Newton its", "damped", "tied"], rows)


if __name__ == "__main__":
    main()
