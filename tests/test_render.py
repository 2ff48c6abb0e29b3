"""The renderer: anti-aliased coverage is exact enough to test a sub-pixel detector against.

Checks: the grey-level centroid of a rendered circle is the centre of its exact image ellipse
(conic geometry, checked against an independent boundary-sampling computation), its coverage
area is the ellipse area, plates occlude in depth order, a plate seen from behind shows no
circles, and noise is seeded.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from cpc2urdf.identification.vision.plate_poses import ellipse_centre_offset
from cpc2urdf.identification.vision.render import (
    BACKGROUND_LEVEL,
    PLATE_BACK_LEVEL,
    PinholeView,
    render_view,
)
from cpc2urdf.identification.vision.targets import plate_design, target_design

GRID3 = (
    np.array(
        [
            [0, 0, 0],
            [-25, -25, 0],
            [0, -25, 0],
            [25, -25, 0],
            [-25, 0, 0],
            [25, 0, 0],
            [-25, 25, 0],
            [0, 25, 0],
            [25, 25, 0],
        ],
        dtype=float,
    )
    * 1e-3
)
K = np.array([[1600.0, 0.0, 319.5], [0.0, 1600.0, 239.5], [0.0, 0.0, 1.0]])


def _pose(rotvec: list[float], t: list[float]) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = t
    return T


def _facing(tilt_deg: float, spin_deg: float, t: list[float]) -> np.ndarray:
    """A plate facing the camera (its +z towards it), tilted about a random in-plane axis."""
    R = Rotation.from_euler("x", 180, degrees=True) * Rotation.from_euler(
        "zxz", [spin_deg, tilt_deg, 0], degrees=True
    )
    T = np.eye(4)
    T[:3, :3] = R.as_matrix()
    T[:3, 3] = t
    return T


def _centroid(
    img: np.ndarray, uv: np.ndarray, radius: float, level_bg: float
) -> tuple[np.ndarray, float]:
    R = int(math.ceil(radius)) + 3
    u0, v0 = int(round(uv[0])), int(round(uv[1]))
    win = img[v0 - R : v0 + R + 1, u0 - R : u0 + R + 1].astype(float)
    vv, uu = np.mgrid[v0 - R : v0 + R + 1, u0 - R : u0 + R + 1]
    w = level_bg - win
    w[np.hypot(uu - uv[0], vv - uv[1]) > R] = 0.0
    return np.array([(w * uu).sum(), (w * vv).sum()]) / w.sum(), float(w.sum())


def _ellipse_centre_by_sampling(T_cp: np.ndarray, c: np.ndarray, r: float) -> np.ndarray:
    # Independent of the conic algebra: the extreme points of the projected boundary along u
    # (and v) are symmetric about the ellipse centre.
    a = np.linspace(0, 2 * np.pi, 400001)
    p = np.stack([c[0] + r * np.cos(a), c[1] + r * np.sin(a), np.zeros_like(a)], axis=1)
    pc = p @ T_cp[:3, :3].T + T_cp[:3, 3]
    uv = (pc[:, :2] / pc[:, 2:3]) * [K[0, 0], K[1, 1]] + [K[0, 2], K[1, 2]]
    return np.array([(uv[:, 0].max() + uv[:, 0].min()) / 2, (uv[:, 1].max() + uv[:, 1].min()) / 2])


def test_ellipse_offset_matches_boundary_sampling() -> None:
    design = plate_design("p", GRID3, marker_index=1)
    T = _facing(40.0, 25.0, [0.05, -0.03, 1.0])
    off = ellipse_centre_offset(K, T, design)
    for i in (0, 1, 8):
        c, r = design.layout[i], design.radii[i]
        p = T[:3, :3] @ c + T[:3, 3]
        proj = K[:2, :2] @ (p[:2] / p[2]) + K[:2, 2]
        np.testing.assert_allclose(off[i], _ellipse_centre_by_sampling(T, c, r) - proj, atol=2e-5)
    assert np.all(np.linalg.norm(off, axis=1) > 1e-3)  # the bias is real at this tilt


def test_rendered_centroid_is_the_ellipse_centre_and_area_is_covered() -> None:
    design = plate_design("p", GRID3, marker_index=1, margin=0.02)  # window clear of the plate edge
    view = PinholeView(K, np.zeros(5), (640, 480))
    rng = np.random.default_rng(0)
    errs, area_err = [], []
    for _ in range(3):
        T = _facing(
            rng.uniform(0, 55),
            rng.uniform(0, 360),
            [rng.uniform(-0.02, 0.02), rng.uniform(-0.02, 0.02), 0.8],
        )
        img = render_view(view, [(design, T)], supersample=8)
        off = ellipse_centre_offset(K, T, design)
        H = K @ np.column_stack([T[:3, 0], T[:3, 1], T[:3, 3]])
        for i, (c, r) in enumerate(zip(design.layout, design.radii, strict=True)):
            p = H @ np.array([c[0], c[1], 1.0])
            centre = p[:2] / p[2] + off[i]
            got, mass = _centroid(img, centre, r * 1600 / 0.8, 0.9 * 255)
            errs.append(np.linalg.norm(got - centre))
            # Coverage area: the ellipse's area is pi r^2 |det J| (up to 2nd order).
            w = H[2] @ np.array([c[0], c[1], 1.0])
            area = math.pi * r * r * abs(np.linalg.det(H)) / w**3
            area_err.append(mass / ((0.9 - 0.08) * 255) / area - 1)
    assert max(errs) < 0.015, max(errs)  # [px]: 8-bit quantisation and 8x8 supersampling
    assert max(abs(a) for a in area_err) < 0.01


def test_occlusion_back_face_and_clipping() -> None:
    design = plate_design("p", GRID3, marker_index=1)
    view = PinholeView(K, np.zeros(5), (640, 480))
    front = _facing(0.0, 0.0, [0.0, 0.0, 0.8])
    back = front @ _pose([np.pi, 0, 0], [0, 0, 0])  # turned round: printed face away
    img_back = render_view(view, [(design, back)])
    centre = img_back[230:250, 310:330]
    assert np.all(centre == round(PLATE_BACK_LEVEL * 255))
    img_front = render_view(view, [(design, front)])
    assert img_front[240, 320] < 40  # the central circle
    # A nearer plate hides a farther one, whatever order they are given in.
    near = _facing(0.0, 0.0, [0.0, 0.0, 0.5])
    a = render_view(view, [(design, near), (design, front)])
    b = render_view(view, [(design, front), (design, near)])
    assert np.array_equal(a, b)
    # Behind the camera: nothing drawn.
    behind = _facing(0.0, 0.0, [0.0, 0.0, -0.8])
    assert np.all(render_view(view, [(design, behind)]) == round(BACKGROUND_LEVEL * 255))


def test_noise_blur_distortion_and_target() -> None:
    design = target_design()  # stage 2's 5 x 5 disks, 40 mm pitch
    assert design.dot_level > design.plate_level and design.radii[0] > design.radii[1]
    D = np.array([-0.2, 0.1, 0.0, 0.0, 0.0])
    view = PinholeView(K, D, (640, 480))
    T = _facing(20.0, 10.0, [0.0, 0.0, 0.8])
    a = render_view(
        view, [(design, T)], blur_sigma=0.8, noise_sigma=2.0, rng=np.random.default_rng(0)
    )
    b = render_view(
        view, [(design, T)], blur_sigma=0.8, noise_sigma=2.0, rng=np.random.default_rng(0)
    )
    c = render_view(view, [(design, T)], blur_sigma=0.8)
    assert np.array_equal(a, b)
    resid = a.astype(float) - c
    assert abs(resid.std() - 2.0) < 0.5  # the requested noise of 2 grey levels
    # The centre disk lands where cv2.projectPoints (with distortion) puts it.
    uv = view.project((T[:3, :3] @ design.layout[12] + T[:3, 3])[None])[0]
    assert c[int(round(uv[1])), int(round(uv[0]))] > 200
