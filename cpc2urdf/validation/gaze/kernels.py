"""The compiled inner loop of the gaze solver (numba, ``cache=True``): FK, camera Jacobians,
the pointing residual and the bounded, damped Gauss-Newton with the policy in the null space.

Everything works on the flat arrays of :class:`~cpc2urdf.validation.gaze.chain.HeadChain`
packed in one tuple ``ch`` (:func:`pack`). Unknowns ``u`` (shape (m,)); chain readings
``q = A u + b``.

Kinematics (as Pinocchio): ``T_world_j = T_world_parent * placement_j * M_j(q_j)`` with
``M_j`` a rotation by ``q_j`` about ``axis_j`` (Rodrigues) or a translation ``q_j axis_j``;
``T_world_cam = T_world_parent * placement_cam``. The world axis of joint ``j`` is
``a_j = R_world_j axis_j``; a revolute joint moves a camera centre ``o`` by ``a_j x (o - p_j)``
and turns it by ``a_j``, a prismatic one moves it by ``a_j``.

Pointing residual per solved camera (as before): ``r = u - e_z`` with ``u`` the unit target
direction in the camera frame, ``p_cam = R^T (p - o)``; ``|r| = 2 sin(err / 2)``. With the
camera's world twist ``(v, w)``: ``d p_cam = R^T ((p - o) x w - v)`` and
``d u = (I - u u^T) d p_cam / |p_cam|``. ``d u`` lies in the plane orthogonal to ``u``, so the
Jacobian is kept in a basis ``t1, t2`` of that plane (:func:`_tangent`): two rows per camera,
``J_t = T^T d p_cam / |p_cam|``, with the residual's own part there, ``r_t = T^T r``. Every product
the step takes is the same as with the three rows (``J^T J = J_t^T J_t``, ``J^T r = J_t^T r_t``,
``J J^T`` has ``J_t J_t^T``'s eigenvalues and one zero a camera), and ``J_x J_x^T`` of the redundant heads
is ``2S x 2S`` instead of ``3S x 3S`` (fifteenth pass, docs/gaze.md).

Step (task priority, Levenberg-Marquardt; unknowns scaled by the square root of the policy's
weights so the secondary task is ``|x - x_ref|^2 / 2``): with ``J^T J = V diag(l) V^T`` over the
free unknowns, the pointing task moves along the eigen-directions with ``l > cut``
(``-v (v . J^T r) / (l + mu)``, ``mu = damping |r|^2``) and the policy along the others
(``-gain v v^T (x - x_ref)``), the *near-null space* of the pointing error. ``cut`` is
``null_rel * max(l)``: 1e-12 on heads that can fixate exactly (only the exact null space; on two
eyes near a fixating posture 1e-9, :data:`BINOCULAR_NULL`), larger on a binocular head that cannot (its weak direction, along which exact fixation would swing the
neck and eyes far from the policy's posture, is left to the policy). With a zero-version row
``c`` (:func:`pack`; the nominal binocular head's cyclopean policy) the null-space move is the
Newton step of ``|x - x_ref|^2 / 2 + w (c . (u - home))^2 / 2`` over the null directions
(Sherman-Morrison, ``w`` large: version held at zero), and the polish zeroes a small remaining
version exactly. With a minimum viewing distance (:func:`pack`) the null move keeps the solved
camera nearest the target from coming nearer than it (:func:`_hold_off`). Joints at a bound whose step
points outward are held (active set); the step is capped and projected on the bounds. With more
free unknowns than residual rows (a camera on an arm, iCub's torso, neck and eyes, TALOS's torso
and head) the same step comes from ``J_x J_x^T`` (``M x M``, ``M = 2S``) instead
(:func:`_step_from_rows`).

Near the answer (``|r|^2 <= ACCELERATE_BELOW``) the policy phase of a head that fixates
exactly, with no zero-version task, takes Anderson-accelerated steps: its plain step ignores how
the null space turns as the joints move, so it converges linearly (on the redundant heads, iCub's
neck and eyes or a camera on an arm, 2-4x per step); a multisecant step over the last
``HISTORY`` pairs of (unknowns, plain step) removes most of that, with the plain step as the
fallback and the stopping test.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from cpc2urdf.transforms import Array
from cpc2urdf.validation.gaze.chain import HeadChain

MIN_TARGET_DISTANCE = 1e-9  # [m]: closer to a camera centre, a target has no direction
FAR_TARGET = 1e15  # [m]: a target with a coordinate beyond this is solved for by its direction
MAX_STEP = 0.5  # [rad]/[m]: largest change of one unknown per step
BACKTRACKS = 10  # step halvings per iteration
POLISH_ITERATIONS = 12  # iterations of the polish (pointing alone) after the policy phase
PROBE_ITERATIONS = 8  # policy iterations a further start gets before it must beat the best answer
# [-]: a polish step that lowers |r|^2 by less than this fraction ends the polish. A residual the
# head can remove falls by orders of magnitude per step (Gauss-Newton on a zero residual converges
# quadratically); one this slow is what a bound or the head's disparity leaves, and what further
# steps could still take off is of the order of this fraction of it (pointing error ~5e-7 relative)
STALLED = 1e-6
SECONDARY_GAIN = 1.0  # [-]: fraction of the policy's (first-order) error removed per step
POLICY_STEP_TOL = 1e-5  # [rad]/[m]: a policy step this small ends the policy phase (then pointing alone)
DAMPING = 1e-4  # [-]: Levenberg-Marquardt damping, times |r|^2
SAME_BASIN = 1e-3  # [rad]/[m]: a probe this close to the best answer (every unknown) is converging to it
OVERSHOOT = 0.1  # [-]: a step back along the last one by more than this fraction of it is shortened (secant)
STEP_TOL = 1e-13  # [rad]/[m]: a step this small ends the iteration
VERSION_POLISH = 1e-4  # [rad]: the polish zeroes a version this small (larger: a bound holds it)
EXACT_RESIDUAL = 1e-30  # [-]: |r|^2 below this is exact (pointing error ~1e-15 rad)
POLISHED = 1e-22  # [-]: |r|^2 at which the polish stops (pointing error ~1e-11 rad, 1/100 of the tolerance)
VERSION_SETTLED = 1e-13  # [rad]: a version this small is zero for the polish
AT_BOUND = 1e-12  # [rad]/[m]: an unknown (a reading) this close to a bound (a limit) is at it
# [-]: pointing with no descent direction inside the bounds: |projected J^T r| <= this |J| |r|.
# Nominal IIS-head: answers of unreachable targets 0 - 2.9e-6 (300), first answers of reachable
# targets the zero-version task held at a bound 0.06 - 0.20 (all 7 of 40,000)
STATIONARY = 1e-4
HISTORY = 2  # pairs (x, step) the policy phase's Anderson acceleration uses (its 2x2 solve: 2 only)
ACCELERATE_BELOW = 1e-6  # [-]: |r|^2 under which the policy phase is accelerated (pointing error ~1e-3 rad)
START_DISTANCE = 0.01  # [-]: best_starts' cost of a start's squared (scaled) distance from u_ref
# the same on a one-camera head with spare joints (more than its 3 residual rows: a camera on an
# arm, TALOS's torso and head), where a start that faces the target from far off the reference
# walks far in the null space. Panda camera, 8,000 reachable targets, 0.01 / 0.1 / 0.3 / 1.0:
# mean iterations 16.9 / 11.9 / 10.9 / 11.0, at the iteration cap 43 / 7 / 3 / 4; mean policy
# cost (2,000 targets) 1.40 / 1.32 / 1.20 / 1.20. TALOS 6.11 / 5.84 / 5.91 / 6.56 (answers within
# 2e-5). Without the minimum viewing distance (_hold_off) it walked more answers onto their target.
START_DISTANCE_REDUNDANT = 0.3
# [-] (scaled unknowns): a target's last table start differs from each table start before it by
# this much in some unknown, when an entry does (further_start). The best-facing entries are
# often one cluster (the policy's answers for nearby directions), all in one basin: iCub with its
# torso, 7,500 random targets in a 6 m cube (bench_gaze.audit_targets, seeds 0-4), 321 not
# fixated, 13 of them fixated from one of 20 random starts; now 309 and 1 (docs/gaze.md,
# eighteenth pass)
DISTINCT_START = 0.25
DISTANCE_REACH = 1e-6  # [-]: |P a|^2 / |a|^2 below which the null space does not move a camera's distance (see _hold_off)
ACCELERATE_NULL_REL = 1e-9  # [-]: the policy phase is accelerated on heads whose null_rel is at most this (exact null spaces)
# A binocular head whose eyes' axes sweep one plane (iCub, the nominal IIS-head: CompiledGaze
# finds the pointing Jacobian's 4th eigenvalue at rounding level, STRUCTURAL_NULL, at every fixating
# table entry and sets pack's near_rel) cuts its null space at BINOCULAR_NULL near a fixating
# posture (|r|^2 <= NEAR_FIXATION, pointing error ~1e-2 rad). At a fixating posture that 4th
# eigenvalue is 0 (rounding: 1e-16 of the 1st), and near one it grows with the square of the distance (iCub, 200 answers moved by 1e-4 / 1e-3 / 1e-2 rad: 7e-12 / 5e-10 / 7e-8
# of the 1st, median). Cut at null_rel (1e-12) that direction stayed pointing's until the last
# steps, and the policy walk got it only then: a long step along it that the next steps took back
# (iCub 10.1 iterations a reachable target, 8.8 so). Farther from fixation (an unreachable
# target's best answer) the cut stays null_rel: cut at 1e-9 there, the direction's pointing went
# undone (nominal IIS-head, 1,500 random targets: 27 -> 44 answers at the iteration cap, 40 best
# answers worse by up to 0.65 deg). 1e-8 and 1e-7 gave iCub 8.6 and 8.5 iterations; 1e-9 stays
# three orders below a calibrated head's weak direction (2.8e-7 of the 1st), which is no exact
# null direction. (The policy phase's acceleration goes by null_rel: unchanged.)
# Not on two eyes that fixate exactly without such a direction (each eye on its own roll and tilt:
# its roll is a real pointing direction whose eigenvalue is small near straight ahead; cut at 1e-9,
# 1,369 of 2,400 exactly reachable targets 50 m-60 km off were left unfixated, review).
BINOCULAR_NULL = 1e-9
NEAR_FIXATION = 1e-4
STRUCTURAL_NULL = 1e-12  # [-]: a 4th eigenvalue at most this of the 1st at every fixating table entry is structural

# every kernel: cached across runs; IEEE division (no zero-division checks in the loops: every
# division is guarded where it matters); the GIL released (a batch is split over threads, one
# per core)
kernel = njit(cache=True, error_model="numpy", nogil=True)
# the small ones are inlined into their callers by LLVM (forceinline: numba's own inline="always"
# gave the same speed at ~1.7x the cold compile): a call that passes the chain's tuple of arrays
# costs ~100-400 ns, as much as their arithmetic
inline_kernel = njit(cache=True, error_model="numpy", nogil=True, forceinline=True)
# the solve's kernels below the entry points (_solve_into, solve_single, solve_one, best_starts,
# _iterate) allocate nothing (every buffer is one of the workspace's arrays) and return no array,
# so they are compiled without numba's reference counting (its CPU target option _nrt=False):
# every array they see is owned by the entry point's frame, or by solve_flat's Python caller
# (CompiledGaze._scratch), for the whole call. With it, numba increfs every array argument (a
# tuple's every member: the chain's 14, the workspace's 47) on entry and decrefs it on return,
# each an atomic operation; its pruning pass removes such pairs
# in simple functions (fk) but not in these. Nominal IIS-head, 100 reachable targets in one
# batch: 439 increfs and 590 decrefs a target before, 2 and 2 now (counted at breakpoints on
# NRT_incref/NRT_decref); the batch kernel's time a target 14.3 -> 10.8 us (TALOS 14.8 -> 11.2,
# TIAGo 9.1 -> 6.1); answers identical bit for bit. A function compiled so must not call one
# that returns a new array: nothing would release it
# (the option is in numba's own tests, not in the type stubs mypy reads)
kernel_without_refcounts = njit(cache=True, error_model="numpy", nogil=True, _nrt=False)  # type: ignore[call-overload]

# status codes of the compiled solve (indices into result.py's STATUSES)
S_FIXATED, S_LIMITS, S_BEHIND, S_TOO_CLOSE, S_NO_SOLUTION, S_DISPARITY = 0, 1, 2, 3, 4, 5
S_NOT_FINITE = -1  # solve_flat's answer to a target with a NaN or infinite coordinate (nothing solved)


def pack(
    chain: HeadChain, version_row: Array | None = None, version_weight: float = 0.0, min_distance: float = 0.0
) -> tuple:  # type: ignore[type-arg]
    """The chain's arrays as the tuple the kernels take, then the policy's secondary tasks: the
    zero-version task's row ``c`` over the unknowns (shape (m,); zeros: none), and ``(weight,
    c . home, min_distance, near_rel)``: the version's weight and reference, the minimum viewing
    distance [m] the policy phase keeps each solved camera from the target (0: none; see
    :func:`_iterate`), and the null cut near a fixating posture (0: ``null_rel`` there too; set
    to :data:`BINOCULAR_NULL` by ``CompiledGaze`` on two eyes with a structural null direction)."""
    m = chain.m
    c = np.zeros(m) if version_row is None else np.ascontiguousarray(version_row, dtype=float)
    home = 0.5 * (chain.lower + chain.upper)
    vw = np.array([float(version_weight) if version_row is not None else 0.0, float(c @ home), float(min_distance),
                   0.0])
    return (
        chain.parent,
        chain.jtype,
        chain.axis,
        chain.R,
        chain.t,
        chain.A,
        chain.b,
        chain.cam_parent,
        chain.cam_R,
        chain.cam_t,
        np.ascontiguousarray(chain.anc, dtype=np.int64),
        chain.solve_cameras,
        c,
        vw,
    )


@inline_kernel
def _fk_scalars(ch, u, b, JR, Jp, Ja, CR, Co):  # type: ignore[no-untyped-def]
    """:func:`fk`'s arithmetic, inlined into the residual (the solve's hot path)."""
    parent, jtype, axis, R, t, A, cam_parent, cam_R, cam_t = ch[0], ch[1], ch[2], ch[3], ch[4], ch[5], ch[7], ch[8], ch[9]
    K = parent.shape[0]
    m = u.shape[0]
    for k in range(K):
        q = b[k]
        for v in range(m):
            q += A[k, v] * u[v]
        pk = parent[k]
        if pk >= 0:
            p00, p01, p02 = JR[pk, 0, 0], JR[pk, 0, 1], JR[pk, 0, 2]
            p10, p11, p12 = JR[pk, 1, 0], JR[pk, 1, 1], JR[pk, 1, 2]
            p20, p21, p22 = JR[pk, 2, 0], JR[pk, 2, 1], JR[pk, 2, 2]
            ox, oy, oz = Jp[pk, 0], Jp[pk, 1], Jp[pk, 2]
        else:
            p00, p01, p02, p10, p11, p12, p20, p21, p22 = 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0
            ox, oy, oz = 0.0, 0.0, 0.0
        tx, ty, tz = t[k, 0], t[k, 1], t[k, 2]
        px = ox + p00 * tx + p01 * ty + p02 * tz
        py = oy + p10 * tx + p11 * ty + p12 * tz
        pz = oz + p20 * tx + p21 * ty + p22 * tz
        # M0 = Rparent * R[k]
        q00 = p00 * R[k, 0, 0] + p01 * R[k, 1, 0] + p02 * R[k, 2, 0]
        q01 = p00 * R[k, 0, 1] + p01 * R[k, 1, 1] + p02 * R[k, 2, 1]
        q02 = p00 * R[k, 0, 2] + p01 * R[k, 1, 2] + p02 * R[k, 2, 2]
        q10 = p10 * R[k, 0, 0] + p11 * R[k, 1, 0] + p12 * R[k, 2, 0]
        q11 = p10 * R[k, 0, 1] + p11 * R[k, 1, 1] + p12 * R[k, 2, 1]
        q12 = p10 * R[k, 0, 2] + p11 * R[k, 1, 2] + p12 * R[k, 2, 2]
        q20 = p20 * R[k, 0, 0] + p21 * R[k, 1, 0] + p22 * R[k, 2, 0]
        q21 = p20 * R[k, 0, 1] + p21 * R[k, 1, 1] + p22 * R[k, 2, 1]
        q22 = p20 * R[k, 0, 2] + p21 * R[k, 1, 2] + p22 * R[k, 2, 2]
        ax, ay, az = axis[k, 0], axis[k, 1], axis[k, 2]
        wx = q00 * ax + q01 * ay + q02 * az
        wy = q10 * ax + q11 * ay + q12 * az
        wz = q20 * ax + q21 * ay + q22 * az
        Ja[k, 0], Ja[k, 1], Ja[k, 2] = wx, wy, wz
        if jtype[k] == 0:
            c, s = math.cos(q), math.sin(q)
            C1 = 1.0 - c
            r00 = c + ax * ax * C1
            r01 = ax * ay * C1 - az * s
            r02 = ax * az * C1 + ay * s
            r10 = ay * ax * C1 + az * s
            r11 = c + ay * ay * C1
            r12 = ay * az * C1 - ax * s
            r20 = az * ax * C1 - ay * s
            r21 = az * ay * C1 + ax * s
            r22 = c + az * az * C1
            JR[k, 0, 0] = q00 * r00 + q01 * r10 + q02 * r20
            JR[k, 0, 1] = q00 * r01 + q01 * r11 + q02 * r21
            JR[k, 0, 2] = q00 * r02 + q01 * r12 + q02 * r22
            JR[k, 1, 0] = q10 * r00 + q11 * r10 + q12 * r20
            JR[k, 1, 1] = q10 * r01 + q11 * r11 + q12 * r21
            JR[k, 1, 2] = q10 * r02 + q11 * r12 + q12 * r22
            JR[k, 2, 0] = q20 * r00 + q21 * r10 + q22 * r20
            JR[k, 2, 1] = q20 * r01 + q21 * r11 + q22 * r21
            JR[k, 2, 2] = q20 * r02 + q21 * r12 + q22 * r22
        else:
            JR[k, 0, 0], JR[k, 0, 1], JR[k, 0, 2] = q00, q01, q02
            JR[k, 1, 0], JR[k, 1, 1], JR[k, 1, 2] = q10, q11, q12
            JR[k, 2, 0], JR[k, 2, 1], JR[k, 2, 2] = q20, q21, q22
            px += q * wx
            py += q * wy
            pz += q * wz
        Jp[k, 0], Jp[k, 1], Jp[k, 2] = px, py, pz
    C = cam_parent.shape[0]
    for c in range(C):
        pk = cam_parent[c]
        for i in range(3):
            for j in range(3):
                s = 0.0
                for l in range(3):
                    s += (JR[pk, i, l] if pk >= 0 else (1.0 if i == l else 0.0)) * cam_R[c, l, j]
                CR[c, i, j] = s
            s = 0.0
            for l in range(3):
                s += (JR[pk, i, l] if pk >= 0 else (1.0 if i == l else 0.0)) * cam_t[c, l]
            Co[c, i] = s + (Jp[pk, i] if pk >= 0 else 0.0)


# the FK is inlined into the residual, the solve's hot path (_fk_scalars): numba passes each
# array of a call as its fields, and the chain's tuple and the workspace's arrays cost more
# there than the FK's arithmetic. Every other caller calls fk (one compiled copy, a shorter
# compile). (Before, a second dispatcher of fk's own Python function did that job: numba
# compiled it under fk's name, and _iterate called fk at three sites instead of inlining it.)
@kernel
def fk(ch, u, b, JR, Jp, Ja, CR, Co):  # type: ignore[no-untyped-def]
    """World rotation ``JR`` (K, 3, 3), origin ``Jp`` (K, 3) and axis ``Ja`` (K, 3) of every
    chain joint, and rotation ``CR`` (C, 3, 3) and centre ``Co`` (C, 3) of every camera, at
    unknowns ``u`` (chain readings ``A u + b``; ``b`` given per solve). Written out in scalars
    (3x3 products unrolled, no temporaries): the trigonometry is most of its cost."""
    _fk_scalars(ch, u, b, JR, Jp, Ja, CR, Co)


@inline_kernel
def camera_jacobian(ch, c, Jp, Ja, CR, Co, Jc):  # type: ignore[no-untyped-def]
    """World Jacobian ``Jc`` (6, K) of camera ``c`` by the chain readings: rows (v, w)."""
    jtype, anc = ch[1], ch[10]
    K = jtype.shape[0]
    for k in range(K):
        if not anc[c, k]:
            for i in range(6):
                Jc[i, k] = 0.0
            continue
        ax, ay, az = Ja[k, 0], Ja[k, 1], Ja[k, 2]
        if jtype[k] == 0:
            dx, dy, dz = Co[c, 0] - Jp[k, 0], Co[c, 1] - Jp[k, 1], Co[c, 2] - Jp[k, 2]
            Jc[0, k] = ay * dz - az * dy
            Jc[1, k] = az * dx - ax * dz
            Jc[2, k] = ax * dy - ay * dx
            Jc[3, k], Jc[4, k], Jc[5, k] = ax, ay, az
        else:
            Jc[0, k], Jc[1, k], Jc[2, k] = ax, ay, az
            Jc[3, k], Jc[4, k], Jc[5, k] = 0.0, 0.0, 0.0


@inline_kernel
def _tangent(ux, uy, uz):  # type: ignore[no-untyped-def]
    """Two unit vectors ``t1, t2`` (6 scalars) that complete the unit direction ``u`` to an
    orthonormal basis: the rotation taking ``e_z`` to ``u`` (``-e_z`` when ``u_z < -1/2``: the
    first is singular at ``u = -e_z``) applied to ``e_x`` and ``e_y``, ``R = I + [k] + [k]^2 / (1 +
    a . u)``, ``k = a x u``. Continuous in ``u`` on either side, so a warm-started decomposition
    of ``J_x J_x^T`` stays warm from step to step. ``u = 0`` (a target on the camera centre):
    ``e_x, e_y``. The residual's tangent part ``T^T (u - e_z)`` is ``(u_x, u_y)`` on the first side.
    The side is read from ``u_z - 1`` as the residual holds it, so that :func:`_tangent_residual`
    (which has only the residual) takes the same side at every double (``u_z = -1/2 - 2^-53``:
    ``u_z + 1 - 1`` rounds across)."""
    if uz - 1.0 >= -1.5:
        c = 1.0 / (1.0 + uz)
        return 1.0 - ux * ux * c, -ux * uy * c, -ux, -ux * uy * c, 1.0 - uy * uy * c, -uy
    c = 1.0 / (1.0 - uz)
    return 1.0 - ux * ux * c, -ux * uy * c, ux, -ux * uy * c, 1.0 - uy * uy * c, uy


@inline_kernel
def _tangent_residual(r, s):  # type: ignore[no-untyped-def]
    """``r_t = T^T r_s`` (2 scalars) of solved camera ``s`` from its residual ``r_s = u - e_z``
    (``r[3 s:3 s + 3]``): the part of ``r`` that the Jacobian's rows see (its part along ``u``,
    ``(u . r) u``, no joint motion changes to first order). ``T^T (u - e_z) = -T^T e_z``, which in
    the bases of :func:`_tangent` is ``(u_x, u_y)``, and ``(-u_x, -u_y)`` on the side ``u_z < -1/2``:
    no basis to build."""
    if r[3 * s + 2] >= -1.5:  # the side :func:`_tangent` takes (from the same double)
        return r[3 * s], r[3 * s + 1]
    return -r[3 * s], -r[3 * s + 1]


@inline_kernel
def _gradient_entry(J, r, v):  # type: ignore[no-untyped-def]
    """``(J^T r)_v``, unknown ``v``'s entry of the pointing error's gradient ``J^T r = J_t^T r_t``
    (the Jacobian's two rows a camera against its tangent residual, :func:`_tangent_residual`)."""
    gv = 0.0
    for c in range(J.shape[0] // 2):
        rt1, rt2 = _tangent_residual(r, c)
        gv += J[2 * c, v] * rt1 + J[2 * c + 1, v] * rt2
    return gv


@inline_kernel
def _residual_hot(ch, u, b, p, r, J, want_jac, JR, Jp, Ja, CR, Co, Jc, Pc):  # type: ignore[no-untyped-def]
    """Pointing residual ``r`` (3 S,) of the solved cameras at ``u`` for target ``p`` (world),
    its Jacobian ``J`` (2 S, m) by ``u`` in each camera's tangent basis (:func:`_tangent`: ``T^T
    d r`` with ``T`` taken at this ``u``, the only part of ``d r`` there is) when ``want_jac``, and each solved camera's view of
    the target ``Pc`` (S, 5 + m): ``p_cam``, ``|p_cam|``, and with the Jacobian (``want_jac``:
    columns 4 on, left as they are by a trial's evaluation) ``|p_cam|`` again and its gradient
    by ``u``. Returns ``|r|^2``."""
    _fk_scalars(ch, u, b, JR, Jp, Ja, CR, Co)
    return residual_at_fk(ch, p, r, J, want_jac, JR, Jp, Ja, CR, Co, Jc, Pc)


@kernel
def residual(ch, u, b, p, r, J, want_jac, JR, Jp, Ja, CR, Co, Jc, Pc):  # type: ignore[no-untyped-def]
    """:func:`_residual_hot` as one compiled copy: Python, and the cold callers (the iteration's
    two calls inline it; as with :func:`fk`, not a second dispatcher of the same function,
    which numba compiles under the same name)."""
    return _residual_hot(ch, u, b, p, r, J, want_jac, JR, Jp, Ja, CR, Co, Jc, Pc)


@inline_kernel
def residual_at_fk(ch, p, r, J, want_jac, JR, Jp, Ja, CR, Co, Jc, Pc):  # type: ignore[no-untyped-def]
    """:func:`residual` on the kinematics already in ``JR``, ``Jp``, ``Ja``, ``CR``, ``Co`` (the
    last :func:`fk`): an accepted trial step's configuration is not evaluated twice."""
    A, solve_cams = ch[5], ch[11]
    S = solve_cams.shape[0]
    K = A.shape[0]
    m = A.shape[1]
    rr = 0.0
    for s in range(S):
        c = solve_cams[s]
        dx, dy, dz = p[0] - Co[c, 0], p[1] - Co[c, 1], p[2] - Co[c, 2]
        x = CR[c, 0, 0] * dx + CR[c, 1, 0] * dy + CR[c, 2, 0] * dz
        y = CR[c, 0, 1] * dx + CR[c, 1, 1] * dy + CR[c, 2, 1] * dz
        z = CR[c, 0, 2] * dx + CR[c, 1, 2] * dy + CR[c, 2, 2] * dz
        nrm = math.sqrt(x * x + y * y + z * z)
        Pc[s, 0], Pc[s, 1], Pc[s, 2], Pc[s, 3] = x, y, z, nrm
        if nrm >= MIN_TARGET_DISTANCE:
            inv = 1.0 / nrm
            ux, uy, uz = x * inv, y * inv, z * inv
        else:  # on the camera centre: no direction (missed by pi), no gradient from this eye
            inv, ux, uy, uz = 0.0, 0.0, 0.0, 0.0
        r[3 * s], r[3 * s + 1], r[3 * s + 2] = ux, uy, uz - 1.0
        rr += ux * ux + uy * uy + (uz - 1.0) * (uz - 1.0)
        if not want_jac:
            continue
        camera_jacobian(ch, c, Jp, Ja, CR, Co, Jc)
        t1x, t1y, t1z, t2x, t2y, t2z = _tangent(ux, uy, uz)
        for v in range(m):
            J[2 * s, v] = 0.0
            J[2 * s + 1, v] = 0.0
            Pc[s, 5 + v] = 0.0
        Pc[s, 4] = nrm
        for k in range(K):
            # d(p - o) x w - v in world, then R^T: d p_cam; its tangent part T^T d p_cam / |p_cam|
            # is T^T d r (d r = (I - u u^T) d p_cam / |p_cam| and I - u u^T = T T^T)
            wx, wy, wz = Jc[3, k], Jc[4, k], Jc[5, k]
            ex = dy * wz - dz * wy - Jc[0, k]
            ey = dz * wx - dx * wz - Jc[1, k]
            ez = dx * wy - dy * wx - Jc[2, k]
            gx = CR[c, 0, 0] * ex + CR[c, 1, 0] * ey + CR[c, 2, 0] * ez
            gy = CR[c, 0, 1] * ex + CR[c, 1, 1] * ey + CR[c, 2, 1] * ez
            gz = CR[c, 0, 2] * ex + CR[c, 1, 2] * ey + CR[c, 2, 2] * ez
            d = ux * gx + uy * gy + uz * gz  # d |p_cam|
            h1 = (t1x * gx + t1y * gy + t1z * gz) * inv
            h2 = (t2x * gx + t2y * gy + t2z * gz) * inv
            for v in range(m):
                a = A[k, v]
                if a != 0.0:
                    J[2 * s, v] += h1 * a
                    J[2 * s + 1, v] += h2 * a
                    Pc[s, 5 + v] += d * a
    return rr


@kernel
def jacobi_eigh(H, f, lam, V):  # type: ignore[no-untyped-def]
    """Eigen-decomposition of the symmetric ``H[:f, :f]`` (destroyed) by cyclic Jacobi
    rotations: ``lam[:f]`` ascending, eigenvectors in the columns of ``V[:f, :f]``. Small ``f``
    (the unknowns of a head): cheaper than a LAPACK call and allocation-free.

    A sweep visits the pairs in round-robin order: each round's pairs are disjoint, so a
    rotation's angle does not wait on the rotation before it and the processor overlaps their
    divisions and square roots (in row order each waited on the last). ``f = 4``, the step's
    ``J_x J_x^T`` on every binocular head, and ``f = 2``, one camera's, run in scalars
    (:func:`_jacobi4`, :func:`_jacobi2`): the same rotations, bit for bit (up to the sign of a
    zero, which a solve's ``H``, sums from ``0.0``, never holds). Before both, iCub spent about
    30 % of a solve here (docs/gaze.md, nineteenth pass). The round-robin order is equivalent to
    the row order (a relabelling of its pairs) and converges like it, quadratically."""
    if f == 4:
        _jacobi4(H, lam, V)
    elif f == 2:
        _jacobi2(H, lam, V)
    else:
        _jacobi_any(H, f, lam, V)


@kernel
def _jacobi_any(H, f, lam, V):  # type: ignore[no-untyped-def]
    """:func:`jacobi_eigh` for any ``f`` (arrays and loops)."""
    for i in range(f):
        for j in range(f):
            V[i, j] = 1.0 if i == j else 0.0
    n = f + (f & 1)  # players of the round-robin (a dummy one when f is odd)
    for _ in range(50):
        off = 0.0
        diag = 0.0
        for i in range(f):
            diag += H[i, i] * H[i, i]
            for j in range(i + 1, f):
                off += H[i, j] * H[i, j]
        if off <= 1e-24 * diag or off == 0.0:  # off-diagonal at 1e-12 of the diagonal (a Newton step needs no more)
            break
        tiny = 1e-24 * diag / (f * f)  # elements this small cannot keep the test above from passing: not rotated
        # the circle method: player n - 1 fixed, the others turning; round r pairs (r, n - 1)
        # and ((r + i) mod (n - 1), (r - i) mod (n - 1)), i = 1 .. n/2 - 1
        for r in range(n - 1):
            if n == f:  # (no dummy player)
                _rotate_pair(H, V, f, r, n - 1, tiny)
            for i in range(1, n // 2):
                a = (r + i) % (n - 1)
                c = (r - i + n - 1) % (n - 1)
                _rotate_pair(H, V, f, min(a, c), max(a, c), tiny)
    for i in range(f):
        lam[i] = H[i, i]
    _sort_eigen(lam, V, f)


@inline_kernel
def _jacobi_angle(hpp, hqq, hpq, tiny):  # type: ignore[no-untyped-def]
    """The rotation that zeroes ``hpq`` between the diagonal entries ``hpp``, ``hqq`` as
    ``(cos, sin, tan, keep)``: ``tan`` of the smaller angle (Numerical Recipes' ``theta`` form, no
    overflow); ``keep`` 0. Where ``hpq^2 <= tiny``, none: ``(1, 0, 0, 1)``."""
    if hpq * hpq <= tiny:
        return 1.0, 0.0, 0.0, 1.0
    theta = (hqq - hpp) / (2.0 * hpq)
    tt = (1.0 if theta >= 0 else -1.0) / (abs(theta) + math.sqrt(theta * theta + 1.0))
    t2 = tt * tt
    if t2 < 1.1102230246251565e-16:  # 1 + t^2 rounds to 1: cos is exactly 1 (as computed below)
        return 1.0, tt, tt, 0.0
    cs = 1.0 / math.sqrt(t2 + 1.0)
    return cs, tt * cs, tt, 0.0


@inline_kernel
def _rotate_pair(H, V, f, a, c, tiny):  # type: ignore[no-untyped-def]
    """One rotation of :func:`jacobi_eigh` (``a < c``; :func:`_jacobi_angle`). It touches rows and
    columns ``a`` and ``c`` only: the pivot's two diagonal entries in closed form, the others in
    pairs (a third of the updates of rotating all of H's rows and columns)."""
    cs, sn, tt, keep = _jacobi_angle(H[a, a], H[c, c], H[a, c], tiny)
    if keep == 1.0:
        return
    hac = H[a, c]
    H[a, a] -= tt * hac
    H[c, c] += tt * hac
    H[a, c] = 0.0
    H[c, a] = 0.0
    for k in range(f):
        if k != a and k != c:
            hka, hkc = H[k, a], H[k, c]
            H[k, a] = cs * hka - sn * hkc
            H[k, c] = sn * hka + cs * hkc
            H[a, k] = H[k, a]
            H[c, k] = H[k, c]
    for k in range(f):
        vka, vkc = V[k, a], V[k, c]
        V[k, a] = cs * vka - sn * vkc
        V[k, c] = sn * vka + cs * vkc


@inline_kernel
def _jacobi4(H, lam, V):  # type: ignore[no-untyped-def]
    """:func:`jacobi_eigh` of a 4 x 4 ``H`` (the step's ``J_x J_x^T`` on every binocular head) in
    scalars: the same rotations in the same order as :func:`_jacobi_any`, bit for bit, without
    its indexing, short inner loops and branches. Written out by a generator (the round-robin
    order below); tests/test_gaze_heads.py checks it against :func:`_jacobi_any`."""
    h00, h01, h02, h03 = H[0, 0], H[0, 1], H[0, 2], H[0, 3]
    h11, h12, h13 = H[1, 1], H[1, 2], H[1, 3]
    h22, h23 = H[2, 2], H[2, 3]
    h33 = H[3, 3]
    v00, v01, v02, v03 = 1.0, 0.0, 0.0, 0.0
    v10, v11, v12, v13 = 0.0, 1.0, 0.0, 0.0
    v20, v21, v22, v23 = 0.0, 0.0, 1.0, 0.0
    v30, v31, v32, v33 = 0.0, 0.0, 0.0, 1.0
    for _ in range(50):
        off = h01 * h01 + h02 * h02 + h03 * h03 + h12 * h12 + h13 * h13 + h23 * h23
        diag = h00 * h00 + h11 * h11 + h22 * h22 + h33 * h33
        if off <= 1e-24 * diag or off == 0.0:
            break
        tiny = 1e-24 * diag / 16.0
        cs, sn, tt, keep = _jacobi_angle(h00, h33, h03, tiny)  # pair (0, 3)
        h00, h33, h03 = h00 - tt * h03, h33 + tt * h03, keep * h03
        h01, h13 = cs * h01 - sn * h13, sn * h01 + cs * h13
        h02, h23 = cs * h02 - sn * h23, sn * h02 + cs * h23
        v00, v03 = cs * v00 - sn * v03, sn * v00 + cs * v03
        v10, v13 = cs * v10 - sn * v13, sn * v10 + cs * v13
        v20, v23 = cs * v20 - sn * v23, sn * v20 + cs * v23
        v30, v33 = cs * v30 - sn * v33, sn * v30 + cs * v33
        cs, sn, tt, keep = _jacobi_angle(h11, h22, h12, tiny)  # pair (1, 2)
        h11, h22, h12 = h11 - tt * h12, h22 + tt * h12, keep * h12
        h01, h02 = cs * h01 - sn * h02, sn * h01 + cs * h02
        h13, h23 = cs * h13 - sn * h23, sn * h13 + cs * h23
        v01, v02 = cs * v01 - sn * v02, sn * v01 + cs * v02
        v11, v12 = cs * v11 - sn * v12, sn * v11 + cs * v12
        v21, v22 = cs * v21 - sn * v22, sn * v21 + cs * v22
        v31, v32 = cs * v31 - sn * v32, sn * v31 + cs * v32
        cs, sn, tt, keep = _jacobi_angle(h11, h33, h13, tiny)  # pair (1, 3)
        h11, h33, h13 = h11 - tt * h13, h33 + tt * h13, keep * h13
        h01, h03 = cs * h01 - sn * h03, sn * h01 + cs * h03
        h12, h23 = cs * h12 - sn * h23, sn * h12 + cs * h23
        v01, v03 = cs * v01 - sn * v03, sn * v01 + cs * v03
        v11, v13 = cs * v11 - sn * v13, sn * v11 + cs * v13
        v21, v23 = cs * v21 - sn * v23, sn * v21 + cs * v23
        v31, v33 = cs * v31 - sn * v33, sn * v31 + cs * v33
        cs, sn, tt, keep = _jacobi_angle(h00, h22, h02, tiny)  # pair (0, 2)
        h00, h22, h02 = h00 - tt * h02, h22 + tt * h02, keep * h02
        h01, h12 = cs * h01 - sn * h12, sn * h01 + cs * h12
        h03, h23 = cs * h03 - sn * h23, sn * h03 + cs * h23
        v00, v02 = cs * v00 - sn * v02, sn * v00 + cs * v02
        v10, v12 = cs * v10 - sn * v12, sn * v10 + cs * v12
        v20, v22 = cs * v20 - sn * v22, sn * v20 + cs * v22
        v30, v32 = cs * v30 - sn * v32, sn * v30 + cs * v32
        cs, sn, tt, keep = _jacobi_angle(h22, h33, h23, tiny)  # pair (2, 3)
        h22, h33, h23 = h22 - tt * h23, h33 + tt * h23, keep * h23
        h02, h03 = cs * h02 - sn * h03, sn * h02 + cs * h03
        h12, h13 = cs * h12 - sn * h13, sn * h12 + cs * h13
        v02, v03 = cs * v02 - sn * v03, sn * v02 + cs * v03
        v12, v13 = cs * v12 - sn * v13, sn * v12 + cs * v13
        v22, v23 = cs * v22 - sn * v23, sn * v22 + cs * v23
        v32, v33 = cs * v32 - sn * v33, sn * v32 + cs * v33
        cs, sn, tt, keep = _jacobi_angle(h00, h11, h01, tiny)  # pair (0, 1)
        h00, h11, h01 = h00 - tt * h01, h11 + tt * h01, keep * h01
        h02, h12 = cs * h02 - sn * h12, sn * h02 + cs * h12
        h03, h13 = cs * h03 - sn * h13, sn * h03 + cs * h13
        v00, v01 = cs * v00 - sn * v01, sn * v00 + cs * v01
        v10, v11 = cs * v10 - sn * v11, sn * v10 + cs * v11
        v20, v21 = cs * v20 - sn * v21, sn * v20 + cs * v21
        v30, v31 = cs * v30 - sn * v31, sn * v30 + cs * v31
    lam[0], lam[1], lam[2], lam[3] = h00, h11, h22, h33
    V[0, 0], V[0, 1], V[0, 2], V[0, 3] = v00, v01, v02, v03
    V[1, 0], V[1, 1], V[1, 2], V[1, 3] = v10, v11, v12, v13
    V[2, 0], V[2, 1], V[2, 2], V[2, 3] = v20, v21, v22, v23
    V[3, 0], V[3, 1], V[3, 2], V[3, 3] = v30, v31, v32, v33
    _sort_eigen(lam, V, np.int64(4))  # not the literal: one compiled _sort_eigen


@inline_kernel
def _jacobi2(H, lam, V):  # type: ignore[no-untyped-def]
    """:func:`_jacobi4` for a 2 x 2 ``H`` (one camera's ``J_x J_x^T``). Its one rotation zeroes the
    only off-diagonal entry, so the general loops' second sweep always stops at its test: one
    test, at most one rotation (where the test fails, ``h01^2`` is above the skip threshold)."""
    h00, h01, h11 = H[0, 0], H[0, 1], H[1, 1]
    v00, v01, v10, v11 = 1.0, 0.0, 0.0, 1.0
    off = h01 * h01
    diag = h00 * h00 + h11 * h11
    if not (off <= 1e-24 * diag or off == 0.0):
        cs, sn, tt, keep = _jacobi_angle(h00, h11, h01, 1e-24 * diag / 4.0)  # pair (0, 1)
        h00, h11 = h00 - tt * h01, h11 + tt * h01
        v00, v01 = cs * v00 - sn * v01, sn * v00 + cs * v01
        v10, v11 = cs * v10 - sn * v11, sn * v10 + cs * v11
    lam[0], lam[1] = h00, h11
    V[0, 0], V[0, 1] = v00, v01
    V[1, 0], V[1, 1] = v10, v11
    _sort_eigen(lam, V, np.int64(2))


@inline_kernel
def _sort_eigen(lam, V, f):  # type: ignore[no-untyped-def]
    """``lam[:f]`` ascending by insertion sort, the columns of ``V[:f, :f]`` with them."""
    for i in range(1, f):
        j = i
        while j > 0 and lam[j - 1] > lam[j]:
            lam[j - 1], lam[j] = lam[j], lam[j - 1]
            for k in range(f):
                V[k, j - 1], V[k, j] = V[k, j], V[k, j - 1]
            j -= 1


@inline_kernel
def _capped(dx, sw, m):  # type: ignore[no-untyped-def]
    """The step ``dx`` (scaled unknowns) as ``(big, scale)``: its largest change of one unknown
    and the factor that caps that at :data:`MAX_STEP`."""
    big = 0.0
    for v in range(m):
        big = max(big, abs(dx[v] / sw[v]))
    return big, (1.0 if big <= MAX_STEP else MAX_STEP / big)


@inline_kernel
def _policy_allowance(dx, sw, scale, gain, m):  # type: ignore[no-untyped-def]
    """The rise of ``|r|^2`` a policy step ``scale dx`` may cause (its null-space move's second
    order): 1e-2 of its squared length (at most 1), times the gain."""
    allowance = 0.0
    for v in range(m):
        d = dx[v] / sw[v] * scale
        allowance += d * d
    return min(allowance, 1.0) * 1e-2 * min(1.0, gain)


@inline_kernel
def _version(vc, vw_ref, u):  # type: ignore[no-untyped-def]
    """The version ``c . (u - home)`` of the zero-version task (``vw_ref = c . home``)."""
    ver = -vw_ref
    for v in range(u.shape[0]):
        ver += vc[v] * u[v]
    return ver


@inline_kernel
def _zero_version_gain(aa, ab, ver, vr, vw_w, gain):  # type: ignore[no-untyped-def]
    """The null move's coefficient ``k`` along ``P c_x`` of the zero-version task, from ``aa =
    |P c_x|^2`` and ``ab = P c_x . z`` (sums over the null directions), the version ``ver`` and
    what the pointing step moves it by, ``vr``. Sherman-Morrison on ``(I + w a a^T) z = -(b + w a
    (ver + vr))``, without the ``w^2`` terms: the version after the whole step is zero. The
    polish (``gain == 0``) zeroes the version alone (the least null move), and only where the
    policy phase left it near zero."""
    if gain > 0.0 or abs(ver) <= VERSION_POLISH:
        if gain == 0.0:
            ab = 0.0
        return vw_w * (ab - ver - vr) / (1.0 + vw_w * aa)
    return 0.0


@inline_kernel
def _product(A, B, out, n):  # type: ignore[no-untyped-def]
    """``out[:n, :n] = A[:n, :n] B[:n, :n]``."""
    for a in range(n):
        for c in range(n):
            s = 0.0
            for k in range(n):
                s += A[a, k] * B[k, c]
            out[a, c] = s


@inline_kernel
def _eigh_warm(H, n, lam, V, Vp, Hb, warm, keep):  # type: ignore[no-untyped-def]
    """:func:`jacobi_eigh` of ``H[:n, :n]``, warm-started from the eigenvectors in ``Vp`` when
    ``warm`` (the last step's, every unknown free): in that basis ``H`` is nearly diagonal, so the
    sweeps are few, and the eigenvectors are then ``Vp`` times those found. ``keep``: ``Vp``
    takes the result (for the next step's warm start)."""
    if warm:
        _product(H, Vp, Hb, n)
        for a in range(n):  # H = Vp^T (H Vp), symmetric
            for c in range(a, n):
                s = 0.0
                for k in range(n):
                    s += Vp[k, a] * Hb[k, c]
                H[a, c] = s
                H[c, a] = s
        jacobi_eigh(H, n, lam, V)
        _product(Vp, V, Hb, n)
        for a in range(n):
            for c in range(n):
                V[a, c] = Hb[a, c]
    else:
        jacobi_eigh(H, n, lam, V)
    if keep:
        for a in range(n):
            for c in range(n):
                Vp[a, c] = V[a, c]


@inline_kernel
def _null_cut(lam, n, null_rel):  # type: ignore[no-untyped-def]
    """The eigenvalue at or below which a direction of the step's decomposition (``n``
    eigenvalues ``lam``, ascending) is in the pointing task's null space: ``null_rel`` of the
    largest. The step (both forms) and the minimum viewing distance's null part share it."""
    return null_rel * max(lam[n - 1], 1e-300)


@inline_kernel
def _range_direction(J, W, root, e, M, f, idx, sw, v):  # type: ignore[no-untyped-def]
    """``v[:f]``: the range direction ``v_e = J_x^T w_e / sqrt(l_e)`` (``root = sqrt(l_e)``) of
    ``J_x^T J_x`` over the free unknowns ``idx[:f]``, from the eigenvector ``w_e`` (column ``e``
    of ``W``) of ``J_x J_x^T`` (``J_x = J / sw``)."""
    for a in range(f):
        va = idx[a]
        t = 0.0
        for i in range(M):
            t += J[i, va] * W[i, e]
        v[a] = t / (root * sw[va])


@inline_kernel
def _step_from_rows(J, r, W, lam, M, f, idx, sw, u, u_ref, vc, vw_w, vw_ref, null_rel, mu, gain, accelerate, v, pz,
                    pc, dx, dn):  # type: ignore[no-untyped-def]
    """:func:`_iterate`'s step (added to ``dx``, its null move to ``dn`` if ``accelerate``) when
    the free unknowns ``idx[:f]`` outnumber the ``M`` residual rows, from ``J_x J_x^T = W diag(l)
    W^T`` (``J_x = J / sw``): the range directions of ``J_x^T J_x`` are ``v_e = J_x^T w_e /
    sqrt(l_e)`` (:func:`_range_direction`, each in turn in ``v``), its null directions are everything orthogonal to them, and
    each null-space sum of the column form is a projection by ``P = I - sum_e v_e v_e^T``. The
    same step as the column form's, from an M x M eigen-problem instead of f x f. Returns the
    null move's squared length.

    The pointing step along ``v_e`` is ``-v_e (v_e . g) / (l_e + mu)`` (``g = J_x^T r_t``), with
    ``v_e . g`` taken as ``sqrt(l_e) (w_e . r_t)``, ``r_t`` the residual in the rows' tangent
    bases (:func:`_tangent_residual`). That keeps the Jacobi sweeps' error out of a weak
    direction's step: they stop with off-diagonal terms ~1e-12 of ``l_max``, so a weak ``w_e``
    holds ~1e-12 of the strong eigenvectors, and from ``J_x^T w_e`` ``v_e . g`` would move by
    ~1e-12 ``l_max |r| / sqrt(l_e)``. iCub's pointing Jacobian loses rank at its answers (a 4th
    eigenvalue 1e-11..1e-8 of ``l_max``, just above the cut): taken so, 2 of 2,000 targets ended
    at a limit. (With three rows a camera, ``r`` itself moved a weak step by that fraction of
    its radial part ``(u . r) u``, along the zero eigenvalues: up to 0.3 of their unit direction.)
    """
    cut = _null_cut(lam, M, null_rel)
    for a in range(f):  # the policy's offset z = sw (u - u_ref) and the version row c_x = c / sw
        va = idx[a]
        pz[a] = sw[va] * (u[va] - u_ref[va])
        pc[a] = vc[va] / sw[va]
    vr = 0.0
    for e in range(M):
        if lam[e] <= cut:
            continue
        root = math.sqrt(lam[e])
        _range_direction(J, W, root, e, M, f, idx, sw, v)
        a_e = 0.0
        bz = 0.0
        for a in range(f):
            a_e += v[a] * pc[a]
            bz += v[a] * pz[a]
        # the pointing step along v_e (Gauss-Newton, damped) and the version it moves by; z and
        # c_x lose their v_e component (Gram-Schmidt, one range direction at a time)
        s = 0.0
        for c in range(M // 2):  # w_e . r_t
            rt1, rt2 = _tangent_residual(r, c)
            s += W[2 * c, e] * rt1 + W[2 * c + 1, e] * rt2
        s = -root * s / (lam[e] + mu)
        vr += a_e * s
        for a in range(f):
            dx[idx[a]] += v[a] * s
            pz[a] -= bz * v[a]
            pc[a] -= a_e * v[a]
    # the zero-version task over the null space (as the column form, whose sums over the null
    # directions of a_e^2 and a_e b_e are |P c_x|^2 and P c_x . z)
    kv = 0.0
    if vw_w > 0.0:
        aa = 0.0
        ab = 0.0
        for a in range(f):
            aa += pc[a] * pc[a]
            ab += pc[a] * pz[a]
        kv = _zero_version_gain(aa, ab, _version(vc, vw_ref, u), vr, vw_w, gain)
    # the null move: -gain P z + k P c_x (the column form's sum of v_e s_e over the null directions)
    k = (gain if gain > 0.0 else 1.0) * kv
    vmove = 0.0
    for a in range(f):
        s = -gain * pz[a] + k * pc[a]
        vmove += s * s
        dx[idx[a]] += s
        if accelerate:
            dn[idx[a]] += s
    return vmove


@inline_kernel
def _null_part(J, V, lam, rows, M, f, idx, sw, null_rel, a, v, pa):  # type: ignore[no-untyped-def]
    """``pa[:f]``: the part of ``a`` (scaled unknowns, shape (m,)) in the null space the policy
    moves in, over the free unknowns ``idx[:f]``, from the step's decomposition (``V``,
    ``lam``): in the column form the sum of ``v_e (v_e . a)`` over its null directions, in the
    rows form (``rows``) ``a`` less its range part ``v_e (v_e . a)``, ``v_e = J_x^T w_e /
    sqrt(l_e)`` (:func:`_range_direction`, each in turn in ``v``). Returns ``|pa|^2``."""
    if rows:
        cut = _null_cut(lam, M, null_rel)
        for i in range(f):
            pa[i] = a[idx[i]]
        for e in range(M):
            if lam[e] <= cut:
                continue
            _range_direction(J, V, math.sqrt(lam[e]), e, M, f, idx, sw, v)
            va = 0.0
            for i in range(f):
                va += v[i] * a[idx[i]]
            for i in range(f):
                pa[i] -= va * v[i]
    else:
        cut = _null_cut(lam, f, null_rel)
        for i in range(f):
            pa[i] = 0.0
        for e in range(f):
            if lam[e] <= cut:
                va = 0.0
                for i in range(f):
                    va += V[i, e] * a[idx[i]]
                for i in range(f):
                    pa[i] += V[i, e] * va
    aa = 0.0
    for i in range(f):
        aa += pa[i] * pa[i]
    return aa


@inline_kernel
def _hold_off(J, V, lam, rows, M, f, idx, sw, null_rel, Pc, d_min, vc, vw_w, accelerate, v, pa, a, cx, pc, dx,
              dn):  # type: ignore[no-untyped-def]
    """The minimum viewing distance ``d_min`` [m] of the policy phase, applied to the step
    ``dx`` (and to its null move in ``dn`` if ``accelerate``). Returns whether it held the step.

    Without it a camera on an arm is walked onto its target: the pointing task's null space
    includes sliding the camera along its optical axis, and where the policy's nearest posture
    lies beyond the target, the walk ends with the camera on it.

    ``a`` is the gradient of the distance of the solved camera nearest the target (``Pc``:
    :func:`residual`) by the scaled unknowns, ``P a`` its part in the null space
    (:func:`_null_part`): moving along ``P a`` changes the distance and, to first order, not the
    pointing. The hold acts where the step, capped at :data:`MAX_STEP`, would take the camera
    nearer than ``d_min`` to first order, and the null move alone would too. The null move then
    gains ``k P a``, with ``k`` such that the null move ends at ``d_min``; the whole step is then
    capped as any other (not the gain alone: capped on its own, it cancelled a policy pull along
    ``P a`` as long as itself, and the walk stopped 0.1 m short of a stated 0.3 m). Held so, the
    policy walks along the distance's level set to the nearest posture there.

    - The pointing step's own change of the distance is not held: far from fixation it is large
      and its first-order prediction poor (held against it, a Panda target took 60 iterations of
      steps halved 7 times). The next step's null move takes back what it took.
    - Judged on the capped step, a long walk towards a home beyond the target is held only once it
      nears ``d_min``. Held from its first step, the walk along the curved level set had its steps
      halved: of 8,000 Panda targets, the one that ends at the iteration cap nearer than ``d_min``
      ended 0.047 m from its target (0.070 m so).
    - With the zero-version task (``vw_w > 0``) ``P a`` loses its part along ``P c_x``: the task
      outranks the distance (held against it, the nominal IIS-head's cyclopean answers to targets
      nearer than ``d_min`` turned the version by up to 0.15 rad).
    - Nothing where the null space cannot move the distance (``|P a|^2`` at most
      :data:`DISTANCE_REACH` ``|a|^2``: a pan-tilt, most binocular postures).
    - ``d`` and ``a`` are taken where ``J`` was (``Pc`` columns 4 on): a probe that ends on a
      refused trial leaves that trial's distance in columns 0-3.

    Scratch: ``v``, ``pa``, ``pc`` (f,), ``a``, ``cx`` (m,)."""
    S = Pc.shape[0]
    m = dx.shape[0]
    near = 0
    for s in range(1, S):
        if Pc[s, 4] < Pc[near, 4]:
            near = s
    d = Pc[near, 4]  # at the Jacobian's u (columns 0-3 may hold a refused trial's)
    if d < MIN_TARGET_DISTANCE:  # on the camera centre: no gradient
        return False
    ahead = 0.0
    for w in range(m):
        a[w] = Pc[near, 5 + w] / sw[w]
        ahead += a[w] * dx[w]
    if d + _capped(dx, sw, m)[1] * ahead >= d_min:
        return False
    aa = _null_part(J, V, lam, rows, M, f, idx, sw, null_rel, a, v, pa)
    a2 = 0.0
    short = d_min - d  # what the null move leaves: P a . dx is a . (the null move)
    for i in range(f):
        a2 += a[idx[i]] * a[idx[i]]
        short -= pa[i] * dx[idx[i]]
    if short <= 0.0:
        return False
    if vw_w > 0.0:
        # the zero-version task outranks the distance: P a loses its part along P c_x (the
        # nominal IIS-head's null space is one direction, the version's: nothing is left)
        for w in range(m):
            cx[w] = vc[w] / sw[w]
        cc = _null_part(J, V, lam, rows, M, f, idx, sw, null_rel, cx, v, pc)
        c2 = 0.0
        for i in range(f):
            c2 += cx[idx[i]] * cx[idx[i]]
        if cc > DISTANCE_REACH * c2:
            ac = 0.0
            for i in range(f):
                ac += pa[i] * pc[i]
            aa = 0.0
            for i in range(f):
                pa[i] -= ac / cc * pc[i]
                aa += pa[i] * pa[i]
    if aa <= DISTANCE_REACH * a2:
        return False
    k = short / aa  # P a . (k pa) = k |pa|^2: pa is P a less a part orthogonal to it
    for i in range(f):
        t = k * pa[i]
        dx[idx[i]] += t
        if accelerate:
            dn[idx[i]] += t
    return True


@kernel_without_refcounts
def _iterate(ch, p, b, u, u_ref, lower, upper, sw, gain, null_rel, max_it, ws, rr_at_u):  # type: ignore[no-untyped-def]
    """Task-priority Gauss-Newton from ``u`` (updated in place); returns (iterations, |r|^2),
    with the residual and its Jacobian at the returned ``u`` left in the workspace. Given
    ``rr_at_u >= 0`` (the previous phase's return), they are taken from there, not
    re-evaluated; -1.0: evaluated at ``u``. (No argument has a default, and callers pass the
    cap as a runtime int: see :func:`solve_one`.)"""
    JR, Jp, Ja, CR, Co, Jc, Pc, r, J, r2, J2, g, H, V, lam, idx, free, dx, trial, Hb, Vp, eig, s_prev, u_near, acc = ws[:25]
    null_z, null_c = ws[41], ws[42]
    moved_before = False  # s_prev holds the last accepted step of this call (before its scale sigma_prev)
    sigma_prev = 1.0
    # eig[0] > 0: Vp holds the eigenvectors of a recent step with every unknown free (a warm
    # start of the next decomposition, whatever u is now); eig[1] > 0: V, lam are the
    # decomposition of J^T J at this very u, every unknown free (the policy phase ended on a
    # small step without moving: the polish's first step needs no decomposition of its own);
    # eig[2] > 0: stop once u is within SAME_BASIN of u_near (a probe reaching the best answer)
    have_v = eig[0] > 0.0
    exact_v = eig[1] > 0.0 and rr_at_u >= 0.0
    eig[1] = 0.0
    vc = ch[12]
    vw_w, vw_ref, d_min = ch[13][0], ch[13][1], ch[13][2]
    m = u.shape[0]
    M = J.shape[0]  # two rows a solved camera (its tangent basis)
    # the policy phase's Anderson acceleration (heads that fixate exactly, policy = distance
    # from u_ref: the version task's and a disparity head's near-null moves are left as they are);
    # acc rows: the history's unknowns hx and plain steps hf (newest first), their differences
    # to the current ones dXh, dFh, then the plain step d_plain
    accelerate = gain > 0.0 and vw_w == 0.0 and null_rel <= ACCELERATE_NULL_REL and m <= 62
    near_rel = max(ch[13][3], null_rel)  # the null cut near a fixating posture (BINOCULAR_NULL)
    hx, hf = acc[0:HISTORY], acc[HISTORY:2 * HISTORY]
    dXh, dFh, d_plain = acc[2 * HISTORY:3 * HISTORY], acc[3 * HISTORY:4 * HISTORY], acc[4 * HISTORY]
    dn = acc[4 * HISTORY + 1]  # the null (policy) move of the step dx
    nh = 0  # pairs (x, F) in the history
    rr_old = 0.0  # |r|^2 before the last accepted step
    h_free = 0  # the free unknowns of the pairs in the history, as bits
    rr = rr_at_u if rr_at_u >= 0.0 else _residual_hot(ch, u, b, p, r, J, True, JR, Jp, Ja, CR, Co, Jc, Pc)
    it = 0
    while it < max_it:
        if gain == 0.0 and rr <= POLISHED:  # polished: no further step (and its eigen-solve) needed
            ver = _version(vc, vw_ref, u)
            if vw_w == 0.0 or abs(ver) <= VERSION_SETTLED or abs(ver) > VERSION_POLISH:
                break
        it += 1
        nr = near_rel if rr <= NEAR_FIXATION else null_rel  # this iteration's null cut (relative)
        have_g = False  # g = J_x^T r (J_x = J / sw) at this u: the column form's, made once when first needed
        for v in range(m):
            free[v] = 1
        for _ in range(m + 1):  # active set: hold unknowns at a bound that the step pushes out
            # the count of free unknowns; np.int64, not 0: numba's inference first sees the literal 0
            # and compiled seven of the calls below for it too (jacobi_eigh, _eigh_warm, the step's
            # helpers), overloads the solve never used
            f = np.int64(0)
            for v in range(m):
                if free[v]:
                    idx[f] = v
                    f += 1
            for v in range(m):
                dx[v] = 0.0
            if accelerate:  # the null move on its own (the split cap below)
                for v in range(m):
                    dn[v] = 0.0
            vmove = 0.0  # squared length of the null-space (policy) move, scaled
            # more free unknowns than residual rows (a camera on an arm, iCub, TALOS's torso and head):
            # the decomposition is of J_x J_x^T (M x M), whose nonzero eigenvalues are J^T J's
            rows = f > M
            # the null cut: near fixation the structural null direction is among the eigenvalues
            # only with at least as many free unknowns as rows
            cut_rel = nr if f >= M else null_rel
            if f > 0 and f == m and exact_v:
                exact_v = False  # V, lam already hold this decomposition at this u
            elif rows:
                for i in range(M):
                    for j in range(i, M):
                        s = 0.0
                        for a in range(f):
                            va = idx[a]
                            s += J[i, va] * J[j, va] / (sw[va] * sw[va])
                        H[i, j] = s
                        H[j, i] = s
                _eigh_warm(H, M, lam, V, Vp, Hb, f == m and have_v, f == m)
                if f == m:
                    have_v = True
            elif f > 0:
                for a in range(f):
                    for c in range(a, f):
                        s = 0.0
                        for i in range(M):
                            s += J[i, idx[a]] * J[i, idx[c]]
                        s /= sw[idx[a]] * sw[idx[c]]
                        H[a, c] = s
                        H[c, a] = s
                _eigh_warm(H, f, lam, V, Vp, Hb, f == m and have_v, f == m)
                if f == m:
                    have_v = True
            if rows:
                vmove = _step_from_rows(J, r, V, lam, M, f, idx, sw, u, u_ref, vc, vw_w, vw_ref, cut_rel, DAMPING * rr,
                                        gain, accelerate, Hb[0], null_z, null_c, dx, dn)
            elif f > 0:
                if not have_g:  # g = J_x^T r
                    for v in range(m):
                        g[v] = _gradient_entry(J, r, v) / sw[v]
                    have_g = True
                cut = _null_cut(lam, f, cut_rel)
                mu = DAMPING * rr
                # the pointing step along the strong directions (Gauss-Newton, damped), and
                # the version it moves by, vr = c_x . dx_range (the null move makes up for it)
                vr = 0.0
                for e in range(f):
                    if lam[e] > cut:
                        s = 0.0
                        a_e = 0.0
                        for a in range(f):
                            va = idx[a]
                            s += V[a, e] * g[va]
                            a_e += V[a, e] * vc[va] / sw[va]
                        s = -s / (lam[e] + mu)
                        vr += a_e * s
                        for a in range(f):
                            dx[idx[a]] += V[a, e] * s
                # zero-version task over the null directions: a_e = v_e . c_x, c_x = c / sw
                kv = 0.0
                if vw_w > 0.0:
                    aa = 0.0
                    ab = 0.0
                    for e in range(f):
                        if lam[e] <= cut:
                            a_e = 0.0
                            b_e = 0.0
                            for a in range(f):
                                va = idx[a]
                                a_e += V[a, e] * vc[va] / sw[va]
                                b_e += V[a, e] * sw[va] * (u[va] - u_ref[va])
                            aa += a_e * a_e
                            ab += a_e * b_e
                    kv = _zero_version_gain(aa, ab, _version(vc, vw_ref, u), vr, vw_w, gain)
                for e in range(f):
                    if lam[e] <= cut:
                        s = 0.0
                        a_e = 0.0
                        for a in range(f):
                            va = idx[a]
                            s += V[a, e] * sw[va] * (u[va] - u_ref[va])
                            a_e += V[a, e] * vc[va] / sw[va]
                        s = -gain * s + (gain if gain > 0.0 else 1.0) * a_e * kv
                        vmove += s * s
                        for a in range(f):
                            dx[idx[a]] += V[a, e] * s
                        if accelerate:
                            for a in range(f):
                                dn[idx[a]] += V[a, e] * s
            held_off = False
            if d_min > 0.0 and gain > 0.0 and f > 0:
                held_off = _hold_off(J, V, lam, rows, M, f, idx, sw, cut_rel, Pc, d_min, vc, vw_w, accelerate,
                                     null_z, null_c, Hb[0], trial, Hb[1 % m], dx, dn)  # m >= 2 with a version row
            changed = False
            for v in range(m):
                if free[v]:
                    du = dx[v] / sw[v]
                    if (u[v] <= lower[v] + AT_BOUND and du < 0.0) or (u[v] >= upper[v] - AT_BOUND and du > 0.0):
                        free[v] = 0
                        changed = True
            if not changed:
                break
        accel = False
        if accelerate:
            bits = 0  # the history holds for one active set (of the bounds and the viewing distance)
            for v in range(m):
                if free[v]:
                    bits |= 1 << v
            if held_off:
                bits |= 1 << m
            if bits != h_free:
                nh = 0
                h_free = bits
        if nh > 0:
            # safeguard: the history is dropped when the step map grew since its last pair
            # (the acceleration did not bring it nearer its fixed point)
            f_now = 0.0
            f_last = 0.0
            for v in range(m):
                f_now += dx[v] * dx[v]
                f_last += hf[0, v] * hf[0, v]
            if f_now >= f_last:
                nh = 0
        if accelerate and rr <= ACCELERATE_BELOW and vmove > 0.0:
            # the policy phase converges linearly near the answer: its step ignores how the
            # pointing constraint's null space turns (error map e -> -C e, C the derivative of
            # the null projector applied to the answer's offset from the policy's posture).
            # Anderson acceleration (a multisecant quasi-Newton step on the step map
            # F(x) = dx) over the last HISTORY pairs (x_i, F_i): gamma = argmin |F - dF gamma|,
            # step F - (dX + dF) gamma, dX_j = x - x_j, dF_j = F - F_j
            for j in range(nh):
                for v in range(m):
                    dXh[j, v] = sw[v] * u[v] - hx[j, v]
                    dFh[j, v] = dx[v] - hf[j, v]
            # push (x, F) into the history (newest first)
            for j in range(HISTORY - 1, 0, -1):
                for v in range(m):
                    hx[j, v] = hx[j - 1, v]
                    hf[j, v] = hf[j - 1, v]
            for v in range(m):
                hx[0, v] = sw[v] * u[v]
                hf[0, v] = dx[v]
            k = nh
            nh = min(nh + 1, HISTORY)
            if k > 0:
                # normal equations of the small least squares (k <= 2), solved by Cramer
                g11 = 0.0
                g12 = 0.0
                g22 = 0.0
                c1 = 0.0
                c2 = 0.0
                for v in range(m):
                    g11 += dFh[0, v] * dFh[0, v]
                    c1 += dFh[0, v] * dx[v]
                    if k > 1:
                        g12 += dFh[0, v] * dFh[1, v]
                        g22 += dFh[1, v] * dFh[1, v]
                        c2 += dFh[1, v] * dx[v]
                ga1 = 0.0
                ga2 = 0.0
                det = g11 * g22 - g12 * g12
                if k > 1 and det > 1e-10 * g11 * g22:
                    ga1 = (c1 * g22 - c2 * g12) / det
                    ga2 = (g11 * c2 - g12 * c1) / det
                elif g11 > 0.0:
                    ga1 = c1 / g11
                if g11 > 0.0:
                    for v in range(m):
                        d_plain[v] = dx[v]
                        dx[v] -= ga1 * (dXh[0, v] + dFh[0, v])
                        if k > 1:
                            dx[v] -= ga2 * (dXh[1, v] + dFh[1, v])
                    accel = True
        else:
            nh = 0
        big, scale = _capped(dx, sw, m)
        if accelerate and not accel and scale < 1.0 and vmove > 0.0 and moved_before and rr > rr_old:
            # a long policy walk that raised the pointing error over its last step is capped on
            # its own, not the pointing step with it: scaled together, the pointing error
            # settles where the walk's drift off the fixating postures balances a fraction of
            # its correction, and the walk circles there (a camera on an arm: 60 iterations)
            big_r = 0.0
            big_n = 0.0
            for v in range(m):
                big_r = max(big_r, abs((dx[v] - dn[v]) / sw[v]))
                big_n = max(big_n, abs(dn[v] / sw[v]))
            if big_r < MAX_STEP:
                tn = (MAX_STEP - big_r) / big_n
                for v in range(m):
                    dx[v] += (tn - 1.0) * dn[v]
                big, scale = _capped(dx, sw, m)
        plain = big * scale
        if accel:  # converged is judged on the plain step (an accelerated one can stagnate)
            plain = 0.0
            for v in range(m):
                plain = max(plain, abs(d_plain[v] / sw[v]))
        if plain < (STEP_TOL if gain == 0.0 else POLICY_STEP_TOL):
            if f == m:  # not moved: the decomposition holds at u for the next phase
                eig[1] = 1.0
            break
        if moved_before and not accel:
            # a Gauss-Newton step that turns back along the last one overshoots (a large
            # residual's curvature, e.g. one free joint against bounded ones: the iterates
            # alternate and converge linearly). Along the last step s' (taken at scale sigma)
            # the steps are rho = s . s' / |s'|^2 of each other; where they fall linearly (a
            # secant of the gradient along s') the minimum is at sigma / (1 - rho) of this step
            dd = 0.0
            pp = 0.0
            for v in range(m):
                dd += dx[v] / sw[v] * s_prev[v]
                pp += s_prev[v] * s_prev[v]
            rho = dd / pp if pp > 0.0 else 0.0
            if rho < -OVERSHOOT:
                scale = min(scale, sigma_prev / (1.0 - max(rho, -10.0)))
        allowance = 0.0  # the policy's null-space move may raise |r|^2 to second order
        if gain > 0.0:
            allowance = _policy_allowance(dx, sw, scale, gain, m)
        elif vmove > 0.0:  # the polish's zero-version move (scaled unknowns)
            allowance = min(vmove, 1.0) * 1e-2
        accepted = False
        limited = False  # the step was cut to take an unknown exactly to its bound (below)
        allow = allowance * scale * scale
        tries = BACKTRACKS + 1 if accel else BACKTRACKS  # the fallback to the plain step is not a halving
        cut_tried = gain == 0.0  # the policy phase's cut at the first bound (below), tried once
        sb = -1.0  # the step's scale at the first bound it reaches (-1: not yet found)
        vb = -1  # the unknown there
        for k in range(tries):
            for v in range(m):
                trial[v] = min(max(u[v] + scale * dx[v] / sw[v], lower[v]), upper[v])
            rr_new = _residual_hot(ch, trial, b, p, r2, J2, False, JR, Jp, Ja, CR, Co, Jc, Pc)
            if rr_new <= rr + allow or rr_new <= EXACT_RESIDUAL:
                accepted = True
                break
            if accel:  # the accelerated step failed: the plain one (its own allowance), a fresh history
                accel = False
                nh = 0
                for v in range(m):
                    dx[v] = d_plain[v]
                big, scale = _capped(dx, sw, m)
                allowance = _policy_allowance(dx, sw, scale, gain, m)
                allow = allowance * scale * scale
                continue
            if not cut_tried:
                # the plain policy step refused: where it takes a free unknown through its bound,
                # the trial is clipped there and leaves the null space, and |r|^2 grows with the
                # step. Halving on until a trial no longer reaches the bound left the unknown
                # short of it, free again, and the next step pushed it through again: the walk
                # crept on by the halvings' fraction and stopped far from the policy's minimum
                # (iCub, three unknowns at bounds: policy gradient 8e-4 after 17 iterations; a
                # policy walk that freed an unknown a few 1e-5 from its bound ended the phase the
                # same way). So the step is cut at the first bound it reaches (ratio test: it
                # stays in the linearised null space, and that unknown is then at its bound, held
                # by the active set from the next iteration on) where halving would first fall
                # short of that bound, or at the last halving. Not at the first refusal: a bound
                # reached early in a long step (0.6 % of it) cut the step to that fraction, and a
                # calibrated head's walk to an unreachable target's answer crept to the cap. And
                # only near a fixating posture (|r|^2 <= ACCELERATE_BELOW, where the step's null
                # move is the walk): on an unreachable target's large residual, cut before the
                # last halving, TALOS's best answers to 3 of 2,000 random targets were 5-13 deg
                # worse after walks that crept to the cap.
                if sb < 0.0:
                    sb = scale
                    for v in range(m):
                        du = dx[v] / sw[v]
                        if du < 0.0 and u[v] + sb * du < lower[v]:
                            sb = max((lower[v] - u[v]) / du, 0.0)
                            vb = v
                        elif du > 0.0 and u[v] + sb * du > upper[v]:
                            sb = max((upper[v] - u[v]) / du, 0.0)
                            vb = v
                    if vb < 0:
                        cut_tried = True  # no bound on the way: halving alone
                if vb >= 0 and ((rr <= ACCELERATE_BELOW and 0.5 * scale < sb) or k == tries - 1):
                    cut_tried = True
                    for v in range(m):
                        trial[v] = min(max(u[v] + sb * dx[v] / sw[v], lower[v]), upper[v])
                    du = dx[vb] / sw[vb]
                    trial[vb] = lower[vb] if du < 0.0 else upper[vb]
                    rr_new = _residual_hot(ch, trial, b, p, r2, J2, False, JR, Jp, Ja, CR, Co, Jc, Pc)
                    if rr_new <= rr + allowance * sb * sb or rr_new <= EXACT_RESIDUAL:
                        accepted = True
                        limited = True
                        scale = sb
                        break
            allow *= 0.25
            scale *= 0.5
        if not accepted:
            break
        moved = 0.0
        for v in range(m):
            s_prev[v] = dx[v] / sw[v]
            moved = max(moved, abs(trial[v] - u[v]))
            u[v] = trial[v]
        sigma_prev = scale
        # the secant rule (OVERSHOOT) compares a plain step with the last plain one: not after
        # an accelerated step or a step cut at a bound
        moved_before = not accel and not limited
        rr_old = rr
        rr = residual_at_fk(ch, p, r, J, True, JR, Jp, Ja, CR, Co, Jc, Pc)  # the FK of the trial
        if eig[2] > 0.0:
            near = 0.0
            for v in range(m):
                near = max(near, abs(u[v] - u_near[v]))
            if near < SAME_BASIN:
                break
        if moved < (STEP_TOL if gain == 0.0 else POLICY_STEP_TOL) and not accel and not limited:
            break
        if gain == 0.0 and vmove == 0.0 and rr > rr_old * (1.0 - STALLED):
            break  # a residual that cannot be removed (a bound, disparity): polished to the floor
    eig[0] = 1.0 if have_v else 0.0
    return it, rr


@inline_kernel
def _carve(buf, o, n):  # type: ignore[no-untyped-def]
    """The ``n`` elements of ``buf`` from offset ``o`` (a view), and the offset after them."""
    return buf[o:o + n], o + n


@inline_kernel
def _sizes(I):  # type: ignore[no-untyped-def]
    """``(K, C, S, m, G, n_top)`` of a workspace for the packed head whose ints are ``I``
    (:func:`pack_flat`): its joints, cameras, solved axes, unknowns, table entries and starts
    per target."""
    return I[0], I[1], I[2], I[3], I[4], I[6] + 1


@kernel
def _new_buffers(sizes):  # type: ignore[no-untyped-def]
    """The two buffers (float, int) a workspace of ``sizes`` (:func:`_sizes`) is carved from
    (:func:`_carve_workspace`), with the values a workspace starts with: no reference posture
    cached (``best_starts``), no warm eigenvectors (``_iterate``), equal weights."""
    K, C, S, m, G, n_top = sizes
    M = 2 * S  # the Jacobian's rows (the residual has 3 S)
    f = np.empty(9 * K + 3 * K + 3 * K + 9 * C + 3 * C + 6 * K + (5 + m) * S + 3 * S + M * m + 3 * S + M * m + m
                 + 4 * m * m + m + m + m + 3 + m + m + (4 * HISTORY + 2) * m + m + G + 1 + 3 + K + m + m + n_top * m
                 + m + S + m + S + m + m + S + m + m + m + m + K + 6 + G + 4)
    ints = np.empty(m + n_top + m, dtype=np.int64)
    ws = _carve_workspace(f, ints, sizes)
    ws[43][:] = np.nan  # ref_key: no target's u_ref and b yet
    ws[21][:] = 0.0  # eig
    ws[40][:] = 1.0  # ones
    return f, ints


@kernel
def _workspace(K, C, S, m, G, n_top):  # type: ignore[no-untyped-def]
    """Scratch arrays of one solve (reused from target to target): the chain's K joints, C
    cameras, S solved axes, m unknowns, G table entries and n_top starts per target (0, 0: for
    :func:`fk` and :func:`residual` only), carved from two new buffers (:func:`_new_buffers`)."""
    sizes = (K, C, S, m, G, n_top)
    f, ints = _new_buffers(sizes)
    return _carve_workspace(f, ints, sizes)


@kernel
def scratch(I):  # type: ignore[no-untyped-def]
    """The two buffers (float, int) of a workspace for the packed head whose ints are ``I``
    (:func:`pack_flat`): what :func:`solve_flat` carves its workspace from. ``CompiledGaze``
    keeps one pair per thread, so that a single solve neither allocates nor scores the
    reference posture again (:func:`best_starts`' cache)."""
    return _new_buffers(_sizes(I))


@inline_kernel
def _carve_workspace(f, ints, sizes):  # type: ignore[no-untyped-def]
    """The workspace's 47 arrays as views of the float buffer ``f`` and the int buffer ``ints``
    (:func:`_new_buffers`) for ``sizes`` (:func:`_sizes`); nothing written or allocated. ~0.5 us
    a call on the nominal IIS-head (its reshapes call numba's runtime)."""
    K, C, S, m, G, n_top = sizes
    M = 2 * S
    JR, o = _carve(f, 0, 9 * K)
    Jp, o = _carve(f, o, 3 * K)
    Ja, o = _carve(f, o, 3 * K)
    CR, o = _carve(f, o, 9 * C)
    Co, o = _carve(f, o, 3 * C)
    Jc, o = _carve(f, o, 6 * K)
    Pc, o = _carve(f, o, (5 + m) * S)
    r, o = _carve(f, o, 3 * S)
    J, o = _carve(f, o, M * m)
    r2, o = _carve(f, o, 3 * S)
    J2, o = _carve(f, o, M * m)
    g, o = _carve(f, o, m)
    H, o = _carve(f, o, m * m)
    V, o = _carve(f, o, m * m)
    lam, o = _carve(f, o, m)
    dx, o = _carve(f, o, m)
    trial, o = _carve(f, o, m)
    Hb, o = _carve(f, o, m * m)
    Vp, o = _carve(f, o, m * m)
    eig, o = _carve(f, o, 3)
    s_prev, o = _carve(f, o, m)
    u_near, o = _carve(f, o, m)
    acc, o = _carve(f, o, (4 * HISTORY + 2) * m)
    u, o = _carve(f, o, m)
    score, o = _carve(f, o, G + 1)
    ps, o = _carve(f, o, 3)
    b, o = _carve(f, o, K)
    u_ref, o = _carve(f, o, m)
    u_start, o = _carve(f, o, m)
    starts, o = _carve(f, o, n_top * m)
    u_out, o = _carve(f, o, m)
    e_out, o = _carve(f, o, S)
    u1, o = _carve(f, o, m)
    e1, o = _carve(f, o, S)
    best_start, o = _carve(f, o, m)
    u2, o = _carve(f, o, m)
    e2, o = _carve(f, o, S)
    ones, o = _carve(f, o, m)
    null_z, o = _carve(f, o, m)
    null_c, o = _carve(f, o, m)
    ref_key, o = _carve(f, o, m + K)
    ref_axis, o = _carve(f, o, 6)
    ref_cost, o = _carve(f, o, G)
    vw_plain, o = _carve(f, o, 4)
    return (
        JR.reshape((K, 3, 3)),
        Jp.reshape((K, 3)),
        Ja.reshape((K, 3)),
        CR.reshape((C, 3, 3)),
        Co.reshape((C, 3)),
        Jc.reshape((6, K)),
        Pc.reshape((S, 5 + m)),
        r,
        J.reshape((M, m)),
        r2,
        J2.reshape((M, m)),
        g,
        H.reshape((m, m)),
        V.reshape((m, m)),
        lam,
        ints[0:m],  # idx
        ints[m + n_top:m + n_top + m],  # free (1: free, 0: held at a bound)
        dx,
        trial,
        Hb.reshape((m, m)),
        Vp.reshape((m, m)),
        eig,  # see _iterate
        s_prev,  # see _iterate
        u_near,  # see _iterate
        acc.reshape((4 * HISTORY + 2, m)),  # see _iterate
        u,  # see solve_one
        score,  # see best_starts
        ints[m:m + n_top],  # top_g: the starts chosen (see best_starts, further_start)
        ps,  # see _solve_into
        b,  # see _solve_into
        u_ref,  # see _solve_into
        u_start,  # see _solve_into
        starts.reshape((n_top, m)),  # see _solve_into
        u_out,  # see _solve_into
        e_out,  # see _solve_into
        u1,  # see _solve_into
        e1,  # see _solve_into
        best_start,  # see _solve_into
        u2,  # see _solve_into
        e2,  # see _solve_into
        ones,  # equal weights: see _solve_into
        null_z,  # see _step_from_rows
        null_c,  # see _step_from_rows
        ref_key,  # see best_starts
        ref_axis,  # see best_starts
        ref_cost,  # see best_starts
        vw_plain,  # the chain without its zero-version task: see _without_version
    )


@kernel
def pointing_error(x, y, z):  # type: ignore[no-untyped-def]
    """Angle [rad] between the optical axis and a target at ``(x, y, z)`` in the camera frame
    (scaled first: no overflow for any finite coordinates); pi on the centre."""
    big = max(abs(x), abs(y), abs(z))
    if big == 0.0 or not big < np.inf:
        return math.pi if big == 0.0 else math.atan2(math.hypot(x, y), z)
    if big < MIN_TARGET_DISTANCE:
        return math.pi
    x, y, z = x / big, y / big, z / big
    return math.atan2(math.sqrt(x * x + y * y), z)


@kernel_without_refcounts
def solve_one(ch, p_solve, p, b, u_ref, lower, upper, sw, starts, table_from, table_u, null_rel, tol, max_it,
              disparity_head, baseline, u_out, err_out, ws, rr_to_beat):  # type: ignore[no-untyped-def]
    """One target: the policy phase, then pointing alone, from the best start of ``starts``
    (rows, best first); a further start only if the answer is neither fixated nor decided by
    geometry (behind, too close). Rows from ``table_from`` on are the table's starts: the first
    is given (:func:`best_starts`), the others picked when reached (:func:`further_start`), so a
    target fixated from its first start pays for no other. Given a finite ``rr_to_beat`` (|r|^2
    of the answer already in ``u_out``), every start is probed and kept only if it does better.
    Returns ``(iterations, status)``; ``u_out`` the readings, ``err_out`` (S,) the solved
    cameras' pointing errors [rad] on ``p``."""
    JR, Jp, Ja, CR, Co, Jc, Pc, r, J = ws[0], ws[1], ws[2], ws[3], ws[4], ws[5], ws[6], ws[7], ws[8]
    m = u_ref.shape[0]
    S = err_out.shape[0]
    solve_cams = ch[11]
    u = ws[25]
    best_rr = rr_to_beat
    total = 0
    # every call below compiles to one _iterate (~85 kB of machine code): numba types a module
    # constant as a literal and an omitted argument as its default, and compiles a copy of the
    # callee for each. Four copies, before, took half the cold compile (183 -> 87 s without)
    # (tests/test_gaze.py::test_every_kernel_is_compiled_for_one_signature)
    probe_it, polish_it = np.int64(PROBE_ITERATIONS), np.int64(POLISH_ITERATIONS)
    n_rows = starts.shape[0]
    for k in range(n_rows):
        if k > table_from:
            further_start(k - table_from, n_rows - table_from, u_ref, sw, table_u, ws[26], ws[27], starts[k])
        for v in range(m):
            u[v] = starts[k, v]
        if k == 0 and best_rr == np.inf:
            it1, rr = _iterate(ch, p_solve, b, u, u_ref, lower, upper, sw, SECONDARY_GAIN, null_rel, max_it, ws,
                               -1.0)
        else:
            # a further start is probed first: it goes on only if it already does better than
            # the best answer so far (an unreachable target costs a few iterations per start,
            # not a full solve each)
            u_near = ws[23]
            for v in range(m):
                u_near[v] = u_out[v]
            ws[21][2] = 1.0
            it1, rr = _iterate(ch, p_solve, b, u, u_ref, lower, upper, sw, SECONDARY_GAIN, null_rel,
                               probe_it, ws, -1.0)
            ws[21][2] = 0.0
            near = 0.0
            for v in range(m):
                near = max(near, abs(u[v] - u_out[v]))
            if near < SAME_BASIN:  # on its way to the best answer: nothing new
                total += it1
                continue
            if it1 == probe_it:
                if rr >= best_rr:
                    total += it1
                    continue
                it1b, rr = _iterate(ch, p_solve, b, u, u_ref, lower, upper, sw, SECONDARY_GAIN, null_rel,
                                    max_it - probe_it, ws, rr)
                it1 += it1b
        # polish: pointing alone (same near-null space), to the rounding floor
        it2, rr = _iterate(ch, p_solve, b, u, u_ref, lower, upper, sw, 0.0, null_rel, polish_it, ws, rr)
        total += it1 + it2
        if rr < best_rr:
            best_rr = rr
            for v in range(m):
                u_out[v] = u[v]
        if best_rr <= EXACT_RESIDUAL * 1e8:
            break
        if disparity_head:  # the near-null posture: no other start (see the module's docs)
            break
        # decided by geometry at this answer? (evaluated below on the best one)
        residual(ch, u_out, b, p_solve, r, J, False, JR, Jp, Ja, CR, Co, Jc, Pc)
        decided = False
        for s in range(S):
            if Pc[s, 2] <= 0.0 or Pc[s, 3] < baseline:
                decided = True
        if decided:
            break
    # the answer, judged on the target itself
    fk(ch, u_out, b, JR, Jp, Ja, CR, Co)
    fixated = True
    behind = False
    close = False
    for s in range(S):
        c = solve_cams[s]
        dx, dy, dz = p[0] - Co[c, 0], p[1] - Co[c, 1], p[2] - Co[c, 2]
        big = max(abs(dx), abs(dy), abs(dz))
        if big > 1e150:  # scaled by a power of two: no overflow in the rotation
            f = math.ldexp(1.0, -math.frexp(big)[1])
            dx, dy, dz = dx * f, dy * f, dz * f
        else:
            f = 1.0
        x = CR[c, 0, 0] * dx + CR[c, 1, 0] * dy + CR[c, 2, 0] * dz
        y = CR[c, 0, 1] * dx + CR[c, 1, 1] * dy + CR[c, 2, 1] * dz
        z = CR[c, 0, 2] * dx + CR[c, 1, 2] * dy + CR[c, 2, 2] * dz
        e = pointing_error(x, y, z)
        err_out[s] = e
        dist = math.sqrt(x * x + y * y + z * z) / f
        if e > tol:
            fixated = False
        if f == 1.0 and dist < MIN_TARGET_DISTANCE:
            close = True
        elif z <= 0.0:
            behind = True
        elif dist < baseline:
            close = True
    if fixated:
        return total, S_FIXATED
    if close:
        return total, S_TOO_CLOSE
    if behind:
        return total, S_BEHIND
    for v in range(m):
        if lower[v] < upper[v] and (u_out[v] <= lower[v] + AT_BOUND or u_out[v] >= upper[v] - AT_BOUND):
            return total, S_LIMITS
    if disparity_head:
        return total, S_DISPARITY
    return total, S_NO_SOLUTION


@kernel_without_refcounts
def best_starts(ch, p, b, u_ref, sw, table_u, table_o, table_z, out, ws):  # type: ignore[no-untyped-def]
    """The start that best faces target ``p`` (into ``out`` (m,)) among ``u_ref`` and the table
    entries (unknowns ``table_u`` (m, G), cyclopean centre ``table_o`` and axis ``table_z`` (3,
    G), world; one column per entry), by the cosine of the angle between their axis and the
    target direction, less a small cost of their distance (scaled) from ``u_ref``
    (:data:`START_DISTANCE`; :data:`START_DISTANCE_REDUNDANT` on a one-camera head with spare
    joints). The scores stay in the workspace for :func:`further_start`. They are computed
    column-wise (loops the compiler vectorises), then the best picked. ``u_ref``'s centre and
    axis and each entry's distance cost stay in the workspace too (``ws[43:46]``), keyed by
    ``u_ref`` and ``b``: a batch's targets share them. A workspace serves one packed head (its
    table, ``sw`` and chain), so the key needs nothing else."""
    JR, Jp, Ja, CR, Co = ws[0], ws[1], ws[2], ws[3], ws[4]
    m, G = table_u.shape
    solve_cams = ch[11]
    S = solve_cams.shape[0]
    key, axis, cost = ws[43], ws[44], ws[45]
    K = b.shape[0]
    same = True  # the same u_ref and b as the last target's (a batch's every target, from one q_current)?
    for v in range(m):
        if key[v] != u_ref[v]:  # (a NaN key, as made: never)
            same = False
    for k in range(K):
        if key[m + k] != b[k]:
            same = False
    if not same:  # u_ref's cyclopean centre and axis, and each entry's cost of its distance from u_ref
        for v in range(m):
            key[v] = u_ref[v]
        for k in range(K):
            key[m + k] = b[k]
        fk(ch, u_ref, b, JR, Jp, Ja, CR, Co)
        for i in range(6):
            axis[i] = 0.0
        for s in range(S):
            c = solve_cams[s]
            axis[0] += Co[c, 0] / S
            axis[1] += Co[c, 1] / S
            axis[2] += Co[c, 2] / S
            axis[3] += CR[c, 0, 2]
            axis[4] += CR[c, 1, 2]
            axis[5] += CR[c, 2, 2]
        w0 = START_DISTANCE_REDUNDANT if S == 1 and m > 3 else START_DISTANCE
        for g in range(G):
            cost[g] = 0.0
        for v in range(m):
            w = w0 * sw[v] * sw[v]
            r = u_ref[v]
            for g in range(G):
                d = table_u[v, g] - r
                cost[g] += w * d * d
    ox, oy, oz, zx, zy, zz = axis[0], axis[1], axis[2], axis[3], axis[4], axis[5]
    # the table's axes are unit vectors and targets are within FAR_TARGET (1e15 m): |p - o|^2
    # cannot overflow, so no scaling in the loop (the start at u_ref is g = G, scored last)
    px, py, pz = p[0], p[1], p[2]
    score = ws[26]
    for g in range(G):
        dx, dy, dz = px - table_o[0, g], py - table_o[1, g], pz - table_o[2, g]
        nd2 = max(dx * dx + dy * dy + dz * dz, 1e-300)
        score[g] = (dx * table_z[0, g] + dy * table_z[1, g] + dz * table_z[2, g]) / math.sqrt(nd2) - cost[g]
    nzr = math.sqrt(zx * zx + zy * zy + zz * zz) + 1e-300
    dx, dy, dz = px - ox, py - oy, pz - oz
    nd2 = dx * dx + dy * dy + dz * dz
    score[G] = (dx * zx + dy * zy + dz * zz) / nzr / math.sqrt(nd2) if nd2 > 0.0 else 0.0
    top_g = ws[27]
    best = -np.inf
    top_g[0] = G
    for g in range(G + 1):
        if score[g] > best:
            best = score[g]
            top_g[0] = g
    _entry(top_g[0], u_ref, table_u, out)


@inline_kernel
def _entry(g, u_ref, table_u, out):  # type: ignore[no-untyped-def]
    """Start ``g`` of :func:`best_starts`' scores into ``out``: a table column, or ``u_ref`` (g = G)."""
    G = table_u.shape[1]
    for v in range(out.shape[0]):
        out[v] = u_ref[v] if g == G else table_u[v, g]


@kernel_without_refcounts
def further_start(j, n_table, u_ref, sw, table_u, score, top_g, out):  # type: ignore[no-untyped-def]
    """The table's ``j``-th start (j >= 1) of ``n_table`` for the target :func:`best_starts`
    scored last (its ``score`` and picks ``top_g``, the workspace's, into which this one goes;
    the start into ``out`` (m,)): the best-scored not chosen before. The last one also
    differs from each table start before it by :data:`DISTINCT_START` in some scaled unknown,
    when any entry does (a warm start before them is not counted): the best-facing entries are
    often one cluster, all in one basin."""
    G = table_u.shape[1]
    g = -1
    if j == n_table - 1:
        g = _best_other(score, top_g, j, True, u_ref, sw, table_u)
    if g < 0:
        g = _best_other(score, top_g, j, False, u_ref, sw, table_u)
    top_g[j] = G if g < 0 else g  # (a table of one entry: u_ref again)
    _entry(top_g[j], u_ref, table_u, out)


@inline_kernel
def _best_other(score, top_g, j, distinct, u_ref, sw, table_u):  # type: ignore[no-untyped-def]
    """The best-scored start (column of ``score``, G + 1) not among ``top_g[:j]``, and, when
    ``distinct``, at least :data:`DISTINCT_START` from each of them in some scaled unknown;
    -1 if none."""
    m, G = table_u.shape
    best = -np.inf
    pick = -1
    for g in range(G + 1):
        if not score[g] > best:  # (and never a NaN score)
            continue
        ok = True
        for i in range(j):
            h = top_g[i]
            if h == g:
                ok = False
                break
            if distinct:
                far = 0.0
                for v in range(m):
                    a = u_ref[v] if g == G else table_u[v, g]
                    c = u_ref[v] if h == G else table_u[v, h]
                    far = max(far, abs(a - c) * sw[v])
                if far < DISTINCT_START:
                    ok = False
                    break
        if ok:
            best = score[g]
            pick = g
    return pick


@kernel_without_refcounts
def solve_single(ch, p_solve, p, b, u_ref, u_start, warm, lower, upper, sw, table_u, table_o, table_z, null_rel,
                 tol, max_it, disparity_head, baseline, starts, u_out, err_out, ws, rr_to_beat):  # type: ignore[no-untyped-def]
    """:func:`solve_one` for one target with preallocated buffers (``starts`` (n_starts + 1, m)):
    from the warm start ``u_start`` first when ``warm`` (e.g. the previous answer while
    tracking), then the table's best starts only if that does not fixate and is not decided
    by geometry. On return ``ws[3]``/``ws[4]`` hold the cameras' rotations and centres at
    ``u_out``. Returns ``(iterations, status)``."""
    n_rows = starts.shape[0]
    m = u_ref.shape[0]
    if warm:
        for v in range(m):
            starts[0, v] = min(max(u_start[v], lower[v]), upper[v])
        best_starts(ch, p_solve, b, u_ref, sw, table_u, table_o, table_z, starts[1], ws)
        return solve_one(ch, p_solve, p, b, u_ref, lower, upper, sw, starts, np.int64(1), table_u, null_rel, tol,
                         max_it, disparity_head, baseline, u_out, err_out, ws, rr_to_beat)
    best_starts(ch, p_solve, b, u_ref, sw, table_u, table_o, table_z, starts[0], ws)
    return solve_one(ch, p_solve, p, b, u_ref, lower, upper, sw, starts[: n_rows - 1], np.int64(0), table_u,
                     null_rel, tol, max_it, disparity_head, baseline, u_out, err_out, ws, rr_to_beat)



# ---- one call per solve from Python: the head and its workspace as flat arrays ----------------
# numba's dispatcher types every argument of a call: the chain's and the workspace's tuples (35
# arrays) cost ~5 us a call, more than the solve's arithmetic. The entry below takes the head as
# one float and one int array (:func:`pack_flat`), views them (:func:`_unpack`, same layout)
# and writes the whole answer (readings, errors, misses, fixation point, vergence, limits) into
# one output array.
I_HEADER = 9  # K, C, S, m, G, n, starts per target, iteration cap, disparity head (0/1)
F_SCALARS = 7  # null_rel, tolerance, baseline, has a zero-version task (0/1), the head's centre (3)


def pack_flat(
    ch: tuple,  # type: ignore[type-arg]
    lower: Array,
    upper: Array,
    sw: Array,
    table: tuple[Array, Array, Array],
    robot: tuple[Array, Array, Array, Array, NDArray[np.floating[Any]]],
    joint_index: NDArray[np.integer[Any]],
    held: NDArray[np.bool_],
    still: NDArray[np.bool_],
    n_starts: int,
    max_it: int,
    null_rel: float,
    tol: float,
    baseline: float,
    disparity_head: bool,
    centre: Array,
) -> tuple[Array, Array]:
    """The head as ``(F, I)`` for :func:`solve_flat`: the chain's tuple ``ch`` (:func:`pack`),
    the unknowns' bounds and scale ``sw``, the start ``table`` (unknowns (m, G), centres and
    axes (3, G)), the ``robot`` map (``robot_A``, ``robot_b``, readings' lower and upper
    limits, ``pinv`` of ``robot_A``), per chain joint its robot index and whether it is held at
    its reading, per robot joint whether the head leaves it still, and the solve's constants
    (``centre``: the point far targets are pulled in towards, world [m], shape (3,))."""
    parent, jtype, axis, R, t, A, b, cam_parent, cam_R, cam_t, anc, solve_cams, c, vw = ch
    table_u, table_o, table_z = table
    robot_A, robot_b, robot_lo, robot_hi, pinv = robot
    K, C, S, m, G, n = len(parent), len(cam_parent), len(solve_cams), len(lower), table_u.shape[1], len(robot_b)
    floats = [axis, R, t, A, b, cam_R, cam_t, c, vw, lower, upper, sw, 0.5 * (lower + upper), table_u, table_o,
              table_z, robot_A, robot_b, robot_lo, robot_hi, pinv,
              np.array([null_rel, tol, baseline, 1.0 if vw[0] > 0.0 else 0.0]), np.asarray(centre, dtype=float)]
    ints = [np.array([K, C, S, m, G, n, n_starts, max_it, int(bool(disparity_head))]), parent, jtype, cam_parent,
            anc, solve_cams, joint_index, held, still]
    F = np.concatenate([np.asarray(x, dtype=float).ravel() for x in floats])
    I = np.concatenate([np.asarray(x).astype(np.int64).ravel() for x in ints])
    return np.ascontiguousarray(F), np.ascontiguousarray(I)


@inline_kernel
def _unpack(F, I):  # type: ignore[no-untyped-def]
    """Views of :func:`pack_flat`'s arrays: ``(ch, lower, upper, sw, home, table_u, table_o,
    table_z, robot_A, robot_b, robot_lo, robot_hi, pinv, scalars, joint_index, held, still)``."""
    K, C, S, m, G, n = I[0], I[1], I[2], I[3], I[4], I[5]
    o = I_HEADER
    parent = I[o:o + K]
    o += K
    jtype = I[o:o + K]
    o += K
    cam_parent = I[o:o + C]
    o += C
    anc = I[o:o + C * K].reshape((C, K))
    o += C * K
    solve_cams = I[o:o + S]
    o += S
    joint_index = I[o:o + K]
    o += K
    held = I[o:o + K]
    o += K
    still = I[o:o + n]
    f = 0
    axis = F[f:f + 3 * K].reshape((K, 3))
    f += 3 * K
    R = F[f:f + 9 * K].reshape((K, 3, 3))
    f += 9 * K
    t = F[f:f + 3 * K].reshape((K, 3))
    f += 3 * K
    A = F[f:f + K * m].reshape((K, m))
    f += K * m
    b = F[f:f + K]
    f += K
    cam_R = F[f:f + 9 * C].reshape((C, 3, 3))
    f += 9 * C
    cam_t = F[f:f + 3 * C].reshape((C, 3))
    f += 3 * C
    c = F[f:f + m]
    f += m
    vw = F[f:f + 4]
    f += 4
    lower = F[f:f + m]
    f += m
    upper = F[f:f + m]
    f += m
    sw = F[f:f + m]
    f += m
    home = F[f:f + m]
    f += m
    table_u = F[f:f + G * m].reshape((m, G))
    f += G * m
    table_o = F[f:f + 3 * G].reshape((3, G))
    f += 3 * G
    table_z = F[f:f + 3 * G].reshape((3, G))
    f += 3 * G
    robot_A = F[f:f + n * m].reshape((n, m))
    f += n * m
    robot_b = F[f:f + n]
    f += n
    robot_lo = F[f:f + n]
    f += n
    robot_hi = F[f:f + n]
    f += n
    pinv = F[f:f + m * n].reshape((m, n))
    f += m * n
    scalars = F[f:f + F_SCALARS]
    ch = (parent, jtype, axis, R, t, A, b, cam_parent, cam_R, cam_t, anc, solve_cams, c, vw)
    return (ch, lower, upper, sw, home, table_u, table_o, table_z, robot_A, robot_b, robot_lo, robot_hi, pinv,
            scalars, joint_index, held, still)


def out_size(n: int, S: int) -> int:
    """Length of :func:`solve_flat`'s output for ``n`` robot joints and ``S`` solved axes."""
    return 2 + n + 2 * S + 4 + n + 3


@inline_kernel
def _u_of_q(q, robot_b, pinv, lower, upper, u):  # type: ignore[no-untyped-def]
    """Unknowns ``u`` closest to robot readings ``q`` in least squares, clipped to the bounds
    (:meth:`~cpc2urdf.validation.gaze.chain.HeadChain.u_from_q`)."""
    m, n = pinv.shape
    for v in range(m):
        s = 0.0
        for i in range(n):
            s += pinv[v, i] * (q[i] - robot_b[i])
        u[v] = min(max(s, lower[v]), upper[v])


@inline_kernel
def _aim_point(p, centre, ps):  # type: ignore[no-untyped-def]
    """Writes into ``ps`` (3,) the point the iteration aims at for target ``p``: ``p`` itself, or for a target with a
    coordinate beyond :data:`FAR_TARGET` the point on the ray from ``centre`` through ``p`` at
    that distance. Seen from any camera the two differ in direction by less than the head's
    reach over FAR_TARGET (~1e-15 rad), below the rounding of a direction at that distance;
    beyond it the start table and the policies would square coordinates out of the float
    range. The answer is judged on ``p`` itself."""
    big = max(abs(p[0]), abs(p[1]), abs(p[2]))
    if big <= FAR_TARGET:
        ps[0], ps[1], ps[2] = p[0], p[1], p[2]
        return
    dx, dy, dz = p[0] - centre[0], p[1] - centre[1], p[2] - centre[2]
    big = max(abs(dx), abs(dy), abs(dz))  # components scaled into [-1, 1]: no overflow in the norm
    dx, dy, dz = dx / big, dy / big, dz / big
    k = FAR_TARGET / math.sqrt(dx * dx + dy * dy + dz * dz)
    ps[0], ps[1], ps[2] = centre[0] + k * dx, centre[1] + k * dy, centre[2] + k * dz


@inline_kernel
def _copy(src, dst):  # type: ignore[no-untyped-def]
    """``dst[:] = src`` (1-D, same length), as a loop: no view or temporary."""
    for i in range(src.shape[0]):
        dst[i] = src[i]


@inline_kernel
def _largest(a):  # type: ignore[no-untyped-def]
    """``a.max()`` of a non-empty 1-D array, as a loop."""
    big = a[0]
    for i in range(1, a.shape[0]):
        big = max(big, a[i])
    return big


@inline_kernel
def _without_version(ch, vw):  # type: ignore[no-untyped-def]
    """The chain tuple ``ch`` without its zero-version task (weight 0; the minimum viewing
    distance kept), its task scalars written into ``vw`` (4,): nothing allocated."""
    vw[0] = 0.0
    vw[1] = 0.0
    vw[2] = ch[13][2]
    vw[3] = ch[13][3]
    return (ch[0], ch[1], ch[2], ch[3], ch[4], ch[5], ch[6], ch[7], ch[8], ch[9], ch[10], ch[11], ch[12], vw)


@inline_kernel
def _pointing_stationary(ch, u, b, p, lower, upper, ws):  # type: ignore[no-untyped-def]
    """Whether pointing alone (chain ``ch``) has no descent direction at ``u`` inside the
    bounds: the gradient ``J^T r`` without its components that push an unknown out through the
    bound it is at is at most :data:`STATIONARY` ``|J| |r|`` (a KKT point of the pointing
    error). Leaves the FK at ``u`` in the workspace."""
    JR, Jp, Ja, CR, Co, Jc, Pc, r, J = ws[0], ws[1], ws[2], ws[3], ws[4], ws[5], ws[6], ws[7], ws[8]
    rr = residual(ch, u, b, p, r, J, True, JR, Jp, Ja, CR, Co, Jc, Pc)
    M, m = J.shape
    g2 = 0.0
    j2 = 0.0
    for v in range(m):
        gv = _gradient_entry(J, r, v)
        for i in range(M):
            j2 += J[i, v] * J[i, v]
        if (u[v] <= lower[v] + AT_BOUND and gv > 0.0) or (u[v] >= upper[v] - AT_BOUND and gv < 0.0):
            continue  # descent (-g) pushes u[v] out through its bound
        g2 += gv * gv
    return g2 <= STATIONARY * STATIONARY * j2 * rr


@kernel_without_refcounts
def _solve_into(head, plain, I, ws, p, qin, mode, out):  # type: ignore[no-untyped-def]
    """One target, the whole answer in one call. ``head``: :func:`_unpack` of the packed head
    ``(F, I)``; ``plain``: its chain :func:`_without_version`; ``ws``: a :func:`_workspace` for
    it (reused from target to target: nothing of one solve is read by the next but
    :func:`best_starts`' cache of the reference posture, keyed by it; every buffer of this call
    is one of its arrays); ``p`` (3,): the target (world) [m], finite;
    ``qin`` (2 n,): ``q_current`` then ``q_start``;
    ``mode``: bit 1 ``q_current`` given, bit 2 warm start at ``q_start``, bit 4 the fallback
    without the zero-version task when the first answer is at a limit or has no solution.

    ``out`` (:func:`out_size`): status, iterations, readings (n), pointing errors (S), miss
    distances (S), fixation point (3; NaN when the two axes are parallel or S = 1), vergence,
    per robot joint 1.0 at a limit (n), the target (3). A target with a coordinate that is not
    finite: status :data:`S_NOT_FINITE`, nothing else written (the caller checks it here, not
    in Python: ``GazeSolver.solve`` passes a float array to this call as it is)."""
    if not (math.isfinite(p[0]) and math.isfinite(p[1]) and math.isfinite(p[2])):
        out[0] = S_NOT_FINITE
        return
    (ch, lower, upper, sw, home, table_u, table_o, table_z, robot_A, robot_b, robot_lo, robot_hi, pinv, scalars,
     joint_index, held, still) = head
    K, S, m, n, max_it = I[0], I[2], I[3], I[5], I[7]
    disparity_head = I[8] != 0
    null_rel, tol, baseline = scalars[0], scalars[1], scalars[2]
    eig = ws[21]  # the one state _iterate keeps in the workspace: no warm eigenvectors from another target
    eig[0] = 0.0
    eig[1] = 0.0
    eig[2] = 0.0
    ps, b, u_ref, u_start, starts, u_out, e_out = ws[28], ws[29], ws[30], ws[31], ws[32], ws[33], ws[34]
    _aim_point(p, scalars[4:7], ps)
    has_qc = (mode & 1) != 0
    warm = (mode & 2) != 0
    _copy(ch[6], b)
    _copy(home, u_ref)
    if has_qc:
        _u_of_q(qin[0:n], robot_b, pinv, lower, upper, u_ref)
        for k in range(K):
            if held[k] != 0:
                b[k] = qin[joint_index[k]]
    if warm:
        _u_of_q(qin[n:2 * n], robot_b, pinv, lower, upper, u_start)
    it, st = solve_single(ch, ps, p, b, u_ref, u_start, warm, lower, upper, sw, table_u, table_o, table_z, null_rel,
                          tol, max_it, disparity_head, baseline, starts, u_out, e_out, ws, np.inf)
    if ((mode & 4) != 0 and scalars[3] > 0.0 and (st == S_LIMITS or st == S_NO_SOLUTION)
            and not _pointing_stationary(plain, u_out, b, ps, lower, upper, ws)):
        # the zero-version task can hold a joint at a bound where fixation needs it inside (e.g.
        # pan at 0 with tilt at its limit): the weighted home alone, from the first answer (the
        # constraint gone, the pointing task moves along the direction it held). Not from the
        # table's starts again: they reach the same minima as the first pass did (nominal
        # IIS-head, 300 unreachable targets: 35.4 -> 19.9 iterations on average, the same
        # answers to 3e-13 relative; 40,000 reachable: 6 not fixated without the fallback, 2 with
        # it, as from the table's starts; those 2: below). Only where the task held pointing
        # back: at a first answer where pointing alone has no descent direction inside the
        # bounds (an unreachable target's), neither this nor the rescue below lowered the error
        # by more than 1e-8 relative (23 of 200 bench targets; the rest not at all)
        u1, e1, best_start = ws[35], ws[36], ws[37]
        _copy(u_out, u1)
        _copy(e_out, e1)
        _copy(starts[1 if warm else 0], best_start)
        _copy(u1, starts[0])
        it2, st2 = solve_one(plain, ps, p, b, u_ref, lower, upper, sw, starts[:1], np.int64(0), table_u, null_rel,
                             tol, max_it, disparity_head, baseline, u_out, e_out, ws, np.inf)
        if st2 == S_LIMITS:
            # the weighted home pulls the eyes to their middle so hard that pointing can end in a
            # corner of the bounds (pan at 0, tilt at its limit) where fixation needs an eye at
            # its own bound instead: last, the same task with equal weights from the best start
            # (nominal IIS-head, 40,000 reachable targets: 2 such, both fixated so; 300
            # unreachable: 19.9 -> 25.3 iterations; probed for 8 iterations it fixated neither:
            # the way out of that corner first raises |r|^2)
            u2, e2 = ws[38], ws[39]
            _copy(u_out, u2)
            _copy(e_out, e2)
            _copy(best_start, starts[0])
            it3, st3 = solve_one(plain, ps, p, b, u_ref, lower, upper, ws[40], starts[:1], np.int64(0), table_u, null_rel,
                                 tol, max_it, disparity_head, baseline, u_out, e_out, ws, np.inf)
            it2 += it3
            if st3 == S_FIXATED or _largest(e_out) < _largest(e2):
                st2 = st3
            else:
                _copy(u2, u_out)
                _copy(e2, e_out)
                fk(ch, u_out, b, ws[0], ws[1], ws[2], ws[3], ws[4])  # the cameras at the kept answer
        if st2 != S_FIXATED and _largest(e_out) >= _largest(e1):
            _copy(u1, u_out)
            _copy(e1, e_out)
            fk(ch, u_out, b, ws[0], ws[1], ws[2], ws[3], ws[4])  # the cameras at the kept answer
        else:
            st = st2
        it += it2
    # the report, on the cameras at u_out (ws[3], ws[4])
    out[0] = st
    out[1] = it
    q = out[2:2 + n]
    for i in range(n):
        s = robot_b[i]
        for v in range(m):
            s += robot_A[i, v] * u_out[v]
        q[i] = qin[i] if (has_qc and still[i] != 0) else s
    CR, Co = ws[3], ws[4]
    solve_cams = ch[11]
    o = 2 + n
    for s_ in range(S):
        cam = solve_cams[s_]
        out[o + s_] = e_out[s_]
        dx, dy, dz = p[0] - Co[cam, 0], p[1] - Co[cam, 1], p[2] - Co[cam, 2]
        big = max(abs(dx), abs(dy), abs(dz))
        f = math.ldexp(1.0, -math.frexp(big)[1]) if big > 1e150 else 1.0
        dx, dy, dz = dx * f, dy * f, dz * f
        x = CR[cam, 0, 0] * dx + CR[cam, 1, 0] * dy + CR[cam, 2, 0] * dz
        y = CR[cam, 0, 1] * dx + CR[cam, 1, 1] * dy + CR[cam, 2, 1] * dz
        z = CR[cam, 0, 2] * dx + CR[cam, 1, 2] * dy + CR[cam, 2, 2] * dz
        # the lateral offset in front of the camera, the distance behind it
        out[o + S + s_] = (math.sqrt(x * x + y * y) if z >= 0 else math.sqrt(x * x + y * y + z * z)) / f
    o += 2 * S
    out[o], out[o + 1], out[o + 2], out[o + 3] = np.nan, np.nan, np.nan, 0.0
    if S == 2:
        c0, c1 = solve_cams[0], solve_cams[1]
        d0x, d0y, d0z = CR[c0, 0, 2], CR[c0, 1, 2], CR[c0, 2, 2]
        d1x, d1y, d1z = CR[c1, 0, 2], CR[c1, 1, 2], CR[c1, 2, 2]
        wx, wy, wz = Co[c0, 0] - Co[c1, 0], Co[c0, 1] - Co[c1, 1], Co[c0, 2] - Co[c1, 2]
        aa = d0x * d0x + d0y * d0y + d0z * d0z
        bb = d0x * d1x + d0y * d1y + d0z * d1z
        cc = d1x * d1x + d1y * d1y + d1z * d1z
        den = aa * cc - bb * bb
        if den >= 1e-14:  # the midpoint of the closest points of the two axes
            dd = d0x * wx + d0y * wy + d0z * wz
            ee = d1x * wx + d1y * wy + d1z * wz
            s0 = (bb * ee - cc * dd) / den
            t0 = (aa * ee - bb * dd) / den
            out[o] = 0.5 * (Co[c0, 0] + s0 * d0x + Co[c1, 0] + t0 * d1x)
            out[o + 1] = 0.5 * (Co[c0, 1] + s0 * d0y + Co[c1, 1] + t0 * d1y)
            out[o + 2] = 0.5 * (Co[c0, 2] + s0 * d0z + Co[c1, 2] + t0 * d1z)
        out[o + 3] = math.acos(max(-1.0, min(1.0, bb)))
    o += 4
    for i in range(n):
        out[o + i] = 1.0 if (q[i] <= robot_lo[i] + AT_BOUND or q[i] >= robot_hi[i] - AT_BOUND) else 0.0
    o += n
    out[o], out[o + 1], out[o + 2] = p[0], p[1], p[2]



@kernel_without_refcounts
def solve_flat(F, I, p, qin, mode, out, f, ints):  # type: ignore[no-untyped-def]
    """One target (see :func:`_solve_into`): the entry of ``GazeSolver.solve``. The workspace
    is carved from the buffers ``f`` and ``ints`` (:func:`scratch`), which keep, from call to
    call, the reference posture's scores (:func:`best_starts`); no other call may use them
    at the same time (this one runs without the GIL)."""
    head = _unpack(F, I)
    ws = _carve_workspace(f, ints, _sizes(I))
    _solve_into(head, _without_version(head[0], ws[46]), I, ws, p, qin, mode, out)


@kernel
def solve_flat_many(F, I, T, qin, mode, OUT):  # type: ignore[no-untyped-def]
    """:func:`_solve_into` for every row of ``T`` (N, 3), answers in the rows of ``OUT``:
    ``solve_many``'s answers are ``solve``'s, target by target.

    Serial, without the GIL: ``solve_many`` runs one call per core on its share of the rows
    from Python threads. (numba's ``prange`` kernel took ~105 s of a 120 s cold compile, paid
    by every fresh clone; threads cost nothing to compile.)"""
    head = _unpack(F, I)  # once per batch
    K, C, S, m, G, n_top = _sizes(I)
    ws = _workspace(K, C, S, m, G, n_top)
    plain = _without_version(head[0], ws[46])
    for i in range(T.shape[0]):
        _solve_into(head, plain, I, ws, T[i], qin, mode, OUT[i])


def workspace(chain: HeadChain) -> tuple[Array, ...]:
    """Scratch arrays of one solve on ``chain``."""
    return _workspace(len(chain.parent), len(chain.cam_parent), len(chain.solve_cameras), chain.m, 0, 0)  # type: ignore[no-any-return]


__all__ = [
    "BACKTRACKS",
    "DAMPING",
    "EXACT_RESIDUAL",
    "FAR_TARGET",
    "MAX_STEP",
    "MIN_TARGET_DISTANCE",
    "POLISHED",
    "PROBE_ITERATIONS",
    "POLISH_ITERATIONS",
    "SECONDARY_GAIN",
    "STATIONARY",
    "STEP_TOL",
    "S_BEHIND",
    "S_DISPARITY",
    "S_FIXATED",
    "S_LIMITS",
    "S_NO_SOLUTION",
    "S_NOT_FINITE",
    "S_TOO_CLOSE",
    "best_starts",
    "camera_jacobian",
    "fk",
    "further_start",
    "out_size",
    "pack_flat",
    "solve_flat",
    "solve_flat_many",
    "pack",
    "pointing_error",
    "scratch",
    "residual",
    "residual_at_fk",
    "solve_one",
    "solve_single",
    "workspace",
]
