"""The exceptions qsc_petsc raises, so callers can catch its own failures apart from bugs."""


class QscError(Exception):
    """Base of every error qsc_petsc raises on purpose; the message is one line for the user."""


class SceneError(QscError):
    """Bad scene input; the message starts with the key path, e.g. ``load.steps: ...``."""


class MeshError(QscError):
    """Bad mesh or mesh entity (missing file, unknown surface, degenerate cell)."""


class ConvergenceError(QscError):
    """A solve failed; the message names the reason, the load step and the iteration counts."""
