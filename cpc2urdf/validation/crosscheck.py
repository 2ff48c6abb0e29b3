"""Cross-check a URDF against the CPC model with three independent URDF parsers.

- Pinocchio (``pin.buildModelFromUrdf``): pose of every frame at N configurations;
- yourdfpy (its own XML parser and scene graph): the same poses;
- urdfdom (``check_urdf``, shipped with ``pin``): parses the file and prints the link tree; it
  exposes no poses, so for it we check that it parses and that its tree equals the model's.

Every named frame, ``base``, every joint's link frame and every camera body link the URDF has
(:func:`cpc2urdf.urdf.document.camera_body_names`; URDFs of earlier versions have none) is compared, at
seeded random configurations inside the joint limits plus the two limit corners. A URDF that passes
agrees with the CPC model to ``FK_AGREEMENT_TOL`` (1e-9 m / 1e-9 rad) in both FK parsers.

Either mount of :mod:`cpc2urdf.urdf.document` passes: the URDF's ``world`` -> ``base`` must be the model's
``T_world_base`` (``mount="rig"``: poses compared in the model's world) or a rotation at the base
origin (``mount="base"``, the gravity-aligned world of ``cpc2urdf export``: poses compared relative
to ``base``, i.e. the model's poses carried into that world). Anything else is a discrepancy.

A model built from a user's URDF (it has a ``urdf`` section, :func:`cpc2urdf.urdf.robot.urdf_source`)
is checked against the URDF written back from it (:func:`cross_check_writeback`): the links are the
user's, named as in that URDF, so the compared ones are every link on the paths from its root to
the model's frames, where :func:`cpc2urdf.urdf.origins.urdf_link_poses` puts them (in the root
link's frame; the write-back plan is made on the checked file), the rest of the robot at 0. A
fourth row, ``source``, compares every joint the model was built from with its record (a
calibrated joint may differ only in its origin), so an edit of a joint folded into the model is
named. The first link off, root first, is named with the joint above it.

A URDF that does not parse is bad input, not a discrepancy: :func:`cpc2urdf.urdf.input.read_urdf`
checks it before any parser sees it, and a parser that still cannot read it raises
:class:`~cpc2urdf.errors.InputFileError` naming the file and the parser's first complaint. What the
parsers print themselves (urdfdom's C++ messages, yourdfpy's log) is captured, never shown. A
report (and ``check``'s exit code 1) is only for a URDF that parses but disagrees with the model.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from cpc2urdf.errors import InputFileError
from cpc2urdf.model import BASE, CPCModel
from cpc2urdf.tolerances import FK_AGREEMENT_TOL
from cpc2urdf.transforms import Array, rotation_error
from cpc2urdf.urdf.document import T_BODY_OPTICAL, camera_body_names, link_name
from cpc2urdf.urdf.input import read_urdf
from cpc2urdf.urdf.native_output import captured_output
from cpc2urdf.urdf.origins import WritebackPlan, plan_for_tree, urdf_link_poses
from cpc2urdf.urdf.pinocchio import (
    PinocchioRobot,
    UnsupportedJointError,
    build_pinocchio_model,
)
from cpc2urdf.urdf.robot import UrdfSource, urdf_source
from cpc2urdf.urdf.tree import UrdfTree, parse_urdf_tree

LIMIT_TOL = 1e-12  # [m] or [rad]: joint limits must survive the URDF round trip exactly


@dataclass
class ParserReport:
    """What one parser saw.

    Attributes:
        parser: ``"pinocchio"``, ``"yourdfpy"`` or ``"urdfdom"`` (and ``"source"``, the record
            of a model built from a URDF, :func:`cross_check_writeback`).
        ok: True when everything it can check agrees within tolerance.
        max_position_error: Worst frame position discrepancy [m], None if it gives no poses.
        max_rotation_error: Worst frame rotation discrepancy [rad], None if it gives no poses.
        worst_frame: The frame where the worst discrepancy occurred.
        problems: Structural problems (missing frames/joints, wrong types or limits).
    """

    parser: str
    ok: bool
    max_position_error: float | None = None
    max_rotation_error: float | None = None
    worst_frame: str | None = None
    problems: list[str] = field(default_factory=list)
    note: str = ""


@dataclass
class CrossCheckReport:
    """The result of :func:`cross_check` (``compared``: what :attr:`frames` are, for the text)."""

    urdf: str
    n_configurations: int
    frames: list[str]
    parsers: list[ParserReport]
    tolerance: float = FK_AGREEMENT_TOL
    compared: str = "frames"

    @property
    def ok(self) -> bool:
        return all(p.ok for p in self.parsers)

    def to_json(self) -> dict[str, Any]:
        return {
            "urdf": self.urdf,
            "ok": self.ok,
            "tolerance": self.tolerance,
            "n_configurations": self.n_configurations,
            "frames": self.frames,
            "parsers": [p.__dict__ for p in self.parsers],
        }

    def format(self) -> str:
        lines = [
            f"cross-check of {self.urdf}: {len(self.frames)} {self.compared} at {self.n_configurations} "
            f"configurations, tolerance {self.tolerance:g} m / {self.tolerance:g} rad"
        ]
        for p in self.parsers:
            if p.parser == "source":
                err = "the joints and links the model depends on, against its record"
            elif p.max_position_error is None:
                err = "no poses (parse + tree only)"
            else:
                err = (
                    f"worst position {p.max_position_error:.3e} m, rotation "
                    f"{p.max_rotation_error:.3e} rad (at {p.worst_frame})"
                )
            lines.append(
                f"  {p.parser:10s} {'OK  ' if p.ok else 'FAIL'} {err}{'; ' + p.note if p.note else ''}"
            )
            lines.extend(f"             - {msg}" for msg in p.problems)
        lines.append(
            "result: " + ("all parsers agree with the CPC model" if self.ok else "DISCREPANCY")
        )
        return "\n".join(lines)


def _compared_frames(model: CPCModel, bodies: dict[str, str] | None = None) -> list[str]:
    s = model.structure
    return [BASE, *(link_name(n) for n in s.joint_names), *s.frame_names, *(bodies or {}).values()]


def _bodies_in(model: CPCModel, links: object) -> dict[str, str]:
    """``{camera frame: body link}`` for the camera body links the URDF has (``links`` supports ``in``)."""
    return {f: b for f, b in camera_body_names(model.structure).items() if b in links}  # type: ignore[operator]


def _reference_poses(
    model: CPCModel,
    Q: Array,
    bodies: dict[str, str] | None = None,
    T_world_base: Array | None = None,
) -> dict[str, Array]:
    """CPC poses (N, 4, 4) of every compared frame, keyed by URDF link name, in the model's world
    or, given the URDF's ``T_world_base``, in the URDF's world (the same poses relative to base)."""
    _, link = model.link_poses(Q)
    ref = {link_name(n): link[:, i] for i, n in enumerate(model.structure.joint_names)}
    ref.update(model.fk(Q, [BASE, *model.structure.frame_names]))
    for frame, body in (bodies or {}).items():
        ref[body] = ref[frame] @ T_BODY_OPTICAL.T
    if T_world_base is not None:
        M = T_world_base @ np.linalg.inv(model.T_world_base())
        ref = {k: M @ v for k, v in ref.items()}
    return ref


def _mount(model: CPCModel, T_world_base: Array, report: ParserReport) -> Array:
    """The URDF's ``world`` -> ``base`` (shape (4, 4)) as the poses are compared: the model's
    ``T_world_base`` (rig mount), or the URDF's own rotation at the base origin (base mount); a
    problem in ``report`` if it is neither."""
    T_model = model.T_world_base()
    if float(np.max(np.abs(T_world_base - T_model))) <= FK_AGREEMENT_TOL:
        report.note = "world: the model's world (mount rig)"
        return T_model
    if float(np.linalg.norm(T_world_base[:3, 3])) <= FK_AGREEMENT_TOL:
        report.note = (
            "world: a rotation at the base origin (mount base); poses compared relative to base"
        )
        return T_world_base
    report.problems.append(
        "world -> base is neither the model's T_world_base (mount rig) nor a rotation at the base origin (mount base)"
    )
    return T_model


def sample_configurations(model: CPCModel, n: int, seed: int = 0) -> Array:
    """``n`` seeded uniform configurations within the limits, plus both limit corners."""
    s = model.structure
    rng = np.random.default_rng(seed)
    Q = rng.uniform(s.lower, s.upper, size=(max(n - 2, 0), s.n_joints))
    return np.vstack([s.lower, s.upper, Q])[: max(n, 2)]


def _worst(report: ParserReport, errors: dict[str, tuple[float, float]]) -> None:
    pos = max(errors.items(), key=lambda kv: kv[1][0])
    rot = max(errors.items(), key=lambda kv: kv[1][1])
    report.max_position_error = pos[1][0]
    report.max_rotation_error = rot[1][1]
    report.worst_frame = pos[0] if pos[1][0] >= rot[1][1] else rot[0]
    if report.max_position_error > FK_AGREEMENT_TOL or report.max_rotation_error > FK_AGREEMENT_TOL:
        report.ok = False


def _or_zero(value: float | None) -> float:
    return 0.0 if value is None else float(value)  # an absent URDF limit bound is 0


def _compare(ref: Array, got: Array) -> tuple[float, float]:
    dp = float(np.max(np.linalg.norm(ref[:, :3, 3] - got[:, :3, 3], axis=-1)))
    dr = float(np.max(rotation_error(ref[:, :3, :3], got[:, :3, :3])))
    return dp, dr


def check_pinocchio(model: CPCModel, urdf_path: str, Q: Array) -> ParserReport:
    """FK of every compared frame with Pinocchio vs the CPC model.

    Raises:
        InputFileError: The URDF does not parse (:meth:`PinocchioRobot.from_urdf`).
    """
    rep = ParserReport("pinocchio", True)
    try:
        robot = PinocchioRobot.from_urdf(Path(urdf_path))
    except UnsupportedJointError as e:  # parses, but has joints the CPC model cannot have
        rep.ok = False
        rep.problems.extend(
            f"joint {name!r} is {kind}, expected revolute or prismatic" for name, kind in e.joints
        )
        return rep
    pmodel = robot.model
    s = model.structure
    idx_q = {}
    for j in s.joints:
        if j.name not in robot.joint_names:
            rep.problems.append(f"joint {j.name!r} missing")
            continue
        i = robot.joint_index(j.name)
        idx_q[j.name] = i
        lo, hi = robot.lower[i], robot.upper[i]
        if abs(lo - j.lower) > LIMIT_TOL or abs(hi - j.upper) > LIMIT_TOL:
            rep.problems.append(f"joint {j.name!r} limits [{lo}, {hi}] != [{j.lower}, {j.upper}]")
    if robot.n_joints != s.n_joints:
        rep.problems.append(f"model has nq={robot.n_joints}, expected {s.n_joints}")
    bodies = _bodies_in(model, robot.frame_names(pin.FrameType.BODY))
    frames = _compared_frames(model, bodies)
    fids = {}
    for f in frames:
        if not robot.has_frame(f, pin.FrameType.BODY):
            rep.problems.append(f"frame {f!r} missing")
        else:
            fids[f] = robot.frame_id(f, pin.FrameType.BODY)
    if rep.problems:
        rep.ok = False
        return rep
    data = pmodel.createData()
    got = {f: np.empty((len(Q), 4, 4)) for f in frames}
    qp = np.zeros(pmodel.nq)
    for k, q in enumerate(Q):
        for i, name in enumerate(s.joint_names):
            qp[idx_q[name]] = q[i]
        pin.framesForwardKinematics(pmodel, data, qp)
        for f in frames:
            got[f][k] = data.oMf[fids[f]].homogeneous
    ref = _reference_poses(model, Q, bodies, _mount(model, got[BASE][0], rep))
    _worst(rep, {f: _compare(ref[f], got[f]) for f in frames})
    rep.ok = rep.ok and not rep.problems
    return rep


def _load_yourdfpy(urdf_path: str) -> Any:
    """``yourdfpy.URDF`` of the file, without meshes; :class:`InputFileError` if it cannot."""
    import yourdfpy

    read_urdf(urdf_path)
    with captured_output() as out:  # yourdfpy logs its parse problems; they are not our output
        try:
            robot = yourdfpy.URDF.load(
                urdf_path,
                load_meshes=False,
                build_collision_scene_graph=False,
                load_collision_meshes=False,
            )
        except Exception as e:  # lxml/yourdfpy errors have no common base
            failure: Exception | None = e
        else:
            failure = None
    if failure is not None:
        said = (str(failure).strip() or out.text.strip() or type(failure).__name__).splitlines()[0]
        raise InputFileError(urdf_path, f"yourdfpy cannot read it ({said})") from failure
    return robot


def yourdfpy_pose(robot: Any, frame_to: str, frame_from: str) -> Array:
    """``T_<frame_from>_<frame_to>`` (4x4) at the configuration of yourdfpy's last
    ``update_cfg``, composed from yourdfpy's own joint transforms (its parse, its joint
    motion, its mimic rule) along the links' parent chain. Not ``robot.get_transform``: that
    reads trimesh's scene graph, which keeps an edge whose new matrix is within 1e-8 of the old
    one (``EnforcedForest.add_edge``), so a joint moved by less than ~1e-8 rad or m since the
    previous ``update_cfg`` comes back stale: an error of that size in a check at 1e-9 (seen:
    1.3e-8 rad on a gaze answer 6.6e-9 rad off a limit)."""
    above = {j.child: j for j in robot.robot.joints}

    def to_root(link: str) -> tuple[str, Array]:
        T = np.eye(4)
        while link in above:
            joint = above[link]
            T = robot._forward_kinematics_joint(joint)[0] @ T  # yourdfpy's joint FK (no public one)
            link = joint.parent
        return link, T

    root_to, T_to = to_root(frame_to)
    root_from, T_from = to_root(frame_from)
    if root_to != root_from:
        raise ValueError(f"links {frame_from!r} and {frame_to!r} are in different trees")
    return np.asarray(np.linalg.solve(T_from, T_to), dtype=np.float64)


def check_yourdfpy(model: CPCModel, urdf_path: str, Q: Array) -> ParserReport:
    """FK of every compared frame with yourdfpy vs the CPC model.

    Raises:
        InputFileError: The URDF does not parse (:func:`~cpc2urdf.urdf.input.read_urdf`, or
            yourdfpy cannot load it).
    """
    rep = ParserReport("yourdfpy", True)
    robot = _load_yourdfpy(urdf_path)
    s = model.structure
    names = list(robot.actuated_joint_names)
    missing = [n for n in s.joint_names if n not in names]
    extra = [n for n in names if n not in s.joint_names]
    if missing or extra:
        rep.problems.append(f"actuated joints differ: missing {missing}, unexpected {extra}")
    for j in s.joints:
        if j.name in robot.joint_map:
            uj = robot.joint_map[j.name]
            if uj.type != j.type:
                rep.problems.append(f"joint {j.name!r} has type {uj.type}, expected {j.type}")
            elif (
                uj.limit is None
                or max(
                    abs(_or_zero(uj.limit.lower) - j.lower), abs(_or_zero(uj.limit.upper) - j.upper)
                )
                > LIMIT_TOL
            ):
                rep.problems.append(f"joint {j.name!r} limits differ")
    bodies = _bodies_in(model, robot.link_map)
    frames = _compared_frames(model, bodies)
    for f in ["world", *frames]:  # poses are taken from "world"
        if f not in robot.link_map:
            rep.problems.append(f"frame {f!r} missing")
    if rep.problems:
        rep.ok = False
        return rep
    order = [s.joint_index(n) for n in names]
    got = {f: np.empty((len(Q), 4, 4)) for f in frames}
    for k, q in enumerate(Q):
        robot.update_cfg(q[order])
        for f in frames:
            got[f][k] = yourdfpy_pose(robot, f, "world")
    ref = _reference_poses(model, Q, bodies, _mount(model, got[BASE][0], rep))
    _worst(rep, {f: _compare(ref[f], got[f]) for f in frames})
    rep.ok = rep.ok and not rep.problems
    return rep


def check_urdfdom_executable() -> str | None:
    """Path of urdfdom's ``check_urdf`` (installed with ``pin``), or None."""
    found = shutil.which("check_urdf")
    if found:
        return found
    try:
        import cmeel  # type: ignore[import-not-found]  # pin's binary prefix

        cand = Path(cmeel.__file__).resolve().parent.parent / "cmeel.prefix" / "bin" / "check_urdf"
    except ImportError:
        return None
    return str(cand) if cand.is_file() else None


def _urdfdom_edges(urdf_path: str, rep: ParserReport) -> set[tuple[str, str]] | None:
    """The (parent, child) link edges urdfdom's ``check_urdf`` prints, or None (and ``rep``
    failed) when ``check_urdf`` is not installed.

    Raises:
        InputFileError: The URDF does not parse (:func:`~cpc2urdf.urdf.input.read_urdf`, or
            ``check_urdf`` refuses it).
    """
    read_urdf(urdf_path)
    exe = check_urdfdom_executable()
    if exe is None:
        rep.ok = False
        rep.problems.append("check_urdf not found (it ships with the 'pin' package)")
        return None
    proc = subprocess.run(
        [exe, urdf_path],
        capture_output=True,
        text=True,
        errors="replace",
        timeout=60,
        env={**os.environ, "LC_ALL": "C"},
    )
    # check_urdf also reports an error and goes on without the part it could not read.
    said = [
        ln.strip()
        for ln in (proc.stderr + proc.stdout).splitlines()
        if ln.strip().lower().startswith("error")
    ]
    if proc.returncode != 0 or "Successfully Parsed XML" not in proc.stdout or said:
        why = said[0].removeprefix("Error:").strip() if said else f"exit code {proc.returncode}"
        raise InputFileError(urdf_path, f"urdfdom's check_urdf cannot read it ({why})")
    edges = set()
    stack: list[tuple[int, str]] = []
    root = re.search(r"root Link: (\S+)", proc.stdout)
    if root:
        stack.append((-1, root.group(1)))
    for line in proc.stdout.splitlines():
        m = re.match(r"^(\s*)child\(\d+\):\s+(\S+)", line)
        if not m:
            continue
        depth = len(m.group(1))
        while stack and stack[-1][0] >= depth:
            stack.pop()
        if stack:
            edges.add((stack[-1][1], m.group(2)))
        stack.append((depth, m.group(2)))
    return edges


def check_urdfdom(model: CPCModel, urdf_path: str) -> ParserReport:
    """urdfdom's ``check_urdf``: the file parses and its link tree equals the model's.

    Raises:
        InputFileError: The URDF does not parse (:func:`~cpc2urdf.urdf.input.read_urdf`, or
            ``check_urdf`` refuses it).
    """
    rep = ParserReport("urdfdom", True, note="check_urdf prints no poses")
    edges = _urdfdom_edges(urdf_path, rep)
    if edges is None:
        return rep
    s = model.structure
    bodies = _bodies_in(model, {child for _, child in edges})
    expected = {("world", BASE)}
    expected |= {(link_name(j.parent), link_name(j.name)) for j in s.joints}
    expected |= {(link_name(f.parent), f.name) for f in s.frames if f.name not in bodies}
    expected |= {(link_name(s.frame(f).parent), b) for f, b in bodies.items()}
    expected |= {(b, f) for f, b in bodies.items()}
    if edges != expected:
        rep.ok = False
        rep.problems.append(
            f"link tree differs: missing {sorted(expected - edges)}, unexpected {sorted(edges - expected)}"
        )
    return rep


# ---- a model built from a user's URDF: the written-back file, links by the URDF's own names ----


def _unit(v: object) -> Array:
    """``v`` scaled to length 1 (a zero vector, as fixed joints may write, stays zero)."""
    a = np.asarray(v, dtype=float)
    n = float(np.linalg.norm(a))
    return a / n if n > 0.0 else a


def _source_problems(tree: UrdfTree, source: UrdfSource, calibrated: set[str]) -> list[str]:
    """Every joint the model's constants were derived from that the file has changed: a
    calibrated joint in anything but its origin, any other joint on the paths in anything."""
    out = []
    if tree.root != source.root:
        out.append(f"root link is {tree.root!r}, the model's URDF has {source.root!r}")
    for name, then in source.kinematics.items():
        j = tree.joints.get(name)
        if j is None:
            out.append(f"joint {name!r}, which the model was built from, is missing")
            continue
        now = j.kinematics()
        # write-back changes a calibrated joint's origin, and its <axis> only to the unit vector
        free = ("xyz", "rpy", "axis") if name in calibrated else ()
        changed = [k for k in then if k not in free and now.get(k) != then[k]]
        if name in calibrated and not np.allclose(
            _unit(now["axis"]), _unit(then["axis"]), rtol=0.0, atol=LIMIT_TOL
        ):
            changed.append("axis")
        if changed:
            k = changed[0]
            out.append(
                f"joint {name!r} (line {j.line}): {k} is {now.get(k)}, the model was built from {then[k]}"
            )
    return out


def _writeback_plan(
    model: CPCModel, tree: UrdfTree, source: UrdfSource, rep: ParserReport
) -> WritebackPlan | None:
    """The write-back plan of ``model`` on the checked file, or None with the reason in ``rep``."""
    try:
        plan = plan_for_tree(model, tree, source)
    except InputFileError as e:  # the file lacks a link or joint the model needs: a discrepancy
        rep.problems.append(str(e))
        rep.ok = False
        return None
    rep.problems.extend(_source_problems(tree, source, {c.joint.name for c in plan.changes}))
    rep.ok = not rep.problems
    return plan


def _urdf_q(model: CPCModel, source: UrdfSource, q: Array) -> dict[str, float]:
    """Readings ``q`` (model joint order, shape (n,)) keyed by URDF joint name."""
    return {source.joints[n]: float(v) for n, v in zip(model.structure.joint_names, q, strict=True)}


def _urdf_limit_problems(
    model: CPCModel, source: UrdfSource, limits: dict[str, tuple[float, float]]
) -> list[str]:
    """The model's joints whose limits in the file (``{URDF joint: (lower, upper)}``, continuous
    joints left out) differ from the model's."""
    out = []
    for j in model.structure.joints:
        u = source.joints[j.name]
        if u in limits:
            lo, hi = limits[u]
            if abs(lo - j.lower) > LIMIT_TOL or abs(hi - j.upper) > LIMIT_TOL:
                out.append(f"joint {u!r} limits [{lo}, {hi}] != [{j.lower}, {j.upper}]")
    return out


def _worst_link(
    rep: ParserReport, plan: WritebackPlan, errors: dict[str, tuple[float, float]]
) -> None:
    """:func:`_worst`, and the first link from the root that is off, with the joint above it:
    where the file and the model part (every link below it follows)."""
    _worst(rep, errors)
    for link in plan.placements:  # root first
        dp, dr = errors[link]
        if dp > FK_AGREEMENT_TOL or dr > FK_AGREEMENT_TOL:
            j = plan.tree.parent_joint(link)
            above = f" below joint {j.name!r} (line {j.line})" if j is not None else ""
            rep.problems.append(
                f"link {link!r}{above} is {dp:.3e} m, {dr:.3e} rad from where the model puts it"
            )
            return


def _pinocchio_of(urdf_path: str) -> pin.Model:
    """Pinocchio's model of the whole file, whatever its joints off the calibrated paths
    (floating, planar: a user's URDF may have them; they stay at their neutral configuration).

    Raises:
        InputFileError: Pinocchio cannot read the file (its first complaint).
    """
    return build_pinocchio_model(read_urdf(urdf_path), urdf_path)[0]


def check_pinocchio_writeback(
    model: CPCModel, urdf_path: str, Q: Array, plan: WritebackPlan
) -> ParserReport:
    """FK by Pinocchio of every link of ``plan`` (the paths from the root to the model's frames)
    in the written-back URDF, against :func:`~cpc2urdf.urdf.origins.urdf_link_poses`; the other
    joints of the file at Pinocchio's neutral configuration.

    Raises:
        InputFileError: Pinocchio cannot read the URDF.
    """
    rep = ParserReport(
        "pinocchio", True, note="links by the URDF's names, in its root link's frame"
    )
    pmodel = _pinocchio_of(urdf_path)
    source = plan.source
    slots: dict[str, tuple[int, bool]] = {}  # URDF joint -> (index in q, continuous: (cos, sin))
    limits = {}
    for u in source.joints.values():
        if not pmodel.existJointName(u):
            rep.problems.append(f"joint {u!r} missing")
            continue
        jid = pmodel.getJointId(u)
        joint = pmodel.joints[jid]
        if joint.nv != 1 or joint.nq not in (1, 2):
            rep.problems.append(
                f"joint {u!r} is {joint.shortname()}, expected revolute, continuous or prismatic"
            )
            continue
        slots[u] = (joint.idx_q, joint.nq == 2)
        if joint.nq == 1:
            limits[u] = (
                float(pmodel.lowerPositionLimit[joint.idx_q]),
                float(pmodel.upperPositionLimit[joint.idx_q]),
            )
    rep.problems.extend(_urdf_limit_problems(model, source, limits))
    links = list(plan.placements)
    rep.problems.extend(
        f"link {ln!r} missing" for ln in links if not pmodel.existFrame(ln, pin.FrameType.BODY)
    )
    if rep.problems:
        rep.ok = False
        return rep
    fids = {ln: pmodel.getFrameId(ln, pin.FrameType.BODY) for ln in links}
    data = pmodel.createData()
    got = {ln: np.empty((len(Q), 4, 4)) for ln in links}
    qp = pin.neutral(pmodel)
    for k, q in enumerate(Q):
        for u, v in _urdf_q(model, source, q).items():
            i, continuous = slots[u]
            if continuous:
                qp[i], qp[i + 1] = np.cos(v), np.sin(v)
            else:
                qp[i] = v
        pin.framesForwardKinematics(pmodel, data, qp)
        for ln in links:
            got[ln][k] = data.oMf[fids[ln]].homogeneous
    _worst_link(
        rep,
        plan,
        {ln: _compare(ref, got[ln]) for ln, ref in urdf_link_poses(model, plan, Q).items()},
    )
    return rep


def check_yourdfpy_writeback(
    model: CPCModel, urdf_path: str, Q: Array, plan: WritebackPlan
) -> ParserReport:
    """:func:`check_pinocchio_writeback` with yourdfpy (poses relative to the root link).

    Raises:
        InputFileError: yourdfpy cannot load the URDF.
    """
    rep = ParserReport("yourdfpy", True, note="links by the URDF's names, in its root link's frame")
    robot = _load_yourdfpy(urdf_path)
    source = plan.source
    rep.problems.extend(
        f"joint {u!r} missing" for u in source.joints.values() if u not in robot.joint_map
    )
    limits = {}
    for u in source.joints.values():
        uj = robot.joint_map.get(u)
        if uj is not None and uj.type != "continuous":
            lim = uj.limit
            limits[u] = (
                _or_zero(None if lim is None else lim.lower),
                _or_zero(None if lim is None else lim.upper),
            )
    rep.problems.extend(_urdf_limit_problems(model, source, limits))
    links = list(plan.placements)
    rep.problems.extend(f"link {ln!r} missing" for ln in links if ln not in robot.link_map)
    if rep.problems:
        rep.ok = False
        return rep
    root = plan.tree.root
    got = {ln: np.empty((len(Q), 4, 4)) for ln in links}
    for k, q in enumerate(Q):
        robot.update_cfg(_urdf_q(model, source, q))
        for ln in links:
            got[ln][k] = yourdfpy_pose(robot, ln, root)
    _worst_link(
        rep,
        plan,
        {ln: _compare(ref, got[ln]) for ln, ref in urdf_link_poses(model, plan, Q).items()},
    )
    return rep


def check_urdfdom_writeback(urdf_path: str, plan: WritebackPlan) -> ParserReport:
    """urdfdom's ``check_urdf``: the file parses and has every parent -> child edge of the
    plan's links (the rest of the robot is the user's and not compared).

    Raises:
        InputFileError: ``check_urdf`` refuses the URDF.
    """
    rep = ParserReport("urdfdom", True, note="check_urdf prints no poses")
    edges = _urdfdom_edges(urdf_path, rep)
    if edges is None:
        return rep
    expected = set()
    for link in plan.placements:
        j = plan.tree.parent_joint(link)
        if j is not None:
            expected.add((j.parent, link))
    if not expected <= edges:
        rep.ok = False
        rep.problems.append(f"link tree lacks {sorted(expected - edges)}")
    return rep


def cross_check_writeback(model: CPCModel, path: str, Q: Array) -> CrossCheckReport:
    """:func:`cross_check` of a model built from a user's URDF against a URDF written back from
    it (:mod:`cpc2urdf.urdf.writeback`): every link on the paths from the root to the model's
    frames (the measured links, cameras, and every link between) where
    :func:`~cpc2urdf.urdf.origins.urdf_link_poses` puts it, in the root link's frame, by
    Pinocchio and yourdfpy; urdfdom's tree has those links; and every joint the model depends on
    is as the model recorded it (a calibrated joint may differ only in its origin), the row
    ``source``.

    Raises:
        InputFileError: The URDF does not parse (any of the three parsers).
    """
    tree = parse_urdf_tree(read_urdf(path), path)
    source = urdf_source(model)
    assert source is not None
    src = ParserReport(
        "source", True, note=f"the joints {os.path.basename(source.path)} gave the model"
    )
    plan = _writeback_plan(model, tree, source, src)
    if plan is None:
        urdfdom = ParserReport("urdfdom", True, note="check_urdf prints no poses")
        _urdfdom_edges(path, urdfdom)
        skipped = [
            ParserReport(p, False, problems=["no reference poses (see 'source')"])
            for p in ("pinocchio", "yourdfpy")
        ]
        return CrossCheckReport(
            path, len(Q), [], [*skipped, urdfdom, src], compared="links of the written-back URDF"
        )
    reports = [
        check_pinocchio_writeback(model, path, Q, plan),
        check_yourdfpy_writeback(model, path, Q, plan),
        check_urdfdom_writeback(path, plan),
        src,
    ]
    return CrossCheckReport(
        path, len(Q), list(plan.placements), reports, compared="links of the written-back URDF"
    )


def cross_check(
    model: CPCModel, urdf_path: str | os.PathLike[str], n: int = 100, seed: int = 0
) -> CrossCheckReport:
    """Compare ``urdf_path`` with ``model`` using Pinocchio, yourdfpy and urdfdom (a model built
    from a user's URDF: :func:`cross_check_writeback`, the module docstring).

    Args:
        model: The CPC model the URDF should describe.
        urdf_path: The URDF file.
        n: Number of configurations (seeded uniform within limits, incl. both limit corners).
        seed: Seed of the configurations.

    Raises:
        InputFileError: The URDF file is missing, unreadable or does not parse (any of the three
            parsers); a URDF that parses but disagrees is a report with ``ok`` False instead.
    """
    import xml.etree.ElementTree as ET

    path = os.fspath(urdf_path)
    text = read_urdf(path)
    Q = sample_configurations(model, n, seed)
    if urdf_source(model) is not None:
        return cross_check_writeback(model, path, Q)
    reports = [
        check_pinocchio(model, path, Q),
        check_yourdfpy(model, path, Q),
        check_urdfdom(model, path),
    ]
    links = {el.get("name") for el in ET.fromstring(text).iter("link")}
    return CrossCheckReport(
        path, len(Q), _compared_frames(model, _bodies_in(model, links)), reports
    )


__all__ = [
    "LIMIT_TOL",
    "CrossCheckReport",
    "ParserReport",
    "check_pinocchio",
    "check_pinocchio_writeback",
    "check_urdfdom",
    "check_urdfdom_executable",
    "check_urdfdom_writeback",
    "check_yourdfpy",
    "check_yourdfpy_writeback",
    "cross_check",
    "cross_check_writeback",
    "sample_configurations",
]
