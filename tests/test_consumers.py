"""Consumers as tests: every URDF we export loads UNMODIFIED and SILENTLY in Pinocchio, yourdfpy,
urdfdom's ``check_urdf``, MuJoCo and PyBullet, and all five agree on the pose of every link to
1e-12 m / 1e-12 rad at seeded configurations; the dynamics are usable (finite ``aba``, positive
mass, a few simulation steps stay finite); ``world`` is gravity-aligned where a spec says which
way is up; and ``cpc2urdf check`` passes the same files.

What each consumer prints while loading is captured at the file-descriptor level
(:func:`cpc2urdf.urdf.native_output.captured_output`: urdfdom's and PyBullet's C++ ``b3Warning`` lines,
MuJoCo's compiler warnings) together with Python warnings and log records, and must be empty.

How each consumer is loaded, and how its poses are read (PyBullet's from its exact
centre-of-mass items), is in ``consumer_checks.py``, shared with ``test_real_robots.py``.
"""

from __future__ import annotations

import logging
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from consumer_checks import CONSUMER_TOL, CONSUMERS, LOADERS, fk_disagreement, links, load_pinocchio

from cpc2urdf.cli import main
from cpc2urdf.files.model_file import save_model
from cpc2urdf.files.robot_ref import load_model, load_robot
from cpc2urdf.identification.kinematics.methods import identify
from cpc2urdf.identification.simulation.random_robots import random_model
from cpc2urdf.identification.simulation.stage1_experiment import simulate_experiment
from cpc2urdf.model import CPCModel
from cpc2urdf.urdf.document import camera_body_names, write_urdf
from cpc2urdf.urdf.mass_properties import is_physical
from cpc2urdf.urdf.native_output import captured_output
from cpc2urdf.validation.crosscheck import cross_check

N_CONFIGURATIONS = 12  # seeded, plus both limit corners


# ---- the URDFs -------------------------------------------------------------------------------


def _calibrated(folder: Path) -> Path:
    """An identified IIS-head (simulated stage 1, closed form) with the nominal cameras, as a model
    file whose provenance names the robot 'iis_head' (so export finds its density and 'up')."""
    _, measured, _ = simulate_experiment("iis_head", seed=3, M=3, n_heldout=0)
    model = identify(measured, "closed-form")
    nominal = load_model("iis_head")
    for f in nominal.structure.frames:
        if f.name not in model.structure.frame_names:
            model = model.with_frame(f, nominal.frames[f.name])
    return save_model(model, folder / "calibrated.json")


def _random(seed: int, **kw: Any) -> CPCModel:
    return random_model(np.random.default_rng(seed), kw.pop("n", 6), **kw)


RANDOM = {
    "random_tree_s0": dict(seed=0, n=7, serial=False, extra_plates=1, cameras=2),
    "random_serial_s1": dict(seed=1, n=6, serial=True, p_prismatic=0.5, cameras=1),
    "random_tree_s2": dict(seed=2, n=5, serial=False, p_branch=0.8, cameras=2),
}
CASES = ("nominal", "nominal_rig", "calibrated", *RANDOM)


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[CPCModel, Path]]:
    """Every case: the CPC model and its URDF, written as a user would (``cpc2urdf export``) or by
    :func:`write_urdf` with ``mount="base"`` (random trees, base +z up)."""
    d = tmp_path_factory.mktemp("consumers")
    out: dict[str, tuple[CPCModel, Path]] = {}
    with captured_output():  # export's own summary lines
        assert main(["export", "iis_head", "-o", str(d / "nominal.urdf")]) == 0
        assert (
            main(["export", "iis_head", "-o", str(d / "nominal_rig.urdf"), "--mount", "rig"]) == 0
        )
        model_file = _calibrated(d)
        assert main(["export", str(model_file), "-o", str(d / "calibrated.urdf")]) == 0
    out["nominal"] = (load_model("iis_head"), d / "nominal.urdf")
    out["nominal_rig"] = (load_model("iis_head"), d / "nominal_rig.urdf")
    out["calibrated"] = (load_model(model_file), d / "calibrated.urdf")
    for name, kw in RANDOM.items():
        model = _random(**kw)
        out[name] = (model, write_urdf(model, d / f"{name}.urdf", mount="base"))
    return out


# ---- loading each consumer, silently --------------------------------------------------------


@pytest.fixture()
def quiet(caplog: pytest.LogCaptureFixture) -> Iterator[Callable[[], str]]:
    """Call inside a ``captured_output()`` block: returns the Python warnings and log records
    (INFO and up) of the test so far, as text, to add to what was printed."""
    caplog.set_level(logging.INFO)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield lambda: "\n".join(
            [str(w.message) for w in caught] + [r.getMessage() for r in caplog.records]
        )


def _configurations(model: CPCModel) -> list[dict[str, float]]:
    s = model.structure
    rng = np.random.default_rng(7)
    Q = np.vstack([s.lower, s.upper, rng.uniform(s.lower, s.upper, (N_CONFIGURATIONS, s.n_joints))])
    return [s.q_to_dict(q) for q in Q]


# ---- the matrix -------------------------------------------------------------------------------


@pytest.mark.parametrize("consumer", CONSUMERS)
@pytest.mark.parametrize("case", CASES)
def test_loads_silently_and_agrees_on_every_link(
    exported: dict[str, tuple[CPCModel, Path]],
    case: str,
    consumer: str,
    quiet: Callable[[], str],
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    model, path = exported[case]
    monkeypatch.chdir(tmp_path)  # MuJoCo would write MUJOCO_LOG.TXT here on a warning
    fk, printed, close = LOADERS[consumer](path)
    try:
        said = (printed + "\n" + quiet()).strip()
        assert said == "", f"{consumer} on {case}: {said[:500]}"
        assert not list(tmp_path.iterdir())
        if fk is None:  # check_urdf exposes no poses (its tree is checked by cpc2urdf check below)
            return
        reference, _, _ = load_pinocchio(path, geometry=False)
        dp, dr, where = fk_disagreement(fk, reference, links(path), _configurations(model))
        assert dp < CONSUMER_TOL and dr < CONSUMER_TOL, (
            f"{consumer} {case}: {dp:.2e} m, {dr:.2e} rad, {where}"
        )
    finally:
        close()


@pytest.mark.parametrize("case", CASES)
def test_cpc2urdf_check_passes_and_matches_to_1e_12(
    exported: dict[str, tuple[CPCModel, Path]], case: str
) -> None:
    model, path = exported[case]
    report = cross_check(model, path, n=8, seed=1)
    assert report.ok, report.format()
    for p in report.parsers:
        if p.max_position_error is not None:
            assert p.max_position_error < CONSUMER_TOL and p.max_rotation_error is not None
            assert p.max_rotation_error < CONSUMER_TOL, report.format()
    bodies = camera_body_names(model.structure)  # compared too
    assert len(bodies) == sum(f.kind == "camera" for f in model.structure.frames) > 0
    assert set(bodies.values()) <= set(report.frames)


@pytest.mark.parametrize("case", CASES)
def test_dynamics_are_usable(exported: dict[str, tuple[CPCModel, Path]], case: str) -> None:
    """Every inertial is physical; Pinocchio's aba is finite with positive total mass; MuJoCo and
    PyBullet keep a finite state over 0.1 s of free fall under gravity."""
    import mujoco
    import pinocchio as pin

    _, path = exported[case]
    root = ET.parse(path).getroot()
    for link in root.iter("link"):
        inertial = link.find("inertial")
        if link.get("name") == "world":
            assert inertial is None
            continue
        assert inertial is not None, link.get("name")
        mass = float(inertial.find("mass").get("value"))  # type: ignore[union-attr]
        I = inertial.find("inertia")
        assert I is not None and mass > 0
        assert [I.get(k) for k in ("ixy", "ixz", "iyz")] == ["0", "0", "0"]  # principal axes
        assert is_physical([float(I.get(k, "nan")) for k in ("ixx", "iyy", "izz")]), link.get(
            "name"
        )
    pm = pin.buildModelFromUrdf(str(path))
    pd = pm.createData()
    q = pin.neutral(pm)
    assert sum(pm.inertias[i].mass for i in range(pm.njoints)) > 0
    assert np.all(np.isfinite(pin.aba(pm, pd, q, np.zeros(pm.nv), np.zeros(pm.nv))))
    mm = mujoco.MjModel.from_xml_path(str(path))
    md = mujoco.MjData(mm)
    mujoco.mj_step(mm, md, nstep=int(0.1 / mm.opt.timestep))
    assert np.all(np.isfinite(md.qpos)) and np.all(np.isfinite(md.qvel))
    assert mm.ngeom > 0 and np.any(mm.geom_contype > 0)  # collisions exist, visuals kept too
    with captured_output():
        import pybullet as pb

        client = pb.connect(pb.DIRECT)
    try:
        body = pb.loadURDF(str(path), useFixedBase=True, physicsClientId=client)
        pb.setGravity(0, 0, -9.81, physicsClientId=client)
        for _ in range(24):
            pb.stepSimulation(physicsClientId=client)
        states = pb.getJointStates(
            body, list(range(pb.getNumJoints(body, physicsClientId=client))), physicsClientId=client
        )
        assert np.all(np.isfinite([s[0] for s in states]))
    finally:
        pb.disconnect(physicsClientId=client)


@pytest.mark.parametrize("case", ["nominal", "calibrated"])
def test_world_is_gravity_aligned_where_the_spec_says_which_way_is_up(
    exported: dict[str, tuple[CPCModel, Path]], case: str
) -> None:
    """The IIS-head spec says ``"up": {"joint": "pan"}``: in MuJoCo (gravity along -z of the root)
    the pan axis is +z at zero readings, for the nominal and the identified head alike, while the
    rig mount keeps the model's world (the pan axis along the rig's direction of it)."""
    import mujoco

    _, path = exported[case]
    m = mujoco.MjModel.from_xml_path(str(path))
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    pan = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "pan")
    assert np.max(np.abs(d.xaxis[pan] - [0.0, 0.0, 1.0])) < CONSUMER_TOL
    assert np.all(
        d.xpos[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "base")] == 0.0
    )  # the base origin is world's
    rig, rig_path = exported["nominal_rig"]
    mr = mujoco.MjModel.from_xml_path(str(rig_path))
    dr = mujoco.MjData(mr)
    mujoco.mj_kinematics(mr, dr)
    axis = rig.joint_axes_world(np.zeros(rig.structure.n_joints))[1][
        0, rig.structure.joint_index("pan")
    ]
    assert (
        np.max(np.abs(dr.xaxis[mujoco.mj_name2id(mr, mujoco.mjtObj.mjOBJ_JOINT, "pan")] - axis))
        < CONSUMER_TOL
    )
    assert abs(axis[2]) < 1e-12  # the nominal model's world has the head on its side


def test_export_names_where_the_physical_properties_came_from(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A calibrated model file finds its robot's density and up through its provenance."""
    robot = load_robot("iis_head")
    assert robot.physical.density == 2700.0 and robot.physical.up_joint == "pan"
    model_file = _calibrated(tmp_path)
    assert main(["export", str(model_file), "-o", str(tmp_path / "c.urdf")]) == 0
    out = capsys.readouterr().out
    assert "physical properties from robot iis_head" in out and "up = +axis of joint 'pan'" in out
    assert "2700 kg/m^3" in (tmp_path / "c.urdf").read_text()
