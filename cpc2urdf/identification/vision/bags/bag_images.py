"""Image topics of a bag -> an images folder that ``cpc2urdf measure`` reads.

Each camera's images (``sensor_msgs/Image``, written losslessly as PNG, or
``sensor_msgs/CompressedImage``, written as the bytes the bag holds) go to ``<camera>/<record>``,
the paired joint readings to ``joints.csv`` (SI units) and the bag, topics, rule and skipped
samples to ``bag_provenance.json``. A sample needs an image of every camera. See ``docs/bags.md``.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from cpc2urdf.errors import ConfigurationError, InputFileError, OutputError
from cpc2urdf.files.jsonio import write_json
from cpc2urdf.files.spec import RobotSpec
from cpc2urdf.identification.vision.bags.bag_reader import (
    IMAGE_TYPES,
    JOINT_STATES_TOPIC,
    NS,
    open_bag,
    read_bag,
    short_type,
    stamp_ns,
)
from cpc2urdf.identification.vision.bags.bag_sync import (
    BagSamples,
    SyncRule,
    check_limits,
    check_topic_options,
    group_messages,
    joint_names_for,
    pair_samples,
    provenance,
    stamp_label,
)
from cpc2urdf.identification.vision.image_folders import write_image
from cpc2urdf.identification.vision.joints_csv import write_joints_csv

BAG_PROVENANCE = (
    "bag_provenance.json"  # in an images folder: the bag, topics, rule and skipped samples
)


@dataclass(frozen=True)
class ImageTopic:
    """Where a camera's images are in the bag: ``camera`` names the sub-folder (``left``,
    ``right``, or a head camera frame such as ``camera_left_optical``)."""

    camera: str
    topic: str

    @classmethod
    def parse(cls, text: str) -> ImageTopic:
        """``CAMERA=TOPIC``."""
        camera, sep, topic = text.partition("=")
        if not sep or not camera or not topic or "/" in camera or camera in (".", ".."):
            raise ConfigurationError(
                f"--image expects CAMERA=TOPIC (CAMERA a folder name: left, right or a "
                f"camera frame), got {text!r}"
            )
        return cls(camera, topic)


@dataclass
class BagImages:
    """What :func:`image_folder_from_bag` wrote: the folder, its records, and how they were paired."""

    folder: Path
    records: list[str]
    samples: BagSamples


# sensor_msgs/Image encodings we write losslessly: (channels, dtype, cv2 conversion to BGR or None).
ENCODINGS: dict[str, tuple[int, Any, int | None]] = {
    "mono8": (1, np.uint8, None),
    "8UC1": (1, np.uint8, None),
    "mono16": (1, np.uint16, None),
    "16UC1": (1, np.uint16, None),
    "bgr8": (3, np.uint8, None),
    "8UC3": (3, np.uint8, None),
    "rgb8": (3, np.uint8, cv2.COLOR_RGB2BGR),
    "bgra8": (4, np.uint8, None),
    "rgba8": (4, np.uint8, cv2.COLOR_RGBA2BGRA),
}
COMPRESSED = {"png": ".png", "jpeg": ".jpg", "jpg": ".jpg", "tiff": ".tif", "bmp": ".bmp"}


def image_from_msg(msg: Any, where: str, bag: Path) -> NDArray[Any]:
    """A ``sensor_msgs/Image`` as an array OpenCV writes (grey, BGR or BGRA)."""
    enc = str(msg.encoding)
    if enc not in ENCODINGS:
        raise InputFileError(
            bag,
            f"{where}: image encoding {enc!r} is not supported; expected one of "
            f"{', '.join(ENCODINGS)}",
        )
    ch, dtype, conv = ENCODINGS[enc]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    item = np.dtype(dtype).itemsize
    data = np.asarray(msg.data, dtype=np.uint8)
    if h <= 0 or w <= 0 or step < w * ch * item or data.size < h * step:
        raise InputFileError(
            bag, f"{where}: {data.size} bytes do not hold a {w} x {h} {enc} image with step {step}"
        )
    rows = data[: h * step].reshape(h, step)[:, : w * ch * item]
    img = (
        rows.copy()
        .view(np.dtype(dtype).newbyteorder(">" if msg.is_bigendian else "<"))
        .astype(dtype)
    )
    img = img.reshape(h, w, ch) if ch > 1 else img.reshape(h, w)
    if conv is not None:
        img = cv2.cvtColor(img, conv)
    return img


def compressed_suffix(msg: Any, where: str, bag: Path) -> str:
    # The format field is e.g. "png", "jpeg", or "bgr8; jpeg compressed bgr8" (image_transport).
    fmt = str(msg.format).lower()
    for key, suffix in COMPRESSED.items():
        if key in fmt:
            return suffix
    raise InputFileError(
        bag, f"{where}: compressed format {msg.format!r} is not one of {', '.join(COMPRESSED)}"
    )


@contextmanager
def new_folder(out: Path) -> Iterator[Path]:
    """A temporary folder next to ``out`` renamed to ``out`` on success, removed on failure."""
    if out.exists() and not (out.is_dir() and not any(out.iterdir())):
        raise OutputError(f"{out}: already exists; give a new (or empty) folder")
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir():
        raise OutputError(f"{out}: parent folder {parent} does not exist")
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=parent))
    try:
        yield tmp
        if out.exists():
            out.rmdir()
        os.replace(tmp, out)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


def image_folder_from_bag(
    bag: str | os.PathLike[str],
    robot: RobotSpec,
    images: Sequence[ImageTopic],
    out: str | os.PathLike[str],
    *,
    joint_topic: str = JOINT_STATES_TOPIC,
    rule: SyncRule | None = None,
) -> BagImages:
    """Write an images folder (``out/<camera>/<record>.<ext>`` and ``out/joints.csv``, SI units;
    ``out/bag_provenance.json``: the bag, topics, rule and skipped samples) from a bag's image
    topics and joint states; ``cpc2urdf measure`` reads it (``docs/images.md``).

    A sample needs an image of every camera; one without is skipped and listed. Raw images are
    written as PNG (lossless), compressed ones as the bytes the bag holds. The folder appears only
    when everything was written (nothing is left behind on an error).

    Raises:
        InputFileError: As :func:`measurements_from_bag`, plus an unsupported image encoding.
        OutputError: ``out`` exists and is not an empty folder, or its parent is missing.
    """
    rule = rule or SyncRule()
    path, out_p = Path(bag), Path(out)
    cams = [c.camera for c in images]
    check_topic_options(cams, "--image", "image", "camera", "CAMERA=TOPIC")
    topics = [c.topic for c in images]
    if len(set(topics)) != len(topics):
        raise ConfigurationError(
            f"--image: topic {next(t for t in topics if topics.count(t) > 1)!r} given for two cameras"
        )
    if out_p.exists() and not (out_p.is_dir() and not any(out_p.iterdir())):
        raise OutputError(f"{out_p}: already exists; give a new (or empty) folder")
    joints, kinds, model_names = joint_names_for(robot, [])
    by_topic: dict[str, list[str]] = {}
    for c in images:
        by_topic.setdefault(c.topic, []).append(c.camera)

    def read_one(
        topic: str, msgtype: str, msg: Any, t_bag: int, where: str
    ) -> list[tuple[int | None, str, Any]]:
        # Only the stamp now: the images are read again when they are written (a bag's images
        # need not fit in memory).
        t, stamped = stamp_ns(msg.header, t_bag)
        return [(t if stamped else None, cam, None) for cam in by_topic[topic]]

    sources = {c.topic: (f"images of {c.camera}", IMAGE_TYPES) for c in images}
    series, messages, n_bag_time = read_bag(path, joint_topic, joints, sources, read_one)
    groups = group_messages(messages, int(round(rule.sync_tolerance * NS)))
    incomplete = []
    complete, numbers = [], []  # the samples with every camera, and their numbers among all samples
    for gi, g in enumerate(groups):
        missing = [c for c in cams if c not in {m.key for m in g}]
        if missing:
            incomplete.append(
                f"sample {gi} ({stamp_label(g[0].t)}: {', '.join(m.where for m in g)}): no image of "
                f"{', '.join(missing)} within {rule.sync_tolerance:g} s"
            )
        else:
            complete.append(g)
            numbers.append(gi)
    stamps, q, skipped, kept = pair_samples(
        path, complete, series, kinds, rule, joint_topic, numbers
    )
    skipped = incomplete + skipped
    if not kept:
        raise InputFileError(
            path,
            f"no sample with every camera's image and the joints at rest ({len(groups)} "
            f"samples skipped; first: {skipped[0] if skipped else 'none'})",
        )
    samples = BagSamples(
        stamps, [stamp_label(t) for t in stamps], q, joints, skipped, n_bag_time, len(messages)
    )
    records = [f"{k:04d}" for k in range(len(kept))]
    s = robot.structure
    order = [joints.index(next(f for f, m in model_names.items() if m == n)) for n in s.joint_names]
    check_limits(
        path, s, q, order, joints, samples.labels
    )  # what `cpc2urdf measure` would refuse, before writing
    wanted = {
        (m.topic, m.index): (m.key, rec)
        for rec, gi in zip(records, kept, strict=True)
        for m in complete[gi]
    }
    with new_folder(out_p) as tmp:
        for cam in cams:
            (tmp / cam).mkdir()
        with open_bag(path) as reader:
            counts: dict[str, int] = {}
            for conn, _, raw in reader.messages(
                connections=[c for c in reader.connections if c.topic in by_topic]
            ):
                k = counts.get(conn.topic, 0)
                counts[conn.topic] = k + 1
                if (conn.topic, k) not in wanted:
                    continue
                where = f"{conn.topic} message {k}"
                msg = reader.deserialize(raw, conn.msgtype)
                cam, rec = wanted[(conn.topic, k)]
                if short_type(conn.msgtype) == "sensor_msgs/CompressedImage":
                    data = np.asarray(msg.data, dtype=np.uint8)
                    suffix = compressed_suffix(msg, where, path)
                    if data.size == 0 or cv2.imdecode(data, cv2.IMREAD_UNCHANGED) is None:
                        raise InputFileError(
                            path, f"{where}: the compressed image ({msg.format}) cannot be decoded"
                        )
                    (tmp / cam / f"{rec}{suffix}").write_bytes(data.tobytes())
                else:
                    write_image(tmp / cam / f"{rec}.png", image_from_msg(msg, where, path))
        write_joints_csv(
            tmp / "joints.csv", s, records, q[:, order], samples.labels, length="m", angle="rad"
        )
        write_json(
            tmp / BAG_PROVENANCE,
            provenance(
                path, joint_topic, rule, samples, {c.camera: c.topic for c in images}, "images"
            ),
        )
    return BagImages(out_p, records, samples)


__all__ = [
    "BAG_PROVENANCE",
    "BagImages",
    "ImageTopic",
    "compressed_suffix",
    "image_folder_from_bag",
    "image_from_msg",
]
