"""A calibrated airspeed scale as autopilot parameters (estimator/autopilot.py, ``fpr autopilot``).

The airspeed channel's model is tas_measured = (1 + k) tas_true, the measured airspeed being what
the autopilot computed in flight with the parameters then in force. The exported parameter must
reproduce the calibrated airspeed from what the autopilot measures: ArduPilot's
sqrt(ARSPD_RATIO * dp) from the logged differential pressure, PX4's ASPD_SCALE times the raw
indicated airspeed. A FAILURE verdict, or a scale factor held or on its bound, writes nothing.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from campaigns.cli import main
from estimator.autopilot import ExportRefused, corrected, from_result, in_force_from_ulog

PX4_LOG = Path(__file__).resolve().parents[3] / "shared" / "data" / "px4" / "sample_log_small.ulg"
RHO = 1.225


def test_the_exported_ratio_reproduces_the_calibrated_airspeed_from_the_differential_pressure():
    rng = np.random.default_rng(7)
    tas_true = rng.uniform(12.0, 25.0, 200)
    k, ratio_old = 0.071, 1.9936
    # the logged airspeed, (1 + k) too high, is sqrt(ratio_old * dp) of the logged pressure
    dp_pa = ((1 + k) * tas_true) ** 2 / ratio_old
    p = corrected("ardupilot", ratio_old, k, 0.004)
    assert np.allclose(np.sqrt(p.value * dp_pa), tas_true, rtol=1e-12)
    # PX4: the indicated airspeed is ASPD_SCALE times the sensor's; the new scale gives the true one
    raw = (1 + k) * tas_true / 1.05
    q = corrected("px4", 1.05, k, 0.004)
    assert np.allclose(q.value * raw, tas_true, rtol=1e-12)


@pytest.mark.parametrize("autopilot", ["px4", "ardupilot"])
def test_the_deviation_is_the_scale_factors_propagated(autopilot):
    k, s, h = 0.05, 0.01, 1e-6
    p = corrected(autopilot, 2.0, k, s)
    slope = (corrected(autopilot, 2.0, k + h, s).value - corrected(autopilot, 2.0, k - h, s).value) / (2 * h)
    assert p.std == pytest.approx(abs(slope) * s, rel=1e-6)


def _result(tmp_path: Path, verdict: str = "SUCCESS", state: str = "estimated") -> Path:
    doc = {"verdict": verdict, "verdict_text": f"{verdict.lower()}: ...",
           "parameters": [{"key": "k_tas", "kind": "scale", "state": state, "reason": "",
                           "value": -0.0614, "std_crb": 0.0007, "std_colored": 0.0105},
                          {"key": "k_a", "kind": "scale", "state": "estimated", "value": 0.1,
                           "std_colored": 0.01}]}
    path = tmp_path / "result.json"
    path.write_text(json.dumps(doc))
    return path


def test_a_result_to_use_gives_its_parameter_with_the_honest_deviation(tmp_path):
    p = from_result(_result(tmp_path), "ardupilot", 2.0, "k_tas")
    assert p.value == pytest.approx(2.0 / (1 - 0.0614) ** 2) and p.k_std == 0.0105


@pytest.mark.parametrize(("verdict", "state", "why"), [("FAILURE", "estimated", "verdict is FAILURE"),
                                                       ("SUCCESS", "on_bound", "k_tas is on_bound"),
                                                       ("SUCCESS", "held", "k_tas is held")])
def test_an_estimate_not_to_use_is_refused_with_the_reason(tmp_path, verdict, state, why):
    with pytest.raises(ExportRefused, match=why):
        from_result(_result(tmp_path, verdict, state), "px4", 1.0, "k_tas")
    with pytest.raises(ExportRefused, match=r"no parameter 'k_ias'.*\['k_a', 'k_tas'\]"):
        from_result(_result(tmp_path), "px4", 1.0, scale_key="k_ias")


def test_fpr_autopilot_writes_the_ground_stations_files_and_refuses_a_failure(tmp_path, capsys):
    res = _result(tmp_path)
    assert main(["autopilot", str(tmp_path), "--autopilot", "px4", "--in-force", "1.0", "--scale", "k_tas",
                 "--out", str(tmp_path / "aspd.params")]) == 0
    text = (tmp_path / "aspd.params").read_text()
    rows = [ln.split("\t") for ln in text.splitlines() if not ln.startswith("#")]
    assert rows == [["1", "1", "ASPD_SCALE_1", f"{1 / (1 - 0.0614):.6f}", "9"]]
    assert main(["autopilot", str(res), "--autopilot", "ardupilot", "--in-force", "2.0", "--scale", "k_tas",
                 "--out", str(tmp_path / "arspd.param")]) == 0
    lines = [ln for ln in (tmp_path / "arspd.param").read_text().splitlines() if not ln.startswith("#")]
    assert lines == [f"ARSPD_RATIO,{2.0 / (1 - 0.0614) ** 2:.6f}"]
    assert main(["autopilot", str(res), "--autopilot", "ardupilot", "--in-force", "2.0", "--scale", "k_tas",
                 "--out", str(tmp_path / "arspd.param")]) == 2, "an existing file is never replaced"
    _result(tmp_path, "FAILURE")
    capsys.readouterr()
    assert main(["autopilot", str(res), "--autopilot", "px4", "--in-force", "1.0", "--scale", "k_tas",
                 "--out", str(tmp_path / "bad.params")]) == 1
    assert "refused" in capsys.readouterr().err and not (tmp_path / "bad.params").exists()


@pytest.mark.skipif(not PX4_LOG.is_file(), reason="../shared/data/px4 absent")
def test_the_value_in_force_is_read_from_a_px4_log():
    assert in_force_from_ulog(PX4_LOG, "ASPD_SCALE") == 1.0
    with pytest.raises(ValueError, match="no parameter 'ASPD_SCALE_9'"):
        in_force_from_ulog(PX4_LOG, "ASPD_SCALE_9")
