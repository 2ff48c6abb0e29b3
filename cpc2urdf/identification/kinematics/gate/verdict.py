"""The consistency gate's tests and verdict: is one stage-1 fit consistent with its data's noise?

:func:`evaluate` puts a maximum-likelihood fit (:class:`~cpc2urdf.identification.kinematics.
fit_statistics.FitStatistics`) through the gate's tests (docs/identification.md, "Consistency
gate"):

- with a noise statement (:class:`Noise` ``known``): the chi-square tests of the translation and
  rotation residuals, both tails, each at ``FALSE_ALARM / 8``, and every pose's exact test at
  ``FALSE_ALARM / (2 n)`` (Bonferroni: the family-wise false-alarm probability is
  :data:`FALSE_ALARM`);
- without one: every pose against :data:`OUTLIER_RATIO` times its frame's median residual;
- always: the size of the robot the data imply (:mod:`plausibility`).

:class:`Diagnosis` is the most likely cause of a failure (found by :mod:`diagnosis`), and
:class:`ConsistencyReport` the gate's verdict on one identification, with the one-line refusal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from cpc2urdf.errors import InconsistentDataError
from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.identification.kinematics.gate.fit_statistics import FitStatistics
from cpc2urdf.identification.kinematics.gate.plausibility import SizeCheck, size_check, times
from cpc2urdf.model import CPCModel
from cpc2urdf.tolerances import FK_AGREEMENT_TOL

# Probability that the gate refuses consistent data (family-wise, with a noise statement).
FALSE_ALARM = 1e-6  # [-]
# Without a noise statement: a pose whose residual exceeds this many times its frame's median is
# a gross outlier (half-normal and chi(3) residuals exceed 10x their median with p < 1e-10).
OUTLIER_RATIO = 10.0  # [-]
# Dropping more than this share of the poses is not "outliers" but a wrong data set.
MAX_OUTLIER_FRACTION = 0.2  # [-]
# Without a noise statement, a fix must cut the variance factor at least this much to count.
MIN_IMPROVEMENT = 4.0  # [-]
# Fixes refined (and tested) after the closed-form screening.
SCREENED = 3
# Solver evaluations per stage for the gate's refits: a consistent fit converges in about 5; data
# that are far off crawl, and their exact optimum does not change the verdict.
STATS_NFEV = 50
# With stated noise, a fix is refitted when its closed form's |log(chi2 / expected)| summed over
# translations and rotations is below this (a consistent fix's closed form scores ~0.3-1.5).
PROMISING = 2.0 * math.log(10.0)  # [-]
ACCEPT_HINT = "or pass --accept-inconsistent"


@dataclass(frozen=True)
class Noise:
    """The noise the fit is judged against: stated by the file (``known``) or assumed weights.

    Attributes:
        sigma_t: Translation noise per entry [m].
        sigma_r: Rotation noise angle [rad].
        known: The measurement file states them.
    """

    sigma_t: float
    sigma_r: float
    known: bool

    def describe(self) -> str:
        return f"{self.sigma_t * 1e3:.3g} mm / {math.degrees(self.sigma_r):.3g} deg"


@dataclass(frozen=True)
class Diagnosis:
    """The most likely cause of inconsistent data.

    Attributes:
        kind: An :class:`Alternative` kind, ``"outliers"``, ``"noise"`` or ``"size"``.
        cause: What the data look like, in words.
        evidence: The numbers: the fit as read and with the fix.
        remedy: What to change.
        key: The fix that made the data consistent ("" if none).
        records: Record indices concerned (outliers).
    """

    kind: str
    cause: str
    evidence: str
    remedy: str
    key: str = ""
    records: tuple[int, ...] = ()

    def line(self) -> str:
        return f"{self.cause} ({self.evidence}) — {self.remedy}"


@dataclass(frozen=True)
class ConsistencyReport:
    """The gate's verdict on one identification.

    Attributes:
        consistent: The data agree with the model and their noise.
        source: The measurement file.
        noise: What the fit was judged against.
        statistics: The maximum-likelihood fit of the data as read.
        problems: The failed tests, in words (empty if consistent).
        diagnosis: The most likely cause (None if consistent).
        tested: Keys of the fixes refitted and tested.
        size: The plausibility check, if there was a yardstick.
    """

    consistent: bool
    source: str
    noise: Noise
    statistics: FitStatistics
    problems: tuple[str, ...] = ()
    diagnosis: Diagnosis | None = None
    tested: tuple[str, ...] = ()
    size: SizeCheck | None = None

    def line(self) -> str:
        """The diagnosis in one line (without the file name)."""
        if self.consistent or self.diagnosis is None:
            return "consistent"
        return self.diagnosis.line()

    def error(self) -> InconsistentDataError:
        """The one-line refusal."""
        return InconsistentDataError(f"{self.source}: {self.line()}, {ACCEPT_HINT}", self)

    def to_json(self) -> dict[str, Any]:
        """The ``consistency`` entry of a model's provenance details (SI units)."""
        out: dict[str, Any] = {
            "consistent": self.consistent,
            "test": (
                "chi-square of the weighted residuals (both tails) and per-pose tests against the stated noise"
                if self.noise.known
                else "robust residual scale, refits of likely mistakes, robot size"
            ),
            "false_alarm_probability": FALSE_ALARM if self.noise.known else None,
            "noise": "stated" if self.noise.known else "not stated (relative weights)",
            "fit": self.statistics.to_json(),
            "fit_over_noise": {
                "translation": self.statistics.ratio_t,
                "rotation": self.statistics.ratio_r,
            }
            if self.noise.known
            else None,
            "size": None
            if self.size is None
            else {
                "yardstick": self.size.yardstick,
                "ratio": self.size.ratio,
                "plausible": self.size.plausible,
            },
            "problems": list(self.problems),
            "alternatives_tested": list(self.tested),
        }
        if self.diagnosis is not None:
            d = self.diagnosis
            out["diagnosis"] = {
                "kind": d.kind,
                "cause": d.cause,
                "evidence": d.evidence,
                "remedy": d.remedy,
                "fix": d.key,
                "records": list(d.records),
            }
        return out


def outlier_poses(stats: FitStatistics, noise: Noise) -> list[tuple[str, int]]:
    """Poses that fail the per-pose test (stated noise) or the robust ratio rule (no statement)."""
    out = []
    if noise.known:
        for f, p in stats.pose_p_values().items():
            out += [
                (f, int(stats.records[f][i]))
                for i in np.flatnonzero(p < FALSE_ALARM / (2 * stats.n_poses))
            ]
        return out
    for f in stats.translation:
        t, r = stats.translation[f], stats.rotation[f]
        bad = ((t > OUTLIER_RATIO * np.median(t)) & (t > FK_AGREEMENT_TOL)) | (
            (r > OUTLIER_RATIO * np.median(r)) & (r > FK_AGREEMENT_TOL)
        )
        out += [(f, int(stats.records[f][i])) for i in np.flatnonzero(bad)]
    return out


def noise_problems(stats: FitStatistics, noise: Noise) -> list[str]:
    """The chi-square tails that fail (stated noise only)."""
    if not noise.known:
        return []
    tails = stats.tails()
    out = []
    for part, ratio in (("translation", stats.ratio_t), ("rotation", stats.ratio_r)):
        if tails[f"{part}_high"] < FALSE_ALARM / 8:
            out.append(f"{part} residuals {times(ratio)} the stated noise")
        elif tails[f"{part}_low"] < FALSE_ALARM / 8:
            out.append(f"{part} residuals {times(ratio)} the stated noise (far below it)")
    return out


def is_exact(stats: FitStatistics) -> bool:
    t, r = stats.rms()
    return t < FK_AGREEMENT_TOL and r < FK_AGREEMENT_TOL


def evaluate(
    stats: FitStatistics,
    noise: Noise,
    ms: MeasurementSet,
    nominal: CPCModel | None,
    outlier_share: float = 0.0,
) -> tuple[list[str], list[tuple[str, int]], SizeCheck | None]:
    """``(problems, outlier poses, size)`` of one fit."""
    problems = noise_problems(stats, noise)
    poses = outlier_poses(stats, noise)
    if poses:
        problems.append(f"{len(poses)} poses far off the fit")
    if outlier_share > MAX_OUTLIER_FRACTION:
        problems.append(f"the robust fit rejected {outlier_share:.0%} of the poses")
    size = size_check(ms, nominal)
    if size is not None and not size.plausible:
        problems.append(size.describe())
    return problems, poses, size


__all__ = [
    "ACCEPT_HINT",
    "FALSE_ALARM",
    "MAX_OUTLIER_FRACTION",
    "MIN_IMPROVEMENT",
    "OUTLIER_RATIO",
    "PROMISING",
    "SCREENED",
    "STATS_NFEV",
    "ConsistencyReport",
    "Diagnosis",
    "Noise",
    "evaluate",
    "is_exact",
    "noise_problems",
    "outlier_poses",
    "times",
]
