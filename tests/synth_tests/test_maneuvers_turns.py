"""Wind-up turns as a test pilot flies them: coordinated (sideslip held near zero with rudder),
winding up in bank and load factor at constant Mach and about constant altitude, to the alpha the
f16's FCS allows (high-alpha turns at low dynamic pressure); the alpha they cover shows in
`fpr show`."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from aircraft_models import load_fleet
from campaigns.cli import main
from synth.campaign import load_campaign
from synth.dataset import alpha_coverage, load_dataset
from synth.environment import Environment
from synth.flight import FlightError, fly_maneuver
from synth.maneuvers import ManeuverSpec

DEG = math.pi / 180.0
FLEET = load_fleet()
#: the default campaign's air: steady wind, calm
CAMPAIGN_AIR = Environment(planet="flat", wind_ned_mps=(6.0, -4.0, 0.0), turbulence="none")
#: a coordinated turn: the sideslip a test pilot holds with the rudder
MAX_COORDINATED_BETA_RAD = 0.5 * DEG
#: altitude held within this (the uncoordinated turn climbed 250-400 m)
MAX_ALTITUDE_DRIFT_M = 150.0


def _quarter_means(values: np.ndarray) -> list[float]:
    n = len(values)
    return [float(values[i * n // 4:(i + 1) * n // 4].mean()) for i in range(4)]


@pytest.mark.parametrize("aircraft, mach, altitude_m", [
    ("PV1", 0.3, 3000.0),   # low Mach: alpha binds (the default campaign's low-Mach block)
    ("PV2", 0.6, 6000.0),
    ("PT1", 0.9, 8000.0),   # high Mach, forward CG: load factor binds
])
def test_windup_turn_is_coordinated_and_winds_up(aircraft, mach, altitude_m):
    (tr,) = fly_maneuver(ManeuverSpec(kind="windup_turn", mach=mach, altitude_m=altitude_m),
                         FLEET.airframe, FLEET.aircraft[aircraft], CAMPAIGN_AIR)
    assert np.max(np.abs(tr.beta_rad)) <= MAX_COORDINATED_BETA_RAD, (
        f"|beta| up to {np.degrees(np.max(np.abs(tr.beta_rad))):.2f} deg")
    # the rudder does it (the f16's yaw damper is removed in the generated model)
    assert np.max(np.abs(tr.controls["rudder_cmd_norm"])) > 0.1
    # winding up: bank and load factor rise quarter by quarter, alpha is swept from trim
    nz = -tr.specific_force_cg_body_mps2[:, 2] / tr.g_mps2
    bank = np.abs(tr.euler_rad[:, 0])
    for name, series in (("load factor", nz), ("bank", bank)):
        q = _quarter_means(series)
        assert all(b > a for a, b in zip(q, q[1:], strict=False)), f"{name} quarter means {q}"
    assert np.degrees(bank[-1]) > 40.0
    assert np.ptp(tr.alpha_rad) >= 4.0 * DEG
    # constant Mach, about constant altitude
    assert np.max(np.abs(tr.mach - mach)) <= 0.05
    assert np.max(np.abs(tr.h_m - tr.h_m[0])) <= MAX_ALTITUDE_DRIFT_M


#: the default campaign's high-alpha turns (campaigns/default.toml): target, Mach, altitude
HIGH_ALPHA_DEG = 22.0
HIGH_ALPHA_POINTS = [(0.3, 5500.0), (0.4, 9500.0)]
#: issue 13: the high-alpha turn reaches at least this at Mach 0.3 and 0.4 (the paper's Tejas
#: calibration went well past 20 deg at low Mach)
REQUIRED_PEAK_ALPHA_RAD = 20.0 * DEG
#: the f16's limits (its FCS limits load factor to 9 g; the real F-16's alpha limiter, 25 deg)
F16_NZ_LIMIT = 9.0
F16_ALPHA_LIMIT_RAD = 25.0 * DEG


@pytest.mark.parametrize("mach, altitude_m", HIGH_ALPHA_POINTS)
@pytest.mark.parametrize("aircraft", ["PV3", "PT1"])  # CG furthest aft / forward
def test_high_alpha_windup_turn(aircraft, mach, altitude_m):
    spec = ManeuverSpec.from_dict({"kind": "windup_turn", "mach": mach, "altitude_m": altitude_m,
                                   "alpha_max_deg": HIGH_ALPHA_DEG})
    (tr,) = fly_maneuver(spec, FLEET.airframe, FLEET.aircraft[aircraft], CAMPAIGN_AIR)
    notes = tr.meta["controller"]
    peak_rad = float(np.max(tr.alpha_rad))
    # the target itself, with command to spare (forward CG too), within the f16's limits
    assert peak_rad >= (HIGH_ALPHA_DEG - 0.1) * DEG and not notes["aft_stop"]
    assert peak_rad >= REQUIRED_PEAK_ALPHA_RAD
    assert peak_rad < F16_ALPHA_LIMIT_RAD
    nz = -tr.specific_force_cg_body_mps2[:, 2] / tr.g_mps2
    assert nz.max() < F16_NZ_LIMIT
    assert np.max(np.abs(tr.beta_rad)) <= MAX_COORDINATED_BETA_RAD
    assert np.max(np.abs(tr.mach - mach)) <= 0.05
    assert np.max(np.abs(tr.h_m - tr.h_m[0])) <= 200.0  # climbs about 100 m
    assert np.ptp(tr.alpha_rad) >= 2.0 * DEG


def test_windup_turn_beyond_the_fcs_limit_fails():
    """The generated f16's FCS still caps alpha (synth.maneuvers.WindupTurn): PT1 (forward CG)
    at Mach 0.3, 3000 m stops near 21 deg of a 25 deg target; the failure says the command was
    at its stop."""
    spec = ManeuverSpec.from_dict({"kind": "windup_turn", "mach": 0.3, "altitude_m": 3000.0,
                                   "alpha_max_deg": 25.0})
    with pytest.raises(FlightError, match="reached neither alpha 25.0 deg .*aft stop"):
        fly_maneuver(spec, FLEET.airframe, FLEET.aircraft["PT1"], CAMPAIGN_AIR)


def test_forward_cg_windup_ends_at_the_fcs_limit():
    """PT1 (forward CG) at Mach 0.3, 5500 m asked for 23.5 deg: the FCS stops the wind-up 1-2 deg
    short with the command at its stop; that ends it, as it does a test pilot's."""
    spec = ManeuverSpec.from_dict({"kind": "windup_turn", "mach": 0.3, "altitude_m": 5500.0,
                                   "alpha_max_deg": 23.5})
    (tr,) = fly_maneuver(spec, FLEET.airframe, FLEET.aircraft["PT1"], CAMPAIGN_AIR)
    spec, notes = tr.meta["maneuver"], tr.meta["controller"]
    assert notes["aft_stop"]
    assert (spec["alpha_max_rad"] - 2.0 * DEG <= notes["alpha_peak_rad"]
            < spec["alpha_max_rad"] - 1.0 * DEG)


def test_default_campaign_flies_a_windup_turn_at_every_clean_mach():
    camp = load_campaign("default")
    flown = {(j.configuration_id, j.maneuver["mach"]) for j in camp.jobs
             if j.maneuver["kind"] == "windup_turn" and not j.maneuver.get("gear_down")}
    machs = sorted({m for _, m in flown})
    assert machs == [0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9]
    assert len(flown) == len(FLEET.configurations) * len(machs)
    high = {(j.configuration_id, j.maneuver["mach"], j.maneuver["altitude_m"]) for j in camp.jobs
            if j.maneuver.get("alpha_max_deg") == HIGH_ALPHA_DEG}
    assert high == {(c, m, h) for c in FLEET.configurations for m, h in HIGH_ALPHA_POINTS}
    demo = load_campaign("demo")
    assert {(j.configuration_id, j.maneuver["mach"]) for j in demo.jobs
            if j.maneuver.get("alpha_max_deg") == HIGH_ALPHA_DEG} == {
        (c, 0.5) for c in FLEET.configurations}


@pytest.mark.slow
def test_fpr_show_prints_the_alpha_coverage_per_mach(tmp_path, capsys):
    out = tmp_path / "ds"
    assert main(["fly", "--config", "PV1-NP", "--mach", "0.3", "0.4", "--maneuver", "windup_turn",
                 "pitch_doublet", "--altitude-m", "3000", "--out", str(out), "--workers", "1"]) == 0
    capsys.readouterr()
    assert main(["show", str(out)]) == 0
    text = capsys.readouterr().out
    head = "true angle of attack at the CG per nominal Mach, deg:"
    assert head in text
    rows = text.split(head, 1)[1].strip().splitlines()[2:]  # after the column and index headers
    printed = {float(r.split()[0]): [float(v) for v in r.split()[1:]] for r in rows}
    # against the truth in the parquet files
    ds = load_dataset(out)
    truth: dict[float, list[np.ndarray]] = {}
    for entry, df in ds:
        truth.setdefault(entry["mach_nominal"], []).append(np.degrees(df["true_alpha_cg_rad"]))
    assert sorted(printed) == sorted(truth) == [0.3, 0.4]
    for mach, alphas in truth.items():
        a = np.concatenate(alphas)
        n, lo, hi = printed[mach]
        assert n == len(alphas) == 2
        assert lo == pytest.approx(a.min(), abs=0.006) and hi == pytest.approx(a.max(), abs=0.006)
        # the wind-up turn takes each Mach well past the doublet's few degrees
        assert hi - lo > 4.0
    cov = alpha_coverage(ds)
    assert isinstance(cov, pd.DataFrame) and list(cov.index) == [0.3, 0.4]
    assert cov.loc[0.4, "alpha_max_deg"] == pytest.approx(
        max(np.degrees(df["true_alpha_cg_rad"]).max() for e, df in ds if e["mach_nominal"] == 0.4))
