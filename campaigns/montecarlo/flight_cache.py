"""The shared-flight cache of a Monte Carlo run: the truth segments of one flown maneuver in a file.

A run folder can come from anyone (copied from a colleague, downloaded), so nothing in it is
unpickled: the cache is a NumPy ``.npz`` archive read with ``allow_pickle=False``. Each array of
each :class:`~synth.truth.TruthTrajectory` segment (``t_s``, ``v_body_mps``, ..., every control)
is one ``.npy`` member, written with its dtype and shape, so float64 values come back bit for bit;
a member ``header.npy`` (UTF-8 JSON bytes) says which member is which field and holds each
segment's ``planet`` and ``meta``. The meta is plain JSON (floats written as Python's shortest
round-trip repr, NaN and infinities included; keys in their order) with tuples tagged so that they
come back as tuples; NumPy scalars in it are stored as the Python numbers they equal.

The archive is written deterministically (fixed member order and time stamps), so one flight gives
one byte string, whatever the run.
"""

from __future__ import annotations

import dataclasses
import io
import json
import zipfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from synth.truth import TruthTrajectory

#: the cache file's suffix (``flights/j0007.npz``)
SUFFIX = ".npz"
FORMAT = "fpr-montecarlo-flight"
FORMAT_VERSION = 1
_HEADER = "header"
_TUPLE = "__tuple__"  # JSON tag of a tuple in a segment's meta
_ZIP_TIME = (1980, 1, 1, 0, 0, 0)  # the earliest a zip can say: no wall time in the file
_ARRAY_FIELDS = tuple(f.name for f in dataclasses.fields(TruthTrajectory)
                      if f.name not in ("controls", "planet", "meta"))


def flight_file(directory: str | Path, job_index: int) -> Path:
    """The cache file of maneuver (job) ``job_index`` in a run's ``flights/`` directory."""
    return Path(directory) / f"j{job_index:04d}{SUFFIX}"


def _encode_meta(value, where: str):
    """``value`` as JSON-ready data that :func:`_decode_meta` turns back into an equal value."""
    if isinstance(value, dict):
        if set(value) == {_TUPLE}:
            raise ValueError(f"{where}: the key {_TUPLE!r} is reserved by the flight cache")
        out = {}
        for k, v in value.items():
            if not isinstance(k, str):
                raise TypeError(f"{where}: key {k!r} is a {type(k).__name__}; the flight cache "
                                "stores string keys only")
            out[k] = _encode_meta(v, f"{where}.{k}")
        return out
    if isinstance(value, tuple):
        return {_TUPLE: [_encode_meta(v, f"{where}[{i}]") for i, v in enumerate(value)]}
    if isinstance(value, list):
        return [_encode_meta(v, f"{where}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, np.generic):
        return value.item()
    if value is None or type(value) in (str, int, float, bool):
        return value
    raise TypeError(f"{where}: a {type(value).__name__} cannot be stored in the flight cache "
                    "(JSON values, lists, tuples and dicts only)")


def _decode_meta(value):
    if isinstance(value, dict):
        if set(value) == {_TUPLE}:
            return tuple(_decode_meta(v) for v in value[_TUPLE])
        return {k: _decode_meta(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_decode_meta(v) for v in value]
    return value


def flight_bytes(segments: Sequence[TruthTrajectory]) -> bytes:
    """The cache file's content for one maneuver's truth segments (deterministic).

    Parameters
    ----------
    segments : the segments :func:`synth.flight.fly_maneuver` returned.

    Raises
    ------
    TypeError, ValueError
        A segment's meta holds something JSON cannot carry faithfully (the key is named).
    """
    members: list[tuple[str, np.ndarray]] = []
    header = {"format": FORMAT, "format_version": FORMAT_VERSION, "segments": []}
    for i, seg in enumerate(segments):
        arrays = {name: getattr(seg, name) for name in _ARRAY_FIELDS}
        controls = list(seg.controls)
        header["segments"].append({
            "arrays": list(arrays), "controls": controls, "planet": seg.planet,
            "meta": _encode_meta(dict(seg.meta), f"segment {i} meta")})
        # members are numbered, not named after the fields: a control's name never becomes a path
        members += [(f"s{i}_a{k}", np.asarray(a)) for k, a in enumerate(arrays.values())]
        members += [(f"s{i}_c{k}", np.asarray(seg.controls[c])) for k, c in enumerate(controls)]
    # keys in their own order (not sorted): a dict comes back as it went in
    text = json.dumps(header, allow_nan=True).encode()
    members.insert(0, (_HEADER, np.frombuffer(text, dtype=np.uint8)))
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name, array in members:
            info = zipfile.ZipInfo(f"{name}.npy", date_time=_ZIP_TIME)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            with zf.open(info, "w", force_zip64=True) as fh:
                np.lib.format.write_array(fh, array, allow_pickle=False)
    return buf.getvalue()


def read_flight(path: str | Path) -> tuple[TruthTrajectory, ...]:
    """Read one maneuver's truth segments from its cache file (never unpickles anything).

    Raises
    ------
    ValueError
        The file is not a flight-cache file of this format (the message names it and says to
        delete it: the flight is then flown again).
    """
    path = Path(path)
    fix = f"delete {path} and run the same command again: the flight is flown again"
    try:
        loaded = np.load(path, allow_pickle=False)
        if not isinstance(loaded, np.lib.npyio.NpzFile):
            raise ValueError("a single array, not an archive")
        with loaded as z:
            header = json.loads(bytes(z[_HEADER]).decode())
            if header.get("format") != FORMAT or header.get("format_version") != FORMAT_VERSION:
                raise ValueError(f"format {header.get('format')!r} version "
                                 f"{header.get('format_version')!r}, expected {FORMAT!r} "
                                 f"version {FORMAT_VERSION}")
            out = []
            for i, seg in enumerate(header["segments"]):
                unknown = set(seg["arrays"]) - set(_ARRAY_FIELDS)
                if unknown:
                    raise ValueError(f"segment {i}: unknown fields {sorted(unknown)}")
                arrays = {name: z[f"s{i}_a{k}"] for k, name in enumerate(seg["arrays"])}
                controls = {name: z[f"s{i}_c{k}"] for k, name in enumerate(seg["controls"])}
                out.append(TruthTrajectory(**arrays, controls=controls, planet=str(seg["planet"]),
                                           meta=_decode_meta(seg["meta"])))
    except FileNotFoundError:
        raise
    except (OSError, KeyError, TypeError, ValueError, zipfile.BadZipFile, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: not a readable flight-cache file ({type(exc).__name__}: {exc}); "
                         f"{fix}") from None
    return tuple(out)

