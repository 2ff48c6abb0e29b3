"""The Python API is the product: the README's block runs, and gives the CLI's model."""

from __future__ import annotations

import contextlib
import io
import os
import re
from pathlib import Path

import numpy as np
import pytest

import cpc2urdf
from cpc2urdf.cli import main
from cpc2urdf.errors import ConfigurationError
from cpc2urdf.files.robot_ref import load_model

README = Path(__file__).resolve().parents[1] / "README.md"


def readme_python_block() -> str:
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    assert len(blocks) == 1, "the README has one Python block: the pipeline"
    return blocks[0]


def assert_same_geometry(a: cpc2urdf.CPCModel, b: cpc2urdf.CPCModel, tol: float = 1e-12) -> None:
    assert a.structure.joint_names == b.structure.joint_names
    assert a.structure.frame_names == b.structure.frame_names
    np.testing.assert_allclose(a.world_to_base.matrix(), b.world_to_base.matrix(), rtol=0, atol=tol)
    for name in a.structure.joint_names:
        np.testing.assert_allclose(
            a.joints[name].matrix(), b.joints[name].matrix(), rtol=0, atol=tol, err_msg=name
        )
    for name in a.structure.frame_names:
        np.testing.assert_allclose(
            a.frames[name].matrix(), b.frames[name].matrix(), rtol=0, atol=tol, err_msg=name
        )


@pytest.fixture(scope="module")
def readme_run(tmp_path_factory):
    """The README's block, run in an empty folder."""
    work = tmp_path_factory.mktemp("readme")
    cwd = os.getcwd()
    os.chdir(work)
    out = io.StringIO()
    try:
        with contextlib.redirect_stdout(out):
            exec(compile(readme_python_block(), str(README), "exec"), {"__name__": "__readme__"})
    finally:
        os.chdir(cwd)
    return work, out.getvalue()


def test_readme_block_runs_and_writes_every_artefact(readme_run):
    work, out = readme_run
    for name in ("model.json", "head.urdf", "view.html"):
        assert (work / name).is_file(), name
    assert "plate_left held-out rms" in out and "plate_right held-out rms" in out


def test_readme_block_gives_the_cli_model(readme_run, capsys):
    work, _ = readme_run
    cli_out = work / "cli_model.json"
    assert main(["simulate", "iis_head", "--seed", "0", "-o", str(work / "sim")]) == 0
    assert main(["identify", str(work / "sim" / "measurements.json"), "-o", str(cli_out)]) == 0
    capsys.readouterr()
    api_model, cli_model = load_model(work / "model.json"), load_model(cli_out)
    assert_same_geometry(api_model, cli_model)
    assert api_model.metadata.provenance.method == cli_model.metadata.provenance.method == "refined"


def test_api_defaults_are_the_stages_defaults():
    """The API spells its defaults out (its stages load on first call); they are the stages' own."""
    import inspect

    from cpc2urdf.identification.handeye.solvers import DEFAULT_HANDEYE_METHOD
    from cpc2urdf.identification.kinematics.methods import DEFAULT_METHOD
    from cpc2urdf.identification.planning.plan_selection import DEFAULT_CANDIDATES
    from cpc2urdf.identification.simulation import stage1_experiment as sim

    def default(f, name):
        return inspect.signature(f).parameters[name].default

    assert default(cpc2urdf.identify, "method") == DEFAULT_METHOD
    assert (
        default(cpc2urdf.solve_handeye, "method")
        == default(cpc2urdf.calibrate_cameras, "method")
        == DEFAULT_HANDEYE_METHOD
    )
    assert default(cpc2urdf.plan_experiment, "candidates") == DEFAULT_CANDIDATES
    assert default(cpc2urdf.simulate, "M") == sim.DEFAULT_M
    assert default(cpc2urdf.simulate, "heldout") == sim.DEFAULT_HELDOUT
    assert default(cpc2urdf.simulate, "sigma_mm") == pytest.approx(sim.DEFAULT_SIGMA_T * 1e3)
    assert default(cpc2urdf.simulate, "sigma_deg") == pytest.approx(np.degrees(sim.DEFAULT_SIGMA_R))


@pytest.fixture(scope="module")
def measurement_file(tmp_path_factory):
    """``cpc2urdf simulate iis_head``'s measurement file."""
    d = tmp_path_factory.mktemp("sim")
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["simulate", "iis_head", "-o", str(d)]) == 0
    return d / "measurements.json"


def test_identify_from_a_path_equals_identify_of_the_loaded_set(measurement_file):
    path = measurement_file
    a = cpc2urdf.identify(path, "closed-form")
    b = cpc2urdf.identify(cpc2urdf.load_measurements(path), "closed-form")
    assert_same_geometry(a, b, tol=0.0)
    # the robot's nominal model keeps the camera frames the plates do not measure
    assert "camera_left_optical" in a.structure.frame_names


def test_api_refuses_robot_override_with_a_loaded_set(measurement_file):
    ms = cpc2urdf.load_measurements(measurement_file)
    with pytest.raises(ConfigurationError, match="robot= applies to a measurement file path"):
        cpc2urdf.identify(ms, robot="iis_head")


def test_import_cpc2urdf_is_light_and_lists_the_api():
    import subprocess
    import sys

    code = (
        "import sys, cpc2urdf; heavy = [m for m in ('pinocchio', 'cv2', 'meshcat', 'numba') if m in sys.modules]; "
        "print(heavy); print(callable(cpc2urdf.identify))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout.split("\n")
    assert out[0] == "[]" and out[1] == "True"
    assert {
        "identify",
        "export_urdf",
        "check_urdf",
        "calibrate_cameras",
        "gaze_solver",
        "write_view",
    } <= set(cpc2urdf.__all__)
    assert (
        len(cpc2urdf.__all__) <= 22
    )  # the pipeline's verbs and the model type; result types stay in their subpackages


def test_identify_from_a_file_loads_no_pinocchio_opencv_meshcat_or_numba(measurement_file):
    import subprocess
    import sys

    path = measurement_file
    code = (
        f"import sys, cpc2urdf; cpc2urdf.identify({str(path)!r}); "
        "print([m for m in ('pinocchio', 'cv2', 'meshcat', 'numba') if m in sys.modules])"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    assert out.strip() == "[]"
