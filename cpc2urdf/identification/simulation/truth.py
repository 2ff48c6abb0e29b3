"""The "true" robot of a simulation: the nominal model plus seeded random geometric errors.

A real head is not its drawing. Every CPC placement (``world_to_base``, each joint's, each
frame's) gets the same kind of error as a Fig. 10 measurement (:func:`~cpc2urdf.identification.
simulation.noise.fig10_noise`, the package's one pose-perturbation convention), applied to the
pair (rotation ``R``, CPC offset ``l``) of eq. (3): ``R' = Rot(u, phi) R`` with ``u`` uniform on
the sphere and ``phi ~ N(0, sigma_r)`` (this tilts the axis ``b`` and changes ``beta``), and
``l' = l + N(0, sigma_t^2 I)``.

Example::

    truth = perturbed_model(nominal, np.random.default_rng(0), 1e-3, np.radians(0.5))
"""

from __future__ import annotations

import math

import numpy as np

from cpc2urdf.identification.simulation.measurement_noise import fig10_noise
from cpc2urdf.model import CPCModel, CPCParams
from cpc2urdf.transforms import homogeneous

DEFAULT_GEOMETRY_ERROR_T = 1e-3  # [m], per CPC offset component
DEFAULT_GEOMETRY_ERROR_R = math.radians(0.5)  # [rad], about a random axis


def perturb_params(
    p: CPCParams, rng: np.random.Generator, sigma_t: float, sigma_r: float
) -> CPCParams:
    """``p`` with its rotation pre-multiplied by a random small rotation and ``l`` offset.

    Args:
        p: Nominal CPC constants.
        rng: Random generator.
        sigma_t: Standard deviation of each component of the offset added to ``l`` [m].
        sigma_r: Standard deviation of the rotation angle about a random axis [rad]; this tilts
            the axis direction ``b`` and changes ``beta``.
    """
    # Fig. 10 on (R, l): draws the rotation, then the offset, as the measurement noise does.
    Rl = fig10_noise(homogeneous(p.rotation(), np.asarray(p.l)), sigma_t, sigma_r, rng)
    R, l = Rl[:3, :3], Rl[:3, 3]
    return CPCParams.from_matrix(homogeneous(R, R @ l))


def perturbed_model(
    nominal: CPCModel, rng: np.random.Generator, sigma_t: float, sigma_r: float
) -> CPCModel:
    """A "true" robot: every joint's and frame's CPC constants and ``world_to_base`` perturbed
    (:func:`perturb_params`, in that order: joints, frames, then ``world_to_base``).

    Args:
        nominal: The nominal robot.
        rng: Random generator.
        sigma_t: Standard deviation of each CPC offset component's error [m].
        sigma_r: Standard deviation of each rotation error angle [rad].
    """
    s = nominal.structure
    joints = {n: perturb_params(nominal.joints[n], rng, sigma_t, sigma_r) for n in s.joint_names}
    frames = {n: perturb_params(nominal.frames[n], rng, sigma_t, sigma_r) for n in s.frame_names}
    w2b = perturb_params(nominal.world_to_base, rng, sigma_t, sigma_r)
    return nominal.with_params(world_to_base=w2b, joints=joints, frames=frames)


__all__ = [
    "DEFAULT_GEOMETRY_ERROR_T",
    "DEFAULT_GEOMETRY_ERROR_R",
    "perturb_params",
    "perturbed_model",
]
