"""fcsod.toml and job.toml: validation, defaults, messages that name the file and the key."""

from __future__ import annotations

import pytest

from fcso.config import DesignConfig
from fcso.errors import ConfigError
from fcsod.cli import main
from fcsod.config import load_daemon_config, parse_manifest
from tests.fcsod_helpers import REPO, free_port, write_config


def test_config_paths_are_relative_to_the_config_file(tmp_path):
    config = load_daemon_config(write_config(tmp_path, free_port(), settle_seconds=2.5))
    assert config.watch.roots == [tmp_path / "watch"]
    assert config.output.root == tmp_path / "out" and config.state.dir == tmp_path / "state"
    assert config.watch.settle_seconds == 2.5
    assert config.zenoh.listen == [f"tcp/127.0.0.1:{config.zenoh.listen[0].rsplit(':', 1)[1]}"]
    assert config.zenoh.multicast_scouting is False
    assert config.design.sampler.length_mm == 10 and config.design.poses.select == "most_probable"


def test_deployed_example_config_is_valid(tmp_path):
    text = (REPO / "deploy" / "fcsod.toml").read_text()
    (tmp_path / "spool").mkdir()
    # the example's absolute folders point at the print server; check it with local ones
    text = text.replace("/var/spool/fcsod/jobs", str(tmp_path / "spool")).replace(
        "/etc/fcsod/zenoh.json5", str(REPO / "deploy" / "zenoh.json5")
    )
    (tmp_path / "fcsod.toml").write_text(text)
    config = load_daemon_config(tmp_path / "fcsod.toml")
    assert config.zenoh.config_file == REPO / "deploy" / "zenoh.json5"
    # as shipped, finger sets are judged by truth (issue 48) within a stated budget
    assert config.verify.enabled and config.design.finger_sets.truth_budget_s > 0
    from fcsod.bus.session import session_config

    assert session_config(config.zenoh) is not None


@pytest.mark.parametrize(
    ("old", "new", "key"),
    [
        ("settle_seconds = 0.7", "settle_secs = 3", "watch.settle_secs: unknown key"),
        ('cell = "test"', 'cell = "a/b"', "bus.cell"),
        ("length_mm = 10", "length_mm = -1", "design.sampler.length_mm"),
        ("chunk_size_bytes = 4096", 'compression = "gzip"', "mcap.compression"),
    ],
)
def test_bad_config_fails_naming_the_key(tmp_path, old, new, key):
    path = write_config(tmp_path, free_port())
    path.write_text(path.read_text().replace(old, new))
    with pytest.raises(ConfigError) as error:
        load_daemon_config(path)
    assert str(error.value).startswith(f"{path}: ") and key in str(error.value)


def test_verify_takes_every_verification_setting_and_is_their_only_home(tmp_path):
    path = write_config(tmp_path, free_port(), verify='enabled = false\nforce_limit_n = 45\ncache_dir = "sim-cache"')
    settings = load_daemon_config(path).verify
    verification = settings.verify_config()
    assert verification.force_limit_n == 45 and verification.cache_dir == tmp_path / "sim-cache"
    # a density not given follows the design's print profile, as in fcso verify
    assert "density_g_cm3" not in verification.model_fields_set
    path.write_text(path.read_text() + "\n[design.verify]\nforce_limit_n = 50\n")
    with pytest.raises(ConfigError, match="design: .*daemon's \\[verify\\]"):
        load_daemon_config(path)


def test_output_inside_a_watch_root_is_refused(tmp_path):
    path = write_config(tmp_path, free_port())
    path.write_text(path.read_text().replace('root = "out"', 'root = "watch/results"'))
    with pytest.raises(ConfigError, match="never go into watched folders"):
        load_daemon_config(path)


def test_cli_bad_config_exits_2_with_one_line(tmp_path, capsys):
    path = tmp_path / "fcsod.toml"
    path.write_text("[watch]\nroots = ['nowhere']\n[output]\nroot = 'out'\n[state]\ndir = 's'\n")
    assert main(["run", "--config", str(path)]) == 2
    error = capsys.readouterr().err.strip()
    assert error.count("\n") == 0 and str(path) in error and "watch.roots.0" in error
    assert main(["run", "--config", str(tmp_path / "missing.toml")]) == 2
    assert "file not found" in capsys.readouterr().err


def test_manifest_overrides_apply_over_daemon_defaults():
    defaults = DesignConfig().updated({"sampler": {"thickness_mm": 4, "penetration_mm": 3}})
    text = (
        '[[parts]]\nfile = "a.stl"\nunits = "inch"\nquantity = 2\n\n[sampler]\nthickness_mm = '
        "3.5\n\n[poses]\ncount = 1\n"
    )
    manifest = parse_manifest(text, "job.toml", defaults)
    settings = manifest.design_config(defaults)
    # penetration 3 from the daemon's defaults stays below the job's thickness 3.5
    assert (settings.sampler.thickness_mm, settings.sampler.penetration_mm) == (3.5, 3)
    assert settings.poses.count == 1 and manifest.parts[0].units == "inch" and manifest.parts[0].quantity == 2


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[sampler]\nlenght_mm = 3\n", "sampler.lenght_mm: unknown key"),
        ("colour = 'red'\n", "colour: unknown key"),
        ('[[parts]]\nfile = "a.stl"\nquantity = 0\n', "parts.0.quantity"),
        ('[[parts]]\nfile = "a.stl"\nunits = "furlong"\n', "parts.0.units"),
        ("[sampler]\npenetration_mm = 9\n", "penetration_mm (9.0) must be smaller than thickness_mm"),
        ("[poses\n", "not valid TOML"),
    ],
)
def test_bad_manifest_names_the_key(text, message):
    with pytest.raises(ConfigError) as error:
        parse_manifest(text, "batch/job.toml", DesignConfig())
    assert str(error.value).startswith("batch/job.toml: ") and message in str(error.value)
