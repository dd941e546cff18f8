#!/usr/bin/env python3
"""Benchmark a hex-box elasticity solve (no contact) at about 0.1, 0.3 and 1 million dofs on 1 and 2 ranks.

Writes the table into docs/performance.md. Usage: .venv/bin/python scripts/bench_elasticity.py [--cells 31 45 68] [--ranks 1 2]
[--repeat 3]

--repeat R runs each size and rank count R times in a row and reports the median of every column (the assembly's
range in brackets): these VMs hand freed memory back to their host after a few seconds, so the first of
several runs pays to touch its memory again (docs/performance.md, session 21).
"""

import argparse
import functools
import statistics

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


def _median(runs, value):
    """The median over runs [(summary, wall), ...] of value(summary, wall)."""
    return statistics.median(value(*sample) for sample in runs)


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--cells", type=int, nargs="+", default=[31, 45, 68], help="cells per direction")
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--repeat", type=int, default=1, help="runs of each size and rank count, in a row (medians kept)")
    add_docs_args(ap, "Elasticity (no contact)")
    args = ap.parse_args()
    rows = []
    for n in args.cells:
        for r in args.ranks:
            runs = [run(SCENE.format(n=n), r, args.petsc.split()) for _ in range(args.repeat)]
            s = runs[0][0]
            med = functools.partial(_median, runs)
            times = {k: med(lambda s, w, k=k: s["time"][k]) for k in ("mesh", "assembly", "solve", "output")}
            assembly = [sample[0]["time"]["assembly"] for sample in runs]
            shown = f"{times['assembly']:.2f}" + (f" ({min(assembly):.2f}-{max(assembly):.2f})" if len(runs) > 1 else "")
            dofs = s["mesh"]["dofs"]
            rows.append(f"| {dofs} | {r} | {times['mesh']:.2f} | {shown} | {times['solve']:.2f} | "
                        f"{times['output']:.2f} | {med(lambda s, w: w):.2f} | "
                        f"{med(lambda s, w: s['steps'][-1]['ksp_iterations']):.0f} | "
                        f"{med(lambda s, w: s['peak_memory_mib']['max_rank']):.0f} | "
                        f"{med(lambda s, w: s['peak_memory_mib']['total']):.0f} | "
                        f"{dofs / max(times['assembly'], 1e-9) / r / 1e6:.2f} | "
                        f"{s['mesh']['stiffness_assembly']} | {s['mesh']['partitioner']} |")
            print(rows[-1], flush=True)
    description = ("unit box, Q1 hexes, bottom clamped, pressure on top, CG + GAMG, rtol 1e-10; PETSc options "
                   f"`{args.petsc or '(defaults)'}`. Times in seconds, max over ranks; wall = the whole "
                   "`mpirun qsc run` including Python start-up; memory = peak resident set in MiB"
                   + (f". Each column the median of {args.repeat} runs in a row, the assembly's range in brackets; "
                      "Mdofs/s/rank from the median assembly" if args.repeat > 1 else ""))
    write_table(ROOT / "docs" / "performance.md", args.title, "bench_elasticity.py", description,
                ["dofs", "ranks", "mesh", "assembly", "solve", "output", "wall", "KSP its", "mem/rank max",
                 "mem total", "assembly Mdofs/s/rank", "stiffness", "partition"], rows)


if __name__ == "__main__":
    main()
