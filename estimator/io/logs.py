"""Flight logs as recorded: PX4 ULog and MATLAB files read into streams, each on its own clock.

A log holds **streams**: a ULog topic instance (``sensor_combined``, ``vehicle_gps_position``,
``sensor_accel:1`` for the second instance of a multi-instance topic), or a MATLAB struct whose
fields are vectors of one length (``flight_data``; the file's top-level vectors are the stream
``""``). A stream's samples carry its own time stamps: the field ``timestamp`` of a ULog topic
(microseconds since boot), the struct's time field in a MATLAB file (the field the problem file's
``t`` column names, e.g. ``time``).

A problem file's ``[columns]`` name a **path** into the log: the stream, a dot, the field
(``sensor_combined.accelerometer_m_s2[0]``, ``flight_data.aoa``; ``[i]`` takes column ``i`` of a
MATLAB matrix, as it does element ``i`` of a ULog array field). A quaternion field of four
components, scalar first (PX4's ``vehicle_attitude.q``: body to NED), gives Euler angles (ZYX:
yaw, pitch, roll) with the suffix ``.roll``, ``.pitch`` or ``.yaw`` (rad).

Onto one time base (:func:`log_frame`): the ``t`` column's stream is the base; a column of
another stream is linearly interpolated onto the base's stamps from its own stamps (plus a
declared clock offset per stream, ``offsets_s``), or, marked ``own_rate = true``, placed at the
base sample nearest each of its own samples (empty between them: fitted only where it has a
sample). Base samples outside another stream's span, or inside a dropout of it (a step longer
than :data:`DROPOUT_FACTOR` times its median step), get no value (NaN): the import's checks then
name the channel and the time, instead of a value made up across the gap.

Formats: ``ulog`` (``.ulg``; read with pyulog), ``mat`` (``.mat``: MATLAB v5 through
:func:`scipy.io.loadmat`, v7.3, which is HDF5, through h5py).
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from estimator.io.errors import DataError, close_match, warn

#: The log formats and their extensions.
LOG_FORMATS = ("ulog", "mat")
LOG_EXTENSIONS = {".ulg": "ulog", ".ulog": "ulog", ".mat": "mat"}
#: A stream's step longer than this times its median step is a dropout (lost samples).
DROPOUT_FACTOR = 3.0
#: The suffixes that turn a quaternion (w, x, y, z) into one Euler angle.
EULER_SUFFIXES = ("roll", "pitch", "yaw")
#: Names a MATLAB struct's time field is looked for under when listing streams.
TIME_FIELD_NAMES = ("time", "t", "timestamp", "Time", "TIME", "t_s")
#: The ULog topics' time stamp field and its unit.
ULOG_TIME_FIELD, ULOG_TIME_UNIT = "timestamp", "us"

_INDEX = re.compile(r"^(?P<name>.+)\[(?P<i>\d+)\]$")


@dataclass(frozen=True)
class Stream:
    """One stream of a log: fields of equal length, sampled together.

    Attributes
    ----------
    name : ``"sensor_combined"``, ``"sensor_accel:1"`` (a second instance), ``"flight_data"``.
    fields : field name -> (N,) or (N, k) values as recorded.
    time_field : the field holding its time stamps (None if it has none of its own).
    """

    name: str
    fields: Mapping[str, np.ndarray]
    time_field: str | None = None
    #: fields of another length than the stream's (a MATLAB struct's odd ones out): name -> length
    left_out: Mapping[str, int] = dataclasses.field(default_factory=dict)

    @property
    def samples(self) -> int:
        return len(next(iter(self.fields.values()))) if self.fields else 0


# --------------------------------------------------------------------------------------------------
# reading


def read_streams(path: Path, fmt: str, streams: Sequence[str] | None = None) -> dict[str, Stream]:
    """Every stream of a log file (or only ``streams``, by name: faster for a large ULog).

    Parameters
    ----------
    path : the file.
    fmt : ``"ulog"`` or ``"mat"``.
    streams : the stream names needed (None: all).
    """
    try:
        if fmt == "ulog":
            return _read_ulog(path, streams)
        if fmt == "mat":
            return _read_mat(path)
    except DataError:
        raise
    except (OSError, ValueError, TypeError, KeyError, IndexError, NotImplementedError) as exc:
        raise DataError(f"{path}: cannot read it as {fmt}: {str(exc).strip() or type(exc).__name__}; "
                        "check that the file is a complete, uncorrupted "
                        f"{'PX4 ULog' if fmt == 'ulog' else 'MATLAB'} file, and its format under its "
                        "[[files]] entry") from None
    raise DataError(f"{path}: format {fmt!r} is not a log format ({LOG_FORMATS})")


def _read_ulog(path: Path, streams: Sequence[str] | None) -> dict[str, Stream]:
    from pyulog import ULog

    topics = None if streams is None else sorted({s.split(":", 1)[0] for s in streams})
    try:
        log = ULog(str(path), message_name_filter_list=topics)
    except Exception as exc:  # pyulog's ULogException derives from Exception only
        if isinstance(exc, (OSError, MemoryError)):
            raise
        raise DataError(f"{path}: not a readable PX4 ULog ({str(exc).strip() or type(exc).__name__}); "
                        "check that the file is a complete .ulg log, and its format under its "
                        "[[files]] entry") from None
    if getattr(log, "file_corruption", False):
        warn(f"{path}: the log is corrupted in places (pyulog skipped damaged messages): check the "
             "streams' dropouts (fpr streams) before trusting it")
    out: dict[str, Stream] = {}
    for d in log.data_list:
        name = d.name if d.multi_id == 0 else f"{d.name}:{d.multi_id}"
        out[name] = Stream(name, dict(d.data), ULOG_TIME_FIELD)
    return out


def _read_mat(path: Path) -> dict[str, Stream]:
    with open(path, "rb") as fh:
        head = fh.read(128)
    if b"MATLAB 7.3" in head or _is_hdf5(path):
        return _read_mat73(path)
    from scipy.io import loadmat

    raw = loadmat(str(path), squeeze_me=True, struct_as_record=False)
    out: dict[str, Stream] = {}
    top = {k: v for k, v in raw.items() if not k.startswith("__")}
    _collect_mat(top, "", out, lambda v: getattr(v, "_fieldnames", None) is not None,
                 lambda v: {f: getattr(v, f) for f in v._fieldnames}, lambda v: np.asarray(v))
    return out


def _is_hdf5(path: Path) -> bool:
    with open(path, "rb") as fh:
        fh.seek(512)
        return fh.read(8) == b"\x89HDF\r\n\x1a\n"


def _read_mat73(path: Path) -> dict[str, Stream]:
    import h5py

    out: dict[str, Stream] = {}
    with h5py.File(path, "r") as f:
        top = {k: f[k] for k in f if not k.startswith("#")}
        # MATLAB writes column-major: an N-vector is a (1, N) dataset, an N x k matrix a (k, N) one
        _collect_mat(top, "", out, lambda v: isinstance(v, h5py.Group),
                     lambda v: {k: v[k] for k in v if not k.startswith("#")},
                     lambda v: np.asarray(v[()]).T)
    return out


def _collect_mat(items: Mapping, prefix: str, out: dict[str, Stream], is_struct, fields_of,
                 array_of) -> None:
    """Streams of a MATLAB file: the numeric vectors and matrices of each struct (and of the top
    level), grouped by their length; structs inside are walked with their dotted path."""
    arrays: dict[str, np.ndarray] = {}
    for key, value in items.items():
        if is_struct(value):
            _collect_mat(fields_of(value), f"{prefix}{key}.", out, is_struct, fields_of, array_of)
            continue
        a = array_of(value)
        if a.dtype.kind in "biuf" and a.ndim in (1, 2) and a.size > 1:
            arrays[key] = np.atleast_1d(np.squeeze(a)) if a.ndim == 2 and 1 in a.shape else a
    if not arrays:
        return
    # the stream's length: its time vector's, else the commonest (ties: the longest)
    timed = next((t for t in TIME_FIELD_NAMES if t in arrays and arrays[t].ndim == 1), None)
    lengths = [len(a) for a in arrays.values()]
    n = len(arrays[timed]) if timed else max(lengths, key=lambda k: (lengths.count(k), k))
    name = prefix[:-1]
    fields = {k: a for k, a in arrays.items() if len(a) == n}
    out[name] = Stream(name, fields, timed, {k: len(a) for k, a in arrays.items() if len(a) != n})


# --------------------------------------------------------------------------------------------------
# paths


def split_path(source: str) -> tuple[str, str]:
    """``"sensor_combined.gyro_rad[0]"`` -> ``("sensor_combined", "gyro_rad[0]")``; a MATLAB
    struct path splits at its last dot that leaves a field (``"a.b.c"`` -> ``("a.b", "c")``), a
    top-level variable has the stream ``""``."""
    if source.endswith(tuple(f".{s}" for s in EULER_SUFFIXES)):
        head, suffix = source.rsplit(".", 1)
        stream, field = split_path(head)
        return stream, f"{field}.{suffix}"
    if "." not in source:
        return "", source
    return tuple(source.rsplit(".", 1))  # type: ignore[return-value]


def _stream_of(streams: Mapping[str, Stream], source: str) -> tuple[Stream, str]:
    """The stream a column path names and the field within it. ULog field names may hold dots
    (``previous.lat``): the longest stream name that prefixes the path wins."""
    for name in sorted(streams, key=len, reverse=True):
        if name and source.startswith(name + "."):
            return streams[name], source[len(name) + 1:]
    if "" in streams:
        return streams[""], source
    return None, source  # type: ignore[return-value]


def field_values(stream: Stream, field: str, where: str) -> np.ndarray:
    """The (N,) values of ``field`` in ``stream``: a field, an element ``name[i]`` of an array
    field, or an Euler angle ``q.roll`` / ``q.pitch`` / ``q.yaw`` of a quaternion field."""
    if field in stream.fields and np.ndim(stream.fields[field]) == 1:
        return np.asarray(stream.fields[field], dtype=float)
    base, _, suffix = field.rpartition(".")
    if suffix in EULER_SUFFIXES and base:
        return euler_from_quaternion(_quaternion(stream, base, where))[EULER_SUFFIXES.index(suffix)]
    m = _INDEX.match(field)
    if m and m["name"] in stream.fields and np.ndim(stream.fields[m["name"]]) == 2:
        a = stream.fields[m["name"]]
        i = int(m["i"])
        if i >= a.shape[1]:
            raise DataError(f"{where}: {field!r}: {m['name']} has {a.shape[1]} columns (0 to "
                            f"{a.shape[1] - 1}); fix the index")
        return np.asarray(a[:, i], dtype=float)
    if field in stream.fields or f"{field}[0]" in stream.fields:
        k = np.shape(stream.fields[field])[1] if field in stream.fields else sum(
            1 for f in stream.fields if _INDEX.match(f) and _INDEX.match(f)["name"] == field)
        extra = (f"; a quaternion: take {field}.roll, {field}.pitch or {field}.yaw" if k == 4 else "")
        raise DataError(f"{where}: {field!r} has {k} components: take one, e.g. {field}[0]{extra}")
    base_name = (m["name"] if m else field)
    if base_name in stream.left_out:
        raise DataError(f"{where}: {base_name!r} has {stream.left_out[base_name]} samples, the other fields "
                        f"of stream {stream.name!r} {stream.samples}: it is not on their time base; "
                        "write it into a struct of its own with its own time vector")
    near = close_match(field, list(stream.fields))
    raise DataError(f"{where}: stream {stream.name or '(top level)'!r} has no field {field!r}"
                    + (f"; did you mean {near!r}?" if near else "")
                    + f"; its fields: {_shown(stream.fields)}")


def _quaternion(stream: Stream, field: str, where: str) -> np.ndarray:
    """(4, N) quaternion components, scalar first, of a ULog array field ``q[0..3]`` or a MATLAB
    N x 4 matrix."""
    if all(f"{field}[{i}]" in stream.fields for i in range(4)):
        return np.array([np.asarray(stream.fields[f"{field}[{i}]"], dtype=float) for i in range(4)])
    a = stream.fields.get(field)
    if a is not None and np.ndim(a) == 2 and np.shape(a)[1] == 4:
        return np.asarray(a, dtype=float).T
    raise DataError(f"{where}: {field!r} is not a quaternion of four components (w, x, y, z) in "
                    f"stream {stream.name!r}; its fields: {_shown(stream.fields)}")


def euler_from_quaternion(q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Roll, pitch, yaw (rad; ZYX Euler angles) of unit quaternions ``q = (w, x, y, z)`` rotating
    body axes into the navigation frame (PX4's ``vehicle_attitude.q``, body FRD to NED).

    Parameters
    ----------
    q : (4, N) quaternions, scalar first (normalised here).

    Returns
    -------
    roll_rad, pitch_rad, yaw_rad : (N,) each; yaw in (-pi, pi].
    """
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q, axis=0)
    roll = np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2.0 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return roll, pitch, yaw


def _shown(fields: Mapping) -> str:
    names = list(fields)
    return str(names[:40] + (["..."] if len(names) > 40 else []))


# --------------------------------------------------------------------------------------------------
# onto one time base


def log_frame(path: Path, fmt: str, columns: Mapping[str, Mapping], where: str,
              offsets_s: Mapping[str, float] | None = None, time_factor_s: float = 1.0) -> pd.DataFrame:
    """The problem file's columns of a log on the time base of its ``t`` column's stream.

    Parameters
    ----------
    path, fmt : the log file and its format (:data:`LOG_FORMATS`).
    columns : canonical name -> ``{"column": path, "own_rate": bool, "optional": bool}``; ``t``
        names the base stream's time field (``sensor_combined.timestamp``).
    where : how messages name the ``[[files]]`` entry.
    offsets_s : stream -> clock offset, s, added to that stream's stamps to bring them onto the
        base stream's clock (a declared offset; 0 where absent).
    time_factor_s : seconds per unit of the stamps (the ``t`` column's unit: 1e-6 for ULog's us).

    Returns
    -------
    One row per base sample, one column per path (named by the path), values as recorded.
    """
    if "t" not in columns or not isinstance(columns["t"].get("column"), str):
        raise DataError(f"{where}: a log needs t = {{ column = \"STREAM.TIME_FIELD\", unit = ... }} under "
                        "[columns]: the stream whose time stamps are the time base (e.g. "
                        "\"sensor_combined.timestamp\", unit \"us\"; \"flight_data.time\", unit \"s\")")
    paths = {name: spec["column"] for name, spec in columns.items()}
    _check_paths(paths, columns, where)
    # a ULog topic's name holds no dot (its fields may: previous.lat); instances are topic:k
    topics = [p.split(".", 1)[0] for p in paths.values()]
    streams = read_streams(path, fmt, topics if fmt == "ulog" else None)
    base, t_field = _stream_of(streams, paths["t"])
    if base is None:
        raise _no_stream(path, fmt, streams, paths["t"], "t")
    t_base = field_values(base, t_field, f"{path}: t")  # raw stamps, in the t column's unit
    offsets = _checked_offsets(offsets_s, streams, paths, base, where)
    frame, holes = {paths["t"]: t_base}, {}
    for name, src in paths.items():
        if name == "t":
            continue
        stream, field = _stream_of(streams, src)
        if columns[name].get("optional", False) and not _holds(stream, field):
            continue  # a log that legitimately lacks it: no such channel, as for a table
        if stream is None:
            raise _no_stream(path, fmt, streams, src, name)
        label = f"{path}: {name} (column {src!r})"
        values = field_values(stream, field, label)
        if stream is not base:
            t_own = _stream_time(stream, t_field, label)
            if t_own is not None:
                t_own = t_own + offsets.get(stream.name, 0.0) / time_factor_s
                holes[src] = stream_holes(t_own, stream.name, time_factor_s)
            values = _onto_base(t_base, t_own, stream.name, values, field, label,
                                columns[name].get("own_rate", False))
        frame[src] = values
    df = pd.DataFrame(frame)
    df.attrs["holes"] = holes
    return df


def stream_holes(t_own: np.ndarray, stream: str, time_factor_s: float) -> list[tuple[float, float, str]]:
    """Where a stream has no samples, s on the base clock: its dropouts (steps over
    :data:`DROPOUT_FACTOR` times its median) as ``(start_s, end_s, what)``, and the open ends
    before its first and after its last sample."""
    t = np.asarray(t_own, dtype=float) * time_factor_s
    out = [(-math.inf, float(t[0]), f"before stream {stream!r}'s first sample"),
           (float(t[-1]), math.inf, f"after stream {stream!r}'s last sample")]
    if t.size > 2:
        steps = np.diff(t)
        for i in np.flatnonzero(steps > DROPOUT_FACTOR * np.median(steps)):
            out.append((float(t[i]), float(t[i + 1]),
                        f"in a dropout of stream {stream!r} (no samples for {steps[i]:.3g} s)"))
    return out


def _check_paths(paths: Mapping[str, object], columns: Mapping[str, Mapping], where: str) -> None:
    """Every column a path; a path used twice only the same way (interpolated or own-rate)."""
    seen: dict[str, bool] = {}
    for name, src in paths.items():
        if not isinstance(src, str):
            raise DataError(f"{where}: {name} = {{ column = {src!r} }}: a log's columns are paths "
                            "(\"STREAM.FIELD\"), not indices")
        own = bool(columns[name].get("own_rate", False))
        if seen.setdefault(src, own) != own:
            raise DataError(f"{where}: {src!r} is mapped twice, once with own_rate = true and once "
                            "without: map it once")


def _holds(stream: Stream | None, field: str) -> bool:
    """Does the stream hold the field (or the array or quaternion it names)? Only a column whose
    data are absent is skipped as optional: a wrong index or suffix is still an error."""
    if stream is None:
        return False
    base = field.rpartition(".")[0] if field.endswith(tuple(f".{s}" for s in EULER_SUFFIXES)) else field
    m = _INDEX.match(base)
    name = m["name"] if m else base
    return name in stream.fields or f"{name}[0]" in stream.fields


def _checked_offsets(offsets_s: Mapping[str, float] | None, streams: Mapping[str, Stream],
                     paths: Mapping[str, str], base: Stream, where: str) -> dict[str, float]:
    """The declared clock offsets, s: each of a stream a column uses, and none of the base's."""
    offsets = dict(offsets_s or {})
    used = {s.name for s, _ in (_stream_of(streams, p) for p in paths.values()) if s is not None}
    unknown = sorted(set(offsets) - used)
    if unknown:
        raise DataError(f"{where}: offsets_s names stream(s) {unknown} that no column takes data from; "
                        f"the columns' streams: {sorted(used)}")
    if offsets.get(base.name, 0.0) != 0.0:
        raise DataError(f"{where}: offsets_s gives the time base's own stream {base.name!r} an offset: "
                        "the base defines the clock; give the other streams the opposite offset")
    return offsets


def _onto_base(t_base: np.ndarray, t_own: np.ndarray | None, stream: str, values: np.ndarray, field: str,
               label: str, own_rate: bool) -> np.ndarray:
    """A column of another stream on the base stamps; ``t_own``: its own stamps on the base clock
    (offset applied), in the base's unit, or None when the stream has no time field."""
    if t_own is None:
        if len(values) != len(t_base):
            raise DataError(f"{label}: stream {stream!r} has {len(values)} samples and no time field of "
                            f"its own, the time base {len(t_base)}: give it one, or take the column from "
                            "the base stream")
        return values
    if own_rate:
        return _nearest(t_base, t_own, values, label)
    if field.endswith((".roll", ".yaw")):
        # an angle that wraps at +-180 deg: interpolated unwrapped, wrapped again
        return np.mod(_interpolated(t_base, t_own, np.unwrap(values)) + np.pi, 2.0 * np.pi) - np.pi
    return _interpolated(t_base, t_own, values)


def _no_stream(path: Path, fmt: str, streams: Mapping[str, Stream], src: str, name: str) -> DataError:
    if fmt == "ulog":  # the streams read were only the ones asked for: list them all
        streams = read_streams(path, fmt)
    stream = src.split(".", 1)[0] if fmt == "ulog" else split_path(src)[0]
    near = close_match(stream, [s for s in streams if s])
    return DataError(f"{path}: {name} (column {src!r}): the file has no stream {stream!r}"
                     + (f"; did you mean {near!r}?" if near else "")
                     + f"; its streams: {_shown(streams)} (`fpr streams {path.name}` lists them with "
                     "their rates)")


def _stream_time(stream: Stream, t_field: str, where: str) -> np.ndarray | None:
    """A stream's own stamps, in the base's unit: its field of the base's time field's name (ULog:
    ``timestamp``; a MATLAB struct: e.g. ``time``), None when it has none; checked to increase."""
    if t_field not in stream.fields:
        return None
    t = np.asarray(stream.fields[t_field], dtype=float)
    steps = np.diff(t)
    bad = np.flatnonzero(~(steps > 0))
    if bad.size:
        raise DataError(f"{where}: stream {stream.name!r}'s time stamps ({t_field}) do not increase at "
                        f"sample {int(bad[0]) + 1} ({t[bad[0]]!r} then {t[bad[0] + 1]!r}; {bad.size} such "
                        "steps): the stream cannot be put on the time base; take the column from another "
                        "stream, or repair the log's stamps")
    return t


def _dropout_mask(t_base: np.ndarray, t_own: np.ndarray) -> np.ndarray:
    """Base samples outside the stream's span or strictly inside one of its dropouts."""
    out = (t_base < t_own[0]) | (t_base > t_own[-1])
    if t_own.size > 2:
        steps = np.diff(t_own)
        gap = np.flatnonzero(steps > DROPOUT_FACTOR * np.median(steps))
        if gap.size:
            k = np.searchsorted(t_own, t_base, side="right") - 1  # the stream sample at or before
            inside = (k >= 0) & (k < t_own.size - 1)
            kk = np.clip(k, 0, t_own.size - 1)
            out |= inside & np.isin(k, gap) & (t_base > t_own[kk])
    return out


def _interpolated(t_base: np.ndarray, t_own: np.ndarray, values: np.ndarray) -> np.ndarray:
    v = np.interp(t_base, t_own, values)
    v[_dropout_mask(t_base, t_own)] = np.nan
    return v


def _nearest(t_base: np.ndarray, t_own: np.ndarray, values: np.ndarray, label: str) -> np.ndarray:
    """Each own sample at the base sample nearest it (NaN elsewhere): an own-rate column. A sample
    more than half a base step from every base sample (in a gap of the base) is left out; two on
    one base sample mean the stream is not slower than the base: an error."""
    v = np.full(t_base.size, np.nan)
    inside = (t_own >= t_base[0]) & (t_own <= t_base[-1])
    t_in, v_in = t_own[inside], values[inside]
    k = np.clip(np.searchsorted(t_base, t_in), 1, t_base.size - 1)
    k -= (t_in - t_base[k - 1]) < (t_base[k] - t_in)
    half_step = 0.5 * float(np.median(np.diff(t_base))) if t_base.size > 1 else np.inf
    near = np.abs(t_in - t_base[k]) <= half_step
    k, v_in = k[near], v_in[near]
    if k.size and np.any(np.diff(k) == 0):
        raise DataError(f"{label}: own_rate = true, but two of its samples fall on one sample of the "
                        "time base: the stream is not slower than the base; leave own_rate out (it is "
                        "then interpolated)")
    v[k] = v_in
    return v


# --------------------------------------------------------------------------------------------------
# what a log holds


def stream_table(path: str | Path, fmt: str | None = None,
                 time_factor_s: float | None = None) -> pd.DataFrame:
    """One row per stream of a log: its samples, time span, rate and dropouts.

    Parameters
    ----------
    path : a ULog or MATLAB file.
    fmt : ``"ulog"`` or ``"mat"`` (None: from the extension).
    time_factor_s : seconds per unit of the stamps (None: 1e-6 for ULog, 1 for MATLAB files).

    Returns
    -------
    Columns ``stream``, ``fields``, ``samples``, ``time_field``, ``first_s``, ``last_s``,
    ``span_s``, ``rate_hz`` (median step), ``dropouts`` (steps over :data:`DROPOUT_FACTOR` times
    the median), ``longest_dropout_s``, ``bad_stamps`` (steps that do not increase).
    """
    p = Path(path)
    if not p.is_file():
        raise DataError(f"{p}: no such file")
    fmt = fmt or LOG_EXTENSIONS.get(p.suffix.lower())
    if fmt not in LOG_FORMATS:
        raise DataError(f"{p}: cannot tell the log format from the extension {p.suffix!r} (known: "
                        f"{sorted(LOG_EXTENSIONS)}); give it (ulog or mat)")
    factor = time_factor_s if time_factor_s is not None else (1e-6 if fmt == "ulog" else 1.0)
    rows = [_stream_row(s, factor) for s in read_streams(p, fmt).values()]
    if not rows:
        raise DataError(f"{p}: the log holds no stream with data (no topic with samples, no numeric "
                        "vector); check that it is the right file and complete")
    return pd.DataFrame(rows).sort_values("stream", kind="stable").reset_index(drop=True)


def _stream_row(s: Stream, factor: float) -> dict:
    row = {"stream": s.name or "(top level)", "fields": len(s.fields), "samples": s.samples,
           "time_field": s.time_field or "", "first_s": math.nan, "last_s": math.nan,
           "span_s": math.nan, "rate_hz": math.nan, "dropouts": 0, "longest_dropout_s": 0.0,
           "bad_stamps": 0}
    if s.time_field is None or s.samples < 2:
        return row
    t = np.asarray(s.fields[s.time_field], dtype=float) * factor
    steps = np.diff(t)
    good = steps[steps > 0]
    row.update(first_s=float(t[0]), last_s=float(t[-1]), span_s=float(t[-1] - t[0]),
               bad_stamps=int(np.sum(~(steps > 0))))
    if good.size:
        med = float(np.median(good))
        long = good[good > DROPOUT_FACTOR * med]
        row.update(rate_hz=1.0 / med, dropouts=int(long.size),
                   longest_dropout_s=float(long.max()) if long.size else 0.0)
    return row
