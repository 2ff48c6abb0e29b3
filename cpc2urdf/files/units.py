"""Unit handling at the file boundary: files may say mm/deg, everything inside is m/rad."""

from __future__ import annotations

import math
from collections.abc import Mapping

LENGTH_UNITS: dict[str, float] = {"m": 1.0, "cm": 0.01, "mm": 0.001}
ANGLE_UNITS: dict[str, float] = {"rad": 1.0, "deg": math.pi / 180.0}


class Units:
    """Scale factors from a file's units to SI (metres, radians).

    Args:
        length: Name of the length unit, one of ``LENGTH_UNITS``.
        angle: Name of the angle unit, one of ``ANGLE_UNITS``.
    """

    def __init__(self, length: str = "m", angle: str = "rad") -> None:
        if length not in LENGTH_UNITS:
            raise ValueError(f"units.length must be one of {sorted(LENGTH_UNITS)}, got {length!r}")
        if angle not in ANGLE_UNITS:
            raise ValueError(f"units.angle must be one of {sorted(ANGLE_UNITS)}, got {angle!r}")
        self.length_name = length
        self.angle_name = angle
        self.length = LENGTH_UNITS[length]  # [m per file unit]
        self.angle = ANGLE_UNITS[angle]  # [rad per file unit]

    @classmethod
    def from_json(cls, obj: object) -> Units:
        """Parse ``{"length": "mm", "angle": "deg"}``; a missing key means SI.

        Raises:
            ValueError: Not a mapping, unknown keys, or unknown unit names.
        """
        if obj is None:
            return cls()
        if not isinstance(obj, Mapping):
            raise ValueError(
                f"units must be an object like {{'length': 'm', 'angle': 'rad'}}, got {obj!r}"
            )
        unknown = set(obj) - {"length", "angle"}
        if unknown:
            raise ValueError(
                f"units has unknown keys {sorted(unknown)}; expected 'length' and 'angle'"
            )
        return cls(str(obj.get("length", "m")), str(obj.get("angle", "rad")))

    def to_json(self) -> dict[str, str]:
        return {"length": self.length_name, "angle": self.angle_name}

    def joint_scale(self, joint_type: str) -> float:
        """Factor from a file value of a joint of ``joint_type`` to SI (m or rad)."""
        return self.length if joint_type == "prismatic" else self.angle


SI = Units()


__all__ = [
    "ANGLE_UNITS",
    "LENGTH_UNITS",
    "SI",
    "Units",
]
