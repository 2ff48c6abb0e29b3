"""``cpc2urdf.files.jsonio``: the one JSON reader (depth, duplicate keys, non-finite numbers, encodings)
and the checks of input and output paths, each refused as one line naming the file and place."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import pytest

from cpc2urdf.cli import main
from cpc2urdf.errors import InputFileError, OutputError
from cpc2urdf.files.jsonio import (
    JSON_MAX_DEPTH,
    check_output_path,
    read_json,
    read_text_file,
    write_all_atomic,
    write_atomic,
)
from cpc2urdf.files.model_file import model_to_json
from cpc2urdf.files.robot_ref import load_model


def _refused(tmp_path: Path, text: str | bytes, name: str = "f.json") -> str:
    p = tmp_path / name
    if isinstance(text, bytes):
        p.write_bytes(text)
    else:
        p.write_text(text, encoding="utf-8")
    with pytest.raises(InputFileError) as e:
        read_json(p)
    msg = str(e.value)
    assert msg.startswith(f"{p}: ") and "\n" not in msg
    return msg.removeprefix(f"{p}: ")


def test_clean_json_reads_as_json_loads(tmp_path: Path) -> None:
    doc = {
        "format": "x",
        "records": [{"joints": {"pan": 1.5, "tilt": -2}, "label": "a\u00e9\U0001f600"}],
        "n": None,
    }
    (tmp_path / "ok.json").write_text(json.dumps(doc, indent=2), encoding="utf-8")
    assert read_json(tmp_path / "ok.json") == doc
    (tmp_path / "pair.json").write_text(
        '{"s": "\\ud83d\\ude00"}'
    )  # an escaped surrogate pair is fine
    assert read_json(tmp_path / "pair.json") == {"s": "\U0001f600"}


def test_nesting_deeper_than_the_limit_is_one_line(tmp_path: Path) -> None:
    # Today's RecursionError: far deeper than Python's recursion limit.
    msg = _refused(tmp_path, "[" * 100000 + "]" * 100000)
    assert (
        msg
        == f"nested more than {JSON_MAX_DEPTH} levels deep (line 1, column {JSON_MAX_DEPTH + 1})"
    )
    # Just past the limit (json itself reads it): named by its path.
    msg = _refused(tmp_path, '{"a": ' * (JSON_MAX_DEPTH + 1) + "1" + "}" * (JSON_MAX_DEPTH + 1))
    assert (
        msg.startswith(f"nested more than {JSON_MAX_DEPTH} levels deep (at a.a.a")
        and len(msg) < 200
    )
    (tmp_path / "ok.json").write_text("[" * JSON_MAX_DEPTH + "]" * JSON_MAX_DEPTH)
    assert read_json(tmp_path / "ok.json") is not None


@pytest.mark.parametrize(
    "text, place",
    [
        ('{"a": 1, "a": 2}', "a"),
        (
            '{"records": [{}, {}, {}, {"joints": {"pan": 1, "tilt": 2, "pan": 3}}]}',
            "records[3].joints.pan",
        ),
        ('{"x": {"a b": {"c": 1, "c": 1}}}', 'x["a b"].c'),
        ('[{"p": [{"q": {"k": 0, "k": 0}}]}]', "[0].p[0].q.k"),
    ],
)
def test_duplicate_keys_are_refused_with_their_path(tmp_path: Path, text: str, place: str) -> None:
    assert _refused(tmp_path, text) == f"duplicate key {place!r}"


def test_the_first_duplicate_in_file_order_is_named(tmp_path: Path) -> None:
    text = '{"a": [{"b": {"c": 1, "c": 2}}], "d": {"e": 1, "e": 2}, "a2": 0}'
    assert _refused(tmp_path, text) == "duplicate key 'a[0].b.c'"


@pytest.mark.parametrize(
    "literal, why",
    [
        ("NaN", "non-finite number NaN is not allowed"),
        ("Infinity", "non-finite number Infinity is not allowed"),
        ("-Infinity", "non-finite number -Infinity is not allowed"),
        ("1e999", "number 1e999 is out of range (it reads as infinity)"),
        ("-2.5E+400", "number -2.5E+400 is out of range (it reads as infinity)"),
        ("1" * 5000, "an integer of 5000 digits is too long"),
    ],
)
def test_non_finite_numbers_are_refused_with_their_path(
    tmp_path: Path, literal: str, why: str
) -> None:
    assert (
        _refused(tmp_path, f'{{"records": [{{"joints": {{"pan": {literal}}}}}]}}')
        == f"records[0].joints.pan: {why}"
    )


def test_a_lone_surrogate_is_refused(tmp_path: Path) -> None:
    assert (
        _refused(tmp_path, '{"name": "a\\ud800"}')
        == "name: string is not valid Unicode (a lone surrogate)"
    )
    assert (
        _refused(tmp_path, '{"\\udc00": 1}')
        == '["\\udc00"]: key is not valid Unicode (a lone surrogate)'
    )


def test_syntax_errors_name_line_and_column(tmp_path: Path) -> None:
    assert (
        _refused(tmp_path, '{\n  "a": ,\n}') == "not valid JSON (line 2, column 8: Expecting value)"
    )
    assert _refused(tmp_path, "") == "not valid JSON (line 1, column 1: Expecting value)"


def test_encodings(tmp_path: Path) -> None:
    (tmp_path / "bom.json").write_bytes(b'\xef\xbb\xbf{"a": 1}')  # Windows editors write a BOM
    assert read_json(tmp_path / "bom.json") == {"a": 1}
    assert (
        _refused(tmp_path, '{"a": "\u00e9"}'.encode("utf-16"))
        == "is UTF-16 text, expected a JSON file in UTF-8"
    )
    assert (
        _refused(tmp_path, '{"a": "\u00e9"}'.encode("utf-32"))
        == "is UTF-32 text, expected a JSON file in UTF-8"
    )
    latin1 = '{\n"a": "\u00e9"}'.encode("latin-1")
    assert (
        _refused(tmp_path, latin1)
        == "is not UTF-8 text (byte 0xe9 on line 2), expected a JSON file"
    )
    assert (
        _refused(tmp_path, b"\x89PNG\r\n\x1a\n\x00\x00") == "is a binary file, expected a JSON file"
    )


def test_text_files_keep_reading_universal_newlines(tmp_path: Path) -> None:
    (tmp_path / "crlf.csv").write_bytes(b"a,b\r\n1,2\r3\n")
    assert read_text_file(tmp_path / "crlf.csv", "a CSV file") == "a,b\n1,2\n3\n"


def test_missing_and_folder(tmp_path: Path) -> None:
    with pytest.raises(InputFileError, match="no such file"):
        read_json(tmp_path / "nope.json")
    with pytest.raises(InputFileError, match="is a folder, expected a JSON file"):
        read_json(tmp_path)


def test_output_paths_are_checked_before_the_work(tmp_path: Path) -> None:
    assert check_output_path(tmp_path / "out.json") == tmp_path / "out.json"
    with pytest.raises(OutputError, match="is a folder, expected a file path"):
        check_output_path(tmp_path)
    with pytest.raises(
        OutputError, match=f"folder {re.escape(str(tmp_path / 'no'))} does not exist"
    ):
        check_output_path(tmp_path / "no" / "out.json")
    with pytest.raises(OutputError, match="does not exist"):
        write_atomic(tmp_path / "no" / "out.json", "x")


@pytest.mark.parametrize(
    "edit, expected",
    [
        (lambda t: t.replace('"name": ', '"name": "x", "name": ', 1), "duplicate key 'name'"),
        (
            lambda t: re.sub(r'("joints": \[\s*\{)', r'\1"name": "a", ', t, count=1),
            "duplicate key 'joints[0].name'",
        ),
        (
            lambda t: re.sub(r'("lower": )[-0-9.e]+', r"\1NaN", t, count=1),
            "joints[0].lower: non-finite number NaN is not allowed",
        ),
        (lambda t: "[" * 100000 + "]" * 100000, "nested more than 64 levels deep"),
    ],
)
def test_the_cli_refuses_such_files_with_one_line_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], edit, expected: str
) -> None:
    text = json.dumps(model_to_json(load_model("iis_head")), indent=2)
    bad = tmp_path / "model.json"
    bad.write_text(edit(text))
    assert bad.read_text() != text
    out = tmp_path / "head.urdf"
    assert main(["export", str(bad), "-o", str(out)]) == 2
    cap = capsys.readouterr()
    err = cap.err.strip().splitlines()
    assert len(err) == 1 and f"{bad}: {expected}" in err[0] and "Traceback" not in cap.err, cap.err
    assert cap.out == "" and not out.exists()


# ---- atomic writes -------------------------------------------------------------------------------


def _mode(p: Path) -> int:
    return p.stat().st_mode & 0o777


def test_atomic_writes_get_the_mode_open_gives_text_or_bytes(tmp_path: Path) -> None:
    plain = tmp_path / "plain.txt"
    plain.write_text("x")  # what open() gives under this umask (0644 under the usual 022)
    text = write_atomic(tmp_path / "a.json", "{}\n")
    data = write_atomic(tmp_path / "a.png", b"\x89PNG\r\n\x00")
    both = write_all_atomic({tmp_path / "b.json": "{}\n", tmp_path / "b.png": b"\x00\x01"})
    for p in (text, data, *both):
        assert _mode(p) == _mode(plain), p
    assert data.read_bytes() == b"\x89PNG\r\n\x00" and text.read_text() == "{}\n"
    assert both[1].read_bytes() == b"\x00\x01"
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "a.json",
        "a.png",
        "b.json",
        "b.png",
        "plain.txt",
    ]


def test_write_all_leaves_none_of_the_new_files_when_the_last_rename_fails(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    old = tmp_path / "plan.json"
    old.write_text("old plan\n")
    paths = [old, tmp_path / "plan.csv", tmp_path / "plan.png"]
    real = os.replace

    def failing(src: str, dst: str | os.PathLike[str]) -> None:
        if Path(dst) == paths[-1] and str(src).endswith(".tmp"):
            raise OSError(28, "No space left on device")
        real(src, dst)

    monkeypatch.setattr(os, "replace", failing)
    with pytest.raises(OutputError, match=r"plan\.png: cannot write \(No space left on device\)"):
        write_all_atomic({paths[0]: "new plan\n", paths[1]: "csv\n", paths[2]: b"png"})
    # The file that existed is the old one again; the others were not created; no temp files.
    assert old.read_text() == "old plan\n"
    assert [p.name for p in tmp_path.iterdir()] == ["plan.json"]


def test_write_all_refuses_a_bad_path_before_writing_any(tmp_path: Path) -> None:
    with pytest.raises(OutputError, match="does not exist"):
        write_all_atomic({tmp_path / "a.json": "x", tmp_path / "no" / "b.csv": "y"})
    assert not list(tmp_path.iterdir())
