"""Stiffness rows of generated hex boxes as stencils: every vertex row is one of 27 templates. Pure NumPy.

In a box of congruent hexes (meshgen.box_mesh) with one material, a vertex's stiffness row
depends only on which of its 8 surrounding cells exist, that is on whether it sits at the low
end, inside or at the high end of each axis: 27 classes. The row of class c holds the 3x3
block T[c, d] at the neighbour offset d in {-1, 0, 1}^3 wherever P[c, d] (the two vertices share
a cell). Assembly then reads templates instead of summing element blocks (assembly.py).
"""

import functools
from dataclasses import dataclass

import numpy as np

from . import elasticity
from .meshgen import HEX_CORNERS, rotation_matrix

# the 27 neighbour offsets d, x fastest: index (dx + 1) + 3 (dy + 1) + 9 (dz + 1)
OFFSETS = np.array([(x, y, z) for z in (-1, 0, 1) for y in (-1, 0, 1) for x in (-1, 0, 1)])


@dataclass
class BoxLattice:
    """One generated hex box: its vertices' ids in the merged mesh and its cells' stiffness."""
    offset: int                # id of the box's vertex (0, 0, 0) in the merged mesh
    cells: tuple               # (nx, ny, nz)
    Ke: np.ndarray             # (24, 24) stiffness of every cell [N/m]

    @property
    def n_vertices(self):
        nx, ny, nz = self.cells
        return (nx + 1) * (ny + 1) * (nz + 1)

    @property
    def stride(self):
        """Id step of one vertex along x, y, z (meshgen.box_mesh numbers vertices x fastest)."""
        nx, ny, _ = self.cells
        return np.array([1, nx + 1, (nx + 1) * (ny + 1)])


def box_lattices(scene):
    """The BoxLattice of every body, or None unless every body is a generated hex box."""
    out, offset = [], 0
    for body in scene.bodies:
        spec = body.mesh
        if spec.type != "box" or spec.element != "hex":
            return None
        n = np.asarray(spec.cells, int)
        # cell (0, 0, 0) as box_mesh makes it: every cell of the box is its translate
        xe = np.asarray(spec.origin, float) + HEX_CORNERS * (np.asarray(spec.size, float) / n)
        if np.any(np.asarray(spec.rotation, float) != 0.0):
            xe = xe @ rotation_matrix(spec.rotation).T
        lmbda, mu = elasticity.lame(body.material.youngs_modulus, body.material.poissons_ratio)
        kappa = elasticity.mean_dilatation_bulk(body.material.youngs_modulus, body.material.poissons_ratio,
                                                body.material.volumetric)
        Ke = elasticity.stiffness("hex", xe[None], lmbda, mu, kappa=kappa)[0]
        out.append(BoxLattice(offset, tuple(int(v) for v in n), Ke))
        offset += out[-1].n_vertices
    return out


@functools.cache
def _template_terms():
    """Which element block sums into which template block: (class c, offset k, node a, node b) of every term
    T[c, :, k, :] += K[a, :, b, :] (see templates), by class, then cell (lower corner - vertex, each axis -1
    before 0), then offset. Class c's cells: per axis, 0 above the vertex at the low end, -1 below it at the
    high end, both inside; node a is the vertex in the cell, node b the neighbour at offset k."""
    c, o, k = (g.ravel() for g in np.meshgrid(np.arange(27), np.arange(8), np.arange(27), indexing="ij"))
    cls = np.stack([c % 3, c // 3 % 3, c // 9], axis=1)
    cell = np.stack([o // 4, o // 2 % 2, o % 2], axis=1) - 1           # x slowest: the order of nested loops
    corner = OFFSETS[k] - cell                                           # the neighbour's corner in the cell
    keep = np.where(cell < 0, cls >= 1, cls <= 1).all(axis=1) & ((corner >= 0) & (corner <= 1)).all(axis=1)
    node = np.empty((2, 2, 2), dtype=np.int64)                          # hex node (VTK order) at a corner
    node[tuple(HEX_CORNERS.T)] = np.arange(8)
    a, b = node[tuple((-cell[keep]).T)], node[tuple(corner[keep].T)]
    return c[keep], k[keep], a, b


def templates(Ke):
    """(T, P) of one box: T (27 classes, 3, 27 offsets, 3) summed blocks laid out as point rows
    (T[c, i, d, j] = K[3 v + i, 3 (v + d) + j]), P (27, 27) where the block exists.

    Class c = cx + 3 cy + 9 cz with, per axis, 0 at the low end (only the cell above exists),
    1 inside (both), 2 at the high end (only the cell below)."""
    c, k, a, b = _template_terms()
    T = np.zeros((27, 27, 3, 3))
    np.add.at(T, (c, k), Ke.reshape(8, 3, 8, 3)[a, :, b, :])       # term by term, in their order
    P = np.zeros((27, 27), bool)
    P[c, k] = True
    return np.ascontiguousarray(T.transpose(0, 2, 1, 3)), P


def vertex_classes(lattice, ids):
    """Template class (0-26, see templates) of vertices ids (local to the box: 0 <= ids < n_vertices)."""
    nx, ny, _ = lattice.cells
    ijk = np.stack([ids % (nx + 1), ids // (nx + 1) % (ny + 1), ids // ((nx + 1) * (ny + 1))], axis=1)
    ends = np.array(lattice.cells)
    cls = np.where(ijk == 0, 0, np.where(ijk == ends, 2, 1))
    return cls @ np.array([1, 3, 9])
