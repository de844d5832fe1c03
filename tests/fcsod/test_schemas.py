"""The committed JSON Schemas in schemas/ match fcsod's models (regenerate with ``fcsod schema --out schemas/``)."""

from __future__ import annotations

import pytest

from fcso.schema import schema_text
from fcsod.record.recorder import CHANNELS
from fcsod.schema import FCSOD_SCHEMAS
from tests.fcsod_helpers import REPO


@pytest.mark.parametrize("name", sorted(FCSOD_SCHEMAS))
def test_committed_schema_matches_model(name):
    path = REPO / "schemas" / name
    assert path.is_file(), f"{path} missing: run fcsod schema --out schemas/"
    assert path.read_text(encoding="utf-8") == schema_text(FCSOD_SCHEMAS[name]), (
        f"{path} drifted from its model: run fcsod schema --out schemas/"
    )


def test_every_mcap_channel_and_zenoh_body_has_a_schema_file():
    models = set(FCSOD_SCHEMAS.values())
    assert set(CHANNELS.values()) <= models
