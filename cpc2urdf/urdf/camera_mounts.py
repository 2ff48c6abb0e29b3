"""Camera links placed by hand-eye calibration, written back into the user's URDF.

Hand-eye calibration gives ``X = T_hand_optical`` per camera (the hand: the parent link of the
camera link's fixed mount joint). :func:`write_camera_mounts` writes each camera link's mount
origin into a copy of the URDF, in the convention of the link the user named
(:mod:`cpc2urdf.urdf.camera_frames`: ``T_hand_link = X @ inv(T_link_optical)``, so an x-forward
link stays x-forward), through the one write-back of :mod:`cpc2urdf.urdf.writeback`: only those
``<origin>`` tags change, a calibration report goes next to the file.

:func:`with_camera_links` is the model side: a model built from a URDF (the URDF itself, or one
identified from measurements of it) with camera link frames (kind ``camera``) where calibration
puts them; ``cpc2urdf export`` writes such a model back the same way.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from cpc2urdf.errors import InputFileError, SpecError
from cpc2urdf.model import BASE, CPCModel, CPCParams, Frame
from cpc2urdf.transforms import Array, homogeneous, inverse
from cpc2urdf.urdf.camera_frames import CameraLink, camera_link, split_convention
from cpc2urdf.urdf.robot import NameMap, UrdfSource, urdf_robot, urdf_source, with_urdf_source
from cpc2urdf.urdf.tree import UrdfTree, read_urdf_tree
from cpc2urdf.urdf.writeback import write_calibrated_urdf


def link_placement(model: CPCModel, tree: UrdfTree, link: str) -> tuple[str, Array]:
    """Where ``model`` (built from ``tree``) puts URDF link ``link``: the model joint whose link
    frame carries it (or ``base``) and its pose there, shape (4, 4). Moving joints are the
    model's; fixed joints keep the file's origins, except those carrying a model frame (as the
    write-back does, :mod:`cpc2urdf.urdf.origins`).

    Raises:
        SpecError: The model was not built from a URDF.
        InputFileError: A moving joint on the path to ``link`` is not a joint of the model.
    """
    source = _source(model)
    cpc_of_joint = {u: c for c, u in source.joints.items()}
    frame_of_link = {source.urdf_link(f): f for f in model.structure.frame_names}
    K, T = BASE, np.eye(4)
    for j in tree.path(link):
        if j.moving:
            cpc = cpc_of_joint.get(j.name)
            if cpc is None:
                raise InputFileError(
                    tree.source,
                    f"joint {j.name!r} ({j.type}, line {j.line}) on the path to link {link!r} is not a "
                    f"joint of model {model.structure.name!r}; calibrate with the URDF itself",
                )
            K, T = cpc, homogeneous(source.axis_rotation(cpc).T, np.zeros(3))
        elif j.child in frame_of_link and model.structure.frame(frame_of_link[j.child]).parent == K:
            T = model.frames[frame_of_link[j.child]].matrix()
        else:
            T = T @ j.origin
    return K, T


def _source(model: CPCModel) -> UrdfSource:
    source = urdf_source(model)
    if source is None:
        raise SpecError(
            f"model {model.structure.name!r} was not built from a URDF (it has no 'urdf' section)"
        )
    return source


def frame_name(model: CPCModel, tree: UrdfTree, link: str) -> str:
    """The model's frame name of URDF link ``link`` (its own, or the URDF's name mapping)."""
    source = _source(model)
    known = {u: c for c, u in source.frames.items()}
    return known.get(link) or NameMap.of(tree).links[link]


def with_camera_links(model: CPCModel, tree: UrdfTree, mounts: Mapping[str, Array]) -> CPCModel:
    """``model`` (built from ``tree``) with each camera link ``link`` a frame of kind ``camera``
    at ``mounts[link] = T_hand_link`` (its mount origin, in the link's own convention).

    Raises:
        SpecError: The model was not built from a URDF.
        InputFileError: A camera link that does not hang on a fixed joint; a joint on its path
            the model lacks.
    """
    out = model
    for link, T_hand_link in mounts.items():
        mount = tree.parent_joint(link)
        if mount is None or mount.type != "fixed":
            raise InputFileError(
                tree.source, f"camera link {link!r} does not hang on a fixed joint"
            )
        K, T_K_hand = link_placement(out, tree, mount.parent)
        name = frame_name(out, tree, link)
        out = out.with_frame(
            Frame(name, K, "camera"), CPCParams.from_matrix(T_K_hand @ np.asarray(T_hand_link))
        )
        source = _source(out)
        path = {j.name: j.kinematics() for j in tree.path(link)}
        out = with_urdf_source(
            out,
            dataclasses.replace(
                source,
                frames={**source.frames, name: link},
                kinematics={**source.kinematics, **path},
            ),
        )
    return out


def camera_links(tree: UrdfTree, links: Mapping[str, str | None]) -> dict[str, CameraLink]:
    """:func:`~cpc2urdf.urdf.camera_frames.camera_link` of each ``{link: stated convention or None}``."""
    return {link: camera_link(tree, link, convention) for link, convention in links.items()}


def optical_frames_model(
    tree: UrdfTree, cameras: Sequence[str], holding: str | None = None
) -> tuple[CPCModel, dict[str, CameraLink]]:
    """The URDF's sub-tree on the paths to ``cameras`` (link names, ``LINK:optical``/``LINK:body``
    where the file cannot tell) and to the link ``holding`` a board, for a fit on pixels: each
    camera link a frame of kind ``camera`` at its OPTICAL pose (named as the link's frame), the
    holding link a measured frame where the URDF puts it. :func:`in_link_conventions` turns the
    camera frames back into their links' conventions for the write-back.

    Raises:
        InputFileError: A camera link the URDF cannot carry or whose convention cannot be told; a
            holding link that is not a link of the URDF (:func:`urdf_robot`'s refusal).
    """
    cams = camera_links(tree, dict(split_convention(c) for c in cameras))
    model = urdf_robot(tree, [*cams, *([holding] if holding else [])]).nominal
    assert model is not None
    for link, cam in cams.items():
        K, T_K_link = link_placement(model, tree, link)
        model = model.with_frame(
            Frame(frame_name(model, tree, link), K, "camera"),
            CPCParams.from_matrix(T_K_link @ cam.T_link_optical),
        )
    return model, cams


def in_link_conventions(
    model: CPCModel, tree: UrdfTree, cams: Mapping[str, CameraLink]
) -> CPCModel:
    """``model`` of :func:`optical_frames_model` with each camera frame at its link's own pose
    (an x-forward link stays x-forward when written back)."""
    out = model
    for link, cam in cams.items():
        name = frame_name(model, tree, link)
        T = model.frames[name].matrix() @ inverse(cam.T_link_optical)
        out = out.with_frame(model.structure.frame(name), CPCParams.from_matrix(T))
    return out


def write_camera_mounts(
    urdf: str | os.PathLike[str],
    mounts: Mapping[str, Array],
    path: str | os.PathLike[str],
    *,
    conventions: Mapping[str, str] | None = None,
) -> Path:
    """Write ``urdf`` as ``path`` with each camera link's mount origin from hand-eye calibration.

    Args:
        urdf: The user's URDF.
        mounts: Camera link (the user's name, either convention) -> ``X = T_hand_optical``, the
            camera's optical frame in the mount's parent link, shape (4, 4) [m].
        path: The calibrated URDF (its report goes next to it, ``docs/urdf.md``).
        conventions: Stated conventions of links the file cannot tell (``optical``/``body``).

    Returns:
        ``path``. Only the mounts' ``<origin>`` tags differ from ``urdf``; an x-forward link's
        origin keeps x forward.

    Raises:
        InputFileError: One line naming the URDF and the link (see
            :func:`~cpc2urdf.urdf.camera_frames.camera_link`); nothing is written.
    """
    tree = read_urdf_tree(urdf)
    stated = conventions or {}
    cams = camera_links(tree, {link: stated.get(link) for link in mounts})
    model = urdf_robot(tree, list(mounts)).nominal
    assert model is not None
    placed = {link: cams[link].link_pose(np.asarray(X)) for link, X in mounts.items()}
    return write_calibrated_urdf(with_camera_links(model, tree, placed), path)


__all__ = [
    "camera_links",
    "frame_name",
    "in_link_conventions",
    "link_placement",
    "optical_frames_model",
    "with_camera_links",
    "write_camera_mounts",
]
