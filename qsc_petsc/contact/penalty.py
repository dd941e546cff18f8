"""Penalised (or augmented-Lagrangian) contact energy, row forces and row stiffnesses, the same for every formulation.

Pure NumPy on row-space arrays (formulation.md section 4); the caller forms
c = G u - g and the products F_c = G^T m, J_c = G^T diag(d) G. With a row
multiplier a_r = lmbda_r + eps_n c_r / W_r (a pressure, lmbda = 0 for pure
penalty):

    energy = sum_r phi W_r / (2 eps_n) (<a_r>_+^2 - lmbda_r^2)   (= phi eps_n <c_r>_+^2 / (2 W_r) at lmbda = 0)
    m_r    = phi <a_r>_+,   d_r = phi eps_n [active_r] / W_r

Rows with W_r <= 0 do not exist (m = d = 0). Gated rows (sticking) are
equalities: active iff their gate row is, m_r = phi a_r of either sign.
"""

import numpy as np


def gate_positions(row_ids, gate_rows, gate_of):
    """gate_of for row_response: for each entry of row_ids (r,), the position of its gate row in row_ids, or -1.

    row_ids are the global ids of the local row array; gate_rows / gate_of the
    Rows fields (global ids). A gated row present without its gate row is an error.
    """
    row_ids = np.asarray(row_ids, dtype=np.int64)
    out = np.full(len(row_ids), -1, dtype=np.int64)
    gate_rows = np.asarray(gate_rows, dtype=np.int64)
    gate_of = np.asarray(gate_of, dtype=np.int64)
    if len(gate_rows) == 0 or len(row_ids) == 0:
        return out
    order = np.argsort(row_ids, kind="stable")
    srt = row_ids[order]

    def find(ids):
        i = np.minimum(np.searchsorted(srt, ids), len(srt) - 1)
        return np.where(srt[i] == ids, order[i], -1)

    here = find(gate_rows)
    present = here >= 0
    gate_pos = find(gate_of[present])
    if (gate_pos < 0).any():
        missing = gate_of[present][gate_pos < 0][0]
        raise ValueError(f"gated row {gate_rows[present][gate_pos < 0][0]} is here but its gate row {missing} is not")
    out[here[present]] = gate_pos
    return out


def _equality_mask(gate_of, r):
    if gate_of is None:
        return np.zeros(r, dtype=bool), None
    gate_of = np.asarray(gate_of, dtype=np.int64)
    if gate_of.shape != (r,):
        raise ValueError(f"gate_of must have shape ({r},), got {gate_of.shape}")
    eq = gate_of >= 0
    if (gate_of[gate_of[eq]] >= 0).any():
        raise ValueError("a gate row may not itself be gated")
    return eq, gate_of


def row_response(c, W, eps_n, phi, closed_tol=None, lmbda=None, gate_of=None, bilateral=False):
    """Energy, row forces m (r,), row stiffnesses d (r,) and active set (r,) of rows c = G u - g with weights W.

    eps_n: penalty stiffness [Pa/m]; phi: the formulation's factor (scalar or (r,)).
    closed_tol (r,) or scalar: rows with c >= -closed_tol count as active (closed-set
    start; their force is 0 unless bilateral). lmbda (r,): augmented-Lagrangian multipliers [Pa].
    gate_of (r,): position of each gated (equality) row's gate row, -1 for ordinary rows.
    bilateral: every active row is an equality (force of either sign), as in the first
    iteration of an increment: the Newton step from there solves the closed (glued) problem.
    """
    c = np.asarray(c, dtype=float)
    W = np.asarray(W, dtype=float)
    r = len(c)
    if W.shape != c.shape:
        raise ValueError(f"c {c.shape} and W {W.shape} must have the same shape")
    if not eps_n > 0:
        raise ValueError(f"eps_n must be > 0, got {eps_n}")
    exists = W > 0
    Ws = np.where(exists, W, 1.0)
    lm = np.zeros(r) if lmbda is None else np.asarray(lmbda, dtype=float)
    a = lm + eps_n * c / Ws
    if closed_tol is None:
        active = a > 0.0
    else:
        active = a >= -eps_n * np.asarray(closed_tol, dtype=float) / Ws
    active &= exists
    eq, gate_of = _equality_mask(gate_of, r)
    if eq.any():
        active[eq] = active[gate_of[eq]] & exists[eq]
    mult = np.where(active, np.where(eq | bilateral, a, np.maximum(a, 0.0)), 0.0)
    phi = np.asarray(phi, dtype=float)
    m = phi * mult
    d = np.where(active, phi * eps_n / Ws, 0.0)
    e = np.where(exists, phi * Ws / (2.0 * eps_n) * (mult * mult - lm * lm), 0.0)
    return float(e.sum()), m, d, active


def multipliers_update(lmbda, c, W, eps_n, gate_of=None):
    """Uzawa update lmbda <- <lmbda + eps_n c / W>_+ (equality rows: lmbda + eps_n c / W while their gate is active)."""
    c = np.asarray(c, dtype=float)
    W = np.asarray(W, dtype=float)
    exists = W > 0
    a = np.asarray(lmbda, dtype=float) + eps_n * c / np.where(exists, W, 1.0)
    new = np.where(exists, np.maximum(a, 0.0), 0.0)
    eq, gate_of = _equality_mask(gate_of, len(c))
    if eq.any():
        new[eq] = np.where(exists[eq] & (new[gate_of[eq]] > 0.0), a[eq], 0.0)
    return new
