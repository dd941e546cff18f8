"""The near-nullspace handed to GAMG: rigid-body modes per body, without the components rigid dies hold.

Runs serially in the suite and again under mpirun -n 2 and -n 3; assertions use all-reduced values."""

import numpy as np
from conftest import CONFIGS
from mpi4py import MPI

from qsc_petsc import assembly
from qsc_petsc.mesh import distribute_mesh
from qsc_petsc.scene import load_scene

# lower.zmin under a sticking die, upper.zmax under a frictionless one with a tilted normal
SETS = ["die.1.condition=frictionless", "die.1.normal=[0.0, 0.6, -0.8]"]


def owned_blocks(mesh, vec, surface=None):
    """(n, 3) owned dof blocks of a mode, on a surface's owned vertices or on all owned vertices."""
    r0 = vec.getOwnershipRange()[0]
    v = np.flatnonzero(mesh.owned) if surface is None else mesh.surface_vertices(surface)
    v = v[mesh.owned[v]]
    return vec.getArray()[(3 * mesh.gvert[v] - r0)[:, None] + np.arange(3)]


def test_die_held_components_leave_the_modes(comm):
    """Rigid-body modes shall vanish on a sticking die's vertices, have no component along a frictionless
    die's normal on its vertices, still span six independent motions per body, and stay orthonormal."""
    scene = load_scene(CONFIGS / "two_cubes_dies.toml", SETS)
    mesh = distribute_mesh(scene, comm)
    K = assembly.stiffness_matrix(mesh, *assembly.cell_materials(mesh, scene))
    u = K.createVecRight()
    n_top = np.array(scene.die[1].normal)
    held = [("lower.zmin", None), ("upper.zmax", n_top)]
    modes = assembly.rigid_body_modes(mesh, u, held).getVecs()
    assert len(modes) == 12
    sticking = max(np.abs(owned_blocks(mesh, m, "lower.zmin")).max(initial=0.0) for m in modes)
    normal = max(np.abs(owned_blocks(mesh, m, "upper.zmax") @ n_top).max(initial=0.0) for m in modes)
    tangential = max(np.abs(owned_blocks(mesh, m, "upper.zmax")).max(initial=0.0) for m in modes)
    gram = np.array([[a.dot(b) for b in modes] for a in modes])
    assert comm.allreduce(sticking, op=MPI.MAX) == 0.0
    assert comm.allreduce(normal, op=MPI.MAX) < 1e-14
    assert comm.allreduce(tangential, op=MPI.MAX) > 1e-3          # the die's tangent plane keeps its motions
    assert np.allclose(gram, np.eye(12), atol=1e-12)
    free = assembly.rigid_body_modes(mesh, u).getVecs()         # nothing held: the plain modes, nonzero there
    assert comm.allreduce(max(np.abs(owned_blocks(mesh, m, "lower.zmin")).max(initial=0.0) for m in free),
                          op=MPI.MAX) > 1e-3
    K.destroy()
