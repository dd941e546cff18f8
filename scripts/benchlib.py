"""Shared by the benchmark scripts: run a scene under mpirun, collect summary.json, update docs/performance.md."""

import json
import os
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
QSC = ROOT / ".venv" / "bin" / "qsc"
ENV = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1", OMP_NUM_THREADS="1")


def run(scene_text, ranks, extra=(), timeout=1800):
    """Run a scene given as TOML text on `ranks` ranks; returns (summary dict, wall seconds)."""
    with tempfile.TemporaryDirectory(prefix="qsc_bench_") as tmp:
        scene = Path(tmp) / "scene.toml"
        scene.write_text(scene_text)
        out = Path(tmp) / "out"
        cmd = ["mpirun", "--oversubscribe", "-n", str(ranks), str(QSC), "run", str(scene), "--out", str(out), *extra]
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, env=ENV, capture_output=True, text=True, timeout=timeout, check=False)
        wall = time.perf_counter() - t0
        if proc.returncode != 0:
            sys.stderr.write(proc.stdout + proc.stderr)
            raise RuntimeError(f"run failed ({proc.returncode}): {' '.join(cmd)}")
        return json.loads((out / "summary.json").read_text()), wall


def replace_section(path, title, body):
    """Replace (or append) the '## title' section of a Markdown file."""
    path = Path(path)
    text = path.read_text() if path.exists() else "# Performance\n\nMeasured on this project's machines (2 cores, 24 GiB); each table says the command that made it.\n"
    head = f"## {title}\n"
    start = text.find(head)
    if start < 0:
        text = text.rstrip("\n") + "\n\n" + head + body
    else:
        end = text.find("\n## ", start + len(head))
        text = text[:start] + head + body.rstrip("\n") + "\n\n" + (text[end + 1:] if end >= 0 else "")
    path.write_text(text.rstrip("\n") + "\n")


def add_docs_args(parser, title, petsc=True):
    """The options every docs-writing script shares: extra PETSc options and the section to (re)write."""
    if petsc:
        parser.add_argument("--petsc", default="", help='PETSc options for every run, e.g. "-qsc_pc_type lu"')
    parser.add_argument("--title", default=title, help="the docs section to (re)write")


def write_table(path, title, script, description, columns, rows):
    """(Re)write a docs section: the command that made it (this process's arguments), what it measures,
    and a Markdown table with the given column names and pre-formatted '| ... |' rows."""
    command = " ".join([".venv/bin/python", f"scripts/{script}", shlex.join(sys.argv[1:])]).rstrip()
    table = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns), *rows]
    replace_section(path, title, f"Command: `{command}` ({description})\n\n" + "\n".join(table) + "\n")
