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
