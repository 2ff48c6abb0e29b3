"""The Fig. 11 study runs end to end at tiny sizes (the full study is `cpc2urdf study fig11`)."""

from __future__ import annotations

from pathlib import Path

from cpc2urdf.cli import main


def test_fig11_study_writes_table_json_and_plot(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "fig11"
    argv = [
        "study",
        "fig11",
        "--M",
        "2,5",
        "--sigmas",
        "0,0.5",
        "--trials",
        "1",
        "--heldout",
        "3",
        "--out",
        str(out),
    ]
    assert main(argv) == 0
    text = (out / "fig11.md").read_text()
    assert "| 5 |" in text and "σ = 0.5 mm" in text and "paper's conclusion" in text
    assert (out / "fig11.png").stat().st_size > 1000
    assert "Reference (same run, noise-free data)" in capsys.readouterr().out


def test_fig11_bad_options_exit_2(tmp_path: Path) -> None:
    assert main(["study", "fig11", "--M", "1:3", "--out", str(tmp_path)]) == 2
    assert main(["study", "fig11", "--M", "x", "--out", str(tmp_path)]) == 2
