"""Shared fixtures: MPI-safe temporary folders and a one-call scene runner (collective under mpirun)."""

import gc
import shutil
import tempfile
from pathlib import Path

import numpy as np
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


def block_and_cube(name, size, cells, upper_cells, rest, lower_modulus=1000.0):
    """Scene text: a block of `size` and `cells` on z = 0 and a 0.5 m cube of `upper_cells` on it at x, y = 0.25
    (E 1000, nu 0.3), then `rest` (pairs, dies, boundaries, load), solved by MUMPS."""
    body = ('[[bodies]]\nname = "{}"\nmesh = {{ type = "box", origin = {}, size = {}, cells = {} }}\n'
            'material = {{ youngs_modulus = {!r}, poissons_ratio = 0.3 }}\n')
    return (f'name = "{name}"\n' + body.format("lower", [0.0, 0.0, 0.0], list(size), list(cells), lower_modulus)
            + body.format("upper", [0.25, 0.25, 0.5], [0.5, 0.5, 0.5], list(upper_cells), 1000.0) + rest
            + '[petsc]\nksp_type = "preonly"\npc_type = "lu"\npc_factor_mat_solver_type = "mumps"\n')


def die(name, point, normal, surfaces, motion=None, condition="frictionless"):
    """A [[die]] table's text."""
    return (f'[[die]]\nname = "{name}"\npoint = {list(point)}\nnormal = {list(normal)}\n'
            + (f"motion = {list(motion)}\n" if motion is not None else "")
            + f'surfaces = {list(surfaces)}\ncondition = "{condition}"\n'.replace("'", '"'))


def all_close(comm, ok):
    """True on every rank iff ok on every rank (assert only on such values under MPI)."""
    return comm.allreduce(bool(ok), op=MPI.LAND)


def write_gmsh(path, points, cells, element, surfaces):
    """A mesh file in gmsh 2.2 format: cells of one element type ("hex" or "tet") and the named physical surfaces
    {name: faces (k, nv) of vertex indices}."""
    import meshio
    face = {"hex": "quad", "tet": "triangle"}[element]
    blocks = [({"hex": "hexahedron", "tet": "tetra"}[element], cells)]
    tags, names = [np.full(len(cells), 100)], {"solid": np.array([100, 3])}
    for tag, (name, faces) in enumerate(surfaces.items(), start=1):
        blocks.append((face, faces))
        tags.append(np.full(len(faces), tag))
        names[name] = np.array([tag, 2])
    meshio.write(path, meshio.Mesh(points, blocks, cell_data={"gmsh:physical": tags, "gmsh:geometrical": tags},
                                   field_data=names), file_format="gmsh22", binary=False)


def write_gmsh_box(path, groups=None, cells=(2, 2, 2), element="tet", origin=(0.0, 0.0, 0.0), size=(1.0, 1.0, 1.0)):
    """A generated box written as a gmsh 2.2 file (write_gmsh); groups maps a physical surface name to a box side
    (None: every side under its own name). Returns the box (meshgen.box_mesh)."""
    from qsc_petsc import fem
    from qsc_petsc.meshgen import box_mesh
    box = box_mesh(origin, size, cells, element)
    groups = {side: side for side in box.surfaces} if groups is None else groups
    write_gmsh(path, box.points, box.cells, element, {
        name: fem.cell_faces(element, box.cells[box.surfaces[side][:, 0]], box.surfaces[side][:, 1])
        for name, side in groups.items()})
    return box
