"""The package version (``brdffit.__version__``), importable from the ground layer."""

__version__ = "0.1.0"
