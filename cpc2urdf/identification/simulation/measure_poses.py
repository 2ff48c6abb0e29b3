"""Measuring a simulated robot: noisy plate poses under one of the noise models.

``"fig10"`` (Shih et al. Fig. 10: ``sigma_t`` per translation entry, ``sigma_r`` about a random
axis), ``"stereo"`` (pixel noise through a stereo rig, triangulation and registration) or
``"none"`` (the true poses); the models themselves are in
:mod:`~cpc2urdf.identification.simulation.measurement_noise`.

Example::

    poses, points = measure_poses(truth, q, ["plate_left"], rng, noise="stereo", rig=rig)
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import ConfigurationError
from cpc2urdf.identification.simulation.measurement_noise import fig10_noise, stereo_noise
from cpc2urdf.identification.vision.stereo import StereoRig
from cpc2urdf.model import CPCModel

Array = NDArray[np.float64]

NOISE_MODELS = ("fig10", "stereo", "none")
# Defaults (SI). The paper's Fig. 11 uses one sigma_O for both: sigma_O mm and sigma_O degrees.
DEFAULT_SIGMA_T = 0.5e-3  # [m]: the paper's rig accuracy (sec. 6)
DEFAULT_SIGMA_R = math.radians(0.5)  # [rad]
DEFAULT_PIXEL_SIGMA = (
    0.15  # [px]: ~0.5 mm per circle centre with the default rig (docs/measurements.md)
)


def measure_poses(
    model: CPCModel,
    q: ArrayLike,
    frames: Sequence[str],
    rng: np.random.Generator,
    *,
    noise: str = "fig10",
    sigma_t: float = DEFAULT_SIGMA_T,
    sigma_r: float = DEFAULT_SIGMA_R,
    rig: StereoRig | None = None,
    pixel_sigma: float = DEFAULT_PIXEL_SIGMA,
) -> tuple[dict[str, Array], dict[str, Array]]:
    """Noisy ``T_world_<frame>`` of ``model`` at ``q`` (N, n) under a noise model.

    Args:
        model: The true robot (placed in the rig's world).
        q: Configurations, shape (N, n).
        frames: Frames to measure (plates).
        rng: Random generator.
        noise: ``"fig10"`` (sigma_t, sigma_r), ``"stereo"`` (pixel_sigma through ``rig``) or
            ``"none"``.
        sigma_t: Fig. 10 translation noise per entry [m].
        sigma_r: Fig. 10 rotation noise angle [rad].
        rig: The stereo rig (``"stereo"`` only).
        pixel_sigma: Pixel noise per coordinate [px] (``"stereo"`` only).

    Returns:
        ``(poses, points)``: frame -> (N, 4, 4); for the stereo model also frame -> (N, K, 3)
        triangulated circle centres.
    """
    true = model.fk(np.atleast_2d(np.asarray(q, dtype=float)), frames)
    poses: dict[str, Array] = {}
    points: dict[str, Array] = {}
    for f in frames:
        if noise == "none":
            poses[f] = true[f]
        elif noise == "fig10":
            poses[f] = fig10_noise(true[f], sigma_t, sigma_r, rng)
        elif noise == "stereo":
            layout = model.structure.frame(f).layout
            if rig is None or layout is None:
                raise ConfigurationError(f"stereo noise needs a rig and a circle layout for {f!r}")
            poses[f], points[f] = stereo_noise(true[f], np.array(layout), rig, pixel_sigma, rng)
        else:
            raise ConfigurationError(f"noise model must be one of {NOISE_MODELS}, got {noise!r}")
    return poses, points


__all__ = [
    "DEFAULT_PIXEL_SIGMA",
    "DEFAULT_SIGMA_R",
    "DEFAULT_SIGMA_T",
    "NOISE_MODELS",
    "measure_poses",
]
