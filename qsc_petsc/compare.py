"""Comparison of a finished run with a reference run, on possibly different meshes: displacement, energy, contact errors.

Pure NumPy plus h5py (no PETSc, no MPI). A run folder is read as output.py writes it
(solution.h5 in the original numbering, summary.json, scene.resolved.toml). The run's
quadrature points are located in the reference mesh -- only in cells of the body the point
belongs to, so points on an interface between two bodies are not ambiguous -- and the
reference displacement and its gradient are interpolated there:

* ``displacement_l2``: ||u - u_ref||_L2 / ||u_ref||_L2 over the run's mesh;
* ``energy``: sqrt(a(u - u_ref, u - u_ref) / a(u_ref, u_ref)), a the strain-energy form with the
  run's materials, over the run's mesh;
* per contact pair and die (matched by index, ``contact[0]``, ``die[1]``): relative differences of
  the total force and of the largest penetration, from summary.json;
* ``traction``: relative RMS difference of ``contact_traction`` at the run's contact nodes (those
  with ``contact_status >= 0``) against the reference traction sampled there.
"""

import json
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import elasticity, fem
from .errors import QscError

CELL_TYPE = {8: "hex", 4: "tet"}
# the run-side quadrature: 27 points on each of 8 sub-cells of a cell. 27 points on the cell are exact for the
# products of trilinear/linear fields on one mesh, but the reference's kinks cross the run's cells: against a
# reference refined 2x, whose faces lie on the run cells' middle planes, they read the L2 and energy errors 16 %
# and 7 % high (hunt32_3); the sub-cells make that case exact and others closer (9 against 12 cells: -0.6 % and
# +0.9 % before)
SUBCELLS = 2
RULE = {"hex": fem.gauss_hex(3, SUBCELLS), "tet": fem.gauss_tet(3, SUBCELLS)}
CHUNK = 256           # run cells per vectorised batch (216 points each)
INSIDE_TOL = 1e-10    # a point within this fraction of the mesh size of a cell is inside it
NEWTON_MAX = 30


@dataclass
class Result:
    """One load step of a finished run: mesh, fields, summary and resolved scene."""

    path: Path
    step: int                           # load step number (1-based) of the fields
    cell_type: str
    points: np.ndarray                  # (n, 3) undeformed coordinates, m
    cells: np.ndarray                   # (m, k) vertex ids
    point_data: dict = field(default_factory=dict)
    cell_data: dict = field(default_factory=dict)
    summary: dict = field(default_factory=dict)
    scene: dict = field(default_factory=dict)
    theta: np.ndarray = field(default=None, repr=False)    # mean_dilatations, once computed

    @property
    def body_names(self):
        return [b["name"] for b in self.scene.get("bodies", [])] or list(self.summary.get("mesh", {}).get("bodies", []))

    @property
    def cell_body(self):
        return np.rint(self.cell_data["body"][:, 0]).astype(np.int64)

    def point_body(self):
        """Body index of every vertex (bodies never share vertices); -1 for a vertex of no cell."""
        out = np.full(len(self.points), -1, dtype=np.int64)
        out[self.cells] = self.cell_body[:, None]
        return out

    def step_record(self):
        """This step's entry of summary.json's steps, or {} if the summary has none."""
        for rec in self.summary.get("steps", []):
            if rec.get("step") == self.step:
                return rec
        return {}

    def lame(self):
        """Lame parameters (lmbda, mu) in Pa of every cell, from the resolved scene's materials."""
        mats = [b["material"] for b in self.scene["bodies"]]
        E = np.array([m["youngs_modulus"] for m in mats], float)
        nu = np.array([m.get("poissons_ratio", 0.3) for m in mats], float)
        lm, mu = elasticity.lame(E, nu)
        b = self.cell_body
        return lm[b], mu[b]

    def mean_bulk(self):
        """Per cell, the bulk modulus its body takes with the cell's mean dilatation (material.volumetric =
        "mean_dilatation"), else 0; None when no body does (assembly.cell_mean_bulk's)."""
        bulk = np.array([elasticity.mean_dilatation_bulk(m["youngs_modulus"], m.get("poissons_ratio", 0.3),
                                                         m.get("volumetric", "full"))
                         for m in (b["material"] for b in self.scene["bodies"])])
        return bulk[self.cell_body] if bulk.any() else None

    def mean_dilatations(self):
        """Each cell's mean dilatation (elasticity.mean_dilatation), computed once."""
        if self.theta is None:
            u = self.point_data["displacement"]
            self.theta = np.concatenate([
                elasticity.mean_dilatation(self.cell_type, self.points[self.cells[s:s + CHUNK]],
                                           u[self.cells[s:s + CHUNK]].reshape(len(self.cells[s:s + CHUNK]), -1))
                for s in range(0, len(self.cells), CHUNK)]) if len(self.cells) else np.zeros(0)
        return self.theta


def available_steps(path):
    """Load step numbers stored in a run folder's solution.h5, ascending."""
    import h5py
    h5file = Path(path) / "solution.h5"
    if not h5file.is_file():
        raise QscError(f"{path}: no solution.h5 (not a run folder, or a run with output.xdmf = false)")
    with h5py.File(h5file, "r") as h5:
        return sorted(int(k[5:]) for k in h5 if k.startswith("step_"))


def load_result(path, step=-1):
    """Read a run folder: `step` is a load step number (1, 2, ...) or a negative index (-1: the last step written)."""
    import h5py
    path = Path(path)
    steps = available_steps(path)
    if not steps:
        raise QscError(f"{path}: solution.h5 holds no load step")
    if step < 0:
        if -step > len(steps):
            raise QscError(f"{path}: step {step}: only {len(steps)} load step(s) written")
        step = steps[step]
    elif step not in steps:
        raise QscError(f"{path}: no load step {step} (written: {', '.join(map(str, steps))})")
    with h5py.File(path / "solution.h5", "r") as h5:
        points = h5["mesh/geometry"][...]
        cells = h5["mesh/topology"][...].astype(np.int64)
        group = h5[f"step_{step:04d}"]
        data = {name: group[name][...] for name in group}
    data = {k: (v[:, None] if v.ndim == 1 else v) for k, v in data.items()}
    if cells.shape[1] not in CELL_TYPE:
        raise QscError(f"{path}: cells with {cells.shape[1]} nodes (expected 8 for hex or 4 for tet)")
    centers = _centers(path, step)
    at_nodes = {k: centers[k] == "Node" if k in centers else len(v) == len(points) for k, v in data.items()}
    point_data = {k: v for k, v in data.items() if at_nodes[k]}
    cell_data = {k: v for k, v in data.items() if not at_nodes[k]}
    summary = json.loads((path / "summary.json").read_text()) if (path / "summary.json").is_file() else {}
    scene_file = path / "scene.resolved.toml"
    if not scene_file.is_file():
        raise QscError(f"{path}: no scene.resolved.toml (the materials come from it)")
    scene = tomllib.loads(scene_file.read_text())
    for name, where in (("displacement", point_data), ("body", cell_data)):
        if name not in where:
            raise QscError(f"{path}: step {step} has no field {name!r}")
    return Result(path, step, CELL_TYPE[cells.shape[1]], points, cells, point_data, cell_data, summary, scene)


def _centers(path, step):
    """{field name: "Node" or "Cell"} from the step's XDMF file ({} if it is missing)."""
    xdmf = path / "steps" / f"step_{step:04d}.xdmf"
    if not xdmf.is_file():
        return {}
    text = xdmf.read_text()
    return dict(re.findall(r'<Attribute Name="([^"]+)"[^>]*Center="(Node|Cell)"', text))


# ---------------------------------------------------------------- point location

def _reference_coords(cell_type, xe, p):
    """Reference coordinates (n, 3) of points p (n, 3) in cells xe (n, k, 3): direct for tets, Newton for hexes.

    Outside a hex the Newton iterate is an extrapolation; it is bounded, so a far candidate cell
    gives a large distance rather than NaN."""
    if cell_type == "tet":
        A = (xe[:, 1:] - xe[:, :1]).transpose(0, 2, 1)
        return np.linalg.solve(A, (p - xe[:, 0])[..., None])[..., 0]
    xi = np.zeros_like(p)
    todo = np.arange(len(p))
    for _ in range(NEWTON_MAX):
        N, dN = fem.shape_hex(xi[todo])
        todo_xe = xe[todo]
        x = np.matmul(N[:, None, :], todo_xe)[:, 0]
        J = np.matmul(todo_xe.transpose(0, 2, 1), dN)               # d x_i / d xi_k
        step = np.linalg.solve(J, (x - p[todo])[..., None])[..., 0]
        xi[todo] = np.clip(xi[todo] - step, -3.0, 3.0)
        todo = todo[np.abs(step).max(axis=1) > 1e-13]               # xi is O(1): round-off is ~1e-16
        if not len(todo):
            break
    return xi


def _clamp(cell_type, xi):
    """The reference point nearest to xi inside the reference cell (tets: barycentrics clipped and renormalised)."""
    if cell_type == "hex":
        return np.clip(xi, -1.0, 1.0)
    lam = np.column_stack([1.0 - xi.sum(axis=1), xi])
    lam = np.clip(lam, 0.0, None)
    return lam[:, 1:] / lam.sum(axis=1, keepdims=True)


class Locator:
    """A bucket grid over the cells' bounding boxes; finds, for points of a given body, a cell of that body and xi."""

    def __init__(self, result):
        self.result = result
        self.cell_type = result.cell_type
        self.xe = result.points[result.cells]                       # (m, k, 3)
        self.body = result.cell_body
        lo, hi = self.lo, self.hi = self.xe.min(axis=1), self.xe.max(axis=1)
        span = float(np.ptp(result.points, axis=0).max()) or 1.0
        self.tol = INSIDE_TOL * span
        m = len(self.xe)
        h = max(float(np.median((hi - lo).max(axis=1))), 1e-12 * span)
        self.origin = result.points.min(axis=0)
        dims = np.floor((result.points.max(axis=0) - self.origin) / h).astype(np.int64) + 1
        while dims.prod() > 8 * m + 64:           # a few cells per bucket at most, whatever the aspect ratio
            h *= 1.5
            dims = np.floor((result.points.max(axis=0) - self.origin) / h).astype(np.int64) + 1
        self.h, self.dims = h, dims
        i0 = self._index(lo - self.tol)
        i1 = self._index(hi + self.tol)
        n = i1 - i0 + 1                                               # buckets per direction, per cell
        count = n.prod(axis=1)
        cell = np.repeat(np.arange(m), count)
        r = np.arange(len(cell)) - np.repeat(np.cumsum(count) - count, count)
        nc = n[cell]
        ijk = i0[cell] + np.column_stack([r % nc[:, 0], (r // nc[:, 0]) % nc[:, 1], r // (nc[:, 0] * nc[:, 1])])
        bucket = self._flat(ijk)
        order = np.argsort(bucket, kind="stable")
        self.bucket_cells = cell[order]
        self.starts = np.searchsorted(bucket[order], np.arange(dims.prod() + 1))

    def _index(self, x):
        return np.clip(np.floor((x - self.origin) / self.h).astype(np.int64), 0, self.dims - 1)

    def _flat(self, ijk):
        return (ijk[:, 2] * self.dims[1] + ijk[:, 1]) * self.dims[0] + ijk[:, 0]

    def _candidates(self, x, body, ring):
        """(point, cell) pairs: cells of the point's body in the buckets within `ring` of the point's bucket."""
        base = np.floor((x - self.origin) / self.h).astype(np.int64)     # unclipped: far points find nothing
        pts, cells = [], []
        offsets = np.array([(a, b, c) for c in range(-ring, ring + 1) for b in range(-ring, ring + 1)
                            for a in range(-ring, ring + 1)])
        for off in offsets:
            ijk = base + off
            ok = ((ijk >= 0) & (ijk < self.dims)).all(axis=1)
            p = np.flatnonzero(ok)
            b = self._flat(ijk[ok])
            s, e = self.starts[b], self.starts[b + 1]
            cnt = e - s
            pp = np.repeat(p, cnt)
            cc = self.bucket_cells[np.repeat(s, cnt) + np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)]
            same = self.body[cc] == body[pp]
            pts.append(pp[same])
            cells.append(cc[same])
        pp, cc = np.concatenate(pts), np.concatenate(cells)
        if ring > 0:                                   # a cell spans several buckets: keep each pair once
            key = np.unique(pp.astype(np.int64) * len(self.xe) + cc)
            pp, cc = key // len(self.xe), key % len(self.xe)
        return pp, cc

    def locate(self, x, body):
        """Cell (n,), clamped reference coordinates xi (n, 3) and distance (n,) in m of points x (n, 3) of bodies body (n,).

        A point outside every cell of its body (a faceted curved boundary meshed differently) gets the
        nearest candidate cell and the nearest point in it; one farther than a bucket from every cell of
        its body is an error: the two meshes do not describe the same bodies."""
        x = np.asarray(x, float)
        n = len(x)
        cell = np.full(n, -1, dtype=np.int64)
        xi = np.zeros((n, 3))
        dist = np.full(n, np.inf)
        todo = np.arange(n)
        for ring in (0, 1):
            if not len(todo):
                break
            pp, cc = self._candidates(x[todo], body[todo], ring)
            if ring == 0:                              # cheap bounding-box test first
                p = x[todo][pp]
                inside = ((self.lo[cc] - self.tol <= p) & (p <= self.hi[cc] + self.tol)).all(axis=1)
                pp, cc = pp[inside], cc[inside]
            if len(pp):
                p = x[todo][pp]
                xr = _clamp(self.cell_type, _reference_coords(self.cell_type, self.xe[cc], p))
                N, _ = fem.SHAPE[self.cell_type](xr)
                d = np.linalg.norm(np.matmul(N[:, None, :], self.xe[cc])[:, 0] - p, axis=1)
                order = np.lexsort((d, pp))
                first = order[np.unique(pp[order], return_index=True)[1]]
                q = todo[pp[first]]
                better = d[first] < dist[q]
                q, first = q[better], first[better]
                cell[q], xi[q], dist[q] = cc[first], xr[first], d[first]
            todo = todo[dist[todo] > self.tol]
        missing = np.flatnonzero(cell < 0)
        if len(missing):
            i = missing[0]
            name = self.result.body_names[body[i]] if body[i] < len(self.result.body_names) else body[i]
            raise QscError(f"point {x[i].tolist()} of body {name!r} is not within a cell of the same body in "
                           f"{self.result.path} ({len(missing)} such points): the runs do not mesh the same bodies")
        return cell, xi, dist

    def values(self, name, cell, xi):
        """Point field `name` interpolated at (cell, xi): (n, k)."""
        N, _ = fem.SHAPE[self.cell_type](xi)
        f = self.result.point_data[name][self.result.cells[cell]]     # (n, nodes, k)
        return np.einsum("pa,pak->pk", N, f)

    def gradient(self, name, cell, xi):
        """Gradient d f_i / d x_k (n, k, 3) of point field `name` at (cell, xi)."""
        _, dN = fem.SHAPE[self.cell_type](xi)
        xe = self.xe[cell]
        J = np.einsum("pai,pak->pik", xe, dN)                         # d x_i / d xi_k
        G = np.linalg.solve(J.transpose(0, 2, 1), dN.transpose(0, 2, 1)).transpose(0, 2, 1)   # d N_a / d x
        f = self.result.point_data[name][self.result.cells[cell]]
        return np.einsum("pai,pak->pki", G, f)


# ---------------------------------------------------------------- errors

def _voigt_strain(grad):
    """Engineering Voigt strains (n, 6) (xx, yy, zz, yz, xz, xy) of displacement gradients (n, 3, 3)."""
    g = grad
    return np.column_stack([g[:, 0, 0], g[:, 1, 1], g[:, 2, 2], g[:, 1, 2] + g[:, 2, 1],
                            g[:, 0, 2] + g[:, 2, 0], g[:, 0, 1] + g[:, 1, 0]])


def _energy_density(eps, lmbda, mu):
    """eps : D eps (n,) for Voigt strains (n, 6) and Lame parameters (n,)."""
    tr = eps[:, :3].sum(axis=1)
    return lmbda * tr ** 2 + 2.0 * mu * (eps[:, :3] ** 2).sum(axis=1) + mu * (eps[:, 3:] ** 2).sum(axis=1)


def _body_map(run, reference):
    """Reference body index of each run body, matched by name."""
    ref_names = reference.body_names
    out = []
    for name in run.body_names:
        if name not in ref_names:
            raise QscError(f"body {name!r} of {run.path} is not in the reference {reference.path} "
                           f"(bodies: {', '.join(ref_names)})")
        out.append(ref_names.index(name))
    return np.array(out, dtype=np.int64)


def same_mesh(run, reference):
    """True if both results hold the same mesh (then points need no search: cell c is cell c)."""
    return (run.points.shape == reference.points.shape and run.cells.shape == reference.cells.shape
            and np.array_equal(run.points, reference.points) and np.array_equal(run.cells, reference.cells)
            and np.array_equal(run.cell_body, reference.cell_body) and run.body_names == reference.body_names)


def field_errors(run, reference, locator=None):
    """Displacement L2 and energy-norm errors of `run` against `reference`, integrated over the run's mesh."""
    loc = locator or Locator(reference)
    identical = same_mesh(run, reference)
    to_ref = _body_map(run, reference)
    xi_q, w_q = RULE[run.cell_type]
    N_q, _ = fem.SHAPE[run.cell_type](xi_q)
    lmbda, mu = run.lame()
    # a mean-dilatation body's strain takes its cell's mean dilatation as its volumetric part, as its energy does:
    # the pointwise one, weighted by a nearly incompressible body's bulk modulus, read a run 0.06 % off as 78 % off
    # in energy and a locked one 50 % off as 64 % (hunt33_4)
    kappa, kappa_ref = run.mean_bulk(), reference.mean_bulk()
    u_all = run.point_data["displacement"]
    sums = {"e2": 0.0, "r2": 0.0, "ee": 0.0, "er": 0.0}
    n_outside, worst = 0, 0.0
    body = run.cell_body
    for s in range(0, len(run.cells), CHUNK):
        c = np.arange(s, min(s + CHUNK, len(run.cells)))
        xe = run.points[run.cells[c]]
        ue = u_all[run.cells[c]]                                     # (m, k, 3)
        B, detJ = elasticity.strain_displacement(run.cell_type, xe, xi_q)
        wq = (detJ * w_q).ravel()                                     # (m * nq,)
        xq = np.einsum("qa,mai->mqi", N_q, xe).reshape(-1, 3)
        uq = np.einsum("qa,mai->mqi", N_q, ue).reshape(-1, 3)
        eps = (B @ ue.reshape(len(c), -1)[:, None, :, None])[..., 0].reshape(-1, 6)
        if identical:     # the same arithmetic on both sides: identical runs compare to exactly 0
            ue_ref = reference.point_data["displacement"][run.cells[c]]
            u_ref = np.einsum("qa,mai->mqi", N_q, ue_ref).reshape(-1, 3)
            eps_ref = (B @ ue_ref.reshape(len(c), -1)[:, None, :, None])[..., 0].reshape(-1, 6)
            cell = np.repeat(c, len(w_q))
        else:
            cell, xr, dist = loc.locate(xq, np.repeat(to_ref[body[c]], len(w_q)))
            n_outside += int((dist > loc.tol).sum())
            worst = max(worst, float(dist.max(initial=0.0)))
            u_ref = loc.values("displacement", cell, xr)
            eps_ref = _voigt_strain(loc.gradient("displacement", cell, xr))
        if kappa is not None:
            at = np.repeat(kappa[c] > 0, len(w_q))
            eps[at] = elasticity.with_mean_dilatation(eps[at], np.repeat(run.mean_dilatations()[c], len(w_q))[at])
        if kappa_ref is not None:
            at = kappa_ref[cell] > 0
            eps_ref[at] = elasticity.with_mean_dilatation(eps_ref[at], reference.mean_dilatations()[cell[at]])
        lm, m_ = np.repeat(lmbda[c], len(w_q)), np.repeat(mu[c], len(w_q))
        sums["e2"] += float(wq @ ((uq - u_ref) ** 2).sum(axis=1))
        sums["r2"] += float(wq @ (u_ref ** 2).sum(axis=1))
        sums["ee"] += float(wq @ _energy_density(eps - eps_ref, lm, m_))
        sums["er"] += float(wq @ _energy_density(eps_ref, lm, m_))
    return {"displacement_l2": _ratio(sums["e2"], sums["r2"]), "energy": _ratio(sums["ee"], sums["er"]),
            "outside_points": n_outside, "max_outside_distance": worst}


def _ratio(num, den):
    if den > 0:
        return float(np.sqrt(num / den))
    return 0.0 if num == 0 else float("inf")


def strain_energy(result):
    """Strain energy 1/2 a(u, u) in J of a result with its own materials, on its own mesh."""
    lmbda, mu = result.lame()
    kappa = result.mean_bulk()
    u = result.point_data["displacement"]
    total = 0.0
    for s in range(0, len(result.cells), CHUNK):
        c = slice(s, s + CHUNK)
        xe = result.points[result.cells[c]]
        ue = u[result.cells[c]].reshape(len(xe), -1)
        total += float(elasticity.strain_energy(result.cell_type, xe, ue, lmbda[c], mu[c],
                                                None if kappa is None else kappa[c]).sum())
    return total


def traction_error(run, reference, locator=None):
    """Relative RMS difference of contact_traction at the run's contact nodes (contact_status >= 0), or None."""
    needed = ("contact_traction", "contact_status")
    if not all(k in run.point_data for k in needed) or "contact_traction" not in reference.point_data:
        return None
    nodes = np.flatnonzero(run.point_data["contact_status"][:, 0] >= 0)
    if not len(nodes):
        return None
    if same_mesh(run, reference):
        t_ref = reference.point_data["contact_traction"][nodes, 0]
    else:
        loc = locator or Locator(reference)
        body = _body_map(run, reference)[run.point_body()[nodes]]
        cell, xr, _ = loc.locate(run.points[nodes], body)
        t_ref = loc.values("contact_traction", cell, xr)[:, 0]
    t = run.point_data["contact_traction"][nodes, 0]
    return _ratio(float(((t - t_ref) ** 2).sum()), float((t_ref ** 2).sum()))


def _rel(a, b):
    a, b = np.atleast_1d(np.asarray(a, float)), np.atleast_1d(np.asarray(b, float))
    den = np.linalg.norm(b)
    num = np.linalg.norm(a - b)
    return float(num / den) if den > 0 else (0.0 if num == 0 else float("inf"))


def _interactions(record):
    """{"contact[i]" or "die[i]": (force vector in N, largest penetration in m, (slave, master) or None)} of a
    summary step record (a pair's key: "contact[i] slave / master")."""
    out = {}
    for key, entry in record.get("contact", {}).items():
        tag, _, surfaces = key.partition(" ")
        if tag.startswith("contact["):
            pen = _largest(entry.get("max_penetration_slave"), entry.get("max_penetration_master"))
            out[tag] = (entry["force_on_slave"], pen, tuple(part.strip() for part in surfaces.split(" / ")))
        else:
            out[tag] = (entry["force_on_bodies"], entry.get("max_penetration"), None)
    return out


def _largest(*values):
    """The largest of the values that are there (None: no node faced the other surface), or None."""
    there = [v for v in values if v is not None]
    return max(there) if there else None


def contact_errors(run, reference):
    """Per contact pair and die present in both: relative differences of the total force and the largest penetration."""
    mine, theirs = _interactions(run.step_record()), _interactions(reference.step_record())
    out = {}
    for tag in sorted(set(mine) & set(theirs)):
        (f, p, roles), (f_ref, p_ref, roles_ref) = mine[tag], theirs[tag]
        if roles is not None and roles_ref is not None and roles == roles_ref[::-1] and roles != roles_ref:
            # the pair with slave and master swapped: its force on the slave is the reference's on its master,
            # the reference's own force reversed (a 200 % error on the same answer; hunt32_3)
            f = [-x for x in f]
        out[tag] = {"force": _rel(f, f_ref), "max_penetration": None if p is None or p_ref is None else _rel(p, p_ref),
                    "force_value": list(f), "force_reference": list(f_ref),
                    "max_penetration_value": p, "max_penetration_reference": p_ref}
    return out


def errors(run, reference):
    """Every error of `run` against `reference` (Result objects or run folders, last load step), as a flat-ish dict.

    Keys: displacement_l2, energy (relative), strain_energy and strain_energy_reference (J, each with its
    own materials and mesh), traction (relative RMS or None), contact ({tag: {force, max_penetration,
    ...}}), force and max_penetration (largest relative difference over pairs and dies, or None),
    outside_points and max_outside_distance (m: run points that are in no reference cell of their body).
    """
    run = run if isinstance(run, Result) else load_result(run)
    reference = reference if isinstance(reference, Result) else load_result(reference)
    loc = Locator(reference)
    out = field_errors(run, reference, loc)
    out["strain_energy"] = strain_energy(run)
    out["strain_energy_reference"] = strain_energy(reference)
    out["traction"] = traction_error(run, reference, loc)
    out["contact"] = contact_errors(run, reference)
    for key in ("force", "max_penetration"):
        out[key] = _largest(*(v[key] for v in out["contact"].values()))
    out["step"], out["reference_step"] = run.step, reference.step
    return out
