"""Calibrating a humanoid's head must not move the rest of it (``identify --method map``).

A humanoid's URDF with a plate added on its head (and, for iCub, whose URDF has no eye joints, a
camera link there too): a true robot whose every joint on the head's path (the torso's and the
neck's) is off by 3 mm / 0.3 deg per coordinate; the plate measured (0.5 mm / 0.1 deg noise) while
only the neck moves, the torso held. The neck is calibrated, the torso keeps the URDF's values, and
the first neck joint's placement on the torso, which head-only data cannot see, keeps the user's
value (the measuring frame absorbs it).
"""

from __future__ import annotations

import sys
import sysconfig
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from cpc2urdf import api
from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.identification.kinematics.prior_problem import perturbation
from cpc2urdf.model import CPCModel, CPCParams
from cpc2urdf.transforms import rotation_error
from cpc2urdf.urdf.robot import load_urdf_robot
from cpc2urdf.urdf.tree import read_urdf_tree

SHARE = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix" / "share"  # example-robot-data
ICUB_SHARE = Path(sys.prefix, "share")  # icub-models
SEEDS = range(10)
RECORDS = 30
ERROR_T, ERROR_R = 3e-3, np.radians(0.3)  # [m], [rad] per coordinate of each true joint origin
NOISE_T, NOISE_R = 0.5e-3, np.radians(0.1)  # [m], [rad] measurement noise per coordinate


def _fixed(name: str, parent: str, xyz: str, rpy: str) -> str:
    return (
        f'  <link name="{name}"/>\n  <joint name="{name}_joint" type="fixed">\n'
        f'    <parent link="{parent}"/>\n    <child link="{name}"/>\n'
        f'    <origin xyz="{xyz}" rpy="{rpy}"/>\n  </joint>\n'
    )


@dataclass(frozen=True)
class Head:
    """A humanoid's URDF and what is added and moved.

    Attributes:
        source: The installed URDF.
        head: The link the plate (and the camera) go on.
        camera: The camera link whose orientation is compared.
        neck: The joints that move (the rest of the path is held).
        added: URDF text added (the plate, and a camera link where the URDF has none).
    """

    source: Path
    head: str
    camera: str
    neck: tuple[str, ...]
    added: str


HEADS = {
    "icub": Head(
        ICUB_SHARE / "iCub/robots/iCubGenova04/model.urdf",
        "head",
        "eye_camera",
        ("neck_pitch", "neck_roll", "neck_yaw"),
        _fixed("head_plate", "head", "0.1 0.05 0.12", "0.1 0.2 0.3")
        + _fixed("eye_camera", "head", "-0.034 0.11 0.06", "0 0 0"),
    ),
    "talos": Head(
        SHARE / "example-robot-data/robots/talos_data/robots/talos_full_v2.urdf",
        "head_2_link",
        "rgbd_optical_frame",
        ("head_1", "head_2"),
        _fixed("head_plate", "head_2_link", "0.1 0.05 0.12", "0.1 0.2 0.3"),
    ),
}


def _urdf(head: Head, folder: Path) -> Path:
    text = head.source.read_text()
    end = text.rindex("</robot>")
    path = folder / "robot.urdf"
    path.write_text(text[:end] + head.added + text[end:])
    return path


def _camera_in_torso(model: CPCModel, q: np.ndarray, head: Head) -> np.ndarray:
    """Orientation of the camera relative to the link the first neck joint hangs on, (N, 3, 3)."""
    _, link = model.link_poses(q)
    L = link[:, model.structure.joint_index(model.structure.joint(head.neck[0]).parent)]
    C = model.fk(q, [head.camera])[head.camera]
    return np.transpose(L[:, :3, :3], (0, 2, 1)) @ C[:, :3, :3]


def _experiment(urdf: Path, head: Head, seed: int) -> tuple[CPCModel, CPCModel, MeasurementSet]:
    robot = load_urdf_robot(urdf, ["head_plate", head.camera])
    nominal = robot.nominal_model()
    rng = np.random.default_rng(seed)
    joints = {
        j: CPCParams.from_matrix(
            nominal.joints[j].matrix()
            @ perturbation(np.concatenate([rng.normal(0, ERROR_T, 3), rng.normal(0, ERROR_R, 3)]))
        )
        for j in nominal.structure.joint_names
    }
    truth = nominal.with_params(joints=joints)
    s = nominal.structure
    q = np.zeros((RECORDS, s.n_joints))
    for j in head.neck:
        k = s.joint_index(j)
        q[:, k] = rng.uniform(s.joints[k].lower, s.joints[k].upper, RECORDS)
    T = truth.fk(q, ["head_plate"])["head_plate"].copy()
    T[:, :3, 3] += rng.normal(0, NOISE_T, (RECORDS, 3))
    T[:, :3, :3] = np.stack(
        [perturbation(np.r_[0, 0, 0, rng.normal(0, NOISE_R, 3)])[:3, :3] @ R for R in T[:, :3, :3]]
    )
    ms = MeasurementSet.from_arrays(s, q, {"head_plate": T})
    ms.spec = robot
    return nominal, truth, ms


@pytest.mark.parametrize("name", list(HEADS))
def test_head_only_data_calibrate_the_neck_and_keep_the_rest(name: str, tmp_path: Path) -> None:
    """Every link not below a neck joint stays where the URDF puts it, to 1e-9 m. iCub's camera
    (three neck joints) comes nearer the truth relative to the torso than the stock URDF's in at
    least 8 of 10 seeds (9 here; 35 of 40 over 40 seeds). TALOS's two neck joints leave as much
    unseen as seen (the first joint's placement, its offset): nearer in the median only (26 of 40)."""
    head = HEADS[name]
    urdf = _urdf(head, tmp_path)
    calibrated = {f"{j}_joint" if name == "talos" else j for j in head.neck}
    stock, ours = [], []
    for seed in SEEDS:
        nominal, truth, ms = _experiment(urdf, head, seed)
        model = api.identify(ms, "map")
        assert model.metadata.provenance is not None
        assert model.metadata.provenance.details["calibrated_joints"] == list(head.neck)
        written = api.export_urdf(model, tmp_path / f"calibrated_{seed}.urdf")
        before, after = read_urdf_tree(urdf), read_urdf_tree(written)
        changed = {
            j
            for j in before.joints
            if (before.joints[j].xyz, before.joints[j].rpy)
            != (after.joints[j].xyz, after.joints[j].rpy)
        }
        assert changed <= calibrated | {"head_plate_joint"}
        F0, F1 = before.fk(), after.fk()
        for link in before.links:
            if not {j.name for j in before.path(link)} & calibrated:
                assert np.abs(F0[link] - F1[link]).max() < 1e-9, link
        true_cam = _camera_in_torso(truth, ms.q, head)
        stock.append(rotation_error(true_cam, _camera_in_torso(nominal, ms.q, head)).mean())
        ours.append(rotation_error(true_cam, _camera_in_torso(model, ms.q, head)).mean())
    closer = int(np.sum(np.array(ours) < np.array(stock)))
    if name == "icub":
        assert closer >= 8
    assert np.median(ours) < 0.8 * np.median(stock)
