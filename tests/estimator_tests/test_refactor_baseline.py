"""The estimator's numbers, pinned: a refactor of :mod:`estimator` must not change a single one.

Three fast fits on analytic flights (:class:`campaigns.analytic_flight.Flight`, as in
``test_estimator.py`` and ``test_filter_error.py``) were recorded on main before the estimator's
modules were reorganised, into ``refactor_baseline.json`` beside this file:

- ``output_error``: white noise, a poor start, the default options (staged start, diagnostics,
  coloured deviations, the IMU noise estimated);
- ``filter_error``: light turbulence (1 m/s, 25 s), the filter-error method from the staged start;
- ``output_error_robust``: the same turbulent data by the output-error method with ``robust``
  (the outliers excluded and the estimation repeated).

Each estimate, Cramér-Rao deviation, the cost history, the residual statistics, the status, the
verdict and every finding (code, severity, message) must agree: the cost within 1e-12 relative,
the Cramér-Rao deviations within 1e-9, the estimates within 1e-9 of them and the residuals' mean,
std and rms within 1e-9 of the channel's rms (a number near zero carries the round-off of its
scale, not of itself), everything else equal. The honest deviations (coloured, IMU noise) and the
correlations' row sums within 1e-9 relative (the IMU noise's share: 1e-9 of the honest deviation it
is part of): their spectral sums may be ordered and factored for speed, which moves the last
digits, never more.

Marked slow (three estimations, about ten seconds): run it alone after each change of the estimator,
``python -m pytest -q tests/estimator_tests/test_refactor_baseline.py``. Regenerate (only for a
deliberate change of the numbers): ``python tests/estimator_tests/test_refactor_baseline.py``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

BASELINE = Path(__file__).with_name("refactor_baseline.json")
#: On the machine that pinned them the numbers agree exactly (checked at the end of the refactor);
#: 1e-12 leaves room for another machine's compiled kernels (vector widths, fused multiply-adds)
#: and for the honest deviations' sums whose order follows the worker threads, not for a change
RTOL = 1e-12
#: ... of what a number's round-off scales with, where it can be near zero: an estimate's deviation
#: (an IMU bias of 2e-5 m/s^2 moved 5e-14 on a host without AVX-512: 2e-11 of itself, 3e-11 of its
#: deviation), a residual mean's channel rms (a mean near zero moved 7 % of itself on that host)
RTOL_OF_SCALE = 1e-9
#: The honest deviations' sums over frequencies and channels: summed in another order, or with another
#: factor of a cross-spectral matrix (Cholesky or eigenvectors: the same product), the low-power
#: frequencies' round-off (relative 1e-16 of the whole band's power) moves them by up to 1e-10
RTOL_HONEST = 1e-9


def _fits() -> dict[str, object]:
    """name -> EstimationResult of each pinned fit."""
    from campaigns.analytic_flight import NOISE_SIGMA, Flight, poor_start, truth_values
    from estimator.io.modelset import load_model_set
    from estimator.solver import SolverOptions, estimate

    specs = load_model_set("tejas")[1]
    white = Flight(truth_values(np.random.default_rng(5)), specs)
    prob = white.problem(start=poor_start, noise=NOISE_SIGMA, rng=np.random.default_rng(11))
    turbulent = Flight(truth_values(np.random.default_rng(5)), specs, T=25.0, turbulence=(1.0, 533.4, 7))
    tprob = turbulent.problem(noise=NOISE_SIGMA, rng=np.random.default_rng(3))
    return {
        "output_error": estimate(prob, SolverOptions()),
        "filter_error": estimate(tprob, SolverOptions(method="filter_error")),
        "output_error_robust": estimate(tprob, SolverOptions(robust=True)),
    }


def _floats(a) -> list[float | None]:
    return [None if a is None else float(x) for x in np.asarray(a, dtype=float).ravel()] \
        if a is not None else []


def record(res) -> dict:
    """What a fit is pinned by (plain JSON: floats written exactly, NaN as NaN)."""
    corr = np.asarray(res.correlation, dtype=float)
    return {
        "keys": list(res.parameters.keys),
        "values": _floats(res.parameters.values),
        "std_crb": _floats(res.std_crb),
        "std_colored": _floats(res.std_colored),
        "std_imu_noise": _floats(res.std_imu_noise),
        "correlation_keys": list(res.correlation_keys),
        "correlation_row_sums": _floats(np.abs(corr).sum(axis=1) if corr.size else []),
        "free_estimated": [bool(b) for b in (res.free_estimated if res.free_estimated is not None else [])],
        "iterations": int(res.iterations),
        "cost_history": _floats(res.cost_history),
        "residuals": [[r.maneuver, r.channel, int(r.n), float(r.mean), float(r.std), float(r.rms)]
                      for r in res.residuals],
        "status": res.status.name,
        "verdict": res.verdict.name,
        "state": list(res.state),
        "confounding": [[list(c.parameters), c.kind, c.detail] for c in res.confounding],
        "findings": [[f.code, f.severity.name, f.message] for f in res.findings],
    }


def _array(values: list) -> np.ndarray:
    return np.array([math.nan if x is None else x for x in values], dtype=float)


def _same_numbers(got: list, want: list, what: str, rtol: float = RTOL, scale: list | None = None) -> None:
    """``got`` equals ``want`` within ``rtol`` relative (of ``scale``'s numbers where given)."""
    assert len(got) == len(want), f"{what}: {len(got)} numbers, {len(want)} pinned"
    g, w = _array(got), _array(want)
    if scale is None:
        np.testing.assert_allclose(g, w, rtol=rtol, atol=0.0, equal_nan=True, err_msg=what)
    else:
        assert np.array_equal(np.isnan(g), np.isnan(w)), what
        off = np.abs(g - w)[~np.isnan(w)] / np.abs(_array(scale))[~np.isnan(w)]
        assert off.size == 0 or off.max() <= rtol, f"{what}: {off.max():.2e} of its scale"


@pytest.fixture(scope="module")
def recorded() -> dict:
    return {name: record(res) for name, res in _fits().items()}


@pytest.fixture(scope="module")
def pinned() -> dict:
    return json.loads(BASELINE.read_text(encoding="utf-8"))


@pytest.mark.slow
@pytest.mark.parametrize("name", ["output_error", "filter_error", "output_error_robust"])
def test_the_numbers_are_the_pinned_ones(recorded, pinned, name):
    got, want = recorded[name], pinned[name]
    assert set(got) == set(want)
    for field, value in want.items():
        if field == "values":
            # a parameter without a deviation (fixed, unidentifiable): of itself, or 1 where it is 0
            scale = [s if s is not None and math.isfinite(s) and s > 0 else (abs(v) or 1.0)
                     for s, v in zip(want["std_crb"], value, strict=True)]
            _same_numbers(got[field], value, f"{name}.{field}", RTOL_OF_SCALE, scale=scale)
        elif field == "std_crb":  # the filter-error method's filter sums: 6e-12 on that host
            _same_numbers(got[field], value, f"{name}.{field}", RTOL_OF_SCALE)
        elif field == "cost_history":
            _same_numbers(got[field], value, f"{name}.{field}")
        elif field in ("std_colored", "correlation_row_sums"):
            _same_numbers(got[field], value, f"{name}.{field}", RTOL_HONEST)
        elif field == "std_imu_noise":
            _same_numbers(got[field], value, f"{name}.{field}", RTOL_HONEST, scale=want["std_colored"])
        elif field == "residuals":
            assert [r[:3] for r in got[field]] == [r[:3] for r in value], f"{name}.residuals"
            # mean, std and rms, each against the channel's rms (1 where it is 0: all three are)
            rms = [r[5] or 1.0 for r in value for _ in r[3:]]
            _same_numbers([x for r in got[field] for x in r[3:]], [x for r in value for x in r[3:]],
                          f"{name}.residuals", RTOL_OF_SCALE, scale=rms)
        else:
            assert got[field] == value, f"{name}.{field}"


if __name__ == "__main__":
    doc = {name: record(res) for name, res in _fits().items()}
    BASELINE.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    print(f"wrote {BASELINE}")
