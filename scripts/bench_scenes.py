#!/usr/bin/env python3
"""The iterative solver's options across the contact scenes of configs/: Newton and Krylov iterations and time of
each scene (as written, its [petsc] table dropped so that the iterative defaults run) with each variant of the
contact band preconditioner, on 2 ranks. Writes the table into docs/performance.md.

Usage: .venv/bin/python scripts/bench_scenes.py [--scenes two_cubes_dies flat_punch ...] [--variants ...]
"""

import argparse

from benchlib import ROOT, add_docs_args, run, write_table

SCENES = ["patch_test", "cubes_upsetting", "two_cubes_quarter", "two_cubes_dies", "sliding_cubes", "flat_punch", "stiff_plate",
          "hertz_medium"]
VARIANTS = {
    "defaults": [],
    "no slip modes": ["--set", "solver.contact_slip_modes=false"],
    "multigrid alpha 1": ["--set", "solver.contact_multigrid_alpha=1"],
    "small sliding": ["--set", "contact.0.sliding=small"],
}


def iterative(name):
    """configs/<name>.toml's text without its [petsc] table (the last table of every config that has one)."""
    text = (ROOT / "configs" / f"{name}.toml").read_text()
    cut = text.find("\n[petsc]")
    return text if cut < 0 else text[:cut + 1]


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--scenes", nargs="+", default=SCENES, help="names of configs/*.toml with contact pairs")
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    ap.add_argument("--ranks", type=int, default=2)
    add_docs_args(ap, "Contact scenes: the iterative solver's options")
    args = ap.parse_args()
    rows = []
    for name in args.scenes:
        for variant in args.variants:
            s, wall = run(iterative(name), args.ranks, VARIANTS[variant] + args.petsc.split())
            steps = s["steps"]
            newton = sum(st["snes_iterations"] for st in steps)
            krylov = sum(st["ksp_iterations"] for st in steps)
            per_step = " + ".join(str(st["ksp_iterations"]) for st in steps)
            t = s["time"]
            rows.append(f"| {name} | {s['mesh']['dofs']} | {variant} | {newton} | {krylov} ({per_step}) | "
                        f"{t['solve']:.2f} | {sum(t.values()):.2f} | {wall:.2f} |")
            print(rows[-1], flush=True)
    description = (f"{args.ranks} ranks; each scene of configs/ as written but for its [petsc] table, so that the "
                   "iterative defaults run (GMRES + BoomerAMG with the contact band, slip modes on); variants: "
                   "`no slip modes` = `solver.contact_slip_modes = false`, `multigrid alpha 1` = "
                   "`solver.contact_multigrid_alpha = 1`, `small sliding` = `contact.0.sliding = \"small\"`; "
                   f"PETSc options `{args.petsc or '(defaults)'}`. Krylov: in all (per load step); seconds, max "
                   "over ranks; total = the sum of the phases, wall = the whole `mpirun qsc run`; single runs")
    write_table(ROOT / "docs" / "performance.md", args.title, "bench_scenes.py", description,
                ["scene", "dofs", "variant", "Newton its", "Krylov its", "solve", "total", "wall"], rows)


if __name__ == "__main__":
    main()
