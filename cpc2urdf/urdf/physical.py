"""What a simulator needs of a robot besides its kinematics: density, link masses, which way is up.

A robot spec (:mod:`cpc2urdf.files.spec`) may state them; the URDF writer (:mod:`cpc2urdf.urdf.document`) uses them
for every link's ``<inertial>`` and for the gravity-aligned ``world`` of ``mount="base"``::

    "density": 2700,                     # kg/m^3 (SI whatever "units" says); default 1000
    "masses": {"pan_link": 1.5},         # kg, by URDF link name; default: from the drawn solids
    "up": [-1, 0, 0]                     # a direction in base coordinates; default base +z
    "up": {"joint": "pan"}               # or: the axis of a joint at zero readings
    "up": {"joint": "pan", "sign": -1}   #     (sign -1: against the axis)

The joint form follows the robot through calibration: an identified model's base frame is a gauge
choice of the identification, but its joint axes are measured, so "the pan axis is vertical" stays
true of the identified model where a vector in base coordinates may not.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cpc2urdf.errors import SpecError, UnknownNameError
from cpc2urdf.files.jsonio import finite_float, float_list
from cpc2urdf.model import CPCModel
from cpc2urdf.transforms import Array, cpc_rotation

DEFAULT_DENSITY = 1000.0  # [kg/m^3]: of the drawn solids when a spec states none
SPEC_KEYS = ("density", "masses", "up")


@dataclass(frozen=True)
class PhysicalProperties:
    """Density, link masses and the up direction of a robot (all optional in a spec).

    Attributes:
        density: Density of the solid primitives drawn on each link [kg/m^3], > 0.
        masses: Mass [kg] of some links, by URDF link name (``base``, ``<joint>_link``, a frame,
            a camera body); the link's inertia keeps the shape of its solids' (scaled), or is a
            small sphere's if nothing solid is drawn on it.
        up: The up direction in base coordinates (unit, shape (3,)), or None.
        up_joint: Or the joint whose axis (at zero readings) points up; None if not given.
        up_sign: +1 along that joint's axis, -1 against it.
        stated: Keys a spec stated (for messages: what came from the spec, what is a default).
    """

    density: float = DEFAULT_DENSITY
    masses: Mapping[str, float] = field(default_factory=dict)
    up: tuple[float, float, float] | None = None
    up_joint: str | None = None
    up_sign: float = 1.0
    stated: tuple[str, ...] = ()

    def up_in_base(self, model: CPCModel) -> Array:
        """The up direction in ``model``'s base coordinates, unit, shape (3,).

        Raises:
            UnknownNameError: ``up_joint`` is not a joint of ``model``.
        """
        if self.up_joint is not None:
            s = model.structure
            if self.up_joint not in s.joint_names:
                raise UnknownNameError("joint", self.up_joint, s.joint_names)
            _, axes = model.joint_axes_world(np.zeros(s.n_joints))  # (1, n, 3) in world
            u = model.T_world_base()[:3, :3].T @ axes[0, s.joint_index(self.up_joint)]
            return self.up_sign * u / np.linalg.norm(u)
        if self.up is not None:
            return np.array(self.up, dtype=float)
        return np.array([0.0, 0.0, 1.0])

    def describe_up(self) -> str:
        """The up direction as the spec gave it, for messages and the URDF header."""
        if self.up_joint is not None:
            return f"{'-' if self.up_sign < 0 else '+'}axis of joint {self.up_joint!r} at zero readings"
        if self.up is not None:
            return "base (" + ", ".join(f"{v:.6g}" for v in self.up) + ")"
        return "base +z (no 'up' stated)"


def gravity_rotation(up_base: Array) -> Array:
    """``R_world_base`` (shape (3, 3)) of a gravity-aligned world: the smallest rotation taking
    ``up_base`` (unit, base coordinates) to world +z. ``R(b)`` of eq. (4) maps z onto ``b``, so
    with ``b = up_base`` it is ``R_base_world``."""
    return cpc_rotation(np.asarray(up_base, dtype=float)).T


def _up_from_json(value: Any) -> tuple[tuple[float, float, float] | None, str | None, float]:
    if isinstance(value, Mapping):
        unknown = set(value) - {"joint", "sign"}
        if unknown:
            raise ValueError(
                f"'up' has unknown keys {sorted(unknown)}; expected 'joint' and optionally 'sign'"
            )
        joint = value.get("joint")
        if not isinstance(joint, str) or not joint:
            raise ValueError(f"'up.joint' must be a joint name, got {joint!r}")
        sign = value.get("sign", 1)
        if sign not in (1, -1) or isinstance(sign, bool):
            raise ValueError(f"'up.sign' must be 1 or -1, got {sign!r}")
        return None, joint, float(sign)
    v = np.array(float_list(value, 3, "'up'"))
    n = float(np.linalg.norm(v))
    if n < 1e-9:
        raise ValueError(
            f"'up' must be a non-zero direction [x, y, z] in base coordinates, got {value!r}"
        )
    u = v / n
    return (float(u[0]), float(u[1]), float(u[2])), None, 1.0


def physical_from_json(
    doc: Mapping[str, Any], joint_names: tuple[str, ...] = ()
) -> PhysicalProperties:
    """The ``density``, ``masses`` and ``up`` keys of a spec document (all optional).

    Args:
        doc: The spec document.
        joint_names: The robot's joints, to check ``up.joint`` (empty: not checked).

    Raises:
        ValueError: A key of the wrong form, naming it (the spec reader adds the file).
    """
    stated = tuple(k for k in SPEC_KEYS if k in doc)
    density = DEFAULT_DENSITY
    if "density" in doc:
        density = finite_float(doc["density"], "'density'")
        if density <= 0:
            raise ValueError(f"'density' must be > 0 kg/m^3, got {doc['density']!r}")
    masses: dict[str, float] = {}
    if "masses" in doc:
        raw = doc["masses"]
        if not isinstance(raw, Mapping):
            raise ValueError(f"'masses' must be an object {{link name: kg}}, got {raw!r}")
        for name, value in raw.items():
            m = finite_float(value, f"'masses.{name}'")
            if not m > 0 or not math.isfinite(m):
                raise ValueError(f"'masses.{name}' must be > 0 kg, got {value!r}")
            masses[str(name)] = m
    up, up_joint, sign = (None, None, 1.0) if "up" not in doc else _up_from_json(doc["up"])
    if up_joint is not None and joint_names and up_joint not in joint_names:
        raise ValueError(
            f"'up.joint' {up_joint!r} is not a joint of this robot ({', '.join(joint_names)})"
        )
    return PhysicalProperties(density, masses, up, up_joint, sign, stated)


def check_masses(physical: PhysicalProperties, links: list[str] | tuple[str, ...]) -> None:
    """:class:`SpecError` if ``physical.masses`` names a link not in ``links``."""
    unknown = [n for n in physical.masses if n not in links]
    if unknown:
        raise SpecError(
            f"'masses' names links {unknown} the URDF does not have; its links are {list(links)}"
        )


__all__ = [
    "DEFAULT_DENSITY",
    "SPEC_KEYS",
    "PhysicalProperties",
    "check_masses",
    "gravity_rotation",
    "physical_from_json",
]
