"""Monte Carlo run folders are safe to open and their files are reproducible (issue 11).

- A run folder may come from anyone: nothing in it is unpickled. A planted ``flights/*.pkl`` is
  ignored (said so) and the flight flown again; files the tool did not write are left alone.
- The shared-flight cache (``flights/jNNNN.npz``) gives back exactly what was flown.
- An interrupted run, resumed, ends with the same bytes as an uninterrupted one (timings apart).
- The worker processes end with the run's process, even when it is killed.
- The summary replaces only the files it wrote itself, unchanged (``.fpr-summary.json``): a user's
  ``summary.txt`` or an edited summary file is refused by name, before any replication is run.
- A run folder's foreign files survive a resume; one with a result's name that the run did not
  write (another scenario's replication, a user's ``timings.csv``) is refused, never counted.
- Ctrl-C (SIGINT to the process group, as a terminal sends it): the workers ignore it, the run
  stops them (their scratch data removed), says how many replications are written and how to
  resume, exits 130 without a traceback; the same command completes it to the same bytes.

The tiny scenario of tests/campaigns_tests/test_montecarlo.py (a replication takes about half a second).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import pathlib
import pickle
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from _processes import (
    HAVE_PROC,
    descendants,
    ignores,
    left_after,
    patched_on_import_env,
    reap,
    sigint_default,
)
from test_montecarlo import SCENARIO_TOML, _scenario

from campaigns import montecarlo_cli
from campaigns.montecarlo import (
    ReplicationResult,
    load_scenario,
    replication,
    run_montecarlo,
    runner,
    summarize,
)
from campaigns.montecarlo import summary as summary_module
from campaigns.montecarlo.flight_cache import flight_bytes, flight_file, read_flight
from campaigns.montecarlo.summary import load_results
from estimator.io import outdir
from synth.truth import TruthTrajectory

HERE = Path(__file__).resolve().parent  # a child process imports test_montecarlo from here
ROOT = HERE.parents[1]


class _Planted:
    """Unpickling this creates ``marker``: what someone else's code could do instead."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return (pathlib.Path.touch, (pathlib.Path(self.marker),))


def _files(directory: Path) -> dict[str, bytes]:
    return {str(p.relative_to(directory)): p.read_bytes()
            for p in sorted(directory.rglob("*")) if p.is_file()}


@pytest.mark.slow
def test_a_planted_pickle_in_a_copied_run_folder_is_never_loaded(tmp_path, monkeypatch, capsys):
    # no flight held in memory from another test of this process: the folder alone decides
    monkeypatch.setattr(runner, "_PROCESS", {})
    toml = tmp_path / "mc_test.toml"
    toml.write_text(SCENARIO_TOML)
    out = tmp_path / "copied_run"
    runner.prepare_output(_scenario(), out)  # a run folder as `fpr montecarlo` makes it...
    marker = tmp_path / "code_ran"
    planted = pickle.dumps(_Planted(marker))
    for j in (0, 1):  # ...with a flight cache that runs code when unpickled
        (out / "flights" / f"j{j:04d}.pkl").write_bytes(planted)

    status = montecarlo_cli.main(["montecarlo", str(toml), "--out", str(out), "--workers", "1",
                                  "--replications", "1", "--no-summary"])
    text = capsys.readouterr().out
    assert not marker.exists(), "a pickle from the run folder was loaded"
    assert status == 0, text
    assert "2 shared flights flown" in text and "1 replications run now" in text
    for j in (0, 1):
        line = f"ignoring flights/j{j:04d}.pkl: pickle files are never loaded; the flight is flown again"
        assert text.count(line) == 1, text
        assert (out / "flights" / f"j{j:04d}.pkl").read_bytes() == planted  # left where it was
        assert len(read_flight(flight_file(out / "flights", j))) == 1  # flown again, cached safely
    assert runner.finished_replications(out) == {0: "ok"}
    # with the flights cached, the pickles are only mentioned
    report = run_montecarlo(_scenario(), out, replications=1, workers=1)
    assert report.ran == () and report.notes == (
        "ignoring flights/j0000.pkl: pickle files are never loaded",
        "ignoring flights/j0001.pkl: pickle files are never loaded")
    assert not marker.exists()


@pytest.mark.slow
def test_a_run_removes_only_its_own_leftovers(tmp_path):
    out = tmp_path / "run"
    runner.prepare_output(_scenario(), out)
    # the user's own files, some with names a careless cleanup would take for its own
    foreign = {"flights/notes.txt": b"mine", "replications/.draft.tmp": b"mine too",
               "flights/.j0000.npz.tmp": b"not of the tool's pattern",
               "replications/my_table.parquet": b"not a replication", "my_notes.txt": b"keep",
               ".scratch.tmp": b"keep"}
    for name, data in foreign.items():
        (out / name).write_bytes(data)
    # the tool's own temporary files, left by a run killed while writing
    ours = [out / "replications" / ".r00000.parquet.k3j9x_2a.tmp",
            out / "flights" / ".j0001.npz.abc123de.tmp", out / ".montecarlo.json.zz9_qa0b.tmp"]
    for p in ours:
        p.write_bytes(b"half a file")
    report = run_montecarlo(_scenario(), out, replications=1, workers=1)
    assert report.ran == (0,) and not report.failed
    assert runner.finished_replications(out) == {0: "ok"}
    for name, data in foreign.items():
        assert (out / name).read_bytes() == data, name
    assert not any(p.exists() for p in ours)


def test_a_pickle_named_like_a_cache_file_is_refused_without_running_it(tmp_path):
    marker = tmp_path / "code_ran"
    path = flight_file(tmp_path, 7)
    path.write_bytes(pickle.dumps(_Planted(marker)))
    with pytest.raises(ValueError, match=r"j0007\.npz: not a readable flight-cache file.*delete"):
        read_flight(path)
    assert not marker.exists()


def _assert_same_segments(a: tuple[TruthTrajectory, ...], b: tuple[TruthTrajectory, ...]) -> None:
    assert len(a) == len(b)
    for sa, sb in zip(a, b, strict=True):
        for f in dataclasses.fields(TruthTrajectory):
            va, vb = getattr(sa, f.name), getattr(sb, f.name)
            if isinstance(va, np.ndarray):
                assert va.dtype == vb.dtype and va.shape == vb.shape, f.name
                assert va.tobytes() == vb.tobytes(), f.name  # bit for bit, NaN and -0.0 included
            elif f.name == "controls":
                assert list(va) == list(vb)
                for k in va:
                    assert va[k].dtype == vb[k].dtype and va[k].tobytes() == vb[k].tobytes(), k
            else:
                assert va == vb and repr(va) == repr(vb), f.name  # repr: a tuple stays a tuple


def test_the_flight_cache_round_trip_is_lossless_and_deterministic(tmp_path):
    # a real flight, cached by the runner
    scenario = _scenario()
    payload = runner.ScenarioPayload(raw=scenario.raw, source=scenario.source)
    _, flown, error = runner.fly_task(payload, 1)
    assert error is None
    (tmp_path / "flights").mkdir()
    assert runner._store_flights(scenario, tmp_path, [(1, flown, None)]) == 1
    _assert_same_segments(tuple(flown), read_flight(flight_file(tmp_path / "flights", 1)))
    # and two hand-made segments with what a float64 and a meta can hold
    rng = np.random.default_rng(11)
    n = 7
    special = np.array([np.nan, -0.0, np.inf, -np.inf, 5e-324, 1.0 / 3.0, np.finfo(float).max])
    names = [f.name for f in dataclasses.fields(TruthTrajectory)
             if f.name not in ("controls", "planet", "meta")]
    arrays = {name: rng.standard_normal((n, 3) if i % 2 else n) for i, name in enumerate(names)}
    arrays["t_s"] = np.arange(n) * 0.1
    arrays["alpha_rad"] = special
    meta = {"segment": 1, "segment_start_s": 0.1 + 0.2, "trim": {"residuals": {"udot": 1e-17}},
            "wind": (1.5, -2.0, 0.0), "nested": [(1, "a"), {"k": None}], "flag": True, "nan": math.nan,
            "big": 2**70, "np": np.float64(0.1), "text": "Mach 0.6 ° ü"}
    made = tuple(TruthTrajectory(**arrays, controls={"z_last": -special, "a_first": special[::-1].copy()},
                                 planet=planet, meta=dict(meta, segment=i))
                 for i, planet in enumerate(("flat", "wgs84")))
    for segments in (flown, made):
        data = flight_bytes(segments)
        path = flight_file(tmp_path, 3)
        path.write_bytes(data)
        back = read_flight(path)
        assert flight_bytes(back) == data  # the same flight, the same bytes
        if segments is made:  # NaN != NaN, and a NumPy scalar comes back as the float it equals
            assert math.isnan(back[0].meta["nan"]) and type(back[0].meta["np"]) is float
            assert back[0].meta["np"] == 0.1 and back[0].meta["wind"] == (1.5, -2.0, 0.0)
            segments, back = ([dataclasses.replace(s, meta={k: v for k, v in s.meta.items()
                                                            if k not in ("nan", "np")}) for s in x]
                              for x in (segments, back))
        _assert_same_segments(segments, back)


@pytest.mark.slow
def test_an_interrupted_run_resumed_ends_byte_identical_to_an_uninterrupted_one(run3, tmp_path, monkeypatch):
    toml, whole = run3  # the uninterrupted run: replications 0..2 in one go (only read here)
    scenario = load_scenario(str(toml))  # as `fpr montecarlo` reads it
    cut = tmp_path / "cut"
    real = runner.replication_task

    def interrupted_at_1(payload, index, truths):
        if index == 1:
            raise KeyboardInterrupt  # the operator's Ctrl-C in the middle of the run
        return real(payload, index, truths)

    monkeypatch.setattr(runner, "replication_task", interrupted_at_1)
    with pytest.raises(KeyboardInterrupt):
        run_montecarlo(scenario, cut, replications=3, workers=1)
    assert sorted(runner.finished_replications(cut)) == [0]
    monkeypatch.setattr(runner, "replication_task", real)
    # resumed in this process: that a worker process's replication has the same bytes is
    # test_montecarlo.py's interrupted-run test and, by the command line, the Ctrl-C test below
    report = run_montecarlo(scenario, cut, replications=3, workers=1)
    assert report.ran == (1, 2) and report.flights_flown == 0 and not report.failed
    a, b = _files(whole), _files(cut)
    assert set(a) == set(b)
    assert sorted(k for k in a if k.startswith("replications/")) == [
        f"replications/r{k:05d}.parquet" for k in range(3)]
    differ = sorted(k for k in a if a[k] != b[k])
    assert differ == ["timings.csv"]  # replications, flights, montecarlo.json: the same bytes
    # the timings are kept apart, and still read by the summary
    for out in (whole, cut):
        times = [r.elapsed_s for r in load_results(out)]
        assert len(times) == 3 and all(t > 0 for t in times)
        line = "time per replication in its worker (timings.csv, 3 replications): median"
        assert line in summarize(out).text()


#: ``hold`` of the sitecustomize (:func:`_processes.patched_on_import_env`) of a run the test
#: interrupts or kills: a replication other than those whose scratch folder's name holds one of
#: FREE writes its scratch dataset, says so (a file ``held`` there) and then waits inside its
#: scratch folder until the run is stopped, so that the signal comes while the workers are in
#: replications, whatever the machine's speed
_HOLD_REPLICATIONS = """
import time
from pathlib import Path

FREE = {free!r}


def hold(module):
    real = module.write_scratch_dataset

    def held(scenario, draws, truths, models, directory):
        real(scenario, draws, truths, models, directory)
        if not any(free in Path(directory).name for free in FREE):
            (Path(directory) / "held").touch()
            while True:
                time.sleep(0.05)

    module.write_scratch_dataset = held
"""


def _holding_env(tmp_path: Path, free: tuple[str, ...], **env: str) -> dict[str, str]:
    """The environment of a child run whose replications are held (:data:`_HOLD_REPLICATIONS`)."""
    return patched_on_import_env(tmp_path / "hook", "campaigns.montecarlo.replication",
                                 _HOLD_REPLICATIONS.format(free=free), **env)


def _wait_for(condition, child: subprocess.Popen, what: str, seconds: float = 120.0) -> None:
    """Poll ``condition()`` until it holds; fail if the child ends first or after ``seconds``."""
    deadline = time.monotonic() + seconds
    while not condition():
        assert child.poll() is None, ("the run ended before it could be stopped", child.communicate())
        assert time.monotonic() < deadline, f"{what} within {seconds:.0f} s"
        time.sleep(0.05)


_RUN_IN_CHILD = """
import sys
sys.path[:0] = [{here!r}, {tests!r}]
from test_montecarlo import _scenario
from campaigns.montecarlo import run_montecarlo
run_montecarlo(_scenario(), {out!r}, replications=40, workers=2)
"""


@pytest.mark.slow
@pytest.mark.skipif(not HAVE_PROC, reason="reads /proc")
def test_worker_processes_end_when_the_run_is_killed(tmp_path, short_tmp):
    out = tmp_path / "killed"
    tmp = short_tmp  # the system's temporary folder, for the run: nothing may leak there
    script = _RUN_IN_CHILD.format(here=str(HERE), tests=str(ROOT / "tests"), out=str(out))
    # every replication is held in its scratch folder: both workers are inside one when it is killed
    child = subprocess.Popen([sys.executable, "-c", script], cwd=ROOT,
                             env=_holding_env(tmp_path, free=(), TMPDIR=str(tmp)))
    workers: list[tuple[int, str]] = []
    try:
        _wait_for(lambda: len(list((out / ".scratch").glob("r*/held"))) == 2, child,
                  "the two workers were not in replications")
        held = sorted(p.parent.name for p in (out / ".scratch").glob("r*/held"))
        # the workers (and under forkserver the server, their parent, and a resource tracker)
        workers = descendants(child.pid)
        assert len(workers) >= 2, workers
        os.kill(child.pid, signal.SIGKILL)
        child.wait()
        left = left_after(workers, 5.0)
        assert not left, f"worker processes {left} outlived their killed parent by 5 s"
    finally:
        reap(child, workers)
    # the killed workers' scratch datasets are in the run folder, not the system's temporary one
    # (where only multiprocessing's own pymp-* folder of the fork server's socket may be left)
    assert list(tmp.glob("fpr-mc-*")) == []
    scratch = out / ".scratch"
    assert sorted(p.name for p in scratch.iterdir()) == held
    assert all(replication.SCRATCH_NAME.fullmatch(name) for name in held)
    # the next run removes them (and nothing else there)
    (scratch / "r00003-abcd_123" / "maneuvers").mkdir(parents=True)  # one more, of a name it made
    (scratch / "r00007-mine").mkdir()
    run_montecarlo(_scenario(), out, replications=40, indices=[], workers=1)
    assert [p.name for p in scratch.iterdir()] == ["r00007-mine"]


# ---------------------------------------------------------------------------- the summary's files,
# foreign files in a run folder, Ctrl-C


@pytest.fixture(scope="module")
def run3(tmp_path_factory) -> tuple[Path, Path]:
    """(scenario file, run folder): replications 0..2 of the tiny scenario, written by the command
    line without a summary; each test copies the folder."""
    base = tmp_path_factory.mktemp("mc_run3")
    toml = base / "mc_test.toml"
    toml.write_text(SCENARIO_TOML)
    out = base / "run"
    assert montecarlo_cli.main(["montecarlo", str(toml), "--out", str(out), "--workers", "1",
                                "--replications", "3", "--no-summary"]) == 0
    return toml, out


def _copy(run: Path, to: Path) -> Path:
    shutil.copytree(run, to)
    return to


@pytest.mark.slow
def test_a_users_summary_file_is_refused_by_name_never_replaced(run3, tmp_path, capsys):
    out = _copy(run3[1], tmp_path / "run")
    mine = b"my notes on this run\n"
    (out / "summary.txt").write_bytes(mine)
    before = _files(out)
    assert montecarlo_cli.main(["montecarlo-summary", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{out / 'summary.txt'} (fpr montecarlo-summary did not write it)" in err, err
    assert f"Move it out of {out} (or rename it), or write the summary elsewhere with --summary-dir" in err
    assert _files(out) == before  # nothing written, nothing replaced
    # the run command refuses before any replication is run, not after
    toml = run3[0]
    assert montecarlo_cli.main(["montecarlo", str(toml), "--out", str(out), "--workers", "1",
                                "--replications", "4"]) == 2
    err = capsys.readouterr().err
    assert f"{out / 'summary.txt'} (fpr montecarlo did not write it)" in err, err
    assert "--summary-dir DIR, or skip it with --no-summary" in err
    assert _files(out) == before and sorted(runner.finished_replications(out)) == [0, 1, 2]
    # elsewhere, the summary is written; the user's file stays
    elsewhere = tmp_path / "summaries"
    assert montecarlo_cli.main(["montecarlo-summary", str(out), "--summary-dir", str(elsewhere)]) == 0
    assert capsys.readouterr().out.startswith("Monte Carlo mc_test: 3 replications")
    assert sorted(p.name for p in elsewhere.iterdir()) == sorted([*summary_module.SUMMARY_FILES,
                                                                   summary_module.SUMMARY_LISTING])
    assert _files(out) == before


@pytest.mark.slow
def test_the_summarys_own_files_are_replaced_an_edited_one_is_not(run3, tmp_path, capsys):
    out = _copy(run3[1], tmp_path / "run")
    (out / "summary_notes.txt").write_bytes(b"a name beside the summary's: never looked at")
    assert montecarlo_cli.main(["montecarlo-summary", str(out), "--replications", "2"]) == 0
    assert capsys.readouterr().out.startswith("Monte Carlo mc_test: 2 replications")
    listing = json.loads((out / summary_module.SUMMARY_LISTING).read_text())
    assert sorted(e["path"] for e in listing["files"]) == sorted(summary_module.SUMMARY_FILES)
    for e in listing["files"]:
        assert e["sha256"] == hashlib.sha256((out / e["path"]).read_bytes()).hexdigest()
    # the summary's own earlier files, unchanged: replaced
    assert montecarlo_cli.main(["montecarlo-summary", str(out)]) == 0
    assert (out / "summary.txt").read_text().startswith("Monte Carlo mc_test: 3 replications")
    assert (out / "summary_notes.txt").read_bytes() == b"a name beside the summary's: never looked at"
    # one the user edited since: refused, named, kept as edited
    edited = (out / "summary_channels.csv").read_bytes() + b"my own row\n"
    (out / "summary_channels.csv").write_bytes(edited)
    before = _files(out)
    assert montecarlo_cli.main(["montecarlo-summary", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{out / 'summary_channels.csv'} (changed since fpr montecarlo-summary wrote it)" in err, err
    assert _files(out) == before


def test_prepare_files_replaces_only_the_files_it_listed(tmp_path):
    names = ("a.txt", "b.png")
    kw = {"listing_name": ".fpr-test.json", "tool": "the tool"}
    (tmp_path / "other.txt").write_text("the user's")
    with outdir.prepare_files(tmp_path, names, **kw) as folder:
        folder.record(tmp_path / "a.txt").write_text("one")
    assert (tmp_path / ".fpr-test.json").is_file() and not (tmp_path / outdir.LISTING_NAME).exists()
    with outdir.prepare_files(tmp_path, names, **kw) as folder:  # its own: replaced
        assert not (tmp_path / "a.txt").exists()
        folder.record(tmp_path / "b.png").write_text("two")
    assert sorted(p.name for p in tmp_path.iterdir()) == [".fpr-test.json", "b.png", "other.txt"]
    (tmp_path / "a.txt").write_text("the user's a")  # not listed now: the user's
    with pytest.raises(outdir.OutputFolderError, match=r"a\.txt \(the tool did not write it\)"):
        outdir.prepare_files(tmp_path, names, **kw)
    (tmp_path / "a.txt").unlink()
    (tmp_path / "b.png").unlink()
    (tmp_path / "b.png").symlink_to(tmp_path / "other.txt")  # a listed name that became a link
    with pytest.raises(outdir.OutputFolderError, match=r"b\.png \(replaced by a link"):
        outdir.check_files(tmp_path, names, **kw)
    (tmp_path / "b.png").unlink()
    (tmp_path / ".fpr-test.json").write_text("{not json")
    with pytest.raises(outdir.OutputFolderError, match=r"\.fpr-test\.json \(not a listing fpr wrote"):
        outdir.prepare_files(tmp_path, names, **kw)
    with pytest.raises(ValueError, match="a file name"):
        outdir.check_files(tmp_path, ["sub/a.txt"], **kw)
    assert (tmp_path / "other.txt").read_text() == "the user's"


@pytest.mark.slow
def test_foreign_files_in_a_run_folder_survive_a_resume_and_are_not_taken_for_results(run3, tmp_path,
                                                                                      capsys):
    toml, run = run3
    out = _copy(run, tmp_path / "run")
    (out / "replications" / "r00002.parquet").unlink()  # the resume has one replication to run
    foreign = {"notes.txt": b"mine", "plots/fig.png": b"\x89PNG mine", "summary_notes.txt": b"mine",
               "replications/my_table.parquet": b"not a replication", "replications/r2.parquet": b"x",
               "flights/README": b"about the flights", ".lock.bak": b"mine"}
    for name, data in foreign.items():
        (out / name).parent.mkdir(exist_ok=True)
        (out / name).write_bytes(data)
    assert montecarlo_cli.main(["montecarlo", str(toml), "--out", str(out), "--workers", "1"
                                , "--replications", "3"]) == 0
    text = capsys.readouterr().out
    assert "1 replications run now, 2 already done, 3 requested" in text
    assert "Monte Carlo mc_test: 3 replications, 3 summarised" in text
    for name, data in foreign.items():
        assert (out / name).read_bytes() == data, name
    assert sorted(runner.finished_replications(out)) == [0, 1, 2]
    assert (out / "replications" / "r00002.parquet").read_bytes() == \
        (run / "replications" / "r00002.parquet").read_bytes()
    # a folder that is not a run folder: refused, what is there named, nothing touched
    other = tmp_path / "other"
    other.mkdir()
    (other / "thesis.tex").write_bytes(b"mine")
    (other / "figures").mkdir()
    assert montecarlo_cli.main(["montecarlo", str(toml), "--out", str(other), "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert f"{other}: not empty and not a Monte Carlo output" in err and "figures/, thesis.tex" in err
    assert sorted(p.name for p in other.iterdir()) == ["figures", "thesis.tex"]


@pytest.mark.slow
def test_a_file_with_a_result_name_the_run_did_not_write_is_refused(run3, tmp_path, capsys):
    toml, run = run3
    out = _copy(run, tmp_path / "run")
    rep = out / "replications"
    # replication 0's file under replication 3's name (copied by hand); a failure record of another
    # scenario; a user's timings.csv: none is counted as done, written over or appended to
    shutil.copyfile(rep / "r00000.parquet", rep / "r00003.parquet")
    other = ReplicationResult(index=4, ok=False, status=-1, message="of another scenario",
                              noise_seed=1, scenario_hash="0" * 64)
    runner.write_replication(out, other)
    (out / "timings.csv").write_bytes(b"my,own,timings\n1,2,3\n")
    before = _files(out)
    assert montecarlo_cli.main(["montecarlo", str(toml), "--out", str(out), "--workers", "1",
                                "--replications", "5", "--no-summary"]) == 2
    err = capsys.readouterr().err
    assert ("replications/r00003.parquet, replications/r00004.failed.json, timings.csv carry the name "
            "of a file of this run but were not written by it") in err, err
    assert f"Move them out of {out} and run the same command again" in err
    assert _files(out) == before  # refused before anything was written
    # the summary does not read them as this run's either
    (out / "timings.csv").unlink()
    (rep / "r00004.failed.json").unlink()
    assert montecarlo_cli.main(["montecarlo-summary", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{rep / 'r00003.parquet'}: replication 0 of scenario hash" in err and "not replication 3" in err


@pytest.mark.slow
@pytest.mark.skipif(not HAVE_PROC, reason="reads /proc")
def test_ctrl_c_stops_the_workers_cleanly_and_the_same_command_resumes(run3, tmp_path, short_tmp, capsys):
    toml, whole = run3
    out = tmp_path / "cut"
    scratch = short_tmp
    args = ["montecarlo", str(toml), "--out", str(out), "--workers", "2", "--replications", "3",
            "--no-summary"]
    # replication 0 runs to its end; 1 and 2 are held in their scratch folders until the Ctrl-C
    env = _holding_env(tmp_path, free=("r00000-",), TMPDIR=str(scratch))
    # its own process group, as a terminal's foreground job: Ctrl-C goes to the run and its workers
    child = subprocess.Popen([sys.executable, "-m", "campaigns.cli", *args], cwd=ROOT, env=env,
                             process_group=0, preexec_fn=sigint_default, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    workers: list[tuple[int, str]] = []
    try:
        # replication 0 written, both workers held inside a replication (1 and 2)
        _wait_for(lambda: (out / "replications" / "r00000.parquet").exists()
                  and len(list((out / ".scratch").glob("r*/held"))) == 2, child,
                  "the workers were not busy")
        # the workers (and under forkserver the server, their parent, and a resource tracker)
        workers = descendants(child.pid)
        assert len(workers) >= 2, workers
        for w in workers:  # the workers leave Ctrl-C to the run (no traceback from each)
            assert ignores(w[0], signal.SIGINT), f"worker {w} does not ignore SIGINT"
        os.killpg(child.pid, signal.SIGINT)
        stdout, stderr = child.communicate(timeout=60)
        assert not left_after(workers, 5.0), "a worker outlived the interrupted run by 5 s"
    finally:
        reap(child, workers)
    assert child.returncode == 130, stderr
    assert (f"fpr montecarlo: interrupted: 1 of 3 replications written to {out}; run the same "
            "command again to resume") in stderr, stderr
    assert "Traceback" not in stderr + stdout and "KeyboardInterrupt" not in stderr, stderr
    assert sorted(p.name for p in (out / "replications").iterdir()) == ["r00000.parquet"]
    # the stopped workers' scratch datasets are gone (and none was in the system's temporary folder)
    assert list(scratch.iterdir()) == [] and not (out / ".scratch").exists()
    # the same command again completes it, to the bytes of an uninterrupted run
    assert montecarlo_cli.main(args) == 0
    assert "2 replications run now, 1 already done, 3 requested" in capsys.readouterr().out
    a, b = _files(whole), _files(out)
    assert set(a) == set(b)
    assert sorted(k for k in a if a[k] != b[k]) == ["timings.csv"]
