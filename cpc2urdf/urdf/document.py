"""URDF export of a CPC model: kinematically exact, and loadable as it is by simulators.

The tree maps one to one (see :mod:`cpc2urdf.model`):

- root link ``world``; fixed joint ``base_joint`` to link ``base``. What ``world`` is depends on
  ``mount`` (the model's own world is always the measuring rig, ``T_world_base`` of a model file):

  - ``mount="rig"`` (the default of :func:`urdf_from_model`): ``world`` *is* the model's world,
    ``base_joint`` is ``T_world_base``; every pose in the URDF equals the model's FK. The gaze
    solver, the view and ``check`` work in this frame.
  - ``mount="base"`` (the default of ``cpc2urdf export``): ``world`` is gravity-aligned (+z up, the
    spec's ``up``, :mod:`cpc2urdf.urdf.physical`) with its origin at the base origin; ``base_joint`` is
    the rotation :func:`cpc2urdf.urdf.physical.gravity_rotation` only. Simulators put gravity along
    -z of the root, so the robot stands upright. Poses relative to ``base`` are the model's.

- joint ``<j>`` (revolute or prismatic, always with ``<limit>``, never ``continuous``) from its
  parent's link to link ``<j>_link``, with ``<origin>`` = the CPC constants placing its axis frame
  (eq. (3)) and ``<axis xyz="0 0 1"/>``: the URDF joint frame *is* the CPC axis frame, so the
  child link frame is the CPC link frame, ``axis @ Q(q)`` (eq. (6));
- fixed joint ``<frame>_joint`` to link ``<frame>`` for every named frame (plates, cameras), from
  its link, except that a camera optical frame (REP-103: z forward, x right, y down) hangs off a
  camera BODY link (REP-103 body convention: x forward, y left, z up) at the same origin:
  ``<body>_joint`` from the frame's link to ``<body>`` (``camera_left`` for ``camera_left_optical``,
  :func:`camera_body_names`), then ``<frame>_joint`` with the fixed rotation
  :data:`T_BODY_OPTICAL` (rpy ``-pi/2 0 -pi/2``). The optical frame's pose is unchanged.

Simulation: every link but ``world`` has an ``<inertial>`` (:mod:`cpc2urdf.urdf.mass_properties`) from
its solid primitives at the stated density, or the stated mass, on principal axes (a diagonal
tensor); a link with nothing solid on it gets 1 g (:func:`~cpc2urdf.urdf.mass_properties.frame_floor`).
Solid primitives also are the ``<collision>`` geometry (the base plate, plate circles and frame
markers are paint only). Every ``<visual>`` and ``<collision>`` name is unique in the file. A ``<mujoco><compiler
discardvisual="false" fusestatic="false"/></mujoco>`` element (``mujoco=False`` leaves it out)
makes MuJoCo keep every link as a body and draw the visuals; urdfdom, Pinocchio, yourdfpy and
PyBullet ignore it silently.

URDF writes rotations as roll-pitch-yaw; :func:`cpc2urdf.transforms.rpy_from_matrix` keeps that
exact to ~1e-16 even at pitch = ±90°, and numbers are written with ``repr`` (shortest string that
reads back to the same double), so parsers reproduce the model to rounding.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from cpc2urdf.errors import ConfigurationError
from cpc2urdf.files.jsonio import write_atomic
from cpc2urdf.model import BASE, RESERVED_NAMES, WORLD, CPCModel, RobotStructure
from cpc2urdf.transforms import Array, cpc_rotation, rpy_from_matrix
from cpc2urdf.urdf.mass_properties import MassProperties, combined, frame_floor, solid
from cpc2urdf.urdf.physical import PhysicalProperties, check_masses, gravity_rotation

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
MOUNTS = ("rig", "base")
OPTICAL_SUFFIXES = ("_optical_frame", "_optical")
# REP-103: the optical frame (z forward, x right, y down) in the body frame (x forward, y left, z up).
T_BODY_OPTICAL = np.array(
    [[0.0, 0.0, 1.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
)
MUJOCO_ELEMENT = (
    '  <mujoco>\n    <compiler discardvisual="false" fusestatic="false"/>\n  </mujoco>\n'
)


@dataclass(frozen=True, eq=False)
class Primitive:
    """One shape drawn on a link: a ``<visual>``, and if ``solid`` also a ``<collision>`` and part
    of the link's mass.

    Attributes:
        name: Visual name (made unique in the file when written).
        shape: ``"box"`` (size x y z), ``"cylinder"`` (radius, length; axis z) or ``"sphere"`` (radius).
        size: Its dimensions [m].
        T: Pose of its centre in the link frame, shape (4, 4).
        material: A name in :data:`MATERIALS`.
        solid: True for a part with volume (mass, collision); False for paint (plate circles, markers).
    """

    name: str
    shape: str
    size: tuple[float, ...]
    T: Array
    material: str
    solid: bool = True

    def geometry(self) -> str:
        if self.shape == "box":
            return f'<box size="{urdf_vector(self.size)}"/>'
        if self.shape == "cylinder":
            return f'<cylinder radius="{urdf_number(self.size[0])}" length="{urdf_number(self.size[1])}"/>'
        return f'<sphere radius="{urdf_number(self.size[0])}"/>'


def link_name(joint_or_base: str) -> str:
    """URDF link carrying the children of a joint (``<j>_link``), or ``base``."""
    return BASE if joint_or_base == BASE else f"{joint_or_base}_link"


def camera_body_names(structure: RobotStructure) -> dict[str, str]:
    """The body link of every camera frame: ``camera_left`` for ``camera_left_optical`` (or
    ``..._optical_frame``), else ``<frame>_body``; a name already used by a link or joint of the
    URDF falls back to the next of ``<frame>_body``, ``<frame>_body_2``, ..."""
    links = {WORLD, BASE, *(link_name(n) for n in structure.joint_names), *structure.frame_names}
    joints = {"base_joint", *structure.joint_names, *(f"{n}_joint" for n in structure.frame_names)}
    out: dict[str, str] = {}
    for f in structure.frames:
        if f.kind != "camera":
            continue
        stem = next((f.name[: -len(s)] for s in OPTICAL_SUFFIXES if f.name.endswith(s)), "")
        candidates = (
            ([stem] if stem else [])
            + [f"{f.name}_body"]
            + [f"{f.name}_body_{k}" for k in range(2, 100)]
        )
        body = next(
            c
            for c in candidates
            if c not in links and f"{c}_joint" not in joints and c not in RESERVED_NAMES
        )
        out[f.name] = body
        links.add(body)
        joints.add(f"{body}_joint")
    return out


def urdf_link_names(structure: RobotStructure) -> list[str]:
    """Every link the URDF of a robot with this structure has, in file order."""
    bodies = camera_body_names(structure)
    names = [WORLD, BASE, *(link_name(n) for n in structure.joint_names)]
    for f in structure.frames:
        names.extend([bodies[f.name], f.name] if f.name in bodies else [f.name])
    return names


def urdf_number(v: float) -> str:
    """``v`` as URDF text: the shortest text that reads back to the same double; no -0."""
    v = float(v)
    return "0" if v == 0.0 else repr(v)  # also turns -0.0 into 0


def urdf_vector(v: Array | Sequence[float]) -> str:
    """The numbers of ``v`` as URDF text (:func:`urdf_number`), space-separated."""
    return " ".join(urdf_number(x) for x in v)


def origin_attributes(T: Array) -> str:
    """The ``xyz="..." rpy="..."`` attributes of an ``<origin>`` placing pose ``T`` (4x4)."""
    return f'xyz="{urdf_vector(T[:3, 3])}" rpy="{urdf_vector(rpy_from_matrix(T[:3, :3]))}"'


def _origin(T: Array) -> str:
    return f"<origin {origin_attributes(T)}/>"


def _at(xyz: Array | Sequence[float], R: Array | None = None) -> Array:
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    T[:3, 3] = xyz
    return T


def _bone(p: Array, material: str, name: str) -> Primitive:
    """A cylinder from the link origin to point ``p`` [m] in the link frame."""
    length = float(np.linalg.norm(p))
    # eq. (4) maps z onto the bone direction
    return Primitive(
        name, "cylinder", (BONE_RADIUS, length), _at(p / 2.0, cpc_rotation(p / length)), material
    )


def _link_primitives(model: CPCModel, owner: str) -> list[Primitive]:
    """Shapes of the link moved by joint ``owner`` (or of ``base``)."""
    s = model.structure
    material = "cpc2urdf_base" if owner == BASE else "cpc2urdf_head"
    if owner == BASE:
        # A marker of the base frame, not a part: the base is welded to the root, nothing to collide.
        out = [
            Primitive(
                "base_plate", "box", (0.12, 0.12, 0.01), np.eye(4), "cpc2urdf_base", solid=False
            )
        ]
    elif s.joint(owner).type == "revolute":
        out = [
            Primitive(
                f"{owner}_axis",
                "cylinder",
                (JOINT_RADIUS, JOINT_LENGTH),
                np.eye(4),
                "cpc2urdf_joint",
            )
        ]
    else:
        out = [Primitive(f"{owner}_axis", "box", (0.025, 0.025, 0.08), np.eye(4), "cpc2urdf_joint")]
    for child in s.children(owner):
        p = model.joints[child.name].matrix()[:3, 3]
        if np.linalg.norm(p) > MIN_BONE:
            out.append(_bone(p, material, f"to_{child.name}"))
    for f in s.frames:
        if f.parent == owner:
            p = model.frames[f.name].matrix()[:3, 3]
            if np.linalg.norm(p) > MIN_BONE:
                out.append(_bone(p, material, f"to_{f.name}"))
    return out


def _frame_primitives(model: CPCModel, name: str) -> list[Primitive]:
    """Shapes of the link of frame ``name``; a camera's are in its BODY link's frame."""
    f = model.structure.frame(name)
    if f.kind == "plate":
        pts = np.array(f.layout) if f.layout is not None else np.zeros((1, 3))
        half = float(np.max(np.abs(pts[:, :2]))) + 0.015
        out = [
            Primitive(
                f"{name}_board",
                "box",
                (2 * half, 2 * half, 0.004),
                _at([0, 0, -0.002]),
                "cpc2urdf_plate",
            )
        ]
        for k, p in enumerate(pts):
            out.append(
                Primitive(
                    f"{name}_circle_{k}",
                    "cylinder",
                    (0.006, 0.001),
                    _at(p + [0, 0, 0.0005]),
                    "cpc2urdf_circle",
                    solid=False,
                )
            )
        return out
    if f.kind == "camera":  # a housing behind the lens, the lens along the optical axis (optical z)
        return [
            Primitive(
                f"{name}_housing",
                "box",
                (0.045, 0.035, 0.05),
                T_BODY_OPTICAL @ _at([0, 0, -0.03]),
                "cpc2urdf_camera",
            ),
            Primitive(f"{name}_lens", "cylinder", (0.012, 0.02), T_BODY_OPTICAL, "cpc2urdf_lens"),
        ]
    return [
        Primitive(f"{name}_marker", "sphere", (0.006,), np.eye(4), "cpc2urdf_joint", solid=False)
    ]


def _mass_properties(
    prims: Sequence[Primitive], mass: float | None, density: float
) -> MassProperties:
    solids = [solid(p.shape, p.size, p.T, density) for p in prims if p.solid]
    if not solids:
        return frame_floor() if mass is None else frame_floor(mass)
    mp = combined(solids)
    return mp if mass is None else mp.with_mass(mass)


def _inertial(mp: MassProperties) -> str:
    R, moments = mp.principal()
    return (
        f'    <inertial>\n      {_origin(_at(mp.com, R))}\n      <mass value="{urdf_number(mp.mass)}"/>\n'
        f'      <inertia ixx="{urdf_number(moments[0])}" ixy="0" ixz="0" iyy="{urdf_number(moments[1])}" iyz="0" '
        f'izz="{urdf_number(moments[2])}"/>\n    </inertial>\n'
    )


def _link(
    name: str, prims: Sequence[Primitive], names: dict[int, tuple[str, str]], mp: MassProperties
) -> str:
    out = [f"  <link name={quoteattr(name)}>\n", _inertial(mp)]
    for p in prims:
        out.append(
            f"    <visual name={quoteattr(names[id(p)][0])}>\n      {_origin(p.T)}\n"
            f"      <geometry>{p.geometry()}</geometry>\n"
            f'      <material name="{p.material}"/>\n    </visual>\n'
        )
    for p in prims:
        if p.solid:
            out.append(
                f"    <collision name={quoteattr(names[id(p)][1])}>\n      {_origin(p.T)}\n"
                f"      <geometry>{p.geometry()}</geometry>\n    </collision>\n"
            )
    out.append("  </link>\n")
    return "".join(out)


def _unique_names(links: Sequence[tuple[str, list[Primitive]]]) -> dict[int, tuple[str, str]]:
    """``id(primitive) -> (visual name, collision name)``, unique over the whole file."""
    used: set[str] = set()

    def take(want: str) -> str:
        name, k = want, 2
        while name in used:
            name, k = f"{want}_{k}", k + 1
        used.add(name)
        return name

    out = {}
    for _, prims in links:
        for p in prims:
            out[id(p)] = (take(p.name), "")
    for _, prims in links:
        for p in prims:
            if p.solid:
                out[id(p)] = (out[id(p)][0], take(f"{out[id(p)][0]}_collision"))
    return out


def _fixed(name: str, parent: str, child: str, T: Array) -> str:
    return (
        f'  <joint name={quoteattr(name)} type="fixed">\n    <parent link={quoteattr(parent)}/>\n'
        f"    <child link={quoteattr(child)}/>\n    {_origin(T)}\n  </joint>\n"
    )


def T_world_base_of(
    model: CPCModel, mount: str, physical: PhysicalProperties | None = None
) -> Array:
    """The ``base_joint`` origin the URDF of ``model`` gets with ``mount`` (shape (4, 4)):
    ``T_world_base`` for ``"rig"``, the gravity rotation of ``physical``'s up for ``"base"``."""
    if mount not in MOUNTS:
        raise ConfigurationError(f"mount must be one of {', '.join(MOUNTS)}, got {mount!r}")
    if mount == "rig":
        return model.T_world_base()
    up = (physical or PhysicalProperties()).up_in_base(model)
    return _at([0.0, 0.0, 0.0], gravity_rotation(up))


def _header(model: CPCModel, source: str | None, mount: str, physical: PhysicalProperties) -> str:
    from cpc2urdf.version import __version__

    world = (
        "the measuring rig (the model's world)"
        if mount == "rig"
        else f"gravity-aligned (+z up; up = {physical.describe_up()}) at the base origin"
    )
    text = (
        f"generated by cpc2urdf {__version__}{' from ' + source if source else ''}. Units: m, rad, kg. "
        f"Joint frames are CPC axis frames (Shih et al. eq. (3)). Root 'world': {world}. "
        f"Inertials: solid primitives at {physical.density:g} kg/m^3"
        f"{' (masses stated for ' + ', '.join(sorted(physical.masses)) + ')' if physical.masses else ''}; "
        "1 g on links with nothing solid. Camera body links (x forward) carry the optical frames (REP-103)."
    )
    return "<!-- " + text.replace("--", "- -") + " -->\n"


def urdf_from_model(
    model: CPCModel,
    *,
    source: str | None = None,
    mount: str = "rig",
    physical: PhysicalProperties | None = None,
    mujoco: bool = True,
) -> str:
    """The URDF text of ``model`` (deterministic: same model and options, same bytes).

    Args:
        model: The CPC model.
        source: Where the model came from, written in a comment.
        mount: ``"rig"``: root ``world`` is the model's world (the measuring rig); ``"base"``:
            root ``world`` is gravity-aligned at the base origin (see the module docstring).
        physical: Density, link masses and up direction (default :class:`PhysicalProperties`:
            1000 kg/m^3, no stated masses, base +z up).
        mujoco: Write the ``<mujoco><compiler .../></mujoco>`` element.

    Raises:
        ConfigurationError: An unknown ``mount``.
        SpecError: ``physical.masses`` names a link the URDF does not have.
        UnknownNameError: ``physical.up_joint`` is not a joint of the model.
    """
    phys = physical or PhysicalProperties()
    s = model.structure
    check_masses(phys, urdf_link_names(s))
    T_wb = T_world_base_of(model, mount, phys)
    bodies = camera_body_names(s)
    # (link name, shapes) in file order; fixed joints are written between them.
    links: list[tuple[str, list[Primitive]]] = [(BASE, _link_primitives(model, BASE))]
    links += [(link_name(j.name), _link_primitives(model, j.name)) for j in s.joints]
    for f in s.frames:
        if f.name in bodies:
            links += [(bodies[f.name], _frame_primitives(model, f.name)), (f.name, [])]
        else:
            links.append((f.name, _frame_primitives(model, f.name)))
    names = _unique_names(links)
    shapes = dict(links)

    def link_xml(name: str) -> str:
        return _link(
            name,
            shapes[name],
            names,
            _mass_properties(shapes[name], phys.masses.get(name), phys.density),
        )

    out = [
        '<?xml version="1.0"?>\n',
        _header(model, source, mount, phys),
        f"<robot name={quoteattr(s.name)}>\n",
    ]
    if mujoco:
        out.append(MUJOCO_ELEMENT)
    for name, rgba in MATERIALS.items():
        out.append(f'  <material name="{name}"><color rgba="{urdf_vector(rgba)}"/></material>\n')
    out.append(f'  <link name="{WORLD}"/>\n')
    out.append(_fixed("base_joint", WORLD, BASE, T_wb))
    out.append(link_xml(BASE))
    for j in s.joints:
        out.append(
            f'  <joint name={quoteattr(j.name)} type="{j.type}">\n'
            f'    <parent link="{link_name(j.parent)}"/>\n'
            f'    <child link="{link_name(j.name)}"/>\n'
            f"    {_origin(model.joints[j.name].matrix())}\n"
            f'    <axis xyz="0 0 1"/>\n'
            f'    <limit lower="{urdf_number(j.lower)}" upper="{urdf_number(j.upper)}" '
            f'effort="{urdf_number(j.effort)}" velocity="{urdf_number(j.velocity)}"/>\n'
            "  </joint>\n"
        )
        out.append(link_xml(link_name(j.name)))
    for f in s.frames:
        T = model.frames[f.name].matrix()
        if f.name in bodies:
            body = bodies[f.name]
            out.append(_fixed(f"{body}_joint", link_name(f.parent), body, T @ T_BODY_OPTICAL.T))
            out.append(link_xml(body))
            out.append(_fixed(f"{f.name}_joint", body, f.name, T_BODY_OPTICAL))
        else:
            out.append(_fixed(f"{f.name}_joint", link_name(f.parent), f.name, T))
        out.append(link_xml(f.name))
    out.append("</robot>\n")
    return "".join(out)


def write_urdf(
    model: CPCModel,
    path: str | Path,
    *,
    source: str | None = None,
    mount: str = "rig",
    physical: PhysicalProperties | None = None,
    mujoco: bool = True,
) -> Path:
    """Write the URDF of ``model`` (:func:`urdf_from_model`, same options) to ``path`` atomically
    (no partial file on failure)."""
    return write_atomic(
        path, urdf_from_model(model, source=source, mount=mount, physical=physical, mujoco=mujoco)
    )


def total_mass(model: CPCModel, physical: PhysicalProperties | None = None) -> float:
    """Sum of the ``<inertial>`` masses [kg] the URDF of ``model`` gets."""
    import xml.etree.ElementTree as ET

    root = ET.fromstring(urdf_from_model(model, physical=physical, mujoco=False))
    return math.fsum(float(m.get("value", "0")) for m in root.iter("mass"))


__all__ = [
    "BONE_RADIUS",
    "HEAD_RGBA",
    "JOINT_LENGTH",
    "JOINT_RADIUS",
    "MATERIALS",
    "MIN_BONE",
    "MOUNTS",
    "MUJOCO_ELEMENT",
    "OPTICAL_SUFFIXES",
    "T_BODY_OPTICAL",
    "Primitive",
    "T_world_base_of",
    "camera_body_names",
    "link_name",
    "origin_attributes",
    "total_mass",
    "urdf_from_model",
    "urdf_link_names",
    "urdf_number",
    "urdf_vector",
    "write_urdf",
]
