"""cpc2urdf: calibrate active robot heads and turn the result into a URDF you can trust.

``import cpc2urdf`` gives the whole pipeline (:mod:`cpc2urdf.api`, the functions every command
calls): ``load_measurements``, ``identify``, ``calibrate_cameras``, ``export_urdf``,
``check_urdf``, ``accuracy``, ``gaze_solver``/``fixate``, ``write_view``, ``save_model``.

Conventions: SI units inside (m, rad); ``T_a_b`` is the pose of frame b in frame a (maps
b-coordinates to a-coordinates, Pinocchio's ``aMb``); points carry their frame (``p_world``);
camera optical frames follow REP-103 (z forward, x right, y down). ``docs/architecture.md`` maps
the subpackages: the core (this folder's modules), ``identification`` (kinematics, vision,
hand-eye, simulation), ``validation`` (cross-checks, accuracy, gaze, view), ``studies``, ``cli``.

The API names are loaded on first use, so that importing a core module (``cpc2urdf.model``) does
not pull in Pinocchio, OpenCV and meshcat.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from cpc2urdf.errors import Cpc2UrdfError
from cpc2urdf.model import CPCModel, CPCParams, Frame, Joint, RobotStructure
from cpc2urdf.version import __version__

if TYPE_CHECKING:
    from cpc2urdf.api import (
        DEFAULT_HANDEYE_METHOD,
        DEFAULT_METHOD,
        METHODS,
        BranchAccuracy,
        CalibrationReport,
        Coupling,
        CrossCheckReport,
        GazeSolution,
        GazeSolver,
        HandEyePoses,
        HandEyeResult,
        LoadedPlan,
        MeasurementSet,
        PlanOutputs,
        Region,
        RobotSpec,
        ViewSummary,
        accuracy,
        calibrate_cameras,
        calibration_report,
        check_urdf,
        export_urdf,
        fixate,
        gaze_solver,
        identify,
        load_handeye_poses,
        load_marker_csv,
        load_measurements,
        load_model,
        load_plan,
        load_robot,
        measurements_from_bag,
        plan_experiment,
        reachable_region,
        save_model,
        solve_handeye,
        write_view,
    )

_API = (
    "DEFAULT_HANDEYE_METHOD",
    "DEFAULT_METHOD",
    "METHODS",
    "BranchAccuracy",
    "CalibrationReport",
    "CrossCheckReport",
    "GazeSolution",
    "GazeSolver",
    "HandEyePoses",
    "HandEyeResult",
    "LoadedPlan",
    "MeasurementSet",
    "PlanOutputs",
    "Region",
    "Coupling",
    "RobotSpec",
    "ViewSummary",
    "accuracy",
    "calibrate_cameras",
    "calibration_report",
    "check_urdf",
    "export_urdf",
    "fixate",
    "gaze_solver",
    "plan_experiment",
    "reachable_region",
    "identify",
    "load_handeye_poses",
    "load_marker_csv",
    "load_measurements",
    "load_plan",
    "load_model",
    "load_robot",
    "measurements_from_bag",
    "save_model",
    "solve_handeye",
    "write_view",
)


def __getattr__(name: str) -> Any:
    if name in _API:
        return getattr(importlib.import_module("cpc2urdf.api"), name)
    raise AttributeError(f"module 'cpc2urdf' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *_API})


__all__ = [
    "BranchAccuracy",
    "CalibrationReport",
    "CPCModel",
    "CPCParams",
    "Cpc2UrdfError",
    "CrossCheckReport",
    "DEFAULT_HANDEYE_METHOD",
    "DEFAULT_METHOD",
    "Frame",
    "GazeSolution",
    "GazeSolver",
    "HandEyePoses",
    "HandEyeResult",
    "LoadedPlan",
    "Joint",
    "METHODS",
    "MeasurementSet",
    "PlanOutputs",
    "Region",
    "Coupling",
    "RobotSpec",
    "RobotStructure",
    "ViewSummary",
    "__version__",
    "accuracy",
    "calibrate_cameras",
    "calibration_report",
    "check_urdf",
    "export_urdf",
    "fixate",
    "gaze_solver",
    "plan_experiment",
    "reachable_region",
    "identify",
    "load_handeye_poses",
    "load_marker_csv",
    "load_measurements",
    "load_plan",
    "load_model",
    "load_robot",
    "measurements_from_bag",
    "save_model",
    "solve_handeye",
    "write_view",
]
