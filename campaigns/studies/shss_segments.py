"""Planning study (a): the steady-heading sideslip flown as one long maneuver or split into segments.

The paper (Saraf & Kumaresan, §3): "In case of steady heading sideslips, the maneuvers have been
split into multiple maneuvers of 30-40 seconds each. This enables a good match and consistent
calibration." Here the same 105 s SHSS run is estimated as one maneuver (``1x105``), as two
52.5 s pieces (``2x52``) or as the paper's three 35 s pieces (``3x35``): the same flight time and
the same flown data, cut differently (:class:`synth.maneuvers.ManeuverSpec` ``segment_s``). Each
piece is a maneuver of its own to the estimator, with its own initial conditions, IMU biases,
pressure-altitude scale factor and DGPS offset.

Every variant flies, per configuration (PV1 with side and nose probes, PT1 with the boom) and
Mach number, one pitch doublet (so the angle-of-attack parameters are determined the same way in
every variant) and the SHSS run to both sides (+-4.5 deg). Conditions:

* ``calm``: calm air, steady wind, every typical error of SPEC §6 (IMU noise included: the
  estimator takes the IMU as a noise-free input, so its noise is integrated over the maneuver),
  IMU biases drawn per maneuver around the typical values and the estimator started at the
  typical values (a "warm" start: good to 0.02 deg/s, as a kinematic-consistency pre-pass gives);
* ``ideal_imu``: as calm with the IMU's noise and quantization off;
* ``turbulence``: as calm in light turbulence (MIL-F-8785C, a new realisation per replication;
  the output-error method models none);
* ``cold_start``: as calm, the IMU biases drawn as in ``campaigns/mc_20maneuvers.toml`` and the
  estimator started at zero IMU biases, as ``fpr calibrate`` starts every maneuver.

Metrics per variant, over the Monte Carlo replications: the predicted Cramér-Rao deviation (mean
over the replications) and the Monte Carlo scatter of estimate - truth of the sideslip-relevant
parameters (side-probe, nose-probe and boom sideslip biases, scale factors and tables, the
sidewash coupling f2, the vane AOA biases); the residual fit (1-sigma per channel); the accuracy
of each calibrated sideslip channel against the true flow angle (``|mean| + 3 std``, the same
definition as study (c)); and how many replications the estimator fitted at all (a fit whose
attitude residuals exceed :data:`~campaigns.studies.common.ATTITUDE_FIT_LIMIT_DEG` 3-sigma sits in
a wrong minimum, although the solver may report convergence).

Run (resumable: the same command again skips finished replications)::

    python -m campaigns.studies.shss_segments --out runs/shss --results campaigns/studies/results
    python -m campaigns.studies.shss_segments --out /tmp/shss --size tiny --replications 1

It writes ``shss_segments.txt`` (the tables, headed by the command, machine and wall time, ending
with a conclusion drawn from the numbers) and ``shss_segments.png`` into ``--results`` (default:
``--out``); each variant's Monte Carlo run stays in ``OUT/runs/``.
"""

from __future__ import annotations

import math
import sys
import textwrap
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from campaigns.montecarlo.replication import ReplicationResult
from campaigns.montecarlo.summary import summarize_results
from campaigns.studies import scaffold
from campaigns.studies.common import (
    ALTITUDE_M,
    ATTITUDE_FIT_LIMIT_DEG,
    COMMON_DRAWS,
    IMU_SPREAD_ACCEL_MPS2,
    IMU_SPREAD_GYRO_DEG_S,
    SEED,
    VANE_BIAS_FAMILIES,
    WIND_NED_MPS,
    read_run,
    typical_imu_biases,
)
from campaigns.studies.scaffold import Invocations, fmt, paragraph
from estimator.parameters import family_of

STUDY = "shss_segments"
SHSS_BETA_DEG = 4.5
CONDITIONS: dict[str, str] = {
    "calm": "calm air, typical errors (IMU noise on), warm IMU-bias start",
    "ideal_imu": "as calm, IMU noise and quantization off",
    "turbulence": "as calm, light turbulence redrawn every replication",
    "cold_start": "as calm, mc_20maneuvers' IMU-bias spread, estimator started at zero IMU biases",
}
#: IMU-bias spread drawn per maneuver around the typical values: (accel m/s^2, gyro deg/s)
WARM_IMU_SPREAD = (0.01, 0.02)
COLD_IMU_SPREAD = (IMU_SPREAD_ACCEL_MPS2, IMU_SPREAD_GYRO_DEG_S)
MAX_ITERATIONS = 60
#: parameter families the sideslip calibration is about (the vane AOA biases:
#: :data:`~campaigns.studies.common.VANE_BIAS_FAMILIES`)
SIDESLIP_FAMILIES = ("b_sb", "b_n", "b_bu", "b_bl", "k_bu", "k_bl", "k_spr", "f4", "f5", "f2")
#: calibrated sideslip channels: label, desired accuracy deg (SPEC §8; None: no requirement)
SIDESLIP_CHANNELS: dict[str, tuple[str, float | None]] = {
    "beta_zsp": ("side-probe AOSS", 1.0),
    "beta_znp": ("nose-probe AOSS", 0.5),
    "beta_zbu": ("boom AOSS upper", None),
    "beta_zbl": ("boom AOSS lower", None),
}
#: residual channels shown (1-sigma of measurement - model)
RESIDUAL_CHANNELS = ("phi", "theta", "psi", "tas", "beta_zsp", "beta_zbu")


@dataclass(frozen=True)
class Variant:
    """One Monte Carlo run of the study: a Mach number, a condition, a split."""

    mach: float
    condition: str
    pieces: int
    duration_s: float

    @property
    def segment_s(self) -> float:
        return self.duration_s / self.pieces

    @property
    def split(self) -> str:
        """``3x35``: pieces x their length, s."""
        return f"{self.pieces}x{math.floor(self.segment_s):d}"

    @property
    def name(self) -> str:
        """Directory name of its run."""
        return f"M{self.mach:.2f}_{self.condition}_{self.split}"

    @property
    def label(self) -> str:
        return f"M{self.mach:g} {self.condition} {self.split}"

    def cut(self, pieces: int) -> Variant:
        """The same Mach number and condition, another split."""
        return Variant(self.mach, self.condition, pieces, self.duration_s)


@dataclass(frozen=True)
class StudyConfig:
    """What a study size flies (``full``: the committed study; ``tiny``: a smoke run)."""

    configurations: tuple[str, ...]
    betas_deg: tuple[float, ...]
    variants: tuple[Variant, ...]
    replications: int
    #: pieces of the paper's split (30-40 s each), the reference of the relative columns
    reference_pieces: int


def _variants(duration_s: float, machs: Sequence[float], pieces: Sequence[int], extra: Sequence[str],
              extra_pieces: Sequence[int]) -> tuple[Variant, ...]:
    out = [Variant(m, "calm", k, duration_s) for m in machs for k in pieces]
    out += [Variant(machs[0], c, k, duration_s) for c in extra for k in extra_pieces]
    return tuple(out)


SIZES: dict[str, StudyConfig] = {
    # the SHSS's default run (105 s) as 1, 2 or 3 maneuvers at Mach 0.5 and 0.7; the other conditions
    # at Mach 0.5, unsplit and in the paper's split
    "full": StudyConfig(configurations=("PV1-NP", "PT1-BOOM"), betas_deg=(SHSS_BETA_DEG, -SHSS_BETA_DEG),
                        variants=_variants(105.0, (0.5, 0.7), (1, 2, 3),
                                           ("ideal_imu", "turbulence", "cold_start"), (1, 3)),
                        replications=15, reference_pieces=3),
    # a smoke run: PV1, one side, a 50 s run as 1 or 2 maneuvers
    "tiny": StudyConfig(configurations=("PV1-NP",), betas_deg=(SHSS_BETA_DEG,),
                        variants=_variants(50.0, (0.5,), (1, 2), (), ()),
                        replications=1, reference_pieces=2),
}


# ---------------------------------------------------------------------------- scenarios


def scenario_raw(variant: Variant, config: StudyConfig, replications: int) -> dict:
    """The Monte Carlo scenario (TOML tables) of one variant."""
    cold = variant.condition == "cold_start"
    accel_std, gyro_std = COLD_IMU_SPREAD if cold else WARM_IMU_SPREAD
    draws = {"imu.accel_bias_mps2": {"dist": "normal", "std": accel_std, "scope": "maneuver"},
             "imu.gyro_bias_deg_s": {"dist": "normal", "std": gyro_std, "scope": "maneuver"},
             **COMMON_DRAWS}
    errors: dict = {"preset": "typical", "nose_probe_irregularity": False}
    if variant.condition == "ideal_imu":
        errors["imu"] = {"accel_noise_mps2": 0.0, "gyro_noise_deg_s": 0.0, "accel_quant_mps2": 0.0,
                         "gyro_quant_deg_s": 0.0}
    parameters: dict = {"h0": {"free": True}}
    if not cold:  # warm start: the typical IMU biases (SI)
        accel, gyro = typical_imu_biases()
        for name, value in zip(("dax", "day", "daz", "dp", "dq", "dr"), accel + gyro, strict=True):
            parameters[name] = {"value": value}
    configs = list(config.configurations)
    flights: list[dict] = [{"configurations": configs, "mach": [variant.mach], "maneuvers": ["pitch_doublet"],
                            "altitude_m": ALTITUDE_M}]
    for beta in config.betas_deg:
        flights.append({"configurations": configs, "mach": [variant.mach], "maneuvers": ["shss"],
                        "altitude_m": ALTITUDE_M,
                        "maneuver": {"duration_s": variant.duration_s, "segment_s": variant.segment_s,
                                     "beta_deg": beta}})
    return {
        "name": f"{STUDY}_{variant.name}",
        "description": f"study (a): SHSS {variant.split} s at Mach {variant.mach}, "
                       f"{CONDITIONS[variant.condition]}",
        "seed": SEED, "replications": int(replications),
        "local_flow_truth": "local_flow_linear", "adc_baseline": "adc_baseline_linear",
        "common_rate_hz": 40.0,
        "environment": {"planet": "flat", "wind_ned_mps": list(WIND_NED_MPS),
                        "turbulence": "light" if variant.condition == "turbulence" else "none"},
        "errors": errors,
        "flights": flights,
        "draw": {"errors": draws},
        "estimator": {"model": "tejas", "max_iterations": MAX_ITERATIONS, "colored": True,
                      "parameters": parameters},
    }


# ---------------------------------------------------------------------------- metrics


def channel_rows(results: Sequence[ReplicationResult]) -> pd.DataFrame:
    """Per replication and channel: residual 1-sigma, and the calibrated channel's accuracy against
    the truth ``|mean| + 3 std`` with its parts (display units)."""
    rows = []
    for r in results:
        for c in r.channels.itertuples():
            rows.append({"replication": r.index, "name": c.name, "kind": c.kind, "mean": c.mean, "std": c.std,
                         "accuracy": abs(c.mean) + 3.0 * c.std})
    return pd.DataFrame(rows, columns=["replication", "name", "kind", "mean", "std", "accuracy"])


@dataclass
class RunMetrics:
    """What one Monte Carlo run gave (see the module docstring).

    Attributes
    ----------
    requested : N.
    files : replications with a file.
    failed : replications whose estimation failed or did not converge.
    wrong_minimum : converged replications whose fit is not one
        (:func:`~campaigns.studies.common.fit_ok`).
    used : replications in the statistics.
    parameters : the Monte Carlo summary per parameter (crb_mean, mc_std, ratio_crb, ...).
    channels : per replication and channel (:func:`channel_rows`) of the used replications.
    elapsed_s : median wall time of a replication, s.
    held : used replications in which the estimator held (at its start value, as not determined
        by the data) a scalar flow-angle calibration parameter (:func:`held_in`) that it estimated
        in other replications of the run.
    held_names : those parameters.
    parameters_unheld : the summary over the used replications without such a held parameter.
    """

    requested: int
    files: int
    failed: int
    wrong_minimum: int
    used: int
    parameters: pd.DataFrame = field(repr=False)
    channels: pd.DataFrame = field(repr=False)
    elapsed_s: float
    held: int = 0
    held_names: tuple[str, ...] = ()
    parameters_unheld: pd.DataFrame = field(default_factory=pd.DataFrame, repr=False)

    def accuracy(self, channel: str) -> float:
        """Median over the replications of the calibrated channel's ``|mean| + 3 std``, deg."""
        c = self.channels
        v = c.loc[(c["name"] == channel) & (c["kind"] == "calibrated"), "accuracy"]
        return float(v.median()) if len(v) else math.nan

    def residual_std(self, channel: str) -> float:
        """Median over the replications of the channel's residual 1-sigma (display units)."""
        c = self.channels
        v = c.loc[(c["name"] == channel) & (c["kind"] == "residual"), "std"]
        return float(v.median()) if len(v) else math.nan


def run_metrics(run_dir: Path, replications: int) -> RunMetrics:
    """Read a run's replications 0..N-1 and reduce them to :class:`RunMetrics`."""
    run = read_run(run_dir, replications)
    used = run.used
    params = summarize_results(used).parameters if used else pd.DataFrame()
    held = intermittently_held(used)
    unheld = [r for r in used if not held_in(r) & held]
    return RunMetrics(requested=replications, files=len(run.results), failed=run.failed,
                      wrong_minimum=run.wrong_minimum, used=len(used), parameters=params,
                      channels=channel_rows(used), elapsed_s=run.elapsed_s,
                      held=len(used) - len(unheld), held_names=tuple(sorted(held)),
                      parameters_unheld=summarize_results(unheld).parameters if unheld else pd.DataFrame())


#: the flow sensors' time delays
FLOW_DELAYS = ("tau_alpha_zl", "tau_alpha_zr", "tau_sp", "tau_np", "tau_ba", "tau_bu", "tau_bl")


def held_in(result: ReplicationResult) -> set[str]:
    """Scalar flow-angle calibration parameters (biases, scale factors, flow-sensor delays) the
    estimator held in this replication (no Cramér-Rao deviation). Table elements are not counted:
    breakpoints at the edge of the flown range come and go with the noise; nor are the TAS,
    altitude and attitude delays, which do not move the flow-angle calibration."""
    p = result.parameters
    p = p[p["kind"].isin(("bias", "scale")) | p["family"].isin(FLOW_DELAYS)]
    p = p[p["family"].isin(SIDESLIP_FAMILIES + VANE_BIAS_FAMILIES + FLOW_DELAYS)]
    return set(p.loc[~np.isfinite(p["std_crb"].to_numpy(dtype=float)), "name"])


def intermittently_held(results: Sequence[ReplicationResult]) -> set[str]:
    """Calibration parameters held in some replications and estimated in others: the estimator's
    screening (at the start values) decided differently from one replication to the next."""
    if not results:
        return set()
    sets = [held_in(r) for r in results]
    return set.union(*sets) - set.intersection(*sets)


def geo_mean(values: Sequence[float]) -> float:
    """Geometric mean of the finite positive values (NaN if none)."""
    a = np.asarray(values, dtype=float)
    a = a[np.isfinite(a) & (a > 0)]
    return float(np.exp(np.mean(np.log(a)))) if a.size else math.nan


def study_parameters(params: pd.DataFrame, families: Sequence[str]) -> list[str]:
    """The parameters of ``families`` that the estimator determined (finite Cramér-Rao deviation)."""
    if not len(params):
        return []
    p = params[params["family"].isin(families) & np.isfinite(params["crb_mean"])]
    return list(p.index)


def parameter_names(metrics: Mapping[Variant, RunMetrics]) -> tuple[list[str], list[str]]:
    """The determined parameters of the study's families over every variant (first-seen order), and
    those of them that are sideslip parameters (the vane AOA biases left out)."""
    names: list[str] = []
    for m in metrics.values():
        names += [n for n in study_parameters(m.parameters, SIDESLIP_FAMILIES + VANE_BIAS_FAMILIES)
                  if n not in names]
    return names, [n for n in names if family_of(n) in SIDESLIP_FAMILIES]


#: a parameter enters the geometric means when its Cramér-Rao std in the reference run is below
#: this (display unit -> limit): breakpoints at the edge of the flown range, barely determined,
#: would otherwise dominate them
WELL_DETERMINED = {"deg": 0.1, "1": 0.05, "m": 0.5}


def collect(config: StudyConfig, out_dir: Path, replications: int) -> dict[Variant, RunMetrics]:
    """Every variant's metrics."""
    return {v: run_metrics(out_dir / "runs" / v.name, replications) for v in config.variants}


def reference_of(v: Variant, config: StudyConfig, metrics: Mapping[Variant, RunMetrics]) -> RunMetrics | None:
    """The run of the paper's split at the same Mach number and condition."""
    return metrics.get(v.cut(config.reference_pieces))


def ratios(m: RunMetrics, ref: RunMetrics | None, column: str, names: Sequence[str],
           unheld: bool = False) -> np.ndarray:
    """``column`` of ``m`` over that of the reference run, per well-determined parameter of ``names``
    (``unheld``: over the replications without an intermittently held parameter)."""
    if ref is None:
        return np.array([])
    p, q = (m.parameters_unheld, ref.parameters_unheld) if unheld else (m.parameters, ref.parameters)
    if not len(p) or not len(q):
        return np.array([])
    # a parameter held in every replication of either run (no Cramér-Rao std) is not compared: its
    # "scatter" is that of its truth around the start value
    out = [p.at[n, column] / q.at[n, column] for n in names if n in p.index and n in q.index
           and np.isfinite(p.at[n, "crb_mean"])
           and q.at[n, "crb_mean"] < WELL_DETERMINED.get(str(q.at[n, "unit"]), math.inf)]
    a = np.asarray(out, dtype=float)
    return a[np.isfinite(a) & (a > 0)]


def relative(m: RunMetrics, ref: RunMetrics | None, column: str, names: Sequence[str],
             unheld: bool = False) -> float:
    """Geometric mean of :func:`ratios`."""
    return geo_mean(ratios(m, ref, column, names, unheld))


def scatter_over_bound(m: RunMetrics, ref: RunMetrics | None, names: Sequence[str]) -> float:
    """Median over the well-determined parameters of ``names`` of scatter / mean Cramér-Rao std."""
    if ref is None or m.used < 2 or not len(ref.parameters):
        return math.nan
    p, q = m.parameters, ref.parameters
    r = [p.at[n, "ratio_crb"] for n in names if n in p.index and n in q.index
         and q.at[n, "crb_mean"] < WELL_DETERMINED.get(str(q.at[n, "unit"]), math.inf)]
    r = np.asarray(r, dtype=float)
    r = r[np.isfinite(r)]
    return float(np.median(r)) if r.size else math.nan


def summary_frame(config: StudyConfig, metrics: Mapping[Variant, RunMetrics],
                  names: Sequence[str]) -> pd.DataFrame:
    """One row per variant: runs, relative bounds and scatter, residuals, accuracies."""
    rows = []
    for k, v in enumerate(config.variants, start=1):
        m = metrics[v]
        ref = reference_of(v, config, metrics)
        row = {"id": f"v{k}", "variant": v.label, "used": f"{m.used}/{m.requested}", "wrong": m.wrong_minimum,
               "held": m.held, "crb_rel": relative(m, ref, "crb_mean", names),
               "mc_rel": relative(m, ref, "mc_std", names),
               "mc_rel*": relative(m, ref, "mc_std", names, unheld=True),
               "mc/crb": scatter_over_bound(m, ref, names)}
        for ch in RESIDUAL_CHANNELS:
            row[f"res_{ch}"] = m.residual_std(ch)
        for ch in SIDESLIP_CHANNELS:
            row[f"acc_{ch}"] = m.accuracy(ch)
        row["acc_alpha_zl"] = m.accuracy("alpha_zl")
        row["s/rep"] = m.elapsed_s
        rows.append(row)
    return pd.DataFrame(rows)


_SHORT = {"res_phi": "r_phi", "res_theta": "r_tht", "res_psi": "r_psi", "res_tas": "r_tas",
          "res_beta_zsp": "r_bsp", "res_beta_zbu": "r_bbu", "acc_beta_zsp": "a_bsp", "acc_beta_znp": "a_bnp",
          "acc_beta_zbu": "a_bbu", "acc_beta_zbl": "a_bbl", "acc_alpha_zl": "a_vane"}


def summary_text(df: pd.DataFrame) -> str:
    """The per-variant table, numbers to three significant digits, '-' where there are none."""
    out = df.rename(columns=_SHORT).copy()
    for c in out.columns:
        if out[c].dtype.kind == "f":
            out[c] = [fmt(x, ".3g") for x in out[c]]
    return out.to_string(index=False)


def grid_text(config: StudyConfig, metrics: Mapping[Variant, RunMetrics], names: Sequence[str],
              column: str) -> str:
    """Parameters x variants grid of one summary column (display units)."""
    ids = [f"v{k}" for k in range(1, len(config.variants) + 1)]
    lines = [f"{'parameter':<12} {'unit':<4}" + "".join(f"{i:>9}" for i in ids)]
    for n in names:
        unit, cells = "", []
        for v in config.variants:
            p = metrics[v].parameters
            if len(p) and n in p.index:
                unit = str(p.at[n, "unit"])
                cells.append(fmt(float(p.at[n, column]), ".3g"))
            else:
                cells.append("-")
        lines.append(f"{n:<12} {unit:<4}" + "".join(f"{c:>9}" for c in cells))
    return "\n".join(lines)


def _pair(config: StudyConfig, metrics: Mapping[Variant, RunMetrics], v: Variant
          ) -> tuple[RunMetrics, RunMetrics] | None:
    """(unsplit, paper's split) runs of ``v``'s Mach number and condition."""
    long, split = metrics.get(v.cut(1)), metrics.get(v.cut(config.reference_pieces))
    return (long, split) if long is not None and split is not None else None


def _accuracy_ratios(long: RunMetrics, split: RunMetrics) -> np.ndarray:
    """Calibrated sideslip channels' accuracy, unsplit over split."""
    a = np.array([long.accuracy(c) / split.accuracy(c) for c in SIDESLIP_CHANNELS])
    return a[np.isfinite(a)]


def _word(ratio: float, tolerance: float) -> str:
    if not np.isfinite(ratio):
        return "(not measured)"
    if ratio < 1.0 / tolerance:
        return f"{ratio:.2f}x, smaller"
    if ratio > tolerance:
        return f"{ratio:.2f}x, larger"
    return f"{ratio:.2f}x, the same within the run's resolution"


def scatter_tolerance(replications: int) -> float:
    """A scatter ratio this far from 1 is resolved: twice the relative error of a standard deviation
    from N replications, 1/sqrt(2(N-1)), for each of the two runs compared."""
    return 1.0 + 2.0 * math.sqrt(2.0) / math.sqrt(2.0 * max(replications - 1, 1))


#: a ratio of Cramér-Rao bounds this far from 1 counts (they move with the drawn truths a little)
CRB_TOLERANCE = 1.1
#: a calibrated channel this much less accurate counts as worse
ACCURACY_TOLERANCE = 1.2


@dataclass(frozen=True)
class Comparison:
    """The unsplit run against the paper's split at one Mach number and condition.

    Attributes
    ----------
    where : "calm at Mach 0.5".
    condition : the condition.
    crb, mc, mc_unheld : geometric-mean ratios (unsplit / split) of the sideslip parameters' mean
        Cramér-Rao std, Monte Carlo scatter, and scatter over the replications without an
        intermittently held parameter.
    held : replications of the unsplit run with such a held parameter; held_names : which.
    accuracy : ratios of the calibrated sideslip channels' accuracy.
    misses : calibrated sideslip channels of the split run that miss their desired accuracy.
    """

    where: str
    condition: str
    crb: float
    mc: float
    mc_unheld: float
    held: int
    held_names: tuple[str, ...]
    accuracy: np.ndarray
    misses: tuple[str, ...]


def compare(config: StudyConfig, metrics: Mapping[Variant, RunMetrics], v: Variant,
            names: Sequence[str]) -> Comparison | None:
    """:class:`Comparison` of ``v``'s Mach number and condition (None: a run is missing or empty)."""
    pair = _pair(config, metrics, v)
    if pair is None or not pair[0].used or not pair[1].used:
        return None
    long, split = pair
    misses = tuple(f"{label} {split.accuracy(ch):.2f} deg"
                   for ch, (label, req) in SIDESLIP_CHANNELS.items()
                   if req is not None and split.accuracy(ch) > req)
    return Comparison(where=f"{v.condition.replace('_', ' ')} at Mach {v.mach:g}", condition=v.condition,
                      crb=relative(long, split, "crb_mean", names), mc=relative(long, split, "mc_std", names),
                      mc_unheld=relative(long, split, "mc_std", names, unheld=True), held=long.held,
                      held_names=long.held_names, accuracy=_accuracy_ratios(long, split), misses=misses)


def _clause(c: Comparison, tol: float) -> str:
    acc = c.accuracy
    spread = acc.size > 1 and round(acc.min(), 2) != round(acc.max(), 2)
    acc_text = (f"{acc.min():.2f}-{acc.max():.2f}x" if spread else f"{acc[0]:.2f}x" if acc.size
                else "(none)")
    held = (f" ({c.mc_unheld:.2f}x without the {c.held} replications in which the estimator held "
            f"{', '.join(c.held_names)})" if c.held and np.isfinite(c.mc_unheld) else "")
    text = (f"{c.where} the unsplit run's sideslip Cramer-Rao bounds are {_word(c.crb, CRB_TOLERANCE)}, "
            f"its Monte Carlo scatter {_word(c.mc, tol)}{held}, its calibrated sideslip accuracy {acc_text} "
            "those of the split run")
    if c.misses:
        text += f", and neither meets the desired accuracy (split: {', '.join(c.misses)})"
    return text


def findings(config: StudyConfig, metrics: Mapping[Variant, RunMetrics], names: Sequence[str],
             replications: int) -> tuple[list[str], list[Comparison], tuple[RunMetrics, RunMetrics] | None]:
    """Per condition, a line comparing the unsplit run with the split one; the comparisons; the
    cold-start pair (None when not run)."""
    tol = scatter_tolerance(replications)
    lines: list[str] = []
    comparisons: list[Comparison] = []
    cold: tuple[RunMetrics, RunMetrics] | None = None
    for v in config.variants:
        if v.pieces != 1:
            continue
        if v.condition == "cold_start":
            cold = _pair(config, metrics, v)
            if cold is not None:
                long, split = cold
                lines.append(f"cold start at Mach {v.mach:g}: the estimator fitted {long.used}/"
                             f"{long.requested} replications of the unsplit run ({long.wrong_minimum} "
                             f"converged to a wrong minimum, {long.failed} did not converge) and "
                             f"{split.used}/{split.requested} of the split one")
            continue
        c = compare(config, metrics, v, names)
        if c is None:
            pair = _pair(config, metrics, v)
            runs = [] if pair is None else zip(("unsplit", "split"), pair, strict=True)
            counts = " (" + "; ".join(
                f"{who} {m.used}/{m.requested} usable, {m.failed} with a failure verdict or not converged, "
                f"{m.wrong_minimum} at a wrong minimum" for who, m in runs) + ")" if pair else ""
            lines.append(f"{v.condition.replace('_', ' ')} at Mach {v.mach:g}: too few usable replications "
                         f"to compare{counts}")
            continue
        comparisons.append(c)
        lines.append(_clause(c, tol))
    return lines, comparisons, cold


def _range(values: Sequence[float]) -> str:
    a = np.asarray([x for x in values if np.isfinite(x)], dtype=float)
    if not a.size:
        return "-"
    return f"{a.min():.2f}x" if round(a.min(), 2) == round(a.max(), 2) else f"{a.min():.2f}-{a.max():.2f}x"


def conclusion(config: StudyConfig, metrics: Mapping[Variant, RunMetrics], names: Sequence[str],
               replications: int) -> str:
    """One sentence drawn from the numbers: is the paper's split borne out, and why."""
    tol = scatter_tolerance(replications)
    _, comparisons, cold = findings(config, metrics, names, replications)
    calm_air = [c for c in comparisons if c.condition != "turbulence"] or list(comparisons)
    crb = [c.crb for c in calm_air]
    acc = [float(x) for c in calm_air for x in c.accuracy]
    worse = [c for c in comparisons if np.isfinite(c.mc) and c.mc > tol]
    less_info = any(x > CRB_TOLERANCE for x in crb if np.isfinite(x))
    less_accurate = any(x > ACCURACY_TOLERANCE for x in acc)
    robust = cold is not None and cold[0].used < cold[1].used
    parts = [f"in calm air the unsplit {config.variants[0].duration_s:g} s run carries "
             + ("less" if less_info else "at least as much" if max(crb, default=1.0) <= 1.0 else "as much")
             + " information (sideslip Cramer-Rao bounds "
             f"{_range(crb)} those of the split run) and calibrates the sideslip channels "
             + ("less" if less_accurate else "as") + f" accurately ({_range(acc)}, the 3-sigma being mostly "
             "sensor noise)"]
    if worse:
        held = [c for c in worse if c.held]
        text = ("; its parameter scatter is larger ("
                + ", ".join(f"{c.where} {c.mc:.2f}x" for c in worse) + ")")
        if held:
            text += (", largely from replications in which this estimator held scalar parameters ("
                     + ", ".join(f"{c.held}/{replications}" for c in held) + ": "
                     + ", ".join(dict.fromkeys(n for c in held for n in c.held_names)) + ")")
        parts.append(text)
    if robust:
        parts.append(f"; and from the usual start at zero IMU biases it reached a wrong minimum in "
                     f"{cold[0].wrong_minimum + cold[0].failed} of {cold[0].requested} replications "
                     f"against {cold[1].wrong_minimum + cold[1].failed} of {cold[1].requested} split")
    turbulent = [c for c in comparisons if c.condition == "turbulence" and c.misses]
    rejected = [p for v in config.variants if v.pieces == 1 and v.condition == "turbulence"
                for p in [_pair(config, metrics, v)] if p is not None and not p[0].used and not p[1].used]
    if rejected:
        long, split = rejected[0]
        parts.append(f"; in light turbulence the estimator rejected every fit ({long.failed} of "
                     f"{long.requested} unsplit, {split.failed} of {split.requested} split with a failure "
                     "verdict), as it should: no accuracy is claimed there")
    elif turbulent:
        parts.append("; in light turbulence neither meets the desired sideslip accuracy ("
                     + ", ".join(turbulent[0].misses) + " split)")
    if robust or worse or less_info or less_accurate:
        head = ("the paper's split is borne out" + (" - for robustness and consistency, not for accuracy"
                                                    if not (less_info or less_accurate) else "") + ": ")
    else:
        head = "the paper's claim is not borne out here: "
    return "Conclusion: " + head + "".join(parts) + "."


# ---------------------------------------------------------------------------- plot


def plot(metrics: Mapping[Variant, RunMetrics], config: StudyConfig, path: Path, replications: int) -> Path:
    """Four panels: relative bounds, relative scatter, calibrated sideslip accuracy, residuals."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    names = parameter_names(metrics)[1]
    variants = list(config.variants)
    x = np.arange(len(variants))
    labels = [f"v{k + 1} {v.label}" for k, v in enumerate(variants)]
    fig = Figure(figsize=(13.0, 9.5), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, 2, sharex=True)
    ref_label = variants[0].cut(config.reference_pieces).split
    for ax, column, title in ((axes[0, 0], "crb_mean", "predicted Cramér-Rao std"),
                              (axes[0, 1], "mc_std", "Monte Carlo scatter")):
        for k, v in enumerate(variants):
            r = ratios(metrics[v], reference_of(v, config, metrics), column, names)
            if not r.size:
                continue
            ax.plot(k + np.linspace(-0.25, 0.25, r.size), r, ".", color="0.6", ms=4)
            ax.plot(k, geo_mean(r), "D", color=f"C{v.pieces - 1}", ms=7)
            m = metrics[v]
            if m.used < m.requested:  # wrong minima or failures left out: say how many are left
                ax.annotate(f"{m.used}/{m.requested}\nfitted", (k, geo_mean(r)), textcoords="offset points",
                            xytext=(0, -24), ha="center", fontsize=7, color="r")
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set_yscale("log")
        ax.set_ylabel(f"relative to {ref_label} (same Mach, condition)")
        ax.set_title(f"sideslip parameters: {title} (dots: each; diamond: geometric mean)", fontsize=9)
    ax = axes[1, 0]
    markers = {"beta_zsp": "o", "beta_znp": "s", "beta_zbu": "^", "beta_zbl": "v"}
    for ch, (label, req) in SIDESLIP_CHANNELS.items():
        ax.plot(x, [metrics[v].accuracy(ch) for v in variants], markers[ch], mfc="none", label=label)
        if req is not None:
            ax.axhline(req, color="r", lw=0.8, ls="--")
    ax.set_yscale("log")
    ax.set_ylabel("|mean| + 3 std of calibrated - true, deg")
    ax.set_title("calibrated sideslip channels against the truth, median over the replications\n"
                 "(dashed: desired, nose probe 0.5, side probe 1 deg)", fontsize=9)
    ax.legend(fontsize=8)
    ax = axes[1, 1]
    for ch in ("phi", "theta", "psi", "beta_zsp", "beta_zbu"):
        ax.plot(x, [metrics[v].residual_std(ch) for v in variants], "o-", ms=4, lw=0.6, label=ch)
    ax.set_yscale("log")
    ax.set_ylabel("residual 1-sigma, deg")
    ax.set_title("residual fit (measurement - model), median over the replications", fontsize=9)
    ax.legend(fontsize=8)
    for ax in axes[1]:
        ax.set_xticks(x, labels, rotation=60, ha="right", fontsize=8)
    fig.suptitle(f"Study (a): the {variants[0].duration_s:g} s SHSS as one maneuver or split "
                 f"({', '.join(dict.fromkeys(v.split for v in variants))} s); {replications} replications "
                 "per variant", fontsize=11)
    fig.savefig(path, dpi=100)
    return path


# ---------------------------------------------------------------------------- report


def report(metrics: Mapping[Variant, RunMetrics], config: StudyConfig, replications: int, command: str,
           invocations: Invocations) -> str:
    """The text file: header (command, machine, cost), setup, legend, tables, conclusion."""
    names, side = parameter_names(metrics)
    accel, gyro = typical_imu_biases()
    df = summary_frame(config, metrics, side)
    legend = ", ".join(f"{r['id']} = {r['variant']}" for _, r in df.iterrows())
    duration = config.variants[0].duration_s
    ref = config.variants[0].cut(config.reference_pieces).split
    limits = ", ".join(f"{v:g} {u}" for u, v in WELL_DETERMINED.items())
    lines = [
        *scaffold.header_lines(
            f"Planning study (a): the steady-heading sideslip (SHSS) flown as one {duration:g} s maneuver "
            f"or split into pieces ({ref} s is the paper's 30-40 s practice). Every variant a Monte Carlo "
            "run of campaigns/montecarlo.", command, __file__,
            f"{replications} replications per variant, {len(config.variants)} variants", invocations),
        *paragraph(f"flights per variant: {' + '.join(config.configurations)} at the variant's Mach number, "
                   f"{ALTITUDE_M:g} m: one pitch doublet and the {duration:g} s SHSS at "
                   f"{', '.join(f'{b:+g}' for b in config.betas_deg)} deg sideslip, cut into the variant's "
                   "pieces (one flight, cut differently). local_flow_linear / adc_baseline_linear "
                   "(representable: any error is estimation error); steady wind "
                   f"{list(WIND_NED_MPS)} m/s; typical errors of SPEC §6 (nose-probe irregularity off) with "
                   "vane delays, INS clock offset and boom scale factors drawn as in mc_20maneuvers. "
                   f"Estimator: tejas model set, every channel with data, h0 free, at most {MAX_ITERATIONS} "
                   "iterations."),
        *paragraph("conditions: " + "; ".join(f"{k} = {v}" for k, v in CONDITIONS.items())
                   + f". Warm start: IMU biases drawn per maneuver around the typical values (accel {accel} "
                   f"m/s^2, gyro {[round(math.degrees(g), 3) for g in gyro]} deg/s) with std "
                   f"{WARM_IMU_SPREAD[0]:g} m/s^2 / {WARM_IMU_SPREAD[1]:g} deg/s, the estimator started at "
                   f"the typical values; cold start: std {COLD_IMU_SPREAD[0]:g} / {COLD_IMU_SPREAD[1]:g}, "
                   "started at zero."),
        *paragraph(
            "columns: used = replications in the statistics / N; wrong = converged by the solver's test "
            f"but attitude residual 3-sigma > {ATTITUDE_FIT_LIMIT_DEG:g} deg (a wrong minimum; left out); "
            "held = replications in which the estimator held (at its start value, judged undetermined) a "
            "scalar flow-angle calibration parameter (sideslip or vane bias, scale factor, flow-sensor "
            "delay) it estimated in other replications of the run; "
            "crb_rel, mc_rel = geometric mean over the sideslip parameters below (vane biases excluded; "
            f"those with a Cramer-Rao std in the reference run under {limits}) of the mean Cramer-Rao "
            f"std and of the Monte Carlo scatter relative to {ref} of the same Mach number and "
            "condition; mc_rel* = the same over the replications without such a held parameter (in both "
            "runs); mc/crb = median over them of scatter / mean Cramer-Rao std; r_* = residual "
            "1-sigma (phi, theta, psi, side-probe and boom-upper AOSS deg, tas m/s), median over the "
            "replications; a_* = |mean| + 3 std of (calibrated channel - true flow angle) over every "
            "sample, deg, median over the replications (bsp side-probe AOSS, desired 1; bnp nose-probe "
            "AOSS, desired 0.5; bbu/bbl boom AOSS; vane = left vane AOA, desired 0.5); s/rep = median "
            "wall time of a replication in one process, s."),
        f"variants: {legend}",
        "",
        summary_text(df),
        "",
        "predicted Cramer-Rao std (mean over the replications), display units:",
        grid_text(config, metrics, names, "crb_mean"),
        "",
        "Monte Carlo scatter (std of estimate - truth over the replications):",
        grid_text(config, metrics, names, "mc_std"),
        "",
        "scatter / mean Cramer-Rao std:",
        grid_text(config, metrics, names, "ratio_crb"),
        "",
    ]
    lines.append("findings (unsplit run against the paper's split, same flight):")
    for line in findings(config, metrics, side, replications)[0]:
        lines += textwrap.wrap(line, width=108, initial_indent="- ", subsequent_indent="  ")
    lines.append("")
    lines += textwrap.wrap(conclusion(config, metrics, side, replications), width=108)
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------- command line


STUDY_SPEC = scaffold.Study(
    name=STUDY, file=__file__, sizes=SIZES, unit="variant",
    description="Planning study (a): the 105 s SHSS as one maneuver or split into 52.5 / 35 s pieces; "
    "Cramer-Rao bounds, Monte Carlo scatter, residual fit and calibrated sideslip accuracy. Resumable: "
    "run the same command again.",
    workers_help="worker processes per Monte Carlo run (default: 2; 1 runs in this process)",
    size_help="full: the study; tiny: a smoke run (PV1, one side, a 50 s run as 1 or 2 pieces)",
    run=scaffold.monte_carlo_runs(lambda config: config.variants, scenario_raw),
    analyse=lambda config, out_dir, n, _: collect(config, out_dir, n), report=report, plot=plot)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m campaigns.studies.shss_segments --out DIR [--replications N] ...``"""
    return scaffold.main(STUDY_SPEC, argv)


if __name__ == "__main__":
    sys.exit(main())
