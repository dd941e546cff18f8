"""Body meshes as plain arrays on one rank: structured boxes, meshio files, and their named boundary surfaces."""

import io
import os
import sys
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import dataclass, field
from itertools import permutations

import numpy as np

from qsc_petsc import fem
from qsc_petsc.errors import MeshError

BOX_SURFACES = ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")  # the order of fem.HEX_FACES
MESHIO_TYPES = {"tetra": "tet", "hexahedron": "hex"}
FACET_TYPES = {"tet": "triangle", "hex": "quad"}

# corners of the unit cube in VTK hex order
HEX_CORNERS = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]])


def _kuhn_tets():
    """The 6 Kuhn tets of the unit cube as hex-local node lists (6, 4), all positively oriented.

    Each tet walks from corner 0 to corner 6 along the edges e_a, e_b, e_c of one axis
    permutation; every hex face is then cut along its diagonal through the face's lowest
    corner, the same in neighbouring hexes, so the split is conforming.
    """
    corner = {tuple(c): i for i, c in enumerate(HEX_CORNERS)}
    tets = []
    for a, b, _ in permutations(range(3)):
        v1 = np.eye(3, dtype=int)[a]
        v2 = v1 + np.eye(3, dtype=int)[b]
        tet = [0, corner[tuple(v1)], corner[tuple(v2)], 6]
        if np.linalg.det(np.array([v1, v2, [1, 1, 1]])) < 0:
            tet[1], tet[2] = tet[2], tet[1]
        tets.append(tet)
    return np.array(tets)


KUHN_TETS = _kuhn_tets()


def _kuhn_faces_on(side):
    """(tet in hex, local tet face) pairs (2, 2) that lie on box side 0..5 (xmin, xmax, ...)."""
    axis, value = divmod(side, 2)
    return np.array([(t, f) for t in range(6) for f in range(4)
                     if (HEX_CORNERS[KUHN_TETS[t][fem.TET_FACES[f]], axis] == value).all()])


@dataclass
class BodyMesh:
    """One body's mesh: VTK-ordered cells with positive volume and named boundary surfaces."""
    points: np.ndarray                 # (n, 3) float64
    cells: np.ndarray                  # (m, 8) hex or (m, 4) tet, int64
    cell_type: str                     # "hex" | "tet"
    surfaces: dict[str, np.ndarray] = field(default_factory=dict)  # name -> (k, 2) int64 (cell, local face)
    # a mesh file's groups of faces that cannot be surfaces, name -> why: an error only where a scene names one
    unusable: dict[str, str] = field(default_factory=dict)


def rotation_matrix(rotation_degrees):
    """The rotation (3, 3) of a rotation vector: axis times angle in degrees (Rodrigues)."""
    v = np.radians(np.asarray(rotation_degrees, dtype=float).reshape(3))
    theta = np.linalg.norm(v)
    if theta == 0.0:
        return np.eye(3)
    k = v / theta
    Kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(theta) * Kx + (1.0 - np.cos(theta)) * Kx @ Kx


def box_mesh(origin, size, cells, element="hex", rotation=(0.0, 0.0, 0.0)):
    """Structured mesh of the box [origin, origin + size] with cells = (nx, ny, nz) hexes, or 6 tets per hex,
    rotated about the point (0, 0, 0) by the rotation vector `rotation` (axis times angle, degrees), so that
    boxes stacked in one frame and given the same rotation stay stacked."""
    n = np.asarray(cells)
    if n.shape != (3,) or not np.issubdtype(n.dtype, np.integer) or (n < 1).any():
        raise MeshError(f"box cells must be three positive integers, got {cells!r}")
    if np.shape(size) != (3,) or (np.asarray(size, float) <= 0).any():
        raise MeshError(f"box size must be three positive lengths, got {size!r}")
    if np.shape(origin) != (3,):
        raise MeshError(f"box origin must be a point (x, y, z), got {origin!r}")
    if element not in ("hex", "tet"):
        raise MeshError(f"box element must be 'hex' or 'tet', got {element!r}")
    nx, ny, nz = (int(v) for v in n)
    axes = [o + s * np.arange(k + 1) / k for o, s, k in zip(np.asarray(origin, float), np.asarray(size, float), n)]
    Z, Y, X = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")      # point id i + (nx+1) (j + (ny+1) k)
    points = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])
    if np.any(np.asarray(rotation, dtype=float) != 0.0):
        points = points @ rotation_matrix(rotation).T
    stride = np.array([1, nx + 1, (nx + 1) * (ny + 1)])
    base = (np.arange(nx) + stride[1] * np.arange(ny)[:, None] + stride[2] * np.arange(nz)[:, None, None]).ravel()
    hexes = base[:, None] + HEX_CORNERS @ stride                               # cell id i + nx (j + ny k)
    ids = np.arange(nx * ny * nz).reshape(nz, ny, nx)
    on_side = [ids[:, :, 0], ids[:, :, -1], ids[:, 0, :], ids[:, -1, :], ids[0], ids[-1]]
    if element == "hex":
        surfaces = {name: np.column_stack([c.ravel(), np.full(c.size, side)])
                    for side, (name, c) in enumerate(zip(BOX_SURFACES, on_side))}
        return BodyMesh(points, hexes.astype(np.int64), "hex", surfaces)
    surfaces = {}
    for side, (name, c) in enumerate(zip(BOX_SURFACES, on_side)):
        tf = _kuhn_faces_on(side)
        surfaces[name] = np.column_stack([(6 * c.ravel()[:, None] + tf[:, 0]).ravel(),
                                          np.tile(tf[:, 1], c.size)])
    return BodyMesh(points, hexes[:, KUHN_TETS].reshape(-1, 4).astype(np.int64), "tet", surfaces)


def _row_ids(rows, n):
    """Id (k,) of each row of integers in [0, n), equal rows sharing one id."""
    bits = max(int(n - 1).bit_length(), 1)
    per = max(63 // bits, 1)                   # columns packed into each int64 sort key
    keys = []
    for s in range(0, rows.shape[1], per):
        k = np.zeros(len(rows), np.int64)
        for col in rows[:, s:s + per].T:
            k = (k << bits) | col
        keys.append(k)
    order = np.argsort(keys[0]) if len(keys) == 1 else np.lexsort(keys[::-1])
    sk = np.stack(keys)[:, order]
    new = np.r_[True, (sk[:, 1:] != sk[:, :-1]).any(axis=0)]
    ids = np.empty(len(rows), np.int64)
    ids[order] = np.cumsum(new) - 1
    return ids


def cell_pieces(cells, n_points):
    """The connected pieces of a mesh (cells sharing a vertex are connected): (piece of each cell (m,), number of
    pieces), pieces numbered by their first cell. Label propagation with pointer jumping, vectorised."""
    cells = np.asarray(cells, np.int64)
    if len(cells) == 0:
        return np.zeros(0, np.int64), 0
    label = np.arange(n_points, dtype=np.int64)
    while True:
        low = label[cells].min(axis=1)
        new = label.copy()
        for col in cells.T:                       # every vertex takes the lowest label of its cells
            np.minimum.at(new, col, low)
        while True:                               # and its label's label, to a fixed point
            jumped = new[new]
            if np.array_equal(jumped, new):
                break
            new = jumped
        if np.array_equal(new, label):
            break
        label = new
    _, first, piece = np.unique(label[cells[:, 0]], return_index=True, return_inverse=True)
    rank = np.empty(len(first), np.int64)
    rank[np.argsort(first)] = np.arange(len(first))
    return rank[piece], len(first)


def _face_counts(cell_type, cells):
    """Every cell face, in (cell, local face) order flattened: its id (of its sorted node tuple) and how many
    cells hold it."""
    table = fem.CELL_FACES[cell_type]
    faces = np.sort(cells[:, table].reshape(-1, table.shape[1]), axis=1)
    if len(faces) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    ids = _row_ids(faces, cells.max() + 1)
    return ids, np.bincount(ids)[ids]


def _faces_held(cell_type, count, n):
    """(cell, local face) rows (k, 2) of the faces held by n cells (_face_counts' count)."""
    k = np.flatnonzero(count == n)
    per_cell = len(fem.CELL_FACES[cell_type])
    return np.column_stack([k // per_cell, k % per_cell]).astype(np.int64)


def boundary_faces(cell_type, cells):
    """(cell, local face) rows (k, 2) of every face that belongs to one cell only."""
    return _faces_held(cell_type, _face_counts(cell_type, np.asarray(cells, np.int64))[1], 1)


def _orient(cell_type, points, cells):
    """Cells reordered so that each has positive volume (tets by a node swap, mirrored hexes top for bottom)."""
    if cell_type == "tet":
        x = points[cells]
        vol = np.einsum("mi,mi->m", x[:, 1] - x[:, 0], np.cross(x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]))
        flip = [0, 2, 1, 3]
    else:
        _, dN = fem.shape_hex(np.zeros(3))
        vol = np.linalg.det(np.einsum("mai,ak->mik", points[cells], dN[0]))
        flip = [4, 5, 6, 7, 0, 1, 2, 3]
    cells = cells.copy()
    cells[vol < 0] = cells[vol < 0][:, flip]
    return cells


def _gmsh_format(path):
    """(version, binary, data size) from a gmsh file's $MeshFormat header, or None for another file."""
    try:
        with open(path, "rb") as f:
            if f.readline().strip() != b"$MeshFormat":
                return None
            version, binary, size = f.readline().split()[:3]
            return version.decode(), binary == b"1", int(size)
    except (OSError, ValueError):
        return None


def _gmsh41_surface_groups(path, binary, data_size):
    """{entity tag: [physical tags]} of the surface entities of a gmsh 4.1 file, read from its $Entities
    section with meshio's own reader of it; None when the file has none. meshio's mesh keeps an entity's
    first physical tag alone (`gmsh:physical`), so a face in two groups went to the first one only: an
    unnamed group lost the top face it shared with a named one, whose pressure then never applied (exit 0;
    hunt33_1)."""
    from meshio.gmsh._gmsh41 import _read_entities
    with open(path, "rb") as f:
        for line in f:
            if line.strip() == b"$Entities":
                return _read_entities(f, not binary, data_size)[0][2]
    return None


def _shared_physical_names(path):
    """{(dimension, name): [tags]} of the names a gmsh file's $PhysicalNames section gives to several groups of one
    dimension (the section is text in ascii and binary files alike). meshio keys them by name: all but one group
    went, a top face's pressure with it, exit 0 (hunt34_3)."""
    seen = {}
    with open(path, "rb") as f:
        for line in f:
            if line.strip() == b"$PhysicalNames":
                for _ in range(int(f.readline())):
                    dim, tag, name = f.readline().decode("utf-8", "replace").split(maxsplit=2)
                    seen.setdefault((int(dim), name.strip().strip('"')), []).append(int(tag))
                break
    return {key: tags for key, tags in seen.items() if len(tags) > 1}


def _named_facets(mesh, entity_groups=None):
    """Surface groups of a meshio mesh: {name: [(meshio cell type, facet node array), ...]}. entity_groups: a
    gmsh 4.1 file's {surface entity: [physical tags]} (_gmsh41_surface_groups), which meshio's
    `gmsh:physical` cuts to the first tag."""
    groups = {}
    names = {int(v[0]): k for k, v in mesh.field_data.items() if len(v) > 1 and int(v[1]) == 2}
    entities = mesh.cell_data.get("gmsh:geometrical")
    tags = mesh.cell_data.get("gmsh:physical")
    if entity_groups is not None and entities is not None:
        # every physical group of faces, named or not: meshio's cell_sets of the named ones would add them again
        for block, e in zip(mesh.cells, entities):
            if block.dim == 2 and len(e):
                for tag in entity_groups.get(int(e[0]), ()):
                    groups.setdefault(names.get(int(tag), f"surface{tag}"), []).append((block.type, block.data))
        return groups
    if tags is not None:
        for block, t in zip(mesh.cells, tags):
            if block.dim == 2:
                for tag in np.unique(t):
                    name = names.get(int(tag), f"surface{tag}")
                    groups.setdefault(name, []).append((block.type, block.data[t == tag]))
    for name, per_block in mesh.cell_sets.items():
        if name.startswith("gmsh:"):
            continue
        for block, idx in zip(mesh.cells, per_block):
            if idx is not None and len(idx) and block.dim == 2:
                groups.setdefault(name, []).append((block.type, block.data[np.asarray(idx)]))
    return groups


def read_mesh_file(path, scale=1.0):
    """Read a first-order all-tet or all-hex mesh with meshio; 2D physical groups become named surfaces.

    Coordinates are multiplied by scale. Adds the surface "boundary" (all boundary faces),
    drops points no volume cell uses, and reorders inverted cells. Raises MeshError.
    """
    import meshio  # only needed here

    if os.path.isfile(path) and os.path.getsize(path) == 0:
        # meshio's "need at least one array to concatenate" (hunt34_3)
        raise MeshError(f"cannot read mesh file {path}: the file is empty")
    gmsh = _gmsh_format(path)
    if gmsh is not None and gmsh[0].startswith("4") and gmsh[0] != "4.1":
        # meshio reads 4.1 and 2.2: 4.0 failed with "not enough values to unpack" (hunt33_1)
        raise MeshError(f"cannot read mesh file {path}: gmsh's format {gmsh[0]} is not read; save it as 4.1 or 2.2 "
                        f"(Mesh.MshFileVersion)")
    # meshio prints a failed reader's reason and then calls sys.exit: capture both
    printed = io.StringIO()
    try:
        with redirect_stdout(printed), redirect_stderr(printed):
            mesh = meshio.read(path)
    except (Exception, SystemExit) as e:  # noqa: BLE001 - meshio raises ReadError, OSError, ValueError, KeyError, ...
        if isinstance(e, SystemExit):  # its reason was printed, wrapped to the terminal width
            reason = " ".join(s.strip() for s in printed.getvalue().splitlines() if s.strip())
        else:
            reason = " ".join(f"{type(e).__name__}: {e}".split())
        if "Incompatible cell data 'gmsh:physical'" in reason:
            reason += (" (elements outside every physical group, as gmsh's Mesh.SaveAll = 1 writes them, which "
                       "meshio cannot read beside the groups: save without it)")
        raise MeshError(f"cannot read mesh file {path}: {reason}") from None
    if printed.getvalue().strip():
        sys.stdout.write(printed.getvalue())  # meshio's warnings on a successful read
    shared = _shared_physical_names(path) if gmsh is not None else {}
    if shared:
        (dim, name), tags = next(iter(shared.items()))
        raise MeshError(f"mesh file {path}: the physical name {name!r} is given to {dim}-D groups "
                        f"{', '.join(map(str, tags))}, of which a reader keeps one: give each group a name of its own, "
                        f"or make them one group")
    found = {}
    for block in mesh.cells:
        if block.dim == 3:
            found[block.type] = found.get(block.type, 0) + len(block.data)
    if len(found) != 1 or next(iter(found)) not in MESHIO_TYPES:
        what = ", ".join(f"{n} {t}" for t, n in found.items()) or "no volume cells"
        raise MeshError(f"mesh file {path}: volume cells must be all tetra or all hexahedron (first order), "
                        f"found {what}")
    (mtype,) = found
    cell_type = MESHIO_TYPES[mtype]
    points = np.asarray(mesh.points, float)
    if points.ndim != 2 or points.shape[1] != 3:
        raise MeshError(f"mesh file {path}: points must be 3D, got shape {points.shape}")
    cells = np.concatenate([b.data for b in mesh.cells if b.type == mtype]).astype(np.int64)
    used = np.unique(cells)
    wrong = used[~np.isfinite(points[used]).all(axis=1)]
    if len(wrong):
        # it went on to "bodies[0].mesh.scale: the body is nan across", which no scale cures (hunt34_3)
        raise MeshError(f"mesh file {path}: {len(wrong)} point(s) of its cells have a coordinate that is not a finite "
                        f"number, e.g. point {int(wrong[0])} (0-based, in the file's order): {points[wrong[0]].tolist()}")
    # gmsh's msh2 lists an element once per physical volume it belongs to: a cell counted twice would add its
    # stiffness twice (an inner region tagged apart inside the whole: 9.8 % off in displacement, no warning)
    _, first = np.unique(_row_ids(np.sort(cells, axis=1), len(points)), return_index=True)
    index = np.arange(len(cells))                       # the cells' places among the file's volume cells
    if len(first) < len(cells):
        sys.stdout.write(f"qsc: mesh file {path}: {len(cells) - len(first)} of {len(cells)} {mtype} cells are listed "
                         f"more than once (msh2 writes an element once per physical volume): each is used once\n")
        index = np.sort(first)
        cells = cells[index]
    cells = _orient(cell_type, points, cells)
    ids, count = _face_counts(cell_type, cells)
    # a face of three cells or more: cells that overlap (an extra cell over others: 2 % off, exit 0, a helper's
    # test pass, session 26); a valid mesh has each face in one cell (boundary) or two
    crowded = np.flatnonzero(count > 2)
    if len(crowded):
        table = fem.CELL_FACES[cell_type]
        face = crowded[ids[crowded] == ids[crowded[0]]]
        nodes = cells[face[0] // len(table)][table[face[0] % len(table)]]
        raise MeshError(f"mesh file {path}: {len(np.unique(ids[crowded]))} face(s) belong to more than two "
                        f"{mtype} cells (the cells overlap), e.g. {mtype} cells "
                        f"{', '.join(str(i) for i in index[face // len(table)])} (0-based, in the file's order) "
                        f"share the face of points {sorted(int(v) for v in nodes)}")
    boundary = _faces_held(cell_type, count, 1)
    groups = _named_facets(mesh, _gmsh41_surface_groups(path, *gmsh[1:]) if gmsh and gmsh[0] == "4.1" else None)
    if "boundary" in groups:
        raise MeshError(f"mesh file {path}: surface name 'boundary' is reserved for all boundary faces")
    # a group that cannot be a surface stops the run only if the scene names it (an unused interior group of a
    # gmsh model made the whole file unreadable; hunt33_1)
    unusable = {name: f"the file names it (physical group {int(v[0])}) but no face of it is in the file (an empty "
                      f"group, or gmsh's Mesh.SaveAll = 1, which writes every element outside its groups)"
                for name, v in mesh.field_data.items()
                if len(v) > 1 and int(v[1]) == 2 and name not in groups and name != "boundary"}
    names, facets = [], []
    for name, per_block in groups.items():
        wrong = sorted({ftype for ftype, _ in per_block if ftype != FACET_TYPES[cell_type]})
        if wrong:
            unusable[name] = f"it has {', '.join(wrong)} facets, but {mtype} cells have {FACET_TYPES[cell_type]} faces"
            continue
        names.append(name)
        facets.append(np.concatenate([d for _, d in per_block]).astype(np.int64))
    # join facets to boundary faces by their sorted node tuples
    bnodes = fem.cell_faces(cell_type, cells[boundary[:, 0]], boundary[:, 1])
    rows = np.sort(np.concatenate([bnodes] + facets), axis=1)
    ids = _row_ids(rows, len(points))
    face_of = np.full(ids.max() + 1 if len(ids) else 0, -1)
    face_of[ids[:len(boundary)]] = np.arange(len(boundary))
    hit = face_of[ids[len(boundary):]]
    surfaces, start = {}, 0
    for name, f in zip(names, facets):
        h = hit[start:start + len(f)]
        start += len(f)
        if (h < 0).any():
            unusable[name] = f"{(h < 0).sum()} of {len(h)} of its facets are not boundary faces of the {mtype} cells"
            continue
        surfaces[name] = boundary[np.unique(h)]
    surfaces["boundary"] = boundary

    used = np.unique(cells)
    renumber = np.full(len(points), -1, np.int64)
    renumber[used] = np.arange(len(used))
    return BodyMesh(points[used] * scale, renumber[cells], cell_type, surfaces, unusable)
