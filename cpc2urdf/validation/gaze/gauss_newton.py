"""Task-priority Gauss-Newton with joint limits as constraints: the gaze solver's iteration.

Priority 1 is fixation (:mod:`cpc2urdf.validation.gaze.fixation`). Steps are
Levenberg-Marquardt damped with ``mu = |r|^2`` and halved while they increase the residual.
Priority 2, the redundancy policy (:mod:`cpc2urdf.validation.gaze.policies`), moves only in the
null space of priority 1. Joint limits: a joint that a step would push past its limit is first
kept still by trading its motion for null-space motion; if fixation itself needs it beyond, it
is held at the limit (active set) and the step is re-solved over the others; it is released when
the gradient pulls it back inside.

Solving fixation alone (``secondary=False``), a watchdog accepts a long step followed by one
correction when the pair lowers the residual.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg.lapack import dsyevd

from cpc2urdf.transforms import Array
from cpc2urdf.validation.gaze.fixation import NULL_EIGENVALUE, FixationState, evaluate_fixation
from cpc2urdf.validation.gaze.head import GazeHead, Index
from cpc2urdf.validation.gaze.policies import secondary_task

MAX_ITERATIONS = 60  # default iteration cap of a solve
MAX_STEP = 0.5  # [rad] or [m]: the largest joint change of one Gauss-Newton step
BACKTRACKS = 8  # step halvings allowed per iteration
STALL_RESIDUAL = 1e-12  # [-]: fixation alone stops when |r1|^2 above this falls < 5 % in 3 steps
PHASE2_DAMPING = 1e-4  # [-]: Levenberg-Marquardt damping factor (x |r1|^2) when solving fixation alone
CONVERGED_RESIDUAL = 1e-30  # [-]: |u_L - e_z|^2 + |u_R - e_z|^2 below which fixation is exact
FLOOR_RESIDUAL = 1e-22  # [-]: ... or below this once steps stop (pointing error ~1e-11 rad)
CONVERGED_STEP = 1e-11  # [rad] or [m]: ... and the policy step is this small


class ActiveSetGaussNewton:
    """The iteration of the gaze solver on one head.

    Args:
        head: The head.
        viewing_distance: ``"use-table"`` policy: cyclopean point to target [m].
    """

    def __init__(self, head: GazeHead, viewing_distance: float) -> None:
        self.head = head
        self.viewing_distance = viewing_distance
        self._syevd = dsyevd

    def iterate(
        self,
        p: Array,
        q: Array,
        q_ref: Array,
        policy: str,
        free: Index,
        max_iterations: int,
        *,
        secondary: bool,
        st: FixationState | None = None,
    ) -> tuple[Array, int, FixationState]:
        """Task-priority Gauss-Newton with an active set of joints held at their limits.

        With ``secondary=False`` only fixation is solved (with light damping), and the loop
        runs until it converges or stalls; with ``secondary=True`` it also stops when the
        fixation residual stops falling (the policy then holds a direction fixation needs).
        ``st`` is the state at ``q`` when the caller has it already.

        The limit tests run on Python floats (``n`` is small): each numpy call on a 6-vector
        costs about as much as the whole float loop.

        Args:
            p: Target (world) [m], shape (3,).
            q: Start readings [rad]/[m], shape (n,), inside the limits.
            q_ref: Reference readings of the policy (``q_current`` or home), shape (n,).
            policy: The redundancy policy.
            free: Indices of the joints the policy lets move.
            max_iterations: Iteration cap.
            secondary: Whether the policy's secondary task is solved too.
            st: The fixation state at ``q``, if the caller has it.

        Returns:
            ``(q, iterations, state)``: the last readings, the iterations used and the fixation
            state at those readings.
        """
        slow = 0
        head = self.head
        evaluate = evaluate_fixation
        lo, hi = head.lower, head.upper
        lo_l, hi_l = head.lower_list, head.upper_list
        n = head.n
        q = q.copy()
        held = np.zeros(n, dtype=bool)
        any_held = False
        use_table = policy == "use-table"
        sec_policy = policy if secondary else None
        prev = math.inf
        it = 0
        if st is None:
            st = evaluate(head, q, p, jacobian=False)
        for it in range(1, max_iterations + 1):  # noqa: B007
            if use_table:
                # world Jacobians of the camera centres at q (data may hold another configuration)
                st.Jo = head.camera_centre_jacobians(q)
            rr = st.rr
            if rr < FLOOR_RESIDUAL and (
                not secondary
                or (policy == "cyclopean" and abs(head.version(q)) < CONVERGED_STEP)
            ):
                break  # fixated, and the policy has nothing left to ask: skip the last step
            q_l = q.tolist()
            if any_held:
                # release held joints whose gradient of |r1|^2 pulls them back inside
                g = st.J.T @ st.r
                held &= ((q <= lo) & (g > 0)) | ((q >= hi) & (g < 0))
                any_held = bool(held.any())
            act = free[~held[free]] if any_held else free
            if act.size == 0:
                break
            block_l = [i for i in range(n) if (q_l[i] <= lo_l[i] or q_l[i] >= hi_l[i]) and not held[i]]
            block = np.array(block_l, dtype=int) if block_l else None
            dq = self.step(sec_policy, q, q_ref, p, st, act, block)
            inside = False  # whether q + dq is known to be inside the limits
            for _ in range(4):
                nq_l = (q + dq).tolist()
                out_l = [i for i in range(n) if nq_l[i] < lo_l[i] or nq_l[i] > hi_l[i]]
                if not out_l:
                    inside = True
                    break
                # sorted-set algebra on lists: np.union1d/setdiff1d cost 10-30 us each at this size
                old_block = set() if block is None else set(block.tolist())
                new_block = old_block.union(out_l)
                if len(new_block) == len(old_block):
                    # The null space cannot keep them inside: fixation itself needs them
                    # beyond the limit. Hold those at a limit (active set); others get a
                    # shortened step below.
                    push = ((q <= lo) & (dq < 0)) | ((q >= hi) & (dq > 0))
                    if not push.any():
                        break
                    held |= push
                    any_held = True
                    block = np.array(sorted(old_block.difference(np.flatnonzero(push).tolist())), dtype=int)
                    act = free[~held[free]]
                    if act.size == 0:
                        dq = np.zeros(n)
                        break
                else:
                    block = np.array(sorted(new_block), dtype=int)
                dq = self.step(sec_policy, q, q_ref, p, st, act, block)
            nq = q + dq
            dq_l = dq.tolist()
            if not inside:
                nq_l = nq.tolist()
                inside = not any(nq_l[i] < lo_l[i] or nq_l[i] > hi_l[i] for i in range(n))
            if not inside:
                # shorten the step to the first limit it meets (projected steps would zig-zag)
                t = [
                    (lo_l[i] - q_l[i]) / dq_l[i] if dq_l[i] < 0 else (hi_l[i] - q_l[i]) / dq_l[i]
                    for i in range(n)
                    if dq_l[i] != 0 and lo_l[i] < q_l[i] < hi_l[i]  # joints at a limit are projected instead
                ]
                if t:
                    dq = dq * max(min(min(t), 1.0), 0.0)
                nq = np.clip(q + dq, lo, hi)
            step = max(map(abs, dq.tolist()))
            if rr < CONVERGED_RESIDUAL or (rr < FLOOR_RESIDUAL and step < CONVERGED_STEP):
                break
            if rr >= prev * (1.0 - 1e-6) and step < 1e-8:
                break  # stalled at a least-squares minimum (unreachable target)
            if secondary and rr > CONVERGED_RESIDUAL and rr > 0.5 * prev:
                slow += 1
                if slow >= 2:
                    break
            elif not secondary and rr > STALL_RESIDUAL and rr > 0.95 * prev:
                slow += 1  # linear convergence to a non-zero minimum: an unreachable target
                if slow >= 6:
                    break
            else:
                slow = 0
            prev = rr
            new = evaluate(head, nq, p, jacobian=False)
            if not secondary and new.rr > rr:
                # Watchdog: a long step along a weakly determined direction (the calibrated
                # head's version) lands off the curved solution set; one corrective step from
                # there usually ends below the start. Accept the pair if it does.
                dq2 = self.step(None, nq, q_ref, p, new, act, None)
                nq2 = np.clip(nq + dq2, lo, hi)
                new2 = evaluate(head, nq2, p, jacobian=False)
                if new2.rr < rr:
                    q, st = nq2, new2
                    continue
            for _ in range(BACKTRACKS):  # halve steps that increase the fixation residual
                rn = new.rr
                if rn <= rr or rn < 1e-20:
                    break
                dq *= 0.5
                nq = np.clip(q + dq, lo, hi)
                new = evaluate(head, nq, p, jacobian=False)
            q = nq
            st = new
        return q, it, st

    def _eigh(self, A: Array) -> tuple[Array, Array]:
        """Eigenvalues (ascending) and eigenvectors of the small symmetric ``A``.

        LAPACK's ``syevd`` (the routine ``np.linalg.eigh`` uses, lower triangle too) called
        through scipy: a third of the call overhead of ``np.linalg.eigh`` at this size.
        """
        lam, V, info = self._syevd(A, compute_v=1, lower=1)
        if info != 0:
            return np.linalg.eigh(A)  # type: ignore[no-any-return]
        return lam, V

    def step(
        self, policy: str | None, q: Array, q_ref: Array, p: Array, st: FixationState, act: Index, block: Index | None = None
    ) -> Array:
        """One task-priority Gauss-Newton step over the joints ``act``, shape (n,).

        Priority 1 (fixation) takes the truncated pseudo-inverse step; priority 2 (policy) moves
        only in the exact null space of priority 1 (eigenvectors of ``J1^T J1`` with eigenvalue
        below :data:`NULL_EIGENVALUE`), and not the joints in ``block`` (held by their limits).
        """
        J1 = st.J[:, act]
        lam, V = self._eigh(J1.T @ J1)
        # Levenberg-Marquardt damping mu = |r1|^2 (Yamashita-Fukushima: quadratic convergence on
        # consistent problems even where J1 is singular). Directions weaker than the damping
        # (or than NULL_EIGENVALUE) belong to the null space: fixation cannot use them now.
        mu = st.rr * (1.0 if policy is not None else PHASE2_DAMPING)
        # eigh sorts lam ascending: the null space is the first k0 columns of V, the range the rest
        lam_l = lam.tolist()
        thr = max(mu, NULL_EIGENVALUE)
        k0 = sum(1 for v in lam_l if v <= thr)
        # d = -V diag(1 / (lam + mu), range only) V^T J1^T r; coefficients as floats (tiny)
        c = (st.r @ J1 @ V).tolist()
        coef = [0.0] * k0 + [-c[j] / (lam_l[j] + mu) for j in range(k0, len(lam_l))]
        d_arr = V @ np.array(coef)
        dl = d_arr.tolist()
        m = len(dl)
        has_block = block is not None and block.size > 0
        if k0 and policy == "cyclopean" and not has_block:
            # Null space of fixation V0 = V[:, :k0]; the policy is one row (version), so
            # A2 = a^T (1, k0) and (a a^T + eps I)^-1 a = a / (|a|^2 + eps). The version row
            # over the active joints: an eye joint held at its limit (not in act) does not move,
            # so it contributes to the version's value only, not to its change.
            act_l = act.tolist()
            head = self.head
            e0, e1, vs = head.e0, head.e1, head.version_sign
            Vl = V.tolist()
            if e0 in act_l and e1 in act_l:  # the version row's entries (both eyes free: the usual case)
                i0, i1 = act_l.index(e0), act_l.index(e1)
                a = [Vl[i0][j] + vs * Vl[i1][j] for j in range(k0)]
                e2 = head.version(q) + (dl[i0] + vs * dl[i1])
            else:
                a = [0.0] * k0
                e2 = head.version(q)
                for joint, weight in ((e0, 1.0), (e1, vs)):
                    if joint in act_l:
                        i = act_l.index(joint)
                        a = [a[j] + weight * Vl[i][j] for j in range(k0)]
                        e2 += weight * dl[i]
            aa = sum(x * x for x in a)
            if aa > 0.0:  # else both eyes are held: the policy has nothing to move
                f = e2 / (aa + (1e-24 if k0 == 1 else 1e-12))
                if k0 == 1:
                    fa = f * a[0]
                    dl = [dl[i] - fa * Vl[i][0] for i in range(m)]
                else:
                    dl = (d_arr - V[:, :k0] @ (f * np.array(a))).tolist()
        elif k0:
            # Null space of fixation (at this damping), in coordinates y: motion V0 @ y.
            d = d_arr
            V0 = V[:, :k0]
            ke = sum(1 for v in lam_l if v <= NULL_EIGENVALUE)  # the exact null space: V[:, :ke]
            blocked = set(block.tolist()) if block is not None else set()
            b = np.array([k for k, j in enumerate(act.tolist()) if j in blocked], dtype=int)  # positions in act
            if b.size:
                # Blocked joints (at a limit) must not move: first trade the fixation step's
                # motion of them for motion in the exact null space (fixation unchanged to
                # first order) as far as possible, then keep the policy off them.
                if ke:
                    Ve = V0[:, :ke]
                    y, *_ = np.linalg.lstsq(Ve[b], -d[b], rcond=1e-9)
                    d = d + Ve @ y
                _, sv, Wt = np.linalg.svd(V0[b], full_matrices=True)
                k = int(np.sum(sv > 1e-9))
                V0 = V0 @ Wt[k:].T  # null space directions that leave the blocked joints still
            if policy is not None and V0.shape[1]:
                r2, J2full = secondary_task(self.head, policy, q, q_ref, p, st, self.viewing_distance)
                if r2.size:
                    A2 = J2full[:, act] @ V0
                    e2v = r2 + J2full[:, act] @ d
                    if A2.shape[0] == 1 and A2.shape[1] == 1:
                        a2 = float(A2[0, 0])
                        y = np.array([-float(e2v[0]) * a2 / (a2 * a2 + 1e-24)])
                    else:
                        M = A2.T @ A2
                        M.flat[:: M.shape[0] + 1] += 1e-12
                        y = -np.linalg.solve(M, A2.T @ e2v)
                    d = d + V0 @ y
            dl = d.tolist()
        out = [0.0] * self.head.n
        for i, v in zip(act.tolist(), dl, strict=True):
            out[i] = v
        big = max(map(abs, dl))
        if big > MAX_STEP:
            s = MAX_STEP / big
            out = [v * s for v in out]
        return np.array(out)


__all__ = [
    "BACKTRACKS",
    "CONVERGED_RESIDUAL",
    "CONVERGED_STEP",
    "FLOOR_RESIDUAL",
    "MAX_ITERATIONS",
    "MAX_STEP",
    "PHASE2_DAMPING",
    "STALL_RESIDUAL",
    "ActiveSetGaussNewton",
]
