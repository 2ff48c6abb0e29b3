"""What a view shows (:class:`ViewSummary`): for the CLI to print and tests to check."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from cpc2urdf.transforms import Array
from cpc2urdf.validation.gaze import DEFAULT_CAMERAS, GazeSolution
from cpc2urdf.validation.view.camera import VIEWER_FOV
from cpc2urdf.validation.view.change import CHANGE_GREEN, CHANGE_RED, LinkChange
from cpc2urdf.validation.view.meshes import VisualMeshes
from cpc2urdf.validation.view.region import RegionShown


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
        cameras: The camera optical frames of the gaze (one, or left and right).
        link_changes: With a ghost (the nominal model) and change colours: how far calibration
            moved each link, link name -> :class:`~cpc2urdf.validation.view.change.LinkChange`
            (:mod:`cpc2urdf.validation.view.change`); empty otherwise.
        unmatched_links: Links of the robot the ghost does not have (drawn grey).
        ghost_anchor: The link both have to align on (``base``, or the robot's root link;
            :func:`~cpc2urdf.validation.view.scene.ghost_alignment`), or None.
        ghost_offset: ``T_r T_g^-1`` of the anchor: the ghost's world in the robot's, shape
            (4, 4) (identity when both describe the same world).
        ghost_aligned: Whether the ghost was put on the anchor (links compared relative to it);
            False: compared in one world.
        meshes: What the robot's visuals are made of (mesh count, files, triangles).
        region: The reachable region drawn (counts, point size, where it was put), or None.
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
    link_changes: dict[str, LinkChange] = field(default_factory=dict)
    unmatched_links: tuple[str, ...] = ()
    ghost_anchor: str | None = None
    ghost_offset: Array = field(default_factory=lambda: np.eye(4))
    ghost_aligned: bool = False
    meshes: VisualMeshes | None = None
    region: RegionShown | None = None

    def largest_changes(self, n: int = 5) -> list[LinkChange]:
        """The ``n`` links calibration moved most, largest first."""
        return sorted(self.link_changes.values(), key=lambda c: -c.displacement)[:n]

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

    def alignment(self) -> str:
        """How the ghost is placed, in words (:attr:`ghost_anchor`, :attr:`ghost_offset`)."""
        if self.ghost_anchor is None:
            return "none (no link in common to align on); compared in one world"
        T = self.ghost_offset
        d = float(np.linalg.norm(T[:3, 3]))
        angle = math.degrees(
            math.acos(max(-1.0, min(1.0, 0.5 * (float(np.trace(T[:3, :3])) - 1.0))))
        )
        apart = f"{self.ghost_anchor!r} {1e3 * d:.4g} mm, {angle:.4g} deg apart"
        if self.ghost_aligned:
            return f"on link {self.ghost_anchor!r}, poses compared relative to it (the worlds' {apart})"
        return f"none, compared in one world ({apart})"

    def format(self) -> str:
        """A few lines for a terminal."""
        lines = [f"robot {self.robot}: " + ", ".join(f"{k}={v:.6g}" for k, v in self.q.items())]
        if self.target is not None and self.gaze is not None:
            errors = self.gaze.pointing_error.tolist()
            # one error per solved axis: each camera's, or a rigid pair's one cyclopean axis
            axes = (
                self.cameras
                if len(errors) == len(self.cameras)
                else ("cyclopean axis",) * len(errors)
            )
            err = ", ".join(
                f"{k} {math.degrees(v):.3g} deg" for k, v in zip(axes, errors, strict=True)
            )
            lines.append(
                f"target {np.array2string(self.target, precision=4)} m: {self.gaze.status}"
                f" (reachable={self.gaze.reachable}; pointing error {err})"
            )
        if self.meshes is not None and self.meshes.n_meshes:
            lines.append(self.meshes.format())
        if self.ghost:
            lines.append(f"ghost aligned: {self.alignment()}")
        if self.ghost and self.link_changes:
            lines.append(f"ghost: {self.ghost} (translucent blue, same joint readings)")
            d = np.array([c.displacement for c in self.link_changes.values()])
            lines.append(
                f"calibration moved {len(d)} links (matched by name): "
                f"{int((d < CHANGE_GREEN).sum())} < {1e3 * CHANGE_GREEN:g} mm (green), "
                f"{int(((d >= CHANGE_GREEN) & (d < CHANGE_RED)).sum())} in between (yellow), "
                f"{int((d >= CHANGE_RED).sum())} >= {1e3 * CHANGE_RED:g} mm (red); most: "
                + "; ".join(c.format() for c in self.largest_changes(3))
            )
            if self.unmatched_links:
                lines.append(f"not in the ghost (grey): {', '.join(self.unmatched_links)}")
        elif self.ghost:
            lines.append(f"ghost: {self.ghost} (translucent green, same configuration)")
        if self.n_measured:
            lines.append(
                f"measurements: {self.n_measured} plate positions, residual rms {1e3 * self.residual_rms:.3g} mm,"
                f" max {1e3 * self.residual_max:.3g} mm (bars magnified x{self.residual_scale:.3g})"
            )
        if self.region is not None:
            lines.append(self.region.format())
        if self.skipped_visuals:
            lines.append(
                f"note: {self.skipped_visuals} URDF visuals could not be drawn (unsupported shape or mesh)"
            )
        return "\n".join(lines)


__all__ = ["ViewSummary"]
