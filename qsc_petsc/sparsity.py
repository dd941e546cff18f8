"""Vertex-block sparsity of a cell mesh: the exact CSR pattern, which element blocks sum into which matrix
block, and where blocks land in a point CSR split at the diagonal columns. Pure NumPy.

A row is a vertex and holds one 3x3 block per vertex it shares a cell with. For every row the
*candidates* are the k vertices of each of its cells ("cell entries" e = cell * k + slot), plus
optional extra columns (blocks that other ranks will add). Sorting each row's candidates by
column gives at once the distinct columns (the CSR pattern) and, run by run, which element
blocks sum into which matrix block, so values can be summed segment by segment (assembly.py does
it as one sparse-dense product) instead of by a scatter with collisions.
"""

from dataclasses import dataclass

import numpy as np

ROW_BATCH = 1 << 20        # candidates sorted per batch: bounds the temporaries (~10 MB each)
MIN_RUN = 4                # rows: shorter runs of equal rows go value by value


@dataclass
class BlockPattern:
    """Rows (in the given order) of a vertex-block CSR and where each row's candidates go.

    cptr[i]:cptr[i+1] are row i's candidates, sorted by column; src[c] = i_e * k + b names the
    element block of candidate c: cell entry entries[i_e] (= cell * k + slot a) and column slot b,
    or is -1 for an extra column; first[p] is the first candidate summing into block p."""
    rowptr: np.ndarray     # (n + 1,) blocks per row, cumulated
    col: np.ndarray        # (nnzb,) column ids, ascending within a row
    cptr: np.ndarray       # (n + 1,) candidates per row, cumulated
    src: np.ndarray        # (ncand,)
    first: np.ndarray      # (nnzb,)


def incidence(cell_rows, n_rows):
    """(ptr, entries): the cell entries (cell * k + slot) of every row, row by row.

    cell_rows (m, k): the row of each cell vertex. A stable sort keeps cells ascending within a row,
    and is near linear on meshes whose numbering follows the cell order (timsort finds the runs)."""
    flat = cell_rows.ravel()
    entries = np.argsort(flat, kind="stable")
    ptr = np.zeros(n_rows + 1, np.int64)
    np.cumsum(np.bincount(flat, minlength=n_rows), out=ptr[1:])
    return ptr, entries


def block_pattern(rows, cell_cols, ptr, entries, extra_ptr=None, extra_cols=None):
    """The BlockPattern of `rows` (indices into ptr) from the cells' column ids cell_cols (m, k).

    Column ids must be non-negative; extra_ptr/extra_cols (CSR over `rows`, same id space) add
    columns that no local cell has. Consecutive rows are sorted together as one 2D array padded
    to the widest row of its width (within a factor 2) in the batch: NumPy sorts short int32 rows with SIMD,
    ~50x faster than an int64 key sort."""
    k = cell_cols.shape[1]
    rows = np.asarray(rows, np.int64)
    n_inc = ptr[rows + 1] - ptr[rows]
    n_ext = np.zeros(len(rows), np.int64) if extra_ptr is None else np.diff(extra_ptr)
    cptr = np.zeros(len(rows) + 1, np.int64)
    np.cumsum(n_inc * k + n_ext, out=cptr[1:])
    src = np.empty(cptr[-1], np.int64 if len(cell_cols) * k * k >= 2**31 else np.int32)
    ncol = int(max(cell_cols.max(initial=0), 0 if extra_cols is None else extra_cols.max(initial=0))) + 1
    sorted_cols = np.empty(cptr[-1], np.int32 if ncol < 2**31 else np.int64)
    is_first = np.empty(cptr[-1], bool)
    nb = np.zeros(len(rows), np.int64)
    # rows of about one width together: padded to the widest of its batch, a coarse face's node against a fine
    # surface (thousands of extra columns) widened every row near it (tetrahedra, 2 x 2 cells on 40 x 40:
    # 3.3 s and 1.4 GB for 10k dofs)
    width_class = np.frexp(n_inc * k + n_ext)[1]
    for r0, r1 in row_batches(cptr, ROW_BATCH):
        classes = np.unique(width_class[r0:r1])
        for c in classes:
            g = slice(r0, r1) if len(classes) == 1 else r0 + np.flatnonzero(width_class[r0:r1] == c)
            _sort_rows(g, rows[g], k, ncol, cell_cols, ptr, entries, extra_ptr, extra_cols, cptr, src,
                       sorted_cols, is_first, nb)
    rowptr = np.zeros(len(rows) + 1, np.int64)
    np.cumsum(nb, out=rowptr[1:])
    first = np.flatnonzero(is_first)
    return BlockPattern(rowptr, sorted_cols[first], cptr, src, first)


def _sort_rows(g, r, k, ncol, cell_cols, ptr, entries, extra_ptr, extra_cols, cptr, src, sorted_cols, is_first, nb):
    """Sort the candidates of pattern rows g (a slice of consecutive rows, or ascending indices; mesh rows r) and
    store them at cptr[g]."""
    n_inc = ptr[r + 1] - ptr[r]
    c = int(n_inc.max(initial=0))
    idx = np.arange(g.start, g.stop) if isinstance(g, slice) else g
    n_ext = np.zeros(len(r), np.int64) if extra_ptr is None else extra_ptr[idx + 1] - extra_ptr[idx]
    ne = int(n_ext.max(initial=0))
    L = c * k + ne
    if L == 0:
        return
    # one key carries the column and the candidate's slot q (low bits), so the sort is also the
    # argsort; padding (column ncol) sorts last
    bits = (L - 1).bit_length()
    dtype = np.int32 if (ncol + 1) << bits < 2**31 else np.int64
    j = np.arange(c)
    e = entries[np.minimum(ptr[r][:, None] + j, len(entries) - 1)]      # (n, c) cell entries, padded
    key = np.empty((len(r), L), dtype)
    key[:, :c * k] = np.where((j < n_inc[:, None])[:, :, None], cell_cols[e // k], ncol).reshape(len(r), -1)
    if ne:
        x = np.arange(ne)
        x_at = np.minimum(extra_ptr[g][:, None] + x, max(len(extra_cols) - 1, 0))
        key[:, c * k:] = np.where(x < n_ext[:, None], extra_cols[x_at] if len(extra_cols) else ncol, ncol)
    key <<= bits
    key |= np.arange(L, dtype=dtype)
    key.sort(axis=1)
    col = key >> bits
    valid = col < ncol
    new = valid.copy()
    new[:, 1:] &= col[:, 1:] != col[:, :-1]
    nb[g] = new.sum(axis=1)
    at = np.flatnonzero(valid)
    out = slice(cptr[g.start], cptr[g.stop]) if isinstance(g, slice) else row_spans(cptr, g)[0]
    sorted_cols[out] = col.ravel()[at]
    is_first[out] = new.ravel()[at]
    q = key.ravel()[at] & ((1 << bits) - 1)
    # a cell candidate's source is its position in `entries` times k plus its column slot
    counts = n_inc * k + n_ext
    src[out] = np.where(q < np.repeat(n_inc * k, counts), np.repeat(ptr[r] * k, counts) + q, -1)


def split_layout(pattern, lo, hi):
    """Per row counts of a point CSR split into a diagonal part (columns in [lo, hi)) and the rest.

    Returns (n_diag, n_left, rowptr_d, rowptr_o) per block row, where n_left counts the
    off-diagonal blocks left of the diagonal part (columns ascend, so the diagonal ones are one run)."""
    nb = np.diff(pattern.rowptr)
    row = np.repeat(np.arange(len(nb)), nb)
    n_diag = np.bincount(row, (pattern.col >= lo) & (pattern.col < hi), minlength=len(nb)).astype(np.int64)
    n_left = np.bincount(row, pattern.col < lo, minlength=len(nb)).astype(np.int64)
    rowptr_d = np.zeros(len(nb) + 1, np.int64)
    rowptr_o = np.zeros(len(nb) + 1, np.int64)
    np.cumsum(n_diag, out=rowptr_d[1:])
    np.cumsum(nb - n_diag, out=rowptr_o[1:])
    return n_diag, n_left, rowptr_d, rowptr_o


def point_rowptr(rowptr_blocks, n_blocks):
    """Point-row pointers (3n + 1,) of a CSR whose block row i holds n_blocks[i] 3x3 blocks, row-major."""
    p = 9 * rowptr_blocks[:-1, None] + 3 * n_blocks[:, None] * np.arange(3)
    return np.append(p.ravel(), 9 * rowptr_blocks[-1])


def block_positions(pattern, layout, p, row, lo):
    """For blocks p of rows row: where their 3x3 values start in the split value array, the stride
    between their point rows, and their first point column (local to the diagonal part there).

    The split array is the diagonal part's values followed by the off-diagonal part's."""
    n_diag, n_left, rowptr_d, rowptr_o = layout
    t = p - pattern.rowptr[row]                                       # rank of the block in its row
    left, nd = n_left[row], n_diag[row]
    diag = (t >= left) & (t < left + nd)
    base = np.where(diag, 9 * rowptr_d[row] + 3 * (t - left),
                    9 * rowptr_d[-1] + 9 * rowptr_o[row] + 3 * np.where(t < left, t, t - nd))
    stride = 3 * np.where(diag, nd, pattern.rowptr[row + 1] - pattern.rowptr[row] - nd)
    col = pattern.col[p]
    return base, stride, 3 * np.where(diag, col - lo, col)


def scatter_points(base, stride):
    """Flat positions (nb, 3, 3) of blocks in the point CSR: block row r, column s at base + r * stride + s."""
    return base[:, None, None] + stride[:, None, None] * np.arange(3)[:, None] + np.arange(3)


def row_batches(cptr, size):
    """Consecutive row ranges [(r0, r1), ...] holding about `size` candidates each."""
    cuts = np.searchsorted(cptr, np.arange(0, cptr[-1], size), side="right") - 1
    cuts = np.unique(np.concatenate([[0], cuts, [len(cptr) - 1]]))
    return list(zip(cuts[:-1].tolist(), cuts[1:].tolist()))


def equal_runs(nb, plain, offset=0):
    """Maximal runs [(a, b), ...] (plus offset) of at least MIN_RUN consecutive plain rows with equal nb."""
    return continued_runs((nb[1:] == nb[:-1]) & (plain[1:] == plain[:-1]), plain, offset)


def continued_runs(same, keep=None, offset=0):
    """Maximal runs [(a, b), ...] (plus offset) of at least MIN_RUN rows, each row after a run's first continuing
    the one before it (same: (n - 1,) bool), and, given keep (n,), only those whose first row it marks."""
    n = len(same) + 1 if keep is None else len(keep)
    if n == 0:
        return []
    start = np.flatnonzero(np.r_[True, ~same])
    end = np.append(start[1:], n)
    long = end - start >= MIN_RUN
    if keep is not None:
        long &= keep[start]
    return list(zip((start[long] + offset).tolist(), (end[long] + offset).tolist()))


def row_spans(ptr, rows):
    """Flat positions of the entries of CSR rows `rows` (row pointers ptr), row after row, and which of `rows`
    each belongs to."""
    lens = ptr[rows + 1] - ptr[rows]
    first = np.repeat(ptr[rows] - np.cumsum(lens) + lens, lens)
    return first + np.arange(lens.sum()), np.repeat(np.arange(len(rows)), lens)


def covered(runs, n, offset=0):
    """Mask (n,) of the rows (minus offset) that runs [(a, b), ...] from equal_runs cover."""
    mask = np.zeros(n, bool)
    for a, b in runs:
        mask[a - offset:b - offset] = True
    return mask
