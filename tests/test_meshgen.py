"""Tests of body mesh generation and reading: box topology, named faces, conformity, meshio round trips."""

import meshio
import numpy as np
import pytest

from qsc_petsc import fem
from qsc_petsc.errors import MeshError
from qsc_petsc.meshgen import BOX_SURFACES, boundary_faces, box_mesh, cell_pieces, read_mesh_file

ORIGIN, SIZE, CELLS = (1.0, -2.0, 0.5), (2.0, 1.0, 3.0), (3, 2, 4)
OUTWARD = dict(zip(BOX_SURFACES, np.vstack([-np.eye(3), np.eye(3)])[[0, 3, 1, 4, 2, 5]]))


def cell_volumes(mesh):
    """Volumes (m,) by 2x2x2 Gauss on hexes, exactly on tets."""
    if mesh.cell_type == "tet":
        x = mesh.points[mesh.cells]
        return np.linalg.det(x[:, 1:] - x[:, :1]) / 6.0
    xi, w = fem.gauss_hex(2)
    _, dN = fem.shape_hex(xi)
    return np.linalg.det(np.einsum("mai,qak->mqik", mesh.points[mesh.cells], dN)) @ w


def face_coords(mesh, rows):
    return mesh.points[fem.cell_faces(mesh.cell_type, mesh.cells[rows[:, 0]], rows[:, 1])]


def node_sets(mesh, rows):
    """Faces as a set of sorted point-coordinate tuples, independent of numbering."""
    return {tuple(sorted(map(tuple, np.round(f, 12)))) for f in face_coords(mesh, rows)}


@pytest.mark.parametrize("element, per_hex", [("hex", 1), ("tet", 6)])
def test_box_counts_and_volume(element, per_hex):
    mesh = box_mesh(ORIGIN, SIZE, CELLS, element)
    nx, ny, nz = CELLS
    assert mesh.cell_type == element
    assert mesh.points.shape == ((nx + 1) * (ny + 1) * (nz + 1), 3)
    assert mesh.cells.shape == (per_hex * nx * ny * nz, fem.CELL_NODES[element])
    assert mesh.cells.dtype == np.int64 and all(s.dtype == np.int64 for s in mesh.surfaces.values())
    assert sorted(mesh.surfaces) == sorted(BOX_SURFACES)
    quads = {"xmin": ny * nz, "ymin": nx * nz, "zmin": nx * ny}
    for name, rows in mesh.surfaces.items():
        assert len(rows) == quads[name[0] + "min"] * (1 if element == "hex" else 2)
    assert np.allclose(mesh.points.min(axis=0), ORIGIN)
    assert np.allclose(mesh.points.max(axis=0), np.add(ORIGIN, SIZE))
    vol = cell_volumes(mesh)
    assert (vol > 0).all()
    assert vol.sum() == pytest.approx(np.prod(SIZE), rel=1e-12)


@pytest.mark.parametrize("element", ["hex", "tet"])
def test_named_faces_point_outward_and_lie_on_their_side(element):
    mesh = box_mesh(ORIGIN, SIZE, CELLS, element)
    face_type = fem.FACE_TYPE[element]
    for name, rows in mesh.surfaces.items():
        xf = face_coords(mesh, rows)
        n, _ = fem.face_normals(face_type, xf, fem.CENTROID[face_type][None])
        assert np.allclose(n[:, 0], OUTWARD[name], atol=1e-12), name
        axis = int(np.flatnonzero(OUTWARD[name])[0])
        plane = ORIGIN[axis] + (SIZE[axis] if name.endswith("max") else 0.0)
        assert np.allclose(xf[..., axis], plane), name


@pytest.mark.parametrize("element", ["hex", "tet"])
def test_box_is_conforming(element):
    """Only box-boundary faces belong to one cell: the tet split matches across neighbouring hexes."""
    mesh = box_mesh(ORIGIN, SIZE, CELLS, element)
    b = boundary_faces(element, mesh.cells)
    named = np.concatenate(list(mesh.surfaces.values()))
    assert len(b) == len(named)
    assert set(map(tuple, b)) == set(map(tuple, named))


def test_box_rejects_bad_arguments():
    with pytest.raises(MeshError, match="cells"):
        box_mesh(ORIGIN, SIZE, (2, 0, 1))
    with pytest.raises(MeshError, match="element"):
        box_mesh(ORIGIN, SIZE, CELLS, "wedge")


def _write_tet_mesh(path, file_format, interior_facet=False):
    """A tet box written with two named surface groups, one unnamed group, a stray point and inverted tets."""
    mesh = box_mesh(ORIGIN, SIZE, (2, 2, 2), "tet")
    cells = mesh.cells.copy()
    cells[::3] = cells[::3][:, [0, 2, 1, 3]]                       # inverted
    points = np.vstack([mesh.points, [[9.0, 9.0, 9.0]]])          # unused point
    tags = {1: "xmin", 2: "zmax", 7: "ymin"}                       # physical (and geometrical) tag -> side
    tri = {t: fem.cell_faces("tet", mesh.cells[r[:, 0]], r[:, 1]) for t, r in
           ((t, mesh.surfaces[side]) for t, side in tags.items())}
    if interior_facet:
        tri[1] = np.vstack([tri[1], mesh.cells[:1, [1, 2, 3]]])  # on the hex face x = 1, inside the box
    # the v4 writer takes one gmsh entity per cell block, declared through the nodes' dim_tags
    dim_tags = np.tile([3, 1], (len(points), 1))
    for t, f in tri.items():
        dim_tags[f.ravel()] = [2, t]
    facet_tags = [np.full(len(f), t) for t, f in tri.items()]
    out = meshio.Mesh(points, [("tetra", cells)] + [("triangle", f) for f in tri.values()],
                      cell_data={"gmsh:physical": [np.full(len(cells), 3)] + facet_tags,
                                 "gmsh:geometrical": [np.full(len(cells), 1)] + facet_tags},
                      field_data={"left": np.array([1, 2]), "top": np.array([2, 2]), "body": np.array([3, 3])},
                      point_data={"gmsh:dim_tags": dim_tags})
    meshio.write(path, out, file_format=file_format, binary=False)
    return mesh


@pytest.mark.parametrize("file_format", ["gmsh22", "gmsh"])
def test_read_mesh_file_round_trip(tmp_path, file_format):
    path = tmp_path / "body.msh"
    ref = _write_tet_mesh(path, file_format)
    mesh = read_mesh_file(path, scale=2.0)
    assert mesh.cell_type == "tet" and len(mesh.points) == len(ref.points) and len(mesh.cells) == len(ref.cells)
    assert np.allclose(np.unique(mesh.points, axis=0), np.unique(2.0 * ref.points, axis=0))  # v4 renumbers nodes
    assert (cell_volumes(mesh) > 0).all()
    assert sorted(mesh.surfaces) == ["boundary", "left", "surface7", "top"]
    ref.points *= 2.0
    for name, ref_name in [("left", "xmin"), ("top", "zmax"), ("surface7", "ymin")]:
        assert node_sets(mesh, mesh.surfaces[name]) == node_sets(ref, ref.surfaces[ref_name])
    assert node_sets(mesh, mesh.surfaces["boundary"]) == node_sets(ref, np.concatenate(list(ref.surfaces.values())))
    # faces as stored point outward
    xf = face_coords(mesh, mesh.surfaces["left"])
    n, _ = fem.face_normals("tri", xf, fem.CENTROID["tri"][None])
    assert np.allclose(n[:, 0], [-1, 0, 0])


def test_an_empty_file_and_a_point_not_finite_say_so(tmp_path):
    """An empty file read "ValueError: need at least one array to concatenate", and a NaN coordinate was said of
    the body's mesh.scale (hunt34_3)."""
    path = tmp_path / "empty.msh"
    path.write_text("")
    with pytest.raises(MeshError, match="the file is empty"):
        read_mesh_file(path)
    path = tmp_path / "nan.msh"
    _write_tet_mesh(path, "gmsh22")
    text = path.read_text()
    nodes = text.index("$Nodes")
    first = text.index("\n", text.index("\n", nodes) + 1) + 1        # the first node's line
    line = text[first:text.index("\n", first)].split()
    path.write_text(text[:first] + " ".join([line[0], "nan", *line[2:]]) + text[text.index("\n", first):])
    with pytest.raises(MeshError, match=r"1 point\(s\) of its cells have a coordinate that is not a finite number, "
                                        r"e\.g\. point 0"):
        read_mesh_file(path)


@pytest.mark.parametrize("file_format", ["gmsh22", "gmsh"])
def test_a_physical_name_given_to_two_groups_is_refused(tmp_path, file_format):
    """meshio keys a file's physical names by name: of two surface groups named alike one went, a top face's
    pressure with it, exit 0 (hunt34_3). The file is refused, naming the name and the groups."""
    path = tmp_path / "body.msh"
    _write_tet_mesh(path, file_format)
    text = path.read_text()
    names = text[text.index("$PhysicalNames"):text.index("$EndPhysicalNames")]
    path.write_text(text.replace(names, names.replace('"top"', '"left"')))
    with pytest.raises(MeshError, match=r"the physical name 'left' is given to 2-D groups 1, 2, of which a reader "
                                        r"keeps one"):
        read_mesh_file(path)


def test_read_hex_file_unmirrors_cells(tmp_path):
    box = box_mesh(ORIGIN, SIZE, CELLS, "hex")
    cells = box.cells.copy()
    cells[::2] = cells[::2][:, [4, 5, 6, 7, 0, 1, 2, 3]]             # mirrored in z
    meshio.write(tmp_path / "hex.vtu", meshio.Mesh(box.points, [("hexahedron", cells)]))
    mesh = read_mesh_file(tmp_path / "hex.vtu")
    assert mesh.cell_type == "hex" and list(mesh.surfaces) == ["boundary"]
    assert (cell_volumes(mesh) > 0).all()
    assert node_sets(mesh, mesh.surfaces["boundary"]) == node_sets(box, np.concatenate(list(box.surfaces.values())))
    xf = face_coords(mesh, mesh.surfaces["boundary"])
    n, _ = fem.face_normals("quad", xf, fem.CENTROID["quad"][None])
    centre = np.add(ORIGIN, 0.5 * np.asarray(SIZE))
    assert (np.einsum("ki,ki->k", n[:, 0], xf.mean(axis=1) - centre) > 0).all()


def test_cells_listed_twice_are_used_once(tmp_path, capsys):
    """gmsh's msh2 lists an element once per physical volume it belongs to (an inner region tagged inside the
    whole): the reader kept both copies, whose stiffness counted twice (9.8 % off in displacement, exit 0; helper
    pass, session 25). Each cell is now used once, and the reader says how many were listed again."""
    box = box_mesh(ORIGIN, SIZE, (2, 2, 2), "tet")
    inner = box.cells[:5][:, [1, 0, 2, 3]]                       # the same cells, another node order
    out = meshio.Mesh(box.points, [("tetra", box.cells), ("tetra", inner)],
                      cell_data={"gmsh:physical": [np.full(len(box.cells), 1), np.full(5, 2)],
                                 "gmsh:geometrical": [np.full(len(box.cells), 1), np.full(5, 2)]},
                      field_data={"all": np.array([1, 3]), "core": np.array([2, 3])})
    meshio.write(tmp_path / "twice.msh", out, file_format="gmsh22", binary=False)
    mesh = read_mesh_file(tmp_path / "twice.msh")
    assert len(mesh.cells) == len(box.cells) and (cell_volumes(mesh) > 0).all()
    assert "5 of 53 tetra cells are listed more than once" in capsys.readouterr().out


def test_overlapping_cells_are_refused(tmp_path):
    """A cell laid over others (a face then shared by three cells) was accepted: 2 % off in displacement, exit 0
    (a helper's test pass, session 26). A face of more than two cells is a MeshError naming the cells."""
    box = box_mesh(ORIGIN, SIZE, (2, 2, 2), "tet")
    table = fem.CELL_FACES["tet"]
    faces = np.sort(box.cells[:, table].reshape(-1, 3), axis=1)
    _, first, count = np.unique(faces, axis=0, return_index=True, return_counts=True)
    k = first[np.flatnonzero(count == 2)[0]]                    # an inner face, of cell k // 4 and another
    cell, face = box.cells[k // 4], faces[k]
    other = next(v for v in range(len(box.points)) if v not in cell and
                 not any(set(face) | {v} == set(c) for c in box.cells.tolist()))
    extra = np.array([[*face, other]])
    meshio.write(tmp_path / "overlap.vtu", meshio.Mesh(box.points, [("tetra", np.vstack([box.cells, extra]))]))
    with pytest.raises(MeshError, match=r"overlap.vtu: 1 face\(s\) belong to more than two tetra cells \(the cells "
                                        rf"overlap\), e.g. tetra cells \d+, \d+, {len(box.cells)} \(0-based"):
        read_mesh_file(tmp_path / "overlap.vtu")


def test_cell_pieces_counts_unconnected_parts():
    """Cells that share a vertex are one piece; pieces are numbered by their first cell."""
    a = box_mesh(ORIGIN, SIZE, (3, 2, 2), "tet")
    b = box_mesh(ORIGIN, SIZE, (1, 1, 1), "hex")
    piece, n = cell_pieces(a.cells, len(a.points))
    assert n == 1 and not piece.any()
    two = np.vstack([a.cells[:, [0, 1, 2, 3, 0, 1, 2, 3]] + len(b.points), b.cells])      # b's cells come last
    piece, n = cell_pieces(two, len(a.points) + len(b.points))
    assert n == 2 and (piece[:len(a.cells)] == 0).all() and (piece[len(a.cells):] == 1).all()
    chain = np.array([[0, 1], [2, 3], [1, 2], [5, 6]])            # 0-1-2-3 joined by the third, 5-6 apart
    assert cell_pieces(chain, 7)[1] == 2 and list(cell_pieces(chain, 7)[0]) == [0, 0, 0, 1]


def test_surface_facet_not_on_boundary(tmp_path):
    """A group with faces inside the body cannot be a surface: it is set aside with the reason, an error only where a
    scene names it (an unused interior group of a gmsh model made the whole file unreadable; hunt33_1)."""
    path = tmp_path / "interior.msh"
    _write_tet_mesh(path, "gmsh22", interior_facet=True)
    mesh = read_mesh_file(path)
    assert "left" not in mesh.surfaces and "top" in mesh.surfaces
    assert mesh.unusable["left"] == "1 of 9 of its facets are not boundary faces of the tetra cells"


def _gmsh_box(path, version, groups, save_all=False, binary=False):
    """A gmsh box [0, 1] x [0, 1] x [0, 0.5] of tets written as msh `version`; groups: (name or None, tag, sides)
    physical groups of faces. Returns the number of faces on each side."""
    gmsh = pytest.importorskip("gmsh")
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        volume = gmsh.model.occ.addBox(0, 0, 0, 1, 1, 0.5)
        gmsh.model.occ.synchronize()
        side = {}
        for _, t in gmsh.model.getEntities(2):
            c = gmsh.model.occ.getCenterOfMass(2, t)
            side[["xmin", "xmax", "ymin", "ymax", "zmin", "zmax"][
                int(np.argmin([abs(c[0]), abs(c[0] - 1), abs(c[1]), abs(c[1] - 1), abs(c[2]), abs(c[2] - 0.5)]))]] = t
        for name, tag, sides in groups:
            gmsh.model.addPhysicalGroup(2, [side[k] for k in sides], tag, name=name or "")
        gmsh.model.addPhysicalGroup(3, [volume], 100, name="solid")
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.25)
        gmsh.option.setNumber("Mesh.MshFileVersion", version)
        gmsh.option.setNumber("Mesh.SaveAll", int(save_all))
        gmsh.option.setNumber("Mesh.Binary", int(binary))
        gmsh.model.mesh.generate(3)
        faces = {k: len(gmsh.model.mesh.getElements(2, t)[1][0]) for k, t in side.items()}
        gmsh.write(str(path))
    finally:
        gmsh.finalize()
    return faces


@pytest.mark.parametrize("version, binary", [(2.2, False), (4.1, False), (4.1, True)])
def test_gmsh_groups_that_share_faces(tmp_path, version, binary):
    """A face in two physical groups belongs to both. meshio keeps a msh 4.1 entity's first group alone: an
    unnamed group lost the top it shared with a named one, and a pressure on it never applied (exit 0; hunt33_1)."""
    path = tmp_path / "box.msh"
    faces = _gmsh_box(path, version, [("top", 1, ["zmax"]), (None, 20, ["zmax", "xmax"]),
                                      ("skin", 2, ["xmin", "zmin", "zmax"])], binary=binary)
    mesh = read_mesh_file(path)
    counts = {name: len(rows) for name, rows in mesh.surfaces.items()}
    assert counts["top"] == faces["zmax"]
    assert counts["surface20"] == faces["zmax"] + faces["xmax"]
    assert counts["skin"] == faces["xmin"] + faces["zmin"] + faces["zmax"]


def test_gmsh_files_meshio_cannot_read_say_why(tmp_path):
    """gmsh's Mesh.SaveAll = 1 in msh 4.1 made meshio fail with "Incompatible cell data", and msh 4.0 with "not enough
    values to unpack"; in msh 2.2 it drops every group, and a scene naming one read "unknown surface" beside a file
    that lists it (hunt33_1)."""
    groups = [("top", 1, ["zmax"])]
    _gmsh_box(tmp_path / "all41.msh", 4.1, groups, save_all=True)
    with pytest.raises(MeshError, match=r"Incompatible cell data .*Mesh.SaveAll = 1"):
        read_mesh_file(tmp_path / "all41.msh")
    _gmsh_box(tmp_path / "v40.msh", 4.0, groups)
    with pytest.raises(MeshError, match="gmsh's format 4 is not read; save it as 4.1 or 2.2"):
        read_mesh_file(tmp_path / "v40.msh")
    _gmsh_box(tmp_path / "all22.msh", 2.2, groups, save_all=True)
    mesh = read_mesh_file(tmp_path / "all22.msh")
    assert "top" not in mesh.surfaces and "Mesh.SaveAll = 1" in mesh.unusable["top"]


def test_read_errors(tmp_path):
    garbage = tmp_path / "garbage.msh"
    garbage.write_bytes(np.random.default_rng(0).bytes(2000))
    text = tmp_path / "text.msh"
    text.write_text("this is not a mesh\n")
    for path in (garbage, text, tmp_path / "missing.msh", tmp_path / "unknown.xyz"):
        with pytest.raises(MeshError, match="cannot read mesh file") as err:
            read_mesh_file(path)
        assert str(path) in str(err.value) and "\n" not in str(err.value)

    mixed = tmp_path / "mixed.vtu"
    hexes = box_mesh(ORIGIN, SIZE, (1, 1, 1), "hex")
    meshio.write(mixed, meshio.Mesh(hexes.points, [("hexahedron", hexes.cells), ("tetra", np.array([[0, 1, 3, 4]]))]))
    with pytest.raises(MeshError, match="all tetra or all hexahedron.*1 hexahedron, 1 tetra"):
        read_mesh_file(mixed)


def test_rotated_box_keeps_shape_and_face_names():
    """A rotated box shall be the rigidly rotated box: same distances, faces with the same names, rotated normals."""
    from qsc_petsc.meshgen import rotation_matrix
    rot = [10.0, 20.0, -30.0]
    plain = box_mesh(ORIGIN, SIZE, CELLS, "hex")
    turned = box_mesh(ORIGIN, SIZE, CELLS, "hex", rot)
    R = rotation_matrix(rot)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-15)
    np.testing.assert_allclose(turned.points, plain.points @ R.T, atol=1e-14)
    assert turned.surfaces.keys() == plain.surfaces.keys()
    np.testing.assert_array_equal(turned.cells, plain.cells)
    np.testing.assert_allclose(rotation_matrix([0, 0, 90]) @ [1, 0, 0], [0, 1, 0], atol=1e-15)


def test_memory_floor_refuses_a_box_no_node_can_hold():
    """A box whose measured memory floor exceeds the node's available memory shall be a SceneError naming the
    key before any matrix is made (the kernel killed such a run after 110 s, without a word); a node that does
    not say how much it has is not checked."""
    from conftest import CONFIGS
    from mpi4py import MPI

    from qsc_petsc.errors import SceneError
    from qsc_petsc.mesh import MEMORY_PER_DOF, check_size
    from qsc_petsc.scene import load_scene
    scene = load_scene(CONFIGS / "block_compression.toml", ["bodies.0.mesh.cells=[100, 100, 100]"])
    dofs = 3 * 101**3
    with pytest.raises(SceneError, match=rf"^bodies\[0\]\.mesh\.cells: \[100, 100, 100\] makes the generated boxes "
                                         rf"{dofs} dofs, which need at least .* GiB on a node .* more than its 1\.0 "
                                         rf"GiB available: use fewer cells or more nodes$"):
        check_size(scene, MPI.COMM_SELF, available=lambda: 2**30)
    check_size(scene, MPI.COMM_SELF, available=lambda: None)
    check_size(scene, MPI.COMM_SELF, available=lambda: 2 * MEMORY_PER_DOF * dofs)     # fits


@pytest.mark.parametrize("mode, expected", [("0", 8 * 2**30), ("2", 3 * 2**30), (None, 8 * 2**30)])
def test_available_memory_within_the_commit_limit(tmp_path, mode, expected):
    """A node's available memory is MemAvailable, and no more than the commit limit leaves where the kernel does
    not overcommit (vm.overcommit_memory = 2); a kernel that says neither leaves it unknown."""
    from qsc_petsc.mesh import available_memory
    meminfo = tmp_path / "meminfo"
    meminfo.write_text(f"MemTotal: {16 * 2**20} kB\nMemAvailable: {8 * 2**20} kB\nCommitLimit: {12 * 2**20} kB\n"
                       f"Committed_AS: {9 * 2**20} kB\nHugePages_Total:       0\n")
    overcommit = tmp_path / "overcommit_memory"
    if mode is not None:
        overcommit.write_text(mode + "\n")
    assert available_memory(meminfo, overcommit) == expected
    assert available_memory(tmp_path / "absent", overcommit) is None
