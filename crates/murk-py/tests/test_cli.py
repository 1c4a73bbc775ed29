"""Byte equality with the `murk` CLI of this workspace on the real scans.

The CLI seeds each scan by (seed, key), key = the file's path relative to the
input argument; murk.apply(..., key=...) with the same key must give the bytes
the CLI writes.
"""

from __future__ import annotations

import json
import shutil
import subprocess

import numpy as np
import pytest

import murk
from conftest import CAMPAIGN, real

SCANS = [
    ("kitti-000008.bin", 4, None),
    ("nuscenes-lidar-top.pcd.bin", 5, "xyzir"),
]

VARIANTS = [
    ("fog", ["--mor", "60"], dict(mor=60.0)),
    ("fog", ["--mor", "25", "--soft-edge", "--seed", "3"], dict(mor=25.0, soft_edge=True, seed=3)),
    ("fog", ["--mor", "40", "--near-range", "--seed", "11"], dict(mor=40.0, near_range=True, seed=11)),
    (
        "snow",
        ["--mor", "80", "--range-noise", "0.05", "--attenuate-intensity", "--seed", "5"],
        dict(mor=80.0, range_noise=0.05, attenuate_intensity=True, seed=5),
    ),
    ("rain", ["--rain-rate", "20", "--clamp", "--slope", "quantile"], dict(rain_rate=20.0, clamp=True, slope="quantile")),
    (
        "fog",
        ["--mor", "30", "--near-range", "--range-noise", "0.05", "--min-range", "1", "--seed", "7"],
        dict(mor=30.0, near_range=True, range_noise=0.05, min_range=1.0, seed=7),
    ),
]


def run_cli(cli, *args):
    p = subprocess.run([str(cli), *map(str, args)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    return p


@pytest.mark.parametrize("name, cols, layout", SCANS)
@pytest.mark.parametrize("weather, flags, kwargs", VARIANTS)
def test_apply_bytes_equal_cli(tmp_path, cli, fitted_every_weather, name, cols, layout, weather, flags, kwargs):
    fitted = fitted_every_weather
    src = real(name)
    table = murk.Table.load(fitted)
    if weather not in table.weathers:
        pytest.skip(f"the default campaign's table has no {weather}")
    run_cli(cli, "apply", "--coefficients", fitted, "--weather", weather, *flags, src, "--out", tmp_path / "out")
    want = (tmp_path / "out" / name).read_bytes()
    pts = np.fromfile(src, np.float32).reshape(-1, cols)
    got = murk.apply(pts, table, weather, key=name, layout=layout, **kwargs)
    assert got.shape[1] == cols
    assert got.tobytes() == want
    # And through a dict of columns (intensity scale stated as the reader's).
    if cols == 5:
        cols_in = {k: pts[:, i].copy() for i, k in enumerate(["x", "y", "z", "intensity"])}
        cols_in["ring"] = pts[:, 4].astype(np.uint16)
        d = murk.apply(cols_in, table, weather, key=name, **kwargs)
        np.testing.assert_array_equal(d["x"], got[:, 0])
        np.testing.assert_array_equal(d["ring"], got[:, 4].astype(np.uint16))


def test_folder_key_is_the_relative_path(tmp_path, cli, fitted):
    src = real("kitti-000008.bin")
    (tmp_path / "in" / "seq").mkdir(parents=True)
    shutil.copy(src, tmp_path / "in" / "seq" / "a.bin")
    run_cli(cli, "apply", "--coefficients", fitted, "--weather", "fog", "--mor", "30", "--soft-edge",
            "--seed", "9", tmp_path / "in", "--out", tmp_path / "out")
    want = (tmp_path / "out" / "seq" / "a.bin").read_bytes()
    pts = np.fromfile(src, np.float32).reshape(-1, 4)
    table = murk.Table.load(fitted)
    assert murk.apply(pts, table, "fog", mor=30, soft_edge=True, seed=9, key="seq/a.bin").tobytes() == want
    assert murk.apply(pts, table, "fog", mor=30, soft_edge=True, seed=9, key="a.bin").tobytes() != want


def test_read_then_write_equals_cli_convert(tmp_path, cli):
    src = real("nuscenes-lidar-top.pcd.bin")
    run_cli(cli, "convert", src, "--out", tmp_path / "cli", "--format", "pcd")
    (out,) = (tmp_path / "cli").iterdir()
    murk.write(tmp_path / "py.pcd", murk.read(src))
    assert (tmp_path / "py.pcd").read_bytes() == out.read_bytes()


def test_fit_equals_cli(fitted):
    t = murk.fit(CAMPAIGN, bootstrap=20)
    assert t.to_json() == fitted.read_text()
    assert "fog" in t.weathers


def test_fit_with_the_reflectivity_law_equals_cli(tmp_path, cli):
    out = tmp_path / "t.json"
    run_cli(cli, "fit", CAMPAIGN, "--out", out, "--bootstrap", "20", "--bend", "--reflectivity-law")
    t = murk.fit(CAMPAIGN, bootstrap=20, bend=True, reflectivity_law=True)
    assert t.to_json() == out.read_text()
    assert "reflectivity" in json.loads(out.read_text())["weathers"]["fog"]["law_choice"]


def test_cli_error_message_is_the_exception_message(tmp_path, cli, fitted):
    bad = tmp_path / "bad.bin"
    bad.write_bytes(b"\0" * 18)
    p = subprocess.run([str(cli), "apply", "--coefficients", str(fitted), "--weather", "fog", "--mor", "30",
                        str(bad), "--out", str(tmp_path / "o")], capture_output=True, text=True)
    assert p.returncode != 0
    with pytest.raises(murk.FileError) as e:
        murk.read(bad)
    assert f"murk: error: {e.value}" in p.stderr


def test_diagnose_equals_cli(tmp_path, cli):
    args = ["--folds", "2", "--permutations", "99", "--sims", "1", "--seed", "2"]
    run_cli(cli, "diagnose", CAMPAIGN, "--weather", "fog", "--out", tmp_path / "r.json", *args)
    want = json.loads((tmp_path / "r.json").read_text())
    # The CLI holds the kept returns in memory; here every recording's
    # spill to a temporary file in tmp_path: the same report.
    got, ext = murk.diagnose(CAMPAIGN, "fog", folds=2, permutations=99, sims=1, seed=2,
                             kept_memory_mb=0.0, spill_dir=tmp_path, extended_table=True)
    assert got == want
    assert (ext is None) == (not (tmp_path / "r.extended.json").exists())
    # The anonymous spill file leaves nothing behind.
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        p for p in ["r.json", "r.extended.json"] if (tmp_path / p).exists())


def test_diagnose_bad_spill_settings_raise_the_cli_message(tmp_path, cli):
    for flag, kw in [(["--kept-memory-mb=-1"], {"kept_memory_mb": -1.0}),
                     (["--spill-dir", str(tmp_path / "missing")], {"spill_dir": tmp_path / "missing"})]:
        p = subprocess.run([str(cli), "diagnose", str(CAMPAIGN), "--weather", "fog",
                            "--out", str(tmp_path / "r.json"), *flag], capture_output=True, text=True)
        assert p.returncode != 0
        with pytest.raises(murk.InputError) as e:
            murk.diagnose(CAMPAIGN, "fog", **kw)
        assert f"murk: error: {e.value}" in p.stderr
