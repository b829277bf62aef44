"""phcnc controller: NC interpreter, curve core, reference-point generator and runtime."""

__version__ = "0.1.0"
