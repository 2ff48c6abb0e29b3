"""cpc2urdf: calibrate active robot heads and turn the result into a URDF you can trust.

``import cpc2urdf`` gives the pipeline's verbs (:mod:`cpc2urdf.api`, the functions every command
calls) and the model type; result types stay in their subpackages. Each verb imports its stage when
called, so ``cpc2urdf.identify`` loads no Pinocchio, OpenCV, meshcat or numba.

Conventions: SI units inside (m, rad); ``T_a_b`` is the pose of frame b in frame a (maps
b-coordinates to a-coordinates, Pinocchio's ``aMb``); points carry their frame (``p_world``);
camera optical frames follow REP-103 (z forward, x right, y down). ``docs/architecture.md`` maps
the subpackages.
"""

from __future__ import annotations

from cpc2urdf.api import (
    accuracy,
    calibrate_cameras,
    calibrate_head,
    calibration_report,
    check_urdf,
    export_urdf,
    gaze_solver,
    identify,
    load_marker_csv,
    load_measurements,
    load_model,
    load_robot,
    measurements_from_bag,
    plan_experiment,
    reachable_region,
    save_model,
    simulate,
    solve_handeye,
    write_view,
)
from cpc2urdf.errors import Cpc2UrdfError
from cpc2urdf.model import CPCModel
from cpc2urdf.version import __version__

__all__ = [
    "CPCModel",
    "Cpc2UrdfError",
    "__version__",
    "accuracy",
    "calibrate_cameras",
    "calibrate_head",
    "calibration_report",
    "check_urdf",
    "export_urdf",
    "gaze_solver",
    "identify",
    "load_marker_csv",
    "load_measurements",
    "load_model",
    "load_robot",
    "measurements_from_bag",
    "plan_experiment",
    "reachable_region",
    "save_model",
    "simulate",
    "solve_handeye",
    "write_view",
]
