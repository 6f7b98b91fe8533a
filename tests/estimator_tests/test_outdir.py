"""Output folders are only ever cleared of what fpr itself wrote (issue 11).

``fpr calibrate`` (the workflow report and ``--single``) and the report folder of ``fpr demo`` keep a
listing of what they wrote (``.fpr-written.json``: path, size, SHA-256 per file); ``--overwrite``
removes exactly those files. A user's summary, plot, notes or backup in a results folder, a listed
file the user has since edited, and the run's own input file are never removed: the command refuses
(exit status 2) and names them.

The CLI tests run on the shared tiny campaign (tests/_campaigns.py: two aircraft, Mach 0.6, a pitch
doublet and a 3211 of 10 s each, one Mach bin of four maneuvers), flown once per session; an earlier
run's report is made once and copied into each test's folder.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pandas as pd
import pytest
from _campaigns import TINY_CAMPAIGN, linear_campaign

from campaigns.benchmarks.user_files import problem_text
from campaigns.cli import main
from estimator.io.outdir import LISTING_NAME, OutputFolderError, check_output, prepare_output
from synth.campaign import parse_campaign
from synth.dataset import load_dataset

# --------------------------------------------------------------------------------------------------
# fixtures


@pytest.fixture(scope="module")
def dataset(tiny_dataset) -> Path:
    """The shared tiny campaign (tests/_campaigns.py), flown once per session; never edited here."""
    return tiny_dataset


@pytest.fixture(scope="module")
def earlier_report(dataset, tmp_path_factory) -> Path:
    """An earlier workflow run's report folder (full run: every writer of the report)."""
    out = tmp_path_factory.mktemp("earlier") / "report"
    assert main(["calibrate", str(dataset), "--out", str(out), "--no-colored"]) in (0, 1, 3)
    return out


@pytest.fixture(scope="module")
def earlier_single(dataset, tmp_path_factory) -> Path:
    """An earlier ``--single`` run's folder, figures included."""
    out = tmp_path_factory.mktemp("earlier") / "single"
    assert main(["calibrate", str(dataset), "--single", "--out", str(out), "--no-colored",
                 "--max-iterations", "8"]) in (0, 1, 3)
    return out


def _copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _listed(folder: Path) -> dict:
    return {e["path"]: e for e in json.loads((folder / LISTING_NAME).read_text())["files"]}


def _assert_listing_is_the_folder(folder: Path) -> None:
    """Every file in the folder is in its listing, with its size (nothing written goes unlisted)."""
    listed = _listed(folder)
    present = {p.name for p in folder.iterdir()} - {LISTING_NAME}
    assert set(listed) == present, (sorted(set(listed) ^ present))
    for name, e in listed.items():
        assert e["size"] == (folder / name).stat().st_size and len(e["sha256"]) == 64, name


def _user_csv_problem(dataset: Path, folder: Path, problem_dir: Path) -> tuple[Path, Path]:
    """A problem file (in ``problem_dir``) reading one maneuver from a CSV that lies in ``folder``."""
    ds = load_dataset(dataset)
    entry, df = next(iter(ds))
    cols = {"t": ("t_s", "s"), "ax": ("ax_imu_mps2", "m/s^2"), "ay": ("ay_imu_mps2", "m/s^2"),
            "az": ("az_imu_mps2", "m/s^2"), "p": ("p_rps", "rad/s"), "q": ("q_rps", "rad/s"),
            "r": ("r_rps", "rad/s"), "phi": ("phi_rad", "rad"), "theta": ("theta_rad", "rad"),
            "psi": ("psi_rad", "rad"), "tas": ("tas_mps", "m/s"), "h": ("h_baro_m", "m"),
            "alpha_zl": ("alpha_zl_rad", "rad"), "alpha_zr": ("alpha_zr_rad", "rad")}
    csv = folder / "flight.csv"
    df[[c for c, _ in cols.values()]].to_csv(csv, index=False)
    pos = ds.manifest["airframe"]["positions_body_m"]
    problem = problem_dir / "problem.toml"
    problem.write_text(problem_text(["phi", "theta", "psi", "tas", "h", "alpha_zl", "alpha_zr"],
                                    {k: pos[k] for k in ("imu", "vane_left", "vane_right")},
                                    entry["r_cg_body_m_mean"], cols, f'path = "{csv.as_posix()}"',
                                    model=None))
    return problem, csv


# --------------------------------------------------------------------------------------------------
# fpr calibrate: the workflow report


@pytest.mark.slow
def test_every_file_a_report_writes_is_listed(earlier_report, earlier_single):
    _assert_listing_is_the_folder(earlier_report)
    _assert_listing_is_the_folder(earlier_single)
    assert {"report.html", "table2_model.csv", "recovery.csv"} <= set(_listed(earlier_report))
    assert {"result.json", "recovery.csv", "time_history_match.png"} <= set(_listed(earlier_single))


@pytest.mark.slow
@pytest.mark.parametrize("user_files", [("summary.csv", "plot.png", "backup.csv"), ("notes.txt",)])
def test_overwrite_refuses_a_report_folder_holding_user_files(dataset, earlier_report, tmp_path, capsys,
                                                              user_files):
    out = _copy(earlier_report, tmp_path / "results")
    for name in user_files:
        (out / name).write_bytes(b"the user's own " + name.encode())
    before = _snapshot(out)
    assert main(["calibrate", str(dataset), "--out", str(out), "--overwrite"]) == 2
    err = capsys.readouterr().err
    for name in user_files:
        assert name in err, err
    assert "choose another --out" in err and "move those files" in err, err
    assert _snapshot(out) == before  # the user's files, and the earlier report, untouched


@pytest.mark.slow
def test_an_input_file_inside_the_results_folder_survives(dataset, earlier_report, tmp_path, capsys):
    out = _copy(earlier_report, tmp_path / "results")
    problem, csv = _user_csv_problem(dataset, out, tmp_path)
    data = csv.read_bytes()
    assert main(["calibrate", str(problem), "--out", str(out), "--overwrite"]) == 2
    err = capsys.readouterr().err
    assert "flight.csv (an input of this run)" in err, err
    assert csv.read_bytes() == data
    assert (out / "report.html").exists()


@pytest.mark.slow
def test_an_earlier_report_is_refused_without_overwrite_and_replaced_with_it(dataset, earlier_report,
                                                                            tmp_path, capsys):
    out = _copy(earlier_report, tmp_path / "results")
    before = _snapshot(out)
    assert main(["calibrate", str(dataset), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "holds the results of an earlier run" in err and "fpr calibrate" in err, err
    assert "pass --overwrite" in err, err
    assert _snapshot(out) == before
    # a short run (stopped after 3 iterations: a failure verdict, a report of the summary only)
    # replaces the whole earlier report: no stale table survives beside the new one
    assert main(["calibrate", str(dataset), "--out", str(out), "--overwrite", "--no-colored",
                 "--max-iterations", "3"]) in (0, 1, 3)
    assert (out / "report.html").read_bytes() != before["report.html"]
    assert not (out / "table2_model.csv").exists(), "a stale table of the earlier run survived"
    _assert_listing_is_the_folder(out)


@pytest.mark.slow
def test_a_report_file_the_user_edited_is_refused_not_deleted(dataset, earlier_report, tmp_path, capsys):
    out = _copy(earlier_report, tmp_path / "results")
    with open(out / "findings.csv", "a") as fh:
        fh.write("my own note\n")
    before = _snapshot(out)
    assert main(["calibrate", str(dataset), "--out", str(out), "--overwrite"]) == 2
    err = capsys.readouterr().err
    assert "findings.csv (changed since fpr calibrate wrote it)" in err, err
    assert _snapshot(out) == before


def test_out_naming_the_input_dataset_is_refused(dataset, capsys):
    before = _snapshot(dataset)
    assert main(["calibrate", str(dataset), "--out", str(dataset), "--overwrite"]) == 2
    assert "is an input of this run" in capsys.readouterr().err
    assert _snapshot(dataset) == before


# --------------------------------------------------------------------------------------------------
# fpr calibrate --single


@pytest.mark.slow
def test_single_overwrite_refuses_user_files_and_edited_files(dataset, earlier_single, tmp_path, capsys):
    out = _copy(earlier_single, tmp_path / "single")
    (out / "summary.csv").write_text("mine\n")
    (out / "plot.png").write_bytes(b"\x89PNG mine")
    with open(out / "parameters.csv", "a") as fh:
        fh.write("edited,by,hand\n")
    before = _snapshot(out)
    args = ["calibrate", str(dataset), "--single", "--out", str(out), "--overwrite", "--no-plots"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "summary.csv" in err and "plot.png" in err, err
    assert "parameters.csv (changed since fpr calibrate --single wrote it)" in err, err
    assert _snapshot(out) == before


@pytest.mark.slow
def test_single_input_file_inside_the_results_folder_survives(dataset, earlier_single, tmp_path, capsys):
    out = _copy(earlier_single, tmp_path / "single")
    problem, csv = _user_csv_problem(dataset, out, tmp_path)
    data = csv.read_bytes()
    assert main(["calibrate", str(problem), "--single", "--out", str(out), "--overwrite"]) == 2
    assert "flight.csv (an input of this run)" in capsys.readouterr().err
    assert csv.read_bytes() == data


@pytest.mark.slow
def test_single_earlier_results_refused_without_overwrite_and_replaced_with_it(dataset, earlier_single,
                                                                              tmp_path, capsys):
    out = _copy(earlier_single, tmp_path / "single")
    before = _snapshot(out)
    args = ["calibrate", str(dataset), "--single", "--out", str(out), "--no-plots", "--no-colored",
            "--max-iterations", "3"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "holds the results of an earlier run" in err and "fpr calibrate --single" in err, err
    assert _snapshot(out) == before
    assert main([*args, "--overwrite"]) in (0, 1, 3)
    assert not (out / "time_history_match.png").exists(), "a stale figure survived"
    assert pd.read_csv(out / "parameters.csv").shape[0] > 0
    _assert_listing_is_the_folder(out)


# --------------------------------------------------------------------------------------------------
# fpr demo: its report folder


#: The light-turbulence block of the tiny demo: one aircraft, the three maneuvers a Mach bin needs
#: (its report folder is written and listed as the calm block's; what it finds is not the subject)
TINY_TURBULENT = linear_campaign("tiny-turbulence", 12, [
    {"configurations": ["PV1-NP"], "mach": [0.6], "maneuvers": ["pitch_doublet", "3211", "pullup_pushover"],
     "maneuver": {"duration_s": 10.0}, "altitude_m": 6000.0}], turbulence="light")


@pytest.fixture
def tiny_demo(monkeypatch):
    """``fpr demo`` flying the small fleet (and a smaller turbulent block) instead of the demo
    campaigns (minutes)."""
    import synth.campaign

    campaigns = {"demo": parse_campaign(TINY_CAMPAIGN, source="tiny demo"),
                 "demo_turbulence": parse_campaign(TINY_TURBULENT, source="tiny demo, turbulent block")}
    monkeypatch.setattr(synth.campaign, "load_campaign", lambda name: campaigns[name])


@pytest.mark.slow
def test_demo_refuses_a_report_folder_holding_user_files_before_flying(tiny_demo, earlier_report,
                                                                       tmp_path, capsys):
    data = tmp_path / "demo"
    report = _copy(earlier_report, tmp_path / "demo-report")
    (report / "summary.csv").write_text("mine\n")
    (report / "my_notes.txt").write_text("keep me\n")
    before = _snapshot(report)
    assert main(["demo", "--out", str(data), "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert "summary.csv" in err and "my_notes.txt" in err, err
    assert _snapshot(report) == before
    assert not data.exists(), "the campaign was flown before the report folder was checked"


@pytest.mark.slow
def test_demo_replaces_its_own_earlier_report(tiny_demo, earlier_report, tmp_path, capsys):
    """With two workers the light-turbulence block runs beside the calm one, in a worker process
    (given the campaign it was handed, not the shipped one): its report is written and listed, and
    its console text comes after the calm block's, whole."""
    data = tmp_path / "demo"
    report = _copy(earlier_report, tmp_path / "demo-report")
    assert main(["demo", "--out", str(data), "--workers", "2"]) in (0, 1, 3)
    out = capsys.readouterr().out
    for folder in (report, tmp_path / "demo-turbulence-report"):
        doc = json.loads((folder / LISTING_NAME).read_text())
        assert doc["tool"] == "fpr demo" and doc["finished_utc"]
        _assert_listing_is_the_folder(folder)
    assert len(list((tmp_path / "demo-turbulence" / "maneuvers").glob("*.parquet"))) == 3
    calm = out.index(f"report: {report}")
    turbulent = out.index("fpr demo: the light-turbulence block: 3 maneuvers")
    assert calm < turbulent < out.index(f"report: {tmp_path / 'demo-turbulence-report'}") < out.index(
        "s in all"), out


# --------------------------------------------------------------------------------------------------
# the module's rules, directly


def _run(folder: Path, names=("a.csv", "b.png"), overwrite=False, tool="fpr test") -> list[Path]:
    with prepare_output(folder, overwrite=overwrite, tool=tool) as out:
        paths = [out.record(folder / n) for n in names]
        for p in paths:
            p.write_text(f"written by the tool: {p.name}\n")
    return paths


def test_a_new_folder_is_created_and_listed(tmp_path):
    out = tmp_path / "deep" / "new"
    _run(out, names=("a.csv", "sub/b.csv"))
    doc = json.loads((out / LISTING_NAME).read_text())
    assert doc["directories"] == ["sub"] and [e["path"] for e in doc["files"]] == ["a.csv", "sub/b.csv"]
    _run(out, names=("c.csv",), overwrite=True)  # the earlier files and the folder it made: gone
    assert sorted(p.name for p in out.iterdir()) == [LISTING_NAME, "c.csv"]


def test_refusal_names_at_most_ten_and_counts_the_rest(tmp_path):
    _run(tmp_path / "o")
    for i in range(15):
        (tmp_path / "o" / f"user{i:02d}.txt").write_text("mine")
    with pytest.raises(OutputFolderError, match=r"user09\.txt and 5 more") as exc:
        prepare_output(tmp_path / "o", overwrite=True, tool="fpr test")
    assert "user10.txt" not in str(exc.value)
    assert len(list((tmp_path / "o").iterdir())) == 15 + 3


def test_a_subfolder_and_a_file_inside_a_listed_folder_are_the_users(tmp_path):
    out = tmp_path / "o"
    _run(out, names=("sub/a.csv",))
    (out / "sub" / "mine.txt").write_text("mine")
    (out / "other").mkdir()
    with pytest.raises(OutputFolderError, match=r"other/.*sub/mine\.txt|sub/mine\.txt.*other/"):
        prepare_output(out, overwrite=True, tool="fpr test")
    assert (out / "sub" / "a.csv").exists() and (out / "sub" / "mine.txt").exists()


def test_a_listed_name_that_became_a_link_is_not_followed(tmp_path):
    out = tmp_path / "o"
    _run(out)
    precious = tmp_path / "precious.csv"
    precious.write_text("elsewhere")
    (out / "a.csv").unlink()
    (out / "a.csv").symlink_to(precious)
    with pytest.raises(OutputFolderError, match=r"a\.csv \(replaced by a link"):
        prepare_output(out, overwrite=True, tool="fpr test")
    assert precious.read_text() == "elsewhere" and (out / "a.csv").is_symlink()


def test_a_run_that_raised_leaves_a_listing_the_next_overwrite_cleans(tmp_path):
    out = tmp_path / "o"
    with pytest.raises(RuntimeError), prepare_output(out, overwrite=False, tool="fpr test") as f:
        f.record(out / "half.csv").write_text("half")
        raise RuntimeError("crash")
    with pytest.raises(OutputFolderError, match="stopped before it finished.*pass --overwrite"):
        check_output(out, overwrite=False)
    _run(out, names=("new.csv",), overwrite=True)
    assert not (out / "half.csv").exists()


def test_a_killed_run_listed_its_files_before_writing_them(tmp_path):
    out = tmp_path / "o"
    f = prepare_output(out, overwrite=False, tool="fpr test")
    f.record(out / "a.csv").write_text("partial")  # killed here: close() never runs
    f.record(out / "sub/b.csv").write_text("partial")
    prepare_output(out, overwrite=True, tool="fpr test").close()
    assert sorted(p.name for p in out.iterdir()) == []


def test_an_unhashed_entry_in_a_finished_listing_is_not_the_tools(tmp_path):
    # a hand-edited (or foreign) listing naming a user's file without size and hash must not get
    # it removed: only a run killed while writing leaves such an entry
    import json
    import os

    out = tmp_path / "o"
    _run(out)
    (out / "mynotes.txt").write_text("mine")
    doc = json.loads((out / LISTING_NAME).read_text())
    doc["files"].append({"path": "mynotes.txt", "size": None, "sha256": None})
    (out / LISTING_NAME).write_text(json.dumps(doc))
    with pytest.raises(OutputFolderError, match=r"mynotes\.txt \(listed without size and hash"):
        prepare_output(out, overwrite=True, tool="fpr test")
    assert (out / "mynotes.txt").read_text() == "mine"
    # ... nor in an unfinished one when the file is older than that run
    doc["finished_utc"] = None
    (out / LISTING_NAME).write_text(json.dumps(doc))
    os.utime(out / "mynotes.txt", (0, 0))
    with pytest.raises(OutputFolderError, match=r"mynotes\.txt \(listed without size and hash"):
        prepare_output(out, overwrite=True, tool="fpr test")
    assert (out / "mynotes.txt").read_text() == "mine"


def test_inputs_are_never_removed(tmp_path):
    out = tmp_path / "o"
    (a, _) = _run(out)
    with pytest.raises(OutputFolderError, match=r"a\.csv is an input of this run"):
        prepare_output(out, overwrite=True, tool="fpr test", protect=[a])
    assert a.exists()
    with pytest.raises(OutputFolderError, match="is an input of this run"):
        prepare_output(tmp_path, overwrite=True, tool="fpr test", protect=[tmp_path])


def test_an_unreadable_listing_trusts_nothing(tmp_path):
    out = tmp_path / "o"
    _run(out)
    (out / LISTING_NAME).write_text("{ not json")
    with pytest.raises(OutputFolderError, match=r"did not write: .*a\.csv.*cannot be read"):
        prepare_output(out, overwrite=True, tool="fpr test")
    assert (out / "a.csv").exists()


def test_a_file_at_out_is_refused(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(OutputFolderError, match="is not a folder"):
        prepare_output(tmp_path / "f", overwrite=True, tool="fpr test")


def test_a_run_that_wrote_nothing_leaves_nothing(tmp_path):
    out = tmp_path / "o"
    prepare_output(out, overwrite=False, tool="fpr test").close()
    assert not out.exists()
    empty = tmp_path / "empty"
    empty.mkdir()
    prepare_output(empty, overwrite=False, tool="fpr test").close()
    assert empty.exists() and not any(empty.iterdir())
