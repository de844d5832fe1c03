"""Message models: what goes on zenoh and into each MCAP channel.

Every body on the bus and every MCAP message is JSON validated by one of
these models; their JSON Schemas are in ``schemas/`` and in each MCAP file.
Times are UTC ISO 8601 strings, lengths mm, areas mm².
"""

from __future__ import annotations

import base64
import re
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from fcso.report.models import CandidateReport, GraspReport, NotServedPart, PickPart, ScenarioQuality

#: States of a job in the journal and on the bus.
JobState = Literal["queued", "running", "done", "failed", "held"]


def rest_frame_id(part: str, pose_index: int) -> str:
    """The frame id of a part's resting frame: ``fcso_<part>_rest<pose_index>`` (characters other than letters, digits
    and ``_`` become ``_``): the frame of its grasp's TCP pose in the grasps message, of its ROS 2 PoseArray and of
    the Foxglove frame tree.
    """
    return re.sub(r"[^A-Za-z0-9_]", "_", f"fcso_{part}_rest{pose_index}")


def utc_now() -> str:
    """Now as a UTC ISO 8601 string with milliseconds."""
    return datetime.now(UTC).isoformat(timespec="milliseconds")


class _Message(BaseModel):
    model_config = ConfigDict(extra="forbid")


# ------------------------------------------------------------------ zenoh bodies


class StatusMessage(_Message):
    """``<prefix>/<cell>/jobs/<job_id>/status``: the job's state."""

    job_id: str
    state: JobState
    folder: str = Field(description="The job folder that was watched")
    attempt: int = Field(1, ge=1, description="Run number of the job (more than 1 after a restart re-queued it)")
    queued_at: str | None = None
    started_at: str | None = None
    finished_at: str | None = None
    error: str | None = Field(
        None,
        description="Why the job failed, naming the file and the defect; held: why its finger waits for an operator "
        "(fcsod approve / reject), its finger not placed into build.3mf and its grasps not published meanwhile",
    )
    outputs: list[str] = Field(default_factory=list, description="Files in <output_root>/<job_id>/ when done")
    warnings: list[str] = Field(
        default_factory=list,
        description="What a done job could not deliver, such as fingers that did not fit into the build volume",
    )


class ScenarioSummary(_Message):
    """Quality of the chosen design for one part in one pose."""

    part: str
    pose_index: int
    rles: float = Field(description="Radius of the largest empty sphere of contact normals (chord, 0..2)")
    contact_area_mm2: float
    effective_area_mm2: float = Field(description="E = A / RLES, mm²")


class QualityMessage(_Message):
    """``<prefix>/<cell>/jobs/<job_id>/quality``: quality summary of the chosen design."""

    job_id: str
    quality: float = Field(
        description="Least over the scenarios of the quality_measure: E in mm² under 'paper' (Q), no unit under "
        "'capture' (METHOD §7b)"
    )
    quality_measure: Literal["capture", "paper"] = Field(description="[quality] measure of the design")
    mean_quality: float = Field(
        description="Mean over the scenarios of the quality_measure (the first tie-break): E in mm² under 'paper', no "
        "unit under 'capture'"
    )
    pad_case: str = Field(description="good, bad or mixed")
    candidates_evaluated: int
    candidates_total: int
    proven_optimal: bool
    scenarios: list[ScenarioSummary]
    finger_volume_mm3: float
    finger_watertight: bool
    min_pad_thickness_mm: float
    warnings: list[str]
    timings_s: dict[str, float]


class CellGrasp(GraspReport):
    """One grasp as the cell runs it: the design's grasp and what to check before the robot moves."""

    job_id: str
    frame_id: str = Field(
        description="The frame of position_mm and quaternion_wxyz, the part's resting frame fcso_<part>_rest<pose>: "
        "the header.frame_id of this grasp's ROS 2 PoseArray on ~/grasps, whose header.stamp is the source timestamp "
        "of this message's ROS 2 form on ~/grasp_details"
    )
    finger_set: int = Field(description="The finger set making this grasp: mount it (1: a job of one finger)")
    approach_opening_mm: float = Field(
        description="Open the gripper at least this wide (between the flat fingers' contact faces) before it comes "
        "down over the part: closing_width_mm + 2 (D + [verify] open_margin_mm), at most the gripper's full opening; "
        "narrower, a pocket's rim lands on the part, mm"
    )
    verified: bool | None = Field(
        description="The finger passed verification in simulation; false: it did not (see verdict); null: not "
        "verified before this message (its verification message follows on .../verification, or verification is off)"
    )
    verdict: str = Field(
        description='This grasp\'s scenario in the verification: "verified: designed 9/10, flat 1/10, holds 30 N", '
        "or why there is none"
    )


class GraspsMessage(_Message):
    """``<prefix>/<cell>/jobs/<job_id>/grasps``: what the robot runs, per part and pose."""

    job_id: str
    grasps: list[CellGrasp]


class MessageSignature(_Message):
    """Ed25519 signature of one zenoh message (see :mod:`fcsod.signing` for the signed bytes)."""

    algorithm: Literal["ed25519"] = "ed25519"
    key_id: str = Field(
        pattern=r"^[0-9a-f]{16}$", description="First 16 hex digits of the SHA-256 of the raw public key"
    )
    signature_base64: str = Field(description="The 64-byte signature, base64")


class SignedAttachment(_Message):
    """Attachment of every ``<prefix>/<cell>/jobs/<job_id>/<topic>`` message but the design's."""

    job_id: str
    signature: MessageSignature


class DesignAttachment(_Message):
    """Attachment of ``<prefix>/<cell>/jobs/<job_id>/design`` (payload: binary STL of the finger)."""

    job_id: str
    sha256: str = Field(pattern=r"^[0-9a-f]{64}$", description="SHA-256 of the STL payload, hex")
    file: str = Field("finger.stl", description="Name of the file in the job's output folder")
    size_bytes: int
    finger_set: int | None = Field(
        None, description="Finger set of this finger when the job has several (key .../design/<set>)"
    )
    signature: MessageSignature | None = Field(None, description="Added by the daemon when it publishes or replies")


class PlanSet(_Message):
    """One finger set of a pick plan: the finger to mount and the parts to pick with it."""

    set: int = Field(description="Finger set, 1 = first; mount the sets in the plan's order")
    finger_key: str = Field(
        description="zenoh key of the set's finger STL (<prefix>/<cell>/jobs/<job_id>/design[/<set>])"
    )
    finger_file: str = Field(description="The finger STL in the job's output folder")
    finger_sha256: str = Field(pattern=r"^[0-9a-f]{64}$", description="SHA-256 of the finger STL, hex")
    finger_copies: int = Field(
        description="Copies of this finger in build.3mf (finger_copies + spare_fingers requested; 0 when reused)"
    )
    quality: float = Field(
        description="Quality of the set's finger, least over its scenarios, in its quality_measure: E in mm² under "
        "'paper', no unit under 'capture'"
    )
    quality_measure: Literal["capture", "paper"] = Field(
        description="[quality] measure the finger was designed with (a reused finger's own)"
    )
    worst_retained: float = Field(description="Least E / E* over the set's scenarios")
    parts: list[PickPart] = Field(description="Parts to pick with this finger, with quantities and grasps")
    finger_id: int | None = Field(
        None,
        description="Id in the cell's finger library of a finger delivered before and reused (fcsod fingers list); "
        "null for a finger this job delivers",
    )
    reused_from_job: str | None = Field(
        None, description="The job that delivered the reused finger (its finger_key and finger_file are that job's)"
    )


class PlanMessage(_Message):
    """``<prefix>/<cell>/jobs/<job_id>/plan``: the pick plan, which finger set to mount and which parts to pick with it (METHOD §11)."""  # noqa: E501

    job_id: str
    sets: list[PlanSet] = Field(description="In the order to mount them")
    min_retained: float = Field(description="[finger_sets] min_retained of the job")
    min_retained_reached: bool = Field(
        description="Every graspable scenario keeps at least min_retained of its solo quality"
    )
    worst_retained: float | None = Field(description="Least E / E* over the job's graspable scenarios")
    ungraspable_parts: list[str] = Field(description="Parts no set can grasp: not in the plan")
    not_served: list[NotServedPart] = Field(
        default_factory=list,
        description="Parts whose best set keeps less than min_retained of their solo quality: not picked with any "
        "set's finger, but with the fallback each names (the cell's flat fingers, or by hand)",
    )
    sets_allowed: int = Field(0, description="The most sets the job could use ([finger_sets] max, or one per part)")
    sets_needed: int | None = Field(
        None, description="Sets the job needs to serve every part at min_retained; null when the plan does not"
    )
    partition: str = Field(description="How the sets were found and what bounds them")


class PlacementMessage(_Message):
    """``<prefix>/<cell>/jobs/<job_id>/placement``: the finger copies in the job's build volume (``build.3mf``)."""

    job_id: str
    mode: Literal["add_fingers", "pack"] = Field(
        description="add_fingers: the job's build was placed, fingers added; pack: unplaced parts and fingers packed"
    )
    fingers_fit: bool = Field(description="All required finger copies are in the build")
    finger_copies_requested: int = Field(description="finger_copies + spare_fingers")
    finger_copies_placed: int
    build_height_mm: float = Field(description="Top of the highest item above the volume floor, mm")
    packing_density: float = Field(description="Volume of the items / (volume x * y * build height)")
    extra_height_needed_mm: float | None = Field(
        description="When items did not fit: the build height missing to fit them, mm; None when everything fits or "
        "nothing would"
    )
    unplaced_items: list[str] = Field(description="Items left out of build.3mf")
    message: str
    file: str = Field("build.3mf", description="Name of the placed build in the job's output folder")


# ------------------------------------------------------------------ MCAP channels


class InputFile(_Message):
    path: str = Field(description="Relative to the job folder")
    size_bytes: int
    sha256: str


class JobSpecRecord(_Message):
    """``/job/spec``: what the job was asked to do."""

    job_id: str
    folder: str
    manifest: str | None = Field(description="Text of job.toml, none without a manifest")
    parts: list[dict] = Field(description="Parts as used: file, units, quantity, scale_to_mm")
    settings: dict = Field(description="The fcso settings of the job (design-config.json)")
    build: dict | None = Field(
        None, description="The job's build placement settings (the [build] section of job-manifest.json)"
    )
    fcsod_version: str
    fcso_version: str


class InputHashesRecord(_Message):
    """``/job/inputs``: content hashes of the job's input files (they define the job id)."""

    job_id: str
    files: list[InputFile]


class StateChangeRecord(_Message):
    """``/job/state``: a state change of the job."""

    job_id: str
    state: JobState
    at: str
    error: str | None = None


class DecisionRecord(_Message):
    """``/job/decision``: an operator's decision on a held job (``fcsod approve | reject``) and the output files it
    changed, which ``fcsod audit --verify`` checks instead of those the job recorded."""

    job_id: str
    decision: Literal["approved", "rejected"]
    by: str = Field(description="The operator's login name, as the command ran")
    requested_at: str = Field(description="When the operator asked, UTC ISO 8601")
    at: str = Field(description="When the daemon carried it out, UTC ISO 8601")
    files: list[InputFile] = Field(description="Output files it wrote (approve: build.3mf with the finger placed)")
    removed: list[str] = Field(description="Output files it removed (build.held.3mf), relative to the output folder")


class LogRecord(_Message):
    """``/job/log``: a log line of the job."""

    level: Literal["debug", "info", "warning", "error"]
    message: str
    stage: str | None = None
    done: int | None = None
    total: int | None = None


class PoseRecord(_Message):
    """``/design/poses``: one chosen stable pose of one part."""

    part: str
    pose_index: int
    probability: float
    rest_transform: list[list[float]] = Field(description="4x4, part file frame to resting frame, mm")


class SamplesRecord(_Message):
    """``/design/samples``: the valid samples and the rejection counts of one scenario."""

    part: str
    pose_index: int
    tried_samples: int
    valid_samples: int
    rejected: dict[str, int]
    samples: list[dict] = Field(description="One SampleReport per valid sample (design-report.json)")


class CandidateRecord(_Message):
    """``/design/candidates``: one evaluated candidate's quality row."""

    candidate: CandidateReport
    best: bool
    per_scenario: list[ScenarioQuality]


class DesignRecord(_Message):
    """``/design/finger``: the design's mesh bytes and hashes."""

    finger_stl_base64: str
    finger_sha256: str
    fingerpad_sha256: str
    finger_volume_mm3: float
    finger_watertight: bool
    finger_set: int = Field(1, description="Finger set of this design (METHOD §11), 1 = first")


class OutputFilesRecord(_Message):
    """``/job/outputs``: the files of the job's output folder with their hashes (checked by ``fcsod audit --verify``)."""  # noqa: E501

    job_id: str
    files: list[InputFile]


class BusRecord(_Message):
    """``/zenoh/published``: a message as it was (or will be) published on zenoh."""

    key_expr: str
    encoding: str
    payload_text: str | None = Field(None, description="UTF-8 payload (JSON bodies)")
    payload_base64: str | None = Field(None, description="Binary payload, base64")
    attachment: str | None = Field(None, description="JSON attachment text")


# ------------------------------------------------------------ keys and outgoing messages

#: Topics published per job.
JOB_TOPICS = ("status", "quality", "grasps", "design", "placement", "verification")

ENCODING_JSON = "application/json"
ENCODING_STL = "model/stl"


def jobs_key(prefix: str, cell: str) -> str:
    """Key expression of every job's messages (the queryable's)."""
    return f"{prefix}/{cell}/jobs/**"


def job_key(prefix: str, cell: str, job_id: str, topic: str) -> str:
    """``<prefix>/<cell>/jobs/<job_id>/<topic>``."""
    return f"{prefix}/{cell}/jobs/{job_id}/{topic}"


def split_job_key(key_expr: str) -> tuple[str, str] | None:
    """``(job_id, topic)`` of a job's key, where a finger set's topics are ``design/<set>`` and ``verification/<set>``;
    None for other keys.
    """
    parts = key_expr.split("/")
    for width in (1, 2):
        if len(parts) >= 3 + width and parts[-2 - width] == "jobs":
            return parts[-1 - width], "/".join(parts[-width:])
    return None


def daemon_key(prefix: str, cell: str) -> str:
    """Key of the daemon's liveliness token."""
    return f"{prefix}/{cell}/daemon"


@dataclass
class BusMessage:
    """A message to publish on zenoh, as the worker hands it to the daemon and the record keeps it.

    Attributes
    ----------
    job_id, topic : str
        Which job and which of :data:`JOB_TOPICS`.
    key_expr : str
        Full key expression.
    encoding : str
        ``application/json`` or ``model/stl``.
    payload : bytes
    attachment : bytes or None
        JSON text (the design's :class:`DesignAttachment`).
    """

    job_id: str
    topic: str
    key_expr: str
    encoding: str
    payload: bytes
    attachment: bytes | None = None

    @classmethod
    def json_body(cls, prefix: str, cell: str, topic: str, body: BaseModel) -> BusMessage:
        """A JSON message of one of the job's topics; ``body`` has a ``job_id``."""
        job_id = body.job_id
        return cls(job_id, topic, job_key(prefix, cell, job_id, topic), ENCODING_JSON, body.model_dump_json().encode())

    def record(self) -> BusRecord:
        """How the MCAP record keeps this message."""
        binary = self.encoding != ENCODING_JSON
        return BusRecord(
            key_expr=self.key_expr,
            encoding=self.encoding,
            payload_text=None if binary else self.payload.decode(),
            payload_base64=base64.b64encode(self.payload).decode() if binary else None,
            attachment=self.attachment.decode() if self.attachment is not None else None,
        )

    @classmethod
    def from_record(cls, record: BusRecord) -> BusMessage:
        """The message a :class:`BusRecord` keeps (for replay)."""
        job_id, topic = split_job_key(record.key_expr) or ("", record.key_expr.rsplit("/", 1)[-1])
        payload = (
            record.payload_text.encode()
            if record.payload_text is not None
            else base64.b64decode(record.payload_base64 or "")
        )
        attachment = record.attachment.encode() if record.attachment is not None else None
        return cls(job_id, topic, record.key_expr, record.encoding, payload, attachment)


class ScenarioOutcome(BaseModel):
    """One scenario of the verification message."""

    model_config = ConfigDict(extra="forbid")

    part: str
    pose_index: int
    verdict: str = Field(
        description='The scenario\'s figures, what to read first: "designed 9/10, flat 1/10, holds 30 N" (successful '
        "precision trials of the designed and of flat fingers, the weakest push the designed grasp held, N)"
    )
    weakest_holding_n: float | None = Field(
        description="The smallest push at which the designed grasp let the part slip, over the six directions, N "
        "(hold_force_n: held every push; 0: does not hold the part at all; null: not tested)"
    )
    success_rate: float = Field(
        description="Designed finger's precision trials within the success limits, of those run, 0..1"
    )
    flat_success_rate: float = Field(description="The same with flat pads")
    trials_run: int = Field(
        0,
        description="Precision trials run per finger: fewer than [verify] trials when they stopped once the designed "
        "finger could no longer pass",
    )
    median_error_mm: float | None
    flat_median_error_mm: float | None
    holding_n: dict[str, float | None] = Field(
        description="Slip force per push direction, N; null: held at the limit; empty: not tested (the precision "
        "trials had already failed)"
    )
    flat_holding_n: dict[str, float | None]


class VerificationMessage(BaseModel):
    """``<prefix>/<cell>/jobs/<job_id>/verification``: the design's simulated precision and holding."""

    model_config = ConfigDict(extra="forbid")

    job_id: str
    state: Literal["done", "failed", "skipped"] = Field(
        "done",
        description="done: verified (see passed); failed: the verification did not finish (time limit, error: see "
        "error); skipped: nothing to verify (see error)",
    )
    error: str | None = Field(None, description="Why the verification failed or was skipped")
    verdict: str = Field(
        "",
        description='What to read first (METHOD §12b): "verified" or "not verified", then per scenario "designed '
        '9/10, flat 1/10, holds 30 N"; empty unless state is done',
    )
    passed: bool = Field(description="Every scenario reached the success threshold (false unless state is done)")
    better_than_flat: bool = Field(
        False,
        description="The designed finger passed, or did at least as well as flat pads in every scenario (successful "
        "trials, holding) and better in one (false unless state is done)",
    )
    not_held: list[str] = Field(
        default_factory=list,
        description="Scenarios ('<part> pose <index>') the designed grasp does not hold at all (0 N in every push "
        "direction): a finger near zero quality; never move the robot on these",
    )
    file: str | None = Field(description="The full result, relative to the job's output folder (none unless done)")
    finger_set: int | None = Field(
        None, description="The finger set verified when the job has several (key .../verification/<set>)"
    )
    scenarios: list[ScenarioOutcome]
    chosen_candidate: int | None = Field(None, description="top_k: the candidate verification delivered")
    choice: str | None = Field(None, description="top_k: which candidate was delivered and why")
    warnings: list[str]


@dataclass
class StoredMessage:
    """The latest message of one topic of one job, as the journal keeps it for late joiners.

    A design's payload is read from ``file``.
    """

    job_id: str
    topic: str
    key_expr: str
    encoding: str
    payload: bytes | None
    attachment: str | None
    file: str | None
