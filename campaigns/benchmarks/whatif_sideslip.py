"""What-if study of the filter-error method's sideslip offsets and delays on JSBSim data.

JSBSim flies PT1-BOOM's maneuvers of the demo's light-turbulence block (Mach 0.6, 6000 m, a 7-m/s
steady wind); before the sensors see it, the wind in the truth is replaced, and the filter-error
method (model set ``tejas_ins``) calibrates the result. What each case keeps of the flight: the
aircraft's motion is JSBSim's turbulent flight (it answered the real gusts) but in the two cases
that say otherwise; only the air the flow sensors and the airspeed see changes,
``V_air = V_ground - C_bn W`` (alpha, beta, TAS, Mach, dynamic pressure recomputed from it). Cases:

- ``jsbsim``: JSBSim's wind (turb-type 4, Tustin: Dryden, second-order laterally and vertically);
- ``jsbsim_120hz``: the same, on a 120-Hz common time base (JSBSim's own rate) instead of 40 Hz:
  whether the sampling (the wind states' placement on the samples, the interpolation) makes the
  delays;
- ``jsbsim_dryden_states``: the same, calibrated with the filter's Dryden form
  (``WindOptions(form="dryden")``: body-axis wind states, second-order laterally and vertically);
- ``reversed``: the steady wind plus JSBSim's turbulence run backwards in time: the same
  statistics, its timing against the motion the gusts caused scrambled (it still lines up with
  itself at the segment's middle);
- ``shifted``: the steady wind plus JSBSim's turbulence shifted circularly by half the segment:
  JSBSim's own series, its statistics kept (one step at the wrap point) but its timing against the
  motion the gusts caused lost;
- ``jsbsim_noise_free``: the same, without the IMU's and the flow sensors' noise and quantization
  (the other channels' noise kept): how the delays' error depends on how closely the filter can
  follow the gusts;
- ``jsbsim_quiet_imu``, ``jsbsim_quiet_sensors``: the same, without the IMU's noise and
  quantization only, and without the flow sensors' only: which noise makes the delays' error;
- ``calm_motion``: JSBSim flies the maneuver in the steady wind only (no turbulence); the sensors
  see the steady wind plus the turbulence JSBSim made in the turbulent flight of the same maneuver:
  JSBSim's own gust series exactly, the aircraft's answer to them removed;
- ``gauss_markov_flown``: JSBSim flies through the steady wind plus three independent first-order
  Gauss-Markov components (the filter's own wind model, rms 1.1 m/s as JSBSim's, the 533.4-m scale
  length, from zero at the maneuver's start), set at every step: the aircraft answers these gusts
  and the sensors see them; the filter's wind model is exact;
- ``gauss_markov``: the steady wind plus three independent first-order Gauss-Markov components of
  JSBSim's rms and the 533.4-m scale length: the filter's own wind model;
- ``dryden_body``: the steady wind plus MIL-F-8785C Dryden turbulence of JSBSim's rms drawn in body
  axes (second-order laterally and vertically: JSBSim's form) and turned to NED with the flight's
  attitude, drawn apart from the flight;
- ``steady``: the steady wind only, the filter's wind states forced on at 1 m/s;
- ``steady_vane_biases``: as ``steady`` with no injected error but white noise, the local-flow
  truth and the vanes' installation biases (-0.44 and -0.12 deg);
- ``steady_no_biases``: the same without the installation biases (the control).

Printed and written (``--write``): each case's sideslip offsets, the vanes' sideslip reference
offset ``c_vb``, the flow delays and the airspeed delay against their truth, in honest deviations,
how many flow channels the ``gust_answer`` finding names (the innovations correlate with the
IMU: the aircraft's answer to the gusts, seen from the data alone) and how many delays' deviations
the feedback check widened (:mod:`estimator.core.instrumental`: by the instrumental estimate's
difference, or for a weak instrument); and, on the ``jsbsim`` case,
what holding the flow delays (alone, and with the sideslip offsets) at their truth, as a perfect
calm-air calibration would, does to the calibrated sensors' accuracy against the truth.
Run: ``python campaigns/benchmarks/whatif_sideslip.py --out DIR --write
campaigns/benchmarks/results/whatif_sideslip.txt`` (about seven minutes on 2 cores).
"""

from __future__ import annotations

import argparse
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

import synth.campaign as synth_campaign
from campaigns.analytic_flight import dryden_body_wind, gauss_markov_wind
from campaigns.studies.invocations import code_version
from campaigns.truth import recovery_table, true_parameters
from estimator.filter_error import DRYDEN_SCALE_LENGTH_M, WindOptions
from estimator.io import problem_from_dataset
from estimator.solver import SolverOptions, estimate
from synth.campaign import fly_campaign, parse_campaign
from synth.environment import Environment
from synth.sensors import dcm_body_to_ned

CASES = ("jsbsim", "jsbsim_120hz", "jsbsim_dryden_states", "jsbsim_noise_free", "jsbsim_quiet_imu",
         "jsbsim_quiet_sensors", "calm_motion",
         "gauss_markov_flown",
         "reversed", "shifted", "gauss_markov", "dryden_body", "steady", "steady_vane_biases",
         "steady_no_biases")
#: rms of each gauss_markov_flown component, m/s: JSBSim's light turbulence in the demo's block
#: (its maneuvers' per-axis rms 0.8-1.8 m/s, 0.9-1.4 m/s over the three axes)
FLOWN_SIGMA_MPS = 1.1
#: the airspeed of the Gauss-Markov decorrelation V / L, m/s: Mach 0.6 at 6000 m, the block's point
FLOWN_TAS_MPS = 190.0
KINDS = ["pitch_doublet", "3211", "roller_coaster", "pullup_rudder_doublets", "windup_turn", "shss"]
STEADY_WIND_NED_MPS = [6.0, -4.0, 0.0]
VANES = ("vane_left", "vane_right", "boom_alpha_vane", "boom_beta_upper_vane", "boom_beta_lower_vane")
PROBES = ("side_probe_left", "side_probe_right", "nose_probe")
#: PT1 with the vanes' installation biases only (the default fleet's values)
VANE_BIAS_FLEET = """airframe = "f16-testbed"
[[aircraft]]
id = "PT1"
fuel_kg = 1300.0
ballast_kg = 120.0
ballast_position_body_m = [8.5, 0.0, 0.2]
[aircraft.installation_bias_deg]
vane_left = -0.44
vane_right = -0.12
side_probe_left = 0.0
side_probe_right = 0.0
nose_probe = 0.0
boom_alpha_vane = 0.0
boom_beta_upper_vane = 0.0
boom_beta_lower_vane = 0.0
[[configuration]]
id = "PT1-BOOM"
aircraft = "PT1"
nose_sensor = "boom"
"""
NOISE_ONLY = {
    "preset": "none", "local_flow": True, "installation_biases": True,
    "imu": {"accel_noise_mps2": 0.02, "gyro_noise_deg_s": 0.01},
    "ins": {"euler_noise_deg": 0.03, "velocity_noise_mps": 0.05},
    "airdata": {"qc_noise_pa": 15.0, "ps_noise_pa": 10.0, "tt_noise_k": 0.2},
    "dgps": {"h_noise_m": 0.3},
    "sensors": {**{s: {"noise_deg": 0.07} for s in VANES},
                **{s: {"noise_pa": 20.0} for s in ("side_probe_left", "side_probe_right")}},
}
ROWS = ("b_sb[PT1]", "b_bu[PT1]", "b_bl[PT1]", "c_vb[PT1]", "tau_alpha_zl", "tau_alpha_zr", "tau_sp",
        "tau_ba", "tau_bu", "tau_bl", "tau_tas")


def with_wind(truth, wind_ned_mps: np.ndarray):
    """The truth with the air moving at ``wind_ned_mps`` (N, 3) instead: the motion unchanged."""
    v_air = truth.v_body_mps - np.einsum("nji,nj->ni", dcm_body_to_ned(truth.euler_rad), wind_ned_mps)
    tas = np.linalg.norm(v_air, axis=1)
    return replace(truth, wind_ned_mps=wind_ned_mps, v_air_body_mps=v_air, tas_mps=tas,
                   mach=tas * truth.mach / truth.tas_mps, qbar_pa=0.5 * truth.rho_kgpm3 * tas ** 2,
                   alpha_rad=np.arctan2(v_air[:, 2], v_air[:, 0]), beta_rad=np.arcsin(v_air[:, 1] / tas))


def fly(case: str, out: Path) -> None:
    """Fly the case's dataset into ``out`` (JSBSim's flight, the case's wind)."""
    steady = np.asarray(STEADY_WIND_NED_MPS)
    rng = np.random.default_rng(2026)
    original = synth_campaign.fly_maneuver

    def replaced(spec, airframe, aircraft, env: Environment):
        if case == "gauss_markov_flown":
            def added(t_s: np.ndarray) -> np.ndarray:
                w = gauss_markov_wind(t_s, FLOWN_SIGMA_MPS, DRYDEN_SCALE_LENGTH_M, FLOWN_TAS_MPS, rng)
                # the process from zero at the start (no step into the gusts): x_k - a^k x_0
                return w - w[:1] * np.exp(-FLOWN_TAS_MPS * (t_s - t_s[0]) / DRYDEN_SCALE_LENGTH_M)[:, None]

            return original(spec, airframe, aircraft, replace(env, turbulence="none"),
                            added_wind=added)
        calm = (original(spec, airframe, aircraft, replace(env, turbulence="none"))
                if case == "calm_motion" else None)
        out_segments = []
        for j, tr in enumerate(original(spec, airframe, aircraft, env)):
            turb = tr.wind_ned_mps - steady
            if case in ("jsbsim", "jsbsim_120hz", "jsbsim_dryden_states", "jsbsim_noise_free",
                        "jsbsim_quiet_imu", "jsbsim_quiet_sensors"):
                w = tr.wind_ned_mps
            elif case == "calm_motion":
                # the calm flight's samples are at the same times (a scripted maneuver, one step)
                tc = calm[j]
                w = steady + np.stack([np.interp(tc.t_s, tr.t_s, turb[:, i]) for i in range(3)], 1)
                out_segments.append(with_wind(tc, w))
                continue
            elif case == "shifted":
                w = steady + np.roll(turb, turb.shape[0] // 2, axis=0)
            elif case == "reversed":
                w = steady + turb[::-1]
            elif case == "dryden_body":
                b = dryden_body_wind(tr.t_s, float(np.sqrt(np.mean(turb ** 2))), DRYDEN_SCALE_LENGTH_M,
                                     float(tr.tas_mps.mean()), rng)
                w = steady + np.einsum("nij,nj->ni", dcm_body_to_ned(tr.euler_rad), b)
            elif case == "gauss_markov":
                w = steady + gauss_markov_wind(tr.t_s, float(np.sqrt(np.mean(turb ** 2))),
                                               DRYDEN_SCALE_LENGTH_M, float(tr.tas_mps.mean()), rng)
            else:
                w = np.broadcast_to(steady, turb.shape).copy()
            out_segments.append(with_wind(tr, w))
        return out_segments

    raw = {"name": f"whatif_{case}", "fleet": "fleet_default", "seed": 14001,
           "common_rate_hz": 120.0 if case == "jsbsim_120hz" else 40.0,
           "environment": {"planet": "flat", "wind_ned_mps": STEADY_WIND_NED_MPS, "turbulence": "light"},
           "errors": {"preset": "typical"},
           "flights": [{"configurations": ["PT1-BOOM"], "mach": [0.6], "maneuvers": KINDS,
                        "altitude_m": 6000.0}]}
    if case in ("jsbsim_noise_free", "jsbsim_quiet_imu"):
        raw["errors"] = {"preset": "typical",
                         "imu": {"accel_noise_mps2": 0.0, "gyro_noise_deg_s": 0.0,
                                 "accel_quant_mps2": 0.0, "gyro_quant_deg_s": 0.0}}
    if case in ("jsbsim_noise_free", "jsbsim_quiet_sensors"):
        raw["errors"] = {"preset": "typical", **raw["errors"],
                         "sensors": {**{s: {"noise_deg": 0.0, "quant_deg": 0.0} for s in VANES},
                                     **{s: {"noise_pa": 0.0, "quant_pa": 0.0} for s in PROBES}}}
    if case in ("steady_vane_biases", "steady_no_biases"):
        out.parent.mkdir(parents=True, exist_ok=True)
        fleet = out.parent / "fleet_vane_biases.toml"
        if fleet.exists() and fleet.read_text() != VANE_BIAS_FLEET:  # never overwrite a user's file
            raise SystemExit(f"{fleet} exists and is not this study's fleet: give another --out")
        fleet.write_text(VANE_BIAS_FLEET)
        raw |= {"fleet": str(fleet),
                "errors": NOISE_ONLY | {"installation_biases": case == "steady_vane_biases"}}
    # why the module attribute is replaced: fly_campaign offers no hook between JSBSim's flight
    # and the instrumentation, and this study must change exactly that (one process: workers=1)
    synth_campaign.fly_maneuver = replaced
    try:
        fly_campaign(parse_campaign(raw), out, workers=1, overwrite=True)
    finally:
        synth_campaign.fly_maneuver = original


def calibrate(case: str, dataset: Path):
    form = "dryden" if case.endswith("dryden_states") else "gauss_markov"
    wind = WindOptions(where="all", sigma_mps=1.0) if case.startswith("steady") else WindOptions(form=form)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        p = problem_from_dataset(dataset, model="tejas_ins")
        r = estimate(p, SolverOptions(method="filter_error", wind=wind))
    return r, recovery_table(r, true_parameters(p, r.free_estimated))


#: the flow channels' delays, and the sideslip offsets (every sideslip channel's bias and the
#: vanes' reference offset) of PT1: what the fixing variants hold at their truth
FLOW_DELAYS = ("tau_alpha_zl", "tau_alpha_zr", "tau_sp", "tau_ba", "tau_bu", "tau_bl")
SIDESLIP_OFFSETS = ("b_sb[PT1]", "b_bu[PT1]", "b_bl[PT1]", "c_vb[PT1]")


def fixing(dataset: Path) -> list[str]:
    """What holding parameters at a calm-air calibration's values does on JSBSim's turbulence
    (the truth stands in for a perfect calm-air calibration): the calibrated sensors' accuracy
    against the truth, Table 2's 3 sigma (:func:`estimator.workflow.three_sigma`: 3 x the rms of
    calibrated - true flow angle at the sensor, a mean offset counted), deg, with everything free,
    the flow delays held, and the delays and the sideslip offsets held."""
    from campaigns.workflow_truth import calibrated_errors
    from estimator.workflow import three_sigma

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        p = problem_from_dataset(dataset, model="tejas_ins")
        r = estimate(p, SolverOptions(method="filter_error", wind=WindOptions(), diagnose=False))
        truth = true_parameters(p, r.free_estimated).values
        rows = []
        for label, held in (("all free", ()), ("flow delays held", FLOW_DELAYS),
                            ("delays and sideslip offsets held", FLOW_DELAYS + SIDESLIP_OFFSETS)):
            ps = p.parameters.with_values({k: truth[k] for k in held}).with_free({k: False for k in held})
            q = replace(p, parameters=ps)
            res = r if not held else estimate(q, SolverOptions(method="filter_error", wind=WindOptions(),
                                                               diagnose=False))
            errs = calibrated_errors(q, res)
            rows.append((label, {c: three_sigma(np.degrees(d["error_rad"].to_numpy()))
                                 for c, d in errs.items()}))
    names = list(rows[0][1])
    head = f"{'jsbsim case, held at the truth':34s} " + " ".join(f"{c:>9s}" for c in names)
    return ["", "What holding parameters at a (perfect) calm-air calibration does on the jsbsim case: the",
            "calibrated sensors' 3 sigma against the truth (Table 2's: 3 x rms of the error), deg",
            head, "-" * len(head)] + [
        f"{label:34s} " + " ".join(f"{acc[c]:9.3f}" for c in names) for label, acc in rows]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="scratch directory for the datasets")
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=CASES)
    ap.add_argument("--write", type=Path, help="write the table to this text file")
    a = ap.parse_args()
    lines = ["filter-error method (tejas_ins) on PT1-BOOM's maneuvers of the demo's light-turbulence",
             "block, JSBSim's flight, the wind the sensors see replaced: estimate - truth (honest "
             "deviations)", f"code: {code_version(__file__)}", ""]
    header = (f"{'case':20s} " + " ".join(f"{k:>15s}" for k in ROWS) + f" {'answer':>7s} {'widened':>8s}"
              + "  verdict")
    lines += [header, "-" * len(header)]
    for case in a.cases:
        t0 = time.perf_counter()
        fly(case, a.out / case)
        r, rt = calibrate(case, a.out / case)
        cells = []
        for k in ROWS:
            row = rt.loc[k]
            unit = "ms" if k.startswith("tau_") else "deg"
            cells.append(f"{row['error_display']:+.3f}{unit[0]} ({row['z_colored']:+.1f})"
                         if unit == "deg" else f"{row['error_display']:+.1f}ms ({row['z_colored']:+.1f})")
        answered = sum(f.code == "gust_answer" for f in r.findings)
        widened = sum(len(f.parameters) for f in r.findings
                      if f.code in ("delay_feedback", "delay_weak_instrument"))
        failed = dict.fromkeys(f.code for f in r.findings if f.severity.name == "FAILURE")
        bound = [p for f in r.findings if f.code == "on_bound" and f.severity.name == "WARNING"
                 for p in f.parameters]
        said = (r.verdict.name + "".join(f" {c}" for c in failed)
                + (f", on its bound: {', '.join(bound)}" if bound else ""))
        lines.append(f"{case:20s} " + " ".join(f"{c:>15s}" for c in cells) + f" {answered:>7d}"
                     + f" {widened:>8d}  {said}")
        print(lines[-1], f"[{r.verdict.name}, {time.perf_counter() - t0:.0f} s]", flush=True)
    if "jsbsim" in a.cases:
        lines += fixing(a.out / "jsbsim")
        print("\n".join(lines[-6:]), flush=True)
    lines += ["", "d: deg; the steady cases force the wind states on at 1 m/s (calm air).",
              "answer: the flow channels (of 8) whose innovations correlate with the IMU's specific "
              "force, the aircraft's",
              "answer to the gusts (gust_answer findings: FilterErrorLikelihood.answer_findings).",
              "widened: the delays whose honest deviation the feedback check widened (an "
              "instrumental-variable estimate,",
              "the delay's sensitivity 50-100 ms earlier as its instrument, differs, or the "
              "instrument is too weak to tell:",
              "estimator.core.instrumental, delay_feedback and delay_weak_instrument); the "
              "deviations in brackets are the widened ones.",
              "verdict: the estimation's, its FAILURE findings and the parameters on a bound it warns "
              "of (on_bound)."]
    text = "\n".join(lines) + "\n"
    print(text)
    if a.write:
        a.write.write_text(text)


if __name__ == "__main__":
    main()
