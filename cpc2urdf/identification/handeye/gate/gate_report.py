"""What the hand-eye consistency gate concludes: :class:`ConsistencyReport`, and the refusal.

:func:`~cpc2urdf.identification.handeye.gate.handeye_gate.check_consistency` returns a report;
:func:`~cpc2urdf.identification.handeye.solvers.calibrate` with ``gate=True`` raises
:class:`InconsistentPosesError` carrying it, or (``accept_inconsistent=True``) attaches it to the
result, from where it is stored in the model (``metadata.handeye[camera].details["consistency"]``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from cpc2urdf.errors import InconsistentDataError

#: How the residuals were judged: against the noise the pose file states, or an estimate of it.
STATED = "stated"
ESTIMATED = "estimated"


@dataclass(frozen=True)
class ConsistencyReport:
    """The verdict on one set of hand-eye poses.

    Attributes:
        consistent: The data agree with ``A X = Z B`` and the noise (stated or estimated).
        code: ``""`` if consistent; else a mistake code of
            :data:`~cpc2urdf.identification.handeye.gate.mistakes.MISTAKE_CODES`, ``"outliers"``,
            ``"noise_exceeded"`` (residuals above the stated noise), ``"below_noise"`` (far below
            it), ``"implausible"`` (a solution no real setup has, no tested mistake explains it).
        cause: The most likely cause, in words ("" if consistent).
        evidence: The numbers behind the verdict.
        fix: What to change in the input ("" if consistent).
        noise: :data:`STATED` or :data:`ESTIMATED`.
        rms_translation: RMS position residual of the gate's reference fit of the data as given [m].
        rms_rotation: RMS rotation residual of that fit [rad].
        noise_ratio: With stated noise, ``sqrt(chi2 / dof)`` of the reference fit (1 = as stated);
            NaN when the noise is estimated.
        outliers: Labels of the poses found to be gross outliers.
        alternatives: ``(code, improvement)`` per tested mistake: how many times smaller the
            residual variance became when it was undone (below 1: worse).
        false_alarm: Probability that the gate refuses data that are consistent (its tests' level).
        warnings: Consistent but suspicious data (large residuals, an implausible camera offset).
    """

    consistent: bool
    code: str = ""
    cause: str = ""
    evidence: str = ""
    fix: str = ""
    noise: str = ESTIMATED
    rms_translation: float = math.nan
    rms_rotation: float = math.nan
    noise_ratio: float = math.nan
    outliers: tuple[str, ...] = ()
    alternatives: tuple[tuple[str, float], ...] = field(default=())
    false_alarm: float = math.nan
    warnings: tuple[str, ...] = ()

    def summary(self) -> str:
        """One line: the cause and its evidence (or that the data are consistent)."""
        if self.consistent:
            return f"consistent ({self.noise} noise): {self.evidence}"
        return f"{self.cause} ({self.evidence})"

    def to_json(self) -> dict[str, Any]:
        """Plain JSON (residuals in mm and deg, as the model file's hand-eye section)."""
        doc: dict[str, Any] = {
            "consistent": self.consistent,
            "code": self.code,
            "cause": self.cause,
            "evidence": self.evidence,
            "fix": self.fix,
            "noise": self.noise,
            "rms_translation_mm": self.rms_translation * 1e3,
            "rms_rotation_deg": math.degrees(self.rms_rotation),
            "outliers": list(self.outliers),
            "false_alarm": self.false_alarm,
            "warnings": list(self.warnings),
        }
        if math.isfinite(self.noise_ratio):
            doc["noise_ratio"] = self.noise_ratio
        doc["alternatives"] = {c: v for c, v in self.alternatives}
        return doc


class InconsistentPosesError(InconsistentDataError):
    """Hand-eye poses that contradict ``A X = Z B`` beyond chance; the message names the likely cause.

    A :class:`~cpc2urdf.errors.InconsistentDataError` (hence a ``DegenerateDataError``: the data
    cannot give a trustworthy answer), so code that catches those catches this too.

    Args:
        report: The gate's report (``report.consistent`` is False).
        source: The pose file (or ``"<memory>"``), named first in the message.
    """

    def __init__(self, report: ConsistencyReport, source: str = "") -> None:
        where = f"{source}: " if source and source != "<memory>" else ""
        super().__init__(
            f"{where}inconsistent data: {report.cause} ({report.evidence}); {report.fix}; "
            "--accept-inconsistent (accept_inconsistent=True) keeps the result with this diagnosis",
            report,
        )
        self.report: ConsistencyReport = report


__all__ = ["ESTIMATED", "STATED", "ConsistencyReport", "InconsistentPosesError"]
