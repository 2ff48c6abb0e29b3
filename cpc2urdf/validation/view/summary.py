"""What a view shows (:class:`ViewSummary`): for the CLI to print and tests to check."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from cpc2urdf.transforms import Array
from cpc2urdf.validation.gaze import DEFAULT_CAMERAS, GazeSolution
from cpc2urdf.validation.view.camera import VIEWER_FOV


@dataclass
class ViewSummary:
    """What a view shows, for the CLI to print and tests to check.

    Attributes:
        robot: Robot name.
        q: Shown configuration, joint name -> value [rad]/[m].
        target: The target [m], shape (3,), or None.
        gaze: The gaze solve (its readings are :attr:`q`), or None without a target.
        ghost: Source of the ghost model, or None.
        n_measured: Measured plate positions drawn.
        residual_max: Longest measured-to-predicted distance [m] (NaN without measurements).
        residual_rms: RMS of those distances [m] (NaN without measurements).
        residual_scale: Magnification of the residual bars (1 = true length).
        skipped_visuals: URDF visuals the view cannot draw (unsupported shapes, missing meshes).
        camera_position: Where the viewer camera was placed [m], shape (3,), in world.
        camera_target: The point it looks at [m], shape (3,), in world.
        up: The world direction shown upwards, unit, shape (3,).
        cameras: The two camera optical frames (left, right) of the gaze.
    """

    robot: str
    q: dict[str, float]
    target: Array | None = None
    gaze: GazeSolution | None = None
    ghost: str | None = None
    n_measured: int = 0
    residual_max: float = float("nan")
    residual_rms: float = float("nan")
    residual_scale: float = 1.0
    skipped_visuals: int = 0
    camera_position: Array = field(default_factory=lambda: np.zeros(3))
    camera_target: Array = field(default_factory=lambda: np.zeros(3))
    up: Array = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    cameras: tuple[str, ...] = DEFAULT_CAMERAS

    def pixel(
        self, p_world: ArrayLike, width: int = 1024, height: int = 768
    ) -> tuple[float, float]:
        """Where ``p_world`` [m], shape (3,), appears in a ``width`` x ``height`` [px] screenshot
        of the page before the user moves the camera: (column, row) from the top left [px]."""
        back = self.camera_position - self.camera_target
        back /= np.linalg.norm(back)
        right = np.cross(self.up, back)
        right /= np.linalg.norm(right)
        cam_up = np.cross(back, right)
        d = np.asarray(p_world, dtype=float) - self.camera_position
        depth = -float(d @ back)
        tan_v = math.tan(math.radians(VIEWER_FOV / 2.0))
        tan_u = tan_v * width / height
        x, y = float(d @ right) / depth / tan_u, float(d @ cam_up) / depth / tan_v
        return 0.5 * width * (1.0 + x), 0.5 * height * (1.0 - y)

    def format(self) -> str:
        """A few lines for a terminal."""
        lines = [f"robot {self.robot}: " + ", ".join(f"{k}={v:.6g}" for k, v in self.q.items())]
        if self.target is not None and self.gaze is not None:
            err = ", ".join(
                f"{k} {math.degrees(v):.3g} deg"
                for k, v in zip(self.cameras, self.gaze.pointing_error.tolist(), strict=True)
            )
            lines.append(
                f"target {np.array2string(self.target, precision=4)} m: {self.gaze.status}"
                f" (reachable={self.gaze.reachable}; pointing error {err})"
            )
        if self.ghost:
            lines.append(f"ghost: {self.ghost} (translucent green, same configuration)")
        if self.n_measured:
            lines.append(
                f"measurements: {self.n_measured} plate positions, residual rms {1e3 * self.residual_rms:.3g} mm,"
                f" max {1e3 * self.residual_max:.3g} mm (bars magnified x{self.residual_scale:.3g})"
            )
        if self.skipped_visuals:
            lines.append(
                f"note: {self.skipped_visuals} URDF visuals could not be drawn (unsupported shape or mesh)"
            )
        return "\n".join(lines)


__all__ = ["ViewSummary"]
