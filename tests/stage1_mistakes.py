"""The stage-1 mistakes a user makes, as functions of a measurement document (they live with the
study that measures the gate, :mod:`cpc2urdf.studies.gate`)."""

from cpc2urdf.studies.gate import (
    MISTAKES,
    duplicated_records,
    joint_never_moved,
    joints_swapped,
    metres_as_mm,
    next_record_poses,
    noise_understated,
    only_q0,
    outliers,
    plates_swapped,
    poses_inverted,
    q0_copies,
    quaternion_wxyz,
    radians_as_degrees,
    rotations_transposed,
)

__all__ = [
    "MISTAKES",
    "duplicated_records",
    "joint_never_moved",
    "joints_swapped",
    "metres_as_mm",
    "next_record_poses",
    "noise_understated",
    "only_q0",
    "outliers",
    "plates_swapped",
    "poses_inverted",
    "q0_copies",
    "quaternion_wxyz",
    "radians_as_degrees",
    "rotations_transposed",
]
