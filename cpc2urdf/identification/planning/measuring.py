"""The measuring setup of a plan: the rig, where the robot stands in front of it, and the noise.

The robot is placed exactly as :func:`~cpc2urdf.identification.simulation.stage1_experiment.
simulate_experiment` places it (:func:`~cpc2urdf.identification.simulation.placement.
experiment_placement` over the paper's protocol with ``M = DEFAULT_M``), so that a plan, the paper's protocol and the simulator all see the same
scene. A configuration is *measurable* when :func:`~cpc2urdf.identification.simulation.visibility.
check_view` finds, on the nominal robot, every circle (or, for a frame without a circle layout,
its origin) of every measured frame at least ``PLAN_VIEW_MARGIN_PX`` inside both images, no more
than ``PLAN_MAX_VIEW_ANGLE`` off face-on, and hidden by no plate with ``PLAN_OCCLUSION_MARGIN_PX``
of clearance: more than the simulator's own limits on the true robot (20 px, 75 deg, 3 px), so
that the real robot, ~1 mm / 0.5 deg per placement away from its nominal model (a few mm, a few
px at 1.5 m), still shows every circle.

The pose noise is the simulator's Fig. 10 model (``sigma_t`` per translation entry, a rotation of
angle ``N(0, sigma_r)`` about a random axis): the noise the identification problem's weights
assume (:mod:`~cpc2urdf.identification.kinematics.problem`); or (``noise="stereo"``) the
simulator's stereo model, ``pixel_sigma`` per pixel coordinate of each circle centre through
triangulation and registration, whose pose covariance differs per view (:mod:`stereo`); or
(``markers > 0``) position-only data: that many markers of unknown position on each measured
frame, each point with ``marker_sigma`` per coordinate (:mod:`markers`; the markers are assumed
seen wherever the rig sees the plates: the candidates stay those the rig sees, as ``simulate
--plan --markers`` simulates the plate experiment first).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import ConfigurationError
from cpc2urdf.identification.planning.information import (
    PoseMeasurement,
    StereoPoseMeasurement,
)
from cpc2urdf.identification.planning.marker_setup import (
    DEFAULT_MARKER_SIGMA,
    MarkerMeasurement,
    plan_markers,
)
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
)
from cpc2urdf.identification.simulation.placement import experiment_placement
from cpc2urdf.identification.simulation.visibility import check_view
from cpc2urdf.identification.vision.stereo import StereoRig
from cpc2urdf.model import CPCModel, CPCParams

Array = NDArray[np.float64]

# Limits a planned configuration must meet on the nominal robot (see the module docstring).
PLAN_VIEW_MARGIN_PX = 40.0  # [px]
PLAN_MAX_VIEW_ANGLE = math.radians(70.0)  # [rad]
PLAN_OCCLUSION_MARGIN_PX = 25.0  # [px]
SETUP_NOISE_MODELS = ("fig10", "stereo")


@dataclass(frozen=True)
class MeasuringSetup:
    """What measures the robot, and how well.

    Attributes:
        nominal: The robot's nominal model, placed in the rig's world (``world_to_base`` set).
        rig: The stereo rig (world = its left camera frame).
        frames: The measured frames (plates).
        ranges: Calibration ranges per joint ``[lo, hi]`` [m]/[rad], shape (n, 2).
        sigma_t: Fig. 10 translation noise per entry [m] (stereo: not used).
        sigma_r: Fig. 10 rotation noise angle [rad] (stereo: not used).
        noise: ``"fig10"`` or ``"stereo"`` (pixel noise through the rig).
        pixel_sigma: Stereo pixel noise per coordinate [px].
        markers: Markers per measured frame (0: the plates' poses are measured).
        marker_sigma: Noise of each marker point coordinate [m].
        marker_seed: Seed of the markers' placement (as ``simulate --markers K --seed S``).
    """

    nominal: CPCModel
    rig: StereoRig
    frames: tuple[str, ...]
    ranges: Array
    sigma_t: float = DEFAULT_SIGMA_T
    sigma_r: float = DEFAULT_SIGMA_R
    noise: str = "fig10"
    pixel_sigma: float = DEFAULT_PIXEL_SIGMA
    markers: int = 0
    marker_sigma: float = DEFAULT_MARKER_SIGMA
    marker_seed: int = 0

    def measurement(self) -> PoseMeasurement | StereoPoseMeasurement | MarkerMeasurement:
        """What is measured and how noisily: :class:`PoseMeasurement` (Fig. 10),
        :class:`StereoPoseMeasurement` (the frames' circle layouts through the rig) or
        :class:`MarkerMeasurement` (marker points)."""
        if self.markers > 0:
            return MarkerMeasurement(
                plan_markers(self.nominal, self.frames, self.markers, self.marker_seed),
                self.marker_sigma,
            )
        if self.noise == "stereo":
            s = self.nominal.structure
            layouts = tuple(np.array(s.frame(f).layout, dtype=float) for f in self.frames)
            return StereoPoseMeasurement(self.frames, layouts, self.rig, self.pixel_sigma)
        return PoseMeasurement(self.frames, self.sigma_t, self.sigma_r)

    def measurable(self, q: ArrayLike) -> NDArray[np.bool_]:
        """Which configurations ``q`` (N, n) [m]/[rad] a plan may use: every frame of the nominal
        robot seen with the planning limits (module docstring), shape (N,)."""
        qq = np.atleast_2d(np.asarray(q, dtype=float))
        view = check_view(
            self.nominal,
            self.rig,
            qq,
            self.frames,
            [str(i) for i in range(len(qq))],
            margin_px=PLAN_VIEW_MARGIN_PX,
            max_angle=PLAN_MAX_VIEW_ANGLE,
            occlusion_margin_px=PLAN_OCCLUSION_MARGIN_PX,
        )
        return (view.hidden_per_config == 0) & (view.unseen_per_config == 0)

    def problems(
        self, q: ArrayLike, labels: Sequence[str], model: CPCModel | None = None
    ) -> list[str]:
        """What the rig fails to see at ``q`` (one line per configuration and frame), with the
        simulator's own clearance (:func:`check_view`'s defaults)."""
        return check_view(
            model or self.nominal,
            self.rig,
            np.atleast_2d(np.asarray(q, dtype=float)),
            self.frames,
            labels,
        ).problems


def measuring_setup(
    nominal: CPCModel,
    *,
    rig: StereoRig | None = None,
    sigma_t: float = DEFAULT_SIGMA_T,
    sigma_r: float = DEFAULT_SIGMA_R,
    ranges: Mapping[str, tuple[float, float]] | None = None,
    frames: Sequence[str] | None = None,
    world_to_base: CPCParams | None = None,
    noise: str = "fig10",
    pixel_sigma: float = DEFAULT_PIXEL_SIGMA,
    markers: int = 0,
    marker_sigma: float = DEFAULT_MARKER_SIGMA,
    marker_seed: int = 0,
) -> MeasuringSetup:
    """The setup :func:`simulate_experiment` would simulate for this robot and rig.

    Args:
        nominal: The robot's nominal model (needs geometry; its ``world_to_base`` is replaced).
        rig: The rig (default :meth:`StereoRig.verged`, the paper's).
        sigma_t: Translation noise per entry [m].
        sigma_r: Rotation noise angle [rad].
        ranges: Calibration ranges ``{joint: (lo, hi)}`` [m]/[rad] overriding the spec's.
        frames: Measured frames (default: the frames of kind ``"plate"``).
        world_to_base: The robot's place in the rig's world (default: the simulator's search).
        noise: ``"fig10"`` (pose noise ``sigma_t``/``sigma_r``) or ``"stereo"`` (``pixel_sigma``).
        pixel_sigma: Stereo pixel noise per coordinate [px].
        markers: Markers per measured frame (0: plate poses; else position-only data, ``noise`` unused).
        marker_sigma: Noise of each marker point coordinate [m].
        marker_seed: Seed of the markers' placement.

    Raises:
        ConfigurationError: No measured frame, a frame that is not the robot's, non-positive noise,
            an unknown noise model, stereo noise on a frame without a circle layout.
    """
    s = nominal.structure
    if noise not in SETUP_NOISE_MODELS:
        raise ConfigurationError(f"noise model must be one of {SETUP_NOISE_MODELS}, got {noise!r}")
    if markers < 0:
        raise ConfigurationError(f"markers must be >= 0 per measured frame, got {markers}")
    for name, v in (
        ("sigma_t", sigma_t),
        ("sigma_r", sigma_r),
        ("pixel_sigma", pixel_sigma),
        ("marker_sigma", marker_sigma),
    ):
        if not (math.isfinite(v) and v > 0):
            raise ConfigurationError(f"{name} must be a finite number > 0, got {v}")
    fr = list(frames) if frames is not None else measured_frames(s)
    if not fr:
        raise ConfigurationError(f"robot {s.name!r} has no frame of kind 'plate' to measure")
    for f in fr:
        if f not in s.frame_names:
            raise ConfigurationError(
                f"measured frame {f!r} is not a frame of robot {s.name!r} ({list(s.frame_names)})"
            )
        if noise == "stereo" and not markers and s.frame(f).layout is None:
            raise ConfigurationError(
                f"stereo noise needs the circle layout of measured frame {f!r}, and it has none"
            )
    rig = rig or StereoRig.verged()
    r = calibration_ranges(s, ranges)
    if world_to_base is None:
        q, _ = protocol_configurations(r, DEFAULT_M, s.joint_names)
        world_to_base = experiment_placement(nominal, rig, q, fr, r)  # as simulate_experiment
    return MeasuringSetup(
        nominal.with_params(world_to_base=world_to_base),
        rig,
        tuple(fr),
        r,
        float(sigma_t),
        float(sigma_r),
        noise,
        float(pixel_sigma),
        int(markers),
        float(marker_sigma),
        int(marker_seed),
    )


__all__ = [
    "PLAN_MAX_VIEW_ANGLE",
    "PLAN_OCCLUSION_MARGIN_PX",
    "PLAN_VIEW_MARGIN_PX",
    "SETUP_NOISE_MODELS",
    "MeasuringSetup",
    "measuring_setup",
]
