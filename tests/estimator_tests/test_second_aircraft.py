"""A second aircraft calibrated with no Python edited (issue 12, must-show 2).

``estimator/models/uav_example.toml`` declares a fleet of jet target drones: one angle-of-attack
vane, one sideslip vane, a pitot-static airspeed, an INS and a height, each vane with a bias and
a scale factor, and everything the workflow and its report need (Table 2's rows, the bias family
to apportion, the reference Mach, the initial conditions' sources, the figures' channels). No
Python names its channels.

The data are made here as a user's would come: CSV files (angles in deg, rates in deg/s) and a
problem file naming the model set. The flight is the analytic one of ``campaigns/analytic_flight.py``
(states and IMU inputs that satisfy the state equations exactly): three aircraft, four maneuvers
each, two at 500 m (Mach 0.44: the Mach 0.4 bin) and two at 8000 m (Mach 0.49: the 0.5 bin); each
vane reads its model with the injected installation biases, fleet offset, scale factors and time
shifts, every channel with white noise, the IMU with biases and no noise (the output-error method
has no process noise). Then:

- ``load_problem`` reads it with the UAV's channels and the model set's declarations, and starts
  the initial conditions from the UAV's vanes;
- the single estimation recovers every calibration parameter within 3 Cramér-Rao deviations;
- the workflow splits the vane biases into the fleet mean and installation biases (within
  3 deviations of the truth), re-estimates the fleet's offset with them held, and its Table 2 and
  report name the UAV's sensors and draw its figures at the model set's reference Mach 0.4;
- ``fpr calibrate`` on the problem file does the same.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pandas as pd
import pytest

from campaigns.analytic_flight import analytic
from estimator.io import load_problem
from estimator.io.modelset import declarations_of

D2R = math.pi / 180.0
RATE_HZ = 50.0
DURATION_S = 20.0
IMU_M = np.array([0.1, 0.0, 0.05])      # the IMU sits at the CG: the analytic specific force is the CG's
SENSORS_M = {"aoa_vane": np.array([1.6, -0.25, 0.05]), "sideslip_vane": np.array([1.9, 0.0, -0.10])}
#: the injected calibration (deg where angles): installation biases per aircraft, the fleet offset
B_A_DEG = {"U1": 0.4, "U2": -0.2, "U3": 0.1}
B_B_DEG = {"U1": -0.3, "U2": 0.25, "U3": 0.0}
C_A_DEG = 0.3
K_A, K_B = 0.05, -0.04
TAU_S = {"tas": 0.05, "a": 0.04, "b": 0.02}
NOISE = {"phi": 0.03 * D2R, "theta": 0.03 * D2R, "psi": 0.03 * D2R, "tas": 0.2, "h": 1.0,
         "alpha_v": 0.05 * D2R, "beta_v": 0.05 * D2R}
ALTITUDES_M = (500.0, 8000.0)
Z_MAX = 3.0


def _speed_of_sound(h_m):
    return np.sqrt(1.4 * 287.053 * (288.15 - 0.0065 * h_m))


def _flow_at(states, omega, sensor):
    """alpha and flank at a sensor: V + omega x (r_sensor - r_cg), the CG at the IMU."""
    v = states[:, :3] + np.cross(omega, SENSORS_M[sensor] - IMU_M)
    return np.arctan2(v[:, 2], v[:, 0]), np.arctan2(v[:, 1], v[:, 0])


def _maneuver(rng, h0_m, t0_s, ac):
    """One maneuver's file contents (SI) and its true Mach."""
    amp = {k: rng.uniform(0.6, 1.2) * base for k, base in
           (("au", 5.0), ("av", 3.0), ("aw", 4.0), ("aphi", 0.5), ("ath", 0.2))}
    inputs, states = analytic(amp)
    t = np.arange(int(round(DURATION_S * RATE_HZ)) + 1) / RATE_HZ
    tt = t + t0_s                                       # a phase of its own
    acc, om = inputs(tt)
    x = states(tt, h0_m)

    def at(tau):                                         # the flow and speed a sensor saw tau earlier
        xs, (_, oms) = states(tt - tau, h0_m), inputs(tt - tau)
        return xs, oms

    xa, oma = at(TAU_S["a"])
    xb, omb = at(TAU_S["b"])
    xt, _ = at(TAU_S["tas"])
    alpha_a, _ = _flow_at(xa, oma, "aoa_vane")
    _, flank_b = _flow_at(xb, omb, "sideslip_vane")
    tas = np.linalg.norm(x[:, :3], axis=1)
    clean = {
        "phi": x[:, 3], "theta": x[:, 4], "psi": x[:, 5], "h": x[:, 6],
        "tas": np.linalg.norm(xt[:, :3], axis=1),
        "alpha_v": (1 + K_A) * alpha_a + (C_A_DEG + B_A_DEG[ac]) * D2R,
        "beta_v": (1 + K_B) * flank_b + B_B_DEG[ac] * D2R,
    }
    meas = {k: v + NOISE[k] * rng.standard_normal(v.shape) for k, v in clean.items()}
    imu_bias = rng.normal(0.0, [0.05, 0.05, 0.05, 0.002, 0.002, 0.002])
    mach = tas / _speed_of_sound(x[:, 6])
    df = pd.DataFrame({
        "time": t,
        "AX": acc[:, 0] + imu_bias[0], "AY": acc[:, 1] + imu_bias[1], "AZ": acc[:, 2] + imu_bias[2],
        "P": (om[:, 0] + imu_bias[3]) / D2R, "Q": (om[:, 1] + imu_bias[4]) / D2R,
        "R": (om[:, 2] + imu_bias[5]) / D2R,
        "PHI": meas["phi"] / D2R, "THETA": meas["theta"] / D2R, "PSI": meas["psi"] / D2R,
        "TAS": meas["tas"], "HGT": meas["h"], "AOA": meas["alpha_v"] / D2R, "AOS": meas["beta_v"] / D2R,
        "MACH": mach,
    })
    return df, float(mach.mean())


PROBLEM = """title = "UAV fleet, hand-made data"
model = "uav_example"

[sensors]
imu = [{imu}]
aoa_vane = [{aoa}]
sideslip_vane = [{aos}]

{aircraft}
[columns]
t = {{ column = "time", unit = "s" }}
ax = {{ column = "AX", unit = "m/s^2" }}
ay = {{ column = "AY", unit = "m/s^2" }}
az = {{ column = "AZ", unit = "m/s^2" }}
p = {{ column = "P", unit = "deg/s" }}
q = {{ column = "Q", unit = "deg/s" }}
r = {{ column = "R", unit = "deg/s" }}
phi = {{ column = "PHI", unit = "deg" }}
theta = {{ column = "THETA", unit = "deg" }}
psi = {{ column = "PSI", unit = "deg" }}
tas = {{ column = "TAS", unit = "m/s" }}
h = {{ column = "HGT", unit = "m" }}
alpha_v = {{ column = "AOA", unit = "deg" }}
beta_v = {{ column = "AOS", unit = "deg" }}
mach = {{ column = "MACH", unit = "1" }}

{files}"""


@pytest.fixture(scope="module")
def uav_problem_file(tmp_path_factory):
    """The fleet's CSV files and problem file (seed 12); returns its path and the true Mach means."""
    folder = tmp_path_factory.mktemp("uav")
    rng = np.random.default_rng(12)
    files, machs = [], {}
    for ac in B_A_DEG:
        for k, h0 in enumerate(ALTITUDES_M * 2):
            name = f"{ac}_{k}"
            df, machs[name] = _maneuver(rng, h0, t0_s=7.0 * k + 3.0 * int(ac[1]), ac=ac)
            df.to_csv(folder / f"{name}.csv", index=False)
            files.append(f'[[files]]\npath = "{name}.csv"\naircraft = "{ac}"\n')
    fmt = ", ".join
    text = PROBLEM.format(
        imu=fmt(map(str, IMU_M)), aoa=fmt(map(str, SENSORS_M["aoa_vane"])),
        aos=fmt(map(str, SENSORS_M["sideslip_vane"])),
        aircraft="".join(f"[aircraft.{ac}]\nr_cg_body_m = [{fmt(map(str, IMU_M))}]\n" for ac in B_A_DEG),
        files="\n".join(files))
    path = folder / "uav.toml"
    path.write_text(text)
    return path, machs


@pytest.fixture(scope="module")
def problem(uav_problem_file):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # every channel has data: nothing to warn about
        return load_problem(uav_problem_file[0])


@pytest.mark.slow
def test_the_problem_file_reads_with_the_uav_channels_and_declarations(problem, uav_problem_file):
    assert [c.name for c in problem.channels] == ["phi", "theta", "psi", "tas", "h", "alpha_v", "beta_v"]
    decl = declarations_of(problem)
    assert decl.source.endswith("uav_example.toml")
    assert {c: r.sensor for c, r in decl.requirements.items()} == {"alpha_v": "AOA vane",
                                                                  "beta_v": "sideslip vane"}
    assert decl.apportion == {"vane": "b_a"} and decl.reference_mach == 0.4
    # the Mach bins the workflow will find: 0.4 at 500 m, 0.5 at 8000 m
    machs = uav_problem_file[1]
    assert {round(m, 1) for m in machs.values()} == {0.4, 0.5}
    # the initial conditions start from the UAV's vanes (the model set's [initial_conditions]):
    # w0 = V sin(alpha) within what the vane's bias and scale and the noise allow
    ps = problem.parameters
    for m in problem.maneuvers:
        w0 = ps[f"w0[{m.id}]"].value
        v0 = ps[f"v0[{m.id}]"].value
        alpha = np.mean(m.measurements["alpha_v"][:5])
        beta = np.mean(m.measurements["beta_v"][:5])
        tas = np.mean(m.measurements["tas"][:5])
        assert w0 == pytest.approx(tas * math.sin(alpha) * math.cos(beta))
        assert v0 == pytest.approx(tas * math.sin(beta))
        assert abs(alpha) > 0.01  # a real angle of attack, not the no-source default of 0


@pytest.mark.slow
def test_the_single_estimation_recovers_the_uav_calibration(problem):
    from estimator.solver import SolverOptions, estimate

    res = estimate(problem, SolverOptions())
    assert res.success, res.message
    # with every aircraft's b_a free, c_a is held at 0 and each b_a carries the fleet offset too
    truth = {**{f"b_a[{a}]": (b + C_A_DEG) * D2R for a, b in B_A_DEG.items()},
             **{f"b_b[{a}]": b * D2R for a, b in B_B_DEG.items()},
             "k_a": K_A, "k_b": K_B, "tau_a": TAU_S["a"], "tau_b": TAU_S["b"], "tau_tas": TAU_S["tas"]}
    z = {k: (res.value(k) - v) / res.std(k) for k, v in truth.items()}
    assert all(abs(v) < Z_MAX for v in z.values()), z
    assert res.value("c_a") == 0.0


@pytest.fixture(scope="module")
def workflow(problem):
    from estimator.workflow import run_workflow

    return run_workflow(problem)


@pytest.mark.slow
def test_the_workflow_apportions_the_uav_vane_and_names_its_sensors(workflow):
    wf = workflow
    assert wf.success, [f.text() for f in wf.findings]
    used = wf.maneuvers[wf.maneuvers["used"]]
    assert sorted(used["bin"].unique()) == [0.4, 0.5]
    # installation biases: b_a minus the fleet mean, taken at the model set's reference Mach
    inst = wf.installation
    assert set(inst["mach"]) == {0.4} and wf.reference_mach == 0.4
    mean_b = np.mean(list(B_A_DEG.values()))
    for a, b in B_A_DEG.items():
        est, std = inst.loc[a, "installation_vane_deg"], inst.loc[a, "std_installation_vane_deg"]
        assert abs(est - (b - mean_b)) < Z_MAX * std, (a, est, b - mean_b, std)
    assert {"b_a_deg", "mean_bias_deg", "fleet_mean_deg"} <= set(wf.vane_bias.columns)
    # with the installation biases held, c_a takes the fleet mean: c_a + mean(b_a)
    for st in wf.final:
        r = st.result
        assert abs(r.value("c_a") - (C_A_DEG + mean_b) * D2R) < Z_MAX * r.std("c_a"), st.mach
        assert not r.parameters.free_mask[r.parameters.index("b_a[U1]")]
    # Table 2: the UAV's sensors, within their desired accuracy (3 x 0.05 deg of noise)
    acc = wf.accuracy
    assert set(acc["sensor"]) == {"AOA vane", "sideslip vane"}
    assert set(acc["channel"]) == {"alpha_v", "beta_v"}
    assert acc["passed"].all() and (acc["three_sigma_deg"] < 0.25).all(), acc
    assert wf.alpha_limit_deg is None and wf.alpha_limit_growth.empty  # no usable-alpha channel


@pytest.mark.slow
def test_the_report_shows_the_uav_channels_at_its_reference_mach(workflow, tmp_path):
    from estimator.calibration import build_report

    out = build_report(workflow, tmp_path / "report", "UAV fleet")
    page = out["report"].read_text()
    for frag in ("AOA vane", "sideslip vane", "Fig. 5: alpha_v measurement - model vs model at Mach 0.40",
                 "Fig. 5: beta_v measurement - model vs model at Mach 0.40", "average vane bias b_a",
                 "Time-history match"):
        assert frag in page, frag
    for name in ("alpha_zl", "beta_znp", "b_l", "nose-probe"):  # nothing of the other aircraft
        assert name not in page, name
    t2 = pd.read_csv(tmp_path / "report" / "table2_model.csv")
    assert set(t2["sensor"]) == {"AOA vane", "sideslip vane"}
    inst = pd.read_csv(tmp_path / "report" / "installation_biases.csv")
    assert "installation_vane_deg" in inst.columns


@pytest.mark.slow
def test_fpr_calibrate_runs_the_uav_problem_file(uav_problem_file, tmp_path, capsys):
    from campaigns.cli import EXIT_STATUS, main

    out = tmp_path / "cli"
    # no --reference-mach: the model set's 0.4 is the default
    code = main(["calibrate", str(uav_problem_file[0]), "--out", str(out)])
    text = capsys.readouterr().out
    assert code in (EXIT_STATUS["SUCCESS"], EXIT_STATUS["SUCCESS_WITH_WARNINGS"]), text
    assert "AOA vane" in text and "sideslip vane" in text, text
    t2 = pd.read_csv(out / "table2_model.csv")
    assert set(t2["sensor"]) == {"AOA vane", "sideslip vane"} and t2["passed"].all()
    assert set(pd.read_csv(out / "installation_biases.csv")["mach"]) == {0.4}
