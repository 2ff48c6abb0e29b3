"""Head shapes for the gaze tests: real URDFs where they exist, small specs otherwise.

Each :func:`head_case` gives a :class:`HeadCase`: the solver, the URDF file an independent FK
(yourdfpy) reads, and seeded targets that are fixatable by construction (sampled readings inside
the limits; one axis: points on it; two eyes whose axes meet: their meeting point).

Shapes (``HEAD_SHAPES``):

- ``iis_nominal`` / ``iis_calibrated``: the shipped IIS-head (table, pan, tilt, two vergence
  eyes) and ``heads.calibrated_iis_head(0)``; calibrated targets from
  ``heads.reachable_targets`` (the eyes' axes meet only on a curve);
- ``tiago``: TIAGo (example-robot-data), torso lift + pan-tilt, one RGB-D camera
  (``xtion_rgb_optical_frame``);
- ``talos``: TALOS (example-robot-data, ``talos_reduced.urdf``), torso + pan-tilt, one camera
  (``rgbd_rgb_optical_frame``);
- ``icub``: iCub's 3-joint neck (icub-models ``iCubGenova04``) with eyes added in a temporary
  copy (``eyes_tilt``, ``l_eye``, ``r_eye`` turning about parallel axes, as iCub's), coupled as
  ``l_eye = version + vergence / 2``, ``r_eye = version - vergence / 2``;
- ``stereo_pan_tilt``: a pan-tilt carrying a rigid stereo pair (spec written here), solved on
  its cyclopean axis;
- ``panda_camera``: Panda (example-robot-data) with a camera on the hand (temporary copy).
"""

from __future__ import annotations

import sys
import sysconfig
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.identification.simulation.heads import calibrated_iis_head, reachable_targets
from cpc2urdf.urdf.document import write_urdf
from cpc2urdf.urdf.pinocchio import PinocchioRobot
from cpc2urdf.validation.crosscheck import yourdfpy_pose
from cpc2urdf.validation.gaze import Coupling, GazeSolver

HEAD_SHAPES = (
    "iis_nominal",
    "iis_calibrated",
    "tiago",
    "talos",
    "icub",
    "stereo_pan_tilt",
    "panda_camera",
)
ERD = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix/share/example-robot-data/robots"
ICUB = Path(sys.prefix) / "share/iCub/robots/iCubGenova04/model.urdf"
OPTICAL_RPY = (
    "-1.5707963267948966 0 -1.5707963267948966"  # REP-103 optical frame on an x-forward body
)

ICUB_EYES = f"""
  <link name="eyes_tilt_link"/>
  <joint name="eyes_tilt" type="revolute">
    <origin xyz="0.02 0.10 0.06" rpy="1.5707963267948966 0 0"/>
    <axis xyz="0 1 0"/>
    <parent link="head"/><child link="eyes_tilt_link"/>
    <limit lower="-0.6" upper="0.6" effort="1" velocity="1"/>
  </joint>
  <link name="l_eye"/>
  <joint name="l_eye_joint" type="revolute">
    <origin xyz="0 0.034 0" rpy="0 0 0"/>
    <axis xyz="0 0 -1"/>
    <parent link="eyes_tilt_link"/><child link="l_eye"/>
    <limit lower="-1.0" upper="1.0" effort="1" velocity="1"/>
  </joint>
  <link name="r_eye"/>
  <joint name="r_eye_joint" type="revolute">
    <origin xyz="0 -0.034 0" rpy="0 0 0"/>
    <axis xyz="0 0 -1"/>
    <parent link="eyes_tilt_link"/><child link="r_eye"/>
    <limit lower="-1.0" upper="1.0" effort="1" velocity="1"/>
  </joint>
  <link name="l_eye_optical"/>
  <joint name="l_eye_optical_joint" type="fixed">
    <origin xyz="0.01 0 0" rpy="{OPTICAL_RPY}"/>
    <parent link="l_eye"/><child link="l_eye_optical"/>
  </joint>
  <link name="r_eye_optical"/>
  <joint name="r_eye_optical_joint" type="fixed">
    <origin xyz="0.01 0 0" rpy="{OPTICAL_RPY}"/>
    <parent link="r_eye"/><child link="r_eye_optical"/>
  </joint>
"""

STEREO_PAN_TILT = f"""<?xml version="1.0"?>
<robot name="stereo_pan_tilt">
  <link name="world"/>
  <link name="pan_link"/>
  <link name="tilt_link"/>
  <link name="left_optical"/>
  <link name="right_optical"/>
  <joint name="pan" type="revolute">
    <origin xyz="0 0 1.2" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <parent link="world"/><child link="pan_link"/>
    <limit lower="-2.5" upper="2.5" effort="1" velocity="2"/>
  </joint>
  <joint name="tilt" type="revolute">
    <origin xyz="0.02 0 0.08" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <parent link="pan_link"/><child link="tilt_link"/>
    <limit lower="-0.9" upper="1.2" effort="1" velocity="2"/>
  </joint>
  <joint name="left_optical_joint" type="fixed">
    <origin xyz="0.05 0.06 0.03" rpy="{OPTICAL_RPY}"/>
    <parent link="tilt_link"/><child link="left_optical"/>
  </joint>
  <joint name="right_optical_joint" type="fixed">
    <origin xyz="0.05 -0.06 0.03" rpy="-1.5707963267948966 0 -1.5507963267948966"/>
    <parent link="tilt_link"/><child link="right_optical"/>
  </joint>
</robot>
"""

PANDA_CAMERA = """
  <link name="hand_camera_optical"/>
  <joint name="hand_camera_joint" type="fixed">
    <origin xyz="0.05 0.0 0.04" rpy="0 -0.3 0"/>
    <parent link="panda_hand"/><child link="hand_camera_optical"/>
  </joint>
"""


@dataclass
class HeadCase:
    """One head shape: its solver, URDF file, camera frames and (for the targets) its shape."""

    name: str
    solver: GazeSolver
    urdf: Path
    cameras: tuple[str, ...]
    model: object | None = None  # the CPC model (IIS heads)

    def axes(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Centres (N, S, 3) and unit optical axes (N, S, 3) of the solved axes at readings Q."""
        comp = self.solver.compiled
        chain = comp.chain
        O = np.empty((len(Q), len(chain.solve_cameras), 3))
        Z = np.empty_like(O)
        for i, q in enumerate(Q):
            R, o = comp._fk(chain.u_from_q(q))
            for s, c in enumerate(chain.solve_cameras.tolist()):
                O[i, s], Z[i, s] = o[c], R[c][:, 2]
        return O, Z

    def reachable_targets(self, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """``(P, Q)``: ``n`` targets (N, 3) and readings (N, n_joints) that fixate them."""
        if self.name in ("iis_nominal", "iis_calibrated"):
            return reachable_targets(self.model, n, seed=seed)  # type: ignore[arg-type]
        rng = np.random.default_rng(seed)
        chain = self.solver.chain
        P, Qs = [], []
        while len(P) < n:
            k = 4 * (n - len(P)) + 16
            lo, hi = chain.lower, chain.upper
            U = rng.uniform(lo + 1e-3 * (hi - lo), hi - 1e-3 * (hi - lo), (k, chain.m))
            Q = chain.q_from_u(U)
            O, Z = self.axes(Q)
            if O.shape[1] == 1:
                t = rng.uniform(0.3, 3.0, k)
                pts = O[:, 0] + t[:, None] * Z[:, 0]
                ok = np.ones(k, dtype=bool)
            else:  # two eyes: the meeting point of their axes, in front of both
                w = O[:, 0] - O[:, 1]
                a = np.einsum("ij,ij->i", Z[:, 0], Z[:, 0])
                b = np.einsum("ij,ij->i", Z[:, 0], Z[:, 1])
                c = np.einsum("ij,ij->i", Z[:, 1], Z[:, 1])
                d = np.einsum("ij,ij->i", Z[:, 0], w)
                e = np.einsum("ij,ij->i", Z[:, 1], w)
                den = a * c - b * b
                den = np.where(den > 1e-12, den, np.nan)
                s = (b * e - c * d) / den
                t = (a * e - b * d) / den
                p0 = O[:, 0] + s[:, None] * Z[:, 0]
                p1 = O[:, 1] + t[:, None] * Z[:, 1]
                gap = np.linalg.norm(p0 - p1, axis=1)
                pts = 0.5 * (p0 + p1)
                ok = (gap < 1e-10) & (s > 0.15) & (s < 5.0) & (t > 0.15) & (t < 5.0)
            P += list(pts[ok])
            Qs += list(Q[ok])
        return np.array(P[:n]), np.array(Qs[:n])


def _write(tmp: Path, name: str, text: str) -> Path:
    path = tmp / f"{name}.urdf"
    path.write_text(text)
    return path


def _insert(urdf: Path, snippet: str) -> str:
    text = urdf.read_text()
    i = text.rindex("</robot>")
    return text[:i] + snippet + text[i:]


def head_case(name: str, tmp: Path) -> HeadCase:
    """The :class:`HeadCase` ``name`` (one of :data:`HEAD_SHAPES`); files go in ``tmp``."""
    if name in ("iis_nominal", "iis_calibrated"):
        model = load_model("iis_head") if name == "iis_nominal" else calibrated_iis_head(0)
        path = write_urdf(model, tmp / f"{name}.urdf")
        cams = ("camera_left_optical", "camera_right_optical")
        return HeadCase(name, GazeSolver(path, cams), Path(path), cams, model)
    if name == "tiago":
        path = ERD / "tiago_description/robots/tiago.urdf"
        cams = ("xtion_rgb_optical_frame",)
        robot = PinocchioRobot.from_urdf(path, continuous_as_revolute=True)
        return HeadCase(name, GazeSolver(robot, cams), path, cams)
    if name == "talos":
        path = ERD / "talos_data/robots/talos_reduced.urdf"
        cams = ("rgbd_rgb_optical_frame",)
        robot = PinocchioRobot.from_urdf(path, continuous_as_revolute=True)
        return HeadCase(name, GazeSolver(robot, cams), path, cams)
    if name == "icub":
        path = _write(tmp, name, _insert(ICUB, ICUB_EYES))
        cams = ("l_eye_optical", "r_eye_optical")
        coupling = Coupling.version_vergence("l_eye_joint", "r_eye_joint", (-0.5, 0.5), (0.0, 0.9))
        return HeadCase(
            name, GazeSolver(PinocchioRobot.from_urdf(path), cams, coupling=coupling), path, cams
        )
    if name == "stereo_pan_tilt":
        path = _write(tmp, name, STEREO_PAN_TILT)
        cams = ("left_optical", "right_optical")
        return HeadCase(name, GazeSolver(path, cams), path, cams)
    if name == "panda_camera":
        path = _write(tmp, name, _insert(ERD / "panda_description/urdf/panda.urdf", PANDA_CAMERA))
        cams = ("hand_camera_optical",)
        return HeadCase(name, GazeSolver(PinocchioRobot.from_urdf(path), cams), path, cams)
    raise KeyError(name)


def yourdfpy_axes(case: HeadCase, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centres and optical axes of the solved axes at readings Q (N, n) by yourdfpy (an FK
    independent of Pinocchio and of the compiled loop); a rigid pair's cyclopean axis from its
    two cameras (midpoint, sum of the optical axes)."""
    import yourdfpy

    robot = yourdfpy.URDF.load(
        str(case.urdf), load_meshes=False, build_collision_scene_graph=False, build_scene_graph=True
    )
    names = case.solver.joint_names
    order = [names.index(j) for j in robot.actuated_joint_names]
    chain = case.solver.chain
    S = len(chain.solve_cameras)
    O = np.empty((len(Q), S, 3))
    Z = np.empty_like(O)
    for i, q in enumerate(Q):
        robot.update_cfg(q[order])
        T = [yourdfpy_pose(robot, c, robot.base_link) for c in case.cameras]
        for s, c in enumerate(chain.solve_cameras.tolist()):
            if c < len(case.cameras):
                O[i, s], Z[i, s] = T[c][:3, 3], T[c][:3, 2]
            else:
                z = T[0][:3, 2] + T[1][:3, 2]
                O[i, s], Z[i, s] = 0.5 * (T[0][:3, 3] + T[1][:3, 3]), z / np.linalg.norm(z)
    return O, Z


def pointing_errors(O: np.ndarray, Z: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Angle [rad] between each axis (N, S, 3) and the direction to its target (N, 3)."""
    d = P[:, None, :] - O
    c = np.einsum("nsj,nsj->ns", d, Z)
    s = np.linalg.norm(np.cross(d, Z), axis=2)
    return np.arctan2(s, c)


IIS_CAMERAS = ("camera_left_optical", "camera_right_optical")


def model_pointing_errors(model, Q, P) -> np.ndarray:
    """Pointing error of each IIS eye [rad], shape (N, 2), from the CPC model's FK (not Pinocchio)."""
    T = model.fk(np.atleast_2d(Q), IIS_CAMERAS)
    out = []
    for cam in IIS_CAMERAS:
        R, o = T[cam][:, :3, :3], T[cam][:, :3, 3]
        pc = np.einsum("nji,nj->ni", R, np.atleast_2d(P) - o)
        out.append(np.arctan2(np.hypot(pc[:, 0], pc[:, 1]), pc[:, 2]))
    return np.stack(out, axis=1)


__all__ = [
    "HEAD_SHAPES",
    "IIS_CAMERAS",
    "HeadCase",
    "head_case",
    "model_pointing_errors",
    "pointing_errors",
    "yourdfpy_axes",
]
