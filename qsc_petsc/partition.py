"""Recursive coordinate bisection of cells: the default mesh partition, computed in NumPy where the mesh is built.

Each cut splits a set of cells (in proportion to the ranks on either side) across the widest
extent of their centroids. For generated boxes this gives slabs and blocks; for any mesh it is
deterministic and needs no cell graph (PETSc's graph partitioners build one first).

With contact pairs, a cut goes across the contact surfaces rather than along them while the part
is not much longer the other way (SPLIT_ASPECT): each rank then searches, builds rows for and
factors the band of its share of the interface, instead of one rank doing all of it while the
others wait (two cubes stacked, 2 ranks, alternated runs: search and rows 0.75-1.17 -> 0.57-0.64 s
at 212k dofs, the run 42.8 -> 36.7 s at 808k; docs/performance.md, session 16).

Given the cells' vertices, a cut balances the vertices (dofs) each side will own rather than
cells: DMPlex gives a vertex on a cut to the higher rank, so equal cells left the higher side a
whole plane of vertices more (98k-dof box, 2 ranks: 1.032 max / mean owned dofs; two cubes of
17^3 and 25^3 cells, cut through both: 1.043). Rows are what the box stencils assemble and the
solver works on.
"""

import numpy as np

SPLIT_ASPECT = 4.0       # a cut across the contact surfaces while the part is at most this much longer the other way


def cell_centroids(points, cells):
    """Centroids (m, 3) of cells (m, k) of vertex ids into points (n, 3): summed one vertex column at a time, no
    (m, k, 3) temporary (985k-dof box: 31 against 68 ms for points[cells].mean(axis=1), the same sums)."""
    total = points[cells[:, 0]].copy()
    for j in range(1, cells.shape[1]):
        total += points[cells[:, j]]
    return total / cells.shape[1]


def coordinate_bisection(centroids, n_parts, contact=None, cells=None):
    """Part (0 .. n_parts - 1) of every cell, from cell centroids (m, 3).

    contact: (m,) bool, the cells with a face on a contact surface (None: none). cells: None, then part p gets
    about m / n_parts cells; or (m, k) vertex ids of every cell, then each cut balances the vertices its sides
    will own, a vertex shared by several parts going to the highest."""
    m = len(centroids)
    part = np.zeros(m, np.int64)
    contact = np.zeros(m, bool) if contact is None else np.asarray(contact, bool)
    owners = None if cells is None else _Owners(np.asarray(cells))
    _bisect(np.asarray(centroids, float), np.arange(m), 0, n_parts, part, contact, owners)
    return part


def cut_axis(pts, on_contact):
    """The axis a set of cells (centroids pts) is cut across: the one along which its contact cells spread
    most, if the cells' extent along it is at least 1 / SPLIT_ASPECT of their largest; else the widest, the last of
    equal ones: generated boxes number x fastest, so a cube cut across z leaves each part whole lines of vertices
    (the box stencils' runs of template rows: 98k-dof cube, 2 ranks, 480 runs of 30 rows per rank instead of 1024 of
    14, assembly 0.053-0.054 -> 0.051-0.053 s)."""
    extent = pts.max(axis=0) - pts.min(axis=0)
    axis = 2 - int(np.argmax(extent[::-1]))
    touching = pts[on_contact]
    if len(touching) > 1:
        spread = touching.max(axis=0) - touching.min(axis=0)
        across = int(np.argmax(spread))
        if spread[across] > 0 and SPLIT_ASPECT * extent[across] >= extent[axis]:
            axis = across
    return axis


def _bisect(x, cells, first, n_parts, part, contact, owners):
    if n_parts == 1 or len(cells) == 0:
        part[cells] = first
        return
    left = n_parts // 2
    pts = x[cells]
    axis = cut_axis(pts, contact[cells])
    k = (len(cells) * left) // n_parts
    # ties at the cut go by cell index, so the split does not depend on the sort's whims
    order = cells[np.lexsort((cells, pts[:, axis]))]
    if owners is not None and len(cells) >= n_parts:
        k = owners.balanced_cut(order, first + n_parts, left / n_parts, k, (left, len(cells) - (n_parts - left)))
        owners.first[order[k:]] = first + left
    _bisect(x, order[:k], first, left, part, contact, owners)
    _bisect(x, order[k:], first + left, n_parts - left, part, contact, owners)


class _Owners:
    """Which vertices a set of cells' parts will own, for the cuts of _bisect."""

    def __init__(self, cells):
        self.cells = cells
        self.n = int(cells.max()) + 1 if cells.size else 0
        self.first = np.zeros(len(cells), np.int64)    # the first part of the set each cell is in, as cut so far

    def _touched(self, cells):
        hit = np.zeros(self.n, bool)
        hit[cells.ravel()] = True
        return hit

    def balanced_cut(self, order, end, share, k, bounds):
        """The number of cells in order (a set's cells along the cut axis, whose parts end before `end`) that go to
        the lower side so that it owns the nearest to `share` of the set's vertices; k: the first guess, bounds:
        the least and most cells it may take. Vertices of cells in sets of higher parts are theirs; the others
        belong to the highest part among their cells, so the lower side owns those whose cells are all in it: a
        count that grows with k, found by the secant method within a shrinking bracket."""
        cells = self.cells[order]            # in cut order: the upper side's cells are a view
        mine = self._touched(cells) & ~self._touched(self.cells[self.first >= end])
        target = share * np.count_nonzero(mine)

        def owned(k):
            return np.count_nonzero(mine & ~self._touched(cells[k:]))

        lo, hi = bounds
        k = min(max(k, lo), hi)
        f = owned(k)
        if f == target:
            return k
        # bracket the target from the first guess, stepping by its deficit at the set's vertices per cell
        step = max(1, int(abs(target - f) * len(order) / max(target / share, 1)))
        while True:
            k2 = min(max(k + step if f < target else k - step, lo), hi)
            f2 = owned(k2)
            if (f2 - target) * (f - target) <= 0 or k2 in (lo, hi):
                break
            k, f, step = k2, f2, 2 * step
        (lo, f_lo), (hi, f_hi) = sorted([(k, f), (k2, f2)])
        if f_lo >= target or f_hi <= target:            # the bound itself is as near as it gets
            return lo if f_lo >= target else hi
        slow = False
        while hi - lo > 1:                # f_lo < target < f_hi: regula falsi, a halving after a slow step
            width = hi - lo
            k = (lo + hi) // 2 if slow else lo + round((target - f_lo) * width / (f_hi - f_lo))
            k = min(max(k, lo + 1), hi - 1)
            f = owned(k)
            if f == target:
                return k
            if f < target:
                lo, f_lo = k, f
            else:
                hi, f_hi = k, f
            slow = 2 * (hi - lo) > width
        return lo if target - f_lo <= f_hi - target else hi
