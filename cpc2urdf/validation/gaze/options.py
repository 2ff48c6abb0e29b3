"""What a gaze solver is asked to do: :class:`GazeOptions`, the policies, and input checks.

One options object serves the Python API (:func:`cpc2urdf.api.gaze_solver`,
:class:`~cpc2urdf.validation.gaze.solver.GazeSolver`, :func:`~cpc2urdf.validation.gaze.solver.solver_for`)
and the command line (``cpc2urdf gaze``, ``reach``: :mod:`cpc2urdf.cli._gaze_options`).

Policies (which fixating posture a solve picks where the head leaves a choice):

- ``"cyclopean"`` (default): the table (prismatic joints both cameras share) stays; the neck
  faces the target and the eyes stay near the middle of their limits (on a two-eye head with a
  neck, zero *version*: the eyes turned equally and oppositely, the cyclopean axis on the
  target). On a head whose eyes cannot fixate exactly, the error left is split between them
  (status ``disparity``).
- ``"min-motion"``: the table stays; the fixating posture nearest ``q_current`` (Euclidean in the
  readings of the joints that move); exact fixation wherever the eyes' axes can meet.
- ``"eyes-only"``: only the eye joints (those on one camera's path) move; a head with two eyes.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import ConfigurationError, UnknownNameError
from cpc2urdf.tolerances import GAZE_PIXEL_FRACTION, GAZE_POINTING_TOL
from cpc2urdf.transforms import Array
from cpc2urdf.validation.gaze.chain import RIGID_MODES, Coupling

Index = NDArray[np.intp]  # joint indices into q
DEFAULT_CAMERAS = ("camera_left_optical", "camera_right_optical")
POLICIES: tuple[str, ...] = ("cyclopean", "min-motion", "eyes-only")


def check_policy(policy: str) -> None:
    """:class:`ConfigurationError` unless ``policy`` is one of :data:`POLICIES`."""
    if policy not in POLICIES:
        raise ConfigurationError(
            f"unknown gaze policy {policy!r}; expected one of {', '.join(POLICIES)}"
        )


def pointing_tolerance(tolerance: float | None = None, focal_px: float | None = None) -> float:
    """The pointing error [rad] below which an axis counts as on its target: ``tolerance``
    itself; else, with the cameras' focal length ``focal_px`` [px] known (the smaller of the
    two), :data:`~cpc2urdf.tolerances.GAZE_PIXEL_FRACTION` of a pixel at the image centre,
    ``atan(0.1 / focal_px)`` (2e-4 rad at 500 px); else
    :data:`~cpc2urdf.tolerances.GAZE_POINTING_TOL` (exact fixation).

    Raises:
        ConfigurationError: Both given, or either not a positive finite number.
    """
    if tolerance is not None and focal_px is not None:
        raise ConfigurationError(
            "give a pointing tolerance [rad] or the cameras' focal length [px], not both"
        )
    if tolerance is not None:
        if not (math.isfinite(tolerance) and tolerance > 0):
            raise ConfigurationError(
                f"the pointing tolerance must be a positive number of radians, got {tolerance}"
            )
        return float(tolerance)
    if focal_px is not None:
        if not (math.isfinite(focal_px) and focal_px > 0):
            raise ConfigurationError(
                f"the focal length must be a positive number of pixels, got {focal_px}"
            )
        return math.atan(GAZE_PIXEL_FRACTION / focal_px)
    return GAZE_POINTING_TOL


@dataclass(frozen=True)
class GazeOptions:
    """How a gaze solver treats its head (checked when made).

    Attributes:
        joints: The joints that may move; None: every joint on the cameras' paths (the others
            stay at ``q_current``).
        coupling: A stated linear coupling of some joints (e.g. ``Coupling.version_vergence``);
            URDF ``<mimic>`` joints are coupled without it.
        rigid: For two cameras with no joint between them: ``"cyclopean"`` (the mid axis through
            the target) or the master camera ``"left"`` / ``"right"``.
        tolerance: Pointing error [rad] below which a target counts as fixated.
        focal_px: Instead of ``tolerance``: the cameras' focal length [px]; fixated within
            :data:`~cpc2urdf.tolerances.GAZE_PIXEL_FRACTION` of a pixel. Neither: exact fixation
            (:data:`~cpc2urdf.tolerances.GAZE_POINTING_TOL`).
        min_distance: Nearest [m] the policy brings a camera to the target where the pointing
            task leaves it the choice (a camera on an arm); 0: no limit; None: 0.1 m. A target
            only a nearer camera can fixate is still fixated.

    Raises:
        ConfigurationError: Both ``tolerance`` and ``focal_px``, either not positive,
            ``min_distance`` negative or not finite, or an unknown ``rigid`` mode.
    """

    joints: tuple[str, ...] | None = None
    coupling: Coupling | None = None
    rigid: str = "cyclopean"
    tolerance: float | None = None
    focal_px: float | None = None
    min_distance: float | None = None

    def __post_init__(self) -> None:
        if self.joints is not None and not isinstance(self.joints, tuple):
            object.__setattr__(self, "joints", tuple(self.joints))
        pointing_tolerance(self.tolerance, self.focal_px)
        if self.min_distance is not None and not (
            math.isfinite(self.min_distance) and self.min_distance >= 0.0
        ):
            raise ConfigurationError(
                f"min_distance must be a finite distance >= 0 [m], got {self.min_distance!r}"
            )
        if self.rigid not in RIGID_MODES:
            raise ConfigurationError(
                f"unknown rigid-stereo mode {self.rigid!r}; expected one of {', '.join(RIGID_MODES)}"
            )

    @property
    def tolerance_rad(self) -> float:
        """[rad] below which an axis counts as on its target (:func:`pointing_tolerance`)."""
        return pointing_tolerance(self.tolerance, self.focal_px)


def check_readings(
    joint_names: Sequence[str], lower: Array, upper: Array, q: ArrayLike | Mapping[str, float]
) -> Array:
    """Readings ``q`` (shape (n,) in ``joint_names`` order, or ``{joint: reading}`` naming every
    joint) as an array inside ``lower``..``upper`` (1e-9 slack, then clipped).

    Raises:
        UnknownNameError: A joint not in ``joint_names``.
        ConfigurationError: Missing joints, the wrong shape, NaN/inf, or a reading outside its
            limits.
    """
    n = len(joint_names)
    if isinstance(q, Mapping):
        unknown = set(q) - set(joint_names)
        if unknown:
            raise UnknownNameError("joint", sorted(unknown)[0], tuple(joint_names))
        missing = [j for j in joint_names if j not in q]
        if missing:
            raise ConfigurationError(f"q_current lacks joints {missing}")
        q = [q[j] for j in joint_names]
    try:
        qa = np.asarray(q, dtype=float)
    except (TypeError, ValueError) as e:
        raise ConfigurationError(f"q_current must be {n} numbers, got {q!r}") from e
    if qa.shape != (n,):
        raise ConfigurationError(
            f"q_current must have shape ({n},) for joints {list(joint_names)}, got shape {qa.shape}"
        )
    if not np.all(np.isfinite(qa)):
        raise ConfigurationError(f"q_current must be finite, got {qa.tolist()}")
    tol = 1e-9
    bad = np.flatnonzero((qa < lower - tol) | (qa > upper + tol))
    if bad.size:
        i = int(bad[0])
        raise ConfigurationError(
            f"q_current: joint {joint_names[i]!r} reading {qa[i]:.9g} outside its limits [{lower[i]:.9g}, {upper[i]:.9g}]"
        )
    return np.clip(qa, lower, upper)


def target_point(p_world: ArrayLike) -> Array:
    """A gaze target as a finite point of shape (3,) [m], or :class:`ConfigurationError` saying
    what is wrong (the solver and the view check targets the same way). Always a new
    C-contiguous array: the solver keeps it in its answer and the kernels take it as it is."""
    try:
        p = np.array(p_world, dtype=float)
    except (TypeError, ValueError) as e:
        raise ConfigurationError(f"target must be three numbers x y z [m], got {p_world!r}") from e
    if p.shape != (3,):
        raise ConfigurationError(f"target must be three numbers x y z [m], got shape {p.shape}")
    x, y, z = p.tolist()
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        raise ConfigurationError(f"target must be finite, got {p.tolist()}")
    return p


__all__ = [
    "DEFAULT_CAMERAS",
    "POLICIES",
    "GazeOptions",
    "Index",
    "check_policy",
    "check_readings",
    "pointing_tolerance",
    "target_point",
]
