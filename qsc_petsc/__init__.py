"""qsc_petsc: parallel finite-element contact between non-matching meshes (master/slave, two-pass, quasi-symmetric)."""

__version__ = "0.1.0"
