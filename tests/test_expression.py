"""Scene expressions (pressure fields): safe parsing, array evaluation, clear errors, consistent loads."""

import numpy as np
import pytest
from conftest import CONFIGS

from qsc_petsc import fem
from qsc_petsc.errors import SceneError
from qsc_petsc.expression import ExpressionError, compile_expression
from qsc_petsc.scene import load_scene


def test_expression_evaluates_on_points():
    f = compile_expression("1 + 0.5*cos(pi*x)*cos(pi*y) - z**2 / 4")
    p = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 2.0], [0.5, 0.3, 1.0]])
    np.testing.assert_allclose(f(p), 1 + 0.5 * np.cos(np.pi * p[:, 0]) * np.cos(np.pi * p[:, 1]) - p[:, 2] ** 2 / 4)
    np.testing.assert_array_equal(compile_expression("3")(p), [3.0, 3.0, 3.0])


@pytest.mark.parametrize("text, message", [
    ("__import__('os')", "unknown function"),
    ("x.real", "not allowed"),
    ("q + 1", "unknown name 'q'"),
    ("1 +", "not a valid expression"),
    ("sin(x, y)", "bad function call"),
    ("[x]", "not allowed"),
    ("1" + "+1" * 20000, "nested too deeply"),        # Python's parser itself recurses too deep
    ("-" * 5000 + "1", "nested too deeply"),
    ("1" + "0" * 400 + " * x", "number too large"),     # an integer beyond any float
])
def test_bad_expressions_are_refused(text, message):
    with pytest.raises(ExpressionError, match=message):
        compile_expression(text)


def test_scene_pressure_expression_is_validated():
    """A bad pressure expression shall be a SceneError naming the key."""
    with pytest.raises(SceneError, match=r"boundary\[5\]\.value: unknown name 'r'"):
        load_scene(CONFIGS / "patch_test.toml", ["boundary.5.value=\"1 + r\""])
    scene = load_scene(CONFIGS / "patch_test.toml", ["boundary.5.value=\"1 + 0.5*cos(pi*x)*cos(pi*y)\""])
    assert scene.boundary[5].value == "1 + 0.5*cos(pi*x)*cos(pi*y)"


def test_pressure_field_loads_integrate_the_field():
    """Nodal loads of a pressure field on a flat face grid shall sum to its integral (exact for a bilinear field)."""
    n = 4
    t = np.linspace(0, 1, n + 1)
    X, Y = np.meshgrid(t, t, indexing="ij")
    xyz = np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])
    v = np.arange(xyz.shape[0]).reshape(n + 1, n + 1)
    quads = np.column_stack([v[:-1, :-1].ravel(), v[1:, :-1].ravel(), v[1:, 1:].ravel(), v[:-1, 1:].ravel()])
    f = compile_expression("2 + x*y")
    loads = fem.face_pressure_loads("quad", xyz[quads], f)
    assert loads[..., 2].sum() == pytest.approx(-(2 + 0.25), rel=1e-13)    # outward +z: pushes along -z
    # the moment about the y axis, int x p dA = int x (2 + x y) = 1 + 1/6, is matched by the consistent loads
    moment = np.einsum("mv,mv->", xyz[quads][..., 0], loads[..., 2])
    assert moment == pytest.approx(-(1 + 1 / 6), rel=1e-13)


@pytest.mark.parametrize("value", ["1/0", "sqrt(-1)", "10**400", "1/(x - x)"])
def test_pressure_that_is_not_finite_is_a_scene_error(value, tmp_path):
    """A pressure expression that evaluates to inf or NaN on a face shall be a SceneError naming the key and
    where, not a solve that fails with DIVERGED_FNORM_NAN after every cutback."""
    from conftest import run_scene
    with pytest.raises(SceneError, match=r"^boundary\[5\]\.value: the pressure .* on upper\.zmax is not finite "
                                          r"on the face near x, y, z = "):
        run_scene(CONFIGS / "patch_test.toml", tmp_path, [f"boundary.5.value={value!r}"])


@pytest.mark.parametrize("value", ["1e150 * (1 + x)", "1e-200", "2**1000"])
def test_pressure_beyond_the_number_limits_is_a_scene_error(value, tmp_path):
    """A pressure field whose finite values break the scene's number limits (0 or of magnitude 1e-100 to 1e100)
    shall be a SceneError naming the key, where and the value: 1e150 * x ran to "converged" displacements of
    1e147 m, 1e-200 to DIVERGED_MAX_IT."""
    from conftest import run_scene
    with pytest.raises(SceneError, match=r"^boundary\[5\]\.value: the pressure .* on upper\.zmax is \S+ on the face "
                                          r"near x, y, z = .*: a value must be 0 or of magnitude between 1e-100"):
        run_scene(CONFIGS / "patch_test.toml", tmp_path, [f"boundary.5.value={value!r}"])


def test_a_pressure_field_whose_tail_underflows_is_applied(tmp_path):
    """A Gaussian patch's values fall below the scene's 1e-100 floor far from its centre (1e-189 at a corner): they
    are no load, made 0, where the field was refused (hunt33_2). The same load as the field zeroed by hand there;
    a field all of whose values lie below the floor stays an error (above)."""
    from conftest import run_scene
    gauss = "10 * exp(-((x - 0.5)**2 + (y - 0.5)**2) / 0.001)"
    forces = []
    for value in (gauss, f"maximum({gauss} - 1e-90, 0)"):
        run, summary = run_scene(CONFIGS / "patch_test.toml", tmp_path / str(len(forces)),
                                 [f"boundary.5.value={value!r}"])
        run.destroy()
        assert summary["status"] == "ok"
        forces.append(summary["steps"][-1]["reactions"]["boundary[0] lower.zmin"][2])
    assert forces[0] > 0.01 and forces[0] == pytest.approx(forces[1], rel=1e-12)
