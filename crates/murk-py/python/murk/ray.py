"""murk on Ray: ``murk apply`` over folders or lists of files with Ray Data.

Install with ``pip install "murk[ray]"`` (Ray pinned to the tested release).

>>> import ray, murk, murk.ray
>>> ray.init(num_cpus=2)                     # or ray.init(address="auto") on a cluster
>>> table = murk.Table.load("coefficients.json")
>>> report = murk.ray.apply(["scans/"], "foggy/", table, "fog", mor=60, seed=1)

The plan (which input goes to which output, and each scan's seed key) is
``murk apply``'s own, made once on the driver; each Ray task runs whole files
through the same Rust code as the CLI (``murk._murk.apply_file``: read, apply,
write to a temporary file in the output folder, sync, rename), so every output
is byte-identical to what ``murk apply`` writes with the same flags, whatever
the number of workers. On a cluster the input and output folders must be on a
file system every node sees (NFS, a mounted bucket).

:func:`fit` fits a campaign as map and merge on Ray: the clear recordings
in ``shards`` blocks mapped into partial states and merged, then the degraded
recordings in ``shards`` blocks mapped against the merged clear state, and
everything merged (pairwise, in a tree of Ray tasks) and finished; the table
is byte-identical to ``murk fit`` with the same parameters.

>>> table = murk.ray.fit("campaign/", shards=8, bootstrap=1000)
"""

from __future__ import annotations

import os
from typing import Any, Dict, List, Optional, Sequence, Union

import numpy as np

from . import FitState, Table
from . import _murk

PathLike = Union[str, "os.PathLike[str]"]


class _ApplyFiles:
    """The map_batches callable: applies every job of a batch."""

    def __init__(self, table_json: str, weather: str, options: Dict[str, Any]) -> None:
        self.table = Table.from_json(table_json)
        self.weather = weather
        self.options = options

    def __call__(self, batch: Dict[str, np.ndarray]) -> Dict[str, np.ndarray]:
        out: Dict[str, List[Any]] = {"input": [], "output": [], "key": [], "points_in": [], "points_out": []}
        for inp, outp, key in zip(batch["input"], batch["output"], batch["key"]):
            s = _murk.apply_file(str(inp), str(outp), str(key), self.table, self.weather, **self.options)
            out["input"].append(str(inp))
            out["output"].append(str(outp))
            out["key"].append(str(key))
            out["points_in"].append(s["points_in"])
            out["points_out"].append(s["points_out"])
        return {k: np.array(v) for k, v in out.items()}


def plan(inputs: Union[PathLike, Sequence[PathLike]], out: PathLike, *, format: Optional[str] = None):
    """``murk apply``'s plan: ``(jobs, skipped)``, jobs as ``(input, output, key)``."""
    if isinstance(inputs, (str, os.PathLike)):
        inputs = [inputs]
    return _murk.plan([os.fspath(p) for p in inputs], os.fspath(out), format=format)


def apply(
    inputs: Union[PathLike, Sequence[PathLike]],
    out: PathLike,
    table: Union[Table, PathLike],
    weather: str,
    *,
    batch_size: int = 4,
    concurrency: Optional[int] = None,
    **options: Any,
) -> List[Dict[str, Any]]:
    """Apply ``table``'s ``weather`` to every point-cloud file of ``inputs``
    (files or folders, walked as ``murk apply`` walks them) into ``out``.

    ``options`` are :func:`murk.apply`'s model keywords plus ``format``,
    ``pcd_data`` and ``intensity_scale`` (``murk apply``'s flags). Each Ray
    task runs one murk thread per file (``threads=1`` unless given). Returns
    one row per file: input, output, key, points_in, points_out, in plan
    order. Raises murk errors as the CLI does (the first failing file).
    """
    import ray
    import ray.data

    if not isinstance(table, Table):
        table = Table.load(table)
    options = dict(options)
    options.setdefault("threads", 1)
    jobs, _skipped = plan(inputs, out, format=options.get("format"))
    if not jobs:
        raise _murk.InputError("no point-cloud file among the inputs")
    # Fail on the driver, not in a task: the same checks as a real job.
    _murk.apply(np.zeros((0, 4), np.float32), table, weather,
                **{k: v for k, v in options.items() if k not in ("format", "pcd_data")})
    if not ray.is_initialized():
        ray.init()
    if concurrency is None:
        concurrency = max(1, int(ray.cluster_resources().get("CPU", 1)))
    rows = [{"input": i, "output": o, "key": k} for i, o, k in jobs]
    done = ray.data.from_items(rows).map_batches(
        _ApplyFiles,
        fn_constructor_kwargs={"table_json": table.to_json(), "weather": weather, "options": options},
        batch_size=batch_size,
        batch_format="numpy",
        concurrency=concurrency,
        num_cpus=1,
    ).take_all()
    by_key = {r["key"]: r for r in done}
    return [
        {
            "input": by_key[k]["input"],
            "output": by_key[k]["output"],
            "key": k,
            "points_in": int(by_key[k]["points_in"]),
            "points_out": int(by_key[k]["points_out"]),
        }
        for _, _, k in jobs
    ]


def _map(campaign: str, k: int, n: int, reference: Optional[FitState], threads: int,
         params: Dict[str, Any]) -> FitState:
    return _murk.fit_partial(campaign, shard=(k, n), reference=reference, threads=threads, **params)


def _merge(a: FitState, b: FitState) -> FitState:
    return a.merge(b)


def _finish(state: FitState, threads: int) -> str:
    return state.finish(threads=threads).to_json()


def _tree(refs: List[Any], merge: Any) -> Any:
    """Pairwise merges as Ray tasks until one state is left (log depth)."""
    while len(refs) > 1:
        nxt = [merge.remote(refs[i], refs[i + 1]) for i in range(0, len(refs) - 1, 2)]
        if len(refs) % 2:
            nxt.append(refs[-1])
        refs = nxt
    return refs[0]


def fit(campaign: PathLike, shards: int = 8, *, threads: int = 1, **params: Any) -> Table:
    """Fit ``campaign`` as map and merge on Ray: byte-identical to
    ``murk fit`` (and :func:`murk.fit`) with the same ``params`` (its flags as
    keywords).

    Phase 1 maps the clear recordings in ``shards`` blocks (Ray tasks of
    ``threads`` murk threads each) and merges them into the clear state;
    phase 2 maps the degraded recordings in ``shards`` blocks against it;
    every state is then merged pairwise in a tree of Ray tasks and
    finished. On a cluster the campaign folder must be on a file system
    every node sees. Raises murk errors as :func:`murk.fit_partial` does.
    """
    import ray

    if shards < 1:
        raise _murk.InputError(f"shards: {shards} must be at least 1")
    campaign = os.fspath(campaign)
    # Check the parameters on the driver, not in a task.
    _murk.fit_partial(campaign, [], **params)
    if not ray.is_initialized():
        ray.init()
    map_task = ray.remote(num_cpus=threads)(_map)
    merge_task = ray.remote(num_cpus=threads)(_merge)
    finish_task = ray.remote(num_cpus=threads)(_finish)
    clear = _tree([map_task.remote(campaign, k, shards, None, threads, params)
                   for k in range(1, shards + 1)], merge_task)
    degraded = [map_task.remote(campaign, k, shards, clear, threads, params)
                for k in range(1, shards + 1)]
    whole = _tree([clear] + degraded, merge_task)
    return Table.from_json(ray.get(finish_task.remote(whole, threads)))
