"""Distributed PETSc operators: stiffness preallocation and assembly, triplet matrices, loads, constraints, near-nullspace.

Dofs are interleaved by vertex (dof = 3 * global vertex + component) and owned with their
vertex, so every matrix here is square in the dof space with block size 3.
"""

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from . import elasticity, fem
from .expression import compile_expression

CHUNK = 16384              # cells per vectorised kernel call: bounds temporary memory
ADD = PETSc.InsertMode.ADD_VALUES


def ownership_starts(comm, n_owned):
    """Start of every rank's owned range, plus the global size at the end."""
    counts = comm.allgather(int(n_owned))
    return np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)


def send_to_owners(comm, starts, keys, *payload):
    """Route rows (keys: global indices into a range-distributed space) to the ranks owning them.

    Returns the keys and payload arrays this rank receives (its own rows included)."""
    dest = np.searchsorted(starts, keys, side="right") - 1
    order = np.argsort(dest, kind="stable")
    counts = np.bincount(dest, minlength=comm.size).astype(np.int64)
    rcounts = np.empty_like(counts)
    comm.Alltoall(counts, rcounts)
    out = []
    for arr in (keys, *payload):
        arr = np.ascontiguousarray(np.asarray(arr)[order])
        recv = np.empty(int(rcounts.sum()), dtype=arr.dtype)
        mpitype = MPI._typedict[arr.dtype.char]
        comm.Alltoallv([arr, (counts, None), mpitype], [recv, (rcounts, None), mpitype])
        out.append(recv)
    return out


def vertex_graph_counts(mesh):
    """Per owned vertex: how many distinct vertices (itself included) share a cell with it, split
    into those owned by this rank (diagonal block) and the others, for exact AIJ preallocation."""
    comm = mesh.comm
    n = np.int64(mesh.n_vertices)
    g = mesh.gvert[mesh.cells]
    iu, ju = np.triu_indices(g.shape[1], 1)
    a, b = g[:, iu].ravel(), g[:, ju].ravel()
    pairs = np.unique(np.minimum(a, b) * n + np.maximum(a, b))
    lo, hi = pairs // n, pairs % n
    rows, cols = np.concatenate([lo, hi]), np.concatenate([hi, lo])      # unique on this rank
    starts = ownership_starts(comm, mesh.owned.sum())
    r0, r1 = starts[comm.rank], starts[comm.rank + 1]
    mine = (rows >= r0) & (rows < r1)
    got_rows, got_cols = send_to_owners(comm, starts, rows[~mine], cols[~mine])
    rows, cols = rows[mine], cols[mine]
    if len(got_rows):
        # an edge on a partition boundary may come from several ranks: dedupe only the rows that received some
        shared = np.isin(rows, np.unique(got_rows))
        merged = np.unique(np.concatenate([rows[shared], got_rows]) * n + np.concatenate([cols[shared], got_cols]))
        rows = np.concatenate([rows[~shared], merged // n])
        cols = np.concatenate([cols[~shared], merged % n])
    diag = (cols >= r0) & (cols < r1)
    d = np.bincount(rows[diag] - r0, minlength=r1 - r0) + 1
    o = np.bincount(rows[~diag] - r0, minlength=r1 - r0)
    return d, o


def create_dof_matrix(mesh, d_vertex, o_vertex):
    """An empty MPIAIJ matrix in the dof space (block size 3) preallocated from per-vertex block counts."""
    n_own = 3 * int(mesh.owned.sum())
    A = PETSc.Mat().create(comm=mesh.comm)
    A.setSizes(((n_own, 3 * mesh.n_vertices), (n_own, 3 * mesh.n_vertices)), bsize=3)
    A.setType(PETSc.Mat.Type.AIJ)
    d = np.repeat(3 * np.asarray(d_vertex), 3).astype(PETSc.IntType)
    o = np.repeat(3 * np.asarray(o_vertex), 3).astype(PETSc.IntType)
    A.setPreallocationNNZ((d, o))
    A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
    return A


def cell_dofs(mesh, cells):
    """Global dofs (m, 3k) of the given local cells, node-major."""
    g = mesh.gvert[mesh.cells[cells]]
    return (3 * g[:, :, None] + np.arange(3)).reshape(len(g), -1)


def cell_materials(mesh, scene):
    """Lame parameters (lmbda, mu) [Pa] of every local cell, from its body's material."""
    lame = np.array([elasticity.lame(b.material.youngs_modulus, b.material.poissons_ratio)
                     for b in scene.bodies])
    return lame[mesh.cell_body, 0], lame[mesh.cell_body, 1]


def assemble_stiffness(mesh, A, lmbda, mu):
    """Add the elastic stiffness of every local cell into A (off-process rows go through PETSc's stash)."""
    for s in range(0, len(mesh.cells), CHUNK):
        c = np.arange(s, min(s + CHUNK, len(mesh.cells)))
        Ke = elasticity.stiffness(mesh.cell_type, mesh.coords[mesh.cells[c]], lmbda[c], mu[c])
        dofs = cell_dofs(mesh, c).astype(PETSc.IntType)
        A.setValuesRCV(dofs, dofs, np.ascontiguousarray(Ke), addv=ADD)
    A.assemble()
    return A


def internal_force(mesh, u_local, lmbda, mu):
    """Element-by-element K u (local, ghosted dof array): reactions need K before constraints."""
    f = np.zeros(3 * len(mesh.coords))
    k = mesh.cells.shape[1]
    for s in range(0, len(mesh.cells), CHUNK):
        c = np.arange(s, min(s + CHUNK, len(mesh.cells)))
        ue = u_local.reshape(-1, 3)[mesh.cells[c]].reshape(len(c), 3 * k)
        Ke = elasticity.stiffness(mesh.cell_type, mesh.coords[mesh.cells[c]], lmbda[c], mu[c])
        ldofs = (3 * mesh.cells[c][:, :, None] + np.arange(3)).reshape(len(c), -1)
        np.add.at(f, ldofs.ravel(), np.einsum("mij,mj->mi", Ke, ue).ravel())
    return f


def triplet_matrix(mesh, rows, cols, vals):
    """A dof-space MPIAIJ matrix from (row, col, value) triplets given on any rank (duplicates summed).

    Triplets are sent to their row's owner, summed there, and the local CSR is handed to PETSc
    in one call, so the preallocation is exact."""
    comm = mesh.comm
    starts = 3 * ownership_starts(comm, mesh.owned.sum())
    rows, cols, vals = send_to_owners(comm, starts, np.asarray(rows, np.int64),
                                      np.asarray(cols, np.int64), np.asarray(vals, float))
    r0, r1 = starts[comm.rank], starts[comm.rank + 1]
    n = np.int64(starts[-1])
    keys, inv = np.unique((rows - r0) * n + cols, return_inverse=True)
    summed = np.bincount(inv, weights=vals, minlength=len(keys))
    lrow, col = keys // n, keys % n
    indptr = np.concatenate([[0], np.cumsum(np.bincount(lrow, minlength=r1 - r0))])
    A = PETSc.Mat().createAIJ(((r1 - r0, n), (r1 - r0, n)), bsize=1,
                              csr=(indptr.astype(PETSc.IntType), col.astype(PETSc.IntType), summed),
                              comm=comm)
    return A


def row_vector(mesh, rows, vals, template):
    """A dof-space Vec holding the sums of (row, value) pairs given on any rank."""
    v = template.duplicate()
    v.set(0.0)
    v.setValues(np.asarray(rows, dtype=PETSc.IntType), np.asarray(vals, dtype=float), addv=ADD)
    v.assemble()
    return v


def surface_load(mesh, scene, template):
    """External force Vec [N] of every pressure boundary at full load."""
    f = template.duplicate()
    f.set(0.0)
    for bc in scene.boundary:
        if bc.type != "pressure":
            continue
        c, lf = mesh.surface_faces(bc.surface)
        nodes = mesh.face_nodes(c, lf)
        field = isinstance(bc.value, str)
        # a pressure field varies within faces: a 3-point rule per direction integrates it better than 2
        fe = fem.face_pressure_loads(mesh.face_type, mesh.coords[nodes],
                                     compile_expression(bc.value) if field else bc.value, n_gauss=3 if field else 2)
        dofs = (3 * mesh.gvert[nodes][:, :, None] + np.arange(3)).ravel()
        f.setValues(dofs.astype(PETSc.IntType), fe.ravel(), addv=ADD)
    f.assemble()
    return f


def dirichlet_dofs(mesh, scene):
    """Owned constrained dofs and their values [m] at full load, from displacement and symmetry boundaries.

    Returns (dofs, values, per_boundary) where per_boundary[i] lists the owned dofs of boundary i."""
    dofs, vals, per_bc = [], [], []
    for i, bc in enumerate(scene.boundary):
        if bc.type == "pressure":
            per_bc.append(np.zeros(0, np.int64))
            continue
        v = mesh.surface_vertices(bc.surface)
        v = v[mesh.owned[v]]
        if bc.type == "displacement":
            comps = [(c, getattr(bc, k)) for c, k in enumerate(("ux", "uy", "uz")) if getattr(bc, k) is not None]
        else:
            comps = [(symmetry_axis(mesh, i, bc.surface), 0.0)]
        mine = []
        for comp, value in comps:
            d = 3 * mesh.gvert[v] + comp
            dofs.append(d)
            vals.append(np.full(len(d), float(value)))
            mine.append(d)
        per_bc.append(np.concatenate(mine) if mine else np.zeros(0, np.int64))
    if not dofs:
        return np.zeros(0, np.int64), np.zeros(0), per_bc
    dofs, vals = np.concatenate(dofs), np.concatenate(vals)
    dofs, first = np.unique(dofs, return_index=True)     # a dof on two boundaries keeps its first value
    return dofs, vals[first], per_bc


def symmetry_axis(mesh, index, surface):
    """The axis normal to an axis-aligned symmetry surface (collective: all ranks agree)."""
    from .errors import MeshError
    c, lf = mesh.surface_faces(surface)
    xf = mesh.coords[mesh.face_nodes(c, lf)]
    n, _ = fem.face_normals(mesh.face_type, xf, fem.CENTROID[mesh.face_type][None, :])
    total = mesh.comm.allreduce(np.abs(n[:, 0, :]).sum(axis=0) if len(n) else np.zeros(3), op=MPI.SUM)
    count = mesh.comm.allreduce(len(n), op=MPI.SUM)
    axis = int(np.argmax(total))
    if count == 0 or total[axis] < count * (1.0 - 1e-9):
        raise MeshError(f"boundary[{index}].surface: symmetry surface {surface!r} is not a plane "
                        f"normal to x, y or z")
    return axis


def rigid_body_modes(mesh, template):
    """Near-nullspace: the 6 rigid-body modes of every body, each supported on its own body only."""
    vecs = []
    owned_v = np.flatnonzero(mesh.owned)
    rows = (3 * mesh.gvert[owned_v] - template.getOwnershipRange()[0]).astype(np.int64)
    for b in range(len(mesh.body_names)):
        in_body = np.zeros(len(mesh.coords), dtype=bool)
        in_body[mesh.body_vertices(b)] = True
        sel = in_body[owned_v]
        x = mesh.coords[owned_v[sel]]
        r = rows[sel]
        centre = mesh.comm.allreduce(x.sum(axis=0), op=MPI.SUM) / max(mesh.comm.allreduce(len(x)), 1)
        x = x - centre
        modes = []
        for k in range(6):
            v = template.duplicate()
            v.set(0.0)
            a = v.getArray()
            if k < 3:
                a[r + k] = 1.0
            else:
                i, j = ((0, 1), (1, 2), (2, 0))[k - 3]
                a[r + i] = -x[:, j]
                a[r + j] = x[:, i]
            modes.append(v)
        # modified Gram-Schmidt: MatNullSpace wants an orthonormal basis
        for k, v in enumerate(modes):
            for w in modes[:k]:
                v.axpy(-v.dot(w), w)
            v.normalize()
        vecs.extend(modes)
    return PETSc.NullSpace().create(vectors=vecs, comm=mesh.comm)
