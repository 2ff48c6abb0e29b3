"""Seeded simulated stage-1 data for the refinement tests (independent of identification/simulate.py).

Truth: the nominal IIS-head (or any model) with every placement perturbed; data: the
one-joint-at-a-time protocol (sec. 4.1) or random configurations; noise: Fig. 10 (N(0, sigma_t)
per translation entry, rotation pre-multiplied by a random-axis rotation of angle N(0, sigma_r)).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from cpc2urdf.measurements import MeasurementSet
from cpc2urdf.model import CPCModel, CPCParams


def _perturb(p: CPCParams, rng: np.random.Generator, st: float, sr: float) -> CPCParams:
    D = np.eye(4)
    D[:3, :3] = Rotation.from_rotvec(rng.normal(0.0, sr, 3)).as_matrix()
    D[:3, 3] = rng.normal(0.0, st, 3)
    return CPCParams.from_matrix(p.matrix() @ D)


def perturbed(model: CPCModel, rng: np.random.Generator, st: float = 5e-3, sr: float = 0.02) -> CPCModel:
    """Every placement (world_to_base, joints, frames) moved by a random small rigid motion."""
    return model.with_params(
        world_to_base=_perturb(model.world_to_base, rng, st, sr),
        joints={k: _perturb(v, rng, st, sr) for k, v in model.joints.items()},
        frames={k: _perturb(v, rng, st, sr) for k, v in model.frames.items()},
    )


def ranges(model: CPCModel) -> np.ndarray:
    """Calibration ranges (or limits), shape (n, 2)."""
    return np.array([j.calibration_range or (j.lower, j.upper) for j in model.structure.joints])


def protocol_q(model: CPCModel, M: int) -> np.ndarray:
    """q0 (range centres), then each joint alone through M values: shape (n*M + 1, n)."""
    r = ranges(model)
    q0 = r.mean(axis=1)
    qs = [q0]
    for i in range(len(q0)):
        for v in np.linspace(r[i, 0], r[i, 1], M):
            q = q0.copy()
            q[i] = v
            qs.append(q)
    return np.array(qs)


def random_q(model: CPCModel, n: int, rng: np.random.Generator) -> np.ndarray:
    r = ranges(model)
    return rng.uniform(r[:, 0], r[:, 1], size=(n, len(r)))


def measure(
    truth: CPCModel, q: np.ndarray, rng: np.random.Generator, sigma_t: float, sigma_r: float,
    frames: tuple[str, ...] = ("plate_left", "plate_right"),
) -> MeasurementSet:
    """Fig. 10 noisy poses of ``frames`` at ``q``."""
    T = truth.fk(q, frames)
    poses = {}
    for f in frames:
        P = T[f].copy()
        n = len(q)
        axis = rng.normal(size=(n, 3))
        axis /= np.linalg.norm(axis, axis=1, keepdims=True)
        angle = rng.normal(0.0, sigma_r, n)
        P[:, :3, :3] = Rotation.from_rotvec(axis * angle[:, None]).as_matrix() @ P[:, :3, :3]
        P[:, :3, 3] += rng.normal(0.0, sigma_t, (n, 3))
        poses[f] = P
    return MeasurementSet(truth.structure, q, poses)
