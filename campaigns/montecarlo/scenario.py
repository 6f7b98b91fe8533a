"""Monte Carlo scenarios: the flights of a synth campaign, error distributions, N replications.

A scenario file is a campaign file (:mod:`synth.campaign`: fleet, local-flow truth, ADC baseline,
``seed``, ``common_rate_hz``, ``[environment]``, ``[errors]``, ``[[flights]]``) plus three things
a campaign does not have::

    replications = 100              # N
    seed = 2026                     # the master seed (the campaign's own ``seed`` key)

    [draw]                          # what changes from one replication to the next
    turbulence = "redraw"           # "redraw" (default): a new turbulence realisation per
                                    # replication; "frozen": the campaign's one realisation
    [draw.errors]                   # dotted error paths (synth.errors.ErrorConfig.with_values),
                                    # edge units allowed in the last part (_deg, _deg_s, _ms)
    "imu.accel_bias_mps2" = { dist = "normal", std = 0.05, scope = "maneuver" }
    "imu.gyro_bias_deg_s" = { dist = "normal", mean = [0.0, 0.0, 0.0], std = 0.2 }
    "sensors.vane_left.delay_ms" = { dist = "uniform", half_width = 20.0 }
    "recorders.ins.clock_offset_ms" = { dist = "uniform", low = -40.0, high = 40.0 }
    [draw.environment]
    wind_ned_mps = { dist = "uniform", half_width = [10.0, 10.0, 0.0] }

    [estimator]                     # what the estimator is asked (estimator.io.problem_from_dataset)
    model = "tejas"                 # model set
    channels = ["phi", "theta", "psi", "tas", "h", "alpha_zl", "alpha_zr"]   # optional
    select = { kind = ["pitch_doublet", "3211"] }   # optional: the maneuvers to estimate from
    lever_arm = "imu_point"
    max_iterations = 40             # kept here for old scenario files: solver options, as under
    colored = true                  # [estimator.solver] (Morelli-Klein coloured-residual deviations)
    [estimator.solver]              # estimator.solver.SolverOptions by name, as a problem file's
    start = "staged"                # [solver] and fpr calibrate's flags (one mapping:
    robust = false                  # estimator.calibration.CalibrationOptions.from_mapping)
    [estimator.parameters]          # which parameters are free: [parameter.NAME] of a problem file
    h0 = { free = true }
    f2 = { free = false }

A distribution is ``normal`` (``std``, centred on ``mean``) or ``uniform`` (``low``/``high``, or
``half_width`` around ``mean``); ``mean`` defaults to the value the campaign's ``[errors]`` (or
``[environment]``) gives the path, so ``std`` alone scatters around the typical value. Numbers are
scalars or vectors as the path's value is. ``scope`` says who shares a draw: ``"replication"``
(default: one value for the whole fleet, as the estimator's global parameters assume — time
delays, table errors), ``"aircraft"`` (one per aircraft, like the estimator's per-aircraft biases)
or ``"maneuver"`` (one per flown maneuver, like its per-maneuver IMU biases). Everything not drawn
is fixed at the campaign's value.

Seeds. Replication ``k`` draws everything from generators seeded by ``(seed, k, ...)``: its error
values (``default_rng([seed, k, 1, crc32(path), instance])``), its noise seeds (every
``[errors]`` source seed derives from ``seed_k``, itself from ``SeedSequence([seed, k])``) and its
turbulence seeds. Nothing depends on the order in which replications run or on the executor.
``[errors.seeds]`` is refused: fixed noise seeds would give every replication the same noise.

Flights. A maneuver whose flight does not change between replications (no drawn wind, turbulence
"none" or "frozen") is flown once and its truth reused; only the sensors are re-instrumented.
"""

from __future__ import annotations

import copy
import hashlib
import json
import tomllib
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from aircraft_models.schema import SUFFIXES, check, did_you_mean
from estimator.calibration import CalibrationOptions, option_tables
from estimator.io import StateEquations, problem_from_dataset
from estimator.problem import Problem
from estimator.solver import SolverOptions
from synth.campaign import CAMPAIGN_DIR, Campaign, Job, parse_campaign
from synth.environment import Environment
from synth.errors import ErrorConfig

#: keys a scenario adds to a synth campaign file
_MC_KEYS = {"replications", "draw", "estimator"}
_DRAW_KEYS = ("turbulence", "errors", "environment")
_DIST_KEYS = ("dist", "mean", "std", "low", "high", "half_width", "scope")
_ESTIMATOR_KEYS = ("model", "channels", "select", "lever_arm", "max_iterations", "colored",
                   "parameters", "g_mps2", "solver")
#: solver options an [estimator] table may give directly (older scenario files), not under [estimator.solver]
_FLAT_SOLVER_KEYS = ("max_iterations", "colored")
SCOPES = ("replication", "aircraft", "maneuver")
#: edge-unit suffix of a drawn error path -> (SI suffix, factor to SI), the edge units synth.errors
#: accepts, from the schema's one table (the longer suffix first: _deg_per_deg, _deg_s, _deg, _ms)
_EDGE_UNITS = tuple((edge, SUFFIXES[unit][0][0], factor) for unit in ("rad/rad", "rad/s", "rad", "s")
                    for edge, factor in SUFFIXES[unit][1:])
#: environment fields a scenario may draw
_ENV_DRAWABLE = ("wind_ned_mps",)


class ScenarioError(ValueError):
    """A Monte Carlo scenario that cannot be run as written; the message says how to fix it."""


def _si_path(path: str) -> tuple[str, float]:
    """The SI form of a dotted error path and the factor from its edge unit to SI."""
    head, _, last = path.rpartition(".")
    for edge, si, factor in _EDGE_UNITS:
        if last.endswith(edge):
            return (f"{head}." if head else "") + last[: -len(edge)] + si, factor
    return path, 1.0


def _lookup(tree: Mapping, path: str) -> Any:
    node: Any = tree
    for part in path.split("."):
        if not isinstance(node, Mapping) or part not in node:
            raise KeyError(path)
        node = node[part]
    return node


@dataclass(frozen=True)
class Distribution:
    """One drawn value: which path, which law, who shares it. Parameters are SI.

    Attributes
    ----------
    target : "errors" (an ErrorConfig path) or "environment" (an Environment field).
    path : dotted SI path (``imu.gyro_bias_rps``) or environment field (``wind_ned_mps``).
    dist : "normal" or "uniform".
    mean : centre; None = the campaign's value for the maneuver.
    std : normal standard deviation.
    low, high : uniform bounds (absolute), or None with ``half_width`` around the centre.
    scope : "replication", "aircraft" or "maneuver" (see the module docstring).
    """

    target: str
    path: str
    dist: str
    mean: np.ndarray | None = None
    std: np.ndarray | None = None
    low: np.ndarray | None = None
    high: np.ndarray | None = None
    half_width: np.ndarray | None = None
    scope: str = "replication"

    @property
    def stream(self) -> int:
        """A stable number of this path, part of its generator's seed: adding or reordering
        distributions in the file does not change the others' draws."""
        return zlib.crc32(f"{self.target}:{self.path}".encode())

    def value(self, unit_draw: np.ndarray, centre: np.ndarray) -> np.ndarray:
        """The drawn value from standard draws (N(0,1) or U(0,1)) and the campaign's value."""
        centre = centre if self.mean is None else self.mean
        if self.dist == "normal":
            return centre + self.std * unit_draw
        if self.low is not None:
            return self.low + (self.high - self.low) * unit_draw
        return centre + self.half_width * (2.0 * unit_draw - 1.0)

    def standard_draw(self, rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
        return rng.standard_normal(shape) if self.dist == "normal" else rng.random(shape)


def _parse_distribution(target: str, key: str, spec: Any, where: str) -> Distribution:
    if not isinstance(spec, Mapping):
        raise ScenarioError(f"{where}: {key} = {spec!r}; give a table such as "
                            "{ dist = \"normal\", std = 0.1 } or { dist = \"uniform\", half_width = 0.2 }")
    check(spec, _DIST_KEYS, f"{where}: {key}", ScenarioError)
    dist = spec.get("dist")
    if dist not in ("normal", "uniform"):
        raise ScenarioError(f"{where}: {key}: dist = {dist!r}; give dist = \"normal\" or \"uniform\"")
    scope = spec.get("scope", "replication")
    if scope not in SCOPES:
        raise ScenarioError(f"{where}: {key}: scope = {scope!r}{did_you_mean(scope, SCOPES)}; "
                            f"valid: {list(SCOPES)}")
    path, factor = _si_path(key) if target == "errors" else (key, 1.0)

    def arr(name: str) -> np.ndarray | None:
        if name not in spec:
            return None
        try:
            a = np.asarray(spec[name], dtype=float) * factor
        except (TypeError, ValueError):
            raise ScenarioError(f"{where}: {key}.{name} = {spec[name]!r} is not a number or list of "
                                "numbers") from None
        if not np.all(np.isfinite(a)):
            raise ScenarioError(f"{where}: {key}.{name} must be finite")
        a.setflags(write=False)
        return a

    d = Distribution(target=target, path=path, dist=dist, mean=arr("mean"), std=arr("std"),
                     low=arr("low"), high=arr("high"), half_width=arr("half_width"), scope=scope)
    if dist == "normal":
        if d.std is None or np.any(d.std < 0):
            raise ScenarioError(f"{where}: {key}: a normal distribution needs std >= 0")
        if d.low is not None or d.high is not None or d.half_width is not None:
            raise ScenarioError(f"{where}: {key}: low/high/half_width belong to dist = \"uniform\"")
    else:
        if d.std is not None:
            raise ScenarioError(f"{where}: {key}: std belongs to dist = \"normal\"")
        bounds = d.low is not None and d.high is not None
        if bounds == (d.half_width is not None) or (d.low is None) != (d.high is None):
            raise ScenarioError(f"{where}: {key}: a uniform distribution needs low and high, or "
                                "half_width (around mean or the campaign's value), not both")
        if bounds and (d.mean is not None or np.any(d.high < d.low)):
            raise ScenarioError(f"{where}: {key}: needs low <= high, and no mean beside them")
        if d.half_width is not None and np.any(d.half_width < 0):
            raise ScenarioError(f"{where}: {key}: half_width must be >= 0")
    return d


@dataclass(frozen=True)
class EstimatorSettings:
    """What each replication's estimation is asked (see the module docstring, ``[estimator]``)."""

    model: str = "tejas"
    channels: tuple[str, ...] | None = None
    select: Mapping[str, Any] | None = None
    lever_arm: str = "imu_point"
    max_iterations: int = 40
    colored: bool = True
    parameters: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    g_mps2: float = 9.80665
    #: the solver's options (``[estimator.solver]`` and the flat ``max_iterations``/``colored``,
    #: mapped by :meth:`estimator.calibration.CalibrationOptions.from_mapping`)
    solver: SolverOptions = field(default_factory=SolverOptions)

    def problem(self, dataset: str | Path) -> Problem:
        """The estimation problem of a replication's ``dataset`` folder, as these settings ask."""
        return problem_from_dataset(dataset, select=self.select, model=self.model, channels=self.channels,
                                    overrides=self.parameters or None,
                                    equations=StateEquations(self.g_mps2, self.lever_arm))


@dataclass(frozen=True)
class ManeuverDraw:
    """One maneuver of one replication: the errors its sensors get and the air it flies in."""

    job: Job
    errors: ErrorConfig
    environment: Environment
    reflown: bool


@dataclass(frozen=True)
class ReplicationDraw:
    """Everything replication ``index`` draws.

    Attributes
    ----------
    index : the replication.
    noise_seed : the master seed of its noise sources (``ErrorConfig.from_dict(seed=...)``).
    maneuvers : per campaign job, in job order.
    values : one row per drawn value: (path, instance, component, value SI).
    """

    index: int
    noise_seed: int
    maneuvers: tuple[ManeuverDraw, ...]
    values: tuple[tuple[str, str, int, float], ...]


@dataclass(frozen=True)
class Scenario:
    """A parsed Monte Carlo scenario (see the module docstring).

    Attributes
    ----------
    campaign : the flights (synth's campaign of the same file; ``campaign.seed`` is the master seed).
    replications : N.
    distributions : the drawn values.
    turbulence : "redraw" or "frozen".
    estimator : the estimation settings.
    raw : the scenario as read (TOML tables), hashed into :attr:`hash`.
    source : where it came from.
    """

    name: str
    description: str
    campaign: Campaign
    replications: int
    distributions: tuple[Distribution, ...]
    turbulence: str
    estimator: EstimatorSettings
    raw: dict = field(repr=False)
    source: str = "<dict>"

    @property
    def seed(self) -> int:
        return self.campaign.seed

    @property
    def hash(self) -> str:
        """Fingerprint of everything that decides the results, N excepted (a campaign may grow)."""
        return scenario_hash(self.raw)

    def reflies(self, job: Job) -> bool:
        """True when the maneuver's flight changes from replication to replication."""
        if any(d.target == "environment" for d in self.distributions):
            return True
        return self.turbulence == "redraw" and job.environment.get("turbulence", "none") != "none"

    @property
    def fixed_jobs(self) -> tuple[Job, ...]:
        """The maneuvers flown once for all replications."""
        return tuple(j for j in self.campaign.jobs if not self.reflies(j))

    def draw(self, index: int) -> ReplicationDraw:
        """Replication ``index``'s error values, noise seeds and environments (deterministic)."""
        if index < 0:
            raise ValueError(f"replication index {index} must be >= 0")
        seed = self.seed
        noise_seed = int(np.random.SeedSequence([seed, index]).generate_state(1)[0])
        aircraft_ids = sorted(self.campaign.fleet.aircraft)
        fleet = self.campaign.fleet
        values: dict[tuple[str, str, int], float] = {}
        out = []
        for job in self.campaign.jobs:
            aircraft = fleet.configurations[job.configuration_id].aircraft.id
            instance = {"replication": ("", 0), "aircraft": (aircraft, 1 + aircraft_ids.index(aircraft)),
                        "maneuver": (f"j{job.index:04d}", job.index)}
            base = ErrorConfig.from_dict(job.errors, seed=noise_seed)
            base_tree = base.to_dict()
            # the full form, defaults included, so an undrawn-but-defaulted field has a centre
            env_tree = Environment.from_dict(dict(job.environment)).to_dict()
            err_changes: dict[str, Any] = {}
            for d in self.distributions:
                label, inst = instance[d.scope]
                tree = base_tree if d.target == "errors" else env_tree
                centre = np.asarray(_lookup(tree, d.path), dtype=float)
                rng = np.random.default_rng([seed, index, 1, d.stream, inst])
                v = d.value(d.standard_draw(rng, centre.shape), centre)
                for c, x in enumerate(np.ravel(v)):
                    values[(f"{d.target}.{d.path}", label, c)] = float(x)
                if d.target == "errors":
                    err_changes[d.path] = tuple(v.tolist()) if v.ndim else float(v)
                else:
                    env_tree[d.path] = v.tolist()
            reflown = self.reflies(job)
            if reflown and self.turbulence == "redraw" and env_tree.get("turbulence", "none") != "none":
                env_tree["turbulence_seed"] = int(
                    np.random.SeedSequence([seed, index, 3, job.index]).generate_state(1)[0] % 2**31)
            where = f"{self.source}: replication {index}, maneuver {job.index}"
            try:
                errors = base.with_values(err_changes) if err_changes else base
                env = Environment.from_dict(env_tree)
            except (ValueError, TypeError) as exc:
                raise ScenarioError(f"{where}: a drawn value is not allowed: {exc}; narrow the "
                                    "distribution in [draw]") from None
            out.append(ManeuverDraw(job=job, errors=errors, environment=env, reflown=reflown))
        rows = tuple((p, inst, c, v) for (p, inst, c), v in sorted(values.items()))
        return ReplicationDraw(index=index, noise_seed=noise_seed, maneuvers=tuple(out), values=rows)


def scenario_hash(raw: Mapping) -> str:
    """sha256 of the scenario's canonical JSON, ``replications`` left out."""
    doc = {k: v for k, v in raw.items() if k != "replications"}
    text = json.dumps(doc, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def _solver_options(est: Mapping, where: str) -> SolverOptions:
    """``[estimator.solver]`` and the flat ``max_iterations``/``colored`` through the one mapping
    of option names (:meth:`estimator.calibration.CalibrationOptions.from_mapping`)."""
    table = est.get("solver", {})
    if not isinstance(table, Mapping):
        raise ScenarioError(f"{where}.solver must be a table of option = value, got {table!r}")
    check(table, option_tables()["solver"], f"{where}.solver", ScenarioError, what="solver option")
    twice = [k for k in _FLAT_SOLVER_KEYS if k in est and k in table]
    if twice:
        raise ScenarioError(f"{where}: {twice} given both in [estimator] and [estimator.solver]; keep one")
    options = {**{k: est[k] for k in _FLAT_SOLVER_KEYS if k in est}, **table}
    try:
        return CalibrationOptions.from_mapping(options).workflow.solver
    except (TypeError, ValueError) as exc:
        raise ScenarioError(f"{where}: {exc}") from None


def parse_scenario(raw: Mapping, source: str = "<dict>") -> Scenario:
    """Validate a scenario mapping (as read from TOML); errors name the file and the key."""
    raw = copy.deepcopy(dict(raw))
    campaign_raw = {k: v for k, v in raw.items() if k not in _MC_KEYS}
    if "seeds" in raw.get("errors", {}) or any(
            "seeds" in v for v in raw.get("errors", {}).get("aircraft", {}).values()):
        raise ScenarioError(f"{source}: [errors.seeds] would give every replication the same noise; "
                            "remove it (each replication derives its noise seeds from seed and its index)")
    if "seed" not in raw:
        raise ScenarioError(f"{source}: give seed = <integer>, the master seed of every replication")
    try:
        campaign = parse_campaign(campaign_raw, source=source)
    except (ValueError, KeyError) as exc:
        raise ScenarioError(str(exc).strip("'\"")) from None
    n = raw.get("replications")
    if not isinstance(n, int) or isinstance(n, bool) or n < 1:
        raise ScenarioError(f"{source}: replications = {n!r}; give the number of replications, an "
                            "integer >= 1 (the command line's --replications overrides it)")
    draw = dict(raw.get("draw", {}))
    check(draw, _DRAW_KEYS, f"{source}: [draw]", ScenarioError)
    turbulence = draw.get("turbulence", "redraw")
    if turbulence not in ("redraw", "frozen"):
        raise ScenarioError(f"{source}: [draw] turbulence = {turbulence!r}; give \"redraw\" or \"frozen\"")
    dists = [_parse_distribution("errors", k, v, f"{source}: [draw.errors]")
             for k, v in dict(draw.get("errors", {})).items()]
    for k, v in dict(draw.get("environment", {})).items():
        if k not in _ENV_DRAWABLE:
            raise ScenarioError(f"{source}: [draw.environment]: {k!r} cannot be drawn"
                                f"{did_you_mean(k, _ENV_DRAWABLE)}; drawable: "
                                f"{list(_ENV_DRAWABLE)} (turbulence realisations: [draw] turbulence)")
        dists.append(_parse_distribution("environment", k, v, f"{source}: [draw.environment]"))
    seen: set[str] = set()
    for d in dists:
        if d.path in seen:
            raise ScenarioError(f"{source}: [draw] {d.path} is drawn twice (in two units?); keep one")
        seen.add(d.path)
    est = dict(raw.get("estimator", {}))
    check(est, _ESTIMATOR_KEYS, f"{source}: [estimator]", ScenarioError)
    channels = est.get("channels")
    solver = _solver_options(est, f"{source}: [estimator]")
    settings = EstimatorSettings(
        model=str(est.get("model", "tejas")),
        channels=None if channels is None else tuple(str(c) for c in channels),
        select=est.get("select"),
        lever_arm=str(est.get("lever_arm", "imu_point")),
        max_iterations=solver.max_iterations,
        colored=solver.colored,
        parameters={str(k): dict(v) for k, v in dict(est.get("parameters", {})).items()},
        g_mps2=float(est.get("g_mps2", 9.80665)),
        solver=solver,
    )
    scenario = Scenario(name=str(raw.get("name", Path(source).stem)),
                        description=str(raw.get("description", "")), campaign=campaign,
                        replications=n, distributions=tuple(dists), turbulence=turbulence,
                        estimator=settings, raw=raw, source=source)
    # draw replication 0 now: a path that does not exist or a value out of range fails before
    # an hour of computing, with the key named
    for d in dists:
        if d.target == "errors":
            base = ErrorConfig.from_dict(campaign.jobs[0].errors).to_dict()
            try:
                centre = np.asarray(_lookup(base, d.path), dtype=float)
            except KeyError:
                raise ScenarioError(
                    f"{source}: [draw.errors] {d.path!r} is not an error value; use a dotted path of "
                    "synth.errors.ErrorConfig such as imu.accel_bias_mps2, sensors.vane_left.delay_ms, "
                    "recorders.ins.clock_offset_ms") from None
            for name in ("mean", "std", "low", "high", "half_width"):
                a = getattr(d, name)
                if a is not None and a.ndim and a.shape != centre.shape:
                    raise ScenarioError(f"{source}: [draw.errors] {d.path}.{name} has {a.size} values, "
                                        f"the error has {centre.size}")
    scenario.draw(0)
    return scenario


def resolve_scenario_path(name_or_path: str | Path) -> Path:
    """A scenario file path, or the name of one shipped in ``campaigns/`` (``mc_20maneuvers``)."""
    p = Path(name_or_path)
    if p.is_file():
        return p
    shipped = CAMPAIGN_DIR / f"{p.name}.toml"
    if len(p.parts) == 1 and not p.suffix and shipped.exists():
        return shipped
    raise FileNotFoundError(
        f"{name_or_path}: no such scenario file, nor one shipped in {CAMPAIGN_DIR} "
        f"(shipped: {sorted(q.stem for q in CAMPAIGN_DIR.glob('mc_*.toml'))})")


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Read and validate a scenario TOML file (path or shipped name)."""
    path = resolve_scenario_path(name_or_path)
    try:
        raw = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path}: not valid TOML: {exc}") from None
    return parse_scenario(raw, source=str(path))


def with_replications(scenario: Scenario, n: int | None) -> Scenario:
    """The same scenario with another N (the hash does not change)."""
    if n is None or n == scenario.replications:
        return scenario
    if n < 1:
        raise ScenarioError(f"--replications {n}: give at least 1")
    raw = dict(scenario.raw, replications=int(n))
    return parse_scenario(raw, source=scenario.source)


def draws_table(draw: ReplicationDraw) -> Sequence[dict]:
    """The drawn values as records (path, instance, component, value)."""
    return [{"path": p, "instance": i, "component": c, "value": v} for p, i, c, v in draw.values]
