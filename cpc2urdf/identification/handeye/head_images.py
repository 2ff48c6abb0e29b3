"""Stage 2 from images: head-camera target poses + the identified model -> hand-eye input.

:func:`~cpc2urdf.identification.vision.measure_head.measure_head_images` measures
``T_camera_target`` per camera and record. Paired with ``T_base_hand`` from the identified
kinematic model at the records' joint readings, these are the absolute poses of hand-eye
calibration (:mod:`cpc2urdf.identification.handeye.axxb`):

- :func:`write_handeye_files` writes one ``cpc2urdf/handeye-poses@1`` file per camera, the input
  of ``cpc2urdf handeye``;
- :func:`stage2_observations` gives the records every camera measured as
  :class:`~cpc2urdf.identification.handeye.stage2.Stage2Observations`, for
  :func:`~cpc2urdf.identification.handeye.stage2.calibrate_cameras`.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from cpc2urdf.errors import ConfigurationError, DegenerateDataError, OutputError
from cpc2urdf.files.units import Units
from cpc2urdf.identification.handeye.pose_file import save_handeye_poses
from cpc2urdf.identification.handeye.stage2 import (
    HAND_OF_CAMERA,
    CameraIntrinsics,
    Stage2Observations,
)
from cpc2urdf.identification.vision.measure_head import HeadCamera, HeadImageMeasurement
from cpc2urdf.model import CPCModel
from cpc2urdf.transforms import inverse


def stage2_observations(
    result: HeadImageMeasurement, cameras: Mapping[str, HeadCamera]
) -> Stage2Observations:
    """The records every camera measured, as :class:`~cpc2urdf.identification.handeye.stage2.Stage2Observations`
    (for :func:`~cpc2urdf.identification.handeye.stage2.calibrate_cameras`, which puts the cameras
    into the model). ``T_base_target`` is unknown from images and left as NaN; ``image_points``
    empty.

    Raises:
        DegenerateDataError: Fewer than 3 records seen by every camera.
    """
    names = list(result.T_camera_target)
    common = [lab for lab in result.labels[names[0]] if all(lab in result.labels[c] for c in names)]
    if len(common) < 3:
        raise DegenerateDataError(
            f"only {len(common)} records were measured by every camera ({', '.join(names)}); need 3"
        )
    idx = {c: [result.labels[c].index(lab) for lab in common] for c in names}
    cam = cameras[names[0]]
    intr = CameraIntrinsics(
        float(cam.K[0, 0]),
        float(cam.K[1, 1]),
        float(cam.K[0, 2]),
        float(cam.K[1, 2]),
        int(cam.image_size[0]),
        int(cam.image_size[1]),
        tuple(float(v) for v in cam.D),
    )
    return Stage2Observations(
        result.q[names[0]][idx[names[0]]],
        {c: result.T_camera_target[c][idx[c]] for c in names},
        {},
        intr,
        float("nan"),
        np.full((4, 4), np.nan),
    )


def write_handeye_files(
    result: HeadImageMeasurement,
    model: CPCModel,
    folder: str | Path,
    *,
    hands: Mapping[str, str] | None = None,
) -> dict[str, Path]:
    """One ``cpc2urdf/handeye-poses@1`` file per camera (``handeye_<camera>.json``, mm/deg), with
    ``T_base_hand`` of the camera's hand frame from ``model`` at the records' readings."""
    hands = dict(hands or HAND_OF_CAMERA)
    out_dir = Path(folder)
    if not out_dir.is_dir():
        raise OutputError(f"{out_dir}: output folder does not exist")
    paths = {}
    for c, C in result.T_camera_target.items():
        if c not in hands:
            raise ConfigurationError(
                f"no hand frame known for camera {c!r}; known: {sorted(hands)}"
            )
        hand = hands[c]
        model.structure.frame(hand)
        T_base_hand = inverse(model.T_world_base())[None] @ model.fk_frame(hand, result.q[c])
        paths[c] = save_handeye_poses(
            out_dir / f"handeye_{c}.json",
            T_base_hand,
            C,
            labels=result.labels[c],
            camera=c,
            hand=hand,
            units=Units("mm", "deg"),
            description=f"stage-2 target poses from images ({len(C)} records), hand poses from the identified model",
        )
    return paths


__all__ = ["stage2_observations", "write_handeye_files"]
