"""Shared test fixtures: the synthetic campaigns the end-to-end tests fly, flown once per session.

:func:`fly_once` flies a campaign dict once per test session, however many modules ask for it, into
a session temporary folder; :func:`tiny_dataset` is the shared tiny campaign
(:data:`_campaigns.TINY_CAMPAIGN`) flown. The campaign dicts themselves are built in
``tests/_campaigns.py`` (a plain module, so that test files can import them; pytest advises against
importing from a conftest). A flown folder is shared: read it, and copy it
(:func:`shutil.copytree`) before editing a file in it. Seeds are explicit in every campaign dict;
the same dict flies to byte-identical files (tests/test_campaign.py).

The ``slow`` marker (pyproject.toml) marks tests that take seconds — a module fixture that flies
and calibrates, or a run of estimations; ``python -m pytest -m "not slow"`` is the fast lane.
"""

from __future__ import annotations

import copy
import json
from collections.abc import Callable, Mapping
from pathlib import Path

import pytest
from _campaigns import TINY_CAMPAIGN, TINY_SOURCE

from synth.campaign import fly_campaign, parse_campaign


@pytest.fixture(scope="session")
def fly_once(tmp_path_factory) -> Callable[..., Path]:
    """``fly_once(campaign, source, workers=1) -> Path``: the campaign dict flown once per session.

    ``source`` is the label the manifest records (as ``parse_campaign``'s). Every maneuver must fly
    (asserted). The folder is shared between modules: copy it before editing anything in it.
    """
    flown: dict[str, Path] = {}

    def fly(campaign: Mapping, source: str, workers: int | None = 1) -> Path:
        # workers change only how fast it flies, never the bytes: not part of the key
        key = json.dumps({"campaign": campaign, "source": source}, sort_keys=True)
        if key not in flown:
            out = tmp_path_factory.mktemp(f"flown-{campaign.get('name', 'campaign')}") / "data"
            res = fly_campaign(parse_campaign(copy.deepcopy(dict(campaign)), source=source), out,
                               workers=workers)
            assert res.ok, res.failures
            flown[key] = out
        return flown[key]

    return fly


@pytest.fixture(scope="session")
def tiny_dataset(fly_once) -> Path:
    """:data:`TINY_CAMPAIGN` flown (shared: copy before editing)."""
    return fly_once(TINY_CAMPAIGN, TINY_SOURCE)


# --------------------------------------------------------------------------------------------------
# the fast lane

#: Slow tests in files other hands were editing when the marker was placed (issue 11): marked here,
#: by name or by the module fixture that runs a Monte Carlo campaign; the marks belong in the files.
_SLOW_ELSEWHERE = {
    "test_montecarlo.py": {
        "fixtures": {"base_run"},
        "names": {"test_failed_replication_is_recorded_and_others_continue"},
    },
    "test_montecarlo_safety.py": {
        "fixtures": {"run3"},
        "names": {"test_an_interrupted_run_resumed_ends_byte_identical_to_an_uninterrupted_one",
                  "test_ctrl_c_stops_the_workers_cleanly_and_the_same_command_resumes",
                  "test_worker_processes_end_when_the_run_is_killed",
                  "test_a_run_removes_only_its_own_leftovers",
                  "test_a_planted_pickle_in_a_copied_run_folder_is_never_loaded"},
    },
}


def pytest_collection_modifyitems(config, items):
    files = {}
    for item in items:
        spec = _SLOW_ELSEWHERE.get(item.path.name)
        if spec is None:
            continue
        files[item.path.name] = item.path
        if item.originalname in spec["names"] or spec["fixtures"] & set(item.fixturenames):
            item.add_marker(pytest.mark.slow)
    for name, path in files.items():
        # a renamed test would silently join the fast lane: say so (a warning, not a failure: those
        # files may be mid-edit); read from the file, so that running a single test does not warn
        source = path.read_text(encoding="utf-8")
        for gone in sorted(n for n in _SLOW_ELSEWHERE[name]["names"] if f"def {n}(" not in source):
            config.issue_config_time_warning(pytest.PytestWarning(
                f"tests/conftest.py marks {name}::{gone} slow, but the file defines no such test: "
                "rename it in _SLOW_ELSEWHERE or remove it"), stacklevel=2)
