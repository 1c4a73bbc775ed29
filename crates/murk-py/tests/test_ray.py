"""murk.ray on a local Ray cluster: outputs equal the CLI's bytes."""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest

import murk
from conftest import CAMPAIGN, REAL, scan

ray = pytest.importorskip("ray", reason="ray is not installed (pip install 'murk[ray]')")
import murk.ray  # noqa: E402


@pytest.fixture(scope="module")
def local_ray():
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


def make_inputs(root):
    """A folder of scans in several formats and sub-folders (real ones when present)."""
    (root / "a" / "b").mkdir(parents=True)
    for i in range(6):
        pts = scan(20000, seed=100 + i)
        pts.tofile(root / "a" / f"s{i}.bin")
        murk.write(root / "a" / "b" / f"s{i}.pcd", pts, layout="xyzi")
    murk.write(root / "a" / "c.csv", scan(5000, seed=99, columns=5))
    for name in ("kitti-000008.bin", "nuscenes-lidar-top.pcd.bin"):
        if (REAL / name).is_file():
            shutil.copy(REAL / name, root / name)
    (root / "notes.txt").write_text("not a scan")


def test_ray_apply_equals_cli(tmp_path, cli, fitted, local_ray):
    make_inputs(tmp_path / "in")
    flags = ["--weather", "fog", "--mor", "35", "--soft-edge", "--near-range", "--seed", "4"]
    p = subprocess.run([str(cli), "apply", "--coefficients", str(fitted), *flags, str(tmp_path / "in"),
                        "--out", str(tmp_path / "cli")], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    rows = murk.ray.apply([tmp_path / "in"], tmp_path / "ray", murk.Table.load(fitted), "fog",
                          mor=35.0, soft_edge=True, near_range=True, seed=4, batch_size=3)
    cli_files = sorted(f.relative_to(tmp_path / "cli") for f in (tmp_path / "cli").rglob("*") if f.is_file())
    ray_files = sorted(f.relative_to(tmp_path / "ray") for f in (tmp_path / "ray").rglob("*") if f.is_file())
    assert cli_files == ray_files and len(ray_files) >= 13
    for f in cli_files:
        assert (tmp_path / "ray" / f).read_bytes() == (tmp_path / "cli" / f).read_bytes(), f
    assert [r["key"] for r in rows] == [j[2] for j in murk.ray.plan([tmp_path / "in"], tmp_path / "x")[0]]
    assert all(r["points_out"] <= r["points_in"] + 10000 for r in rows)


def test_apply_files_in_process_equals_ray(tmp_path, fitted, local_ray):
    make_inputs(tmp_path / "in")
    table = murk.Table.load(fitted)
    a = murk.apply_files(tmp_path / "in", tmp_path / "local", table, "fog", mor=50.0, seed=2)
    b = murk.ray.apply(tmp_path / "in", tmp_path / "ray", table, "fog", mor=50.0, seed=2)
    assert [x["points_out"] for x in a] == [x["points_out"] for x in b]
    for r in b:
        rel = r["key"]
        assert (tmp_path / "ray" / rel).read_bytes() == (tmp_path / "local" / rel).read_bytes()


def test_ray_errors_are_raised_on_the_driver(tmp_path, fitted, local_ray):
    make_inputs(tmp_path / "in")
    with pytest.raises(murk.InputError, match="weather: unknown weather class"):
        murk.ray.apply(tmp_path / "in", tmp_path / "o", fitted, "hail", mor=30.0)
    (tmp_path / "empty").mkdir()
    with pytest.raises(murk.InputError, match="no point-cloud file"):
        murk.ray.apply(tmp_path / "empty", tmp_path / "o", fitted, "fog", mor=30.0)


def test_ray_fit_equals_cli(fitted, local_ray):
    """Map (3 clear and 3 degraded shards) and merge on Ray: murk fit's bytes."""
    t = murk.ray.fit(CAMPAIGN, shards=3, bootstrap=20)
    assert t.to_json() == fitted.read_text()
