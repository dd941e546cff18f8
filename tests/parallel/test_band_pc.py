"""The contact-band preconditioner (preconditioner.py): same answer as the plain options, far fewer Krylov
iterations with CG + GAMG or BoomerAMG, on 1, 2 and 3 ranks (interface split across ranks)."""

import numpy as np
import pytest
from conftest import CONFIGS, all_close, scene_without_petsc
from mpi4py import MPI

MESHES = ["petsc.ksp_rtol=1e-10", "output.xdmf=false", "bodies.0.mesh.cells=[4,4,2]", "bodies.1.mesh.cells=[7,7,2]"]
ITERATIVE = ["petsc.ksp_type=cg", *MESHES]


def band_apply(band, x, y):
    """y = the band's solve of x's band entries, 0 elsewhere (Vecs of the whole system)."""
    answer = band.solve(x.getArray(readonly=True)[band.rows])
    y.set(0.0)
    y.getArray()[band.rows] = answer


def solve(comm, tmp, sets, path=CONFIGS / "patch_test.toml", base=ITERATIVE):
    from qsc_petsc.preconditioner import multigrid
    from qsc_petsc.run import Run
    from qsc_petsc.scene import load_scene
    run = Run(load_scene(path, base + sets), comm, tmp, log=lambda *a: None)
    s = run.execute()
    band = run.system.band_dofs
    pc = run.system.snes.getKSP().getPC()
    amg = multigrid(pc)
    s["multigrid"] = amg.getType() if amg is not None else None
    s["krylov"] = run.system.snes.getKSP().getType()
    run.destroy()
    pair = next(iter(s["steps"][-1]["contact"].values()))
    return s, band, [s["steps"][-1]["max_abs_displacement"], pair["total_normal_force"],
                     pair["max_penetration_slave"], pair["contact_area"]]


@pytest.mark.parametrize("krylov", ["cg", "gmres"])
@pytest.mark.parametrize("amg", ["gamg", "hypre"])
@pytest.mark.parametrize("formulation", ["master_slave", "quasi_symmetric"])
def test_band_preconditioner_same_answer_fewer_iterations(comm, mpi_tmp, formulation, amg, krylov):
    """With alpha 1e4 the band preconditioner gives the plain Krylov + multigrid answer (to the solver
    tolerance) in less than half the Krylov iterations, under CG and under GMRES."""
    common = [f"contact.0.formulation={formulation}", "contact.0.penalty=1e4", f"petsc.pc_type={amg}",
              f"petsc.ksp_type={krylov}"]
    if (amg, krylov) == ("hypre", "cg"):   # plain CG + BoomerAMG: hybrid Gauss-Seidel went indefinite on 3 ranks
        common.append("petsc.pc_hypre_boomeramg_relax_type_all=l1scaled-SOR/Jacobi")
    s_band, band, q_band = solve(comm, mpi_tmp / "band", common + ["solver.contact_preconditioner=auto"], base=MESHES)
    s_none, none_band, q_none = solve(comm, mpi_tmp / "none", common + ["solver.contact_preconditioner=none"],
                                      base=MESHES)
    assert s_band["status"] == "ok" and s_none["status"] == "ok"
    assert band > 0 and none_band == 0
    assert all_close(comm, np.allclose(q_band, q_none, rtol=1e-6, atol=1e-14))
    its = [sum(st["ksp_iterations"] for st in s["steps"]) for s in (s_band, s_none)]
    assert 2 * its[0] < its[1], its


def test_band_preconditioner_is_not_used_with_a_direct_solver(comm, mpi_tmp):
    """"auto" leaves a user's LU alone."""
    _, band, _ = solve(comm, mpi_tmp, ["petsc.ksp_type=preonly", "petsc.pc_type=lu",
                                       "petsc.pc_factor_mat_solver_type=mumps"])
    assert band == 0


def test_band_preconditioner_defaults_to_gmres_and_boomeramg(comm, mpi_tmp):
    """With contact pairs and neither ksp_type nor pc_type, "auto" composes hypre's BoomerAMG with the band
    under GMRES: the same answer as CG with the band and GAMG named explicitly."""
    path = mpi_tmp / "no_petsc.toml"       # the patch test without its [petsc] table (its last): no pc_type
    if comm.rank == 0:
        path.write_text((CONFIGS / "patch_test.toml").read_text().split("\n[petsc]")[0])
    comm.Barrier()
    s_default, band, q_default = solve(comm, mpi_tmp / "default", [], path, base=MESHES)
    s_named, _, q_named = solve(comm, mpi_tmp / "gamg", ["petsc.pc_type=gamg"])
    assert s_default["status"] == "ok" and band > 0
    assert (s_default["krylov"], s_default["multigrid"]) == ("gmres", "hypre")
    assert (s_named["krylov"], s_named["multigrid"]) == ("cg", "gamg")
    assert all_close(comm, np.allclose(q_default, q_named, rtol=1e-6, atol=1e-14))


def test_band_is_one_solve_across_ranks(comm, mpi_tmp):
    """The band's dofs are listed once, by their owners, however the partition cuts the interface, and the
    band's solve is exact: applied to J x restricted to the band, it returns x there (band_dofs, BandSolve).
    Its factorization takes the -qsc_band_* options."""
    from petsc4py import PETSc

    from qsc_petsc.preconditioner import BandSolve
    from qsc_petsc.run import Run
    from qsc_petsc.scene import load_scene
    run = Run(load_scene(CONFIGS / "patch_test.toml", MESHES + ["petsc.ksp_type=gmres", "petsc.pc_type=hypre",
                                                                 "petsc.band_pc_type=lu"]), comm, mpi_tmp,
              log=lambda *a: None)
    run.execute()
    ksp = run.system.snes.getKSP()
    band = ksp.getPC().getPythonContext().band
    assert isinstance(band, BandSolve) and band.ksp.getPC().getType() == "lu"
    dofs = band.iset.getIndices()
    r0, r1 = run.system.J.getOwnershipRange()
    assert np.all((dofs >= r0) & (dofs < r1)) and np.all(np.diff(dofs) > 0)
    assert comm.allreduce(len(dofs)) == run.system.band_dofs > 0
    J = run.system.J
    x, y = J.createVecs()
    x.setRandom()
    Jx = J.createVecLeft()
    # only the band block acts: x zero off the band, so (J x) on the band is J_bb x_b
    off = np.setdiff1d(np.arange(r0, r1), dofs) - r0
    x.getArray()[off] = 0.0
    J.mult(x, Jx)
    band_apply(band, Jx, y)
    assert all_close(comm, np.allclose(y.getArray(), x.getArray(), rtol=0, atol=1e-8 * x.norm(PETSc.NormType.INFINITY)))
    run.destroy()


def test_slip_modes_are_rigid_motions_faded_towards_the_far_side(comm, mpi_tmp):
    """assembly.slip_modes on the two cubes: per body 6 rows; a translation is w = 1 - d / D on its body's
    vertices (d from the contact plane z = 1, D = 1) and 0 on the other body: its global sum of squares is
    (nx + 1)(ny + 1) sum_k (k / nz)^2, whatever the ranks; the twist about the normal is orthogonal to it."""
    from qsc_petsc.run import Run
    from qsc_petsc.scene import load_scene
    run = Run(load_scene(scene_without_petsc(mpi_tmp), ["output.xdmf=false"]), comm, mpi_tmp / "out",
              log=lambda *a: None)
    blocks = run.system.slip_modes
    assert len(blocks) == 2 and all(values.shape == (6, len(cols)) for cols, values in blocks)
    Z = np.zeros((12, run.system.u.getLocalSize()))
    for k, (cols, values) in enumerate(blocks):
        Z[6 * k:6 * k + 6, cols] = values
    squares = comm.allreduce(np.sum(Z ** 2, axis=1))
    for body, n in enumerate((6, 9)):
        expected = (n + 1) ** 2 * np.sum((np.arange(n + 1) / n) ** 2)
        assert np.allclose(squares[6 * body:6 * body + 3], expected, rtol=1e-12), (body, squares)
    gram = comm.allreduce(Z @ Z.T)
    assert np.allclose(gram[0, 6:], 0.0) and abs(gram[0, 3]) < 1e-12 * gram[0, 0]
    run.destroy()


def test_slip_modes_do_not_depend_on_the_length_unit(comm, mpi_tmp):
    """The two cubes in metres and scaled by 1e6: the slip modes' rotations were in metres, 1e12 x the
    translations' scale in Z^T J Z there, and half the modes fell under the preconditioner's cutoff (flat_punch: 1-3
    more Krylov iterations; hunt34_1). They are taken at unit speed at each body's farthest point: the same values."""
    from qsc_petsc.run import Run
    from qsc_petsc.scene import load_scene
    scaled = ["bodies.0.mesh.size=[1e6,1e6,1e6]", "bodies.1.mesh.origin=[0,0,1e6]", "bodies.1.mesh.size=[1e6,1e6,1e6]",
              "die.1.point=[0,0,2e6]", "die.1.motion=[0,0,-2e4]"]
    values = []
    for sets in ([], scaled):
        run = Run(load_scene(scene_without_petsc(mpi_tmp), ["output.xdmf=false", *sets]), comm, mpi_tmp / "out",
                  log=lambda *a: None)
        values.append([block[1].copy() for block in run.system.slip_modes])
        run.destroy()
    assert all_close(comm, all(np.allclose(a, b, rtol=1e-9, atol=1e-12) for a, b in zip(*values)))


def test_slip_modes_cut_the_krylov_count_same_answer(comm, mpi_tmp):
    """Two cubes sliding freely on each other between sticking dies (GMRES + BoomerAMG + band, the defaults):
    the Galerkin correction on the slip modes gives the same answer in fewer Krylov iterations (6/9 cells, 1
    rank, measured with 6^3: 34 against 43; with 4^3: 34 against 42). The lower cube has 4^3 cells here, so that on 2 and 3 ranks the cut runs
    through the upper one and a rank holds none of the lower body's dofs."""
    path = scene_without_petsc(mpi_tmp)
    results = {}
    for slip in (True, False):
        s, _, q = solve(comm, mpi_tmp / f"slip_{slip}", [f"solver.contact_slip_modes={str(slip).lower()}"], path,
                        base=["output.xdmf=false", "bodies.0.mesh.cells=[4,4,4]"])
        assert s["status"] == "ok"
        results[slip] = (sum(st["ksp_iterations"] for st in s["steps"]), q)
    assert results[True][0] < results[False][0], results
    assert all_close(comm, np.allclose(results[True][1], results[False][1], rtol=1e-6, atol=1e-14))


@pytest.mark.parametrize("krylov", ["gmres", "cg"])
def test_slip_modes_only_where_the_preconditioner_may_be_unsymmetric(comm, mpi_tmp, krylov):
    """The correction (between the multigrid and the band's solve) is not symmetric: a named CG's composite goes
    without it."""
    from qsc_petsc.run import Run
    from qsc_petsc.scene import load_scene
    run = Run(load_scene(scene_without_petsc(mpi_tmp), ["output.xdmf=false", f"petsc.ksp_type={krylov}"]), comm,
              mpi_tmp / "out", log=lambda *a: None)
    assert run.execute()["status"] == "ok"
    composite = run.system.snes.getKSP().getPC().getPythonContext()
    assert (composite.slip is not None) == (krylov == "gmres")
    run.destroy()


@pytest.mark.parametrize("krylov", ["gmres", "cg"])
def test_band_composite_is_the_multiplicative_composite(comm, mpi_tmp, krylov):
    """BandComposite forms the residual between its parts on the band's rows only (and Z^T r from J Z): its
    application is the plain multiplicative composite's, y = M x, r = x - J y, c = (Z^T J Z)^-1 Z^T r,
    y += Z c + B (r - J Z c) (and under CG y += M (x - J y) again), with every residual formed in full."""
    from qsc_petsc.run import Run
    from qsc_petsc.scene import load_scene
    run = Run(load_scene(scene_without_petsc(mpi_tmp), ["output.xdmf=false", f"petsc.ksp_type={krylov}"]), comm,
              mpi_tmp / "out", log=lambda *a: None)
    assert run.execute()["status"] == "ok"
    pc = run.system.snes.getKSP().getPC()
    composite, J = pc.getPythonContext(), run.system.J
    run.system.band_parts.keep = False
    composite.setUp(pc)                       # every part on the J at hand
    x, y = J.createVecs()
    x.setRandom()
    composite.apply(pc, x, y)

    ref, r, t = x.duplicate(), x.duplicate(), x.duplicate()
    composite.inner.apply(x, ref)
    J.mult(ref, r)
    r.aypx(-1.0, x)                           # r = x - J y
    if composite.slip is not None:
        Z = np.zeros((composite.slip.modes(), len(r.getArray())))
        for k, (cols, values) in enumerate(run.system.slip_modes):
            Z[6 * k:6 * k + 6, cols] = values
        c = composite.slip.E_inv @ comm.allreduce(Z @ r.getArray())
        t.getArray()[:] = c @ Z
        ref.axpy(1.0, t)                      # y += Z c
        Jt = t.duplicate()
        J.mult(t, Jt)
        r.axpy(-1.0, Jt)                      # r -= J Z c
    band_apply(composite.band, r, t)
    ref.axpy(1.0, t)
    if krylov == "cg":
        J.mult(ref, r)
        r.aypx(-1.0, x)
        composite.inner.apply(r, t)
        ref.axpy(1.0, t)
    scale = comm.allreduce(float(np.abs(ref.getArray()).max()), op=MPI.MAX)
    assert all_close(comm, np.allclose(y.getArray(), ref.getArray(), rtol=0, atol=1e-9 * scale))
    assert (composite.slip is not None) == (krylov == "gmres")
    run.destroy()


def test_band_is_factored_as_spd(comm, mpi_tmp):
    """The band's submatrix is declared SPD, so MUMPS factors it without pivoting (SYM = 1): its
    symmetric-indefinite mode (SYM = 2) returned NaN now and then on the 212k cubes with no band ring."""
    from petsc4py import PETSc

    from qsc_petsc.run import Run
    from qsc_petsc.scene import load_scene
    run = Run(load_scene(scene_without_petsc(mpi_tmp), ["output.xdmf=false"]), comm, mpi_tmp / "out",
              log=lambda *a: None)
    assert run.execute()["status"] == "ok"
    band = run.system.snes.getKSP().getPC().getPythonContext().band
    path = mpi_tmp / "band.txt"
    viewer = PETSc.Viewer().createASCII(str(path), comm=band.ksp.getComm())
    viewer.pushFormat(PETSc.Viewer.Format.ASCII_INFO_DETAIL)
    band.ksp.view(viewer)
    viewer.destroy()
    run.destroy()
    text = comm.bcast(path.read_text() if comm.rank == 0 else None)
    assert "SYM (matrix type):                   1" in text


def test_softened_multigrid_same_answer_fewer_iterations(comm, mpi_tmp):
    """solver.contact_multigrid_alpha = 1: BoomerAMG is set up with the pair's rows at alpha 1 (the Krylov method
    and the band's solve keep alpha 1e4): the same answer in fewer Krylov iterations on the two cubes (8^3 / 12^3
    cells, 1 rank, measured: 32 against 40)."""
    path = scene_without_petsc(mpi_tmp)
    mesh = ["output.xdmf=false", "bodies.0.mesh.cells=[8,8,8]", "bodies.1.mesh.cells=[12,12,12]"]
    results = {}
    for alpha in (None, 1.0):
        sets = [] if alpha is None else [f"solver.contact_multigrid_alpha={alpha}"]
        s, _, q = solve(comm, mpi_tmp / f"alpha_{alpha}", sets, path, base=mesh)
        assert s["status"] == "ok"
        results[alpha] = (sum(st["ksp_iterations"] for st in s["steps"]), q)
    assert results[1.0][0] < results[None][0], results
    assert all_close(comm, np.allclose(results[1.0][1], results[None][1], rtol=1e-6, atol=1e-14))


def test_softened_operator_is_put_back(comm, mpi_tmp):
    """System.softened changes the pair's rows of J while it is open, and leaves J's values (to round-off) and its
    object state as they were, so that no PC on J sets itself up again."""
    from petsc4py import PETSc

    from qsc_petsc.run import Run
    from qsc_petsc.scene import load_scene
    run = Run(load_scene(scene_without_petsc(mpi_tmp), ["output.xdmf=false", "solver.contact_multigrid_alpha=1"]),
              comm, mpi_tmp / "out", log=lambda *a: None)
    assert run.execute()["status"] == "ok"
    J = run.system.J
    before, state = J.copy(), J.stateGet()
    with run.system.softened(J):
        inside = J.copy()
        inside.axpy(-1.0, before)
    # inside - before = (1 / 1e4 - 1) G^T diag(d) G of the pair (no held dofs here), d the stiffnesses J holds
    pair = [k for k, term in enumerate(run.system.terms) if not term.node_local]
    assert len(pair) == 1
    C = run.system.terms[pair[0]].jacobian(run.system.jacobian_d[pair[0]])
    inside.axpy(1.0 - 1e-4, C, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    assert inside.norm() <= 1e-12 * C.norm() and C.norm() > 0
    assert J.stateGet() == state
    before.axpy(-1.0, J)
    assert before.norm() <= 1e-14 * J.norm()
    inside.destroy()
    before.destroy()
    run.destroy()


def test_softened_multigrid_needs_boomeramg(comm, mpi_tmp):
    """With GAMG named the key is an input error, on every rank, before anything is solved."""
    from qsc_petsc.errors import SceneError
    from qsc_petsc.run import Run
    from qsc_petsc.scene import load_scene
    scene = load_scene(scene_without_petsc(mpi_tmp), ["solver.contact_multigrid_alpha=1", "petsc.pc_type=gamg"])
    with pytest.raises(SceneError, match=r"solver.contact_multigrid_alpha: .*'gamg'"):
        Run(scene, comm, mpi_tmp / "out", log=lambda *a: None)


def test_softening_is_bounded(comm, mpi_tmp):
    """The multigrid's rows are at most SOFTEST times the pair's own (alpha 1e6, key 1: 1e-4, not 1e-6), and a
    pair above SOFTENED_UP_TO (alpha 1e8) keeps its own: softer, the linear solves stopped at 2000 iterations."""
    from qsc_petsc.run import Run
    from qsc_petsc.scene import load_scene
    from qsc_petsc.solver import SOFTEST
    for alpha, expected in ((1e6, SOFTEST - 1.0), (1e8, 0.0)):
        run = Run(load_scene(scene_without_petsc(mpi_tmp), ["output.xdmf=false", "solver.contact_multigrid_alpha=1",
                                                         f"contact.0.penalty={alpha}"]),
                  comm, mpi_tmp / f"out_{alpha}", log=lambda *a: None)
        assert run.execute()["status"] == "ok"
        J = run.system.J
        before = J.copy()
        with run.system.softened(J):
            change = J.copy()
            change.axpy(-1.0, before)
        k = next(k for k, term in enumerate(run.system.terms) if not term.node_local)
        C = run.system.terms[k].jacobian(run.system.jacobian_d[k])
        change.axpy(-expected, C, structure=change.Structure.DIFFERENT_NONZERO_PATTERN)
        assert change.norm() <= 1e-12 * C.norm(), alpha
        for mat in (before, change):
            mat.destroy()
        run.destroy()


def _increments(comm, tmp, path, sets):
    """Krylov iterations per load step, the last displacement, and whether the last increment kept the
    preconditioner of the one before."""
    from qsc_petsc.run import Run
    from qsc_petsc.scene import load_scene
    run = Run(load_scene(path, ["output.xdmf=false", *sets]), comm, tmp, log=lambda *a: None)
    s = run.execute()
    kept = run.system.pc_stale
    run.destroy()
    assert s["status"] == "ok"
    return [st["ksp_iterations"] for st in s["steps"]], s["steps"][-1]["max_abs_displacement"], kept


def test_a_sliding_contact_sets_the_preconditioner_up_again(comm, mpi_tmp, monkeypatch):
    """The flat punch's edges slide on the block between its increments (alpha x the relative change of G^T G:
    170): the second increment sets its preconditioner up again and costs about what the first did; kept as
    the rows are the same (STALE_CHANGE infinite, as before), it took 116-152 Krylov iterations against 24."""
    from qsc_petsc import solver
    path = CONFIGS / "flat_punch.toml"
    its, u, kept = _increments(comm, mpi_tmp / "new", path, [])
    monkeypatch.setattr(solver, "STALE_CHANGE", float("inf"))
    its_stale, u_stale, kept_stale = _increments(comm, mpi_tmp / "stale", path, [])
    assert not kept and kept_stale
    assert its[1] <= 1.5 * its[0], its
    assert its_stale[1] > 3 * its[1], (its, its_stale)
    assert u == pytest.approx(u_stale, rel=1e-8)


def test_a_contact_that_did_not_slide_keeps_the_preconditioner(comm, mpi_tmp):
    """Two cubes between dies expand alike on both sides of their interface: its rows barely move between the
    increments (0.023 of the threshold's measure at 70k dofs), and the second keeps the first's preconditioner.
    (4^3 / 6^3 cells: at 8^3 / 12^3 some projections change faces, and J's pattern with them.)"""
    path = scene_without_petsc(mpi_tmp, comm=comm)
    _, _, kept = _increments(comm, mpi_tmp / "out", path, ["bodies.0.mesh.cells=[4,4,4]", "bodies.1.mesh.cells=[6,6,6]",
                                                           "contact.0.reuse_tolerance=0"])
    assert kept


def test_band_gets_more_mumps_workspace_when_its_estimate_falls_short(comm, mpi_tmp):
    """configs/stiff_plate.toml with Gauss rows: on 2 ranks MUMPS's Cholesky of the band (AMF ordering) ran out of
    the workspace its analysis estimated (INFOG(1) = -9), and the band's solve returned inf: KSP DIVERGED_NANORINF
    at every cutback, exit 3 (a test pass of every config with each integration rule, session 26). The band is
    factored again with twice the memory relaxation ICNTL(14), as System does for its own factors; the option
    it set leaves the database with the run."""
    from petsc4py import PETSc

    from qsc_petsc.run import Run
    from qsc_petsc.scene import load_scene
    run = Run(load_scene(CONFIGS / "stiff_plate.toml", ["contact.0.integration=\"gauss\"", "output.xdmf=false"]),
              comm, mpi_tmp / "out", log=lambda *a: None)
    summary = run.execute()
    band = run.system.snes.getKSP().getPC().getPythonContext().band
    F = band.ksp.getPC().getFactorMatrix()
    assert F.getMumpsInfog(1) == 0
    relaxed = band.own_options
    run.destroy()
    assert summary["status"] == "ok"
    assert all(st["cutbacks"] == 0 for st in summary["steps"])
    if comm.size == 2:            # Debian's MUMPS 5.5.1 on this partition (3 ranks factor it at once)
        assert relaxed == {"qsc_band_mat_mumps_icntl_14"}
    assert not PETSc.Options().hasName("qsc_band_mat_mumps_icntl_14")


def test_a_band_factorization_that_fails_is_named(comm, mpi_tmp):
    """A band whose MUMPS factorization fails for good (here a 1 MB memory cap, INFOG(1) = -19) returned inf
    from its solve: KSP DIVERGED_NANORINF at every cutback named nothing. It is now a ConvergenceError naming
    MUMPS's INFOG codes and the band's options, at once (a smaller increment has the same band)."""
    from qsc_petsc.errors import ConvergenceError
    from qsc_petsc.run import Run
    from qsc_petsc.scene import load_scene
    scene = load_scene(scene_without_petsc(mpi_tmp), ["output.xdmf=false", "petsc.band_mat_mumps_icntl_23=1"])
    run = Run(scene, comm, mpi_tmp / "out", log=lambda *a: None)
    with pytest.raises(ConvergenceError, match=r"the contact band's MUMPS factorization failed: INFOG\(1\) = -19, "
                                               r".*cap ICNTL\(23\) = 1 MB.*-qsc_band_mat_mumps_\*"):
        run.execute()
    run.destroy()
