"""Tracker CSV exports -> measurement sets: both layouts, units from a header or an option, the same
set as the JSON route, and refusals naming the file, row and column."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from cpc2urdf.errors import InputFileError
from cpc2urdf.files.marker_csv import load_marker_csv
from cpc2urdf.files.robot_ref import load_robot
from cpc2urdf.identification.simulation.design import protocol_q
from cpc2urdf.identification.simulation.marker_points import place_markers_on, simulate_markers
from cpc2urdf.identification.simulation.truth import perturbed_model


@pytest.fixture(scope="module")
def data():
    spec = load_robot("iis_head")
    rng = np.random.default_rng(0)
    truth = perturbed_model(spec.nominal_model(), rng, 1e-3, np.radians(0.5))
    markers = place_markers_on(truth, {"plate_left": 2, "plate_right": 1}, rng)
    ms = simulate_markers(truth, markers, protocol_q(truth, 2), robot="iis_head")
    return spec, ms, {m: f for m, (f, _) in markers.items()}


def _write(
    path: Path, header: list[str], rows: list[list[object]], units: str | None = None
) -> Path:
    with path.open("w", newline="") as fh:
        if units:
            fh.write(f"# units: {units}\n")
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)
    return path


def _one_file(ms, folder: Path, mm_deg: bool) -> Path:
    s = ms.structure
    k_len, k_ang = (1e3, np.degrees(1.0)) if mm_deg else (1.0, 1.0)
    rows = []
    for i in range(ms.n_records):
        q = [
            v * (k_len if j.type == "prismatic" else k_ang)
            for v, j in zip(ms.q[i], s.joints, strict=True)
        ]
        for m, Y in ms.marker_points.items():
            rows.append([f"c{i}", m, *(Y[i] * k_len), *q])
    return _write(
        folder / "points.csv",
        ["config", "marker", "x", "y", "z", *s.joint_names],
        rows,
        "length=mm angle=deg" if mm_deg else None,
    )


def _assert_same(got, ms) -> None:
    np.testing.assert_allclose(got.q, ms.q, rtol=1e-12, atol=1e-15)
    assert set(got.marker_points) == set(ms.marker_points)
    for m, Y in ms.marker_points.items():
        np.testing.assert_allclose(got.marker_points[m], Y, rtol=1e-12, atol=1e-15)
        assert got.markers[m].frame == ms.markers[m].frame
    assert got.labels == [f"c{i}" for i in range(ms.n_records)]


@pytest.mark.parametrize("mm_deg", [False, True])
def test_one_file_layout(data, tmp_path, mm_deg):
    spec, ms, links = data
    got = load_marker_csv(_one_file(ms, tmp_path, mm_deg), spec, links, robot_ref="iis_head")
    _assert_same(got, ms)


def test_two_file_layout_with_units_option(data, tmp_path):
    spec, ms, links = data
    s = ms.structure
    pts = _write(
        tmp_path / "p.csv",
        ["config", "marker", "x", "y", "z"],
        [
            [f"c{i}", m, *(Y[i] * 1e3)]
            for i in range(ms.n_records)
            for m, Y in ms.marker_points.items()
        ],
    )
    jts = _write(
        tmp_path / "j.csv",
        ["config", *s.joint_names],
        [
            [f"c{i}", *(ms.q[i] * [1e3 if j.type == "prismatic" else 1.0 for j in s.joints])]
            for i in range(ms.n_records)
        ],
    )
    got = load_marker_csv(
        pts, spec, links, joints_csv=jts, length="mm", angle="rad", noise_sigma_p=1e-4
    )
    _assert_same(got, ms)
    assert got.metadata["noise"]["sigma_p_m"] == 1e-4


def test_refusals_name_file_row_and_column(data, tmp_path):
    spec, ms, links = data
    good = _one_file(ms, tmp_path, False)
    text = good.read_text().splitlines()

    def refused(lines: list[str], match: str, **kw) -> None:
        path = tmp_path / "bad.csv"
        path.write_text("\n".join(lines) + "\n")
        with pytest.raises(InputFileError, match=match) as e:
            load_marker_csv(path, spec, kw.pop("links", links), **kw)
        assert str(path) in str(e.value) and "\n" not in str(e.value)

    refused(
        [text[0] + ",temperature", *(r + ",20" for r in text[1:])], "unknown column 'temperature'"
    )
    refused([text[0].replace("x,", "east,"), *text[1:]], "lacks column 'x'")
    refused(
        text,
        "marker 'plate_right_m0' has no link",
        links={k: v for k, v in links.items() if k != "plate_right_m0"},
    )
    bad = text[1].split(",")
    bad[2] = "n/a"
    refused([text[0], ",".join(bad), *text[2:]], "row 2, column 'x': 'n/a' is not a number")
    refused([text[0], *text[1:], text[1]], "appears twice in configuration 'c0'")
    other = text[2].split(",")
    other[-1] = str(float(other[-1]) + 0.1)
    refused(
        [text[0], text[1], ",".join(other), *text[3:]],
        "configuration 'c0' has other joint readings",
    )
    refused(["# units: length=furlong", *text], "units.length must be one of")
    refused(text, "'elbow'", links={**links, "plate_left_m0": "elbow"})
