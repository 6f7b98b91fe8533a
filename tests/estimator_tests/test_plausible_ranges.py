"""Plausible ranges declared for the aircraft (``[plausible]`` in the model set or the problem file).

The import's unit checks (estimator/io/plausibility.py) know a fighter's and an airliner's ranges:
a median true airspeed of 15 to 700 m/s. A 12 m/s UAV's airspeed is then refused as "cannot be a
true airspeed" although it is one; the message says how to declare the aircraft's range, and a
declared range replaces the built-in one (wider or narrower), from the model set or the problem
file (the problem file's wins).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from campaigns.benchmarks.user_files import USER_COLUMNS, write_user_files
from estimator.io import load_problem
from estimator.io.errors import DataError, Where
from estimator.io.modelset import MODELS_DIR
from estimator.io.plausibility import check_plausible, check_zero_dropouts, parse_ranges

WHERE = Where("uav.csv", "leg1")


def _uav_airspeed(n: int = 500) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(n) * 0.02
    return t, 12.0 + 0.5 * np.sin(t)


def test_a_slow_uav_airspeed_is_refused_by_default_with_the_fix_named():
    t, v = _uav_airspeed()
    with pytest.raises(DataError, match=r"cannot be a true airspeed.*declare the range under \[plausible\]"):
        check_plausible("tas", "tas (column 'IAS')", v, "m/s", t, np.arange(t.size), WHERE)


def test_a_declared_range_replaces_the_built_in_one():
    t, v = _uav_airspeed()
    ranges = parse_ranges({"tas": {"range": [10.0, 80.0], "unit": "kt"}}, "test")
    assert ranges["tas"][:2] == pytest.approx((10.0 * 1852 / 3600, 80.0 * 1852 / 3600))
    assert ranges["tas"][2] == "speed"
    check_plausible("tas", "tas", v, "m/s", t, np.arange(t.size), WHERE, ranges)  # 23 kt: plausible
    with pytest.raises(DataError, match=r"cannot be a true airspeed.*outside the range declared for it"):
        check_plausible("tas", "tas", np.full(t.size, 150.0), "m/s", t, np.arange(t.size), WHERE, ranges)
    with pytest.raises(DataError, match=r"is in speed units, the column in 'deg' \(angle\)"):
        check_plausible("tas", "tas", v, "deg", t, np.arange(t.size), WHERE, ranges)


def test_an_angle_or_rate_range_bounds_its_largest_magnitude():
    t = np.arange(500) * 0.02
    p = np.radians(400.0) * np.sin(t)  # an agile UAV rolling at 400 deg/s
    with pytest.raises(DataError, match=r"\[plausible\]"):
        check_plausible("p", "p", p, "rad/s", t, np.arange(t.size), WHERE)
    ranges = parse_ranges({"p": {"range": [-500.0, 450.0], "unit": "deg/s"}}, "test")
    check_plausible("p", "p", p, "rad/s", t, np.arange(t.size), WHERE, ranges)  # |p| <= 500 deg/s


@pytest.mark.parametrize("bad", [{"tas": [5, 40]}, {"tas": {"range": [40, 5], "unit": "m/s"}},
                                 {"tas": {"range": [5, 40], "unit": "furlong"}},
                                 {"tas": {"range": [5, float("inf")], "unit": "m/s"}},
                                 {"t": {"range": [0, 1], "unit": "s"}},
                                 {"az": {"range": [0, 100], "unit": "m/s^2"}},
                                 {"airspeed": {"range": [5, 40], "unit": "m/s"}}])
def test_a_malformed_range_is_named(bad):
    with pytest.raises(DataError, match=r"\[plausible\] (tas|t|az|airspeed)|unknown unit"):
        parse_ranges(bad, "problem.toml", names=["tas", "h", "accel"])


def test_the_problem_file_and_the_model_set_declare_ranges(tiny_dataset, tmp_path):
    cols = {k: USER_COLUMNS[k] for k in ("ax", "ay", "az", "p", "q", "r", "phi", "theta", "psi", "tas", "h")}
    channels = ["phi", "theta", "psi", "tas", "h"]
    problem = write_user_files(tiny_dataset, tmp_path / "u", cols, channels, "ranges")
    text = problem.read_text()
    narrow = '\n[plausible]\ntas = { range = [5.0, 60.0], unit = "kt" }\n'
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        load_problem(problem)  # the tiny campaign's ~300 kt: plausible by default
        problem.write_text(text + narrow)
        with pytest.raises(DataError, match=r"cannot be a true airspeed \(plausible: 2.572 to 30.87"):
            load_problem(problem)
        # the same range from a model set of one's own; the problem file's own range wins over it
        model = tmp_path / "u" / "narrow.toml"
        model.write_text((MODELS_DIR / "tejas.toml").read_text() + narrow)
        problem.write_text(text.replace('model = "tejas"', 'model = "narrow.toml"'))
        with pytest.raises(DataError, match="cannot be a true airspeed"):
            load_problem(problem)
        problem.write_text(text.replace('model = "tejas"', 'model = "narrow.toml"')
                           + '\n[plausible]\ntas = { range = [50.0, 900.0], unit = "kt" }\n')
        load_problem(problem)


def test_a_dropout_written_as_zero_is_named_whatever_the_column():
    t = np.arange(500) * 0.02
    for unit, v in (("m/s", 17.0 + 0.5 * np.sin(t)), ("kPa", 0.16 + 0.01 * np.sin(t)),
                    ("deg", 3.0 + np.sin(t))):
        v = v.copy()
        v[[200, 201]] = 0.0  # a sample-and-hold that lost its input for two samples
        with pytest.raises(DataError, match=r"exactly 0 at t = 4.000 s .*2 sample\(s\).*written as zero"):
            check_zero_dropouts(v, unit, t, np.arange(t.size), WHERE, "x (column 'X')")
    # a signal passing through 0 (a sideslip, one sample exactly 0) steps there as elsewhere: no dropout
    beta = np.round(np.sin(t), 2)
    assert (beta == 0.0).any()
    check_zero_dropouts(beta, "deg", t, np.arange(t.size), WHERE, "beta")
    check_zero_dropouts(np.r_[np.ones(10), 0.0, np.ones(10)], "1", t[:21], np.arange(21), WHERE, "gear")
    # a pitch rate crossing 0 steeply in a doublet (quiet elsewhere): a crossing, not a dropout
    quiet = 1e-4 * np.random.default_rng(5).normal(size=400)
    q = np.r_[quiet[:200], -0.0063, 0.0, 0.0054, quiet[200:]]
    check_zero_dropouts(q, "rad/s", np.arange(q.size) * 0.025, np.arange(q.size), WHERE, "q")
