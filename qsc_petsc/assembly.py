"""Distributed PETSc operators: stiffness preallocation and assembly, triplet matrices, loads, constraints, near-nullspace.

Dofs are interleaved by vertex (dof = 3 * global vertex + component) and owned with their
vertex, so every matrix here is square in the dof space with block size 3. The stiffness matrix
is built as CSR arrays in NumPy (sparsity.py) and handed to PETSc in one call.
"""

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from . import elasticity, elimination, fem, lattice, sparsity
from .errors import MeshError, SceneError
from .expression import compile_expression
from .mesh import on_all
from .scene import MAX_MAGNITUDE, MIN_MAGNITUDE

CHUNK = 16384              # cells per vectorised kernel call: bounds temporary memory
FEW_GROUPS = 64            # congruent cell groups up to which K u goes group by group
ADD = PETSc.InsertMode.ADD_VALUES


def ownership_starts(comm, n_owned):
    """Start of every rank's owned range, plus the global size at the end."""
    counts = comm.allgather(int(n_owned))
    return np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)


def send_to_owners(comm, starts, keys, *payload):
    """Route rows (keys: global indices into a range-distributed space) to the ranks owning them.

    Returns the keys and payload arrays this rank receives (its own rows included)."""
    dest = np.searchsorted(starts, keys, side="right") - 1
    # a stable sort of 16-bit keys is a radix sort in NumPy: linear in the number of rows sent
    order = np.argsort(dest.astype(np.int16 if comm.size < 1 << 15 else np.int64), kind="stable")
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


def cell_materials(mesh, scene):
    """Lame parameters (lmbda, mu) [Pa] of every local cell, from its body's material."""
    lame = np.array([elasticity.lame(b.material.youngs_modulus, b.material.poissons_ratio)
                     for b in scene.bodies])
    return lame[mesh.cell_body, 0], lame[mesh.cell_body, 1]


# material.volumetric = "full" warns from this Poisson's ratio on (flat_punch, coarse: the punch's force 1.13x its
# nu = 0.3 value at 0.45, 1.34x at 0.49, 2.6x at 0.499 and 14x at 0.4999 on hexes; 1.41x at 0.49 on tets; hunt33_3)
LOCKING_NU = 0.45


def locking_warnings(scene, cell_type):
    """Lines for the bodies whose elements lock in volume: Poisson's ratio at LOCKING_NU or more, integrated fully
    (hexes without mean_dilatation, or linear tets, which have nothing else)."""
    lines = []
    for i, body in enumerate(scene.bodies):
        nu = body.material.poissons_ratio
        if nu < LOCKING_NU or body.material.volumetric == "mean_dilatation":
            continue
        cure = (f'set bodies[{i}].material.volumetric = "mean_dilatation" (B-bar)' if cell_type == "hex" else
                "linear tetrahedra have no cure here: mesh the body with hexahedra and mean_dilatation")
        lines.append(f"bodies[{i}] ({body.name}): Poisson's ratio {nu:g} with fully integrated "
                     f"{'hexahedra' if cell_type == 'hex' else 'linear tetrahedra'}, which lock in volume: "
                     f"the body answers too stiff wherever its strain is not uniform (a punch's force 1.3x at nu "
                     f"0.49, 2.6x at 0.499 on hexes); {cure}")
    return lines


def cell_mean_bulk(mesh, scene):
    """The bulk modulus lmbda + 2 mu / 3 [Pa] of every local cell whose body takes its volumetric energy with the
    cell's mean dilatation (material.volumetric = "mean_dilatation": B-bar), 0 for the others; None when no body
    does (every kernel then integrates fully, as before)."""
    if all(b.material.volumetric == "full" for b in scene.bodies):
        return None
    bulk = np.array([elasticity.mean_dilatation_bulk(b.material.youngs_modulus, b.material.poissons_ratio,
                                                     b.material.volumetric) for b in scene.bodies])
    return bulk[mesh.cell_body]


def plain_rows(A):
    """Let A multiply with AIJ's plain row kernel instead of the i-node one (rows of identical pattern
    taken together), unless -mat_no_inode 0 says otherwise: on the 985k-dof box at 2 ranks, three runs
    each, MatMult took 5.5-6.0 s against 6.6-6.7 s and KSPSolve 6.0-6.5 s against 7.1-7.2 s (433
    products; docs/performance.md). PETSc reads the flag when it multiplies, so it also holds for a
    matrix already assembled; a matrix PETSc makes anew (MatAXPY with a new pattern) needs it again."""
    A.setOption(PETSc.Mat.Option.USE_INODES, not PETSc.Options().getBool("mat_no_inode", True))


def _stiffness_operator(size, csr, comm, r0, fixed):
    """K from its CSR arrays (split diagonal / off-diagonal parts on several ranks), as both assemblies hand it
    over: block size 3, no new nonzeros, the plain row kernel. fixed: None, or (owned dofs, values) whose rows
    and columns are taken out first (elimination.py): then (K0, lifting)."""
    lift = None if fixed is None else elimination.eliminate(csr, r0, *fixed, comm)
    opts = PETSc.Options()
    # createAIJWithArrays assembles at once, and the assembly scans every row for i-nodes (rows of one pattern)
    # unless -mat_no_inode is in the database when the matrix is made: plain_rows turns them off anyway
    scan = opts.hasName("mat_no_inode")
    if not scan:
        opts.setValue("mat_no_inode", True)
    try:
        A = PETSc.Mat().createAIJWithArrays(size, csr, comm=comm)
    finally:
        if not scan:
            opts.delValue("mat_no_inode")
    A.setBlockSizes(3, 3)          # createAIJWithArrays ignores bsize; GAMG aggregates by it
    A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
    plain_rows(A)
    return A if fixed is None else (A, lift)


BATCH = 1 << 19           # candidates (element blocks) summed per batch: ~40 MB of temporaries


def stiffness_matrix(mesh, lmbda, mu, extra=None, fixed=None, kappa=None):
    """The elastic stiffness K: a dof-space MPIAIJ matrix (block size 3) whose CSR arrays are built here.

    Rows are vertices (sparsity.py). Each rank sums its cells' element blocks into the rows it
    owns, sends the blocks of rows owned elsewhere to their owners, and hands PETSc its rows as
    split (diagonal | off-diagonal) CSR arrays, which PETSc uses without copying. The pattern is
    exact: no new nonzero may be added later. Element kernels run once per group of congruent
    cells (elasticity.congruent_groups) and batch of rows. lmbda, mu: (local cells,) [Pa]; kappa: None or (local
    cells,) [Pa], the bulk modulus each cell takes with its mean dilatation (cell_mean_bulk). extra: None or
    (rows, cols, bits) as lattice_stiffness_matrix takes it: the blocks are held whole. fixed: None, or
    (owned dofs, values) of the Dirichlet conditions: then (K0, lifting) (_stiffness_operator)."""
    comm = mesh.comm
    v0, v1 = mesh.vertex_range
    order = np.argsort(mesh.gvert, kind="stable")            # rows in global order: owned ones are one run
    gsorted = mesh.gvert[order]
    row_of = np.empty(len(order), np.int64)
    row_of[order] = np.arange(len(order))
    cell_rows = row_of[mesh.cells].astype(np.int32 if len(order) < 2**31 else np.int64)
    ptr, entries = sparsity.incidence(cell_rows, len(order))
    o0, o1 = np.searchsorted(gsorted, [v0, v1])
    ghost = np.r_[0:o0, o1:len(order)]
    ghost_pat = sparsity.block_pattern(ghost, cell_rows, ptr, entries)
    ghost_row = np.repeat(gsorted[ghost], np.diff(ghost_pat.rowptr))
    ghost_col = gsorted[ghost_pat.col]
    starts = ownership_starts(comm, o1 - o0)
    # the owners of ghost rows reserve those blocks: they may hold columns no local cell has
    x_row, x_col = send_to_owners(comm, starts, ghost_row, ghost_col)
    if extra is not None:          # whole blocks: this pattern is one of blocks
        x_row, x_col = (np.concatenate([x, np.asarray(e, x.dtype)]) for x, e in zip((x_row, x_col), extra[:2]))
    colspace = np.union1d(gsorted, x_col)
    cell_cols = np.searchsorted(colspace, gsorted).astype(cell_rows.dtype)[cell_rows]
    x_order = np.argsort(x_row, kind="stable")
    x_ptr = np.zeros(o1 - o0 + 1, np.int64)
    np.cumsum(np.bincount(x_row - v0, minlength=o1 - o0), out=x_ptr[1:])
    pattern = sparsity.block_pattern(np.arange(o0, o1), cell_cols, ptr, entries,
                                     x_ptr, np.searchsorted(colspace, x_col[x_order]))
    pattern.col = colspace[pattern.col]
    layout = sparsity.split_layout(pattern, v0, v1)

    def local_sums():
        groups = elasticity.congruent_groups(mesh.coords[mesh.cells], lmbda, mu, kappa)
        last = _last_rows(cell_rows, groups[1], len(groups[0]), o0)
        vals, cols = _owned_sums(mesh, pattern, entries, layout, groups, (lmbda, mu, kappa), last)
        return vals, cols, _row_sums(mesh, ghost_pat, entries, groups, (lmbda, mu, kappa))
    vals, cols, ghost_vals = on_all(comm, local_sums)       # a degenerate cell fails every rank
    received = send_to_owners(comm, starts, ghost_row, ghost_col, *ghost_vals.reshape(-1, 9).T)
    _add_received(pattern, layout, vals, v0, received[0], received[1], np.column_stack(received[2:]))

    n_diag, _, rowptr_d, rowptr_o = layout
    n_d = 9 * rowptr_d[-1]
    di = sparsity.point_rowptr(rowptr_d, n_diag).astype(PETSc.IntType)
    n_own = 3 * (v1 - v0)
    size = ((n_own, 3 * mesh.n_vertices), (n_own, 3 * mesh.n_vertices))
    if comm.size == 1:
        csr = (di, cols, vals)
    else:
        oi = sparsity.point_rowptr(rowptr_o, np.diff(pattern.rowptr) - n_diag).astype(PETSc.IntType)
        csr = ((di, cols[:n_d], vals[:n_d]), (oi, cols[n_d:], vals[n_d:]))
    return _stiffness_operator(size, csr, comm, 3 * v0, fixed)


def lattice_stiffness_matrix(mesh, lattices, extra=None, fixed=None):
    """The elastic stiffness K of a mesh made only of generated hex boxes, read from row templates
    (lattice.py): the same matrix as stiffness_matrix up to round-off, without summing element blocks.

    Every owned vertex row is complete on its owner (the templates know the cells of other ranks),
    so no values are sent; the global numbers of the neighbours come from a PETSc application
    ordering (original vertex id -> PETSc vertex number). A row whose neighbours are all owned
    and numbered in lattice order (distribute_mesh numbers owned vertices in original order: most
    rows) is its template as it stands: runs of such rows with one template are written as one
    broadcast, such rows outside a run template by template; only the other rows are sorted and
    gathered block by block.

    extra: None or (rows, cols, bits): entries to hold in the pattern with value 0, e.g. a contact stencil,
    by 3x3 block (global vertex numbers, rows owned here) and which of the block's entries (bit 3 i + k:
    row i, column k; a flat contact's rows couple only the normal components). fixed: as stiffness_matrix."""
    comm = mesh.comm
    v0, v1 = mesh.vertex_range
    T, P, tid, gcol, valid = _box_rows(mesh, lattices)
    n = len(tid)
    owned = (gcol >= v0) & (gcol < v1)
    blocks_of = [np.flatnonzero(P[t]) for t in range(len(T))]       # a template's blocks, in offset order
    # a natural row: every block owned and the columns ascending in offset order, its template as it stands
    natural = (owned | ~valid).all(axis=1)
    for t in np.unique(tid[natural]):
        rows = np.flatnonzero(natural & (tid == t))
        g = gcol[rows] if len(blocks_of[t]) == 27 else gcol[rows[:, None], blocks_of[t]]
        natural[rows] = (g[:, 1:] > g[:, :-1]).all(axis=1)
    widened = np.zeros(n, bool)
    if extra is not None and len(extra[0]):
        widened[np.asarray(extra[0], np.int64) - v0] = True
        natural &= ~widened
    runs = sparsity.equal_runs(tid, natural)
    odd = np.flatnonzero(~sparsity.covered(runs, n))
    lone, odd = odd[natural[odd]], odd[~natural[odd]]      # natural rows outside the runs, and the others
    # the other rows: one sort per row orders the blocks as PETSc's split CSR wants them: diagonal part,
    # off-diagonal part, absent ones last, each by column; the block's offset index in the low bits
    part = np.where(~valid[odd], 2, np.where(owned[odd], 0, 1))
    key = (part << _PART_SHIFT) | (gcol[odd] << _IDX_BITS) | np.arange(27)
    key.sort(axis=1)
    d, part, ocol = _unkey(key)
    # entries per point row (3 per vertex row) in the diagonal and off-diagonal parts
    count = [np.zeros((n, 3), np.int64), np.zeros((n, 3), np.int64)]
    count[0][:] = (3 * P.sum(axis=1))[tid, None]
    for p in (0, 1):
        count[p][odd] = 3 * (part == p).sum(axis=1)[:, None]
    # the other rows, the widened ones with their extra blocks: (rows, offset index, part, global column, entry
    # mask (bit 3 i + k) of each of their blocks)
    wide = widened[odd]
    # runs of the other rows: consecutive rows of one template whose blocks sort alike and whose columns all step by
    # one vertex, e.g. along a cut (its neighbours on either side are numbered along the line): written like the
    # natural runs, part by part
    plain = np.flatnonzero(~wide)
    split = _split_runs(odd[plain], tid[odd[plain]], d[plain], part[plain], ocol[plain])
    rest = plain[~sparsity.covered(split, len(plain))]
    groups = [(odd[rest], d[rest], part[rest], ocol[rest], None)]
    if wide.any():
        blocks = _extra_blocks(extra)
        width = np.bincount(blocks[0] - v0, minlength=n)[odd[wide]]
        # rows of about one width together: padded to the widest of all, a coarse face's node against a fine
        # surface (thousands of blocks) widened every surface row to it (2 x 2 cells on 60 x 60: 7.2 s and 2.3 GB
        # for 22k dofs)
        width_class = np.frexp(width)[1]
        for c in np.unique(width_class):
            this = np.flatnonzero(wide)[width_class == c]
            groups.append((odd[this], *_widen_rows(key[this], odd[this] + v0, blocks, v0, v1)))
    masks = []                  # per group and part: which of its (rows, 3, w, 3) entries it holds
    for rows, od, opart, _, bits in groups:
        masks.append([])
        held = None if bits is None else ((bits[:, None, :, None] >> (3 * np.arange(3)[:, None, None] + np.arange(3)))
                                          & 1) > 0
        for p in (0, 1):
            sel = np.broadcast_to((opart == p)[:, None, :, None], (len(rows), 3, od.shape[1], 3))
            if held is not None:
                sel = sel & held
                count[p][rows] = sel.sum(axis=(2, 3))
            masks[-1].append(sel)
    ptr = [np.concatenate([[0], np.cumsum(c.ravel())]) for c in count]     # point-row pointers
    vals_d, cols_d = np.empty(ptr[0][-1]), np.empty(ptr[0][-1], PETSc.IntType)
    vals_o, cols_o = np.empty(ptr[1][-1]), np.empty(ptr[1][-1], PETSc.IntType)
    trip = np.arange(3, dtype=PETSc.IntType)
    present = [T[t][:, P[t]].ravel() for t in range(len(T))]      # a natural row's values: its template's blocks
    step = 3 * np.arange(max((b - a for a, b in runs + split), default=0), dtype=PETSc.IntType)[:, None]
    heads = np.array([a for a, _ in runs], np.int64)
    for t in np.unique(tid[heads]):                # the runs of one template: their first rows' columns at once
        which = np.flatnonzero(tid[heads] == t)
        nb = len(blocks_of[t])
        first = (3 * (gcol[heads[which][:, None], blocks_of[t]] - v0)).astype(PETSc.IntType)
        first = np.broadcast_to(first[:, None, :, None] + trip, (len(which), 3, nb, 3)).reshape(len(which), -1)
        for (a, b), head in zip((runs[i] for i in which), first):
            _fill_run(vals_d, cols_d, ptr[0], a, b, present[t], head, step)
    for i0, i1 in split:
        j = plain[i0]
        a = odd[j]
        for p, vals, cols in ((0, vals_d, cols_d), (1, vals_o, cols_o)):
            sel = part[j] == p
            if sel.any():
                head = (3 * (ocol[j, sel] - (v0 if p == 0 else 0))).astype(PETSc.IntType)[:, None] + trip
                _fill_run(vals, cols, ptr[p], a, a + i1 - i0, T[tid[a]][:, d[j, sel], :].ravel(),
                          np.broadcast_to(head, (3,) + head.shape).ravel(), step)
    for t in np.unique(tid[lone]):               # natural rows alone: template by template
        rows = lone[tid[lone] == t]
        nb = len(blocks_of[t])
        at = ptr[0][3 * rows][:, None] + np.arange(9 * nb)
        vals_d[at] = present[t]
        first = (3 * (gcol[rows[:, None], blocks_of[t]] - v0))[:, None, :, None] + trip
        cols_d[at] = np.broadcast_to(first, (len(rows), 3, nb, 3)).reshape(len(rows), -1)
    for (rows, od, opart, ocols, _), sels in zip(groups, masks):
        blocks = T[tid[rows, None, None], np.arange(3)[:, None], np.minimum(od, 26)[:, None, :]]    # (rows, 3, w, 3)
        if od.shape[1] > 27:
            blocks[np.broadcast_to(od[:, None, :, None] >= 27, blocks.shape)] = 0.0      # extra blocks hold 0
        col0 = np.where(opart == 0, 3 * (ocols - v0), 3 * ocols).astype(PETSc.IntType)[:, None, :, None] + trip
        col0 = np.broadcast_to(col0, blocks.shape)
        for p, vals, cols in ((0, vals_d, cols_d), (1, vals_o, cols_o)):
            at, _ = sparsity.row_spans(ptr[p], (3 * rows[:, None] + np.arange(3)).ravel())
            vals[at], cols[at] = blocks[sels[p]], col0[sels[p]]
    csr = (ptr[0].astype(PETSc.IntType), cols_d, vals_d)
    if comm.size > 1:
        csr = (csr, (ptr[1].astype(PETSc.IntType), cols_o, vals_o))
    size = ((3 * n, 3 * mesh.n_vertices), (3 * n, 3 * mesh.n_vertices))
    return _stiffness_operator(size, csr, comm, 3 * v0, fixed)


# lattice_stiffness_matrix's sort keys: part (0 diagonal, 1 off-diagonal, 2 absent) | global column | offset index
_IDX_BITS, _PART_SHIFT = 5, 60


def _split_runs(rows, tid, d, part, ocol):
    """Runs [(i0, i1), ...] (at least MIN_RUN long) of the rows (ascending) whose every next row is the row after
    it, of the same template, with its blocks in the same sorted order (d: offset index, part) and each present
    block's global column one more (ocol): the first row's layout then holds for the whole run, shifted."""
    if len(rows) == 0:
        return []
    return sparsity.continued_runs(
        (rows[1:] == rows[:-1] + 1) & (tid[1:] == tid[:-1]) & (d[1:] == d[:-1]).all(axis=1)
        & (part[1:] == part[:-1]).all(axis=1) & ((ocol[1:] == ocol[:-1] + 1) | (part[1:] == 2)).all(axis=1))


def _fill_run(vals, cols, ptr, a, b, row_values, head, step):
    """Vertex rows a..b of one CSR part (point-row pointers ptr) that all hold row_values, with the columns head in
    the first and 3 more per row after it (step: 3 * arange as a column): a run's rows are consecutive vertices
    whose neighbours are numbered consecutively too. One broadcast and one add over whole rows."""
    p0, p1 = ptr[3 * a], ptr[3 * b]
    vals[p0:p1].reshape(b - a, -1)[:] = row_values
    np.add(head, step[:b - a], out=cols[p0:p1].reshape(b - a, -1))


def _unkey(key, idx_bits=_IDX_BITS):
    """(offset index, part, global column) of lattice_stiffness_matrix's sort keys."""
    return key & ((1 << idx_bits) - 1), key >> _PART_SHIFT, (key >> idx_bits) & ((1 << (_PART_SHIFT - idx_bits)) - 1)


def _extra_blocks(extra):
    """lattice_stiffness_matrix's extra blocks (rows, cols, bits) with each (row, column) once, its bits OR-ed,
    sorted by row, then column."""
    er, ec, eb = (np.asarray(a, np.int64) for a in extra)
    block = (er << 32) | ec                      # by row, then column (vertex numbers < 2^31): one key, not lexsort
    # stable: its merge sort takes the sorted columns of a contact stencil's point rows as runs (517k entries at
    # 212k dofs: 2.6 ms against 11 ms); the ties are one block's entries, OR-ed below whatever their order
    order = np.argsort(block, kind="stable")
    block, eb = block[order], eb[order]
    starts = np.flatnonzero(np.r_[True, block[1:] != block[:-1]])          # one block per (row, column)
    block, eb = block[starts], np.bitwise_or.reduceat(eb, starts) if len(eb) else eb
    return block >> 32, block & 0xFFFFFFFF, eb


def _widen_rows(key, rows, blocks, v0, v1):
    """The sorted blocks of rows (global vertex numbers, ascending; key: their 27 sorted template keys) with
    their extra blocks (_extra_blocks) added as offset indices 27, 28, ...: (offset index, part, global column,
    entry mask), each (len(rows), width); a template block's mask is all nine entries. An extra block the
    template has already is not added again."""
    er, ec, eb = blocks
    pos = np.searchsorted(rows, er)
    keep = (pos < len(rows)) & (rows[np.minimum(pos, len(rows) - 1)] == er)
    pos, cols, eb = pos[keep], ec[keep], eb[keep]
    count = np.bincount(pos, minlength=len(rows))
    width = int(count.max(initial=0))
    bits = max(_IDX_BITS, (27 + width).bit_length())         # room for the offset indices of the widest row
    d, part, gcol = _unkey(key)
    rank = np.arange(len(pos)) - np.repeat(np.cumsum(count) - count, count)   # blocks are sorted by row
    wide = np.empty((len(rows), 27 + width), np.int64)
    wide[:, :27] = (part << _PART_SHIFT) | (gcol << bits) | d
    wide[:, 27:] = (2 << _PART_SHIFT) | (27 + np.arange(width))          # absent unless filled below
    mask = np.zeros(wide.shape, np.int64)
    mask[:, :27] = 0x1FF
    part = np.where((cols >= v0) & (cols < v1), 0, 1)
    wide[pos, 27 + rank] = (part << _PART_SHIFT) | (cols << bits) | (27 + rank)
    mask[pos, 27 + rank] = eb
    order = np.argsort(wide, axis=1)
    wide, mask = np.take_along_axis(wide, order, axis=1), np.take_along_axis(mask, order, axis=1)
    same = np.zeros(wide.shape, bool)                 # an extra block the template has: it sorts after it
    same[:, 1:] = ((wide[:, 1:] >> bits) == (wide[:, :-1] >> bits)) & ((wide[:, 1:] >> _PART_SHIFT) < 2)
    wide[same] = (2 << _PART_SHIFT) | (wide[same] & ((1 << _PART_SHIFT) - 1))
    return (*_unkey(wide, bits), mask)


def _box_rows(mesh, lattices):
    """Templates T (27 per box, 3, 27, 3) and P of lattice.templates, and per owned row (ascending global
    vertex) its template id, the global vertex number of each of its 27 neighbour offsets (any
    valid number where P says there is none) and which of them exist (P of its template)."""
    own = mesh.owned_rows                                    # row r is global vertex v0 + r
    orig = mesh.vert_orig[own].astype(np.int64)
    ends = np.array([b.offset for b in lattices] + [lattices[-1].offset + lattices[-1].n_vertices])
    body = np.searchsorted(ends, orig, side="right") - 1
    nt = 27 * len(lattices)
    T, P = np.empty((nt, 3, 27, 3)), np.empty((nt, 27), bool)
    tid, steps = np.empty(len(own), np.int64), np.empty((len(lattices), 27), PETSc.IntType)
    for b, box in enumerate(lattices):
        T[27 * b:27 * b + 27], P[27 * b:27 * b + 27] = lattice.templates(box.Ke)
        mine = body == b
        tid[mine] = 27 * b + lattice.vertex_classes(box, orig[mine] - box.offset)
        steps[b] = lattice.OFFSETS @ box.stride
    ao = PETSc.AO().createBasic(mesh.vert_orig[mesh.owned].astype(PETSc.IntType),
                                mesh.gvert[mesh.owned].astype(PETSc.IntType), comm=mesh.comm)
    nbr = orig.astype(PETSc.IntType)[:, None] + (steps[0] if len(lattices) == 1 else steps[body])
    valid = P[tid]
    nbr = np.where(valid, nbr, 0).ravel()
    gcol = np.asarray(ao.app2petsc(nbr), np.int64).reshape(len(own), 27)
    ao.destroy()
    return T, P, tid, gcol, valid


def _row_sums(mesh, pattern, entries, groups, moduli):
    """Summed element blocks (nnzb, 3, 3) of every block of a pattern, batch by batch of rows."""
    out = np.empty((len(pattern.col), 3, 3))
    for r0, r1 in sparsity.row_batches(pattern.cptr, BATCH):
        p0, p1 = pattern.rowptr[r0], pattern.rowptr[r1]
        out[p0:p1] = _batch_sums(mesh, pattern, entries, r0, r1, groups, moduli).reshape(-1, 3, 3)
    return out


def _owned_sums(mesh, pattern, entries, layout, groups, moduli, last):
    """Split CSR values and point columns of the owned rows: (vals, cols) in one array each.

    Consecutive rows with the same number of blocks, all in the diagonal part, are copied as one
    strided block (every interior row of a structured mesh); other rows go value by value."""
    n_diag, n_left, rowptr_d, _ = layout
    n = 9 * (rowptr_d[-1] + layout[3][-1])
    vals, cols = np.empty(n), np.empty(n, PETSc.IntType)
    v0 = mesh.vertex_range[0]
    nb = np.diff(pattern.rowptr)
    plain = (n_diag == nb) & (n_left == 0)
    cache = _KernelCache(mesh, groups, moduli, last)
    for r0, r1 in sparsity.row_batches(pattern.cptr, BATCH):
        V = _batch_sums(mesh, pattern, entries, r0, r1, groups, moduli, cache)        # (blocks of the batch, 9)
        q0 = pattern.rowptr[r0]
        runs = sparsity.equal_runs(nb[r0:r1], plain[r0:r1], r0)
        for a, b in runs:
            p0, p1, w = pattern.rowptr[a], pattern.rowptr[b], nb[a]
            d0, d1 = 9 * rowptr_d[a], 9 * rowptr_d[b]
            shape = (b - a, 3, w, 3)
            vals[d0:d1].reshape(shape)[...] = V[p0 - q0:p1 - q0].reshape(b - a, w, 3, 3).transpose(0, 2, 1, 3)
            cols[d0:d1].reshape(shape)[...] = (3 * (pattern.col[p0:p1] - v0)).reshape(b - a, 1, w, 1) + np.arange(3)
        odd = np.flatnonzero(~sparsity.covered(runs, r1 - r0, r0)) + r0
        if len(odd):
            p, which = sparsity.row_spans(pattern.rowptr, odd)
            row = odd[which]
            base, stride, col0 = sparsity.block_positions(pattern, layout, p, row, v0)
            pos = sparsity.scatter_points(base, stride)
            vals[pos] = V[p - q0].reshape(-1, 3, 3)
            cols[pos] = (col0[:, None] + np.arange(3))[:, None, :]
    return vals, cols


def _batch_sums(mesh, pattern, entries, r0, r1, groups, moduli, cache=None):
    """Summed element blocks (nb, 9) of the blocks of rows r0:r1 (row-major 3x3), kernels run once per
    congruent group (and, with a _KernelCache, once per run of batches needing it).

    The segmented sum is a sparse-dense product S T in PETSc (S: one row per block, a 1 per
    candidate at its element block's row of table T): about 4x faster than NumPy's reduceat."""
    first, group = groups
    k = mesh.cells.shape[1]
    kk = k * k
    c0, c1 = pattern.cptr[r0], pattern.cptr[r1]
    p0, p1 = pattern.rowptr[r0], pattern.rowptr[r1]
    if p1 == p0:
        return np.zeros((0, 9))
    src = pattern.src[c0:c1]
    entry = entries[src // k]                             # extras (src = -1) are masked below
    cell = entry // k
    g = group[cell]
    need = np.zeros(len(first), bool)
    need[g[src >= 0]] = True
    reps = np.flatnonzero(need)
    slot = np.zeros(len(first), np.int64)
    slot[reps] = np.arange(len(reps))
    # T channel by channel (PETSc's dense matrices are column-major); its last row is the zero of extra columns
    table = np.zeros((9, len(reps) * kk + 1))
    (cache or _KernelCache(mesh, groups, moduli)).fill(table[:, :-1].reshape(9, len(reps), kk), reps, r1)
    ids = np.where(src >= 0, slot[g] * kk + (entry - cell * k) * k + src % k, len(reps) * kk).astype(PETSc.IntType)
    indptr = np.append(pattern.first[p0:p1] - c0, c1 - c0).astype(PETSc.IntType)
    S = PETSc.Mat().createAIJWithArrays((p1 - p0, table.shape[1]), (indptr, ids, np.ones(len(ids))),
                                        comm=PETSc.COMM_SELF)
    T = PETSc.Mat().createDense(table.T.shape, array=table.T, comm=PETSc.COMM_SELF)
    Y = S.matMult(T)
    out = np.ascontiguousarray(Y.getDenseArray())          # PETSc's dense matrices are column-major
    for m in (Y, T, S):
        m.destroy()
    return out


class _KernelCache:
    """Element blocks of congruent groups, channel by channel (9, groups, kk), kept from one row batch to
    the next while a later batch still needs them: batches of consecutive rows share the cells between them.

    last[g]: the last pattern row whose batch needs group g (None: keep nothing)."""

    def __init__(self, mesh, groups, moduli, last=None):
        # moduli: (lmbda, mu, kappa) of the local cells (kappa: None, or each cell's mean-dilatation bulk modulus)
        self.mesh, self.groups, self.last = mesh, groups, last
        self.lmbda, self.mu, self.kappa = moduli
        k = mesh.cells.shape[1]
        self.ids, self.kept = np.zeros(0, np.int64), np.zeros((9, 0, k * k))

    def fill(self, out, reps, r1):
        """Write the blocks of the (ascending) groups reps into out (9, len(reps), kk), for a batch ending at row r1."""
        mesh, k = self.mesh, self.mesh.cells.shape[1]
        hit = np.isin(reps, self.ids, assume_unique=True)
        out[:, hit] = self.kept[:, np.searchsorted(self.ids, reps[hit])]
        c = self.groups[0][reps[~hit]]
        try:
            Ke = elasticity.stiffness(mesh.cell_type, mesh.coords[mesh.cells[c]], self.lmbda[c], self.mu[c],
                                      share_translates=False, ids=mesh.cell_orig[c],
                                      kappa=None if self.kappa is None else self.kappa[c])
        except elasticity.DegenerateCell as exc:      # named where the user can find it: body, file, cell there
            raise MeshError(f"{mesh.describe_cell(exc.cell)} is inverted or degenerate: {exc.detail}") from None
        out[:, ~hit] = Ke.reshape(-1, k, 3, k, 3).transpose(2, 4, 0, 1, 3).reshape(9, -1, k * k)
        if self.last is not None:
            keep = self.last[reps] >= r1
            self.ids, self.kept = reps[keep], out[:, keep]


def _last_rows(cell_rows, group, n_groups, offset):
    """Per group, the last row (minus offset) of any of its cells: until then a batch may need it."""
    last = cell_rows.max(axis=1, initial=0) - offset if len(cell_rows) else np.zeros(0, np.int64)
    order = np.lexsort((last, group))                # by group, then row: a group's maximum ends its run
    g = group[order]
    end = np.flatnonzero(np.r_[g[1:] != g[:-1], True]) if len(g) else np.zeros(0, np.int64)
    out = np.full(n_groups, -1, np.int64)
    out[g[end]] = last[order][end]
    return out


def _add_received(pattern, layout, vals, v0, rows, cols, blocks):
    """Add blocks (n, 9) at global (rows, cols) of owned rows into the split values (duplicates summed)."""
    if len(rows) == 0:
        return
    row = rows - v0
    p = pattern.rowptr[row] + _rank_in_row(pattern, row, cols)
    order = np.argsort(p, kind="stable")
    p, row, blocks = p[order], row[order], blocks[order]
    head = np.flatnonzero(np.r_[True, p[1:] != p[:-1]])
    base, stride, _ = sparsity.block_positions(pattern, layout, p[head], row[head], v0)
    vals[sparsity.scatter_points(base, stride)] += np.add.reduceat(blocks, head, axis=0).reshape(-1, 3, 3)


def _rank_in_row(pattern, row, cols):
    """Position of column cols in block row row of the pattern (every pair must be in it)."""
    lo, hi = pattern.rowptr[row], pattern.rowptr[row + 1]
    t = np.zeros(len(row), np.int64)
    # binary search, all pairs at once: rows hold at most a few dozen blocks
    width = int((hi - lo).max(initial=1))
    step = 1 << int(np.ceil(np.log2(max(width, 1))))
    while step:
        probe = t + step
        ok = probe < hi - lo
        ok[ok] = pattern.col[lo[ok] + probe[ok]] <= cols[ok]
        t[ok] = probe[ok]
        step >>= 1
    return t


def internal_force(mesh, u_local, lmbda, mu, which=None, kappa=None):
    """Element-by-element K u (local, ghosted dof array): reactions need K before constraints.

    which: None, every local cell; or the indices of the cells to sum, so that the entries of a vertex all of
    whose local cells are among them are K u's (the others partial). Cells in few congruent groups (generated
    boxes) take one product per group with the group's stiffness; other meshes go chunk by chunk with every
    cell's own."""
    cells = mesh.cells if which is None else mesh.cells[which]
    if which is not None:
        lmbda, mu = lmbda[which], mu[which]
        kappa = None if kappa is None else kappa[which]
    m, k = cells.shape
    ue = u_local.reshape(-1, 3)[cells].reshape(m, 3 * k)
    xe = mesh.coords[cells]
    first, group = elasticity.congruent_groups(xe, lmbda, mu, kappa) if m else (np.zeros(0, np.int64),) * 2
    fe = np.empty_like(ue)
    if len(first) <= FEW_GROUPS:
        Kg = elasticity.stiffness(mesh.cell_type, xe[first], lmbda[first], mu[first], share_translates=False,
                                  kappa=None if kappa is None else kappa[first])
        for g, Ke in enumerate(Kg):
            sel = np.flatnonzero(group == g)
            fe[sel] = ue[sel] @ Ke.T
    else:
        # chunk by chunk; stiffness() groups each chunk's translates again only where the grouping above found
        # them worth sharing (an unstructured mesh has next to none)
        share = len(first) <= m // 2
        for s in range(0, m, CHUNK):
            c = slice(s, s + CHUNK)
            Kc = elasticity.stiffness(mesh.cell_type, xe[c], lmbda[c], mu[c], share_translates=share,
                                      kappa=None if kappa is None else kappa[c])
            fe[c] = np.einsum("mij,mj->mi", Kc, ue[c])
    ldofs = 3 * cells[:, :, None] + np.arange(3)
    return np.bincount(ldofs.ravel(), fe.ravel(), minlength=3 * len(mesh.coords))


def triplet_matrix(mesh, rows, cols, vals):
    """A dof-space MPIAIJ matrix from (row, col, value) triplets given on any rank (duplicates summed).

    Triplets are sent to their row's owner and added there by PETSc into storage preallocated for
    every triplet (summing repeats in C beat sorting them in NumPy 2x, measured on contact rows before
    the row builder summed each face pair's points); the assembled matrix is then duplicated at its
    exact size."""
    comm = mesh.comm
    starts = 3 * ownership_starts(comm, mesh.owned.sum())
    rows, cols, vals = send_to_owners(comm, starts, np.asarray(rows, np.int64),
                                      np.asarray(cols, np.int64), np.asarray(vals, float))
    r0, r1 = starts[comm.rank], starts[comm.rank + 1]
    m, n = int(r1 - r0), int(starts[-1])
    lrow = rows - r0
    diag = (cols >= r0) & (cols < r1)
    d_nnz = np.minimum(np.bincount(lrow[diag], minlength=m), m)
    o_nnz = np.minimum(np.bincount(lrow[~diag], minlength=m), n - m)
    A = PETSc.Mat().createAIJ(((m, n), (m, n)), bsize=1, nnz=(d_nnz.astype(PETSc.IntType), o_nnz.astype(PETSc.IntType)),
                              comm=comm)
    A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
    if len(rows):          # (petsc4py 3.18 divides by the block count: no call without triplets)
        A.setValuesRCV(rows.astype(PETSc.IntType)[:, None], cols.astype(PETSc.IntType)[:, None],
                       vals[:, None, None], addv=ADD)
    A.assemble()
    exact = A.duplicate(copy=True)
    A.destroy()
    return exact


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
    for i, bc in enumerate(scene.boundary):
        if bc.type != "pressure":
            continue
        c, lf = mesh.surface_faces(bc.surface)
        nodes = mesh.face_nodes(c, lf)
        field = isinstance(bc.value, str)
        # a field's values at the quadrature points are kept for the check below
        pressure, values = _recording(compile_expression(bc.value)) if field else (bc.value, [])
        # a pressure field varies within faces: a 3-point rule per direction integrates it better than 2
        fe = fem.face_pressure_loads(mesh.face_type, mesh.coords[nodes], pressure, n_gauss=3 if field else 2)
        if field and len(nodes):
            # ... and at the faces' nodes: 1/x, infinite on an edge of the surface, passed at the quadrature points
            # and its total load grew by ln 2 at each refinement (hunt34_3)
            pressure(mesh.coords[nodes].reshape(-1, 3))
        _check_pressure_field(mesh, i, bc, np.hstack([v.reshape(len(nodes), -1) for v in values])
                              if values and len(nodes) else None, nodes)
        dofs = (3 * mesh.gvert[nodes][:, :, None] + np.arange(3)).ravel()
        f.setValues(dofs.astype(PETSc.IntType), fe.ravel(), addv=ADD)
    f.assemble()
    return f


def _recording(field):
    """The function `field` of points with its values of magnitude below MIN_MAGNITUDE made 0, and the list each of
    its answers (before that) goes to. A field's tail under the scene's limit is no load: a Gaussian patch's
    corners at 1e-189 Pa were refused (hunt33_2); a field all of whose values lie there is (_check_pressure_field)."""
    seen = []

    def recorded(x):
        seen.append(np.asarray(field(x), dtype=float))
        return np.where(np.abs(seen[-1]) < MIN_MAGNITUDE, 0.0, seen[-1])
    return recorded, seen


def _check_pressure_field(mesh, index, bc, p, nodes):
    """A SceneError naming boundary[index].value when its field's values p (faces, points; None for a number: the
    scene checked it) are not finite or of magnitude above the scene's limit anywhere, or all 0 or below its lower
    limit (made 0 by _recording) but not all 0 (collective)."""
    bad = None
    # a rank may hold no face
    loaded = mesh.comm.allreduce(p is not None and bool((np.abs(p) >= MIN_MAGNITUDE).any()), op=MPI.LOR)
    if p is not None:
        wrong = ~np.isfinite(p) | (np.abs(p) > MAX_MAGNITUDE) | ((p != 0) & (not loaded))
        face = np.flatnonzero(wrong.any(axis=1))
        if len(face):
            bad = (mesh.coords[nodes[face[0]]].mean(axis=0), float(p[face[0]][wrong[face[0]]][0]))
    bad = next((b for b in mesh.comm.allgather(bad) if b is not None), None)
    if bad is None:
        return
    near, value = bad
    where = f"the face near x, y, z = {', '.join(f'{v:.4g}' for v in near)}"
    head = f"boundary[{index}].value: the pressure {bc.value!r} on {bc.surface} is"
    if not np.isfinite(value):
        raise SceneError(f"{head} not finite on {where} (a division by zero, the log or square root of a negative "
                         f"number, or an overflow)")
    raise SceneError(f"{head} {value:.3g} on {where}: a value must be 0 or of magnitude between {MIN_MAGNITUDE:g} and "
                     f"{MAX_MAGNITUDE:g}")


def dirichlet_dofs(mesh, scene):
    """Owned constrained dofs and their values [m] at full load, from displacement and symmetry boundaries.

    Returns (dofs, values, per_boundary) where per_boundary[i] lists the owned dofs whose reaction boundary i
    reports: those it holds, each dof that several boundaries hold given to the first of them in the scene (a
    clamped face's edge on a symmetry plane counted in both had the reactions off balance by that edge's)."""
    dofs, vals, where = [], [], []
    for i, bc in enumerate(scene.boundary):
        if bc.type == "pressure":
            continue
        v = mesh.surface_vertices(bc.surface)
        v = v[mesh.owned[v]]
        if bc.type == "displacement":
            comps = [(c, getattr(bc, k)) for c, k in enumerate(("ux", "uy", "uz")) if getattr(bc, k) is not None]
        else:
            comps = [(symmetry_axis(mesh, i, bc.surface), 0.0)]
        for comp, value in comps:
            d = 3 * mesh.gvert[v] + comp
            dofs.append(d)
            vals.append(np.full(len(d), float(value)))
            where.append(np.stack([np.full(len(d), i), v, np.full(len(d), comp)], axis=1))
    dofs = np.concatenate(dofs) if dofs else np.zeros(0, np.int64)
    vals = np.concatenate(vals) if vals else np.zeros(0)
    where = np.concatenate(where) if where else np.zeros((0, 3), np.int64)
    # the entries go in scene order: a dof's first entry is the first boundary that holds it
    dofs, first, inverse = np.unique(dofs, return_index=True, return_inverse=True)
    _check_one_value(mesh, scene, vals, where, first[inverse])
    owner = where[first, 0]
    return dofs, vals[first], [dofs[owner == i] for i in range(len(scene.boundary))]


def _check_one_value(mesh, scene, vals, where, first_of):
    """A SceneError (on every rank) if two boundaries prescribe different values to one dof: entry k (value vals[k],
    (boundary, vertex, component) where[k]) against the first entry of its dof, first_of[k]; the message names
    the clash at the lowest original vertex id, so that it is the same on any number of ranks (collective)."""
    clash = np.flatnonzero(np.abs(vals - vals[first_of]) > 1e-12 * np.maximum(np.abs(vals), np.abs(vals[first_of])))
    found = None
    if len(clash):
        k = clash[np.argmin(mesh.vert_orig[where[clash, 1]])]
        (a, vertex, comp), b = where[first_of[k]], where[k][0]
        found = (int(mesh.vert_orig[vertex]), int(a), int(b), int(comp), float(vals[first_of[k]]), float(vals[k]),
                 mesh.coords[vertex].tolist())
    if mesh.comm.allreduce(len(clash), op=MPI.SUM):
        _, a, b, comp, va, vb, x = min(f for f in mesh.comm.allgather(found) if f is not None)
        # the nodes of the clash named, not of every clash (xmin against zmin and zmax read 10 for zmin's 5; hunt33_5)
        named = (where[first_of[clash], 0] == a) & (where[clash, 0] == b) & (where[clash, 2] == comp)
        count = mesh.comm.allreduce(int(named.sum()), op=MPI.SUM)
        u = "xyz"[comp]
        raise SceneError(f"boundary[{b}]: u{u} = {vb:g} m on {scene.boundary[b].surface} where boundary[{a}] holds "
                         f"u{u} = {va:g} m ({scene.boundary[a].surface}), on {count} node(s), the first at x, y, z = "
                         f"{', '.join(f'{c:.4g}' for c in x)}: a node takes one value per component")


def plane_axis(mesh, surface):
    """The axis (0, 1, 2) a surface is a plane normal to, or None (collective: all ranks agree)."""
    c, lf = mesh.surface_faces(surface)
    xf = mesh.coords[mesh.face_nodes(c, lf)]
    n = fem.centroid_normals(mesh.face_type, xf)
    total = mesh.comm.allreduce(np.abs(n).sum(axis=0) if len(n) else np.zeros(3), op=MPI.SUM)
    count = mesh.comm.allreduce(len(n), op=MPI.SUM)
    axis = int(np.argmax(total))
    return None if count == 0 or total[axis] < count * (1.0 - 1e-9) else axis


def symmetry_axis(mesh, index, surface):
    """The axis normal to an axis-aligned symmetry surface (collective: all ranks agree)."""
    axis = plane_axis(mesh, surface)
    if axis is None:
        raise MeshError(f"boundary[{index}].surface: symmetry surface {surface!r} is not a plane "
                        f"normal to x, y or z")
    return axis


def _centred(comm, x):
    """Points x (k, 3) of one body spread over comm's ranks, less the body's centroid."""
    return x - comm.allreduce(x.sum(axis=0), op=MPI.SUM) / max(comm.allreduce(len(x)), 1)


def _body_rows(mesh):
    """Per body (collective): this rank's vertex rows of it (a slice when they are all the rank's rows: strided
    writes, not scattered ones) and their points less the body's centroid."""
    row_body = mesh.vertex_body[mesh.owned_rows]
    for b in range(len(mesh.body_names)):
        r = np.flatnonzero(row_body == b)
        x = _centred(mesh.comm, mesh.coords[mesh.owned_rows[r]])
        yield (slice(None) if len(r) == len(row_body) else r), x


def dilatations(mesh, template):
    """Per body, the displacement of a unit strain in every direction on it, u = x - (its centroid), and 0
    elsewhere (Vecs like template): K times one is the force scale of a unit strain of that body (System's force
    floor)."""
    out = []
    for r, x in _body_rows(mesh):
        vec = template.duplicate()
        vec.set(0.0)
        vec.getArray().reshape(-1, 3)[r] = x
        out.append(vec)
    return out


def rigid_body_modes(mesh, template, held=()):
    """Near-nullspace: the 6 rigid-body modes of every body, each supported on its own body only.

    held: (surface name, unit normal or None) pairs whose vertices a penalty holds (rigid dies): the
    modes lose the normal component there (None: all three). A die's stiff penalty rows make a rigid
    motion of those vertices far from near-null; left in, smoothed aggregation built coarse spaces
    that fought them (GAMG: 98 Krylov iterations against 49 on two cubes between sticking dies, 70k dofs)."""
    comm = mesh.comm
    v0 = mesh.vertex_range[0]
    held_rows = []
    for surface, normal in held:
        v = mesh.surface_vertices(surface)
        held_rows.append((mesh.gvert[v[mesh.owned[v]]] - v0, normal))
    vecs = []
    for r, x in _body_rows(mesh):
        modes = [template.duplicate() for _ in range(6)]
        for k, v in enumerate(modes):      # about the centroid
            v.set(0.0)
            a = v.getArray().reshape(-1, 3)            # by vertex row
            elasticity.write_rigid_motion(a, r, k, x)
            for rows, normal in held_rows:
                if normal is None:
                    a[rows] = 0.0
                else:
                    a[rows] -= np.outer(a[rows] @ normal, normal)
        # modified Gram-Schmidt: MatNullSpace wants an orthonormal basis
        for k, v in enumerate(modes):
            for w in modes[:k]:
                v.axpy(-v.dot(w), w)
            v.normalize()
        vecs.extend(modes)
    return PETSc.NullSpace().create(vectors=vecs, comm=comm)


def slip_modes(mesh, template, surfaces, held_dofs):
    """The contact band preconditioner's coarse space: per body with a contact surface, its 6 rigid motions
    weighted by w = 1 - d / D, where d is the distance from the surface's best-fit plane and D the largest d
    over the body (w = 1 on the surface, 0 on its far side; a body with several contact surfaces takes the
    largest w). Returns one block per body, (owned dof positions on this rank, their values (6, positions)),
    zero on held_dofs (global).

    Frictionless contact lets two bodies slide on each other, resisted only by their deformation between the
    contact and their supports: a smooth, global, soft motion. The multigrid does not resolve it (its coarse
    spaces follow the stiff normal coupling across the interface): on two cubes between sticking dies (70k
    dofs) the smallest eigenvalues of the preconditioned operator, 0.05-0.09, were the relative slides along
    x and y and the twist about the normal, each a rigid motion of the interface fading towards the die.
    These fields span them closely enough for a Galerkin correction (docs/performance.md)."""
    comm = mesh.comm
    owned_v = np.flatnonzero(mesh.owned)
    r0, r1 = template.getOwnershipRange()
    rows = (3 * mesh.gvert[owned_v] - r0).astype(np.int64)
    weights, in_body = {}, {}          # per body: w on this rank's owned vertices, and which of them are its
    for name in surfaces:
        v = mesh.surface_vertices(name)
        x = mesh.coords[v[mesh.owned[v]]]
        count = comm.allreduce(len(x))
        centre = comm.allreduce(x.sum(axis=0)) / count
        normal = np.linalg.eigh(comm.allreduce((x - centre).T @ (x - centre)))[1][:, 0]
        cells = mesh.surface_faces(name)[0]
        body = comm.allreduce(int(mesh.cell_body[cells[0]]) if len(cells) else -1, op=MPI.MAX)
        if body not in in_body:
            in_body[body] = mesh.body_mask(body)[owned_v]
        d = np.abs((mesh.coords[owned_v] - centre) @ normal)
        far = comm.allreduce(float(d[in_body[body]].max(initial=0.0)), op=MPI.MAX)
        w = np.where(in_body[body], np.clip(1.0 - d / far, 0.0, 1.0) if far > 0 else 1.0, 0.0)
        weights[body] = np.maximum(weights.get(body, 0.0), w)
    held = np.zeros(r1 - r0, dtype=bool)
    held[np.asarray(held_dofs, dtype=np.int64) - r0] = True
    blocks = []
    for body in sorted(weights):
        mine = in_body[body]
        # rotations about the centroid at unit speed at the body's farthest point, as translations are: in metres
        # they scaled with the body, and at 1e6 m (or 1e-6) half the modes fell under preconditioner.COARSE_CUTOFF
        # (flat_punch: 1-3 more Krylov iterations; hunt34_1)
        x = _centred(comm, mesh.coords[owned_v[mine]])
        radius = comm.allreduce(float(np.linalg.norm(x, axis=1).max(initial=0.0)), op=MPI.MAX)
        fields = elasticity.rigid_motions(x / (radius or 1.0))
        fields *= weights[body][mine][None, :, None]
        cols = (rows[mine][:, None] + np.arange(3)).ravel()
        values = fields.reshape(6, -1)
        values[:, held[cols]] = 0.0
        order = np.argsort(cols)
        blocks.append((cols[order], np.ascontiguousarray(values[:, order])))
    return blocks
