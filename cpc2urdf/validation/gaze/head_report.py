"""The gaze head as a property of the model, reported once: its kind and, for two eyes, whether
their optical axes can meet exactly and, if not, the vertical disparity left over the workspace
ahead, with the head facing the target, and what fixation alone reaches turned away from it.

Used by ``cpc2urdf check`` (a model with two camera frames) and ``cpc2urdf gaze ROBOT --report``.
The numbers come from :meth:`~cpc2urdf.validation.gaze.GazeSolver.disparity_report`: seeded
targets 0.4-3 m ahead of the home cyclopean axis within 30 deg of it
(:meth:`~cpc2urdf.validation.gaze.GazeSolver.ahead_targets`), each solved by the compiled solver
with its cyclopean policy; the pointing error left is the larger of the two eyes'. On a head
that cannot fixate exactly with the head facing the target, the same targets are also solved by
fixation alone (the ``min-motion`` policy, where the head has it): a calibrated head's axes may
still meet at isolated postures turned away from the target (``calibrated_iis_head(0)``: exactly,
pan 3.6-21 deg off facing), or nowhere in the limits (the demo's head: 0.45-0.55 deg, pan 36-47
deg off).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from cpc2urdf.validation.gaze.chain import KIND_BINOCULAR
from cpc2urdf.validation.gaze.result import STATUS_DISPARITY, STATUS_FIXATED, STATUS_LIMITS
from cpc2urdf.validation.gaze.solver import GazeSolver

REPORT_TARGETS = 200  # targets of the disparity report (a few ms of compiled solves)
REPORT_SEED = 0


def head_report(
    solver: GazeSolver, n: int = REPORT_TARGETS, seed: int = REPORT_SEED
) -> dict[str, Any]:
    """``{"cameras", "kind", "joints"}`` (``joints``: what the solver moves) and, on a two-eye
    (``binocular``) head, ``"exact"`` (whether the eyes' axes can meet exactly), ``"disparity"``
    (:meth:`GazeSolver.disparity_report` over ``n`` seeded targets ahead) and, where they cannot
    and the head's min-motion policy solves fixation alone, ``"fixation_alone"``: over the same
    targets, how many fixation alone fixates, its statuses, and over the ``answered`` ones (fixated,
    or its best held by a limit; not the failed ones) the median and max pointing error it leaves
    [rad] and how far it turns a joint from the facing posture (median and max over the targets
    of the largest change of a revolute joint) [rad]."""
    rep: dict[str, Any] = {
        "cameras": list(solver.cameras),
        "kind": solver.kind,
        "joints": list(solver.moving),
    }
    if solver.kind == KIND_BINOCULAR:
        d = solver.disparity_report(n, seed)
        rep["exact"] = not solver.disparity_head
        rep["disparity"] = d
        if solver.disparity_head:
            alone = _fixation_alone(solver, n, seed)
            if alone is not None:
                rep["fixation_alone"] = alone
    return rep


def _fixation_alone(solver: GazeSolver, n: int, seed: int) -> dict[str, Any] | None:
    """The ``fixation_alone`` part of :func:`head_report`; None on a head whose min-motion
    policy is its cyclopean one (the facing answer: nothing to compare)."""
    if not solver._policy_engine("min-motion").exact:
        return None
    P = solver.ahead_targets(n, seed)
    facing = solver.solve_many(P)
    revolute = np.array([solver.joint_kinds[j] == "revolute" for j in solver.joint_names])
    errors, turns, statuses = [], [], []
    for i, p in enumerate(P):
        sol = solver.solve(p, policy="min-motion")
        statuses.append(sol.status)
        errors.append(float(np.max(sol.pointing_error)))
        turns.append(float(np.max(np.abs(sol.q - facing.q[i])[revolute], initial=0.0)))
    # its best in-limit answers (fixated, or held by a limit); not the failed ones (no solution, behind)
    kept = np.array([st in (STATUS_FIXATED, STATUS_LIMITS, STATUS_DISPARITY) for st in statuses])
    e, t = np.array(errors)[kept], np.array(turns)[kept]
    return {
        "targets": n,
        "fixated": int(sum(st == STATUS_FIXATED for st in statuses)),
        "answered": int(kept.sum()),
        "median_rad": float(np.median(e)) if e.size else None,
        "max_rad": float(e.max()) if e.size else None,
        "turn_median_rad": float(np.median(t)) if t.size else None,
        "turn_max_rad": float(t.max()) if t.size else None,
        "statuses": {st: statuses.count(st) for st in sorted(set(statuses))},
    }


def format_head_report(rep: dict[str, Any]) -> list[str]:
    """The lines of :func:`head_report` for a terminal (angles in degrees)."""
    cams = ", ".join(rep["cameras"])
    lines = [f"gaze head ({cams}): {rep['kind']}, moving {', '.join(rep['joints'])}"]
    if "disparity" not in rep:
        return lines
    d = rep["disparity"]
    n = d["targets"]
    counts = d["statuses"]
    over = f"{n} targets 0.4-3 m ahead"
    others = ", ".join(
        f"{k} {v}" for k, v in counts.items() if v and k not in (STATUS_FIXATED, STATUS_DISPARITY)
    )
    tail = f"; not pointed at: {others}" if others else ""
    if not d["answered"]:
        lines.append(f"  none of {over} is pointed at with the moving joints ({others})")
        return lines
    median, worst = math.degrees(d["median_rad"]), math.degrees(d["max_rad"])
    if rep["exact"]:
        lines.append(
            f"  the two eyes' axes can meet exactly: {counts[STATUS_FIXATED]} of {over} fixated "
            f"(pointing error max {worst:.3g} deg){tail}"
        )
        return lines
    lines.append(
        f"  the two eyes' axes meet only on a curve (vertical disparity): with the head facing the target "
        f"(cyclopean policy) each eye is off by median {median:.3g} deg, max {worst:.3g} deg over {d['answered']} of "
        f"{over} ({counts[STATUS_DISPARITY]} answered with status disparity, {counts[STATUS_FIXATED]} within the "
        f"tolerance){tail}"
    )
    a = rep.get("fixation_alone")
    if a is not None and a["answered"]:
        failed = a["targets"] - a["answered"]
        lines.append(
            f"  turned away from facing, fixation alone (policy min-motion) fixates {a['fixated']} of them within the tolerance "
            f"(pointing error median {math.degrees(a['median_rad']):.3g} deg, max {math.degrees(a['max_rad']):.3g} deg"
            + (
                f", over the {a['answered']} it answers in the limits; {failed} failed"
                if failed
                else ""
            )
            + f"); it turns a joint by median {math.degrees(a['turn_median_rad']):.3g} deg, "
            f"max {math.degrees(a['turn_max_rad']):.3g} deg from the facing posture"
        )
    return lines


__all__ = ["REPORT_SEED", "REPORT_TARGETS", "format_head_report", "head_report"]
