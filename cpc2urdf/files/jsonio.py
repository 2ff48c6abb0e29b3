"""Reading JSON files with one clear error, and writing files atomically.

An output file is written to a temporary file in the same folder and renamed over the target, so
a failure never leaves a partial or corrupted file behind.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import tempfile
import uuid
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

from cpc2urdf.errors import InputFileError, OutputError

_PathT = TypeVar("_PathT", bound="str | os.PathLike[str]")


def read_text_file(path: str | os.PathLike[str], expected: str, encoding: str = "utf-8") -> str:
    """The text of a user's input file, or one :class:`InputFileError` naming the file and why:
    missing, a folder, binary (NUL bytes), UTF-16/32 or otherwise not UTF-8, unreadable.

    Args:
        path: The file.
        expected: What it should be, for the message (e.g. ``"a JSON file"``).
        encoding: Text encoding (``"utf-8-sig"`` accepts a byte-order mark).
    """
    p = Path(path)
    if not p.exists():
        raise InputFileError(p, "no such file")
    if p.is_dir():
        raise InputFileError(p, f"is a folder, expected {expected}")
    try:
        data = p.read_bytes()
    except OSError as e:
        raise InputFileError(p, f"cannot read ({e.strerror})") from None
    for bom, name in _OTHER_ENCODINGS:
        if data.startswith(bom):
            raise InputFileError(p, f"is {name} text, expected {expected} in UTF-8")
    if b"\x00" in data:
        raise InputFileError(p, f"is a binary file, expected {expected}")
    try:
        text = data.decode(encoding)
    except UnicodeDecodeError as e:
        line = data.count(b"\n", 0, e.start) + 1
        raise InputFileError(
            p, f"is not UTF-8 text (byte 0x{data[e.start]:02x} on line {line}), expected {expected}"
        ) from None
    return text.replace("\r\n", "\n").replace("\r", "\n")  # universal newlines, as open() reads


# Byte-order marks of encodings we do not read (UTF-32 first: its LE mark starts like UTF-16's).
_OTHER_ENCODINGS = (
    (b"\xff\xfe\x00\x00", "UTF-32"),
    (b"\x00\x00\xfe\xff", "UTF-32"),
    (b"\xff\xfe", "UTF-16"),
    (b"\xfe\xff", "UTF-16"),
)


JSON_MAX_DEPTH = 64  # nesting levels of arrays/objects; our formats need fewer than 10


def read_json(path: str | os.PathLike[str]) -> Any:
    """Load a JSON file, the one JSON reader of every cpc2urdf input file.

    Beyond the JSON grammar it refuses, as one :class:`InputFileError` naming the file and the
    place: nesting deeper than :data:`JSON_MAX_DEPTH`, a key repeated in one object (``json``
    would keep the last value silently), ``NaN``/``Infinity`` literals and numbers that overflow
    to infinity, integers too long to convert, and strings that are not valid Unicode (lone
    surrogates). Places are written ``records[3].joints.pan``. A UTF-8 byte-order mark is
    accepted.

    Raises:
        InputFileError: Missing, a folder, binary, not JSON, or one of the problems above.
    """
    p = Path(path)
    text = read_text_file(p, "a JSON file", encoding="utf-8-sig")
    reader = _StrictJson()
    try:
        doc = json.loads(
            text,
            object_pairs_hook=reader.object,
            parse_constant=reader.constant,
            parse_float=reader.float,
            parse_int=reader.int,
        )
    except json.JSONDecodeError as e:
        raise InputFileError(
            p, f"not valid JSON (line {e.lineno}, column {e.colno}: {e.msg})"
        ) from None
    except RecursionError:  # nested far deeper than JSON_MAX_DEPTH: find where from the text
        raise InputFileError(p, _too_deep(_deep_position(text))) from None
    # Only a \uD800-\uDFFF escape gives a lone surrogate: look at the strings only then.
    problem = reader.first_problem(doc, check_strings=_SURROGATE_ESCAPE.search(text) is not None)
    if problem:
        raise InputFileError(p, problem)
    return doc


def _too_deep(where: str) -> str:
    if len(where) > 80:  # a path 64 levels deep: its start and its end say enough
        where = f"{where[:40]}...{where[-30:]}"
    return f"nested more than {JSON_MAX_DEPTH} levels deep ({where})"


class _Rejected:
    """A value ``json`` parsed that the file must not contain (kept to be named with its place)."""

    __slots__ = ("why",)

    def __init__(self, why: str) -> None:
        self.why = why


class _StrictJson:
    """Hooks for :func:`json.loads` that mark duplicate keys and non-finite numbers, and a walk
    that names the first such place (in file order) and checks the depth."""

    def __init__(self) -> None:
        self.duplicates: dict[int, str] = {}  # id(object) -> its first repeated key
        self.keep: list[dict[str, Any]] = []  # keeps those ids alive and unique
        self.rejected = 0

    def object(self, pairs: list[tuple[str, Any]]) -> dict[str, Any]:
        obj = dict(pairs)
        if len(obj) != len(pairs):
            seen: set[str] = set()
            for key, _ in pairs:
                if key in seen:
                    self.duplicates[id(obj)] = key
                    self.keep.append(obj)
                    break
                seen.add(key)
        return obj

    def constant(self, name: str) -> _Rejected:
        self.rejected += 1
        return _Rejected(f"non-finite number {name} is not allowed")

    def float(self, text: str) -> float | _Rejected:
        v = float(text)
        if math.isfinite(v):
            return v
        self.rejected += 1
        return _Rejected(f"number {text} is out of range (it reads as infinity)")

    def int(self, text: str) -> int | _Rejected:
        try:
            return int(text)
        except ValueError:  # longer than sys.get_int_max_str_digits()
            self.rejected += 1
            return _Rejected(f"an integer of {len(text)} digits is too long")

    def first_problem(self, doc: Any, check_strings: bool) -> str | None:
        """The first problem in file order, or None (a walk without recursion).

        Args:
            doc: What :func:`json.loads` returned with these hooks.
            check_strings: Also look for lone surrogates in keys and strings.
        """
        scalars = check_strings or self.rejected > 0  # else only objects and arrays need a look
        # (value, depth, trail): the trail (parent trail, key or index) is spelled out only
        # for the message, so a clean file costs one tuple per object or array.
        stack: list[tuple[Any, int, _Trail]] = [(doc, 0, None)]
        while stack:
            value, depth, trail = stack.pop()
            if isinstance(value, dict):
                if depth >= JSON_MAX_DEPTH:
                    return _too_deep(f"at {_spell(trail)}")
                if id(value) in self.duplicates:
                    return f"duplicate key {_spell((trail, self.duplicates[id(value)]))!r}"
                if check_strings:
                    bad = next((k for k in value if not _is_unicode(k)), None)
                    if bad is not None:
                        return (
                            f"{_spell((trail, bad))}: key is not valid Unicode (a lone surrogate)"
                        )
                children: list[tuple[str | int, Any]] = list(value.items())
            elif isinstance(value, list):
                if depth >= JSON_MAX_DEPTH:
                    return _too_deep(f"at {_spell(trail)}")
                children = list(enumerate(value))
            elif isinstance(value, _Rejected):
                return f"{_spell(trail)}: {value.why}"
            elif check_strings and isinstance(value, str) and not _is_unicode(value):
                return f"{_spell(trail)}: string is not valid Unicode (a lone surrogate)"
            else:
                continue
            stack.extend(
                (v, depth + 1, (trail, k))
                for k, v in reversed(children)
                if scalars or isinstance(v, (dict, list))
            )
        return None


_Trail = tuple[Any, str | int] | None  # (parent trail, key or index), None at the top level


def _spell(trail: _Trail) -> str:
    """``records[3].joints.pan``; a key that is not a plain name is quoted: ``x["a b"]``."""
    parts: list[str] = []
    while trail is not None:
        trail, key = trail
        if isinstance(key, int):
            parts.append(f"[{key}]")
        elif _PLAIN_KEY.match(key):
            parts.append(f".{key}")
        else:
            parts.append(f"[{json.dumps(key)}]")
    text = "".join(reversed(parts)).removeprefix(".")
    return text or "the top level"


_SURROGATE_ESCAPE = re.compile(r"\\u[dD][89a-fA-F]")
_PLAIN_KEY = re.compile(r"[A-Za-z_][A-Za-z0-9_\-]*\Z")


def _is_unicode(s: str) -> bool:
    try:
        s.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def _deep_position(text: str) -> str:
    """``line L, column C`` where brackets outside strings first nest deeper than the limit."""
    depth = 0
    for m in re.finditer(r'"(?:[^"\\]|\\.)*"|[\[\]{}]', text):
        c = m.group()
        if c in "[{":
            depth += 1
            if depth > JSON_MAX_DEPTH:
                line = text.count("\n", 0, m.start()) + 1
                col = m.start() - (text.rfind("\n", 0, m.start()) + 1) + 1
                return f"line {line}, column {col}"
        elif c in "]}":
            depth -= 1
    return "somewhere in the file"


def require_format(doc: Any, expected: str, path: object) -> Mapping[str, Any]:
    """Check that ``doc`` is an object whose ``format`` tag is ``expected`` (any ``@`` version
    of the same family is named in the error)."""
    if not isinstance(doc, Mapping):
        raise InputFileError(path, f'expected a JSON object with "format": "{expected}"')
    tag = doc.get("format")
    if tag != expected:
        raise InputFileError(path, f"format is {tag!r}, expected {expected!r}")
    return doc


def make_folder(path: str | os.PathLike[str]) -> Path:
    """Create the output folder ``path`` (and its parents) if missing, or :class:`OutputError`."""
    p = Path(path)
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise OutputError(f"{p}: cannot create folder ({e.strerror})") from e
    return p


def check_output_path(path: str | os.PathLike[str]) -> Path:
    """``path`` as a file :func:`write_atomic` can create: call it before long work whose result
    goes there, so that a bad ``-o`` is refused first, not after the work.

    Raises:
        OutputError: The path is a folder, or its folder does not exist.
    """
    p = Path(path)
    folder = p.parent if str(p.parent) else Path(".")
    if p.is_dir():
        raise OutputError(f"{p}: is a folder, expected a file path")
    if not folder.is_dir():
        what = "is a file, not a folder" if folder.exists() else "does not exist"
        raise OutputError(f"{p}: cannot write, folder {folder} {what}")
    return p


def write_atomic(path: str | os.PathLike[str], data: str | bytes) -> Path:
    """Write ``data`` (text, UTF-8; or bytes) to ``path`` atomically (temp file in the same
    folder, then rename). The file gets the mode a plain ``open()`` would give it.

    Raises:
        OutputError: The folder does not exist or is not writable, or the path is a folder.
    """
    p = check_output_path(path)
    tmp = _temp_copy(p, data)
    try:
        os.replace(tmp, p)
    except OSError as e:
        _unlink(tmp)
        raise OutputError(f"{p}: cannot write ({e.strerror})") from e
    return p


def write_all_atomic(files: Mapping[_PathT, str | bytes]) -> list[Path]:
    """Write several files all or nothing: every one to a temp file first, then rename them.

    If writing or renaming any of them fails, none of the new files is left: the temp files are
    removed, files already renamed into place are removed again or, where a file of that name
    existed before, the old file is put back.

    Args:
        files: Path -> content (text, UTF-8; or bytes).

    Returns:
        The paths, in the order given.

    Raises:
        OutputError: As :func:`write_atomic`, naming the file that failed; or a path given twice.
    """
    paths = [check_output_path(f) for f in files]
    if len({os.path.abspath(p) for p in paths}) != len(paths):
        raise OutputError(f"{', '.join(map(str, paths))}: a file is named twice")
    temps: list[str] = []
    backups: dict[
        Path, str | None
    ] = {}  # target -> hard link to the file it replaces (None: new file)
    try:
        for p, data in zip(paths, files.values(), strict=True):
            temps.append(_temp_copy(p, data))
        for p, tmp in zip(paths, temps, strict=True):
            backups[p] = _backup(p)
            try:
                os.replace(tmp, p)
            except OSError as e:
                raise OutputError(f"{p}: cannot write ({e.strerror})") from e
    except BaseException:
        for tmp in temps:
            _unlink(tmp)
        for p, old in backups.items():
            if old is None:
                _unlink(str(p))
            else:
                try:
                    os.replace(old, p)
                except OSError:
                    pass
        raise
    for old in backups.values():
        if old is not None:
            _unlink(old)
    return paths


def _temp_copy(p: Path, data: str | bytes) -> str:
    """``data`` in a new temp file next to ``p`` with the mode ``open()`` would give ``p``."""
    folder = p.parent if str(p.parent) else Path(".")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=folder)
    except OSError as e:
        raise OutputError(f"{p}: cannot write ({e.strerror})") from e
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data.encode("utf-8") if isinstance(data, str) else data)
        # mkstemp creates 0600; give the file the mode a plain open() would have given it.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
    except OSError as e:
        _unlink(tmp)
        raise OutputError(f"{p}: cannot write ({e.strerror})") from e
    except BaseException:
        _unlink(tmp)
        raise
    return tmp


def _backup(p: Path) -> str | None:
    """A second name of the file at ``p`` (to put it back), or None if there is none."""
    if not p.exists():
        return None
    folder = p.parent if str(p.parent) else Path(".")
    name = str(folder / f".{p.name}.{uuid.uuid4().hex[:12]}.old")
    try:
        os.link(p, name)  # fails if the name exists: never touches another file
    except OSError:
        try:  # a file system without hard links
            shutil.copy2(p, name)
        except OSError as e:
            _unlink(name)
            raise OutputError(f"{p}: cannot write ({e.strerror})") from e
    return name


def _unlink(path: str) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass


def dumps(doc: Any) -> str:
    """Deterministic JSON text (sorted keys are not used: field order is part of the format)."""
    return json.dumps(doc, indent=2, allow_nan=False) + "\n"


def write_json(path: str | os.PathLike[str], doc: Any) -> Path:
    """Atomically write ``doc`` as JSON (NaN/inf refused)."""
    try:
        text = dumps(doc)
    except ValueError as e:
        raise OutputError(f"{path}: refusing to write non-finite numbers ({e})") from e
    return write_atomic(path, text)


def finite_float(value: Any, where: str) -> float:
    """``value`` as a finite float, or ``ValueError`` naming ``where``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{where} must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{where} must be finite, got {value!r}")
    return v


def float_list(value: Any, n: int, where: str) -> list[float]:
    """``value`` as a list of ``n`` finite floats, or ``ValueError`` naming ``where``."""
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise ValueError(f"{where} must be a list of {n} numbers, got {value!r}")
    return [finite_float(v, f"{where}[{i}]") for i, v in enumerate(value)]


__all__ = [
    "JSON_MAX_DEPTH",
    "check_output_path",
    "dumps",
    "finite_float",
    "float_list",
    "make_folder",
    "read_json",
    "read_text_file",
    "require_format",
    "write_all_atomic",
    "write_atomic",
    "write_json",
]
