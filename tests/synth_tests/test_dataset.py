"""The dataset format: round trip, self-describing files, atomic writes, no clobbering."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from synth.dataset import (
    FORMAT,
    FORMAT_VERSION,
    load_dataset,
    prepare_directory,
    read_maneuver_metadata,
    write_maneuver,
    write_manifest,
)


def _frame(seed=0, n=100):
    rng = np.random.default_rng(seed)
    return pd.DataFrame({
        "t_s": np.arange(n) / 40.0,
        "alpha_zl_rad": rng.normal(0.05, 0.01, n),
        "true_alpha_cg_rad": rng.normal(0.05, 0.01, n),
    })


def _write(directory, frames):
    prepare_directory(directory)
    entries = []
    for i, df in enumerate(frames):
        entry = {"id": f"m{i:04d}", "file": f"maneuvers/m{i:04d}.parquet", "kind": "pitch_doublet",
                 "configuration": "PV1-NP", "aircraft": "PV1", "mach_nominal": 0.5,
                 "injected": {"imu.accel_bias_mps2": np.array([0.1, 0.0, -0.05])},
                 "n_samples": len(df), "duration_s": float(df.t_s.iloc[-1])}
        write_maneuver(directory / entry["file"], df, entry)
        entries.append(entry)
    write_manifest(directory, {"format": FORMAT, "format_version": FORMAT_VERSION, "maneuvers": entries})


def test_round_trip(tmp_path):
    frames = [_frame(0), _frame(1)]
    _write(tmp_path / "ds", frames)
    ds = load_dataset(tmp_path / "ds")
    assert len(ds) == 2
    assert list(ds.index.index) == ["m0000", "m0001"]
    pd.testing.assert_frame_equal(ds.load("m0001"), frames[1])
    meta = read_maneuver_metadata(tmp_path / "ds" / "maneuvers" / "m0000.parquet")
    assert meta["injected"]["imu.accel_bias_mps2"] == [0.1, 0.0, -0.05]
    for (_entry, df), ref in zip(ds, frames, strict=True):
        pd.testing.assert_frame_equal(df, ref)


def test_same_data_same_bytes(tmp_path):
    _write(tmp_path / "a", [_frame(3)])
    _write(tmp_path / "b", [_frame(3)])
    for name in ("manifest.json", "maneuvers/m0000.parquet"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name


def test_refuses_to_overwrite(tmp_path):
    _write(tmp_path / "ds", [_frame()])
    with pytest.raises(FileExistsError, match="--overwrite"):
        prepare_directory(tmp_path / "ds")
    # a directory that is not a dataset is never deleted, even with overwrite
    other = tmp_path / "precious"
    other.mkdir()
    (other / "flight_data.csv").write_text("t,alpha\n0,1\n")
    with pytest.raises(FileExistsError, match="not an fpr dataset"):
        prepare_directory(other, overwrite=True)
    assert (other / "flight_data.csv").exists()


def test_missing_file_is_reported(tmp_path):
    _write(tmp_path / "ds", [_frame(), _frame(1)])
    (tmp_path / "ds" / "maneuvers" / "m0001.parquet").unlink()
    with pytest.raises(FileNotFoundError, match="m0001.parquet"):
        load_dataset(tmp_path / "ds")


def test_not_a_dataset(tmp_path):
    with pytest.raises(FileNotFoundError, match="no manifest"):
        load_dataset(tmp_path)


def test_overwrite_deletes_only_an_fpr_dataset(tmp_path):
    # a user's directory that merely has a maneuvers/ folder is not a dataset: never deleted
    user = tmp_path / "flight_tests"
    (user / "maneuvers").mkdir(parents=True)
    (user / "maneuvers" / "notes.txt").write_text("flight 421")
    with pytest.raises(FileExistsError, match="not an fpr dataset"):
        prepare_directory(user, overwrite=True)
    assert (user / "maneuvers" / "notes.txt").exists()


def test_dataset_files_are_not_private(tmp_path):
    import os
    import stat

    _write(tmp_path / "ds", [_frame()])
    umask = os.umask(0)
    os.umask(umask)
    mode = stat.S_IMODE((tmp_path / "ds" / "manifest.json").stat().st_mode)
    assert mode == 0o666 & ~umask, oct(mode)


# --------------------------------------------------------------------------------------------------
# the estimator's reader: the format's own columns, and the model set's channels


def test_column_names_come_from_the_format_and_the_unit_suffix():
    from estimator.io.fprdataset import FPR_COLUMNS, canonical_name, dataset_column, dataset_columns

    assert canonical_name("h_baro_m") == "h" and canonical_name("gear_down") == "gear"
    assert canonical_name("alpha_zl_rad") == "alpha_zl" and canonical_name("mach") == "mach"
    cols = ["t_s", "q_rps", "h_baro_m", "alpha_zl_rad", "alpha_lm_rad", "true_alpha_zl_rad", "qc_pa"]
    assert dataset_column("alpha_zl", cols) == "alpha_zl_rad"
    assert dataset_column("h", cols) == "h_baro_m"
    assert dataset_column("beta_x", cols) == "beta_x"  # none: the name itself
    # the format's own columns always; others only when named, never the truth
    assert dataset_columns([], cols) == {"t_s": "t", "q_rps": "q", "h_baro_m": "h"}
    assert dataset_columns(["alpha_zl"], cols) == {"t_s": "t", "q_rps": "q", "h_baro_m": "h",
                                                   "alpha_zl_rad": "alpha_zl"}
    assert "alpha_zl" not in FPR_COLUMNS.values()  # a flow channel is the model set's, not the format's


@pytest.mark.slow
def test_the_reader_reads_the_model_sets_channels_and_no_list_of_its_own(tiny_dataset):
    from estimator.io import FPR_COLUMNS, load_dataset_maneuvers, problem_from_dataset
    from estimator.io.modelset import load_model_set

    tejas, _ = load_model_set("tejas")
    (table, _req), *_ = load_dataset_maneuvers(tiny_dataset, {"ids": "m0000"}, tejas)[0]
    own = set(FPR_COLUMNS.values())
    assert set(table.values) - own == {"alpha_zl", "alpha_zr", "alpha_zsp", "beta_zsp", "beta_znp"}
    assert table.labels["alpha_zl"] == "alpha_zl (column 'alpha_zl_rad')"
    assert table.units["alpha_zl"] == "rad"
    (table, _req), *_ = load_dataset_maneuvers(tiny_dataset, {"ids": "m0000"})[0]
    assert set(table.values) <= own

    # a channel only the problem declares reads its column too: the left vane's raw output
    problem = problem_from_dataset(tiny_dataset, {"ids": "m0000"}, channels=["theta", "alpha_lm"],
                                   extra_channels=[{"name": "alpha_lm", "sensor": "vane_left",
                                                    "measures": "alpha_s", "model": "alpha_s"}])
    m = problem.maneuvers[0]
    assert [c.name for c in problem.channels] == ["theta", "alpha_lm"]
    raw = pd.read_parquet(tiny_dataset / m.meta["file"], columns=["alpha_lm_rad"])["alpha_lm_rad"]
    np.testing.assert_array_equal(m.measurements["alpha_lm"], raw.to_numpy())
