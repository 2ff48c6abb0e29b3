"""The five URDF consumers as test helpers: load a file the way each consumer's users do, capture
everything it prints while loading, and read back the pose of every link at joint readings given
by URDF joint name.

Shared by ``test_consumers.py`` (URDFs we export) and ``test_real_robots.py`` (third-party URDFs
written back after calibration). A third-party URDF names its meshes ``package://NAME/...``; the
loaders take ``packages``, folders holding the packages (``DIR/NAME/...``), and use each
consumer's own way of finding them:

- Pinocchio: ``buildGeomFromUrdf(..., package_dirs=packages)``;
- yourdfpy: a ``filename_handler`` mapping ``package://NAME/REST`` to ``DIR/NAME/REST``;
- urdfdom's ``check_urdf``: reads no mesh;
- MuJoCo: its URDF importer does not know ``package://`` (it opens ``package:/NAME/...`` as a
  relative path), so with ``packages`` the file is read with ``mujoco.MjSpec.from_file``, every
  mesh's file name resolved in memory, and compiled; ``keep_links`` turns off the importer's
  ``fusestatic`` (in memory) so that every link stays a body, and ``drop_undecodable`` removes
  geoms whose mesh format MuJoCo has no decoder for (COLLADA ``.dae``);
- PyBullet: strips ``package://`` and tries the rest below every folder above the URDF
  (``UrdfFindMeshFile.h``); ``pybullet.setAdditionalSearchPath`` does not apply to meshes. So
  the URDF must sit in a folder that has the packages (or links to them) next to it, as in a
  ROS workspace's ``share`` folder: :func:`package_folder`.

PyBullet's link-frame items of ``getLinkState`` (4, 5) carry its own ~1e-7 error (it shows the
same on its bundled KUKA model; see ../shared/reviews/urdf-consumers.md); its centre-of-mass items
(0, 1) are exact, so the link frame is taken from them and the ``<inertial><origin>`` written in
the file: ``T_world_link = T_world_com inv(T_link_inertial)`` (the base's pose too is its inertial
frame's). PyBullet's state queries fail on a body with more than 128 links (its shared-memory limit
``MAX_DEGREE_OF_FREEDOM``, bulletphysics/bullet3#4621: "GetBasePositionAndOrientation failed"), as
on iCub's 214-joint URDF.
"""

from __future__ import annotations

import subprocess
import xml.etree.ElementTree as ET
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cpc2urdf.transforms import Array, matrix_from_rpy, rotation_error
from cpc2urdf.urdf.native_output import captured_output
from cpc2urdf.validation.crosscheck import check_urdfdom_executable, yourdfpy_pose

CONSUMER_TOL = 1e-12  # [m] and [rad]: every consumer's pose of every link vs Pinocchio's
CONSUMERS = ("pinocchio", "yourdfpy", "check_urdf", "mujoco", "pybullet")
PACKAGE_SCHEME = "package://"
MUJOCO_UNDECODABLE = (".dae",)  # mesh formats MuJoCo 3/4 has no decoder for
Poses = dict[str, Array]
# (FK by joint name, what it printed while loading, how to let it go)
Loaded = tuple[Callable[[dict[str, float]], Poses] | None, str, Callable[[], None]]


def links(path: Path) -> list[str]:
    """Every ``<link>`` name of the URDF, in file order."""
    return [el.get("name", "") for el in ET.parse(path).getroot().iter("link")]


def inertial_origins(path: Path) -> dict[str, Array]:
    """``T_link_inertial`` (4, 4) of every link, from the file's ``<inertial><origin>``."""
    out = {}
    for link in ET.parse(path).getroot().iter("link"):
        T = np.eye(4)
        origin = link.find("inertial/origin")
        if origin is not None:
            T[:3, :3] = matrix_from_rpy([float(v) for v in origin.get("rpy", "0 0 0").split()])
            T[:3, 3] = [float(v) for v in origin.get("xyz", "0 0 0").split()]
        out[link.get("name", "")] = T
    return out


def resolve_package(filename: str, packages: Sequence[Path]) -> str:
    """``package://NAME/REST`` as ``DIR/NAME/REST`` for the first of ``packages`` that has it;
    any other file name unchanged."""
    if not filename.startswith(PACKAGE_SCHEME):
        return filename
    rest = filename[len(PACKAGE_SCHEME) :]
    for d in packages:
        if (Path(d) / rest).exists():
            return str(Path(d) / rest)
    return filename


def package_folder(folder: Path, packages: Mapping[str, Path]) -> Path:
    """``folder`` with a symbolic link ``folder/NAME`` to each package (a ROS-workspace-like
    ``share`` folder): a URDF written into it finds ``package://NAME/...`` in every consumer."""
    folder.mkdir(parents=True, exist_ok=True)
    for name, target in packages.items():
        link = folder / name
        if not link.exists():
            link.symlink_to(target, target_is_directory=True)
    return folder


def pinocchio_q(model: Any, readings: Mapping[str, float]) -> Array:
    """Pinocchio's configuration of ``model`` with ``readings`` (joints by URDF name), the other
    joints neutral."""
    import pinocchio as pin

    q = pin.neutral(model)
    for name, v in readings.items():
        jid = model.getJointId(name)
        i = model.idx_qs[jid]
        if model.joints[jid].nq == 2:  # continuous: (cos, sin)
            q[i], q[i + 1] = np.cos(v), np.sin(v)
        else:
            q[i] = v
    return q


def load_pinocchio(path: Path, packages: Sequence[Path] = (), *, geometry: bool = True) -> Loaded:
    """Pinocchio's model (and, with ``geometry``, its visual and collision models) of the URDF."""
    import pinocchio as pin

    with captured_output() as out:
        model = pin.buildModelFromUrdf(str(path))
        for kind in (pin.GeometryType.VISUAL, pin.GeometryType.COLLISION) if geometry else ():
            pin.buildGeomFromUrdf(model, str(path), kind, package_dirs=[str(d) for d in packages])
    data = model.createData()
    body = {f.name: i for i, f in enumerate(model.frames) if f.type == pin.FrameType.BODY}

    def fk(q: dict[str, float]) -> Poses:
        pin.framesForwardKinematics(model, data, pinocchio_q(model, q))
        return {link: data.oMf[i].homogeneous.copy() for link, i in body.items()}

    return fk, out.text, lambda: None


def load_yourdfpy(path: Path, packages: Sequence[Path] = ()) -> Loaded:
    import yourdfpy

    kw: dict[str, Any] = {}
    if packages:
        kw["filename_handler"] = lambda fname: resolve_package(fname, packages)
    with captured_output() as out:
        robot = yourdfpy.URDF.load(str(path), **kw)
        assert robot.validate()
    root = robot.base_link

    def fk(q: dict[str, float]) -> Poses:
        # yourdfpy's own joint transforms, composed (crosscheck.yourdfpy_pose), not its
        # get_transform: that reads trimesh's scene graph, which keeps an edge moved by < 1e-8
        robot.update_cfg(q)
        return {link: yourdfpy_pose(robot, link, root) for link in robot.link_map}

    return fk, out.text, lambda: None


def load_check_urdf(path: Path, packages: Sequence[Path] = ()) -> Loaded:
    exe = check_urdfdom_executable()
    assert exe is not None, "check_urdf ships with the 'pin' package"
    proc = subprocess.run([exe, str(path)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and "Successfully Parsed XML" in proc.stdout, (
        proc.stdout + proc.stderr
    )
    said = [
        ln for ln in proc.stdout.splitlines() if ln.strip().lower().startswith(("error", "warn"))
    ]
    return None, proc.stderr + "\n".join(said), lambda: None


def mujoco_model(
    path: Path,
    packages: Sequence[Path] = (),
    *,
    keep_links: bool = False,
    drop_undecodable: bool = False,
    kinematics_only: bool = False,
) -> Any:
    """``mujoco.MjModel`` of the URDF: ``from_xml_path`` without ``packages`` or options, else
    through ``MjSpec`` with, in memory, the mesh file names resolved (module docstring), and
    ``kinematics_only``: every geom and mesh removed and every body given the same valid inertia
    (unit mass, 1e-3 kg m^2 about its origin), so that only the kinematic tree is MuJoCo's reading
    of the file (for a robot whose own inertias MuJoCo refuses)."""
    import mujoco

    if not packages and not (keep_links or drop_undecodable or kinematics_only):
        return mujoco.MjModel.from_xml_path(str(path))
    spec = mujoco.MjSpec.from_file(str(path))
    if keep_links:
        spec.compiler.fusestatic = False
    if kinematics_only:
        for geom in list(spec.geoms):
            spec.delete(geom)
        for mesh in list(spec.meshes):
            spec.delete(mesh)
        for body in spec.bodies:
            body.explicitinertial = True
            body.mass, body.ipos, body.iquat = 1.0, [0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]
            body.inertia, body.fullinertia = [1e-3, 1e-3, 1e-3], [float("nan")] + [0.0] * 5
    for mesh in list(spec.meshes):
        mesh.file = resolve_package(mesh.file, packages)
        if drop_undecodable and mesh.file.lower().endswith(MUJOCO_UNDECODABLE):
            for geom in [g for g in spec.geoms if g.meshname == mesh.name]:
                spec.delete(geom)
            spec.delete(mesh)
    return spec.compile()


def load_mujoco(path: Path, packages: Sequence[Path] = (), **kw: bool) -> Loaded:
    import mujoco

    with captured_output() as out:
        model = mujoco_model(path, packages, **kw)
    data = mujoco.MjData(model)
    bodies = {mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, i): i for i in range(model.nbody)}

    def fk(q: dict[str, float]) -> Poses:
        data.qpos[:] = 0.0
        for name, v in q.items():
            j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
            data.qpos[model.jnt_qposadr[j]] = v
        mujoco.mj_kinematics(model, data)
        out = {}
        for link, i in bodies.items():
            T = np.eye(4)
            T[:3, :3] = data.xmat[i].reshape(3, 3)
            T[:3, 3] = data.xpos[i]
            out[link] = T
        return out

    return fk, out.text, lambda: None


def load_pybullet(path: Path, packages: Sequence[Path] = ()) -> Loaded:
    with captured_output():
        import pybullet as pb  # prints its build time on import

        client = pb.connect(pb.DIRECT)
    try:
        with captured_output() as out:
            body = pb.loadURDF(str(path), useFixedBase=True, physicsClientId=client)
    except BaseException:
        pb.disconnect(physicsClientId=client)
        raise
    root = pb.getBodyInfo(body, physicsClientId=client)[0].decode()
    joint, child = {}, {}
    for j in range(pb.getNumJoints(body, physicsClientId=client)):
        info = pb.getJointInfo(body, j, physicsClientId=client)
        joint[info[1].decode()] = j
        child[info[12].decode()] = j
    T_link_inertial = inertial_origins(path)

    def pose(pos: Any, quat: Any) -> Array:
        T = np.eye(4)
        T[:3, :3] = np.array(pb.getMatrixFromQuaternion(quat)).reshape(3, 3)
        T[:3, 3] = pos
        return T

    def fk(q: dict[str, float]) -> Poses:
        for name, v in q.items():
            pb.resetJointState(body, joint[name], v, physicsClientId=client)
        base = pose(
            *pb.getBasePositionAndOrientation(body, physicsClientId=client)
        )  # its inertial frame
        out = {root: base @ np.linalg.inv(T_link_inertial[root])}
        for link, j in child.items():
            st = pb.getLinkState(body, j, computeForwardKinematics=True, physicsClientId=client)
            out[link] = pose(st[0], st[1]) @ np.linalg.inv(
                T_link_inertial[link]
            )  # items 0/1: exact
        return out

    return fk, out.text, lambda: pb.disconnect(physicsClientId=client)


LOADERS: dict[str, Callable[..., Loaded]] = {
    "pinocchio": load_pinocchio,
    "yourdfpy": load_yourdfpy,
    "check_urdf": load_check_urdf,
    "mujoco": load_mujoco,
    "pybullet": load_pybullet,
}


def fk_disagreement(
    fk: Callable[[dict[str, float]], Poses],
    reference: Callable[[dict[str, float]], Poses],
    names: Sequence[str],
    configurations: Sequence[dict[str, float]],
) -> tuple[float, float, str]:
    """Largest position [m] and rotation [rad] difference between ``fk`` and ``reference`` over
    the links ``names`` at ``configurations``, and where it is (``link`` at ``q``).

    Raises:
        AssertionError: ``fk`` lacks one of the links.
    """
    worst = (0.0, 0.0, "")
    for q in configurations:
        ref, got = reference(q), fk(q)
        missing = sorted(set(names) - set(got))
        assert not missing, f"lacks links {missing}"
        for link in names:
            dp = float(np.linalg.norm(got[link][:3, 3] - ref[link][:3, 3]))
            dr = float(rotation_error(ref[link][:3, :3], got[link][:3, :3]))
            if max(dp, dr) > max(worst[:2]):
                worst = (dp, dr, f"{link} at {q}")
    return worst
