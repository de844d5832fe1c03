"""Settings of the grasp verification (METHOD §12): the ``[verify]`` table."""

from __future__ import annotations

from pathlib import Path

from pydantic import ValidationError

from ..config import DesignConfig, VerifyConfig, format_validation_error, read_toml
from ..errors import ConfigError


def load_verify_config(path: str | Path | None) -> VerifyConfig:
    """The ``[verify]`` table of a TOML file (defaults without a file or table).

    Raises
    ------
    ConfigError
        Unreadable file, unknown key or bad value, naming the file and key.
    """
    if path is None:
        return VerifyConfig()
    table = read_toml(path).get("verify", {})
    try:
        return VerifyConfig.model_validate(table)
    except ValidationError as exc:
        raise ConfigError(path, format_validation_error(exc)) from None


def with_print_density(config: VerifyConfig, design: DesignConfig) -> VerifyConfig:
    """``config`` with the part density of the design's ``[print]`` profile, unless ``[verify]`` set its own.

    Parameters
    ----------
    config : VerifyConfig
    design : DesignConfig
        The settings the design was made with (its ``report.json`` keeps them).
    """
    if "density_g_cm3" in config.model_fields_set:
        return config
    return config.model_copy(update={"density_g_cm3": design.print.resolved()["density_g_cm3"]})
