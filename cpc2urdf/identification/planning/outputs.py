"""What ``cpc2urdf plan`` writes: the plan file, the joints CSV and the curve plot, all or nothing.

:func:`plan_robot` is the command's one call: robot reference -> setup -> plan -> file texts.
:func:`write_plan_outputs` writes ``plan.json`` (``cpc2urdf/plan@1``, :mod:`plan_file`),
``plan.csv`` (record, label, one column per joint in mm / deg, a URDF robot's joints by the URDF's
names: the layout :func:`~cpc2urdf.identification.vision.joints_csv.read_joints_csv` reads, so the
same file can drive the robot and later name the images) and ``plan.png`` (predicted RMS position error vs N
per strategy). Everything is computed and rendered in memory first; the three files are then
written all or nothing (temp files first, then renamed), so bad input or a failed write leaves
none of them.
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from cpc2urdf.errors import ConfigurationError, OutputError
from cpc2urdf.files.jsonio import check_output_path, dumps, write_all_atomic
from cpc2urdf.files.spec import RobotSpec
from cpc2urdf.files.units import ANGLE_UNITS, LENGTH_UNITS
from cpc2urdf.identification.planning.marker_setup import DEFAULT_MARKER_SIGMA
from cpc2urdf.identification.planning.measuring import MeasuringSetup, measuring_setup
from cpc2urdf.identification.planning.plan_file import plan_to_json
from cpc2urdf.identification.planning.plan_selection import (
    DEFAULT_CANDIDATES,
    DEFAULT_TASK,
    CurvePoint,
    PlanResult,
    make_plan,
    task_configurations,
)
from cpc2urdf.identification.simulation.measure_poses import (
    DEFAULT_PIXEL_SIGMA,
    DEFAULT_SIGMA_R,
    DEFAULT_SIGMA_T,
)
from cpc2urdf.identification.vision.joints_csv import urdf_joint_columns
from cpc2urdf.identification.vision.stereo import StereoRig
from cpc2urdf.model import RobotStructure


@dataclass
class PlanOutputs:
    """A plan and the texts of its files."""

    result: PlanResult
    setup: MeasuringSetup
    doc: dict[str, Any]
    csv_text: str
    png: bytes


def robot_for_plan(spec: RobotSpec, measured: Sequence[str] | None) -> RobotSpec:
    """``spec`` restricted to the ``measured`` links (a URDF), or checked to have them as frames.

    Raises:
        ConfigurationError: A URDF without ``measured`` links, or a name that is not a frame.
    """
    from cpc2urdf.urdf.robot import UrdfRobot

    if isinstance(spec, UrdfRobot):
        if not measured:
            raise ConfigurationError(
                f"{spec.source}: a URDF robot needs the measured links (--measure LINK, e.g. the link of a calibration plate)"
            )
        return spec.restricted(measured)
    if measured:
        unknown = [m for m in measured if m not in spec.structure.frame_names]
        if unknown:
            raise ConfigurationError(
                f"--measure {unknown[0]!r} is not a frame of robot {spec.structure.name!r} "
                f"({list(spec.structure.frame_names)})"
            )
    return spec


def plan_robot(
    spec: RobotSpec,
    *,
    robot_ref: str,
    measured: Sequence[str] | None = None,
    rig: StereoRig | None = None,
    sigma_t: float = DEFAULT_SIGMA_T,
    sigma_r: float = DEFAULT_SIGMA_R,
    ranges: Mapping[str, tuple[float, float]] | None = None,
    n: int | None = None,
    target_error: float | None = None,
    one_joint: bool = False,
    task_region: str | ArrayLike = "calibration",
    n_task: int = DEFAULT_TASK,
    n_candidates: int = DEFAULT_CANDIDATES,
    grid: bool = False,
    seed: int = 0,
    curve_ns: Sequence[int] | None = None,
    noise: str = "fig10",
    pixel_sigma: float = DEFAULT_PIXEL_SIGMA,
    markers: int = 0,
    marker_sigma: float = DEFAULT_MARKER_SIGMA,
    marker_seed: int = 0,
) -> PlanOutputs:
    """Plan an experiment for a robot and render its files (nothing written).

    Args:
        spec: The robot (needs nominal geometry).
        robot_ref: How the plan file names the robot.
        measured: Measured frames (a URDF's links; default: the spec's plates).
        rig: The stereo rig (default: the paper's, :meth:`StereoRig.verged`).
        sigma_t: Fig. 10 translation noise per entry [m].
        sigma_r: Fig. 10 rotation noise angle [rad].
        ranges: Calibration ranges ``{joint: (lo, hi)}`` [m]/[rad] overriding the spec's.
        n: Configurations to plan (or ``target_error``).
        target_error: RMS position error to reach over the task region [m].
        one_joint: Keep the one-joint-at-a-time structure.
        task_region: ``"calibration"``, ``"limits"`` or task configurations (K, n) [m]/[rad].
        n_task: Task configurations drawn for ``"calibration"``/``"limits"``.
        n_candidates: Candidate set size.
        grid: Grid candidates instead of random ones.
        seed: Seed of the candidates.
        curve_ns: Plan sizes of the curve (default: :func:`make_plan`'s).
        noise: ``"fig10"`` (pose noise ``sigma_t``/``sigma_r``) or ``"stereo"`` (pixel noise).
        pixel_sigma: Stereo pixel noise per coordinate [px].
        markers: Markers per measured frame (position-only data; 0: plate poses).
        marker_sigma: Marker point noise per coordinate [m].
        marker_seed: Seed of the markers' placement (``simulate --markers K --seed marker_seed``).

    Raises:
        Cpc2UrdfError: Bad input (named).
    """
    from cpc2urdf.urdf.robot import UrdfRobot

    is_urdf = isinstance(spec, UrdfRobot)
    spec = robot_for_plan(spec, measured)
    nominal = spec.nominal_model()
    frames = (
        list(measured)
        if measured and not is_urdf
        else [f.name for f in nominal.structure.frames if f.kind == "plate"]
    )
    setup = measuring_setup(
        nominal,
        rig=rig,
        sigma_t=sigma_t,
        sigma_r=sigma_r,
        ranges=ranges,
        frames=frames or None,
        noise=noise,
        pixel_sigma=pixel_sigma,
        markers=markers,
        marker_sigma=marker_sigma,
        marker_seed=marker_seed,
    )
    if isinstance(task_region, str):
        q_task = task_configurations(setup, task_region, n=n_task)
        task_doc: dict[str, Any] = {"kind": task_region, "n": int(len(q_task))}
    else:
        q_task = task_configurations(setup, task_region)
        task_doc = {"kind": "configurations", "n": int(len(q_task))}
    result = make_plan(
        setup,
        n=n,
        target_error=target_error,
        q_task=q_task,
        one_joint=one_joint,
        n_candidates=n_candidates,
        seed=seed,
        grid=grid,
        curve_ns=curve_ns,
    )
    assert result.candidates is not None
    cand_doc = {
        "kind": "one-joint" if one_joint else ("grid" if grid else "random"),
        "n": int(len(result.candidates.q)),
        "dropped_unmeasurable": result.candidates.dropped,
        "seed": seed,
    }
    doc = plan_to_json(result, setup, robot=robot_ref, task_region=task_doc, candidates=cand_doc)
    # The CSV goes to the robot: a URDF robot's joints by the URDF's names (its /joint_states names).
    columns = {c: u for u, c in urdf_joint_columns(nominal).items()}
    csv_text = joints_csv_text(nominal.structure, result.q, result.labels, columns)
    png = curve_png(
        result.curve, f"{nominal.structure.name}: predicted held-out error vs N", result
    )
    return PlanOutputs(result, setup, doc, csv_text, png)


def joints_csv_text(
    structure: RobotStructure,
    q: ArrayLike,
    labels: Sequence[str],
    columns: Mapping[str, str] | None = None,
) -> str:
    """A ``joints.csv`` (records ``0000``, ``0001``, ...; lengths in mm, angles in deg; ``columns``:
    joint name -> column name, e.g. a URDF's joint names)."""
    qq = np.atleast_2d(np.asarray(q, dtype=float))
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    col = columns or {}
    w.writerow(
        ["record", "label"]
        + [
            f"{col.get(j.name, j.name)}[{'mm' if j.type == 'prismatic' else 'deg'}]"
            for j in structure.joints
        ]
    )
    scale = [
        LENGTH_UNITS["mm"] if j.type == "prismatic" else ANGLE_UNITS["deg"]
        for j in structure.joints
    ]
    for i, (lab, row) in enumerate(zip(labels, qq, strict=True)):
        w.writerow(
            [f"{i:04d}", lab]
            + [repr(round(float(v / s), 9)) for v, s in zip(row, scale, strict=True)]
        )
    return buf.getvalue()


def curve_png(curve: Sequence[CurvePoint], title: str, result: PlanResult | None = None) -> bytes:
    """The plot of predicted RMS position error [mm] vs N, one line per strategy, as PNG bytes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for strategy, style in (("I-optimal", "o-"), ("D-optimal", "s--"), ("protocol", "^:")):
        pts = sorted(
            (c.n, c.position_rms * 1e3)
            for c in curve
            if c.strategy == strategy and math.isfinite(c.position_rms)
        )
        if pts:
            ax.plot(
                [p[0] for p in pts],
                [p[1] for p in pts],
                style,
                label=strategy
                if strategy != "protocol"
                else "paper's protocol (one joint at a time)",
            )
    if result is not None and math.isfinite(result.prediction.position_rms):
        ax.plot(
            [len(result.q)], [result.prediction.position_rms * 1e3], "k*", ms=12, label="this plan"
        )
    if result is not None and result.target_error is not None:
        ax.axhline(result.target_error * 1e3, color="k", lw=1, ls="--", label="target")
    ax.set_xlabel("configurations measured N")
    ax.set_ylabel("predicted RMS position error [mm]")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return buf.getvalue()


def output_paths(plan_path: str | os.PathLike[str]) -> tuple[Path, Path, Path]:
    """``plan.json`` -> (``plan.json``, ``plan.csv``, ``plan.png``), each checked writable.

    Raises:
        OutputError: A path is a folder or its folder does not exist; the plan path ends in .csv/.png.
    """
    p = Path(plan_path)
    if p.name in ("", ".", "..") or p.is_dir():
        raise OutputError(
            f"{p}: a folder; the plan needs a file name (PLAN.json, with PLAN.csv and PLAN.png next to it)"
        )
    if p.suffix.lower() in (".csv", ".png"):
        raise OutputError(
            f"{p}: the plan file needs another name than its .csv and .png companions"
        )
    paths = (p, p.with_suffix(".csv"), p.with_suffix(".png"))
    for q in paths:
        check_output_path(q)
    return paths


def write_plan_outputs(
    out: PlanOutputs, plan_path: str | os.PathLike[str]
) -> tuple[Path, Path, Path]:
    """Write ``plan.json``, ``plan.csv`` and ``plan.png``, all or nothing
    (:func:`~cpc2urdf.files.jsonio.write_all_atomic`)."""
    json_path, csv_path, png_path = output_paths(plan_path)
    try:
        text = dumps(out.doc)
    except ValueError as e:
        raise OutputError(f"{json_path}: refusing to write non-finite numbers ({e})") from e
    write_all_atomic({json_path: text, csv_path: out.csv_text, png_path: out.png})
    return json_path, csv_path, png_path


__all__ = [
    "PlanOutputs",
    "curve_png",
    "joints_csv_text",
    "output_paths",
    "plan_robot",
    "robot_for_plan",
    "write_plan_outputs",
]
