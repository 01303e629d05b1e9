"""The package version (one place; read by the package, gain tables and the command line)."""

__version__ = "0.1.0"
