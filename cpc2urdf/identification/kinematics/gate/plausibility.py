"""Is the robot the data imply of a plausible size? A scale check that needs no noise statement.

A file whose lengths are in the wrong unit (metres labelled mm) describes a robot 1000x too
small, and fits it perfectly: the residuals shrink with it, so only a yardstick from outside the
data can catch it. Two yardsticks, in this order:

- the robot's **nominal model** (its spec's geometry): the spread of the measured frame origins
  over the records (RMS distance from their mean) and the distances between frames measured in
  the same record, against the nominal model's at the same readings (both are independent of
  where the robot stands in the measuring system's world);
- without nominal geometry, the **joint limits**: the prismatic joints' travel in the records
  against the travel their limits allow.

:func:`size_check` returns the ratio and whether it lies within a factor :data:`SIZE_RATIO_TOL`
of 1 (or, for joint limits, whether the travel is at least :data:`MIN_TRAVEL_FRACTION` of the
range and at most all of it).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.model import CPCModel

# The data's robot is implausible if it is this many times larger or smaller than the nominal one
# (geometric errors of a real robot are millimetres on links of decimetres).
SIZE_RATIO_TOL = 3.0  # [-]
# Without nominal geometry: a calibration that moved every prismatic joint over less than this
# share of its range is implausible (and so is more than all of it).
MIN_TRAVEL_FRACTION = 0.01  # [-]


@dataclass(frozen=True)
class SizeCheck:
    """Size of the robot the data imply against a yardstick.

    Attributes:
        ratio: Measured over nominal size, or (``yardstick = "limits"``) the largest share of
            its limit range a prismatic joint travels [-].
        yardstick: ``"nominal"`` or ``"limits"``.
        plausible: Within the tolerance.
    """

    ratio: float
    yardstick: str
    plausible: bool

    @property
    def what(self) -> str:
        return (
            "the measured robot's size against the nominal model's"
            if self.yardstick == "nominal"
            else "the prismatic joints' travel against their limits"
        )

    def describe(self) -> str:
        if self.yardstick == "nominal":
            return f"the measured robot is {times(self.ratio)} the size of the nominal model"
        return f"the prismatic joints travel at most {self.ratio:.3g} of their limit ranges"


def times(r: float) -> str:
    """A ratio in words: ``"2.5x"``, ``"250x"`` or ``"1/1000 of"``."""
    if r >= 0.5:
        return f"{r:.3g}x" if r < 100 else f"{r:.0f}x"
    inv = 1.0 / max(r, 1e-300)
    return f"1/{inv:.3g} of" if inv < 100 else f"1/{inv:.0f} of"


def _spread(P: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((P - P.mean(axis=0)) ** 2, axis=1)))) if len(P) else 0.0


def nominal_size_ratio(ms: MeasurementSet, nominal: CPCModel) -> float | None:
    """Measured over nominal size: geometric mean of the frames' spread ratio and the ratio of
    the median distance between frames measured together; None if nothing compares."""
    frames = [f for f in ms.frames if f in nominal.structure.frame_names]
    if not frames:
        return None
    T = nominal.fk(ms.q, frames)
    ratios = []
    meas = np.concatenate([ms.poses[f][ms.has_pose(f), :3, 3] for f in frames])
    pred = np.concatenate([T[f][ms.has_pose(f), :3, 3] for f in frames])
    s_m, s_p = _spread(meas), _spread(pred)
    if s_m > 0 and s_p > 0:
        ratios.append(s_m / s_p)
    for a, b in itertools.combinations(frames, 2):
        both = ms.has_pose(a) & ms.has_pose(b)
        if not both.any():
            continue
        d_m = np.median(np.linalg.norm(ms.poses[a][both, :3, 3] - ms.poses[b][both, :3, 3], axis=1))
        d_p = np.median(np.linalg.norm(T[a][both, :3, 3] - T[b][both, :3, 3], axis=1))
        if d_m > 0 and d_p > 0:
            ratios.append(float(d_m / d_p))
    return float(np.exp(np.mean(np.log(ratios)))) if ratios else None


def travel_fraction(ms: MeasurementSet) -> float | None:
    """Largest share of its limit range that a prismatic joint travels in the records; None if
    the robot has no prismatic joint with finite limits."""
    out = []
    for k, j in enumerate(ms.structure.joints):
        span = j.upper - j.lower
        if j.type == "prismatic" and np.isfinite(span) and span > 0:
            out.append(float(np.ptp(ms.q[:, k]) / span))
    return max(out) if out else None


def size_check(ms: MeasurementSet, nominal: CPCModel | None) -> SizeCheck | None:
    """The data's robot size against the nominal model, else the joint limits; None if neither
    gives a yardstick."""
    if nominal is not None:
        r = nominal_size_ratio(ms, nominal)
        if r is not None:
            return SizeCheck(r, "nominal", 1.0 / SIZE_RATIO_TOL <= r <= SIZE_RATIO_TOL)
    t = travel_fraction(ms)
    if t is not None:
        return SizeCheck(t, "limits", MIN_TRAVEL_FRACTION <= t <= 1.0 + 1e-9)
    return None


__all__ = [
    "MIN_TRAVEL_FRACTION",
    "SIZE_RATIO_TOL",
    "SizeCheck",
    "nominal_size_ratio",
    "size_check",
    "times",
    "travel_fraction",
]
