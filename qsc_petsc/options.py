"""PETSc start-up and the options database: scene [petsc] tables under the qsc_ prefix, command line first."""

import os
import re
import sys

PREFIX = "qsc_"
_AT_START_UP = set()    # option names in the database when PETSc started: command line, PETSC_OPTIONS, .petscrc
_COMMAND_LINE = set()   # option names given on the command line


def split_petsc_args(argv):
    """Separate PETSc options (single dash, e.g. -qsc_pc_type lu) from the CLI's own arguments.

    A token after a PETSc option is its value unless it is itself an option or a scene file. -h is the CLI's help
    (PETSc's is -help)."""
    own, petsc = [], []
    i = 0
    while i < len(argv):
        tok = argv[i]
        if tok.startswith("-") and not tok.startswith("--") and not _is_number(tok) and len(tok) > 1 and tok != "-h":
            petsc.append(tok)
            nxt = argv[i + 1] if i + 1 < len(argv) else None
            if nxt is not None and (not nxt.startswith("-") or _is_number(nxt)) and not nxt.endswith(".toml"):
                petsc.append(nxt)
                i += 1
        else:
            own.append(tok)
        i += 1
    return own, petsc


def _is_number(tok):
    try:
        float(tok)
        return True
    except ValueError:
        return False


def init_petsc(petsc_args):
    """Initialise petsc4py with the given options (before any module imports PETSc)."""
    import petsc4py
    petsc4py.init([sys.argv[0]] + list(petsc_args))
    _COMMAND_LINE.update(tok[1:] for tok in petsc_args if tok.startswith("-") and not _is_number(tok))
    from petsc4py import PETSc
    _AT_START_UP.update(PETSc.Options().getAll())
    return PETSc


def insert_options(defaults):
    """Put options {key: value} under the qsc_ prefix, unless the database has them already (command line,
    scene); returns {name: value} of those inserted, for remove_options."""
    from petsc4py import PETSc
    opts = PETSc.Options()
    inserted = {}
    for key, value in defaults.items():
        name = PREFIX + key
        if not opts.hasName(name):
            opts.setValue(name, value)
            inserted[name] = value
    return inserted


def remove_options(names):
    """Take options insert_options put in back out of the database (an in-process run must not leak them)."""
    from petsc4py import PETSc
    opts = PETSc.Options()
    for name in names:
        opts.delValue(name)


# MUMPS INFOG(1) when one of its work arrays was too small (numerical pivoting delayed more pivots than the
# analysis foresaw, or a parallel factorization's estimate fell short): more memory relaxation ICNTL(14) cures
# it; measured on a 1.7k-dof patch test on 3 ranks (LU), and on the contact band of configs/stiff_plate.toml with
# Gauss rows on 2 ranks (Cholesky, AMF ordering: -9, the band's solve then returned inf)
MUMPS_WORKSPACE_ERRORS = (-8, -9, -14, -15, -17, -20)
MUMPS_MAX_RELAXATION = 1000    # percent


def factored_by_mumps(pc):
    """Whether pc is an LU or Cholesky factorization by MUMPS, named or PETSc's own choice (MUMPS on several
    ranks, PETSc's own on one)."""
    package = pc.getFactorSolverType() or ("mumps" if pc.getComm().getSize() > 1 else "petsc")
    return pc.getType() in ("lu", "cholesky") and package == "mumps"


def mumps_factor(pc):
    """pc's MUMPS factor, or None before its first factorization (a try that failed before its first linear
    solve: PETSc error 58 from PCFactorGetMatrix)."""
    from petsc4py import PETSc
    try:
        return pc.getFactorMatrix()
    except PETSc.Error as exc:
        if exc.ierr == 58:
            return None
        raise


def more_mumps_workspace(pc, prefix, own):
    """After pc's MUMPS factorization ran out of workspace (INFOG(1) in MUMPS_WORKSPACE_ERRORS): its memory
    relaxation ICNTL(14) doubled in the options database as -<prefix>mat_mumps_icntl_14 (read when a factor is
    made; the name added to the set `own`, whose options the caller removes at its end) and pc reset, for PETSc
    skips the numeric factorization of a failed MUMPS factor: its next setup makes a new one. Returns the new
    relaxation, or None when that was not the failure, the relaxation is spent, or the user set it (it stands).
    Collective (INFOG is global)."""
    from petsc4py import PETSc
    F = mumps_factor(pc)
    if F is None:
        return None
    relax = 2 * max(F.getMumpsIcntl(14), 20)
    if F.getMumpsInfog(1) not in MUMPS_WORKSPACE_ERRORS or relax > MUMPS_MAX_RELAXATION:
        return None
    name = f"{prefix}mat_mumps_icntl_14"
    opts = PETSc.Options()
    if opts.hasName(name) and name not in own:
        return None
    opts.setValue(name, relax)
    own.add(name)
    pc.reset()
    return relax


def reset_failed_mumps(pc):
    """pc reset when its last MUMPS factorization failed (INFOG(1) < 0; -10: a numerically singular matrix), so
    that its next setup makes new factors: PETSc skips the numeric factorization of a failed MUMPS factor, and the
    next solve called MUMPS with none (INFOG(1) = -3, PETSc error 76). A body pulled off the contact that held it,
    on 2 ranks: that error ended the run instead of the cutbacks and their diagnostic, on a machine where MUMPS's
    parallel pivoting met the singular iterate's null pivot. Returns whether it reset pc. Collective."""
    if not factored_by_mumps(pc):
        return False
    F = mumps_factor(pc)
    if F is None or F.getMumpsInfog(1) >= 0:
        return False
    pc.reset()
    return True


def option_value(key, default=None):
    """The value of option qsc_<key> in the database (command line, scene, code), or default when it is unset."""
    from petsc4py import PETSc
    opts = PETSc.Options()
    return opts.getString(PREFIX + key) if opts.hasName(PREFIX + key) else default


def options_in_effect():
    """Every option in the database, as {name: value}."""
    from petsc4py import PETSc
    return dict(sorted(PETSc.Options().getAll().items()))


def options_text(options, from_scene, settings=(), scene_defaults=None):
    """petsc_options.txt: the options database (source: scene [petsc] table, or that table's default when the
    value is `scene_defaults`' ({key: value}, without the prefix), command line, environment or program default),
    then `settings`, lines naming what the solver objects hold that no option in the database says."""
    header = ("# PETSc options in the database (source: scene [petsc] table or its default, command line, environment "
              "(PETSC_OPTIONS or a .petscrc) or program default)")
    defaults = {PREFIX + key: str(value) for key, value in (scene_defaults or {}).items()}
    lines = [header]
    for name, value in options.items():
        source = (("scene default" if defaults.get(name) == value else "scene") if name in from_scene else
                  "command line" if name in _COMMAND_LINE else
                  "environment" if name in _AT_START_UP else "program default")
        lines.append(f"-{name}" + (f" {value}" if value not in (None, "") else "") + f"    # {source}")
    if settings:
        lines += ["# the solver objects at the end of the run (what qsc set through the API, and PETSc's defaults)",
                  *settings]
    return "\n".join(lines) + "\n"


UNREAD_FAMILIES = ("ksp_", "pc_", "snes_")     # solver options that only a prefixed object of qsc's reads


def unread_option(name):
    """Why the option `name` (without its dash) would go unread, or None: a solver option without the qsc_
    prefix, which none of qsc's solvers reads (-ksp_type preonly ran GMRES without a word; a sweep varying -pc_type
    made identical rows)."""
    if name.startswith(UNREAD_FAMILIES):
        band = f"; the contact band's solve: -{PREFIX}band_{name}" if not name.startswith("snes_") else ""
        return f"-{name}: qsc's solvers read their options under the {PREFIX} prefix (-{PREFIX}{name}{band}); " \
               f"unprefixed, nothing reads it"
    return None


def value_error(name, value):
    """Why option `name` (without its dash) cannot take `value` (a string, None for no value), or None: a
    -qsc_*_rtol / _atol / _stol / _divtol or _max_it option with no value, a negative or infinite number, a
    Newton solve's ksp_rtol, snes_rtol or snes_stol of 1 or more, or its snes_max_it / ksp_max_it of 0. A value
    that is no number is left to PETSc, whose message names it.
    Needs no PETSc (qsc sweep checks its runs' values with it before the first)."""
    kind = re.search(r"_(rtol|atol|stol|divtol|max_it)$", name) if name.startswith(PREFIX) else None
    if kind is None:
        return None
    integer = kind.group(1) == "max_it"
    if value in (None, ""):
        # the value forgotten (-qsc_ksp_max_it -qsc_ksp_monitor, or `ksp_rtol = true` in [petsc]): float(None)
        # raised a TypeError, a traceback and exit 1 on every rank (hunt32_3)
        return f"-{name}: needs {'an integer' if integer else 'a number'} (no value given)"
    try:
        number = int(value) if integer else float(value)
    except ValueError:
        return None
    if not number >= 0 or (not integer and number == float("inf")):
        return f"-{name}: must be {'an integer' if integer else 'a finite number'} >= 0, got {value!r}"
    if name in (f"{PREFIX}snes_rtol", f"{PREFIX}snes_stol") and number >= 1:
        # the Newton test then passes before the answer: snes_rtol 10 left the bodies at rest, snes_stol 1 with a
        # loose linear solve 9 % off, each "ok" (hunt34_3)
        return (f"-{name}: must be below 1 (at {value} the Newton test passes before the answer is reached), "
                f"got {value!r}")
    if name == f"{PREFIX}ksp_rtol" and number >= 1:      # the Newton solve's (the band's is a direct solve)
        # every linear solve then stops before its first iteration: zero Newton steps, which the step test
        # took for a converged solve (the two cubes never moved, exit 0; hunt30_6)
        return (f"-{name}: must be below 1 (at {value} every linear solve stops before its first iteration), "
                f"got {value!r}")
    if name in (f"{PREFIX}snes_max_it", f"{PREFIX}ksp_max_it") and number == 0:
        # no Newton step or no Krylov iteration: every try failed, 4 cutbacks and "DIVERGED_MAX_IT after 0
        # iterations", exit 3 (session 33)
        return f"-{name}: must be at least 1 (at 0 no {'Newton step' if 'snes' in name else 'Krylov iteration'} " \
               f"is taken), got {value!r}"
    return None


def check_options():
    """A SceneError for a solver option without the qsc_ prefix on the command line (unread_option; one from
    PETSC_OPTIONS or a .petscrc, perhaps kept for other programs, is left alone), or a value value_error refuses:
    PETSc takes a negative tolerance as its own default without a word, and the solve then failed with a reason
    that did not name the option."""
    from petsc4py import PETSc

    from .errors import SceneError
    for name, value in options_in_effect().items():
        if name in _COMMAND_LINE and "=" in name:
            # PETSc reads -qsc_pc_type=lu as an option named "qsc_pc_type=lu" with no value: the run went on with
            # the defaults, -qsc_ksp_rtol=2 (refused as -qsc_ksp_rtol 2) too (hunt34_3)
            key, _, given = name.partition("=")
            raise SceneError(f"-{name}: PETSc options take their value after a space: write -{key} {given}")
        unread = unread_option(name) if name in _COMMAND_LINE else None
        if unread is not None:
            raise SceneError(unread)
        why = value_error(name, value)
        if why is not None:
            raise SceneError(why)
    for name, value in options_in_effect().items():
        path = _viewer_file(value) if name.startswith(PREFIX) or name == "log_view" else None
        if path is None:
            continue
        folder = os.path.dirname(os.path.abspath(path))
        why = ("a folder is there" if os.path.isdir(path) else
               None if os.path.isdir(folder) and os.access(folder, os.W_OK) else
               "its folder does not exist or is not writable")
        if why:
            # rank 0 alone opens an ASCII viewer's file: its failure there left the other ranks waiting (exit 1
            # after 40 s on 2 ranks; hunt30_6, hunt30_7: ":FILE", a folder as FILE, -log_view at the end).
            # PetscFinalize writes -log_view's report: out of the database, or its error stack follows the line
            # (hunt32_3)
            if name == "log_view":
                PETSc.Options().delValue(name)
            raise SceneError(f"PETSc options: {OPTION_ERRORS[65]} in -{name} ({path!r}: {why})")


def _viewer_file(value):
    """The file a viewer option's value names (type:file[:format][:append]; no type: ascii), or None."""
    parts = (value or "").split(":")
    if len(parts) >= 2 and parts[0] in ("", "ascii", "binary", "hdf5", "vtk") and parts[1]:
        return parts[1]
    return None


# PETSc error codes that setFromOptions raises for a bad option: wrong argument, out of range (a value
# that does not parse), a value that is none of the option's choices, unknown type (a misspelt or
# missing solver package)
OPTION_ERRORS = {56: "a value the option does not support (a viewer option such as -qsc_ksp_monitor takes no "
                      "value, or ascii:FILE)", 62: "a wrong argument", 63: "a value out of range or not a number",
                  65: "a file that cannot be opened", 83: "a value that is none of the option's choices",
                  86: "an unknown type", 92: "a factorization that no installed package provides for this matrix "
                                             "(-qsc_pc_factor_mat_solver_type, -qsc_band_pc_factor_mat_solver_type)"}


def set_from_options(obj, what):
    """obj.setFromOptions(), with a refused option turned into a SceneError (exit 2 on every rank: the
    options database is the same everywhere, so every rank fails here together)."""
    from petsc4py import PETSc

    from .errors import SceneError
    try:
        obj.setFromOptions()
    except PETSc.Error as exc:
        if exc.ierr not in OPTION_ERRORS:
            raise
        raise SceneError(f"PETSc options of the {what}: {refused_option(exc)}") from None


def refused_option(exc):
    """What a PETSc error raised for a bad option says: the kind, the options it is about, PETSc's detail."""
    from .errors import petsc_detail

    detail = petsc_detail(exc)
    return f"{OPTION_ERRORS[exc.ierr]}{_holders(detail)} (PETSc error {exc.ierr} in {detail})"


def _holders(detail):
    """The options PETSc's message is about, as ' in -name': those whose value it quotes (as not a number, an
    unsupported viewer or a file it cannot open: it names the value, not the option), or a type option given no
    value; '' if none is found."""
    quoted = (re.search(r"Input string (\S+) has no (?:numeric|integer) value", detail)
              or re.search(r"Unsupported viewer (\S+)", detail) or re.search(r"file: (\S+)", detail)
              or re.search(r"Unknown viewer format (\S+)", detail))
    names = [f"-{name}" for name, value in options_in_effect().items()
             if quoted and value and (value == quoted.group(1) or value.endswith(":" + quoted.group(1)))]
    if "Unable to find requested" in detail:        # a type option given no value: PETSc quotes an empty name
        names = [f"-{name} (no value given)" for name, value in options_in_effect().items()
                 if name.startswith(PREFIX) and name.endswith("_type") and not value]
    return f" in {', '.join(names)}" if names else ""
