"""qsc sweep: argument checks before any run, the three output files, failed runs recorded while the sweep goes on.

The sweeps start real `qsc run` subprocesses (through mpirun) on a tiny patch test (150 dofs), so
these tests run only in the serial suite.
"""

import csv
import os
import shutil
from pathlib import Path

import pytest
from conftest import CONFIGS
from mpi4py import MPI

from qsc_petsc import cli
from qsc_petsc.sweep import SweepInputError, mark_pareto, pareto_front, parse_variation, split_values

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="starts MPI jobs itself: serial suite only")

SCENE = str(CONFIGS / "patch_test.toml")
TINY = ["--set", "bodies.0.mesh.cells=[2,2,1]", "--set", "bodies.1.mesh.cells=[3,3,1]"]


@pytest.fixture
def mpi_env(monkeypatch):
    monkeypatch.setenv("OMPI_ALLOW_RUN_AS_ROOT", "1")
    monkeypatch.setenv("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
    monkeypatch.setenv("OMP_NUM_THREADS", "1")


def read_csv(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_values_split_outside_brackets():
    assert split_values("[2,2,1],[4,4,2]") == ["[2,2,1]", "[4,4,2]"]
    assert split_values('1e2, 1e4,"a,b"') == ["1e2", "1e4", '"a,b"']
    assert split_values("1,maximum(x,0.5)") == ["1", "maximum(x,0.5)"]      # an expression's arguments stay whole
    v = parse_variation("-qsc_pc_type=gamg,hypre,lu", "--vary", "ranks")
    assert (v.kind, v.values) == ("petsc", ["gamg", "hypre", "lu"])
    assert parse_variation("ranks=1,2", "--vary", "ranks").kind == "ranks"
    for bad in ("contact.0.penalty", "=1,2", "ranks=0,2", "contact.0.penalty=1e2,,1e4", "-qsc pc=1,2", "a=1,1"):
        with pytest.raises(SweepInputError):
            parse_variation(bad, "--vary", "ranks")
    # an unprefixed solver option, which no run would read: its rows were identical (a helper's pass)
    with pytest.raises(SweepInputError, match="-qsc_pc_type"):
        parse_variation("-pc_type=lu,gamg", "--vary", "ranks")


def test_pareto_marks_follow_the_later_runs():
    """The outputs are rewritten after every run: a row on the front after the first runs shall lose its mark once
    a later run is both faster and more accurate (it kept it: the sweep marked beaten runs as non-dominated)."""
    def row(seconds, error):
        return {"status": "ok", "time": {"solve": seconds}, "errors": {"displacement_l2": error}}
    rows = [row(0.0112, 3.15e-11), row(0.0116, 3.97e-12)]
    mark_pareto(rows)
    assert [r["pareto"] for r in rows] == [True, True]
    rows.append(row(0.0107, 3.06e-13))              # faster and more accurate than both
    mark_pareto(rows)
    assert [r["pareto"] for r in rows] == [False, False, True]


def test_pareto_front():
    pts = [(1.0, 1.0), (2.0, 0.5), (2.0, 2.0), (3.0, 0.5), (0.5, 3.0), (1.0, 1.0)]
    # (2, 2) is dominated by (1, 1); (3, 0.5) by (2, 0.5); the two equal points dominate neither each other
    assert pareto_front(pts) == [0, 1, 4, 5]
    # the same answer on 2 ranks, slower, round-off apart: not on the front (hunt32_3)
    assert pareto_front([(0.73, 8.330889926361691e-4), (2.03, 8.330889926359006e-4)]) == [0]


@pytest.mark.parametrize("args, names", [
    (["--vary", "contact.0.formulaton=master_slave,two_pass"], "contact.0.formulaton"),
    (["--vary", "contact.0.formulation=master_slave,bogus"], "bogus"),
    (["--vary", "contact.0.penalty"], "contact.0.penalty"),
    (["--vary", "contact.0.penalty=1e2", "--vary", "contact.0.penalty=1e4"], "varied twice"),
    (["--vary", "contact.0.penalty=1e2", "--reference", "bodies.7.mesh.cells=[2,2,2]"], "bodies[7]"),
    (["--vary", "petsc.pc_type=lu", "-qsc_pc_type", "lu", "--vary", "-qsc_pc_type=gamg,lu"], "-qsc_pc_type"),
    (["--vary", "contact.0.penalty=1e2,1e4", "--timeout", "-5"], "--timeout: must be a positive number"),
    # an OverflowError in the wait, after the earlier sweep was removed (hunt34_3)
    (["--vary", "contact.0.penalty=1e2,1e4", "--timeout", "inf"], "--timeout: must be a positive number of seconds up to"),
    (["--vary", "contact.0.penalty=1e2,1e4", "--timeout", "1e7"], "--timeout: must be a positive number of seconds up to"),
    # a scene [petsc] value the command line overrides: every run alike, labelled apart (hunt32_3)
    (["--vary", "petsc.pc_type=gamg,hypre", "-qsc_pc_type", "lu"], "the PETSc option -qsc_pc_type for every run"),
    # values each run would refuse, refused before the first (hunt32_3)
    (["--vary", "-qsc_ksp_rtol=1e-8,2"], "-qsc_ksp_rtol: must be below 1"),
    (["--vary", "petsc.ksp_max_it=-1,3"], "-qsc_ksp_max_it: must be an integer >= 0"),
    (["--vary", "contact.0.penalty=1e2,1e4", "-qsc_ksp_rtol"], "-qsc_ksp_rtol: needs a number (no value given)"),
])
def test_bad_arguments_exit_2_before_any_run(tmp_path, capsys, args, names):
    out = tmp_path / "sweep"
    assert cli.main(["sweep", SCENE, "--out", str(out)] + TINY + args) == 2
    text = capsys.readouterr().out
    assert len(text.strip().splitlines()) == 1 and names in text, text
    assert not out.exists()


def test_empty_out_is_refused(capsys):
    assert cli.main(["sweep", SCENE, "--out", ""] + TINY + ["--vary", "contact.0.penalty=1e2,1e4"]) == 2
    assert "--out: an empty folder name" in capsys.readouterr().out


@pytest.mark.parametrize("layout, said", [
    ("file", "--out: cannot create the folder"), ("under a file", "--out: cannot create the folder"),
    ("table folder", "sweep.csv' is a folder"), ("reference file", "reference' is a file")])
def test_an_out_that_cannot_hold_the_results_is_refused(tmp_path, capsys, layout, said):
    """An --out the sweep cannot write in ended in a traceback, exit 1 (hunt32_3): one line, exit 2."""
    out = {"file": tmp_path / "f", "under a file": tmp_path / "f" / "sub"}.get(layout, tmp_path / "sweep")
    (tmp_path / "f").write_text("")
    if layout == "table folder":
        (out / "sweep.csv").mkdir(parents=True)
    if layout == "reference file":
        out.mkdir()
        (out / "reference").write_text("")
    assert cli.main(["sweep", SCENE, "--out", str(out)] + TINY + ["--vary", "contact.0.penalty=1e2,1e4"]) == 2
    text = capsys.readouterr().out
    assert len(text.strip().splitlines()) == 1 and said in text, text


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not found")
def test_sweep_writes_csv_table_and_plot(tmp_path, capsys, mpi_env):
    out = tmp_path / "sweep"
    code = cli.main(["sweep", SCENE, *TINY, "--vary", "contact.0.formulation=master_slave,two_pass",
                     "--vary", "contact.0.penalty=1e2,1e4", "--reference", "contact.0.formulation=two_pass",
                     "--out", str(out)])
    assert code == 0
    progress = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("[")]
    assert len(progress) == 5 and all(": ok in " in ln for ln in progress)
    rows = read_csv(out / "sweep.csv")
    assert [r["run"] for r in rows] == ["reference", "run_001", "run_002", "run_003", "run_004"]
    combos = [(r["contact.0.formulation"], r["contact.0.penalty"]) for r in rows]
    assert combos == [("two_pass", "1e2"), ("master_slave", "1e2"), ("master_slave", "1e4"),
                      ("two_pass", "1e2"), ("two_pass", "1e4")]
    assert all(r["status"] == "ok" and r["dofs"] == "150" and int(r["newton_iterations"]) >= 1 for r in rows)
    assert rows[3]["folder"] == rows[0]["folder"]              # the reference's own combination is not run twice
    assert float(rows[0]["displacement_l2"]) == 0.0 == float(rows[3]["displacement_l2"])
    # a flat patch under uniform pressure: master_slave and two_pass both give the exact state at one penalty,
    # so run_001 differs from the reference by rounding only (exactly 0 on some machines); the penalty shows
    assert float(rows[1]["displacement_l2"]) < 1e-10 and float(rows[1]["max_penetration"]) < 1e-10
    for r in (rows[2], rows[4]):
        assert 0.0 < float(r["displacement_l2"]) < 1.0
        assert float(r["energy"]) > 0 and float(r["max_penetration"]) > 0.9 and r["traction"]
    for r in (rows[1], rows[2], rows[4]):
        assert float(r["force"]) < 1e-6                          # every formulation carries the 1 N load
        assert float(r["time_solve_s"]) > 0 and float(r["peak_memory_total_mib"]) > 0
    assert sum(r["pareto"] == "yes" for r in rows) >= 1
    table = (out / "sweep.md").read_text().splitlines()
    assert sum(ln.startswith(("| run_", "| reference")) for ln in table) == 5
    assert (out / "pareto.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not found")
def test_failed_and_unconverged_runs_are_recorded(tmp_path, capsys, mpi_env):
    """One CG iteration cannot converge, a malformed option value is refused as bad input: both recorded, the
    sweep goes on."""
    out = tmp_path / "sweep"
    code = cli.main(["sweep", SCENE, *TINY, "--set", "petsc.ksp_type=cg", "--set", "petsc.pc_type=jacobi",
                     "--set", "solver.max_cutbacks=0", "--vary", "-qsc_ksp_max_it=1000,1,many", "--out", str(out)])
    assert code == 0
    rows = {r["run"]: r for r in read_csv(out / "sweep.csv")}
    assert rows["reference"]["status"] == "ok"
    stuck = rows["run_002"]
    assert (stuck["-qsc_ksp_max_it"], stuck["status"], stuck["exit_code"]) == ("1", "not converged", "3")
    assert "DIVERGED" in stuck["message"] and stuck["displacement_l2"] == ""
    crashed = rows["run_003"]
    assert (crashed["-qsc_ksp_max_it"], crashed["status"]) == ("many", "failed")
    assert crashed["exit_code"] == "2" and "PETSc options" in crashed["message"], crashed["message"]
    assert len([ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("[")]) == 4   # one per run


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not found")
def test_failed_reference_exits_3(tmp_path, capsys, mpi_env):
    out = tmp_path / "sweep"
    code = cli.main(["sweep", SCENE, *TINY, "--vary", "-qsc_pc_type=nonexistent,lu", "--out", str(out)])
    assert code == 3
    rows = read_csv(out / "sweep.csv")
    assert [r["status"] for r in rows] == ["failed", "failed", "ok"]
    assert rows[2]["displacement_l2"] == ""                          # nothing to compare with
    assert "reference run did not succeed" in capsys.readouterr().out
    assert os.path.isfile(out / "sweep.md") and os.path.isfile(out / "pareto.png")


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not found")
def test_ranks_key_sets_the_rank_count(tmp_path, capsys, mpi_env):
    """ranks=1,2: the run on 2 ranks says so in its summary and gives the 1-rank answer."""
    out = tmp_path / "sweep"
    assert cli.main(["sweep", SCENE, *TINY, "--vary", "ranks=1,2", "--out", str(out)]) == 0
    rows = read_csv(out / "sweep.csv")
    assert [(r["ranks"], r["mpi_ranks"]) for r in rows] == [("1", "1"), ("1", "1"), ("2", "2")]
    assert float(rows[2]["displacement_l2"]) < 1e-10 and float(rows[2]["traction"]) < 1e-8


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not found")
def test_a_second_sweep_reuses_the_reference_run(tmp_path, capsys, mpi_env):
    """sweep(plan, reference=rows[0]): the earlier reference run is compared against, not solved again."""
    from qsc_petsc.sweep import make_plan, sweep
    common = [SCENE, *TINY, "--reference", "contact.0.penalty=1e6"]
    first = sweep(make_plan([*common, "--vary", "contact.0.penalty=1e2", "--out", str(tmp_path / "a")]))
    stale = tmp_path / "b" / "run_1000"         # an earlier, longer sweep's run (a helper's test pass, session 26)
    stale.mkdir(parents=True)
    (stale / "summary.json").write_text('{"status": "ok"}')
    (tmp_path / "b" / "notes.txt").write_text("the user's")
    second = sweep(make_plan([*common, "--vary", "contact.0.penalty=1e4", "--out", str(tmp_path / "b")]),
                   reference=first[0])
    assert not (tmp_path / "b" / "reference").exists()
    assert not stale.exists() and (tmp_path / "b" / "notes.txt").is_file()
    assert second[0]["folder"] == first[0]["folder"] and second[1]["status"] == "ok"
    assert 0.0 < second[1]["errors"]["displacement_l2"] < first[1]["errors"]["displacement_l2"]
    rows = read_csv(tmp_path / "b" / "sweep.csv")
    assert rows[0]["folder"] == str(tmp_path / "a" / "reference")
    for other in ([SCENE, *TINY, "--vary", "contact.0.penalty=1e4"],                         # reference 1e4
                  [*common, "--set", "contact.0.integration=gauss", "--vary", "contact.0.penalty=1e4"]):
        with pytest.raises(ValueError, match="reused reference"):
            sweep(make_plan([*other, "--out", str(tmp_path / "c")]), reference=first[0])


def test_ctrl_c_stops_the_run_it_was_on(tmp_path, mpi_env):
    """Ctrl-C on qsc sweep ended the sweep with a traceback while the run it was on (a session of its own) went on
    without it and wrote "ok" that no sweep.csv listed (helper pass, session 25). The interrupt is passed on to
    the run's process group (then SIGTERM, SIGKILL): the run stops, and the sweep says where the rows done are and
    exits 130."""
    import json
    import signal
    import subprocess
    import sys
    import time
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "qsc_petsc.cli", "sweep", str(CONFIGS / "block_compression.toml"),
           "--vary", "ranks=1", "--set", "bodies.0.mesh.cells=[30,30,30]", "--set", "load.steps=12",
           "--set", "solver.predictor=previous", "-qsc_ksp_type", "cg", "-qsc_pc_type", "jacobi", "--out", str(out)]
    # this process's MPI (a singleton) left variables in the environment that stop a child's mpirun at once
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_MCA_", "PMIX_", "OMPI_COMM", "OMPI_FIRST",
                                                                      "OMPI_FILE", "OMPI_NUM", "OMPI_UNIVERSE"))}
    # Ctrl-C as a terminal delivers it: not ignored (a job started in the background ignores it, and so would
    # the sweep this process starts), restored in a launcher that then becomes the sweep
    restore = ("import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_DFL); "
               "os.execv(sys.executable, [sys.executable] + sys.argv[1:])")
    launcher = [sys.executable, "-c", restore]
    proc = subprocess.Popen(launcher + cmd[1:], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    deadline = time.time() + 60
    while not (out / "reference" / "summary.json").is_file() and time.time() < deadline:
        time.sleep(0.2)
    time.sleep(1.0)              # inside the reference run, after its first step's summary (12 steps of ~1 s)
    proc.send_signal(signal.SIGINT)
    text, _ = proc.communicate(timeout=60)
    assert proc.returncode == 130 and "Traceback" not in text, text
    # no sweep.csv to point to yet (it named one that did not exist)
    assert "qsc sweep: interrupted before any run was done" in text and not (out / "sweep.csv").exists(), text
    # stopped: "interrupted" when the rank wrote it before mpirun's SIGKILL followed its SIGTERM, else "running"
    assert json.loads((out / "reference" / "summary.json").read_text())["status"] in ("interrupted", "running")
    def left():
        """The processes still naming the run's folder (no pgrep in the image)."""
        found = []
        for cmdline in Path("/proc").glob("[0-9]*/cmdline"):
            try:
                if str(out / "reference").encode() in cmdline.read_bytes():
                    found.append(cmdline.parent.name)
            except OSError:
                continue
        return found
    # a rank that SIGKILL reached may take a moment to be gone on a loaded machine (CI beside a helper's runs)
    deadline = time.time() + 20
    while left() and time.time() < deadline:
        time.sleep(0.5)
    assert not left(), left()


def test_a_sweep_under_mpirun_says_why_its_runs_fail():
    """qsc sweep started under mpirun: each run's mpirun refused a recursive call, and every row read "failed
    (*****...)", Open MPI's banner (hunt35_2)."""
    from qsc_petsc.sweep import _last_error_line
    banner = ("\n\n" + "*" * 58 + "\n\nmpirun does not support recursive calls\n\n" + "*" * 58 + "\n")
    assert _last_error_line("", banner).startswith("mpirun does not support recursive calls: run qsc sweep without")
    assert _last_error_line("", "[0] Unable to find requested PC type x\n" + "*" * 10 + "\n") == \
        "Unable to find requested PC type x"


def test_a_reader_that_leaves_does_not_end_the_sweep(tmp_path):
    """`qsc sweep ... | head -1`: a BrokenPipeError traceback after the reference run, exit 1, no sweep.csv
    (hunt35_3). The rest of the lines go nowhere and the sweep writes its table."""
    import subprocess
    import sys
    # without this process's singleton MPI variables, which stop a child's mpirun at once (as above)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_MCA_", "PMIX_", "OMPI_COMM", "OMPI_FIRST",
                                                                      "OMPI_FILE", "OMPI_NUM", "OMPI_UNIVERSE"))}
    proc = subprocess.Popen([sys.executable, "-m", "qsc_petsc.cli", "sweep", SCENE, *TINY, "--vary",
                             "contact.0.formulation=master_slave,two_pass", "--out", str(tmp_path / "sw")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        first = proc.stdout.readline()
        proc.stdout.close()
        _, err = proc.communicate(timeout=300)
    finally:
        proc.kill()
    assert first.startswith("qsc sweep: patch_test: 2 combination(s)"), first
    assert proc.returncode == 0 and "Traceback" not in err, err
    assert (tmp_path / "sw" / "sweep.csv").is_file()
