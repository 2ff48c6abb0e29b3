"""Seeded random robots (trees of revolute and prismatic joints) with plates, for tests and studies.

``random_model(rng, n_joints)`` draws a :class:`~cpc2urdf.model.RobotStructure` and a
:class:`~cpc2urdf.model.CPCModel`: random joint types (prismatic after prismatic included),
random parents (branches) or a serial chain, random CPC constants (axes in every direction,
including anti-parallel to the parent's), one measured plate on every leaf link (so every joint
moves some plate and the tree is identifiable from plate poses), optional extra plates on inner
links and optional unmeasured camera frames.

Every joint gets a calibration range inside its limits, so the experiment design of
:mod:`~cpc2urdf.identification.simulation.design` applies unchanged. This is the package's one
random-robot generator (``tests/random_trees.py`` draws through it).

Example::

    rng = np.random.default_rng(0)
    model = random_model(rng, 5, serial=False)
    T = model.fk(model.structure.lower)   # {frame: T_world_frame}
    q = protocol_q(model, 4, rng)         # design.protocol_q: the sec. 4.1 protocol, jittered
"""

from __future__ import annotations

import math

import numpy as np

from cpc2urdf.model import BASE, CPCModel, CPCParams, Frame, Joint, RobotStructure

# Readings are drawn within these limits [rad] / [m].
REVOLUTE_LIMITS = (-math.pi / 2, math.pi / 2)
PRISMATIC_LIMITS = (-0.2, 0.3)


def random_unit(rng: np.random.Generator) -> tuple[float, float, float]:
    """A unit vector drawn uniformly on the sphere (any sign of z)."""
    v = rng.normal(size=3)
    v /= np.linalg.norm(v)
    return (float(v[0]), float(v[1]), float(v[2]))


def random_params(
    rng: np.random.Generator, *, scale: float = 0.2, p_parallel: float = 0.2
) -> CPCParams:
    """Random CPC constants (eq. (3)): an axis in any direction (parallel to the parent's with
    probability ``p_parallel``), any ``beta``, offsets up to ``scale`` [m] per component."""
    b = (0.0, 0.0, 1.0) if rng.random() < p_parallel else random_unit(rng)
    # Keep clear of the CPC singularity b = -z: eq. (4) is exact there only through a switch.
    if b[2] < -0.999:
        b = (b[0], b[1], -b[2])
    return CPCParams(b, float(rng.uniform(-math.pi, math.pi)), tuple(rng.uniform(-scale, scale, 3)))  # type: ignore[arg-type]


def random_model(
    rng: np.random.Generator,
    n_joints: int,
    *,
    p_prismatic: float = 0.35,
    serial: bool = False,
    p_branch: float = 0.4,
    extra_plates: int = 0,
    cameras: int = 0,
    name: str = "random_robot",
) -> CPCModel:
    """A random tree robot with a plate on every leaf.

    Args:
        rng: Seeded random generator.
        n_joints: Number of joints (>= 1).
        p_prismatic: Probability that a joint is prismatic.
        serial: A serial chain (each joint's parent is the previous joint).
        p_branch: For trees, probability that a joint hangs off a random earlier joint (or the
            base) instead of the previous one.
        extra_plates: Plates added on random links besides the leaf plates.
        cameras: Camera frames (kind ``"camera"``, not measured) added on random links.
        name: Robot name.

    Returns:
        A :class:`CPCModel` with joints ``j0..``, plates ``plate0..`` and cameras ``camera0..``.
    """
    if n_joints < 1:
        raise ValueError(f"n_joints must be >= 1, got {n_joints}")
    joints: list[Joint] = []
    for i in range(n_joints):
        if i == 0:
            parent = BASE
        elif serial or rng.random() >= p_branch:
            parent = f"j{i - 1}"
        else:
            k = int(rng.integers(-1, i))
            parent = BASE if k < 0 else f"j{k}"
        jtype = "prismatic" if rng.random() < p_prismatic else "revolute"
        lo, hi = PRISMATIC_LIMITS if jtype == "prismatic" else REVOLUTE_LIMITS
        cal_lo = float(rng.uniform(lo, 0.5 * (lo + hi) - 0.1 * (hi - lo)))
        cal_hi = float(rng.uniform(0.5 * (lo + hi) + 0.1 * (hi - lo), hi))
        joints.append(Joint(f"j{i}", jtype, parent, lo, hi, calibration_range=(cal_lo, cal_hi)))
    parents = {j.parent for j in joints}
    leaves = [j.name for j in joints if j.name not in parents]
    frames = [Frame(f"plate{k}", leaf, "plate") for k, leaf in enumerate(leaves)]
    for k in range(extra_plates):
        frames.append(
            Frame(f"plate{len(leaves) + k}", f"j{int(rng.integers(0, n_joints))}", "plate")
        )
    for k in range(cameras):
        frames.append(Frame(f"camera{k}", f"j{int(rng.integers(0, n_joints))}", "camera"))
    structure = RobotStructure(name, joints, frames)
    return CPCModel(
        structure,
        random_params(rng, scale=1.0, p_parallel=0.0),
        {j.name: random_params(rng) for j in joints},
        {f.name: random_params(rng, p_parallel=0.1) for f in frames},
    )


__all__ = ["PRISMATIC_LIMITS", "REVOLUTE_LIMITS", "random_model", "random_params", "random_unit"]
