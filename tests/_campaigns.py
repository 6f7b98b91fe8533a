"""The campaign dicts of the end-to-end tests (see tests/conftest.py for flying them once).

Most end-to-end tests fly a small campaign on the *linear pair* — the model-representable local-flow
truth and airdata-computer baseline (``aircraft_models/local_flow_linear.toml``,
``adc_baseline_linear.toml``) — with the typical errors but without the nose probe's irregularity
(a pseudo-random function of alpha and beta that no table can find, paper §4.2), so that the model
set can represent the truth and every difference is estimation error. :func:`linear_campaign`
builds those dicts; :data:`TINY_CAMPAIGN` is the smallest useful one, the shared tiny campaign.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence

#: IMU noise and quantization off: in the output-error method they act as unmodelled process noise
#: (integrated into the states), for which its Cramér-Rao bound is not the yardstick
QUIET_IMU = {"accel_noise_mps2": 0.0, "gyro_noise_deg_s": 0.0,
             "accel_quant_mps2": 0.0, "gyro_quant_deg_s": 0.0}


def linear_campaign(name: str, seed: int, flights: Sequence[Mapping], *,
                    wind_ned_mps: Sequence[float] = (0.0, 0.0, 0.0), turbulence: str | None = None,
                    quiet_imu: bool = False, errors: Mapping | None = None) -> dict:
    """A campaign dict on the linear pair, flat Earth, typical errors without the nose-probe irregularity.

    Parameters
    ----------
    name, seed : the campaign's name (recorded in the manifest) and master seed.
    flights : the ``[[flights]]`` blocks.
    wind_ned_mps : the steady wind.
    turbulence : written into ``[environment]`` when given (the campaign default is calm air).
    quiet_imu : IMU noise and quantization off (:data:`QUIET_IMU`).
    errors : further ``[errors]`` keys (e.g. ``{"sensors": {...}}``).
    """
    environment = {"planet": "flat", "wind_ned_mps": list(wind_ned_mps)}
    if turbulence is not None:
        environment["turbulence"] = turbulence
    errs = {"preset": "typical", "nose_probe_irregularity": False, **copy.deepcopy(dict(errors or {}))}
    if quiet_imu:
        errs["imu"] = dict(QUIET_IMU)
    return {"name": name, "seed": seed, "local_flow_truth": "local_flow_linear",
            "adc_baseline": "adc_baseline_linear", "environment": environment, "errors": errs,
            "flights": copy.deepcopy(list(flights))}


#: The shared tiny campaign: two aircraft (PV1-NP, PV2-NP), Mach 0.6, a pitch doublet and a 3211 of
#: 10 s each — one Mach bin of four maneuvers, which the workflow and ``--single`` both calibrate in
#: seconds; no wind, calm air.
TINY_CAMPAIGN = linear_campaign("tiny", 11, [
    {"configurations": ["PV1-NP", "PV2-NP"], "mach": [0.6], "maneuvers": ["pitch_doublet", "3211"],
     "maneuver": {"duration_s": 10.0}, "altitude_m": 6000.0}])
TINY_SOURCE = "tiny campaign (tests/_campaigns.py)"
