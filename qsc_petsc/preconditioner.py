"""The contact-band preconditioner: GAMG composed with an exact solve on the band of dofs the contact rows couple.

Penalty rows between bodies add eps_n G^T D G, a coupling 1e2-1e6 times stiffer than the elements
around it and not diagonal (a slave node against a master face): GAMG's aggregates and smoothers
do not see it, and CG + GAMG needed 9-11x the iterations of the same mesh merged into one body
(docs/performance.md). Composing GAMG multiplicatively with a sparse Cholesky on the rows the
contact stencil touches (plus `layers` rings of element neighbours) removes that stiff part
exactly: the band is two-dimensional, so its factor is cheap next to the 3-D solve.

Options (prefix qsc_): the composite's GAMG is `qsc_sub_0_`, the band's ASM `qsc_sub_1_` (its
factor: `qsc_sub_1_sub_pc_type`, default cholesky with MUMPS).
"""

import numpy as np
from petsc4py import PETSc

from .options import set_from_options

DEFAULTS = {"sub_1_sub_pc_type": "cholesky", "sub_1_sub_pc_factor_mat_solver_type": "mumps",
            "sub_1_sub_ksp_type": "preonly"}


def band_dofs(K, couplings, layers=1):
    """Global dofs (sorted) of this rank's owned rows touched by the contact couplings (Mats with K's row
    layout, e.g. G^T G) and their coupling partners, grown by `layers` rings of K's sparsity around the
    owned ones (partners and rings may be owned elsewhere: the subdomains overlap across ranks)."""
    r0, r1 = K.getOwnershipRange()
    touched = np.zeros(r1 - r0, dtype=bool)
    partners = []
    for C in couplings:
        ia, ja, _ = C.getValuesCSR()
        touched |= np.diff(ia) > 1          # a row coupled to more than itself
        partners.append(ja)                 # its partners may live on other ranks: the band follows the coupling
    band = np.union1d(np.flatnonzero(touched) + r0, np.concatenate(partners) if partners else [])
    if layers > 0:
        ia, ja, _ = K.getValuesCSR()
        frontier = band
        for _ in range(layers):
            loc = frontier[(frontier >= r0) & (frontier < r1)] - r0
            if len(loc) == 0:
                break
            counts = ia[loc + 1] - ia[loc]
            idx = np.repeat(ia[loc], counts) + (np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts))
            frontier = np.setdiff1d(np.unique(ja[idx]), band)
            band = np.union1d(band, frontier)
    return np.asarray(band, dtype=np.int64).astype(PETSc.IntType)


def effective_option(name, default=None):
    """The value of option qsc_<name> in the database, or default."""
    return PETSc.Options().getString("qsc_" + name, default)


def wants_band(mode, has_pairs):
    """Whether to use the band preconditioner: mode "band" always (with contact pairs), "auto" when the
    options choose GAMG (the default), "none" never."""
    if not has_pairs or mode == "none":
        return False
    return mode == "band" or effective_option("pc_type", "gamg") == "gamg"


def install_band_pc(ksp, K, couplings, layers, comm):
    """Give ksp a fresh composite PC: GAMG, then ASM with one subdomain per rank = its contact band.

    Symmetric-multiplicative (so CG stays valid) when the KSP is CG, multiplicative otherwise.
    Returns the global number of band dofs. A fresh PC per search: ASM subdomains are fixed at setup."""
    band = band_dofs(K, couplings, layers)
    opts = PETSc.Options()
    for key, value in DEFAULTS.items():
        if not opts.hasName("qsc_" + key):
            opts.setValue("qsc_" + key, value)
    pc = PETSc.PC().create(comm=comm)
    pc.setOptionsPrefix("qsc_")
    pc.setType("composite")
    symmetric = (effective_option("ksp_type", "cg") == "cg")
    pc.setCompositeType(PETSc.PC.CompositeType.SYMMETRIC_MULTIPLICATIVE if symmetric
                        else PETSc.PC.CompositeType.MULTIPLICATIVE)
    pc.addCompositePCType("gamg")
    pc.addCompositePCType("asm")
    gamg, asm = pc.getCompositePC(0), pc.getCompositePC(1)
    sub = PETSc.IS().createGeneral(band, comm=PETSc.COMM_SELF)
    asm.setASMLocalSubdomains(1, [sub], [sub])
    asm.setASMType(PETSc.PC.ASMType.BASIC)
    set_from_options(gamg, "contact band's GAMG (-qsc_sub_0_*)")
    set_from_options(asm, "contact band's ASM (-qsc_sub_1_*)")
    ksp.setPC(pc)
    sub.destroy()
    return comm.allreduce(len(band))
