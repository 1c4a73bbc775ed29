"""Type stubs of the murk package (see murk/__init__.py for the overview)."""

import os
from typing import Any, Dict, List, Literal, Mapping, Optional, Sequence, Tuple, Union, overload

import numpy as np
import numpy.typing as npt

__version__: str

PathLike = Union[str, "os.PathLike[str]"]
Records = npt.NDArray[np.float32]
"""float32 array of shape (N, 4) ``x y z intensity`` or (N, 5) ``x y z intensity ring|time``."""
Columns = Dict[str, np.ndarray]
"""``x y z intensity`` (float32), ``ring`` (uint16; any integer dtype in), ``time`` (float32, optional)."""
Points = Union[Records, Mapping[str, np.ndarray]]
IntensityScaleArg = Union[str, Tuple[float, float], None]
Layout = Literal["xyzi", "kitti", "xyzir", "nuscenes", "ring", "xyzit", "time"]

class MurkError(Exception):
    """Base class of every error murk raises; the message is the CLI's."""

class InputError(MurkError):
    """Bad argument: array shape/dtype/contiguity, NaN coordinates, unknown weather, missing column, parameter out of range."""

class TableError(MurkError):
    """A coefficient table that cannot be read or lacks what is asked (a weather, a coefficient)."""

class FileError(MurkError):
    """A point-cloud file that cannot be read or written."""

class CampaignError(MurkError):
    """A campaign folder that cannot be opened or checked."""

class FitError(MurkError):
    """A fit that cannot be done on the campaign."""

class DiagnoseError(MurkError):
    """A diagnosis that cannot be done on the campaign."""

class Table:
    """A fitted coefficient table (``weather-noise-coefficients/1``), validated on load."""

    @staticmethod
    def load(path: PathLike) -> "Table":
        """Read and validate a table file written by ``murk fit``. Raises TableError."""
    @staticmethod
    def from_json(text: str) -> "Table":
        """Parse and validate a table from its JSON text. Raises TableError."""
    def to_json(self) -> str:
        """The table as JSON text, byte for byte what ``murk fit`` writes."""
    @property
    def weathers(self) -> List[str]:
        """Degraded weathers with coefficients, sorted (e.g. ``["fog", "rain", "snow"]``)."""
    @property
    def absent(self) -> List[Tuple[str, str]]:
        """Weathers the fit left out, with the reason."""
    @property
    def campaign(self) -> str:
        """The campaign the table was fitted on."""
    @property
    def path(self) -> Optional[str]:
        """The file the table was loaded from (None when built in memory)."""
    def __eq__(self, other: object) -> bool: ...
    def __reduce__(self) -> Tuple[Any, Tuple[str]]: ...

@overload
def read(
    path: PathLike,
    *,
    format: Optional[str] = None,
    intensity_scale: IntensityScaleArg = None,
    frames: Literal[False] = False,
    pcap_return: Optional[Literal["strongest", "last"]] = None,
) -> Columns:
    """Read a point-cloud file (format from the extension, or ``format``: pcd, bin,
    nuscenes, csv, parquet, pcap) into numpy columns. Intensity is as stored (never
    converted). ``frames=True`` gives one dict per revolution of a pcap;
    ``pcap_return`` reads one return of each firing from a dual-return pcap (default:
    as recorded). Raises FileError."""

@overload
def read(
    path: PathLike,
    *,
    format: Optional[str] = None,
    intensity_scale: IntensityScaleArg = None,
    frames: Literal[True],
    pcap_return: Optional[Literal["strongest", "last"]] = None,
) -> List[Columns]: ...
def write(
    path: PathLike,
    cloud: Points,
    *,
    format: Optional[str] = None,
    pcd_data: Literal["ascii", "binary", "binary_compressed"] = "binary",
    layout: Optional[Layout] = None,
    intensity_scale: IntensityScaleArg = None,
) -> None:
    """Write a cloud atomically (temporary file + rename) in the format of the
    extension or ``format``; the bytes equal the CLI's for the same cloud."""

@overload
def apply(
    points: Points,
    table: Union[Table, PathLike],
    weather: str,
    *,
    mor: Optional[float] = None,
    rain_rate: Optional[float] = None,
    seed: int = 0,
    key: Optional[str] = None,
    layout: Optional[Layout] = None,
    intensity_scale: IntensityScaleArg = None,
    near_range: bool = False,
    near_range_count_scale: float = 1.0,
    soft_edge: bool = False,
    range_noise: Optional[float] = None,
    attenuate_intensity: bool = False,
    slope: Literal["survival", "quantile"] = "survival",
    clamp: bool = False,
    covariates: Optional[Mapping[str, Union[str, float]]] = None,
    extensions: bool = True,
    range_scale: Optional[float] = None,
    clear_mor_threshold: Optional[float] = None,
    min_range: Optional[float] = None,
    threads: Optional[int] = None,
    summary: Literal[False] = False,
) -> Any:
    """Degrade one scan with ``table``'s model of ``weather`` at ``mor`` metres
    (or ``rain_rate`` mm/h, converted by the table). Keyword arguments are the
    flags of ``murk apply``.

    ``points``: float32 C-contiguous ``(N, 4)`` (KITTI ``x y z intensity``;
    intensity 0–1 by default), ``(N, 5)`` (``layout="xyzir"``, the default:
    nuScenes/STF ring last; ``layout="xyzit"``: time last), or a dict of
    columns. Arrays of records are read without a copy. The result has the
    same layout (a dict for a dict): kept points in order, then added
    near-range returns.

    Reproducing the CLI: ``murk apply FILE --seed S`` seeds each scan by
    ``(S, key)`` where ``key`` is the file's path relative to the input
    argument (its file name for a file argument). ``apply(points, table,
    weather, mor=M, seed=S, key="000008.bin")`` on that file's records gives
    the same bytes the CLI writes. Default ``key``: ``""``.

    ``intensity_scale``: the scale the input's intensity is in (default: KITTI
    0–1 for ``xyzi``, calibrated otherwise; names as ``--intensity-scale``, or
    ``(gain, offset)``). ``min_range``: points nearer than this many metres
    are not returns (nuScenes' no-return firings at the origin): written as
    they were, in their places. ``summary=True`` also returns the applied model and
    the scan's counts (``murk-apply-summary/1``'s ``model`` and file entry).
    """

@overload
def apply(
    points: Points,
    table: Union[Table, PathLike],
    weather: str,
    *,
    mor: Optional[float] = None,
    rain_rate: Optional[float] = None,
    seed: int = 0,
    key: Optional[str] = None,
    layout: Optional[Layout] = None,
    intensity_scale: IntensityScaleArg = None,
    near_range: bool = False,
    near_range_count_scale: float = 1.0,
    soft_edge: bool = False,
    range_noise: Optional[float] = None,
    attenuate_intensity: bool = False,
    slope: Literal["survival", "quantile"] = "survival",
    clamp: bool = False,
    covariates: Optional[Mapping[str, Union[str, float]]] = None,
    extensions: bool = True,
    range_scale: Optional[float] = None,
    clear_mor_threshold: Optional[float] = None,
    min_range: Optional[float] = None,
    threads: Optional[int] = None,
    summary: Literal[True],
) -> Tuple[Any, Dict[str, Any]]: ...
def fit(campaign: PathLike, *, threads: Optional[int] = None, **params: Any) -> Table:
    """``murk fit CAMPAIGN``: the coefficient table of a campaign folder.

    ``params`` are ``murk fit``'s flags with underscores: quantile, mor_bin_width,
    bands, sweep, ghost_range, ring_range, pairing_tolerance,
    pairing_tolerance_rel, min_points_per_bin, censor_fraction, edge,
    per_band_width, keep_unconfirmed_slopes, bend, no_law_comparison, reflectivity_law, fixed_dropout,
    bootstrap, seed, radar_tolerance.
    ``fit(c).to_json()`` equals the file ``murk fit c --out T.json`` writes."""

class FitState:
    """The statistics of part of a campaign's recordings (``murk fit --partial``).

    Merging is associative and commutative; a complete state finishes into
    the table one :func:`fit` over everything gives, byte for byte.
    Picklable: its pickle is the state file's bytes.
    """

    @staticmethod
    def read(path: PathLike) -> FitState:
        """Read a state file (``murk fit --partial``'s output)."""
    def write(self, path: PathLike) -> None:
        """Write the state file atomically."""
    def to_bytes(self) -> bytes:
        """The state file's bytes."""
    @staticmethod
    def from_bytes(data: bytes, label: str = ...) -> FitState:
        """A state from a state file's bytes; ``label`` names it in errors."""
    def merge(self, other: FitState) -> FitState:
        """Both states in one (FitError if of other campaigns, parameters or
        murk versions, overlapping, or paired against different references)."""
    def finish(self, *, threads: Optional[int] = None) -> Table:
        """The table of a complete state (FitError naming what is missing)."""
    @property
    def complete(self) -> bool:
        """Whether every selected recording is in the state."""
    @property
    def missing(self) -> Optional[str]:
        """What the state lacks before it gives a table, or None."""
    @property
    def recordings(self) -> List[str]:
        """Ids of the recordings in the state, in campaign order."""
    @property
    def campaign(self) -> str:
        """The campaign's name."""
    def __reduce__(self) -> Any: ...

def fit_partial(
    campaign: PathLike,
    recordings: Optional[Sequence[str]] = None,
    *,
    shard: Optional[Tuple[int, int]] = None,
    reference: Optional[FitState] = None,
    threads: Optional[int] = None,
    **params: Any,
) -> FitState:
    """Map part of a campaign (``murk fit --partial``): without ``reference``
    its clear recordings (all, ``recordings`` by id, or ``shard=(k, n)``,
    block k of n, 1-based), with ``reference`` (every clear recording,
    merged) its degraded ones paired against it."""

@overload
def diagnose(
    campaign: PathLike,
    weather: str,
    *,
    coefficients: Union[Table, PathLike, None] = None,
    folds: int = 3,
    seed: int = 0,
    permutations: int = 1999,
    alpha: float = 0.05,
    sims: int = 2,
    voxel: float = 1.0,
    local_box: Optional[Sequence[float]] = None,
    threads: Optional[int] = None,
    kept_memory_mb: float = 256.0,
    spill_dir: Optional[PathLike] = None,
    extended_table: Literal[False] = False,
) -> Dict[str, Any]:
    """``murk diagnose CAMPAIGN --weather W``: the report (``murk diagnose``'s
    JSON) as a dict; with ``extended_table=True`` also the extended table (or None).
    ``kept_memory_mb``: megabytes of kept returns held in memory, the rest
    spilled to an anonymous temporary file in ``spill_dir`` (same result)."""

@overload
def diagnose(
    campaign: PathLike,
    weather: str,
    *,
    coefficients: Union[Table, PathLike, None] = None,
    folds: int = 3,
    seed: int = 0,
    permutations: int = 1999,
    alpha: float = 0.05,
    sims: int = 2,
    voxel: float = 1.0,
    local_box: Optional[Sequence[float]] = None,
    threads: Optional[int] = None,
    kept_memory_mb: float = 256.0,
    spill_dir: Optional[PathLike] = None,
    extended_table: Literal[True],
) -> Tuple[Dict[str, Any], Optional[Table]]: ...
def set_num_threads(n: int) -> None:
    """Default worker threads of every call (0: back to ``MURK_NUM_THREADS``, else the CPU count)."""

def set_clear_memory(mb: float, spill_dir: Optional[PathLike] = None) -> None:
    """Megabytes of clear cell images a fit or diagnosis holds in memory, the rest in a temporary file in ``spill_dir`` (``--clear-memory-mb``, ``--spill-dir``); memory only, never a result."""

def get_num_threads() -> int:
    """The default worker threads of a call."""

def augment_key(index: int) -> str:
    """The scan key Augment passes to apply for sample ``index``."""

class Augment:
    """Seeded random weather for DataLoader pipelines: ``aug(points, index)``.

    Deterministic per ``(seed, index)``, fork-safe, one murk thread per call by default."""

    table: Table
    weather: str
    p: float
    seed: int
    def __init__(
        self,
        table: Union[Table, PathLike],
        weather: str,
        mor: Union[float, Tuple[float, float], None] = None,
        *,
        rain_rate: Union[float, Tuple[float, float], None] = None,
        p: float = 1.0,
        seed: int = 0,
        log: bool = False,
        threads: Optional[int] = 1,
        **options: Any,
    ) -> None: ...
    def params(self, index: int) -> Dict[str, Any]:
        """What sample ``index`` gets: ``applied``, ``mor`` or ``rain_rate``, ``key``."""
    def __call__(self, points: Any, index: int) -> Any:
        """``points`` augmented for sample ``index`` (same layout)."""

def plan(
    inputs: Sequence[PathLike], out: PathLike, *, format: Optional[str] = None
) -> Tuple[List[Tuple[str, str, str]], List[Tuple[str, str]]]:
    """``murk apply``'s plan: jobs ``(input, output, key)`` and skipped files ``(path, reason)``.
    Creates the output folders."""

def apply_file(
    input: PathLike,
    output: PathLike,
    key: str,
    table: Union[Table, PathLike],
    weather: str,
    *,
    mor: Optional[float] = None,
    rain_rate: Optional[float] = None,
    seed: int = 0,
    format: Optional[str] = None,
    pcd_data: str = "binary",
    intensity_scale: IntensityScaleArg = None,
    near_range: bool = False,
    near_range_count_scale: float = 1.0,
    soft_edge: bool = False,
    range_noise: Optional[float] = None,
    attenuate_intensity: bool = False,
    slope: str = "survival",
    clamp: bool = False,
    covariates: Optional[Mapping[str, Union[str, float]]] = None,
    extensions: bool = True,
    range_scale: Optional[float] = None,
    clear_mor_threshold: Optional[float] = None,
    min_range: Optional[float] = None,
    threads: Optional[int] = None,
) -> Dict[str, Any]:
    """One job of ``murk apply`` (read, apply with scan key ``key``, write atomically),
    byte for byte what the CLI writes; returns the file's summary."""

def apply_files(
    inputs: Union[PathLike, Sequence[PathLike]],
    out: PathLike,
    table: Union[Table, PathLike],
    weather: str,
    **options: Any,
) -> List[Dict[str, Any]]:
    """``murk apply INPUTS --out OUT`` in this process (same plan, same bytes)."""
