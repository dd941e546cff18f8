"""`qsc check`: validate a scene, build and distribute its mesh, check that every body is held, and report what a run
would model."""

import numpy as np
from mpi4py import MPI

from .mesh import check_cells, distribute_mesh


def check(scene, comm):
    """Collective; returns the report text (meaningful on rank 0)."""
    from . import options
    from .preconditioner import check_multigrid_alpha
    from .solver import check_solver_options
    inserted = options.insert_options(scene.petsc)      # as the run would: the scene's, then the command line's
    try:
        options.check_options()
        check_solver_options(comm, scene.solver.contact_preconditioner if scene.contact else None)
        check_multigrid_alpha(scene)
    finally:
        options.remove_options(inserted)
    mesh = distribute_mesh(scene, comm)
    check_cells(mesh, scene)
    cells = comm.gather(len(mesh.cells), root=0)
    owned = comm.gather(int(mesh.owned.sum()), root=0)
    ghosts = comm.gather(int((~mesh.owned).sum()), root=0)
    surfaces = {}
    for name in mesh.surface_names:
        c, _ = mesh.surface_faces(name)
        surfaces[name] = comm.allreduce(len(c), op=MPI.SUM)
    bodies = [comm.allreduce(int(np.sum(mesh.cell_body == b)), op=MPI.SUM) for b in range(len(mesh.body_names))]
    from .assembly import dirichlet_dofs, surface_load
    from .contact.model import contact_plan
    from .restraint import Restraint, describe
    from .solver import free_motion_error
    template = mesh.dof_vector()
    # the pressure fields as the run evaluates them: check said "valid" for fields the run refused (hunt34_3)
    surface_load(mesh, scene, template).destroy()
    fixed = dirichlet_dofs(mesh, scene)
    restraint = Restraint(mesh, fixed[0], template)

    def held(terms):
        # the run's check before its first solve: every body held by the boundaries and the rows within reach
        free = describe(restraint.free(terms, False))
        if free:
            raise free_motion_error(1, free)
    try:
        plan = contact_plan(mesh, scene, held, fixed)
    finally:
        restraint.destroy()
        template.destroy()
    mesh.dm.destroy()
    if comm.rank != 0:
        return ""
    lines = [f"scene {scene.name}: valid",
             f"mesh: {mesh.n_cells} {mesh.cell_type} cells, {mesh.n_vertices} vertices, {3 * mesh.n_vertices} dofs",
             "bodies: " + ", ".join(f"{n} ({c} cells)" for n, c in zip(mesh.body_names, bodies)),
             "surfaces: " + ", ".join(f"{n} ({k} faces)" for n, k in surfaces.items()),
             f"partition over {comm.size} rank(s)" + (f" ({mesh.partitioner}):" if comm.size > 1 else ":")]
    for r in range(comm.size):
        lines.append(f"  rank {r}: {cells[r]} cells, {3 * owned[r]} owned dofs, {ghosts[r]} ghost vertices")
    lines.append(f"  balance (max/mean owned dofs): {max(owned) / max(np.mean(owned), 1):.3f}")
    lines.append(f"load steps: {scene.load.steps}; boundary conditions: {len(scene.boundary)}")
    from .assembly import locking_warnings
    lines.extend(f"warning: {line}" for line in locking_warnings(scene, mesh.cell_type))
    lines.extend(plan)
    return "\n".join(lines)
