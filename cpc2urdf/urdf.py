"""URDF export of a CPC model.

The tree maps one to one (see :mod:`cpc2urdf.model`):

- root link ``world``; fixed joint ``base_joint`` to link ``base`` at ``T_world_base``;
- joint ``<j>`` (revolute or prismatic, always with ``<limit>``, never ``continuous``) from its
  parent's link to link ``<j>_link``, with ``<origin>`` = the CPC constants placing its axis frame
  (eq. (3)) and ``<axis xyz="0 0 1"/>``: the URDF joint frame *is* the CPC axis frame, so the
  child link frame is the CPC link frame, ``axis @ Q(q)`` (eq. (6));
- fixed joint ``<frame>_joint`` to link ``<frame>`` for every named frame (plates, cameras).

URDF writes rotations as roll-pitch-yaw; :func:`cpc2urdf.transforms.rpy_from_matrix` keeps that
exact to ~1e-16 even at pitch = ±90°, and numbers are written with ``repr`` (shortest string that
reads back to the same double), so parsers reproduce the model to rounding.

Visuals are primitives (cylinders on joint axes, bones between joint frames, plates with their
circles, camera bodies with a lens along the optical axis) so the head is visible in meshcat.
"""

from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from cpc2urdf.fileio import write_atomic
from cpc2urdf.model import BASE, WORLD, CPCModel
from cpc2urdf.transforms import Array, cpc_rotation, rpy_from_matrix

# name: rgba. HEAD_RGBA is the colour of the moving head links, which the browser test looks for.
HEAD_RGBA = (0.15, 0.35, 0.85, 1.0)
MATERIALS: dict[str, tuple[float, float, float, float]] = {
    "cpc2urdf_base": (0.55, 0.55, 0.55, 1.0),
    "cpc2urdf_head": HEAD_RGBA,
    "cpc2urdf_joint": (0.95, 0.55, 0.1, 1.0),
    "cpc2urdf_plate": (0.95, 0.95, 0.92, 1.0),
    "cpc2urdf_circle": (0.1, 0.1, 0.1, 1.0),
    "cpc2urdf_camera": (0.12, 0.12, 0.12, 1.0),
    "cpc2urdf_lens": (0.3, 0.8, 0.9, 1.0),
}
BONE_RADIUS = 0.008  # [m]
JOINT_RADIUS = 0.02  # [m]
JOINT_LENGTH = 0.05  # [m]
MIN_BONE = 1e-3  # [m]: shorter offsets get no bone


def link_name(joint_or_base: str) -> str:
    """URDF link carrying the children of a joint (``<j>_link``), or ``base``."""
    return BASE if joint_or_base == BASE else f"{joint_or_base}_link"


def _num(v: float) -> str:
    v = float(v)
    return "0" if v == 0.0 else repr(v)  # also turns -0.0 into 0


def _vec(v: Array | list[float] | tuple[float, ...]) -> str:
    return " ".join(_num(x) for x in v)


def _origin(T: Array) -> str:
    return f'<origin xyz="{_vec(T[:3, 3])}" rpy="{_vec(rpy_from_matrix(T[:3, :3]))}"/>'


def _visual(geometry: str, T: Array, material: str, name: str) -> str:
    return (
        f"    <visual name={quoteattr(name)}>\n      {_origin(T)}\n"
        f"      <geometry>{geometry}</geometry>\n"
        f'      <material name="{material}"/>\n    </visual>\n'
    )


def _bone(p: Array, material: str, name: str) -> str:
    """A cylinder from the link origin to point ``p`` [m] in the link frame."""
    length = float(np.linalg.norm(p))
    T = np.eye(4)
    T[:3, :3] = cpc_rotation(p / length)  # eq. (4) maps z onto the bone direction
    T[:3, 3] = p / 2.0
    return _visual(f'<cylinder radius="{_num(BONE_RADIUS)}" length="{_num(length)}"/>', T, material, name)


def _link_visuals(model: CPCModel, owner: str) -> str:
    """Visuals of the link moved by joint ``owner`` (or of ``base``)."""
    s = model.structure
    out = []
    material = "cpc2urdf_base" if owner == BASE else "cpc2urdf_head"
    if owner == BASE:
        out.append(_visual('<box size="0.12 0.12 0.01"/>', np.eye(4), "cpc2urdf_base", "base_plate"))
    else:
        joint = s.joint(owner)
        if joint.type == "revolute":
            geo = f'<cylinder radius="{_num(JOINT_RADIUS)}" length="{_num(JOINT_LENGTH)}"/>'
        else:
            geo = '<box size="0.025 0.025 0.08"/>'
        out.append(_visual(geo, np.eye(4), "cpc2urdf_joint", f"{owner}_axis"))
    for child in s.children(owner):
        p = model.joints[child.name].matrix()[:3, 3]
        if np.linalg.norm(p) > MIN_BONE:
            out.append(_bone(p, material, f"to_{child.name}"))
    for f in s.frames:
        if f.parent == owner:
            p = model.frames[f.name].matrix()[:3, 3]
            if np.linalg.norm(p) > MIN_BONE:
                out.append(_bone(p, material, f"to_{f.name}"))
    return "".join(out)


def _frame_visuals(model: CPCModel, name: str) -> str:
    f = model.structure.frame(name)
    if f.kind == "plate":
        pts = np.array(f.layout) if f.layout is not None else np.zeros((1, 3))
        half = float(np.max(np.abs(pts[:, :2]))) + 0.015
        T = np.eye(4)
        T[2, 3] = -0.002
        out = [_visual(f'<box size="{_num(2 * half)} {_num(2 * half)} 0.004"/>', T, "cpc2urdf_plate", "plate")]
        for k, p in enumerate(pts):
            Tc = np.eye(4)
            Tc[:3, 3] = p
            Tc[2, 3] += 0.0005
            out.append(_visual('<cylinder radius="0.006" length="0.001"/>', Tc, "cpc2urdf_circle", f"circle_{k}"))
        return "".join(out)
    if f.kind == "camera":
        Tb = np.eye(4)
        Tb[2, 3] = -0.03
        Tl = np.eye(4)
        Tl[2, 3] = 0.0
        return _visual('<box size="0.045 0.035 0.05"/>', Tb, "cpc2urdf_camera", "body") + _visual(
            '<cylinder radius="0.012" length="0.02"/>', Tl, "cpc2urdf_lens", "lens"
        )
    return _visual('<sphere radius="0.006"/>', np.eye(4), "cpc2urdf_joint", "marker")


def urdf_from_model(model: CPCModel, *, source: str | None = None) -> str:
    """The URDF text of ``model`` (deterministic: same model, same bytes).

    Args:
        model: The CPC model.
        source: Where the model came from, written in a comment.
    """
    from cpc2urdf.version import __version__

    s = model.structure
    out = ['<?xml version="1.0"?>\n']
    out.append(f"<!-- generated by cpc2urdf {__version__}")
    if source:
        out.append(f" from {source.replace('--', '- -')}")
    out.append(". Units: m, rad. Joint frames are CPC axis frames (Shih et al. eq. (3)). -->\n")
    out.append(f"<robot name={quoteattr(s.name)}>\n")
    for name, rgba in MATERIALS.items():
        out.append(f'  <material name="{name}"><color rgba="{_vec(rgba)}"/></material>\n')
    out.append(f'  <link name="{WORLD}"/>\n')
    out.append(
        f'  <joint name="base_joint" type="fixed">\n    <parent link="{WORLD}"/>\n'
        f'    <child link="{BASE}"/>\n    {_origin(model.T_world_base())}\n  </joint>\n'
    )
    out.append(f'  <link name="{BASE}">\n{_link_visuals(model, BASE)}  </link>\n')
    for j in s.joints:
        out.append(
            f"  <joint name={quoteattr(j.name)} type=\"{j.type}\">\n"
            f'    <parent link="{link_name(j.parent)}"/>\n'
            f'    <child link="{link_name(j.name)}"/>\n'
            f"    {_origin(model.joints[j.name].matrix())}\n"
            f'    <axis xyz="0 0 1"/>\n'
            f'    <limit lower="{_num(j.lower)}" upper="{_num(j.upper)}" '
            f'effort="{_num(j.effort)}" velocity="{_num(j.velocity)}"/>\n'
            "  </joint>\n"
        )
        out.append(f'  <link name="{link_name(j.name)}">\n{_link_visuals(model, j.name)}  </link>\n')
    for f in s.frames:
        out.append(
            f'  <joint name="{f.name}_joint" type="fixed">\n'
            f'    <parent link="{link_name(f.parent)}"/>\n'
            f'    <child link="{f.name}"/>\n'
            f"    {_origin(model.frames[f.name].matrix())}\n  </joint>\n"
        )
        out.append(f'  <link name="{f.name}">\n{_frame_visuals(model, f.name)}  </link>\n')
    out.append("</robot>\n")
    return "".join(out)


def write_urdf(model: CPCModel, path: str | Path, *, source: str | None = None) -> Path:
    """Write the URDF of ``model`` to ``path`` atomically (no partial file on failure)."""
    return write_atomic(path, urdf_from_model(model, source=source))


__all__ = [
    "BONE_RADIUS",
    "HEAD_RGBA",
    "JOINT_LENGTH",
    "JOINT_RADIUS",
    "MATERIALS",
    "MIN_BONE",
    "link_name",
    "urdf_from_model",
    "write_urdf",
]
