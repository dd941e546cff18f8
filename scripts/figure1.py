#!/usr/bin/env python3
"""The paper's Figure 1: two cubes squeezed between flat dies, each contact case against a fine matching reference.

configs/cubes_upsetting.toml (quarter model, node-to-segment rows, alpha 1e4, MUMPS, serial) with
frictionless and with sticking dies. Cases (quarter cells in-plane, 2x that vertically):
(1) matching 4/4; on the non-matching pair lower 4 / upper 7: (2) slave finer (upper slave, master_slave),
(3) master finer with master_slave (lower slave), (4) master finer with quasi_symmetric w = 0.5 (the
paper), and with the lower (coarser) body as slave also two_pass, quasi_symmetric {power = 4}, and
quasi_symmetric with the default segment integration (exact integration, for comparison). Each case is
compared (qsc_petsc.compare) with the matching 16/16 reference and with the same case with the slave
and master surfaces swapped. Writes docs/figure1.png (vertical displacement on the mid-plane x = 0.5,
mirrored to the full width, and its difference from the reference) and a table in docs/verification.md.
Usage (~1 min): .venv/bin/python scripts/figure1.py
"""

import argparse
import sys
from pathlib import Path

import numpy as np
from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))
from benchlib import add_docs_args, write_table

from qsc_petsc.compare import Locator, errors, load_result

SCENE = ROOT / "configs" / "cubes_upsetting.toml"
OUT = ROOT / "results" / "figure1"
SIDES = {"upper": ("upper.zmin", "lower.zmax"), "lower": ("lower.zmax", "upper.zmin")}
SWAP = {"upper": "lower", "lower": "upper"}
CONDITIONS = ("frictionless", "sticking")
COARSE, FINE, REFERENCE = 4, 7, 16
SEGMENT = "contact.0.integration=segment"
# (label, lower cells, upper cells, formulation, weight, slave, extra --set)
CASES = [
    ("(1) matching", COARSE, COARSE, "master_slave", None, "upper", []),
    ("(2) slave finer, master_slave", COARSE, FINE, "master_slave", None, "upper", []),
    ("(3) master finer, master_slave", COARSE, FINE, "master_slave", None, "lower", []),
    ("(4) master finer, quasi_symmetric 0.5", COARSE, FINE, "quasi_symmetric", 0.5, "lower", []),
    ("master finer, two_pass", COARSE, FINE, "two_pass", None, "lower", []),
    ("master finer, quasi_symmetric h^4", COARSE, FINE, "quasi_symmetric", "{power=4}", "lower", []),
    ("master finer, quasi_symmetric 0.5, segment", COARSE, FINE, "quasi_symmetric", 0.5, "lower", [SEGMENT]),
]


def case_sets(lower, upper, formulation="master_slave", weight=None, slave="upper", condition="sticking", extra=()):
    """--set overrides of configs/cubes_upsetting.toml for one run."""
    s_ref, m_ref = SIDES[slave]
    sets = [f"bodies.0.mesh.cells=[{lower},{lower},{2 * lower}]", f"bodies.1.mesh.cells=[{upper},{upper},{2 * upper}]",
            f"contact.0.formulation={formulation}", f"contact.0.slave={s_ref}", f"contact.0.master={m_ref}",
            f"die.0.condition={condition}", f"die.1.condition={condition}", *extra]
    if weight is not None:
        sets.append(f"contact.0.weight={weight}")
    return sets


def run(out, sets, reuse=False):
    """Run configs/cubes_upsetting.toml with `sets` in this process (serial) into folder `out`; returns `out`.

    reuse: keep a finished run already in `out` (same overrides, recorded in sets.txt)."""
    from qsc_petsc.run import Run
    from qsc_petsc.scene import load_scene
    out = Path(out)
    record = "\n".join(sets)
    if reuse and (out / "sets.txt").is_file() and (out / "sets.txt").read_text() == record \
            and (out / "solution.h5").is_file():
        return out
    scene = load_scene(SCENE, list(sets))
    r = Run(scene, MPI.COMM_SELF, out, log=lambda *a, **k: None)
    try:
        summary = r.execute()
    finally:
        r.destroy()
    if summary.get("status") != "ok":
        raise RuntimeError(f"{out}: run did not converge ({summary.get('status')})")
    (out / "sets.txt").write_text(record)
    return out


def midplane(result, x0=0.5, tol=1e-9):
    """(y, z, uz, body) of the nodes on the plane x = x0, mirrored about y = 0.5 to the full width (duplicates kept once)."""
    on = np.abs(result.points[:, 0] - x0) < tol
    y, z = result.points[on, 1], result.points[on, 2]
    uz = result.point_data["displacement"][on, 2]
    body = result.point_body()[on]
    keep = y > 0.5 + tol
    return (np.concatenate([y, 1.0 - y[keep]]), np.concatenate([z, z[keep]]), np.concatenate([uz, uz[keep]]),
            np.concatenate([body, body[keep]]))


def reference_at(ref, result, x0=0.5, tol=1e-9):
    """Reference uz interpolated at the same mid-plane nodes (and mirror images) as midplane(result)."""
    loc = Locator(ref)
    on = np.flatnonzero(np.abs(result.points[:, 0] - x0) < tol)
    names = ref.body_names
    body = np.array([names.index(result.body_names[b]) for b in result.point_body()[on]])
    cell, xi, _ = loc.locate(result.points[on], body)
    uz = loc.values("displacement", cell, xi)[:, 2]
    keep = result.points[on, 1] > 0.5 + tol
    return np.concatenate([uz, uz[keep]])


def plot(panels, path):
    """panels: {condition: [(label, result, uz_ref_at_nodes)]} -> rows uz and uz - ref per condition."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.tri import Triangulation
    ncol = max(len(v) for v in panels.values())
    fig, axes = plt.subplots(2 * len(panels), ncol, figsize=(2.0 * ncol + 1.2, 3.6 * 2 * len(panels)),
                             squeeze=False, constrained_layout=True)
    for i, (condition, items) in enumerate(panels.items()):
        data = [(label, *midplane(res), uref) for label, res, uref in items]
        umin = min(d[3].min() for d in data)
        dmax = max(np.abs(d[3] - d[5]).max() for d in data) or 1.0
        for j, (label, y, z, uz, body, uref) in enumerate(data):
            for k, (values, levels, cmap) in enumerate(((uz, np.linspace(umin, 0.0, 21), "viridis"),
                                                        (uz - uref, np.linspace(-dmax, dmax, 21), "RdBu_r"))):
                ax = axes[2 * i + k, j]
                for b in np.unique(body):          # one triangulation per body: the interface is a jump
                    on = body == b
                    cs = ax.tricontourf(Triangulation(y[on], z[on]), values[on], levels=levels, cmap=cmap,
                                        extend="both")
                ax.axhline(1.0, color="k", lw=0.6)
                ax.set_aspect("equal")
                ax.set_xticks([])
                ax.set_yticks([0, 1, 2] if j == 0 else [])
                if k == 0:
                    ax.set_title(label.replace(", ", ",\n", 1), fontsize=7)
                if j == 0:
                    ax.set_ylabel(f"{condition}\n{'u_z (m)' if k == 0 else 'u_z - u_z,ref (m)'}", fontsize=8)
                if j == len(data) - 1:
                    fig.colorbar(cs, ax=axes[2 * i + k, :], shrink=0.8, format="%.1e")
    fig.suptitle("Vertical displacement on the mid-plane x = 0.5 (two cubes, top die -0.02 m; "
                 f"reference: matching {2 * REFERENCE}^3 cells per cube)", fontsize=9)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--reuse", action="store_true", help="keep finished runs in results/figure1")
    add_docs_args(ap, "Figure 1: two cubes between flat dies", petsc=False)
    args = ap.parse_args()
    rows, panels = [], {}
    for condition in CONDITIONS:
        ref = load_result(run(OUT / f"{condition}_reference",
                              case_sets(REFERENCE, REFERENCE, condition=condition), args.reuse))
        panels[condition] = []
        for label, lower, upper, formulation, weight, slave, extra in CASES:
            tag = f"{condition}_{lower}_{upper}_{formulation}_{weight}_{'seg' if extra else 'nodal'}"
            folders = {s: run(OUT / f"{tag}_{s}", case_sets(lower, upper, formulation, weight, s, condition, extra),
                              args.reuse) for s in (slave, SWAP[slave])}
            res = load_result(folders[slave])
            e = errors(res, ref)
            swap = errors(res, load_result(folders[SWAP[slave]]))
            rows.append((condition, label, slave, e["displacement_l2"], e["energy"], e["traction"],
                         swap["displacement_l2"]))
            print(f"{condition:12s} {label:45s} u L2 {e['displacement_l2']:.3e}  energy {e['energy']:.3e}  "
                  f"traction {e['traction']:.3e}  swap {swap['displacement_l2']:.3e}", flush=True)
            panels[condition].append((label, res, reference_at(ref, res)))
    plot(panels, ROOT / "docs" / "figure1.png")
    table = [f"| {c} | {label} | {s} | {u:.2e} | {en:.2e} | {t:.2e} | {sw:.2e} |"
             for c, label, s, u, en, t, sw in rows]
    description = (f"serial, MUMPS, alpha 1e4, quarter model of configs/cubes_upsetting.toml, top die -0.02 m; "
                   f"quarter cells per cube {COARSE}x{COARSE}x{2 * COARSE} (coarse) and {FINE}x{FINE}x{2 * FINE} (fine); "
                   "node-to-segment (nodal) rows unless the case says segment; errors relative to the matching "
                   f"{REFERENCE}x{REFERENCE}x{2 * REFERENCE} reference (compare.errors: u L2, energy norm, RMS "
                   "traction at the run's contact nodes); swap = u L2 difference from the same case with slave "
                   "and master swapped; figure: docs/figure1.png")
    write_table(ROOT / "docs" / "verification.md", args.title, "figure1.py", description,
                ["dies", "case", "slave", "u L2 vs ref", "energy vs ref", "traction vs ref", "swap (u L2)"], table)


if __name__ == "__main__":
    main()
