"""Accuracy of hand-eye on example-robot-data camera links (docs/handeye.md, "Your own robot's cameras").

    python tests/handeye_urdf_trials.py [--seeds 10]

Median error of the written-back mount against the true one, per solver, translation [mm] /
rotation [deg], 0.1 px, 20 and 30 poses; and the largest noise-free error. ~30 s.
"""

from __future__ import annotations

import argparse
import math
import sysconfig
from pathlib import Path

import numpy as np

import cpc2urdf
from cpc2urdf.identification.handeye.solvers import ALL_METHODS, calibrate
from cpc2urdf.transforms import rotation_error

ROBOTS = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix/share/example-robot-data/robots"
CAMERAS = {
    "TALOS": (ROBOTS / "talos_data/robots/talos_reduced.urdf", "rgbd_link"),
    "TIAGo": (ROBOTS / "tiago_description/robots/tiago.urdf", "xtion_link"),
}


def errors(
    urdf: Path, link: str, poses: int, noise: float, seed: int
) -> dict[str, tuple[float, float]]:
    sim = cpc2urdf.simulate(urdf, cameras=[link], poses=poses, pixel_noise=noise, seed=seed)
    cam, true = sim.rig.cameras[link], sim.true_mounts()[link]
    out = {}
    for m in ALL_METHODS:
        T = cam.link_pose(calibrate(sim.T_base_hand[link], sim.T_camera_target[link], m).X)
        out[m] = (
            float(np.linalg.norm(T[:3, 3] - true[:3, 3]) * 1e3),
            math.degrees(rotation_error(T[:3, :3], true[:3, :3])),
        )
    return out


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--seeds", type=int, default=10)
    args = p.parse_args()
    print("| robot, link | poses | " + " | ".join(ALL_METHODS) + " |")
    print("|---|---:|" + "---|" * len(ALL_METHODS))
    worst = (0.0, 0.0)
    for robot, (urdf, link) in CAMERAS.items():
        for poses in (20, 30):
            runs = [errors(urdf, link, poses, 0.1, s) for s in range(args.seeds)]
            cells = [np.median([r[m] for r in runs], axis=0) for m in ALL_METHODS]
            print(
                f"| {robot} `{link}` | {poses} | "
                + " | ".join(f"{t:.2f} / {r:.3f}" for t, r in cells)
                + " |"
            )
        for s in range(args.seeds):
            for t, r in errors(urdf, link, 20, 0.0, s).values():
                worst = (max(worst[0], t), max(worst[1], r))
    print(f"noise-free, largest error: {worst[0]:.2e} mm / {worst[1]:.2e} deg")


if __name__ == "__main__":
    main()
