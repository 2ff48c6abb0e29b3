"""The calibration report of a written-back URDF: what calibration changed, joint by joint.

For every calibrated joint (:mod:`cpc2urdf.urdf.origins`) the report gives how far its origin
moved [mm] and turned [deg], how far a moving joint's axis tilted [deg] (its direction in the
parent link's frame), both origins as the file writes them, and, when the model carries a
covariance (``identify --method refined``), the standard deviation of each of the three. The
standard deviations come from :func:`cpc2urdf.identification.kinematics.origin_uncertainty.
origin_uncertainty` (the covariance lives in the identification layer); they are first-order and
in the model's own gauge: what the data leave open (a frame's position along its joint's axis,
say) is not a parameter and has no spread.

Two forms: JSON (``<output>.report.json``, format ``cpc2urdf/calibration-report@1``) and text
(``<output>.report.txt``, also what ``cpc2urdf export`` prints).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from cpc2urdf.model import CPCModel
from cpc2urdf.transforms import Array, rpy_from_matrix
from cpc2urdf.urdf.origins import OriginChange, WritebackPlan, writeback_plan

REPORT_FORMAT = "cpc2urdf/calibration-report@1"


@dataclass(frozen=True)
class OriginStd:
    """First-order standard deviations of a calibrated joint's origin (None: not determined).

    Attributes:
        translation: RMS Euclidean error of the origin's position, ``sqrt(trace(Sigma_p))`` [m].
        rotation: RMS rotation error of its orientation, ``sqrt(trace(Sigma_w))`` [rad].
        axis: RMS error of a moving joint's axis direction [rad], None for fixed joints.
    """

    translation: float | None
    rotation: float | None
    axis: float | None = None


def _mm(v: float | None) -> float | None:
    return None if v is None else v * 1e3


def _deg(v: float | None) -> float | None:
    return None if v is None else math.degrees(v)


def _origin_json(T: Array) -> dict[str, list[float]]:
    return {
        "xyz_m": [float(v) for v in T[:3, 3]],
        "rpy_rad": [float(v) for v in rpy_from_matrix(T[:3, :3])],
    }


@dataclass(frozen=True, eq=False)
class CalibrationReport:
    """What a calibrated model changes in its URDF.

    Attributes:
        source: The URDF the model was built from.
        output: The calibrated URDF written, or None.
        robot: ``<robot name>``.
        root: Its root link.
        changes: One entry per calibrated joint, root first.
        uncertainty: URDF joint -> :class:`OriginStd` (empty without a covariance).
        T_world_root: Pose of the root link in the measuring system's world (the model's
            ``T_world_base``; not part of the URDF), shape (4, 4).
        notes: Free-text remarks (how the uncertainty was scaled, ...).
    """

    source: str
    output: str | None
    robot: str
    root: str
    changes: tuple[OriginChange, ...]
    uncertainty: Mapping[str, OriginStd] = field(default_factory=dict)
    T_world_root: Array = field(default_factory=lambda: np.eye(4))
    notes: tuple[str, ...] = ()

    def to_json(self) -> dict[str, Any]:
        """The ``cpc2urdf/calibration-report@1`` document (units in the key names)."""
        joints = []
        for c in self.changes:
            std = self.uncertainty.get(c.joint.name)
            joints.append(
                {
                    "joint": c.joint.name,
                    "type": c.joint.type,
                    "role": c.role,
                    "model_name": c.owner,
                    "parent": c.joint.parent,
                    "child": c.joint.child,
                    "changed": c.changed,
                    "translation_mm": c.translation * 1e3,
                    "rotation_deg": math.degrees(c.rotation),
                    "axis_deg": _deg(c.axis_change),
                    "delta_xyz_mm": [float(v) * 1e3 for v in c.delta_xyz],
                    "nominal": _origin_json(c.nominal),
                    "calibrated": _origin_json(c.calibrated),
                    "std": None
                    if std is None
                    else {
                        "translation_mm": _mm(std.translation),
                        "rotation_deg": _deg(std.rotation),
                        "axis_deg": _deg(std.axis),
                    },
                }
            )
        return {
            "format": REPORT_FORMAT,
            "urdf": self.source,
            "written": self.output,
            "robot": self.robot,
            "root": self.root,
            "joints": joints,
            "unchanged": "every other element of the URDF (links, inertials, meshes, collisions, materials, "
            "transmissions, gazebo/ros2_control tags, other joints, comments)",
            "world_to_root": {
                "xyz_mm": [float(v) * 1e3 for v in self.T_world_root[:3, 3]],
                "rpy_deg": [math.degrees(v) for v in rpy_from_matrix(self.T_world_root[:3, :3])],
                "note": "pose of the root link in the measuring system; not written into the URDF",
            },
            "notes": list(self.notes),
        }

    def to_text(self) -> str:
        """A table for people: one line per calibrated joint."""
        n_changed = sum(c.changed for c in self.changes)
        lines = [
            f"calibration of {self.robot!r} (root link {self.root!r}) from {self.source}"
            + (f" -> {self.output}" if self.output else ""),
            f"{n_changed} of {len(self.changes)} calibrated joints changed; every other element of the URDF is kept",
        ]
        width = max([len(c.joint.name) for c in self.changes] + [5])
        has_std = bool(self.uncertainty)
        head = f"  {'joint':<{width}}  {'role':<13}  {'moved [mm]':>10}  {'turned [deg]':>12}  {'axis [deg]':>10}"
        lines.append(head + ("  1-sigma: mm / deg / deg" if has_std else ""))
        for c in self.changes:
            axis = "" if c.axis_change is None else f"{math.degrees(c.axis_change):.4f}"
            row = (
                f"  {c.joint.name:<{width}}  {c.role:<13}  {c.translation * 1e3:>10.4f}  "
                f"{math.degrees(c.rotation):>12.4f}  {axis:>10}"
            )
            std = self.uncertainty.get(c.joint.name)
            if std is not None:
                parts = [_fmt(_mm(std.translation)), _fmt(_deg(std.rotation))]
                if std.axis is not None or c.axis is not None:
                    parts.append(_fmt(_deg(std.axis)))
                row += "  " + " / ".join(parts)
            lines.append(row)
        xyz = ", ".join(f"{v * 1e3:.3f}" for v in self.T_world_root[:3, 3])
        rpy = ", ".join(
            f"{math.degrees(v):.3f}" for v in rpy_from_matrix(self.T_world_root[:3, :3])
        )
        lines.append(
            f"root link in the measuring system: xyz [{xyz}] mm, rpy [{rpy}] deg (not in the URDF)"
        )
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines) + "\n"


def _fmt(v: float | None) -> str:
    return "undetermined" if v is None else f"{v:.4f}"


def calibration_report(
    model: CPCModel,
    *,
    plan: WritebackPlan | None = None,
    uncertainty: Mapping[str, OriginStd] | None = None,
    output: str | os.PathLike[str] | None = None,
) -> CalibrationReport:
    """The calibration report of ``model`` (a model built from a URDF).

    Args:
        model: The calibrated model.
        plan: Its write-back plan (default: :func:`~cpc2urdf.urdf.origins.writeback_plan`).
        uncertainty: Per URDF joint, the spread of its new origin (see the module docstring);
            None or empty: the report gives none.
        output: The calibrated URDF's path, for the report to name.

    Raises:
        SpecError, InputFileError: As :func:`~cpc2urdf.urdf.origins.writeback_plan`.
    """
    plan = plan if plan is not None else writeback_plan(model)
    notes = []
    cov = model.metadata.uncertainty
    if uncertainty:
        scale = cov.scale if cov is not None else "unknown"
        notes.append(
            f"1-sigma from the model's covariance (scale {scale}), first order, in the model's gauge"
        )
    elif cov is None:
        notes.append(
            "no uncertainty: the model carries no covariance (identify with --method refined)"
        )
    else:
        notes.append(
            "the model carries a covariance, not propagated here (cpc2urdf.api.calibration_report does)"
        )
    return CalibrationReport(
        source=plan.tree.source,
        output=None if output is None else os.fspath(output),
        robot=plan.tree.name,
        root=plan.tree.root,
        changes=plan.changes,
        uncertainty=dict(uncertainty or {}),
        T_world_root=model.T_world_base(),
        notes=tuple(notes),
    )


def report_paths(urdf_path: str | os.PathLike[str]) -> tuple[Path, Path]:
    """The report files next to a calibrated URDF: ``x.urdf`` -> ``x.report.json``, ``x.report.txt``."""
    p = Path(urdf_path)
    return p.with_suffix(".report.json"), p.with_suffix(".report.txt")


def written_reports(urdf_path: str | os.PathLike[str]) -> dict[str, str]:
    """The report files a written-back URDF brings, as a command's ``written`` outputs (none for
    a path without a file name, which the command refuses before writing)."""
    try:
        json_path, text_path = report_paths(urdf_path)
    except ValueError:
        return {}
    return {"-o (its report)": str(json_path), "-o (its text report)": str(text_path)}


__all__ = [
    "REPORT_FORMAT",
    "CalibrationReport",
    "OriginStd",
    "calibration_report",
    "report_paths",
    "written_reports",
]
