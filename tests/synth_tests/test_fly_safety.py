"""`fpr fly` keeps the user's files, says whether a dataset is complete, resumes an interrupted one
to the same bytes, and leaves no worker behind (issue 11)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from _processes import HAVE_PROC, descendants, left_after, patched_on_import_env, reap, sigint_default

from campaigns.cli import main
from estimator.io.errors import DataError
from estimator.io.fprdataset import read_manifest
from synth.campaign import fly_campaign, load_campaign, parse_campaign
from synth.dataset import MANIFEST, IncompleteDatasetError, load_dataset, prepare_directory, write_manifest

REPO = Path(__file__).resolve().parents[2]

#: one short maneuver per job, three jobs: in the killed run the first is written by a worker held
#: before its result reaches the run, the second held halfway through its write, the third not
#: started (:data:`_HOLD_WRITES`); the resume flies the last two
KILL_CAMPAIGN = """\
name = "kill-test"
seed = 17
[errors]
preset = "typical"
[[flights]]
configurations = ["PV1-NP"]
mach = [0.45, 0.55, 0.65]
maneuvers = ["pitch_doublet"]
[flights.maneuver]
duration_s = 10.0
"""

TINY = {
    "name": "tiny",
    "seed": 3,
    "errors": {"preset": "typical"},
    "flights": [{"configurations": ["PV1-NP", "PT1-BOOM"], "mach": [0.6], "maneuvers": ["pitch_doublet"],
                 "maneuver": {"duration_s": 10.0}}],
}


def _files(directory: Path) -> dict[str, bytes]:
    return {p.relative_to(directory).as_posix(): p.read_bytes()
            for p in sorted(directory.rglob("*")) if p.is_file()}


def _fly_tiny(out: Path, raw: dict = TINY, **kw):
    res = fly_campaign(parse_campaign(raw, source="tiny"), out, workers=1, **kw)
    assert res.ok, res.failures
    return res


# ------------------------------------------------------------------------- the user's files
def test_fly_overwrite_keeps_user_files_and_lists_them(tmp_path, capsys):
    out = tmp_path / "ds"
    _fly_tiny(out)
    before = _files(out)
    (out / "my_notes.txt").write_text("flight 421: left vane sticky")
    (out / "maneuvers" / "backup.csv").write_text("t,alpha\n0,1\n")
    code = main(["fly", "--config", "PV1-NP", "--mach", "0.6", "--maneuver", "pitch_doublet",
                 "--out", str(out), "--overwrite", "--workers", "1"])
    err = capsys.readouterr().err
    assert code == 2
    assert "my_notes.txt" in err and "maneuvers/backup.csv" in err and "Traceback" not in err
    assert (out / "my_notes.txt").read_text() == "flight 421: left vane sticky"
    assert (out / "maneuvers" / "backup.csv").exists()
    # refused before anything was removed: the dataset is untouched too
    assert {k: v for k, v in _files(out).items() if k in before} == before


def test_overwrite_removes_exactly_the_datasets_own_files(tmp_path):
    out = tmp_path / "ds"
    _fly_tiny(out)  # two jobs: m0000, m0001
    (out / "maneuvers" / ".m0001.parquet.k2j_x9.tmp").write_bytes(b"half a file")  # a killed write
    one_job = {**TINY, "flights": [{**TINY["flights"][0], "configurations": ["PV1-NP"]}]}
    _fly_tiny(out, one_job, overwrite=True)
    assert sorted(_files(out)) == sorted([MANIFEST, "maneuvers/m0000.parquet"]), "stale files left"
    # a file of the tool's name pattern that the manifest does not list is the user's
    (out / "maneuvers" / "m0007.parquet").write_bytes(b"mine")
    with pytest.raises(FileExistsError, match="maneuvers/m0007.parquet"):
        prepare_directory(out, overwrite=True)
    assert (out / "maneuvers" / "m0007.parquet").read_bytes() == b"mine"


def test_demo_replaces_only_its_own_dataset(tmp_path, monkeypatch, capsys):
    import campaigns.cli as cli
    import synth.campaign

    # the demo campaign shrunk to two maneuvers, no calibration: only the dataset part is tested
    monkeypatch.setattr(synth.campaign, "load_campaign", lambda name: parse_campaign(TINY, source="tiny"))
    monkeypatch.setattr(cli, "_workflow", lambda *a, **k: 0)
    out = tmp_path / "demo"
    _fly_tiny(out)  # an earlier demo's dataset ...
    before = _files(out)
    (out / "my_notes.txt").write_text("keep me")  # ... beside which the user put a file
    code = main(["demo", "--out", str(out), "--workers", "1"])
    err = capsys.readouterr().err
    assert code == 2 and "my_notes.txt" in err and "Traceback" not in err
    assert (out / "my_notes.txt").read_text() == "keep me"
    assert {k: v for k, v in _files(out).items() if k != "my_notes.txt"} == before
    # the library call the demo makes refuses the same way
    with pytest.raises(FileExistsError, match="my_notes.txt"):
        fly_campaign(parse_campaign(TINY, source="tiny"), out, workers=1, overwrite=True)
    # without the user's file, the demo replaces its own dataset
    (out / "my_notes.txt").unlink()
    (out / "maneuvers" / "m0001.parquet").unlink()
    assert main(["demo", "--out", str(out), "--workers", "1"]) == 0
    assert _files(out) == before


def test_demo_refuses_a_turbulent_dataset_folder_holding_user_files_before_flying(tmp_path, capsys):
    """Every folder the demo writes is checked before anything is flown or removed: a user's file
    in the light-turbulence block's dataset folder is named at once, the calm block not flown."""
    out = tmp_path / "demo"
    turbulent = tmp_path / "demo-turbulence"
    turbulent.mkdir()
    (turbulent / "my_notes.txt").write_text("keep me")
    code = main(["demo", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and "my_notes.txt" in err and "Traceback" not in err, err
    assert not out.exists(), "the calm block was flown before the turbulent folder was checked"
    assert [p.name for p in turbulent.iterdir()] == ["my_notes.txt"]


def test_an_error_in_the_demos_turbulent_block_ends_that_block_said_not_the_demo(tmp_path, capsys,
                                                                                 monkeypatch):
    """The light-turbulence block beside the calm one returns what went wrong as its text: an input
    error as the command line says one (status 2), anything else with its traceback (1)."""
    import campaigns.cli as cli

    code, text, errors = cli._turbulent_block({"flights": "not a list"}, "bad.toml", tmp_path / "d",
                                              tmp_path / "r")
    assert code == 2 and errors.startswith("fpr demo: error: ") and "bad.toml" in errors, errors
    assert not (tmp_path / "d").exists()

    def broken(*args, **kwargs):
        print("flying")
        raise RuntimeError("a bug")

    monkeypatch.setattr(cli, "_turbulent_run", broken)
    shipped = load_campaign("demo_turbulence")
    code, text, errors = cli._turbulent_block(shipped.raw, shipped.source, tmp_path / "d", tmp_path / "r")
    assert code == 1 and text == "flying\n" and "RuntimeError: a bug" in errors
    assert "the light-turbulence block failed" in errors and "Traceback" in errors
    assert capsys.readouterr() == ("", "")  # all of it returned, nothing printed


def test_out_naming_a_file_is_a_clear_error(tmp_path, capsys):
    target = tmp_path / "flight.csv"
    target.write_text("t,alpha\n0,1\n")
    code = main(["fly", "--maneuver", "all", "--config", "all", "--out", str(target)])
    err = capsys.readouterr().err
    assert code == 2
    assert "is a file" in err and str(target) in err and "Traceback" not in err
    assert target.read_text() == "t,alpha\n0,1\n"


# ------------------------------------------------------------------------------------ flags
def test_maneuver_all_and_config_all_are_accepted():
    from campaigns.cli import build_parser
    from synth.campaign import flags_campaign
    from synth.maneuvers import MANEUVER_KINDS

    args = build_parser().parse_args(["fly", "--maneuver", "all", "--config", "all", "--out", "x"])
    camp = parse_campaign(flags_campaign(configurations=args.config, maneuvers=args.maneuver), source="flags")
    assert {j.maneuver["kind"] for j in camp.jobs} == set(MANEUVER_KINDS)
    assert len({j.configuration_id for j in camp.jobs}) == len(camp.fleet.configurations)


def test_fly_and_show_help_point_only_at_things_that_exist(capsys):
    from aircraft_models import load_fleet
    from synth.maneuvers import MANEUVER_KINDS

    with pytest.raises(SystemExit):
        main(["fly", "--help"])
    text = capsys.readouterr().out
    for kind in MANEUVER_KINDS:
        assert kind in text
    for cid in load_fleet("fleet_default").configurations:
        assert cid in text
    for path in ("campaigns/default.toml", "campaigns/demo.toml", "synth/errors.py"):
        assert path in text and (REPO / path).exists(), path
    assert "--resume" in text and "SPEC" not in text
    with pytest.raises(SystemExit):
        main(["show", "--help"])
    assert "incomplete" in capsys.readouterr().out


@pytest.mark.slow
def test_show_into_a_closed_pipe_ends_quietly(kill_campaign, tmp_path):
    _, out, _ = kill_campaign  # a complete dataset, only read
    procs, writes = [], []
    try:
        for dataset in (out, tmp_path / "missing"):  # output, or an error message (to stderr)
            read, write = os.pipe()
            os.close(read)  # `fpr show DIR | head` after head has gone: every write fails
            writes.append(write)
            # the two runs at once: each is mostly Python's start and the imports
            procs.append(subprocess.Popen([sys.executable, "-m", "campaigns.cli", "show", str(dataset)],
                                          cwd=REPO, stdout=write, stderr=subprocess.PIPE, text=True))
        (shown, shown_err), (missing, missing_err) = ((p, p.communicate(timeout=120)[1]) for p in procs)
    finally:
        for write in writes:
            os.close(write)
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()
    assert shown.returncode == 141 and shown_err == "", shown_err
    assert missing.returncode == 2 and "Traceback" not in missing_err, missing_err


# ------------------------------------------------------------------------ incomplete datasets
def _interrupt(out: Path) -> None:
    """What a run killed after its first maneuver leaves: the first manifest, some files."""
    manifest = json.loads((out / MANIFEST).read_text())
    write_manifest(out, {**manifest, "complete": False, "maneuvers": [], "failures": []})
    (out / "maneuvers" / "m0001.parquet").unlink()


def test_readers_refuse_an_incomplete_dataset_and_say_how_to_resume(tmp_path):
    out = tmp_path / "ds"
    _fly_tiny(out)
    _interrupt(out)
    with pytest.raises(IncompleteDatasetError, match=r"1 of 2 maneuvers.*fpr fly --resume --out"):
        load_dataset(out)
    with pytest.raises(DataError, match=r"incomplete dataset.*fpr fly --resume --out"):
        read_manifest(out)
    with pytest.raises(FileExistsError, match="incomplete.*--resume"):
        prepare_directory(out)


def test_an_edited_or_damaged_manifest_is_named_with_what_to_do(tmp_path, capsys):
    out = tmp_path / "ds"
    _fly_tiny(out)
    _interrupt(out)
    manifest = json.loads((out / MANIFEST).read_text())
    del manifest["jobs"][0]["files"]  # edited by hand
    write_manifest(out, manifest)
    assert main(["show", str(out)]) == 2
    err = capsys.readouterr().err
    assert f'{out / MANIFEST}: planned job 0 (job_index 0) has no list of "files"' in err
    assert "Restore it, or move" in err and "Traceback" not in err
    # the estimator's reader: the manifest says incomplete, and that is all it needs to know
    with pytest.raises(DataError, match=r"incomplete dataset.*fpr fly --resume --out"):
        read_manifest(out)
    # the resume reads the campaign from this manifest: it cannot advise itself
    assert main(["fly", "--resume", "--out", str(out), "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert "differs from its own campaign" in err and "in jobs" in err and "--resume" not in err
    (out / MANIFEST).write_text((out / MANIFEST).read_text()[:300])  # truncated
    assert main(["show", str(out)]) == 2
    assert "the manifest is damaged" in capsys.readouterr().err
    assert main(["fly", "--resume", "--out", str(out), "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert f"{out / MANIFEST}: cannot be read" in err and f"move {out} aside" in err
    assert "--resume" not in err and "Traceback" not in err


def test_resume_refuses_another_campaign_and_completes_its_own(tmp_path, capsys):
    out = tmp_path / "ds"
    _fly_tiny(out)
    reference = _files(out)
    _interrupt(out)
    code = main(["fly", "--mach", "0.7", "--maneuver", "3211", "--out", str(out), "--resume"])
    err = capsys.readouterr().err
    assert code == 2 and "another campaign" in err and "definition" in err
    res = fly_campaign(parse_campaign(TINY, source="elsewhere/tiny.toml"), out, workers=1, resume=True)
    assert res.flown == 1
    assert _files(out) == reference


def test_a_damaged_maneuver_file_is_named_and_flown_again_on_resume(tmp_path, capsys):
    out = tmp_path / "ds"
    _fly_tiny(out)
    reference = _files(out)
    _interrupt(out)
    damaged = out / "maneuvers" / "m0000.parquet"
    damaged.write_bytes(damaged.read_bytes()[:-100])  # truncated: the footer is gone
    assert main(["show", str(out)]) == 1
    shown = capsys.readouterr().out
    assert "0 of 2 maneuvers written" in shown and f"{damaged} (" in shown and "damaged" in shown
    assert "`fpr fly --resume` flies them again" in shown and "Traceback" not in shown
    assert main(["fly", "--resume", "--out", str(out), "--workers", "1"]) == 0
    err = capsys.readouterr().err
    assert f"{damaged}: damaged (" in err and "its maneuver is flown again" in err
    assert _files(out) == reference
    # a folder at a maneuver file's name is not the tool's: refused, left alone
    _interrupt(out)
    damaged.unlink()
    (damaged / "mine").mkdir(parents=True)
    assert main(["fly", "--resume", "--out", str(out), "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert "maneuvers/m0000.parquet: a folder where `fpr fly` writes a maneuver file" in err
    assert (damaged / "mine").is_dir()


def test_resume_refuses_a_maneuvers_folder_that_is_a_link_or_a_file(tmp_path, capsys):
    out = tmp_path / "ds"
    _fly_tiny(out)
    _interrupt(out)
    elsewhere = tmp_path / "elsewhere"
    (out / "maneuvers").rename(elsewhere)
    (out / "maneuvers").symlink_to(elsewhere)
    before = _files(elsewhere)
    assert main(["fly", "--resume", "--out", str(out), "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert f"{out / 'maneuvers'}: a link, not the maneuvers/ folder `fpr fly` made" in err
    assert "Traceback" not in err
    assert _files(elsewhere) == before  # nothing written through the link
    (out / "maneuvers").unlink()
    (out / "maneuvers").write_text("mine")
    assert main(["fly", "--resume", "--out", str(out), "--workers", "1"]) == 2
    assert f"{out / 'maneuvers'}: not a folder" in capsys.readouterr().err
    assert (out / "maneuvers").read_text() == "mine"


# ---------------------------------------------------------- killed runs: resume, no orphans
#: ``hold`` of the sitecustomize (:func:`_processes.patched_on_import_env`) of the run the test
#: kills: writing m0000.parquet, a worker writes it whole and then waits before its result reaches
#: the run; writing m0001.parquet, it writes half of it to a temporary file as
#: ``atomic_write_bytes`` names it (``.NAME.RANDOM.tmp``) and waits. Each says so (a file of that
#: name in HELD). So the signal comes while both workers are inside jobs, each after one flight,
#: with a whole file the run has not heard of and a half-written one, whatever the machine's speed.
_HOLD_WRITES = """
import os
import tempfile
import time
from pathlib import Path

HELD = Path({held!r})


def hold(module):
    real = module.atomic_write_bytes

    def held(path, payload):
        path = Path(path)
        if path.name == "m0000.parquet":
            real(path, payload)
        elif path.name == "m0001.parquet":
            fd, _ = tempfile.mkstemp(dir=path.parent, prefix=f".{{path.name}}.", suffix=".tmp")
            os.write(fd, payload[: len(payload) // 2])
        else:
            return real(path, payload)
        (HELD / path.name).touch()
        while True:
            time.sleep(0.05)

    module.atomic_write_bytes = held
"""


@pytest.fixture(scope="module")
def kill_campaign(tmp_path_factory):
    """The kill test's campaign file, and its dataset flown uninterrupted by a pool, as the killed
    run flies (its folder, its files); shared: copy the folder before editing it."""
    base = tmp_path_factory.mktemp("kill")
    toml = base / "kill.toml"
    toml.write_text(KILL_CAMPAIGN)
    ref = base / "reference"
    assert main(["fly", str(toml), "--out", str(ref), "--workers", "2"]) == 0
    return toml, ref, _files(ref)


@pytest.mark.slow
@pytest.mark.skipif(not HAVE_PROC, reason="finds worker processes in /proc")
@pytest.mark.parametrize("how", ["SIGINT", "SIGKILL"])
def test_a_killed_fly_leaves_no_worker_and_resumes_to_the_same_bytes(kill_campaign, tmp_path, short_tmp, how,
                                                                     capsys):
    toml, _, reference = kill_campaign
    out = tmp_path / "ds"
    log_out, log_err = tmp_path / "stdout.txt", tmp_path / "stderr.txt"
    held = tmp_path / "held"
    held.mkdir()
    # multiprocessing's own folder (the fork server's socket), which a killed parent leaves
    env = patched_on_import_env(tmp_path / "hook", "synth.dataset", _HOLD_WRITES.format(held=str(held)),
                                TMPDIR=str(short_tmp))
    with open(log_out, "w") as fo, open(log_err, "w") as fe:
        proc = subprocess.Popen(
            [sys.executable, "-m", "campaigns.cli", "fly", str(toml), "--out", str(out), "--workers", "2"],
            stdout=fo, stderr=fe, cwd=REPO, start_new_session=True, preexec_fn=sigint_default,
            env=env)
    workers = []
    try:
        # wait until both workers are held inside their jobs (bounded: a stuck start fails
        # instead of hanging)
        deadline = time.monotonic() + 120.0
        while not ((held / "m0000.parquet").exists() and (held / "m0001.parquet").exists()):
            assert proc.poll() is None, f"fpr fly ended early: {log_err.read_text()}"
            assert time.monotonic() < deadline, "the workers not held within 120 s"
            time.sleep(0.05)
        # the workers, and under forkserver the server (their parent) and a resource tracker
        workers = descendants(proc.pid)
        assert len(workers) >= 2, workers
        if how == "SIGINT":
            os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in a terminal does: the whole group
        else:
            os.kill(proc.pid, signal.SIGKILL)  # the parent alone
        code = proc.wait(timeout=60)
    finally:
        if proc.poll() is None:  # failed before the run ended: end it and its held workers
            reap(proc, workers)
    # no worker outlives its parent by more than 5 s (the bound)
    orphans = left_after(workers, 5.0)
    reap(proc, orphans)  # a held worker left would wait forever
    assert not orphans, "orphaned worker processes"
    err = log_err.read_text()
    temporary = sorted(p.name for p in (out / "maneuvers").glob(".m0001.parquet.*.tmp"))
    if how == "SIGINT":
        assert code == 130, err
        assert "interrupted:" in err and f"fpr fly --resume --out {out}" in err
        assert "Traceback" not in err
        assert temporary == [], "the interrupted run left its half-written file"
    else:
        assert code == -signal.SIGKILL
        assert len(temporary) == 1, temporary  # what the resume must clear
    # the dataset says it is incomplete, and how to complete it; the whole file counts, though the
    # run never heard of it
    assert json.loads((out / MANIFEST).read_text())["complete"] is False
    assert main(["show", str(out)]) == 1
    shown = capsys.readouterr().out
    assert "INCOMPLETE" in shown and f"fpr fly --resume --out {out}" in shown
    assert f"1 of {len(reference) - 1} maneuvers written" in shown
    # resumed, it is byte for byte the uninterrupted run (no stray temporary file either): the
    # killed run's file kept, the others flown again. In this process: workers change only how fast
    # it flies (the reference and the kept file come from pools), and a new pool's workers would
    # import everything anew
    assert main(["fly", "--resume", "--out", str(out), "--workers", "1"]) == 0
    got = _files(out)
    assert sorted(got) == sorted(reference)
    assert [k for k in reference if got[k] != reference[k]] == []
    assert main(["show", str(out)]) == 0
