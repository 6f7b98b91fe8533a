"""The study scaffold (campaigns/studies/scaffold.py): its command line, its invocation record (a
resumed study states what every invocation cost, the log of studies (a) and (b) before the scaffold
included) and its results files, with a study of its own that computes nothing."""

from __future__ import annotations

import json
import operator
from types import SimpleNamespace

import pandas as pd
import pytest

from campaigns.studies import scaffold
from campaigns.studies.invocations import LEGACY_LOG


def _study(calls: list) -> scaffold.Study:
    """A study whose run computes one replication per call and whose report is its header."""

    def run(config, out_dir, n, workers, log):
        calls.append(("run", config.name, n, workers))
        return 1, {"note": "from the run"}

    def analyse(config, out_dir, n, outcome):
        return pd.DataFrame({"replication": range(n), "note": [outcome["note"]] * n})

    def report(df, config, n, command, invocations):
        return "\n".join(scaffold.header_lines("A study of nothing.", command, scaffold.__file__,
                                               f"{n} replications, {len(df)} rows", invocations)) + "\n"

    def plot(df, config, path, n):
        path.write_bytes(b"png")
        return path

    return scaffold.Study(name="nothing", file=scaffold.__file__, description="a test study",
                          sizes={"full": SimpleNamespace(name="full", replications=3),
                                 "tiny": SimpleNamespace(name="tiny", replications=1)},
                          unit="point", workers_help="-", size_help="-", run=run, analyse=analyse,
                          report=report, plot=plot, table=lambda df: df)


def test_arguments_take_the_sizes_default_and_keep_the_command_as_typed(tmp_path):
    study = _study([])
    args = scaffold.parse_arguments(study, ["--out", str(tmp_path / "a b"), "--size", "tiny"])
    assert args.replications == 1 and args.config.name == "tiny" and args.results == tmp_path / "a b"
    assert args.command == f"python -m campaigns.studies.nothing --out '{tmp_path / 'a b'}' --size tiny"
    args = scaffold.parse_arguments(study, ["--out", "x", "--results", "y", "--replications", "7",
                                            "--workers", "1"])
    assert (args.replications, args.workers, args.config.name, str(args.results)) == (7, 1, "full", "y")
    for bad in ("0", "-2"):  # (0 once meant the default, silently)
        with pytest.raises(SystemExit):
            scaffold.parse_arguments(study, ["--out", "x", "--replications", bad])


def test_main_writes_the_results_and_a_resumed_study_states_every_invocation(tmp_path, capsys):
    calls: list = []
    study = _study(calls)
    out, results = tmp_path / "work", tmp_path / "results"
    # the log studies (a) and (b) kept before the scaffold: its invocations are the history
    out.mkdir()
    (out / LEGACY_LOG).write_text(json.dumps({"wall_s": 460.0, "computed": 400, "replications": 20,
                                              "runs": 20, "code": "804b3a0"}) + "\n")
    argv = ["--out", str(out), "--results", str(results), "--workers", "1"]
    assert scaffold.main(study, argv) == 0
    assert scaffold.main(study, argv) == 0
    assert calls == [("run", "full", 3, 1)] * 2
    text = (results / "nothing.txt").read_text()
    assert capsys.readouterr().out.endswith(text + "\n")
    lines = text.splitlines()
    assert lines[2] == f"$ python -m campaigns.studies.nothing {' '.join(argv)}"
    assert lines[3].startswith("machine: ") and lines[4].startswith("code: ")
    assert lines[5] == "3 replications, 3 rows"
    assert lines[6].startswith("this invocation: wall ") and "1 replications computed" in lines[6]
    # 460 s and 400 replications of the legacy log, then the two invocations; its CPU time unknown
    assert lines[7].startswith("the replications were computed over 3 invocations (resumed): wall 460 s, "
                               "CPU ? s, 402 replications in all:")
    assert lines[8] == "  ?: 400 replications, wall 460 s, CPU ? s, code 804b3a0"
    records = json.loads((out / study.invocations_file).read_text())
    assert [r["replications_run"] for r in records] == [400, 1, 1]
    assert pd.read_csv(results / "nothing.csv")["note"].tolist() == ["from the run"] * 3
    assert (results / "nothing.png").read_bytes() == b"png"


@pytest.mark.parametrize("workers", [1, 2])
def test_run_in_processes_hands_every_result_to_this_process(workers):
    got: list = []
    scaffold.run_in_processes(operator.mul, [(k, 10) for k in range(5)], workers, got.append)
    assert sorted(got) == [0, 10, 20, 30, 40]
    if workers == 1:
        assert got == [0, 10, 20, 30, 40]  # in this process, in order


def test_fmt_and_paragraph():
    assert scaffold.fmt(float("nan")) == "-" and scaffold.fmt(None) == "-"
    assert scaffold.fmt(0.12345) == "0.123" and scaffold.fmt(2.0, ".1f") == "2.0"
    lines = scaffold.paragraph("a " * 60, width=20)
    assert lines[-1] == "" and len(lines) == 6 + 1 and max(map(len, lines)) <= 20
