"""Shared fixtures: MPI-safe temporary folders and a one-call scene runner (collective under mpirun)."""

import gc
import shutil
import tempfile
from pathlib import Path

import pytest
from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "configs"


@pytest.fixture
def comm():
    return MPI.COMM_WORLD


@pytest.fixture
def mpi_tmp(comm):
    """A temporary folder shared by all ranks (made by rank 0), removed after the test."""
    path = tempfile.mkdtemp(prefix="qsc_test_") if comm.rank == 0 else None
    path = Path(comm.bcast(path, root=0))
    yield path
    gc.collect()
    comm.Barrier()
    if comm.rank == 0:
        shutil.rmtree(path, ignore_errors=True)


def run_scene(scene_path, out, overrides=(), comm=MPI.COMM_WORLD, log=None):
    """Load, run and return (run, summary); every rank calls it. log receives the run's lines (rank 0's)."""
    from qsc_petsc.run import Run
    from qsc_petsc.scene import load_scene
    scene = load_scene(scene_path, overrides)
    run = Run(scene, comm, out, log=log or (lambda *a, **k: None))
    summary = run.execute()
    return run, summary


def scene_without_petsc(folder, petsc="", comm=MPI.COMM_WORLD):
    """configs/two_cubes_dies.toml with its [petsc] table (MUMPS) replaced by `petsc`: the defaults if empty.
    Written by rank 0 into a folder all ranks share; every rank calls it."""
    path = folder / "scene.toml"
    if comm.rank == 0:
        text = (CONFIGS / "two_cubes_dies.toml").read_text()
        path.write_text(text[:text.index("[petsc]")] + (f"[petsc]\n{petsc}\n" if petsc else ""))
    comm.Barrier()
    return path


def all_close(comm, ok):
    """True on every rank iff ok on every rank (assert only on such values under MPI)."""
    return comm.allreduce(bool(ok), op=MPI.LAND)
