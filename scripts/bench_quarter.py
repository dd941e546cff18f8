#!/usr/bin/env python3
"""Benchmark the quarter two-cube model against the full one: wall time and die reaction per formulation.

configs/two_cubes_full.toml (lower (2n)^3, upper (3n)^3 cells) against configs/two_cubes_quarter.toml
(lower n x n x 2n, upper 1.5n x 1.5n x 3n: the same cells on [0.5, 1]^2 with symmetry planes), both
with the scenes' MUMPS LU. Writes its section of docs/performance.md. Usage:
.venv/bin/python scripts/bench_quarter.py [--n 8] [--ranks 1 2] (n even).
"""

import argparse

from benchlib import ROOT, add_docs_args, run, write_table

FORMULATIONS = ["master_slave", "two_pass", "quasi_symmetric"]


def cells(model, n):
    """--set overrides of the two bodies' cells for the full or the quarter model."""
    m = 3 * n // 2
    if model == "full":
        lower, upper = (2 * n, 2 * n, 2 * n), (3 * n, 3 * n, 3 * n)
    else:
        lower, upper = (n, n, 2 * n), (m, m, 3 * n)
    return [f"bodies.0.mesh.cells=[{','.join(map(str, lower))}]", f"bodies.1.mesh.cells=[{','.join(map(str, upper))}]"]


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--n", type=int, nargs="+", default=[8], help="quarter lower cells in x and y (even)")
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--formulations", nargs="+", default=FORMULATIONS)
    add_docs_args(ap, "Quarter model: two cubes between sticking dies")
    args = ap.parse_args()
    if any(n % 2 for n in args.n):
        ap.error("--n must be even (the upper body has 1.5 n cells)")
    rows, wall_ratio, phase_ratio, diff = [], [], [], []
    for n in args.n:
        for ranks in args.ranks:
            for formulation in args.formulations:
                result = {}
                for model in ("full", "quarter"):
                    text = (ROOT / "configs" / f"two_cubes_{model}.toml").read_text()
                    sets = cells(model, n) + [f"contact.0.formulation={formulation}"]
                    extra = [a for s in sets for a in ("--set", s)] + args.petsc.split()
                    result[model] = run(text, ranks, extra)
                (full, full_wall), (quarter, quarter_wall) = result["full"], result["quarter"]
                f_top = full["steps"][-1]["contact"]["die[1] top"]["force_on_bodies"][2]
                q_top = 4 * quarter["steps"][-1]["contact"]["die[1] top"]["force_on_bodies"][2]
                phases = {m: sum(s["time"].values()) for m, (s, _) in result.items()}
                for model, (s, wall) in result.items():
                    top = f_top if model == "full" else q_top
                    rows.append(
                        f"| {n} | {ranks} | {formulation} | {model} | {s['mesh']['dofs']} | {s['time']['solve']:.2f} | "
                        f"{phases[model]:.2f} | {wall:.2f} | {sum(x['snes_iterations'] for x in s['steps'])} | "
                        f"{top:.10g} | {s['peak_memory_mib']['total']:.0f} |")
                    print(rows[-1], flush=True)
                wall_ratio.append(full_wall / quarter_wall)
                phase_ratio.append(phases["full"] / phases["quarter"])
                diff.append(abs(q_top - f_top) / abs(f_top))
                rows.append(f"| {n} | {ranks} | {formulation} | full / quarter | "
                            f"{full['mesh']['dofs'] / quarter['mesh']['dofs']:.2f} | "
                            f"{full['time']['solve'] / quarter['time']['solve']:.2f} | "
                            f"{phases['full'] / phases['quarter']:.2f} | {full_wall / quarter_wall:.2f} | | "
                            f"rel. diff {abs(q_top - f_top) / abs(f_top):.1e} | |")
                print(rows[-1], flush=True)
    description = ("configs/two_cubes_full.toml with lower (2n)^3 and upper (3n)^3 cells against "
                   "configs/two_cubes_quarter.toml with lower n x n x 2n and upper 1.5n x 1.5n x 3n on [0.5, 1]^2 "
                   "(symmetry planes x = 0.5 and y = 0.5), MUMPS LU (the scenes' `[petsc]`), 2 load steps"
                   f"{', PETSc options `' + args.petsc + '`' if args.petsc else ''}. solve and phases (the sum of "
                   "mesh, assembly, search, rows, solve, output): seconds, max over ranks; wall: the whole "
                   "`mpirun qsc run` including start-up; top die Fz [N]: the quarter's times 4; memory: peak "
                   "resident set over all ranks, MiB. The machine (2 cores) is shared with other work: times "
                   "carry that noise, the ratios less so. Measured: the quarter is "
                   f"{min(wall_ratio):.1f}-{max(wall_ratio):.1f}x faster end to end ("
                   f"{min(phase_ratio):.1f}-{max(phase_ratio):.1f}x in the phases) and 4 x its top-die reaction "
                   f"is the full model's to {max(diff):.1e} relative or better")
    write_table(ROOT / "docs" / "performance.md", args.title, "bench_quarter.py", description,
                ["n", "ranks", "formulation", "model", "dofs", "solve", "phases", "wall", "Newton its",
                 "top die Fz", "mem total"], rows)


if __name__ == "__main__":
    main()
