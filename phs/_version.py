"""The package version, importable without the rest of :mod:`phs`."""

__version__ = "0.1.0"
