"""Real robots end to end: URDFs no one here wrote, from pip packages.

For TIAGo's head (``torso_lift_joint`` prismatic, ``head_1_joint``, ``head_2_joint``; a
``calib_plate`` link added on ``head_2_link``), TALOS's head (``torso_1/2``, ``head_1/2``;
its own RGB-D optical frame measured) and iCub's neck on its torso (``torso_pitch/roll/yaw``,
``neck_pitch/roll/yaw``; the icub-models URDFs have no eye joints, so two camera links are added on
``head`` with fixed joints): a seeded perturbed true robot is measured with the one-joint-at-a-time
protocol (:func:`~cpc2urdf.identification.simulation.stage1_experiment.simulate_experiment`, Fig. 10
noise), identified by the default pipeline with its consistency gate (``cpc2urdf.api.identify``),
written back into the URDF (``cpc2urdf.api.export_urdf``), and the written file is read back by
Pinocchio and checked:

- the measured links at held-out configurations are within the error the model's covariance
  predicts: observed / predicted RMS within the central 99.99 % of its distribution under that
  covariance (:func:`heldout_ratio_bounds`, two-sided);
- every other URDF element is unchanged (the parsed XML trees, and yourdfpy's parsed links and
  joints): only the calibrated joints' ``<origin>`` (and a non-unit ``<axis>``) differ;
- every link frame on the measured paths is within :data:`LINK_FACTOR` x its own true geometric
  error of the true link, that error being the larger of the nominal's distance with the nominal
  placed at the true base and with it placed on the measured link (the frames stay on the parts;
  :func:`link_errors`, docs/urdf.md "How close the links are");
- noise-free data give the measured links exactly (:data:`EXACT`);
- the consumer matrix (``consumer_checks.py``): the written file loads in Pinocchio, yourdfpy,
  urdfdom's ``check_urdf``, MuJoCo and PyBullet exactly as the original does (same printed output,
  same success), FK of every link agrees with Pinocchio to 1e-12 and Pinocchio's ``aba`` is finite.

More seeds than the tests run, with every number (``--json FILE``: every link of every run):
``PYTHONPATH=. python tests/test_real_robots.py --seeds 20``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shutil
import sys
import sysconfig
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from consumer_checks import (
    CONSUMER_TOL,
    CONSUMERS,
    LOADERS,
    fk_disagreement,
    links,
    load_pinocchio,
    package_folder,
)

from cpc2urdf import api
from cpc2urdf.identification.kinematics.parametrization import Parametrization
from cpc2urdf.identification.kinematics.uncertainty import (
    covariance_of_model,
    predicted_position_std,
)
from cpc2urdf.identification.simulation.stage1_experiment import Experiment, simulate_experiment
from cpc2urdf.model import CPCModel
from cpc2urdf.transforms import Array
from cpc2urdf.urdf.origins import WritebackPlan, writeback_plan
from cpc2urdf.urdf.robot import UrdfRobot, load_urdf_robot

SHARE = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix/share"  # example-robot-data
ICUB_SHARE = Path(sys.prefix, "share")  # icub-models
PACKAGES = {"example-robot-data": SHARE / "example-robot-data", "iCub": ICUB_SHARE / "iCub"}

# Held-out RMS error of the measured links / the predicted RMS: two-sided, within the central
# 1 - HELDOUT_ALPHA of its distribution under the model's covariance (:func:`heldout_ratio_bounds`).
# The N_HELDOUT x frames points are not independent (every error comes from the same 16-36
# parameter errors), so the RMS is not chi with 3 x 30 x frames = 90-180 dof (bounds 0.74-1.29 at
# 99.9 %, which the 20-seed run leaves: 0.62-1.65); the squared ratio is sum(mu_i z_i^2) / sum(mu_i),
# mu_i the eigenvalues of the stacked held-out position covariance: effective dof
# (sum mu)^2 / sum mu^2 of 8.6-10.0 (TIAGo), 11.3-13.2 (TALOS), 16.9-18.7 (iCub). HELDOUT_ALPHA = 1e-4:
# a false alarm in the 60 runs of ``--seeds 20`` below 1 %; bounds about [0.30, 2.0] (TIAGo),
# [0.36, 1.9] (TALOS), [0.47, 1.75] (iCub); measured 0.58-1.55, 0.71-1.36, 0.66-1.65, none outside.
# At 1e-3 iCub's seed 10 (1.65) would leave its 1.61. Numbers: docs/urdf.md.
HELDOUT_ALPHA = 1e-4
CHUNK = 100_000  # draws of the ratio's distribution at a time
LINK_FACTOR = 3.0  # [-]: every link within this x its true geometric error (see link_errors)
EXACT = 1e-9  # [m]: noise-free data, measured links of the written file vs the truth
SIGMA_T = 0.5e-3  # [m]: Fig. 10 noise per translation entry (the paper's rig)
SIGMA_R = np.radians(0.5)  # [rad]
M = 7  # protocol values per joint
N_HELDOUT = 30
SEEDS = (0, 1)


def _fixed_link(name: str, parent: str, xyz: str, rpy: str) -> str:
    """A link fixed to ``parent``, as a user adds a target (docs/urdf.md)."""
    return (
        f'  <link name="{name}"/>\n  <joint name="{name}_joint" type="fixed">\n'
        f'    <parent link="{parent}"/>\n    <child link="{name}"/>\n'
        f'    <origin xyz="{xyz}" rpy="{rpy}"/>\n  </joint>\n'
    )


def _with_links(source: Path, target: Path, added: str) -> Path:
    text = source.read_text()
    end = text.rindex("</robot>")
    target.write_text(text[:end] + added + text[end:])
    return target


@dataclass(frozen=True)
class RealRobot:
    """A third-party URDF with the links to measure.

    Attributes:
        source: The installed URDF.
        measured: The measured links (a link added here where the robot has none).
        added: URDF text added before ``</robot>`` (fixed target links).
    """

    source: Path
    measured: tuple[str, ...]
    added: str = ""

    def write(self, folder: Path, name: str) -> Path:
        """The URDF as the user's copy ``folder/name.urdf`` (with the added links)."""
        return _with_links(self.source, folder / f"{name}.urdf", self.added)


ROBOTS = {
    "tiago": RealRobot(
        SHARE / "example-robot-data/robots/tiago_description/robots/tiago.urdf",
        ("calib_plate",),
        _fixed_link("calib_plate", "head_2_link", "0.1 0.05 0.02", "0.1 0.2 0.3"),
    ),
    "talos": RealRobot(
        SHARE / "example-robot-data/robots/talos_data/robots/talos_reduced.urdf",
        ("rgbd_rgb_optical_frame",),
    ),
    # Two camera links on iCub's head link, 68 mm apart (a guess at the eyes; their pose is what is identified).
    "icub": RealRobot(
        ICUB_SHARE / "iCub/robots/iCubGenova04/model.urdf",
        ("l_eye_camera", "r_eye_camera"),
        _fixed_link("l_eye_camera", "head", "-0.034 0.11 0.06", "0 0 0")
        + _fixed_link("r_eye_camera", "head", "0.034 0.11 0.06", "0 0 0"),
    ),
}


@dataclass(frozen=True)
class Run:
    """One simulated calibration of a real robot, written back.

    Attributes:
        urdf: The user's URDF (input).
        robot: Its measured sub-tree.
        experiment: The true robot, its measurements and held-out set (true poses).
        model: The identified model (remembers the URDF).
        written: The calibrated URDF written back.
        plan: The write-back plan (which joints changed, the links it covers).
    """

    urdf: Path
    robot: UrdfRobot
    experiment: Experiment
    model: CPCModel
    written: Path
    plan: WritebackPlan


def calibrate(name: str, folder: Path, seed: int, *, noise: str = "fig10") -> Run:
    """Simulate, identify (default pipeline, consistency gate) and write back ``ROBOTS[name]``."""
    urdf = ROBOTS[name].write(package_folder(folder, PACKAGES), name)
    robot = load_urdf_robot(urdf, ROBOTS[name].measured)
    exp = simulate_experiment(
        robot, seed=seed, M=M, noise=noise, sigma_t=SIGMA_T, sigma_r=SIGMA_R, n_heldout=N_HELDOUT
    )
    model = api.identify(exp.measured)
    written = api.export_urdf(model, folder / f"{name}_calibrated.urdf")
    return Run(urdf, robot, exp, model, written, writeback_plan(model))


def _readings(run: Run, q: Array) -> dict[str, float]:
    names = dict(run.plan.source.joints)
    return {names[n]: float(v) for n, v in zip(run.model.structure.joint_names, q, strict=True)}


def _links_in_world(urdf: Path, run: Run, T_world_root: Array, names: list[str]) -> Array:
    """``T_world_link`` of ``names`` by Pinocchio from ``urdf`` at the held-out configurations,
    shape (N, L, 4, 4)."""
    fk, _, _ = load_pinocchio(urdf, geometry=False)
    out = []
    for q in run.experiment.heldout.q:
        poses = fk(_readings(run, q))
        out.append([T_world_root @ poses[n] for n in names])
    return np.array(out)


# ---- the measurements -----------------------------------------------------------------------


def heldout_error(run: Run) -> tuple[float, float]:
    """Observed and predicted RMS position error [m] of the measured links of the written URDF
    (Pinocchio, placed by the identified ``T_world_base``) at the held-out configurations, against
    the true poses; predicted from the model's covariance (no measuring noise: true poses)."""
    frames = list(run.model.structure.frame_names)
    measured = [run.plan.source.urdf_link(f) for f in frames]
    T = _links_in_world(run.written, run, run.model.T_world_base(), measured)
    held = run.experiment.heldout
    d = np.stack(
        [
            np.linalg.norm(T[:, k, :3, 3] - held.poses[f][:, :3, 3], axis=1)
            for k, f in enumerate(frames)
        ]
    )
    std = predicted_position_std(run.model, held.q, frames)
    return float(np.sqrt(np.mean(d**2))), float(
        np.sqrt(np.mean(np.concatenate([std[f] ** 2 for f in frames])))
    )


def heldout_ratio_bounds(
    run: Run, alpha: float = HELDOUT_ALPHA, draws: int = 2_000_000
) -> tuple[float, float, float]:
    """``(lower, upper, nu)``: the central ``1 - alpha`` interval of observed / predicted held-out RMS
    (:func:`heldout_error`) under the model's covariance, and its effective degrees of freedom.

    The stacked held-out position errors are ``G dtheta`` with ``dtheta ~ N(0, Sigma)``: the squared
    ratio is ``sum(mu_i z_i^2) / sum(mu_i)``, ``mu_i`` the eigenvalues of ``G Sigma G^T`` and ``z_i``
    standard normal; its quantiles are drawn (seeded), ``nu = (sum mu)^2 / sum mu^2``."""
    cov = covariance_of_model(run.model)
    chart = Parametrization(run.model, cov.frames)
    _, D = chart.pose_jacobian(np.zeros(chart.n_params), run.experiment.heldout.q)
    G = np.concatenate(
        [D[f][:, :3, :].reshape(-1, chart.n_params) for f in run.model.structure.frame_names]
    )
    mu = np.linalg.eigvalsh(G @ cov.matrix @ G.T)
    mu = mu[mu > mu.max() * 1e-12]
    rng = np.random.default_rng(0)
    squared = (
        np.concatenate(
            [rng.standard_normal((CHUNK, len(mu))) ** 2 @ mu for _ in range(draws // CHUNK)]
        )
        / mu.sum()
    )
    lower, upper = np.sqrt(np.quantile(squared, [alpha / 2, 1 - alpha / 2]))
    return float(lower), float(upper), float(mu.sum() ** 2 / (mu**2).sum())


def link_errors(run: Run, folder: Path) -> tuple[list[str], Array, Array, Array]:
    """Per link on the measured paths, the largest distance [m] over the held-out configurations
    of (identified link, true link) and of (nominal link, true link): all three read by Pinocchio
    from URDFs (the written one, the truth written back, the user's). The nominal is placed at the
    true base (its distance is then the robot's true geometric error, as in test_gauge.py); the
    last array places it instead, at each configuration, with its first measured link on the
    truth's (the error as seen from the measured end, which the links near the root follow)."""
    truth = run.experiment.truth
    truth_urdf = api.export_urdf(truth, folder / "truth.urdf")
    names = list(run.plan.placements)
    ident = _links_in_world(run.written, run, run.model.T_world_base(), names)
    true = _links_in_world(truth_urdf, run, truth.T_world_base(), names)
    nominal = _links_in_world(run.urdf, run, truth.T_world_base(), names)
    k = names.index(run.robot.measured[0])
    anchored = np.einsum("nij,nljk->nlik", true[:, k] @ np.linalg.inv(nominal[:, k]), nominal)

    def dist(A: Array, B: Array) -> Array:
        return np.asarray(np.linalg.norm(A[..., :3, 3] - B[..., :3, 3], axis=-1).max(axis=0))

    return names, dist(ident, true), dist(nominal, true), dist(anchored, true)


# ---- the tests --------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> Callable[[str, int], Run]:
    cache: dict[tuple[str, int], Run] = {}

    def get(name: str, seed: int) -> Run:
        if (name, seed) not in cache:
            cache[name, seed] = calibrate(name, tmp_path_factory.mktemp(f"{name}_{seed}"), seed)
        return cache[name, seed]

    return get


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("name", ROBOTS)
def test_heldout_measured_links_within_the_predicted_error(
    runs: Callable[[str, int], Run], name: str, seed: int
) -> None:
    run = runs(name, seed)
    assert (
        run.model.metadata.uncertainty is not None
        and run.model.metadata.uncertainty.scale == "known"
    )
    observed, predicted = heldout_error(run)
    lower, upper, nu = heldout_ratio_bounds(run)
    assert lower * predicted <= observed <= upper * predicted, (
        f"{name} seed {seed}: observed {observed * 1e3:.3f} mm, predicted {predicted * 1e3:.3f} mm "
        f"(ratio {observed / predicted:.2f}, outside [{lower:.2f}, {upper:.2f}], nu {nu:.1f})"
    )


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("name", ROBOTS)
def test_every_link_stays_on_its_part(
    runs: Callable[[str, int], Run], name: str, seed: int, tmp_path: Path
) -> None:
    names, ident, at_base, anchored = link_errors(runs(name, seed), tmp_path)
    assert at_base.max() > 1e-3  # the truth is millimetres from the drawing
    # Per link, against the larger of its two true errors: a root-fixed link is 0 from the truth at the
    # true base, yet its identified pose follows the measured end (the gauge keeps the nominal's shape),
    # and a measured link is 0 from the truth once anchored there (docs/urdf.md).
    true_error = np.maximum(at_base, anchored)
    ratio = ident / true_error
    worst = int(np.argmax(ratio))
    assert ratio.max() <= LINK_FACTOR, (
        f"{name} seed {seed}: link {names[worst]} {ident[worst] * 1e3:.2f} mm from the true part; its true error is "
        f"{at_base[worst] * 1e3:.2f} mm at the true base, {anchored[worst] * 1e3:.2f} mm anchored on the measured link"
    )


def _xml(path: Path) -> ET.Element:
    return ET.parse(
        path, parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    ).getroot()


def _same_xml(a: ET.Element, b: ET.Element, skip: tuple[str, ...] = ()) -> bool:
    """Tag, attributes, text and children equal (children tagged ``skip`` left out)."""
    ka = [c for c in a if c.tag not in skip]
    kb = [c for c in b if c.tag not in skip]
    return (
        (a.tag, a.attrib, (a.text or "").strip(), (a.tail or "").strip())
        == (b.tag, b.attrib, (b.text or "").strip(), (b.tail or "").strip())
        and len(ka) == len(kb)
        and all(_same_xml(x, y) for x, y in zip(ka, kb, strict=True))
    )


def _same_parsed(a: Any, b: Any, skip: tuple[str, ...] = ()) -> bool:
    """yourdfpy's parsed elements equal field by field (arrays exactly)."""
    if dataclasses.is_dataclass(a) and dataclasses.is_dataclass(b):
        return type(a) is type(b) and all(
            _same_parsed(getattr(a, f.name), getattr(b, f.name))
            for f in dataclasses.fields(a)
            if f.name not in skip
        )
    if isinstance(a, list | tuple) and isinstance(b, list | tuple):
        return len(a) == len(b) and all(_same_parsed(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return bool(np.array_equal(a, b))
    return bool(a == b)


@pytest.mark.parametrize("name", ROBOTS)
def test_only_the_calibrated_joints_change(runs: Callable[[str, int], Run], name: str) -> None:
    import yourdfpy

    run = runs(name, SEEDS[0])
    calibrated = {c.joint.name for c in run.plan.changes}
    moving = {
        j for j in run.plan.source.kinematics if run.plan.source.kinematics[j]["type"] != "fixed"
    }
    assert moving <= calibrated and set(run.robot.measured) <= {
        c.joint.child for c in run.plan.changes
    }
    before, after = _xml(run.urdf), _xml(run.written)
    assert len(before) == len(after)
    changed = set()
    for x, y in zip(before, after, strict=True):
        if _same_xml(x, y):
            continue
        assert x.tag == "joint" and x.get("name") in calibrated, f"{x.tag} {x.get('name')} changed"
        assert _same_xml(x, y, skip=("origin", "axis")), (
            f"joint {x.get('name')}: more than origin/axis changed"
        )
        changed.add(x.get("name"))
    assert changed == calibrated  # noisy data move every calibrated origin
    kw: dict[str, Any] = dict(
        load_meshes=False, build_collision_scene_graph=False, load_collision_meshes=False
    )
    a, b = yourdfpy.URDF.load(str(run.urdf), **kw), yourdfpy.URDF.load(str(run.written), **kw)
    assert list(a.link_map) == list(b.link_map) and list(a.joint_map) == list(b.joint_map)
    assert all(
        _same_parsed(a.link_map[n], b.link_map[n]) for n in a.link_map
    )  # inertials, visuals, collisions
    for n in a.joint_map:
        skip = ("origin", "axis") if n in calibrated else ()
        assert _same_parsed(a.joint_map[n], b.joint_map[n], skip), n
    assert _same_parsed(a.robot.materials, b.robot.materials)
    assert sum(
        not np.array_equal(a.joint_map[n].origin, b.joint_map[n].origin) for n in calibrated
    ) == len(calibrated)


@pytest.mark.parametrize("name", ROBOTS)
def test_noise_free_data_give_the_measured_links_exactly(name: str, tmp_path: Path) -> None:
    run = calibrate(name, tmp_path, seed=5, noise="none")
    frames = list(run.model.structure.frame_names)
    T = _links_in_world(
        run.written, run, run.model.T_world_base(), [run.plan.source.urdf_link(f) for f in frames]
    )
    held = run.experiment.heldout
    for k, f in enumerate(frames):
        assert np.abs(T[:, k] - held.poses[f]).max() < EXACT, f


# ---- the consumer matrix -----------------------------------------------------------------------

# How each consumer reads the files: (packages given?, loader options). MuJoCo's URDF importer does
# not resolve package:// (it opens 'package:/NAME/...'): read as is, the original and the written
# file fail alike. Through MjSpec with the meshes resolved in memory TALOS and iCub load (their
# static links fused into bodies, MuJoCo's URDF default), and with fusestatic off every link is a
# body. TIAGo's COLLADA (.dae) collision meshes have no MuJoCo decoder; with those geoms dropped in
# memory MuJoCo refuses the inertia of its base_antenna_left_link ("inertia must have positive
# eigenvalues"), for the original and the written file alike. The last mode compares MuJoCo's
# kinematic tree alone (geoms dropped, one valid inertia for every body, in memory): every link of
# every robot, TIAGo's included.
MODES: dict[str, list[tuple[bool, dict[str, bool]]]] = {
    "mujoco": [
        (False, {}),
        (True, {}),
        (True, {"keep_links": True}),
        (True, {"drop_undecodable": True}),
        (True, {"keep_links": True, "drop_undecodable": True}),
        (True, {"keep_links": True, "kinematics_only": True}),
    ]
}


def _load(consumer: str, path: Path, packages: bool, **kw: bool) -> tuple[Any, str]:
    """``(loaded or the exception, what was printed / raised)``, file paths replaced by ``FILE``;
    ``packages``: the packages are found in the URDF's folder (``package_folder``)."""
    try:
        loaded = LOADERS[consumer](path, [path.parent] if packages else [], **kw)
        said = loaded[1]
    except Exception as e:  # compared between the original and the written file
        loaded, said = e, f"{type(e).__name__}: {e}"
    return loaded, said.replace(str(path), "FILE").replace(path.name, "FILE")


@pytest.mark.parametrize("consumer", CONSUMERS)
@pytest.mark.parametrize("name", ROBOTS)
def test_written_urdf_loads_as_the_original_and_agrees(
    runs: Callable[[str, int], Run],
    name: str,
    consumer: str,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The written file loads exactly as the user's (same output, same success or the same error);
    where it loads, every link it has agrees with Pinocchio's FK of the written file to 1e-12."""
    run = runs(name, SEEDS[0])
    monkeypatch.chdir(tmp_path)  # MuJoCo would write MUJOCO_LOG.TXT here on a warning
    compared = 0
    for packages, kw in MODES.get(consumer, [(True, {})]):
        original, said_original = _load(consumer, run.urdf, packages, **kw)
        written, said_written = _load(consumer, run.written, packages, **kw)
        assert said_written == said_original, (
            f"{consumer} {kw}: written file says\n{said_written[:800]}\n"
            f"the original says\n{said_original[:800]}"
        )
        if isinstance(original, Exception):
            assert isinstance(written, Exception)
            continue
        fk, _, close = written
        try:
            if fk is None:  # check_urdf: no poses
                compared += 1
                continue
            s = run.model.structure
            Q = np.vstack(
                [
                    s.lower,
                    s.upper,
                    np.random.default_rng(7).uniform(s.lower, s.upper, (8, s.n_joints)),
                ]
            )
            configurations = [_readings(run, q) for q in Q]
            refused = _refusal(original[0], configurations[0])
            if refused is not None:  # PyBullet on iCub (> 128 links): no poses from either file
                assert _refusal(fk, configurations[0]) == refused
                continue
            reference, _, _ = load_pinocchio(run.written, geometry=False)
            names = links(run.written)
            if consumer == "mujoco" and not kw.get(
                "keep_links"
            ):  # fusestatic: links on fixed joints merge
                names = [n for n in names if n in fk(configurations[0])]
                assert {c.joint.child for c in run.plan.changes if c.role == "joint"} <= set(names)
            dp, dr, where = fk_disagreement(fk, reference, names, configurations)
            assert dp < CONSUMER_TOL and dr < CONSUMER_TOL, (
                f"{consumer} {name}: {dp:.2e} m, {dr:.2e} rad, {where}"
            )
            compared += 1
        finally:
            close()
            original[2]()
    assert compared or (consumer, name) == ("pybullet", "icub"), (
        "no way to load it compared anything"
    )


def _refusal(fk: Callable[[dict[str, float]], Any], q: dict[str, float]) -> str | None:
    """What ``fk(q)`` raises, or None."""
    try:
        fk(q)
    except Exception as e:  # compared between the original and the written file
        return f"{type(e).__name__}: {e}"
    return None


@pytest.mark.parametrize("name", ROBOTS)
def test_written_urdf_dynamics_are_usable(runs: Callable[[str, int], Run], name: str) -> None:
    import pinocchio as pin

    run = runs(name, SEEDS[0])
    model = pin.buildModelFromUrdf(str(run.written))
    data = model.createData()
    assert sum(model.inertias[i].mass for i in range(model.njoints)) > 0
    q = pin.neutral(model)
    assert np.all(np.isfinite(pin.aba(model, data, q, np.zeros(model.nv), np.zeros(model.nv))))


# ---- more seeds, by a command ------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    """Every number of the checks above over more seeds (no assertion): one line per run."""
    import tempfile

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=10)
    p.add_argument("--robot", choices=list(ROBOTS), action="append")
    p.add_argument("--json", type=Path, help="also write every per-link number here")
    args = p.parse_args(argv)
    dump: dict[str, Any] = {}
    print(
        "robot  seed  held-out RMS obs / pred [mm]  ratio [bounds] nu | worst link: identified / true error [mm] | "
        "max identified / max true error: nominal at the true base, anchored on the measured link"
    )
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.robot or list(ROBOTS):
            ratios, link_ratios, anchored_ratios, per_link, outside = [], [], [], [], 0
            for seed in range(args.seeds):
                folder = Path(tmp, f"{name}_{seed}")
                run = calibrate(name, folder, seed)
                obs, pred = heldout_error(run)
                lower, upper, nu = heldout_ratio_bounds(run)
                names, ident, true_error, anchored = link_errors(run, folder)
                dump.setdefault(name, []).append(
                    {
                        "seed": seed,
                        "observed": obs,
                        "predicted": pred,
                        "lower": lower,
                        "upper": upper,
                        "nu": nu,
                        "links": names,
                        "identified": ident.tolist(),
                        "true": true_error.tolist(),
                        "anchored": anchored.tolist(),
                    }
                )
                w = int(np.argmax(ident / np.maximum(true_error, 1e-15)))
                ratios.append(obs / pred)
                outside += not lower <= obs / pred <= upper
                per_link.append(ident / np.maximum(true_error, anchored))
                link_ratios.append(ident.max() / true_error.max())
                anchored_ratios.append(ident.max() / anchored.max())
                print(
                    f"{name:6s} {seed:4d}  {obs * 1e3:6.3f} / {pred * 1e3:6.3f}  {obs / pred:5.2f} "
                    f"[{lower:.2f}, {upper:.2f}] nu {nu:4.1f} | "
                    f"{names[w]} {ident[w] * 1e3:.2f} / {true_error[w] * 1e3:.2f} | "
                    f"{link_ratios[-1]:5.2f} {anchored_ratios[-1]:5.2f}"
                )
                shutil.rmtree(folder)
            print(
                f"{name}: held-out ratio mean {np.mean(ratios):.2f} max {np.max(ratios):.2f} "
                f"(RMS of ratios {np.sqrt(np.mean(np.square(ratios))):.2f}); max identified / max true error: "
                f"at the true base max {np.max(link_ratios):.2f}, anchored max {np.max(anchored_ratios):.2f}; "
                f"{outside} held-out ratio(s) outside the bounds; per link, identified / the larger true error: "
                f"max {np.max(per_link):.2f}"
            )
            if args.json:
                args.json.write_text(json.dumps(dump))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
