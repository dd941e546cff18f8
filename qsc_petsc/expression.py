"""Scene expressions: arithmetic in the coordinates x, y, z [m] (e.g. a pressure field), parsed safely, evaluated on arrays."""

import ast
import math

import numpy as np

FUNCTIONS = {"sin": np.sin, "cos": np.cos, "tan": np.tan, "exp": np.exp, "log": np.log, "sqrt": np.sqrt,
             "abs": np.abs, "tanh": np.tanh, "arctan": np.arctan, "minimum": np.minimum, "maximum": np.maximum}
CONSTANTS = {"pi": math.pi, "e": math.e}
VARIABLES = ("x", "y", "z")
_OPS = {ast.Add: np.add, ast.Sub: np.subtract, ast.Mult: np.multiply, ast.Div: np.divide, ast.Pow: np.power}


class ExpressionError(ValueError):
    pass


def _check(node, text):
    if isinstance(node, ast.Expression):
        return _check(node.body, text)
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
        try:
            float(node.value)
        except OverflowError:
            raise ExpressionError(f"number too large: an integer of {node.value.bit_length()} bits") from None
        return
    if isinstance(node, ast.Name):
        if node.id not in VARIABLES and node.id not in CONSTANTS:
            raise ExpressionError(f"unknown name {node.id!r} (allowed: x, y, z, pi, e and the functions "
                                  f"{', '.join(FUNCTIONS)})")
        return
    if isinstance(node, ast.BinOp) and type(node.op) in _OPS:
        _check(node.left, text)
        return _check(node.right, text)
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.UAdd, ast.USub)):
        return _check(node.operand, text)
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and not node.keywords:
        if node.func.id not in FUNCTIONS:
            raise ExpressionError(f"unknown function {node.func.id!r} (allowed: {', '.join(FUNCTIONS)})")
        arity = 2 if node.func.id in ("minimum", "maximum") else 1
        if len(node.args) != arity:
            raise ExpressionError(f"bad function call: {node.func.id} takes {arity} argument(s), got {len(node.args)}")
        for a in node.args:
            _check(a, text)
        return
    raise ExpressionError(f"not allowed in an expression: {ast.get_source_segment(text, node) or type(node).__name__!r}")


def _eval(node, env):
    if isinstance(node, ast.Expression):
        return _eval(node.body, env)
    if isinstance(node, ast.Constant):
        return float(node.value)
    if isinstance(node, ast.Name):
        return env[node.id] if node.id in env else CONSTANTS[node.id]
    if isinstance(node, ast.BinOp):
        return _OPS[type(node.op)](_eval(node.left, env), _eval(node.right, env))
    if isinstance(node, ast.UnaryOp):
        v = _eval(node.operand, env)
        return -v if isinstance(node.op, ast.USub) else v
    return FUNCTIONS[node.func.id](*(_eval(a, env) for a in node.args))


def compile_expression(text):
    """A function f(points (n, 3)) -> (n,) of the expression text in x, y, z; ExpressionError if it is not valid."""
    try:
        tree = ast.parse(text.strip(), mode="eval")
        _check(tree, text)
    except ExpressionError:
        raise
    except SyntaxError as exc:
        raise ExpressionError(f"not a valid expression ({exc.msg})") from None
    except (RecursionError, MemoryError):
        raise ExpressionError("nested too deeply to parse") from None
    except ValueError as exc:          # an integer literal of over 4300 digits
        raise ExpressionError(f"not a valid expression ({exc})") from None

    def f(points):
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        env = dict(zip(VARIABLES, points.T))
        with np.errstate(all="ignore"):
            out = np.broadcast_to(np.asarray(_eval(tree, env), dtype=float), (len(points),)).copy()
        return out
    return f
