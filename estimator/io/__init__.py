r"""Import flight data into an estimation :class:`~estimator.problem.Problem`.

Two ways in, one set of checks:

- :func:`load_problem` reads a **problem file** (TOML, below) that points at your flight data
  (CSV, whitespace-separated text, Parquet; PX4 ULog and MATLAB logs, :mod:`estimator.io.logs`)
  or at a dataset written by ``fpr fly``;
- :func:`problem_from_dataset` does the same for an ``fpr fly`` dataset from Python.

The problem file
----------------

Everything the estimator needs to know about your aircraft, your files and your model, in one
place. Paths are relative to the problem file. Positions are body axes (x forward, y right,
z down) from the aircraft's reference point::

    title = "PV1 vane calibration, flight 421"
    g_mps2 = 9.80665          # gravity of the flat-earth state equations (default 9.80665)
    lever_arm = "imu_point"   # optional: the accelerometers' lever arm in the state equations:
                              # "imu_point" (default; integrates the IMU point's velocity, exact)
                              # or "differentiated" (SPEC §3: angular accelerations from smoothed
                              # differentiation of the rates)
    model = "tejas"           # model set: a shipped name (estimator/models/*.toml) or a path
    channels = ["phi", "theta", "psi", "tas", "h", "h_dgps", "alpha_zl", "alpha_zr"]
                              # optional: the channels to fit; default: every channel of the
                              # model set that has data (the others are left out with a warning)
    resample_hz = 40.0        # optional, for every file: see "Sampling" below
    positions_checked = false # optional: true skips the check that refuses a position far outside
                              # the airframe the others span where inches or feet would fit (below)

    [sensors]                 # metres; a key ending _in or _ft gives inches or feet instead
    imu = [1.80, 0.10, 0.20]  # required: the accelerometer position (lever-arm correction)
    vane_left = [6.20, -0.45, 0.25]
    vane_right = [6.20, 0.45, 0.25]
    side_probe = [6.60, 0.0, 0.05]   # if absent, the mean of side_probe_left and side_probe_right
                                     # (the model set's [sensor_midpoints])
    # every sensor a channel of the model set names (tejas: vane_left, vane_right, side_probe,
    # nose_probe, boom_alpha_vane, boom_beta_upper_vane, boom_beta_lower_vane) needs a position

    [aircraft.PV1]            # one table per aircraft (tail number)
    r_cg_body_m = [0.33, 0.0, 0.13]  # CG (or r_cg_body_in / r_cg_body_ft); may be overridden
                                     # per [[files]] entry or per maneuver

    [columns]                 # canonical name -> source column (name or 0-based index) and unit
    t = { column = "Time", unit = "s" }
    ax = { column = "AX", unit = "g" }     # ax, ay, az: specific force at the IMU, body axes
    ay = { column = "AY", unit = "g" }
    az = { column = "AZ", unit = "g" }
    p = { column = "P", unit = "deg/s" }   # p, q, r: IMU body rates
    q = { column = "Q", unit = "deg/s" }
    r = { column = "R", unit = "deg/s" }
    phi = { column = "PHI", unit = "deg" } # Euler angles (INS)
    theta = { column = "THETA", unit = "deg" }
    psi = { column = "PSI", unit = "deg" } # heading may wrap (0/360 or +-180): it is unwrapped
    tas = { column = "TAS", unit = "kt" }  # true airspeed
    h = { column = "HP", unit = "ft" }     # pressure altitude
    alpha_zl = { column = 7, unit = "deg" }
    alpha_zr = { column = "AOA_R", unit = "deg", optional = true }
                              # optional: a file without this column simply has no such channel
    h_dgps = { column = "GPS_ALT", unit = "ft", own_rate = true }
                              # own_rate: recorded slower than the file's time base and empty
                              # between its samples (a 10 Hz GPS height in a 40 Hz file): fitted
                              # at its own samples only (interpolating it would delay it); or held,
                              # each sample repeated until the next (a 1-Hz GPS at 50 Hz): kept
                              # where its value changes
    gear = { column = "GEAR", unit = "1" } # any other data signal a model uses (1 = gear down)
    mach = { column = "MACH", unit = "1" }

    [[files]]                 # one entry per file
    path = "flight421.csv"
    format = "csv"            # csv | whitespace | parquet | ulog | mat; default from the
                              # extension (.csv; .txt .dat .asc; .parquet .pq; .ulg .ulog; .mat)
    header = true             # text files: first line names the columns; false: by index only
                              # (a first line of numbers is data, not a header: see below)
    delimiter = ","           # csv only (default ","; ";" for many European exports)
    decimal = "."             # text files: the decimal mark (default "."; "," for a decimal comma)
    skip_rows = 0             # text files: lines before the header (e.g. a title block)
    encoding = "utf-8"        # text files (default utf-8; e.g. "latin-1", "cp1252", "utf-16")
    aircraft = "PV1"          # default: the only [aircraft.*] table
    configuration = "PV1-NP"  # default: the aircraft id
    resample_hz = 40.0        # overrides the top-level value for this file
    columns = { alpha_zl = { column = "AOA_L", unit = "deg" } }  # per-file column changes
    maneuvers = [             # time ranges (s, in the file's time base after converting t to
                              # seconds), both ends included; omit: the whole file is
                              # one maneuver whose id is the file name without extension
      { id = "pd1", t_start_s = 120.0, t_end_s = 155.0 },
      { id = "wut1", t_start_s = 300.0, t_end_s = 340.0, configuration = "PV1-NP" },
    ]

    [plausible]               # optional: the aircraft's ranges where the import's unit checks
    tas = { range = [60.0, 900.0], unit = "kt" }   # (built in: a fighter's or an airliner's)
                              # are not its own: a median airspeed of 15-700 m/s, a height of
                              # -500 to 25 000 m (a 12 m/s UAV: range = [5, 40], unit = "m/s");
                              # also in the model set; the problem file's wins
    [parameter.b_l]           # change any parameter of the model set; the keys are the model-set
    free = true               # format's (estimator/io/modelset.py) and merge into its declaration:
    bounds_deg = [-3.0, 3.0]  # value_deg replaces value, bounds replaces bounds_deg, ...
    [parameter.u0]
    values = { pd1 = 152.0 }  # start values of particular instances (here: maneuver pd1, m/s)

    [[channel]]               # channels of your own, same format as the model set; a channel
    name = "alpha_5h"         # with a model-set channel's name replaces it
    sensor = "five_hole"
    model = "alpha_s + k_5h * alpha_s + b_5h"
    delay = "tau_5h"
    [parameter.b_5h]          # ... and its parameters
    unit = "rad"
    kind = "bias"
    scope = "aircraft"

    [solver]                  # options of the calibration (optional), by the names fpr calibrate's
    max_iterations = 60       # flags set: estimator.solver.SolverOptions ...
    start = "staged"          # "staged", "given" or "both"
    [workflow]                # ... estimator.workflow.WorkflowOptions ...
    max_mach_variation = 0.05
    reference_mach = 0.5
    [report]                  # ... and the report's
    plots = true

Instead of ``[[files]]``, ``[columns]`` and ``[aircraft]``, a dataset written by ``fpr fly``::

    [data]
    dataset = "data/small"    # the directory holding manifest.json
    select = { kind = ["pitch_doublet", "3211"], configuration = ["PV1-NP"], aircraft = ["PV1"],
               mach_min = 0.45, mach_max = 0.55, gear_down = false, ids = ["m0000"] }

Its columns are known by their SI names: the format's own (``t_s`` -> ``t``, ``q_rps`` -> ``q``,
``gear_down`` -> ``gear``, ``mach``, ...: :data:`FPR_COLUMNS`) and, for every other column, its
name less its unit suffix (``alpha_zl_rad`` -> ``alpha_zl``); besides the format's own, only the
columns of the model set's channels and of the data signals their models read are read. Sensor
positions come from the manifest's airframe (``[sensors]`` may add or replace some), each
maneuver's CG from its ``r_cg_body_m_mean``, aircraft and configuration from its entry. The
truth (``true_*`` columns) is not part of the problem; each maneuver's ``meta`` keeps its manifest
entry and the dataset path, and :func:`load_truth` reads the truth for the comparison afterwards.

The ``[solver]``, ``[workflow]`` and ``[report]`` tables each take only their own options (a
misspelt or misplaced one is refused with the close match);
:meth:`estimator.calibration.CalibrationOptions.from_mapping` maps them, the one mapping
``fpr calibrate``'s flags and a Monte Carlo scenario's ``[estimator]`` go through too. They are
kept in ``problem.options`` and :func:`estimator.calibrate` uses them unless given others.
Precedence, lowest first: the defaults; the model set's declarations (its own ``[workflow]
reference_mach`` declares the aircraft's reference Mach); the problem file's options; the flags
given to ``fpr calibrate`` (or the mapping passed to :func:`estimator.calibrate`).

Canonical names. ``t``, ``ax``, ``ay``, ``az``, ``p``, ``q``, ``r`` are required. A name that is
the ``column`` of a model-set channel (tejas: ``phi theta psi tas h h_dgps alpha_zl alpha_zr
alpha_zsp beta_zsp beta_znp alpha_zb beta_zbu beta_zbl``) is that channel's measurement; ``gear``,
``mach`` and any other name a channel model reads are data signals. Any other name is an error (a
typo such as ``alpha_lz`` would silently drop the channel): the message suggests the closest valid
name and lists them all. A channel without data in some maneuvers (a nose probe on one aircraft, a
boom on another) is simply not fitted there; its aircraft- or configuration-scoped parameters are
held fixed for the aircraft that have no data for them.

Units (``value_SI = value * factor + offset``): time ``s ms``; angle ``rad deg mrad``; angular
rate ``rad/s deg/s``; acceleration ``m/s^2 g ft/s^2`` (g = 9.80665 m/s^2); speed ``m/s kt ft/s
km/h``; length ``m ft in``; dimensionless ``1 bool``; pressure ``Pa hPa kPa mbar psf``;
temperature ``K degC``. A unit must fit the quantity (``t`` a time, ``p`` an angular rate, a
channel its model set's unit).

What is checked
---------------

Bad input raises :class:`DataError` naming the file, maneuver, time range, channel and source
column, the time and data row (0-based, after the header) of the first bad sample, and the fix:

- a missing file, an unknown key, an unknown canonical name under ``[columns]``, a
  ``[parameter.NAME]`` the model set does not have and no channel uses (each with the closest
  valid name suggested), an unknown unit (the valid ones are listed), a unit of the wrong
  dimension, a column the file does not have (its columns are listed, with the closest), a
  column name the file has twice, a data path that is missing, a folder or an empty file, text
  that is not UTF-8 (or the declared ``encoding``), a file that does not parse (the message names
  the ``delimiter`` its lines use, a decimal comma, or the ``skip_rows`` of a title block),
  numbers with a decimal comma (``decimal = ","``);
- the header: a first line (after ``skip_rows``) that parses as numbers is data, not a header.
  With every column taken by index it is read as the first data row, with a
  :class:`DataWarning`; with columns taken by name it is an error (set ``header = false`` and give
  0-based column indices). A first line of names read with ``header = false`` is an error;
- no data for a required input; a channel listed in ``channels`` that no maneuver has data for
  (unlisted channels without data are left out with a :class:`DataWarning`); a channel model
  using a data signal a maneuver lacks; a sensor without a position;
- time not strictly increasing (duplicated or going back) anywhere in a file; a maneuver's time
  range outside the file's span;
- NaN, empty or non-numeric cells in any mapped column inside a maneuver (an ``own_rate``
  channel may be empty between its samples, but needs two of them). A column empty on all but
  every k-th row is named as a slower channel: the message says to mark it ``own_rate = true``
  (a measured channel) or to fill it in (an IMU input, an Euler angle, a data signal). A channel
  that repeats each value for k rows (a slower channel written by holding) gives a warning
  naming ``own_rate``;
- gaps: a step longer than :data:`~estimator.io.timebase.GAP_FACTOR` (1.5) times the median step;
- non-uniform sampling: steps off the median by more than
  :data:`~estimator.io.timebase.JITTER_FRACTION` (1 %). Stamps that stay within
  :data:`~estimator.io.timebase.STAMP_TOLERANCE` (10 %) of a step of a uniform grid — a recorder's
  clock resolution or jitter (1 ms stamps at 64 Hz, 1/1024 s ticks at 50 Hz) — are taken as that
  grid's samples, at its nominal rate (a common recorder rate or whole hertz when it fits, else
  the fitted rate), with a :class:`DataWarning` giving the largest deviation. Stamps rounded to a
  tick (time written with 2 decimals) that stay within half that tick of a uniform grid are taken
  as that grid, the warning saying they were rounded; stamps straying further when half a tick
  exceeds 10 % of a step give an error asking for more decimals (not ``resample_hz``, which would
  interpolate from stamps that are themselves off). Other non-uniform
  sampling is an error naming the nominal rate, unless ``resample_hz`` is given, in which case
  the maneuver is linearly interpolated from its stamps onto ``t_start + k / resample_hz`` (no
  anti-aliasing filter; downsampling by more than 2 gives a warning);
- units that cannot be right: values far outside what an aircraft does in the declared unit
  (angles declared rad beyond ~1.6 rad, rates beyond 6 rad/s, a mean specific force outside
  0.4 to 4 g, airspeed outside 15 to 700 m/s, altitude outside -500 to 25 000 m, a time step
  outside 0.1 ms to 2 s, ...); true airspeed / Mach that is not a speed of sound; Euler angles
  that change 57 times faster or slower than the body rates say (a degree/radian mistake of
  that angle, or of the rates if all angles disagree alike or the angle's declared unit cannot be
  off that way: rates in rad/s declared deg/s, tested on the pitch angle of a pitch doublet). The
  message gives the observed value and suggests a unit only when the bulk of the data (without
  its 1 % extremes) is implausible in the declared unit; otherwise the out-of-range samples are
  named as spikes (:mod:`estimator.io.plausibility`, :mod:`estimator.io.consistency`);
- spikes: samples (one, or a burst) that jump far outside the plausible range while the rest of
  the channel is plausible are named with their times and rows as spikes, never as a unit error
  (and a unit is never suggested from them): replace them in the file or cut them out of the
  maneuver's time range;
- a maneuver shorter than :data:`~estimator.io.modelset.MIN_DURATION_S` (5 s) or with fewer than
  :data:`~estimator.io.modelset.MIN_SAMPLES_PER_FREE_PARAMETER` (10) samples per free
  per-maneuver parameter: those parameters (initial conditions, IMU biases) are estimated from
  that maneuver alone;
- duplicate maneuver ids; a g_mps2 that is not an Earth gravity in m/s^2;
- positions (``[sensors]``, every ``r_cg_body_*``) that cannot be points of one airframe
  (:mod:`estimator.io.positions`): two positions further apart than any aircraft (120 m); a
  position under a metre key far outside the cross-section the others span (more than twice its
  extent, at least 3 m from each) that lands among them read as inches (/ 39.37) or feet
  (/ 3.281): a CG in inches under ``r_cg_body_m``. The message names the key and its line, the
  unit and the key to write it under (``r_cg_body_in``); ``positions_checked = true`` skips the
  second check for a layout that is right (never the first).

Each maneuver's ``meta`` holds its file and time range (or its manifest entry) and, from the
data, ``mach_mean``, ``mach_min``, ``mach_max`` and ``gear_down`` when Mach and gear are mapped.
The calibration workflow (:mod:`estimator.workflow`, ``fpr calibrate``) sorts maneuvers into Mach
bins by ``mach_mean``: without a ``mach`` column it stops with a message saying so and naming
the single estimation over all maneuvers (``fpr calibrate --single``), which needs no Mach.

Start values of the initial conditions ``u0 v0 w0 phi0 theta0 psi0 h0`` come from the first
:data:`~estimator.io.modelset.IC_AVERAGE_SAMPLES` samples of each maneuver (measured TAS, the first
measured flow angles, Euler angles, altitude); values given in the problem file win.
"""

from estimator.io.build import StateEquations, subproblem
from estimator.io.dataset_problem import load_dataset_maneuvers, problem_from_dataset
from estimator.io.errors import DataError, DataWarning
from estimator.io.fprdataset import FPR_COLUMNS, dataset_column, load_truth
from estimator.io.modelset import (
    IC_AVERAGE_SAMPLES,
    MIN_DURATION_S,
    MIN_SAMPLES_PER_FREE_PARAMETER,
    initial_condition_starts,
)
from estimator.io.problemfile import load_problem
from estimator.io.timebase import GAP_FACTOR, JITTER_FRACTION, STAMP_TOLERANCE
from estimator.io.units import UNITS, to_si

__all__ = [
    "FPR_COLUMNS", "GAP_FACTOR", "IC_AVERAGE_SAMPLES", "JITTER_FRACTION", "MIN_DURATION_S",
    "MIN_SAMPLES_PER_FREE_PARAMETER", "STAMP_TOLERANCE", "UNITS", "DataError", "DataWarning",
    "StateEquations", "dataset_column", "initial_condition_starts", "load_dataset_maneuvers",
    "load_problem", "load_truth", "problem_from_dataset", "subproblem", "to_si",
]
