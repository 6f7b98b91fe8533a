"""The results API (issue 12): the status enum, results read back from JSON, immutable results, and
the public API of ``import estimator``.

- ``Status`` follows scipy's rule: a positive status is a success, zero or negative is not; every
  member carries its message; the values written to files never change.
- ``EstimationResult.from_json`` gives back what ``to_json`` wrote: values, deviations,
  correlations, verdict, findings, status, parameter states, residuals, fit quality, outliers;
  written again, the file is byte-identical. A file written before the format was named reads too.
- A result cannot be changed in place, however it was made (``build``, ``replace``, the
  constructor, ``from_json``).
- ``from estimator import ...`` gives the public API, loaded on first use: ``import estimator``
  loads neither NumPy, pandas, SciPy, numba nor the solver.

The estimation is test_identifiability's ``bounded`` case (analytic flight, white noise): a
parameter on its bound, held ones, an unidentifiable set, warnings — every state a result can hold.
"""

from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from test_identifiability import NOISE, _with_bounds

import estimator
from campaigns.analytic_flight import DEG, Flight
from campaigns.analytic_flight import truth_values as _truth_values
from estimator.io.modelset import load_model_set
from estimator.parameters import ParameterSet, ParameterSpec
from estimator.result import JSON_FORMAT, STATUS_TEXT, EstimationResult, ReadOnlyTable
from estimator.solver import SolverOptions, estimate
from estimator.verdict import Finding, Severity, Status, Verdict, judge


# ------------------------------------------------------------------------------------ the status
def test_status_success_is_positive_and_every_member_carries_its_message():
    for s in Status:
        assert s.success == s.converged == (s.value > 0), s
        assert s.message.startswith("converged" if s.success else ("not converged", "failed")), s
        assert STATUS_TEXT[s.value] == s.label == s.name.lower().replace("_", " ")
    # the failures of the iteration are not successes (scipy: 0 is its iteration limit)
    assert not any(s.success for s in (Status.ITERATION_LIMIT, Status.STALLED, Status.MODEL_ERROR,
                                       Status.UNDETERMINED))
    assert judge(Status.STALLED, ()) == Verdict.FAILURE
    assert judge(Status.CONVERGED_DECREASE, ()) == Verdict.SUCCESS


def test_status_values_written_to_files_are_stable():
    # result.json, the Monte Carlo replications and the studies' tables store these integers
    assert {s.name: s.value for s in Status} == {
        "CONVERGED_STEP": 1, "CONVERGED_DECREASE": 2, "ITERATION_LIMIT": 0, "STALLED": -2,
        "MODEL_ERROR": -3, "UNDETERMINED": -4}
    assert Status(2) is Status.CONVERGED_DECREASE and Status(-2) is Status.STALLED


def test_verdict_success_is_positive():
    for v in Verdict:
        assert v.success == (v.code > 0) and v.message == v.text


# ------------------------------------------------------------------------------------ a result
@pytest.fixture(scope="module")
def result():
    _, specs = load_model_set("tejas")
    flight = Flight(_truth_values(np.random.default_rng(5)), specs)
    prob = flight.problem(noise=NOISE, rng=np.random.default_rng(4))
    prob = _with_bounds(prob, "b_l", (-0.1 * DEG, 0.1 * DEG))
    ps = prob.parameters
    params = tuple(replace(p, free=True) if p.key == "f1[2]" else p for p in ps)
    prob = replace(prob, parameters=ParameterSet(params, ps.specs))
    res = estimate(prob, SolverOptions())
    # outliers as the diagnostics would report them (this clean flight has none)
    res = replace(res, outliers={(prob.maneuvers[0].id, "alpha_zl"): [1.25, 7.5]})
    states = set(res.state)
    assert {"estimated", "held", "on_bound"} <= states, states
    assert res.fit_quality is not None and res.imu_noise_psd is not None and res.findings
    return res


def _same(a, b):
    """Arrays equal, NaN where NaN, dtype aside."""
    if a is None or b is None:
        return a is None and b is None
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and bool(np.all((a == b) | (pd.isna(a) & pd.isna(b))))


@pytest.mark.slow
def test_from_json_gives_back_the_result(result, tmp_path):
    result.to_json(tmp_path / "result.json")
    back = EstimationResult.from_json(tmp_path / "result.json")
    # values, deviations, correlations
    assert back.parameters.parameters == result.parameters.parameters
    assert dict(back.parameters.specs) == dict(result.parameters.specs)
    for a in ("std_crb", "std_colored", "correlation", "correlation_colored", "std_imu_noise",
              "free_estimated"):
        assert _same(getattr(back, a), getattr(result, a)), a
    assert back.correlation_keys == result.correlation_keys
    # the verdict, its findings, the status, each parameter's state and reason
    assert back.verdict is result.verdict and back.status is result.status
    assert back.findings == result.findings
    assert back.state == result.state and back.state_reason == result.state_reason
    assert (back.message, back.iterations, back.cost_history, back.confounding, back.source,
            back.g_mps2, back.elapsed_s) == (result.message, result.iterations, result.cost_history,
                                             result.confounding, result.source, result.g_mps2,
                                             result.elapsed_s)
    # residuals, noise, fit quality, outliers, display units
    assert dict(back.R) == dict(result.R) and back.channel_display == result.channel_display
    assert len(back.residuals) == len(result.residuals)
    assert all(_same(dataclasses.astuple(x), dataclasses.astuple(y))
               for x, y in zip(back.residuals, result.residuals, strict=True))
    assert back.imu_noise_psd.keys() == result.imu_noise_psd.keys()
    assert all(_same(back.imu_noise_psd[k], v) for k, v in result.imu_noise_psd.items())
    assert back.outliers.keys() == result.outliers.keys()
    assert all(_same(back.outliers[k], v) for k, v in result.outliers.items())
    pd.testing.assert_frame_equal(back.diagnostics, result.diagnostics)
    # every table and the summary as they were; written again, the same file
    pd.testing.assert_frame_equal(back.to_pandas(), result.to_pandas())
    pd.testing.assert_frame_equal(back.residuals_table(), result.residuals_table())
    pd.testing.assert_frame_equal(back.findings_table(), result.findings_table())
    assert back.summary() == result.summary()
    assert _same(back.covariance(["b_r[AC1]", "tau_alpha_zl"], colored=True),
                 result.covariance(["b_r[AC1]", "tau_alpha_zl"], colored=True))
    back.to_json(tmp_path / "again.json")
    assert (tmp_path / "again.json").read_text() == (tmp_path / "result.json").read_text()


def test_from_json_reads_a_file_written_before_the_format_was_named(result, tmp_path):
    result.to_json(tmp_path / "result.json")
    doc = json.loads((tmp_path / "result.json").read_text())
    for k in ("format", "fit_quality_columns", "state", "state_reason", "free_estimated", "std_imu_noise",
              "channel_display", "outliers", "parameter_specs"):
        del doc[k]
    for f in doc["findings"]:
        del f["index"]
    for row in doc["parameters"]:
        del row["bounds"], row["display_scale"]
        row["element"] = None if row["element"] is None else float(row["element"])  # as pandas wrote it
    (tmp_path / "old.json").write_text(json.dumps(doc))
    back = EstimationResult.from_json(tmp_path / "old.json")
    pd.testing.assert_frame_equal(back.to_pandas(), result.to_pandas())
    pd.testing.assert_frame_equal(back.diagnostics, result.diagnostics)
    assert back.verdict is result.verdict and back.status is result.status
    assert back.findings == tuple(sorted(result.findings, key=lambda f: -int(f.severity)))  # the file's order
    scale = [p.display_scale for p in result.parameters]
    assert [p.display_scale for p in back.parameters] == pytest.approx(scale)
    assert all(p.bounds == (-math.inf, math.inf) for p in back.parameters) and not back.parameters.specs


def test_from_json_refuses_what_is_not_a_result(result, tmp_path):
    (tmp_path / "broken.json").write_text("{ not json")
    with pytest.raises(ValueError, match=r"broken\.json: not JSON"):
        EstimationResult.from_json(tmp_path / "broken.json")
    (tmp_path / "other.json").write_text(json.dumps({"verdict": "SUCCESS"}))
    with pytest.raises(ValueError, match=r"other\.json: not an estimation result \(no status, parameters"):
        EstimationResult.from_json(tmp_path / "other.json")
    result.to_json(tmp_path / "future.json")
    doc = json.loads((tmp_path / "future.json").read_text())
    assert doc["format"] == JSON_FORMAT
    doc["format"] = "fpr-estimation-result/99"
    (tmp_path / "future.json").write_text(json.dumps(doc))
    with pytest.raises(ValueError, match="format 'fpr-estimation-result/99'"):
        EstimationResult.from_json(tmp_path / "future.json")
    doc["format"], doc["status"] = JSON_FORMAT, 7
    (tmp_path / "status.json").write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=r"status\.json: not a readable estimation result.*7"):
        EstimationResult.from_json(tmp_path / "status.json")


def test_finding_round_trips_through_its_dict():
    f = Finding("outlier", Severity.WARNING, "a spike", "look at it", channel="alpha_zl", maneuver="m1",
                t_s=[1.5, 2.0], parameters=["b_l[PV1]"], value=4.0)
    assert f.t_s == (1.5, 2.0) and f.parameters == ("b_l[PV1]",)  # the caller's lists became tuples
    assert Finding.from_dict(json.loads(json.dumps(f.to_dict()))) == f


# ------------------------------------------------------------------------------------ immutability
def _cannot_change(result):
    key = next(iter(result.R))
    with pytest.raises(TypeError):
        result.R[key] = 0.0
    for name in ("std_crb", "std_colored", "std_imu_noise", "free_estimated"):
        with pytest.raises(ValueError, match="read-only"):
            getattr(result, name)[0] = 0
    with pytest.raises(ValueError, match="read-only"):
        result.correlation[0, 0] = 0.5
    with pytest.raises(ValueError, match="read-only"):
        result.correlation_colored[0, 0] = 0.5
    with pytest.raises(dataclasses.FrozenInstanceError):
        result.status = Status.CONVERGED_STEP
    with pytest.raises(TypeError):
        result.channel_display["alpha_zl"] = (1.0, "rad")
    k = next(iter(result.outliers))
    with pytest.raises(ValueError, match="read-only"):
        result.outliers[k][0] = 0.0
    with pytest.raises(TypeError):
        result.outliers[("m", "c")] = np.zeros(1)
    a = next(iter(result.imu_noise_psd))
    with pytest.raises(ValueError, match="read-only"):
        result.imu_noise_psd[a][0] = 0.0
    with pytest.raises(TypeError):
        result.parameters.specs["b_l"] = None
    with pytest.raises(TypeError):
        result.parameters.specs["b_l"].per_instance["AC1"] = 0.0
    with pytest.raises(ValueError, match="read-only"):
        result.fit_quality.data[result.fit_quality.columns.index("rms")][0] = 0.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        result.findings[0].message = "nothing"
    # what a caller is handed is its own to change
    diag = result.diagnostics
    diag.loc[:, "rms"] = -1.0
    assert (result.diagnostics["rms"] > 0).all()
    values = result.values
    values[:] = 0.0
    assert np.any(result.values != 0.0)
    for seq in ("residuals", "cost_history", "findings", "state", "state_reason", "confounding",
                "correlation_keys"):
        assert isinstance(getattr(result, seq), tuple), seq


def test_a_result_cannot_be_changed_in_place(result):
    _cannot_change(result)


def test_a_result_read_back_or_copied_cannot_be_changed_either(result, tmp_path):
    result.to_json(tmp_path / "result.json")
    _cannot_change(EstimationResult.from_json(tmp_path / "result.json"))
    # replace() with the caller's own arrays and dicts: the result holds read-only copies
    mine = np.ones(len(result.parameters))
    R = dict(result.R)
    copied = replace(result, std_crb=mine, R=R, fit_quality=result.diagnostics)
    _cannot_change(copied)
    mine[0], R["x"] = 2.0, 1.0  # the caller's stay writable and change nothing in the result
    assert copied.std_crb[0] == 1.0 and "x" not in copied.R
    assert isinstance(copied.fit_quality, ReadOnlyTable)


def test_a_parameter_spec_is_immutable_and_names_a_bad_value():
    values = {"PV1": [0.0, 1.0]}
    s = ParameterSpec("f9", "rad", value=np.zeros(2), breakpoints=np.array([0.0, 1.0]), scope="aircraft",
                      per_instance=values)
    values["PV1"][0] = 5.0
    assert s.per_instance["PV1"] == (0.0, 1.0) and s.value == (0.0, 0.0) and s.breakpoints == (0.0, 1.0)
    with pytest.raises(ValueError, match="parameter f9: value 'abc' is not a number"):
        ParameterSpec("f9", "rad", value="abc")


# ------------------------------------------------------------------------------------ the public API
def test_the_public_api_is_importable_from_the_package():
    assert sorted(estimator.__all__) == sorted(estimator._API)
    for name in estimator.__all__:
        assert getattr(estimator, name) is not None, name
    from estimator.io import load_problem
    from estimator.workflow import run_workflow
    assert estimator.load_problem is load_problem and estimator.run_workflow is run_workflow
    assert estimator.EstimationResult is EstimationResult and estimator.Status is Status
    with pytest.raises(AttributeError, match="no attribute 'nothing_here'"):
        estimator.nothing_here  # noqa: B018
    assert set(estimator.__all__) <= set(dir(estimator))


def test_import_estimator_is_light():
    # the names load on first use: importing the package loads neither numba nor the solver
    code = ("import sys, estimator; print([m for m in ('numpy', 'numba', 'scipy', 'pandas', "
            "'estimator.solver') if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr


# ------------------------------------------------------------------------------------ as plain values
def test_a_result_goes_to_plain_values_and_back(result):
    doc = result.to_dict()
    assert json.loads(json.dumps(doc, allow_nan=False)) == doc  # strict JSON already
    back = EstimationResult.from_dict(doc)
    assert back.to_dict() == doc
    pd.testing.assert_frame_equal(back.to_pandas(), result.to_pandas())


def test_a_read_only_table_keeps_its_index_dtypes_and_missing_values():
    frame = pd.DataFrame({"mach": [0.5, np.nan], "passed": [True, None],
                          "n": np.array([3, 4], dtype=np.int64), "ok": [True, False],
                          "aircraft": ["PV1", None]}, index=pd.Index(["a", "b"], name="aircraft_id"))
    frame.columns.name = "column"
    table = ReadOnlyTable.of(frame, keep_index=True)
    pd.testing.assert_frame_equal(table.to_pandas(), frame, check_exact=True)
    back = ReadOnlyTable.from_dict(json.loads(json.dumps(table.to_dict(), allow_nan=False)))
    pd.testing.assert_frame_equal(back.to_pandas(), frame, check_exact=True)
    with pytest.raises(ValueError, match="read-only"):
        back.data[0][0] = 1.0
    with pytest.raises(ValueError, match="read-only"):
        table.index[0][0] = "c"
    mine = table.to_pandas()  # the caller's to change
    mine.loc["a", "mach"] = 9.0
    assert table.to_pandas().loc["a", "mach"] == 0.5
    # without keep_index (a result's fit-quality table) the index is the default one
    assert ReadOnlyTable.of(frame).to_pandas().index.equals(pd.RangeIndex(2))
