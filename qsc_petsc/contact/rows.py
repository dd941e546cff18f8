"""Constraint rows C_r = G_r . u - g_r and weights W_r of each contact formulation, as triplets with global ids.

Pure NumPy (formulation.md sections 3, 7 and 8). A "pass" integrates surface S
against surface T with some quadrature of S: points x_q with weights w_q (the S
nodes with their tributary areas for nodal quadrature, Gauss points, or the
pieces of S faces cut by T faces for segment integration), each projected on a
T face, with the penetration

    h_q = -(u_S(x_q) - sum_j N_T^j(xi_q) u_T^j) . n_T - delta0_q,

n_T the T face's own outward normal at xi_q, frozen between two searches.
R_S = Phi_S^T diag(w) H tests h_q with S's shape functions at x_q (pass_rows),
R_T = Phi_T^T diag(w) H with T's shape functions at the projection
(_spread_rows). The row of a node constraint of vertex v is dof 3 v (component
slot 0); sticking die rows also use 3 v + 1 and 3 v + 2. The caller adds the
triplets into a distributed matrix (duplicates are summed), so rows may belong
to any rank.
"""

from dataclasses import dataclass, field

import numpy as np

from ..sparsity import row_spans
from .search import found_entries

_I = np.int64


def _ints(n=0):
    return np.zeros(n, dtype=_I)


@dataclass
class Rows:
    """Triplets of G (rows x dofs), g and W (by row) and the factor phi of one contact formulation.

    Rows listed in gate_rows are equalities active iff the row gate_of (same
    position) is active; all other rows are inequalities <C_r>_+.
    """
    G_rows: np.ndarray
    G_cols: np.ndarray
    G_vals: np.ndarray
    g_rows: np.ndarray
    g_vals: np.ndarray
    W_rows: np.ndarray
    W_vals: np.ndarray
    phi: float
    gate_rows: np.ndarray = field(default_factory=_ints)
    gate_of: np.ndarray = field(default_factory=_ints)

    @staticmethod
    def empty(phi=1.0):
        z = np.zeros(0)
        return Rows(_ints(), _ints(), z, _ints(), z, _ints(), z, float(phi))

    def with_unit_phi(self):
        """The same constraints with phi folded into G, g and W (phi = 1).

        Scaling C_r and W_r by phi leaves the multipliers eps <C_r>_+ / W_r, the
        penalty energy, force and Jacobian, and sum phi W unchanged.
        """
        s = float(self.phi)
        return Rows(self.G_rows, self.G_cols, s * self.G_vals, self.g_rows, s * self.g_vals,
                    self.W_rows, s * self.W_vals, 1.0, self.gate_rows, self.gate_of)

    @staticmethod
    def concat(a, b):
        """Rows of a and b together; if their phi differ, phi is first folded into each (with_unit_phi)."""
        if a.phi != b.phi:
            a, b = a.with_unit_phi(), b.with_unit_phi()
        cat = np.concatenate
        return Rows(cat([a.G_rows, b.G_rows]), cat([a.G_cols, b.G_cols]), cat([a.G_vals, b.G_vals]),
                    cat([a.g_rows, b.g_rows]), cat([a.g_vals, b.g_vals]),
                    cat([a.W_rows, b.W_rows]), cat([a.W_vals, b.W_vals]), a.phi,
                    cat([a.gate_rows, b.gate_rows]), cat([a.gate_of, b.gate_of]))


@dataclass
class Pass:
    """Quadrature points of a surface S projected on faces of a surface T (global vertex ids), one entry per point.

    Nodal quadrature: each point is an S node (source_nodes (p, 1), source_shape 1,
    the default when they are not given) and area its tributary area.
    """
    node: np.ndarray            # (p,) global vertex id of the S node (for points: the S node nearest the point)
    area: np.ndarray            # (p,) quadrature weight w_q: area the point stands for on S  [m^2]
    size: np.ndarray            # (p,) local element size on S at the point  [m]
    target_nodes: np.ndarray    # (p, nv) global vertex ids of the T face it projects on
    shape: np.ndarray           # (p, nv) N_T(xi) at the projection
    normal: np.ndarray          # (p, 3) T's outward unit normal at xi
    delta0: np.ndarray          # (p,) initial gap (x_S - x_closest) . n, >= 0 when apart  [m]
    target_size: np.ndarray     # (p,) size of that T face  [m]
    source_nodes: np.ndarray = None   # (p, ns) global vertex ids of the S face holding the point
    source_shape: np.ndarray = None   # (p, ns) N_S at the point

    def __post_init__(self):
        self.node = np.asarray(self.node, dtype=_I).reshape(-1)
        p = len(self.node)
        self.target_nodes = np.asarray(self.target_nodes, dtype=_I)
        if self.target_nodes.ndim != 2 or len(self.target_nodes) != p:
            raise ValueError(f"Pass.target_nodes must have shape ({p}, nv), got {self.target_nodes.shape}")
        if self.source_nodes is None:
            self.source_nodes, self.source_shape = self.node[:, None], np.ones((p, 1))
        self.source_nodes = np.asarray(self.source_nodes, dtype=_I)
        if self.source_nodes.ndim != 2 or len(self.source_nodes) != p:
            raise ValueError(f"Pass.source_nodes must have shape ({p}, ns), got {self.source_nodes.shape}")
        nv, ns = self.target_nodes.shape[1], self.source_nodes.shape[1]
        expect = {"area": (p,), "size": (p,), "shape": (p, nv), "normal": (p, 3),
                  "delta0": (p,), "target_size": (p,), "source_shape": (p, ns)}
        for name, shp in expect.items():
            a = np.asarray(getattr(self, name), dtype=float)
            if a.shape != shp:
                raise ValueError(f"Pass.{name} must have shape {shp}, got {a.shape}")
            setattr(self, name, a)

    def subset(self, keep):
        """The pass of the points of the mask keep."""
        return Pass(**{name: getattr(self, name)[keep] for name in (
            "node", "area", "size", "target_nodes", "shape", "normal", "delta0", "target_size", "source_nodes",
            "source_shape")})

    @staticmethod
    def empty(ns, nv):
        """A pass without points, for S faces with ns nodes and T faces with nv nodes."""
        z = np.zeros(0)
        return Pass(node=_ints(), area=z, size=z, target_nodes=np.zeros((0, nv), dtype=_I), shape=np.zeros((0, nv)),
                    normal=np.zeros((0, 3)), delta0=z, target_size=z, source_nodes=np.zeros((0, ns), dtype=_I),
                    source_shape=np.zeros((0, ns)))

    @staticmethod
    def from_search(node, area, size, found, face_nodes, face_size):
        """The Pass of the points that found a face: found is search.closest_faces' dict for points `node`.

        face_nodes (m, nv) global vertex ids and face_size (m,) of the faces given to the search; a point's area
        is scaled by its edge_factor and shared among the faces at the same distance (search.found_entries).
        """
        q, e, part = found_entries(found, ("face", "shape", "normal", "signed_gap"))
        return Pass(node=np.asarray(node)[q], area=np.asarray(area)[q] * part, size=np.asarray(size)[q],
                    target_nodes=np.asarray(face_nodes)[e["face"]], shape=e["shape"], normal=e["normal"],
                    delta0=e["signed_gap"], target_size=np.asarray(face_size)[e["face"]])


def _pass_entries(pss):
    """Unscaled h_q of each point times w_q: the nodes of its columns (p, ns + nv) (columns 3 node + 0, 1, 2),
    values (p, 3 (ns + nv)), g (p,), W (p,)."""
    p, nv = pss.target_nodes.shape
    ns = pss.source_nodes.shape[1]
    nodes = np.concatenate([pss.source_nodes, pss.target_nodes], axis=1)               # (p, ns + nv)
    coef = np.concatenate([-pss.source_shape, pss.shape], axis=1)                      # dh/du along -N_S n / +N_T n
    vals = (pss.area[:, None, None] * coef[:, :, None] * pss.normal[:, None, :]).reshape(p, 3 * (ns + nv))
    return nodes, vals, pss.area * pss.delta0, pss.area.copy()


def _grouped_products(a, b, starts, counts):
    """The sum over each group's rows q of a[q] (outer) b[q], for rows sorted by group (group i: counts[i] rows from
    starts[i]): one batched product per group size, so no (rows, a, b) temporary (212k dofs, a segment pass
    of 45k points: 5 ms against 30 ms for the outer products summed with reduceat)."""
    out = np.empty((len(starts), a.shape[1], b.shape[1]))
    for size in np.unique(counts):
        groups = np.flatnonzero(counts == size)
        rows = starts[groups, None] + np.arange(size)
        out[groups] = np.matmul(a[rows].transpose(0, 2, 1), b[rows])
    return out


def _tested_rows(pss, scale, test_nodes, test_shape):
    """Point q's w_q h_q, times scale_q N^k, added to row 3 k for every test node k (test_nodes (p, nt)).

    The points of one (S face, T face) pair share their columns and test rows: their entries are summed
    here, one block per pair (per run of its points) and test node (segment integration has tens of points
    per pair, and the distributed matrix would otherwise receive and sum each entry that many times)."""
    nodes, vals, g, W = _pass_entries(pss)
    p = len(pss.node)
    ncol = vals.shape[1]
    f = np.broadcast_to(np.asarray(scale, dtype=float), (p,))[:, None] * test_shape   # (p, nt)
    if p == 0:
        return _ints(), _ints(), np.zeros(0), _ints(), np.zeros(0), _ints(), np.zeros(0)
    # a pair's points come together (a segment pass groups them by pair, a Gauss pass by S face): each run of
    # points with the same faces is summed; a pair met again in a later run is summed by the matrix's assembly
    # (np.unique over the rows found every repeat: 43 ms a run at 212k dofs against 3 ms)
    first = np.flatnonzero(np.r_[True, (nodes[1:] != nodes[:-1]).any(axis=1)])

    def summed(x):
        return np.add.reduceat(x, first, axis=0)

    Gv = _grouped_products(f, vals, first, np.diff(np.r_[first, p]))   # (runs, nt, ncol)
    gv, Wv, weight = summed(f * g[:, None]), summed(f * W[:, None]), summed(np.abs(f))
    keep = weight != 0.0       # N^k = 0 at every point (on an edge) or a zero weight adds nothing
    lk, kk = np.nonzero(keep)
    row = 3 * test_nodes[first[lk], kk]
    cols = (3 * nodes[first[lk], :, None] + np.arange(3, dtype=_I)).reshape(-1)
    return (np.repeat(row, ncol), cols, Gv[lk, kk].reshape(-1),
            row, gv[lk, kk], row.copy(), Wv[lk, kk])


def pass_rows(pss, scale):
    """R_S: scale * w_q h_q tested by S's shape functions at the point (nodal: A_k h_k on row 3 node_k)."""
    return _tested_rows(pss, scale, pss.source_nodes, pss.source_shape)


def _spread_rows(pss, scale):
    """R_T: scale * w_q h_q tested by T's shape functions at the projection, on the rows of the T face's nodes."""
    return _tested_rows(pss, scale, pss.target_nodes, pss.shape)


def _rows(parts, phi):
    G_r, G_c, G_v, g_r, g_v, W_r, W_v = (np.concatenate(x) for x in zip(*parts))
    return Rows(G_r.astype(_I), G_c.astype(_I), G_v, g_r.astype(_I), g_v, W_r.astype(_I), W_v, float(phi))


def master_slave(slave_pass):
    """One row per slave node k: A_k h_k (phi = 1)."""
    return _rows([pass_rows(slave_pass, 1.0)], 1.0)


def two_pass(slave_pass, master_pass):
    """One row per slave node (A_k h_k) and one per master node (B_l h_l), phi = 1/2."""
    return _rows([pass_rows(slave_pass, 1.0), pass_rows(master_pass, 1.0)], 0.5)


def with_nodal_rows(rows, passes, ids, extra=()):
    """rows with the rows of global ids `ids` (every rank's) taken out and the nodal rows of the passes (nodal
    projections of those nodes, pass_rows) put in their place, at rows' phi: a feature node's own row against
    the other surface instead of its weighted one (contact[].feature_angle); the nodal rows of the passes
    `extra` are added beside their nodes' own, on row 3 k + 1 (a node's second slot)."""
    for pss in extra:
        G_r, G_c, G_v, g_r, g_v, W_r, W_v = pass_rows(pss, 1.0)
        rows = Rows.concat(rows, _rows([(G_r + 1, G_c, G_v, g_r + 1, g_v, W_r + 1, W_v)], rows.phi))
    if not len(ids):
        return rows
    out = Rows(*(x[~np.isin(rows_of, ids)] for x, rows_of in (
        (rows.G_rows, rows.G_rows), (rows.G_cols, rows.G_rows), (rows.G_vals, rows.G_rows),
        (rows.g_rows, rows.g_rows), (rows.g_vals, rows.g_rows), (rows.W_rows, rows.W_rows),
        (rows.W_vals, rows.W_rows))), rows.phi)
    keep = ~np.isin(rows.gate_rows, ids) & ~np.isin(rows.gate_of, ids)
    out.gate_rows, out.gate_of = rows.gate_rows[keep], rows.gate_of[keep]
    for pss in passes:
        out = Rows.concat(out, _rows([pass_rows(pss, 1.0)], rows.phi))
    return out


FINER_POWER = 4.0    # the "finer" rule: w_a = h_b^4 / (h_a^4 + h_b^4) (formulation.md section 8)


def weight_power(rule):
    """The exponent p of a size-based weight rule ("finer" or {"power": p}), or None for a constant weight."""
    if isinstance(rule, str):
        if rule != "finer":
            raise ValueError(f"weight rule must be a number in [0, 1], 'finer' or {{'power': p}}, got {rule!r}")
        return FINER_POWER
    if isinstance(rule, dict):
        p = float(rule.get("power", float("nan")))
        if set(rule) != {"power"} or not p > 0:
            raise ValueError(f"weight rule {{'power': p}} needs exactly one key power > 0, got {rule!r}")
        return p
    return None


def weights(rule, slave_size, master_size):
    """Slave-side weight w_a (w_b = 1 - w_a) of weighted quasi-symmetry, elementwise.

    rule: a float in [0, 1] (constant w_a; 0.5 is the paper, 1 is master/slave),
    {"power": p}: w_a = h_b^p / (h_a^p + h_b^p), h_a the slave-side and h_b the
    master-side element size, which weights integration toward the finer side
    whichever body is called the slave; "finer" is p = 4.
    """
    h_a = np.asarray(slave_size, dtype=float)
    h_b = np.asarray(master_size, dtype=float)
    shape = np.broadcast(h_a, h_b).shape
    p = weight_power(rule)
    if p is not None:
        # in ratio form, so that a large p cannot overflow: w_a = 1 / (1 + (h_a / h_b)^p)
        r = (h_a / h_b) ** p
        return np.broadcast_to(1.0 / (1.0 + r), shape).copy()
    w = float(rule)
    if not 0.0 <= w <= 1.0:
        raise ValueError(f"weight rule must be a number in [0, 1], 'finer' or {{'power': p}}, got {rule!r}")
    return np.full(shape, w)


def quasi_symmetric(slave_pass, master_pass, weight=0.5):
    """One row per slave node: C = 2 w_a R_S(a on b) + 2 w_b R_T(b on a), phi = 1/2 (paper [12], section 8).

    R_S(a on b): the slave pass tested by the slave's shape functions. R_T(b on a):
    each master point's row w_l h_l (measured against slave face f_a^l) tested by
    the slave's shape functions at its projection, N_a^k(xi_a^l): the slave
    multiplier evaluated at the master point. With nodal quadrature this is the
    paper's master multiplier interpolated from slave nodes (paper [8]-[10]). With
    a size-based weight rule w is evaluated per contribution from the two faces'
    sizes local to it. A slave node with no projection of its own keeps the second
    term only. Contributions with a zero weight are left out (so weight = 1 gives
    exactly the master/slave rows x 2).
    """
    w_a = weights(weight, slave_pass.size, slave_pass.target_size)
    # master pass: the slave side is the target face, the master side the projected point
    w_b = 1.0 - weights(weight, master_pass.target_size, master_pass.size)
    return _rows([pass_rows(slave_pass, 2.0 * w_a), _spread_rows(master_pass, 2.0 * w_b)], 0.5)


def project_master_rows(parts, node_pass):
    """P^T R: each row 3 l of the triplets parts (R's (G_rows, G_cols, G_vals, g_rows, g_vals, W_rows, W_vals)),
    times N_a^k(xi_a^l), moved to row 3 k of every node k of the slave face master node l projects on.

    node_pass: the nodal pass of master nodes on the slave (master node l -> slave face, shape values):
    the master multiplier interpolated from slave-node values (paper [8]-[10]). A master node shared by
    several slave faces (search.closest_faces: as near to each) has an entry for each, and each takes its
    share of the node's area. Rows of master nodes without a projection here are dropped. Pure join on l; the
    caller puts R's rows on the rank that holds l's projection.
    """
    G_r, G_c, G_v, g_r, g_v, W_r, W_v = parts
    order = np.argsort(node_pass.node, kind="stable")
    known = node_pass.node[order]
    # the entries of each master node, CSR-like over its distinct nodes, and each entry's part of its node (1
    # unless shared)
    starts = np.flatnonzero(np.r_[True, known[1:] != known[:-1]]) if len(known) else np.zeros(0, _I)
    nodes, ptr = known[starts], np.r_[starts, len(known)]
    area = node_pass.area[order]
    total = np.repeat(np.add.reduceat(area, starts), np.diff(ptr)) if len(known) else area
    part = np.empty(len(known))
    part[order] = np.divide(area, total, out=np.ones(len(known)), where=total > 0)

    def spread(rows):
        """For every entry of row 3 l: the new rows 3 k, the entry it comes from and its factor N^k."""
        l = np.asarray(rows, dtype=_I) // 3
        i = np.minimum(np.searchsorted(nodes, l), max(len(nodes) - 1, 0))
        hit = (nodes[i] == l) if len(nodes) else np.zeros(len(l), dtype=bool)
        at, which = row_spans(ptr, i[hit])
        pos = order[at]
        N = node_pass.shape[pos] * part[pos][:, None]               # (h, nv)
        e, kk = np.nonzero(N != 0.0)
        return 3 * node_pass.target_nodes[pos[e], kk], np.flatnonzero(hit)[which][e], N[e, kk]

    G_rows, src, f = spread(G_r)
    g_rows, g_src, g_f = spread(g_r)
    W_rows, W_src, W_f = spread(W_r)
    return (G_rows, np.asarray(G_c, dtype=_I)[src], np.asarray(G_v)[src] * f,
            g_rows, np.asarray(g_v)[g_src] * g_f, W_rows, np.asarray(W_v)[W_src] * W_f)


def quasi_symmetric_master_nodes(slave_pass, master_pass, master_node_pass, weight=0.5, move=None):
    """quasi_symmetric with the master multiplier from master-node values: C = 2 w_a R_S(a on b) + 2 w_b P^T R_S(b on a).

    master_pass: the master's quadrature points on the slave (rows tested by the master's shape
    functions); master_node_pass: the master nodes' projections (P). With nodal quadrature both
    passes are the same and this equals quasi_symmetric. move(parts) -> parts, if given, first routes
    R_S(b on a)'s triplets to where master_node_pass lives (parallel runs).
    """
    w_a = weights(weight, slave_pass.size, slave_pass.target_size)
    w_b = 1.0 - weights(weight, master_pass.target_size, master_pass.size)
    R = pass_rows(master_pass, 2.0 * w_b)
    if move is not None:
        R = move(R)
    return _rows([pass_rows(slave_pass, 2.0 * w_a), project_master_rows(R, master_node_pass)], 0.5)


def die_tangents(n):
    """The two tangents of a die's sticking rows (die_rows), as a (2, 3) array."""
    return np.array(_tangent_basis(np.asarray(n, dtype=float).reshape(3)))


def _tangent_basis(n):
    """Two unit tangents t1, t2 with (t1, t2, n) orthonormal, built deterministically from n."""
    e = np.zeros(3)
    e[np.argmin(np.abs(n))] = 1.0
    t1 = np.cross(n, e)
    t1 /= np.linalg.norm(t1)
    return t1, np.cross(n, t1)


def die_rows(node, area, xyz, point, normal, u_die, sticking=False, anchor=None):
    """Rows of body nodes against a rigid plane (die) through `point` with unit `normal` pointing toward the body.

    h_k = -(u_k - u_die) . n - delta0_k, delta0_k = (x_k - point) . n (>= 0 apart);
    row 3 v: A_k h_k, phi = 1. With sticking, rows 3 v + 1 and 3 v + 2 add the
    tangential equalities A_k ((u_k - u_die) . t_i - a_ki) = 0, active iff row 3 v is, with t_i
    die_tangents(normal) and a_k = anchor[k] (p, 2) the node's place on the die where it stuck (default 0:
    where it started).
    """
    node = np.asarray(node, dtype=_I).reshape(-1)
    p = len(node)
    area = np.broadcast_to(np.asarray(area, dtype=float), (p,))
    xyz = np.asarray(xyz, dtype=float).reshape(p, 3)
    n = np.asarray(normal, dtype=float).reshape(3)
    if not abs(np.linalg.norm(n) - 1.0) < 1e-12:
        raise ValueError(f"die normal must be a unit vector, got {n}")
    u_die = np.asarray(u_die, dtype=float).reshape(3)
    delta0 = (xyz - np.asarray(point, dtype=float).reshape(3)) @ n
    comp = np.arange(3, dtype=_I)
    row = 3 * node

    def row_block(slot, direction, rhs):
        r = row + slot
        return (np.repeat(r, 3), (3 * node[:, None] + comp).reshape(-1),
                (area[:, None] * direction).reshape(-1), r, area * rhs, r.copy(), area.copy())

    parts = [row_block(0, np.broadcast_to(-n, (p, 3)), delta0 - u_die @ n)]
    gate_rows, gate_of = _ints(), _ints()
    if sticking:
        anchor = np.zeros((p, 2)) if anchor is None else np.asarray(anchor, dtype=float).reshape(p, 2)
        for i, (slot, t) in enumerate(zip((1, 2), die_tangents(n))):
            parts.append(row_block(slot, np.broadcast_to(t, (p, 3)), u_die @ t + anchor[:, i]))
        gate_rows = np.concatenate([row + 1, row + 2])
        gate_of = np.concatenate([row, row])
    rows = _rows(parts, 1.0)
    rows.gate_rows, rows.gate_of = gate_rows, gate_of
    return rows
