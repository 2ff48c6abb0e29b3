"""Mass properties of solid primitives (box, cylinder, sphere) and of rigid sets of them.

A URDF ``<inertial>`` holds a mass, the pose of a frame at the centre of mass and the inertia
tensor about that centre in that frame. :class:`MassProperties` is that triple, in the frame of the
link that carries it; :func:`solid` gives it for one uniform primitive placed on the link,
:func:`combined` for several (parallel-axis theorem, eq. ``I_c = sum R I R^T + m (|d|^2 E - d d^T)``),
and :meth:`MassProperties.principal` turns it into the form every consumer reads the same way: the
inertial frame on the principal axes, so the tensor written is diagonal (PyBullet otherwise
diagonalises it itself, iteratively, and moves its centre-of-mass frame by what that leaves).

Every tensor made here is a physical one: symmetric positive definite, and its principal moments
satisfy the triangle inequality ``I_a + I_b >= I_c`` (MuJoCo refuses others, Pinocchio's dynamics
need them). A frame-only link (nothing solid on it) gets :func:`frame_floor`: 1 g with the inertia of
a 1 cm solid sphere. MuJoCo refuses a moving body whose mass or inertia is below ``mjMINVAL`` and
PyBullet replaces a missing ``<inertial>`` with 1 kg and a warning; 1 g is far below any real part
and keeps the joint-space inertia matrix well conditioned.

Units: kg, m, kg m^2.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cpc2urdf.errors import SpecError
from cpc2urdf.transforms import Array

FRAME_MASS = 1e-3  # [kg]: mass of a link with nothing solid on it
FRAME_RADIUS = 0.01  # [m]: ... with the inertia of a solid sphere of this radius
SHAPES = ("box", "cylinder", "sphere")


@dataclass(frozen=True)
class MassProperties:
    """Mass, centre of mass and inertia of a rigid body, in the frame of the link carrying it.

    Attributes:
        mass: Mass [kg], > 0.
        com: Centre of mass in the link frame [m], shape (3,).
        inertia: Inertia tensor about the centre of mass, axes of the link frame [kg m^2],
            shape (3, 3), symmetric positive definite.
    """

    mass: float
    com: Array
    inertia: Array

    def principal(self) -> tuple[Array, Array]:
        """The principal form of :attr:`inertia`: ``(R, moments)`` with ``inertia = R diag(moments) R^T``.

        ``R`` (shape (3, 3)) is a rotation (its columns are the principal axes in the link frame);
        an already diagonal tensor keeps ``R = I`` and its own order of moments (shape (3,)).
        """
        inertia = 0.5 * (self.inertia + self.inertia.T)
        off = inertia[0, 1] ** 2 + inertia[0, 2] ** 2 + inertia[1, 2] ** 2
        if off <= (1e-14 * float(np.max(np.abs(np.diag(inertia))))) ** 2:
            return np.eye(3), np.diag(inertia).copy()
        moments, R = np.linalg.eigh(inertia)
        if np.linalg.det(R) < 0:
            R[:, 2] = -R[:, 2]
        return R, moments

    def with_mass(self, mass: float) -> MassProperties:
        """The same distribution (centre, shape of the tensor) scaled to ``mass`` [kg] > 0."""
        if not (math.isfinite(mass) and mass > 0):
            raise SpecError(f"a link mass must be a finite number > 0 kg, got {mass!r}")
        return MassProperties(float(mass), self.com.copy(), self.inertia * (mass / self.mass))


def _primitive_inertia(shape: str, size: Sequence[float], mass: float) -> Array:
    """Inertia about the centre of a uniform primitive in its own frame (cylinder axis z)."""
    if shape == "box":
        a, b, c = (float(v) for v in size)
        return (mass / 12.0) * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])
    if shape == "cylinder":
        r, length = (float(v) for v in size)
        side = mass * (3.0 * r * r + length * length) / 12.0
        return np.diag([side, side, 0.5 * mass * r * r])
    if shape == "sphere":
        (r,) = (float(v) for v in size)
        return np.eye(3) * (0.4 * mass * r * r)
    raise SpecError(f"no mass properties for shape {shape!r}; expected one of {SHAPES}")


def volume(shape: str, size: Sequence[float]) -> float:
    """Volume [m^3] of a primitive: box ``(x, y, z)``, cylinder ``(radius, length)``, sphere ``(radius,)``."""
    if shape == "box":
        return float(np.prod([float(v) for v in size]))
    if shape == "cylinder":
        r, length = (float(v) for v in size)
        return math.pi * r * r * length
    if shape == "sphere":
        return 4.0 / 3.0 * math.pi * float(size[0]) ** 3
    raise SpecError(f"no volume for shape {shape!r}; expected one of {SHAPES}")


def solid(shape: str, size: Sequence[float], T_link_shape: Array, density: float) -> MassProperties:
    """A uniform primitive of ``density`` [kg/m^3] at pose ``T_link_shape`` (shape (4, 4)) on a link.

    Args:
        shape: ``"box"``, ``"cylinder"`` (axis z, as in URDF) or ``"sphere"``.
        size: Box edge lengths (3,), cylinder ``(radius, length)``, or sphere ``(radius,)`` [m], > 0.
        T_link_shape: Pose of the primitive's centre in the link frame.
        density: [kg/m^3], > 0.
    """
    mass = density * volume(shape, size)
    R = np.asarray(T_link_shape, dtype=float)[:3, :3]
    inertia = R @ _primitive_inertia(shape, size, mass) @ R.T
    return MassProperties(mass, np.asarray(T_link_shape, dtype=float)[:3, 3].copy(), inertia)


def combined(parts: Sequence[MassProperties]) -> MassProperties:
    """One rigid body made of ``parts`` (at least one), about its own centre of mass."""
    if not parts:
        raise SpecError("combined() needs at least one part")
    mass = sum(p.mass for p in parts)
    com = sum((p.mass * p.com for p in parts), np.zeros(3)) / mass
    inertia = np.zeros((3, 3))
    for p in parts:
        d = p.com - com
        inertia += p.inertia + p.mass * (float(d @ d) * np.eye(3) - np.outer(d, d))  # parallel axes
    return MassProperties(float(mass), com, 0.5 * (inertia + inertia.T))


def frame_floor(mass: float = FRAME_MASS) -> MassProperties:
    """The mass properties of a link with nothing solid on it: a solid sphere of radius
    :data:`FRAME_RADIUS` at the link origin, of ``mass`` [kg] (default :data:`FRAME_MASS`)."""
    return MassProperties(float(mass), np.zeros(3), np.eye(3) * (0.4 * mass * FRAME_RADIUS**2))


def is_physical(moments: Sequence[float], *, rtol: float = 1e-9) -> bool:
    """True if principal moments [kg m^2] are all > 0 and satisfy the triangle inequality
    (each at most the sum of the other two, to ``rtol`` of the largest)."""
    m = np.asarray(moments, dtype=float)
    if m.shape != (3,) or not np.all(np.isfinite(m)) or np.any(m <= 0):
        return False
    slack = rtol * float(np.max(m))
    return all(m[i] <= m[(i + 1) % 3] + m[(i + 2) % 3] + slack for i in range(3))


__all__ = [
    "FRAME_MASS",
    "FRAME_RADIUS",
    "SHAPES",
    "MassProperties",
    "combined",
    "frame_floor",
    "is_physical",
    "solid",
    "volume",
]
