"""The view's meshes: ``package://``, ``file://`` and relative paths resolved by the stated rules,
drawn from the files' own triangles, on a real robot (TIAGo, from example-robot-data) and on small
packages made here; a mesh that does not resolve or load is one line naming URDF, link and mesh."""

from __future__ import annotations

import math
import shutil
import struct
import sysconfig
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import umsgpack
from scipy.spatial.transform import Rotation
from test_view import decoded

from cpc2urdf.errors import InputFileError
from cpc2urdf.validation.view import (
    MeshSearch,
    UnresolvedMeshError,
    build_view,
    load_view_robot,
    static_visualizer,
)

SHARE = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix" / "share"
TIAGO = SHARE / "example-robot-data" / "robots" / "tiago_description" / "robots" / "tiago.urdf"


# ---- meshes made here -------------------------------------------------------------------------

TETRA = np.array([[0.0, 0, 0], [0.02, 0, 0], [0, 0.03, 0], [0, 0, 0.04]])  # [m]
TETRA_FACES = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def write_stl(path: Path, vertices: np.ndarray = TETRA, faces: np.ndarray = TETRA_FACES) -> Path:
    """A binary STL of the triangles."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("wb") as f:
        f.write(b"\0" * 80 + struct.pack("<I", len(faces)))
        for tri in faces:
            f.write(struct.pack("<3f", 0, 0, 0))
            for v in vertices[tri]:
                f.write(struct.pack("<3f", *v))
            f.write(b"\0\0")
    return path


def write_obj(path: Path, vertices: np.ndarray = TETRA, faces: np.ndarray = TETRA_FACES) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = [f"v {x} {y} {z}" for x, y, z in vertices] + [
        f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces
    ]
    path.write_text("\n".join(lines) + "\n")
    return path


def write_dae(path: Path, vertices: np.ndarray = TETRA, faces: np.ndarray = TETRA_FACES) -> Path:
    """A minimal Collada file (metres, Z up) of the triangles."""
    path.parent.mkdir(parents=True, exist_ok=True)
    pos = " ".join(f"{c:g}" for c in vertices.ravel())
    idx = " ".join(str(int(i)) for i in faces.ravel())
    path.write_text(f"""<?xml version="1.0" encoding="utf-8"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit name="meter" meter="1"/><up_axis>Z_UP</up_axis></asset>
  <library_geometries><geometry id="g"><mesh>
    <source id="p"><float_array id="pa" count="{vertices.size}">{pos}</float_array>
      <technique_common><accessor source="#pa" count="{len(vertices)}" stride="3">
        <param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/>
      </accessor></technique_common></source>
    <vertices id="v"><input semantic="POSITION" source="#p"/></vertices>
    <triangles count="{len(faces)}"><input semantic="VERTEX" source="#v" offset="0"/><p>{idx}</p></triangles>
  </mesh></geometry></library_geometries>
  <library_visual_scenes><visual_scene id="s"><node id="n">
    <instance_geometry url="#g"/></node></visual_scene></library_visual_scenes>
  <scene><instance_visual_scene url="#s"/></scene>
</COLLADA>
""")
    return path


def urdf_with_meshes(path: Path, meshes: list[tuple[str, str]], scale: str = "1 1 1") -> Path:
    """A URDF whose link ``lK`` (one per entry, chained by revolute joints) has one mesh visual
    ``(filename, rgba)``, 0.1 m above its origin."""
    parts = ['<robot name="m">']
    for k, (filename, rgba) in enumerate(meshes):
        parts.append(
            f'<link name="l{k}"><visual><origin xyz="0 0 0.1"/><geometry>'
            f'<mesh filename="{filename}" scale="{scale}"/></geometry>'
            f'<material name="c{k}"><color rgba="{rgba}"/></material></visual></link>'
        )
        if k:
            parts.append(
                f'<joint name="j{k}" type="revolute"><parent link="l{k - 1}"/><child link="l{k}"/>'
                '<origin xyz="0 0 0.2"/><axis xyz="0 0 1"/>'
                '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
            )
    parts.append("</robot>")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(parts))
    return path


def drawn_vertices(scene: dict[str, dict[str, object]], link: str) -> np.ndarray:
    """The vertices [m], shape (N, 3), of the one mesh drawn on ``link``."""
    paths = [
        p
        for p, e in scene.items()
        if p.startswith(f"/meshcat/head/{link}/")
        and "object" in e
        and e["object"]["geometries"][0]["type"] == "BufferGeometry"  # type: ignore[index]
    ]
    assert len(paths) == 1, paths
    geometry = scene[paths[0]]["object"]["geometries"][0]  # type: ignore[index]
    data = geometry["data"]["attributes"]["position"]["array"].data
    return np.frombuffer(data, dtype=np.float32).reshape(-1, 3).astype(float)


def same_colour(colour: int, rgba: str) -> bool:
    """meshcat's ``0xRRGGBB`` is the URDF's ``rgba`` (Pinocchio keeps colours in float32: one
    step of 1/255 either way)."""
    want = [round(255 * float(c)) for c in rgba.split()[:3]]
    got = [(colour >> 16) & 255, (colour >> 8) & 255, colour & 255]
    return all(abs(a - b) <= 1 for a, b in zip(got, want, strict=True))


def same_points(a: np.ndarray, b: np.ndarray, tol: float = 1e-6) -> bool:
    """The same set of points (each within ``tol`` of one of the other)."""
    d = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2)
    return bool(d.min(axis=1).max() < tol and d.min(axis=0).max() < tol)


# ---- resolution rules -------------------------------------------------------------------------


def test_each_resolution_rule_finds_its_file(tmp_path: Path) -> None:
    ws = tmp_path / "ws" / "src"
    urdf = ws / "my_pkg" / "urdf" / "r.urdf"
    urdf.parent.mkdir(parents=True)
    own = write_stl(ws / "my_pkg" / "meshes" / "a.stl")
    sibling = write_obj(ws / "other_pkg" / "m" / "b.obj")
    search = MeshSearch.of(urdf, environ={})
    # (c) a folder above the URDF named like the package, and a package beside one of them.
    assert search.resolve("package://my_pkg/meshes/a.stl") == own.resolve()
    assert search.resolve("package://other_pkg/m/b.obj") == sibling.resolve()
    # Relative and file:// paths against the URDF's folder; absolute file:// as is.
    assert search.resolve("../meshes/a.stl") == own.resolve()
    assert search.resolve("file://../meshes/a.stl") == own.resolve()
    assert search.resolve(f"file://{own}") == own.resolve()
    assert search.resolve(str(own)) == own.resolve()
    # (a) user package directories come first: a folder holding the package, or the package.
    mine = write_stl(tmp_path / "user" / "my_pkg" / "meshes" / "a.stl")
    assert (
        MeshSearch.of(urdf, [tmp_path / "user"], {}).resolve("package://my_pkg/meshes/a.stl")
        == mine.resolve()
    )
    assert (
        MeshSearch.of(urdf, [tmp_path / "user" / "my_pkg"], {}).resolve(
            "package://my_pkg/meshes/a.stl"
        )
        == mine.resolve()
    )
    # (b) ROS_PACKAGE_PATH (folders of packages) and AMENT_PREFIX_PATH (PREFIX/share/NAME),
    # before the folders above the URDF; the user's directories before both.
    ros = write_stl(tmp_path / "ros" / "my_pkg" / "meshes" / "a.stl")
    ament = write_stl(tmp_path / "install" / "share" / "third" / "c.stl")
    env = {
        "ROS_PACKAGE_PATH": f"/nonexistent:{tmp_path / 'ros'}",
        "AMENT_PREFIX_PATH": str(tmp_path / "install"),
    }
    assert (
        MeshSearch.of(urdf, environ=env).resolve("package://my_pkg/meshes/a.stl") == ros.resolve()
    )
    assert MeshSearch.of(urdf, environ=env).resolve("package://third/c.stl") == ament.resolve()
    assert (
        MeshSearch.of(urdf, [tmp_path / "user"], env).resolve("package://my_pkg/meshes/a.stl")
        == mine.resolve()
    )


@pytest.mark.parametrize(
    ("filename", "message"),
    [
        ("package://nowhere/a.stl", "no package 'nowhere' in --package-path"),
        ("package://my_pkg/meshes/missing.stl", "has no file meshes/missing.stl"),
        ("meshes/missing.stl", "not found (no file"),
        ("model://my_pkg/a.stl", "scheme other than package:// or file://"),
        ("package://my_pkg", "is not package://NAME/PATH"),
    ],
)
def test_unresolved_mesh_names_urdf_link_and_path(
    tmp_path: Path, filename: str, message: str
) -> None:
    write_stl(tmp_path / "my_pkg" / "meshes" / "a.stl")
    urdf = urdf_with_meshes(
        tmp_path / "my_pkg" / "urdf" / "r.urdf",
        [("package://my_pkg/meshes/a.stl", "1 0 0 1"), (filename, "0 1 0 1")],
    )
    with pytest.raises(UnresolvedMeshError) as e:
        load_view_robot(urdf)
    text = str(e.value)
    assert text.startswith(f"{urdf}: link 'l1': mesh {filename!r}") and message in text, text
    assert "\n" not in text and e.value.link == "l1" and e.value.mesh == filename


def test_unreadable_or_empty_mesh_and_bad_package_dir(tmp_path: Path) -> None:
    (tmp_path / "garbage.stl").write_bytes(b"this is not a mesh")
    urdf = urdf_with_meshes(tmp_path / "r.urdf", [("garbage.stl", "1 0 0 1")])
    with pytest.raises(
        UnresolvedMeshError, match=r"link 'l0': mesh 'garbage.stl' cannot be read \("
    ) as e:
        load_view_robot(urdf)
    assert "\n" not in str(e.value)
    with pytest.raises(InputFileError, match="no such folder"):
        load_view_robot(urdf, package_dirs=[tmp_path / "nope"])


# ---- the triangles drawn are the file's ---------------------------------------------------------


def test_stl_obj_dae_drawn_with_scale_pose_and_colour(tmp_path: Path) -> None:
    """Three formats, each drawn with the file's vertices times the scale, 0.1 m above its link,
    in its URDF material colour."""
    write_stl(tmp_path / "pkg" / "a.stl")
    write_obj(tmp_path / "pkg" / "b.obj")
    write_dae(tmp_path / "pkg" / "c.dae")
    colours = ["0.9 0.2 0.1 1", "0.1 0.8 0.2 1", "0.2 0.3 0.9 1"]
    urdf = urdf_with_meshes(
        tmp_path / "pkg" / "robots" / "r.urdf",
        list(zip(["package://pkg/a.stl", "../b.obj", "file://../c.dae"], colours, strict=True)),
        scale="2 3 4",
    )
    robot = load_view_robot(urdf)
    assert robot.meshes.n_visuals == 3 and robot.meshes.n_meshes == 3
    vis = static_visualizer()
    build_view(vis, robot, sweep=False)
    scene = decoded(vis.window)
    for k, rgba in enumerate(colours):
        V = drawn_vertices(scene, f"l{k}")
        assert same_points(V, TETRA * [2.0, 3.0, 4.0]), f"l{k}"
        node = next(
            p for p in scene if p.startswith(f"/meshcat/head/l{k}/") and "object" in scene[p]
        )
        assert np.allclose(scene[node]["transform"][:3, 3], [0.0, 0.0, 0.1])
        colour = scene[node]["object"]["materials"][0]["color"]
        assert same_colour(colour, rgba)


def test_collada_unit_is_applied(tmp_path: Path) -> None:
    """A Collada file in millimetres is drawn in metres (as RViz does; assimp through coal
    ignores the unit)."""
    dae = write_dae(tmp_path / "mm.dae", TETRA * 1000.0)
    dae.write_text(dae.read_text().replace('meter="1"', 'meter="0.001"'))
    urdf = urdf_with_meshes(tmp_path / "r.urdf", [("mm.dae", "1 1 1 1")], scale="1 2 1")
    vis = static_visualizer()
    build_view(vis, load_view_robot(urdf), sweep=False)
    assert same_points(drawn_vertices(decoded(vis.window), "l0"), TETRA * [1.0, 2.0, 1.0])


# ---- a real robot: TIAGo ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def tiago_scene() -> tuple[object, dict[str, dict[str, object]]]:
    robot = load_view_robot(TIAGO)  # package://example-robot-data/... found above the URDF
    vis = static_visualizer()
    build_view(vis, robot, sweep=False)
    return robot, decoded(vis.window)


def test_tiago_every_mesh_resolves_to_its_file(tiago_scene: tuple[object, dict]) -> None:
    robot, _ = tiago_scene
    root = ET.parse(TIAGO).getroot()
    expected = [
        (link.get("name"), mesh.get("filename"))
        for link in root.findall("link")
        for visual in link.findall("visual")
        if (mesh := visual.find("geometry/mesh")) is not None
    ]
    n_visuals = sum(len(link.findall("visual")) for link in root.findall("link"))
    meshes = robot.meshes  # type: ignore[attr-defined]
    assert (meshes.n_visuals, meshes.n_meshes) == (n_visuals, len(expected)) == (65, 44)
    assert [(m.link, m.filename) for m in meshes.meshes] == expected
    for m in meshes.meshes:
        rest = m.filename.removeprefix("package://example-robot-data/")
        assert m.path == (SHARE / "example-robot-data" / rest).resolve() and m.path.is_file()
    # Continuous wheels are read as unlimited revolute joints.
    assert robot.pinocchio.continuous_joints == ("wheel_left_joint", "wheel_right_joint")  # type: ignore[attr-defined]


def test_tiago_head_mesh_is_the_stl_file_at_its_urdf_origin(
    tiago_scene: tuple[object, dict],
) -> None:
    """head_2_link's mesh: the STL's own vertices (read here with numpy), placed by the URDF
    visual's origin, in its URDF material's colour."""
    _, scene = tiago_scene
    stl = SHARE / "example-robot-data/robots/tiago_description/meshes/head/head_2.stl"
    raw = stl.read_bytes()
    n = struct.unpack_from("<I", raw, 80)[0]
    tris = np.frombuffer(
        raw, dtype=np.dtype([("n", "<3f4"), ("v", "<9f4"), ("a", "<u2")]), count=n, offset=84
    )
    stl_vertices = np.unique(tris["v"].reshape(-1, 3).astype(float), axis=0)
    drawn = np.unique(drawn_vertices(scene, "head_2_link"), axis=0)
    assert drawn.shape == stl_vertices.shape and np.allclose(drawn, stl_vertices, atol=1e-7)
    root = ET.parse(TIAGO).getroot()
    link = next(lk for lk in root.findall("link") if lk.get("name") == "head_2_link")
    visual = link.find("visual")
    origin = visual.find("origin")  # type: ignore[union-attr]
    xyz = [float(v) for v in (origin.get("xyz") if origin is not None else "0 0 0").split()]
    rpy = [float(v) for v in (origin.get("rpy") if origin is not None else "0 0 0").split()]
    node = next(
        p for p in scene if p.startswith("/meshcat/head/head_2_link/") and "object" in scene[p]
    )
    T = scene[node]["transform"]
    assert np.allclose(T[:3, 3], xyz, atol=1e-12)
    assert np.allclose(T[:3, :3], Rotation.from_euler("xyz", rpy).as_matrix(), atol=1e-12)
    name = visual.find("material").get("name")  # type: ignore[union-attr]
    rgba = (
        next(m for m in root.findall("material") if m.get("name") == name).find("color").get("rgba")
    )  # type: ignore[union-attr]
    assert same_colour(scene[node]["object"]["materials"][0]["color"], rgba)


def test_tiago_copied_elsewhere_needs_its_package_path(tmp_path: Path) -> None:
    copy = Path(shutil.copy(TIAGO, tmp_path / "tiago.urdf"))
    with pytest.raises(UnresolvedMeshError, match="no package 'example-robot-data'"):
        load_view_robot(copy)
    robot = load_view_robot(copy, package_dirs=[SHARE])
    assert robot.meshes.n_meshes == 44
    assert math.isinf(robot.pinocchio.upper[robot.joint_names.index("wheel_left_joint")])


def test_sixteen_bit_indices_when_they_fit() -> None:
    from cpc2urdf.validation.view.geometry import TriangleMesh

    small = TriangleMesh(TETRA, TETRA_FACES).lower({})
    assert small["data"]["index"]["type"] == "Uint16Array"
    assert np.array_equal(
        np.frombuffer(small["data"]["index"]["array"].data, np.uint16), TETRA_FACES.ravel()
    )
    big_v = np.zeros((70000, 3))
    big = TriangleMesh(big_v, np.array([[0, 1, 69999]])).lower({})
    assert big["data"]["index"]["type"] == "Uint32Array"
    assert umsgpack.unpackb(umsgpack.packb(big))["data"]["index"]["array"].data[-4:] == struct.pack(
        "<I", 69999
    )


def test_urdf_text_resolves_from_the_file_it_stands_for(tmp_path: Path) -> None:
    """URDF text (e.g. written back from a user's URDF) given with the file it stands for finds
    that file's relative meshes; without it, the current folder is the URDF's folder."""
    from cpc2urdf.urdf.pinocchio import PinocchioRobot
    from cpc2urdf.validation.view.view_robot import view_robot

    write_stl(tmp_path / "robot" / "meshes" / "a.stl")
    text = urdf_with_meshes(
        tmp_path / "robot" / "r.urdf", [("meshes/a.stl", "1 0 0 1")]
    ).read_text()
    robot = PinocchioRobot.from_urdf(text, path=tmp_path / "robot" / "r.urdf")
    assert (
        view_robot(robot).meshes.meshes[0].path
        == (tmp_path / "robot" / "meshes" / "a.stl").resolve()
    )
    with pytest.raises(UnresolvedMeshError, match="<URDF string>: link 'l0'"):
        view_robot(PinocchioRobot.from_urdf(text))
