"""Does a calibrated head answer targets ahead facing them? The demo's heads, seed by seed.

``cpc2urdf demo --seed S`` calibrates a simulated IIS-head: ``simulate`` (a true head with seeded
geometric errors, measured by a stereo rig), ``identify``, then hand-eye on both cameras
(:func:`demo_head` repeats those steps, without the demo's other stages). Targets in a cone ahead
of the nominal head (10 deg about its home cyclopean axis, 0.8-3 m from its cyclopean point) are
solved on the nominal head and on the calibrated one; the calibrated head should answer each with
its pan and tilt within a few degrees of the nominal head's answer (its neck facing the target),
whether it can fixate exactly or not.

The calibrated model's world is the stereo rig's (it was measured there), not the nominal
head's: the targets are carried over by the rigid transform that best maps the nominal head's
camera centres and optical axes onto the calibrated head's over seeded configurations
(:func:`world_map`).

Run: ``cpc2urdf study gaze-ahead [SEED ...]`` (default 0-9).
"""

from __future__ import annotations

import math
import sys
from collections import Counter
from typing import Any

import numpy as np

from cpc2urdf.model import CPCModel
from cpc2urdf.transforms import Array

CAMERAS = ("camera_left_optical", "camera_right_optical")
CONE = math.radians(10.0)  # [rad]: half-angle of the cone of targets about the home cyclopean axis
NEAR, FAR = 0.8, 3.0  # [m]: the targets' distances from the home cyclopean point
MAX_DEVIATION = math.radians(
    5.0
)  # [rad]: pan and tilt of the calibrated head's answer vs the nominal's


def demo_head(seed: int) -> CPCModel:
    """The calibrated IIS-head of ``cpc2urdf demo --seed SEED`` (its ``model.json``): the demo's
    simulate, identify and hand-eye stages, in memory."""
    from cpc2urdf.api import identify, simulate
    from cpc2urdf.identification.handeye.stage2 import perturb_cameras, run_stage2

    truth, measured, _ = simulate("iis_head", seed=seed)
    truth = perturb_cameras(truth, np.random.default_rng(seed))
    return run_stage2(identify(measured), truth, seed=seed, method="refined").model


def _axis_points(model: CPCModel, Q: Array) -> Array:
    """Each camera's centre and the point 0.5 m along its optical axis at readings ``Q`` (N, n)."""
    T = model.fk(Q, CAMERAS)
    return np.concatenate(
        [p for c in CAMERAS for p in (T[c][:, :3, 3], T[c][:, :3, 3] + 0.5 * T[c][:, :3, 2])]
    )


def world_map(nominal: CPCModel, calibrated: CPCModel, n: int = 100, seed: int = 0) -> Array:
    """``T_cal_nom`` (4, 4): the rigid transform from the nominal head's world to the calibrated
    head's, fitted (Kabsch) on camera centres and axis points at ``n`` seeded readings."""
    from cpc2urdf.registration import transforms_from_point_pairs

    s = nominal.structure
    Q = np.random.default_rng(seed).uniform(s.lower, s.upper, (n, len(s.lower)))
    return transforms_from_point_pairs(_axis_points(nominal, Q), _axis_points(calibrated, Q))


def targets_ahead(solver: Any, n: int = 30, seed: int = 0) -> Array:
    """``n`` seeded targets (world) [m], shape (n, 3), in the cone :data:`CONE` about the home
    cyclopean axis of ``solver`` (a :class:`~cpc2urdf.validation.gaze.GazeSolver`), between
    :data:`NEAR` and :data:`FAR` from its home cyclopean point."""
    L, R = solver.camera_poses(solver.home)
    c = 0.5 * (L[:3, 3] + R[:3, 3])
    z = L[:3, 2] + R[:3, 2]
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0] if abs(z[2]) < 0.9 else [1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    rng = np.random.default_rng(seed)
    ang = CONE * np.sqrt(rng.uniform(0.0, 1.0, n))
    phi = rng.uniform(0.0, 2.0 * math.pi, n)
    dist = rng.uniform(NEAR, FAR, n)
    d = np.cos(ang)[:, None] * z + np.sin(ang)[:, None] * (
        np.cos(phi)[:, None] * x + np.sin(phi)[:, None] * y
    )
    return c + dist[:, None] * d  # type: ignore[no-any-return]


def ahead_deviation(calibrated: CPCModel, n: int = 30, seed: int = 0) -> dict[str, Any]:
    """Targets ahead of the nominal IIS-head solved on it and on ``calibrated``: the largest pan
    and tilt deviation [rad] of the calibrated head's answers, their statuses and vergence range."""
    from cpc2urdf.api import load_model
    from cpc2urdf.validation.gaze import GazeSolver

    nominal = load_model("iis_head")
    nom, cal = GazeSolver.from_model(nominal), GazeSolver.from_model(calibrated)
    P = targets_ahead(nom, n, seed)
    T = world_map(nominal, calibrated)
    neck = [nom.joint_names.index("pan"), nom.joint_names.index("tilt")]
    dev, status, vergence = [], Counter[str](), []
    for p in P:
        a, b = nom.solve(p), cal.solve(T[:3, :3] @ p + T[:3, 3])
        dev.append(np.abs(b.q[neck] - a.q[neck]))
        status[b.status] += 1
        vergence.append(b.vergence)
    D = np.array(dev)
    return {
        "pan": float(D[:, 0].max()),
        "tilt": float(D[:, 1].max()),
        "statuses": dict(status),
        "vergence": (float(min(vergence)), float(max(vergence))),
    }


def main(argv: list[str] | None = None) -> int:
    """Print the deviations for the seeds in ``argv`` (default 0-9); exit 1 if any exceeds
    :data:`MAX_DEVIATION`."""
    from cpc2urdf.argparsing import OneLineParser

    ap = OneLineParser(prog="cpc2urdf study gaze-ahead", description=__doc__.split("\n")[0])
    ap.add_argument("seeds", nargs="*", type=int, help="demo seeds (default 0-9)")
    seeds = ap.parse_args(sys.argv[1:] if argv is None else argv).seeds or list(range(10))
    worst = 0.0
    print("seed  max |pan| dev  max |tilt| dev  vergence [deg]  statuses")
    for seed in seeds:
        r = ahead_deviation(demo_head(seed))
        worst = max(worst, r["pan"], r["tilt"])
        lo, hi = (math.degrees(v) for v in r["vergence"])
        print(
            f"{seed:4d}  {math.degrees(r['pan']):9.2f} deg  {math.degrees(r['tilt']):10.2f} deg"
            f"  {lo:5.2f}-{hi:5.2f}     {r['statuses']}"
        )
    return 0 if worst <= MAX_DEVIATION else 1


if __name__ == "__main__":
    raise SystemExit(main())
