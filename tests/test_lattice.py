"""Row templates of generated hex boxes (lattice.py): pure NumPy checks against the element stiffness."""

import numpy as np

from qsc_petsc import elasticity, lattice
from qsc_petsc.meshgen import HEX_CORNERS

KE = elasticity.stiffness("hex", (HEX_CORNERS * [0.5, 0.3, 0.2])[None], *elasticity.lame(1000.0, 0.3))[0]


def test_every_template_row_annihilates_translations():
    """Each of the 27 row templates shall sum to zero over its blocks (K times a rigid translation is 0)."""
    T, _ = lattice.templates(KE)
    assert np.abs(T.sum(axis=2)).max() <= 1e-12 * np.abs(KE).max()


def test_template_patterns_count_the_shared_cells():
    """An interior vertex shall couple to all 27 neighbours, a corner to the 8 of its one cell, an edge
    vertex to 12 and a face vertex to 18; the interior diagonal block shall be 8 cells' diagonal blocks."""
    T, P = lattice.templates(KE)
    counts = {c: int(P[c].sum()) for c in (0, 1, 4, 13)}        # corner, edge, face, interior
    assert counts == {0: 8, 1: 12, 4: 18, 13: 27}
    K = KE.reshape(8, 3, 8, 3)
    assert np.allclose(T[13, :, 13, :], sum(K[a, :, a, :] for a in range(8)))


def test_vertex_classes_of_a_small_box():
    """On a 2 x 1 x 1 box the classes shall say low end, inside or high end per axis."""
    box = lattice.BoxLattice(0, (2, 1, 1), KE)
    ids = np.arange(box.n_vertices)              # x fastest: (0,0,0) (1,0,0) (2,0,0) (0,1,0) ...
    cls = lattice.vertex_classes(box, ids)
    assert cls[:3].tolist() == [0, 1, 2]                         # along x at y = z = 0
    assert cls[3:6].tolist() == [6, 7, 8]                        # y at its high end
    assert cls[-1] == 2 + 6 + 18                                 # (2, 1, 1): the far corner
