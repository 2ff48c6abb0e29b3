"""Measuring a plan in simulation, identifying, and the held-out error: the prediction's check.

:func:`simulate_plan` is :func:`~cpc2urdf.identification.simulation.stage1_experiment.simulate_experiment`
for any list of configurations: the same random streams (``seed`` spawns the true geometry, the
noise and the held-out streams, in that order), so a plan and the protocol measured with the same
seed measure the same true robot; the robot is placed as :func:`~cpc2urdf.identification.planning.
measuring.measuring_setup` placed it. Held-out configurations are the task region's, with their
true poses. :func:`heldout_errors` identifies (``refined``: from the closed form when the plan is
one joint at a time, else from the nominal model placed in world) and returns the errors of the
identified frames against the truth.

:func:`simulate_from_plan` does the same for a plan file (``cpc2urdf simulate --plan``).

Example::

    exp = simulate_plan(setup, plan.q, plan.labels, seed=3, q_heldout=q_task)
    errors = heldout_errors(exp, setup.nominal)     # position [m], angle [rad] per config and frame
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import ConfigurationError, DegenerateDataError
from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.identification.kinematics.methods import identify_refined
from cpc2urdf.identification.kinematics.points.circle_point import marker_sigma, nominal_point_start
from cpc2urdf.identification.kinematics.points.point_identify import (
    identify_points,
    marker_positions,
)
from cpc2urdf.identification.kinematics.points.point_refine import refine_points
from cpc2urdf.identification.planning.marker_setup import MarkerMeasurement
from cpc2urdf.identification.planning.measuring import MeasuringSetup, measuring_setup
from cpc2urdf.identification.planning.plan_file import LoadedPlan
from cpc2urdf.identification.simulation.marker_points import simulate_markers
from cpc2urdf.identification.simulation.measure_poses import measure_poses
from cpc2urdf.identification.simulation.stage1_experiment import DEFAULT_HELDOUT, Experiment
from cpc2urdf.identification.simulation.truth import (
    DEFAULT_GEOMETRY_ERROR_R,
    DEFAULT_GEOMETRY_ERROR_T,
    perturbed_model,
)
from cpc2urdf.identification.simulation.visibility import visible_heldout
from cpc2urdf.model import CPCModel, CPCParams
from cpc2urdf.transforms import rotation_error

Array = NDArray[np.float64]

PLAN_NOISE_MODELS = ("fig10", "stereo", "none")


def simulate_plan(
    setup: MeasuringSetup,
    q: ArrayLike,
    labels: Sequence[str] | None = None,
    *,
    seed: int = 0,
    noise: str = "fig10",
    geometry_error_t: float = DEFAULT_GEOMETRY_ERROR_T,
    geometry_error_r: float = DEFAULT_GEOMETRY_ERROR_R,
    q_heldout: ArrayLike | None = None,
    require_view: bool = True,
    robot_ref: str | None = None,
) -> Experiment:
    """Simulate measuring the configurations ``q`` (N, n) of a plan with ``setup``.

    Args:
        setup: The measuring setup (nominal robot placed in front of the rig, Fig. 10 noise sigmas).
        q: The plan's configurations [m]/[rad], shape (N, n).
        labels: One per configuration (default ``"plan i"``).
        seed: Seed of the true robot, the noise and nothing else (held-out configurations are given).
        noise: ``"fig10"`` (the setup's sigmas), ``"stereo"`` (the setup's pixel noise through its rig)
            or ``"none"``; the prediction assumes the setup's own model (``setup.noise``).
        geometry_error_t: True robot: std of each CPC offset component's error [m].
        geometry_error_r: True robot: std of each placement's rotation error [rad].
        q_heldout: Held-out configurations (true poses), shape (K, n) (default: none).
        require_view: Refuse a plan the rig does not see completely on the true robot.
        robot_ref: Robot reference written into the measurement sets.

    Raises:
        ConfigurationError: Bad arguments, or (``require_view``) a configuration in which the rig
            does not see every circle of every measured frame of the true robot (named).
    """
    if noise not in PLAN_NOISE_MODELS:
        raise ConfigurationError(f"noise model must be one of {PLAN_NOISE_MODELS}, got {noise!r}")
    nominal = setup.nominal
    s = nominal.structure
    qq = np.atleast_2d(np.asarray(q, dtype=float))
    if qq.shape[1] != s.n_joints or not np.all(np.isfinite(qq)):
        raise ConfigurationError(
            f"plan: expected finite configurations of {s.n_joints} joint values, got shape {qq.shape}"
        )
    labs = list(labels) if labels is not None else [f"plan {i}" for i in range(len(qq))]
    frames = list(setup.frames)
    rng_geometry, rng_noise, _ = (
        np.random.default_rng(c) for c in np.random.SeedSequence(seed).spawn(3)
    )
    truth = perturbed_model(nominal, rng_geometry, geometry_error_t, geometry_error_r)
    problems = setup.problems(qq, labs, model=truth)  # the simulator's own limits, on the truth
    if require_view and problems:
        more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
        raise ConfigurationError(f"the rig does not see {problems[0]}{more}")
    poses, _ = measure_poses(
        truth,
        qq,
        frames,
        rng_noise,
        noise=noise,
        sigma_t=setup.sigma_t,
        sigma_r=setup.sigma_r,
        rig=setup.rig,
        pixel_sigma=setup.pixel_sigma,
    )
    noise_doc: dict[str, Any] = {"model": noise}
    if noise == "fig10":
        noise_doc.update(sigma_t_m=setup.sigma_t, sigma_r_rad=setup.sigma_r)
    elif (
        noise == "stereo"
    ):  # as simulate_experiment: no pose sigma stated (the identification's defaults)
        noise_doc.update(pixel_sigma_px=setup.pixel_sigma)
    provenance = {
        "simulator": "cpc2urdf.identification.planning.experiment",
        "seed": seed,
        "protocol": "a plan (cpc2urdf plan)",
        "geometry_error": {"sigma_t_m": geometry_error_t, "sigma_r_rad": geometry_error_r},
        "rig": setup.rig.to_json(),
        "view": {"problems": problems[:10]},
    }
    ref = robot_ref or s.name
    measured = MeasurementSet.from_arrays(
        s,
        qq,
        poses,
        robot=ref,
        labels=labs,
        source="<simulated plan>",
        metadata={
            "description": f"simulated measurements of a plan for {s.name}",
            "noise": noise_doc,
            "provenance": provenance,
        },
    )
    qh = (
        np.zeros((0, s.n_joints))
        if q_heldout is None
        else np.atleast_2d(np.asarray(q_heldout, dtype=float))
    )
    held_true = truth.fk(qh, frames) if len(qh) else {f: np.empty((0, 4, 4)) for f in frames}
    heldout = MeasurementSet.from_arrays(
        s,
        qh,
        held_true,
        robot=ref,
        labels=[f"heldout {i}" for i in range(len(qh))],
        source="<simulated heldout>",
        metadata={
            "description": f"held-out configurations of {s.name} with TRUE poses",
            "noise": {"model": "none"},
        },
    )
    return Experiment(truth, measured, heldout)


def simulate_from_plan(
    nominal: CPCModel,
    plan: LoadedPlan,
    *,
    seed: int = 0,
    noise: str | None = None,
    sigma_t: float | None = None,
    sigma_r: float | None = None,
    pixel_sigma: float | None = None,
    geometry_error_t: float = DEFAULT_GEOMETRY_ERROR_T,
    geometry_error_r: float = DEFAULT_GEOMETRY_ERROR_R,
    n_heldout: int = DEFAULT_HELDOUT,
    require_view: bool = True,
    robot_ref: str | None = None,
) -> Experiment:
    """``cpc2urdf simulate --plan``: measure a plan file's configurations from where the plan put
    the robot, with the plan's rig (and noise, unless given); held-out configurations drawn as
    :func:`simulate_experiment` draws them (uniform in the plan's calibration ranges, so a joint the
    plan held still stays still; redrawn until the rig sees them, from the seed's held-out stream).

    Args:
        nominal: The robot's nominal model (its joints are the plan's; see :func:`load_plan`).
        plan: The loaded plan.
        seed: Seed of the true robot, the noise and the held-out configurations.
        noise: ``"fig10"``, ``"stereo"`` or ``"none"`` (default: the plan's model).
        sigma_t: Translation noise [m] (default: the plan's).
        sigma_r: Rotation noise angle [rad] (default: the plan's).
        pixel_sigma: Stereo pixel noise [px] (default: the plan's).
        geometry_error_t: True robot: std of each CPC offset component's error [m].
        geometry_error_r: True robot: std of each placement's rotation error [rad].
        n_heldout: Held-out configurations.
        require_view: Refuse a plan the rig does not see completely on the true robot.
        robot_ref: Robot reference written into the measurement sets.
    """
    setup = measuring_setup(
        nominal,
        rig=plan.rig,
        ranges=plan.ranges,
        sigma_t=plan.sigma_t if sigma_t is None else sigma_t,
        sigma_r=plan.sigma_r if sigma_r is None else sigma_r,
        frames=plan.measured_frames,
        world_to_base=CPCParams.from_matrix(plan.T_world_base),
        noise="stereo" if (noise or plan.noise) == "stereo" else "fig10",
        pixel_sigma=plan.pixel_sigma if pixel_sigma is None else pixel_sigma,
    )
    truth = perturbed_model(
        setup.nominal,
        np.random.default_rng(np.random.SeedSequence(seed).spawn(3)[0]),
        geometry_error_t,
        geometry_error_r,
    )
    rng_heldout = np.random.default_rng(np.random.SeedSequence(seed).spawn(3)[2])
    q_held, _ = visible_heldout(
        truth, setup.rig, setup.ranges, n_heldout, setup.frames, rng_heldout
    )
    return simulate_plan(
        setup,
        plan.q,
        plan.labels,
        seed=seed,
        noise=noise or plan.noise,
        geometry_error_t=geometry_error_t,
        geometry_error_r=geometry_error_r,
        q_heldout=q_held,
        require_view=require_view,
        robot_ref=robot_ref or plan.robot,
    )


@dataclass
class MarkerExperiment:
    """A marker plan measured in simulation.

    Attributes:
        truth: The true robot.
        measured: Marker points at the plan's configurations, with noise (``cpc2urdf/measurements@2``).
        markers: Marker name -> (frame, true position in the frame [m]).
        q_heldout: Held-out configurations, shape (K, n).
    """

    truth: CPCModel
    measured: MeasurementSet
    markers: dict[str, tuple[str, Array]]
    q_heldout: Array


def simulate_plan_markers(
    setup: MeasuringSetup,
    q: ArrayLike,
    labels: Sequence[str] | None = None,
    *,
    seed: int = 0,
    q_heldout: ArrayLike | None = None,
    geometry_error_t: float = DEFAULT_GEOMETRY_ERROR_T,
    geometry_error_r: float = DEFAULT_GEOMETRY_ERROR_R,
) -> MarkerExperiment:
    """Measure a marker plan: the setup's markers (``setup.markers`` per frame, placed with its
    ``marker_seed``, fixed to the robot like a real setup's) on the true robot of ``seed`` (the same
    true robot as :func:`simulate_plan`'s), their points with ``setup.marker_sigma`` noise from the
    seed's noise stream.

    Raises:
        ConfigurationError: The setup has no markers, or configurations of the wrong shape.
    """
    meas = setup.measurement()
    if not isinstance(meas, MarkerMeasurement):
        raise ConfigurationError(
            "the measuring setup has no markers (markers per frame must be >= 1)"
        )
    s = setup.nominal.structure
    qq = np.atleast_2d(np.asarray(q, dtype=float))
    if qq.shape[1] != s.n_joints or not np.all(np.isfinite(qq)):
        raise ConfigurationError(
            f"plan: expected finite configurations of {s.n_joints} joint values, got shape {qq.shape}"
        )
    rng_geometry, rng_noise, _ = (
        np.random.default_rng(c) for c in np.random.SeedSequence(seed).spawn(3)
    )
    truth = perturbed_model(setup.nominal, rng_geometry, geometry_error_t, geometry_error_r)
    ms = simulate_markers(
        truth, meas.markers, qq, sigma_p=setup.marker_sigma, rng=rng_noise, robot=s.name
    )
    labs = list(labels) if labels is not None else [f"plan {i}" for i in range(len(qq))]
    ms = dataclasses.replace(ms, labels=labs, source="<simulated marker plan>")
    qh = (
        np.zeros((0, s.n_joints))
        if q_heldout is None
        else np.atleast_2d(np.asarray(q_heldout, dtype=float))
    )
    return MarkerExperiment(truth, ms, meas.markers, qh)


def heldout_point_errors(exp: MarkerExperiment, nominal: CPCModel) -> tuple[Array, str]:
    """Identify the marker points and return the identified markers' point errors at the held-out
    configurations against the truth, shape (K, n_markers) [m], and where the refinement started.

    :func:`identify_points` (refined, the consistency gate not enforced); where its circle-point
    start refuses the data (its circle test can reject a good marker, see docs/planning.md), the
    same refinement from the nominal model placed in world (``"nominal (circle-point refused)"``).
    """
    try:
        model = identify_points(exp.measured, "refined", nominal, accept_inconsistent=True)
        found = {m: p for m, (_, p) in marker_positions(model).items()}
        prov = model.metadata.provenance
        start = str(prov.details.get("start", "?")) if prov is not None else "?"
    except DegenerateDataError:
        sigma_p, _ = marker_sigma(exp.measured.metadata)
        m0, pos0 = nominal_point_start(nominal, exp.measured)
        res = refine_points(m0, exp.measured, pos0, sigma_p, warn=False)
        model, found, start = res.model, dict(res.positions), "nominal (circle-point refused)"
    frames = list(dict.fromkeys(f for f, _ in exp.markers.values()))
    T, Tt = model.fk(exp.q_heldout, frames), exp.truth.fk(exp.q_heldout, frames)
    out = []
    for m, (f, p_true) in exp.markers.items():
        y = T[f][:, :3, :3] @ found[m] + T[f][:, :3, 3]
        yt = Tt[f][:, :3, :3] @ p_true + Tt[f][:, :3, 3]
        out.append(np.linalg.norm(y - yt, axis=1))
    return np.stack(out, axis=1), start


@dataclass
class HeldoutErrors:
    """Errors of an identified model on held-out configurations with true poses.

    Attributes:
        position: Origin errors, shape (K, n_frames) [m].
        angle: Rotation-error angles, shape (K, n_frames) [rad].
        start: Where the refinement started (``"closed-form"`` or ``"nominal"``).
    """

    position: Array
    angle: Array
    start: str

    @property
    def position_rms(self) -> float:
        return float(np.sqrt(np.mean(self.position**2)))


def heldout_errors(exp: Experiment, nominal: CPCModel | None) -> HeldoutErrors:
    """Identify ``exp.measured`` (refined; closed-form start when it applies, else the nominal
    model placed in world) and compare with ``exp.heldout``'s true poses."""
    model = identify_refined(exp.measured, nominal)
    frames = list(exp.heldout.poses)
    T = model.fk(exp.heldout.q, frames)
    pos = np.stack(
        [np.linalg.norm(T[f][:, :3, 3] - exp.heldout.poses[f][:, :3, 3], axis=1) for f in frames],
        axis=1,
    )
    ang = np.stack(
        [rotation_error(T[f][:, :3, :3], exp.heldout.poses[f][:, :3, :3]) for f in frames], axis=1
    )
    prov = model.metadata.provenance
    start = str(prov.details.get("start", "?")) if prov is not None else "?"
    return HeldoutErrors(pos, ang, start)


__all__ = [
    "PLAN_NOISE_MODELS",
    "HeldoutErrors",
    "MarkerExperiment",
    "heldout_errors",
    "heldout_point_errors",
    "simulate_from_plan",
    "simulate_plan",
    "simulate_plan_markers",
]
