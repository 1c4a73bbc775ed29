#!/usr/bin/env python3
"""The pandas way of applying the seed's vanishing model to CSV scans, as a
speed baseline for `murk apply` (issue #4: CSV in/out must be >= 20x faster).

    python3 scripts/apply_pandas.py generate DIR --files 8 --points 250000
    python3 scripts/apply_pandas.py real DIR --murk target/release/murk
    python3 scripts/apply_pandas.py apply DIR OUT --mor 60
    python3 scripts/apply_pandas.py compare DIR --mor 60 --murk target/release/murk

`generate` writes CSV scans in murk's layout (x,y,z,intensity,ring) from a
fixed seed, ranges uniform in 0.5-100 m: far more distant points than a real
scan has, so at MOR 60 about 80 % of them vanish (the hardest case for murk,
whose cost is reading every row, and the easiest for pandas, whose cost
grows with the rows it writes). `real` converts the real recordings of
../shared/data/real (VLP-16 pcap frames, KITTI, nuScenes) to CSV files with
`murk convert`, one folder, so the comparison can run on real scans (about
98 % of their points are within the vanishing distance at MOR 60);
`apply` does read_csv -> mask -> to_csv per file and prints
points/s; `compare` times both on the same files (`murk apply` with a table of
the same slopes) and prints the ratio. The mask is the seed's rule with the
low-reflectivity slope applied (the published filter's precedence bug fixed):
keep when range <= slope(band) * MOR * range_scale.

Needs pandas and numpy (`pip install pandas numpy`).
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np
import pandas as pd

# The seed report's Table 4 (fog).
FOG_LOW = 0.30286536
FOG_HIGH = 0.34634364


def generate(out_dir, files, points, seed):
    os.makedirs(out_dir, exist_ok=True)
    rng = np.random.default_rng(seed)
    elevation = np.deg2rad(
        np.array([-15, 1, -13, 3, -11, 5, -9, 7, -7, 9, -5, 11, -3, 13, -1, 15], dtype=np.float64)
    )
    for f in range(files):
        r = rng.uniform(0.5, 100.0, points)
        az = rng.uniform(0.0, 2 * np.pi, points)
        ring = np.arange(points) % 16
        el = elevation[ring]
        df = pd.DataFrame(
            {
                "x": (r * np.cos(el) * np.cos(az)).astype(np.float32),
                "y": (r * np.cos(el) * np.sin(az)).astype(np.float32),
                "z": (r * np.sin(el)).astype(np.float32),
                "intensity": np.floor(rng.uniform(0, 256, points)).clip(0, 255).astype(np.float32),
                "ring": ring.astype(np.uint16),
            }
        )
        df.to_csv(os.path.join(out_dir, f"{f:06d}.csv"), index=False)


def apply_dir(in_dir, out_dir, mor, range_scale=1.0):
    """read_csv -> mask -> to_csv for every CSV of in_dir; returns points read."""
    os.makedirs(out_dir, exist_ok=True)
    total = 0
    for name in sorted(os.listdir(in_dir)):
        if not name.endswith(".csv"):
            continue
        df = pd.read_csv(os.path.join(in_dir, name))
        total += len(df)
        rng2 = df["x"] ** 2 + df["y"] ** 2 + df["z"] ** 2
        slope = np.where(df["intensity"] < 10, FOG_LOW, FOG_HIGH)
        keep = rng2 <= (slope * mor * range_scale) ** 2
        df[keep].to_csv(os.path.join(out_dir, name), index=False)
    return total


def table(path):
    t = {
        "format": "weather-noise-coefficients/1",
        "campaign": "pandas-baseline",
        "lidar": {"model": "VLP16", "range_scale": 1.0},
        "weathers": {
            "fog": {
                "recordings": 1,
                "quantile": 0.99,
                "no_change_rate": None,
                "vanishing_slope": [
                    {"reflectivity_min": 0, "reflectivity_max": 10, "slope": FOG_LOW, "points": 1},
                    {"reflectivity_min": 10, "reflectivity_max": None, "slope": FOG_HIGH, "points": 1},
                ],
                "ghost": None,
                "ring": None,
            }
        },
        "provenance": {"tool": "apply_pandas.py", "inputs_sha256": "", "parameters": {}},
    }
    with open(path, "w") as f:
        json.dump(t, f)


def real(out_dir, data, murk):
    """Real scans as CSV files in out_dir, via `murk convert`."""
    inputs = sorted(
        os.path.join(data, n)
        for n in os.listdir(data)
        if n.endswith((".pcap", ".bin", ".pcd"))
    )
    if not inputs:
        sys.exit(f"no point-cloud files in {data}")
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run([murk, "convert", *inputs, "--out", tmp, "--format", "csv"],
                       check=True, stdout=subprocess.DEVNULL)
        os.makedirs(out_dir, exist_ok=True)
        for root, _, names in os.walk(tmp):
            for n in names:
                if n.endswith(".csv"):
                    rel = os.path.relpath(os.path.join(root, n), tmp).replace(os.sep, "_")
                    os.replace(os.path.join(root, n), os.path.join(out_dir, rel))


def count_rows(d):
    n = 0
    for name in os.listdir(d):
        if name.endswith(".csv"):
            with open(os.path.join(d, name)) as f:
                n += sum(1 for _ in f) - 1
    return n


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    g = sub.add_parser("generate")
    g.add_argument("dir")
    g.add_argument("--files", type=int, default=8)
    g.add_argument("--points", type=int, default=250_000)
    g.add_argument("--seed", type=int, default=1)
    r = sub.add_parser("real")
    r.add_argument("dir")
    r.add_argument("--data", default=os.path.join(os.path.dirname(__file__), "..", "..", "shared", "data", "real"))
    r.add_argument("--murk", default="target/release/murk")
    a = sub.add_parser("apply")
    a.add_argument("dir")
    a.add_argument("out")
    a.add_argument("--mor", type=float, default=60.0)
    c = sub.add_parser("compare")
    c.add_argument("dir")
    c.add_argument("--mor", type=float, default=60.0)
    c.add_argument("--murk", default="target/release/murk")
    c.add_argument("--repeat", type=int, default=3)
    args = p.parse_args()

    if args.cmd == "generate":
        generate(args.dir, args.files, args.points, args.seed)
        return
    if args.cmd == "real":
        real(args.dir, args.data, args.murk)
        return
    if args.cmd == "apply":
        t0 = time.perf_counter()
        n = apply_dir(args.dir, args.out, args.mor)
        dt = time.perf_counter() - t0
        print(f"pandas: {n} points in {dt:.3f} s = {n / dt / 1e6:.2f} M points/s")
        return

    with tempfile.TemporaryDirectory() as tmp:
        tpath = os.path.join(tmp, "table.json")
        table(tpath)
        best_pd = best_murk = float("inf")
        for i in range(args.repeat):
            t0 = time.perf_counter()
            n = apply_dir(args.dir, os.path.join(tmp, f"pd{i}"), args.mor)
            best_pd = min(best_pd, time.perf_counter() - t0)
            out = os.path.join(tmp, f"murk{i}")
            t0 = time.perf_counter()
            subprocess.run(
                [args.murk, "apply", "--coefficients", tpath, "--weather", "fog",
                 "--mor", str(args.mor), args.dir, "--out", out],
                check=True, stdout=subprocess.DEVNULL,
            )
            best_murk = min(best_murk, time.perf_counter() - t0)
        kept_pd, kept_murk = count_rows(os.path.join(tmp, "pd0")), count_rows(os.path.join(tmp, "murk0"))
        print(f"points: {n}; kept: pandas {kept_pd}, murk {kept_murk}")
        print(f"pandas: best of {args.repeat} {best_pd:.3f} s = {n / best_pd / 1e6:.2f} M points/s")
        print(f"murk  : best of {args.repeat} {best_murk:.3f} s = {n / best_murk / 1e6:.2f} M points/s")
        print(f"ratio : murk is {best_pd / best_murk:.1f}x faster")
        if kept_pd != kept_murk:
            print("warning: the two disagree on the kept count", file=sys.stderr)


if __name__ == "__main__":
    main()
