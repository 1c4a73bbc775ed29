"""murk: data-driven LiDAR weather noise models, from Python.

A thin layer over murk's Rust libraries (the same code as the ``murk`` CLI):

- :func:`read` / :func:`write`: every point-cloud format murk reads and writes
  (PCD, KITTI ``.bin``, nuScenes ``.pcd.bin``, CSV, Parquet; Velodyne
  ``.pcap`` read only), as dicts of numpy columns;
- :class:`Table`: a fitted coefficient table (``murk fit``'s JSON);
- :func:`apply`: degrade one scan (a float32 ``(N, 4)``/``(N, 5)`` array or a
  dict of columns), byte-identical to ``murk apply`` on the same scan;
- :func:`fit` / :func:`diagnose`: ``murk fit`` / ``murk diagnose`` on a
  campaign folder;
- :class:`Augment`: a seeded, fork-safe callable for DataLoader pipelines.

Threads: murk runs each call on a rayon pool of its own, rebuilt in a forked
child, so it is safe in ``fork``-started workers (PyTorch DataLoader,
multiprocessing). The number of threads is the call's ``threads`` argument,
else :func:`set_num_threads`, else the ``MURK_NUM_THREADS`` environment
variable, else the number of CPUs. :class:`Augment` uses one thread per call
by default (DataLoader parallelism is across workers). Results never depend
on the thread count. Parquet reading and writing goes through polars, whose
own global pool is not fork-safe: do not read Parquet in a forked child whose
parent already did.

The GIL is released while murk works. Do not modify an input array from
another thread during the call.
"""

from __future__ import annotations

import hashlib
import math
import struct
import numpy as _np
from typing import Any, Mapping, Optional, Sequence, Tuple, Union

from ._murk import (  # noqa: F401
    CampaignError,
    DiagnoseError,
    FileError,
    FitError,
    FitState,
    InputError,
    MurkError,
    Table,
    TableError,
    __version__,
    apply,
    apply_file,
    diagnose,
    fit,
    fit_partial,
    get_num_threads,
    plan,
    read,
    set_num_threads,
    set_clear_memory,
    write,
)

__all__ = [
    "Augment",
    "CampaignError",
    "DiagnoseError",
    "FileError",
    "FitError",
    "FitState",
    "InputError",
    "MurkError",
    "Table",
    "TableError",
    "apply",
    "apply_file",
    "apply_files",
    "augment_key",
    "diagnose",
    "plan",
    "fit",
    "fit_partial",
    "get_num_threads",
    "read",
    "set_num_threads",
    "set_clear_memory",
    "write",
]

Range = Union[float, Tuple[float, float], Sequence[float]]


def augment_key(index: int) -> str:
    """The scan key :class:`Augment` passes to :func:`apply` for sample ``index``."""
    return f"augment/{int(index)}"


def _unit(seed: int, index: int, what: bytes) -> float:
    """A uniform draw in [0, 1) fixed by (seed, index, what)."""
    h = hashlib.sha256(b"murk-py/augment/1" + struct.pack("<QQ", seed, index & 0xFFFFFFFFFFFFFFFF) + what)
    return (int.from_bytes(h.digest()[:8], "little") >> 11) / float(1 << 53)


def _range(name: str, value: Optional[Range]) -> Optional[Tuple[float, float]]:
    if value is None:
        return None
    if isinstance(value, (int, float)):
        lo = hi = float(value)
    else:
        try:
            lo, hi = (float(v) for v in value)
        except (TypeError, ValueError):
            raise InputError(f"{name}: expected a number or a (lo, hi) pair, got {value!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and 0 <= lo <= hi):
        raise InputError(f"{name}: ({lo}, {hi}) is not a range 0 <= lo <= hi of finite numbers")
    return lo, hi


class Augment:
    """Random weather for training pipelines: ``aug(points, index)``.

    For sample ``index`` the weather is applied with probability ``p``; its
    severity is drawn uniformly from ``mor=(lo, hi)`` metres (or
    ``rain_rate=(lo, hi)`` mm/h; a number fixes it; ``log=True`` draws the
    logarithm uniformly). Every draw is fixed by ``(seed, index)`` alone, so a
    sample gets the same augmentation in any worker, in any order, after
    ``fork`` or ``spawn``. :meth:`params` says what sample ``index`` gets; the
    result equals ``murk.apply(points, table, weather, mor=m, seed=seed,
    key=murk.augment_key(index), **options)``.

    ``threads`` (default 1) is the number of murk threads per call: DataLoader
    workers already run in parallel. Other keyword arguments are passed to
    :func:`apply` (``near_range``, ``soft_edge``, ``layout``,
    ``intensity_scale``, ...). Picklable (the table travels as JSON).
    """

    def __init__(
        self,
        table: Union[Table, str],
        weather: str,
        mor: Optional[Range] = None,
        *,
        rain_rate: Optional[Range] = None,
        p: float = 1.0,
        seed: int = 0,
        log: bool = False,
        threads: Optional[int] = 1,
        **options: Any,
    ) -> None:
        self.table = table if isinstance(table, Table) else Table.load(table)
        self.weather = str(weather)
        self.mor = _range("mor", mor)
        self.rain_rate = _range("rain_rate", rain_rate)
        if (self.mor is None) == (self.rain_rate is None):
            raise InputError("Augment: give mor=(lo, hi) or rain_rate=(lo, hi), exactly one")
        if log and (self.mor or self.rain_rate)[0] <= 0:
            raise InputError("log: the range must be > 0 to draw its logarithm")
        if not (isinstance(p, (int, float)) and 0.0 <= p <= 1.0):
            raise InputError(f"p: {p!r} is not a probability in [0, 1]")
        if not isinstance(seed, int) or seed < 0 or seed >= 1 << 64:
            raise InputError(f"seed: {seed!r} is not an integer in [0, 2**64)")
        for k in ("mor", "rain_rate", "seed", "key", "threads"):
            if k in options:
                raise InputError(f"Augment: {k} is set by Augment itself")
        self.p = float(p)
        self.seed = seed
        self.log = bool(log)
        self.threads = threads
        self.options = dict(options)
        # Fail now, not in a worker: unknown weather, a table without it, bad
        # options (an empty scan goes through every check but the points').
        layout = self.options.get("layout")
        width = 5 if layout in ("xyzir", "nuscenes", "ring", "xyzit", "time") else 4
        lo = (self.mor or self.rain_rate)[0]
        sev = {"mor": lo} if self.mor else {"rain_rate": lo}
        apply(_np.zeros((0, width), _np.float32), self.table, self.weather, threads=1, **sev, **self.options)

    def params(self, index: int) -> dict:
        """What sample ``index`` gets: ``{"applied": bool, "mor" or "rain_rate": value, "key": str}``."""
        index = int(index)
        applied = _unit(self.seed, index, b"p") < self.p
        name, (lo, hi) = ("mor", self.mor) if self.mor else ("rain_rate", self.rain_rate)
        u = _unit(self.seed, index, name.encode())
        if self.log:
            value = math.exp(math.log(lo) + u * (math.log(hi) - math.log(lo)))
        else:
            value = lo + u * (hi - lo)
        return {"applied": applied, name: value, "key": augment_key(index)}

    def __call__(self, points: Any, index: int) -> Any:
        """``points`` augmented for sample ``index`` (the same layout back;
        the input itself when the draw says not to apply)."""
        prm = self.params(index)
        if not prm["applied"]:
            return points
        sev = {"mor": prm["mor"]} if "mor" in prm else {"rain_rate": prm["rain_rate"]}
        return apply(
            points,
            self.table,
            self.weather,
            seed=self.seed,
            key=prm["key"],
            threads=self.threads,
            **sev,
            **self.options,
        )

    def __repr__(self) -> str:
        sev = f"mor={self.mor}" if self.mor else f"rain_rate={self.rain_rate}"
        return f"murk.Augment({self.table!r}, {self.weather!r}, {sev}, p={self.p}, seed={self.seed})"


def apply_files(inputs: Any, out: Any, table: Union[Table, str], weather: str, **options: Any) -> list:
    """``murk apply INPUTS --out OUT`` from Python, in this process: the CLI's
    plan (files or folders walked in name order; keys are paths relative to
    each input argument), each file read, applied and written atomically by the
    same code as the CLI, so outputs are byte-identical to ``murk apply``'s.

    ``options``: :func:`apply`'s model keywords plus ``format``, ``pcd_data``,
    ``intensity_scale``. Returns each file's summary, in plan order. For a
    cluster, see :mod:`murk.ray`.
    """
    import os

    if isinstance(inputs, (str, os.PathLike)):
        inputs = [inputs]
    if not isinstance(table, Table):
        table = Table.load(table)
    jobs, _skipped = plan([os.fspath(p) for p in inputs], os.fspath(out), format=options.get("format"))
    if not jobs:
        raise InputError("no point-cloud file among the inputs")
    return [apply_file(i, o, k, table, weather, **options) for i, o, k in jobs]
