"""A tilted patch test (issue 7): the contact patch test rotated off the axes, rollers made of frictionless rigid
dies, exact (segment) integration: the uniaxial stress state -p along the rotated axis, on 1, 2 and 3 ranks."""

import numpy as np
import pytest
from conftest import CONFIGS
from mpi4py import MPI

from qsc_petsc.meshgen import rotation_matrix

ROTATION = [12.0, -20.0, 31.0]        # degrees: no face is axis-aligned


def tilted_scene(lower, upper, formulation, slave, master):
    from qsc_petsc.scene import load_scene, parse_scene
    data = load_scene(CONFIGS / "patch_test.toml", [f"bodies.0.mesh.cells=[{lower},{lower},2]",
                                                    f"bodies.1.mesh.cells=[{upper},{upper},2]"]).to_dict()
    R = rotation_matrix(ROTATION)
    for body in data["bodies"]:
        body["mesh"]["rotation"] = ROTATION
    # the axis-aligned rollers become frictionless dies on the rotated planes (normal toward the body)
    data["boundary"] = [b for b in data["boundary"] if b["type"] == "pressure"]
    dies = [("lower_bottom", "lower.zmin", 2), ("lower_x", "lower.xmin", 0), ("lower_y", "lower.ymin", 1),
            ("upper_x", "upper.xmin", 0), ("upper_y", "upper.ymin", 1)]
    data["die"] = [{"name": name, "point": [0.0, 0.0, 0.0], "normal": R[:, axis].tolist(), "surfaces": [surface],
                    "condition": "frictionless", "penalty": 1e6} for name, surface, axis in dies]
    data["contact"][0].update({"formulation": formulation, "integration": "segment", "slave": slave,
                               "master": master})
    data["output"] = {"xdmf": False}
    return parse_scene(data, CONFIGS, "tilted_patch")


@pytest.mark.parametrize("formulation", ["master_slave", "two_pass", "quasi_symmetric"])
@pytest.mark.parametrize("slave, master", [("upper.zmin", "lower.zmax"), ("lower.zmax", "upper.zmin")])
def test_tilted_patch_test_with_segment_integration(comm, mpi_tmp, formulation, slave, master):
    """Non-nested (3, 7) meshes, rotated: R^T sigma R = diag(0, 0, -p) in every cell to 1e-8 p."""
    from qsc_petsc.run import Run
    run = Run(tilted_scene(3, 7, formulation, slave, master), comm, mpi_tmp, log=lambda *a: None)
    summary = run.execute()
    assert summary["status"] == "ok"
    _, cell, _ = run.fields(run.u)
    s = cell["stress"]                       # Voigt xx yy zz yz xz xy
    S = np.empty((len(s), 3, 3))
    S[:, 0, 0], S[:, 1, 1], S[:, 2, 2] = s[:, 0], s[:, 1], s[:, 2]
    S[:, 1, 2] = S[:, 2, 1] = s[:, 3]
    S[:, 0, 2] = S[:, 2, 0] = s[:, 4]
    S[:, 0, 1] = S[:, 1, 0] = s[:, 5]
    R = rotation_matrix(ROTATION)
    local = np.einsum("ia,mij,jb->mab", R, S, R)     # stress in the box frame
    expected = np.diag([0.0, 0.0, -1.0])
    err = comm.allreduce(float(np.abs(local - expected).max(initial=0.0)), op=MPI.MAX)
    run.destroy()
    assert err < 1e-8
