"""Robot spec files (``cpc2urdf/robot@1``): what a user writes for their own head or arm.

A spec gives the tree (joint names, types, parents, limits; named frames such as plates and
camera optical frames) and, optionally, nominal geometry. Identification needs only the tree;
viewing, gaze and simulation need geometry. Format (lengths/angles in the file's ``units``)::

    {
      "format": "cpc2urdf/robot@1",
      "name": "my_head",
      "units": {"length": "mm", "angle": "deg"},
      "geometry": "dh",                     # optional: "dh" or "cpc" (default "cpc")
      "world_to_base": {"xyz": [0, 0, 0], "rpy": [0, 0, 0]},            # optional
      "up": {"joint": "pan"},              # optional: or [x, y, z] in base coordinates
      "density": 2700,                     # optional: kg/m^3 of the drawn solids (SI always)
      "masses": {"camera_left": 0.3},      # optional: kg by URDF link name
      "joints": [
        {"name": "pan", "type": "revolute", "parent": "base",
         "lower": -90, "upper": 90, "velocity": 60, "effort": 5,        # velocity, effort optional
         "calibration_range": [-30, 30],                                # optional
         "nominal": {"dh": {"theta": 0, "d": 450, "a": 0, "alpha": -90}}}  # optional
      ],
      "frames": [
        {"name": "plate_left", "parent": "vergence_left", "kind": "plate",
         "layout": [[0, 0, 0], [20, 0, 0], ...],                        # plates only, optional
         "nominal": {"dh_frame": true}}
      ]
    }

Nominal geometry, per joint and frame, is one of:

- ``{"cpc": {"b": [bx, by, bz], "beta": beta, "l": [lx, ly, lz]}}``: the CPC constants of eq. (3)
  placing the joint's axis frame (or the frame) on its parent link;
- ``{"xyz": [...], "rpy": [...]}`` or ``{"xyz": [...], "quat_xyzw": [...]}`` or ``{"matrix": ...}``:
  the same placement as a pose;
- with ``"geometry": "dh"``: each joint gives its standard DH row ``{"dh": {"theta", "d", "a",
  "alpha"}}`` (the joint variable's own entry is ignored and may be 0). Then ``base`` is DH frame
  0, every child of joint i has its axis on DH frame i's z axis, and a frame is either
  ``{"dh_frame": true}`` (it *is* DH frame i of its parent joint i) or a pose relative to DH
  frame i. This makes ``T_base_frame = A_1 ... A_i`` exact (:func:`cpc2urdf.dh.cpc_from_dh`).

``up``, ``density`` and ``masses`` are for simulators (:mod:`cpc2urdf.urdf.physical`): which way is up
(``cpc2urdf export``'s gravity-aligned ``world``), and the link inertials of the URDF
(:mod:`cpc2urdf.urdf.document`). ``masses`` names URDF links (:func:`cpc2urdf.urdf.document.urdf_link_names`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from cpc2urdf.dh import dh_matrix
from cpc2urdf.errors import Cpc2UrdfError, InputFileError, SpecError
from cpc2urdf.files.jsonio import finite_float, float_list, read_json, require_format
from cpc2urdf.files.poses import pose_from_json
from cpc2urdf.files.units import Units
from cpc2urdf.model import BASE, IDENTITY, CPCModel, CPCParams, Frame, Joint, RobotStructure
from cpc2urdf.urdf.document import urdf_link_names
from cpc2urdf.urdf.physical import SPEC_KEYS, PhysicalProperties, check_masses, physical_from_json

ROBOT_FORMAT = "cpc2urdf/robot@1"
DEFAULT_VELOCITY = {"revolute": 1.0, "prismatic": 0.1}  # [rad/s], [m/s]
DEFAULT_EFFORT = {"revolute": 10.0, "prismatic": 100.0}  # [N m], [N]

_JOINT_KEYS = {
    "name",
    "type",
    "parent",
    "lower",
    "upper",
    "velocity",
    "effort",
    "calibration_range",
    "nominal",
    "cpc",
    "description",
}
_FRAME_KEYS = {"name", "parent", "kind", "layout", "nominal", "cpc", "description"}


@dataclass
class RobotSpec:
    """A parsed robot spec: its tree, the nominal model if the spec had geometry, and what a
    simulator needs (density, masses, up: :class:`~cpc2urdf.urdf.physical.PhysicalProperties`)."""

    structure: RobotStructure
    nominal: CPCModel | None
    source: str
    physical: PhysicalProperties = field(default_factory=PhysicalProperties)

    def nominal_model(self) -> CPCModel:
        """The nominal model, or :class:`SpecError` if the spec gives no geometry."""
        if self.nominal is None:
            raise SpecError(
                f"{self.source}: robot {self.structure.name!r} has no nominal geometry "
                "(give 'nominal' for every joint and frame, or identify it from measurements)"
            )
        return self.nominal


def _mapping(obj: Any, where: str) -> Mapping[str, Any]:
    if not isinstance(obj, Mapping):
        raise ValueError(f"{where} must be an object, got {obj!r}")
    return obj


def parse_cpc(obj: Any, units: Units, where: str) -> CPCParams:
    """Parse ``{"b": [3], "beta": x, "l": [3]}`` (beta in angle units, l in length units)."""
    m = _mapping(obj, where)
    unknown = set(m) - {"b", "beta", "l"}
    if unknown:
        raise ValueError(f"{where} has unknown keys {sorted(unknown)}; expected b, beta, l")
    for k in ("b", "beta", "l"):
        if k not in m:
            raise ValueError(f"{where} lacks {k!r}")
    b = float_list(m["b"], 3, f"{where}.b")
    n = math.sqrt(sum(v * v for v in b))
    if abs(n - 1.0) > 1e-6:
        raise ValueError(f"{where}.b must be a unit vector, |b| = {n:.9g}")
    beta = finite_float(m["beta"], f"{where}.beta") * units.angle
    l = [v * units.length for v in float_list(m["l"], 3, f"{where}.l")]
    return CPCParams(tuple(b), beta, tuple(l))  # type: ignore[arg-type]


def cpc_to_json(p: CPCParams) -> dict[str, Any]:
    """CPC constants in SI units for a file (full float precision)."""
    return {"b": [float(v) for v in p.b], "beta": float(p.beta), "l": [float(v) for v in p.l]}


def parse_placement(obj: Any, units: Units, where: str) -> CPCParams:
    """A placement given as ``{"cpc": {...}}`` or as a pose (xyz+rpy/quat_xyzw, matrix)."""
    m = _mapping(obj, where)
    if "cpc" in m:
        if len(m) != 1:
            raise ValueError(f"{where}: give either 'cpc' or a pose, not both")
        return parse_cpc(m["cpc"], units, f"{where}.cpc")
    return CPCParams.from_matrix(pose_from_json(m, units, where))


def _named_entry(
    obj: Any, kind: str, i: int, keys: set[str]
) -> tuple[Mapping[str, Any], str, str, str]:
    """Common checks of a ``joints[i]`` / ``frames[i]`` entry: an object with a non-empty name,
    known keys only, a parent name. Returns ``(entry, name, where, parent)``."""
    where = f"{kind}s[{i}]"
    m = _mapping(obj, where)
    name = m.get("name")
    if not isinstance(name, str) or not name:
        raise ValueError(f"{where}.name must be a non-empty string")
    where = f"{kind} {name!r}"
    unknown = set(m) - keys
    if unknown:
        raise ValueError(
            f"{where} has unknown keys {sorted(unknown)}; expected some of {sorted(keys)}"
        )
    parent = m.get("parent", BASE)
    if not isinstance(parent, str):
        raise ValueError(f"{where}.parent must be a joint name or 'base', got {parent!r}")
    return m, name, where, parent


def _parse_joint(obj: Any, units: Units, i: int) -> tuple[Joint, Any]:
    m, name, where, parent = _named_entry(obj, "joint", i, _JOINT_KEYS)
    jtype = m.get("type")
    if jtype not in ("revolute", "prismatic"):
        raise ValueError(f"{where}.type must be 'revolute' or 'prismatic', got {jtype!r}")
    s = units.joint_scale(jtype)
    for k in ("lower", "upper"):
        if k not in m:
            raise ValueError(f"{where} lacks {k!r} (URDF needs limits; no continuous joints)")
    lower = finite_float(m["lower"], f"{where}.lower") * s
    upper = finite_float(m["upper"], f"{where}.upper") * s
    velocity = (
        finite_float(m["velocity"], f"{where}.velocity") * s
        if "velocity" in m
        else DEFAULT_VELOCITY[jtype]
    )
    effort = (
        finite_float(m["effort"], f"{where}.effort") if "effort" in m else DEFAULT_EFFORT[jtype]
    )
    cal = None
    if "calibration_range" in m:
        lo, hi = float_list(m["calibration_range"], 2, f"{where}.calibration_range")
        cal = (lo * s, hi * s)
    geometry = m.get("cpc", m.get("nominal"))
    if "cpc" in m and "nominal" in m:
        raise ValueError(f"{where}: give either 'cpc' or 'nominal', not both")
    if "cpc" in m:
        geometry = {"cpc": m["cpc"]}
    joint = Joint(name, jtype, parent, lower, upper, velocity, effort, cal)
    return joint, geometry


def _parse_frame(obj: Any, units: Units, i: int) -> tuple[Frame, Any]:
    m, name, where, parent = _named_entry(obj, "frame", i, _FRAME_KEYS)
    kind = m.get("kind", "frame")
    layout = None
    if "layout" in m:
        pts = m["layout"]
        if not isinstance(pts, list) or len(pts) < 3:
            raise ValueError(f"{where}.layout must be a list of at least 3 points [x, y, z]")
        layout = tuple(
            tuple(v * units.length for v in float_list(p, 3, f"{where}.layout[{k}]"))
            for k, p in enumerate(pts)
        )
    if "cpc" in m and "nominal" in m:
        raise ValueError(f"{where}: give either 'cpc' or 'nominal', not both")
    geometry = {"cpc": m["cpc"]} if "cpc" in m else m.get("nominal")
    return Frame(name, parent, str(kind), layout), geometry  # type: ignore[arg-type]


def parse_tree(doc: Mapping[str, Any], units: Units) -> tuple[RobotStructure, list[Any], list[Any]]:
    """The tree of a spec or model document, and the raw geometry entries of joints and frames."""
    name = doc.get("name")
    if not isinstance(name, str) or not name:
        raise ValueError("'name' must be a non-empty string")
    joints_raw = doc.get("joints")
    if not isinstance(joints_raw, list) or not joints_raw:
        raise ValueError("'joints' must be a non-empty list")
    frames_raw = doc.get("frames", [])
    if not isinstance(frames_raw, list):
        raise ValueError("'frames' must be a list")
    parsed_j = [_parse_joint(o, units, i) for i, o in enumerate(joints_raw)]
    parsed_f = [_parse_frame(o, units, i) for i, o in enumerate(frames_raw)]
    structure = RobotStructure(name, [j for j, _ in parsed_j], [f for f, _ in parsed_f])
    geo_j = {j.name: g for j, g in parsed_j}
    geo_f = {f.name: g for f, g in parsed_f}
    return (
        structure,
        [geo_j[n] for n in structure.joint_names],
        [geo_f[n] for n in structure.frame_names],
    )


def _nominal_from_dh(
    structure: RobotStructure, geo_j: list[Any], geo_f: list[Any], units: Units, T_wb: CPCParams
) -> CPCModel:
    C: dict[str, np.ndarray] = {}
    for j, g in zip(structure.joints, geo_j, strict=True):
        where = f"joint {j.name!r}.nominal"
        dh = _mapping(_mapping(g, where).get("dh"), f"{where}.dh")
        unknown = set(dh) - {"theta", "d", "a", "alpha"}
        if unknown:
            raise ValueError(f"{where}.dh has unknown keys {sorted(unknown)}")
        vals = {
            k: finite_float(dh.get(k, 0.0), f"{where}.dh.{k}") for k in ("theta", "d", "a", "alpha")
        }
        # The joint variable replaces theta (revolute) or d (prismatic): it is the reading.
        theta = 0.0 if j.type == "revolute" else vals["theta"] * units.angle
        d = 0.0 if j.type == "prismatic" else vals["d"] * units.length
        C[j.name] = dh_matrix(theta, d, vals["a"] * units.length, vals["alpha"] * units.angle)
    joints = {
        j.name: (IDENTITY if j.parent == BASE else CPCParams.from_matrix(C[j.parent]))
        for j in structure.joints
    }
    frames: dict[str, CPCParams] = {}
    for f, g in zip(structure.frames, geo_f, strict=True):
        where = f"frame {f.name!r}.nominal"
        m = _mapping(g, where)
        C_parent = np.eye(4) if f.parent == BASE else C[f.parent]
        if m.get("dh_frame") is True:
            if len(m) != 1:
                raise ValueError(f"{where}: 'dh_frame' stands alone")
            frames[f.name] = CPCParams.from_matrix(C_parent)
        else:
            frames[f.name] = CPCParams.from_matrix(C_parent @ pose_from_json(m, units, where))
    return CPCModel(structure, T_wb, joints, frames)


def spec_from_json(doc: Any, source: str = "<spec>") -> RobotSpec:
    """Parse a ``cpc2urdf/robot@1`` document; errors name ``source`` and the field."""
    try:
        d = require_format(doc, ROBOT_FORMAT, source)
        allowed = {
            "format",
            "name",
            "description",
            "units",
            "geometry",
            "world_to_base",
            "joints",
            "frames",
            *SPEC_KEYS,
        }
        unknown = set(d) - allowed
        if unknown:
            raise ValueError(f"unknown keys {sorted(unknown)}; expected some of {sorted(allowed)}")
        units = Units.from_json(d.get("units"))
        structure, geo_j, geo_f = parse_tree(d, units)
        physical = physical_from_json(d, structure.joint_names)
        check_masses(physical, urdf_link_names(structure))
        T_wb = (
            parse_placement(d["world_to_base"], units, "world_to_base")
            if "world_to_base" in d
            else IDENTITY
        )
        style = d.get("geometry", "cpc")
        if style not in ("cpc", "dh"):
            raise ValueError(f"'geometry' must be 'cpc' or 'dh', got {style!r}")
        given = [g is not None for g in geo_j + geo_f]
        nominal: CPCModel | None = None
        if any(given):
            names = list(structure.joint_names) + list(structure.frame_names)
            lacking = [n for n, ok in zip(names, given, strict=True) if not ok]
            if lacking:
                raise ValueError(
                    f"nominal geometry is given for some joints/frames but not for {lacking}"
                )
            if style == "dh":
                nominal = _nominal_from_dh(structure, geo_j, geo_f, units, T_wb)
            else:
                joints = {
                    j.name: parse_placement(g, units, f"joint {j.name!r}.nominal")
                    for j, g in zip(structure.joints, geo_j, strict=True)
                }
                frames = {
                    f.name: parse_placement(g, units, f"frame {f.name!r}.nominal")
                    for f, g in zip(structure.frames, geo_f, strict=True)
                }
                nominal = CPCModel(structure, T_wb, joints, frames)
        return RobotSpec(structure, nominal, source, physical)
    except InputFileError:
        raise
    except (ValueError, Cpc2UrdfError) as e:
        raise InputFileError(source, str(e)) from e


def load_spec(path: str | Path) -> RobotSpec:
    """Read and parse a robot spec file."""
    return spec_from_json(read_json(path), str(path))


__all__ = [
    "DEFAULT_EFFORT",
    "DEFAULT_VELOCITY",
    "ROBOT_FORMAT",
    "RobotSpec",
    "cpc_to_json",
    "load_spec",
    "parse_cpc",
    "parse_placement",
    "parse_tree",
    "spec_from_json",
]
