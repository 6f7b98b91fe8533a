"""The calibration workflow's arithmetic (issue 4): Mach bins, bias apportionment, alpha limit; its
result immutable, written and read back (issue 12)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from estimator.workflow import alpha_limit, apportion, three_sigma


def test_apportionment_of_hand_made_biases():
    # three aircraft; the correction model's bias is +0.2 deg on both vanes, the installation
    # biases (fleet mean zero) are -0.1/+0.3, 0.0/-0.2 and +0.1/-0.1 deg
    model = 0.2
    inst_l = {"A": -0.1, "B": 0.0, "C": 0.1}
    inst_r = {"A": 0.3, "B": -0.2, "C": -0.1}
    left = {a: model + v for a, v in inst_l.items()}
    right = {a: model + v for a, v in inst_r.items()}
    ap = apportion(left, right)
    # (b_l + b_r)/2 per aircraft: 0.3, 0.1, 0.2; fleet mean 0.2 = the model update
    np.testing.assert_allclose(ap["mean_bias"], [0.3, 0.1, 0.2])
    np.testing.assert_allclose(ap["fleet_mean"], 0.2)
    np.testing.assert_allclose(ap["installation_mean"], [0.1, -0.1, 0.0], atol=1e-15)
    np.testing.assert_allclose(ap["installation_left"], list(inst_l.values()), atol=1e-15)
    np.testing.assert_allclose(ap["installation_right"], list(inst_r.values()), atol=1e-15)
    assert ap["std_fleet_mean"].isna().all()  # no covariance given, no deviations invented


def test_apportionment_deviations_follow_the_covariance():
    # independent biases of std s: fleet mean of n aircraft's (l + r)/2 has std s / sqrt(2n);
    # an installation bias b_l - M has variance s^2 (1 - 1/n + 1/(2n)) = s^2 (1 - 1/(2n))
    n, s = 4, 0.01
    ac = [f"a{i}" for i in range(n)]
    ap = apportion(dict.fromkeys(ac, 0.0), dict.fromkeys(ac, 0.0), np.eye(2 * n) * s**2)
    np.testing.assert_allclose(ap["std_fleet_mean"], s / np.sqrt(2 * n))
    np.testing.assert_allclose(ap["std_installation_left"], s * np.sqrt(1 - 1 / (2 * n)))
    np.testing.assert_allclose(ap["std_mean_bias"], s / np.sqrt(2))
    # and against a Monte Carlo of the same arithmetic
    rng = np.random.default_rng(3)
    draws = rng.normal(0.0, s, size=(20000, 2 * n))
    inst = draws[:, :n] - draws.mean(axis=1, keepdims=True)
    assert np.std(inst[:, 0]) == pytest.approx(ap["std_installation_left"].iloc[0], rel=0.03)


def test_apportionment_rejects_mismatched_aircraft():
    with pytest.raises(ValueError, match="same aircraft"):
        apportion({"A": 0.1}, {"B": 0.2})


def test_alpha_limit_is_where_the_error_first_grows_beyond_the_desired_value():
    rng = np.random.default_rng(0)
    alpha = rng.uniform(0.0, 20.0, 40000)
    # 3 sigma 0.15 deg below 12 deg, growing beyond (the nose probe's high-AOA irregularity)
    sigma = np.where(alpha < 12.0, 0.05, 0.05 + 0.2 * (alpha - 12.0))
    err = rng.normal(0.0, sigma)
    bands, limit = alpha_limit(alpha, err, desired_deg=0.5, band_deg=2.0, min_samples=200)
    assert limit == 12.0
    assert bands.loc[bands["alpha_lo_deg"] == 12.0, "passed"].item() is False
    assert three_sigma(np.array([1.0, -1.0])) == pytest.approx(3.0)
    # too few samples in a band: not judged, and no limit at all without judged bands
    bands, limit = alpha_limit(alpha[:50], err[:50], 0.5, 2.0, 200)
    assert limit is None and bands["passed"].isna().all()


def test_assign_bins_leaves_out_varying_mach_and_small_bins():
    from types import SimpleNamespace

    from estimator.workflow import WorkflowOptions, assign_bins

    def man(i, mean, lo, hi, gear=False):
        return SimpleNamespace(id=f"m{i}", aircraft="A", configuration="A",
                               meta={"mach_mean": mean, "mach_min": lo, "mach_max": hi, "gear_down": gear})

    mans = [man(0, 0.51, 0.50, 0.52), man(1, 0.49, 0.47, 0.51), man(2, 0.52, 0.45, 0.60),
            man(3, 0.70, 0.69, 0.71), man(4, 0.31, 0.30, 0.32, True), man(5, 0.48, 0.47, 0.49)]
    df = assign_bins(SimpleNamespace(maneuvers=mans), WorkflowOptions(min_maneuvers=2))
    df = df.set_index("id")
    assert list(df.loc[["m0", "m1", "m5"], "bin"]) == [0.5, 0.5, 0.5] and df.loc["m0", "used"]
    assert not df.loc["m2", "used"] and "varies" in df.loc["m2", "reason"]
    assert not df.loc["m3", "used"] and "only 1" in df.loc["m3", "reason"]
    assert not df.loc["m4", "used"] and "gear-down" in df.loc["m4", "reason"]
    assert isinstance(df, pd.DataFrame)


def test_apportionment_of_one_bias_family_is_the_fleet_mean_split():
    # one vane per aircraft (a UAV fleet): the installation bias is the bias minus the fleet mean
    from estimator.workflow import apportion_biases

    b = {"A": 0.3, "B": 0.1, "C": 0.2}
    ap = apportion_biases({"vane": b}, np.eye(3) * 0.01**2)
    np.testing.assert_allclose(ap["fleet_mean"], 0.2)
    np.testing.assert_allclose(ap["installation_vane"], [0.1, -0.1, 0.0], atol=1e-15)
    np.testing.assert_allclose(ap["installation_mean"], ap["installation_vane"])
    np.testing.assert_allclose(ap["std_fleet_mean"], 0.01 / np.sqrt(3))
    # two families give what the left/right form gives
    two = apportion_biases({"left": b, "right": {"A": 0.1, "B": 0.0, "C": 0.5}})
    pair = apportion(b, {"A": 0.1, "B": 0.0, "C": 0.5})
    pd.testing.assert_frame_equal(two, pair)


def _tejas_raw():
    import tomllib

    from estimator.io.modelset import model_set_path

    with open(model_set_path("tejas"), "rb") as fh:
        return tomllib.load(fh)


@pytest.mark.parametrize("edit, fragments", [
    (lambda r: r["requirements"].update(alpha_zz=r["requirements"].pop("alpha_zr")),
     ["[requirements]", "'alpha_zz' is not a channel", "did you mean 'alpha_zr'"]),
    (lambda r: r["workflow"].update(reference_mac=r["workflow"].pop("reference_mach")),
     ["[workflow]", "'reference_mac'", "did you mean 'reference_mach'"]),
    (lambda r: r["workflow"].update(apportion_biases={"left": "f1"}),
     ["apportion_biases left = 'f1'", "aircraft-scoped"]),
    (lambda r: r["workflow"].update(correction_model=["f1", "f9"]),
     ["correction_model", "'f9' is not a global parameter", "f5"]),
    (lambda r: r["workflow"].update(correction_model=["b_l"]),
     ["correction_model", "'b_l' is not a global parameter"]),
    (lambda r: r["workflow"].pop("alpha_limit_channel"),
     ["low_alpha_only", "alpha_limit_channel"]),
    (lambda r: r["initial_conditions"].update(alpha=["alpha_zl", "alpha_zbb"]),
     ["[initial_conditions] alpha", "'alpha_zbb'", "did you mean 'alpha_zb'"]),
    (lambda r: r["report"].update(time_history="theta"), ["[report] time_history", "list"]),
    (lambda r: r.update(reqirements={}), ["unknown key 'reqirements'", "did you mean 'requirements'"]),
])
def test_model_set_declarations_name_what_is_wrong(edit, fragments):
    from estimator.io.modelset import parse_model_set

    raw = _tejas_raw()
    edit(raw)
    with pytest.raises(ValueError) as info:
        parse_model_set(raw, "my_set.toml")
    msg = str(info.value)
    for frag in ["my_set.toml", *fragments]:
        assert frag in msg, msg


def test_tejas_declarations_reach_the_workflow_through_the_channels():
    from estimator.io.modelset import declarations_of, load_model_set
    from estimator.problem import ChannelSpec

    channels, _ = load_model_set("tejas")
    decl = declarations_of(channels)
    assert decl.reference_mach == 0.5 and decl.apportion == {"left": "b_l", "right": "b_r"}
    assert decl.requirements["beta_znp"].low_alpha_only and decl.alpha_limit_channel == "beta_znp"
    assert decl.initial_conditions.alpha[0] == "alpha_zl"
    # a channel built by hand declares nothing: no Table 2 rows, no apportionment
    plain = ChannelSpec(channels[6].name, channels[6].column, channels[6].model, channels[6].sensor,
                        channels[6].delay, channels[6].recorder, channels[6].unit,
                        channels[6].display_scale, channels[6].display_unit, channels[6].measures)
    assert declarations_of([plain]).requirements == {} and not declarations_of([plain]).apportion
    assert declarations_of([plain, channels[6]]) is decl


# --------------------------------------------------------------------------------------------------
# the workflow's result: immutable, written and read back (issue 12)


@pytest.fixture(scope="module")
def small_workflow(tiny_dataset):
    """The workflow on the shared tiny campaign (one Mach bin of four maneuvers, two aircraft).

    The tests here are about the result's structure (immutability, the JSON round trip, the report's
    captions), not the estimates' accuracy: the Gauss-Newton iterations stop once a step predicts
    less than 0.1 log-likelihood units instead of the default 0.001 (a chi-square change of 0.2: the
    step left is at most sqrt(0.2) = 0.45 Cramér-Rao deviations in any direction). On this small
    problem the default creeps ~80 iterations along the weakly determined initial conditions; 0.1
    takes ~20, with the same verdicts and every table filled (asserted below)."""
    import warnings

    from estimator.io import problem_from_dataset
    from estimator.options import SolverOptions, WorkflowOptions
    from estimator.workflow import run_workflow

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the boom channels have no data in the tiny campaign
        problem = problem_from_dataset(tiny_dataset)
    wf = run_workflow(problem, WorkflowOptions(solver=SolverOptions(decrease_tol=0.1)))
    # every stage a success: Table 2, the installation biases and the figures rest on them
    assert wf.stages and all(st.result.success for st in wf.stages), [st.result.verdict for st in wf.stages]
    assert wf.final and len(wf.installation) and len(wf.accuracy) and wf.notes  # every part filled
    return problem, wf


_TABLES = ("maneuvers", "vane_bias", "installation", "accuracy", "alpha_limit_growth")


def _cannot_change(wf):
    import dataclasses

    with pytest.raises(dataclasses.FrozenInstanceError):
        wf.notes = ()
    # each table read is the caller's own copy: changing it changes nothing in the result
    for name in _TABLES:
        before = getattr(wf, name)
        mine = getattr(wf, name)
        if len(mine.columns):
            mine[mine.columns[0]] = 0
        mine["added"] = 1
        pd.testing.assert_frame_equal(getattr(wf, name), before)
    for seq in ("first", "final", "gear_down", "notes", "findings"):
        assert isinstance(getattr(wf, seq), tuple), seq
    with pytest.raises(TypeError):
        wf.declarations.requirements["alpha_zl"] = None
    with pytest.raises(TypeError):
        wf.declarations.apportion["left"] = "b_r"
    st = wf.final[0]
    with pytest.raises(dataclasses.FrozenInstanceError):
        st.mach = 0.9
    with pytest.raises(ValueError, match="read-only"):
        st.start_values[0] = 0.0
    with pytest.raises(TypeError):
        st.result.R["theta"] = 0.0
    if st.problem is not None:
        ch = next(iter(st.residuals))
        with pytest.raises(TypeError):
            st.residuals[ch] = None
        with pytest.raises(ValueError, match="read-only"):
            st.residuals[ch].z[0] = 0.0


@pytest.mark.slow
def test_a_workflow_result_cannot_be_changed_in_place(small_workflow):
    from dataclasses import replace

    problem, wf = small_workflow
    _cannot_change(wf)
    # replace() with the caller's own frame and list: the result holds read-only copies
    mine, notes = wf.maneuvers, ["a note"]
    copied = replace(wf, maneuvers=mine, notes=notes)
    mine.loc[0, "used"] = not mine.loc[0, "used"]
    notes.append("another")
    assert copied.maneuvers.loc[0, "used"] == wf.maneuvers.loc[0, "used"] and copied.notes == ("a note",)
    _cannot_change(copied)


@pytest.mark.slow
def test_a_calibration_cannot_be_changed_in_place(small_workflow):
    import dataclasses

    from estimator.calibration import Calibration, CalibrationOptions

    problem, wf = small_workflow
    cal = Calibration(problem, CalibrationOptions(plots=False), wf)
    table = cal.to_pandas("maneuvers")
    table.loc[0, "id"] = "changed"
    assert cal.to_pandas("maneuvers").loc[0, "id"] != "changed"
    assert all(cal.tables()["table2_model"].equals(cal.to_pandas("table2")) for _ in range(2))
    with pytest.raises(TypeError):
        cal._tables["maneuvers"] = None  # noqa: SLF001 - its store is read-only too
    with pytest.raises(dataclasses.FrozenInstanceError):
        cal.workflow = wf
    _cannot_change(cal.workflow)


@pytest.mark.slow
def test_from_json_gives_back_the_workflow_result(small_workflow, tmp_path):
    from estimator.workflow import JSON_FORMAT, WorkflowResult

    problem, wf = small_workflow
    wf.to_json(tmp_path / "workflow.json")
    assert JSON_FORMAT == "fpr-workflow-result/1"
    assert json.loads((tmp_path / "workflow.json").read_text())["format"] == JSON_FORMAT
    back = WorkflowResult.from_json(tmp_path / "workflow.json", problem)
    for name in _TABLES:
        pd.testing.assert_frame_equal(getattr(back, name), getattr(wf, name), check_exact=True)
    assert (back.notes, back.findings, back.declarations, back.verdict, back.elapsed_s, back.alpha_limit_deg,
            back.reference_mach) == (wf.notes, wf.findings, wf.declarations, wf.verdict, wf.elapsed_s,
                                     wf.alpha_limit_deg, wf.reference_mach)
    assert len(back.stages) == len(wf.stages)
    for a, b in zip(wf.stages, back.stages, strict=True):
        assert (a.name, a.mach, a.gear_down, a.maneuver_ids) == (b.name, b.mach, b.gear_down, b.maneuver_ids)
        pd.testing.assert_frame_equal(b.result.to_pandas(), a.result.to_pandas())
        assert b.result.verdict is a.result.verdict and b.result.findings == a.result.findings
        # the stage's problem rebuilt from the workflow's: the same parameters, the same residuals
        assert b.problem.parameters == a.problem.parameters
        assert [m.id for m in b.problem.maneuvers] == [m.id for m in a.problem.maneuvers]
        assert b.residuals.keys() == a.residuals.keys()
        for ch, r in a.residuals.items():
            np.testing.assert_array_equal(b.residuals[ch].e, r.e)
    pd.testing.assert_frame_equal(back.table_updates(), wf.table_updates())
    _cannot_change(back)
    # written again, the same file
    back.to_json(tmp_path / "again.json")
    assert (tmp_path / "again.json").read_text() == (tmp_path / "workflow.json").read_text()

    # without the problem: every table and result, no data behind the stages
    bare = WorkflowResult.from_json(tmp_path / "workflow.json")
    assert all(st.problem is None for st in bare.stages)
    pd.testing.assert_frame_equal(bare.table_updates(), wf.table_updates())
    with pytest.raises(ValueError, match=r"from_json\(path, problem\)"):
        bare.final[0].residuals  # noqa: B018
    bare.to_json(tmp_path / "bare.json")
    assert (tmp_path / "bare.json").read_text() == (tmp_path / "workflow.json").read_text()


@pytest.mark.slow
def test_from_json_refuses_what_is_not_a_workflow_result(small_workflow, tmp_path):
    from estimator.io import subproblem
    from estimator.workflow import WorkflowResult

    problem, wf = small_workflow
    (tmp_path / "broken.json").write_text("{ not json")
    with pytest.raises(ValueError, match=r"broken\.json: not JSON"):
        WorkflowResult.from_json(tmp_path / "broken.json")
    (tmp_path / "result.json").write_text(json.dumps({"format": "fpr-estimation-result/2"}))
    with pytest.raises(ValueError, match=r"result\.json: format 'fpr-estimation-result/2'.*WorkflowResult"):
        WorkflowResult.from_json(tmp_path / "result.json")
    wf.to_json(tmp_path / "workflow.json")
    doc = json.loads((tmp_path / "workflow.json").read_text())
    del doc["tables"]
    (tmp_path / "cut.json").write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=r"cut\.json: not a readable workflow result.*tables"):
        WorkflowResult.from_json(tmp_path / "cut.json")
    # another problem (one aircraft's maneuvers only): its parameters are not the stages'
    first = problem.maneuvers[0].aircraft
    one = subproblem(problem, [m.id for m in problem.maneuvers if m.aircraft == first])
    with pytest.raises(ValueError, match="give the problem the workflow ran on"):
        WorkflowResult.from_json(tmp_path / "workflow.json", one)


@pytest.mark.slow
def test_fig7_says_why_there_is_no_usable_alpha_range(small_workflow, tmp_path):
    """The nose probe's Fig. 7 caption gives its usable alpha limit, and where there is none it
    says why (it said "alpha = None deg" on the demo's turbulent block, whose lowest band misses
    the accuracy in the model residuals): the lowest judged band misses, or no band is judged."""
    from dataclasses import replace

    from estimator.calibration import build_report

    problem, wf = small_workflow
    g = wf.alpha_limit_growth
    # the caption is the subject, not the other figures: the model set's [report] cross-plots
    # (Fig. 5) and time history (Fig. 3) are declared empty, so each report draws Figs. 4 and 7 only
    # (Fig. 7 rests on the alpha-limit channel and the growth table, neither of them changed)
    wf = replace(wf, declarations=replace(wf.declarations, crossplots=(), time_history=()))
    assert wf.declarations.alpha_limit_channel in wf.final[0].residuals
    captions = {}
    for case, growth, limit in (
            ("limit", g.assign(passed=True), 12.0),
            ("misses", g.assign(passed=[False] + [True] * (len(g) - 1)), None),
            ("unjudged", g.assign(passed=None), None)):
        html = build_report(replace(wf, alpha_limit_growth=growth, alpha_limit_deg=limit),
                            tmp_path / case, case)["report"].read_text()
        (captions[case],) = [c for c in html.split('"') if c.startswith("Fig. 7:")]
    assert captions["limit"].endswith("its usable range ends at alpha = 12 deg")
    assert captions["misses"].endswith("its lowest judged alpha band already misses the desired accuracy")
    assert captions["unjudged"].endswith("no alpha band has enough samples to be judged")
    assert not any("None" in c for c in captions.values())
