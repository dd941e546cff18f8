"""Vertex-block patterns and block sums (sparsity.py) against plain set and dense computations."""

import numpy as np
import pytest

from qsc_petsc import sparsity


def random_cells(seed, m=60, n_rows=40, k=4):
    """Cells with k distinct vertices each, drawn at random (ragged incidence, unsorted numbering)."""
    rng = np.random.default_rng(seed)
    return np.array([rng.choice(n_rows, k, replace=False) for _ in range(m)]), rng


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_block_pattern_matches_sets(seed):
    """Every row shall hold exactly the columns its cells and extras give, sorted, and every candidate
    shall name the element block (cell, a, b) that sums into its block."""
    cells, rng = random_cells(seed)
    n_rows, k = 45, cells.shape[1]                      # rows 40..44 touch no cell: empty unless extras
    ptr, entries = sparsity.incidence(cells, n_rows)
    rows = np.sort(rng.choice(n_rows, 30, replace=False))
    n_ext = rng.integers(0, 3, len(rows))
    extra_ptr = np.concatenate([[0], np.cumsum(n_ext)])
    extra_cols = rng.integers(0, 60, extra_ptr[-1])
    pat = sparsity.block_pattern(rows, cells, ptr, entries, extra_ptr, extra_cols)
    for i, r in enumerate(rows):
        c, _ = np.nonzero(cells == r)
        expect = set(cells[c].ravel()) | set(extra_cols[extra_ptr[i]:extra_ptr[i + 1]])
        assert pat.col[pat.rowptr[i]:pat.rowptr[i + 1]].tolist() == sorted(expect)
        src = pat.src[pat.cptr[i]:pat.cptr[i + 1]]
        assert (src < 0).sum() == n_ext[i]
        e = entries[src[src >= 0] // k]
        assert (cells.ravel()[e] == r).all()            # the candidate's cell entry is this row's vertex
    # each candidate's column is the column of the block it sums into
    block = np.searchsorted(pat.first, np.arange(len(pat.src)), side="right") - 1
    ok = pat.src >= 0
    e, b = entries[pat.src[ok] // k], pat.src[ok] % k
    assert (cells[e // k, b] == pat.col[block[ok]]).all()



def test_block_pattern_sorts_a_wide_row_apart(monkeypatch):
    """One row with 2000 extra columns among rows with a few: the pattern shall be right, and the narrow rows shall
    be sorted among rows of their own width, not padded to the wide one (a coarse face's node against a fine
    surface widened every row near it: 3.3 s and 1.4 GB for a 10k-dof tetrahedral scene; hunt27_2)."""
    cells, rng = random_cells(3, m=200, n_rows=120)
    k = cells.shape[1]
    ptr, entries = sparsity.incidence(cells, 120)
    rows = np.arange(120)
    n_ext = rng.integers(0, 3, len(rows))
    n_ext[50] = 2000
    extra_ptr = np.concatenate([[0], np.cumsum(n_ext)])
    extra_cols = rng.integers(0, 5000, extra_ptr[-1])
    padded = []
    original = sparsity._sort_rows

    def spy(g, r, *args):
        ep = args[5]
        idx = np.arange(g.start, g.stop) if isinstance(g, slice) else g
        widths = (ptr[r + 1] - ptr[r]) * k + ep[idx + 1] - ep[idx]
        padded.append(len(r) * widths.max())
        return original(g, r, *args)

    monkeypatch.setattr(sparsity, "_sort_rows", spy)
    pat = sparsity.block_pattern(rows, cells, ptr, entries, extra_ptr, extra_cols)
    for i in (0, 50, 119):
        c, _ = np.nonzero(cells == rows[i])
        expect = set(cells[c].ravel()) | set(extra_cols[extra_ptr[i]:extra_ptr[i + 1]])
        assert pat.col[pat.rowptr[i]:pat.rowptr[i + 1]].tolist() == sorted(expect)
    assert sum(padded) <= 2 * pat.cptr[-1]          # padded to 119 x 2000 before

def test_point_layout_matches_dense():
    """Blocks placed by block_positions shall give the dense matrix, split at the diagonal columns."""
    cells, rng = random_cells(3, m=30, n_rows=20)
    ptr, entries = sparsity.incidence(cells, 20)
    rows = np.arange(20)
    pat = sparsity.block_pattern(rows, cells, ptr, entries)
    blocks = rng.standard_normal((len(pat.col), 3, 3))
    lo, hi = 5, 12
    layout = sparsity.split_layout(pat, lo, hi)
    n_d = 9 * layout[2][-1]
    vals, cols = np.zeros(9 * len(pat.col)), np.zeros(9 * len(pat.col), np.int64)
    row = np.repeat(rows, np.diff(pat.rowptr))
    base, stride, col0 = sparsity.block_positions(pat, layout, np.arange(len(pat.col)), row, lo)
    pos = sparsity.scatter_points(base, stride)
    vals[pos] = blocks
    cols[pos] = (col0[:, None] + np.arange(3))[:, None, :]
    dense = np.zeros((60, 60))
    for p, (i, j) in enumerate(zip(row, pat.col)):
        dense[3 * i:3 * i + 3, 3 * j:3 * j + 3] = blocks[p]
    di = sparsity.point_rowptr(layout[2], layout[0])
    oi = sparsity.point_rowptr(layout[3], np.diff(pat.rowptr) - layout[0])
    got = np.zeros_like(dense)
    for r in range(60):
        d = slice(di[r], di[r + 1])
        o = slice(n_d + oi[r], n_d + oi[r + 1])
        assert np.all(np.diff(cols[d]) > 0) and np.all(np.diff(cols[o]) > 0)
        got[r, cols[d] + 3 * lo] = vals[d]                  # diagonal part: local columns
        got[r, cols[o]] = vals[o]
        assert ((cols[o] < 3 * lo) | (cols[o] >= 3 * hi)).all()
    assert np.array_equal(got, dense)


def test_equal_runs():
    """Runs of at least MIN_RUN consecutive plain rows with equal block counts, offset to batch rows."""
    nb = np.array([8, 27, 27, 27, 27, 27, 18, 18, 18, 18])
    plain = np.array([True] * 9 + [False])
    assert sparsity.equal_runs(nb, plain, 100) == [(101, 106)]
    assert sparsity.covered(sparsity.equal_runs(nb, plain), len(nb)).tolist() == [False] + [True] * 5 + [False] * 4
    assert sparsity.covered(sparsity.equal_runs(nb, plain, 100), len(nb), 100).tolist() == \
        [False] + [True] * 5 + [False] * 4
