"""Planning studies (issue 5): each study's script runs end to end at a tiny size and writes its
table and plot. The full studies are benchmarks (campaigns/studies/results/), not tests.
"""

from __future__ import annotations

import dataclasses
import re

import pytest

pytestmark = pytest.mark.slow

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _check_outputs(directory, stem: str, command: str) -> str:
    text = (directory / f"{stem}.txt").read_text()
    png = (directory / f"{stem}.png").read_bytes()
    assert png.startswith(PNG_MAGIC) and len(png) > 10_000
    lines = text.splitlines()
    head = f"$ python -m campaigns.studies.{stem} "
    assert any(line.startswith(head) and command in line for line in lines)
    assert any(line.startswith("machine: ") for line in lines)
    assert re.search(r"^this invocation: wall \d+ s, CPU \d+ s in its processes and their pool workers, "
                     r"\d+ replications computed",
                     text, re.M)
    assert "Conclusion: " in text and text.rstrip().endswith(".")
    return text


def _keep_metrics(monkeypatch, study) -> list:
    """The metrics the study's own analysis computes (its module's ``collect``), kept for the test:
    what the report and plot were made from, without reading every run a second time."""
    kept = []
    collect = study.collect

    def keep(*args, **kwargs):
        kept.append(collect(*args, **kwargs))
        return kept[-1]

    monkeypatch.setattr(study, "collect", keep)
    return kept


def test_shss_segments_tiny(tmp_path, monkeypatch):
    from campaigns.studies import scaffold
    from campaigns.studies import shss_segments as study

    kept = _keep_metrics(monkeypatch, study)
    out, results = tmp_path / "work", tmp_path / "results"
    argv = ["--out", str(out), "--results", str(results), "--size", "tiny", "--workers", "1"]
    assert study.main(argv) == 0
    text = _check_outputs(results, "shss_segments", "--size tiny")
    config = study.SIZES["tiny"]
    for v in config.variants:  # every variant ran, fitted, and is in the table
        assert (out / "runs" / v.name / "replications" / "r00000.parquet").exists()
        assert re.search(rf"{re.escape(v.label)}\s+1/1\s+0\s", text), v.label
    # the reference split is 1x relative to itself; the bounds of both splits are finite
    assert kept
    metrics = kept[-1]
    assert set(metrics) == set(config.variants)
    names = study.parameter_names(metrics)[1]
    ref = config.variants[-1]
    assert ref.pieces == config.reference_pieces and names
    assert study.relative(metrics[ref], metrics[ref], "crb_mean", names) == pytest.approx(1.0)
    long = study.relative(metrics[config.variants[0]], metrics[ref], "crb_mean", names)
    assert 0.2 < long < 5.0
    for m in metrics.values():
        assert 0.0 < m.accuracy("beta_zsp") < 1.0  # calm air: the side-probe AOSS within its 1 deg
    # the same command again resumes: nothing is recomputed, the table is rebuilt. The figure is
    # the first run's subject (checked above), not the resumption's: this invocation draws none
    mtime = (out / "runs" / ref.name / "replications" / "r00000.parquet").stat().st_mtime_ns
    no_figure = dataclasses.replace(study.STUDY_SPEC, plot=lambda analysis, config, path, n: path)
    assert scaffold.main(no_figure, argv) == 0
    assert (out / "runs" / ref.name / "replications" / "r00000.parquet").stat().st_mtime_ns == mtime
    again = (results / "shss_segments.txt").read_text()
    assert re.search(r"^this invocation: .*, 0 replications computed;", again, re.M), again[:2000]
    assert "over 2 invocations (resumed)" in again
    assert f"{len(config.variants)} replications in all" in again
    assert all(re.search(rf"{re.escape(v.label)}\s+1/1\s+0\s", again) for v in config.variants)


def test_maneuvers_per_bin_tiny(tmp_path, monkeypatch):
    from campaigns.studies import maneuvers_per_bin as study

    kept = _keep_metrics(monkeypatch, study)
    assert study.main(["--out", str(tmp_path), "--size", "tiny", "--workers", "1"]) == 0
    text = _check_outputs(tmp_path, "maneuvers_per_bin", "--size tiny")
    config = study.SIZES["tiny"]
    assert kept
    metrics = kept[-1]
    sets = config.sets
    assert [s.n for s in sets] == list(config.counts)
    for s in sets:
        m = metrics[s]
        assert m.used == 1 and 0.0 < m.vane_stat("accuracy") < 1.0
        assert m.alpha_deg[0] < m.alpha_deg[1]
    # nested sets: more maneuvers cover at least the same alpha range and determine at least the
    # same f1 breakpoints
    small, big = metrics[sets[0]], metrics[sets[-1]]
    assert big.alpha_deg[0] <= small.alpha_deg[0] and big.alpha_deg[1] >= small.alpha_deg[1]
    assert set(study.determined(small, "f1")) <= set(study.determined(big, "f1"))
    for s in sets:
        assert re.search(rf"^\s*{s.world}\s+{s.mach:g}\s+{s.n}\s+1/1\s", text, re.M), s.label
