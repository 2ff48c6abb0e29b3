"""The one argument parser every command, study and benchmark uses.

argparse's own parser prints the whole usage block and raises ``SystemExit`` on a bad option; the
CLI contract is one line and exit code 2, returned by ``main`` rather than raised.
"""

from __future__ import annotations

import argparse
import math
import os
import re
from collections.abc import Sequence
from typing import Any, NoReturn

from cpc2urdf.errors import ConfigurationError

# What argparse takes for a negative number rather than an option: its own pattern knows only
# -1 and -1.5, so "--target -1e-3 0 1" was "expected 3 arguments"; exponents, -inf and -nan too
# (the last two are then refused as not finite by the command, naming the option).
NEGATIVE_NUMBER = re.compile(
    r"^-(?:(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|inf|infinity|nan)$", re.IGNORECASE
)


class OneLineParser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` whose usage errors are one line on stderr and exit code 2, and
    which reads ``-1e-3`` as a negative number (argparse alone takes it for an unknown option)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NEGATIVE_NUMBER

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message}\n")

    def parse_args(self, args: Sequence[str] | None = None, namespace: Any = None) -> Any:  # type: ignore[override]
        """As argparse's, but an unrecognised argument is named by the sub-command it was given to
        (``cpc2urdf demo: error: unrecognized arguments: --fast``, not ``cpc2urdf: error: ...``)."""
        parsed, extras = self.parse_known_args(args, namespace)
        if extras:
            _innermost(self, parsed).error(f"unrecognized arguments: {' '.join(extras)}")
        return parsed


def _innermost(
    parser: argparse.ArgumentParser, parsed: argparse.Namespace
) -> argparse.ArgumentParser:
    """The sub-command parser (``cpc2urdf demo``) that ``parsed`` was parsed with, or ``parser``."""
    while True:
        sub = next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)
        name = (
            getattr(parsed, sub.dest, None)
            if sub is not None and sub.dest != argparse.SUPPRESS
            else None
        )
        if sub is None or name not in sub.choices:
            return parser
        parser = sub.choices[name]


def exit_code(e: SystemExit) -> int:
    """The exit code a ``SystemExit`` carries (``--help`` gives 0; a message or None is 2/0)."""
    if isinstance(e.code, int):
        return e.code
    return 0 if e.code is None else 2


def finite_numbers(values: Sequence[str], what: str) -> list[float]:
    """``values`` as floats; :class:`ConfigurationError` naming ``what`` (e.g. ``"--target X Y
    Z"``) for one that is not a number or not finite."""
    out = []
    for v in values:
        try:
            x = float(v)
        except ValueError:
            raise ConfigurationError(f"{what} must be numbers, got {v!r}") from None
        if not math.isfinite(x):
            raise ConfigurationError(f"{what} must be finite, got {v!r}")
        out.append(x)
    return out


def joint_readings(
    values: Sequence[str] | None, option: str
) -> dict[str, float] | list[float] | None:
    """Joint readings given to ``option`` (e.g. ``"--q"``): ``{joint: value}`` from
    ``NAME=VALUE`` items, or a list of values in the robot's joint order; None if none given."""
    if not values:
        return None
    if all("=" in v for v in values):
        out: dict[str, float] = {}
        for item in values:
            name, _, value = item.partition("=")
            out[name] = finite_numbers([value], f"{option} {name}")[0]
        return out
    if any("=" in v for v in values):
        raise ConfigurationError(
            f"{option} takes either NAME=VALUE pairs or one number per joint, not both"
        )
    return finite_numbers(values, f"{option} values")


# Options that name a file a command writes (``--json`` only where it takes a path, not a flag).
OUTPUT_OPTIONS = {"output": "-o", "json": "--json", "html": "--html", "screenshot": "--screenshot"}
MAX_REFERENCING_FILE = (
    16 * 2**20
)  # [bytes]: inputs larger than this are not searched for files they name
_HOOKS = (
    "run",
    "command",
    "may_replace",
    "written",
    "read",
)  # parser defaults that are not arguments


def _same_file(a: str, b: str) -> bool:
    """Whether two paths name one file: the same real path, or (both existing) one file under two
    names (a case-insensitive file system, a hard link)."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def json_object(path: str) -> dict[str, Any] | None:
    """The JSON object in file ``path`` when its text (after a UTF-8 byte-order mark and white
    space, as the loaders read it) starts with ``{``; None for anything else, a file over
    :data:`MAX_REFERENCING_FILE`, or one that cannot be read or parsed."""
    import json

    try:
        if os.path.getsize(path) > MAX_REFERENCING_FILE:
            return None
        with open(path, "rb") as f:
            text = f.read().removeprefix(b"\xef\xbb\xbf").lstrip()
        if not text.startswith(b"{"):  # a URDF, an image, a CSV
            return None
        doc = json.loads(text.decode("utf-8"))
    except (OSError, ValueError, RecursionError):  # unreadable, not text, not JSON, nested too deep
        return None  # the command itself names what is wrong with it
    return doc if isinstance(doc, dict) else None


def referenced_files(path: str) -> list[str]:
    """Files a JSON input names and a command reads through it, resolved as the loaders resolve
    them: a model's ``urdf.path`` (the URDF it was identified from, written back into; as
    written) and a ``robot`` that is a file (a measurement file's robot: a path, relative to the
    JSON's folder first; a bare name is the shipped robot unless such a file is here). Any file
    whose text starts with ``{`` is read as JSON, whatever its name (the loaders do the same);
    empty for other files."""
    doc = json_object(path)
    if doc is None:
        return []
    found = []
    urdf = doc.get("urdf")
    if (
        isinstance(urdf, dict)
        and isinstance(urdf.get("path"), str)
        and os.path.isfile(urdf["path"])
    ):
        found.append(urdf["path"])
    robot = doc.get("robot")
    if isinstance(robot, str) and robot:
        from cpc2urdf.files.robot_ref import looks_like_path

        if looks_like_path(robot) or os.path.exists(robot):  # else the shipped robot of that name
            beside = os.path.join(os.path.dirname(path), robot)
            candidate = beside if not os.path.isabs(robot) and os.path.exists(beside) else robot
            if os.path.isfile(candidate):
                found.append(candidate)
    return found


def _named_files(value: object) -> list[str]:
    """The existing files an argument's value names: a path, or the FILE of ``NAME=FILE``
    (``measure --board FRAME=FILE``, ``--camera NAME=FILE``); each element of a list."""
    found = []
    for v in value if isinstance(value, (list, tuple)) else [value]:
        if not isinstance(v, str) or not v:
            continue
        for candidate in (v, v.split("=", 1)[1] if "=" in v else ""):
            if candidate and os.path.isfile(candidate):
                found.append(candidate)
                break
    return found


def check_outputs_are_not_inputs(args: argparse.Namespace) -> None:
    """:class:`ConfigurationError` when a file a command would write is one it reads, or two of
    its outputs are one file, or an output is an empty path.

    Written: the :data:`OUTPUT_OPTIONS` that name a path, and what ``args.written(args)`` adds
    (``{label: path}``: ``plan``'s PLAN.csv/PLAN.png next to ``-o``, ``simulate``'s files in its
    folder). Read: every other argument naming an existing file (a path, or ``NAME=FILE``), the
    files those name (:func:`referenced_files`: ``export model.json -o <the URDF it was
    identified from>`` replaced the user's URDF), and what ``args.read(args)`` adds (``{label:
    path}``: ``measure``'s default ``IMAGES_DIR/joints.csv``). A command that updates a file in
    place on purpose lists the arguments it may replace in ``args.may_replace`` (``handeye --model
    M -o M``): only that file itself, when it is a JSON file (a model, not a URDF), not the files
    it names.
    """
    outputs = {
        opt: v
        for dest, opt in OUTPUT_OPTIONS.items()
        if isinstance(v := getattr(args, dest, None), str)
    }
    for opt, path in outputs.items():
        if not path:
            raise ConfigurationError(f"{opt} '': an empty path; name the file or folder to write")
    written = getattr(args, "written", None)
    if callable(written) and outputs:
        outputs.update({k: v for k, v in written(args).items() if v})
    if not outputs:
        return
    items = list(outputs.items())
    for k, (opt, path) in enumerate(items):
        for opt2, path2 in items[:k]:
            if _same_file(path, path2):
                raise ConfigurationError(
                    f"{opt} {path}: the same file as {opt2} ({path2}); give each output its own path"
                )
    allowed = set(getattr(args, "may_replace", ()))
    inputs: list[tuple[str, str]] = []  # (what it is, path)
    for dest, value in vars(args).items():
        if dest in OUTPUT_OPTIONS or dest in _HOOKS:
            continue
        label = dest.replace("_", "-")
        for v in _named_files(value):
            if dest not in allowed or json_object(v) is None:  # in place: a model file, not a URDF
                inputs.append((f"the same file as the input {label} ({v})", v))
            inputs.extend(
                (f"the file the input {label} ({v}) refers to", ref) for ref in referenced_files(v)
            )
    read = getattr(args, "read", None)
    if callable(read):
        inputs.extend(
            (f"the same file as the input {k}", v)
            for k, v in read(args).items()
            if v and os.path.isfile(v)
        )
    for opt, path in outputs.items():
        for what, source in inputs:
            if _same_file(path, source):
                raise ConfigurationError(f"{opt} {path}: {what}; give the output its own path")


__all__ = [
    "NEGATIVE_NUMBER",
    "OUTPUT_OPTIONS",
    "OneLineParser",
    "check_outputs_are_not_inputs",
    "json_object",
    "referenced_files",
    "exit_code",
    "finite_numbers",
    "joint_readings",
]
