"""The reachable region of a head: which targets of a grid the gaze solver fixates, and why not.

A grid of targets in front of the head (a spherical shell or a box, in the *head frame*: the
cameras' mid-point at the home posture, x forward along the mean optical axis, z up against the
cameras' mean y axis (REP-103: y down), y left) is solved in one batch, and every target gets
one of :data:`REGION_CATEGORIES`:

- ``fixated``: every camera points at it;
- ``disparity``: with the head facing it (the cyclopean policy) the two cameras cannot both
  fixate it exactly (a calibrated head's vertical disparity); the answer's pointing error is
  kept. Exact fixation may still exist turned away from the target: ``cpc2urdf gaze ROBOT
  --report`` says how often and how far;
- ``joint_limits``: a joint limit stops the head;
- ``behind``: a camera would have to look away;
- ``too_close``: nearer a camera than the baseline (or on a camera centre);
- ``no_solution``: none of the others.

:func:`reachable_region` returns the points, statuses, categories, errors and readings
(:class:`Region`; :meth:`Region.colours` gives an RGB colour per point for a 3D view);
:func:`draw_region` draws a horizontal and a vertical slice through the head frame's origin
(the grid planes nearest it, their elevation/azimuth or height/offset in the panel titles) and
the pointing error of the horizontal slice's targets not fixated, to a PNG.
"""

from __future__ import annotations

import dataclasses
import io
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import ConfigurationError
from cpc2urdf.files.jsonio import check_output_path, write_atomic
from cpc2urdf.transforms import Array
from cpc2urdf.validation.gaze.chain import mid_limits
from cpc2urdf.validation.gaze.result import (
    STATUS_BEHIND,
    STATUS_FIXATED,
    STATUS_LIMITS,
    STATUS_NO_SOLUTION,
    STATUS_TOO_CLOSE,
    STATUSES,
    GazeSolution,
)

REGION_CATEGORIES: tuple[str, ...] = (
    "fixated",
    "disparity",
    "joint_limits",
    "behind",
    "too_close",
    "no_solution",
)
CATEGORY_COLOURS: dict[str, tuple[float, float, float]] = {  # RGB in [0, 1]
    "fixated": (0.17, 0.63, 0.17),
    "disparity": (1.0, 0.50, 0.05),
    "joint_limits": (0.12, 0.47, 0.71),
    "behind": (0.50, 0.50, 0.50),
    "too_close": (0.58, 0.40, 0.74),
    "no_solution": (0.84, 0.15, 0.16),
}
_CATEGORY_OF_STATUS = {
    STATUS_FIXATED: "fixated",
    STATUS_LIMITS: "joint_limits",
    STATUS_BEHIND: "behind",
    STATUS_TOO_CLOSE: "too_close",
    STATUS_NO_SOLUTION: "no_solution",
}
DEFAULT_RANGE = (
    0.2,
    3.0,
)  # [m]: distances from the head frame's origin (shell) / forward extent (box)
DEFAULT_SAMPLES = (
    16,
    37,
    25,
)  # distances x azimuths x elevations (shell); forward x lateral x vertical (box)
SHELL_AZIMUTH = math.radians(90.0)  # [rad]: the shell spans +-90 deg about forward
SHELL_ELEVATION = math.radians(60.0)  # [rad]: and +-60 deg of elevation
GRID_KINDS = ("shell", "box")
MAX_GRID_TARGETS = (
    1_000_000  # [-]: a grid of more targets is refused (1e6: ~30 s, ~1 GB on the 2-core machine)
)
GRID_RANGE = (
    1e-3,
    1e3,
)  # [m]: NEAR and FAR of a grid lie within (a head's targets; plots of wider spans fail)
PROGRESS_CHUNK = (
    20_000  # [-]: targets solved between two redraws of the progress bar of a large grid
)


class BatchSolver(Protocol):
    """What the region needs of a solver (:class:`~cpc2urdf.validation.gaze.GazeSolver`): its
    Pinocchio ``model``, camera frames, joints and limits, and ``solve`` (``solve_many`` is
    used where the solver has it)."""

    model: Any
    cameras: tuple[str, ...]
    joint_names: tuple[str, ...]
    n: int
    lower: Array
    upper: Array

    def solve(self, p_world: ArrayLike, q_current: Any = None) -> Any:
        """Joint readings that fixate ``p_world``: a :class:`GazeSolution`."""
        ...


@dataclass(frozen=True)
class BatchAnswer:
    """The solver's answers for N targets, as arrays.

    Attributes:
        q: Readings [rad]/[m], shape (N, n).
        reachable: Fixated, shape (N,).
        pointing_error: Per camera [rad], shape (N, cameras).
        status: The solver's status names, shape (N,).
        iterations: Iterations per target, shape (N,).
    """

    q: Array
    reachable: NDArray[np.bool_]
    pointing_error: Array
    status: NDArray[np.str_]
    iterations: NDArray[np.int_]


def solve_batch(
    solver: BatchSolver, targets: ArrayLike, q_current: Array | None = None
) -> BatchAnswer:
    """Solve every target of ``targets`` (world) [m], shape (N, 3), with the default policy from
    ``q_current`` (shape (n,); the joints that do not move stay there; None: the home posture):
    ``solver.solve_many`` where the solver has it, else one ``solve`` each."""
    P = np.asarray(targets, dtype=float)
    if P.ndim != 2 or P.shape[1] != 3:
        raise ConfigurationError(f"targets must have shape (N, 3) [m], got shape {P.shape}")
    solve_many = getattr(solver, "solve_many", None)
    if solve_many is not None:
        b = solve_many(P) if q_current is None else solve_many(P, q_current)
        status = np.asarray(b.status)
        if status.dtype.kind in "iu":  # status codes: names from the batch's table
            status = np.asarray(getattr(b, "status_names", STATUSES))[status]
        return BatchAnswer(
            np.asarray(b.q, dtype=float),
            np.asarray(b.reachable, dtype=bool),
            np.asarray(b.pointing_error, dtype=float),
            status.astype(str),
            np.asarray(b.iterations, dtype=int),
        )
    sols: list[GazeSolution] = [
        solver.solve(p) if q_current is None else solver.solve(p, q_current=q_current) for p in P
    ]
    n = solver.n
    return BatchAnswer(
        np.array([s.q for s in sols]).reshape(len(sols), n),
        np.array([s.reachable for s in sols], dtype=bool),
        np.array([s.pointing_error for s in sols]).reshape(len(sols), -1),
        np.array([s.status for s in sols], dtype=str),
        np.array([s.iterations for s in sols], dtype=int),
    )


def category_of_status(status: str) -> str:
    """The region category (:data:`REGION_CATEGORIES`) of a solver status name."""
    if status.startswith("disparity"):
        return "disparity"
    return _CATEGORY_OF_STATUS.get(status, "no_solution")


@dataclass(frozen=True)
class HeadFrame:
    """The frame the grid is laid out in: origin and axes (world), at the home posture.

    Attributes:
        origin: Mid-point of the camera centres (world) [m], shape (3,).
        R_world_head: Columns x forward (mean optical axis), y left, z up (world), shape (3, 3).
    """

    origin: Array
    R_world_head: Array

    def to_world(self, p_head: Array) -> Array:
        """Points (head frame) [m], shape (..., 3), in world."""
        return self.origin + p_head @ self.R_world_head.T

    def from_world(self, p_world: Array) -> Array:
        """Points (world) [m], shape (..., 3), in the head frame."""
        return (p_world - self.origin) @ self.R_world_head


def head_frame_at(model: Any, cameras: Sequence[str], q: Array) -> HeadFrame:
    """The head frame (module docstring) of the camera frames ``cameras`` of the Pinocchio
    ``model`` at readings ``q`` (shape (nq,)): origin at the cameras' mid-point, x along the sum
    of their optical (z) axes, z against the sum of their image y axes (REP-103: y down)."""
    import pinocchio as pin

    data = model.createData()
    pin.framesForwardKinematics(model, data, np.asarray(q, dtype=float))
    poses = [data.oMf[model.getFrameId(name)].homogeneous for name in cameras]
    origin = np.mean([T[:3, 3] for T in poses], axis=0)
    x = np.sum([T[:3, 2] for T in poses], axis=0)
    down = np.sum([T[:3, 1] for T in poses], axis=0)
    x = x / np.linalg.norm(x)
    z = -(down - (down @ x) * x)
    z = z / np.linalg.norm(z)
    return HeadFrame(origin, np.column_stack([x, np.cross(z, x), z]))


def head_frame(solver: BatchSolver) -> HeadFrame:
    """The head frame of the solver's cameras at the home posture (the middle of every joint's
    limits: :func:`~cpc2urdf.validation.gaze.chain.mid_limits`)."""
    return head_frame_at(solver.model, solver.cameras, mid_limits(solver.lower, solver.upper))


@dataclass(frozen=True)
class Grid:
    """Targets on a regular grid in the head frame.

    Attributes:
        kind: ``"shell"`` (axes: distance [m], azimuth [rad] about z, left positive, elevation
            [rad]) or ``"box"`` (axes: forward, left, up [m]).
        axes: The sample values of the three axes.
        frame: The head frame.
        points: The targets (world) [m], shape (N, 3), N the product of the axes' sizes, in
            ``meshgrid(..., indexing="ij")`` order.
        points_head: The same in the head frame, shape (N, 3).
        posture: The readings the head frame was taken at [rad]/[m], shape (n,), in the
            solver's joint order; None: the home posture (the middle of the limits).
    """

    kind: str
    axes: tuple[Array, Array, Array]
    frame: HeadFrame
    points: Array
    points_head: Array
    posture: Array | None = None

    @property
    def shape(self) -> tuple[int, int, int]:
        """Samples per axis."""
        a, b, c = self.axes
        return (a.size, b.size, c.size)


def check_grid_args(near: float, far: float, samples: Sequence[int]) -> None:
    """:class:`ConfigurationError` unless ``near < far`` [m] lie in :data:`GRID_RANGE` and
    ``samples`` are three whole numbers >= 2 whose product is at most :data:`MAX_GRID_TARGETS`."""
    lo, hi = GRID_RANGE
    if not (math.isfinite(near) and math.isfinite(far) and 0.0 < near < far):
        raise ConfigurationError(
            f"range must be two finite distances 0 < NEAR < FAR [m], got {near!r} {far!r}"
        )
    if near < lo or far > hi:
        raise ConfigurationError(f"range must lie within {lo:g}..{hi:g} m, got {near!r} {far!r}")
    if len(samples) != 3 or any(int(k) != k or k < 2 for k in samples):
        raise ConfigurationError(
            f"samples must be three whole numbers >= 2 (one per axis), got {list(samples)}"
        )
    total = math.prod(int(k) for k in samples)
    if total > MAX_GRID_TARGETS:
        raise ConfigurationError(
            f"samples {' '.join(str(int(k)) for k in samples)} make {total} targets; at most {MAX_GRID_TARGETS}"
        )


def shell_grid(
    frame: HeadFrame,
    near: float = DEFAULT_RANGE[0],
    far: float = DEFAULT_RANGE[1],
    samples: Sequence[int] = DEFAULT_SAMPLES,
) -> Grid:
    """A spherical shell about the head frame's origin: ``samples[0]`` distances from ``near``
    to ``far`` [m], ``samples[1]`` azimuths over +-90 deg and ``samples[2]`` elevations over
    +-60 deg."""
    check_grid_args(near, far, samples)
    d = np.linspace(near, far, int(samples[0]))
    az = np.linspace(-SHELL_AZIMUTH, SHELL_AZIMUTH, int(samples[1]))
    el = np.linspace(-SHELL_ELEVATION, SHELL_ELEVATION, int(samples[2]))
    D, A, E = (g.ravel() for g in np.meshgrid(d, az, el, indexing="ij"))
    ph = np.column_stack([D * np.cos(E) * np.cos(A), D * np.cos(E) * np.sin(A), D * np.sin(E)])
    return Grid("shell", (d, az, el), frame, frame.to_world(ph), ph)


def box_grid(
    frame: HeadFrame,
    near: float = DEFAULT_RANGE[0],
    far: float = DEFAULT_RANGE[1],
    samples: Sequence[int] = DEFAULT_SAMPLES,
) -> Grid:
    """A box in front of the head: ``samples[0]`` forward positions from ``near`` to ``far`` [m],
    ``samples[1]`` lateral ones over +-``far`` and ``samples[2]`` vertical ones over +-``far``/2."""
    check_grid_args(near, far, samples)
    x = np.linspace(near, far, int(samples[0]))
    y = np.linspace(-far, far, int(samples[1]))
    z = np.linspace(-far / 2.0, far / 2.0, int(samples[2]))
    ph = np.column_stack([g.ravel() for g in np.meshgrid(x, y, z, indexing="ij")])
    return Grid("box", (x, y, z), frame, frame.to_world(ph), ph)


def make_grid(
    solver: BatchSolver,
    kind: str = "shell",
    near: float = DEFAULT_RANGE[0],
    far: float = DEFAULT_RANGE[1],
    samples: Sequence[int] = DEFAULT_SAMPLES,
    q: Array | None = None,
) -> Grid:
    """The ``kind`` grid (:data:`GRID_KINDS`) in front of the solver's head (see
    :func:`shell_grid`, :func:`box_grid`), its head frame taken at readings ``q`` (shape (n,);
    None: the home posture, :func:`head_frame`)."""
    if kind not in GRID_KINDS:
        raise ConfigurationError(f"grid must be one of {', '.join(GRID_KINDS)}, got {kind!r}")
    check_grid_args(near, far, samples)
    posture = None if q is None else np.array(q, dtype=float)
    frame = (
        head_frame(solver)
        if posture is None
        else head_frame_at(solver.model, solver.cameras, posture)
    )
    grid = (shell_grid if kind == "shell" else box_grid)(frame, near, far, samples)
    return dataclasses.replace(grid, posture=posture)


@dataclass(frozen=True)
class Region:
    """The answer of :func:`reachable_region`.

    Attributes:
        grid: The targets' grid.
        points: The targets (world) [m], shape (N, 3).
        status: The solver's status per target, shape (N,).
        category: Index into :data:`REGION_CATEGORIES` per target, shape (N,).
        error: The largest pointing error over the cameras per target [rad], shape (N,).
        q: The answer's readings [rad]/[m], shape (N, n).
        joint_names: The columns of ``q``.
        cameras: The camera optical frames the grid's head frame was taken from.
    """

    grid: Grid
    points: Array
    status: NDArray[np.str_]
    category: NDArray[np.intp]
    error: Array
    q: Array
    joint_names: tuple[str, ...]
    cameras: tuple[str, ...]

    def colours(self) -> Array:
        """An RGB colour in [0, 1] per target (by category), shape (N, 3): for a 3D view."""
        table = np.array([CATEGORY_COLOURS[c] for c in REGION_CATEGORIES])
        return table[self.category]

    def counts(self) -> dict[str, int]:
        """Targets per category."""
        k = np.bincount(self.category, minlength=len(REGION_CATEGORIES))
        return {c: int(v) for c, v in zip(REGION_CATEGORIES, k, strict=True)}

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (SI units): grid, counts, and per target point, status, error."""
        f = self.grid.frame
        return {
            "grid": {
                "kind": self.grid.kind,
                "axes": [a.tolist() for a in self.grid.axes],
                "head_frame": {
                    "origin": f.origin.tolist(),
                    "R_world_head": f.R_world_head.tolist(),
                },
            },
            "categories": list(REGION_CATEGORIES),
            "counts": self.counts(),
            "joint_names": list(self.joint_names),
            "points": self.points.tolist(),
            "status": self.status.tolist(),
            "category": [REGION_CATEGORIES[i] for i in self.category.tolist()],
            "pointing_error_rad": self.error.tolist(),
        }


def reachable_region(
    solver: BatchSolver, grid: Grid, show_progress: bool = True, q_current: Array | None = None
) -> Region:
    """Solve every target of ``grid`` (:func:`solve_batch`, from ``q_current``: the joints that
    do not move are held there; None: the home posture) and sort it into a category; a grid of
    more than :data:`PROGRESS_CHUNK` targets is solved in chunks under a progress bar."""
    P = grid.points
    if P.shape[0] <= PROGRESS_CHUNK or not show_progress:
        ans = solve_batch(solver, P, q_current)
    else:
        from cpc2urdf.progress import progress_checked

        chunks = [P[a : a + PROGRESS_CHUNK] for a in range(0, P.shape[0], PROGRESS_CHUNK)]
        parts = []
        with progress_checked(
            chunks, f"solving {P.shape[0]} targets ({PROGRESS_CHUNK} a step)"
        ) as it:
            for chunk in it:
                parts.append(solve_batch(solver, chunk, q_current))
        ans = BatchAnswer(
            *(
                np.concatenate([getattr(a, f) for a in parts])
                for f in ("q", "reachable", "pointing_error", "status", "iterations")
            )
        )
    lookup = {s: REGION_CATEGORIES.index(category_of_status(s)) for s in set(ans.status.tolist())}
    category = np.array([lookup[s] for s in ans.status.tolist()], dtype=np.intp)
    return Region(
        grid=grid,
        points=grid.points,
        status=ans.status,
        category=category,
        error=np.max(ans.pointing_error, axis=1),
        q=ans.q,
        joint_names=tuple(solver.joint_names),
        cameras=tuple(solver.cameras),
    )


def _slice_mask(grid: Grid, axis: int) -> tuple[NDArray[np.bool_], str]:
    """Targets on the grid plane nearest zero along ``axis`` (1: azimuth/lateral, 2:
    elevation/vertical), and where that plane is ("elevation -12 deg", "up 0.15 m")."""
    values = grid.axes[axis]
    k = int(np.argmin(np.abs(values)))
    idx = np.unravel_index(np.arange(grid.points.shape[0]), grid.shape)[axis]
    span = float(np.max(np.abs(values)))
    v = float(values[k])
    v = 0.0 if abs(v) <= 1e-9 * span else v  # a plane through 0 up to rounding (linspace: -2.2e-16)
    if grid.kind == "shell":
        where = f"{'azimuth' if axis == 1 else 'elevation'} {math.degrees(v):.3g} deg"
    else:
        where = f"{'left' if axis == 1 else 'up'} {v:.3g} m"
    return np.asarray(idx == k), where


def region_figure_png(region: Region, title: str = "", notes: Sequence[str] = ()) -> bytes:
    """The region drawn as PNG bytes: top view (horizontal slice), side view (vertical slice),
    and the pointing error of the targets not fixated in the horizontal slice; the slices' planes
    in the panel titles, the legend's counts over the whole grid, ``notes`` (lines: what was
    held, the tolerance) under the title."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm
    from matplotlib.lines import Line2D

    ph = region.grid.points_head
    colours = region.colours()
    counts = region.counts()
    fig, axs = plt.subplots(1, 3, figsize=(17, 6.2))
    level, level_at = _slice_mask(region.grid, 2)
    upright, upright_at = _slice_mask(region.grid, 1)
    size = max(6.0, 12000.0 / max(1, int(level.sum())))  # [pt^2]: fewer points, bigger squares
    for ax, mask, (i, j), (xl, yl), name in (
        (axs[0], level, (0, 1), ("forward [m]", "left [m]"), f"top view: slice at {level_at}"),
        (axs[1], upright, (0, 2), ("forward [m]", "up [m]"), f"side view: slice at {upright_at}"),
    ):
        ax.scatter(ph[mask, i], ph[mask, j], c=colours[mask], s=size, marker="s", linewidths=0)
        ax.plot([0.0], [0.0], "k+", markersize=12)
        ax.set_xlabel(xl)
        ax.set_ylabel(yl)
        ax.set_title(name)
        ax.set_aspect("equal")
    miss = level & (region.category != REGION_CATEGORIES.index("fixated"))
    ax = axs[2]
    err = np.degrees(region.error[miss])
    if err.size:
        sc = ax.scatter(
            ph[miss, 0],
            ph[miss, 1],
            c=np.maximum(err, 1e-6),
            s=size,
            marker="s",
            linewidths=0,
            cmap="viridis",
            norm=LogNorm(vmin=max(float(err.min()), 1e-6), vmax=max(float(err.max()), 2e-6)),
        )
        fig.colorbar(sc, ax=ax, label="pointing error [deg]")
    else:
        ax.text(
            0.5, 0.5, "all fixated\nin this slice", transform=ax.transAxes, ha="center", va="center"
        )
    ax.set_xlim(axs[0].get_xlim())
    ax.set_ylim(axs[0].get_ylim())
    ax.set_aspect("equal")
    ax.set_xlabel("forward [m]")
    ax.set_ylabel("left [m]")
    ax.set_title("pointing error where not fixated (top view's slice)")
    dis = region.category == REGION_CATEGORIES.index("disparity")
    labels = []
    for c in REGION_CATEGORIES:
        text = f"{c.replace('_', ' ')}: {counts[c]}"
        if c == "disparity" and dis.any():
            e = np.degrees(region.error[dis])
            text += f" (error median {np.median(e):.3g} deg, max {e.max():.3g} deg)"
        labels.append(text)
    handles = [
        Line2D([], [], marker="s", linestyle="", color=CATEGORY_COLOURS[c])
        for c in REGION_CATEGORIES
    ]
    fig.legend(handles, labels, loc="lower center", ncol=3, frameon=False, title="whole grid")
    n = region.points.shape[0]
    frame = (
        "head frame: the cameras' mid-point at home, x forward along their mean optical axis, "
        "z up (against their image y)"
    )
    fig.suptitle(
        "\n".join(
            [
                f"{title}{': ' if title else ''}reachable region, {n} targets "
                f"({region.grid.kind} grid), {counts['fixated']} fixated",
                frame,
                *notes,
            ]
        ),
        fontsize=10,
    )
    fig.tight_layout(rect=(0.0, 0.12, 1.0, 0.97 - 0.03 * (1 + len(notes))))
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    return buf.getvalue()


def draw_region(region: Region, path: str | os.PathLike[str], title: str = "") -> Path:
    """Draw ``region`` (:func:`region_figure_png`) to the PNG file ``path``, atomically."""
    if Path(path).suffix.lower() != ".png":
        raise ConfigurationError(f"{path}: the region is drawn as PNG, expected a .png path")
    check_output_path(path)
    return write_atomic(path, region_figure_png(region, title))


__all__ = [
    "CATEGORY_COLOURS",
    "DEFAULT_RANGE",
    "DEFAULT_SAMPLES",
    "GRID_KINDS",
    "GRID_RANGE",
    "MAX_GRID_TARGETS",
    "PROGRESS_CHUNK",
    "REGION_CATEGORIES",
    "SHELL_AZIMUTH",
    "SHELL_ELEVATION",
    "BatchAnswer",
    "BatchSolver",
    "Grid",
    "HeadFrame",
    "Region",
    "box_grid",
    "category_of_status",
    "check_grid_args",
    "draw_region",
    "head_frame",
    "head_frame_at",
    "make_grid",
    "reachable_region",
    "region_figure_png",
    "shell_grid",
    "solve_batch",
]
