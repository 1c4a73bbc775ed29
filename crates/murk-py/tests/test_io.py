"""murk.read / murk.write: round trips through every writable format, errors."""

from __future__ import annotations

import numpy as np
import pytest

import murk
from conftest import real


def cloud(n=500, seed=2, time=False):
    rng = np.random.default_rng(seed)
    c = {
        "x": rng.uniform(-50, 50, n).astype(np.float32),
        "y": rng.uniform(-50, 50, n).astype(np.float32),
        "z": rng.uniform(-3, 3, n).astype(np.float32),
        "intensity": rng.integers(0, 256, n).astype(np.float32),
        "ring": rng.integers(0, 16, n).astype(np.uint16),
    }
    if time:
        c["time"] = np.sort(rng.uniform(0, 0.1, n)).astype(np.float32)
    return c


def same(a, b, keys):
    for k in keys:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)


@pytest.mark.parametrize("pcd_data", ["ascii", "binary", "binary_compressed"])
def test_pcd_round_trip(tmp_path, pcd_data):
    c = cloud(time=True)
    murk.write(tmp_path / "a.pcd", c, pcd_data=pcd_data)
    back = murk.read(tmp_path / "a.pcd")
    same(back, c, ["x", "y", "z", "intensity", "ring", "time"])
    assert back["ring"].dtype == np.uint16 and back["x"].dtype == np.float32


@pytest.mark.parametrize("name", ["a.csv", "a.parquet", "a.pcd.bin"])
def test_ring_formats_round_trip(tmp_path, name):
    c = cloud()
    murk.write(tmp_path / name, c)
    same(murk.read(tmp_path / name), c, ["x", "y", "z", "intensity", "ring"])


def test_kitti_round_trip_and_array_write(tmp_path):
    c = cloud()
    murk.write(tmp_path / "a.bin", c)
    back = murk.read(tmp_path / "a.bin")
    same(back, c, ["x", "y", "z", "intensity"])
    # The bytes are the records themselves.
    recs = np.column_stack([c[k] for k in ("x", "y", "z", "intensity")]).astype(np.float32)
    assert (tmp_path / "a.bin").read_bytes() == recs.tobytes()
    murk.write(tmp_path / "b.bin", recs)
    assert (tmp_path / "b.bin").read_bytes() == recs.tobytes()
    # Format forced, whatever the extension.
    murk.write(tmp_path / "c.dat", c, format="nuscenes")
    same(murk.read(tmp_path / "c.dat", format="nuscenes"), c, ["x", "y", "z", "intensity", "ring"])


def test_no_temporary_file_left(tmp_path):
    murk.write(tmp_path / "a.pcd", cloud())
    assert [p.name for p in tmp_path.iterdir()] == ["a.pcd"]


def test_real_scans():
    k = murk.read(real("kitti-000008.bin"))
    raw = np.fromfile(real("kitti-000008.bin"), np.float32).reshape(-1, 4)
    np.testing.assert_array_equal(np.column_stack([k[c] for c in ("x", "y", "z", "intensity")]), raw)
    n = murk.read(real("nuscenes-lidar-top.pcd.bin"))
    raw = np.fromfile(real("nuscenes-lidar-top.pcd.bin"), np.float32).reshape(-1, 5)
    np.testing.assert_array_equal(n["ring"], raw[:, 4].astype(np.uint16))


def test_pcap_frames():
    frames = murk.read(real("vlp16-test-90deg-1-50-frames.pcap"), frames=True)
    whole = murk.read(real("vlp16-test-90deg-1-50-frames.pcap"))
    assert len(frames) >= 49
    assert sum(len(f["x"]) for f in frames) == len(whole["x"])
    assert "time" in whole and whole["ring"].max() <= 15


def test_pcap_return_is_a_return_the_capture_recorded(tmp_path):
    # The real capture is single-return (strongest): its strongest returns
    # are what it recorded; its last ones it does not have, and the error is
    # the CLI's (file, packet).
    path = real("vlp16-test-90deg-1-50-frames.pcap")
    whole = murk.read(path)
    strongest = murk.read(path, pcap_return="strongest")
    for c in ("x", "y", "z", "intensity", "ring"):
        np.testing.assert_array_equal(whole[c], strongest[c])
    with pytest.raises(murk.FileError, match=r"vlp16-test-90deg-1-50-frames.pcap: packet \d+ .*asked for last returns"):
        murk.read(path, pcap_return="last")
    with pytest.raises(murk.InputError, match="pcap_return: .*strongest or last"):
        murk.read(path, pcap_return="first")


def test_read_errors(tmp_path):
    with pytest.raises(murk.FileError, match="missing.pcd"):
        murk.read(tmp_path / "missing.pcd")
    (tmp_path / "bad.bin").write_bytes(b"\0" * 18)
    with pytest.raises(murk.FileError, match=r"bad.bin.*2"):
        murk.read(tmp_path / "bad.bin")
    (tmp_path / "a.txt").write_text("x")
    with pytest.raises(murk.FileError, match="a.txt"):
        murk.read(tmp_path / "a.txt")
    with pytest.raises(murk.InputError, match="format"):
        murk.read(tmp_path / "a.txt", format="las")


def test_write_errors(tmp_path):
    c = cloud()
    with pytest.raises(murk.InputError, match="pcd_data"):
        murk.write(tmp_path / "a.pcd", c, pcd_data="zip")
    with pytest.raises(murk.InputError, match="does not write"):
        murk.write(tmp_path / "a.pcap", c)
    c["x"][3] = np.nan
    with pytest.raises(murk.InputError, match=r"cloud: point 3: x is NaN"):
        murk.write(tmp_path / "a.pcd", c)
    assert not (tmp_path / "a.pcd").exists()
