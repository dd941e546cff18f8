"""Recursive coordinate bisection of cells: the default mesh partition, computed in NumPy where the mesh is built.

Each cut splits a set of cells (in proportion to the ranks on either side) across the widest
extent of their centroids. For generated boxes this gives slabs and blocks; for any mesh it is
deterministic and needs no cell graph (PETSc's graph partitioners build one first).

With contact pairs, a cut goes across the contact surfaces rather than along them while the part
is not much longer the other way (SPLIT_ASPECT): each rank then searches, builds rows for and
factors the band of its share of the interface, instead of one rank doing all of it while the
others wait (two cubes stacked, 2 ranks, alternated runs: search and rows 0.75-1.17 -> 0.57-0.64 s
at 212k dofs, the run 42.8 -> 36.7 s at 808k; docs/performance.md, session 16). A vertex on a cut
goes to the higher rank, so a cut through both bodies balances owned dofs less well (1.008 -> 1.043
there).
"""

import numpy as np

SPLIT_ASPECT = 4.0       # a cut across the contact surfaces while the part is at most this much longer the other way


def coordinate_bisection(centroids, n_parts, contact=None):
    """Part (0 .. n_parts - 1) of every cell, from cell centroids (m, 3); part p gets about m / n_parts cells.

    contact: (m,) bool, the cells with a face on a contact surface (None: none)."""
    part = np.zeros(len(centroids), np.int64)
    contact = np.zeros(len(centroids), bool) if contact is None else np.asarray(contact, bool)
    _bisect(np.asarray(centroids, float), np.arange(len(centroids)), 0, n_parts, part, contact)
    return part


def cut_axis(pts, on_contact):
    """The axis a set of cells (centroids pts) is cut across: the one along which its contact cells spread
    most, if the cells' extent along it is at least 1 / SPLIT_ASPECT of their largest; else the widest."""
    extent = pts.max(axis=0) - pts.min(axis=0)
    axis = int(np.argmax(extent))
    touching = pts[on_contact]
    if len(touching) > 1:
        spread = touching.max(axis=0) - touching.min(axis=0)
        across = int(np.argmax(spread))
        if spread[across] > 0 and SPLIT_ASPECT * extent[across] >= extent[axis]:
            axis = across
    return axis


def _bisect(x, cells, first, n_parts, part, contact):
    if n_parts == 1 or len(cells) == 0:
        part[cells] = first
        return
    left = n_parts // 2
    pts = x[cells]
    axis = cut_axis(pts, contact[cells])
    k = (len(cells) * left) // n_parts
    # ties at the cut go by cell index, so the split does not depend on the sort's whims
    order = np.lexsort((cells, pts[:, axis]))
    _bisect(x, cells[order[:k]], first, left, part, contact)
    _bisect(x, cells[order[k:]], first + left, n_parts - left, part, contact)
