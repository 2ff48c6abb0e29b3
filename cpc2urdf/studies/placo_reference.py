"""placo's axis-align task as a second reference for ``cpc2urdf bench gaze``.

placo (Rhoban, ``pip install placo``) is a task-space inverse kinematics on Pinocchio: each
``KinematicsSolver.solve`` is one quadratic program over a joint step, with the joint limits as
constraints. Its ``AxisAlignTask`` keeps an axis of a frame along a direction in the world. A
gaze solve with it, as a user would write one: for every solved camera, the task keeps the
optical axis (z, REP-103) along the unit direction from the camera's centre to the target; that
direction is set again before every step (the task holds it fixed over a step, but the centre
moves with the joints), and steps are taken until every pointing error is within
:data:`~cpc2urdf.tolerances.GAZE_POINTING_TOL` or placo's :data:`FLOOR`, or the largest has not
fallen for :data:`STALL_STEPS` steps, or after :data:`MAX_STEPS`; the answer is the best posture
seen. The time spent in placo's own calls (the QP step and the kinematics) is kept apart from the
Python around them (:attr:`PlacoGaze.core_seconds`).

Two things limit it, both measured (docs/gaze.md):

- **Its error floor.** The task's error is ``acos(a . t)`` (placo's
  ``src/placo/kinematics/axis_align_task.cpp``). Near zero that resolves only ``sqrt(2 eps)``, about
  2.1e-8 rad: true errors up to ~2.5e-8 rad read 0 and the task stops correcting, so an answer
  within 1e-9 rad comes by chance.
- **Where it installs.** placo 0.10.2 requires ``pin==3.8.0`` exactly, and our tests run the
  newest ``pin`` (4.x), so it is not one of our dependencies: the benchmark uses it when it
  imports (a virtual environment of its own: docs/gaze.md), and says "not installed" otherwise.

It states only heads whose unknowns are plain joints and whose solved axes are real frames: not a
coupling or a URDF ``mimic`` (iCub's version/vergence), nor a rigid pair's cyclopean axis.
"""

from __future__ import annotations

import math
import time
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from cpc2urdf.tolerances import GAZE_POINTING_TOL

if TYPE_CHECKING:
    from cpc2urdf.validation.gaze import GazeSolver

Array = NDArray[np.float64]
MAX_STEPS = 100  # placo steps per target at most
STALL_STEPS = 3  # steps without any fall of the largest pointing error that end a solve (held at a bound, or a minimum)
FLOOR = (
    3e-8  # [rad]: the task reads an error under ~2.5e-8 rad as 0 (acos near 1) and stops correcting
)
REGULARIZATION = 1e-9  # weight of placo's regularization task (|dq|^2): keeps the step unique on a redundant head
NOT_INSTALLED = "placo is not installed (placo 0.10.2 requires pin==3.8.0: a virtual environment of its own, see docs/gaze.md)"


def kinematic_urdf(text: str) -> str:
    """URDF text ``text`` without its links' ``<visual>`` and ``<collision>`` elements: placo
    loads every mesh they name and cannot resolve a ``package://`` path outside a ROS workspace;
    the kinematics are untouched."""
    root = ET.fromstring(text)
    for link in root.iter("link"):
        for tag in ("visual", "collision"):
            for element in link.findall(tag):
                link.remove(element)
    return ET.tostring(root, encoding="unicode")


class PlacoGaze:
    """The gaze solve with placo's axis-align task on one head (see the module's docstring).

    Args:
        urdf: The head's URDF text (the model the solver was built from).
        cameras: The frames whose optical axes go through the target (one or two).
        joint_names: The solver's robot joints, in the order of its readings ``q``.
        free: Indices into ``q`` of the joints placo may move; the others keep their reading.
        path: Indices into ``q`` of the joints on the cameras' paths (set from ``q0`` each solve).
    """

    def __init__(
        self,
        urdf: str,
        cameras: Sequence[str],
        joint_names: Sequence[str],
        free: Sequence[int],
        path: Sequence[int],
    ) -> None:
        import placo

        self.robot = placo.RobotWrapper("", placo.Flags.ignore_collisions, kinematic_urdf(urdf))
        self.cameras = tuple(cameras)
        self.joint_names = tuple(joint_names)
        self.path = [(int(i), self.joint_names[i]) for i in path]
        self.free = [(int(i), self.joint_names[i]) for i in free]
        self.solver = placo.KinematicsSolver(self.robot)
        self.solver.mask_fbase(True)
        free_names = {name for _, name in self.free}
        for name in self.robot.joint_names():
            if name not in free_names:
                self.solver.mask_dof(name)
        self.solver.enable_joint_limits(True)
        z = np.array([0.0, 0.0, 1.0])
        self.tasks = []
        for c in self.cameras:
            task = self.solver.add_axisalign_task(c, z, z)
            task.configure(c, "soft", 1.0)
            self.tasks.append(task)
        self.solver.add_regularization_task(REGULARIZATION)
        self.core_seconds = 0.0  # of the last solve: in placo's step and kinematics [s]

    def solve(self, p: Array, q0: Array) -> tuple[Array, int]:
        """Readings that point the cameras at ``p`` (world [m]) from readings ``q0`` (the best
        posture seen: the smallest largest pointing error), and the number of placo steps
        taken. :attr:`core_seconds` is then the time spent in placo's step and kinematics."""
        clock = time.perf_counter
        robot, tasks, cameras, step = self.robot, self.tasks, self.cameras, self.solver.solve
        px, py, pz = (float(x) for x in p)
        for i, name in self.path:
            robot.set_joint(name, float(q0[i]))
        c0 = clock()
        robot.update_kinematics()
        core = clock() - c0
        best, best_q, last, since, steps = math.inf, [0.0] * len(self.free), math.inf, 0, 0
        while True:
            worst = 0.0
            for c, task in zip(cameras, tasks, strict=True):
                # in floats: numpy's cross and norm on 3-vectors cost ~10x placo's own step
                (_, _, zx, ox), (_, _, zy, oy), (_, _, zz, oz) = robot.get_T_world_frame(c)[
                    :3
                ].tolist()
                dx, dy, dz = px - ox, py - oy, pz - oz
                error = math.atan2(
                    math.hypot(zy * dz - zz * dy, zz * dx - zx * dz, zx * dy - zy * dx),
                    zx * dx + zy * dy + zz * dz,
                )
                worst = max(worst, error)
                d = math.sqrt(dx * dx + dy * dy + dz * dz)
                task.targetAxis_world = np.array((dx / d, dy / d, dz / d))
            if worst < best:
                best, best_q = worst, [robot.get_joint(name) for _, name in self.free]
            since = 0 if worst < last else since + 1
            last = worst
            if worst <= FLOOR or since == STALL_STEPS or steps == MAX_STEPS:
                break
            c0 = clock()
            step(True)
            robot.update_kinematics()
            core += clock() - c0
            steps += 1
        self.core_seconds = core
        q = np.array(q0, dtype=float)
        for (i, _), x in zip(self.free, best_q, strict=True):
            q[i] = x
        return q, steps


def placo_reference(solver: GazeSolver) -> PlacoGaze | str:
    """A :class:`PlacoGaze` for ``solver``'s head (from the URDF text its robot was read from), moving the
    joints ``solver.free_joints("cyclopean")``; or, when there can be none, the reason in one
    line: a head its tasks cannot state, or placo not installed."""
    chain = solver.chain
    C = len(solver.cameras)
    if any(int(c) >= C for c in chain.solve_cameras):
        return "placo's tasks align real frames: this rigid pair is solved on its cyclopean axis (a virtual camera)"
    free = np.asarray(solver.free_joints("cyclopean"))
    A = chain.robot_A[free]
    plain = (
        (np.count_nonzero(A, axis=1) == 1).all()
        and (np.count_nonzero(A, axis=0) <= 1).all()
        and np.all(A[A != 0] == 1.0)
    )
    if (
        plain
    ):  # each free joint its own unknown: with no offset, and the joint's own limits as bounds
        cols = np.argmax(A != 0, axis=1)
        plain = bool(
            np.all(chain.robot_b[free] == 0.0)
            and np.all(chain.lower[cols] == solver.lower[free])
            and np.all(chain.upper[cols] == solver.upper[free])
        )
    if not plain:
        return "placo's tasks move joints one by one within their limits: this head couples, offsets or bounds its joints otherwise (a URDF mimic or a stated coupling)"
    try:
        import placo  # noqa: F401
    except ImportError:
        return NOT_INSTALLED
    cameras = [solver.cameras[int(c)] for c in chain.solve_cameras]
    return PlacoGaze(
        solver.robot.urdf,
        cameras,
        solver.joint_names,
        free.tolist(),
        np.asarray(solver.path_joints).tolist(),
    )


def summary(errors: Array) -> dict[str, Any]:
    """placo's accuracy over its answers' largest pointing errors [rad] (one per target)."""
    return {
        "placo_success": float(np.mean(errors <= GAZE_POINTING_TOL)),
        "placo_within_floor": float(np.mean(errors <= FLOOR)),
        "placo_over_1e-4": float(np.mean(errors > 1e-4)),
        "placo_error_median_rad": float(np.median(errors)),
    }


__all__ = [
    "FLOOR",
    "MAX_STEPS",
    "NOT_INSTALLED",
    "REGULARIZATION",
    "STALL_STEPS",
    "PlacoGaze",
    "kinematic_urdf",
    "placo_reference",
    "summary",
]
