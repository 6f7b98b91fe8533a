"""An analytic flight for the estimator tests: states and IMU inputs that satisfy SPEC §3 exactly.

u, v, w and the Euler angles are sums of sinusoids; the rates follow from the Euler-angle
kinematics and the specific force from the velocity equations, so the state equations hold
exactly and only numerical errors of the code under test remain.
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

G = 9.80665


class Sinus:
    """f(t) = bias + slope t + sum A sin(w t + phase), with its derivative."""

    def __init__(self, bias, slope=0.0, terms=()):
        self.bias, self.slope, self.terms = bias, slope, terms

    def __call__(self, t):
        return self.bias + self.slope * t + sum(a * np.sin(w * t + ph) for a, w, ph in self.terms)

    def d(self, t):
        return self.slope + sum(a * w * np.cos(w * t + ph) for a, w, ph in self.terms)


def analytic(params=None):
    """Inputs (specific force, rates) and states of an exactly consistent trajectory."""
    p = params or {}
    u = Sinus(150.0, 0.0, ((p.get("au", 5.0), 0.4, 0.0),))
    v = Sinus(0.0, 0.0, ((p.get("av", 3.0), 0.9, 0.2),))
    w = Sinus(10.0, 0.0, ((p.get("aw", 4.0), 0.6, 1.0),))
    phi = Sinus(0.0, 0.0, ((p.get("aphi", 0.5), 0.7, 0.0),))
    th = Sinus(0.1, 0.0, ((p.get("ath", 0.2), 0.5, 0.3),))
    psi = Sinus(0.4, 0.05, ((0.1, 0.3, 0.0),))

    def inputs(t):
        ph, tt = phi(t), th(t)
        phd, thd, psd = phi.d(t), th.d(t), psi.d(t)
        pr = phd - psd * np.sin(tt)
        qr = thd * np.cos(ph) + psd * np.cos(tt) * np.sin(ph)
        rr = -thd * np.sin(ph) + psd * np.cos(tt) * np.cos(ph)
        uu, vv, ww = u(t), v(t), w(t)
        ax = u.d(t) - (rr * vv - qr * ww - G * np.sin(tt))
        ay = v.d(t) - (pr * ww - rr * uu + G * np.cos(tt) * np.sin(ph))
        az = w.d(t) - (qr * uu - pr * vv + G * np.cos(tt) * np.cos(ph))
        return np.stack([ax, ay, az], -1), np.stack([pr, qr, rr], -1)

    def states(t, h0=3000.0):
        def hdot(tt, h):
            return [u(tt) * np.sin(th(tt)) - v(tt) * np.cos(th(tt)) * np.sin(phi(tt))
                    - w(tt) * np.cos(th(tt)) * np.cos(phi(tt))]
        if t.size == 1:
            h = np.array([h0])
        else:
            h = solve_ivp(hdot, (t[0], t[-1]), [h0], t_eval=t, rtol=1e-12, atol=1e-10).y[0]
        return np.stack([u(t), v(t), w(t), phi(t), th(t), psi(t), h], -1)

    return inputs, states


