"""Shipped robots: specs and sample data installed with the package.

``available()`` lists the names ``cpc2urdf export NAME`` and friends accept; ``spec_path(name)``
gives the spec file. Each robot is one ``<name>.json`` robot spec in this folder.
"""

from __future__ import annotations

from pathlib import Path

HERE = Path(__file__).resolve().parent


def available() -> list[str]:
    """Names of the shipped robots."""
    return sorted(p.stem for p in HERE.glob("*.json"))


def spec_path(name: str) -> Path | None:
    """Path of the shipped robot spec called ``name``, or None."""
    p = HERE / f"{name}.json"
    return p if p.is_file() else None
