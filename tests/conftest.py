"""Shared helpers: the fixture meshes copied into tests/data and small, fast settings."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from fcso.config import DesignConfig

DATA = Path(__file__).parent / "data"
REPO = Path(__file__).parent.parent

# How long a test waits for a process, a message or a file before it fails. It is not a measure of speed: the longest
# such wait is under 40 s on one core of our machine, so a machine ten times slower passes; it only keeps a hung process
# from holding the CI run (under the whole test's guard, pytest's `timeout`, so that its message is the one seen).
HANG_GUARD_S = 600.0


def data_path(name: str) -> Path:
    """Path of a fixture mesh in tests/data (see tests/data/README.md for origins)."""
    path = DATA / name
    assert path.is_file(), path
    return path


def process_running(pid: int) -> bool:
    """Whether process ``pid`` exists and has not exited (a zombie has)."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def small_config(**sections) -> DesignConfig:
    """A 10 x 10 mm pad (T = 4, D = 3) with a coarse stride, so designs take seconds.

    ``sections`` are merged over it, e.g. ``small_config(poses={"select": [0, 1]})``.
    """
    base = {
        "sampler": {"length_mm": 10.0, "width_mm": 10.0, "thickness_mm": 4.0, "penetration_mm": 3.0, "stride_mm": 5.0},
        "poses": {"count": 1, "select": "most_probable"},
    }
    for section, values in sections.items():
        base.setdefault(section, {}).update(values)
    return DesignConfig().updated(base)


@pytest.fixture(scope="session", autouse=True)
def own_cache(tmp_path_factory) -> Path:
    """The run's own cache of collision pieces and simulation outcomes (``FCSO_CACHE_DIR``, inherited by the daemons
    the tests start), not the user's ``~/.cache/fcso``: a test never reads what another run left there."""
    cache = tmp_path_factory.mktemp("fcso-cache")
    os.environ["FCSO_CACHE_DIR"] = str(cache)
    return cache


@pytest.fixture(scope="session")
def data_dir() -> Path:
    return DATA
