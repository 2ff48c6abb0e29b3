"""How long the first use takes after an install: numba's cache empty, then warm.

Each command runs as a subprocess, twice, with ``NUMBA_CACHE_DIR`` pointing at a new empty folder
(a fresh install). The first run solves with the kernels' Python functions while a background
process compiles them into the cache (``kernels/interpreted.py``); the second run, once that compile
has ended, loads them. Printed: wall time [s] of each run, the first over the second, and how long
the background compile took after the first run.

    cpc2urdf bench first-use [--json out.json] [--commands gaze python check check-gaze]

The commands (as the README and docs/gaze.md show them):

- ``gaze``: ``cpc2urdf gaze iis_head --target -0.6 -0.6 0.7``;
- ``python``: ``cpc2urdf.gaze_solver("iis_head").solve([-0.6, -0.6, 0.7])``;
- ``check``: ``cpc2urdf check head.urdf --model iis_head`` (the URDF written by ``cpc2urdf export``
  first, untimed);
- ``check-gaze``: the same with ``--gaze-report`` (it builds a gaze solver).

The machine's load (``os.getloadavg``) is printed with the table: the times are of this machine
as it is, other work included.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from cpc2urdf.argparsing import OneLineParser

TARGET = ("-0.6", "-0.6", "0.7")
COMMANDS = ("gaze", "python", "check", "check-gaze")  # the keys of commands()
PYTHON_SOLVE = (
    "import cpc2urdf; s = cpc2urdf.gaze_solver('iis_head'); "
    "print(s.solve([-0.6, -0.6, 0.7]).status)"
)
ROOT = Path(__file__).resolve().parents[2]  # the folder holding the cpc2urdf package


def commands(workdir: Path) -> dict[str, list[str]]:
    """The timed commands, by name (``workdir`` holds ``head.urdf``)."""
    cli = [sys.executable, "-m", "cpc2urdf"]
    urdf = str(workdir / "head.urdf")
    return {
        "gaze": [*cli, "gaze", "iis_head", "--target", *TARGET],
        "python": [sys.executable, "-c", PYTHON_SOLVE],
        "check": [*cli, "check", urdf, "--model", "iis_head"],
        "check-gaze": [*cli, "check", urdf, "--model", "iis_head", "--gaze-report"],
    }


def _env(cache: Path) -> dict[str, str]:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    return env


def _timed(cmd: list[str], env: dict[str, str], cwd: Path) -> tuple[float, int, str]:
    """Wall time [s], exit code and the line on stderr about the first use (or its last line) of one run."""
    start = time.perf_counter()
    done = subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True, timeout=1800)
    wall = time.perf_counter() - start
    lines = done.stderr.strip().splitlines() or [""]
    return wall, done.returncode, next((x for x in lines if "first use" in x), lines[-1])


def _background_compile(cache: Path, line: str, timeout: float = 600.0) -> float | None:
    """Seconds until the compiled solve is in ``cache`` after a first run that started compiling it
    in the background (its last line on stderr, ``line``, says so); None for any other run."""

    def done() -> bool:
        return any(cache.rglob("flat._solve_rows-*.nbi"))

    if "in the background" not in line or done():
        return None
    start = time.perf_counter()
    while not done() and time.perf_counter() - start < timeout:
        time.sleep(0.5)
    time.sleep(1.0)  # the worker writes its last files and exits
    return round(time.perf_counter() - start, 1)


def measure(names: list[str]) -> list[dict[str, Any]]:
    """First and second run of each command in ``names``, each with a cache of its own."""
    rows = []
    with tempfile.TemporaryDirectory(prefix="cpc2urdf-first-use-") as tmp:
        work = Path(tmp)
        export = [
            sys.executable,
            "-m",
            "cpc2urdf",
            "export",
            "iis_head",
            "-o",
            str(work / "head.urdf"),
        ]
        subprocess.run(
            export, env=_env(work / "export-cache"), cwd=work, check=True, capture_output=True
        )
        cmds = commands(work)
        for name in names:
            cache = work / f"cache-{name}"
            cache.mkdir()
            env = _env(cache)
            load = os.getloadavg()[0]
            first, rc1, line = _timed(cmds[name], env, work)
            background = _background_compile(cache, line)
            second, rc2, _ = _timed(cmds[name], env, work)
            rows.append(
                {
                    "command": name,
                    "first_s": round(first, 2),
                    "second_s": round(second, 2),
                    "ratio": round(first / second, 2),
                    "exit": [rc1, rc2],
                    "load": round(load, 2),
                    "background_compile_s": background,
                    "line": line,
                }
            )
            after = (
                ""
                if background is None
                else f"compiled in the background {background:.0f} s later; "
            )
            print(
                f"{name:11s} first {first:6.1f} s  second {second:6.1f} s  ({first / second:4.1f}x)  "
                f"exit {rc1},{rc2}  load {load:.1f}  {after}{line}",
                flush=True,
            )
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(prog="cpc2urdf bench first-use", description=__doc__.splitlines()[0])
    parser.add_argument(
        "--commands",
        nargs="+",
        default=list(COMMANDS),
        choices=COMMANDS,
    )
    parser.add_argument("--json", help="also write the rows to this JSON file")
    args = parser.parse_args(argv)
    print(f"{os.cpu_count()} cores; NUMBA_CACHE_DIR empty before each command's first run")
    rows = measure(args.commands)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2))
    return 0 if all(r["exit"] == [0, 0] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
