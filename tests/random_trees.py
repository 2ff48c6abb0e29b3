"""Seeded random CPC trees for property tests, drawn by the package's one random-robot generator
(:func:`~cpc2urdf.identification.simulation.random_robots.random_model`)."""

from __future__ import annotations

import numpy as np

from cpc2urdf.identification.simulation.random_robots import random_model
from cpc2urdf.model import CPCModel


def random_tree(
    rng: np.random.Generator, n_joints: int | None = None, n_frames: int | None = None
) -> CPCModel:
    """A random tree: random types (prismatic after prismatic included), parents (branches from
    any earlier joint or the base), parameters; a plate on every leaf, and ``n_frames`` further
    frames on random links, plates and cameras alternating.

    Args:
        rng: Seeded random generator.
        n_joints: Number of joints (default: 1 to 7, drawn).
        n_frames: Frames besides the leaf plates (default: 1 to 3, drawn).
    """
    n = int(n_joints or rng.integers(1, 8))
    m = int(n_frames or rng.integers(1, 4))
    return random_model(
        rng,
        n,
        p_prismatic=0.4,
        p_branch=1.0,
        extra_plates=(m + 1) // 2,
        cameras=m // 2,
        name="random_tree",
    )
