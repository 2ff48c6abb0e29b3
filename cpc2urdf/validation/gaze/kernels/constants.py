"""Tuning constants, status codes and mode flags of the compiled gaze solve.

Units: [rad] for revolute unknowns, [m] for prismatic ones and distances, [-] for ratios; ``|r|^2``
is the squared pointing residual (``|r| = 2 sin(err / 2)`` a camera). The measurements behind the
values are in CHANGELOG.md and docs/gaze.md.
"""

from __future__ import annotations

MIN_TARGET_DISTANCE = 1e-9  # [m]: closer to a camera centre, a target has no direction
FAR_TARGET = 1e15  # [m]: a target with a coordinate beyond this is solved for by its direction
MAX_STEP = 0.5  # [rad]/[m]: largest change of one unknown per step
BACKTRACKS = 10  # step halvings per iteration
POLISH_ITERATIONS = 12  # iterations of the polish (pointing alone) after the policy phase
PROBE_ITERATIONS = 8  # policy iterations a further start gets before it must beat the best answer
# a polish step that lowers |r|^2 by less than this fraction ends the polish: a removable residual
# falls by orders of magnitude per step, one this slow is left by a bound or the head's disparity
STALLED = 1e-6
SECONDARY_GAIN = 1.0  # [-]: fraction of the policy's (first-order) error removed per step
POLICY_STEP_TOL = (
    1e-5  # [rad]/[m]: a policy step this small ends the policy phase (then pointing alone)
)
DAMPING = 1e-4  # [-]: Levenberg-Marquardt damping, times |r|^2
SAME_BASIN = (
    1e-3  # [rad]/[m]: a probe this close to the best answer (every unknown) is converging to it
)
OVERSHOOT = 0.1  # [-]: a step back along the last one by more than this fraction of it is shortened (secant)
STEP_TOL = 1e-13  # [rad]/[m]: a step this small ends the iteration
VERSION_POLISH = 1e-4  # [rad]: the polish zeroes a version this small (larger: a bound holds it)
EXACT_RESIDUAL = 1e-30  # [-]: |r|^2 below this is exact (pointing error ~1e-15 rad)
POLISHED = 1e-22  # [-]: |r|^2 at which the polish stops (pointing error ~1e-11 rad, 1/100 of the tolerance)
VERSION_SETTLED = 1e-13  # [rad]: a version this small is zero for the polish
AT_BOUND = 1e-12  # [rad]/[m]: an unknown (a reading) this close to a bound (a limit) is at it
# [-]: pointing has no descent direction inside the bounds when |projected J^T r| <= this |J| |r|
# (unreachable answers sit at 0-3e-6, answers held by the zero-version task at 0.06-0.2)
STATIONARY = 1e-4
HISTORY = 2  # pairs (x, step) of the policy phase's Anderson acceleration (its 2x2 solve: 2 only)
ACCELERATE_BELOW = (
    1e-6  # [-]: |r|^2 under which the policy phase is accelerated (pointing error ~1e-3 rad)
)
START_DISTANCE = 0.01  # [-]: best_starts' cost of a start's squared (scaled) distance from u_ref
# the same on a one-camera head with spare joints (a camera on an arm, TALOS), where a start facing
# the target from far off the reference walks far in the null space (fewest iterations at 0.3)
START_DISTANCE_REDUNDANT = 0.3
# [-] (scaled unknowns): a target's last table start differs from each start before it by this much
# in some unknown (further_start): the best-facing entries are often one cluster, in one basin
DISTINCT_START = 0.25
DISTANCE_REACH = 1e-6  # [-]: |P a|^2 / |a|^2 below which the null space does not move a camera's distance (_hold_off)
ACCELERATE_NULL_REL = 1e-9  # [-]: the policy phase is accelerated on heads whose null_rel is at most this (exact null spaces)
# [-]: the null cut near a fixating posture of two eyes whose axes sweep one plane (iCub, the nominal
# IIS-head): their 4th eigenvalue vanishes at fixation and grows with the square of the distance from
# it, so cutting there at null_rel would leave that direction to pointing until the last steps
BINOCULAR_NULL = 1e-9
NEAR_FIXATION = 1e-4  # [-]: |r|^2 under which a posture is near fixation (BINOCULAR_NULL applies)
STRUCTURAL_NULL = 1e-12  # [-]: a 4th eigenvalue at most this of the 1st at every fixating table entry is structural

# status codes of the compiled solve (indices into result.py's STATUSES)
S_FIXATED, S_LIMITS, S_BEHIND, S_TOO_CLOSE, S_NO_SOLUTION, S_DISPARITY = 0, 1, 2, 3, 4, 5
S_NOT_FINITE = (
    -1
)  # solve_flat's answer to a target with a NaN or infinite coordinate (nothing solved)

# the solve's mode: bit flags (solve_flat's ``mode``)
# qin[:n] holds the current readings (the min-motion reference; held joints read there)
MODE_Q_CURRENT = 1
MODE_WARM_START = 2  # qin[n:] holds a start to try first (e.g. the last answer while tracking)
# retry without the zero-version task when the first answer is at a limit or unsolved
MODE_FALLBACK = 4

# the iteration's state flags in the workspace's ``eig`` (3,): > 0 is set
EIG_WARM = 0  # Vp holds the eigenvectors of a recent step with every unknown free (a warm start)
EIG_EXACT = (
    1  # V, lam hold the decomposition at this very u, every unknown free (the polish reuses it)
)
EIG_PROBE = 2  # stop once u is within SAME_BASIN of u_near (a probe reaching the best answer)
