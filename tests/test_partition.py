"""The default partition (recursive coordinate bisection of cell centroids) is balanced, geometric and deterministic."""

import numpy as np

from qsc_petsc.partition import coordinate_bisection


def box_centroids(nx, ny, nz):
    z, y, x = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    return np.column_stack([x.ravel(), y.ravel(), z.ravel()]) + 0.5


def test_two_parts_cut_the_widest_extent_in_half():
    """A 4 x 4 x 8 box shall be cut across z at mid-height into two equal slabs."""
    x = box_centroids(4, 4, 8)
    part = coordinate_bisection(x, 2)
    assert np.bincount(part).tolist() == [64, 64]
    assert x[part == 0, 2].max() < x[part == 1, 2].min()


def test_uneven_part_counts_stay_balanced():
    """Three parts of 128 cells shall get 42, 43 and 43 cells, each a connected block of the box."""
    x = box_centroids(4, 4, 8)
    part = coordinate_bisection(x, 3)
    assert sorted(np.bincount(part).tolist()) == [42, 43, 43]


def test_fewer_cells_than_parts_and_ties():
    """Two cells over three parts leave one part empty; equal centroids split by cell index, not by chance."""
    part = coordinate_bisection(np.zeros((2, 3)), 3)
    assert np.bincount(part, minlength=3).tolist() == [0, 1, 1]
    same = np.zeros((10, 3))
    assert coordinate_bisection(same, 2).tolist() == [0] * 5 + [1] * 5


def stacked_boxes():
    """A 4 x 4 x 4 box on another (z 4..8): centroids, and the cells on either side of the interface z = 4."""
    x = box_centroids(4, 4, 8)
    return x, np.abs(x[:, 2] - 4.0) < 1.0


def test_contact_surfaces_are_cut_across():
    """Two stacked boxes in contact at z = 4: the cut goes across the interface (along x, the first of the
    interface's two equal spreads), not along it at mid-height as without contact; each part gets half of the
    contact cells."""
    x, contact = stacked_boxes()
    part = coordinate_bisection(x, 2, contact)
    assert np.bincount(part).tolist() == [64, 64]
    assert x[part == 0, 0].max() <= x[part == 1, 0].min()
    assert np.bincount(part[contact]).tolist() == [16, 16]
    assert coordinate_bisection(x, 2).tolist() == coordinate_bisection(x, 2, np.zeros(len(x), bool)).tolist()


def test_contact_cuts_stop_at_the_aspect_limit():
    """Four parts cut the interface into quarters (x, then y); a column more than SPLIT_ASPECT times longer than
    the interface is wide is cut along its length instead."""
    from qsc_petsc.partition import SPLIT_ASPECT
    x, contact = stacked_boxes()
    part = coordinate_bisection(x, 4, contact)
    assert np.bincount(part[contact]).tolist() == [8, 8, 8, 8]
    for length, across in ((int(SPLIT_ASPECT) + 1, True), (int(SPLIT_ASPECT) + 4, False)):
        column = box_centroids(2, 2, length)          # extents 1, 1 and length - 1
        at = np.abs(column[:, 2] - column[:, 2].mean()) < 1.0
        part = coordinate_bisection(column, 2, at)
        axis = 0 if across else 2
        assert column[part == 0, axis].max() < column[part == 1, axis].min()


def box_cells(nx, ny, nz):
    """Hex vertex ids (x fastest) of the box_centroids cells."""
    z, y, x = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    base = ((z * (ny + 1) + y) * (nx + 1) + x).ravel()
    corners = [((c >> 2) * (ny + 1) + ((c >> 1) & 1)) * (nx + 1) + (c & 1) for c in range(8)]
    return base[:, None] + np.array(corners)


def owned_vertices(cells, part):
    """Vertices per part when each goes to the highest part among its cells, as DMPlex distributes them."""
    owner = np.full(cells.max() + 1, -1)
    np.maximum.at(owner, cells.ravel(), np.repeat(part, cells.shape[1]))
    return np.bincount(owner).tolist()


def test_cuts_balance_owned_vertices():
    """Given the cells' vertices, a 5 x 5 x 5 box (6 x 6 x 6 vertices) is cut so that each part owns the same number
    of vertices: into 2 parts between cell layers (75 and 50 cells, 108 vertices each), not mid-layer into equal
    cell counts that leave the higher part the cut's vertices (130 against 86); into 3 parts, 72 each."""
    x, cells = box_centroids(5, 5, 5), box_cells(5, 5, 5)
    assert owned_vertices(cells, coordinate_bisection(x, 2)) == [86, 130]
    part = coordinate_bisection(x, 2, cells=cells)
    assert owned_vertices(cells, part) == [108, 108]
    assert np.bincount(part).tolist() == [75, 50]
    assert x[part == 0, 2].max() < x[part == 1, 2].min()          # across z, the last of three equal extents
    assert owned_vertices(cells, coordinate_bisection(x, 3, cells=cells)) == [72, 72, 72]


def test_balanced_cuts_through_unequal_meshes():
    """Two boxes in contact, one with twice the cells per direction, cut across the interface into 2 and 3
    parts: each part owns the nearest to an equal share of the vertices (within one cell's worth), and half the
    contact cells of each body fall on either side of the first cut."""
    coarse, fine = box_centroids(4, 4, 4), box_centroids(8, 8, 8) / 2 + [0, 0, 4]
    x = np.concatenate([coarse, fine])
    cells = np.concatenate([box_cells(4, 4, 4), box_cells(8, 8, 8) + 125])
    contact = np.concatenate([coarse[:, 2] > 3, fine[:, 2] < 4.5])
    for n_parts in (2, 3):
        part = coordinate_bisection(x, n_parts, contact, cells)
        owned = owned_vertices(cells, part)
        assert max(owned) - min(owned) <= 8, owned
    part = coordinate_bisection(x, 2, contact, cells)
    assert x[part == 0, 0].max() <= x[part == 1, 0].min()


def test_cell_centroids():
    """cell_centroids sums vertex columns one at a time: the same centroids as the mean of each cell's points."""
    from qsc_petsc.partition import cell_centroids
    rng = np.random.default_rng(3)
    points = rng.random((60, 3))
    for k in (4, 8):
        cells = rng.integers(0, 60, (40, k))
        assert np.allclose(cell_centroids(points, cells), points[cells].mean(axis=1), rtol=0, atol=1e-15)
