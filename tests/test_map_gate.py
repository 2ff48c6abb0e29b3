"""The gate of ``identify --method map`` (:mod:`cpc2urdf.identification.kinematics.gate.map_gate`) on the
real robots' data: it passes them with the noise it estimates, names unmodelled error when the
stated noise is 5x too small, and names exactly the records where gross outliers were planted."""

from __future__ import annotations

import numpy as np
import pytest

from cpc2urdf.errors import InconsistentDataError
from cpc2urdf.identification.kinematics.map_identify import identify_map
from cpc2urdf.identification.kinematics.prior_fit import Noise
from cpc2urdf.studies.real_data import SETS, load_set
from cpc2urdf.urdf.pinocchio import gravity_loads

NAMES = [s.name for s in SETS]
PLANTED = (5, 12, 20)  # records given a gross error
GROSS = 0.05  # [m]: a marker swapped, a wrong frame


def _set(name: str):  # type: ignore[no-untyped-def]
    _, ms = load_set(next(s for s in SETS if s.name == name))
    return ms, ms.spec.nominal_model(), gravity_loads(ms)


@pytest.mark.parametrize("name", NAMES)
def test_real_data_pass_and_a_noise_five_times_too_small_is_unmodelled_error(name: str) -> None:
    ms, nominal, loads = _set(name)
    model = identify_map(ms, nominal, loads=loads)
    details = model.metadata.provenance.details
    assert details["consistency"]["consistent"]
    shown = details["noise_residuals"]
    stated = Noise(shown["position_m"] / 5, shown["rotation_rad"] / 5)
    with pytest.raises(
        InconsistentDataError,
        match=r"unmodelled error: the fit.s position residuals are (4|5)\.\dx",
    ):
        identify_map(ms, nominal, loads=loads, noise=stated)
    kept = identify_map(ms, nominal, loads=loads, noise=stated, accept_inconsistent=True)
    assert any("INCONSISTENT DATA" in n for n in kept.metadata.notes)


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_planted_gross_outliers_are_named_exactly(name: str) -> None:
    ms, nominal, loads = _set(name)
    for i in PLANTED:
        d = np.random.default_rng(i).normal(size=3)
        d *= GROSS / np.linalg.norm(d)
        for points in ms.marker_points.values():
            points[i] += d
        for poses in ms.poses.values():
            poses[i, :3, 3] += d
    with pytest.raises(InconsistentDataError) as e:
        identify_map(ms, nominal, loads=loads)
    assert str(e.value).endswith(
        "the fit made without them: " + ", ".join(f"record {i}" for i in PLANTED)
    )
    kept = identify_map(ms, nominal, loads=loads, accept_inconsistent=True)  # fitted without them
    assert kept.metadata.provenance.details["consistency"]["outlier_records"] == [
        f"record {i}" for i in PLANTED
    ]


def test_joints_the_data_cannot_vouch_for_are_kept_at_the_urdf() -> None:
    """With a prior as loose as maximum likelihood (0.1 m, 30 deg), TALOS's barely moved wrist
    (``arm_left_5`` spans 0.05 rad, ``arm_left_6`` 0.28 rad) would take the predictions far from
    the URDF's over their whole range: they are named and keep the URDF's values exactly."""
    import math

    from cpc2urdf.identification.kinematics.prior_fit import Tolerances

    ms, nominal, loads = _set("TALOS")
    loose = Tolerances(translation_m=0.1, rotation_rad=math.radians(30))
    model = identify_map(ms, nominal, loads=loads, tolerances=loose, level="geometry")
    assert any(
        n.startswith("kept at the URDF's values: arm_left_5_joint, arm_left_6_joint")
        for n in model.metadata.notes
    )
    for j in ("arm_left_5", "arm_left_6"):
        assert np.array_equal(model.joints[j].matrix(), nominal.joints[j].matrix())
    default = identify_map(ms, nominal, loads=loads)  # the default prior needs no such rescue
    assert not any(n.startswith("kept at") for n in default.metadata.notes)
    assert default.metadata.provenance.details["whole_range"]["whole_range_m"]["p95"] < 0.040


def test_what_the_data_cannot_see_is_named_and_held_by_the_urdf() -> None:
    """The first joint's placement is absorbed by the measuring frame: its data share is 0 and the
    notes name it; TALOS's barely moved wrist is named too (data share = 1 - posterior / prior
    variance)."""
    from cpc2urdf.identification.kinematics.map_identify import calibrate

    ms, nominal, loads = _set("TALOS")
    cal = calibrate(ms, nominal, loads=loads)
    share = cal.fit.data_share
    assert share["torso_1"] < 1e-6
    assert (
        max(share["arm_left_5"], share["arm_left_6"], share["arm_left_7"])
        < 0.25
        < share["arm_left_2"]
    )
    note = next(n for n in cal.notes if n.startswith("the data barely determine"))
    assert "torso_1" in note and "arm_left_5" in note and "arm_left_2" not in note


def test_accepted_outliers_are_left_out_of_every_fit() -> None:
    from cpc2urdf.identification.kinematics.map_identify import calibrate

    ms, nominal, loads = _set("TALOS")
    for i in PLANTED:
        ms.marker_points["m1"][i] += [GROSS, 0.0, 0.0]
    cal = calibrate(ms, nominal, loads=loads, accept_inconsistent=True)
    assert cal.gate.outliers == PLANTED
    assert len(cal.fit.loo_points) == ms.n_records - len(
        PLANTED
    )  # the fit kept saw the others only
    assert cal.fit.noise.position_m < 1e-3  # not inflated by 50 mm errors


def test_a_stated_orientation_noise_too_small_is_named() -> None:
    ms, nominal, loads = _set("UR10")
    shown = identify_map(ms, nominal, loads=loads).metadata.provenance.details["noise_residuals"]
    with pytest.raises(
        InconsistentDataError, match=r"unmodelled error: the fit.s orientation residuals are"
    ):
        identify_map(ms, nominal, noise=Noise(shown["position_m"], shown["rotation_rad"] / 5))


def test_a_joint_read_from_the_horizontal_is_named() -> None:
    """UR10's controller made to report the elbow from the horizontal (``elbow + shoulder_lift``):
    the fit fails by centimetres, and undoing that reading is what explains it."""
    ms, nominal, _ = _set("UR10")
    s = ms.structure
    ms.q[:, s.joint_index("elbow")] += ms.q[:, s.joint_index("shoulder_lift")]
    with pytest.raises(
        InconsistentDataError,
        match=r"joint 'elbow_joint' seems read relative to joint "
        r"'shoulder_lift_joint' \(the reading is elbow_joint \+ shoulder_lift_joint.*fall from .* mm to 1\.9\d mm",
    ):
        identify_map(ms, nominal)
