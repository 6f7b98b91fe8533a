"""The workflow fails loudly when a bin's estimation is not a success (issue 10, build item 1).

A small fleet (two aircraft, Mach 0.5 and 0.6, two maneuver kinds: four maneuvers per bin), calm
air, the model-representable local flow. One vane of one maneuver in the Mach 0.6 bin is stuck:
that bin's estimation is a failure, so it is left out of the apportionment and of the later steps,
the workflow's verdict is a failure naming the bin and the stuck vane, `fpr calibrate` exits with
status 1 and report.html opens with the failure. The Mach 0.5 bin is calibrated as usual.
"""

from __future__ import annotations

import shutil

import pandas as pd
import pytest
from _campaigns import linear_campaign

from campaigns.cli import EXIT_STATUS, main
from synth.dataset import load_dataset, write_maneuver

#: a workflow of two Mach bins through the CLI: ~8 s
pytestmark = pytest.mark.slow

CAMPAIGN = linear_campaign("wfverdict", 21, [
    {"configurations": ["PV1-NP", "PV2-NP"], "mach": [0.5, 0.6], "maneuvers": ["pitch_doublet", "3211"],
     "maneuver": {"duration_s": 20.0}, "altitude_m": 6000.0}],
    wind_ned_mps=[5.0, -3.0, 0.0], turbulence="none")


@pytest.fixture(scope="module")
def faulty(fly_once, tmp_path_factory):
    """The fleet's dataset with the left vane of one Mach 0.6 maneuver stuck at its first value."""
    # the flown folder is shared (tests/conftest.py): the fault goes into a copy
    out = tmp_path_factory.mktemp("wfverdict") / "data"
    shutil.copytree(fly_once(CAMPAIGN, "test_workflow_verdict"), out)
    ds = load_dataset(out)
    entry = next(e for e, _ in ds if abs(e["mach_nominal"] - 0.6) < 1e-9)
    df = ds.load(entry["id"])
    # the file rewritten as the synthesizer writes it, its manifest entry kept
    write_maneuver(out / entry["file"], df.assign(alpha_zl_rad=df["alpha_zl_rad"].iloc[0]), entry)
    return out, entry["id"]


def test_a_failed_bin_fails_the_workflow_loudly(faulty, tmp_path, capsys):
    data, stuck_id = faulty
    report = tmp_path / "report"
    # without figures: the verdict, the findings and the tables are the subject (figures: test_outdir)
    code = main(["calibrate", str(data), "--no-plots", "--out", str(report)])
    text = capsys.readouterr().out
    assert code == EXIT_STATUS["FAILURE"] == 1, text
    assert "VERDICT: FAILURE" in text
    # the bin, and why: the stuck vane in its maneuver
    assert "the Mach 0.60 gear-up bin's estimation failed" in text, text
    findings = pd.read_csv(report / "findings.csv")
    stuck = findings[(findings["code"] == "stuck_channel") & (findings["channel"] == "alpha_zl")]
    assert len(stuck) and (stuck["maneuver"] == stuck_id).all(), findings[["code", "channel", "maneuver"]]
    assert (findings["severity"] == "FAILURE").any()
    # the failed bin is not apportioned and not carried on; the good one is
    vb = pd.read_csv(report / "vane_biases.csv")
    assert set(vb["mach"]) == {0.5}
    assert set(pd.read_csv(report / "table2_model.csv")["mach"]) == {0.5}
    # the report opens with the failure, before its table of contents
    html = (report / "report.html").read_text()
    assert html.index('class="verdict failure"') < html.index("<nav>")
