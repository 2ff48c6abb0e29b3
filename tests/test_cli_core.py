"""CLI of the foundation: export, check, bench fk, demo; exit codes and one-line errors."""

import json
import shutil
import subprocess
import sys

import pytest

from cpc2urdf.cli import main
from cpc2urdf.files.model_file import model_to_json
from cpc2urdf.files.robot_ref import load_model


def run(argv, capsys):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def test_export_then_check_passes(tmp_path, capsys):
    code, out, _ = run(["export", "iis_head", "-o", str(tmp_path / "h.urdf")], capsys)
    assert code == 0 and "6 joints" in out
    code, out, _ = run(
        ["check", str(tmp_path / "h.urdf"), "--model", "iis_head", "-n", "20"], capsys
    )
    assert code == 0
    assert "pinocchio  OK" in out and "yourdfpy   OK" in out and "urdfdom    OK" in out


def test_check_reports_a_tampered_urdf_with_exit_1(tmp_path, capsys):
    run(["export", "iis_head", "-o", str(tmp_path / "h.urdf")], capsys)
    text = (tmp_path / "h.urdf").read_text()
    # move the left vergence axis by 1 micrometre: a model/URDF mismatch the check must see
    tampered = text.replace('xyz="0.05 ', 'xyz="0.050001 ', 1)
    assert tampered != text
    (tmp_path / "t.urdf").write_text(tampered)
    code, out, _ = run(
        ["check", str(tmp_path / "t.urdf"), "--model", "iis_head", "-n", "10", "--json"], capsys
    )
    assert code == 1
    report = json.loads(out)
    by = {p["parser"]: p for p in report["parsers"]}
    assert not by["pinocchio"]["ok"] and not by["yourdfpy"]["ok"]
    assert 5e-7 < by["pinocchio"]["max_position_error"] < 1e-5


def test_check_names_missing_frames(tmp_path, capsys):
    m = load_model("iis_head").without_frames(["camera"])
    from cpc2urdf.urdf.document import write_urdf

    write_urdf(m, tmp_path / "nocam.urdf")
    code, out, _ = run(
        ["check", str(tmp_path / "nocam.urdf"), "--model", "iis_head", "-n", "3"], capsys
    )
    assert code == 1 and "frame 'camera_left_optical' missing" in out


@pytest.mark.parametrize(
    "argv, expected",
    [
        (
            ["export", "no_such_robot", "-o", "{tmp}/x.urdf"],
            "no_such_robot: no such file, and not a shipped robot name",
        ),
        (
            ["export", "iis_head", "-o", "{tmp}/missing/x.urdf"],
            "folder {tmp}/missing does not exist",
        ),
        (["export", "{tmp}/bad.json", "-o", "{tmp}/x.urdf"], "bad.json: not valid JSON"),
        (["export", "{tmp}/cycle.json", "-o", "{tmp}/x.urdf"], "do not connect to 'base'"),
        (["check", "{tmp}/none.urdf", "--model", "iis_head"], "none.urdf: no such file"),
        (
            ["check", "{tmp}/x.urdf", "--model", "iis_head", "-n", "0"],
            "--configurations must be at least 1",
        ),
        (["export", "iis_head"], "the following arguments are required: -o/--output"),
    ],
)
def test_bad_input_one_line_exit_2_no_partial_file(tmp_path, capsys, argv, expected):
    (tmp_path / "bad.json").write_text('{"format": "cpc2urdf/model@1", "name": ')
    doc = model_to_json(load_model("iis_head"))
    doc["joints"][0]["parent"] = "tilt"
    (tmp_path / "cycle.json").write_text(json.dumps(doc))
    before = set(tmp_path.iterdir())
    code, out, err = run([a.replace("{tmp}", str(tmp_path)) for a in argv], capsys)
    assert code == 2
    assert expected.replace("{tmp}", str(tmp_path)) in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert set(tmp_path.iterdir()) == before  # nothing written


def test_console_script_and_module_entry_point(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "cpc2urdf", "export", "nope", "-o", str(tmp_path / "x")],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1


def test_bench_fk_small(capsys):
    code, out, _ = run(
        ["bench", "fk", "--configurations", "200", "--repeat", "1", "--json"], capsys
    )
    r = json.loads(out)
    assert code == 0 and r["max_abs_difference"] < 1e-12 and r["cpc_vectorised_per_s"] > 0


@pytest.mark.slow
def test_demo_runs(demo_run):
    d, code, out = demo_run
    assert code == 0, out
    for name in (
        "nominal.urdf",
        "stage1_model.json",
        "model.json",
        "head.urdf",
        "view.html",
        "reach.png",
        "reach.html",
    ):
        assert (d / name).is_file(), name
    assert out.count("result: all parsers agree with the CPC model") == 3
    assert "predicted rms" in out and "policy cyclopean:" in out
    model = load_model(d / "model.json")
    assert model.metadata.handeye.keys() == {"camera_left_optical", "camera_right_optical"}
    assert model.metadata.uncertainty is not None


@pytest.mark.slow
def test_demo_from_images_runs(tmp_path, capsys):
    code, out, _ = run(["demo", "-o", str(tmp_path / "demo"), "--from-images"], capsys)
    assert code == 0, out
    d = tmp_path / "demo"
    assert len(list((d / "images" / "left").glob("*.png"))) == 55
    assert (d / "measurements.json").is_file() and (
        d / "handeye" / "handeye_camera_left_optical.json"
    ).is_file()
    assert out.count("result: all parsers agree with the CPC model") == 3


@pytest.mark.parametrize(
    "group",
    [["study", "fig11"], ["study", "crb"], ["study", "stage2"], ["bench", "fk"], ["bench", "gaze"]],
)
def test_study_and_bench_options_return_exit_codes(group, capsys):
    # main() returns (never raises SystemExit) for a study's or benchmark's own parser too
    code, _, err = run([*group, "--bogus"], capsys)
    assert code == 2 and err.count("\n") == 1 and "unrecognized arguments: --bogus" in err
    code, out, _ = run([*group, "--help"], capsys)
    assert code == 0 and "usage:" in out


@pytest.mark.slow
@pytest.mark.parametrize(
    "argv, option, read",
    [
        (["export", "{m}", "-o", "{m}"], "-o", "model"),  # replaced the model with a URDF
        (["identify", "{ms}", "-o", "{ms}"], "-o", "measurements"),
        (["view", "{m}", "--html", "{m}"], "--html", "robot"),
        (["view", "{u}", "--html", "{d}/v.html", "--screenshot", "{u}"], "--screenshot", "robot"),
        (["reach", "{m}", "-o", "{d}/r.png", "--json", "{m}"], "--json", "robot"),
        (["reach", "{m}", "-o", "{d}/r.png", "--html", "{d}/./model.json"], "--html", "robot"),
        (
            ["simulate", "{d}/truth.json", "-o", "{d}"],
            "-o (its truth.json)",
            "robot",
        ),  # replaced its robot
        (
            [
                "plan",
                "iis_head",
                "--n",
                "5",
                "--task-region",
                "{d}/task.csv",
                "-o",
                "{d}/task.json",
            ],
            "-o (its .csv)",
            "task-region",
        ),  # wrote its plan's CSV over the task configurations
        (
            ["measure", "{d}", "--rig", "{d}/rig.yaml", "-o", "{d}/joints.csv"],
            "-o",
            "joints (default IMAGES_DIR/joints.csv)",
        ),  # the readings it reads without being named
        (
            ["bench", "gaze", "--urdf", "{u}", "--camera", "camera_left_optical", "--json", "{u}"],
            "--json",
            "urdf",
        ),
        (
            ["measure", "{d}", "--rig", "{r}", "--board", "plate_left={c}", "-o", "{c}"],
            "-o",
            "board",
        ),  # NAME=FILE
    ],
)
def test_no_command_writes_over_a_file_it_reads(demo_run, tmp_path, capsys, argv, option, read):
    """An output naming an input file is refused before anything runs, and the input is intact."""
    d, _, _ = demo_run
    files = {
        "m": tmp_path / "model.json",
        "ms": tmp_path / "measurements.json",
        "u": tmp_path / "head.urdf",
        "t": tmp_path / "truth.json",
        "c": tmp_path / "task.csv",
        "j": tmp_path / "joints.csv",
        "r": tmp_path / "rig.yaml",
    }
    for key, source in (
        ("m", d / "model.json"),
        ("ms", d / "sim" / "measurements.json"),
        ("u", d / "head.urdf"),
        ("t", d / "sim" / "truth.json"),
    ):
        shutil.copy(source, files[key])
    for key in ("c", "j", "r"):
        files[key].write_text("stands for a user's file\n")
    before = {p: p.read_bytes() for p in files.values()}
    args = [a.format(d=tmp_path, **{k: str(v) for k, v in files.items()}) for a in argv]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        len(err) == 1 and f"{option} " in err[0] and f"the same file as the input {read}" in err[0]
    ), err
    assert {p: p.read_bytes() for p in files.values()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(p.name for p in files.values())


def test_an_output_over_a_file_an_input_names_or_another_output_is_refused(tmp_path, capsys):
    """A model identified from a user's URDF names that URDF (export writes back into a copy of
    it); an export over it replaced it and the model could not be exported again. Two outputs
    naming one file are refused too; an output over an existing file nothing reads is not."""
    from test_view_writeback import identified_tiago

    urdf, _, model_file = identified_tiago(tmp_path)
    before = urdf.read_bytes()
    assert main(["export", str(model_file), "-o", str(urdf)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"the file the input model ({model_file}) refers to" in err[0], err
    assert urdf.read_bytes() == before
    assert (
        main(
            [
                "view",
                "iis_head",
                "--html",
                str(tmp_path / "v.html"),
                "--screenshot",
                str(tmp_path / "./v.html"),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert (
        "--screenshot" in err
        and "the same file as --html" in err
        and not (tmp_path / "v.html").exists()
    )
    # handeye may update its model in place, not write over the URDF the model names
    poses = tmp_path / "poses.json"
    poses.write_text("{}")
    assert main(["handeye", str(poses), "--model", str(model_file), "-o", str(urdf)]) == 2
    assert f"the file the input model ({model_file}) refers to" in capsys.readouterr().err
    # a model file by another name is read as JSON all the same (the loaders do)
    other = tmp_path / "calibrated.model"
    shutil.copy(model_file, other)
    assert main(["export", str(other), "-o", str(urdf)]) == 2
    assert "refers to" in capsys.readouterr().err
    assert main(["simulate", "iis_head", "-o", ""]) == 2  # simulate read "" as the current folder
    assert "-o '': an empty path" in capsys.readouterr().err
    # a model saved with a byte-order mark (PowerShell 5) is read as the loaders read it
    bom = tmp_path / "bom.json"
    bom.write_bytes(b"\xef\xbb\xbf  \n" + model_file.read_bytes())
    assert main(["export", str(bom), "-o", str(urdf)]) == 2
    assert "refers to" in capsys.readouterr().err
    # handeye may replace a model file in place, not a URDF given as its model
    assert main(["handeye", str(poses), "--model", str(urdf), "-o", str(urdf)]) == 2
    assert "the same file as the input model" in capsys.readouterr().err
    # export also writes a calibration report next to a written-back URDF
    report = tmp_path / "cal.report.json"
    shutil.copy(model_file, report)
    assert main(["export", str(report), "-o", str(tmp_path / "cal.urdf")]) == 2
    assert "-o (its report)" in capsys.readouterr().err
    # ... only then: a model cpc2urdf exports itself writes no report, so none is refused
    from cpc2urdf.files.model_file import save_model

    plain = save_model(load_model("iis_head"), tmp_path / "plain.report.json")
    assert main(["export", str(plain), "-o", str(tmp_path / "plain.urdf")]) == 0
    capsys.readouterr()
    assert (
        main(["export", str(model_file), "-o", str(tmp_path)]) == 2
    )  # a folder: one line (a traceback before)
    assert "is a folder" in capsys.readouterr().err
    assert urdf.read_bytes() == before
    out = tmp_path / "calibrated.urdf"
    out.write_text("an old export\n")
    assert (
        main(["export", str(model_file), "-o", str(out)]) == 0
    )  # overwriting an output nothing reads
    assert out.read_text().startswith("<?xml")


@pytest.mark.slow
def test_a_bare_robot_name_is_the_shipped_robot_not_a_file_beside(demo_run, tmp_path, capsys):
    """A measurement file's robot "iis_head" is the shipped robot even with a file of that name
    beside it (the loader's rule): an output there is not refused."""
    d, _, _ = demo_run
    folder = tmp_path / "s"
    folder.mkdir()
    shutil.copy(d / "sim" / "measurements.json", folder / "measurements.json")
    (folder / "iis_head").write_text("an earlier output\n")
    assert (
        main(["identify", str(folder / "measurements.json"), "-o", str(folder / "iis_head")]) == 0
    )
    capsys.readouterr()
    assert load_model(folder / "iis_head").structure.joint_names[0] == "table_x"


@pytest.mark.slow
def test_handeye_may_update_its_model_in_place(demo_run, tmp_path, capsys):
    """``handeye --model M -o M`` adds the camera frame to M, as its help says (atomically)."""
    d, _, _ = demo_run
    model = tmp_path / "stage1.json"
    shutil.copy(d / "stage1_model.json", model)
    assert (
        main(
            [
                "handeye",
                str(d / "handeye_camera_left_optical.json"),
                "--model",
                str(model),
                "-o",
                str(model),
            ]
        )
        == 0
    )
    capsys.readouterr()
    assert "camera_left_optical" in [f.name for f in load_model(model).structure.frames]
