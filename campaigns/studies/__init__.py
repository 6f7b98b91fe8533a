"""Planning studies: which maneuvers to fly, judged by Cramér-Rao bounds and Monte Carlo.

Each study is a runnable script that builds Monte Carlo scenarios (:mod:`campaigns.montecarlo`),
runs them (resumably: the same command again skips finished replications) and writes a text
table and a PNG plot; the committed results are in ``campaigns/studies/results/``.

(a) :mod:`campaigns.studies.shss_segments` — the steady-heading sideslip flown as one long
    maneuver or split into 30-40 s segments (the paper's practice)::

        python -m campaigns.studies.shss_segments --out runs/shss --results campaigns/studies/results

(b) :mod:`campaigns.studies.maneuvers_per_bin` — how many maneuvers per Mach bin reach the vane
    AOA requirement (±0.5 deg 3-sigma)::

        python -m campaigns.studies.maneuvers_per_bin --out runs/per_bin --results campaigns/studies/results

(c) :mod:`campaigns.studies.tolerance` — how large IMU biases, time delays, winds and turbulence
    may be before the desired accuracy is lost::

        python -m campaigns.studies.tolerance --out runs/tolerance --results campaigns/studies/results

(d) :mod:`campaigns.studies.robustness` — IMU biases of 1, 2, 3 and -3 times the typical values
    from zero start values: does the estimator reach the true minimum, and does it ever call a
    wrong one a success::

        python -m campaigns.studies.robustness --out runs/robustness --results campaigns/studies/results

Every study stands on :mod:`campaigns.studies.scaffold` (the shared command line ``--out``,
``--results``, ``--replications``, ``--workers``, ``--size``; running the Monte Carlo runs; the
results files ``NAME.txt`` / ``.csv`` / ``.png``; the report's header) and keeps only its own
configuration, analysis and report; what several studies share about their flights and fits is in
:mod:`campaigns.studies.common`. :mod:`campaigns.studies.invocations` records what each run cost and
which code ran it (``OUT/NAME_invocations.json``).
"""
