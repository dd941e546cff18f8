"""qsc sweep: one scene run over the cartesian product of variations, each run measured and compared with a reference run.

Every combination is its own `qsc run` subprocess (through mpirun), so a crash, a hang (with
--timeout) or a non-converged solve is recorded and the sweep goes on. The parent never starts
PETSc: it validates every combination's scene before the first run, then reads each run's
summary.json and compares its results with the reference run (compare.py).
"""

import argparse
import csv
import io
import itertools
import json
import math
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from .errors import QscError, SceneError, folder_error
from .options import PREFIX, split_petsc_args, unread_option, value_error

EXIT_OK, EXIT_INPUT, EXIT_REFERENCE, EXIT_INTERRUPTED = 0, 2, 3, 130
PHASES = ("mesh", "assembly", "search", "rows", "solve", "output")     # run.py's phases, in run order
PETSC_KEY = re.compile(r"-[A-Za-z][A-Za-z0-9_]*")
MAX_TIMEOUT = 1e6       # s (11.6 days): a run's --timeout; wait() takes at most ~2.1e6 (its poll's milliseconds)
ERROR_COLUMNS = ("displacement_l2", "energy", "force", "max_penetration", "traction")


class SweepInputError(QscError):
    """Bad sweep arguments; one line naming the argument."""


# ---------------------------------------------------------------- arguments

def split_values(text):
    """Split v1,v2,... on the commas outside brackets, parentheses and quotes: "[2,2,1],[4,4,2]" -> ["[2,2,1]",
    "[4,4,2]"], "1,maximum(x,0.5)" -> ["1", "maximum(x,0.5)"]."""
    out, depth, quote, cur = [], 0, None, []
    for ch in text:
        if quote:
            quote = None if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch in "[{(":
            depth += 1
        elif ch in "]})":
            depth -= 1
        elif ch == "," and depth == 0:
            out.append("".join(cur).strip())
            cur = []
            continue
        cur.append(ch)
    out.append("".join(cur).strip())
    return out


@dataclass
class Variation:
    """One --vary (or --reference) key: a scene key path, a PETSc option (-name) or the rank count."""

    key: str
    values: list
    kind: str        # "scene", "petsc" or "ranks"
    source: str      # the argument as given, for messages


def parse_variation(text, flag, ranks_key, single=False):
    key, sep, raw = text.partition("=")
    key = key.strip()
    example = "key.path=value" if single else "key.path=v1,v2,..."
    if not sep or not key or not raw.strip():
        raise SweepInputError(f"{flag} {text!r}: expected {example}")
    values = [raw.strip()] if single else split_values(raw)
    if any(not v for v in values):
        raise SweepInputError(f"{flag} {text!r}: empty value in {raw!r}")
    if len(set(values)) != len(values):
        raise SweepInputError(f"{flag} {text!r}: a value is listed twice")
    if key == ranks_key:
        if not all(re.fullmatch(r"[1-9][0-9]*", v) for v in values):
            raise SweepInputError(f"{flag} {text!r}: {ranks_key} takes positive integers (MPI ranks)")
        return Variation(key, values, "ranks", text)
    if key.startswith("-"):
        if not PETSC_KEY.fullmatch(key):
            raise SweepInputError(f"{flag} {text!r}: {key!r} is not a PETSc option name (e.g. -qsc_pc_type)")
        unread = unread_option(key[1:])
        if unread is not None:
            raise SweepInputError(f"{flag} {text!r}: {unread}")
        return Variation(key, values, "petsc", text)
    return Variation(key, values, "scene", text)


def _join_flag_values(argv):
    """--vary X -> --vary=X, so that a value starting with '-' (a PETSc option) is not taken for an option."""
    out, i = [], 0
    while i < len(argv):
        tok = argv[i]
        if tok in ("--vary", "--reference", "--set") and i + 1 < len(argv):
            out.append(f"{tok}={argv[i + 1]}")
            i += 2
            continue
        out.append(tok)
        i += 1
    return out


def build_parser():
    p = argparse.ArgumentParser(
        prog="qsc sweep", allow_abbrev=False,
        description="Run SCENE for every combination of the --vary values (each run a subprocess), compare each "
        "with a reference run, and write sweep.csv, sweep.md and pareto.png. PETSc options after the scene "
        "go to every run.")
    p.add_argument("scene", help="scene file (TOML)")
    p.add_argument("--vary", action="append", default=[], metavar="KEY=V1,V2,...",
                   help="a scene key path (contact.0.penalty=1e2,1e4), a PETSc option (-qsc_pc_type=gamg,lu) or "
                   "the rank count (ranks=1,2); repeatable: the runs are the cartesian product")
    p.add_argument("--reference", action="append", default=[], metavar="KEY=VALUE",
                   help="the reference run's value of a key (default: the first value of each --vary); "
                   "repeatable, may name keys that are not varied (e.g. a finer mesh)")
    p.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                   help="a scene override for every run, the reference included (repeatable)")
    p.add_argument("--out", help="output folder (default: results/<scene name>_sweep)")
    p.add_argument("--ranks-key", default="ranks", help="the --vary/--reference key giving the MPI rank count (default: ranks; without it every "
                                                         "run takes 1 rank)")
    p.add_argument("--timeout", type=float, default=None, metavar="SECONDS",
                   help="stop a run after this wall time, at most 1e6 s, and record it as failed (default: no limit)")
    return p


@dataclass
class Plan:
    """What the sweep will run: the scene, the fixed arguments, the reference and the combinations."""

    scene: Path
    scene_name: str
    out: Path
    variations: list
    reference: dict                      # key -> value (varied keys and reference-only keys)
    reference_only: list                 # Variations given only by --reference
    sets: list = field(default_factory=list)
    petsc: list = field(default_factory=list)
    ranks_key: str = "ranks"
    timeout: float | None = None
    argv: list = field(default_factory=list)

    def combinations(self):
        keys = [v.key for v in self.variations]
        return [dict(zip(keys, values)) for values in itertools.product(*(v.values for v in self.variations))]

    def kinds(self):
        return {v.key: v.kind for v in self.variations + self.reference_only}


def _scene_option(key):
    """The PETSc option a scene key of the [petsc] table sets (petsc.ksp_rtol: -qsc_ksp_rtol; nested tables
    joined by "_"), or None for any other key."""
    return "-" + PREFIX + key[len("petsc."):].replace(".", "_") if key.startswith("petsc.") else None


def make_plan(argv):
    """Parse and validate the sweep's arguments; every combination's scene is loaded (no run yet)."""
    from .scene import load_scene
    own, petsc = split_petsc_args(_join_flag_values(list(argv)))
    args = build_parser().parse_args(own)
    variations, seen = [], set()
    for text in args.vary:
        v = parse_variation(text, "--vary", args.ranks_key)
        if v.key in seen:
            raise SweepInputError(f"--vary {text!r}: {v.key} is varied twice")
        seen.add(v.key)
        variations.append(v)
    if not variations:
        raise SweepInputError("--vary: give at least one variation, e.g. --vary contact.0.penalty=1e2,1e4")
    reference = {v.key: v.values[0] for v in variations}
    reference_only, given = [], set()
    for text in args.reference:
        v = parse_variation(text, "--reference", args.ranks_key, single=True)
        if v.key in given:
            raise SweepInputError(f"--reference {text!r}: {v.key} is given twice")
        given.add(v.key)
        reference[v.key] = v.values[0]
        if v.key not in seen:
            reference_only.append(v)
    petsc_names = {tok for tok in petsc if PETSC_KEY.fullmatch(tok)}
    for name in sorted(petsc_names):
        unread = unread_option(name[1:])
        if unread is not None:
            raise SweepInputError(unread)
    # the values each run's own check would refuse (options.value_error), before any run (hunt32_3)
    values = [(tok[1:], petsc[i + 1] if i + 1 < len(petsc) and not PETSC_KEY.fullmatch(petsc[i + 1]) else None,
               "the PETSc options for every run") for i, tok in enumerate(petsc) if PETSC_KEY.fullmatch(tok)]
    for v in variations + reference_only:
        option = v.key if v.kind == "petsc" else _scene_option(v.key)
        values += [(option[1:], value, repr(v.source)) for value in v.values] if option else []
    for name, value, where in values:
        why = value_error(name, None if value in ("true", "") else value)
        if why is not None:
            raise SweepInputError(f"{where}: {why}")
    set_keys = {s.partition("=")[0].strip() for s in args.set}
    for v in variations + reference_only:
        if v.kind == "petsc" and v.key in petsc_names:
            raise SweepInputError(f"{v.source!r}: {v.key} is also given as a PETSc option for every run")
        if v.kind == "scene" and v.key in set_keys:
            raise SweepInputError(f"{v.source!r}: {v.key} is also given by --set")
        # a scene's [petsc] option yields to the command line's: every run would solve alike, each row labelled
        # with its own value (hunt32_3: petsc.pc_type=gamg,hypre under -qsc_pc_type lu, two LU runs)
        option = _scene_option(v.key) if v.kind == "scene" else None
        if option in petsc_names:
            raise SweepInputError(f"{v.source!r}: {v.key} is also given as the PETSc option {option} for every "
                                  f"run, which takes precedence over the scene's [petsc] table")
    if args.timeout is not None and not 0 < args.timeout <= MAX_TIMEOUT:
        # inf or 1e7 s raised OverflowError in communicate() after the earlier sweep was removed, its reference
        # run left going on alone (hunt34_3)
        raise SweepInputError(f"--timeout: must be a positive number of seconds up to {MAX_TIMEOUT:g} (omit it for "
                              f"no limit), got {args.timeout:g}")
    if args.out == "":
        raise SweepInputError("--out: an empty folder name (omit --out for results/<scene name>_sweep)")
    try:
        scene = load_scene(args.scene, args.set)
    except SceneError as exc:
        raise SweepInputError(f"{exc}" if not args.set else f"--set: {exc}") from None
    # each scene value on its own first, so that the message names the --vary it came from
    for v in variations + reference_only:
        if v.kind != "scene":
            continue
        flag = "--vary" if v in variations else "--reference"
        for value in v.values:
            try:
                load_scene(args.scene, args.set + [f"{v.key}={value}"])
            except SceneError as exc:
                raise SweepInputError(f"{flag} {v.source!r}: {exc}") from None
    plan = Plan(Path(args.scene), scene.name, Path(args.out or f"results/{scene.name}_sweep"), variations,
                reference, reference_only, list(args.set), petsc, args.ranks_key, args.timeout, list(argv))
    for combo in plan.combinations() + [plan.reference]:
        try:
            load_scene(args.scene, plan.sets + scene_sets(combo, plan.kinds()))
        except SceneError as exc:
            raise SweepInputError(f"the combination {describe(combo)}: {exc}") from None
    if any(int(c.get(plan.ranks_key, 1)) > 1 for c in plan.combinations() + [plan.reference]) \
            and shutil.which("mpirun") is None:
        raise SweepInputError(f"{plan.ranks_key}: runs on several ranks need mpirun, which is not on the PATH")
    return plan


def scene_sets(combo, kinds):
    return [f"{k}={v}" for k, v in combo.items() if kinds[k] == "scene"]


def describe(combo):
    return " ".join(f"{k}={v}" for k, v in combo.items()) or "(the scene as it is)"


# ---------------------------------------------------------------- one run

def run_command(plan, combo, folder):
    """The argv of one run: mpirun -n R <python> -m qsc_petsc.cli run SCENE --out folder --set ... [PETSc options]."""
    kinds = plan.kinds()
    ranks = int(combo.get(plan.ranks_key, 1))
    cmd = [sys.executable, "-m", "qsc_petsc.cli", "run", str(plan.scene), "--out", str(folder)]
    for s in plan.sets + scene_sets(combo, kinds):
        cmd += ["--set", s]
    cmd += plan.petsc
    for k, v in combo.items():
        if kinds[k] == "petsc":
            cmd += [k, v]
    mpirun = shutil.which("mpirun")
    if mpirun is None:                       # checked in make_plan: only single-rank runs get here
        return cmd
    launcher = [mpirun]
    if "Open MPI" in _mpirun_version(mpirun):
        launcher.append("--oversubscribe")   # a sweep may ask for more ranks than cores
    return launcher + ["-n", str(ranks)] + cmd


_VERSIONS = {}


def _mpirun_version(mpirun):
    if mpirun not in _VERSIONS:
        try:
            _VERSIONS[mpirun] = subprocess.run([mpirun, "--version"], capture_output=True, text=True,
                                               timeout=30, check=False).stdout
        except (OSError, subprocess.TimeoutExpired):
            _VERSIONS[mpirun] = ""
    return _VERSIONS[mpirun]


_LAUNCHER_NOISE = re.compile(r"^(\[[^\]]*:\d+\]|Primary job|mpirun|a non-zero exit|Process name|Exit code|"
                            r"the job to be terminated|job has been|MPI_ABORT|with errorcode|NOTE: invoking|"
                            r"You may or may not|exactly when|-+$|=+$|\*+$)")


def _last_error_line(stdout, stderr):
    """The line that says why a run failed: qsc's own message, else the last line of stderr or stdout.

    mpirun's epilogue (which only says that a process failed) is skipped, and PETSc's "[0] " rank
    prefix dropped, so a PETSc error ends on its message ("Unable to find requested PC type ...")."""
    for line in reversed(stdout.splitlines() + stderr.splitlines()):
        if line.startswith(("qsc: error:", "qsc: solve failed:")):
            return line.split(": ", 1)[1]
    if "mpirun does not support recursive calls" in stdout + stderr:
        # the sweep itself started under mpirun: every run "failed (*****)", Open MPI's banner (hunt35_2)
        return ("mpirun does not support recursive calls: run qsc sweep without mpirun (it starts each run's own "
                "mpirun)")
    for text in (stderr, stdout):
        lines = [ln.strip() for ln in text.splitlines()]
        lines = [re.sub(r"^\[\d+\]\s*", "", ln) for ln in lines if ln and not _LAUNCHER_NOISE.match(ln)]
        if lines:
            return lines[-1]
    return ""


def _stop(proc, grace=10.0):
    """Ctrl-C to a run's process group (mpirun ends its ranks on it), then SIGTERM and SIGKILL, each after `grace`
    seconds; waits for it."""
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
        try:
            os.killpg(proc.pid, sig)
            proc.communicate(timeout=grace)
            return
        except subprocess.TimeoutExpired:
            continue
        except ProcessLookupError:
            return


def execute(plan, combo, folder):
    """Run one combination into `folder` (made afresh); return its record (status, timings, iterations)."""
    if folder.exists():
        shutil.rmtree(folder)                # a stale summary.json must never pass for this run's
    folder.mkdir(parents=True)
    cmd = run_command(plan, combo, folder)
    env = dict(os.environ)
    env.setdefault("OMP_NUM_THREADS", "1")   # ranks share the cores: no threaded BLAS on top
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                            start_new_session=True)
    try:
        stdout, stderr = proc.communicate(timeout=plan.timeout)
        rc = proc.returncode
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        stdout, stderr = proc.communicate()
        rc = None
    except KeyboardInterrupt:
        # the run has a session of its own (a timeout kills its whole group): pass Ctrl-C on, so that it stops
        # (and says "interrupted" where it can) instead of running on without the sweep
        _stop(proc)
        raise
    wall = time.perf_counter() - t0
    (folder / "sweep_run.log").write_text(f"$ {shlex.join(cmd)}\n# exit code {rc}, {wall:.3f} s\n"
                                          f"--- stdout\n{stdout}--- stderr\n{stderr}")
    record = {"folder": folder, "command": cmd, "exit_code": rc, "wall_time": wall, "message": ""}
    summary = {}
    if (folder / "summary.json").is_file():
        try:
            summary = json.loads((folder / "summary.json").read_text())
        except json.JSONDecodeError:
            summary = {}
    if rc == 0 and summary.get("status") == "ok":
        record["status"] = "ok"
    elif rc == 3:
        record["status"] = "not converged"
        record["message"] = _last_error_line(stdout, stderr)
    else:
        record["status"] = "failed"
        record["message"] = (f"timed out after {plan.timeout:g} s" if rc is None
                             else _last_error_line(stdout, stderr) or f"exit code {rc}")
    record.update(_from_summary(summary))
    return record


def _from_summary(summary):
    steps = summary.get("steps", [])
    mem = summary.get("peak_memory_mib", {})
    return {
        "ranks": summary.get("ranks"), "dofs": summary.get("mesh", {}).get("dofs"),
        "steps": len(steps),
        # of the load steps completed: a step that failed records none
        "newton": sum(s.get("snes_iterations", 0) for s in steps) if steps else None,
        "krylov": sum(s.get("ksp_iterations", 0) for s in steps) if steps else None,
        "cutbacks": sum(s.get("cutbacks", 0) for s in steps) if steps else None,
        "time": dict(summary.get("time", {})),
        "memory_total": mem.get("total"), "memory_max_rank": mem.get("max_rank"),
    }


def compare_with_reference(record, reference):
    from . import compare
    try:
        record["errors"] = compare.errors(record["folder"], reference["folder"])
    except QscError as exc:
        record["errors"] = None
        record["message"] = (record["message"] + "; " if record["message"] else "") + f"compare: {exc}"


# ---------------------------------------------------------------- tables and the plot

def _fmt(x, spec=".3g"):
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return ""
    return format(x, spec) if isinstance(x, float) else str(x)


# errors this close (relative) are the same answer's: 1 and 2 ranks of one scene differ by round-off (3e-16), and
# the slower run was marked on the front beside the faster one (hunt32_3)
ERROR_TIE = 1e-9


def pareto_front(points):
    """Indices of the non-dominated (time, error) points: no other point is as fast and as accurate, and better in
    one (errors within ERROR_TIE of each other, relative, are equal)."""
    front = []
    for i, (t, e) in enumerate(points):
        if not any((t2 <= t and e2 <= e * (1 + ERROR_TIE)) and (t2 < t or e2 < e * (1 - ERROR_TIE))
                   for j, (t2, e2) in enumerate(points) if j != i):
            front.append(i)
    return front


def run_seconds(rec):
    """The run's own wall time: the sum of its phases (max over ranks each), as `qsc run` reports it."""
    return sum(rec["time"].values()) if rec.get("time") else None


def _interaction_tags(rows):
    tags = set()
    for r in rows:
        tags.update((r.get("errors") or {}).get("contact", {}))
    return sorted(tags)


def csv_rows(plan, rows):
    phases = [p for p in PHASES if any(p in r["time"] for r in rows)]
    phases += sorted({p for r in rows for p in r["time"]} - set(phases))
    tags = _interaction_tags(rows)
    keys = [v.key for v in plan.variations] + [v.key for v in plan.reference_only]
    header = (["run", "folder"] + keys + ["status", "exit_code", "message", "mpi_ranks", "dofs", "steps",
                                          "newton_iterations", "krylov_iterations", "cutbacks", "wall_time_s",
                                          "run_time_s"]
              + [f"time_{p}_s" for p in phases] + ["peak_memory_total_mib", "peak_memory_max_rank_mib"]
              + list(ERROR_COLUMNS)
              + [f"{q}[{t}]" for t in tags for q in ("force", "max_penetration", "max_penetration_m")]
              + ["pareto"])
    out = []
    for r in rows:
        e = r.get("errors") or {}
        row = [r["name"], str(r["folder"])] + [r["combo"].get(k, "") for k in keys]
        row += [r["status"], "" if r["exit_code"] is None else r["exit_code"], r["message"], r.get("ranks"),
                r.get("dofs"), r.get("steps"), r.get("newton"), r.get("krylov"), r.get("cutbacks"),
                f"{r['wall_time']:.4g}", _fmt(run_seconds(r), ".4g")]
        row += [_fmt(r["time"].get(p), ".4g") for p in phases]
        row += [_fmt(r.get("memory_total"), ".4g"), _fmt(r.get("memory_max_rank"), ".4g")]
        row += [_fmt(e.get(c), ".6g") for c in ERROR_COLUMNS]
        for t in tags:
            c = e.get("contact", {}).get(t, {})
            row += [_fmt(c.get("force"), ".6g"), _fmt(c.get("max_penetration"), ".6g"),
                    _fmt(c.get("max_penetration_value"), ".6g")]
        row.append("yes" if r.get("pareto") else "")
        out.append(["" if x is None else x for x in row])
    return header, out


def _short_names(keys):
    last = [k.lstrip("-").split(".")[-1] for k in keys]
    return [s if last.count(s) == 1 else k for s, k in zip(last, keys)]


def markdown(plan, rows, command):
    keys = [v.key for v in plan.variations]
    ref_only = ", ".join(f"`{v.key}={plan.reference[v.key]}`" for v in plan.reference_only)
    lines = [f"# qsc sweep: {plan.scene_name}", "", f"Command: `{command}`", "",
             f"Reference run (`reference/`): {describe({k: plan.reference[k] for k in keys})}"
             + (f", and {ref_only}" if ref_only else "") + ".", "",
             ("Errors are relative to the reference run: `u L2` = ||u - u_ref||_L2 / ||u_ref||_L2 and `energy` the "
             "same in the energy norm (over the run's mesh, the reference interpolated there); `force` and "
             "`penetration` the largest relative difference of the total contact force and of the largest "
             "penetration over the contact pairs and dies; `traction` the relative RMS difference of the contact "
             "traction at the run's contact nodes. `run s` is the run's own wall time (sum of its phases, each the "
             "max over ranks), `total s` the whole subprocess (start-up included), `memory` the peak resident "
             "memory summed over ranks. `*`: non-dominated in (run s, u L2) -- no other run is both faster and "
             "more accurate."), ""]
    head = ["run"] + _short_names(keys) + ["status", "dofs", "Newton", "Krylov", "run s", "total s", "solve s",
                                           "memory MiB", "u L2", "energy", "force", "penetration", "traction", ""]
    lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        e = r.get("errors") or {}
        status = r["status"] + (f" ({r['exit_code']}): {r['message']}" if r["status"] != "ok" else "")
        status = (status if len(status) <= 120 else status[:117] + "...").replace("|", "\\|")
        name = r["name"] + (" (= reference)" if r.get("is_reference_copy") else "")
        cells = [name] + [f"`{r['combo'].get(k, '')}`" for k in keys] + [
            status, _fmt(r.get("dofs")), _fmt(r.get("newton")), _fmt(r.get("krylov")),
            _fmt(run_seconds(r), ".3g"), _fmt(r["wall_time"], ".3g"), _fmt(r["time"].get("solve"), ".3g"),
            _fmt(r.get("memory_total"), ".4g")] + [_fmt(e.get(c), ".2e") for c in ERROR_COLUMNS] + [
            "*" if r.get("pareto") else ""]
        lines.append("| " + " | ".join(cells) + " |")
    failed = [r["name"] for r in rows if r["status"] != "ok"]
    lines += ["", f"{len(rows)} rows ({len(rows) - 1} combinations and the reference), "
              f"{len(rows) - len(failed)} ok" + (f"; not ok: {', '.join(failed)}" if failed else "") + "."]
    return "\n".join(lines) + "\n"


def plot_pareto(plan, rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7.5, 5.5))
    pts = [r for r in rows if r.get("plotted")]
    keys = [v.key for v in plan.variations]
    short = dict(zip(keys, _short_names(keys)))
    if pts:
        t = [run_seconds(r) for r in pts]
        e = [r["errors"]["displacement_l2"] for r in pts]
        ax.scatter(t, e, color="0.55", s=28, label="run", zorder=2)
        front = sorted((r for r in pts if r.get("pareto")), key=run_seconds)
        ax.plot([run_seconds(r) for r in front], [r["errors"]["displacement_l2"] for r in front], "o-",
                color="tab:red", ms=7, label="non-dominated", zorder=3)
        for r in front:
            label = ", ".join(f"{short[k]}={r['combo'][k]}" for k in keys)
            ax.annotate(label, (run_seconds(r), r["errors"]["displacement_l2"]), textcoords="offset points",
                        xytext=(6, 4), fontsize=7)
        ax.margins(0.25)                       # room for the labels
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.legend(loc="best", fontsize=8)
    else:
        ax.text(0.5, 0.5, "no run with a nonzero, finite error to plot", ha="center", va="center",
                transform=ax.transAxes)
    skipped = [r["name"] + ("" if r["status"] == "ok" else f" ({r['status']})") for r in rows if not r.get("plotted")]
    ax.set_xlabel("run wall time [s] (sum of phases)")
    ax.set_ylabel("relative displacement L2 error vs reference")
    if len(skipped) > 6:
        skipped = skipped[:5] + [f"{len(skipped) - 5} more"]
    ax.set_title(f"{plan.scene_name}: time against error"
                 + (f"\nnot shown: {', '.join(skipped)}" if skipped else ""), fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def mark_pareto(rows):
    """Set each row's "plotted" (a finished comparison with a run time) and "pareto" (on the front of run time
    against displacement error among the plotted rows) afresh: the outputs are rewritten after every run, and a row
    on an earlier front may be beaten by a later run."""
    for r in rows:
        e = (r.get("errors") or {}).get("displacement_l2")
        r["plotted"] = (r["status"] == "ok" and not r.get("is_reference") and e is not None and math.isfinite(e)
                        and e > 0 and run_seconds(r))
        r["pareto"] = False
    eligible = [r for r in rows if r["plotted"]]
    for i in pareto_front([(run_seconds(r), r["errors"]["displacement_l2"]) for r in eligible]):
        eligible[i]["pareto"] = True


TABLES = ("sweep.csv", "sweep.md", "pareto.png")      # what write_outputs writes


def write_outputs(plan, rows, command):
    """sweep.csv, sweep.md and pareto.png into the output folder; marks the Pareto rows first."""
    mark_pareto(rows)
    header, body = csv_rows(plan, rows)
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(body)
    (plan.out / "sweep.csv").write_text(buf.getvalue())
    (plan.out / "sweep.md").write_text(markdown(plan, rows, command))
    plot_pareto(plan, rows, plan.out / "pareto.png")


# ---------------------------------------------------------------- the sweep

def prepare_out(plan):
    """The sweep's folder made, and an earlier sweep's tables and runs removed: they are not this one's (its
    run_NNN folders beyond this sweep's count stayed beside a sweep.csv that did not list them; a helper's test
    pass, session 26). A SweepInputError when the folder cannot hold the results (a file of its name, or of
    the reference's, a folder named as a table): a traceback and exit 1 before (hunt32_3)."""
    out = plan.out
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SweepInputError(folder_error("--out", out, exc)) from None
    for name in (*TABLES, "reference"):
        path = out / name
        if path.exists() and path.is_dir() != (name == "reference"):
            raise SweepInputError(f"--out: {str(path)!r} is a {'folder' if path.is_dir() else 'file'}: the sweep "
                                  f"writes its {'reference run' if name == 'reference' else 'table'} there")
    try:
        for name in TABLES:
            (out / name).unlink(missing_ok=True)
        for folder in out.glob("run_*"):
            if folder.is_dir() and folder.name[4:].isdigit():      # run_001 ... run_999, run_1000 ...
                shutil.rmtree(folder)
    except OSError as exc:
        raise SweepInputError(f"--out: cannot remove the earlier sweep's {str(exc.filename)!r}: "
                              f"{exc.strerror}") from None


def sweep(plan, say=print, reference=None):
    """Run the reference, then every combination; write the outputs after each run. Returns the rows.

    `reference`: the reference row (rows[0]) of an earlier sweep whose reference run is this plan's
    (the same command), reused instead of solved again -- sweeps that share one costly reference."""
    if reference is not None:
        expected = run_command(plan, plan.reference, reference["folder"])
        if reference.get("command") != expected:
            raise ValueError(f"the reused reference ran {shlex.join(reference.get('command', []))}; this "
                             f"sweep's reference would run {shlex.join(expected)}")
    prepare_out(plan)
    command = "qsc sweep " + shlex.join(plan.argv)
    combos = plan.combinations()
    n = len(combos) + 1
    say(f"qsc sweep: {plan.scene_name}: {len(combos)} combination(s) and the reference, results in {plan.out}")
    rows = []

    def report(i, rec):
        e = (rec.get("errors") or {}).get("displacement_l2")
        what = rec["status"] if rec["status"] == "ok" else f"{rec['status']} ({rec['message']})"
        iters = f", {rec['newton']} Newton / {rec['krylov']} Krylov" if rec.get("newton") is not None else ""
        err = f", u L2 error {e:.3e}" if e is not None else ""
        say(f"[{i}/{n}] {rec['name']}: {describe(rec['combo'])}: {what} in {rec['wall_time']:.2f} s{iters}{err}",
            flush=True)

    if reference is not None:
        ref = dict(reference)
    else:
        ref = execute(plan, plan.reference, plan.out / "reference")
        ref.update(name="reference", combo=dict(plan.reference), is_reference=True)
        if ref["status"] == "ok":
            compare_with_reference(ref, ref)
    rows.append(ref)
    report(1, ref)
    write_outputs(plan, rows, command)
    for i, combo in enumerate(combos, start=1):
        name = f"run_{i:03d}"
        if combo == plan.reference:          # the reference already is this run: reuse it
            rec = dict(ref, name=name, combo=dict(combo), is_reference_copy=True)
        else:
            rec = execute(plan, combo, plan.out / name)
            rec.update(name=name, combo=dict(combo))
            if rec["status"] == "ok" and ref["status"] == "ok":
                compare_with_reference(rec, ref)
        rows.append(rec)
        report(i + 1, rec)
        write_outputs(plan, rows, command)
    say(f"qsc sweep: wrote {plan.out / 'sweep.csv'}, sweep.md, pareto.png")
    return rows


def main(argv):
    """The `qsc sweep` command; returns the exit code (0, 2 bad arguments, 3 the reference run failed). Its lines
    go through cli.say_line: `qsc sweep ... | head -1` ended in a BrokenPipeError traceback after the reference
    run, with no sweep.csv (hunt35_3)."""
    from .cli import say_line as say
    try:
        plan = make_plan(argv)
        prepare_out(plan)
    except QscError as exc:
        say(f"qsc sweep: error: {exc}")
        return EXIT_INPUT
    try:
        rows = sweep(plan, say=say)
    except KeyboardInterrupt:
        table = plan.out / "sweep.csv"
        say(f"qsc sweep: interrupted; the runs done are in {table}" if table.is_file() else
              f"qsc sweep: interrupted before any run was done (the reference's folder: {plan.out / 'reference'})")
        return EXIT_INTERRUPTED
    if rows[0]["status"] != "ok":
        say(f"qsc sweep: the reference run did not succeed ({rows[0]['status']}: {rows[0]['message']}); "
              "no errors were computed")
        return EXIT_REFERENCE
    return EXIT_OK
