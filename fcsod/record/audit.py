"""``fcsod audit``: a job's story from its MCAP record, and a check of the recorded hashes against files."""

from __future__ import annotations

import base64
import hashlib
import json
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import fcso

from ..storage import file_sha256
from .recorder import (
    TOPIC_BUS,
    TOPIC_CANDIDATES,
    TOPIC_DECISION,
    TOPIC_DESIGN,
    TOPIC_INPUTS,
    TOPIC_LOG,
    TOPIC_OUTPUTS,
    TOPIC_PLACEMENT,
    TOPIC_POSES,
    TOPIC_SAMPLES,
    TOPIC_SPEC,
    TOPIC_STATE,
    RecordContent,
    read_record,
)


@dataclass
class AuditResult:
    """What the audit found.

    Attributes
    ----------
    lines : list of str
        The job's story, for a person.
    problems : list of str
        Failed checks (hash mismatches, missing files, a cut-off record when verifying).
    truncated : bool
        The record ends before its footer.
    """

    lines: list[str] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)
    truncated: bool = False


def audit(path: str | Path, verify_dir: str | Path | None = None, inputs_dir: str | Path | None = None) -> AuditResult:
    """Tell a job's story from ``job.mcap`` and, if asked, verify recorded hashes.

    Parameters
    ----------
    path : Path
        The record (may be cut off by a crash).
    verify_dir : Path, optional
        The job's output folder: each recorded output file's SHA-256 is checked.
    inputs_dir : Path, optional
        The job folder: each recorded input file's SHA-256 is checked.

    Returns
    -------
    AuditResult
    """
    content = read_record(path)
    result = AuditResult(truncated=content.truncated)
    result.lines.append(f"record {path}: {len(content.messages)} messages on {len(content.channels)} channels")
    if content.truncated:
        result.lines.append(f"TRUNCATED: the record was cut off ({content.problem}); everything up to the cut is shown")
    result.lines += _spec_lines(content) + _state_and_log_lines(content) + _design_lines(content)
    _check_designs(result, content)
    result.lines += _placement_lines(content)
    _tell_bus(result, content)
    result.lines += _ros2_lines(content)
    outputs = [f for o in content.of(TOPIC_OUTPUTS) for f in o["files"]]
    result.lines += [f"  output {item['path']} {item['size_bytes']} bytes sha256 {item['sha256']}" for item in outputs]
    outputs = _decided(result, content, outputs)
    if verify_dir is not None:
        _verify(result, Path(verify_dir), outputs, "output")
        if content.truncated:
            result.problems.append("the record is truncated: it cannot vouch for the whole job")
    if inputs_dir is not None:
        _verify(result, Path(inputs_dir), [f for i in content.of(TOPIC_INPUTS) for f in i["files"]], "input")
    return result


def _decided(result: AuditResult, content: RecordContent, outputs: list[dict]) -> list[dict]:
    """The output files as the operators' decisions on a held job left them (``fcsod approve | reject``), each decision
    told: what they removed is no longer expected, what they wrote is expected with its new hash."""
    for decision in content.of(TOPIC_DECISION):
        result.lines.append(f"{decision['decision']} by {decision['by']} at {decision['at']}")
        written = {item["path"]: item for item in decision["files"]}
        result.lines += [
            f"  output {item['path']} {item['size_bytes']} bytes sha256 {item['sha256']} (written at the decision)"
            for item in written.values()
        ]
        result.lines += [f"  output {name} removed at the decision" for name in decision["removed"]]
        gone = set(decision["removed"]) | set(written)
        outputs = [item for item in outputs if item["path"] not in gone] + list(written.values())
    return outputs


def _spec_lines(content: RecordContent) -> list[str]:
    """The job's identity, its parts, its manifest and its hashed inputs."""
    lines = []
    for spec in content.of(TOPIC_SPEC):
        lines.append(
            f"job {spec['job_id']} from folder {spec['folder']} (fcsod {spec['fcsod_version']}, fcso "
            f"{spec['fcso_version']})"
        )
        for part in spec["parts"]:
            lines.append(
                f"  part {part['file']}: units {part['units']}, quantity {part['quantity']}"
                + (f", scaled to {part['scale_to_mm']} mm" if part.get("scale_to_mm") else "")
            )
        manifest = spec["manifest"]
        lines.append(
            "  manifest: "
            + ("none (every mesh file, mm)" if manifest is None else f"{len(manifest.splitlines())} lines")
        )
    for inputs in content.of(TOPIC_INPUTS):
        lines += [f"  input {i['path']} {i['size_bytes']} bytes sha256 {i['sha256']}" for i in inputs["files"]]
    return lines


def _state_and_log_lines(content: RecordContent) -> list[str]:
    """State changes and the log records worth a person's attention (not the progress of a stage), in order."""
    lines = []
    for message in content.messages:
        if message.message_encoding != "json":
            continue
        body = message.json()
        if message.topic == TOPIC_STATE:
            lines.append(f"{body['at']} state {body['state']}" + (f": {body['error']}" if body.get("error") else ""))
        elif message.topic == TOPIC_LOG and (
            body["level"] != "info" or body.get("stage") is None or body.get("done") is None
        ):
            lines.append(f"  {body['level']}: {body['message']}")
    return lines


def _design_lines(content: RecordContent) -> list[str]:
    """Poses, samples, candidates and the designed fingers."""
    lines = []
    poses = content.of(TOPIC_POSES)
    if poses:
        lines.append("poses: " + ", ".join(f"{p['part']} #{p['pose_index']} (p={p['probability']:.3f})" for p in poses))
    for samples in content.of(TOPIC_SAMPLES):
        rejected = ", ".join(f"{k} {v}" for k, v in samples["rejected"].items() if v) or "none"
        lines.append(
            f"samples {samples['part']} #{samples['pose_index']}: {samples['valid_samples']} valid of "
            f"{samples['tried_samples']} (rejected: {rejected})"
        )
    candidates = content.of(TOPIC_CANDIDATES)
    if candidates:
        best = [c for c in candidates if c["best"]]
        lines.append(
            f"candidates: {len(candidates)} evaluated"
            + (f", best #{best[0]['candidate']['index']} Q = {best[0]['candidate']['quality']:.3f} mm²" if best else "")
        )
    for design in content.of(TOPIC_DESIGN):
        size = len(base64.b64decode(design["finger_stl_base64"]))
        lines.append(
            f"design: finger set {design.get('finger_set', 1)}: {size} bytes sha256 {design['finger_sha256']}, "
            f"volume {design['finger_volume_mm3']:.1f} mm³"
        )
    return lines


def _check_designs(result: AuditResult, content: RecordContent) -> None:
    """Each recorded finger's bytes against the hash recorded with them."""
    for design in content.of(TOPIC_DESIGN):
        actual = hashlib.sha256(base64.b64decode(design["finger_stl_base64"])).hexdigest()
        if actual != design["finger_sha256"]:
            result.problems.append(
                f"{TOPIC_DESIGN}: recorded finger bytes hash to {actual}, record says {design['finger_sha256']}"
            )


def _placement_lines(content: RecordContent) -> list[str]:
    """The placement of the finger copies in the build volume, with its warnings."""
    lines = []
    for placement in content.of(TOPIC_PLACEMENT):
        volume = " x ".join(f"{size:g}" for size in placement["volume_mm"])
        lines.append(
            f"placement ({placement['mode']}, volume {volume} mm): "
            + ("fingers fit" if placement["fingers_fit"] else "FINGERS DO NOT FIT")
            + f", {placement['finger_copies_placed']} of {placement['finger_copies_requested']} finger copies placed, "
            f"{len(placement['items'])} items, build height {placement['build_height_mm']:.1f} mm, "
            f"packing density {placement['packing_density']:.4f}: {placement['message']}"
        )
        lines += [f"  placement warning: {warning}" for warning in placement["warnings"]]
    return lines


def _tell_bus(result: AuditResult, content: RecordContent) -> None:
    """Every published message (a status with its state, a plan in full), each payload against its announced hash."""
    for body in content.of(TOPIC_BUS):
        payload = None if body["payload_base64"] is None else base64.b64decode(body["payload_base64"])
        size = len(body["payload_text"] or "") if payload is None else len(payload)
        line = f"published {body['key_expr']} ({body['encoding']}, {size} bytes)"
        if body["payload_text"] is not None and body["key_expr"].endswith("/status"):
            status = json.loads(body["payload_text"])
            line += f": {status['state']}" + "".join(f" (warning: {w})" for w in status.get("warnings", []))
        result.lines.append(line)
        if body["payload_text"] is not None and body["key_expr"].endswith("/plan"):
            result.lines += plan_lines(json.loads(body["payload_text"]))
        if body["attachment"] and payload is not None:
            announced = json.loads(body["attachment"]).get("sha256")
            actual = hashlib.sha256(payload).hexdigest()
            if announced != actual:
                result.problems.append(
                    f"{body['key_expr']}: payload hashes to {actual}, attachment announces {announced}"
                )


def _ros2_lines(content: RecordContent) -> list[str]:
    """The ROS 2 (CDR) channels, counted: what ``ros2 bag play`` would replay."""
    ros2 = Counter((m.topic, m.schema_name) for m in content.messages if m.message_encoding == "cdr")
    return [
        f"ROS 2 {topic} ({type_name}, cdr): {count} messages, for ros2 bag play"
        for (topic, type_name), count in ros2.items()
    ]


def _verify(result: AuditResult, folder: Path, files: list[dict], kind: str) -> None:
    for item in files:
        path = folder / item["path"]
        if not path.is_file():
            result.problems.append(f"{kind} {path}: missing")
            continue
        actual = file_sha256(path)
        if actual != item["sha256"]:
            result.problems.append(f"{kind} {path}: sha256 {actual}, recorded {item['sha256']}")
        else:
            result.lines.append(f"verified {kind} {path}")


def plan_lines(plan: dict) -> list[str]:
    """The pick plan as ``fcsod audit`` tells it, from a plan message's JSON body."""
    lines = [
        f"pick plan: {len(plan['sets'])} finger set(s), worst retained "
        + ("-" if plan["worst_retained"] is None else f"{plan['worst_retained']:.3f}")
        + f", min_retained {plan['min_retained']:g} "
        + ("reached" if plan["min_retained_reached"] else "NOT reached")
    ]
    for entry in plan["sets"]:
        reused = entry.get("finger_id")
        lines.append(
            f"  set {entry['set']}: mount "
            + (f"library finger {reused} delivered by {entry['reused_from_job']}, " if reused is not None else "")
            + f"{entry['finger_file']} ({entry['finger_copies']} copies in build.3mf, "
            f"sha256 {entry['finger_sha256']}, "
            f"{fcso.quality_words(entry['quality'], entry['quality_measure'])})"
        )
        for part in entry["parts"]:
            lines.append(
                f"    pick {part['quantity']} x {part['part']} (poses "
                f"{', '.join(str(g['pose_index']) for g in part['grasps'])})"
            )
    for entry in plan.get("not_served", []):
        lines.append(
            f"  not served: {entry['quantity']} x {entry['part']} to {entry['fallback'].replace('_', ' ')} "
            f"(best set {entry['best_set']} keeps {entry['retained']:.3f}: {entry['reason']})"
        )
    if plan["ungraspable_parts"]:
        lines.append("  not picked (no set can grasp them): " + ", ".join(plan["ungraspable_parts"]))
    return lines
