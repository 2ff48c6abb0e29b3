"""The gaze head as a property of the model, reported once: its kind and, for two eyes, whether
they can fixate exactly and the vertical disparity left over the workspace ahead.

Used by ``cpc2urdf check`` (a model with two camera frames) and ``cpc2urdf gaze ROBOT --report``.
The numbers come from :meth:`~cpc2urdf.validation.gaze.GazeSolver.disparity_report`: seeded
targets 0.4-3 m ahead of the home cyclopean axis within 30 deg of it, each solved by the
compiled solver with its cyclopean policy; the pointing error left is the larger of the two eyes'.
"""

from __future__ import annotations

import math
from typing import Any

from cpc2urdf.validation.gaze.chain import KIND_BINOCULAR
from cpc2urdf.validation.gaze.solver import GazeSolver

REPORT_TARGETS = 200  # targets of the disparity report (a few ms of compiled solves)
REPORT_SEED = 0


def head_report(solver: GazeSolver, n: int = REPORT_TARGETS, seed: int = REPORT_SEED) -> dict[str, Any]:
    """``{"cameras", "kind", "joints"}`` and, on a two-eye (``binocular``) head,
    ``"exact"`` (whether the eyes can fixate exactly), ``"disparity"`` (the report: median,
    p95 and max pointing error left [rad] over ``n`` seeded targets ahead, their statuses)."""
    rep: dict[str, Any] = {
        "cameras": list(solver.cameras),
        "kind": solver.kind,
        "joints": list(solver.chain.moving or solver.chain.variables),
    }
    if solver.kind == KIND_BINOCULAR:
        d = solver.disparity_report(n, seed)
        rep["exact"] = not solver.disparity_head
        rep["disparity"] = d
    return rep


def format_head_report(rep: dict[str, Any]) -> list[str]:
    """The lines of :func:`head_report` for a terminal (angles in degrees)."""
    cams = ", ".join(rep["cameras"])
    lines = [f"gaze head ({cams}): {rep['kind']}, moving {', '.join(rep['joints'])}"]
    if "disparity" in rep:
        d = rep["disparity"]
        over = f"over {d['targets']} targets 0.4-3 m ahead"
        median, worst = math.degrees(d["median_rad"]), math.degrees(d["max_rad"])
        if rep["exact"]:
            lines.append(f"  the two eyes can fixate exactly (pointing error left {over}: max {worst:.3g} deg)")
        else:
            lines.append(
                f"  the two eyes cannot fixate exactly (vertical disparity): pointing error left per eye {over}: "
                f"median {median:.3g} deg, max {worst:.3g} deg; such targets are answered with status disparity"
            )
    return lines


__all__ = ["REPORT_SEED", "REPORT_TARGETS", "format_head_report", "head_report"]
