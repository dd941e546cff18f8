#!/usr/bin/env python3
"""The paper's Figure 2: error against number of dofs, matching and non-matching meshes, each formulation.

configs/cubes_upsetting.toml with sticking dies (barrelling: the field is not in the FE space), quarter
model, alpha 1e4, MUMPS, serial. Series (quarter cells per cube in-plane, twice that vertically):
matching n/n for n = 2, 4, 6 (master_slave, two_pass, quasi_symmetric: identical on matching meshes), and
non-matching lower/upper = 2/3, 4/6, 6/9 with node-to-segment (nodal) rows: master_slave with either
body as slave, two_pass, quasi_symmetric w = 0.5 (the paper) and {power = 4}, all with the coarser lower
body as slave unless the label says otherwise; plus quasi_symmetric w = 0.5 with the default segment
integration (exact integration: the reference curve). Reference: the matching 20/20 solution (108,486 dofs, ~45 s, 2.2 GB),
checked against the matching 16/16 one (their difference must be well below the finest run's errors). Errors
from qsc_petsc.compare.errors: displacement L2, energy norm, interface traction (relative RMS at the
run's contact nodes). Slopes: least-squares fit of log(error) against log(dofs) over the three meshes,
reported as s in error ~ dofs^-s (s = 1/3 per unit order in h). Writes docs/figure2.png, docs/figure2.csv
and a table in docs/verification.md. Usage (~2-3 min): .venv/bin/python scripts/figure2.py [--reuse]
"""

import argparse
import csv
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))
from benchlib import add_docs_args, write_table
from figure1 import SEGMENT, case_sets, run

from qsc_petsc.compare import errors, load_result

OUT = ROOT / "results" / "figure2"
MATCHING = [(2, 2), (4, 4), (6, 6)]
NON_MATCHING = [(2, 3), (4, 6), (6, 9)]
REFERENCE, CHECK = 20, 16
NORMS = ("displacement_l2", "energy", "traction")
# (label, mesh series, formulation, weight, slave, extra --set)
SERIES = [
    ("matching, master_slave", MATCHING, "master_slave", None, "lower", []),
    ("matching, two_pass", MATCHING, "two_pass", None, "lower", []),
    ("matching, quasi_symmetric 0.5", MATCHING, "quasi_symmetric", 0.5, "lower", []),
    ("non-matching, master_slave (coarse slave)", NON_MATCHING, "master_slave", None, "lower", []),
    ("non-matching, master_slave (fine slave)", NON_MATCHING, "master_slave", None, "upper", []),
    ("non-matching, two_pass", NON_MATCHING, "two_pass", None, "lower", []),
    ("non-matching, quasi_symmetric 0.5", NON_MATCHING, "quasi_symmetric", 0.5, "lower", []),
    ("non-matching, quasi_symmetric h^4", NON_MATCHING, "quasi_symmetric", "{power=4}", "lower", []),
    ("non-matching, quasi_symmetric 0.5, segment", NON_MATCHING, "quasi_symmetric", 0.5, "lower", [SEGMENT]),
]


def slope(dofs, err):
    """s of the least-squares fit err ~ C dofs^-s (positive when the error falls with refinement)."""
    return -float(np.polyfit(np.log(np.asarray(dofs, float)), np.log(np.asarray(err, float)), 1)[0])


def measure(out_root, series, reference, condition="sticking", reuse=False):
    """Run every (label, meshes, formulation, weight, slave, extra) of `series` and compare with `reference`
    (a run folder or Result); returns rows {label, lower, upper, dofs, displacement_l2, energy, traction}."""
    ref = reference if not isinstance(reference, (str, Path)) else load_result(reference)
    rows = []
    for label, meshes, formulation, weight, slave, extra in series:
        for lower, upper in meshes:
            tag = f"{lower}_{upper}_{formulation}_{weight}_{slave}_{'seg' if extra else 'nodal'}"
            res = load_result(run(Path(out_root) / tag, case_sets(lower, upper, formulation, weight, slave,
                                                                  condition, extra), reuse))
            e = errors(res, ref)
            rows.append({"label": label, "lower": lower, "upper": upper, "dofs": res.summary["mesh"]["dofs"],
                         **{k: e[k] for k in NORMS}})
    return rows


def slopes(rows):
    """{label: {norm: fitted s}} over each label's meshes."""
    out = {}
    for label in dict.fromkeys(r["label"] for r in rows):
        mine = [r for r in rows if r["label"] == label]
        out[label] = {k: slope([r["dofs"] for r in mine], [r[k] for r in mine]) for k in NORMS}
    return out


def plot(rows, path, check):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    titles = {"displacement_l2": "displacement L2", "energy": "energy norm", "traction": "interface traction (RMS)"}
    fig, axes = plt.subplots(1, 3, figsize=(15, 5), constrained_layout=True)
    labels = list(dict.fromkeys(r["label"] for r in rows))
    styles = {lab: ("k" if lab.startswith("matching") else None) for lab in labels}
    markers = "osD^v<>ph"
    for ax, norm in zip(axes, NORMS):
        for i, lab in enumerate(labels):
            mine = [r for r in rows if r["label"] == lab]
            ls = "--" if lab.startswith("matching") and "master_slave" not in lab else "-"
            ax.loglog([r["dofs"] for r in mine], [r[norm] for r in mine], ls, marker=markers[i % len(markers)],
                      color=styles[lab], mfc="none", label=lab, lw=1.2)
        ax.axhline(check[norm], color="grey", lw=0.8, ls=":", label=f"reference {CHECK}/{CHECK} vs {REFERENCE}/{REFERENCE}")
        ax.set_xlabel("dofs (quarter model)")
        ax.set_title(f"relative error, {titles[norm]}", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("relative error against the matching reference")
    axes[2].legend(fontsize=7, loc="lower left")
    fig.suptitle("Two cubes between sticking dies (configs/cubes_upsetting.toml): error against dofs; "
                 "nodal (node-to-segment) rows unless 'segment'", fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--reuse", action="store_true", help="keep finished runs in results/figure2")
    add_docs_args(ap, "Figure 2: error against number of dofs", petsc=False)
    args = ap.parse_args()
    ref_dir = run(OUT / "reference", case_sets(REFERENCE, REFERENCE), args.reuse)
    ref = load_result(ref_dir)
    check = errors(load_result(run(OUT / "reference_check", case_sets(CHECK, CHECK), args.reuse)), ref)
    print(f"reference check ({CHECK} vs {REFERENCE}): " + ", ".join(f"{k} {check[k]:.2e}" for k in NORMS))
    rows = measure(OUT, SERIES, ref, reuse=args.reuse)
    for r in rows:
        print(f"{r['label']:45s} {r['lower']}/{r['upper']} {r['dofs']:6d} dofs  "
              + "  ".join(f"{k} {r[k]:.3e}" for k in NORMS), flush=True)
    finest = min(min(r[k] for r in rows if (r["lower"], r["upper"]) in (MATCHING[-1], NON_MATCHING[-1])) for k in NORMS)
    margin = min(min(r[k] for r in rows if (r["lower"], r["upper"]) in (MATCHING[-1], NON_MATCHING[-1])) / check[k]
                 for k in NORMS)
    print(f"smallest finest-mesh error {finest:.2e}; finest errors / reference check >= {margin:.1f}")
    with open(ROOT / "docs" / "figure2.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    plot(rows, ROOT / "docs" / "figure2.png", check)
    fitted = slopes(rows)
    table = []
    for label, s in fitted.items():
        last = [r for r in rows if r["label"] == label][-1]
        table.append(f"| {label} | {last['dofs']} | " + " | ".join(f"{last[k]:.2e}" for k in NORMS) + " | "
                     + " | ".join(f"{s[k]:.2f}" for k in NORMS) + " |")
    description = ("serial, MUMPS, alpha 1e4, sticking dies, quarter model; meshes: matching 2/2, 4/4, 6/6 and "
                   "non-matching 2/3, 4/6, 6/9 (lower/upper in-plane cells per quarter cube, twice that "
                   f"vertically); reference: matching {REFERENCE}/{REFERENCE} ({ref.summary['mesh']['dofs']:,} dofs), which differs from "
                   f"the {CHECK}/{CHECK} one by u L2 {check['displacement_l2']:.1e}, energy {check['energy']:.1e}, "
                   f"traction {check['traction']:.1e} (the finest runs' errors are >= {margin:.1f}x that); "
                   "slope s: least-squares fit of error ~ dofs^-s over the three meshes (s = 1/3 per order in h); "
                   "every run: docs/figure2.csv; figure: docs/figure2.png")
    write_table(ROOT / "docs" / "verification.md", args.title, "figure2.py", description,
                ["series", "dofs (finest)", "u L2 (finest)", "energy (finest)", "traction (finest)",
                 "s, u L2", "s, energy", "s, traction"], table)


if __name__ == "__main__":
    main()
