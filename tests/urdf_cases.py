"""URDFs for the URDF-input and write-back tests: TIAGo's head (a robot no one here wrote) with a
calibration plate added, a small robot with the awkward cases, and simulated measurements of them."""

from __future__ import annotations

import sysconfig
from pathlib import Path

import numpy as np
import pinocchio as pin
from consumer_checks import pinocchio_q

from cpc2urdf.files.measurements import MeasurementSet, save_measurements
from cpc2urdf.identification.simulation.design import protocol_q
from cpc2urdf.identification.simulation.measurement_noise import fig10_noise
from cpc2urdf.identification.simulation.truth import perturbed_model
from cpc2urdf.model import CPCModel
from cpc2urdf.urdf.robot import UrdfRobot

ROBOTS = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix/share/example-robot-data/robots"
TIAGO = ROBOTS / "tiago_description/robots/tiago.urdf"
TIAGO_HEAD = ("torso_lift_joint", "head_1_joint", "head_2_joint")

# A plate on TIAGo's head: the measured link, on a fixed joint (how a user adds a target).
PLATE = """  <link name="calib_plate"/>
  <joint name="calib_plate_joint" type="fixed">
    <parent link="head_2_link"/>
    <child link="calib_plate"/>
    <origin xyz="0.1 0.05 0.02" rpy="0.1 0.2 0.3"/>
  </joint>
"""

# Prismatic with a non-unit axis, continuous along -z without <origin>, a tilted revolute axis, a
# chain of two fixed joints to the marker, floating and planar joints off the marker's path, and
# the elements write-back must keep (comments, materials, meshes, inertials, transmission, gazebo).
SMALL = """<?xml version="1.0"?>
<!-- a small robot with the cases the mapping must get right -->
<robot name="small">
  <material name="grey"><color rgba="0.5 0.5 0.5 1"/></material>
  <link name="base_link">
    <inertial><mass value="2"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
    <visual><geometry><mesh filename="package://small/meshes/base.stl"/></geometry><material name="grey"/></visual>
  </link>
  <link name="slider"/>
  <link name="turret"/>
  <link name="head"><!-- the head --></link>
  <link name="marker_mount"/>
  <link name="marker"/>
  <link name="floater"/>
  <link name="planar_thing"/>
  <joint name="slide" type="prismatic">
    <parent link="base_link"/><child link="slider"/>
    <origin xyz="0.1 0 0.2" rpy="0 0 0.3"/>
    <axis xyz="0 2 0"/>
    <limit lower="-0.1" upper="0.2" effort="10" velocity="0.5"/>
  </joint>
  <joint name="turret_joint" type="continuous">
    <parent link="slider"/><child link="turret"/>
    <axis xyz="0 0 -1"/>
  </joint>
  <joint name="head_joint" type="revolute">
    <parent link="turret"/><child link="head"/>
    <origin xyz="0 0.05 0.3" rpy="1.2 -0.4 0.1"/>
    <axis xyz="0.6 0 0.8"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
  <joint name="mount_joint" type="fixed">
    <parent link="head"/><child link="marker_mount"/>
    <origin xyz="0.02 0 0.1" rpy="0 0.5 0"/>
  </joint>
  <joint name="marker_joint" type="fixed">
    <parent link="marker_mount"/><child link="marker"/>
    <origin xyz="0.05 0.01 0" rpy="0.1 0 0"/>
  </joint>
  <joint name="float_joint" type="floating">
    <parent link="base_link"/><child link="floater"/>
  </joint>
  <joint name="planar_joint" type="planar">
    <parent link="base_link"/><child link="planar_thing"/>
    <axis xyz="0 0 1"/>
  </joint>
  <transmission name="t1"><type>transmission_interface/SimpleTransmission</type>
    <joint name="head_joint"><hardwareInterface>EffortJointInterface</hardwareInterface></joint>
    <actuator name="m1"><mechanicalReduction>1</mechanicalReduction></actuator></transmission>
  <gazebo reference="head"><material>Gazebo/Grey</material></gazebo>
</robot>
"""


def tiago_with_plate(folder: Path) -> Path:
    """TIAGo's URDF with the ``calib_plate`` link added on ``head_2_link``, written to ``folder``."""
    text = TIAGO.read_text()
    end = text.rindex("</robot>")
    path = folder / "tiago_plate.urdf"
    path.write_text(text[:end] + PLATE + text[end:])
    return path


def write(folder: Path, name: str, text: str) -> Path:
    path = folder / name
    path.write_text(text)
    return path


def simulate(
    robot: UrdfRobot,
    rng: np.random.Generator,
    path: Path,
    *,
    M: int = 7,
    sigma_t: float = 0.0,
    sigma_r: float = 0.0,
) -> CPCModel:
    """A perturbed true robot of ``robot`` (a measured sub-tree), its one-joint-at-a-time
    measurements (Fig. 10 noise of the given sigmas [m], [rad]) saved as ``path`` with the
    URDF's names, robot reference = the URDF's file name; returns the truth."""
    truth = perturbed_model(robot.nominal_model(), rng, 1e-3, np.radians(0.5))
    q = protocol_q(truth, M)
    poses = truth.fk(q)
    if sigma_t > 0:
        poses = {f: fig10_noise(T, sigma_t, sigma_r, rng) for f, T in poses.items()}
    ms = MeasurementSet.from_arrays(truth.structure, q, poses, robot=Path(robot.source).name)
    if sigma_t > 0:
        ms.metadata["noise"] = {"model": "fig10", "sigma_t_m": sigma_t, "sigma_r_rad": sigma_r}
    ms.spec = robot
    save_measurements(ms, path)
    return truth


def pinocchio_poses(
    urdf: Path, readings: dict[str, float], links: list[str]
) -> dict[str, np.ndarray]:
    """``T_root_link`` of ``links`` by Pinocchio (urdfdom) from the file, joints by URDF name."""
    model = pin.buildModelFromUrdf(str(urdf))
    data = model.createData()
    pin.framesForwardKinematics(model, data, pinocchio_q(model, readings))
    return {n: data.oMf[model.getFrameId(n, pin.FrameType.BODY)].homogeneous.copy() for n in links}
