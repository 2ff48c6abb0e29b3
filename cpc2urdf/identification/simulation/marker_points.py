"""Simulated position-only measurements: marker points of a true robot (laser tracker, mocap).

Example::

    truth = perturbed_model(nominal, rng, 1e-3, np.radians(0.5))
    markers = place_markers_on(truth, {"plate_left": 2, "plate_right": 2}, rng)
    ms = simulate_markers(truth, markers, protocol_q(truth, 7), sigma_p=0.1e-3, rng=rng)

Each seen point is ``T_world_F(q) p_m`` of the true robot plus isotropic Gaussian noise of
``sigma_p`` per coordinate (the noise model of :mod:`~cpc2urdf.identification.kinematics.points.point_problem`);
the set's ``noise`` section states ``sigma_p_m`` when there is noise.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np
from numpy.typing import ArrayLike

from cpc2urdf.files.measurements import Marker, MeasurementSet
from cpc2urdf.model import CPCModel

# Markers drawn by place_markers_on lie this far from their frame's origin [m] (a marker ball on
# a rod or a reflector on a plate, well off any axis through the frame).
MARKER_DISTANCE = (0.05, 0.15)


def place_markers_on(
    model: CPCModel,
    counts: Mapping[str, int],
    rng: np.random.Generator,
    distance: tuple[float, float] = MARKER_DISTANCE,
) -> dict[str, tuple[str, np.ndarray]]:
    """Seeded random marker positions: ``counts[frame]`` markers on each frame.

    Returns:
        Marker name (``"<frame>_m<k>"``) -> (frame, position in the frame [m], shape (3,)).
    """
    out: dict[str, tuple[str, np.ndarray]] = {}
    for f, n in counts.items():
        model.structure.frame(f)
        for k in range(n):
            d = rng.normal(size=3)
            out[f"{f}_m{k}"] = (f, d / np.linalg.norm(d) * rng.uniform(*distance))
    return out


def simulate_markers(
    truth: CPCModel,
    markers: Mapping[str, tuple[str, ArrayLike]],
    q: ArrayLike,
    *,
    sigma_p: float = 0.0,
    rng: np.random.Generator | None = None,
    known: Iterable[str] = (),
    robot: str | None = None,
    seen: Mapping[str, ArrayLike] | None = None,
) -> MeasurementSet:
    """Marker points of ``truth`` at configurations ``q``, with noise.

    Args:
        truth: The true robot.
        markers: Marker name -> (frame it is fixed to, its true position in that frame [m]).
        q: Configurations [rad]/[m], shape (N, n).
        sigma_p: Noise of each coordinate [m] (isotropic Gaussian).
        rng: Random generator (needed when ``sigma_p > 0``).
        known: Markers whose position is given in the set (the others are to be identified).
        robot: Robot reference for files (a shipped name or a path).
        seen: Marker -> which records see it, shape (N,) booleans (default: all).

    Returns:
        A :class:`MeasurementSet` with ``markers`` and ``marker_points``.
    """
    qq = np.atleast_2d(np.asarray(q, dtype=float))
    known = set(known)
    frames = list(dict.fromkeys(f for f, _ in markers.values()))
    T = truth.fk(qq, frames)
    defs: dict[str, Marker] = {}
    points: dict[str, np.ndarray] = {}
    if sigma_p > 0 and rng is None:
        raise ValueError("simulate_markers: sigma_p > 0 needs an rng")
    for name, (frame, p) in markers.items():
        p = np.asarray(p, dtype=float)
        defs[name] = Marker(name, frame, tuple(float(v) for v in p) if name in known else None)  # type: ignore[arg-type]
        Y = T[frame][:, :3, :3] @ p + T[frame][:, :3, 3]
        if sigma_p > 0:
            assert rng is not None
            Y = Y + rng.normal(scale=sigma_p, size=Y.shape)
        if seen is not None and name in seen:
            Y = np.where(np.asarray(seen[name], dtype=bool)[:, None], Y, np.nan)
        points[name] = Y
    metadata = (
        {"noise": {"model": "isotropic points", "sigma_p_m": float(sigma_p)}} if sigma_p > 0 else {}
    )
    return MeasurementSet.from_arrays(
        truth.structure, qq, {}, robot=robot, metadata=metadata, markers=defs, marker_points=points
    )


__all__ = ["MARKER_DISTANCE", "place_markers_on", "simulate_markers"]
