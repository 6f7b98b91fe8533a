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
import shutil
import tempfile
from collections.abc import Callable, Mapping
from pathlib import Path

import pytest
from _campaigns import TINY_CAMPAIGN, TINY_SOURCE

from synth.campaign import fly_campaign, parse_campaign


def pytest_collection_modifyitems(session, config, items) -> None:
    """The modules with slow tests first, each module's tests in their order: pytest-xdist hands
    whole modules to its workers in this order, so the long ones start at once and the short ones
    fill in around them, instead of one long module running alone at the end."""
    def module(item) -> str:
        return item.nodeid.split("::", 1)[0]

    slow = {module(item) for item in items if item.get_closest_marker("slow")}
    items.sort(key=lambda item: module(item) not in slow)  # stable: the order kept within


@pytest.fixture(scope="session")
def fly_once(tmp_path_factory) -> Callable[..., Path]:
    """``fly_once(campaign, source) -> Path``: the campaign dict flown once per session.

    ``source`` is the label the manifest records (as ``parse_campaign``'s). Every maneuver must fly
    (asserted). The folder is shared between modules: copy it before editing anything in it.
    Flown in this process: the suite keeps every core busy (pytest-xdist), where a pool would only
    add its start to the CPU time (:data:`synth.campaign.MANEUVERS_PER_DEFAULT_WORKER`).
    """
    flown: dict[str, Path] = {}

    def fly(campaign: Mapping, source: str) -> Path:
        key = json.dumps({"campaign": campaign, "source": source}, sort_keys=True)
        if key not in flown:
            out = tmp_path_factory.mktemp(f"flown-{campaign.get('name', 'campaign')}") / "data"
            res = fly_campaign(parse_campaign(copy.deepcopy(dict(campaign)), source=source), out,
                               workers=1)
            assert res.ok, res.failures
            flown[key] = out
        return flown[key]

    return fly


@pytest.fixture
def short_tmp() -> Path:
    """An empty folder with a short path, for a child process's system temporary folder
    (``TMPDIR``): multiprocessing's fork server puts its socket there, and a socket path may not
    exceed 107 characters, which a test's ``tmp_path`` under pytest-xdist can."""
    folder = Path(tempfile.mkdtemp(prefix="fpr-"))
    yield folder
    shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture(scope="session")
def tiny_dataset(fly_once) -> Path:
    """:data:`TINY_CAMPAIGN` flown (shared: copy before editing)."""
    return fly_once(TINY_CAMPAIGN, TINY_SOURCE)
