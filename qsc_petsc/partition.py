"""Recursive coordinate bisection of cells: the default mesh partition, computed in NumPy where the mesh is built.

Each cut splits a set of cells (in proportion to the ranks on either side) across the widest
extent of their centroids. For generated boxes this gives slabs and blocks; for any mesh it is
deterministic and needs no cell graph (PETSc's graph partitioners build one first).
"""

import numpy as np


def coordinate_bisection(centroids, n_parts):
    """Part (0 .. n_parts - 1) of every cell, from cell centroids (m, 3); part p gets about m / n_parts cells."""
    part = np.zeros(len(centroids), np.int64)
    _bisect(np.asarray(centroids, float), np.arange(len(centroids)), 0, n_parts, part)
    return part


def _bisect(x, cells, first, n_parts, part):
    if n_parts == 1 or len(cells) == 0:
        part[cells] = first
        return
    left = n_parts // 2
    pts = x[cells]
    axis = int(np.argmax(pts.max(axis=0) - pts.min(axis=0)))
    k = (len(cells) * left) // n_parts
    # ties at the cut go by cell index, so the split does not depend on the sort's whims
    order = np.lexsort((cells, pts[:, axis]))
    _bisect(x, cells[order[:k]], first, left, part)
    _bisect(x, cells[order[k:]], first + left, n_parts - left, part)
