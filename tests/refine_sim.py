"""Seeded simulated stage-1 data for the refinement tests, through the simulator's building blocks.

Truth: the nominal IIS-head (or any model) with every placement perturbed
(:func:`~cpc2urdf.identification.simulation.truth.perturbed_model`); data: the one-joint-at-a-time
protocol (sec. 4.1) or random configurations in the calibration ranges
(:mod:`~cpc2urdf.identification.simulation.design`); noise: Fig. 10 (N(0, sigma_t) per translation
entry, rotation pre-multiplied by a random-axis rotation of angle N(0, sigma_r),
:func:`~cpc2urdf.identification.simulation.measurement_noise.fig10_noise`). No placement search, no view
check: the data are exactly the model's poses plus noise.
"""

from __future__ import annotations

import numpy as np

from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.identification.simulation import design
from cpc2urdf.identification.simulation.measurement_noise import fig10_noise
from cpc2urdf.identification.simulation.truth import perturbed_model
from cpc2urdf.model import CPCModel


def perturbed(
    model: CPCModel, rng: np.random.Generator, st: float = 5e-3, sr: float = 0.02
) -> CPCModel:
    """Every placement (world_to_base, joints, frames) moved: ``st`` [m] per offset component,
    ``sr`` [rad] about a random axis."""
    return perturbed_model(model, rng, st, sr)


def ranges(model: CPCModel) -> np.ndarray:
    """Calibration ranges, shape (n, 2) (:func:`~cpc2urdf.identification.simulation.design.calibration_ranges`)."""
    return design.calibration_ranges(model.structure)


def protocol_q(model: CPCModel, M: int) -> np.ndarray:
    """q0 (range centres), then each joint alone through M values: shape (n*M + 1, n)."""
    return design.protocol_q(model, M)


def random_q(model: CPCModel, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` configurations uniform in the calibration ranges, shape (n, n_joints)."""
    return design.random_configurations(ranges(model), n, rng)


def measure(
    truth: CPCModel,
    q: np.ndarray,
    rng: np.random.Generator,
    sigma_t: float,
    sigma_r: float,
    frames: tuple[str, ...] = ("plate_left", "plate_right"),
) -> MeasurementSet:
    """Fig. 10 noisy poses of ``frames`` at ``q``."""
    T = truth.fk(q, frames)
    return MeasurementSet(
        truth.structure, q, {f: fig10_noise(T[f], sigma_t, sigma_r, rng) for f in frames}
    )
