"""Campaign files, `fpr fly`, and reproducibility of whole datasets (issue 2, must-show 4)."""

from __future__ import annotations

import copy
import os

import pytest

from campaigns.cli import main
from synth.campaign import (
    MANEUVERS_PER_DEFAULT_WORKER,
    CampaignError,
    fly_campaign,
    load_campaign,
    parse_campaign,
    pool_size,
)
from synth.dataset import load_dataset, maneuver_file, maneuver_id, maneuver_key, manifest_entry

SMALL = {
    "name": "small",
    "seed": 11,
    "fleet": "fleet_default",
    "environment": {"planet": "flat", "turbulence": "moderate", "wind_ned_mps": [4.0, -2.0, 0.0]},
    "errors": {"preset": "typical"},
    "flights": [{"configurations": ["PT2-BOOM"], "mach": [0.6], "maneuvers": ["pitch_doublet"],
                 "altitude_m": 6000.0, "maneuver": {"duration_s": 20.0}}],
}


def _files(directory):
    return {p.relative_to(directory).as_posix(): p.read_bytes()
            for p in sorted(directory.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def twin_runs(tmp_path_factory):
    base = tmp_path_factory.mktemp("repro")
    out = {}
    for name, seed in (("a", 11), ("b", 11), ("c", 12)):
        raw = copy.deepcopy(SMALL)
        raw["seed"] = seed
        res = fly_campaign(parse_campaign(raw, source="small.toml"), base / name, workers=1)
        assert res.ok, res.failures
        out[name] = base / name
    return out


def test_same_seed_gives_bit_identical_files(twin_runs):
    a, b = _files(twin_runs["a"]), _files(twin_runs["b"])
    assert a.keys() == b.keys()
    differing = [k for k in a if a[k] != b[k]]
    assert not differing, f"same seed, different bytes in {differing}"


def test_other_seed_gives_other_data(twin_runs):
    a, c = _files(twin_runs["a"]), _files(twin_runs["c"])
    parquet = [k for k in a if k.endswith(".parquet")]
    assert parquet and all(a[k] != c[k] for k in parquet)
    da = load_dataset(twin_runs["a"]).load("m0000")
    dc = load_dataset(twin_runs["c"]).load("m0000")
    # the noise differs; with moderate turbulence seeded from the master seed, so does the flight
    assert (da["alpha_zl_rad"] != dc["alpha_zl_rad"]).any()
    assert (da["true_alpha_cg_rad"] != dc["true_alpha_cg_rad"]).any()


def test_manifest_records_what_was_flown(twin_runs):
    ds = load_dataset(twin_runs["a"])
    (entry,) = ds.manifest["maneuvers"]
    assert entry["configuration"] == "PT2-BOOM" and entry["nose_sensor"] == "boom"
    assert entry["kind"] == "pitch_doublet" and entry["mach_nominal"] == 0.6
    assert abs(entry["mach_mean"] - 0.6) < 0.05
    assert entry["injected"], "every injected value must be in the manifest"
    assert ds.manifest["software"]["jsbsim"].startswith("1.3")
    df = ds.load("m0000")
    assert {"alpha_zb_rad", "beta_zbu_rad", "beta_zbl_rad"} <= set(df.columns)
    assert "beta_znp_rad" not in df.columns, "the boom replaces the nose probe"


def test_the_default_pool_grows_with_the_campaign(monkeypatch):
    """A small campaign flies in this process (a worker's start costs about as much as flying a
    few maneuvers), a large one on every CPU; a number given is kept, never above the maneuvers."""
    n = MANEUVERS_PER_DEFAULT_WORKER
    monkeypatch.setattr(os, "cpu_count", lambda: 8)
    for default in (None, 0):
        assert [pool_size(default, k) for k in (0, 1, n, n + 1, 2 * n, 2 * n + 1, 100 * n)] == [
            1, 1, 1, 2, 2, 3, 8]
    assert [pool_size(w, k) for w, k in ((1, 100), (4, 2), (4, 40), (3, 0))] == [1, 2, 4, 1]
    monkeypatch.setattr(os, "cpu_count", lambda: None)  # unknown: one
    assert pool_size(None, 100 * n) == 1


def test_seed_key_and_maneuver_id_layout():
    # job_index * 64 + segment: the key of every (job, segment) is its own
    keys = [maneuver_key(0, 0), maneuver_key(0, 63), maneuver_key(1, 0), maneuver_key(3, 1)]
    assert keys == [0, 63, 64, 193]
    with pytest.raises(ValueError, match=r"segment 64 of job 2 is outside 0-63.*fewer pieces"):
        maneuver_key(2, 64)
    with pytest.raises(ValueError, match="segment -1 of job 2"):
        maneuver_key(2, -1)
    with pytest.raises(ValueError, match="job index -1 is negative"):
        maneuver_key(-1, 0)
    assert maneuver_id(4, 0, 1) == "m0004" and maneuver_id(4, 1, 3) == "m0004s1"
    assert maneuver_id(12345, 0, 1) == "m12345"
    assert maneuver_file("m0004s1") == "maneuvers/m0004s1.parquet"


def test_manifest_entry_keys_and_values():
    from types import SimpleNamespace as NS

    import numpy as np
    import pandas as pd

    cfg = NS(id="PV1-NP", aircraft=NS(id="PV1"), nose_sensor="nose_probe", sensors=("vane_left",))
    spec = NS(kind="shss", mach=0.6, altitude_m=6000.0, gear_down=0, to_dict=lambda: {"kind": "shss"})
    env = NS(to_dict=lambda: {"planet": "flat"})
    truth = NS(mach=np.array([0.5, 0.7]), r_cg_body_m=np.array([[1.0, 0.0, 0.0], [3.0, 0.0, 2.0]]),
               g_mps2=np.array([9.8, 9.81]), meta={"spec": "dropped", "trim": 1})
    inst = NS(data=pd.DataFrame({"t_s": [2.0, 2.5, 4.0]}), injected={"maneuver_key": 193.0},
              channel_units={"q_rps": "rad/s"}, own_rate_columns=("h_dgps_m",))
    entry = manifest_entry(job_index=3, segment=1, n_segments=2, configuration=cfg, spec=spec,
                           environment=env, truth=truth, instrumented=inst, sample_rate_hz=40.0)
    assert list(entry) == [
        "id", "file", "job_index", "configuration", "aircraft", "nose_sensor", "sensors", "kind",
        "segment", "n_segments", "mach_nominal", "mach_mean", "mach_min", "mach_max", "altitude_m",
        "gear_down", "duration_s", "n_samples", "sample_rate_hz", "r_cg_body_m_mean", "g_mps2_mean",
        "maneuver", "environment", "injected", "channel_units", "own_rate_columns", "flight_meta"]
    assert entry["id"] == "m0003s1" and entry["file"] == "maneuvers/m0003s1.parquet"
    assert entry["sensors"] == ["vane_left"] and entry["gear_down"] is False
    assert entry["mach_mean"] == 0.6 and (entry["mach_min"], entry["mach_max"]) == (0.5, 0.7)
    assert entry["duration_s"] == 2.0 and entry["n_samples"] == 3 and entry["sample_rate_hz"] == 40.0
    assert entry["r_cg_body_m_mean"] == [2.0, 0.0, 1.0] and entry["own_rate_columns"] == ["h_dgps_m"]
    assert entry["flight_meta"] == {"trim": 1}


def test_flown_maneuvers_carry_their_seed_key(twin_runs):
    # `fpr fly` seeds each maneuver with maneuver_key and files it under maneuver_id
    for entry in load_dataset(twin_runs["a"]).manifest["maneuvers"]:
        assert entry["injected"]["maneuver_key"] == maneuver_key(entry["job_index"], entry["segment"])
        assert entry["id"] == maneuver_id(entry["job_index"], entry["segment"], entry["n_segments"])


def test_default_campaign_covers_the_fleet_and_the_envelope():
    camp = load_campaign("default")
    configs = {j.configuration_id for j in camp.jobs}
    assert len(configs) == 7 and len({camp.fleet.configurations[c].aircraft.id for c in configs}) == 5
    machs = {j.maneuver["mach"] for j in camp.jobs}
    assert min(machs) == 0.3 and max(machs) == 0.9
    from synth.maneuvers import MANEUVER_KINDS

    assert {j.maneuver["kind"] for j in camp.jobs} == set(MANEUVER_KINDS)
    assert any(j.maneuver["gear_down"] for j in camp.jobs)


@pytest.mark.parametrize(
    "patch, message",
    [
        ({"flightz": []}, "unknown key 'flightz' \\(did you mean 'flights'\\?\\)"),
        ({"flights": []}, "no \\[\\[flights\\]\\]"),
        ({"flights": [{"configurations": ["XX-NP"], "mach": [0.5]}]}, "XX-NP"),
        ({"flights": [{"mach": [0.5], "maneuvers": ["loop"]}]}, "unknown maneuver 'loop'.*valid: "),
        ({"flights": [{"maneuvers": ["3211"]}]}, "mach"),
    ],
)
def test_bad_campaign_files_say_what_is_wrong(patch, message):
    raw = {**copy.deepcopy(SMALL), **patch}
    with pytest.raises((CampaignError, KeyError), match=message):
        parse_campaign(raw, source="bad.toml")


def test_fly_help_explains_itself(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["fly", "--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    for word in ("campaign", "--mach", "--maneuver", "manifest.json", "default.toml"):
        assert word in text


def test_fly_by_flags_writes_a_dataset(tmp_path, capsys):
    out = tmp_path / "flags"
    code = main(["fly", "--config", "PV3-NP", "--mach", "0.4", "--maneuver", "3211",
                 "--altitude-m", "3000", "--out", str(out), "--workers", "1"])
    assert code == 0
    assert len(load_dataset(out)) == 1
    assert "1 maneuver files" in capsys.readouterr().out
    # never clobbers an existing dataset
    assert main(["fly", "--mach", "0.4", "--maneuver", "3211", "--out", str(out)]) == 2


def test_a_mistyped_path_never_falls_back_to_a_shipped_file(tmp_path):
    from aircraft_models import load_fleet

    with pytest.raises(FileNotFoundError, match="no such file"):
        load_fleet(tmp_path / "edited" / "fleet_default.toml")
    with pytest.raises(FileNotFoundError, match="no such campaign"):
        load_campaign(tmp_path / "default.toml")
    assert load_campaign("default").name == "default"  # a bare name is the shipped file
