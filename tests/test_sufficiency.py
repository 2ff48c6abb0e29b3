"""Records that cannot determine the robot are refused before any solver runs, naming what is missing."""

from __future__ import annotations

import numpy as np
import pytest

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.identification.kinematics.sufficiency import (
    check_data_suffice,
    exact_copies,
    noise_evident,
)
from cpc2urdf.identification.simulation.design import protocol_q
from cpc2urdf.identification.simulation.measurement_noise import fig10_noise
from cpc2urdf.identification.simulation.random_robots import random_model


def _head(q: np.ndarray, sigma: float = 0.0, seed: int = 0) -> MeasurementSet:
    head = load_model("iis_head")
    frames = ("plate_left", "plate_right")
    T = head.fk(q, frames)
    rng = np.random.default_rng(seed)
    poses = {f: fig10_noise(T[f], sigma, sigma, rng) if sigma else T[f] for f in frames}
    return MeasurementSet.from_arrays(head.structure, q, poses, source="m.json")


def test_the_protocol_passes_also_noise_free_with_q0_repeated_in_every_sweep() -> None:
    head = load_model("iis_head")
    q = protocol_q(head, 9)  # odd M: every sweep passes through q0 again
    ms = _head(q)
    assert not noise_evident(ms)
    check_data_suffice(ms)  # noise-free repeats are not copies
    check_data_suffice(_head(q, 1e-3))


def test_copied_records_of_noisy_data_are_refused() -> None:
    q = protocol_q(load_model("iis_head"), 9)
    ms = _head(q, 1e-3)
    twice = ms.subset(np.r_[np.arange(len(q)), [3, 17]])
    assert exact_copies(twice) == [(len(q), 3), (len(q) + 1, 17)]
    with pytest.raises(
        DegenerateDataError,
        match=r"record 55 \(record 3\) repeats record 3 to the last digit.*remove the 2 copies",
    ):
        check_data_suffice(twice)


def test_too_few_distinct_configurations_say_how_many_more() -> None:
    head = load_model("iis_head")
    lo, hi = head.structure.lower, head.structure.upper
    q = np.array(
        [lo + 0.3 * (hi - lo), lo + 0.6 * (hi - lo)]
    )  # every joint moves, two configurations
    ms = _head(np.repeat(q, 3, axis=0), 1e-3)
    with pytest.raises(DegenerateDataError) as e:
        check_data_suffice(ms)
    msg = str(e.value)
    assert "too few distinct configurations: 2 among 6 records" in msg
    assert "24 equations for the 32 parameters" in msg and "measure >= 1 more configurations" in msg
    assert "\n" not in msg


def test_several_joints_never_moved_are_all_named() -> None:
    q = protocol_q(load_model("iis_head"), 3)
    keep = [i for i in range(len(q)) if not (1 <= i <= 6)]  # drop the table_x and table_y sweeps
    with pytest.raises(
        DegenerateDataError,
        match=r"joints 'table_x', 'table_y' have fewer than two distinct readings",
    ):
        check_data_suffice(_head(q[keep], 1e-3))


def test_a_joint_moving_no_measured_frame_is_named() -> None:
    rng = np.random.default_rng(3)
    model = random_model(
        rng, 4, serial=False, p_branch=1.0
    )  # each joint on the base: one plate each
    plates = [f.name for f in model.structure.frames if f.kind == "plate"]
    q = protocol_q(model, 3)
    T = model.fk(q, plates[1:])
    ms = MeasurementSet.from_arrays(model.structure, q, T)
    with pytest.raises(
        DegenerateDataError, match=rf"moves no measured frame \(no pose of {plates[0]}"
    ):
        check_data_suffice(ms)
