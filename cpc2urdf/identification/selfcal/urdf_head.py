"""One-stage calibration of a URDF robot's head: its camera links, a board fixed or held.

:func:`calibrate_urdf_head` reads the images (:mod:`images`), builds the user's model of the
sub-tree on the paths to the camera links and, for a held board, to the link holding it
(:func:`~cpc2urdf.urdf.camera_mounts.optical_frames_model`), calibrates it on pixels
(:mod:`calibrate`) and returns the model ready for ``cpc2urdf export``: every joint on those paths
and every camera link's mount, each camera link in its own convention (an x-forward link stays x
forward, REP-103). The held board's placement on its link and the board's pose in the base
(fixed) are in the provenance.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Mapping, Sequence

import numpy as np

from cpc2urdf.errors import ConfigurationError
from cpc2urdf.identification.kinematics.parametrization import Parametrization
from cpc2urdf.identification.selfcal.calibrate import HeadCalibration, calibrate_head
from cpc2urdf.identification.selfcal.images import folder_board, folder_cameras, read_pixel_data
from cpc2urdf.identification.vision.boards.board import Board
from cpc2urdf.model import CPCModel, CPCParams, Frame
from cpc2urdf.model_metadata import Covariance
from cpc2urdf.transforms import inverse
from cpc2urdf.urdf.camera_frames import CameraLink, split_convention
from cpc2urdf.urdf.camera_mounts import (
    frame_name,
    in_link_conventions,
    link_placement,
    optical_frames_model,
)
from cpc2urdf.urdf.robot import NameMap
from cpc2urdf.urdf.tree import UrdfTree, read_urdf_tree

BOARD_FRAME = "board"
CARRY_STEP = 1e-6  # [m] or [rad] per chart coordinate


def head_model(
    tree: UrdfTree, cameras: Sequence[str], board_link: str | None
) -> tuple[CPCModel, list[str], dict[str, CameraLink]]:
    """The user's model for a pixel fit: camera frames (optical) and, when held, a ``board``
    frame at ``board_link``; the camera frames' names; the camera links."""
    links = [split_convention(c)[0] for c in cameras]
    twice = sorted({c for c in links if links.count(c) > 1})
    if twice:
        raise ConfigurationError(f"camera link {twice[0]!r} is given twice")
    model, cams = optical_frames_model(tree, cameras, board_link)
    if board_link is not None:
        K, T = link_placement(model, tree, board_link)
        model = model.with_frame(Frame(BOARD_FRAME, K, "frame"), CPCParams.from_matrix(T))
    return model, [frame_name(model, tree, link) for link in cams], dict(cams)


def calibrate_urdf_head(
    images_dir: str | os.PathLike[str],
    urdf: str | os.PathLike[str],
    cameras: Sequence[str],
    *,
    board: Board | str | os.PathLike[str] | None = None,
    board_link: str | None = None,
    intrinsics_files: Mapping[str, str | os.PathLike[str]] | None = None,
    intrinsics: bool = False,
    accept_inconsistent: bool = False,
    on_error: str = "skip",
    show_progress: bool = False,
) -> tuple[CPCModel, HeadCalibration]:
    """Calibrate ``urdf``'s head from ``images_dir`` (module docstring).

    Args:
        images_dir: ``<camera link>/<record>.png``, ``<camera link>.yaml``, ``joints.csv``
            (columns: the URDF's joint names), ``board.json`` (:mod:`images`).
        urdf: The user's URDF.
        cameras: Camera link names (``LINK:optical``/``LINK:body`` where the file cannot tell).
        board: The board, or its file (default: the folder's ``board.json``).
        board_link: The link holding the board (None: the board is fixed in the world).
        intrinsics_files: Camera link -> intrinsics file (default: ``<camera link>.yaml``).
        intrinsics: Refine the intrinsics too.
        accept_inconsistent: Keep a model the gate refuses, the reason in its notes.
        on_error: An unreadable image: ``"skip"`` it or ``"stop"``.
        show_progress: Progress bar on stderr.

    Returns:
        The model for ``export`` (camera links in their conventions) and the calibration.
    """
    from cpc2urdf.identification.vision.joints_csv import urdf_joint_columns

    tree = read_urdf_tree(urdf)
    model, frames, cams = head_model(tree, cameras, board_link)
    data = read_pixel_data(
        images_dir,
        model.structure,
        folder_cameras(images_dir, list(cams), intrinsics_files),
        folder_board(images_dir, board),
        board_frame=BOARD_FRAME if board_link else None,
        on_error=on_error,
        show_progress=show_progress,
        joint_aliases=urdf_joint_columns(model),
        frame_of=dict(zip(cams, frames, strict=True)),
        other_joints={*tree.joints, *NameMap.of(tree).joints.values()},
    )
    cal = calibrate_head(
        model, data, intrinsics=intrinsics, accept_inconsistent=accept_inconsistent
    )
    out = cal.model
    prov = out.metadata.provenance
    assert prov is not None
    if board_link is not None:
        _, T_K_link = link_placement(model, tree, board_link)
        T = inverse(T_K_link) @ out.frames[BOARD_FRAME].matrix()
        placed = {f"T_{board_link}_board": T.tolist()}
    else:
        placed = {"T_base_board": inverse(out.T_world_base()).tolist()}

    def for_export(m: CPCModel) -> CPCModel:
        return in_link_conventions(m.without_frames(["frame"]), tree, cams)

    exported = for_export(out)
    noise = {cam: cal.fit.sigma[f] for f, cam in zip(frames, cams, strict=True)}
    meta = exported.metadata.replace(
        provenance=prov.with_details(**placed, pixel_noise_px=noise, images_dir=str(images_dir)),
        uncertainty=_carried(cal, exported, for_export),
    )
    return exported.with_params(metadata=meta), cal


def _carried(
    cal: HeadCalibration, out: CPCModel, convert: Callable[[CPCModel], CPCModel]
) -> Covariance:
    """The fit's covariance in the chart of ``out = convert(fit model)``: camera links in their
    conventions, a held board's placement dropped (marginalised), the holding link a measured
    frame where the URDF puts it. ``C' = G C G^T`` with ``G`` by central differences."""
    fit = cal.fit
    cov = cal.model.metadata.uncertainty
    assert cov is not None
    chart = Parametrization(out, list(out.structure.frame_names))
    P = fit.chart.n_params
    G = np.zeros((chart.n_params, P))
    for k in range(P):
        x = np.zeros(P)
        x[k] = CARRY_STEP
        plus = chart.vector_from_model(convert(fit.chart.model_from_vector(x)))
        minus = chart.vector_from_model(convert(fit.chart.model_from_vector(-x)))
        G[:, k] = (plus - minus) / (2.0 * CARRY_STEP)
    N = G @ cov.null_space
    N = N[:, np.linalg.norm(N, axis=0) > 1e-9]
    C = G @ cov.matrix @ G.T
    return dataclasses.replace(
        cov,
        names=tuple(chart.names),
        units=tuple(chart.units),
        frames=tuple(chart.frames),
        matrix=0.5 * (C + C.T),
        null_space=N / np.linalg.norm(N, axis=0) if N.size else np.zeros((chart.n_params, 0)),
    )


__all__ = ["BOARD_FRAME", "calibrate_urdf_head", "head_model"]
