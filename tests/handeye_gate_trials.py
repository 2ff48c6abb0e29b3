"""How often the hand-eye consistency gate refuses clean data: seeded trials over every data source.

Run: ``python tests/handeye_gate_trials.py [--seeds 20]`` (a few minutes). Prints, per data source,
the number of trials and how many the gate refused (it must be 0). Sources:

- ``stage2``: the stage-2 simulation (``cpc2urdf study stage2``'s setup: IIS head, camera mounts
  perturbed by 3 deg / 5 mm, identified = truth without cameras; solvePnP of a 5x5 disk target with
  Gaussian pixel noise), both cameras, 5 / 10 / 20 configurations, 0 to 0.5 px;
- ``stage2-kinematic-error``: the same with hand poses from a model whose CPC constants carry
  stage-1-sized errors (0.1 mm, 0.01 deg per joint) instead of the truth;
- ``li2010``: ``cpc2urdf study li2010``'s data (its seed 0 and its own draws: noise on A, B or both,
  3 to 30 poses, 10 repeats);
- ``tests``: ``tests/test_handeye.py``'s ``make_data`` + ``add_noise`` (noise on both lists, 3 to 20
  poses), with the noise estimated and with it stated in the pose noise model.

The gate judges the data (its own reference fit), not a solver: every solver of the CLI gets the
same verdict, which ``--check-solvers`` confirms by running ``calibrate(..., gate=True)`` with each.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from test_handeye import add_noise, make_data  # noqa: E402

from cpc2urdf.identification.handeye.gate.handeye_gate import check_consistency  # noqa: E402
from cpc2urdf.identification.handeye.pose_noise import PoseNoise  # noqa: E402
from cpc2urdf.identification.handeye.solvers import ALL_METHODS, Gate, calibrate  # noqa: E402
from cpc2urdf.transforms import Array, inverse  # noqa: E402

Trial = tuple[str, Array, Array, PoseNoise | None]


def stage2_trials(seeds: int, kinematic_error: bool) -> Iterator[Trial]:
    from cpc2urdf.files.robot_ref import load_model
    from cpc2urdf.identification.handeye import stage2 as s2
    from cpc2urdf.identification.simulation.truth import perturbed_model

    nominal = load_model("iis_head")
    truth = s2.perturb_cameras(nominal, np.random.default_rng(1))
    hands = truth
    if kinematic_error:
        hands = perturbed_model(truth, np.random.default_rng(2), 1e-4, math.radians(0.01))
    T_base_target = s2.default_target_placement(truth)
    for n in (5, 10, 20):
        for sigma in (0.0, 0.05, 0.1, 0.2, 0.5):
            for seed in range(seeds):
                rng = np.random.default_rng(seed)
                q = s2.sample_configurations(truth, n, rng, T_base_target)
                obs = s2.simulate_observations(truth, q, T_base_target, rng, pixel_noise=sigma)
                for c, C in obs.T_camera_target.items():
                    yield f"n={n} {sigma}px seed {seed} {c}", s2.hand_poses(hands, c, q), C, None


def li2010_trials(repeats: int) -> Iterator[Trial]:
    from cpc2urdf.studies import li2010 as st

    rng = np.random.default_rng(0)
    for case in st.CASES:
        for n in st.POSE_COUNTS:
            for r in range(repeats):
                A, B = st.simulate(n, rng, case)
                yield f"{case} n={n} repeat {r}", A, inverse(B), None


def synthetic_trials(seeds: int) -> Iterator[Trial]:
    noise = PoseNoise(0.0003, math.radians(0.05), 0.0008, math.radians(0.1))
    for n in (3, 4, 6, 10, 20):
        for seed in range(seeds):
            rng = np.random.default_rng(10_000 + seed)
            _, _, H, C = make_data(rng, n)
            H = add_noise(rng, H, noise.hand_angle, noise.hand_position)
            C = add_noise(rng, C, noise.camera_angle, noise.camera_position)
            yield f"n={n} seed {seed} estimated", H, C, None
            yield f"n={n} seed {seed} stated", H, C, noise


def run(name: str, trials: Iterator[Trial], check_solvers: bool) -> tuple[int, int]:
    count = refused = 0
    t0 = time.perf_counter()
    for label, H, C, noise in trials:
        count += 1
        report = check_consistency(H, C, noise=noise)
        if not report.consistent:
            refused += 1
            print(f"  REFUSED {name} {label}: {report.summary()}", flush=True)
        if check_solvers:
            for m in ALL_METHODS:
                try:
                    r = calibrate(H, C, m, gate=Gate(noise=noise, accept_inconsistent=True))
                except Exception as e:  # noqa: BLE001 - a solver's own refusal (zhuang near 180 deg)
                    print(f"  {name} {label} {m}: {e}")
                    continue
                assert r.consistency is not None and r.consistency.consistent == report.consistent
    print(
        f"{name:24s} {count:5d} trials, {refused} refused ({time.perf_counter() - t0:.0f} s)",
        flush=True,
    )
    return count, refused


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=20, help="seeds per stage-2 / test-data setting")
    p.add_argument(
        "--check-solvers", action="store_true", help="also gate every solver (same verdict)"
    )
    p.add_argument("--sources", nargs="*", help="only these sources (default: all)")
    args = p.parse_args(argv)
    sources: list[tuple[str, Callable[[], Iterator[Trial]]]] = [
        ("stage2", lambda: stage2_trials(args.seeds, False)),
        ("stage2-kinematic-error", lambda: stage2_trials(max(args.seeds // 4, 1), True)),
        ("li2010", lambda: li2010_trials(10)),
        ("tests", lambda: synthetic_trials(args.seeds)),
    ]
    total = bad = 0
    for name, make in sources:
        if args.sources and name not in args.sources:
            continue
        c, r = run(name, make(), args.check_solvers)
        total, bad = total + c, bad + r
    print(f"{'all':24s} {total:5d} trials, {bad} refused")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
