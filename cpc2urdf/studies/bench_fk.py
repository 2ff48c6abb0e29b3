"""Benchmark: vectorised CPC forward kinematics vs a Pinocchio per-configuration loop.

Both compute ``T_world_frame`` of every named frame of the same robot at the same N random
configurations, in the same run; we report configurations per second and the ratio, after
checking that the two agree (a benchmark of a wrong answer is worthless).

    cpc2urdf bench fk [--model iis_head] [--configurations 20000] [--repeat 5]
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from typing import TypeVar

import numpy as np

from cpc2urdf.argparsing import OneLineParser

R = TypeVar("R")  # what a timed function returns


def run_benchmark(
    model_name: str = "iis_head", n: int = 20000, repeat: int = 5, seed: int = 0
) -> dict[str, float]:
    """Time both FKs; returns configurations per second and the agreement.

    Args:
        model_name: Model file, robot spec or shipped robot name.
        n: Number of configurations per timing.
        repeat: Timings per method; the best is reported (least disturbed by other load).
        seed: Seed of the configurations.
    """
    import pinocchio as pin

    from cpc2urdf.files.robot_ref import load_model
    from cpc2urdf.urdf.pinocchio import PinocchioRobot
    from cpc2urdf.validation.crosscheck import sample_configurations

    model = load_model(model_name)
    s = model.structure
    Q = sample_configurations(model, n, seed)
    robot = PinocchioRobot.from_model(model)
    pmodel = robot.model
    data = pmodel.createData()
    fids = [robot.frame_id(f, pin.FrameType.BODY) for f in s.frame_names]
    perm = [robot.joint_index(name) for name in s.joint_names]
    Qp = np.zeros_like(Q)
    Qp[:, perm] = Q

    def cpc() -> dict[str, np.ndarray]:
        return model.fk(Q)

    def pinocchio_loop() -> np.ndarray:
        out = np.empty((len(Q), len(fids), 4, 4))
        for k in range(len(Qp)):
            pin.framesForwardKinematics(pmodel, data, Qp[k])
            for i, fid in enumerate(fids):
                out[k, i] = data.oMf[fid].homogeneous
        return out

    def best(fn: Callable[[], R]) -> tuple[float, R]:
        times = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            result = fn()
            times.append(time.perf_counter() - t0)
        return min(times), result

    t_cpc, ours = best(cpc)
    t_pin, theirs = best(pinocchio_loop)
    err = max(float(np.max(np.abs(ours[f] - theirs[:, i]))) for i, f in enumerate(s.frame_names))
    return {
        "configurations": float(len(Q)),
        "frames": float(len(fids)),
        "cpc_vectorised_per_s": len(Q) / t_cpc,
        "pinocchio_loop_per_s": len(Q) / t_pin,
        "speedup": t_pin / t_cpc,
        "max_abs_difference": err,
    }


def main(argv: list[str]) -> int:
    p = OneLineParser(
        prog="cpc2urdf bench fk",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--model", default="iis_head")
    p.add_argument("--configurations", type=int, default=20000)
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    if args.configurations < 2 or args.repeat < 1:
        p.error("--configurations must be >= 2 and --repeat >= 1")
    r = run_benchmark(args.model, args.configurations, args.repeat)
    if args.json:
        print(json.dumps(r, indent=2))
    else:
        print(
            f"forward kinematics of {int(r['frames'])} frames, {int(r['configurations'])} configurations (best of {args.repeat}):"
        )
        print(f"  CPC vectorised (numpy)   {r['cpc_vectorised_per_s']:12,.0f} configurations/s")
        print(f"  Pinocchio loop (python)  {r['pinocchio_loop_per_s']:12,.0f} configurations/s")
        print(f"  ratio                    {r['speedup']:12.1f}x")
        print(f"  max |difference|         {r['max_abs_difference']:12.2e}")
    return 0


__all__ = ["main", "run_benchmark"]
