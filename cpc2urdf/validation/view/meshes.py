"""Where a URDF's visual meshes are, and their triangles: ``package://``, ``file://`` and relative
mesh paths resolved to files, each loaded once (assimp, through coal), into Pinocchio's visual
geometry model.

``package://NAME/REST`` is looked up, first match wins, in

1. the package directories the user gives (``--package-path DIR``, ``package_dirs=``): the
   package is ``DIR/NAME``, or ``DIR`` itself if its folder is named ``NAME``;
2. ``ROS_PACKAGE_PATH`` (folders, as 1.) and ``AMENT_PREFIX_PATH`` (install prefixes: the package
   is ``PREFIX/share/NAME``), if set;
3. the folders above the URDF: a folder named ``NAME`` (a URDF in ``NAME/robots/x.urdf`` finds
   ``NAME``), or a folder ``NAME`` beside one of them (another package of the same workspace).

``file:///abs/path`` and absolute paths are used as they are; ``file://rel/path`` and relative
paths resolve against the URDF's folder (the current folder for URDF text or a CPC model).

Meshes are read as RViz reads them: assimp's coordinates without its root node's transform (so a
Collada ``<up_axis>`` is not applied), times the visual's ``scale`` and, for Collada, the file's
``<unit meter>`` (a millimetre file is drawn in metres).

A mesh that does not resolve, or that assimp cannot read (or that has no triangles), is refused
with one line naming the URDF, the link and the mesh path (:class:`UnresolvedMeshError`), before
anything is drawn. Pinocchio reads the visuals from the URDF with every mesh path replaced by the
file it resolved to, so what is drawn is exactly what was resolved; if it fails, each mesh is read
on its own to name the one that does not load.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin

from cpc2urdf.errors import InputFileError
from cpc2urdf.urdf.native_output import captured_output
from cpc2urdf.urdf.pinocchio import PinocchioRobot

PACKAGE_PATH_VARIABLES = ("ROS_PACKAGE_PATH", "AMENT_PREFIX_PATH")
PACKAGE_SCHEME = "package://"
FILE_SCHEME = "file://"

PackageDirs = Sequence[str | os.PathLike[str]]


class UnresolvedMeshError(InputFileError):
    """A visual mesh that does not resolve to a file, or that cannot be read.

    Args:
        urdf: The URDF's source, as errors name it.
        link: The link whose visual it is.
        mesh: The mesh path as the URDF writes it.
        problem: What is wrong (not found where, or why it cannot be read).
    """

    def __init__(self, urdf: object, link: str, mesh: str, problem: str) -> None:
        self.link = link
        self.mesh = mesh
        super().__init__(urdf, f"link {link!r}: mesh {mesh!r} {problem}")


@dataclass(frozen=True)
class MeshSearch:
    """Where mesh paths are looked up (see the module docstring for the order).

    Attributes:
        package_dirs: Folders given by the user, in order.
        ros_package_path: Folders of ``ROS_PACKAGE_PATH``.
        ament_prefixes: Install prefixes of ``AMENT_PREFIX_PATH``.
        urdf_dir: The URDF's folder (absolute): relative paths start here, and the folders above
            it are searched for packages.
    """

    package_dirs: tuple[Path, ...]
    ros_package_path: tuple[Path, ...]
    ament_prefixes: tuple[Path, ...]
    urdf_dir: Path

    @classmethod
    def of(
        cls,
        urdf_path: str | os.PathLike[str] | None,
        package_dirs: PackageDirs = (),
        environ: Mapping[str, str] | None = None,
    ) -> MeshSearch:
        """The search for a URDF file (None: URDF text, looked up from the current folder),
        with the user's ``package_dirs`` and the package path variables of ``environ`` (default
        ``os.environ``).

        Raises:
            InputFileError: A package directory the user gave is not a folder.
        """
        env = os.environ if environ is None else environ
        for d in package_dirs:
            if not Path(d).is_dir():
                raise InputFileError(d, "no such folder (a package directory, --package-path)")

        def folders(variable: str) -> tuple[Path, ...]:
            return tuple(Path(p) for p in env.get(variable, "").split(os.pathsep) if p)

        base = Path(urdf_path).resolve().parent if urdf_path is not None else Path.cwd()
        return cls(
            tuple(Path(p) for p in package_dirs),
            folders("ROS_PACKAGE_PATH"),
            folders("AMENT_PREFIX_PATH"),
            base,
        )

    def package_candidates(self, name: str) -> list[Path]:
        """The folders that could be package ``name``, in search order (they may not exist)."""
        out: list[Path] = []
        for d in (*self.package_dirs, *self.ros_package_path):
            out.extend([d, d / name] if d.name == name else [d / name])
        out.extend(p / "share" / name for p in self.ament_prefixes)
        for a in (self.urdf_dir, *self.urdf_dir.parents):
            out.extend([a, a / name] if a.name == name else [a / name])
        return out

    def resolve(self, filename: str) -> Path:
        """The file a URDF mesh path means.

        Raises:
            LookupError: It does not resolve; the message says where it was looked for.
        """
        if filename.startswith(PACKAGE_SCHEME):
            name, _, rest = filename[len(PACKAGE_SCHEME) :].partition("/")
            if not name or not rest:
                raise LookupError("is not package://NAME/PATH")
            packages = [p for p in self.package_candidates(name) if p.is_dir()]
            for p in packages:
                if (p / rest).is_file():
                    return (p / rest).resolve()
            if packages:
                where = ", ".join(str(p) for p in dict.fromkeys(packages))
                raise LookupError(f"not found: package {name!r} ({where}) has no file {rest}")
            raise LookupError(
                f"not found: no package {name!r} in --package-path, "
                f"{' or '.join(PACKAGE_PATH_VARIABLES)} or the folders above the URDF "
                f"({self.urdf_dir})"
            )
        path = filename[len(FILE_SCHEME) :] if filename.startswith(FILE_SCHEME) else filename
        if "://" in path:
            raise LookupError("has a scheme other than package:// or file://")
        p = Path(path) if Path(path).is_absolute() else self.urdf_dir / path
        if not p.is_file():
            raise LookupError(f"not found (no file {p})")
        return p.resolve()


@dataclass(frozen=True)
class VisualMesh:
    """One mesh visual of a URDF.

    Attributes:
        link: Its link.
        filename: The mesh path as the URDF writes it.
        path: The file it resolved to.
        n_triangles: Triangles as read (scaled by the visual's ``scale``).
    """

    link: str
    filename: str
    path: Path
    n_triangles: int


@dataclass(frozen=True)
class VisualMeshes:
    """What the visuals of a URDF are made of.

    Attributes:
        n_visuals: ``<visual>`` elements of the URDF's links.
        meshes: Its mesh visuals, in URDF order; each resolved and read.
    """

    n_visuals: int
    meshes: tuple[VisualMesh, ...]

    @property
    def n_meshes(self) -> int:
        """Mesh visuals."""
        return len(self.meshes)

    def format(self) -> str:
        """One line: how many visuals are meshes, and their triangles."""
        tris = sum(m.n_triangles for m in self.meshes)
        return (
            f"visuals: {self.n_visuals}, of which {self.n_meshes} meshes"
            f" ({len({m.path for m in self.meshes})} files, {tris} triangles), all resolved"
        )


def _scale(mesh: ET.Element) -> np.ndarray:
    return np.array([float(v) for v in mesh.get("scale", "1 1 1").split()], dtype=float)


def collada_unit(path: Path) -> float:
    """The ``<asset><unit meter="...">`` of a Collada file [m per file unit]; 1 if it has none
    (or the value is not a positive number)."""
    try:
        for _, el in ET.iterparse(path, events=("start",)):
            tag = el.tag.rsplit("}", 1)[-1]
            if tag == "unit":
                meter = float(el.get("meter", "1"))
                return meter if np.isfinite(meter) and meter > 0 else 1.0
            if tag.startswith("library_"):  # the asset comes first
                break
    except (ET.ParseError, ValueError, OSError):
        pass  # not Collada XML: assimp will say so
    return 1.0


def _why(error: Exception) -> str:
    """The line of assimp's message (through coal) that says why a mesh cannot be read."""
    lines = [ln.strip() for ln in str(error).splitlines() if ln.strip()]
    useful = [
        ln
        for ln in lines
        if not ln.startswith(("From file:", "in function:", "at line:", "Hint:", "message:"))
    ]
    return (useful or lines or [type(error).__name__])[-1]


def visual_geometry(
    robot: PinocchioRobot, package_dirs: PackageDirs = (), environ: Mapping[str, str] | None = None
) -> tuple[pin.GeometryModel, VisualMeshes]:
    """Pinocchio's visual geometry model of ``robot``'s URDF, its meshes resolved and read.

    Args:
        robot: The robot (its URDF text, :attr:`~PinocchioRobot.path` and source).
        package_dirs: Folders where ``package://`` packages are looked up first.
        environ: Environment for ``ROS_PACKAGE_PATH``/``AMENT_PREFIX_PATH`` (default
            ``os.environ``).

    Returns:
        The geometry model (meshes as ``coal.BVHModelOBBRSS`` with the visual's scale applied,
        ``meshPath`` the resolved file) and what its visuals are made of.

    Raises:
        UnresolvedMeshError: A mesh path that does not resolve, or a mesh that cannot be read.
        InputFileError: Pinocchio refuses the visuals otherwise.
    """
    search = MeshSearch.of(robot.path, package_dirs, environ)
    root = ET.fromstring(robot.urdf)
    n_visuals = 0
    found: list[tuple[str, str, Path, ET.Element]] = []  # link, filename, file, <mesh>
    for link in root.findall("link"):
        for visual in link.findall("visual"):
            n_visuals += 1
            mesh = visual.find("geometry/mesh")
            if mesh is None:
                continue
            name, filename = str(link.get("name")), str(mesh.get("filename"))
            try:
                path = search.resolve(filename)
            except LookupError as e:
                raise UnresolvedMeshError(robot.source, name, filename, str(e)) from None
            mesh.set("filename", str(path))
            if path.suffix.lower() == ".dae" and (unit := collada_unit(path)) != 1.0:
                mesh.set("scale", " ".join(repr(float(v)) for v in unit * _scale(mesh)))
            found.append((name, filename, path, mesh))
    text = ET.tostring(root, encoding="unicode") if found else robot.urdf
    with captured_output() as out:
        try:
            geometry = pin.buildGeomFromUrdfString(robot.model, text, pin.GeometryType.VISUAL)
        except (ValueError, RuntimeError) as e:
            failure: Exception | None = e
        else:
            failure = None
    if failure is not None:
        _refuse_unreadable(robot.source, found)
    said = out.error_lines()
    if failure is not None or said:
        why = said[0] if said else _why(failure)  # type: ignore[arg-type]
        raise InputFileError(robot.source, f"visuals Pinocchio cannot read ({why})") from failure
    triangles = {}
    for go in geometry.geometryObjects:
        if str(go.meshPath) and hasattr(go.geometry, "num_tris"):
            triangles[(robot.model.frames[go.parentFrame].name, str(go.meshPath))] = int(
                go.geometry.num_tris
            )
    meshes = []
    for name, filename, path, _ in found:
        n = triangles.get((name, str(path)), 0)
        if n == 0:
            raise UnresolvedMeshError(robot.source, name, filename, f"has no triangles ({path})")
        meshes.append(VisualMesh(name, filename, path, n))
    return geometry, VisualMeshes(n_visuals, tuple(meshes))


def _refuse_unreadable(source: str, found: list[tuple[str, str, Path, ET.Element]]) -> None:
    """Find the mesh assimp cannot read (Pinocchio said only that one failed) and refuse it,
    naming the link and the mesh path; return if each reads on its own."""
    loader = coal.MeshLoader()
    for name, filename, path, mesh in found:
        with captured_output():
            try:
                loader.load(str(path), _scale(mesh))
            except (ValueError, RuntimeError) as e:
                raise UnresolvedMeshError(
                    source, name, filename, f"cannot be read ({path}: {_why(e)})"
                ) from None


__all__ = [
    "FILE_SCHEME",
    "PACKAGE_PATH_VARIABLES",
    "PACKAGE_SCHEME",
    "MeshSearch",
    "PackageDirs",
    "UnresolvedMeshError",
    "VisualMesh",
    "VisualMeshes",
    "collada_unit",
    "visual_geometry",
]
