"""Camera frame conventions of a URDF link: optical (z forward) or body (x forward), REP-103.

ROS gives a camera two frames. The *body* link (REP-103 body convention: x forward, y left, z up)
is what the camera is mounted by; its *optical* child (z forward along the optical axis, x right,
y down) is what images, ``cv2.solvePnP`` and hand-eye calibration speak of. The optical frame sits
in the body frame at ``T_BODY_OPTICAL`` (rpy ``(-pi/2, 0, -pi/2)``, a 120 degree turn), usually
at the same origin. A URDF may have either or both.

:func:`camera_link` tells which a link is:

- **optical**: its name ends in ``_optical_frame`` or ``_optical``, or it hangs on a fixed joint
  whose rotation is REP-103's (the child of a body link);
- **body**: it has a child on a fixed joint whose rotation is REP-103's (its optical child), or
  the user says so (``convention="body"``; then the optical frame is at ``T_BODY_OPTICAL``);
- anything else is refused in one line naming the link and both conventions: nothing is turned
  silently. A stated convention that contradicts what the file shows is refused too.

Hand-eye calibration always solves ``X = T_hand_optical`` (PnP gives the target in the optical
frame). :meth:`CameraLink.link_pose` turns it into the pose of the link the user named, in that
link's own convention: ``T_hand_link = X @ inv(T_link_optical)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cpc2urdf.errors import InputFileError
from cpc2urdf.transforms import Array, inverse, rotation_error
from cpc2urdf.urdf.document import OPTICAL_SUFFIXES, T_BODY_OPTICAL
from cpc2urdf.urdf.tree import UrdfJoint, UrdfTree, link_error

OPTICAL = "optical"
BODY = "body"
CONVENTIONS = (OPTICAL, BODY)
# A fixed joint's rotation within this of REP-103's [rad] turns a body frame into an optical one
# (URDFs write pi/2 as 1.57079632679: 5e-12 off).
REP103_TOL = 1e-6
CONVENTION_WORDS = {
    OPTICAL: "optical (z forward, x right, y down)",
    BODY: "body (x forward, y left, z up)",
}


@dataclass(frozen=True)
class CameraLink:
    """A camera link of a URDF and its convention.

    Attributes:
        link: The link the user named.
        convention: :data:`OPTICAL` or :data:`BODY`.
        mount: The fixed joint carrying ``link`` (its origin is what calibration writes back).
        hand: The mount's parent link (hand-eye's hand: ``X = T_hand_optical``).
        optical: The optical frame's link: ``link`` itself, the body link's optical child, or
            None (a body link without one).
        T_link_optical: The optical frame in ``link``'s frame, shape (4, 4): the identity for an
            optical link, the optical child's origin, or :data:`T_BODY_OPTICAL`.
    """

    link: str
    convention: str
    mount: UrdfJoint
    hand: str
    optical: str | None
    T_link_optical: Array

    def link_pose(self, T_hand_optical: Array) -> Array:
        """``T_hand_link`` (the mount's origin, in the link's convention) from hand-eye's ``X``."""
        return np.asarray(T_hand_optical) @ inverse(self.T_link_optical)

    def optical_pose(self, T_hand_link: Array) -> Array:
        """``T_hand_optical`` from the link's pose in the hand frame."""
        return np.asarray(T_hand_link) @ self.T_link_optical

    @property
    def nominal_optical(self) -> Array:
        """``T_hand_optical`` as the URDF has it, shape (4, 4)."""
        return self.optical_pose(self.mount.origin)


def is_rep103_turn(T: Array) -> bool:
    """True if the rotation of ``T`` is REP-103's body-to-optical rotation (to :data:`REP103_TOL`)."""
    return bool(rotation_error(np.asarray(T)[:3, :3], T_BODY_OPTICAL[:3, :3]) < REP103_TOL)


def split_convention(name: str) -> tuple[str, str | None]:
    """``"LINK:body"`` -> ``("LINK", "body")``; ``"LINK"`` -> ``("LINK", None)``."""
    link, sep, word = name.rpartition(":")
    return (link, word) if sep and word in CONVENTIONS else (name, None)


def _refuse(tree: UrdfTree, link: str, why: str) -> InputFileError:
    return InputFileError(
        tree.source,
        f"camera link {link!r}: {why}; a camera link is {CONVENTION_WORDS[OPTICAL]} (a name ending "
        f"in _optical_frame/_optical, or a fixed child through rpy (-pi/2, 0, -pi/2)) or "
        f"{CONVENTION_WORDS[BODY]} (with such an optical child); name it {link}:optical or "
        f"{link}:body to say which",
    )


def camera_link(tree: UrdfTree, link: str, convention: str | None = None) -> CameraLink:
    """The convention of camera link ``link`` of ``tree`` (module docstring).

    Args:
        tree: The URDF.
        link: The camera link the user named.
        convention: What the user says it is (:data:`OPTICAL`, :data:`BODY`), or None to tell
            from the file.

    Raises:
        InputFileError: One line naming the URDF and the link: not a link, the root, moved by a
            joint directly (a camera hangs on a fixed joint), a convention that cannot be told or
            contradicts the file.
    """
    if convention is not None and convention not in CONVENTIONS:
        raise InputFileError(
            tree.source,
            f"camera link {link!r}: convention {convention!r} is not one of {CONVENTIONS}",
        )
    if not tree.has_link(link):
        raise link_error(tree, link, "a camera link")
    mount = tree.parent_joint(link)
    if mount is None:
        raise InputFileError(tree.source, f"camera link {link!r} is the root of the tree")
    if mount.type != "fixed":
        raise InputFileError(
            tree.source,
            f"camera link {link!r} is moved by joint {mount.name!r} ({mount.type}, line {mount.line}) "
            "directly; a camera link hangs on a fixed joint, whose origin calibration writes",
        )
    optical_children = [
        j for j in tree.children(link) if j.type == "fixed" and is_rep103_turn(j.origin)
    ]
    named_optical = link.endswith(OPTICAL_SUFFIXES)
    seen: str | None = None
    if named_optical or is_rep103_turn(mount.origin):
        seen = OPTICAL
    elif optical_children:
        seen = BODY
    if seen is not None and convention is not None and convention != seen:
        raise _refuse(tree, link, f"stated {convention}, but the file shows {seen}")
    found = seen or convention
    if found is None:
        raise _refuse(tree, link, "its convention cannot be told from the file")
    if found == OPTICAL:
        return CameraLink(link, OPTICAL, mount, mount.parent, link, np.eye(4))
    if len(optical_children) > 1:  # the one at the body's origin, if any
        at_origin = [j for j in optical_children if np.linalg.norm(j.origin[:3, 3]) < 1e-12]
        if not at_origin:
            names = [j.child for j in optical_children]
            raise InputFileError(
                tree.source,
                f"camera link {link!r} has several optical children {names}; name the one the images are from",
            )
        optical_children = at_origin[:1]
    if optical_children:
        child = optical_children[0]
        return CameraLink(link, BODY, mount, mount.parent, child.child, child.origin)
    return CameraLink(link, BODY, mount, mount.parent, None, T_BODY_OPTICAL.copy())


__all__ = [
    "BODY",
    "CONVENTIONS",
    "CONVENTION_WORDS",
    "OPTICAL",
    "REP103_TOL",
    "CameraLink",
    "camera_link",
    "is_rep103_turn",
    "split_convention",
]
