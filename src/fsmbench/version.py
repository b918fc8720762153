"""fsmbench's version, on its own: every module that stamps a file imports it from here,
not from the package root (which imports the public API)."""

__all__ = ["__version__"]

__version__ = "0.1.0"
