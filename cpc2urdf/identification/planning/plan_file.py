"""The plan file ``cpc2urdf/plan@1``: the configurations to measure and what they are predicted to give.

Written by ``cpc2urdf plan`` next to a ``joints.csv`` of the same configurations (the layout
:func:`~cpc2urdf.identification.vision.joints_csv.read_joints_csv` reads) and read back by
:func:`load_plan`. Joint values and ``T_world_base`` are in the file's ``units`` (``mm`` and ``deg``
by default), the rig in SI like every rig file (:meth:`StereoRig.to_json`), and the accuracy fields
(``prediction``, ``target_error_mm``, ``curve``) in mm / deg, as their names say::

    {
      "format": "cpc2urdf/plan@1",
      "robot": "iis_head",
      "units": {"length": "mm", "angle": "deg"},
      "joints": [{"name": "table_x", "type": "prismatic", "unit": "mm"}, ...],   # + "urdf_joint" for a URDF
      "measured_frames": ["plate_left", "plate_right"],
      "strategy": "I-optimal",
      "one_joint": false,
      "configurations": [{"label": "candidate 17", "q": [512.3, 240.0, 95.2, 28.1, 40.0, 47.5]}, ...],
      "setup": {"noise": {"model": "fig10", "sigma_t_mm": 0.5, "sigma_r_deg": 0.5},
                "rig": {...}, "T_world_base": [[...], [...], [...], [0, 0, 0, 1]]},
      "task_region": {"kind": "calibration", "n": 200},
      "candidates": {"kind": "random", "n": 971, "dropped_unmeasurable": 29, "seed": 0},
      "prediction": {"position_rms_mm": 0.30, "orientation_rms_deg": 0.14, "rank": 32, ...},
      "target_error_mm": null,
      "curve": [{"strategy": "I-optimal", "n": 13, "position_rms_mm": 0.37, "orientation_rms_deg": 0.17}, ...]
    }

For a URDF robot, each joint also carries its ``urdf_joint`` name and a ``urdf`` section names the
file and the measured links; ``name`` is the model's joint name, and the CSV's columns are the
URDF's names (what the robot's ``/joint_states`` calls its joints).
``T_world_base`` (translation in the file's length unit) is where the plan assumes the robot
stands in the rig's world; the configurations were checked visible from there.
A plan made for stereo pixel noise states ``{"model": "stereo", "pixel_sigma_px": 0.15,
"sigma_t_mm": 0.5, "sigma_r_deg": 0.5}``: the pixel noise, and the pose sigmas the identification
weights such data with (its prediction is that weighting's, docs/planning.md); a file without
``model`` is ``fig10``.
A plan for a marker setup (``cpc2urdf plan --markers K``) adds ``setup.markers``: ``{"per_frame": K,
"sigma_p_mm": 0.1, "seed": S, "positions": {"plate_left_m0": {"frame": "plate_left", "position_mm":
[...]}, ...}}``, the markers ``cpc2urdf simulate --plan PLAN.json --markers K --seed S`` places
(the positions are informative: they follow from K, the seed and the frames).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cpc2urdf.errors import InputFileError
from cpc2urdf.files.jsonio import finite_float, float_list, read_json, require_format
from cpc2urdf.files.units import Units
from cpc2urdf.identification.planning.information import StereoPoseMeasurement
from cpc2urdf.identification.planning.marker_setup import MarkerMeasurement
from cpc2urdf.identification.planning.measuring import SETUP_NOISE_MODELS, MeasuringSetup
from cpc2urdf.identification.planning.plan_selection import PlanResult
from cpc2urdf.identification.simulation.measure_poses import DEFAULT_PIXEL_SIGMA
from cpc2urdf.identification.vision.stereo import StereoRig
from cpc2urdf.model import CPCModel, RobotStructure
from cpc2urdf.urdf.robot import urdf_source

Array = NDArray[np.float64]

PLAN_FORMAT = "cpc2urdf/plan@1"
SELFCAL_NOISE_MODEL = "pixels"  # a one-stage plan's (planning/selfcal_plan_file.py)


def joints_json(model: CPCModel, u: Units) -> list[dict[str, Any]]:
    """A plan file's ``joints``: name, type, unit and the URDF's own name when it has one."""
    src = urdf_source(model)
    return [
        {
            "name": j.name,
            "type": j.type,
            "unit": u.length_name if j.type == "prismatic" else u.angle_name,
            **(
                {"urdf_joint": src.joints[j.name]}
                if src is not None and j.name in src.joints
                else {}
            ),
        }
        for j in model.structure.joints
    ]


def plan_to_json(
    result: PlanResult,
    setup: MeasuringSetup,
    *,
    robot: str,
    task_region: dict[str, Any],
    candidates: dict[str, Any],
    units: Units | None = None,
) -> dict[str, Any]:
    """The plan file's content (SI inside, ``units`` in the file; default mm / deg).

    ``units`` applies to the joints, the configurations and ``T_world_base``; the accuracy
    fields (``prediction``, ``target_error_mm``, ``curve``) say their unit in their names and are
    always mm / deg.
    """
    from cpc2urdf.urdf.robot import urdf_source

    u = units or Units("mm", "deg")
    s = setup.nominal.structure
    src = urdf_source(setup.nominal)  # a URDF robot: its own joint and link names, for the user
    scale = np.array([u.joint_scale(j.type) for j in s.joints])
    T = setup.nominal.T_world_base().copy()
    T[:3, 3] /= u.length

    def mm(
        v: float,
    ) -> float | None:  # the curve, like the prediction, is in mm / deg whatever the units
        return v * 1e3 if math.isfinite(v) else None

    def deg(v: float) -> float | None:
        return math.degrees(v) if math.isfinite(v) else None

    return {
        "format": PLAN_FORMAT,
        "robot": robot,
        "units": u.to_json(),
        "joints": joints_json(setup.nominal, u),
        "measured_frames": list(setup.frames),
        **(
            {
                "urdf": {
                    "path": src.path,
                    "measured_links": [src.frames.get(f, f) for f in setup.frames],
                }
            }
            if src is not None
            else {}
        ),
        "strategy": result.strategy,
        "one_joint": result.one_joint,
        "configurations": [
            {"label": lab, "q": [float(v) for v in q / scale]}
            for lab, q in zip(result.labels, result.q, strict=True)
        ],
        "setup": {
            "noise": _noise_doc(setup),
            **({"markers": _markers_doc(setup)} if setup.markers else {}),
            "rig": setup.rig.to_json(),
            "T_world_base": T.tolist(),
            "ranges": {
                j.name: [float(v) for v in setup.ranges[i] / scale[i]]
                for i, j in enumerate(s.joints)
            },
        },
        "task_region": task_region,
        "candidates": candidates,
        "prediction": result.prediction.to_json(),
        "target_error_mm": None if result.target_error is None else result.target_error * 1e3,
        "curve": [
            {
                "strategy": c.strategy,
                "n": c.n,
                "position_rms_mm": mm(c.position_rms),
                "orientation_rms_deg": deg(c.orientation_rms),
            }
            for c in result.curve
        ],
    }


def _markers_doc(setup: MeasuringSetup) -> dict[str, Any]:
    m = setup.measurement()
    assert isinstance(m, MarkerMeasurement)
    return {
        "per_frame": setup.markers,
        "sigma_p_mm": setup.marker_sigma * 1e3,
        "seed": setup.marker_seed,
        "positions": {
            name: {"frame": f, "position_mm": [float(v) * 1e3 for v in p]}
            for name, (f, p) in m.markers.items()
        },
    }


def _noise_doc(setup: MeasuringSetup) -> dict[str, Any]:
    m = setup.measurement()
    if isinstance(m, StereoPoseMeasurement):  # the pose sigmas are the identification's weights
        return {
            "model": "stereo",
            "pixel_sigma_px": setup.pixel_sigma,
            "sigma_t_mm": m.sigma_t * 1e3,
            "sigma_r_deg": math.degrees(m.sigma_r),
        }
    return {
        "model": "fig10",
        "sigma_t_mm": setup.sigma_t * 1e3,
        "sigma_r_deg": math.degrees(setup.sigma_r),
    }


@dataclass
class LoadedPlan:
    """What :func:`load_plan` returns (SI units).

    Attributes:
        q: Configurations [m]/[rad], shape (N, n), in ``joint_names`` order (the structure's
            order when one was given).
        labels: One per configuration.
        joint_names: Joint names of the columns of ``q``.
        robot: The robot reference the plan was made for.
        measured_frames: The frames the plan measures.
        T_world_base: Where the plan assumes the robot stands in the rig's world, shape (4, 4) [m].
        rig: The rig the plan was checked with.
        sigma_t: Translation noise the prediction assumed [m].
        sigma_r: Rotation noise angle the prediction assumed [rad].
        one_joint: Whether the plan keeps the one-joint-at-a-time structure.
        prediction: The file's ``prediction`` section (mm / deg).
        noise: The noise model the plan was made for, ``"fig10"`` or ``"stereo"``.
        pixel_sigma: Stereo pixel noise per coordinate [px] (``"stereo"``).
        markers: Markers per measured frame the plan was made for (0: plate poses).
        marker_sigma: Their point noise per coordinate [m].
        marker_seed: The seed that placed them (``simulate --markers K --seed marker_seed``).
        ranges: The calibration ranges the plan drew from, ``{joint: (lo, hi)}`` [m]/[rad] (a
            joint held still has ``lo == hi``), or None in a plan file without them.
    """

    q: Array
    labels: list[str]
    joint_names: tuple[str, ...]
    robot: str
    measured_frames: tuple[str, ...]
    T_world_base: Array
    rig: StereoRig
    sigma_t: float
    sigma_r: float
    one_joint: bool
    prediction: dict[str, Any]
    noise: str = "fig10"
    pixel_sigma: float = DEFAULT_PIXEL_SIGMA
    markers: int = 0
    marker_sigma: float = 0.0
    marker_seed: int = 0
    ranges: dict[str, tuple[float, float]] | None = None


def load_plan(path: str | os.PathLike[str], structure: RobotStructure | None = None) -> LoadedPlan:
    """Read a ``cpc2urdf/plan@1`` file.

    Args:
        path: The plan file.
        structure: If given, the plan's joints must be exactly this robot's (any order); ``q`` is
            returned in the structure's joint order.

    Raises:
        InputFileError: Naming the file and the field: wrong format, missing or non-finite
            values, a configuration with the wrong number of values, a joint the robot does not
            have (or lacks), a reading outside the joint's limits.
    """
    p = Path(path)
    doc = require_format(read_json(p), PLAN_FORMAT, p)
    try:
        return _parse(doc, p, structure)
    except ValueError as e:
        raise InputFileError(p, str(e)) from None


def parse_configurations(
    doc: Any, structure: RobotStructure | None
) -> tuple[Array, list[str], list[str], Units, dict[str, float]]:
    """A plan document's configurations: ``q`` [m]/[rad] (in the structure's joint order when
    given, checked within its limits), labels, joint names, the file's units and each joint's
    scale (file unit -> SI) by name.

    Raises:
        ValueError: Naming the field (the caller adds the file).
    """
    u = Units.from_json(doc.get("units"))
    joints = doc.get("joints")
    if not isinstance(joints, list) or not joints:
        raise ValueError("joints must be a non-empty list of {name, type, unit}")
    names, scale = [], []
    for i, j in enumerate(joints):
        if (
            not isinstance(j, dict)
            or not isinstance(j.get("name"), str)
            or j.get("type") not in ("revolute", "prismatic")
        ):
            raise ValueError(
                f'joints[{i}] must be {{"name": ..., "type": "revolute" or "prismatic"}}'
            )
        names.append(j["name"])
        scale.append(u.joint_scale(j["type"]))
    if len(set(names)) != len(names):
        raise ValueError(f"joints names a joint twice: {names}")
    configs = doc.get("configurations")
    if not isinstance(configs, list) or not configs:
        raise ValueError("configurations must be a non-empty list of {label, q}")
    q = np.zeros((len(configs), len(names)))
    labels = []
    for k, c in enumerate(configs):
        if not isinstance(c, dict):
            raise ValueError(f"configurations[{k}] must be an object {{label, q}}")
        labels.append(str(c.get("label", f"plan {k}")))
        q[k] = np.array(float_list(c.get("q"), len(names), f"configurations[{k}].q")) * scale
    if structure is not None:
        missing = [n for n in structure.joint_names if n not in names]
        extra = [n for n in names if n not in structure.joint_names]
        if missing or extra:
            raise ValueError(
                f"joints {names} do not match robot {structure.name!r}'s "
                f"{list(structure.joint_names)} (missing {missing}, unknown {extra})"
            )
        q = q[:, [names.index(n) for n in structure.joint_names]]
        names = list(structure.joint_names)
        for i, j in enumerate(structure.joints):
            bad = np.flatnonzero((q[:, i] < j.lower - 1e-9) | (q[:, i] > j.upper + 1e-9))
            if bad.size:
                k, sc = int(bad[0]), u.joint_scale(j.type)
                unit = u.length_name if j.type == "prismatic" else u.angle_name
                raise ValueError(
                    f"configurations[{k}].q: joint {j.name!r} reads {q[k, i] / sc:g} {unit}, "
                    f"outside its limits [{j.lower / sc:g}, {j.upper / sc:g}] {unit}"
                )
    return q, labels, names, u, dict(zip([j["name"] for j in joints], scale, strict=True))


def _parse(doc: Any, p: Path, structure: RobotStructure | None) -> LoadedPlan:
    q, labels, names, u, factor = parse_configurations(doc, structure)
    setup = doc.get("setup")
    if not isinstance(setup, dict):
        raise ValueError("setup must be an object with noise, rig and T_world_base")
    noise = setup.get("noise")
    if not isinstance(noise, dict):
        raise ValueError("setup.noise must be an object {model, sigma_t_mm, sigma_r_deg}")
    model = noise.get("model", "fig10")
    if model == SELFCAL_NOISE_MODEL:
        raise ValueError(
            "a one-stage plan (head cameras seeing a board, `cpc2urdf plan --cameras`), not a "
            "stage-1 one: its configurations are in its .csv"
        )
    if model not in SETUP_NOISE_MODELS:
        raise ValueError(
            f"setup.noise.model must be one of {list(SETUP_NOISE_MODELS)}, got {model!r}"
        )
    sigma_t = finite_float(noise.get("sigma_t_mm"), "setup.noise.sigma_t_mm") * 1e-3
    sigma_r = math.radians(finite_float(noise.get("sigma_r_deg"), "setup.noise.sigma_r_deg"))
    if sigma_t <= 0 or sigma_r <= 0:
        raise ValueError("setup.noise sigmas must be > 0")
    pixel_sigma = DEFAULT_PIXEL_SIGMA
    if model == "stereo":
        pixel_sigma = finite_float(noise.get("pixel_sigma_px"), "setup.noise.pixel_sigma_px")
        if pixel_sigma <= 0:
            raise ValueError("setup.noise.pixel_sigma_px must be > 0")
    markers, marker_sigma, marker_seed = 0, 0.0, 0
    mk = setup.get("markers")
    if mk is not None:
        if not isinstance(mk, dict):
            raise ValueError("setup.markers must be an object {per_frame, sigma_p_mm, seed}")
        k_doc, seed_doc = mk.get("per_frame"), mk.get("seed")
        if not isinstance(k_doc, int) or isinstance(k_doc, bool) or k_doc < 1:
            raise ValueError(f"setup.markers.per_frame must be an integer >= 1, got {k_doc!r}")
        if not isinstance(seed_doc, int) or isinstance(seed_doc, bool) or seed_doc < 0:
            raise ValueError(f"setup.markers.seed must be an integer >= 0, got {seed_doc!r}")
        marker_sigma = finite_float(mk.get("sigma_p_mm"), "setup.markers.sigma_p_mm") * 1e-3
        if marker_sigma <= 0:
            raise ValueError("setup.markers.sigma_p_mm must be > 0")
        markers, marker_seed = k_doc, seed_doc
    rig_doc = setup.get("rig")
    if not isinstance(rig_doc, dict):
        raise ValueError("setup.rig must be an object with K1, D1, K2, D2, R, T, image_size")
    rig = StereoRig.from_json(rig_doc, "setup.rig")
    rows = setup.get("T_world_base")
    if not isinstance(rows, list) or len(rows) != 4:
        raise ValueError("setup.T_world_base must be 4 rows of 4 numbers")
    T = np.array([float_list(r, 4, f"setup.T_world_base[{i}]") for i, r in enumerate(rows)])
    T[:3, 3] *= u.length
    R = T[:3, :3]
    if (
        np.abs(R.T @ R - np.eye(3)).max() > 1e-6
        or np.linalg.det(R) <= 0
        or np.abs(T[3] - [0, 0, 0, 1]).max() > 1e-12
    ):
        raise ValueError("setup.T_world_base is not a rigid transform")
    frames = doc.get("measured_frames")
    if not isinstance(frames, list) or not frames or not all(isinstance(f, str) for f in frames):
        raise ValueError("measured_frames must be a non-empty list of frame names")
    if structure is not None:
        unknown = [f for f in frames if f not in structure.frame_names]
        if unknown:
            raise ValueError(
                f"measured_frames {unknown} are not frames of robot {structure.name!r}"
            )
    robot = doc.get("robot")
    if not isinstance(robot, str) or not robot:
        raise ValueError("robot must be the robot reference the plan was made for")
    pred = doc.get("prediction")
    ranges = None
    if setup.get("ranges") is not None:
        doc_ranges = setup["ranges"]
        if not isinstance(doc_ranges, dict) or set(doc_ranges) != set(names):
            raise ValueError(f"setup.ranges must be {{joint: [lo, hi]}} for the joints {names}")
        ranges = {}
        for n, r in doc_ranges.items():
            lo, hi = float_list(r, 2, f"setup.ranges.{n}")
            if lo > hi:
                raise ValueError(f"setup.ranges.{n}: lower {lo:g} > upper {hi:g}")
            ranges[n] = (lo * factor[n], hi * factor[n])
    return LoadedPlan(
        q,
        labels,
        tuple(names),
        robot,
        tuple(frames),
        T,
        rig,
        sigma_t,
        sigma_r,
        bool(doc.get("one_joint", False)),
        pred if isinstance(pred, dict) else {},
        str(model),
        pixel_sigma,
        markers,
        marker_sigma,
        marker_seed,
        ranges,
    )


__all__ = [
    "PLAN_FORMAT",
    "SELFCAL_NOISE_MODEL",
    "LoadedPlan",
    "load_plan",
    "parse_configurations",
    "plan_to_json",
]
