"""``--range JOINT=LO:HI``: calibration ranges given on the command line (``plan``, ``simulate``).

``LO`` and ``HI`` are in mm (prismatic joints) or deg (revolute joints). ``JOINT`` is a joint of
the robot; for a URDF robot it may be the URDF's own joint name (``head_1_joint``) or the model's
(``head_1``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if (
    TYPE_CHECKING
):  # the spec module loads numpy: imported inside the function (fast `cpc2urdf --help`)
    from cpc2urdf.files.spec import RobotSpec


def parse_ranges(items: list[str], spec: RobotSpec) -> dict[str, tuple[float, float]]:
    """``--range`` values by the model's joint name, [m]/[rad].

    Raises:
        ConfigurationError: Not ``JOINT=LO:HI`` with finite ``LO <= HI``, or an unknown joint.
    """
    from cpc2urdf.errors import ConfigurationError
    from cpc2urdf.urdf.robot import UrdfRobot

    structure = spec.structure
    out: dict[str, tuple[float, float]] = {}
    for item in items:
        name, sep, rest = item.partition("=")
        lo_s, sep2, hi_s = rest.partition(":")
        try:
            if not sep or not sep2:
                raise ValueError
            lo, hi = float(lo_s), float(hi_s)
            if not (math.isfinite(lo) and math.isfinite(hi)) or lo > hi:
                raise ValueError
        except ValueError:
            raise ConfigurationError(
                f"--range {item!r}: expected JOINT=LO:HI with LO <= HI (mm or deg)"
            ) from None
        if isinstance(spec, UrdfRobot) and spec.names is not None:
            name = spec.cpc_joint(name) or name
        j = structure.joint(name)
        scale = 1e-3 if j.type == "prismatic" else math.pi / 180
        out[name] = (lo * scale, hi * scale)
    return out


__all__ = ["parse_ranges"]
