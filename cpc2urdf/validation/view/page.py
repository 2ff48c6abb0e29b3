"""The self-contained static HTML page of a view: no server, no network.

The page holds meshcat's viewer script inline, followed by every scene command inline (decoded
synchronously, no ``fetch``), animations last, so it opens without a network and without a
server and renders completely in the first frame. A view with change colours (a calibrated robot
and its nominal ghost) also carries their legend (:func:`~.change.legend_html`), over the scene,
and a view of a reachable region its own (:func:`~.region.region_legend_html`).
"""

from __future__ import annotations

import base64
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Protocol

import meshcat
import umsgpack
from meshcat.servers.tree import SceneTree, find_node, walk

from cpc2urdf.files.jsonio import write_atomic
from cpc2urdf.validation.view.change import LEGEND_CSS, legend_html
from cpc2urdf.validation.view.region import REGION_LEGEND_CSS, region_legend_html
from cpc2urdf.validation.view.scene import build_view
from cpc2urdf.validation.view.summary import ViewSummary
from cpc2urdf.validation.view.view_robot import RobotSource, ViewRobot


class SceneCommand(Protocol):
    """A meshcat scene command (``meshcat.commands.SetObject``, ``SetTransform``, ...)."""

    def lower(self) -> dict[str, Any]:
        """The command as the dict meshcat sends (msgpack)."""
        ...


class StaticWindow:
    """A meshcat window that records the scene instead of talking to a server.

    ``meshcat.Visualizer(window=StaticWindow())`` accepts every scene command; ``static_html()``
    then returns one self-contained page (same scene tree semantics as meshcat's server).

    Attributes:
        overlay: HTML shown over the scene (a legend), or empty.
    """

    def __init__(self) -> None:
        self.tree = SceneTree()
        self.web_url = None
        self.overlay = ""

    def send(self, command: SceneCommand) -> None:
        """Record ``command`` in the scene tree, as meshcat's server does."""
        data = command.lower()
        path = [p for p in data["path"].split("/") if p]
        packed = umsgpack.packb(data)
        kind = data["type"]
        if kind == "delete":
            if path:
                parent = find_node(self.tree, path[:-1])
                parent.pop(path[-1], None)
            else:
                self.tree = SceneTree()
            return
        node = find_node(self.tree, path)
        if kind == "set_object":
            node.object = packed
            node.properties = []
        elif kind == "set_transform":
            node.transform = packed
        elif kind == "set_property":
            node.properties.append(packed)
        elif kind == "set_animation":
            node.animation = packed

    def get_scene(self) -> str:
        """The page: meshcat's viewer script, then every command, animations last (an animation
        binds to the objects that exist when it loads)."""
        commands, animations = [], []
        for node in walk(self.tree):
            if node.object is not None:
                commands.append(node.object)
            commands.extend(node.properties)
            if node.transform is not None:
                commands.append(node.transform)
            if node.animation is not None:
                animations.append(node.animation)
        blobs = ",\n".join(
            f'"{base64.b64encode(c).decode("ascii")}"' for c in commands + animations
        )
        viewer_js = (Path(meshcat.__file__).parent / "viewer" / "dist" / "main.min.js").read_text(
            encoding="utf-8"
        )
        return _PAGE.format(
            viewer_js=viewer_js.replace("</script", "<\\/script"),
            blobs=blobs,
            css=LEGEND_CSS + "\n" + REGION_LEGEND_CSS if self.overlay else "",
            overlay=self.overlay,
        )


_PAGE = """<!DOCTYPE html>
<html>
<head><meta charset="utf-8"><title>cpc2urdf view</title>
<style>body {{ margin: 0; }} #meshcat-pane {{ width: 100vw; height: 100vh; overflow: hidden; }}
{css}</style>
</head>
<body>
<div id="meshcat-pane"></div>
{overlay}
<script>
{viewer_js}
</script>
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
function cpc2urdfBytes(s) {{
  var b = atob(s), a = new Uint8Array(b.length);
  for (var i = 0; i < b.length; i++) a[i] = b.charCodeAt(i);
  return a;
}}
[{blobs}].forEach(function (s) {{ viewer.handle_command_bytearray(cpc2urdfBytes(s)); }});
document.title = "cpc2urdf view (loaded)";
</script>
</body>
</html>
"""


def static_visualizer() -> meshcat.Visualizer:
    """A ``meshcat.Visualizer`` that needs no server; ``vis.static_html()`` gives the page."""
    return meshcat.Visualizer(window=StaticWindow())


def static_view_html(
    robot: ViewRobot | RobotSource, *, region_notes: Sequence[str] = (), **options: Any
) -> tuple[str, ViewSummary]:
    """The self-contained HTML page of :func:`build_view` (same options) and its summary; with a
    ``region``, its legend carries ``region_notes`` (lines: which joints moved, the tolerance)."""
    vis = static_visualizer()
    summary = build_view(vis, robot, **options)
    overlay = []
    if summary.link_changes and summary.ghost is not None:
        overlay.append(
            legend_html(
                summary.link_changes,
                os.path.basename(summary.ghost),
                summary.unmatched_links,
                anchor=summary.ghost_anchor if summary.ghost_aligned else None,
            )
        )
    if summary.region is not None:
        overlay.append(region_legend_html(summary.region, region_notes))
    vis.window.overlay = "\n".join(overlay)
    return vis.static_html(), summary


def write_view_html(
    path: str | os.PathLike[str], robot: ViewRobot | RobotSource, **options: Any
) -> ViewSummary:
    """Write the page of :func:`build_view` to ``path`` atomically (for the demo: a calibrated
    model with ``target=[x, y, z]``); returns the summary.

    Example:
        ``write_view_html("out/view.html", model, target=[-0.9, -0.1, 0.1], ghost="iis_head")``
    """
    html, summary = static_view_html(robot, **options)
    write_atomic(path, html)
    return summary


__all__ = [
    "SceneCommand",
    "StaticWindow",
    "static_view_html",
    "static_visualizer",
    "write_view_html",
]
