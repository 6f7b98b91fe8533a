"""Monte Carlo campaigns: how well does the estimator recover the truth, and are its error bars honest?

A scenario (TOML; :mod:`campaigns.montecarlo.scenario` documents the format) is a synth campaign
— fleet, maneuvers, Mach numbers, errors, winds — plus error *distributions*, the estimator's
settings and N replications. Replication ``k`` draws its error values, noise seeds and (when
drawn) winds and turbulence from ``(seed, k)``, instruments the shared flights, estimates, and
compares every estimate with its truth; one Parquet file per replication, resumable, locally or
on a Dask cluster (:mod:`campaigns.montecarlo.runner`); :mod:`campaigns.montecarlo.summary`
turns the files into bias, RMSE and scatter / Cramér-Rao tables and plots.

>>> from campaigns.montecarlo import load_scenario, run_montecarlo, summarize
>>> scenario = load_scenario("mc_20maneuvers")                     # doctest: +SKIP
>>> run_montecarlo(scenario, "out/mc20", workers=2, progress=True)  # doctest: +SKIP
>>> print(summarize("out/mc20").text())                             # doctest: +SKIP
"""

from .replication import ReplicationResult, run_replication
from .runner import MonteCarloInterrupted, RunReport, read_replication, run_montecarlo, scenario_of
from .scenario import Distribution, Scenario, ScenarioError, load_scenario, parse_scenario
from .summary import MonteCarloSummary, load_results, summarize, summarize_results

__all__ = [
    "Distribution", "MonteCarloInterrupted", "MonteCarloSummary", "ReplicationResult", "RunReport",
    "Scenario", "ScenarioError",
    "load_results", "load_scenario", "parse_scenario", "read_replication", "run_montecarlo",
    "run_replication", "scenario_of", "summarize", "summarize_results",
]
