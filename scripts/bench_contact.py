#!/usr/bin/env python3
"""Benchmark the two-cube scene between rigid dies per formulation, against the same mesh as one conforming body.

Writes the table into docs/performance.md. Usage:
.venv/bin/python scripts/bench_contact.py [--cells 17 25 39] [--ranks 2] [--repeat 3]
(cells = the lower cube's cells per direction; the upper cube has 3/2 as many, non-matching).
--repeat R runs the whole list of formulations R times in turn and reports each one's median run (by total),
with the range of its totals: this machine's speed drifts by up to 1.4x over minutes, and runs taken in turn
see the same drift.
A formulation "<name>+small" is that formulation with small sliding (contact[0].sliding = "small": searched once),
"<name>+soft" with solver.contact_multigrid_alpha = 1 (BoomerAMG set up on the interface at alpha 1), "<name>+fresh"
with contact[0].reuse_tolerance = 0 (finite sliding that takes every search's rows); they combine.
"""

import argparse
import os

from benchlib import ROOT, add_docs_args, run, write_table

BODY = """
[[bodies]]
name = "{name}"
mesh = {{ type = "box", origin = [0.0, 0.0, {z0}], size = [1.0, 1.0, {height}], cells = [{n}, {n}, {nz}] }}
material = {{ youngs_modulus = 1000.0, poissons_ratio = 0.3 }}
"""
DIES = """
[[die]]
name = "bottom"
point = [0.0, 0.0, 0.0]
normal = [0.0, 0.0, 1.0]
surfaces = ["{bottom}"]
condition = "sticking"
[[die]]
name = "top"
point = [0.0, 0.0, 2.0]
normal = [0.0, 0.0, -1.0]
motion = [0.0, 0.0, -0.02]
surfaces = ["{top}"]
condition = "sticking"
"""
LOAD = """
[load]
steps = 2
"""
PAIR = """
[[contact]]
slave = "upper.zmin"
master = "lower.zmax"
formulation = "{formulation}"
penalty = 1e4
"""


MERGED_BOOMERAMG = ["-qsc_pc_type", "hypre"]     # CG + BoomerAMG with the band's tuned defaults


def scene(n, formulation):
    if formulation.startswith("merged"):
        k = round(1.3 * n)        # one conforming body with about as many dofs as the two cubes
        return ('name = "bench_merged"\n' + BODY.format(name="block", z0=0.0, height=2.0, n=k, nz=2 * k)
                + DIES.format(bottom="block.zmin", top="block.zmax") + LOAD)
    m = (3 * n) // 2
    formulation, *variants = formulation.split("+")
    unknown = set(variants) - {"small", "soft", "fresh"}
    if unknown:
        raise SystemExit(f"bench_contact.py: unknown variant(s) {sorted(unknown)} (known: small, soft, fresh)")
    pair = (PAIR.format(formulation=formulation) + ('sliding = "small"\n' if "small" in variants else "")
            + ("reuse_tolerance = 0.0\n" if "fresh" in variants else ""))
    solver = "\n[solver]\ncontact_multigrid_alpha = 1.0\n" if "soft" in variants else ""
    return (f'name = "bench_{formulation}"\n' + BODY.format(name="lower", z0=0.0, height=1.0, n=n, nz=n)
            + BODY.format(name="upper", z0=1.0, height=1.0, n=m, nz=m)
            + DIES.format(bottom="lower.zmin", top="upper.zmax") + pair + LOAD + solver)


def load():
    """The 1, 5 and 15 minute load averages of this machine: timings are only comparable on a quiet one."""
    return "load average {:.2f} / {:.2f} / {:.2f} on {} cores".format(*os.getloadavg(), os.cpu_count())


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--cells", type=int, nargs="+", default=[17, 25, 39])
    ap.add_argument("--ranks", type=int, nargs="+", default=[2])
    ap.add_argument("--repeat", type=int, default=1, help="runs of each formulation, taken in turn (median kept)")
    ap.add_argument("--formulations", nargs="+",
                    default=["merged", "merged_boomeramg", "master_slave", "two_pass", "quasi_symmetric",
                             "quasi_symmetric+fresh", "quasi_symmetric+small", "quasi_symmetric+soft",
                             "quasi_symmetric+small+soft"])
    add_docs_args(ap, "Contact: two cubes between rigid dies")
    args = ap.parse_args()
    rows, loads = [], [load()]
    for n in args.cells:
        for r in args.ranks:
            base, samples = {}, {f: [] for f in args.formulations}
            for _ in range(args.repeat):
                for f in args.formulations:
                    extra = MERGED_BOOMERAMG if f == "merged_boomeramg" else []
                    s, wall = run(scene(n, f), r, args.petsc.split() + extra)
                    samples[f].append((sum(s["time"].values()), wall, s))
            for f in args.formulations:
                ranked = sorted(samples[f], key=lambda sample: sample[0])
                total, _, s = ranked[len(ranked) // 2]
                wall = sorted(sample[1] for sample in samples[f])[len(ranked) // 2]
                t = s["time"]
                if f.startswith("merged"):
                    base[f] = (total, wall)
                ratios = " | ".join(f"{total / base[b][0]:.2f}" if b in base else "-"
                                    for b in ("merged", "merged_boomeramg"))
                wall_ratio = f"{wall / base['merged'][1]:.2f}" if "merged" in base else "-"
                shown = f"{total:.2f}" + (f" ({ranked[0][0]:.2f}-{ranked[-1][0]:.2f})" if len(ranked) > 1 else "")
                rows.append(f"| {s['mesh']['dofs']} | {r} | {f} | {t.get('search', 0):.2f} | {t.get('rows', 0):.2f} | "
                            f"{t['assembly']:.2f} | {t['solve']:.2f} | {shown} | {ratios} | {wall:.2f} | {wall_ratio} | "
                            f"{sum(x['snes_iterations'] for x in s['steps'])} | "
                            f"{sum(x['ksp_iterations'] for x in s['steps'])} | {s['peak_memory_mib']['total']:.0f} |")
                print(rows[-1], flush=True)
    loads.append(load())
    defaults = ("defaults: CG + GAMG for the merged body; with contact pairs GMRES + BoomerAMG composed with the "
                "exact solve on the contact band")
    description = ("two unit cubes, upper mesh 1.5x finer, sticking rigid dies, top die down 1 % of the height in "
                   f"2 load steps, alpha = 1e4, PETSc options: `{args.petsc or defaults}`; `merged` = "
                   "the same 1 x 1 x 2 stack meshed as one conforming body with about the same number of dofs "
                   "(its default CG + GAMG), `merged_boomeramg` = the same with `-qsc_pc_type hypre` (CG + "
                   "BoomerAMG with the defaults the contact band's multigrid uses), `+small` = the pair with small sliding "
                   "(searched once, in the undeformed configuration), `+fresh` = with `reuse_tolerance = 0` (finite "
                   "sliding that takes every search's rows; the others keep the first search's rows when the second "
                   "finds them unchanged within the default 1e-3), `+soft` = with `solver.contact_multigrid_alpha "
                   "= 1` (BoomerAMG set up on the interface at alpha 1, the Krylov method and the band's solve on "
                   "alpha 1e4). "
                   + (f"Each row the median of {args.repeat} runs taken in turn with the other rows' (by total; "
                      "its range in brackets; wall: the median of the walls), ratios between medians. "
                      if args.repeat > 1 else "")
                   + "Seconds, max over ranks; total = the sum of the phases (exclusive: search and rows are not counted "
                   "again in solve, as they were in tables before session 4); x merged, x merged_boomeramg = total "
                   "/ that merged run's total; wall = the whole `mpirun qsc run` as the issue measures it (start-up, "
                   "mesh and output included), x merged wall = wall / the merged run's wall; solve includes the residual/Jacobian contact products; memory = peak resident set over "
                   f"all ranks, MiB; {loads[0]} before, {loads[1]} after)")
    write_table(ROOT / "docs" / "performance.md", args.title, "bench_contact.py", description,
                ["dofs", "ranks", "formulation", "search", "rows", "assembly", "solve", "total", "x merged",
                 "x merged_boomeramg", "wall", "x merged wall", "Newton its",
                 "KSP its", "mem total"], rows)


if __name__ == "__main__":
    main()
