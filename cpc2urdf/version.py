"""The package version (one place; pyproject.toml reads it too)."""

__version__ = "0.1.0"

__all__ = ["__version__"]
