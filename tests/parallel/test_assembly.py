"""The stiffness matrix built as CSR arrays equals an independent dense assembly on any number of ranks.

Runs serially in the suite and again under mpirun -n 2 and -n 3; assertions use all-reduced values."""

import itertools

import numpy as np
import pytest
from conftest import CONFIGS, all_close
from mpi4py import MPI
from petsc4py import PETSc

from qsc_petsc import assembly, elasticity, lattice, sparsity
from qsc_petsc.mesh import distribute_mesh
from qsc_petsc.scene import load_scene

TWO_BODIES = ["bodies.1.mesh.rotation=[10.0, 20.0, 30.0]", "bodies.1.material.youngs_modulus=3000.0",
              "bodies.0.mesh.cells=[3,3,2]", "bodies.1.mesh.cells=[2,3,3]"]
CASES = {
    "hex two cells, a rank may hold none": ("block_compression.toml", ["bodies.0.mesh.cells=[1,1,2]"], False),
    "hex box": ("block_compression.toml", ["bodies.0.mesh.cells=[4,3,5]"], False),
    "tet box": ("block_compression.toml", ["bodies.0.mesh.cells=[3,2,3]", "bodies.0.mesh.element=tet"], False),
    "hex distorted": ("block_compression.toml", ["bodies.0.mesh.cells=[4,3,5]"], True),
    "tet distorted": ("block_compression.toml", ["bodies.0.mesh.cells=[3,2,3]", "bodies.0.mesh.element=tet"], True),
    "hex two bodies, one rotated": ("two_cubes_dies.toml", TWO_BODIES, False),
    "tet two bodies, distorted": ("two_cubes_dies.toml", TWO_BODIES + ["bodies.0.mesh.element=tet",
                                                                       "bodies.1.mesh.element=tet"], True),
    # B-bar in one body of two, the other integrated fully
    "hex mean dilatation, distorted": ("two_cubes_dies.toml", TWO_BODIES + [
        "bodies.1.material.volumetric=mean_dilatation"], True),
}


def distort(x):
    """A smooth map of the coordinates: every rank moves a shared vertex the same way, no cell stays a translate."""
    return x + 0.04 * np.sin(np.column_stack([3 * x[:, 1] + 2 * x[:, 2], 4 * x[:, 2] + x[:, 0], 5 * x[:, 0]]))


def dense_reference(mesh, lmbda, mu, kappa=None):
    """The global stiffness as a dense array, summed element by element (all ranks get it)."""
    n = 3 * mesh.n_vertices
    K = np.zeros((n, n))
    Ke = elasticity.stiffness(mesh.cell_type, mesh.coords[mesh.cells], lmbda, mu, share_translates=False, kappa=kappa)
    dofs = (3 * mesh.gvert[mesh.cells][:, :, None] + np.arange(3)).reshape(len(Ke), 3 * mesh.cells.shape[1])
    for d, ke in zip(dofs, Ke):
        K[np.ix_(d, d)] += ke
    mesh.comm.Allreduce(MPI.IN_PLACE, K, op=MPI.SUM)
    return K


def vertex_pairs(mesh):
    """Number of ordered pairs of vertices (a vertex with itself included) that share a cell."""
    shared = np.zeros((mesh.n_vertices, mesh.n_vertices), np.int32)
    g = mesh.gvert[mesh.cells]
    shared[g[:, :, None], g[:, None, :]] = 1
    mesh.comm.Allreduce(MPI.IN_PLACE, shared, op=MPI.MAX)
    return int(shared.sum())


def owned_dense(A, n):
    """This rank's rows of a PETSc matrix as a dense array, and their first global row."""
    r0, r1 = A.getOwnershipRange()
    indptr, cols, vals = A.getValuesCSR()
    rows = np.zeros((r1 - r0, n))
    rows[np.repeat(np.arange(r1 - r0), np.diff(indptr)), cols] = vals
    return rows, r0


@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize("batch", [1 << 19, 200])
def test_stiffness_matrix_equals_dense_assembly(comm, monkeypatch, case, batch):
    """The CSR-built stiffness shall equal the element-by-element sum to round-off, with exact preallocation,
    in one batch of rows or in many (kernels kept between batches, rows sorted in several passes)."""
    monkeypatch.setattr(assembly, "BATCH", batch)
    monkeypatch.setattr(sparsity, "ROW_BATCH", min(batch, sparsity.ROW_BATCH))
    scene_file, sets, distorted = CASES[case]
    scene = load_scene(CONFIGS / scene_file, sets)
    mesh = distribute_mesh(scene, comm)
    if distorted:
        mesh.coords = distort(mesh.coords)
    lmbda, mu = assembly.cell_materials(mesh, scene)
    kappa = assembly.cell_mean_bulk(mesh, scene)
    A = assembly.stiffness_matrix(mesh, lmbda, mu, kappa=kappa)
    K = dense_reference(mesh, lmbda, mu, kappa)
    rows, r0 = owned_dense(A, len(K))
    ref = K[r0:r0 + len(rows)]
    err = comm.allreduce(float(np.abs(rows - ref).max(initial=0.0)), op=MPI.MAX)
    assert err <= 1e-13 * np.abs(K).max()
    # exact pattern: the 3x3 blocks of the vertex pairs that share a cell, no more
    stored = comm.allreduce(int(A.getValuesCSR()[0][-1]), op=MPI.SUM)
    assert stored == 9 * vertex_pairs(mesh)
    assert A.getBlockSize() == 3
    assert A.getSize() == K.shape
    A.destroy()


LATTICE_CASES = {
    "one cell": ("block_compression.toml", ["bodies.0.mesh.cells=[1,1,1]"]),
    "a rank may hold none": ("block_compression.toml", ["bodies.0.mesh.cells=[1,1,2]"]),
    "one cell thick, unequal sides": ("block_compression.toml", ["bodies.0.mesh.cells=[5,1,3]",
                                                                  "bodies.0.mesh.size=[2.0,0.3,1.0]"]),
    "hex box": ("block_compression.toml", ["bodies.0.mesh.cells=[4,3,5]"]),
    "lines long enough for runs, planes of them": ("block_compression.toml", ["bodies.0.mesh.cells=[9,6,5]"]),
    "cut across z: the cut's rows in runs": ("block_compression.toml", ["bodies.0.mesh.cells=[9,4,27]"]),
    "two bodies, one rotated and stiffer": ("two_cubes_dies.toml", TWO_BODIES),
    "two bodies, one with mean dilatation": ("two_cubes_dies.toml", TWO_BODIES + [
        "bodies.0.material.volumetric=mean_dilatation"]),
}


@pytest.mark.parametrize("case", LATTICE_CASES)
def test_box_stencils_equal_dense_assembly(comm, case):
    """Generated hex boxes read from row templates shall give the element-by-element stiffness to
    round-off with the exact pattern, on any number of ranks."""
    scene = load_scene(CONFIGS / LATTICE_CASES[case][0], LATTICE_CASES[case][1])
    mesh = distribute_mesh(scene, comm)
    lattices = lattice.box_lattices(scene)
    assert lattices is not None
    A = assembly.lattice_stiffness_matrix(mesh, lattices)
    K = dense_reference(mesh, *assembly.cell_materials(mesh, scene), assembly.cell_mean_bulk(mesh, scene))
    rows, r0 = owned_dense(A, len(K))
    err = comm.allreduce(float(np.abs(rows - K[r0:r0 + len(rows)]).max(initial=0.0)), op=MPI.MAX)
    assert err <= 1e-13 * np.abs(K).max()
    assert comm.allreduce(int(A.getValuesCSR()[0][-1]), op=MPI.SUM) == 9 * vertex_pairs(mesh)
    assert A.getBlockSize() == 3
    A.destroy()


def _pattern_rows(A):
    """This rank's rows of A's pattern: a list of sets of global columns."""
    indptr, cols, _ = A.getValuesCSR()
    return [set(cols[a:b].tolist()) for a, b in itertools.pairwise(indptr)]


EXTRA_CASES = {**{f"box stencils, {k}": (v[0], v[1], True) for k, v in LATTICE_CASES.items()},
               **{f"element blocks, {k}": (v[0], v[1], False) for k, v in CASES.items() if not v[2]}}


@pytest.mark.parametrize("case", EXTRA_CASES)
def test_extra_blocks_widen_the_pattern_with_zeros(comm, case):
    """Extra entries (a contact stencil's, by 3x3 block) shall widen K's pattern by exactly those entries (the box
    stencils) or their whole blocks (the element blocks), with value 0, on any number of ranks: blocks K has
    already, blocks to other ranks' vertices, several to one row (up to 40), and none on some rank."""
    scene_file, sets, stencils = EXTRA_CASES[case]
    scene = load_scene(CONFIGS / scene_file, sets)
    mesh = distribute_mesh(scene, comm)
    v0, v1 = mesh.vertex_range
    rng = np.random.default_rng(7 + comm.rank)
    rows = rng.integers(v0, v1, size=4 * (v1 - v0) // 3) if v1 > v0 else np.zeros(0, np.int64)
    cols = rng.integers(0, mesh.n_vertices, size=len(rows))
    rows, cols = np.r_[rows, rows[:3]], np.r_[cols, rows[:3]]          # a block every row has: its own
    wide = np.arange(min(40, mesh.n_vertices))                        # a row wider than its 27 neighbours
    rows, cols = np.r_[rows, np.full(len(wide) if v1 > v0 else 0, v0)], np.r_[cols, wide[:len(wide) * (v1 > v0)]]
    bits = rng.integers(1, 512, size=len(rows))                       # which entries of each block
    bits[-len(wide) - 3:] = 1 << 8                                   # the zz entry alone, as a flat contact's
    extra = (rows, cols, bits)
    if stencils:
        lattices = lattice.box_lattices(scene)
        A, B = (assembly.lattice_stiffness_matrix(mesh, lattices, e) for e in (None, extra))
    else:
        materials = assembly.cell_materials(mesh, scene)
        A, B = (assembly.stiffness_matrix(mesh, *materials, extra=e) for e in (None, extra))
    n = 3 * mesh.n_vertices
    assert all_close(comm, np.array_equal(owned_dense(A, n)[0], owned_dense(B, n)[0]))
    r0 = A.getOwnershipRange()[0]
    expected = _pattern_rows(A)
    for r, c, b in zip(rows, cols, bits):
        for i in range(3):       # the box stencils hold the entries asked for, the element blocks whole blocks
            expected[3 * r + i - r0].update(3 * c + k for k in range(3) if not stencils or b >> (3 * i + k) & 1)
    assert all_close(comm, _pattern_rows(B) == expected)
    A.destroy()
    B.destroy()


@pytest.mark.parametrize("case", EXTRA_CASES)
@pytest.mark.parametrize("share", [0.3, 1.0])
def test_elimination_equals_zero_rows_columns(comm, case, share):
    """Dirichlet rows and columns taken out of K's arrays (elimination.py) shall give MatZeroRowsColumns' K0 (diagonal
    1) exactly and its lifting of a load to round-off, on any number of ranks: fixed dofs scattered over every rank
    (those next to other ranks' vertices too) or all of them, nonzero values, a contact stencil's zero entries."""
    scene_file, sets, stencils = EXTRA_CASES[case]
    scene = load_scene(CONFIGS / scene_file, sets)
    mesh = distribute_mesh(scene, comm)
    v0, v1 = mesh.vertex_range
    rng = np.random.default_rng(11 + comm.rank)
    dofs = np.flatnonzero(rng.random(3 * (v1 - v0)) < share) + 3 * v0
    values = rng.uniform(-1.0, 1.0, len(dofs))
    rows = np.arange(v0, v1)
    extra = (rows, (rows * 7 + 3) % mesh.n_vertices, np.full(len(rows), 0x111))     # far blocks, diagonal entries
    if stencils:
        lattices = lattice.box_lattices(scene)
        A = assembly.lattice_stiffness_matrix(mesh, lattices, extra)
        B, lifting = assembly.lattice_stiffness_matrix(mesh, lattices, extra, (dofs, values))
    else:
        materials = assembly.cell_materials(mesh, scene)
        A = assembly.stiffness_matrix(mesh, *materials, extra=extra)
        B, lifting = assembly.stiffness_matrix(mesh, *materials, extra=extra, fixed=(dofs, values))
    f, ubar = A.createVecs()
    f.setArray(rng.uniform(-1.0, 1.0, f.getLocalSize()))
    ubar.set(0.0)
    ubar.setValues(dofs.astype(PETSc.IntType), values)
    ubar.assemble()
    b = f.copy()
    A.zeroRowsColumns(dofs.astype(PETSc.IntType), 1.0, ubar, b)
    n = 3 * mesh.n_vertices
    assert all_close(comm, np.array_equal(owned_dense(A, n)[0], owned_dense(B, n)[0]))
    assert all_close(comm, _pattern_rows(A) == _pattern_rows(B))
    mine = f.getArray() - lifting
    mine[dofs - 3 * v0] = values
    scale = comm.allreduce(float(np.abs(b.getArray()).max(initial=0.0)), op=MPI.MAX)
    err = comm.allreduce(float(np.abs(mine - b.getArray()).max(initial=0.0)), op=MPI.MAX)
    assert err <= 1e-13 * scale
    for obj in (A, B, f, ubar, b):
        obj.destroy()


@pytest.mark.parametrize("scene_file, sets", [
    ("block_compression.toml", ["bodies.0.mesh.element=tet"]),
    ("hertz_coarse.toml", []),
])
def test_box_stencils_only_for_hex_boxes(scene_file, sets):
    """Tetrahedra and meshes read from files shall take the element-block assembly (no templates)."""
    assert lattice.box_lattices(load_scene(CONFIGS / scene_file, sets)) is None


def test_pattern_is_closed(comm):
    """A value outside the pattern shall be refused on every rank (no silent reallocation)."""
    scene = load_scene(CONFIGS / "block_compression.toml", ["bodies.0.mesh.cells=[4,3,5]"])
    mesh = distribute_mesh(scene, comm)
    A = assembly.stiffness_matrix(mesh, *assembly.cell_materials(mesh, scene))
    r0 = A.getOwnershipRange()[0]
    far = (r0 + A.getSize()[1] // 2 + 40) % A.getSize()[1]     # no vertex shares a cell with one half a box away
    indptr, cols, _ = A.getValuesCSR()
    assert far not in cols[:indptr[1]]
    refused = False
    try:
        A.setValue(r0, far, 1.0, addv=PETSc.InsertMode.ADD_VALUES)
    except PETSc.Error:
        refused = True
    assert all_close(comm, refused)
    A.destroy()


def test_degenerate_cell_fails_every_rank(comm):
    """A flat cell (det J round-off, of either sign) on one rank shall raise MeshError on all ranks, naming the cell."""
    from qsc_petsc.errors import MeshError
    scene = load_scene(CONFIGS / "block_compression.toml", ["bodies.0.mesh.cells=[4,3,5]"])
    mesh = distribute_mesh(scene, comm)
    bad = comm.allreduce(int(mesh.cell_orig.min(initial=10**9)) if comm.rank == comm.size - 1 else 10**9, op=MPI.MIN)
    mine = np.flatnonzero(mesh.cell_orig == bad)
    if len(mine):                                   # flatten one cell: every node onto node 0's plane z
        v = mesh.cells[mine[0]]
        mesh.coords = mesh.coords.copy()
        mesh.coords[v[4:], 2] = mesh.coords[v[0], 2]
    with pytest.raises(MeshError, match=rf"bodies\[0\] \(block, generated box\): hex {bad} \(0-based"):
        assembly.stiffness_matrix(mesh, *assembly.cell_materials(mesh, scene))


def test_cut_rows_go_by_runs(comm, monkeypatch):
    """A tall box (9 x 4 x 27 cells), cut across z on 2 and 3 ranks, puts rows beside a cut (neighbours on another
    rank) in runs along x, which lattice_stiffness_matrix writes like its natural runs
    (test_box_stencils_equal_dense_assembly checks the values)."""
    found = []
    split_runs = assembly._split_runs

    def spy(*args):
        runs = split_runs(*args)
        found.extend(runs)
        return runs
    monkeypatch.setattr(assembly, "_split_runs", spy)
    scene = load_scene(CONFIGS / "block_compression.toml", ["bodies.0.mesh.cells=[9,4,27]"])
    mesh = distribute_mesh(scene, comm)
    assembly.lattice_stiffness_matrix(mesh, lattice.box_lattices(scene)).destroy()
    covered = comm.allreduce(sum(b - a for a, b in found), op=MPI.SUM)
    assert (covered > 0) == (comm.size > 1)                      # one rank has no cut
