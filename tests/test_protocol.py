"""Recognising the one-joint-at-a-time protocol, and naming each kind of degenerate data."""

from __future__ import annotations

import numpy as np
import pytest

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.identification.kinematics.protocol import find_reference, recognise_protocol
from cpc2urdf.identification.simulation.design import protocol_q
from cpc2urdf.identification.simulation.random_robots import random_model


def _data(seed: int = 0, n: int = 4, M: int = 3) -> tuple[MeasurementSet, np.ndarray]:
    rng = np.random.default_rng(seed)
    model = random_model(rng, n, serial=True)
    q = protocol_q(model, M, rng)
    frames = [f.name for f in model.structure.frames if f.kind == "plate"]
    return MeasurementSet.from_arrays(model.structure, q, model.fk(q, frames)), q


def test_finds_q0_and_sweeps_in_any_record_order() -> None:
    ms, q = _data()
    perm = np.random.default_rng(1).permutation(len(q))
    p = recognise_protocol(ms.subset(perm))
    np.testing.assert_array_equal(p.q0, q[0])
    assert [int(perm[i]) for i in p.reference] == [0]
    for k, name in enumerate(ms.structure.joint_names):
        assert sorted(int(perm[i]) for i in p.sweeps[name]) == list(range(1 + 3 * k, 4 + 3 * k))
    assert p.frames == tuple(ms.frames)


def test_repeated_reference_records_are_all_used() -> None:
    ms, q = _data()
    q2 = np.vstack([q, q[:1], q[:1]])
    ms2 = MeasurementSet.from_arrays(
        ms.structure, q2, {f: np.concatenate([T, T[:1], T[:1]]) for f, T in ms.poses.items()}
    )
    assert recognise_protocol(ms2).reference == (0, len(q), len(q) + 1)


def test_reference_found_when_a_sweep_revisits_a_value_more_often_than_q0() -> None:
    q0 = np.zeros(2)
    rows = [q0, [1.0, 0.0], [1.0, 0.0], [1.0, 0.0], [0.0, 2.0]]
    np.testing.assert_array_equal(find_reference(np.array(rows), ("a", "b")), q0)


def test_joint_never_moved_is_named() -> None:
    ms, q = _data()
    keep = [i for i in range(len(q)) if i == 0 or not (4 <= i < 7)]  # drop joint j1's sweep
    with pytest.raises(
        DegenerateDataError, match=r"joint 'j1' has fewer than two distinct readings"
    ):
        recognise_protocol(ms.subset(keep))


def test_missing_reference_configuration_is_named() -> None:
    ms, q = _data()
    with pytest.raises(DegenerateDataError, match="no reference configuration q0"):
        recognise_protocol(ms.subset(np.arange(1, len(q))))


def test_record_moving_several_joints_is_named() -> None:
    ms, q = _data()
    q2 = q.copy()
    q2[5, 0] = q2[1, 0]  # record 5 (joint j1's sweep) also moves j0
    bad = MeasurementSet.from_arrays(
        ms.structure, q2, ms.poses, labels=[f"r{i}" for i in range(len(q))]
    )
    with pytest.raises(DegenerateDataError, match=r"r5 \(record 5\) moved several joints .*j0, j1"):
        recognise_protocol(bad)


def test_branch_without_poses_is_named() -> None:
    rng = np.random.default_rng(3)
    model = random_model(rng, 3, serial=False, p_branch=1.0)
    while len([f for f in model.structure.frames if f.kind == "plate"]) < 2:
        model = random_model(rng, 3, serial=False, p_branch=1.0)
    q = protocol_q(model, 3)
    poses = model.fk(q)
    poses["plate1"][:] = np.nan
    with pytest.raises(DegenerateDataError, match="frame 'plate1' .* has no poses"):
        recognise_protocol(MeasurementSet.from_arrays(model.structure, q, poses))
    del poses["plate1"]
    with pytest.raises(DegenerateDataError, match="moves no measured frame .*plate1"):
        recognise_protocol(MeasurementSet.from_arrays(model.structure, q, poses))


def test_no_pose_at_q0_or_in_a_sweep_is_named() -> None:
    ms, q = _data(n=2)
    poses = {f: T.copy() for f, T in ms.poses.items()}
    f = next(iter(poses))
    poses[f][0] = np.nan
    with pytest.raises(DegenerateDataError, match="no pose at the reference configuration"):
        recognise_protocol(MeasurementSet.from_arrays(ms.structure, q, poses))
    poses = {f: T.copy() for f, T in ms.poses.items()}
    poses[f][4:7] = np.nan
    with pytest.raises(DegenerateDataError, match="joint 'j1' was moved in 3 records but none"):
        recognise_protocol(MeasurementSet.from_arrays(ms.structure, q, poses))


def test_readings_off_by_a_count_still_count_as_q0() -> None:
    """A joint driven back to q0 may read a transducer count off (Table 2: ~6e-5 rad, 5e-6 m)."""
    ms, q = _data(n=3)
    rng = np.random.default_rng(2)
    jittered = q.copy()
    for k in range(1, len(q)):
        moved = (k - 1) // 3
        for i in range(3):
            if i != moved:
                step = 6e-5 if ms.structure.joints[i].type == "revolute" else 5e-6
                jittered[k, i] += step * rng.integers(-1, 2)
    ms2 = MeasurementSet.from_arrays(ms.structure, jittered, ms.poses)
    p = recognise_protocol(ms2)
    assert [len(p.sweeps[n]) for n in ms.structure.joint_names] == [3, 3, 3]
    with pytest.raises(
        DegenerateDataError, match="moved several joints|no reference configuration"
    ):
        recognise_protocol(ms2, tol=1e-9)  # exact equality: the jitter breaks the protocol
