"""The estimator tests' analytic flight, which shipped code owns: :mod:`campaigns.analytic_flight`.

Kept for the tests that import it from here (test_kinematics); new code imports the module itself.
"""

from __future__ import annotations

from campaigns.analytic_flight import G, analytic

__all__ = ["G", "analytic"]
