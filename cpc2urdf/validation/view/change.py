"""How far calibration moved each link, and the colour scale the view paints it with.

A calibrated robot and its nominal model are posed at the same joint readings (joints matched by
name) and their links matched by name. A link's *change* is the largest distance any point of it
moved, ``max_p |T_cal p - T_nom p|`` [m], over

- its origin (the translation of the link frame),
- the corners of its visuals' bounding boxes (the part as drawn), and
- the six points :data:`CHANGE_LEVER` (0.1 m) from its origin along its axes,

so a rotation counts by the size of the part, and by at least a 0.1 m lever for a small or
invisible link (1 deg then reads 1.7 mm, 0.57 deg reads 1 mm). The translation [m] and rotation
angle [rad] are kept as well (:class:`LinkChange`).

The colour scale (:func:`change_rgba`) is green up to :data:`CHANGE_GREEN` (1 mm), yellow at
3.2 mm, red from :data:`CHANGE_RED` (10 mm), interpolated in log(distance) between; links of the
calibrated robot with no link of that name in the nominal model are grey. :func:`legend_html` is
the legend of the static page.
"""

from __future__ import annotations

import html
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from cpc2urdf.transforms import Array

CHANGE_GREEN = 1e-3  # [m]: a link that moved less is green
CHANGE_RED = 10e-3  # [m]: a link that moved this much or more is red
CHANGE_LEVER = 0.1  # [m]: points this far from a link's origin along its axes count too
GREEN_RGBA = (0.15, 0.7, 0.25, 1.0)
YELLOW_RGBA = (0.95, 0.8, 0.1, 1.0)
RED_RGBA = (0.85, 0.1, 0.1, 1.0)
UNMATCHED_RGBA = (0.6, 0.6, 0.6, 1.0)  # a link the nominal model does not have
CHANGE_GHOST_RGBA = (0.45, 0.5, 0.95, 0.3)  # the nominal ghost beside change colours: no green


@dataclass(frozen=True)
class LinkChange:
    """How far calibration moved one link (calibrated vs nominal, same joint readings).

    Attributes:
        link: The link name (the same in both models).
        translation: Distance between the two link origins [m].
        rotation: Angle of the rotation between the two link frames [rad], in [0, pi].
        displacement: The largest distance a point of the link moved [m] (module docstring).
    """

    link: str
    translation: float
    rotation: float
    displacement: float

    def format(self) -> str:
        """``head_2_link 12.3 mm (origin 4.1 mm, 1.2 deg)``."""
        return (
            f"{self.link} {1e3 * self.displacement:.3g} mm"
            f" (origin {1e3 * self.translation:.3g} mm, {math.degrees(self.rotation):.3g} deg)"
        )


def lever_points() -> Array:
    """The link's origin and the six points :data:`CHANGE_LEVER` from it along its axes [m],
    shape (7, 3), in the link frame."""
    return np.vstack([np.zeros(3), CHANGE_LEVER * np.eye(3), -CHANGE_LEVER * np.eye(3)])


def link_change(link: str, T_cal: Array, T_nom: Array, points_link: Array) -> LinkChange:
    """The :class:`LinkChange` of ``link`` from its pose in the calibrated and the nominal model.

    Args:
        link: The link name.
        T_cal: ``T_world_link`` in the calibrated model, shape (4, 4).
        T_nom: ``T_world_link`` in the nominal model, shape (4, 4).
        points_link: Points of the link [m], shape (K, 3), in its frame (bounding-box corners of
            its visuals); its origin and lever points are added.
    """
    P = np.vstack([lever_points(), np.asarray(points_link, dtype=float).reshape(-1, 3)])
    moved = P @ (T_cal[:3, :3] - T_nom[:3, :3]).T + (T_cal[:3, 3] - T_nom[:3, 3])
    R = T_nom[:3, :3].T @ T_cal[:3, :3]
    sin = 0.5 * float(np.linalg.norm([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]))
    angle = math.atan2(sin, 0.5 * (float(np.trace(R)) - 1.0))  # accurate for small angles too
    return LinkChange(
        link,
        float(np.linalg.norm(T_cal[:3, 3] - T_nom[:3, 3])),
        angle,
        float(np.linalg.norm(moved, axis=1).max()),
    )


def link_changes(
    T_cal: Mapping[str, Array],
    T_nom: Mapping[str, Array],
    points_link: Mapping[str, Sequence[Array]] | None = None,
) -> dict[str, LinkChange]:
    """The change of every link of the calibrated model that the nominal model also has.

    Args:
        T_cal: Link name -> ``T_world_link``, shape (4, 4), of the calibrated model.
        T_nom: The same for the nominal model at the same joint readings.
        points_link: Link name -> points of its visuals [m], each shape (K, 3), in its frame.

    Returns:
        Link name -> :class:`LinkChange`, in the calibrated model's link order.
    """
    points_link = points_link or {}
    out = {}
    for link, T in T_cal.items():
        if link in T_nom:
            pts = [np.asarray(p, dtype=float).reshape(-1, 3) for p in points_link.get(link, ())]
            P = np.vstack(pts) if pts else np.zeros((0, 3))
            out[link] = link_change(link, T, T_nom[link], P)
    return out


def _mix(a: Sequence[float], b: Sequence[float], t: float) -> tuple[float, float, float, float]:
    r, g, bl, al = ((1.0 - t) * x + t * y for x, y in zip(a, b, strict=True))
    return (r, g, bl, al)


def change_rgba(displacement: float) -> tuple[float, float, float, float]:
    """The colour of a link that moved ``displacement`` [m]: green up to :data:`CHANGE_GREEN`,
    yellow at their geometric mean (3.2 mm), red from :data:`CHANGE_RED`; in log(distance)."""
    if not displacement > CHANGE_GREEN:  # also NaN: nothing to show
        return GREEN_RGBA
    if displacement >= CHANGE_RED:
        return RED_RGBA
    t = math.log(displacement / CHANGE_GREEN) / math.log(CHANGE_RED / CHANGE_GREEN)
    return (
        _mix(GREEN_RGBA, YELLOW_RGBA, 2 * t) if t < 0.5 else _mix(YELLOW_RGBA, RED_RGBA, 2 * t - 1)
    )


def _css(rgba: Sequence[float]) -> str:
    r, g, b = (round(255 * c) for c in rgba[:3])
    return f"rgb({r},{g},{b})"


def legend_html(
    changes: Mapping[str, LinkChange],
    ghost: str,
    unmatched: Sequence[str] = (),
    top: int = 5,
    anchor: str | None = None,
) -> str:
    """The legend of the change colours, as an HTML block for the static page: the scale, the
    rule, and the ``top`` links that moved most.

    Args:
        changes: Link name -> :class:`LinkChange`.
        ghost: What the nominal model is (its source), as the legend names it.
        unmatched: Links of the calibrated robot the nominal model does not have (grey).
        top: How many of the most moved links to list.
        anchor: The link the ghost was aligned on (poses compared relative to it), or None
            (compared in one world).
    """
    ranked = sorted(changes.values(), key=lambda c: -c.displacement)[:top]
    stops = [(0.0, GREEN_RGBA), (0.5, YELLOW_RGBA), (1.0, RED_RGBA)]
    gradient = ", ".join(f"{_css(c)} {100 * x:.0f}%" for x, c in stops)
    rows = "".join(
        f'<tr><td><span style="background:{_css(change_rgba(c.displacement))}" '
        f'class="sw"></span>{html.escape(c.link)}</td><td>{1e3 * c.displacement:.3g} mm</td>'
        f"<td>{1e3 * c.translation:.3g} mm, {math.degrees(c.rotation):.3g}&deg;</td></tr>"
        for c in ranked
    )
    grey = (
        f'<div><span style="background:{_css(UNMATCHED_RGBA)}" class="sw"></span>'
        f"{len(unmatched)} links not in the nominal model</div>"
        if unmatched
        else ""
    )
    aligned = (
        f"relative to link {html.escape(anchor)} (the ghost aligned on it)"
        if anchor is not None
        else "in one world"
    )
    return f"""<div id="cpc2urdf-legend">
<div><b>How far calibration moved each link</b> (vs {html.escape(ghost)}, links matched by name,
same joint readings, {aligned}; the nominal model is the translucent blue ghost)</div>
<div class="bar" style="background: linear-gradient(to right, {gradient})"></div>
<div class="ticks"><span>&le; {1e3 * CHANGE_GREEN:g} mm</span><span>3.2 mm</span>
<span>&ge; {1e3 * CHANGE_RED:g} mm</span></div>
<div class="rule">largest distance a point of the link moved: its origin, its visuals' bounding
box, and points {1e3 * CHANGE_LEVER:g} mm along its axes (1&deg; &asymp; 1.7 mm)</div>
{grey}<table>{rows}</table>
</div>"""


LEGEND_CSS = """#cpc2urdf-legend { position: absolute; left: 8px; bottom: 8px; width: 330px;
  padding: 6px 8px; background: rgba(255,255,255,0.88); font: 12px sans-serif; color: #222;
  border: 1px solid #bbb; border-radius: 4px; }
#cpc2urdf-legend .bar { height: 12px; margin: 5px 0 2px 0; border: 1px solid #888; }
#cpc2urdf-legend .ticks { display: flex; justify-content: space-between; }
#cpc2urdf-legend .rule { margin: 3px 0; color: #555; font-size: 11px; }
#cpc2urdf-legend table { border-collapse: collapse; margin-top: 3px; }
#cpc2urdf-legend td { padding: 0 6px 0 0; }
#cpc2urdf-legend .sw { display: inline-block; width: 10px; height: 10px; margin-right: 4px;
  border: 1px solid #666; vertical-align: middle; }"""


__all__ = [
    "CHANGE_GHOST_RGBA",
    "CHANGE_GREEN",
    "CHANGE_LEVER",
    "CHANGE_RED",
    "GREEN_RGBA",
    "LEGEND_CSS",
    "RED_RGBA",
    "UNMATCHED_RGBA",
    "YELLOW_RGBA",
    "LinkChange",
    "change_rgba",
    "legend_html",
    "lever_points",
    "link_change",
    "link_changes",
]
