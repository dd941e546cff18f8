"""Results on disk: XDMF/HDF5 fields per load step (rank 0 writes gathered data) and summary.json.

Fields are gathered to rank 0 in the original (rank-independent) vertex and cell numbering,
so files from runs on different numbers of ranks compare entry by entry. solution.xdmf is a
temporal collection for ParaView and meshio.xdmf.TimeSeriesReader; steps/step_NNNN.xdmf hold
one load step each, for meshio.read. Both are rewritten after every step: a run that stops
later keeps what it had written.
"""

import errno
import json
import os
import re
import textwrap
from pathlib import Path

import numpy as np

from .errors import OutputError
from .mesh import on_root

TOPOLOGY = {"hex": "Hexahedron", "tet": "Tetrahedron"}
ATTRIBUTE_TYPE = {1: "Scalar", 3: "Vector", 6: "Tensor6"}
# XDMF's Tensor6 holds a symmetric tensor as xx, xy, xz, yy, yz, zz, and readers take it so: VTK's XDMF reader
# (ParaView's; VTK 9.7) expands it to the full 3 x 3 in that order, and read the fields' Voigt order (xx, yy, zz, yz,
# xz, xy) with zz as xz
VOIGT_TO_TENSOR6 = [0, 5, 4, 1, 3, 2]


# what a run writes in its output folder: (name, is a folder)
RESULTS = (("summary.json", False), ("solution.h5", False), ("solution.xdmf", False), ("steps", True),
           ("scene.resolved.toml", False), ("petsc_options.txt", False))


def check_output_folder(directory):
    """An OutputError if the results cannot go into `directory` (which exists): a result's name taken by
    the other kind of entry, or a folder this process may not write in."""
    for name, folder in RESULTS:
        path = directory / name
        if path.exists() and path.is_dir() != folder:
            raise OutputError(f"output: {str(path)!r} is a {'folder' if path.is_dir() else 'file'}, where the "
                              f"results put a {'folder' if folder else 'file'}: choose another --out or move it")
    if not os.access(directory, os.W_OK | os.X_OK):
        raise OutputError(f"output: cannot write in {str(directory)!r}: permission denied")


ASIDE = ".cleared"         # an earlier result renamed aside, before all of them go (clear_results)


def clear_results(directory):
    """An earlier run's results in `directory` removed (rank 0, at a run's start): a run stopped in its set-up or
    first step, or one without XDMF output, left them beside its own, another scene's fields under this run's
    name. Only the names a run writes go (RESULTS, the step files, temporary files of an atomic write, and files
    a clearing cut short left aside). All or none: each is renamed aside before any goes."""
    steps = directory / "steps"
    names = dict(RESULTS)
    stale = [directory / name for name, folder in RESULTS if not folder]
    stale += [p for suffix in (".tmp", ASIDE) for p in directory.glob("*" + suffix)
              if p.name[:-len(suffix)] in names]
    if steps.is_dir():
        stale += [p for pattern in ("step_*.xdmf", "step_*.xdmf.tmp", "step_*.xdmf" + ASIDE)
                  for p in steps.glob(pattern)]
    stale = [path for path in stale if path.is_file()]
    # all or nothing: a steps/ folder this process may not change lost the earlier run's other results first, and
    # the run then stopped with no summary (hunt33_2)
    for path in stale:
        if not os.access(path.parent, os.W_OK | os.X_OK):
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(path))
    # a file that cannot go though its folder may be written (immutable, or another user's in a sticky folder)
    # did the same (hunt34_3): each is renamed aside first, and back if one cannot be
    aside = []
    try:
        for path in stale:
            if not path.name.endswith(ASIDE):
                path = path.rename(path.with_name(path.name + ASIDE))
            aside.append(path)
    except OSError:
        for path in reversed(aside):
            if path not in stale:
                path.rename(path.with_name(path.name[:-len(ASIDE)]))
        raise
    # a leftover twin (X.cleared beside X) was replaced by X's rename and is listed twice: once each
    for path in dict.fromkeys(aside):
        path.unlink()


def os_reason(exc):
    """An OSError's reason in one line: HDF5's holds its own account over two lines, a time stamp and the
    descriptors (a full disk at solution.h5, hunt34_3), of which the system's message is what says why."""
    text = exc.strerror or str(exc)
    said = re.search(r"error message = '([^']*)'", text)
    if said:
        text = f"{text.split('(')[0].strip()} ({said.group(1)})"
    return " ".join(text.split())


def write_on_root(comm, path, fn):
    """fn() on rank 0, which writes `path`; an OSError there becomes the same OutputError on every rank, so that
    all fail together (collective)."""
    def guarded():
        try:
            return fn()
        except OSError as exc:
            raise OutputError(f"output: cannot write {str(exc.filename or path)!r}: {os_reason(exc)}") from None
    return on_root(comm, guarded)


def gather_rows(comm, ids, values, n_total):
    """Rows of `values` keyed by global ids, gathered into one (n_total, ...) array on rank 0."""
    parts = comm.gather((np.asarray(ids), np.asarray(values)), root=0)
    if comm.rank != 0:
        return None
    shape = parts[0][1].shape[1:]
    dtype = np.result_type(*[p[1].dtype for p in parts])
    out = np.zeros((n_total,) + shape, dtype=dtype)
    for i, v in parts:
        out[i] = v
    return out


class ResultWriter:
    """Writes the mesh once and one group of fields per load step."""

    def __init__(self, mesh, directory, write_xdmf=True):
        self.mesh, self.comm = mesh, mesh.comm
        self.directory = Path(directory)
        self.enabled = write_xdmf
        self.grids = {}          # step -> its grid in solution.xdmf's collection, in the order written
        self.own_v = np.flatnonzero(mesh.owned)
        if not self.enabled:
            return
        points = gather_rows(self.comm, mesh.vert_orig[self.own_v], mesh.coords[self.own_v], mesh.n_vertices)
        cells = gather_rows(self.comm, mesh.cell_orig, mesh.vert_orig[mesh.cells], mesh.n_cells)

        def write():
            import h5py
            (self.directory / "steps").mkdir(parents=True, exist_ok=True)
            with h5py.File(self.directory / "solution.h5", "w") as h5:
                h5["mesh/geometry"] = points
                h5["mesh/topology"] = cells
            self.shape = (len(points), cells.shape)
        write_on_root(self.comm, self.directory / "solution.h5", write)

    def write_step(self, step, time, point_data, cell_data):
        """point_data: name -> (local vertices, k) arrays; cell_data: name -> (local cells, k) arrays, those of 6
        components symmetric tensors in Voigt order (xx, yy, zz, yz, xz, xy), written in XDMF's (xx, xy, xz, yy, yz,
        zz)."""
        if not self.enabled:
            return
        mesh = self.mesh
        gathered = {}
        for name, arr in point_data.items():
            gathered[("Node", name)] = gather_rows(self.comm, mesh.vert_orig[self.own_v],
                                                   np.asarray(arr)[self.own_v], mesh.n_vertices)
        for name, arr in cell_data.items():
            arr = np.asarray(arr)
            gathered[("Cell", name)] = gather_rows(self.comm, mesh.cell_orig,
                                                   arr[:, VOIGT_TO_TENSOR6] if arr.shape[1:] == (6,) else arr,
                                                   mesh.n_cells)

        def write():
            import h5py
            with h5py.File(self.directory / "solution.h5", "a") as h5:
                for (_, name), data in gathered.items():
                    key = f"step_{step:04d}/{name}"
                    if key in h5:
                        del h5[key]
                    h5[key] = data
            fields = [(center, name, data.shape) for (center, name), data in gathered.items()]
            self.grids.pop(step, None)
            self.grids[step] = self._grid(step, time, fields, "solution.h5")
            self._write_xml(step, time, fields)
        write_on_root(self.comm, self.directory / "solution.h5", write)

    def _grid(self, step, time, fields, h5path, with_time=True):
        n_points, (n_cells, k) = self.shape
        kind = TOPOLOGY[self.mesh.cell_type]
        lines = [f'<Grid Name="step_{step:04d}" GridType="Uniform">'] + ([f'<Time Value="{time!r}"/>'] if with_time else [])
        lines += [
            f'<Topology TopologyType="{kind}" NumberOfElements="{n_cells}">',
            (f'<DataItem Dimensions="{n_cells} {k}" NumberType="Int" Precision="8" Format="HDF">'
             f'{h5path}:/mesh/topology</DataItem></Topology>'),
            '<Geometry GeometryType="XYZ">',
            (f'<DataItem Dimensions="{n_points} 3" NumberType="Float" Precision="8" Format="HDF">'
             f'{h5path}:/mesh/geometry</DataItem></Geometry>')]
        for center, name, shape in fields:
            width = shape[1] if len(shape) > 1 else 1
            dims = " ".join(str(s) for s in shape)
            lines.append(f'<Attribute Name="{name}" AttributeType="{ATTRIBUTE_TYPE.get(width, "Matrix")}" '
                         f'Center="{center}"><DataItem Dimensions="{dims}" NumberType="Float" Precision="8" '
                         f'Format="HDF">{h5path}:/step_{step:04d}/{name}</DataItem></Attribute>')
        lines.append("</Grid>")
        return "\n".join(lines)

    def _write_xml(self, step, time, fields):
        """solution.xdmf's collection of every step so far, and the new step's own file: the earlier steps' files
        stand (each step rewrote them all: 250 steps of an 8-cell block spent 122 s writing, 0.46 s solving;
        hunt33_2)."""
        head = '<?xml version="1.0"?>\n<Xdmf Version="3.0">\n<Domain>\n'
        tail = "\n</Domain>\n</Xdmf>\n"
        _atomic_write(self.directory / "solution.xdmf",
                      head + '<Grid Name="load_steps" GridType="Collection" CollectionType="Temporal">\n'
                      + "\n".join(self.grids.values()) + "\n</Grid>" + tail)
        _atomic_write(self.directory / "steps" / f"step_{step:04d}.xdmf",
                      head + self._grid(step, time, fields, "../solution.h5", with_time=False) + tail)


def _atomic_write(path, text):
    """`text` into `path` through a temporary file beside it, renamed over it; an OSError names `path`."""
    tmp = Path(f"{path}.tmp")
    tmp.write_text(text)
    try:
        os.replace(tmp, path)
    except OSError as exc:          # e.g. a folder where the file goes: name it, not the temporary file
        tmp.unlink(missing_ok=True)
        raise OSError(exc.errno, exc.strerror, str(path)) from None


def write_json(path, data, steps_cache=None):
    """Write JSON atomically (rank 0 only is the caller's business). steps_cache (a list, kept by the caller between
    calls): data["steps"]'s records are encoded once, a finished step's record being final, so that a summary
    written after every load step costs its new step's encoding, not every step's again (hunt33_2: 150 steps spent
    5.7 s encoding). The text is json.dumps(data, indent=2)'s."""
    steps = data.get("steps") if steps_cache is not None else None
    if not isinstance(steps, list) or not steps:
        _atomic_write(Path(path), json.dumps(data, indent=2, default=_jsonable) + "\n")
        return
    while steps_cache and (len(steps_cache) > len(steps) or steps_cache[-1][0] is not steps[len(steps_cache) - 1]):
        steps_cache.pop()
    for record in steps[len(steps_cache):]:
        steps_cache.append((record, textwrap.indent(json.dumps(record, indent=2, default=_jsonable), "    ")))
    mark = "\0steps\0"
    text = json.dumps({**data, "steps": mark}, indent=2, default=_jsonable)
    block = "[\n" + ",\n".join(t for _, t in steps_cache) + "\n  ]"
    _atomic_write(Path(path), text.replace(json.dumps(mark), block, 1) + "\n")


def _jsonable(x):
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    raise TypeError(f"not JSON serialisable: {type(x)}")
