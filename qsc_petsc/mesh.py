"""All bodies of a scene in one distributed DMPlex, with body and surface labels and rank-independent ids.

The mesh is built on rank 0 (generated boxes or files), handed to DMPlex as one cell list,
labelled (cell label "body"; one vertex label per surface, named "body.surface") and
distributed by a PETSc partitioner (options prefix ``qsc_``). Each rank then gets, through
the migration SF, the original cell connectivity and original vertex ids, so element node
order and every tie rule stay independent of the number of ranks.
"""

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from . import fem
from .errors import MeshError, QscError, SceneError
from .meshgen import box_mesh, cell_pieces, read_mesh_file
from .options import option_value
from .partition import cell_centroids, coordinate_bisection

# a body's largest extent, in the scene's length unit: areas, stiffnesses and the contact quadrature take powers of
# lengths, which leave double precision far beyond these (a patch test 1e-80 wide failed its contact quadrature);
# docs/stability.md measures scenes scaled from 1e-28 to 1e28
MIN_EXTENT, MAX_EXTENT = 1e-30, 1e30

MAX_SURFACES = 62          # face membership travels as one int64 bitmask per cell face


@dataclass
class GlobalMesh:
    """The whole multi-body mesh, on rank 0 only."""
    points: np.ndarray          # (n, 3)
    cells: np.ndarray           # (m, k) VTK order
    cell_type: str
    cell_body: np.ndarray       # (m,) body index
    face_mask: np.ndarray       # (m, faces per cell) int64 bitmask over surface indices
    surface_names: list         # "body.surface", index = bit
    cell_piece: np.ndarray = None   # (m,) connected piece (index into piece_names)
    piece_names: list = None    # a body's name, or "body piece k of n (around x, y, z)" for a body in pieces
    body_sources: list = None   # per body: (its first cell, "bodies[i] (name, what it was made from)")
    unusable: dict = None       # "body.surface" -> why a mesh file's group of faces cannot be a surface


@dataclass
class LocalMesh:
    """One rank's part of the distributed mesh (no overlap: every cell lives on exactly one rank)."""
    comm: object
    dm: PETSc.DMPlex
    cell_type: str
    body_names: list
    surface_names: list
    coords: np.ndarray          # (nv, 3) local vertex coordinates [m]
    cells: np.ndarray           # (nc, k) local vertex indices, VTK order
    cell_body: np.ndarray       # (nc,)
    cell_orig: np.ndarray       # (nc,) original cell id (rank-independent)
    face_mask: np.ndarray       # (nc, faces per cell)
    vert_orig: np.ndarray       # (nv,) original vertex id (rank-independent)
    gvert: np.ndarray           # (nv,) global vertex number in PETSc's distributed numbering
    owned: np.ndarray           # (nv,) bool: this rank owns the vertex (and its dofs)
    owner: np.ndarray           # (nv,) rank owning each local vertex
    n_vertices: int             # global
    n_cells: int                # global
    vertex_range: tuple         # owned global vertex numbers [start, end)
    cell_piece: np.ndarray = None   # (nc,) connected piece (GlobalMesh.piece_names)
    piece_names: list = None
    body_sources: list = None   # GlobalMesh.body_sources
    partitioner: str = "none"   # what distributed the cells: "coordinate bisection" or PETSc's partitioner type
    _surface_vertices: dict = field(default_factory=dict)

    @property
    def face_type(self):
        return fem.FACE_TYPE[self.cell_type]

    def surface_index(self, name):
        try:
            return self.surface_names.index(name)
        except ValueError:
            raise MeshError(f"unknown surface {name!r}") from None

    def surface_faces(self, name):
        """Local boundary faces of a surface: (cell index (k,), local face index (k,))."""
        bit = np.int64(1) << np.int64(self.surface_index(name))
        c, f = np.nonzero(self.face_mask & bit)
        return c, f

    def face_nodes(self, cells, local_faces):
        """Local vertex indices (k, nv) of the given cell faces, ordered counter-clockwise from outside."""
        return fem.cell_faces(self.cell_type, self.cells[cells], local_faces)

    def surface_vertices(self, name):
        """Local vertex indices of every local copy of a vertex on a surface (from the DMPlex label)."""
        if name not in self._surface_vertices:
            self.surface_index(name)
            label = self.dm.getLabel(name)
            v0 = self.dm.getDepthStratum(0)[0]
            pts = label.getStratumIS(1).getIndices() if label.getStratumSize(1) else np.zeros(0, int)
            self._surface_vertices[name] = np.sort(np.asarray(pts, dtype=np.int64) - v0)
        return self._surface_vertices[name]

    def dof_vector(self):
        """A zeroed dof-space global Vec: 3 dofs per owned vertex, block size 3, the layout of K's rows (collective)."""
        vec = PETSc.Vec().createMPI((3 * int(self.owned.sum()), 3 * self.n_vertices), bsize=3, comm=self.comm)
        vec.set(0.0)
        return vec

    def local_vectors(self, vec):
        """Ghosted local values (nv, 3) of a dof-space global Vec, by local vertex."""
        local = self.dm.createLocalVec()
        self.dm.globalToLocal(vec, local)
        values = local.getArray().reshape(-1, 3).copy()
        local.destroy()
        return values

    def body_vertices(self, body):
        """Local vertex indices of a body."""
        return np.flatnonzero(self.body_mask(body))

    @cached_property
    def owned_rows(self):
        """The local vertex of each owned row: row r is global vertex vertex_range[0] + r."""
        own = np.flatnonzero(self.owned)
        rows = np.empty(len(own), dtype=np.int64)
        rows[self.gvert[own] - self.vertex_range[0]] = own
        return rows

    @cached_property
    def vertex_body(self):
        """Body index of each local vertex (bodies share no vertex; -1 for a vertex in no local cell)."""
        body = np.full(len(self.coords), -1, dtype=self.cell_body.dtype)
        body[self.cells] = self.cell_body[:, None]
        return body

    def describe_cell(self, orig):
        """Where a cell (its original id) is, for a message: 'bodies[1] (upper, mesh file m.msh): tet 100 (0-based,
        in the body's order of cells)'."""
        starts = [first for first, _ in self.body_sources]
        b = int(np.searchsorted(starts, orig, side="right")) - 1
        return f"{self.body_sources[b][1]}: {self.cell_type} {orig - starts[b]} (0-based, in the body's order of cells)"

    @cached_property
    def vertex_piece(self):
        """Connected piece of each local vertex (a body's pieces share no vertex; -1 for a vertex in no local
        cell): what must be held, one rigid body each (restraint)."""
        piece = np.full(len(self.coords), -1, dtype=np.int64)
        piece[self.cells] = self.cell_piece[:, None]
        return piece

    def body_mask(self, body):
        """Whether each local vertex belongs to a body (a mask needs no sorted vertex list)."""
        return self.vertex_body == body


def on_root(comm, fn):
    """Run fn on rank 0 and re-raise its QscError on every rank, so all ranks fail together."""
    result, error = None, None
    if comm.rank == 0:
        try:
            result = fn()
        except QscError as exc:
            error = exc
    error = comm.bcast(error, root=0)
    if error is not None:
        raise error
    return result


# a generated box's cells are translates of one cell, exact but for their coordinates' round-off, eps |x|: they are
# checked (check_cells) only beyond this many cell sizes from the origin (eps |x| 2e-12 of a cell there, against the
# element test's 1e-10 of its volume)
BOX_EXACT_REACH = 1e4


FAR_CELL_SHARE = 1e-3     # a cell's coordinates' round-off against its size above which a degenerate one is said far


def check_cells(mesh, scene):
    """A MeshError on every rank naming the first inverted or degenerate cell of any rank (the assembly's test,
    elasticity.check_cells), before anything uses the cells: `qsc check` called a flat tet valid (hunt33_1), and a
    run with contact met cells degenerate by their coordinates' round-off (1 m boxes 1e16 m out) in its search
    first, a ZeroDivisionError and exit 1 (hunt33_5). A generated box's cells are checked only far from the origin
    (BOX_EXACT_REACH). Collective."""
    from . import elasticity
    check = np.ones(len(mesh.cells), dtype=bool)
    for b, body in enumerate(scene.bodies):
        spec = body.mesh
        if spec.type == "box":
            mine = mesh.cell_body == b
            cell = float(np.min(np.asarray(spec.size, float) / np.asarray(spec.cells, float)))
            far = float(np.abs(mesh.coords[mesh.cells[mine]]).max(initial=0.0))
            check[mine] = far > BOX_EXACT_REACH * cell

    def sound():
        try:
            elasticity.check_cells(mesh.cell_type, mesh.coords, mesh.cells[check], mesh.cell_orig[check])
        except elasticity.DegenerateCell as exc:
            xe = mesh.coords[mesh.cells[np.flatnonzero(mesh.cell_orig == exc.cell)[0]]]
            raise MeshError(f"{mesh.describe_cell(exc.cell)} is inverted or degenerate: {exc.detail}"
                            f"{_far_cell(xe)}") from None
    on_all(mesh.comm, sound)


def _far_cell(xe):
    """', its corners ... from the origin, ...' when a cell's coordinates' round-off is a fair share of its size
    (boxes 1e16 m out: their cells' corners, 2 m apart in round-off, inverted them; the far-from-origin warning
    that names the cause comes after the check, hunt34_3), else ''."""
    reach = float(np.abs(xe).max())
    known = float(np.spacing(reach))
    size = float(np.ptp(xe, axis=0).max())
    if known <= FAR_CELL_SHARE * size:
        return ""
    return (f"; its corners lie {reach:.2g} m from the origin, where coordinates are known to {known:.2g} m "
            f"against its size {size:.2g} m: move the scene nearer to the origin")


def on_all(comm, fn):
    """Run fn on every rank; if any rank raises a QscError, every rank raises the first one (by rank)."""
    result, error = None, None
    try:
        result = fn()
    except QscError as exc:
        error = exc
    errors = comm.allgather(error)
    first = next((e for e in errors if e is not None), None)
    if first is not None:
        raise first
    return result


def first_largest(comm, values, points, tie=0.0, relative=0.0, detail=None):
    """The largest of values (k,) over all ranks, the point (points (k, 3)) it lies at, and detail(i) of it (None
    without detail): of the values within max(tie, relative x |largest|) of the largest, the one first by x, y, z,
    so that it is the same on any number of ranks; (-inf, None, None) when no rank holds any (collective)."""
    top = comm.allreduce(float(np.max(values, initial=-np.inf)), op=MPI.MAX)
    local = None
    level = np.flatnonzero(values >= top - max(tie, relative * abs(top))) if np.isfinite(top) else []
    if len(level):
        k = level[np.lexsort(points[level].T[::-1])[0]]
        local = (float(values[k]), np.asarray(points[k], dtype=float).tolist(), detail(k) if detail else None)
    entries = [entry for entry in comm.allgather(local) if entry is not None]
    return min(entries, key=lambda entry: entry[1]) if entries else (-np.inf, None, None)


# The least memory a run takes, measured (docs/performance.md, elasticity: 985k dofs in 2205 MiB on one rank):
# about 2 KiB per dof, and 150 MiB per process for Python, PETSc and MPI. A scene below it cannot fit.
MEMORY_PER_DOF, MEMORY_PER_RANK = 2048, 150 * 2**20


def box_dofs(scene):
    """(dofs of the scene's generated boxes, (index, mesh spec) of the largest box or None), from the scene alone."""
    boxes = [(b, body.mesh) for b, body in enumerate(scene.bodies) if body.mesh.type == "box"]
    vertices = [int(np.prod([n + 1 for n in spec.cells], dtype=object)) for _, spec in boxes]
    return 3 * sum(vertices), (boxes[int(np.argmax(vertices))] if boxes else None)


def available_memory(meminfo="/proc/meminfo", overcommit="/proc/sys/vm/overcommit_memory"):
    """This node's available memory in bytes, None where the kernel does not say: MemAvailable of /proc/meminfo,
    and no more than the commit limit leaves (CommitLimit - Committed_AS) where the kernel does not overcommit
    (vm.overcommit_memory = 2: allocations beyond it are refused, touched or not)."""
    try:
        with open(meminfo) as lines:
            info = {line.split(":")[0]: int(line.split()[1]) * 1024 for line in lines if line.split()[1:2]}
    except (OSError, ValueError):
        return None
    free = info.get("MemAvailable")
    try:
        with open(overcommit) as mode:
            strict = mode.read().strip() == "2"
    except OSError:
        strict = False
    if free is not None and strict and "CommitLimit" in info and "Committed_AS" in info:
        free = min(free, max(info["CommitLimit"] - info["Committed_AS"], 0))
    return free


def node_memory(comm, available=available_memory):
    """(ranks of comm on this rank's node, the node's available memory in bytes or None) (collective)."""
    node = comm.Split_type(MPI.COMM_TYPE_SHARED)
    ranks = node.size
    node.Free()
    return ranks, available()


def check_size(scene, comm, available=available_memory):
    """A SceneError on every rank, before any mesh array is made, when the generated boxes have more dofs than
    PETSc's indices can number, or cannot fit in some node's available memory even at the measured floor
    (MEMORY_PER_DOF, MEMORY_PER_RANK): the kernel would kill the run minutes in, without a word (a 1e6 x 1 x 1
    box, 12 M dofs, went after 110 s). Collective."""
    dofs, largest = box_dofs(scene)
    if not dofs:
        return
    b, spec = largest
    head = f"bodies[{b}].mesh.cells: {list(spec.cells)} makes the generated boxes {dofs} dofs"
    limit = np.iinfo(PETSc.IntType)
    if dofs > limit.max:          # the same scene on every rank: all raise here together
        raise SceneError(f"{head}, more than PETSc's {limit.bits}-bit indices can number ({limit.max})")
    ranks, free = node_memory(comm, available)
    need = ranks * (MEMORY_PER_RANK + MEMORY_PER_DOF * dofs / comm.size)
    short = [(n, f) for n, f in comm.allgather((need, free)) if f is not None and n > f]
    if short:
        n, f = max(short)
        raise SceneError(f"{head}, which need at least {n / 2**30:.1f} GiB on a node (about "
                         f"{MEMORY_PER_DOF // 1024} KiB a dof and {MEMORY_PER_RANK // 2**20} MiB a rank, measured), "
                         f"more than its {f / 2**30:.1f} GiB available: use fewer cells or more nodes")


def build_global_mesh(scene):
    """Generate or read every body and merge them into one vertex/cell numbering (rank 0)."""
    points, cells, bodies, masks, names, pieces, piece_names, sources = [], [], [], [], [], [], [], []
    unusable = {}
    n_cells = 0
    offset, cell_types = 0, set()
    for b, body in enumerate(scene.bodies):
        spec = body.mesh
        if spec.type == "box":
            bm = box_mesh(spec.origin, spec.size, spec.cells, spec.element, spec.rotation)
        elif spec.type == "hertz":
            from .hertz import mesh_file
            bm = read_mesh_file(str(mesh_file(spec.part, spec.level, spec.radius, spec.cache)))
        else:
            bm = read_mesh_file(spec.path, spec.scale)
        _check_extent(b, spec, bm.points)
        cell_types.add(bm.cell_type)
        if body.material.volumetric == "mean_dilatation" and bm.cell_type != "hex":
            raise SceneError(f"bodies[{b}].material.volumetric: \"mean_dilatation\" is for hexahedra, and the body's "
                             f"mesh is of linear tetrahedra, whose strain is one per cell (nothing to average)")
        if len(cell_types) > 1:
            raise SceneError(f"bodies[{b}].mesh: all bodies must use one element type "
                             f"(found {sorted(cell_types)}); mixed hex/tet meshes are not supported")
        unusable.update({f"{body.name}.{name}": why for name, why in bm.unusable.items()})
        mask = np.zeros((len(bm.cells), len(fem.CELL_FACES[bm.cell_type])), dtype=np.int64)
        for sname, cf in sorted(bm.surfaces.items()):
            bit = len(names)
            if bit >= MAX_SURFACES:
                raise MeshError(f"bodies[{b}].mesh: more than {MAX_SURFACES} named surfaces in the scene")
            names.append(f"{body.name}.{sname}")
            mask[cf[:, 0], cf[:, 1]] |= np.int64(1) << np.int64(bit)
        # a body read from a file may come in several unconnected pieces, each needing its own hold
        piece, n_pieces = (np.zeros(len(bm.cells), np.int64), 1) if spec.type == "box" else \
            cell_pieces(bm.cells, len(bm.points))
        pieces.append(piece + len(piece_names))
        if n_pieces == 1:
            piece_names.append(body.name)
        else:
            for k in range(n_pieces):
                centre = bm.points[np.unique(bm.cells[piece == k])].mean(axis=0)
                piece_names.append(f"{body.name} piece {k + 1} of {n_pieces} (around "
                                   f"{', '.join(f'{c:.3g}' for c in centre)})")
        made = ("generated box" if spec.type == "box" else f"Hertz {spec.part} mesh" if spec.type == "hertz"
                else f"mesh file {spec.path}")
        sources.append((n_cells, f"bodies[{b}] ({body.name}, {made})"))
        n_cells += len(bm.cells)
        points.append(bm.points)
        cells.append(bm.cells + offset)
        bodies.append(np.full(len(bm.cells), b))
        masks.append(mask)
        offset += len(bm.points)
    return GlobalMesh(np.concatenate(points), np.concatenate(cells), cell_types.pop(),
                      np.concatenate(bodies), np.concatenate(masks), names, np.concatenate(pieces), piece_names,
                      sources, unusable)


def _check_extent(index, spec, points):
    """A MeshError naming bodies[index].mesh when the body's largest extent is outside [MIN_EXTENT, MAX_EXTENT]."""
    extent = float(np.ptp(points, axis=0).max()) if len(points) else 0.0
    if MIN_EXTENT <= extent <= MAX_EXTENT:
        return
    key = {"box": ".size", "file": ".scale"}.get(spec.type, "")
    raise MeshError(f"bodies[{index}].mesh{key}: the body is {extent:.3g} across (in the scene's length unit); a body's "
                    f"extent must lie between {MIN_EXTENT:g} and {MAX_EXTENT:g} (areas and stiffnesses take its powers)")


def check_surface_references(scene, surface_names, unusable=None):
    """Every surface named by a boundary condition, contact pair or die must exist in the mesh; unusable: {"body.
    surface": why} of a mesh file's groups of faces that cannot be surfaces (named only where a scene uses one)."""
    def check(key, ref):
        if ref in (unusable or {}):
            raise SceneError(f"{key}: surface {ref!r} of the mesh file cannot be used: {unusable[ref]}")
        if ref not in surface_names:
            body = ref.split(".")[0]
            known = sorted(s.split(".", 1)[1] for s in surface_names if s.split(".")[0] == body)
            raise SceneError(f"{key}: unknown surface {ref!r} (body {body!r} has: {', '.join(known)})")
    for i, bc in enumerate(scene.boundary):
        check(f"boundary[{i}].surface", bc.surface)
    for i, pair in enumerate(scene.contact):
        check(f"contact[{i}].slave", pair.slave)
        check(f"contact[{i}].master", pair.master)
    for i, die in enumerate(scene.die):
        for j, s in enumerate(die.surfaces):
            check(f"die[{i}].surfaces[{j}]", s)


def _bcast_points(sf, root_data, n_leaf):
    """Broadcast per-point int64 rows (width w) from the original to the distributed chart."""
    width = root_data.shape[1]
    leaf = np.full((n_leaf, width), -1, dtype=np.int64)
    unit = MPI.INT64_T.Create_contiguous(width).Commit()
    try:
        sf.bcastBegin(unit, np.ascontiguousarray(root_data), leaf, MPI.REPLACE)
        sf.bcastEnd(unit, np.ascontiguousarray(root_data), leaf, MPI.REPLACE)
    finally:
        unit.Free()
    return leaf


def distribute_mesh(scene, comm):
    """Build, label and distribute the scene's mesh; return this rank's LocalMesh."""
    check_size(scene, comm)
    gm = on_root(comm, lambda: build_global_mesh(scene))
    header = comm.bcast((gm.cell_type, gm.surface_names, len(gm.points), len(gm.cells), gm.piece_names,
                         gm.body_sources, gm.unusable)
                        if comm.rank == 0 else None, root=0)
    cell_type, surface_names, n_vertices, n_cells, piece_names, body_sources, unusable = header
    check_surface_references(scene, surface_names, unusable)
    nn = fem.CELL_NODES[cell_type]
    nf = len(fem.CELL_FACES[cell_type])

    if comm.rank == 0:
        cells = gm.cells.astype(PETSc.IntType)
        coords = gm.points
    else:
        cells = np.zeros((0, nn), dtype=PETSc.IntType)
        coords = np.zeros((0, 3))
    dm = PETSc.DMPlex().createFromCellList(3, cells, coords, interpolate=False, comm=comm)
    dm.setName("qsc_mesh")
    dm.setOptionsPrefix("qsc_")
    c0, c1 = dm.getHeightStratum(0)
    v0, v1 = dm.getDepthStratum(0)

    dm.createLabel("body")
    for name in surface_names:
        dm.createLabel(name)
    if comm.rank == 0:
        body_label = dm.getLabel("body")
        for b in range(len(scene.bodies)):
            ids = np.flatnonzero(gm.cell_body == b).astype(PETSc.IntType) + c0
            body_label.setStratumIS(b, PETSc.IS().createGeneral(ids, comm=PETSc.COMM_SELF))
        faced = np.flatnonzero(gm.face_mask.any(axis=1))        # the cells with a face on a named surface
        masks = gm.face_mask[faced]
        for bit, name in enumerate(surface_names):
            c, f = np.nonzero(masks & (np.int64(1) << np.int64(bit)))
            c = faced[c]
            verts = np.unique(fem.cell_faces(cell_type, gm.cells[c], f)).astype(PETSc.IntType) + v0
            dm.getLabel(name).setStratumIS(1, PETSc.IS().createGeneral(verts, comm=PETSc.COMM_SELF))

    pstart, pend = dm.getChart()
    root = np.full((pend - pstart, nn + nf + 3), -1, dtype=np.int64)
    if comm.rank == 0:
        root[c0:c1, :nn] = gm.cells
        root[c0:c1, nn:nn + nf] = gm.face_mask
        root[c0:c1, nn + nf] = gm.cell_body
        root[c0:c1, nn + nf + 1] = np.arange(n_cells)
        root[c0:c1, nn + nf + 2] = gm.cell_piece
        root[v0:v1, 0] = np.arange(n_vertices)

    partitioner = dm.getPartitioner()
    partitioner.setOptionsPrefix("qsc_")      # -qsc_petscpartitioner_type simple|ptscotch|parmetis|...
    chosen = option_value("petscpartitioner_type")
    if chosen == "shell":     # its partition comes through the API: PETSc stopped with error 62 inside distribute
        raise SceneError("-qsc_petscpartitioner_type: 'shell' takes its partition from a program, not an option; "
                         "leave the option out for qsc's coordinate bisection, or name ptscotch or simple")
    if comm.size > 1 and chosen is None:
        # the default: coordinate bisection of the cells, all of which start on rank 0
        if comm.rank == 0:
            bits = np.int64(0)
            for pair in scene.contact:
                for ref in (pair.slave, pair.master):
                    bits |= np.int64(1) << np.int64(surface_names.index(ref))
            part = coordinate_bisection(cell_centroids(gm.points, gm.cells), comm.size,
                                        contact=(gm.face_mask & bits).any(axis=1), cells=gm.cells)
            sizes, points = np.bincount(part, minlength=comm.size), np.argsort(part, kind="stable")
        else:
            sizes, points = np.zeros(comm.size), np.zeros(0)
        partitioner.setType(PETSc.Partitioner.Type.SHELL)
        partitioner.setShellPartition(comm.size, sizes.astype(PETSc.IntType), points.astype(PETSc.IntType))
    try:
        partitioner.setFromOptions()
        sf = dm.distribute() if comm.size > 1 else None
    except PETSc.Error as exc:
        if exc.ierr not in (56, 86):          # not supported / unknown type: the same on every rank
            raise
        raise SceneError(f"-qsc_petscpartitioner_type: {chosen!r} is not available in this PETSc "
                         f"(try ptscotch or simple)") from None
    if sf is not None:
        q0, q1 = dm.getChart()
        leaf = _bcast_points(sf, root, q1 - q0)
    else:
        leaf = root
    c0, c1 = dm.getHeightStratum(0)
    v0, v1 = dm.getDepthStratum(0)
    vert_orig = leaf[v0:v1, 0].copy()
    conn_orig = leaf[c0:c1, :nn]
    order = np.argsort(vert_orig)
    local_cells = order[np.searchsorted(vert_orig, conn_orig, sorter=order)]

    dm.setNumFields(1)                      # createSection counts the DM's fields: one, 3 components on vertices
    dm.setSection(dm.createSection([3], [3, 0, 0, 0]))
    dofs = dm.getLGMap().getIndices()
    gvert = np.asarray(dofs[0::3], dtype=np.int64) // 3

    owner = np.full(v1 - v0, comm.rank, dtype=np.int64)
    if comm.size > 1:                       # serially the point SF has no graph
        _, leaves, remote = dm.getPointSF().getGraph()
        ghost_v = np.asarray(leaves, dtype=np.int64) - v0
        is_vertex = (ghost_v >= 0) & (ghost_v < v1 - v0)
        owner[ghost_v[is_vertex]] = np.asarray(remote)[is_vertex, 0]
    owned = owner == comm.rank
    n_owned = int(owned.sum())
    vstart = comm.exscan(n_owned) or 0

    return LocalMesh(
        comm=comm, dm=dm, cell_type=cell_type,
        body_names=[b.name for b in scene.bodies], surface_names=surface_names,
        coords=dm.getCoordinatesLocal().getArray().reshape(-1, 3).copy(),
        cells=np.ascontiguousarray(local_cells), cell_body=leaf[c0:c1, nn + nf].copy(),
        cell_orig=leaf[c0:c1, nn + nf + 1].copy(), face_mask=leaf[c0:c1, nn:nn + nf].copy(),
        cell_piece=leaf[c0:c1, nn + nf + 2].copy(), piece_names=piece_names, body_sources=body_sources,
        vert_orig=vert_orig, gvert=gvert, owned=owned, owner=owner,
        n_vertices=n_vertices, n_cells=n_cells, vertex_range=(vstart, vstart + n_owned),
        partitioner=(chosen or "coordinate bisection") if comm.size > 1 else "none")
