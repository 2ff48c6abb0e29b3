"""Gaze control: joint values that point both cameras' optical axes at a 3D target.

A target ``p_world`` [m] is *fixated* when the optical (z) axis of each camera frame passes
through it, in front of the camera. The solver works on the Pinocchio model of a URDF (nominal
or calibrated head alike): it never assumes orthogonal axes or cameras on their axes.

    from cpc2urdf.validation.gaze import GazeSolver, solver_for
    sol = solver_for("iis_head").solve([-0.6, -0.6, 0.7])

Method (one :meth:`GazeSolver.solve` call):

1. **Initial guess** (:mod:`.guess`). The table (prismatic joints shared by both cameras) stays
   at its reading. Neck (revolute joints shared by both cameras) from a grid computed once from
   the model: the entry whose cyclopean ray (midpoint of the camera centres, along the sum of the
   optical axes) best faces the target, refined to first order in pan and tilt (2 x 2 normal
   equations on precomputed ray derivatives; cyclopean policy on a redundant head only); the eyes
   converge symmetrically by ``asin(baseline / 2 / distance)``.
   ``min-motion`` and ``eyes-only`` start from ``q_current``; :meth:`GazeSolver.track` from the
   previous solution.
2. **Task-priority Gauss-Newton with joint limits as constraints** (:mod:`.gauss_newton`).
   Priority 1 is fixation (:mod:`.fixation`): per eye the residual ``u - e_z`` with ``u`` the
   unit target direction in the camera frame (zero only when the camera looks *at*, not away
   from, the target; its norm is ``2 sin(err/2)``). Its Jacobian comes from Pinocchio's LOCAL
   frame Jacobians: ``dp_cam = -v - w x p_cam`` (computed only for configurations a step starts
   from). Steps are Levenberg-Marquardt damped with ``mu = |r|^2`` and halved while they
   increase the residual. Priority 2, the redundancy policy (:mod:`.policies`), moves only in
   the null space of priority 1. Joint limits: a joint that a step would push past its limit is
   first kept still by trading its motion for null-space motion; if fixation itself needs it
   beyond, it is held at the limit (active set) and the step is re-solved over the others; it is
   released when the gradient pulls it back inside.
3. **Fixation alone.** If that does not fixate (the policy held a weak direction fixation
   needed, or a limit blocked the preferred configuration), the same iteration runs on priority 1
   alone, with a watchdog that accepts a long step followed by one correction when the pair
   lowers the residual. If it ends in a local minimum, up to :data:`RETRIES` further starts with
   the eyes already turned are tried, and the best result is kept (:mod:`.solver`).
4. **Answer** (:mod:`.result`). ``reachable`` is True when both eyes point at the target to
   within :data:`cpc2urdf.tolerances.GAZE_POINTING_TOL` (which implies in front of the cameras),
   inside the limits. Otherwise the readings are the best in-limit configuration found (least
   sum of the squared residuals of the two eyes), with the residuals, and ``status`` says why.
   Every finite target gets an answer: a target within :data:`MIN_TARGET_DISTANCE` of a camera
   centre has no direction for that eye (missed by pi, ``too_close``), and one farther than
   :data:`FAR_TARGET` is solved for by its direction and judged on itself.

Redundancy policies (the secondary task, :mod:`.policies`): ``"cyclopean"`` (default, zero
version), ``"min-motion"``, ``"eyes-only"`` and ``"use-table"``.

On a head whose two eyes turn about one common axis (the IIS-head), the nominal model fixates a
target with one degree of freedom to spare (pan vs version). A calibrated model whose eyes do not
sweep exactly the same plane has none: binocular fixation with the table fixed is then a square
problem with isolated solutions (or none), and the policy only chooses the starting point. The
solver reports that honestly through ``reachable``/``status`` instead of clamping.

Modules: :mod:`.head` (camera frames and joint classes on a
:class:`~cpc2urdf.urdf.pinocchio.PinocchioRobot`), :mod:`.fixation`, :mod:`.guess`,
:mod:`.policies`, :mod:`.gauss_newton`, :mod:`.result`, :mod:`.tracking`, :mod:`.solver`; the
compiled solver for any head: :mod:`.chain`, :mod:`.kernels`, :mod:`.batch`; :mod:`.reach` (where a
head can fixate) and :mod:`.head_report` (the head's kind and disparity, reported once).

Frames: ``T_world_x`` is the pose of ``x`` in ``world``; points carry their frame (``p_world``).
"""

from __future__ import annotations

from cpc2urdf.validation.gaze.batch import BATCH_STATUSES, CompiledGaze, GazeBatch
from cpc2urdf.validation.gaze.chain import Coupling, HeadChain, build_chain
from cpc2urdf.validation.gaze.fixation import (
    MIN_TARGET_DISTANCE,
    NULL_EIGENVALUE,
    FixationState,
    target_point,
)
from cpc2urdf.validation.gaze.gauss_newton import (
    BACKTRACKS,
    CONVERGED_RESIDUAL,
    CONVERGED_STEP,
    FLOOR_RESIDUAL,
    MAX_ITERATIONS,
    MAX_STEP,
    PHASE2_DAMPING,
    STALL_RESIDUAL,
)
from cpc2urdf.validation.gaze.guess import GUESS_MAX_CORRECTION
from cpc2urdf.validation.gaze.head import DEFAULT_CAMERAS, GazeHead
from cpc2urdf.validation.gaze.policies import (
    DEFAULT_VIEWING_DISTANCE,
    POLICIES,
    TABLE_TIE_WEIGHT,
)
from cpc2urdf.validation.gaze.reach import Region, make_grid, reachable_region
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
from cpc2urdf.validation.gaze.solver import FAR_TARGET, RETRIES, GazeSolver, solver_for
from cpc2urdf.validation.gaze.tracking import (
    GazeTracker,
    SaccadeRule,
    TrackingStep,
    Trajectory,
    minimum_jerk,
)

__all__ = [
    "BACKTRACKS",
    "BATCH_STATUSES",
    "CONVERGED_RESIDUAL",
    "CONVERGED_STEP",
    "DEFAULT_CAMERAS",
    "DEFAULT_VIEWING_DISTANCE",
    "FAR_TARGET",
    "FLOOR_RESIDUAL",
    "GUESS_MAX_CORRECTION",
    "MAX_ITERATIONS",
    "MAX_STEP",
    "MIN_TARGET_DISTANCE",
    "NULL_EIGENVALUE",
    "PHASE2_DAMPING",
    "POLICIES",
    "RETRIES",
    "STALL_RESIDUAL",
    "STATUSES",
    "STATUS_BEHIND",
    "STATUS_DISPARITY",
    "STATUS_FIXATED",
    "STATUS_LIMITS",
    "STATUS_NO_SOLUTION",
    "STATUS_TOO_CLOSE",
    "TABLE_TIE_WEIGHT",
    "CompiledGaze",
    "Coupling",
    "FixationState",
    "GazeBatch",
    "GazeHead",
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
    "reachable_region",
    "solver_for",
    "target_point",
]
