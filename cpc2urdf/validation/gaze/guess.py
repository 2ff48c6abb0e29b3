"""The gaze solver's starting point: a grid of cyclopean rays over the neck readings.

The table (prismatic joints shared by both cameras) stays at its reading. The neck (revolute
joints shared by both cameras) comes from a grid computed once from the model: the entry whose
cyclopean ray (midpoint of the camera centres, along the sum of the optical axes) best faces the
target, refined to first order in pan and tilt (2 x 2 normal equations on precomputed ray
derivatives); the eyes converge symmetrically by ``asin(baseline / 2 / distance)``. Further
entries, with the eyes already turned, are the retries' starts.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from cpc2urdf.transforms import Array
from cpc2urdf.validation.gaze.head import GazeHead

GUESS_MAX_CORRECTION = 0.2  # [rad]: largest first-order correction of the grid's neck readings
GRID_POINTS = (37, 13)  # interior grid points of the first neck joint, and of every other one
VERSIONS = (0.0, -0.3, 0.3, -0.6, 0.6)  # [rad]: eye turns of the grid (version 0 first)


class GuessTable:
    """Cyclopean rays over a grid of neck readings, in the frame of the last table link.

    The table only translates the head, so rays expressed in the table link frame do not
    depend on the table readings.

    Args:
        head: The head.
        converge_sign: +1 if turning the left eye by ``-h`` and the right one by
            ``version_sign * h`` (``h > 0``) converges the eyes, else -1
            (:func:`cpc2urdf.validation.gaze.fixation.fixation_redundancy`).
    """

    def __init__(self, head: GazeHead, converge_sign: float) -> None:
        self.head = head
        self.converge_sign = converge_sign
        # interior grid points only: a start on a limit would hold that joint from the outset
        grids = [
            np.linspace(head.lower[i], head.upper[i], (GRID_POINTS[0] if k == 0 else GRID_POINTS[1]) + 2)[1:-1]
            for k, i in enumerate(head.neck)
        ]
        if grids:
            mesh = np.stack(np.meshgrid(*grids, indexing="ij"), -1).reshape(-1, len(grids))
        else:
            mesh = np.zeros((1, 0))
        origins, dirs, qs = [], [], []
        e0, e1 = head.e0, head.e1
        # version 0 first (the default starts), then turned eyes (retries near the neck limits)
        rows = [(row, v) for v in VERSIONS for row in mesh]
        self.n_version0 = len(mesh)
        for row, v in rows:
            q = head.home.copy()
            q[head.neck] = row
            q[e0] = np.clip(head.home[e0] + v, head.lower[e0], head.upper[e0])
            q[e1] = np.clip(head.home[e1] + head.version_sign * v, head.lower[e1], head.upper[e1])
            c, d = head.cyclopean_ray(q)
            origins.append(c)
            dirs.append(d)
            qs.append(q)
        # Derivatives of the version-0 rays by the neck readings (central differences), for the
        # first-order refinement of the best grid entry in guess: columns per neck joint.
        h = 1e-6
        dc_rows, dd_rows = [], []
        for q in qs[: self.n_version0]:
            dc, dd = [], []
            for i in head.neck:
                qp, qm = q.copy(), q.copy()
                qp[i] += h
                qm[i] -= h
                (cp, dp), (cm, dm) = head.cyclopean_ray(qp), head.cyclopean_ray(qm)
                dc.append(((cp - cm) / (2 * h)).tolist())
                dd.append(((dp - dm) / (2 * h)).tolist())
            dc_rows.append(dc)
            dd_rows.append(dd)
        self._dc: list[list[list[float]]] = dc_rows
        self._dd: list[list[list[float]]] = dd_rows
        self._dir_list: list[list[float]] = [d.tolist() for d in dirs]
        self._origin = np.array(origins)
        self._dir = np.array(dirs)
        self._q = np.array(qs)
        # per-grid constants of guess
        self._od = np.einsum("ij,ij->i", self._origin, self._dir)
        self._oo = np.einsum("ij,ij->i", self._origin, self._origin)
        self._origin_list: list[list[float]] = self._origin.tolist()
        m = self.n_version0
        self._affine = np.ascontiguousarray(
            np.vstack([
                np.hstack([self._dir[:m], -self._od[:m, None]]),  # v.d
                np.hstack([-2.0 * self._origin[:m], self._oo[:m, None]]),  # |v|^2 - |p_t|^2
            ])
        )
        self._table_key: bytes | None = None
        self._table_pose: Any = None  # pinocchio.SE3 of the last table link, for _table_key

    def guess(self, p: Array, q: Array, rank: int = 0, *, refine: bool = True) -> Array:
        """A start for target ``p`` (world) [m], shape (3,), keeping the table of ``q`` (shape (n,)).

        ``rank`` 0 is the version-0 grid entry whose cyclopean ray best faces ``p``, its neck
        readings refined to first order (``refine``, two neck joints) and the eyes converged on
        the target; ``rank`` k >= 1 is the k-th best entry of the whole grid (eyes turned too).
        """
        head = self.head
        if head.table_link:
            key = q[head.table_chain].tobytes()
            if key != self._table_key:  # the table link pose depends only on the joints up to it
                head.pin.forwardKinematics(head.model, head.data, q)
                self._table_pose = head.data.oMi[head.table_link].copy()
                self._table_key = key
            p_t = self._table_pose.actInv(p)
        else:
            p_t = p
        # cos of the angle between each ray (origin o, unit direction d) and v = p_t - o, from
        # per-grid constants: v.d = p_t.d - o.d and |v|^2 = |p_t|^2 - 2 o.p_t + |o|^2
        px, py, pz = p_t.tolist()
        pp = px * px + py * py + pz * pz
        if rank == 0:
            # one matrix-vector product gives v.d and |v|^2 - |p_t|^2 for every version-0 entry;
            # the best ray has the largest cos|cos| = (v.d)|v.d| / |v|^2
            y = self._affine @ np.array([px, py, pz, 1.0])
            m = self.n_version0
            vd = y[:m]
            k = int(np.argmax(vd * np.abs(vd) / np.maximum(y[m:] + pp, 1e-24)))
        else:
            vd = self._dir @ p_t - self._od
            vv = self._oo - 2.0 * (self._origin @ p_t) + pp
            k = int(np.argsort(-(vd / np.sqrt(np.maximum(vv, 1e-24))))[rank - 1])
        best = self._q[k]
        out = q.copy()
        out[head.neck] = best[head.neck]
        out[head.eyes_all] = best[head.eyes_all]
        if rank == 0:
            ox, oy, oz = self._origin_list[k]
            vx, vy, vz = px - ox, py - oy, pz - oz
            dist = math.sqrt(vx * vx + vy * vy + vz * vz)
            if refine and len(head.neck) == 2 and dist > 1e-9:
                dist = self._refine(k, out, vx, vy, vz, dist)
            # converge the eyes symmetrically on the target's distance along the ray
            h = math.asin(min(1.0, 0.5 * head.baseline / max(dist, 1e-9))) * self.converge_sign
            e0, e1 = head.e0, head.e1
            lo, hi = head.lower_list, head.upper_list
            out[e0] = min(max(out[e0] - h, lo[e0]), hi[e0])
            out[e1] = min(max(out[e1] + head.version_sign * h, lo[e1]), hi[e1])
        return out

    def _refine(self, k: int, out: Array, vx: float, vy: float, vz: float, dist: float) -> float:
        """First-order refinement of grid entry ``k``'s two neck readings in ``out`` (in place);
        ``(vx, vy, vz)`` is the target from the ray's origin (table link frame) [m], ``dist`` its
        length. Returns the target's distance from the refined ray's origin [m]."""
        head = self.head
        # Turn the ray (origin c, direction d, both moving with the neck) onto the target
        # direction t. With t' = -(I - t t^T) c' / dist, solve (d' - t') delta = t - d in least
        # squares (2 x 2 normal equations; d - t is nearly perpendicular to d, so 2 conditions).
        tx, ty, tz = vx / dist, vy / dist, vz / dist
        dx, dy, dz = self._dir_list[k]
        cols = []
        for (cx, cy, cz), (ax, ay, az) in zip(self._dc[k], self._dd[k], strict=True):
            tc = tx * cx + ty * cy + tz * cz
            cols.append((ax + (cx - tc * tx) / dist, ay + (cy - tc * ty) / dist, az + (cz - tc * tz) / dist))
        (a0, a1, a2), (b0, b1, b2) = cols
        ex, ey, ez = tx - dx, ty - dy, tz - dz
        m00 = a0 * a0 + a1 * a1 + a2 * a2
        m01 = a0 * b0 + a1 * b1 + a2 * b2
        m11 = b0 * b0 + b1 * b1 + b2 * b2
        g0 = a0 * ex + a1 * ey + a2 * ez
        g1 = b0 * ex + b1 * ey + b2 * ez
        det = m00 * m11 - m01 * m01
        if det > 1e-12 * m00 * m11:
            d0 = (m11 * g0 - m01 * g1) / det
            d1 = (m00 * g1 - m01 * g0) / det
            i0, i1 = int(head.neck[0]), int(head.neck[1])
            n0, n1 = float(out[i0]) + d0, float(out[i1]) + d1
            # only a small correction, strictly inside the limits (a start on a limit would hold
            # that joint from the outset); else keep the grid entry
            if (
                abs(d0) < GUESS_MAX_CORRECTION
                and abs(d1) < GUESS_MAX_CORRECTION
                and head.lower_list[i0] < n0 < head.upper_list[i0]
                and head.lower_list[i1] < n1 < head.upper_list[i1]
            ):
                out[i0], out[i1] = n0, n1
                (c0x, c0y, c0z), (c1x, c1y, c1z) = self._dc[k]
                vx -= c0x * d0 + c1x * d1
                vy -= c0y * d0 + c1y * d1
                vz -= c0z * d0 + c1z * d1
                dist = math.sqrt(vx * vx + vy * vy + vz * vz)
        return dist


__all__ = ["GUESS_MAX_CORRECTION", "GuessTable"]
