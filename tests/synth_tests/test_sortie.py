"""Whole sorties (issue 13, must-show 4): one continuous flight per configuration, one stream per
recorder, the maneuver boundaries as truth; cut out by them, a maneuver is its test point's."""

from __future__ import annotations

import numpy as np
import pytest

from campaigns.cli import main
from synth.campaign import parse_campaign
from synth.dataset import (
    BOUNDARY_COLUMNS,
    SORTIE_FILES,
    load_dataset,
    load_sortie,
    maneuver_id,
    prepare_sortie_directory,
)
from synth.environment import Environment
from synth.flight import fly_maneuver
from synth.maneuvers import ManeuverSpec
from synth.sortie import fly_sortie_campaign, sortie_jobs

# four short maneuvers at three test points: a speed change and a climb between the first two (the
# level acceleration ends faster than the next point: a deceleration back to it), then a descent,
# a deceleration and the gear down. The climb (300 m) and the descent (800 m) are small: at
# Transition.climb_rate_mps a transition's time is mostly its height change, and each flight of
# this sortie (the module's and test_same_campaign_same_bytes's) is mostly its transitions
SMALL = {
    "name": "sortie-small",
    "seed": 5,
    "fleet": "fleet_default",
    "environment": {"planet": "flat", "turbulence": "none", "wind_ned_mps": [6.0, -4.0, 0.0]},
    "errors": {"preset": "typical"},
    "flights": [
        {"configurations": ["PV1-NP"], "mach": [0.4], "maneuvers": ["pitch_doublet", "level_accel"],
         "altitude_m": 4000.0, "maneuver": {"duration_s": 20.0}},
        {"configurations": ["PV1-NP"], "mach": [0.5], "maneuvers": ["pitch_doublet"],
         "altitude_m": 4300.0, "maneuver": {"duration_s": 20.0}},
        {"configurations": ["PV1-NP"], "mach": [0.3], "maneuvers": ["pitch_doublet"],
         "altitude_m": 3500.0, "gear_down": True, "maneuver": {"duration_s": 20.0}},
    ],
}


@pytest.fixture(scope="module")
def sortie(tmp_path_factory):
    campaign = parse_campaign(SMALL, source="sortie-small.toml")
    out = tmp_path_factory.mktemp("sortie") / "s"
    result = fly_sortie_campaign(campaign, out)
    return campaign, result, load_sortie(out)


@pytest.mark.slow
def test_written_and_loadable_with_boundaries(sortie, capsys):
    campaign, result, s = sortie
    for rel in SORTIE_FILES.values():
        assert (s.path / rel).is_file(), rel
    cid, jobs = sortie_jobs(campaign)
    assert cid == "PV1-NP" and s.manifest["sortie"]["configuration"] == cid
    b = s.boundaries
    assert list(b.columns) == list(BOUNDARY_COLUMNS[1:])
    assert list(b.index) == [maneuver_id(j.index, 0, 1) for j in jobs]
    assert list(b["kind"]) == [j.maneuver["kind"] for j in jobs]
    assert list(b["mach"]) == [j.maneuver["mach"] for j in jobs]
    assert list(b["altitude_m"]) == [j.maneuver["altitude_m"] for j in jobs]
    assert list(b["gear_down"]) == [False, False, False, True]
    assert list(s.transitions["stages"].iloc[-1]) == ["altitude", "mach", "gear", "settle"]
    assert (b["missed"] == "").all(), b["missed"]
    # in flight order, each as long as the maneuver, a transition between neighbours
    assert np.allclose(b["t_end_s"] - b["t_start_s"], 20.0)
    assert (b["t_start_s"].to_numpy()[1:] > b["t_end_s"].to_numpy()[:-1]).all()
    tr = s.transitions
    assert list(tr["to"]) == list(b.index[1:])
    assert np.allclose(tr["t_start_s"], b["t_end_s"].to_numpy()[:-1])
    assert np.allclose(tr["t_end_s"], b["t_start_s"].to_numpy()[1:])
    # the boundaries file says the same
    import pandas as pd

    csv = pd.read_csv(s.path / SORTIE_FILES["boundaries"], keep_default_na=False).set_index("id")
    assert list(csv["kind"]) == list(b["kind"])
    assert np.allclose(csv["t_start_s"], b["t_start_s"])
    # fpr show describes it; the per-maneuver reader says what it is
    assert main(["show", str(s.path)]) == 0
    shown = capsys.readouterr().out
    assert "whole sortie: configuration PV1-NP" in shown and "m0002" in shown
    with pytest.raises(ValueError, match="load_sortie"):
        load_dataset(s.path)


@pytest.mark.slow
def test_streams_are_continuous(sortie):
    _, _, s = sortie
    rate = s.manifest["sortie"]["sample_rate_hz"]
    data = s.load()
    b = s.boundaries
    for name in ("data", "dru", "ins", "dgps"):
        frame = data if name == "data" else s.load(name)
        t = frame["t_s"].to_numpy()
        dt = np.diff(t)
        assert dt.min() > 0 and dt.max() - dt.min() < 1e-9, name  # no gaps, no jumps
        assert t[0] <= b["t_start_s"].iloc[0] + 0.2 and t[-1] >= b["t_end_s"].iloc[-1] - 0.2, name
    assert np.isclose(np.diff(data["t_s"]).mean(), 1.0 / rate)
    # one recorder delay through the sortie: the pitch-rate lag estimated in the first and in the
    # last maneuver (regressing measured - true on the true pitch acceleration) agree
    shift = s.manifest["sortie"]["injected"]["time_shift_s.q_rps"]
    lags = []
    for mid in (b.index[0], b.index[-1]):
        cut = s.cut(mid, data)
        A = np.column_stack([cut["true_qdot_rps2"], np.ones(len(cut))])
        coef = np.linalg.lstsq(A, cut["q_rps"] - cut["true_q_rps"], rcond=None)[0]
        lags.append(-coef[0])
    assert abs(lags[0] - lags[1]) < 0.002, lags
    assert abs(lags[0] - shift) < 0.005, (lags, shift)


@pytest.mark.slow
def test_cut_maneuver_is_at_its_test_point(sortie):
    _, _, s = sortie
    data = s.load()
    # the recorders' lags: the streams start a little after the sortie, end a little before
    t_first, t_last = data["t_s"].iloc[0], data["t_s"].iloc[-1]
    for mid, row in s.boundaries.iterrows():
        spec = ManeuverSpec(kind=row["kind"], mach=row["mach"], altitude_m=row["altitude_m"])
        cut = s.cut(mid, data)
        assert abs(cut["t_s"].iloc[0] - max(row["t_start_s"], t_first)) <= 1.0 / 40 + 1e-9
        assert abs(cut["t_s"].iloc[-1] - min(row["t_end_s"], t_last)) <= 1.0 / 40 + 1e-9
        assert abs(cut["true_mach"].iloc[0] - spec.trim_mach) < 0.005, mid
        assert abs(cut["true_h_m"].iloc[0] - row["altitude_m"]) < 15.0, mid
        assert abs(cut["mach"].mean() - row["mach"]) < 0.02, mid  # measured, as extraction sees it
        assert abs(np.degrees(cut["true_phi_rad"].iloc[0])) < 1.5, mid
        assert (cut["true_gear_pos_norm"] == float(row["gear_down"])).all(), mid
        # a recorder stream cut the same way
        ins = s.cut(mid, "ins")
        assert ins["t_s"].iloc[0] >= row["t_start_s"] - 1e-9 and ins["t_s"].iloc[-1] <= row["t_end_s"] + 1e-9


@pytest.mark.slow
def test_first_maneuver_flies_as_alone(sortie):
    """The sortie starts as a per-maneuver run does (same trim, same controller): its first
    maneuver matches `fly_maneuver`'s up to the fuel it does not burn."""
    campaign, _, s = sortie
    _, jobs = sortie_jobs(campaign)
    spec = ManeuverSpec.from_dict(jobs[0].maneuver)
    fleet = campaign.fleet
    alone = fly_maneuver(spec, fleet.airframe, fleet.configuration("PV1-NP").aircraft,
                         Environment.from_dict(jobs[0].environment))[0]
    cut = s.cut(s.boundaries.index[0])
    alpha = np.interp(cut["t_s"], alone.t_s, alone.alpha_rad)
    assert np.max(np.abs(np.degrees(alpha - cut["true_alpha_cg_rad"]))) < 0.05


@pytest.mark.slow
def test_directory_rules(sortie, tmp_path):
    campaign, _, s = sortie
    with pytest.raises(FileExistsError, match="--overwrite"):
        prepare_sortie_directory(s.path)
    (tmp_path / "mine.txt").write_text("x")
    with pytest.raises(FileExistsError, match="mine.txt"):
        prepare_sortie_directory(tmp_path, overwrite=True)
    assert main(["fly", "--sortie", "NOPE", "--config", "PV1-NP", "--out", str(tmp_path / "n")]) == 2


@pytest.mark.slow
def test_same_campaign_same_bytes(sortie, tmp_path):
    """Flown again (over a copy, with --overwrite), the sortie gives the same files, byte for byte."""
    import shutil

    campaign, _, s = sortie
    again = tmp_path / "again"
    shutil.copytree(s.path, again)
    fly_sortie_campaign(campaign, again, overwrite=True)
    for rel in ("manifest.json", *SORTIE_FILES.values()):
        assert (again / rel).read_bytes() == (s.path / rel).read_bytes(), rel


def test_fly_sortie_command(tmp_path, capsys):
    out = tmp_path / "one"
    assert main(["fly", "--sortie", "--config", "PV1-NP", "--mach", "0.5", "--maneuver",
                 "pitch_doublet", "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "one sortie of configuration PV1-NP, 1 maneuvers" in said and "wrote" in said
    assert list(load_sortie(out).boundaries.index) == ["m0000"]
    assert main(["fly", "--sortie", "--resume", "--out", str(out)]) == 2
    assert "--resume does not apply" in capsys.readouterr().err
