"""progress_checked: the "done" line only after a block that ends without an error."""

import pytest

from cpc2urdf.progress import progress_checked


def test_done_line_only_when_the_block_succeeds(monkeypatch, capsys):
    monkeypatch.setenv("CPC2URDF_PROGRESS", "1")
    with progress_checked([1, 2, 3], "work") as it:
        assert list(it) == [1, 2, 3]
    assert "work: 3 done" in capsys.readouterr().err
    with pytest.raises(ValueError), progress_checked([1, 2, 3], "work") as it:
        for _ in it:
            raise ValueError("bad record")
    assert capsys.readouterr().err == ""


def test_silent_when_not_shown(capsys):
    with progress_checked([1, 2], "work", show=False) as it:
        assert list(it) == [1, 2]
    assert capsys.readouterr().err == ""
