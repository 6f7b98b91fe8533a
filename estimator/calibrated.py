r"""Calibrated channels: the flow angle a channel's calibration model says its measurement means.

A channel model gives the measurement from the flow at the sensor, ``z = F(x, s; theta)`` with
``x`` the flow signal it measures (``ChannelSpec.measures``: ``alpha_s``, ``beta_s`` or
``flank_s``), ``s`` the other signals it uses (``alpha_t``, ``beta_s`` in a vane's sidewash term,
rates, airspeed) and ``theta`` the estimated calibration. Calibrating a measurement is solving that
equation for ``x`` (what the flight-control computer does with the correction tables), here by
Newton's method, sample by sample, with the exact derivative ``dF/dx`` of the expression language:

    x_{k+1} = x_k - (F(x_k, s) - z) / F_x(x_k, s),      x_0 = z

The modelled measurement ``zhat`` of implicit models is the measurement itself here (the FCS has
nothing else). Pure: arrays in, arrays out.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from estimator.core.expressions import Table
from estimator.problem import ChannelSpec

#: Newton iterations at most, and the step (rad) below which a sample has converged.
MAX_ITERATIONS = 20
TOLERANCE_RAD = 1e-12


def calibrated_channel(channel: ChannelSpec, z: np.ndarray, signals: Mapping[str, np.ndarray],
                       params: Mapping[str, float], tables: Mapping[str, tuple[Table, np.ndarray]]
                       ) -> np.ndarray:
    """The flow signal ``channel.measures`` that the channel model maps onto the measurement.

    Parameters
    ----------
    channel : the channel (its model and the signal it measures).
    z : (N,) measurements, SI (rad).
    signals : the model's other signals at the same samples, SI (e.g. ``alpha_t`` rad).
    params : parameter name -> value (SI) for this maneuver's instances.
    tables : table name -> (Table, (K,) values).

    Returns
    -------
    (N,) calibrated values, rad.
    """
    x_name = channel.measures
    if x_name is None:
        raise ValueError(f"channel {channel.name}: it measures no single flow signal (model "
                         f"{channel.model!r}); declare measures = \"alpha_s\" (or beta_s, flank_s)")
    z = np.asarray(z, dtype=float)
    sig = dict(signals)
    sig["z"] = z
    sig["zhat"] = z
    x = z.copy()
    state = frozenset({x_name})
    for _ in range(MAX_ITERATIONS):
        sig[x_name] = x
        dual = channel.expression.evaluate(sig, params, tables, state)
        slope = np.broadcast_to(dual.dsignal.get(x_name, 0.0), z.shape)
        if np.any(np.abs(slope) < 1e-6):
            raise ValueError(f"channel {channel.name}: its model does not depend on {x_name} at some "
                             "samples (zero slope); it cannot be calibrated there")
        step = (np.broadcast_to(dual.value, z.shape) - z) / slope
        x = x - step
        if np.max(np.abs(step), initial=0.0) < TOLERANCE_RAD:
            break
    return x
