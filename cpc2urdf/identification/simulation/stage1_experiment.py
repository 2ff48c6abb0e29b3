"""Simulated stage-1 experiments (Shih et al. sec. 4.1 protocol, sec. 6 / Fig. 10 noise).

A URDF robot is simulated as the sub-tree of its measured links
(:meth:`~cpc2urdf.urdf.robot.UrdfRobot.restricted`; ``cpc2urdf simulate robot.urdf --measure
LINK``): its records read only the joints on the paths to them, and its sets carry the robot, so
that their files use the URDF's joint and link names and identification writes back into it.

A "true" robot is the nominal model plus seeded random geometric errors (a real head is not its
drawing, :mod:`~cpc2urdf.identification.simulation.truth`). It is placed in front of a stereo rig
(world = the rig's left camera frame) so that both cameras see every circle of both plates over
the calibration range (no plate hiding another, :mod:`~cpc2urdf.identification.simulation.
placement`), and measured (:mod:`~cpc2urdf.identification.simulation.measure_poses`) with the
one-joint-at-a-time protocol of :mod:`~cpc2urdf.identification.simulation.design`: one record at
``q0`` (the middle of every joint's calibration range), then, for each joint in turn, ``M`` values
evenly spread over its calibration range with the other joints at ``q0`` (``n M + 1`` records;
6M+1 for the IIS-head). Every record measures every plate.

In memory::

    from cpc2urdf.identification.simulation.stage1_experiment import simulate_experiment
    truth, measured, heldout = simulate_experiment("iis_head", seed=1, M=9, noise="fig10",
                                                   sigma_t=0.5e-3, sigma_r=np.radians(0.5))

``truth`` is a :class:`~cpc2urdf.model.CPCModel`; ``measured`` and ``heldout`` are
:class:`~cpc2urdf.files.measurements.MeasurementSet` (held-out records carry the *true* poses).
``cpc2urdf simulate`` writes the same three things as files.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from cpc2urdf.errors import ConfigurationError
from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.files.spec import RobotSpec
from cpc2urdf.identification.simulation.design import (
    DEFAULT_M,
    calibration_ranges,
    measured_frames,
    protocol_configurations,
)
from cpc2urdf.identification.simulation.measure_poses import (
    DEFAULT_PIXEL_SIGMA,
    DEFAULT_SIGMA_R,
    DEFAULT_SIGMA_T,
    NOISE_MODELS,
    measure_poses,
)
from cpc2urdf.identification.simulation.placement import experiment_placement
from cpc2urdf.identification.simulation.truth import (
    DEFAULT_GEOMETRY_ERROR_R,
    DEFAULT_GEOMETRY_ERROR_T,
    perturbed_model,
)
from cpc2urdf.identification.simulation.visibility import ViewReport, check_view, visible_heldout
from cpc2urdf.identification.vision.stereo import StereoRig
from cpc2urdf.model import CPCModel, CPCParams, RobotStructure
from cpc2urdf.model_metadata import Provenance
from cpc2urdf.progress import progress
from cpc2urdf.urdf.robot import UrdfRobot

DEFAULT_HELDOUT = 50
OCCLUDED_VIEWS_MAX = (
    0.05  # [-]: share of (configuration, plate) views with a hidden circle tolerated
)


class Experiment(NamedTuple):
    """What :func:`simulate_experiment` returns (unpacks as ``truth, measured, heldout``)."""

    truth: CPCModel
    measured: MeasurementSet
    heldout: MeasurementSet


def _as_spec(robot: str | Path | RobotSpec | CPCModel) -> tuple[RobotSpec, str]:
    if isinstance(robot, RobotSpec):
        return robot, robot.source
    if isinstance(robot, CPCModel):
        return RobotSpec(robot.structure, robot, "<memory>"), robot.structure.name
    from cpc2urdf.files.robot_ref import load_robot

    return load_robot(robot), str(robot)


def measured_robot(
    spec: RobotSpec, ref: str, measure: Sequence[str] | None, option: str = "--measure"
) -> RobotSpec:
    """The robot to simulate: a URDF's sub-tree of the ``measure`` links (its measured plates);
    any other robot as it is. ``option`` names the argument in the messages.

    Raises:
        ConfigurationError: ``measure`` with a robot that is not a URDF, or a URDF without it.
        InputFileError: A link that is not in the URDF, is its root, or is moved by a joint
            directly (:func:`cpc2urdf.urdf.robot.urdf_robot` names it).
    """
    if not isinstance(spec, UrdfRobot):
        if measure is not None:
            raise ConfigurationError(
                f"{option} names links of a URDF robot; {ref!r} is not a URDF (its plates are measured)"
            )
        return spec
    if measure is None:
        raise ConfigurationError(
            f"{ref}: name the links the rig measures with {option} LINK [LINK ...] "
            "(plate, marker or camera links, each on a fixed joint)"
        )
    return spec.restricted(list(measure))


def simulate_experiment(
    robot: str | Path | RobotSpec | CPCModel = "iis_head",
    *,
    seed: int = 0,
    M: int = DEFAULT_M,
    noise: str = "fig10",
    sigma_t: float = DEFAULT_SIGMA_T,
    sigma_r: float = DEFAULT_SIGMA_R,
    pixel_sigma: float = DEFAULT_PIXEL_SIGMA,
    geometry_error_t: float = DEFAULT_GEOMETRY_ERROR_T,
    geometry_error_r: float = DEFAULT_GEOMETRY_ERROR_R,
    n_heldout: int = DEFAULT_HELDOUT,
    rig: StereoRig | None = None,
    ranges: Mapping[str, tuple[float, float]] | None = None,
    world_to_base: CPCParams | None = None,
    require_view: bool = True,
    robot_ref: str | None = None,
    show_progress: bool = False,
) -> Experiment:
    """Simulate a stage-1 calibration experiment in memory (no files).

    Random streams for the true geometry, the measurement noise and the held-out configurations
    are independent children of ``seed``: changing the noise keeps the same true robot.

    Args:
        robot: Shipped robot name, robot spec/model path, a :class:`RobotSpec`, or a nominal
            :class:`CPCModel`. Needs nominal geometry.
        seed: Seed of everything random.
        M: Values per joint in the one-joint-at-a-time protocol (n M + 1 records).
        noise: ``"fig10"``, ``"stereo"`` or ``"none"``.
        sigma_t: Fig. 10 translation noise per entry [m].
        sigma_r: Fig. 10 rotation noise angle [rad].
        pixel_sigma: Stereo pixel noise per coordinate [px].
        geometry_error_t: Std of each component of each CPC offset error of the true robot [m].
        geometry_error_r: Std of the rotation error angle of each CPC placement [rad].
        n_heldout: Number of random held-out configurations (true poses, no noise).
        rig: The measuring rig (default :meth:`StereoRig.verged`: 600 mm baseline, 1.5 m).
        ranges: Calibration ranges per joint ``{name: (lo, hi)}`` [m]/[rad] overriding the spec.
        world_to_base: Nominal placement in the rig's world (default: :func:`clear_placement`
            over the protocol and a fixed sample of the calibration ranges, so that no plate
            hides another's circles); the true placement is this plus geometric error.
        require_view: Raise if a plate leaves the view of a camera or a circle is hidden
            (otherwise just record it).
        robot_ref: Robot reference written into the measurement sets (default: ``robot`` if
            it is a name or path).
        show_progress: Draw a progress bar on stderr.

    Returns:
        ``Experiment(truth, measured, heldout)``.

    Raises:
        ConfigurationError: A plate leaves the view of a camera, or a circle is hidden, in some
            configuration (the message names the plate and configuration), or bad arguments.
        SpecError: The robot has no nominal geometry.
    """
    _check_arguments(
        noise,
        n_heldout,
        sigma_t=sigma_t,
        sigma_r=sigma_r,
        pixel_sigma=pixel_sigma,
        geometry_error_t=geometry_error_t,
        geometry_error_r=geometry_error_r,
    )
    spec, ref = _as_spec(robot)
    ref = robot_ref or ref
    nominal = spec.nominal_model()
    s = nominal.structure
    frames = _plates_to_measure(spec, s, noise)
    rig = rig or StereoRig.verged()
    r = calibration_ranges(s, ranges)
    file_names = _file_joint_names(spec, s)
    q, labels = protocol_configurations(r, M, file_names)
    rng_geometry, rng_noise, rng_heldout = (
        np.random.default_rng(c) for c in np.random.SeedSequence(seed).spawn(3)
    )

    # The placement depends on the robot, rig and ranges only (a fixed sample), not on the seed.
    w2b = world_to_base or experiment_placement(nominal, rig, q, frames, r)
    truth = perturbed_model(
        nominal.with_params(world_to_base=w2b), rng_geometry, geometry_error_t, geometry_error_r
    )
    q_held, redrawn = visible_heldout(truth, rig, r, n_heldout, frames, rng_heldout)
    view = _checked_view(truth, rig, q, q_held, frames, labels, require_view)

    poses, points = _measure_protocol(
        truth,
        q,
        frames,
        M,
        rng_noise,
        show_progress=show_progress,
        noise=noise,
        sigma_t=sigma_t,
        sigma_r=sigma_r,
        rig=rig,
        pixel_sigma=pixel_sigma,
    )
    provenance = _provenance(
        seed, M, file_names, r, geometry_error_t, geometry_error_r, rig, view, redrawn
    )
    measured, heldout = _measurement_sets(
        spec,
        truth,
        q,
        labels,
        poses,
        points,
        q_held,
        frames,
        ref,
        _noise_doc(noise, sigma_t, sigma_r, pixel_sigma),
        provenance,
    )
    truth = _with_truth_provenance(truth, nominal, ref, seed, provenance, w2b)
    return Experiment(truth, measured, heldout)


def _plates_to_measure(spec: RobotSpec, s: RobotStructure, noise: str) -> list[str]:
    """The robot's plate frames to measure; refuses a robot without any, or stereo noise on a
    plate without a circle layout (before the placement search, in the file's names)."""
    frames = measured_frames(s)
    if not frames:
        raise ConfigurationError(f"robot {s.name!r} has no frame of kind 'plate' to measure")
    no_layout = [f for f in frames if s.frame(f).layout is None]
    if noise == "stereo" and no_layout:  # refused before the placement search, in the file's names
        name = (
            spec.names.urdf_link(no_layout[0])
            if isinstance(spec, UrdfRobot) and spec.names
            else no_layout[0]
        )
        raise ConfigurationError(
            f"stereo noise needs the circle layout of each measured plate, and {name!r} has none "
            "(a URDF link carries no layout); use fig10 or no noise"
        )
    return frames


def _file_joint_names(spec: RobotSpec, s: RobotStructure) -> list[str]:
    """The joint names the files use: a URDF robot's files name its joints as the URDF does
    (labels, provenance)."""
    return [
        spec.names.urdf_joint(n) if isinstance(spec, UrdfRobot) and spec.names else n
        for n in s.joint_names
    ]


def _checked_view(
    truth: CPCModel,
    rig: StereoRig,
    q: np.ndarray,
    q_held: np.ndarray,
    frames: list[str],
    labels: list[str],
    require_view: bool,
) -> ViewReport:
    """How the rig sees the plates of ``truth`` over the protocol and held-out configurations;
    with ``require_view``, refuses an unmeasurable experiment (:func:`_unmeasurable`)."""
    n_heldout = len(q_held)
    view = check_view(
        truth,
        rig,
        np.vstack([q, q_held]),
        frames,
        labels + [f"heldout {i}" for i in range(n_heldout)],
    )
    unmeasurable = _unmeasurable(view, len(q) + n_heldout, len(frames))
    if require_view and unmeasurable:
        more = f" (and {len(unmeasurable) - 1} more)" if len(unmeasurable) > 1 else ""
        raise ConfigurationError(
            f"the rig does not see {unmeasurable[0]}{more}; narrow the calibration ranges, "
            "widen the rig's field of view or place the robot differently"
        )
    return view


def _measure_protocol(
    truth: CPCModel,
    q: np.ndarray,
    frames: list[str],
    M: int,
    rng_noise: np.random.Generator,
    *,
    show_progress: bool,
    noise: str,
    sigma_t: float,
    sigma_r: float,
    rig: StereoRig,
    pixel_sigma: float,
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Measured plate poses and circle points at the protocol's configurations ``q``, measured
    joint by joint so that a long run shows progress (the protocol's blocks)."""
    n_joints = truth.structure.n_joints
    blocks = [np.arange(1)] + [1 + i * M + np.arange(M) for i in range(n_joints)]
    items = progress(blocks, "simulate") if show_progress else blocks
    parts = [
        measure_poses(
            truth,
            q[b],
            frames,
            rng_noise,
            noise=noise,
            sigma_t=sigma_t,
            sigma_r=sigma_r,
            rig=rig,
            pixel_sigma=pixel_sigma,
        )
        for b in items
    ]
    poses = {f: np.concatenate([p[0][f] for p in parts]) for f in frames}
    points = {f: np.concatenate([p[1][f] for p in parts]) for f in parts[0][1]}
    return poses, points


def _provenance(
    seed: int,
    M: int,
    file_names: list[str],
    r: np.ndarray,
    geometry_error_t: float,
    geometry_error_r: float,
    rig: StereoRig,
    view: ViewReport,
    redrawn: int,
) -> dict[str, Any]:
    """The measurement files' ``provenance`` section: how the experiment was simulated."""
    return {
        "simulator": "cpc2urdf.identification.simulation.stage1_experiment",
        "seed": seed,
        "M": M,
        "protocol": "one joint at a time from q0 (Shih et al. sec. 4.1)",
        "calibration_ranges": {
            n: [float(a), float(b)] for n, (a, b) in zip(file_names, r, strict=True)
        },
        "geometry_error": {"sigma_t_m": geometry_error_t, "sigma_r_rad": geometry_error_r},
        "rig": rig.to_json(),
        "view": {
            "min_margin_px": view.min_margin_px,
            "max_view_angle_rad": view.max_view_angle,
            "distance_range_m": list(view.distance_range),
            "problems": view.problems[:10],
            "hidden_circle_sightings": view.hidden,
            "heldout_redrawn_unmeasurable": redrawn,
        },
    }


def _measurement_sets(
    spec: RobotSpec,
    truth: CPCModel,
    q: np.ndarray,
    labels: list[str],
    poses: dict[str, np.ndarray],
    points: dict[str, np.ndarray],
    q_held: np.ndarray,
    frames: list[str],
    ref: str,
    noise_doc: dict[str, Any],
    provenance: dict[str, Any],
) -> tuple[MeasurementSet, MeasurementSet]:
    """The measured set (noisy poses, circle points and their fit RMS) and the held-out set
    (TRUE poses, no noise)."""
    s = truth.structure
    n_heldout = len(q_held)
    fit_rms = {}
    if points:
        from cpc2urdf.registration import registration_rms

        for f, P in points.items():
            fit_rms[f] = registration_rms(poses[f], np.array(s.frame(f).layout), P)
    # A URDF robot goes with its sets: their files use the URDF's joint and link names, and
    # identification starts from (and writes back into) that URDF. A spec robot's sets stay as
    # they were (its names are the file's; identify's nominal is the caller's choice).
    keep = spec if isinstance(spec, UrdfRobot) else None
    measured = MeasurementSet(
        s,
        q,
        poses,
        "<simulated>",
        ref,
        labels,
        points,
        fit_rms,
        {
            "description": f"simulated stage-1 measurements of {s.name}",
            "noise": noise_doc,
            "provenance": provenance,
        },
        keep,
    )
    held_true = truth.fk(q_held, frames) if n_heldout else {f: np.empty((0, 4, 4)) for f in frames}
    heldout = MeasurementSet(
        s,
        q_held.reshape(-1, s.n_joints),
        held_true,
        "<simulated heldout>",
        ref,
        [f"heldout {i}" for i in range(n_heldout)],
        metadata={
            "description": f"held-out configurations of {s.name} with TRUE poses (no noise)",
            "noise": {"model": "none"},
            "provenance": {**provenance, "seed_stream": "heldout"},
        },
        spec=keep,
    )
    return measured, heldout


def _with_truth_provenance(
    truth: CPCModel,
    nominal: CPCModel,
    ref: str,
    seed: int,
    provenance: dict[str, Any],
    w2b: CPCParams,
) -> CPCModel:
    """``truth`` with the nominal's metadata and a provenance saying it is a simulated truth."""
    return truth.with_params(
        metadata=nominal.metadata.replace(
            provenance=Provenance(
                method="simulated truth",
                robot=ref,
                details={
                    "simulated_truth": True,
                    "seed": seed,
                    "nominal": ref,
                    "geometry_error": provenance["geometry_error"],
                    "nominal_world_to_base": {"b": list(w2b.b), "beta": w2b.beta, "l": list(w2b.l)},
                },
            )
        )
    )


def _check_arguments(noise: str, n_heldout: int, **sigmas: float) -> None:
    if noise not in NOISE_MODELS:
        raise ConfigurationError(f"noise model must be one of {NOISE_MODELS}, got {noise!r}")
    for name, v in sigmas.items():
        if not (math.isfinite(v) and v >= 0):
            raise ConfigurationError(f"{name} must be a finite number >= 0, got {v}")
    if n_heldout < 0:
        raise ConfigurationError(f"n_heldout must be >= 0, got {n_heldout}")


def _noise_doc(noise: str, sigma_t: float, sigma_r: float, pixel_sigma: float) -> dict[str, Any]:
    """The measurement file's ``noise`` section. A file states a noise as a positive number (a
    zero one is no noise in that part: not stated)."""
    doc: dict[str, Any] = {
        "model": noise if noise != "fig10" or sigma_t > 0 or sigma_r > 0 else "none"
    }
    if noise == "fig10":
        doc.update({k: v for k, v in (("sigma_t_m", sigma_t), ("sigma_r_rad", sigma_r)) if v > 0})
    elif noise == "stereo":
        doc.update(pixel_sigma_px=pixel_sigma)
    return doc


def _unmeasurable(view: ViewReport, n_configurations: int, n_frames: int) -> list[str]:
    """The problems of ``view`` (over ``n_configurations`` x ``n_frames`` (configuration, plate)
    views) that make the experiment unmeasurable.

    A plate outside an image or seen edge-on cannot be measured: refuse. A circle hidden by the
    other plate in an occasional view of this particular true robot (the placement was searched
    clear on the nominal one) leaves that plate measurable from its other circles: recorded in
    the provenance. Plates hiding each other in more than OCCLUDED_VIEWS_MAX of the views is a
    bad experiment design: refused too.
    """
    unmeasurable = view.problems[: view.unseen]
    occluded = view.problems[view.unseen :]
    if len(occluded) > OCCLUDED_VIEWS_MAX * n_configurations * n_frames:
        unmeasurable += occluded
    return unmeasurable


__all__ = [
    "DEFAULT_HELDOUT",
    "OCCLUDED_VIEWS_MAX",
    "Experiment",
    "simulate_experiment",
]
