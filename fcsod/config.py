"""The daemon's configuration (``fcsod.toml``) and the job manifest (``job.toml``), as pydantic models.

Lengths are in millimetres (``_mm``), sizes in bytes (``_bytes``), times in
seconds (``_seconds``). Both models forbid unknown keys so a typo is an error
that names the key, never a silently ignored setting.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, ValidationInfo, field_validator, model_validator

from fcso.config import (
    ComputeConfig,
    ContactConfig,
    DesignConfig,
    FilterConfig,
    FingerSetsConfig,
    GripperConfig,
    PosesConfig,
    PrintConfig,
    SamplerConfig,
    SearchConfig,
    VerifyConfig,
    format_validation_error,
    read_toml,
)
from fcso.errors import ConfigError, MeshError
from fcso.verify_config import DEFAULT_TOP_K

from .plate.models import BuildConfig, parse_transform

#: Admin space of rmw_zenoh's liveliness tokens.
LIVELINESS_ADMIN_SPACE = "@ros2_lv"


#: A ROS 2 name token (node names, namespace parts).
NAME_TOKEN = r"[A-Za-z_][A-Za-z0-9_]*"


class Ros2Config(BaseModel):
    """``[ros2]``: the daemon as a ROS 2 node on zenoh, in rmw_zenoh's wire format."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    enabled: bool = Field(False, description="Also publish the ROS 2 topics on the daemon's zenoh session")
    domain_id: int = Field(0, ge=0, le=232, description="ROS_DOMAIN_ID of the cell")
    namespace: str = Field(
        "/", pattern=rf"^/({NAME_TOKEN}(/{NAME_TOKEN})*)?$", description="ROS 2 namespace of the node, e.g. /cell1"
    )
    node_name: str = Field("fcsod", pattern=rf"^{NAME_TOKEN}$", description="ROS 2 node name")
    history_depth: int = Field(
        10, ge=1, description="Keep-last depth: samples per topic a late transient-local subscriber receives"
    )


#: Name of the optional manifest in a job folder.
MANIFEST_NAME = "job.toml"


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class WatchConfig(_Section):
    """Which folders are watched and when a job folder counts as complete."""

    roots: list[Path] = Field(min_length=1, description="Watched roots; each holds one folder per print job")
    settle_seconds: float = Field(
        5.0, ge=0, description="How long the job's files must stay unchanged (size and mtime) before the job starts, s"
    )
    polling: bool = Field(
        False,
        description="Poll the roots instead of using inotify (needed on network shares written by other machines)",
    )
    poll_interval_seconds: float = Field(1.0, gt=0, description="Interval of the polling observer, s")
    rescan_seconds: float = Field(
        60.0, gt=0, description="Full rescan of every root at this interval, s (catches events lost by the observer)"
    )


class OutputConfig(_Section):
    """Where results go (never inside a watched root)."""

    root: Path = Field(description="Results are written to <root>/<job_id>/")


class StateConfig(_Section):
    """Where the daemon keeps its job journal."""

    dir: Path = Field(description="Folder of the SQLite journal (journal.sqlite3) and the daemon's lock file")


class JobsConfig(_Section):
    """How many jobs run at once and for how long."""

    concurrency: int = Field(1, ge=1, description="Jobs running at the same time, each in its own worker process")
    time_limit_seconds: float = Field(1800.0, gt=0, description="A job still running after this long fails, s")
    stop_grace_seconds: float = Field(
        5.0, gt=0, description="Time a worker gets to record its failure after the time limit before it is killed, s"
    )


class LimitsConfig(_Section):
    """Size limits that refuse a job before any mesh is parsed."""

    max_file_bytes: int = Field(200_000_000, gt=0, description="Largest part or manifest file, bytes")
    max_job_bytes: int = Field(1_000_000_000, gt=0, description="Largest total size of a job's input files, bytes")
    max_parts: int = Field(50, ge=1, description="Most distinct part files in one job")
    max_faces: int = Field(2_000_000, gt=0, description="Most triangles in one part mesh")
    max_3mf_uncompressed_bytes: int = Field(
        500_000_000, gt=0, description="Largest total uncompressed size of the entries of a 3MF (zip) file, bytes"
    )
    max_3mf_ratio: float = Field(200.0, gt=1, description="Largest uncompressed/compressed size ratio of a 3MF entry")


class PartsSettings(_Section):
    """How the daemon takes part files (the design's ``[design.parts]`` limits what a repair may change)."""

    repair: bool = Field(
        True,
        description=(
            "Repair part files as a slicer takes them (open and overlapping shells, holes, flipped and duplicated "
            "triangles) unless a job's manifest says repair = false; the report lists what changed"
        ),
    )


class ReuseConfig(_Section):
    """Finger reuse (METHOD §11b): a job whose parts are all served by delivered fingers prints none."""

    enabled: bool = Field(
        True,
        description=(
            "Keep every delivered finger set in the cell's library (<state.dir>/fingers.sqlite3) and serve a job whose "
            "parts all have the geometry of parts of active library fingers, or keep min_retained on them (see "
            "similar_size_percent), with those fingers: no new finger is designed or printed"
        ),
    )
    reprint_after_jobs: int = Field(
        100,
        ge=1,
        description="Wear limit: a finger that served this many jobs (its own included) serves no more; the next "
        "job of its parts designs and prints a new one",
    )
    similar_size_percent: float = Field(
        5.0,
        ge=0,
        le=100,
        description=(
            "A part of no delivered geometry is evaluated on the pad of a library finger (METHOD §11b) when a part the "
            "finger serves has every bounding-box side and the volume within this percentage of its own; the finger "
            "serves it when every scenario keeps [finger_sets] min_retained of its solo quality. 0: only parts of the "
            "same geometry are served"
        ),
    )


class BusConfig(_Section):
    """Zenoh key expressions: ``<prefix>/<cell>/jobs/<job_id>/...``."""

    prefix: str = Field("fcso", pattern=r"^[A-Za-z0-9_\-]+(/[A-Za-z0-9_\-]+)*$", description="Key prefix")
    cell: str = Field("cell1", pattern=r"^[A-Za-z0-9_\-]+$", description="Cell id, one key chunk")
    signing_key: Path | None = Field(
        None,
        description="The daemon's Ed25519 private key (PEM) that signs every message; default "
        "<state.dir>/signing.key, created at first start",
    )
    verify_key: Path | None = Field(
        None,
        description="The daemon's public key (PEM) fcsod subscribe checks messages with; default signing.pub next to "
        "signing_key",
    )


class ZenohConfig(_Section):
    """Zenoh session settings: a zenoh config file (JSON5) and/or inline endpoints (inline wins)."""

    config_file: Path | None = Field(
        None, description="Zenoh configuration file (JSON5): mode, endpoints, TLS, access control"
    )
    mode: Literal["peer", "client", "router"] | None = Field(
        None, description="Session mode; default: the config file's or peer"
    )
    listen: list[str] | None = Field(None, description="Listen endpoints, e.g. tcp/127.0.0.1:7447")
    connect: list[str] | None = Field(None, description="Endpoints to connect to, e.g. tcp/192.168.1.10:7447")
    multicast_scouting: bool | None = Field(
        None, description="UDP multicast scouting; default: the config file's or zenoh's"
    )


class McapConfig(_Section):
    """How ``job.mcap`` is written."""

    compression: Literal["zstd", "lz4", "none"] = Field("zstd", description="Chunk compression")
    chunk_size_bytes: int = Field(
        65536,
        ge=1024,
        description="Chunk size, bytes: small chunks keep a crashed job's record readable up to the crash",
    )


class VerifySettings(VerifyConfig):
    """``[verify]``: grasp verification in simulation (fcso.sim), in ``fcsod.toml`` for every job or in a ``job.toml``.

    Every setting of fcso's ``[verify]`` (the capture measure's test
    conditions among them: the job's design ranks candidates with them),
    and when the daemon verifies. ``choice_budget_s`` defaults to
    ``time_limit_seconds`` and ``cache_dir`` to the state folder's.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    enabled: bool = Field(
        True,
        description="Verify every done job's design in simulation (MuJoCo), after it is published (and with top_k, "
        "choose among candidates by it before); false: no verification at all, no choice by it (top_k is then "
        "ignored), no message on the verification key",
    )
    top_k: int = Field(
        DEFAULT_TOP_K,
        ge=0,
        description="Verify up to K candidates in the order of the design's measure and deliver the first that passes "
        "every scenario, for each finger set (0: verify only the delivered design; ignored when enabled is false)",
    )
    time_limit_seconds: float = Field(
        600.0,
        gt=0,
        description="A verification after the job is done is stopped after this (its status on the verification key "
        "is then failed; the job stays done); choosing among top_k candidates starts no further candidate after it, s",
    )

    deliver: Literal["always", "verified", "better_than_flat"] = Field(
        "always",
        description="Which fingers a job delivers without an operator: always (the verdict travels with every "
        "message, the cell decides: a farm without an operator keeps running); verified (the design passed); "
        "better_than_flat (it passed, or beat flat pads: no fewer successful trials in any scenario, more in one, "
        "holding as well). A job whose finger misses it ends held, its finger not placed into build.3mf and its "
        "grasps not published, until fcsod approve or fcsod reject. With a policy other than always every finger "
        "set's finger is verified before it is placed, one set or several (with top_k 0 too), and any that misses "
        "it holds the job",
    )

    def verify_config(self) -> VerifyConfig:
        """fcso's ``[verify]`` of these settings: every one of its keys that was given (unset ones keep fcso's
        defaults, so the part density still follows the design's print profile)."""
        given = self.model_fields_set & set(VerifyConfig.model_fields)
        return VerifyConfig(**{name: getattr(self, name) for name in given})


#: host:port of a listening socket; the host is a name, an IPv4 address or a bracketed IPv6 address.
HOST_PORT = r"^([A-Za-z0-9.\-]+|\[[0-9A-Fa-f:.]+\]):[0-9]{1,5}$"


def split_host_port(listen: str) -> tuple[str, int]:
    """``"127.0.0.1:9108"`` -> ``("127.0.0.1", 9108)``; a bracketed IPv6 host loses its brackets."""
    host, _, port = listen.rpartition(":")
    return host.strip("[]"), int(port)


class MetricsConfig(_Section):
    """``[metrics]``: the Prometheus endpoint (``http://<listen>/metrics``)."""

    enabled: bool = Field(False, description="Serve the daemon's metrics in Prometheus text format")
    listen: str = Field(
        "127.0.0.1:9108",
        pattern=HOST_PORT,
        description="host:port of the HTTP endpoint; loopback unless the network to the monitoring is trusted",
    )


class FoxgloveConfig(_Section):
    """``[foxglove]``: a live Foxglove WebSocket server publishing the scene and status of running jobs."""

    enabled: bool = Field(False, description="Run the Foxglove WebSocket server (the Foxglove app connects to it)")
    listen: str = Field(
        "127.0.0.1:8765",
        pattern=HOST_PORT,
        description="host:port of the WebSocket server; loopback unless the network to the cell is trusted",
    )


class DaemonConfig(_Section):
    """Every setting of ``fcsod run`` (``fcsod.toml``)."""

    watch: WatchConfig
    output: OutputConfig
    state: StateConfig
    jobs: JobsConfig = Field(default_factory=JobsConfig)
    limits: LimitsConfig = Field(default_factory=LimitsConfig)
    parts: PartsSettings = Field(default_factory=PartsSettings)
    reuse: ReuseConfig = Field(default_factory=ReuseConfig)
    bus: BusConfig = Field(default_factory=BusConfig)
    zenoh: ZenohConfig = Field(default_factory=ZenohConfig)
    mcap: McapConfig = Field(default_factory=McapConfig)
    design: DesignConfig = Field(default_factory=DesignConfig, description="Default fcso settings for every job")
    compute: ComputeConfig = Field(
        default_factory=ComputeConfig,
        description="Where every job's design runs: a Dask scheduler address (tcp://host:8786) shared by several "
        "daemons, or local worker processes (none)",
    )
    build: BuildConfig = Field(
        default_factory=BuildConfig,
        description="Default build volume, spacing and finger copies of every job's build.3mf",
    )
    ros2: Ros2Config = Field(
        default_factory=Ros2Config, description="The daemon as a ROS 2 node over zenoh (rmw_zenoh's wire format)"
    )
    verify: VerifySettings = Field(
        default_factory=VerifySettings, description="Grasp verification of every job's design"
    )
    metrics: MetricsConfig = Field(default_factory=MetricsConfig, description="The Prometheus metrics endpoint")
    foxglove: FoxgloveConfig = Field(default_factory=FoxgloveConfig, description="The live Foxglove server")

    @field_validator("design", mode="before")
    @classmethod
    def _verify_has_one_home(cls, value: Any) -> Any:
        if isinstance(value, dict) and "verify" in value:
            raise ValueError("verify: the verification's settings are the daemon's [verify] section")
        return value

    @model_validator(mode="after")
    def _output_outside_watch_roots(self) -> DaemonConfig:
        output = self.output.root.resolve()
        for root in self.watch.roots:
            resolved = root.resolve()
            if output == resolved or resolved in output.parents or output in resolved.parents:
                raise ValueError(
                    f"output.root {self.output.root} overlaps watch root {root}: results never go into watched folders"
                )
        return self


def _resolve_paths(data: dict, base: Path) -> None:
    """Make the config's relative paths relative to the config file's folder (not the cwd), in place."""

    def fix(section: str, key: str) -> None:
        values = data.get(section)
        if isinstance(values, dict) and isinstance(values.get(key), str) and not Path(values[key]).is_absolute():
            values[key] = str(base / values[key])

    watch = data.get("watch")
    if isinstance(watch, dict) and isinstance(watch.get("roots"), list):
        watch["roots"] = [
            str(base / r) if isinstance(r, str) and not Path(r).is_absolute() else r for r in watch["roots"]
        ]
    fix("output", "root")
    fix("state", "dir")
    fix("zenoh", "config_file")
    fix("bus", "signing_key")
    fix("bus", "verify_key")
    fix("verify", "cache_dir")
    design = data.get("design")
    if isinstance(design, dict):
        fix_finger = design.get("finger")
        if (
            isinstance(fix_finger, dict)
            and isinstance(fix_finger.get("mesh"), str)
            and not Path(fix_finger["mesh"]).is_absolute()
        ):
            fix_finger["mesh"] = str(base / fix_finger["mesh"])


def load_daemon_config(path: str | Path) -> DaemonConfig:
    """Load and validate ``fcsod.toml``.

    Parameters
    ----------
    path : str or Path
        The TOML file; relative paths in it are relative to its folder.

    Returns
    -------
    DaemonConfig

    Raises
    ------
    ConfigError
        Unreadable file, TOML syntax error, unknown key or bad value; the
        message names the file and the dotted key.
    """
    path = Path(path)
    data = read_toml(path)
    _resolve_paths(data, path.resolve().parent)
    try:
        config = DaemonConfig.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(path, format_validation_error(exc)) from None
    for number, root in enumerate(config.watch.roots):
        if not root.is_dir():
            raise ConfigError(path, f"watch.roots.{number}: folder {root} does not exist")
    if config.zenoh.config_file is not None and not config.zenoh.config_file.is_file():
        raise ConfigError(path, f"zenoh.config_file: file {config.zenoh.config_file} does not exist")
    return config


# ---------------------------------------------------------------- job manifest


class PartEntry(_Section):
    """One part of the batch."""

    file: str = Field(min_length=1, description="Mesh file, relative to the job folder (STL, 3MF, OBJ, PLY)")
    units: Literal["mm", "inch", "m"] | float = Field(
        "mm", description="Unit of the file's coordinates, or a factor to mm"
    )
    quantity: int = Field(1, ge=1, description="Copies of this part in the print job")
    scale_to_mm: float | None = Field(None, gt=0, description="Scale so the longest bounding-box side is this long, mm")
    transform: list[float] | list[list[float]] | None = Field(
        None,
        description=(
            "Where the part sits in the build volume: 4x4 from the part's frame (after units and scaling) to the "
            "build's, "
            "16 numbers row-major or 4 rows of 4, mm; without it the part is packed with the fingers"
        ),
    )

    @field_validator("units")
    @classmethod
    def _positive_factor(cls, value: str | float) -> str | float:
        if isinstance(value, float) and not value > 0:
            raise ValueError("a unit factor must be a positive number of mm per file unit")
        return value

    @field_validator("transform")
    @classmethod
    def _proper_transform(cls, value: list | None) -> list[list[float]] | None:
        if value is None:
            return None
        try:
            return parse_transform(value).tolist()
        except MeshError as exc:
            raise ValueError(exc.defect) from None

    @model_validator(mode="after")
    def _one_placement_per_entry(self) -> PartEntry:
        if self.file.lower().endswith(".3mf"):
            # a 3MF is a placed build: its items are the copies, in the file's own unit, where the file puts them
            given = [key for key in ("units", "scale_to_mm", "transform") if key in self.model_fields_set]
            given += ["quantity"] if self.quantity != 1 else []
            if given:
                raise ValueError(f"a 3MF build carries its own items, unit and transforms: remove {', '.join(given)}")
        elif self.transform is not None and self.quantity > 1:
            raise ValueError(
                "a transform places one copy: give each placed copy its own [[parts]] entry with quantity 1"
            )
        return self


#: Manifest sections that override the daemon's fcso settings, with fcso's models.
OVERRIDE_SECTIONS: dict[str, type[BaseModel]] = {
    "sampler": SamplerConfig,
    "gripper": GripperConfig,
    "filter": FilterConfig,
    "poses": PosesConfig,
    "contact": ContactConfig,
    "search": SearchConfig,
    "print": PrintConfig,
    "finger_sets": FingerSetsConfig,
}


class JobManifest(_Section):
    """``job.toml``: the parts of a batch and per-job overrides of fcso's settings.

    Override sections take fcso's keys (``schemas/design-config.json``); keys
    not given keep the daemon's defaults. Validate with
    ``context={"defaults": DesignConfig, "build_defaults": BuildConfig}`` so
    cross-key checks (such as penetration below thickness, or the wall margin
    inside the volume) see the daemon's defaults.
    """

    parts: list[PartEntry] = Field(
        default_factory=list, description="The parts; empty: every mesh file in the folder, in mm, quantity 1"
    )
    repair: bool | None = Field(
        None, description="Repair part meshes that are not closed volumes; default the daemon's [parts] repair"
    )
    sampler: SamplerConfig | None = None
    gripper: GripperConfig | None = None
    filter: FilterConfig | None = None
    poses: PosesConfig | None = None
    contact: ContactConfig | None = None
    search: SearchConfig | None = None
    print: PrintConfig | None = Field(
        None, description="Printer profile, clearance, lead-in and minimum wall (fcso [print])"
    )
    finger_sets: FingerSetsConfig | None = Field(
        None, description="How many finger sets the job may use and what every part keeps (fcso [finger_sets])"
    )
    build: BuildConfig | None = Field(None, description="Overrides of the daemon's [build] settings, key by key")
    verify: VerifySettings | None = Field(None, description="The job's own [verify] settings (replace the daemon's)")

    @model_validator(mode="before")
    @classmethod
    def _fill_from_defaults(cls, data: Any, info: ValidationInfo) -> Any:
        if not isinstance(data, dict):
            return data
        context = info.context or {}
        defaults, build_defaults = context.get("defaults"), context.get("build_defaults")
        filled = dict(data)
        if isinstance(defaults, DesignConfig):
            for section in OVERRIDE_SECTIONS:
                given = data.get(section)
                if isinstance(given, dict):
                    filled[section] = {**getattr(defaults, section).model_dump(), **given}
        if isinstance(build_defaults, BuildConfig) and isinstance(data.get("build"), dict):
            filled["build"] = {**build_defaults.model_dump(), **data["build"]}
        return filled

    def design_config(self, defaults: DesignConfig) -> DesignConfig:
        """The job's fcso settings: ``defaults`` with this manifest's sections applied."""
        overrides = {s: getattr(self, s).model_dump() for s in OVERRIDE_SECTIONS if getattr(self, s) is not None}
        return defaults.updated(overrides)

    def build_config(self, defaults: BuildConfig) -> BuildConfig:
        """The job's build settings: this manifest's ``[build]`` (already filled from the daemon's) or ``defaults``."""
        return self.build if self.build is not None else defaults


def parse_manifest(
    text: str, source: str | Path, defaults: DesignConfig, build_defaults: BuildConfig | None = None
) -> JobManifest:
    """Parse and validate a manifest's text.

    Parameters
    ----------
    text : str
        Content of ``job.toml``.
    source : str or Path
        Name used in error messages.
    defaults : DesignConfig
        The daemon's fcso settings the overrides apply to.
    build_defaults : BuildConfig, optional
        The daemon's ``[build]`` settings a manifest's ``[build]`` overrides
        key by key; default :class:`BuildConfig`'s.

    Raises
    ------
    ConfigError
        TOML syntax, unknown key or bad value, naming ``source`` and the key.
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(source, f"not valid TOML: {exc}") from None
    try:
        context = {"defaults": defaults, "build_defaults": build_defaults or BuildConfig()}
        manifest = JobManifest.model_validate(data, context=context)
        manifest.design_config(defaults)
    except ValidationError as exc:
        raise ConfigError(source, format_validation_error(exc)) from None
    return manifest
