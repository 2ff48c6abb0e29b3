"""Seeded random CPC trees for property tests (independent of the package's own generators)."""

from __future__ import annotations

import numpy as np

from cpc2urdf.model import BASE, CPCModel, CPCParams, Frame, Joint, RobotStructure


def random_unit(rng: np.random.Generator, min_bz: float = -0.9) -> tuple[float, float, float]:
    while True:
        v = rng.normal(size=3)
        v /= np.linalg.norm(v)
        if v[2] >= min_bz:
            return tuple(float(x) for x in v)  # type: ignore[return-value]


def random_params(rng: np.random.Generator, parallel_p: float = 0.25, min_bz: float = -0.9) -> CPCParams:
    b = (0.0, 0.0, 1.0) if rng.random() < parallel_p else random_unit(rng, min_bz)
    return CPCParams(b, float(rng.uniform(-np.pi, np.pi)), tuple(rng.uniform(-0.3, 0.3, 3)))


def random_tree(rng: np.random.Generator, n_joints: int | None = None, n_frames: int | None = None) -> CPCModel:
    """Random types (prismatic after prismatic included), parents (branches), parameters."""
    n = int(n_joints or rng.integers(1, 8))
    joints = []
    for i in range(n):
        parent = BASE if i == 0 or rng.random() < 0.1 else f"j{int(rng.integers(0, i))}"
        jtype = "prismatic" if rng.random() < 0.4 else "revolute"
        lo = float(rng.uniform(-2.0, 0.0)) if jtype == "revolute" else float(rng.uniform(-0.5, 0.0))
        hi = lo + float(rng.uniform(0.1, 3.0 if jtype == "revolute" else 1.0))
        joints.append(Joint(f"j{i}", jtype, parent, lo, hi))
    m = int(n_frames or rng.integers(1, 4))
    frames = [Frame(f"f{k}", f"j{int(rng.integers(0, n))}", "plate" if k % 2 == 0 else "camera") for k in range(m)]
    structure = RobotStructure("random_tree", joints, frames)
    return CPCModel(
        structure,
        random_params(rng, 0.0, -1.0 + 1e-3),
        {j.name: random_params(rng) for j in joints},
        {f.name: random_params(rng, 0.1, -1.0 + 1e-3) for f in frames},
    )
