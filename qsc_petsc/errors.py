"""The exceptions qsc_petsc raises, so callers can catch its own failures apart from bugs."""

import re


class QscError(Exception):
    """Base of every error qsc_petsc raises on purpose; the message is one line for the user."""


class SceneError(QscError):
    """Bad scene input; the message starts with the key path, e.g. ``load.steps: ...``."""


class MeshError(QscError):
    """Bad mesh or mesh entity (missing file, unknown surface, degenerate cell)."""


class OutputError(QscError):
    """Results cannot be written where they are to go (the output folder)."""


class ConvergenceError(QscError):
    """A solve failed; the message names the reason, the load step and the iteration counts."""


def folder_error(key, directory, exc):
    """The line for a folder mkdir could not make (OSError exc): a file of its name said. is_file() itself raised
    on a name too long for the file system, a traceback and exit 1 (hunt34_3)."""
    try:
        what = " (a file of that name is there)" if directory.is_file() else ""
    except OSError:
        what = ""
    return f"{key}: cannot create the folder {str(directory)!r}: {exc.strerror}{what}"


def petsc_detail(exc):
    """PETSc's own account of a PETSc.Error, from the traceback its text carries: the innermost routine and the
    specific message, e.g. "KSPSetType(): Unable to find requested KSP type nonexist"; "a routine PETSc did not
    name" if the text carries no traceback.

    petsc4py keeps PETSc's error message in the exception instead of printing it, so a user sees it only if
    qsc's line quotes it."""
    lines = [re.sub(r"^\[\d+\]\s*", "", line) for line in str(exc).splitlines()[1:]]
    routines = [i for i, line in enumerate(lines) if re.match(r"^\S+\(\) at ", line)]
    if not routines:
        return "a routine PETSc did not name"
    last = routines[-1]
    message = [line for line in lines[last + 1:] if line.strip()]
    # the first line is the error class's generic text ("Error in external library"), the rest the specifics
    specific = message[1:] or message
    return f"{lines[last].split(' at ')[0]}: {' '.join(specific)}".strip().rstrip(":")
