#!/usr/bin/env python3
"""numpy/pandas implementation of the main steps of `murk fit`.

It exists for two reasons:

1. Speed: `murk fit` must be at least 10x faster than a careful numpy/pandas
   implementation of the same steps (issue #3). This is that implementation:
   vectorised throughout (no Python loop over points), streaming one
   recording at a time, with the per-MOR-bin / per-cell statistics kept as
   numpy arrays exactly like the Rust driver.
2. A cross-check of the seed's quantile estimator: its q99 slopes, the
   no-change rates and the OLS rain conversion (`slope_ols`) should agree with the Rust table
   to rounding (same type-7 quantile, same cells, same rules).

Steps (as in fit/src): the pdd-2022-2023 rules + review.csv; a clear
reference per (ring, azimuth bin) cell (median over clear recordings,
presence >= 0.5, MAD <= pairing tolerance); pairing of every degraded return
with its cell (then the azimuth neighbours) within the tolerance, quota = the
cell's expected hits; ghost / ring / scene / far classes; per-MOR-bin 0.99
quantile of the clear range of no-change returns per band, censoring, and the
zero-intercept regression; the survival-boundary maximum likelihood on a
ln(r/MOR) histogram (Nelder-Mead written in numpy: scipy is not a dependency);
truncated-normal ML of the ghost/ring laws; Poisson power law of their counts;
rain conversion; bootstrap of the no-change rates; SHA-256 of every input.

Usage: scripts/fit_reference.py CAMPAIGN [--out reference.json]
Requires: pip install numpy pandas (Python >= 3.11 for tomllib).
"""

import argparse
import hashlib
import json
import math
import pathlib
import sys
import time
import tomllib

import numpy as np
import pandas as pd

QUANTILE = 0.99
MOR_BIN = 10.0
BANDS = [(0.0, 10.0), (10.0, math.inf)]
TOL_ABS, TOL_REL = 0.5, 0.02
MIN_PRESENCE = 0.5
RING = (0.0, 3.0)
GHOST = (3.0, 10.0)
MIN_POINTS = 50
CENSOR_FRACTION, CENSOR_MIN = 0.02, 10
LOG_STEP = 0.01  # as murk-fit's survival_log_step
U_MIN, U_MAX = 1e-4, 1e3
BOOTSTRAP = 1000


# ----------------------------------------------------------------- reading

def read_pcd(path):
    """PCL .pcd, DATA ascii or binary (the generator's default)."""
    raw = path.read_bytes()
    header = {}
    pos = 0
    while True:
        end = raw.index(b"\n", pos)
        line = raw[pos:end].decode("ascii").strip()
        pos = end + 1
        if not line or line.startswith("#"):
            continue
        key, *vals = line.split()
        header[key.upper()] = vals
        if key.upper() == "DATA":
            break
    fields = header["FIELDS"]
    sizes = [int(s) for s in header["SIZE"]]
    types = header["TYPE"]
    counts = [int(c) for c in header.get("COUNT", ["1"] * len(fields))]
    n = int(header["POINTS"][0])
    kinds = {"F": "f", "U": "u", "I": "i"}
    dtype = np.dtype([(f, f"<{kinds[t]}{s}", (c,) if c > 1 else ())
                      for f, s, t, c in zip(fields, sizes, types, counts)])
    mode = header["DATA"][0]
    if mode == "binary":
        arr = np.frombuffer(raw, dtype=dtype, count=n, offset=pos)
    elif mode == "ascii":
        arr = np.loadtxt(raw[pos:].decode().splitlines(), dtype=dtype, ndmin=1)
    else:
        sys.exit(f"{path}: DATA {mode} is not supported by this reference")
    return raw, arr


def read_cloud(path):
    if path.suffix == ".pcd":
        raw, a = read_pcd(path)
        return raw, a["x"].astype(np.float64), a["y"].astype(np.float64), \
            a["z"].astype(np.float64), a["intensity"].astype(np.float64), \
            a["ring"].astype(np.int64)
    if path.suffix == ".csv":
        raw = path.read_bytes()
        df = pd.read_csv(path)
        return raw, df.x.to_numpy(float), df.y.to_numpy(float), df.z.to_numpy(float), \
            df.intensity.to_numpy(float), df.ring.to_numpy(int)
    sys.exit(f"{path}: format not supported by this reference")


# --------------------------------------------------------------- selection

def select(d):
    w = pd.read_csv(d / "weather.csv")
    num = lambda c: pd.to_numeric(w[c], errors="coerce") if c in w else pd.Series(np.nan, index=w.index)
    wt = w.get("PWD12_Weather Type", pd.Series("", index=w.index)).astype(str)
    pr, xr = num("PWD12_Rain intensity (mm/h)"), num("WXT530_Rain intensity (mm/h)")
    pm, vm = num("PWD12_MOR (m)"), num("VS2K_MOR (m)")
    clear = (wt == "Clear") & (pr == 0) & (xr == 0) & (vm >= 2000) & (pm >= 2000)
    rain = (wt == "Rain") & (pr > 0)
    fog = (pr == 0) & (xr == 0) & (vm < 400) & (pm < 400) & ((pm - vm).abs() <= 60)
    snow = wt == "Snow"
    cls = np.select([snow, rain, fog, clear], ["snow", "rain", "fog", "clear"], default="")
    w["class"] = cls
    w["mor"] = pd.concat([pm, vm], axis=1).mean(axis=1, skipna=True)
    w["rain_rate"] = pr.where(pr.notna(), xr)
    # The conversion uses the mean of the gauges that read (as murk fit does).
    w["rain_rate_mean"] = pd.concat([pr, xr], axis=1).mean(axis=1, skipna=True)
    review = d / "review.csv"
    if review.exists():
        r = pd.read_csv(review, dtype={"recording": str})
        keep = set(r.loc[r["keep"].astype(str).str.lower() == "true", "recording"])
        w = w[w["recording"].astype(str).isin(keep)]
    return w[w["class"] != ""].reset_index(drop=True)


# -------------------------------------------------------------- statistics

def erfc(x):
    """Vectorised erfc (W. J. Cody-style rational fit via Numerical Recipes'
    erfcc, relative error < 1.2e-7): numpy has no erfc and scipy is not a
    dependency."""
    z = np.abs(x)
    t = 1.0 / (1.0 + 0.5 * z)
    r = t * np.exp(-z * z - 1.26551223 + t * (1.00002368 + t * (0.37409196 + t * (0.09678418 + t * (
        -0.18628806 + t * (0.27886807 + t * (-1.13520398 + t * (1.48851587 + t * (
            -0.82215223 + t * 0.17087277)))))))))
    return np.where(x >= 0, r, 2.0 - r)


def norm_cdf(z):
    return 0.5 * erfc(-z / math.sqrt(2.0))


def nelder_mead(f, x0, steps, iters=2000, tol=1e-11):
    n = len(x0)
    simplex = [np.array(x0, float)]
    for i in range(n):
        x = np.array(x0, float)
        x[i] += steps[i]
        simplex.append(x)
    vals = [f(x) for x in simplex]
    for _ in range(iters * (n + 1)):
        order = np.argsort(vals)
        simplex = [simplex[i] for i in order]
        vals = [vals[i] for i in order]
        if np.std(vals) < tol:
            break
        c = np.mean(simplex[:-1], axis=0)
        xr = c + (c - simplex[-1])
        fr = f(xr)
        if fr < vals[0]:
            xe = c + 2.0 * (c - simplex[-1])
            fe = f(xe)
            simplex[-1], vals[-1] = (xe, fe) if fe < fr else (xr, fr)
        elif fr < vals[-2]:
            simplex[-1], vals[-1] = xr, fr
        else:
            xc = c + 0.5 * (simplex[-1] - c)
            fc = f(xc)
            if fc < vals[-1]:
                simplex[-1], vals[-1] = xc, fc
            else:
                for i in range(1, n + 1):
                    simplex[i] = simplex[0] + 0.5 * (simplex[i] - simplex[0])
                    vals[i] = f(simplex[i])
    i = int(np.argmin(vals))
    return simplex[i], vals[i]


def weighted_quantile(x_sorted, w, q):
    n = int(w.sum())
    if n == 0:
        return None
    h = (n - 1) * q
    lo = int(math.floor(h))
    cw = np.cumsum(w)
    a = x_sorted[np.searchsorted(cw, lo, side="right")]
    b = x_sorted[np.searchsorted(cw, min(lo + 1, n - 1), side="right")]
    return a + (h - lo) * (b - a)


def survival_fit(k, n, u, eps0):
    """Joint ML over bands: k, n, u are lists (per band) of arrays."""
    nb = len(k)
    s0 = []
    for b in range(nb):
        grid = np.exp(np.linspace(np.log(u[b].min()), np.log(u[b].max()), 161))
        best = min(grid, key=lambda s: band_nll(k[b], n[b], u[b], s, 0.1, eps0, 1e-3))
        s0.append(math.log(best))

    def f(t):
        w = math.exp(t[nb])
        if not 1e-4 <= w <= 5:
            return 1e300
        eps = 1 / (1 + math.exp(-t[nb + 1]))
        pi = (1 - eps) / (1 + math.exp(-t[nb + 2]))
        return sum(band_nll(k[b], n[b], u[b], math.exp(t[b]), w, eps, pi) for b in range(nb))

    x0 = s0 + [math.log(0.1), math.log(eps0 / (1 - eps0)), math.log(1e-3 / (1 - eps0 - 1e-3))]
    x, _ = nelder_mead(f, x0, [0.1] * nb + [0.5, 0.5, 1.0])
    x, _ = nelder_mead(f, x, [0.05] * nb + [0.25, 0.25, 0.5])
    return [math.exp(v) for v in x[:nb]]


def band_nll(k, n, u, s, w, eps, pi):
    z = (u - s) / (w * s)
    a = 1 - eps - pi
    p = np.maximum(pi + a * 0.5 * erfc(z / math.sqrt(2)), 1e-300)
    q = np.maximum(eps + a * 0.5 * erfc(-z / math.sqrt(2)), 1e-300)
    return -float(np.sum(k * np.log(p) + (n - k) * np.log(q)))


def truncnorm_fit(x, c, lo, hi):
    n = c.sum()
    m = (x * c).sum() / n
    sd = max(math.sqrt((c * (x - m) ** 2).sum() / n), 1e-3)

    def f(t):
        mu, s = t[0], math.exp(t[1])
        za = norm_cdf(np.array([(lo - mu) / s]))[0] if math.isfinite(lo) else 0.0
        zb = norm_cdf(np.array([(hi - mu) / s]))[0] if math.isfinite(hi) else 1.0
        if zb - za <= 1e-300:
            return 1e300
        return float((c * 0.5 * ((x - mu) / s) ** 2).sum() + n * (math.log(s) + math.log(zb - za)))

    t, _ = nelder_mead(f, [m, math.log(sd)], [sd, 0.3])
    return float(t[0]), math.exp(t[1])


def power_law(mor, cnt, mor_ref=100.0):
    lm = np.log(mor).mean()
    x = lm - np.log(mor)

    def f(t):
        eta = t[0] + t[1] * x
        return float(np.exp(eta).sum() - (cnt * eta).sum())

    t, _ = nelder_mead(f, [math.log(max(cnt.mean(), 1e-9)), 0.0], [0.2, 0.5])
    return math.exp(t[0] + t[1] * (lm - math.log(mor_ref))), float(t[1])


# ------------------------------------------------------------------- main

def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaign", type=pathlib.Path)
    ap.add_argument("--out", type=pathlib.Path)
    a = ap.parse_args()
    t0 = time.perf_counter()
    d = a.campaign
    meta = tomllib.loads((d / "campaign.toml").read_text())
    lid = meta["lidar"]
    rings = len(lid["elevation_deg"])
    naz = int(round(360.0 / lid.get("azimuth_resolution_deg", 0.2)))
    res = 360.0 / naz
    rs = lid.get("range_scale", 1.0)
    ncell = rings * naz
    sel = select(d)
    digests = {}
    for f in ["campaign.toml", "weather.csv", "review.csv"]:
        if (d / f).exists():
            digests[f] = hashlib.sha256((d / f).read_bytes()).hexdigest()
    ext = {p.stem: p for p in (d / "lidar").iterdir()}

    def load(rec):
        p = ext[str(rec)]
        raw, x, y, z, refl, ring = read_cloud(p)
        digests[f"lidar/{p.name}"] = hashlib.sha256(raw).hexdigest()
        az = np.degrees(np.arctan2(y, x)) % 360.0
        cell = ring * naz + (az / res).astype(np.int64) % naz
        r = np.sqrt(x * x + y * y + z * z)
        return cell, r, refl

    # Clear reference.
    clear = sel[sel["class"] == "clear"]
    if clear.empty:
        sys.exit(f"{d}: no clear reference")
    imgs = []
    for i, rec in enumerate(clear["recording"]):
        cell, r, refl = load(rec)
        df = pd.DataFrame({"cell": cell, "r": r, "f": refl})
        g = df.groupby("cell").agg(r=("r", "median"), f=("f", "median"), h=("r", "size"))
        g["rec"] = i
        imgs.append(g.reset_index())
    allimg = pd.concat(imgs, ignore_index=True)
    nclear = len(imgs)
    grp = allimg.groupby("cell")
    ref = grp.agg(m=("r", "size"), r=("r", "median"), f=("f", "median"), h=("h", "median"))
    ref["h"] = np.maximum(np.floor(ref["h"]).astype(int), 1)
    mad = allimg.merge(ref[["r"]].rename(columns={"r": "rm"}), left_on="cell", right_index=True)
    mad["dev"] = (mad["r"] - mad["rm"]).abs()
    ref["mad"] = mad.groupby("cell")["dev"].median()
    tol = np.maximum(TOL_ABS, TOL_REL * ref["r"])
    ref["stable"] = ref["mad"] <= tol
    env_lo = np.full(ncell, np.nan)
    env_hi = np.full(ncell, np.nan)
    env_lo[grp["r"].min().index] = grp["r"].min().to_numpy()
    env_hi[grp["r"].max().index] = grp["r"].max().to_numpy()
    present = ref[ref["stable"] & (ref["m"] >= MIN_PRESENCE * nclear)]
    R = np.full(ncell, np.nan)
    F = np.full(ncell, np.nan)
    H = np.zeros(ncell, dtype=np.int64)
    R[present.index] = present["r"]
    F[present.index] = present["f"]
    H[present.index] = present["h"]
    pcells = present.index.to_numpy()
    ln_r = np.log(R[pcells])
    nb_u = int(math.ceil(math.log(U_MAX / U_MIN) / LOG_STEP))

    # Degraded recordings: stream, accumulate per-bin / per-cell statistics.
    out = {"weathers": {}}
    conv = None
    rain = sel[(sel["class"] == "rain") & sel["rain_rate"].notna() & sel["mor"].notna()]
    if len(rain) >= 2:
        # Plain OLS on the mean gauge reading: compare with the table's
        # slope_ols/intercept_ols (murk's slope is also corrected for gauge
        # noise, which this comparison script does not do).
        a1, b1 = np.polyfit(rain["rain_rate_mean"], rain["mor"], 1)
        conv = (float(a1), float(b1), len(rain))
    for cls in ["fog", "rain", "snow"]:
        recs = sel[sel["class"] == cls]
        if recs.empty:
            continue
        bins = {}
        surv_k = np.zeros((2, nb_u))
        surv_n = np.zeros((2, nb_u))
        band_of = (F[pcells] >= 10).astype(int)
        rows = []
        ghosts, rings_ = [], []
        for rec, mor in zip(recs["recording"], recs["mor"]):
            cell, r, refl = load(rec)
            matched = np.zeros(ncell, dtype=np.int64)
            left = np.ones(len(r), dtype=bool)
            for off in [0, -1, 1]:
                c = (cell // naz) * naz + (cell % naz + off) % naz
                ok = left & (H[c] > 0) & (np.abs(r - R[c]) <= np.maximum(TOL_ABS, TOL_REL * R[c]))
                idx = np.flatnonzero(ok)
                # quota: the first H[c] candidates of each cell, in point order
                order = np.argsort(c[idx], kind="stable")
                cs = c[idx][order]
                rank = np.arange(len(cs)) - np.searchsorted(cs, cs, side="left")
                take = idx[order][rank < (H[cs] - matched[cs])]
                np.add.at(matched, c[take], 1)
                left[take] = False
            rr, ff, cc = r[left], refl[left], cell[left]
            scene = np.zeros(len(rr), dtype=bool)
            for off in [-1, 0, 1]:
                c = (cc // naz) * naz + (cc % naz + off) % naz
                t = np.maximum(TOL_ABS, TOL_REL * rr)
                scene |= (rr >= env_lo[c] - t) & (rr <= env_hi[c] + t)
            rng_ = ~scene & (rr >= RING[0]) & (rr < RING[1])
            gh = ~scene & (rr >= GHOST[0]) & (rr < GHOST[1])
            ghosts.append(np.c_[rr[gh], ff[gh]])
            rings_.append(np.c_[rr[rng_], ff[rng_]])
            k = int(mor // MOR_BIN)
            n_, kept = bins.get(k, (0, np.zeros(ncell, dtype=np.int64)))
            bins[k] = (n_ + 1, kept + matched)
            ub = np.clip(np.floor((ln_r - math.log(mor * rs) - math.log(U_MIN)) / LOG_STEP), 0, nb_u - 1).astype(int)
            np.add.at(surv_k, (band_of, ub), matched[pcells])
            np.add.at(surv_n, (band_of, ub), H[pcells])
            rows.append((mor, int(matched[pcells].sum()), int(H[pcells].sum()), int(gh.sum()), int(rng_.sum())))
        rows = np.array(rows, dtype=float)
        w = {"recordings": len(rows)}
        # q99 per band with censoring, zero-intercept regression.
        q99 = []
        for (lo, hi) in BANDS:
            cells_b = pcells[(F[pcells] >= lo) & (F[pcells] < hi)]
            cells_b = cells_b[np.argsort(R[cells_b], kind="stable")]
            rb = R[cells_b]
            suffix = np.concatenate([np.cumsum(H[cells_b][::-1])[::-1], [0]])
            xs, ys = [], []
            for kbin in sorted(bins):
                n_, kept = bins[kbin]
                mors = rows[(rows[:, 0] // MOR_BIN) == kbin, 0]
                q = weighted_quantile(rb, kept[cells_b], QUANTILE)
                if q is None:
                    continue
                total = n_ * suffix[0]
                beyond = n_ * suffix[np.searchsorted(rb, q, side="right")]
                if beyond < max(CENSOR_FRACTION * total, CENSOR_MIN) or kept[cells_b].sum() < MIN_POINTS:
                    continue
                xs.append(mors.mean() * rs)
                ys.append(q)
            xs, ys = np.array(xs), np.array(ys)
            q99.append(float((xs * ys).sum() / (xs * xs).sum()) if len(xs) else None)
        w["vanishing_slope_q99"] = q99
        k_, n_, u_ = [], [], []
        centres = np.exp(math.log(U_MIN) + (np.arange(nb_u) + 0.5) * LOG_STEP)
        for b in range(2):
            m = surv_n[b] > 0
            k_.append(surv_k[b][m])
            n_.append(surv_n[b][m])
            u_.append(centres[m])
        w["vanishing_slope"] = survival_fit(k_, n_, u_, 0.01)
        w["no_change_rate"] = float(rows[:, 1].sum() / rows[:, 2].sum())
        gen = np.random.default_rng(0)
        idx = gen.integers(0, len(rows), (BOOTSTRAP, len(rows)))
        reps = rows[idx, 1].sum(axis=1) / rows[idx, 2].sum(axis=1)
        w["no_change_rate_std"] = float(reps.std(ddof=1))
        for name, pts, win, col in [("ghost", ghosts, GHOST, 3), ("ring", rings_, RING, 4)]:
            p = np.concatenate(pts) if pts else np.zeros((0, 2))
            if len(p) < 2:
                w[name] = None
                continue
            hd, ed = np.histogram(p[:, 0], bins=int(round((win[1] - win[0]) / 0.001)), range=win)
            hr, er = np.histogram(p[:, 1], bins=20480, range=(0, 1024))
            cd, cr = 0.5 * (ed[1:] + ed[:-1]), 0.5 * (er[1:] + er[:-1])
            dm = hd > 0
            rm = hr > 0
            n_ref, kexp = power_law(rows[:, 0], rows[:, col])
            w[name] = {
                "distance_m": truncnorm_fit(cd[dm], hd[dm], *win),
                "reflectivity": truncnorm_fit(cr[rm], hr[rm], 0.0, math.inf),
                "points_per_scan": float(rows[:, col].mean()),
                "count_law": {"n_ref": n_ref, "exponent": kexp},
            }
        if cls == "rain" and conv:
            w["mor_from_rain_rate"] = {"slope": conv[0], "intercept": conv[1], "points": conv[2]}
        out["weathers"][cls] = w
    lines = "".join(f"{h}  {p}\n" for p, h in sorted(digests.items()))
    out["inputs_sha256"] = hashlib.sha256(lines.encode()).hexdigest()
    out["seconds"] = time.perf_counter() - t0
    text = json.dumps(out, indent=2)
    if a.out:
        a.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
