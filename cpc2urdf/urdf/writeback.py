"""Write a calibrated model back into the URDF it was built from.

``write_calibrated_urdf(model, "calibrated.urdf")`` writes the source URDF (recorded in the model's
``urdf`` section, :class:`~cpc2urdf.urdf.robot.UrdfSource`) with only the calibrated joints'
``<origin>`` tags replaced (:mod:`cpc2urdf.urdf.origins` says which joints and where they go).
The edit is made on the text: each ``<origin>`` start tag is located by the XML parser and
replaced in place, so every other byte of the file (links, inertials, meshes and their paths,
collisions, materials, transmissions, ``gazebo``/``ros2_control`` tags, other joints, comments,
indentation) stays as it was. A joint without ``<origin>`` gets one after its start tag; the
``<axis>`` of a moving joint whose origin changes is rewritten only if it was not a unit vector
(parsers disagree on those; the model uses the unit vector).
An origin the model leaves where the file has it (to rounding) keeps its text.

Next to the URDF go its calibration report (:mod:`cpc2urdf.urdf.report`):
``calibrated.report.json`` and ``calibrated.report.txt``. Every check runs before any file is
written, and each file is written atomically.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from cpc2urdf.files.jsonio import check_output_path, dumps, write_atomic
from cpc2urdf.model import CPCModel
from cpc2urdf.transforms import Array
from cpc2urdf.urdf.document import origin_attributes, urdf_vector
from cpc2urdf.urdf.input import validate_urdf
from cpc2urdf.urdf.origins import WritebackPlan, writeback_plan
from cpc2urdf.urdf.report import CalibrationReport, OriginStd, calibration_report, report_paths
from cpc2urdf.urdf.tree import TagSpan

UNIT_AXIS_TOL = (
    1e-12  # [-]: an <axis> whose length differs from 1 by more is rewritten as a unit vector
)


def _origin_tag(T: Array, empty: bool) -> bytes:
    end = "/>" if empty else ">"
    return f"<origin {origin_attributes(T)}{end}".encode()


def _indent(data: bytes, tag: TagSpan) -> bytes:
    """The whitespace before the line of ``tag``, plus two spaces (a child element's indent)."""
    line = data.rfind(b"\n", 0, tag.start) + 1
    head = data[line : tag.start]
    return (head if not head.strip() else b"") + b"  "


def calibrated_urdf_text(plan: WritebackPlan) -> str:
    """The source URDF's text with the plan's changed origins (module docstring)."""
    data = plan.tree.text.encode("utf-8")
    edits: list[tuple[int, int, bytes]] = []
    for c in plan.changes:
        j = c.joint
        if c.changed:
            if j.origin_tag is not None:
                edits.append(
                    (
                        j.origin_tag.start,
                        j.origin_tag.end,
                        _origin_tag(c.calibrated, j.origin_tag.empty),
                    )
                )
            elif (
                j.tag.empty
            ):  # <joint .../> has no children to keep; validate_urdf refuses it anyway
                raise AssertionError(f"joint {j.name!r} has no <parent>/<child>")
            else:
                edits.append(
                    (
                        j.tag.end,
                        j.tag.end,
                        b"\n" + _indent(data, j.tag) + _origin_tag(c.calibrated, True),
                    )
                )
        if (
            c.changed
            and c.axis is not None
            and j.axis_tag is not None
            and abs(np.linalg.norm(j.axis) - 1.0) > UNIT_AXIS_TOL
        ):
            end = "/>" if j.axis_tag.empty else ">"
            edits.append(
                (
                    j.axis_tag.start,
                    j.axis_tag.end,
                    f'<axis xyz="{urdf_vector(c.axis)}"{end}'.encode(),
                )
            )
    for first, last, new in sorted(edits, reverse=True):
        data = data[:first] + new + data[last:]
    return data.decode("utf-8")


def write_calibrated_urdf(
    model: CPCModel,
    path: str | os.PathLike[str],
    *,
    urdf: str | os.PathLike[str] | None = None,
    uncertainty: Mapping[str, OriginStd] | None = None,
) -> Path:
    """Write ``model`` into its source URDF as ``path``, with the calibration report beside it.

    Args:
        model: A model built from a URDF (identified from measurements of a URDF robot, or the
            nominal model of one), possibly with camera frames from hand-eye calibration.
        path: The calibrated URDF to write; the report goes to ``<path stem>.report.json`` and
            ``.report.txt``.
        urdf: The URDF to write into (default: the one the model was built from).
        uncertainty: Per URDF joint, the spread of its new origin for the report
            (:func:`cpc2urdf.identification.kinematics.origin_uncertainty.origin_uncertainty`).

    Returns:
        ``path``.

    Raises:
        SpecError: The model was not built from a URDF.
        InputFileError: The source URDF does not parse, changed where the model depends on it, or
            lacks a link the model names (one line: file, element).
        OutputError: ``path``'s folder does not exist (nothing is written).
    """
    out = Path(path)
    json_path, text_path = report_paths(out)
    for p in (out, json_path, text_path):
        check_output_path(p)
    plan = writeback_plan(model, urdf)
    text = calibrated_urdf_text(plan)
    validate_urdf(text, out)
    report = calibration_report(model, plan=plan, uncertainty=uncertainty, output=out)
    write_atomic(out, text)
    write_atomic(json_path, dumps(report.to_json()))
    write_atomic(text_path, report.to_text())
    return out


__all__ = ["UNIT_AXIS_TOL", "CalibrationReport", "calibrated_urdf_text", "write_calibrated_urdf"]
