"""One way from a URDF (or a CPC model) to Pinocchio: :class:`PinocchioRobot`.

The gaze solver, the view, the URDF cross-check and the FK benchmark all need the same few
things from Pinocchio: the kinematic model of a URDF, its joints in configuration order with
their limits, and frame ids by name. :class:`PinocchioRobot` gives them once, with the checks
every user needs:

- the URDF must pass :func:`cpc2urdf.urdf.input.validate_urdf` (well-formed XML, one tree of
  named links and joints, finite numbers, ...) before Pinocchio sees it, and Pinocchio must read
  it without complaint: one clear line otherwise, naming the file; urdfdom's own output is
  captured (:func:`cpc2urdf.urdf.native_output.captured_output`), never shown;
- every moving joint must be a 1-DoF revolute or prismatic joint (no floating or planar joints),
  so the configuration is one reading per joint, in :attr:`joint_names` order; a ``continuous``
  joint is refused too, unless asked to read it as an unlimited revolute joint
  (``continuous_as_revolute=True``, as the view does: limits -inf..inf, one reading, the angle);
- frame and joint names are checked here: Pinocchio's ``getFrameId`` returns ``nframes`` for a
  name it does not know instead of raising.

Which robot a name means (``HEAD.URDF``, a model file, a robot spec, a shipped robot) is decided
by :mod:`cpc2urdf.files.robot_ref` (:meth:`PinocchioRobot.load`).

Frames: ``T_world_<frame>`` is the pose of ``<frame>`` in ``world`` (Pinocchio's ``oMf``).
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from cpc2urdf.errors import InputFileError, SpecError, UnknownNameError
from cpc2urdf.files.jsonio import read_text_file
from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.files.robot_ref import is_urdf_ref, load_model
from cpc2urdf.model import CPCModel
from cpc2urdf.transforms import Array
from cpc2urdf.urdf.document import urdf_from_model
from cpc2urdf.urdf.input import validate_urdf
from cpc2urdf.urdf.native_output import captured_output
from cpc2urdf.urdf.robot import UrdfRobot

PRISMATIC = ("PX", "PY", "PZ", "PrismaticUnaligned")  # Pinocchio joint model short names
REVOLUTE = ("RX", "RY", "RZ", "RevoluteUnaligned")
UNSUPPORTED_KINDS = {  # Pinocchio short name -> the URDF joint type it comes from
    "RUBX": "continuous",
    "RUBY": "continuous",
    "RUBZ": "continuous",
    "RUBUnaligned": "continuous",
    "FreeFlyer": "floating",
    "Planar": "planar",
}
TEXT_SOURCE = "<URDF string>"  # the source named in errors about URDF text given directly
UNLIMITED = 1e300  # [rad]: the limit a continuous joint is given for Pinocchio; set to inf after


class UnsupportedJointError(InputFileError):
    """A URDF with joints other than 1-DoF revolute or prismatic ones.

    Args:
        path: The URDF's source, as errors name it.
        joints: ``(joint, kind)`` of every such joint, ``kind`` being the URDF type
            (``"continuous"``, ``"floating"``, ``"planar"``) or Pinocchio's joint model name.
    """

    def __init__(self, path: object, joints: list[tuple[str, str]]) -> None:
        self.joints = list(joints)
        which = ", ".join(f"joint {name!r} is {kind}" for name, kind in self.joints)
        super().__init__(
            path,
            f"{which}; only revolute and prismatic joints are supported (no continuous, floating or planar joints)",
        )


def build_pinocchio_model(
    text: str, label: str, *, visuals: bool = False
) -> tuple[pin.Model, pin.GeometryModel | None]:
    """Pinocchio's model (and, with ``visuals``, its visual geometry) of URDF text, with urdfdom's
    own complaints captured, never printed.

    Raises:
        InputFileError: Pinocchio cannot read it (its first complaint, naming ``label``).
    """
    with captured_output() as out:  # urdfdom's own complaints are not the message
        try:
            model = pin.buildModelFromXML(text)
            visual = (
                pin.buildGeomFromUrdfString(model, text, pin.GeometryType.VISUAL)
                if visuals
                else None
            )
        except (RuntimeError, ValueError) as e:
            failure: Exception | None = e
        else:
            failure = None
    # urdfdom can also report an error and go on without the part it could not read.
    said = out.error_lines()
    if failure is not None or said:
        why = (
            said[0] if said else (str(failure).strip().splitlines() or [type(failure).__name__])[0]
        )
        raise InputFileError(
            label, f"not a URDF Pinocchio can read ({why.removeprefix('Error:').strip()})"
        ) from failure
    return model, visual


class PinocchioRobot:
    """A URDF through Pinocchio: kinematic model, 1-DoF joints and limits, checked frame lookup.

    Build it with :meth:`from_urdf`, :meth:`from_model` or :meth:`load`.

    Attributes:
        model: ``pinocchio.Model`` of the URDF.
        urdf: The URDF text.
        source: Where it came from (a path, a robot reference, ``<model NAME>`` or
            :data:`TEXT_SOURCE`), as errors name it.
        cpc_model: The :class:`~cpc2urdf.model.CPCModel` the URDF was exported from, or None for
            a URDF file or text.
        visual_model: ``pinocchio.GeometryModel`` of the URDF visuals, or None unless asked for.
        joint_names: The moving joints in configuration order (one reading each).
        joint_kinds: ``"revolute"`` or ``"prismatic"`` per joint, in :attr:`joint_names` order.
        lower: Lower joint limits [rad]/[m], shape (n,), as the URDF gives them.
        upper: Upper joint limits [rad]/[m], shape (n,).
        velocity_limit: Joint speed limits [rad/s]/[m/s], shape (n,).
        links: URDF link names (Pinocchio BODY frames), in tree order.
        path: The URDF file it was read from, or None (URDF text, a CPC model): relative mesh
            paths and ``package://`` look-ups start from its folder.
        continuous_joints: The URDF ``continuous`` joints read as unlimited revolute joints
            (lower -inf, upper inf), in :attr:`joint_names` order.
    """

    def __init__(
        self,
        model: pin.Model,
        urdf: str,
        source: str,
        *,
        cpc_model: CPCModel | None = None,
        visual_model: pin.GeometryModel | None = None,
        path: Path | None = None,
        continuous_joints: tuple[str, ...] = (),
    ) -> None:
        """Wrap a Pinocchio ``model`` of ``urdf``; :class:`UnsupportedJointError` naming ``source``
        if a joint is not a 1-DoF revolute or prismatic joint. The joints named in
        ``continuous_joints`` (made revolute for Pinocchio) get limits -inf..inf."""
        names: list[str] = []
        kinds: list[str] = []
        unsupported: list[tuple[str, str]] = []
        for jid in range(1, model.njoints):
            joint = model.joints[jid]
            short = joint.shortname().replace("JointModel", "")
            if joint.nq != 1 or joint.nv != 1 or short not in PRISMATIC + REVOLUTE:
                unsupported.append((str(model.names[jid]), UNSUPPORTED_KINDS.get(short, short)))
                continue
            names.append(str(model.names[jid]))
            kinds.append("prismatic" if short in PRISMATIC else "revolute")
        if unsupported:
            raise UnsupportedJointError(source, unsupported)
        if any(model.joints[jid].idx_q != jid - 1 for jid in range(1, model.njoints)):
            raise SpecError("unexpected Pinocchio joint ordering")
        self.model = model
        self.urdf = urdf
        self.source = source
        self.cpc_model = cpc_model
        self.visual_model = visual_model
        self.joint_names: tuple[str, ...] = tuple(names)
        self.joint_kinds: tuple[str, ...] = tuple(kinds)
        self.path = path
        self.continuous_joints: tuple[str, ...] = tuple(j for j in names if j in continuous_joints)
        self.lower: Array = np.array(model.lowerPositionLimit, dtype=float)
        self.upper: Array = np.array(model.upperPositionLimit, dtype=float)
        for j in self.continuous_joints:
            k = names.index(j)
            self.lower[k], self.upper[k] = -np.inf, np.inf
            model.lowerPositionLimit[k], model.upperPositionLimit[k] = -np.inf, np.inf
        self.velocity_limit: Array = np.array(model.velocityLimit, dtype=float)
        self.links: tuple[str, ...] = tuple(
            f.name for f in model.frames if f.type == pin.FrameType.BODY
        )

    # ---- construction -------------------------------------------------------------------------

    @classmethod
    def from_urdf(
        cls,
        urdf: str | os.PathLike[str],
        *,
        source: str | None = None,
        visuals: bool = False,
        cpc_model: CPCModel | None = None,
        continuous_as_revolute: bool = False,
        path: str | os.PathLike[str] | None = None,
    ) -> PinocchioRobot:
        """The robot of a URDF file or URDF text.

        Args:
            urdf: A path (a ``str`` not starting with ``<`` is a path) or the URDF text.
            source: How errors name it; default the path, or :data:`TEXT_SOURCE` for text.
            visuals: Also build the visual geometry model (:attr:`visual_model`; meshes must be
                absolute paths: the view resolves ``package://`` itself,
                :mod:`cpc2urdf.validation.view.meshes`).
            cpc_model: The CPC model the text was exported from, if any.
            continuous_as_revolute: Read ``continuous`` joints as revolute joints without limits
                (:attr:`continuous_joints`) instead of refusing them.
            path: For URDF text: the file it stands for (e.g. the URDF a written-back text came
                from), as :attr:`path`; its relative mesh paths resolve from that file's folder.

        Raises:
            InputFileError: A missing or unreadable file, a URDF
                :func:`~cpc2urdf.urdf.input.validate_urdf` refuses, a URDF Pinocchio cannot read,
                or (:class:`UnsupportedJointError`) joints other than revolute/prismatic.
        """
        text = os.fspath(urdf)
        file = None if path is None else Path(path)
        if isinstance(urdf, os.PathLike) or not text.lstrip().startswith("<"):  # a path, not XML
            label = text if source is None else source
            file = Path(text)
            text = read_text_file(file, "a URDF file", encoding="utf-8-sig")
        else:
            label = TEXT_SOURCE if source is None else source
        validate_urdf(text, label)  # one line for what urdfdom would complain about on stderr
        for_pinocchio = text
        continuous: tuple[str, ...] = ()
        if continuous_as_revolute:
            for_pinocchio, continuous = revolute_from_continuous(text)
        model, visual = build_pinocchio_model(for_pinocchio, label, visuals=visuals)
        return cls(
            model,
            text,
            label,
            cpc_model=cpc_model,
            visual_model=visual,
            path=file,
            continuous_joints=continuous,
        )

    @classmethod
    def from_model(
        cls, model: CPCModel, *, source: str | None = None, visuals: bool = False
    ) -> PinocchioRobot:
        """The robot of a :class:`~cpc2urdf.model.CPCModel`, through its URDF
        (:func:`cpc2urdf.urdf.document.urdf_from_model`; ``source`` is written in its comment)."""
        label = source if source is not None else f"<model {model.structure.name}>"
        text = urdf_from_model(model, source=source)
        return cls.from_urdf(text, source=label, visuals=visuals, cpc_model=model)

    @classmethod
    def load(
        cls,
        ref: str | os.PathLike[str] | CPCModel,
        *,
        visuals: bool = False,
        continuous_as_revolute: bool = False,
    ) -> PinocchioRobot:
        """The robot ``ref`` names: a :class:`~cpc2urdf.model.CPCModel`, a URDF file (``.urdf`` in
        any case, or XML text in a file not named ``.json``: :func:`cpc2urdf.files.robot_ref.is_urdf_ref`), or a model file, robot spec or shipped
        robot name (:func:`cpc2urdf.files.robot_ref.load_model`). ``continuous_as_revolute`` as in
        :meth:`from_urdf`.

        Raises:
            InputFileError: As :meth:`from_urdf`, or a reference :func:`load_model` rejects.
        """
        if isinstance(ref, CPCModel):
            return cls.from_model(ref, visuals=visuals)
        if is_urdf_ref(ref):
            return cls.from_urdf(
                Path(ref), visuals=visuals, continuous_as_revolute=continuous_as_revolute
            )
        label = os.fspath(ref)
        return cls.from_model(load_model(label), source=label, visuals=visuals)

    # ---- names ----------------------------------------------------------------------------------

    @property
    def name(self) -> str:
        """The URDF's ``<robot name>`` (or :attr:`source` if it has none)."""
        return str(self.model.name) or self.source

    @property
    def n_joints(self) -> int:
        """Number of moving joints (= configuration size)."""
        return len(self.joint_names)

    def joint_index(self, name: str) -> int:
        """Position of joint ``name`` in the configuration; :class:`UnknownNameError` if none."""
        if name not in self.joint_names:
            raise UnknownNameError("joint", name, self.joint_names)
        return self.joint_names.index(name)

    def frame_names(self, frame_type: pin.FrameType | None = None) -> tuple[str, ...]:
        """Names of the Pinocchio frames (of ``frame_type``, a ``pinocchio.FrameType``; None: all)."""
        return tuple(
            f.name for f in self.model.frames if frame_type is None or f.type == frame_type
        )

    def has_frame(self, name: str, frame_type: pin.FrameType | None = None) -> bool:
        """Whether the model has a frame ``name`` (of ``frame_type``; None: any type)."""
        if frame_type is None:
            return bool(self.model.existFrame(name))
        return bool(self.model.existFrame(name, frame_type))

    def frame_id(self, name: str, frame_type: pin.FrameType | None = None) -> int:
        """Pinocchio's id of frame ``name`` (of ``frame_type``; None: any type).

        Raises:
            UnknownNameError: No such frame, listing the frames there are (of that type).
        """
        if not self.has_frame(name, frame_type):
            raise UnknownNameError("frame", name, self.frame_names(frame_type))
        if frame_type is None:
            return int(self.model.getFrameId(name))
        return int(self.model.getFrameId(name, frame_type))

    def gravity_torques(self, joints: Sequence[str], Q: ArrayLike) -> Array:
        """What each joint carries at rest under gravity (``-z`` of the URDF's root, 9.81 m/s^2),
        from the URDF's inertials: torques [N m] of revolute joints, forces [N] of prismatic ones.

        Args:
            joints: URDF joint names, one per column of ``Q``.
            Q: Readings of those joints, shape (N, len(joints)); every other joint at 0.

        Returns:
            Shape (N, len(joints)).
        """
        cols = [self.joint_index(j) for j in joints]
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        data = self.model.createData()
        q = pin.neutral(self.model)
        out = np.empty(Q.shape)
        for i, row in enumerate(Q):
            q[cols] = row
            out[i] = pin.computeGeneralizedGravity(self.model, data, q)[cols]
        return out


def gravity_loads(ms: MeasurementSet, q: ArrayLike | None = None) -> Array | None:
    """Each joint's gravity load (:meth:`PinocchioRobot.gravity_torques`) at readings ``q``
    (N, n) of a URDF robot's measurement set (default: its records), in its joint order; None
    when the set's robot is not a URDF or its URDF carries no mass on the measured paths."""
    robot = ms.spec
    if not isinstance(robot, UrdfRobot) or robot.tree is None or robot.names is None:
        return None
    pr = PinocchioRobot.from_urdf(robot.tree.source, continuous_as_revolute=True)
    names = [robot.names.urdf_joint(j) for j in ms.structure.joint_names]
    loads = pr.gravity_torques(names, ms.q if q is None else q)
    return loads if np.abs(loads).max() > 0 else None


def revolute_from_continuous(urdf: str) -> tuple[str, tuple[str, ...]]:
    """The URDF text with every ``continuous`` joint made ``revolute`` with limits
    +-:data:`UNLIMITED` (its effort and velocity kept, 0 if it had none), for Pinocchio, and the
    names of those joints. The text must have passed
    :func:`~cpc2urdf.urdf.input.validate_urdf`; without continuous joints it is returned as is."""
    root = ET.fromstring(urdf)
    changed = []
    for joint in root.findall("joint"):
        if joint.get("type") != "continuous":
            continue
        joint.set("type", "revolute")
        limit = joint.find("limit")
        if limit is None:
            limit = ET.SubElement(joint, "limit", effort="0", velocity="0")
        limit.set("lower", repr(-UNLIMITED))
        limit.set("upper", repr(UNLIMITED))
        limit.set("effort", limit.get("effort", "0"))
        limit.set("velocity", limit.get("velocity", "0"))
        changed.append(str(joint.get("name")))
    if not changed:
        return urdf, ()
    return ET.tostring(root, encoding="unicode"), tuple(changed)


__all__ = [
    "build_pinocchio_model",
    "PRISMATIC",
    "REVOLUTE",
    "TEXT_SOURCE",
    "UNLIMITED",
    "UNSUPPORTED_KINDS",
    "PinocchioRobot",
    "UnsupportedJointError",
    "revolute_from_continuous",
]
