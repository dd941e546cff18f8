#!/usr/bin/env python3
"""Benchmark a hex-box elasticity solve (no contact) at about 0.1, 0.3 and 1 million dofs on 1 and 2 ranks.

Writes the table into docs/performance.md. Usage: .venv/bin/python scripts/bench_elasticity.py [--cells 31 45 68] [--ranks 1 2]
"""

import argparse

from benchlib import ROOT, add_docs_args, run, write_table

SCENE = """
name = "bench_box"
[[bodies]]
name = "box"
mesh = {{ type = "box", size = [1.0, 1.0, 1.0], cells = [{n}, {n}, {n}] }}
material = {{ youngs_modulus = 1000.0, poissons_ratio = 0.3 }}
[[boundary]]
surface = "box.zmin"
type = "displacement"
ux = 0.0
uy = 0.0
uz = 0.0
[[boundary]]
surface = "box.zmax"
type = "pressure"
value = 1.0
"""


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--cells", type=int, nargs="+", default=[31, 45, 68], help="cells per direction")
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    add_docs_args(ap, "Elasticity (no contact)")
    args = ap.parse_args()
    rows = []
    for n in args.cells:
        for r in args.ranks:
            s, wall = run(SCENE.format(n=n), r, args.petsc.split())
            t = s["time"]
            dofs = s["mesh"]["dofs"]
            step = s["steps"][-1]
            mem = s["peak_memory_mib"]
            rows.append(f"| {dofs} | {r} | {t['mesh']:.2f} | {t['assembly']:.2f} | {t['solve']:.2f} | "
                        f"{t['output']:.2f} | {wall:.2f} | {step['ksp_iterations']} | {mem['max_rank']:.0f} | "
                        f"{mem['total']:.0f} | {dofs / max(t['assembly'], 1e-9) / r / 1e6:.2f} | "
                        f"{s['mesh']['stiffness_assembly']} | {s['mesh']['partitioner']} |")
            print(rows[-1], flush=True)
    description = ("unit box, Q1 hexes, bottom clamped, pressure on top, CG + GAMG, rtol 1e-10; PETSc options "
                   f"`{args.petsc or '(defaults)'}`. Times in seconds, max over ranks; wall = the whole "
                   "`mpirun qsc run` including Python start-up; memory = peak resident set in MiB")
    write_table(ROOT / "docs" / "performance.md", args.title, "bench_elasticity.py", description,
                ["dofs", "ranks", "mesh", "assembly", "solve", "output", "wall", "KSP its", "mem/rank max",
                 "mem total", "assembly Mdofs/s/rank", "stiffness", "partition"], rows)


if __name__ == "__main__":
    main()
