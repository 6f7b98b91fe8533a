"""Planning study (b): how many maneuvers per Mach bin reach the vane AOA requirement (±0.5 deg 3-sigma)?

One aircraft (PV1 with the nose probe) flies the first N maneuvers of a realistic mix
(:data:`MIX`: pitch doublet, wind-up turn, pull-up with rudder doublets, 3211, roller coaster,
pull-up/push-over, then the same again on other headings) at one Mach number, N = 1, 2, 4, 8, 16;
the sets are nested (N = 4 is the first four of N = 8). Every set is a Monte Carlo run of
:mod:`campaigns.montecarlo` (typical errors of SPEC §6 with IMU biases, vane delays and INS clock
offset drawn as in ``campaigns/mc_20maneuvers.toml``, new noise every replication), estimated with
the tejas model set as one Mach bin, in two worlds:

* ``linear``: the local-flow truth and ADC baseline the model set represents exactly
  (``local_flow_linear`` / ``adc_baseline_linear``): every error is estimation error or noise;
* ``realistic``: the nonlinear local-flow truth and the mismatched ADC baseline
  (``local_flow_truth`` / ``adc_baseline``) that the piecewise-linear tables only approximate.

Metrics per set: the accuracy of the calibrated vane AOA against the true local flow, ``|mean| +
3 std`` of (calibrated channel - true angle) over every sample of the set's maneuvers (the
worse of the left and right vane; the same definition as studies (a) and (c)) with its two parts;
the predicted Cramér-Rao deviation and the Monte Carlo scatter of the vane biases and of the f1 /
f2 table elements; the angle-of-attack coverage (true alpha range flown, and which f1 breakpoints
the data determine). The accuracy is measured over the alpha range the set covers: a set that
covers less is judged on less, so the conclusion asks for coverage too.

Run (resumable: the same command again skips finished replications)::

    python -m campaigns.studies.maneuvers_per_bin --out runs/per_bin --results campaigns/studies/results
    python -m campaigns.studies.maneuvers_per_bin --out /tmp/per_bin --size tiny --replications 1

It writes ``maneuvers_per_bin.txt`` (the table, headed by the command, machine and wall time, ending
with a conclusion drawn from the numbers) and ``maneuvers_per_bin.png`` into ``--results`` (default:
``--out``); each set's Monte Carlo run stays in ``OUT/runs/``.
"""

from __future__ import annotations

import math
import sys
import textwrap
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from campaigns.montecarlo.flight_cache import SUFFIX as FLIGHT_SUFFIX
from campaigns.montecarlo.flight_cache import read_flight
from campaigns.montecarlo.summary import summarize_results
from campaigns.studies import scaffold
from campaigns.studies.common import (
    ALTITUDE_M,
    COMMON_DRAWS,
    IMU_SPREAD_ACCEL_MPS2,
    IMU_SPREAD_GYRO_DEG_S,
    SEED,
    WIND_NED_MPS,
    read_run,
)
from campaigns.studies.scaffold import Invocations, fmt, paragraph
from estimator.io.modelset import load_model_set
from estimator.parameters import family_of

STUDY = "maneuvers_per_bin"
#: the desired vane AOA accuracy, deg 3-sigma (paper Table 2, SPEC §8), and the margin asked for:
#: the 90th percentile of the replications within this fraction of it
DESIRED_VANE_DEG = 0.5
MARGIN = 0.8
#: a set covers the bin when its alpha span is at least this fraction of the largest set's
COVERAGE_FRACTION = 0.9
#: the maneuver mix, in the order they are added: (kind, heading deg)
MIX: tuple[tuple[str, float], ...] = (
    ("pitch_doublet", 0.0), ("windup_turn", 0.0), ("pullup_rudder_doublets", 0.0), ("3211", 0.0),
    ("roller_coaster", 0.0), ("pullup_pushover", 0.0), ("pitch_doublet", 180.0), ("windup_turn", 180.0),
    ("pullup_rudder_doublets", 180.0), ("3211", 180.0), ("roller_coaster", 180.0), ("pullup_pushover", 180.0),
    ("pitch_doublet", 90.0), ("windup_turn", 90.0), ("pullup_rudder_doublets", 90.0), ("3211", 90.0),
)
SHORT_KIND = {"pitch_doublet": "PD", "windup_turn": "WUT", "pullup_rudder_doublets": "PRD", "3211": "3211",
              "roller_coaster": "RC", "pullup_pushover": "PUPO"}
WORLDS: dict[str, tuple[str, str]] = {
    "linear": ("local_flow_linear", "adc_baseline_linear"),
    "realistic": ("local_flow_truth", "adc_baseline"),
}
VANES = ("alpha_zl", "alpha_zr")
MAX_ITERATIONS = 60


@dataclass(frozen=True)
class ManeuverSet:
    """The first ``n`` maneuvers of :data:`MIX` at one Mach number, in one world."""

    world: str
    mach: float
    n: int

    @property
    def name(self) -> str:
        return f"{self.world}_M{self.mach:.2f}_N{self.n:02d}"

    @property
    def label(self) -> str:
        return f"{self.world} M{self.mach:g} N={self.n}"


@dataclass(frozen=True)
class StudyConfig:
    """What a study size flies (``full``: the committed study; ``tiny``: a smoke run)."""

    configuration: str
    worlds: tuple[str, ...]
    machs: tuple[float, ...]
    counts: tuple[int, ...]
    replications: int

    @property
    def sets(self) -> tuple[ManeuverSet, ...]:
        return tuple(ManeuverSet(w, m, n) for w in self.worlds for m in self.machs for n in self.counts)


SIZES: dict[str, StudyConfig] = {
    "full": StudyConfig("PV1-NP", ("linear", "realistic"), (0.5, 0.7), (1, 2, 4, 8, 16), 20),
    # N = 1 (a lone pitch doublet) leaves the sideslip biases confounded with the initial sideslip
    # and the solver does not converge in its iteration budget: a failure, rightly; N >= 2 does
    "tiny": StudyConfig("PV1-NP", ("linear",), (0.5,), (2, 3), 1),
}


# ---------------------------------------------------------------------------- scenarios


def scenario_raw(s: ManeuverSet, config: StudyConfig, replications: int) -> dict:
    """The Monte Carlo scenario (TOML tables) of one maneuver set."""
    truth, baseline = WORLDS[s.world]
    flights = [{"configurations": [config.configuration], "mach": [s.mach], "maneuvers": [kind],
                "altitude_m": ALTITUDE_M, "maneuver": {"heading_rad": math.radians(heading_deg)}}
               for kind, heading_deg in MIX[: s.n]]
    draws = {"imu.accel_bias_mps2": {"dist": "normal", "std": IMU_SPREAD_ACCEL_MPS2, "scope": "maneuver"},
             "imu.gyro_bias_deg_s": {"dist": "normal", "std": IMU_SPREAD_GYRO_DEG_S, "scope": "maneuver"},
             **COMMON_DRAWS}
    return {
        "name": f"{STUDY}_{s.name}",
        "description": f"study (b): the first {s.n} maneuvers of the mix at Mach {s.mach}, "
                       f"{s.world} local flow",
        "seed": SEED, "replications": int(replications),
        "local_flow_truth": truth, "adc_baseline": baseline, "common_rate_hz": 40.0,
        "environment": {"planet": "flat", "wind_ned_mps": list(WIND_NED_MPS), "turbulence": "none"},
        "errors": {"preset": "typical", "nose_probe_irregularity": False},
        "flights": flights,
        "draw": {"errors": draws},
        "estimator": {"model": "tejas", "max_iterations": MAX_ITERATIONS, "colored": True,
                      "parameters": {"h0": {"free": True}}},
    }


# ---------------------------------------------------------------------------- metrics


def coverage_deg(run_dir: Path) -> tuple[float, float, float]:
    """True alpha min and max and the largest |beta| over the set's flown maneuvers, deg (from the
    run's cache of shared flights, ``flights/jNNNN.npz``; never a pickle: a run folder may come
    from anyone)."""
    lo, hi, beta = math.inf, -math.inf, 0.0
    for path in sorted((run_dir / "flights").glob(f"j*{FLIGHT_SUFFIX}")):
        for truth in read_flight(path):
            a = np.degrees(truth.alpha_rad)
            lo, hi = min(lo, float(a.min())), max(hi, float(a.max()))
            beta = max(beta, float(np.degrees(np.abs(truth.beta_rad)).max()))
    return lo, hi, beta


@dataclass
class SetMetrics:
    """What one maneuver set's Monte Carlo run gave.

    Attributes
    ----------
    requested, used, failed, wrong_minimum : N, replications in the statistics, failed or not
        converged, converged to a wrong minimum (:func:`~campaigns.studies.common.fit_ok`).
    vane : per used replication: accuracy, |mean| and 3 std of the worse vane, deg.
    parameters : Monte Carlo summary per parameter.
    alpha_deg : true alpha range flown (min, max), deg; beta_deg : largest |beta|, deg.
    elapsed_s : median wall time of a replication, s.
    """

    requested: int
    used: int
    failed: int
    wrong_minimum: int
    vane: pd.DataFrame
    parameters: pd.DataFrame
    alpha_deg: tuple[float, float]
    beta_deg: float
    elapsed_s: float

    def vane_stat(self, column: str, q: float = 50.0) -> float:
        v = self.vane[column].to_numpy(dtype=float) if len(self.vane) else np.array([])
        return float(np.percentile(v, q)) if v.size else math.nan

    def param(self, name: str, column: str) -> float:
        p = self.parameters
        return float(p.at[name, column]) if len(p) and name in p.index else math.nan


def vane_accuracy(channels: pd.DataFrame) -> dict[str, float]:
    """The worse vane's accuracy ``|mean| + 3 std`` of calibrated - true and its parts, deg."""
    c = channels[(channels["kind"] == "calibrated") & channels["name"].isin(VANES)]
    if not len(c):
        return {"accuracy": math.nan, "offset": math.nan, "three_std": math.nan}
    acc = np.abs(c["mean"].to_numpy()) + 3.0 * c["std"].to_numpy()
    k = int(np.argmax(acc))
    return {"accuracy": float(acc[k]), "offset": float(abs(c["mean"].iloc[k])),
            "three_std": float(3.0 * c["std"].iloc[k])}


def set_metrics(run_dir: Path, replications: int) -> SetMetrics:
    """Read a set's replications 0..N-1 and reduce them to :class:`SetMetrics`."""
    run = read_run(run_dir, replications)
    used = run.used
    vane = pd.DataFrame([vane_accuracy(r.channels) for r in used],
                        columns=["accuracy", "offset", "three_std"])
    params = summarize_results(used).parameters if used else pd.DataFrame()
    lo, hi, beta = coverage_deg(run_dir) if (run_dir / "flights").is_dir() else (math.nan, math.nan, math.nan)
    return SetMetrics(requested=replications, used=len(used), failed=run.failed,
                      wrong_minimum=run.wrong_minimum, vane=vane, parameters=params, alpha_deg=(lo, hi),
                      beta_deg=beta, elapsed_s=run.elapsed_s)


def f1_breakpoints_deg() -> np.ndarray:
    """The f1 table's breakpoints of the tejas model set, deg."""
    _, specs = load_model_set("tejas")
    (f1,) = [p for p in specs if p.name == "f1"]
    return np.degrees(np.asarray(f1.breakpoints, dtype=float))


def determined(m: SetMetrics, family: str) -> list[int]:
    """Indices of the ``family`` table's elements the data determine (finite Cramér-Rao std)."""
    p = m.parameters
    if not len(p):
        return []
    rows = p[(p["family"] == family) & np.isfinite(p["crb_mean"])]
    return sorted(int(n.split("[")[1].rstrip("]")) for n in rows.index)


def collect(config: StudyConfig, out_dir: Path, replications: int) -> dict[ManeuverSet, SetMetrics]:
    return {s: set_metrics(out_dir / "runs" / s.name, replications) for s in config.sets}


# ---------------------------------------------------------------------------- tables


def meets(m: SetMetrics) -> tuple[bool, bool]:
    """(median meets the requirement, 90th percentile within the margin)."""
    return (m.vane_stat("accuracy") <= DESIRED_VANE_DEG,
            m.vane_stat("accuracy", 90.0) <= MARGIN * DESIRED_VANE_DEG)


def covers(config: StudyConfig, metrics: Mapping[ManeuverSet, SetMetrics], s: ManeuverSet) -> bool:
    """The set's alpha span is at least :data:`COVERAGE_FRACTION` of the largest set's of its world
    and Mach number."""
    full = metrics[ManeuverSet(s.world, s.mach, max(config.counts))].alpha_deg
    own = metrics[s].alpha_deg
    return (own[1] - own[0]) >= COVERAGE_FRACTION * (full[1] - full[0])


def table_frame(config: StudyConfig, metrics: Mapping[ManeuverSet, SetMetrics]) -> pd.DataFrame:
    """One row per maneuver set."""
    bp = f1_breakpoints_deg()
    rows = []
    for s in config.sets:
        m = metrics[s]
        f1 = determined(m, "f1")
        ok, margin = meets(m)
        rows.append({
            "world": s.world, "Mach": s.mach, "N": s.n, "used": f"{m.used}/{m.requested}",
            "alpha_deg": f"{fmt(m.alpha_deg[0], '.1f')}..{fmt(m.alpha_deg[1], '.1f')}",
            "f1_deg": f"{bp[f1[0]]:g}..{bp[f1[-1]]:g}" if f1 else "-",
            "acc_med": m.vane_stat("accuracy"), "acc_p90": m.vane_stat("accuracy", 90.0),
            "offset": m.vane_stat("offset"), "3std": m.vane_stat("three_std"),
            "meets": ("yes" if ok else "no") + ("+margin" if ok and margin else ""),
            "covers": "yes" if covers(config, metrics, s) else "no",
            "b_l_crb": m.param("b_l[PV1]", "crb_mean"), "b_l_mc": m.param("b_l[PV1]", "mc_std"),
            "f1[3]_crb": m.param("f1[3]", "crb_mean"), "f1[3]_mc": m.param("f1[3]", "mc_std"),
            "f2[1]_crb": m.param("f2[1]", "crb_mean"), "f2[1]_mc": m.param("f2[1]", "mc_std"),
            "s/rep": m.elapsed_s,
        })
    return pd.DataFrame(rows)


def table_text(df: pd.DataFrame) -> str:
    out = df.copy()
    for c in out.columns:
        if out[c].dtype.kind == "f" and c != "Mach":
            out[c] = [fmt(x, ".3g") for x in out[c]]
    return out.to_string(index=False)


def parameter_grid(config: StudyConfig, metrics: Mapping[ManeuverSet, SetMetrics]) -> str:
    """Vane biases and f1 / f2 elements: mean Cramér-Rao std and Monte Carlo scatter per set."""
    names: list[str] = []
    for m in metrics.values():
        p = m.parameters
        if len(p):
            names += [n for n in p.index[p["family"].isin(["b_l", "b_r", "f1", "f2"])
                                         & np.isfinite(p["crb_mean"])] if n not in names]
    order = {"b_l": 0, "b_r": 1, "f1": 2, "f2": 3}
    names.sort(key=lambda n: (order[family_of(n)], n))
    lines = []
    for world in config.worlds:
        for mach in config.machs:
            sets = [s for s in config.sets if s.world == world and s.mach == mach]
            head = (f"{world} Mach {mach:g}: Cramer-Rao std / Monte Carlo scatter (deg for biases and f1, "
                    "1 for f2)")
            lines += [head, f"{'parameter':<10}" + "".join(f"{'N=' + str(s.n):>20}" for s in sets)]
            for n in names:
                cells = [f"{fmt(metrics[s].param(n, 'crb_mean'), '.2g')} / "
                         f"{fmt(metrics[s].param(n, 'mc_std'), '.2g')}" for s in sets]
                lines.append(f"{n:<10}" + "".join(f"{c:>20}" for c in cells))
            lines.append("")
    return "\n".join(lines)


def _groups(config: StudyConfig) -> list[tuple[str, float, list[ManeuverSet]]]:
    """(world, Mach, its sets in order of N)."""
    return [(w, m, [s for s in config.sets if s.world == w and s.mach == m])
            for w in config.worlds for m in config.machs]


def smallest_sufficient(config: StudyConfig, metrics: Mapping[ManeuverSet, SetMetrics],
                        sets: Sequence[ManeuverSet]) -> ManeuverSet | None:
    """The smallest set that covers the bin and meets the requirement with margin (None: none)."""
    good = [s for s in sets if all(meets(metrics[s])) and covers(config, metrics, s)]
    return good[0] if good else None


def findings(config: StudyConfig, metrics: Mapping[ManeuverSet, SetMetrics]) -> list[str]:
    """One line per world and Mach number: which sets meet the requirement, from which N they cover
    the bin, and the error budget there."""
    lines = []
    for world, mach, sets in _groups(config):
        meeting = [s.n for s in sets if all(meets(metrics[s]))]
        first = metrics[sets[0]]
        acc, p90 = first.vane_stat("accuracy"), first.vane_stat("accuracy", 90.0)
        text = (f"{world} local flow, Mach {mach:g}: N = {', '.join(map(str, meeting)) or 'none'} meet "
                f"+-{DESIRED_VANE_DEG:g} deg with margin on the alpha range they fly (N={sets[0].n}: median "
                f"{fmt(acc, '.2f')}, 90 % {fmt(p90, '.2f')} deg, 3 x vane-bias scatter "
                f"{fmt(3.0 * first.param('b_l[PV1]', 'mc_std'), '.2f')} deg)")
        lost = [f"{metrics[s].wrong_minimum} wrong minima (reported as converged) and {metrics[s].failed} "
                f"failures in {metrics[s].requested} replications at N={s.n}"
                for s in sets if metrics[s].wrong_minimum or metrics[s].failed]
        if lost:
            text += " (left out: " + "; ".join(lost) + ")"
        best = smallest_sufficient(config, metrics, sets)
        if best is None:
            lines.append(text + "; no set both covers the bin's alpha range and meets it with margin")
            continue
        m = metrics[best]
        lines.append(text + f"; from N={best.n} the set covers alpha {fmt(m.alpha_deg[0], '.1f')} to "
                     f"{fmt(m.alpha_deg[1], '.1f')} deg (median {fmt(m.vane_stat('accuracy'), '.2f')}, 90 % "
                     f"{fmt(m.vane_stat('accuracy', 90.0), '.2f')} deg), " + _limit_text(metrics, best))
    return lines


def conclusion(config: StudyConfig, metrics: Mapping[ManeuverSet, SetMetrics]) -> str:
    """One sentence from the numbers: how many maneuvers per bin, and what limits the accuracy."""
    chosen = {(w, m): smallest_sufficient(config, metrics, sets) for w, m, sets in _groups(config)}
    missing = [f"{w} Mach {m:g}" for (w, m), s in chosen.items() if s is None]
    found = [s for s in chosen.values() if s is not None]
    if not found:
        return (f"Conclusion: no set of up to {max(config.counts)} maneuvers meets the "
                f"+-{DESIRED_VANE_DEG:g} deg vane AOA requirement with margin over the bin's alpha range.")
    n_star = max(s.n for s in found)
    kinds = ", ".join(dict.fromkeys(SHORT_KIND[k] for k, _ in MIX[:n_star]))
    at = [ManeuverSet(s.world, s.mach, n_star) for s in found]
    med = [metrics[s].vane_stat("accuracy") for s in at]
    p90 = max(metrics[s].vane_stat("accuracy", 90.0) for s in at)
    budgets = [error_budget(metrics, s) for s in at]
    noise = [b["noise"] for b in budgets]
    residual = max(b["residual"] for b in budgets)
    offset = max(b["offset"] for b in budgets)
    ones = [metrics[sets[0]] for _, _, sets in _groups(config)]
    one_p90 = max(m.vane_stat("accuracy", 90.0) for m in ones)
    one_bias = max(3.0 * m.param("b_l[PV1]", "mc_std") for m in ones)
    where = "every case studied" if not missing else f"all cases but {', '.join(missing)}"
    if max(offset, residual) < min(noise):
        limit = "the limit is the sensor, not the parameters"
    elif residual >= offset:
        limit = "the limit is the local-flow residual the tables cannot represent"
    else:
        limit = "the limit is the calibration offset, the parameters' error"
    noise_text = (f"{min(noise):.2f}" if round(min(noise), 2) == round(max(noise), 2)
                  else f"{min(noise):.2f}-{max(noise):.2f}")
    return (f"Conclusion: {n_star} maneuvers per Mach bin ({kinds}) meet the +-{DESIRED_VANE_DEG:g} deg "
            f"vane AOA requirement with margin over the bin's alpha range in {where} (median "
            f"{min(med):.2f}-{max(med):.2f} deg, 90 % at most {p90:.2f} deg); fewer meet it only on the "
            f"narrower range they fly (N={config.counts[0]}: 90 % up to {one_p90:.2f} deg; its vane bias, "
            f"uncertain to 3 x scatter {one_bias:.2f} deg, is compensated by the f1 table only within that "
            f"range), and more do not improve it: the accuracy is the vane noise ({noise_text} deg 3 std), "
            f"with at most {residual:.2f} deg of local-flow residual and {offset:.3f} deg of calibration "
            f"offset - {limit}.")


def error_budget(metrics: Mapping[ManeuverSet, SetMetrics], s: ManeuverSet) -> dict[str, float]:
    """The vane accuracy's parts, deg (medians): ``offset`` (|mean|: the calibration's constant error),
    ``noise`` (3 std of the linear world at the same Mach number and N: sensor noise, since there the
    model is exact) and ``residual`` (the rest of the 3 std in quadrature: the local flow the tables
    cannot represent; 0 in the linear world)."""
    m = metrics[s]
    spread = m.vane_stat("three_std")
    linear = metrics.get(ManeuverSet("linear", s.mach, s.n))
    noise = linear.vane_stat("three_std") if linear is not None else spread
    noise = min(noise, spread) if np.isfinite(noise) else spread
    return {"offset": m.vane_stat("offset"), "noise": noise,
            "residual": math.sqrt(max(spread**2 - noise**2, 0.0))}


def _limit_text(metrics: Mapping[ManeuverSet, SetMetrics], s: ManeuverSet) -> str:
    budget = error_budget(metrics, s)
    what = {"offset": "the calibration offset (|mean|, parameter error)",
            "noise": "the vane noise (3 std, which more maneuvers do not reduce)",
            "residual": "the local-flow residual the tables cannot represent"}
    top = max(budget, key=lambda k: budget[k] if np.isfinite(budget[k]) else -1.0)
    bias = 3.0 * metrics[s].param("b_l[PV1]", "mc_std")
    return (f"limited by {what[top]}: |mean| {fmt(budget['offset'], '.2f')}, noise 3 std "
            f"{fmt(budget['noise'], '.2f')}, residual {fmt(budget['residual'], '.2f')} deg, while 3 x the "
            f"vane bias's Monte Carlo scatter is {fmt(bias, '.3f')} deg")


# ---------------------------------------------------------------------------- plot


def plot(metrics: Mapping[ManeuverSet, SetMetrics], config: StudyConfig, path: Path,
         replications: int) -> Path:
    """Accuracy vs N, its parts, vane-bias / f1 bounds and scatter vs N, alpha coverage vs N."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12.5, 9.0), layout="constrained")
    FigureCanvasAgg(fig)
    (a_acc, a_parts), (a_par, a_cov) = fig.subplots(2, 2)
    groups = [(w, m) for w in config.worlds for m in config.machs]
    for k, (world, mach) in enumerate(groups):
        sets = [s for s in config.sets if s.world == world and s.mach == mach]
        n = np.array([s.n for s in sets], dtype=float)
        color, style = f"C{k}", "-" if world == "linear" else "--"
        label = f"{world} M{mach:g}"
        med = np.array([metrics[s].vane_stat("accuracy") for s in sets])
        lo = np.array([metrics[s].vane_stat("accuracy", 10.0) for s in sets])
        hi = np.array([metrics[s].vane_stat("accuracy", 90.0) for s in sets])
        a_acc.errorbar(n * (1 + 0.03 * k), med, yerr=[med - lo, hi - med], fmt="o" + style, color=color,
                       capsize=3, label=label)
        a_parts.plot(n, [metrics[s].vane_stat("offset") for s in sets], "v" + style, color=color,
                     label=f"{label} |mean|")
        a_parts.plot(n, [metrics[s].vane_stat("three_std") for s in sets], "^" + style, color=color,
                     mfc="none", label=f"{label} 3 std")
        for name, marker in (("b_l[PV1]", "o"), ("f1[3]", "s")):
            a_par.plot(n, [metrics[s].param(name, "mc_std") for s in sets], marker + style, color=color,
                       label=f"{label} {name} scatter")
            a_par.plot(n, [metrics[s].param(name, "crb_mean") for s in sets], marker, color=color, mfc="none",
                       ls=":")
        cov = np.array([metrics[s].alpha_deg for s in sets])
        a_cov.vlines(n * (1 + 0.05 * k), cov[:, 0], cov[:, 1], color=color, lw=3, label=label)
    a_acc.axhline(DESIRED_VANE_DEG, color="r", ls="--", lw=1, label=f"desired {DESIRED_VANE_DEG:g} deg")
    a_acc.axhline(MARGIN * DESIRED_VANE_DEG, color="r", ls=":", lw=1,
                  label=f"margin {MARGIN * DESIRED_VANE_DEG:g}")
    a_acc.set_title("vane AOA: |mean| + 3 std of calibrated - true (worse vane); median, 10-90 %", fontsize=9)
    a_acc.set_ylabel("deg")
    a_parts.set_title("its parts (median): calibration offset |mean| and 3 std", fontsize=9)
    a_parts.set_ylabel("deg")
    a_par.set_title("Monte Carlo scatter (filled) and mean Cramér-Rao std (open, dotted) of b_l, f1[3]",
                    fontsize=9)
    a_par.set_ylabel("deg")
    a_cov.set_title("true angle of attack flown by the set", fontsize=9)
    a_cov.set_ylabel("alpha, deg")
    a_acc.set_ylim(0.0, 1.1 * DESIRED_VANE_DEG)
    for ax in (a_parts, a_par):
        ax.set_yscale("log")
    for ax in (a_acc, a_parts, a_par, a_cov):
        ax.set_xscale("log", base=2)
        ax.set_xticks(config.counts, [str(c) for c in config.counts])
        ax.set_xlabel("maneuvers per Mach bin (N)")
        ax.legend(fontsize=7, loc="upper left" if ax is a_cov else "best")
    fig.suptitle(f"Study (b): maneuvers per Mach bin for the vane AOA requirement; {replications} "
                 "replications per set", fontsize=11)
    fig.savefig(path, dpi=100)
    return path


# ---------------------------------------------------------------------------- report


def report(metrics: Mapping[ManeuverSet, SetMetrics], config: StudyConfig, replications: int, command: str,
           invocations: Invocations) -> str:
    """The text file: header (command, machine, cost), setup, legend, tables, findings, conclusion."""
    mix = ", ".join(f"{k + 1} {SHORT_KIND[kind]}{'' if not hdg else f' (heading {hdg:g})'}"
                    for k, (kind, hdg) in enumerate(MIX[: max(config.counts)]))
    lines = [
        *scaffold.header_lines(
            "Planning study (b): how many maneuvers per Mach bin reach the vane AOA requirement "
            f"(+-{DESIRED_VANE_DEG:g} deg 3-sigma)? Every set a Monte Carlo run of campaigns/montecarlo.",
            command, __file__, f"{replications} replications per set, {len(config.sets)} sets", invocations),
        *paragraph(
            f"sets: {config.configuration} flies the first N maneuvers of the mix (nested sets) at "
            f"{ALTITUDE_M:g} m, one Mach bin estimated at once: {mix} (PD pitch doublet, WUT wind-up turn, "
            "PRD pull-up with rudder doublets, 3211 multistep, RC roller coaster, PUPO pull-up/push-over; "
            f"default excitation per Mach). Steady wind {list(WIND_NED_MPS)} m/s, calm air; typical errors "
            "of SPEC §6 (nose-probe irregularity off), IMU biases drawn per maneuver (std "
            f"{IMU_SPREAD_ACCEL_MPS2:g} m/s^2, {IMU_SPREAD_GYRO_DEG_S:g} deg/s), vane delays, INS clock "
            "offset drawn as in mc_20maneuvers. Worlds: linear = local_flow_linear / adc_baseline_linear "
            "(representable), realistic = local_flow_truth / adc_baseline. Estimator: tejas model set, "
            f"every channel with data, h0 free, at most {MAX_ITERATIONS} iterations."),
        *paragraph(
            "columns: used = converged replications with a sane fit / N; alpha_deg = true alpha flown "
            "(min..max over the set); f1_deg = the f1 breakpoints the data determine; acc_med, acc_p90 = "
            "median and 90th percentile over the replications of the worse vane's |mean| + 3 std of "
            "(calibrated vane AOA - true local AOA) over every sample of the set, deg; offset, 3std = its "
            f"two parts (medians); meets = acc_med <= {DESIRED_VANE_DEG:g} (+margin: acc_p90 <= "
            f"{MARGIN * DESIRED_VANE_DEG:g}); covers = alpha span >= {COVERAGE_FRACTION:.0%} of the "
            f"N={max(config.counts)} set's; *_crb = mean Cramer-Rao std, *_mc = Monte Carlo scatter of "
            "estimate - truth (b_l deg, f1[3] = f1 at 4 deg in deg, f2[1] = sidewash coupling at 4 deg, 1); "
            "s/rep = median wall time of a replication in one process, s."),
        table_text(table_frame(config, metrics)),
        "",
        parameter_grid(config, metrics),
    ]
    lines.append("findings:")
    for line in findings(config, metrics):
        lines += textwrap.wrap(line, width=108, initial_indent="- ", subsequent_indent="  ")
    lines.append("")
    lines += textwrap.wrap(conclusion(config, metrics), width=108)
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------- command line


STUDY_SPEC = scaffold.Study(
    name=STUDY, file=__file__, sizes=SIZES, unit="set",
    description="Planning study (b): N = 1, 2, 4, 8, 16 maneuvers of a realistic mix per Mach bin; vane "
    "AOA accuracy against the truth, vane-bias and table bounds and scatter, alpha coverage. Resumable: "
    "run the same command again.",
    workers_help="worker processes per Monte Carlo run (default: 2; 1 runs in this process)",
    size_help="full: the study; tiny: a smoke run (linear world, Mach 0.5, N = 2 and 3)",
    run=scaffold.monte_carlo_runs(lambda config: config.sets, scenario_raw),
    analyse=lambda config, out_dir, n, _: collect(config, out_dir, n), report=report, plot=plot)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m campaigns.studies.maneuvers_per_bin --out DIR [--replications N] ...``"""
    return scaffold.main(STUDY_SPEC, argv)


if __name__ == "__main__":
    sys.exit(main())
