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
    assert x[part == 0, 0].max() < x[part == 1, 0].min()
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
