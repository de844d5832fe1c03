"""The end-to-end tests: the daemon runs in its own processes, on real folders, zenoh sessions and records."""

from __future__ import annotations

from pathlib import Path

import pytest

HERE = Path(__file__).parent


def pytest_collection_modifyitems(config, items):
    # every test of this folder is an end-to-end test (pytest -m "not e2e" leaves them out)
    for item in items:
        if item.path.is_relative_to(HERE):
            item.add_marker(pytest.mark.e2e)
