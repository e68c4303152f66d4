"""The package version (one place; ``ials_zoo.__version__`` re-exports it)."""

__version__ = "0.2.0"
