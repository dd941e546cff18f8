"""Scene files: the schema declared once, TOML loading, --set overrides, validation, and the resolved TOML."""

from __future__ import annotations

import copy
import math
import operator
import os
import re
import tomllib
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from .errors import SceneError

OPTIONS_PREFIX = "qsc_"  # root of every PETSc options prefix; the program adds it, scenes must not
BODY_NAME = r"[A-Za-z_][A-Za-z0-9_]*"
BOX_SURFACES = ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")
REQUIRED = object()
# every number of a scene is 0 or of magnitude within [MIN_MAGNITUDE, MAX_MAGNITUDE]: lengths, moduli and
# penalties are multiplied and squared downstream (eps_n = alpha E / h, norms of forces), and a value near the
# floating-point limits overflowed there into a traceback (a box 1e308 m wide) or an infinite stiffness
MAX_MAGNITUDE, MIN_MAGNITUDE = 1e100, 1e-100
# the largest dimensionless penalty alpha (contact pairs and dies): measured sound up to 1e10 (the patch test's
# force balance to 2.5e-7 with MUMPS, docs/stability.md); at 1e11 Hertz's balance was off by 5e-3 and at 1e12
# three identical runs ended "converged" 2.3x apart, the step too small to tell from round-off
MAX_PENALTY = 1e10


# ---------------------------------------------------------------- TOML text

_ESCAPES = {'"': '\\"', "\\": "\\\\", "\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f", "\r": "\\r"}


def _toml_string(text: str) -> str:
    # TOML basic strings forbid raw control characters, DEL included.
    return '"' + "".join(
        _ESCAPES.get(c) or (f"\\u{ord(c):04x}" if ord(c) < 0x20 or ord(c) == 0x7F else c) for c in text
    ) + '"'


def _toml_key(key: str) -> str:
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else _toml_string(key)


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):  # before int: bool is an int subclass
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        return repr(value) if math.isfinite(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, str):
        return _toml_string(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(f"no TOML form for {type(value).__name__}")


def _write_table(table: dict, keys: list[str], lines: list[str]) -> None:
    def is_table_array(v):
        return isinstance(v, list) and v and all(isinstance(x, dict) for x in v)

    # TOML needs a table's plain keys before its first sub-table header; None means "absent".
    for key, value in table.items():
        if value is not None and not isinstance(value, dict) and not is_table_array(value):
            lines.append(f"{_toml_key(key)} = {_toml_value(value)}")
    for key, value in table.items():
        header = ".".join(_toml_key(k) for k in keys + [key])
        if isinstance(value, dict):
            lines += ["", f"[{header}]"]
            _write_table(value, keys + [key], lines)
        elif is_table_array(value):
            for item in value:
                lines += ["", f"[[{header}]]"]
                _write_table(item, keys + [key], lines)


def _show(value: Any, limit: int = 60) -> str:
    """A value as the user wrote it (TOML form), cut short to keep error messages on one line."""
    try:
        text = _toml_value(value)
    except TypeError:
        text = _toml_string(str(value))
    except ValueError:          # an integer past Python's 4300-digit str limit
        text = f"an integer of {value.bit_length()} bits"
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _join(path: str, key: str | int) -> str:
    if isinstance(key, int):
        return f"{path}[{key}]"
    return f"{path}.{_toml_key(key)}" if path else _toml_key(key)


# ---------------------------------------------------------------- schema building blocks

class Field:
    """One scene key: its doc sentence, default (REQUIRED, None = optional, or a value) and unit."""

    kind, noun = "value", "a value"  # for the reference table, and for "expected ..." messages

    def __init__(self, doc: str = "", *, default: Any = REQUIRED, unit: str = "", show_default: str | None = None):
        self.doc, self.default, self.unit, self.show_default = doc, default, unit, show_default

    def check(self, value: Any, path: str) -> Any:
        raise NotImplementedError

    def missing(self, path: str) -> Any:
        if self.default is REQUIRED:
            raise SceneError(f"{path}: required key missing")
        # Defaults go through check() too, so they are normalised exactly like user values.
        return None if self.default is None else self.check(copy.deepcopy(self.default), path)

    def wrong_type(self, value: Any, path: str, extra: str = "") -> SceneError:
        return SceneError(f"{path}: expected {self.noun}{extra}, got {_show(value)}")

    def type_text(self) -> str:
        return self.kind

    def range_text(self) -> str:
        return ""

    def default_text(self) -> str:
        if self.show_default is not None:
            return self.show_default
        if self.default is REQUIRED:
            return "required"
        return "optional" if self.default is None else f"`{_toml_value(self.default)}`"

    def children(self, path: str) -> Iterator[tuple[str, Field, str]]:
        return iter(())


_COMPARE = {">": operator.gt, ">=": operator.ge, "<": operator.lt, "<=": operator.le}


class Float(Field):
    kind, noun = "float", "a number"

    def __init__(self, doc="", *, gt=None, ge=None, lt=None, le=None, also: tuple[str, ...] = (), **kw):
        super().__init__(doc, **kw)
        self.bounds = [(op, b) for op, b in zip(_COMPARE, (gt, ge, lt, le)) if b is not None]
        self.also = also  # strings accepted besides numbers, such as "finer"

    def _also(self) -> str:
        return "".join(f" or {_toml_string(s)}" for s in self.also)

    def _number(self, value, path):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.wrong_type(value, path, self._also())
        try:
            finite = math.isfinite(value)
        except OverflowError:           # an integer beyond any float
            finite = False
        if not finite:
            raise SceneError(f"{path}: expected a finite number, got {_show(value)}")
        if value != 0 and not MIN_MAGNITUDE <= abs(value) <= MAX_MAGNITUDE:
            raise SceneError(f"{path}: must be 0 or of magnitude between {MIN_MAGNITUDE:g} and {MAX_MAGNITUDE:g}, "
                             f"got {_show(value)}")
        if not all(_COMPARE[op](value, bound) for op, bound in self.bounds):
            raise SceneError(f"{path}: must be {self.range_text()}{self._also()}, got {_show(value)}")
        return value

    def check(self, value, path):
        if isinstance(value, str) and value in self.also:
            return value
        return float(self._number(value, path))

    def type_text(self):
        return self.kind + self._also()

    def range_text(self):
        return " and ".join(f"{op} {bound:g}" if isinstance(bound, float) else f"{op} {bound!r}"
                            for op, bound in self.bounds)


class Int(Float):
    """An integer; at most INT_MAX unless a bound says less (PETSc and MPI take C ints)."""

    kind, noun = "int", "an integer"
    INT_MAX = 2**31 - 1

    def check(self, value, path):
        if not isinstance(value, int) or isinstance(value, bool):
            raise self.wrong_type(value, path)
        if value > self.INT_MAX and not any(op in ("<", "<=") for op, _ in self.bounds):
            raise SceneError(f"{path}: must be at most {self.INT_MAX}, got {_show(value)}")
        return int(self._number(value, path))


class Bool(Field):
    kind, noun = "bool", "true or false"

    def check(self, value, path):
        if not isinstance(value, bool):
            raise self.wrong_type(value, path)
        return value


class Str(Field):
    kind, noun = "string", "a string"

    def __init__(self, doc="", *, pattern: str | None = None, **kw):
        super().__init__(doc, **kw)
        self.pattern = pattern

    def check(self, value, path):
        if not isinstance(value, str):
            raise self.wrong_type(value, path)
        if self.pattern and not re.fullmatch(self.pattern, value):
            raise SceneError(f"{path}: must match ^{self.pattern}$, got {_show(value)}")
        return value

    def range_text(self):
        return f"`^{self.pattern}$`" if self.pattern else ""


class FolderName(Str):
    """A string that names a folder: not empty, ".", "..", nor holding a path separator or a control character."""

    def check(self, value, path):
        value = super().check(value, path)
        if value in ("", ".", "..") or re.search(r"[/\\\x00-\x1f]", value):
            raise SceneError(f"{path}: names the output folder: must be a non-empty name without / or \\ "
                             f"(not . or ..), got {_show(value)}")
        return value

    def range_text(self):
        return "a folder name: no / or \\, not . or .."


class Filled(Str):
    """A string that is not empty nor blank: `output.directory = ""` wrote (and cleared) the results in the working
    directory, and `die.name = ""` named its summary entry "die[0] " (hunt34_3)."""

    def check(self, value, path):
        value = super().check(value, path)
        if not value.strip():
            raise SceneError(f"{path}: must not be empty, got {_show(value)}")
        return value

    def range_text(self):
        return "not empty"


class SurfaceRef(Str):
    """A "body.surface" reference; whether the body exists is a cross check (see _cross_check)."""

    kind, noun = '"body.surface"', 'a "body.surface" string'

    def check(self, value, path):
        if not isinstance(value, str) or not re.fullmatch(r"[^.]+\..+", value):
            raise self.wrong_type(value, path)
        return value


class Choice(Str):
    def __init__(self, choices: tuple[str, ...], doc="", **kw):
        super().__init__(doc, **kw)
        self.choices = choices

    def check(self, value, path):
        if not isinstance(value, str) or value not in self.choices:
            raise SceneError(f"{path}: must be one of {self.range_text()}, got {_show(value)}")
        return value

    def range_text(self):
        return ", ".join(_toml_string(c) for c in self.choices)


class ListOf(Field):
    def __init__(self, item: Field, doc="", *, length: int | None = None, min_len: int = 0, **kw):
        super().__init__(doc, **kw)
        self.item, self.length, self.min_len = item, length, min_len

    def check(self, value, path):
        if not isinstance(value, list) or (self.length is not None and len(value) != self.length):
            count = f"{self.length} " if self.length is not None else ""
            plural = self.item.noun.split(" ", 1)[1] + "s"  # "a number" -> "numbers"
            raise SceneError(f"{path}: expected a list of {count}{plural}, got {_show(value)}")
        if len(value) < self.min_len:
            entries = "one entry" if self.min_len == 1 else f"{self.min_len} entries"
            raise SceneError(f"{path}: needs at least {entries}, got {_show(value)}")
        return [self.item.check(v, _join(path, i)) for i, v in enumerate(value)]

    def type_text(self):
        if isinstance(self.item, Table):
            return "array of tables"
        return f"{self.item.kind}[{self.length}]" if self.length else f"list of {self.item.kind}"

    def range_text(self):
        parts = [f"at least {self.min_len}"] if self.min_len else []
        parts += [f"each {self.item.range_text()}"] if self.item.range_text() else []
        return "; ".join(parts)

    def children(self, path):
        return self.item.children(path + "[]")


class NumberOrExpression(Float):
    """A number, or a string expression in the coordinates x, y, z [m] (see qsc_petsc.expression)."""

    kind = "float or expression in x, y, z"

    def check(self, value, path):
        if isinstance(value, str):
            from .expression import ExpressionError, compile_expression
            try:
                compile_expression(value)
            except ExpressionError as exc:
                raise SceneError(f"{path}: {exc}, got {_show(value)}") from None
            return value
        return super().check(value, path)

    def type_text(self):
        return self.kind


class WeightRule(Float):
    """Quasi-symmetric weight: a constant w_a in [0, 1], "finer", or a table {power = p} (p > 0)."""

    kind = 'float, "finer" or {power = p}'

    def _also(self):
        return super()._also() + " or {power = p}"

    def check(self, value, path):
        if isinstance(value, dict):
            if set(value) != {"power"}:
                raise SceneError(f"{path}: a weight table takes exactly one key, power, got {_show(value)}")
            return {"power": Float(gt=0).check(value["power"], _join(path, "power"))}
        return super().check(value, path)

    def type_text(self):
        return self.kind


def Vec3(item: Field, doc="", **kw) -> ListOf:
    return ListOf(item, doc, length=3, **kw)


class Table(Field):
    kind, noun = "table", "a table"

    def __init__(self, fields: dict[str, Field], doc="", **kw):
        kw.setdefault("default", {})  # an absent table is an empty one: all its defaults apply
        super().__init__(doc, **kw)
        self.fields = fields

    def check(self, value, path):
        if not isinstance(value, dict):
            raise self.wrong_type(value, path)
        # None counts as absent (TOML has no null), so that to_dict() output is valid input again.
        for key, v in value.items():
            if v is not None and key not in self.fields:
                raise SceneError(f"{_join(path, key)}: unknown key (expected one of: {', '.join(sorted(self.fields))})")
        out = {}
        for key, field in self.fields.items():
            sub = _join(path, key)
            out[key] = field.check(value[key], sub) if value.get(key) is not None else field.missing(sub)
        return out

    def default_text(self):
        return "" if self.default == {} else super().default_text()

    def children(self, path):
        for key, field in self.fields.items():
            yield _join(path, key), field, ""
            yield from field.children(_join(path, key))


class Variant(Table):
    """A table whose allowed keys depend on the value of one discriminator key."""

    def __init__(self, key: str, key_doc: str, common: dict[str, Field], variants: dict[str, dict[str, Field]],
                 doc="", **kw):
        self.key, self.variants = key, variants
        self.choice = Choice(tuple(variants), key_doc)
        self.tables = {name: Table({key: self.choice, **common, **fields}) for name, fields in variants.items()}
        super().__init__({key: self.choice, **common}, doc, **kw)

    def check(self, value, path):
        if not isinstance(value, dict):
            raise self.wrong_type(value, path)
        sub = _join(path, self.key)
        kind = self.choice.check(value[self.key], sub) if value.get(self.key) is not None else self.choice.missing(sub)
        for k, v in value.items():
            owners = [name for name, fields in self.variants.items() if k in fields and name != kind]
            if owners and v is not None and k not in self.tables[kind].fields:
                raise SceneError(f"{_join(path, k)}: only for {self.key} = {' or '.join(map(_toml_string, owners))}")
        return self.tables[kind].check(value, path)

    def children(self, path):
        yield from super().children(path)
        for name, fields in self.variants.items():
            for key, field in fields.items():
                yield _join(path, key), field, f" Only for {self.key} = {_toml_string(name)}."
                yield from field.children(_join(path, key))


def _flatten_options(table: dict, path: str, prefix: str = "") -> dict[str, tuple[str, Any]]:
    """Nested option tables to {option name: (key path, value)}, names joined by "_"."""
    flat: dict[str, tuple[str, Any]] = {}
    for key, value in table.items():
        sub = _join(path, key)
        if isinstance(value, dict):
            items = _flatten_options(value, sub, f"{prefix}{key}_")
        else:
            items = {prefix + key: (sub, value)}
        for name, (where, v) in items.items():
            if name in flat:
                raise SceneError(f"{where}: same PETSc option as {flat[name][0]} ({name})")
            flat[name] = (where, v)
    return flat


class Options(Field):
    """PETSc options: a nested table flattened to option names, merged over the defaults."""

    kind, noun = "table", "a table"

    def check(self, value, path):
        if not isinstance(value, dict):
            raise self.wrong_type(value, path)
        out = dict(self.default)
        for name, (where, v) in _flatten_options(value, path).items():
            if name.startswith(("-", OPTIONS_PREFIX)):
                raise SceneError(f"{where}: write the option without a leading '-' or the {OPTIONS_PREFIX!r} prefix "
                                 f"(the program adds them)")
            if not re.fullmatch(r"[A-Za-z0-9_]+", name):
                raise SceneError(f"{where}: not a PETSc option name")
            if isinstance(v, bool):      # true: the flag with no value (a viewer option such as ksp_monitor
                out[name] = "" if v else "false"     # refuses "true")
            elif isinstance(v, (int, float, str)):
                out[name] = v if isinstance(v, str) else repr(v)
            else:
                raise SceneError(f"{where}: expected a string, number or boolean, got {_show(v)}")
        return out


# ---------------------------------------------------------------- the schema

PETSC_DEFAULTS = {"ksp_rtol": "1e-10"}      # the [petsc] table's defaults (petsc_options.txt says which)

BODY = Table({
    "name": Str("Unique body name, used in \"body.surface\" references.", pattern=BODY_NAME),
    "mesh": Variant("type", "How the body is meshed: a generated box, a mesh file, or a part of the "
                             "Hertz benchmark generated with gmsh.", common={}, variants={
        "box": {
            "origin": Vec3(Float(), "Corner of the box with the smallest coordinates.", default=[0, 0, 0], unit="m"),
            "size": Vec3(Float(gt=0), "Edge lengths of the box along x, y, z.", unit="m"),
            "cells": Vec3(Int(ge=1), "Number of cells along x, y, z."),
            "element": Choice(("hex", "tet"), "Cell type of the generated mesh.", default="hex"),
            "rotation": Vec3(Float(), "Rotation vector applied to the generated box about (0, 0, 0): axis times "
                             "angle (right hand); faces keep their names; bodies given the same rotation keep "
                             "their relative placement.", default=[0, 0, 0], unit="degrees"),
        },
        "file": {
            "path": Str("Mesh file, relative to the scene file's folder; its physical groups name the surfaces."),
            "scale": Float("Factor multiplying the file's coordinates.", gt=0, default=1.0),
        },
        "hertz": {
            "part": Choice(("sphere", "block"), "Part of the Hertz benchmark (qsc_petsc/hertz.py): the quarter "
                           "sphere (surfaces xmin ymin top contact outer) or the quarter block (xmin ymin zmin "
                           "xmax ymax contact top)."),
            "level": Choice(("coarse", "medium", "fine", "xfine"), "Element size at the contact: 1/4, 1/8, 1/16 "
                            "or 1/32 of a = 0.1 R on the sphere, 1.4x that on the block.", default="coarse"),
            "radius": Float("Sphere radius R; every dimension of both parts scales with it.", gt=0, default=1.0,
                            unit="m"),
            "cache": Str("Folder of the generated .msh files, made with gmsh when missing; relative to the "
                         "working directory.", default="build/meshes"),
        },
    }, doc="The body's mesh."),
    "material": Table({
        "youngs_modulus": Float("Young's modulus E of the linear elastic material.", gt=0, unit="Pa"),
        "poissons_ratio": Float("Poisson's ratio nu.", gt=-1, lt=0.5, default=0.3),
        "volumetric": Choice(("full", "mean_dilatation"),
                             "How hexahedra integrate the volumetric (bulk) energy: at every Gauss point (full), "
                             "which locks as nu nears 0.5 (a punch's force 2.6x at nu = 0.499), or with each cell's "
                             "mean dilatation (B-bar, selectively reduced: no volumetric locking, the patch test "
                             "still exact). Linear tetrahedra have one strain per cell: full only.",
                             default="full"),
    }, "Linear elastic material of the body."),
})

BOUNDARY = Variant("type", "Kind of boundary condition.", common={
    "surface": SurfaceRef("Surface the condition acts on (a generated box has xmin xmax ymin ymax zmin zmax)."),
}, variants={
    "displacement": {
        "ux": Float("Prescribed x displacement at the last load step; absent means free.", default=None, unit="m"),
        "uy": Float("Prescribed y displacement at the last load step; absent means free.", default=None, unit="m"),
        "uz": Float("Prescribed z displacement at the last load step; absent means free.", default=None, unit="m"),
    },
    "pressure": {"value": NumberOrExpression("Pressure at the last load step; positive pushes into the body. A "
                                             "string is a field in x, y, z [m], e.g. \"1 + 0.5*cos(pi*x)*cos(pi*y)\".",
                                             unit="Pa")},
    "symmetry": {},  # zero normal displacement; the mesh layer checks the plane is axis-aligned
})

CONTACT = Table({
    "slave": SurfaceRef("Slave surface: carries the multipliers (and the rows of the constraint)."),
    "master": SurfaceRef("Master surface, on another body than the slave."),
    "formulation": Choice(("master_slave", "two_pass", "quasi_symmetric"), "How the constraint rows are built.",
                          default="quasi_symmetric"),
    "weight": WeightRule("Slave-side weight w_a of quasi_symmetric (0.5: the paper); {power = p}: "
                         "w_a = h_b^p / (h_a^p + h_b^p) from the local face sizes, weighting the finer side; "
                         "\"finer\" is p = 4.", ge=0, le=1, also=("finer",), default=0.5),
    "integration": Choice(("nodal", "gauss", "segment"),
                          "Quadrature of the contact integrals: surface nodes (node-to-segment, the paper), "
                          "gauss_points^2 Gauss points per face, or exact segment integration over the overlaps "
                          "of the two surfaces' faces (the default: exact on every formulation for ~1.2x the "
                          "run time of nodal rows, docs/performance.md).", default="segment"),
    "master_multiplier": Choice(("slave_at_points", "master_nodes"),
                                "quasi_symmetric's multiplier on the master side: the slave multiplier evaluated at "
                                "each master quadrature point's projection, or interpolated from master-node values "
                                "(paper [8]-[10]); the same with nodal integration.", default="slave_at_points"),
    "feature_angle": Float("Sharp edges and corners: the nodes of either surface where it folds convexly, its faces "
                           "tilting on average by more than this angle from the node's normal (45 on a box's edge, "
                           "a knife's faces' tilt from its edge's normal) and whose faces lean from the other "
                           "surface by more than it, take a nodal row of their own (a node against the other "
                           "surface, as node-to-segment) in place of their weighted row, which would let them sink "
                           "about h tan(angle) / 3 with no force, and the other surface's nodes under them a nodal "
                           "row besides theirs (README: Sharp edges); absent: none.", gt=0, lt=90, default=None,
                           unit="degrees"),
    "gauss_points": Int("Gauss points per direction on each face with integration = \"gauss\" (a triangle "
                        "gets a rule symmetric in its vertices, at least n^2 points exact to degree 2n - 2: 1, 6, 12, "
                        "16 points for n = 1-4, 3 n^2 above).", ge=1, le=10, default=3),
    "penalty": Float("Dimensionless alpha of the penalty eps_n = alpha * E_eff / h_eff (E_eff: the smaller Young's "
                     "modulus; h_eff: the smaller of the two surfaces' mean face sizes over the faces that can touch "
                     "the other surface; at most 1e10; tighter contact: enforcement = \"augmented_lagrangian\").",
                     gt=0, le=MAX_PENALTY, default=1e4),
    "enforcement": Choice(("penalty", "augmented_lagrangian"), "How the constraint is enforced.", default="penalty"),
    "augmented_tolerance": Float("Relative change of the multipliers that ends the augmented Lagrangian loop "
                                 "(relative to the pressure of a strain of 1e-6 where the multipliers are smaller).",
                                 gt=0, default=1e-6),
    "augmented_max_iterations": Int("Most augmented Lagrangian updates per load step (one loop updates every "
                                    "augmented pair: the largest of their values holds).", ge=1, default=25),
    "search_distance": Float("Largest gap that still makes a contact row, in units of the pair's element size.",
                             gt=0, default=1.0, unit="h_eff"),
    "sliding": Choice(("finite", "small", "large"),
                      "\"finite\": a new search in the deformed configuration at every load step, so that the rows "
                      "follow the sliding; \"large\": finite, and after every converged solve of an increment a "
                      "new search at the converged state, the increment solved again on its rows until a search "
                      "finds the rows it was solved with (within reuse_tolerance): the answer's rows are its own "
                      "configuration's, however far the increment slid; \"small\": one search, in the undeformed "
                      "configuration, whose rows "
                      "are kept for the whole run (the gap linear in the displacement, for sliding well below an "
                      "element size, as in small-strain problems): no search after the first, and a later increment "
                      "whose active set holds starts on its answer (the extrapolating predictor); only points "
                      "within search_distance at the start can ever touch.", default="finite"),
    "reuse_tolerance": Float("Finite and large sliding: a new search whose rows are the last term's rows, with gaps at the "
                             "increment's start within this fraction of the pair's largest penetration (with the "
                             "augmented Lagrangian: its largest pressure / eps_n) of theirs, "
                             "keeps the last term (its rows linearised about the search they come from, as small "
                             "sliding does), so that an increment over which nothing slid starts on the last "
                             "answer's linear extrapolation; 0: every search makes new rows (not with large "
                             "sliding, whose searches settle by it).", ge=0, default=1e-3),
    "max_searches": Int("Large sliding: most searches per increment, its start's included; an increment whose rows "
                        "have not settled by then is cut in half (slides of configs/sliding_cubes.toml measured in "
                        "session 26 settled in 6-11 searches with segment rows, 7-19 with nodal and 5-14 with Gauss "
                        "rows).", ge=2,
                        default=20),
})

DIE = Table({
    "name": Filled("Unique die name."),
    "point": Vec3(Float(), "A point of the die's flat face.", unit="m"),
    "normal": Vec3(Float(), "Normal of the die face, pointing from the die toward the bodies (normalised here)."),
    "motion": Vec3(Float(), "Die displacement reached at the last load step, ramped linearly.", default=[0, 0, 0],
                   unit="m"),
    "surfaces": ListOf(SurfaceRef(), "Body surfaces the die can touch.", min_len=1),
    "condition": Choice(("frictionless", "sticking"), "Tangential condition on the die face; sticking holds each "
                        "node where it met the die.", default="frictionless"),
    "penalty": Float("Dimensionless alpha of the penalty eps_n = alpha * E / h (h: the mean size of the faces turned "
                     "towards the die; at most 1e10).", gt=0,
                     le=MAX_PENALTY, default=1e4),
    "search_distance": Float("Largest gap that still makes a contact row, in units of the body's element size.",
                             gt=0, default=1.0, unit="h"),
})

SCHEMA = Table({
    "name": FolderName("Scene name, used in the output folder.", show_default="file name without .toml"),
    "description": Str("Free text describing the scene.", default=""),
    "bodies": ListOf(BODY, "The deformable bodies (at least one).", min_len=1),
    "boundary": ListOf(BOUNDARY, "Boundary conditions on body surfaces.", default=[]),
    "contact": ListOf(CONTACT, "Contact pairs between surfaces of two bodies.", default=[]),
    "die": ListOf(DIE, "Rigid flat dies pressed against body surfaces.", default=[]),
    "load": Table({
        "steps": Int("Load steps; loads and prescribed displacements ramp linearly to full at the last.", ge=1,
                     le=1_000_000, default=1),
    }, "Load stepping."),
    "solver": Table({
        "max_cutbacks": Int("How many times a failed load step is halved before the run stops.", ge=0, le=30,
                            default=4),
        "max_active_set_iterations": Int("Most active-set (semi-smooth Newton) iterations per load step.", ge=1,
                                         default=60),
        "active_set_tolerance": Float("Relative closed-set tolerance on the constraint rows.", gt=0, default=1e-12),
        "predictor": Choice(("extrapolate", "previous"),
                            "Where an increment's Newton iterations start: the linear extrapolation of the last "
                            "two converged states along the load (\"extrapolate\"; the previous state on the "
                            "first increment and after a failed try), or the previous converged state.",
                            default="extrapolate"),
        "contact_preconditioner": Choice(("auto", "band", "none"),
                                         "Linear solves with contact pairs: \"auto\" composes an algebraic "
                                         "multigrid (BoomerAMG unless pc_type names gamg) with an exact solve on the "
                                         "contact band when pc_type is unset, hypre or gamg, under GMRES unless "
                                         "ksp_type is named; \"band\" composes whatever pc_type names; \"none\" "
                                         "uses the options as given (CG + GAMG when unset). Without contact pairs "
                                         "the default is CG + GAMG.",
                                         default="auto"),
        "contact_band_layers": Int("Rings of element neighbours added to the contact rows' dofs in the band.",
                                   ge=0, le=5, default=1),
        "contact_multigrid_alpha": Float(
            "Dimensionless penalty of the contact pairs in the operator BoomerAMG's coarse spaces are built from "
            "(the Krylov method and the band's solve keep the pairs' own); absent: the pairs' own. 1 builds them "
            "as if the interface were as stiff as the elements beside it: for large contacts between bodies held "
            "elsewhere (two cubes between dies, 212k dofs: 64 -> 40 Krylov iterations), not small ones (Hertz: "
            "334 -> 461). At most 1e4 times softer than a pair's own; pairs above alpha 1e6 keep theirs.",
            gt=0, default=None),
        "contact_slip_modes": Bool("With the band preconditioner (unless ksp_type is cg): a Galerkin correction "
                                   "on each contact body's rigid motions, faded from its contact surface to its "
                                   "far side, which the multigrid leaves to the Krylov method (frictionless "
                                   "bodies sliding on each other).", default=True),
    }, "Nonlinear solver controls."),
    "petsc": Options(f"PETSc options without the {OPTIONS_PREFIX!r} prefix, nested tables joined by \"_\"; "
                     "merged over the defaults.", default=PETSC_DEFAULTS),
    "output": Table({
        "directory": Filled("Output folder; {name} is the scene name; relative to the working directory.",
                            default="results/{name}"),
        "xdmf": Bool("Write the solution as solution.xdmf/.h5.", default=True),
    }, "What is written, and where."),
})


# ---------------------------------------------------------------- the resolved scene

def _thaw(value: Any) -> Any:
    if isinstance(value, Node):
        return value.to_dict()
    return [_thaw(v) for v in value] if isinstance(value, tuple) else value


def _freeze(value: Any, path: str) -> Any:
    if isinstance(value, dict):
        return Node({k: _freeze(v, _join(path, k)) for k, v in value.items()}, path)
    if isinstance(value, list):
        return tuple(_freeze(v, _join(path, i)) for i, v in enumerate(value))
    return value


class Node:
    """A read-only table of the resolved scene with attribute access (``node.youngs_modulus``)."""

    __slots__ = ("_data", "_path")

    def __init__(self, data: dict, path: str = ""):
        object.__setattr__(self, "_data", dict(data))
        object.__setattr__(self, "_path", path)

    def __getattr__(self, key: str) -> Any:
        if key.startswith("_"):  # never look up internals in _data (e.g. during unpickling)
            raise AttributeError(key)
        try:
            return self._data[key]
        except KeyError:
            raise AttributeError(f"{_join(self._path, key)}: no such key") from None

    def __setattr__(self, key, value):
        raise AttributeError(f"{_join(self._path, key)}: the scene is read-only")

    __delattr__ = __setattr__

    def __eq__(self, other):
        return self._data == other._data if type(other) is type(self) else NotImplemented

    def __reduce__(self):
        return type(self), (self._data, self._path)

    def __repr__(self):
        return f"{type(self).__name__}({self.to_dict()!r})"

    def to_dict(self) -> dict:
        return {k: _thaw(v) for k, v in self._data.items()}


class Scene(Node):
    """The validated scene, every default filled in; equal scenes have equal to_dict()."""

    __slots__ = ("source_dir",)
    name: str
    description: str
    bodies: tuple[Node, ...]
    boundary: tuple[Node, ...]
    contact: tuple[Node, ...]
    die: tuple[Node, ...]
    load: Node
    solver: Node
    output: Node

    def __init__(self, data: dict, source_dir: str | os.PathLike):
        super().__init__(data)
        object.__setattr__(self, "source_dir", Path(source_dir))  # where relative paths were resolved from

    def __reduce__(self):
        return Scene, (self._data, self.source_dir)

    @property
    def petsc(self) -> dict[str, str]:
        """PETSc options, flattened, without the prefix; a fresh dict each time."""
        return self._data["petsc"].to_dict()

    def body(self, name: str) -> Node:
        for body in self.bodies:
            if body.name == name:
                return body
        raise SceneError(f"bodies: no body named {_show(name)} (bodies: {', '.join(b.name for b in self.bodies)})")

    def surface_ref(self, ref: str) -> tuple[str, str]:
        """Split "body.surface" into (body name, surface name), checking the body exists."""
        body, _, surface = ref.partition(".")
        if not surface:
            raise SceneError(f"{_show(ref)}: expected \"body.surface\"")
        return self.body(body).name, surface

    def to_toml(self) -> str:
        lines: list[str] = []
        _write_table(self.to_dict(), [], lines)
        return "\n".join(lines).strip() + "\n"


# ---------------------------------------------------------------- overrides

def _parse_override(text: str) -> tuple[list[str | int], Any]:
    key, sep, raw = text.partition("=")
    segments: list[str | int] = []
    for part in re.sub(r"\[([0-9]+)\]", r".\1", key.strip()).split("."):
        if not part:
            raise SceneError(f"{_show(text)}: override must be key.path=value, e.g. load.steps=4")
        segments.append(int(part) if re.fullmatch("[0-9]+", part) else part)
    if not sep:
        raise SceneError(f"{_show(text)}: override must be key.path=value, e.g. load.steps=4")
    try:
        parsed = tomllib.loads(f"v = {raw.strip()}")
    except (tomllib.TOMLDecodeError, ValueError):      # ValueError: an integer of over 4300 digits
        return segments, raw.strip()  # not a TOML value: a bare string such as two_pass
    return segments, parsed["v"] if len(parsed) == 1 else raw.strip()


def _apply_override(data: dict, text: str) -> None:
    segments, value = _parse_override(text)
    if segments[0] == "petsc" and len(segments) > 1 and isinstance(data.get("petsc", {}), dict):
        # Flatten first, so petsc.ksp_type=... replaces a nested {ksp = {type = ...}} instead of clashing with it.
        flat = {name: v for name, (_, v) in _flatten_options(data.get("petsc", {}), "petsc").items()}
        flat["_".join(map(str, segments[1:]))] = value
        data["petsc"] = flat
        return
    node: Any = data
    path = ""
    for i, seg in enumerate(segments):
        sub = _join(path, seg)
        if isinstance(seg, int):
            if not isinstance(node, list):
                raise SceneError(f"{sub}: {path or 'the scene'} is not a list")
            if seg >= len(node):
                raise SceneError(f"{sub}: no such entry ({path} has {len(node)})")
        elif not isinstance(node, dict):
            raise SceneError(f"{sub}: {path} is not a table")
        elif seg not in node and i + 1 < len(segments):
            if isinstance(segments[i + 1], int):  # list entries are never created, only changed
                raise SceneError(f"{_join(sub, segments[i + 1])}: no such entry (the scene has no {sub})")
            node[seg] = {}
        if i + 1 == len(segments):
            node[seg] = value
        node, path = node[seg], sub


# ---------------------------------------------------------------- cross checks

def _check_ref(ref: str, path: str, bodies: dict[str, dict]) -> str:
    """Check a "body.surface" reference against the bodies; return the body name."""
    body, surface = ref.split(".", 1)
    if body not in bodies:
        raise SceneError(f"{path}: no body named {_show(body)} (bodies: {', '.join(bodies)})")
    # Only generated boxes have surface names known before the mesh is read.
    if bodies[body]["mesh"]["type"] == "box" and surface not in BOX_SURFACES:
        raise SceneError(f"{path}: box body {_show(body)} has no surface {_show(surface)} "
                         f"(expected one of: {', '.join(BOX_SURFACES)})")
    return body


def _cross_check(scene: dict, source_dir: Path) -> None:
    """Checks between keys, and resolution of paths, normals and {name}; edits scene in place."""
    bodies: dict[str, dict] = {}
    for i, body in enumerate(scene["bodies"]):
        if body["name"] in bodies:
            raise SceneError(f"bodies[{i}].name: duplicate body name {_show(body['name'])}")
        bodies[body["name"]] = body
        mesh = body["mesh"]
        if mesh["type"] == "file":
            mesh["path"] = os.path.abspath(source_dir / mesh["path"])
            if not os.path.isfile(mesh["path"]):
                what = "a folder, not a mesh file" if os.path.isdir(mesh["path"]) else "file not found"
                raise SceneError(f"bodies[{i}].mesh.path: {what}: {mesh['path']}")
        elif mesh["type"] == "hertz":
            mesh["cache"] = os.path.abspath(mesh["cache"])
    for i, bc in enumerate(scene["boundary"]):
        _check_ref(bc["surface"], f"boundary[{i}].surface", bodies)
        if bc["type"] == "displacement" and all(bc[k] is None for k in ("ux", "uy", "uz")):
            raise SceneError(f"boundary[{i}]: a displacement boundary needs at least one of ux, uy, uz")
    for i, pair in enumerate(scene["contact"]):
        slave = _check_ref(pair["slave"], f"contact[{i}].slave", bodies)
        master = _check_ref(pair["master"], f"contact[{i}].master", bodies)
        if pair["slave"] == pair["master"]:
            raise SceneError(f"contact[{i}].master: same surface as slave ({_show(pair['slave'])})")
        if slave == master:
            raise SceneError(f"contact[{i}].master: self-contact is not supported "
                             f"(slave and master are both on body {_show(slave)})")
        for j, other in enumerate(scene["contact"][:i]):
            if {other["slave"], other["master"]} == {pair["slave"], pair["master"]}:
                # each copy carried half the force and the interface took twice the penalty, without a word
                raise SceneError(f"contact[{i}]: the same surfaces as contact[{j}] ({_show(pair['slave'])} and "
                                 f"{_show(pair['master'])}): the interface would be held twice, each pair reporting "
                                 f"half its force")
        if pair["sliding"] == "large" and pair["reuse_tolerance"] == 0:
            raise SceneError(f"contact[{i}].reuse_tolerance: large sliding needs a tolerance > 0 to tell that its "
                             f"searches have settled, got 0")
    dies: set[str] = set()
    for i, die in enumerate(scene["die"]):
        if die["name"] in dies:
            raise SceneError(f"die[{i}].name: duplicate die name {_show(die['name'])}")
        dies.add(die["name"])
        moduli = {}
        for j, ref in enumerate(die["surfaces"]):
            body = _check_ref(ref, f"die[{i}].surfaces[{j}]", bodies)
            if ref in die["surfaces"][:j]:
                raise SceneError(f"die[{i}].surfaces[{j}]: {_show(ref)} is listed twice")
            moduli[body] = bodies[body]["material"]["youngs_modulus"]
        if len(set(moduli.values())) > 1:
            # its penalty alpha E / h takes one E: the smallest left a stiffer body 1e3 x softer held 2.5 % low
            raise SceneError(f"die[{i}].surfaces: the die presses bodies of different Young's moduli ("
                             + ", ".join(f"{b} {e:g} Pa" for b, e in moduli.items())
                             + "); its penalty takes one: give each body a die of its own (same point, normal "
                               "and motion)")
        norm = math.sqrt(sum(c * c for c in die["normal"]))
        if norm == 0:
            raise SceneError(f"die[{i}].normal: must be non-zero, got {_show(die['normal'])}")
        # A unit normal is kept as is, so that reloading a written scene gives bit-identical numbers.
        if not math.isclose(norm, 1.0, rel_tol=1e-14, abs_tol=0.0):
            die["normal"] = [c / norm for c in die["normal"]]
        for j, other in enumerate(scene["die"][:i]):
            shared = sorted(set(other["surfaces"]) & set(die["surfaces"]))
            if shared and all(other[k] == die[k] for k in ("point", "normal", "motion", "condition")):
                raise SceneError(f"die[{i}]: the same plane, motion and condition as die[{j}] on {_show(shared)}: "
                                 f"those surfaces would be held twice, each die reporting half the force")
    scene["output"]["directory"] = scene["output"]["directory"].replace("{name}", scene["name"])


# ---------------------------------------------------------------- public API

def parse_scene(data: dict, source_dir: str | os.PathLike, name: str, overrides: Sequence[str] = ()) -> Scene:
    """Validate raw scene data (as read from TOML) after applying overrides; name is the default scene name."""
    if not isinstance(data, dict):
        raise SceneError(f"{name}: expected a table of scene keys, got {_show(data)}")
    data = copy.deepcopy(data)
    for text in overrides:
        _apply_override(data, text)
    data.setdefault("name", name)
    source_dir = Path(os.path.abspath(source_dir))
    resolved = SCHEMA.check(data, "")
    _cross_check(resolved, source_dir)
    return Scene({key: _freeze(value, key) for key, value in resolved.items()}, source_dir)


def load_scene(path: str | os.PathLike, overrides: Sequence[str] = ()) -> Scene:
    """Read, override and validate a scene TOML file."""
    path = Path(path)
    try:
        # utf-8-sig: a file saved with a byte-order mark read "Invalid statement (line 1, column 1)" (hunt34_3)
        data = tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except FileNotFoundError:
        raise SceneError(f"{path}: scene file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError(f"{path}: cannot read scene file: {exc}") from None
    except (tomllib.TOMLDecodeError, ValueError) as exc:     # ValueError: an integer of over 4300 digits
        raise SceneError(f"{path}: invalid TOML: {exc}") from None
    return parse_scene(data, path.parent, path.stem, overrides)


def schema_markdown() -> str:
    """The reference table of every scene key, generated from SCHEMA."""
    rows = ["| key | type | default | range / choices | unit | description |", "|---|---|---|---|---|---|"]
    for path, field, note in SCHEMA.children(""):
        cells = [f"`{path}`", field.type_text(), field.default_text(), field.range_text(), field.unit, field.doc + note]
        rows.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(rows) + "\n"


if __name__ == "__main__":
    print(schema_markdown(), end="")
