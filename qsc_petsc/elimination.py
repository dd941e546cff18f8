"""Dirichlet rows and columns taken out of the stiffness matrix's CSR arrays before PETSc holds them.

What MatZeroRowsColumns(K, fixed, 1, ubar, b) does (K0: fixed rows and columns zero, diagonal 1;
b loses K's fixed columns times ubar), without its pass over every stored entry: a fixed column
appears only in the rows of its vertex's neighbours, which K's symmetric block pattern lists in
the fixed rows themselves. On the 985k-dof box on 2 ranks that pass (40 M entries per rank) took
58 ms (docs/performance.md).
"""

import numpy as np
from petsc4py import PETSc

from .sparsity import row_spans


def eliminate(csr, r0, dofs, values, comm):
    """Zero the rows and columns of the fixed dofs in K's CSR arrays (in place) and put 1 on their diagonal.

    csr: (rowptr, local columns, values) on one rank, else the split ((diagonal part), (off-diagonal part, global
    columns)) that createAIJWithArrays takes; r0: the first owned row; dofs: the owned fixed dofs (global, unique),
    values: their prescribed values ubar. Returns the lifting (owned rows,): sum over fixed columns j of K_ij ubar_j
    in every free row i, so that K0 u = f - lifting on the free rows (0 on the fixed ones). Collective."""
    diag = csr if comm.size == 1 else csr[0]
    ptr, cols, vals = diag
    n = len(ptr) - 1
    rows = np.asarray(dofs, np.int64) - r0
    fixed = np.zeros(n, bool)
    fixed[rows] = True
    ubar = np.zeros(n)
    ubar[rows] = values
    lift = np.zeros(n)
    at, which = row_spans(ptr, rows)
    near = np.zeros(n // 3, bool)             # the fixed dofs' vertex neighbours (local vertices)
    near[cols[at] // 3] = True
    vals[at] = 0.0
    vals[at[cols[at] == rows[which]]] = 1.0
    near = (3 * np.flatnonzero(near)[:, None] + np.arange(3)).ravel()
    near = near[~fixed[near]]
    at, which = row_spans(ptr, near)
    hit = fixed[cols[at]]
    at, which = at[hit], near[which[hit]]
    lift += np.bincount(which, vals[at] * ubar[cols[at]], minlength=n)
    vals[at] = 0.0
    if comm.size > 1:
        lift += _eliminate_remote(csr[1], rows, fixed, ubar, comm)
    return lift


def _eliminate_remote(part, rows, fixed, ubar, comm):
    """eliminate's off-diagonal part (rowptr, global columns, values): its fixed rows zeroed, and its columns that
    other ranks fix (found from their owners by one scatter) zeroed into the lifting."""
    ptr, cols, vals = part
    n = len(ptr) - 1
    at, _ = row_spans(ptr, rows)
    vals[at] = 0.0
    # every global column here asks its owner whether it is fixed, and at what value: [flag, ubar] per dof
    state = PETSc.Vec().createMPI((2 * n, PETSc.DECIDE), bsize=2, comm=comm)
    a = state.getArray().reshape(-1, 2)
    a[:, 0], a[:, 1] = fixed, ubar
    wanted = np.unique(cols).astype(PETSc.IntType)
    index = PETSc.IS().createBlock(2, wanted, comm=PETSc.COMM_SELF)
    got = PETSc.Vec().createSeq(2 * len(wanted), comm=PETSc.COMM_SELF)
    scatter = PETSc.Scatter().create(state, index, got, None)
    scatter.scatter(state, got, addv=PETSc.InsertMode.INSERT_VALUES)
    g = got.getArray().reshape(-1, 2)
    keep = g[:, 0] > 0.5
    far, far_ubar = wanted[keep], g[keep, 1]
    for obj in (scatter, got, index, state):
        obj.destroy()
    lift = np.zeros(n)
    if len(far):
        pos = np.minimum(np.searchsorted(far, cols), len(far) - 1)
        at = np.flatnonzero(far[pos] == cols)
        row = np.searchsorted(ptr, at, side="right") - 1
        lift += np.bincount(row, vals[at] * far_ubar[pos[at]], minlength=n)
        vals[at] = 0.0
    return lift
