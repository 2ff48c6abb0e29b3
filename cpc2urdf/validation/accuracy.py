"""Held-out positioning accuracy of a model: the paper's Table 4 (Shih et al. sec. 6).

For every branch (measured frame, e.g. each plate) and held-out record, the positioning error is
``e = p_model(q) - p_measured`` [m], the model-predicted origin minus the measured one, in world
coordinates. Table 4 reports "the mean and standard deviation of the positioning error in x, y and
z directions"; its means are all positive and of the size of its standard deviations, so it
averages *absolute* components: we report ``mean |e_x|``, ``std |e_x|`` (sample standard
deviation), and the same for y and z, plus the mean Euclidean error ``mean |e|`` (the paper's
"positioning error", Fig. 11), its RMS and maximum, and the rotation error (angle between the
predicted and measured orientations).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.measurements import MeasurementSet
from cpc2urdf.model import CPCModel
from cpc2urdf.transforms import rotation_error

Array = NDArray[np.float64]


@dataclass(frozen=True)
class BranchAccuracy:
    """Table 4 for one branch.

    Attributes:
        frame: The measured frame.
        records: Held-out records that measured it.
        mean_abs: ``mean |e_x|, |e_y|, |e_z|`` [m], shape (3,).
        std_abs: Sample standard deviation of ``|e_x|, |e_y|, |e_z|`` [m], shape (3,).
        mean: Mean Euclidean error ``mean |e|`` [m].
        rms: RMS Euclidean error [m].
        max: Largest Euclidean error [m].
        mean_rotation: Mean rotation error [rad].
        max_rotation: Largest rotation error [rad].
        predicted_rms: RMS Euclidean error [m] that the model's own covariance predicts for these
            records (None when the model carries no ``uncertainty`` section).
    """

    frame: str
    records: int
    mean_abs: Array
    std_abs: Array
    mean: float
    rms: float
    max: float
    mean_rotation: float
    max_rotation: float
    predicted_rms: float | None = None

    def to_json(self) -> dict[str, Any]:
        """In mm and degrees, for machines (``cpc2urdf accuracy --json``)."""
        return {
            "records": self.records,
            "mean_abs_mm": {a: float(v * 1e3) for a, v in zip("xyz", self.mean_abs, strict=True)},
            "std_abs_mm": {a: float(v * 1e3) for a, v in zip("xyz", self.std_abs, strict=True)},
            "mean_mm": self.mean * 1e3,
            "rms_mm": self.rms * 1e3,
            "max_mm": self.max * 1e3,
            "mean_rotation_deg": float(np.degrees(self.mean_rotation)),
            "max_rotation_deg": float(np.degrees(self.max_rotation)),
            "predicted_rms_mm": None if self.predicted_rms is None else self.predicted_rms * 1e3,
        }


def position_errors(model: CPCModel, ms: MeasurementSet, frame: str) -> tuple[Array, Array]:
    """Per record that measured ``frame``: ``e = p_model - p_measured`` [m], shape (K, 3), and the
    rotation error [rad], shape (K,)."""
    ok = ms.has_pose(frame)
    T = model.fk(ms.q[ok], [frame])[frame]
    e = T[:, :3, 3] - ms.poses[frame][ok, :3, 3]
    return e, rotation_error(T[:, :3, :3], ms.poses[frame][ok, :3, :3])


def held_out_poses_are_true(ms: MeasurementSet) -> bool:
    """True when the file says its poses are noise-free truth (``"noise": {"model": "none"}``,
    as the simulator writes held-out sets); real measurements carry the rig's own noise."""
    noise = ms.metadata.get("noise")
    return isinstance(noise, dict) and noise.get("model") == "none"


def predicted_rms(model: CPCModel, ms: MeasurementSet, frame: str) -> float | None:
    """RMS position error [m] the identification's covariance predicts at the records of ``ms``
    that measured ``frame`` (plus the measuring noise unless the poses are true ones); None if the
    model has no uncertainty section."""
    from cpc2urdf.identification.kinematics.uncertainty import (
        NoUncertaintyError,
        predicted_position_std,
    )

    ok = ms.has_pose(frame)
    try:
        std = predicted_position_std(
            model, ms.q[ok], [frame], measurement_noise=not held_out_poses_are_true(ms)
        )[frame]
    except NoUncertaintyError:
        return None
    return float(np.sqrt(np.mean(std**2)))


def accuracy(model: CPCModel, ms: MeasurementSet) -> dict[str, BranchAccuracy]:
    """Table 4 for every frame that both the model has and ``ms`` measured, with the error the
    model's covariance predicts next to it when the model has one (``identify --method refined``).

    Raises:
        DegenerateDataError: The joints differ, or no measured frame is in the model.
    """
    if tuple(ms.structure.joint_names) != tuple(model.structure.joint_names):
        raise DegenerateDataError(
            f"{ms.source}: joints {list(ms.structure.joint_names)} do not match the model's "
            f"{list(model.structure.joint_names)}"
        )
    frames = [f for f in ms.frames if f in model.structure.frame_names]
    if not frames:
        raise DegenerateDataError(
            f"{ms.source}: none of its measured frames ({', '.join(ms.frames) or 'none'}) is in the model "
            f"({', '.join(model.structure.frame_names)})"
        )
    out = {}
    for f in frames:
        e, r = position_errors(model, ms, f)
        a = np.abs(e)
        d = np.linalg.norm(e, axis=1)
        out[f] = BranchAccuracy(
            f, len(e), a.mean(axis=0), a.std(axis=0, ddof=1) if len(e) > 1 else np.zeros(3),
            float(d.mean()), float(np.sqrt(np.mean(d**2))), float(d.max()), float(r.mean()), float(r.max()),
            predicted_rms(model, ms, f) if model.metadata.uncertainty is not None else None,
        )
    return out


def format_table(report: dict[str, BranchAccuracy]) -> str:
    """Table 4 layout: one block per branch, mm and degrees."""
    lines = []
    for f, b in report.items():
        lines.append(f"{f} ({b.records} held-out records):")
        for k, axis in enumerate("xyz"):
            lines.append(f"  mu_{axis} = {b.mean_abs[k] * 1e3:7.3f} mm   sigma_{axis} = {b.std_abs[k] * 1e3:7.3f} mm")
        lines.append(f"  mean |e| = {b.mean * 1e3:.3f} mm   rms {b.rms * 1e3:.3f} mm   max {b.max * 1e3:.3f} mm")
        lines.append(f"  rotation: mean {np.degrees(b.mean_rotation):.4f} deg   max {np.degrees(b.max_rotation):.4f} deg")
        if b.predicted_rms is not None:
            lines.append(
                f"  predicted rms {b.predicted_rms * 1e3:.3f} mm (identification covariance) "
                f"vs observed rms {b.rms * 1e3:.3f} mm"
            )
    lines.append("(mu, sigma: mean and sample standard deviation of the absolute error components in world)")
    return "\n".join(lines)


__all__ = ["BranchAccuracy", "accuracy", "format_table", "held_out_poses_are_true", "position_errors", "predicted_rms"]
