"""Flight data written as the field's recorders write it: a PX4 ULog, a MATLAB v5 or v7.3 file.

The readers of :mod:`estimator.io.logs` are tested end to end against these: the same flight
written here and as Parquet must read into the same problem.

ULog (PX4's format, https://docs.px4.io/main/en/dev_log/ulog_file_format.html): a 16-byte header
(magic, version 1, start time in us), a flag-bits message, one format message per topic
(``name:uint64_t timestamp;double field;double[3] vec``), then the data section: one
add-logged-message per topic instance and one data message per sample, in time order. Every
field is written as ``double`` (``double[k]`` for a vector), so that values come back exactly.

MATLAB: v5 through :func:`scipy.io.savemat`; v7.3 is HDF5 as MATLAB writes it: a 512-byte
user block holding MATLAB's text header, a struct as a group (``MATLAB_class = "struct"``), each
field a ``double`` dataset stored column-major (an N-vector as a (1, N) dataset, an N x k matrix
as (k, N)).
"""

from __future__ import annotations

import struct
from collections.abc import Mapping
from pathlib import Path

import numpy as np

#: ULog's magic bytes and the file-format version written.
ULOG_MAGIC, ULOG_VERSION = b"ULog\x01\x12\x35", 1


def _message(kind: bytes, payload: bytes) -> bytes:
    return struct.pack("<HB", len(payload), kind[0]) + payload


def write_ulog(path: str | Path, topics: Mapping[str, Mapping[str, np.ndarray]], start_us: int = 0) -> Path:
    """Write topics to a ULog file.

    Parameters
    ----------
    path : the file written.
    topics : topic name -> fields; each has ``timestamp`` ((N,) integers, us, increasing) and
        fields of (N,) or (N, k) values, written as ``double`` / ``double[k]``. A second instance
        of a topic is named ``"topic:1"``.
    start_us : the header's start time, us.

    Returns
    -------
    The path.
    """
    formats, adds, samples = [], [], []
    names: dict[str, list[str]] = {}
    for msg_id, (key, fields) in enumerate(topics.items()):
        name, _, instance = key.partition(":")
        t = np.asarray(fields["timestamp"], dtype=np.uint64)
        cols = [(f, np.asarray(v, dtype="<f8").reshape(len(t), -1)) for f, v in fields.items()
                if f != "timestamp"]
        spec = ";".join(["uint64_t timestamp"] + [f"double{f'[{c.shape[1]}]' if c.shape[1] > 1 else ''} {f}"
                                                  for f, c in cols]) + ";"
        if name in names and names[name] != spec:
            raise ValueError(f"{path}: topic {name!r}: its instances must have the same fields")
        if name not in names:
            names[name] = spec
            formats.append(_message(b"F", f"{name}:{spec}".encode("ascii")))
        adds.append(_message(b"A", struct.pack("<BH", int(instance or 0), msg_id) + name.encode("ascii")))
        body = np.hstack([c for _, c in cols]) if cols else np.empty((len(t), 0))
        head = struct.pack("<H", msg_id)
        samples += [(int(ti), msg_id, _message(b"D", head + struct.pack("<Q", int(ti)) + row.tobytes()))
                    for ti, row in zip(t, body, strict=True)]
    samples.sort(key=lambda s: (s[0], s[1]))  # time order, as a logger writes them
    header = ULOG_MAGIC + struct.pack("<BQ", ULOG_VERSION, start_us)
    flags = _message(b"B", bytes(8) + bytes(8) + struct.pack("<3Q", 0, 0, 0))
    out = Path(path)
    out.write_bytes(b"".join([header, flags, *formats, *adds, *(s[2] for s in samples)]))
    return out


def write_mat(path: str | Path, structs: Mapping[str, Mapping[str, np.ndarray]], version: str = "5") -> Path:
    """Write structs of vectors (and N x k matrices) to a MATLAB file.

    Parameters
    ----------
    path : the file written.
    structs : struct name -> field name -> (N,) or (N, k) values (written as double).
    version : ``"5"`` (scipy) or ``"7.3"`` (HDF5, as MATLAB lays it out).
    """
    out = Path(path)
    data = {s: {f: np.asarray(v, dtype=float) for f, v in fields.items()} for s, fields in structs.items()}
    if version == "5":
        import scipy.io

        scipy.io.savemat(out, data)
        return out
    if version != "7.3":
        raise ValueError(f"{path}: MATLAB file version {version!r}: write \"5\" or \"7.3\"")
    import h5py

    with h5py.File(out, "w", userblock_size=512) as f:
        for s, fields in data.items():
            g = f.create_group(s)
            g.attrs["MATLAB_class"] = np.bytes_("struct")
            for name, v in fields.items():
                d = g.create_dataset(name, data=np.atleast_2d(v.T) if v.ndim == 2 else v[None, :])
                d.attrs["MATLAB_class"] = np.bytes_("double")
    with open(out, "r+b") as fh:  # MATLAB's text header in the user block
        fh.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, written by synth.export".ljust(116)
                 + bytes(8) + struct.pack("<H", 0x0200) + b"IM")
    return out


#: A sortie's recorder streams as PX4 topics: topic -> (stream, {field: column or columns}); the
#: flow angles of the side probe as PX4's airflow_aoa / airflow_slip (its AOA and sideslip vanes).
PX4_TOPICS: dict[str, tuple[str, dict[str, str | tuple[str, ...]]]] = {
    "sensor_combined": ("dru", {"gyro_rad": ("p_rps", "q_rps", "r_rps"),
                                "accelerometer_m_s2": ("ax_imu_mps2", "ay_imu_mps2", "az_imu_mps2")}),
    "vehicle_attitude": ("ins", {"q": ("phi_rad", "theta_rad", "psi_rad")}),
    "vehicle_local_position": ("ins", {"vx": "vn_mps", "vy": "ve_mps", "vz": "vd_mps"}),
    "airspeed_validated": ("dru", {"true_airspeed_m_s": "tas_mps"}),
    "vehicle_air_data": ("dru", {"baro_alt_meter": "h_baro_m"}),
    "airflow_aoa": ("dru", {"aoa_rad": "alpha_zsp_rad"}),
    "airflow_slip": ("dru", {"slip_rad": "beta_zsp_rad"}),
}


def quaternion_from_euler(phi_rad: np.ndarray, theta_rad: np.ndarray, psi_rad: np.ndarray) -> np.ndarray:
    """(N, 4) unit quaternions, scalar first, body to NED, of 3-2-1 Euler angles (rad)."""
    cr, sr = np.cos(phi_rad / 2), np.sin(phi_rad / 2)
    cp, sp = np.cos(theta_rad / 2), np.sin(theta_rad / 2)
    cy, sy = np.cos(psi_rad / 2), np.sin(psi_rad / 2)
    return np.column_stack([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                            cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy])


def sortie_px4_topics(directory: str | Path) -> dict[str, dict[str, np.ndarray]]:
    """A testbed sortie's recorder streams as PX4 topics (:data:`PX4_TOPICS`), each on its own
    recorder's clock (``timestamp``: the stream's ``t_s`` in us, rounded), SI as PX4 logs them."""
    import pandas as pd

    directory = Path(directory)
    streams: dict[str, pd.DataFrame] = {}
    topics = {}
    for topic, (stream, fields) in PX4_TOPICS.items():
        if stream not in streams:
            streams[stream] = pd.read_parquet(directory / "streams" / f"{stream}.parquet")
        df = streams[stream]
        out = {"timestamp": np.round(df["t_s"].to_numpy() * 1e6).astype(np.int64)}
        if (out["timestamp"] < 0).any():
            raise ValueError(f"{directory}: stream {stream} starts before t = 0; a ULog's stamps are "
                             "unsigned")
        for name, cols in fields.items():
            if name == "q":
                out[name] = quaternion_from_euler(*(df[c].to_numpy() for c in cols))
            elif isinstance(cols, tuple):
                out[name] = np.column_stack([df[c].to_numpy() for c in cols])
            else:
                out[name] = df[cols].to_numpy()
        topics[topic] = out
    return topics


def write_sortie_log(directory: str | Path, path: str | Path) -> Path:
    """A testbed sortie written as a PX4 log: a ULog (``.ulg``) or a MATLAB file (``.mat``: v5;
    one struct per topic), PX4's topic names (:func:`sortie_px4_topics`)."""
    path = Path(path)
    if path.suffix.lower() not in (".ulg", ".mat"):
        raise ValueError(f"{path}: write a .ulg (PX4 ULog) or a .mat (MATLAB v5) file")
    topics = sortie_px4_topics(directory)
    if path.suffix.lower() == ".ulg":
        return write_ulog(path, topics)
    if path.suffix.lower() == ".mat":
        return write_mat(path, topics)
    raise ValueError(f"{path}: write a .ulg (PX4 ULog) or a .mat (MATLAB v5) file")
