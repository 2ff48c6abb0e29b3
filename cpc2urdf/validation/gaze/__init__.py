"""Gaze control: joint values that point a head's cameras' optical axes at a 3D target.

A target ``p_world`` [m] is *fixated* when the optical (z) axis of each solved camera passes
through it, in front of the camera. The solver works on the Pinocchio model of a URDF (nominal
or calibrated head alike): it never assumes orthogonal axes or cameras on their axes.

    from cpc2urdf.validation.gaze import GazeOptions, solver_for
    solver = solver_for("iis_head", options=GazeOptions(focal_px=500.0))
    sol = solver.solve([-0.6, -0.6, 0.7])

One engine answers every head shape and policy: the head flattened to arrays (:mod:`.chain`),
a compiled task-priority Gauss-Newton loop (:mod:`.kernels`: pointing first, the policy's
posture in its null space, joint limits as an active set) and its starts and batches
(:mod:`.batch`). :mod:`.solver` holds :class:`GazeSolver`, one compiled solver per policy
(:mod:`.options`: ``cyclopean``, ``min-motion``, ``eyes-only``); :mod:`.result` the answer and
its status; :mod:`.tracking` pursuit and saccades; :mod:`.reach` where a head can fixate;
:mod:`.head_report` the head's kind and disparity, reported once.

On a head whose two eyes turn about one common axis (the IIS-head), the nominal model fixates a
target with one degree of freedom to spare (pan vs version). A calibrated model whose eyes do not
sweep exactly the same plane has none: exact fixation then needs a swing along a weak direction;
the default policy keeps the head facing the target and splits the error left between the eyes
(status ``disparity``), ``min-motion`` solves fixation alone.

Frames: ``T_world_x`` is the pose of ``x`` in ``world``; points carry their frame (``p_world``).
"""

from __future__ import annotations

from cpc2urdf.validation.gaze.batch import BATCH_STATUSES, CompiledGaze, GazeBatch
from cpc2urdf.validation.gaze.chain import Coupling, HeadChain, build_chain
from cpc2urdf.validation.gaze.kernels import FAR_TARGET, MIN_TARGET_DISTANCE
from cpc2urdf.validation.gaze.options import (
    DEFAULT_CAMERAS,
    POLICIES,
    GazeOptions,
    pointing_tolerance,
    target_point,
)
from cpc2urdf.validation.gaze.reachable import Region, make_grid, reachable_region
from cpc2urdf.validation.gaze.result import (
    STATUS_BEHIND,
    STATUS_DISPARITY,
    STATUS_FIXATED,
    STATUS_LIMITS,
    STATUS_NO_SOLUTION,
    STATUS_TOO_CLOSE,
    STATUSES,
    GazeSolution,
)
from cpc2urdf.validation.gaze.solver import GazeSolver, solver_for
from cpc2urdf.validation.gaze.tracking import (
    GazeTracker,
    SaccadeRule,
    TrackingStep,
    Trajectory,
    minimum_jerk,
)

__all__ = [
    "BATCH_STATUSES",
    "DEFAULT_CAMERAS",
    "FAR_TARGET",
    "MIN_TARGET_DISTANCE",
    "POLICIES",
    "STATUSES",
    "STATUS_BEHIND",
    "STATUS_DISPARITY",
    "STATUS_FIXATED",
    "STATUS_LIMITS",
    "STATUS_NO_SOLUTION",
    "STATUS_TOO_CLOSE",
    "CompiledGaze",
    "Coupling",
    "GazeBatch",
    "GazeOptions",
    "GazeSolution",
    "GazeSolver",
    "GazeTracker",
    "HeadChain",
    "Region",
    "SaccadeRule",
    "TrackingStep",
    "Trajectory",
    "build_chain",
    "make_grid",
    "minimum_jerk",
    "pointing_tolerance",
    "reachable_region",
    "solver_for",
    "target_point",
]
