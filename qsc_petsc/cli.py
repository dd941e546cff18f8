"""The qsc command: run, check and --version; PETSc options pass through to the options database."""

import argparse
import contextlib
import os
import signal
import sys
import traceback

from .options import init_petsc, split_petsc_args

EXIT_INPUT, EXIT_SOLVE, EXIT_BUG = 2, 3, 1


def launch_rank():
    """This process's rank as its MPI launcher tells it, read before MPI starts; 0 when no launcher started it."""
    for key in ("OMPI_COMM_WORLD_RANK", "PMI_RANK", "PMIX_RANK"):
        if os.environ.get(key, "").isdigit():
            return int(os.environ[key])
    return 0


class Parser(argparse.ArgumentParser):
    """argparse that prints usage, help and errors on rank 0 only: under mpirun every rank parses the same
    arguments and exits with the same code, and one copy of the message is enough."""

    def _print_message(self, message, file=None):
        if launch_rank() == 0:
            super()._print_message(message, file)


def build_parser():
    p = Parser(
        prog="qsc", description="Parallel contact between deformable bodies with non-matching meshes. "
        "PETSc options (e.g. -qsc_ksp_monitor, -qsc_pc_type lu) may follow the scene.")
    p.add_argument("--version", action="store_true", help="print qsc_petsc, PETSc, petsc4py and MPI versions")
    sub = p.add_subparsers(dest="command")
    for name, text in (("run", "solve a scene and write results"),
                       ("check", "validate a scene and print mesh and partition statistics, no solve")):
        s = sub.add_parser(name, help=text, description=text)
        s.add_argument("scene", help="scene file (TOML)")
        s.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                       help="override a scene value, e.g. bodies.0.mesh.cells=[8,8,8] (repeatable)")
        if name == "run":
            s.add_argument("--out", help="output folder (default: the scene's output.directory)")
    sub.add_parser("sweep", add_help=False, help="run a scene over a grid of variations, each run compared with a "
                   "reference run (qsc sweep --help)")
    return p


def versions():
    import petsc4py
    from mpi4py import MPI
    from petsc4py import PETSc

    from . import __version__
    mpi = MPI.Get_library_version().splitlines()[0].strip(" \t\r\n\x00")      # Open MPI's ends in a NUL
    return (f"qsc_petsc {__version__}\nPETSc {'.'.join(map(str, PETSc.Sys.getVersion()))}\n"
            f"petsc4py {petsc4py.__version__}\nMPI {mpi} "
            f"(mpi4py {__import__('mpi4py').__version__})")


def release(run):
    """Destroy a failed run's PETSc objects in order, on every rank, while PETSc is alive: left to the garbage
    collector they went at PetscFinalize, and a half-set-up preconditioner crashed there (SEGV after the
    error line, exit 59 instead of 2)."""
    import gc
    if run is not None:
        try:
            run.destroy()
        except Exception as exc:  # noqa: BLE001 - the run has failed and said why; its remains go to the collector
            sys.stderr.write(f"qsc: note: releasing the failed run: {exc}\n")
    gc.collect()


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def _end_interrupted(line="qsc: interrupted"):
    """Leave at once with 130, saying `line`: in parallel MPI_Abort ends every rank, for the others may wait for
    this one in a collective call, and so would this one's clean-up; no finalizers run (petsc4py's and MPI's are
    collective). Also while MPI and PETSc start."""
    sys.stdout.flush()
    sys.stderr.write(line + "\n")
    sys.stderr.flush()
    with contextlib.suppress(Exception):      # half-started MPI: the exit below ends this process all the same
        from mpi4py import MPI
        if MPI.Is_initialized() and not MPI.Is_finalized() and MPI.COMM_WORLD.size > 1:
            MPI.COMM_WORLD.Abort(130)
    os._exit(130)


def say_line(*args, **kwargs):
    """print, each line as it comes (a pipe or a file sees the run's progress); once stdout's reader has gone,
    the rest goes to /dev/null and the run (or sweep) goes on: its results are its files."""
    try:
        print(*args, **{**kwargs, "flush": True})
    except BrokenPipeError:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["sweep"]:          # runs are subprocesses: the sweep itself never starts PETSc or MPI
        from .sweep import main as sweep_main
        return sweep_main(argv[1:])
    own, petsc_args = split_petsc_args(argv)
    args = build_parser().parse_args(own)
    try:
        init_petsc(petsc_args)
        from mpi4py import MPI
    except KeyboardInterrupt:          # Ctrl-C while MPI and PETSc start: no clean-up, which may be collective
        _end_interrupted()
    comm = MPI.COMM_WORLD
    # SIGTERM (mpirun ending its ranks on Ctrl-C, a batch system's kill) stops a run as Ctrl-C does, once MPI is up:
    # before, it ends the process at once (mpirun then ends the others); a handler there raised in one rank while
    # the others waited for it in a collective call, and its exit's clean-up waited too, for ever
    signal.signal(signal.SIGTERM, _interrupt)
    # a reader that leaves (`qsc run ... | head`): PETSc's handler aborted the run at the next line (exit 59, the
    # summary left "running"; hunt34_3). Ignored, a write fails instead, and say_line sends the rest nowhere
    signal.signal(signal.SIGPIPE, signal.SIG_IGN)
    say = say_line if comm.rank == 0 else (lambda *a, **k: None)
    if args.version:
        say(versions())
        return 0
    if args.command is None:
        build_parser().print_help()
        return EXIT_INPUT
    from .errors import ConvergenceError, QscError
    run = None
    try:
        from .scene import load_scene
        scene = load_scene(args.scene, args.set)
        if args.command == "check":
            from .check import check
            say(check(scene, comm))
            return 0
        from .run import Run
        run = Run(scene, comm, args.out, log=say)
        say(f"qsc: {scene.name}: {run.summary['mesh']['dofs']} dofs on {comm.size} rank(s), "
            f"results in {run.out}")
        summary = run.execute()
        say(f"qsc: done in {sum(summary['time'].values()):.2f} s; results in {run.out}")
        run.destroy()
        return 0
    except ConvergenceError as exc:
        say(f"qsc: solve failed: {exc}")
        release(run)
        return EXIT_SOLVE
    except QscError as exc:
        say(f"qsc: error: {exc}")
        release(run)
        return EXIT_INPUT
    except KeyboardInterrupt:
        if comm.size == 1:
            say("qsc: interrupted")
            return 130
        # in parallel the signal may have reached this rank alone (a kill of one process, or every rank at a
        # different point). The finished steps are on disk: end the job.
        _end_interrupted(f"qsc: interrupted (rank {comm.rank}); ending the job")
    except Exception:  # noqa: BLE001 - a bug: print it and abort, never leave other ranks waiting
        sys.stderr.write(f"[rank {comm.rank}] internal error:\n{traceback.format_exc()}")
        sys.stderr.flush()
        comm.Abort(EXIT_BUG)


def entry():
    sys.exit(main())


if __name__ == "__main__":
    entry()
