"""The robot as the view sees it: a :class:`PinocchioRobot` with visuals (meshes resolved,
:mod:`.meshes`) and display limits."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from cpc2urdf.errors import ConfigurationError, UnknownNameError
from cpc2urdf.files.robot_ref import is_urdf_ref, load_model
from cpc2urdf.model import CPCModel
from cpc2urdf.model_metadata import ModelMetadata
from cpc2urdf.transforms import Array
from cpc2urdf.urdf.document import camera_body_names
from cpc2urdf.urdf.origins import writeback_plan
from cpc2urdf.urdf.pinocchio import PinocchioRobot
from cpc2urdf.urdf.robot import urdf_source
from cpc2urdf.urdf.writeback import calibrated_urdf_text
from cpc2urdf.validation.view.meshes import PackageDirs, VisualMeshes, visual_geometry

RobotSource = str | os.PathLike[str] | CPCModel  # what load_view_robot accepts


@dataclass
class ViewRobot:
    """A robot as the view sees it: Pinocchio's model and visual geometry from its URDF.

    Attributes:
        pinocchio: The URDF through Pinocchio (kinematic model, visual model, joints); the gaze
            solver of a view works on this same model.
        lower: Lower joint limits [rad]/[m], shape (n,), as shown and swept: a URDF joint without
            limits is shown at 0 and swept +-pi.
        upper: Upper joint limits [rad]/[m], shape (n,).
        kinds: Link name -> ``"plate"``/``"camera"``/``"frame"`` for the named frames of a cpc2urdf
            model (for a plain URDF, guessed from the names: ``plate*``, ``*camera*``).
        metadata: A cpc2urdf model's metadata (provenance, residuals, ...), else empty.
        visuals: ``pinocchio.GeometryModel`` of the URDF visuals, meshes resolved and read
            (:func:`~cpc2urdf.validation.view.meshes.visual_geometry`); None: the
            :class:`PinocchioRobot`'s own (built with ``visuals=True``).
        meshes: What the visuals are made of (how many meshes, which files).
        written_back: For a model identified from a user's URDF, that model: the robot is the
            URDF written back from it (:func:`written_back_robot`), in the URDF's root link's
            frame and names; else None.
    """

    pinocchio: PinocchioRobot
    lower: Array
    upper: Array
    kinds: dict[str, str] = field(default_factory=dict)
    metadata: ModelMetadata = field(default_factory=ModelMetadata)
    visuals: pin.GeometryModel | None = None
    meshes: VisualMeshes = field(default_factory=lambda: VisualMeshes(0, ()))
    written_back: CPCModel | None = None

    @property
    def name(self) -> str:
        """Robot name (URDF ``<robot name>``)."""
        return self.pinocchio.name

    @property
    def source(self) -> str:
        """Where it came from (a path or a shipped robot name)."""
        return self.pinocchio.source

    @property
    def urdf(self) -> str:
        """The URDF text."""
        return self.pinocchio.urdf

    @property
    def model(self) -> pin.Model:
        """``pinocchio.Model``."""
        return self.pinocchio.model

    @property
    def visual_model(self) -> pin.GeometryModel:
        """``pinocchio.GeometryModel`` of the URDF visuals."""
        return self.visuals if self.visuals is not None else self.pinocchio.visual_model

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Moving joints in Pinocchio's configuration order (all 1-DoF)."""
        return self.pinocchio.joint_names

    @property
    def links(self) -> tuple[str, ...]:
        """URDF link names (Pinocchio BODY frames), in tree order."""
        return self.pinocchio.links

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    def default_q(self) -> Array:
        """The middle of every joint's range [rad]/[m], shape (n,)."""
        return 0.5 * (self.lower + self.upper)

    def q_from(
        self, values: Mapping[str, float] | ArrayLike | None, *, base: ArrayLike | None = None
    ) -> Array:
        """A configuration of shape (n,) from ``{joint: value}`` (others from ``base``, default
        the middle of the ranges) or from n values in :attr:`joint_names` order.

        Raises:
            UnknownNameError: A joint the robot does not have.
            ConfigurationError: Wrong count, NaN/inf, or a value outside the joint limits.
        """
        q = np.array(base, dtype=float) if base is not None else self.default_q()
        if values is None:
            pass
        elif isinstance(values, Mapping):
            for name, v in values.items():
                if name not in self.joint_names:
                    raise UnknownNameError("joint", str(name), self.joint_names)
                q[self.joint_names.index(name)] = float(v)
        else:
            arr = np.asarray(values, dtype=float)
            if arr.shape != (self.n_joints,):
                raise ConfigurationError(
                    f"configuration needs {self.n_joints} values for joints {list(self.joint_names)}, "
                    f"got shape {arr.shape}"
                )
            q = arr.copy()
        if not np.all(np.isfinite(q)):
            raise ConfigurationError("configuration contains NaN or inf")
        for i, name in enumerate(self.joint_names):
            if not self.lower[i] - 1e-12 <= q[i] <= self.upper[i] + 1e-12:
                raise ConfigurationError(
                    f"joint {name!r}: value {q[i]:.9g} outside its limits [{self.lower[i]:.9g}, {self.upper[i]:.9g}]"
                )
        return q

    def link_poses(self, q: ArrayLike) -> dict[str, Array]:
        """``T_world_<link>`` of every URDF link, each of shape (4, 4), at ``q`` (shape (n,))."""
        data = self.model.createData()
        pin.framesForwardKinematics(self.model, data, np.asarray(q, dtype=float))
        return {
            f.name: data.oMf[i].homogeneous.copy()
            for i, f in enumerate(self.model.frames)
            if f.type == pin.FrameType.BODY
        }

    def links_below(self, joint: str) -> tuple[str, ...]:
        """The links that ``joint`` moves (every link below it), in tree order.

        Raises:
            UnknownNameError: The robot has no such moving joint.
        """
        jid = self.pinocchio.joint_index(joint) + 1  # Pinocchio's joint id (0 is the universe)
        out = []
        for f in self.model.frames:
            if f.type != pin.FrameType.BODY:
                continue
            j = f.parentJoint
            while j > jid:  # parents have smaller ids
                j = self.model.parents[j]
            if j == jid:
                out.append(f.name)
        return tuple(out)

    def links_above(self, link: str) -> tuple[str, ...]:
        """The links from the root down to ``link`` (``link`` left out), root first.

        Raises:
            UnknownNameError: The robot has no such link.
        """
        frames = self.model.frames
        i = self.pinocchio.frame_id(link, pin.FrameType.BODY)
        out = []
        while i != 0:
            i = int(frames[i].parentFrame)
            if frames[i].type == pin.FrameType.BODY:
                out.append(str(frames[i].name))
        return tuple(out[::-1])

    def frame(self, name: str) -> str:
        """``name`` if the robot has a link of that name, else :class:`UnknownNameError`."""
        if name not in self.links:
            raise UnknownNameError("frame", name, self.links)
        return name


def kind_from_name(link: str) -> str:
    """A plain URDF link's kind, guessed from its name: ``plate*``, ``*camera*``, else ``frame``."""
    if link.startswith("plate"):
        return "plate"
    if "camera" in link:
        return "camera"
    return "frame"


def load_view_robot(source: RobotSource, *, package_dirs: PackageDirs = ()) -> ViewRobot:
    """The robot to view: a ``.urdf`` file (any case), a model file, a robot spec, a shipped robot
    name (``iis_head``), or a :class:`cpc2urdf.model.CPCModel` (:meth:`PinocchioRobot.load`).
    A URDF's ``continuous`` joints are read as unlimited revolute joints (shown at 0, swept
    +-pi); its meshes are resolved (``package://`` through ``package_dirs`` first, then
    ``ROS_PACKAGE_PATH``/``AMENT_PREFIX_PATH``, then the folders above the URDF) and read
    (:func:`~cpc2urdf.validation.view.meshes.visual_geometry`).

    Raises:
        InputFileError: Missing or unreadable file, a URDF Pinocchio cannot parse, joints other
            than revolute/prismatic/continuous, or
            (:class:`~cpc2urdf.validation.view.meshes.UnresolvedMeshError`) a mesh that does not
            resolve or cannot be read, naming the link and the mesh path.
    """
    if not isinstance(source, CPCModel) and is_urdf_ref(source):
        return view_robot(
            PinocchioRobot.load(source, continuous_as_revolute=True), package_dirs=package_dirs
        )
    label = None if isinstance(source, CPCModel) else os.fspath(source)
    model = source if isinstance(source, CPCModel) else load_model(os.fspath(source))
    if urdf_source(model) is not None:  # the user's own URDF, calibrated
        return view_robot(
            written_back_robot(model, label), package_dirs=package_dirs, written_back=model
        )
    return view_robot(PinocchioRobot.from_model(model, source=label), package_dirs=package_dirs)


def own_nominal(robot: ViewRobot) -> str:
    """The nominal model of ``robot`` when none is named (``view MODEL --nominal``): the URDF a
    model identified from a user's URDF was built from.

    Raises:
        ConfigurationError: ``robot`` is not such a model (name the nominal model instead).
    """
    source = None if robot.written_back is None else urdf_source(robot.written_back)
    if source is None:
        raise ConfigurationError(
            f"{robot.source}: --nominal without OTHER is the URDF a model was identified from, and "
            "this is not a model identified from a URDF; name the nominal model (--nominal OTHER)"
        )
    return source.path


def written_back_robot(model: CPCModel, label: str | None = None) -> PinocchioRobot:
    """The robot of a model built from a user's URDF: that URDF with the model's calibrated
    origins (:func:`~cpc2urdf.urdf.writeback.calibrated_urdf_text`, in memory), so every one of
    its meshes sits on its calibrated link; meshes resolve from the source URDF's folder. Its
    names are the URDF's (not the model's, which may differ: :class:`~cpc2urdf.urdf.robot.NameMap`),
    so it carries no :attr:`~PinocchioRobot.cpc_model`; :func:`view_robot` takes the model.

    Raises:
        InputFileError: The source URDF cannot be read or changed where the model depends on it
            (:func:`~cpc2urdf.urdf.origins.writeback_plan`), or Pinocchio refuses the text.
    """
    plan = writeback_plan(model)
    name = label if label is not None else f"<model {model.structure.name}>"
    return PinocchioRobot.from_urdf(
        calibrated_urdf_text(plan),
        source=f"{name} (written back into {plan.source.path})",
        continuous_as_revolute=True,
        path=plan.source.path,
    )


def view_robot(
    robot: PinocchioRobot, *, package_dirs: PackageDirs = (), written_back: CPCModel | None = None
) -> ViewRobot:
    """The :class:`ViewRobot` of a loaded robot: its visuals (meshes resolved through
    ``package_dirs``, :func:`~cpc2urdf.validation.view.meshes.visual_geometry`), display limits,
    and the kinds and metadata of the CPC model it came from, if any (``written_back``: the
    model of a user's URDF that ``robot`` is the written-back URDF of,
    :func:`written_back_robot`)."""
    kinds: dict[str, str] = {}
    metadata = ModelMetadata()
    source = None if written_back is None else urdf_source(written_back)
    if written_back is not None and source is not None:
        # a model of a user's URDF names its frames after that URDF's links
        kinds = {source.urdf_link(f.name): f.kind for f in written_back.structure.frames}
        metadata = written_back.metadata
    elif robot.cpc_model is not None:
        # a cpc2urdf model says what each frame is; its camera *body* links carry no triad of their own
        kinds = {f.name: f.kind for f in robot.cpc_model.structure.frames}
        kinds |= {body: "frame" for body in camera_body_names(robot.cpc_model.structure).values()}
        metadata = robot.cpc_model.metadata
    lo, hi = robot.lower.copy(), robot.upper.copy()
    # URDF joints without limits give +-huge; show them at 0 and sweep them +-pi (or +-0.5 m).
    unlimited = ~np.isfinite(lo) | ~np.isfinite(hi) | (hi - lo > 1e6)
    lo[unlimited], hi[unlimited] = -math.pi, math.pi
    links = robot.links
    kinds = {**{ln: kind_from_name(ln) for ln in links if kind_from_name(ln) != "frame"}, **kinds}
    visuals, meshes = visual_geometry(robot, package_dirs)
    return ViewRobot(robot, lo, hi, kinds, metadata, visuals, meshes, written_back)


__all__ = [
    "RobotSource",
    "ViewRobot",
    "kind_from_name",
    "load_view_robot",
    "own_nominal",
    "view_robot",
    "written_back_robot",
]
