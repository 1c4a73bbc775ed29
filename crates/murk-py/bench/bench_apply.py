#!/usr/bin/env python3
"""murk.apply vs the same work timed inside Rust, and the per-call overhead.

    python3 crates/murk-py/bench/bench_apply.py [--points 120000] [--repeats 200]

Build the wheel in release first for meaningful figures
(`pip install ./crates/murk-py`, or `maturin develop --release -m crates/murk-py/Cargo.toml`).

The scan is the real KITTI scan of ../shared/data/real tiled to --points
(synthetic when absent), fog at MOR 60 with the seed's Table 4 slopes. "Rust"
is murk._murk._rust_apply_seconds: build the applier, decode the records,
apply, lay the output out, timed with std::time::Instant inside one call (no
Python in the loop). "murk.apply" is the Python call on the same array,
timed with perf_counter. Their difference is what the binding costs. The
published pandas way (DataFrame, range, band mask, back to numpy) runs on the
same array for comparison, when pandas is installed.
"""

from __future__ import annotations

import argparse
import pathlib
import statistics
import sys
import time

import numpy as np

import murk
from murk import _murk

HERE = pathlib.Path(__file__).resolve()
sys.path.insert(0, str(HERE.parent.parent / "tests"))
from conftest import REAL, TABLE_JSON, scan  # noqa: E402

LOW, HIGH = 0.30286536, 0.34634364


def kitti_scan(n: int) -> np.ndarray:
    p = REAL / "kitti-000008.bin"
    if not p.is_file():
        print(f"({p} absent: synthetic scan)")
        return scan(n, seed=1)
    base = np.fromfile(p, np.float32).reshape(-1, 4)
    reps = -(-n // len(base))
    return np.ascontiguousarray(np.tile(base, (reps, 1))[:n])


def timed(f, repeats):
    ts = []
    for _ in range(repeats):
        t = time.perf_counter()
        f()
        ts.append(time.perf_counter() - t)
    return ts


def pandas_way(pts: np.ndarray, mor: float):
    import pandas as pd

    df = pd.DataFrame(pts, columns=["x", "y", "z", "intensity"])
    r = np.sqrt(df.x**2 + df.y**2 + df.z**2)
    refl = df.intensity * 255
    keep = ((refl < 10) & (r <= LOW * mor)) | ((refl >= 10) & (r <= HIGH * mor))
    return df[keep].to_numpy()


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=120_000)
    ap.add_argument("--repeats", type=int, default=200)
    ap.add_argument("--mor", type=float, default=60.0)
    a = ap.parse_args()
    table = murk.Table.from_json(TABLE_JSON)
    pts = kitti_scan(a.points)
    out = murk.apply(pts, table, "fog", mor=a.mor)
    print(f"scan: {len(pts)} points, {len(out)} kept at MOR {a.mor} m; murk {murk.__version__}")
    med = statistics.median
    for threads in (1, None):
        label = "1 thread" if threads == 1 else f"{murk.get_num_threads()} threads"
        for _ in range(3):  # warm up
            murk.apply(pts, table, "fog", mor=a.mor, threads=threads)
        rust = _murk._rust_apply_seconds(pts, table, "fog", a.mor, a.repeats, threads=threads)
        py = timed(lambda: murk.apply(pts, table, "fog", mor=a.mor, threads=threads), a.repeats)
        r, p = med(rust), med(py)
        print(
            f"{label:>10}: Rust {r * 1e6:8.1f} µs, murk.apply {p * 1e6:8.1f} µs "
            f"({100 * (p / r - 1):+.1f} %), {len(pts) / p / 1e6:.0f} M points/s"
        )
    empty = np.zeros((0, 4), np.float32)
    tiny = pts[:1].copy()
    for name, arr in (("empty scan", empty), ("1-point scan", tiny)):
        rust = med(_murk._rust_apply_seconds(arr, table, "fog", a.mor, 5000, threads=1))
        py = med(timed(lambda: murk.apply(arr, table, "fog", mor=a.mor, threads=1), 5000))
        print(f"per call, {name}: Rust {rust * 1e6:.1f} µs, murk.apply {py * 1e6:.1f} µs, overhead {1e6 * (py - rust):.1f} µs")
    try:
        pandas_way(pts, a.mor)
        pd_t = med(timed(lambda: pandas_way(pts, a.mor), max(20, a.repeats // 4)))
        p1 = med(timed(lambda: murk.apply(pts, table, "fog", mor=a.mor, threads=1), a.repeats))
        print(f"pandas way (same array, same rule): {pd_t * 1e6:.0f} µs; murk.apply (1 thread) is {pd_t / p1:.1f}x faster")
    except ImportError:
        print("pandas not installed: no pandas comparison")


if __name__ == "__main__":
    main()
