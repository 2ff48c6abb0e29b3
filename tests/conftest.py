import contextlib
import io
import os

import pytest

os.environ.setdefault("CPC2URDF_PROGRESS", "0")
os.environ.setdefault("MPLBACKEND", "Agg")
# the gaze kernels compile on their first call, as they did before a first use in Python
# (kernels.interpreted); tests/test_first_use.py runs that first use
os.environ.setdefault("CPC2URDF_GAZE_FIRST_USE", "compile")


@pytest.fixture(scope="session")
def demo_run(tmp_path_factory):
    """``cpc2urdf demo -o DIR`` once per test session: ``(DIR, exit code, stdout)``."""
    from cpc2urdf.cli import main

    d = tmp_path_factory.mktemp("demo") / "demo-out"
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["demo", "-o", str(d)])
    return d, code, out.getvalue()
