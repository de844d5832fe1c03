"""A command's start: fcso's imports run without the garbage collector walking what they load at every step."""

from __future__ import annotations

import gc
import json
import subprocess
import sys

from fcso.startup import collector_paused
from tests.conftest import REPO

# counts the collections that start while `import fcso` runs, in a fresh interpreter
COUNT_COLLECTIONS = """
import gc, json, sys
started = []
gc.callbacks.append(lambda phase, info: started.append(info["generation"]) if phase == "start" else None)
import fcso
during = len(started)
print(json.dumps({"collections": during, "enabled": gc.isenabled()}))
"""


def test_importing_fcso_runs_few_collections_and_leaves_the_collector_on():
    """About 110 collections without the pause; with it, those of the few imports before it and one as it ends."""
    done = subprocess.run(
        [sys.executable, "-c", COUNT_COLLECTIONS], cwd=REPO, check=True, capture_output=True, text=True
    )
    found = json.loads(done.stdout.strip().splitlines()[-1])
    assert found["enabled"]
    assert found["collections"] <= 10


def test_the_pause_leaves_a_collector_turned_off_as_it_was():
    was = gc.isenabled()
    try:
        gc.disable()
        with collector_paused():
            assert not gc.isenabled()
        assert not gc.isenabled()
        gc.enable()
        with collector_paused():
            assert not gc.isenabled()
        assert gc.isenabled()
    finally:
        (gc.enable if was else gc.disable)()


def test_what_a_paused_block_made_joins_the_oldest_generation_without_a_collection():
    """No young collection walks the imports after the block; the collector's frozen objects, if any, stay frozen."""
    collections = []
    gc.callbacks.append(callback := lambda phase, info: collections.append(info) if phase == "start" else None)
    try:
        with collector_paused():
            made = [[k] for k in range(20_000)]
        young = gc.get_objects(generation=0)
        assert not any(item is made for item in young) and len(young) < 1_000
        assert collections == [] and gc.get_freeze_count() == 0
        gc.freeze()
        with collector_paused():
            kept = [[k] for k in range(100)]
        assert gc.get_freeze_count() > 0 and any(item is kept for item in gc.get_objects(generation=0))
    finally:
        gc.callbacks.remove(callback)
        gc.unfreeze()
