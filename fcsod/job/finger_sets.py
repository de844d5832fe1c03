"""A job served by several finger sets (METHOD §11): build placement, messages and the pick plan.

fcso designs the sets (:func:`fcso.sets.design_sets`); here every set's
finger copies go into the job's build, each set's finger and the pick plan
become zenoh messages. With one set a job publishes as before, plus the plan.
"""

from __future__ import annotations

import hashlib

from fcso.layout import set_finger_path
from fcso.report.models import FingerSetsReport
from fcso.sets import SetsResult

from ..bus.messages import ENCODING_STL, BusMessage, DesignAttachment, PlanMessage, PlanSet, job_key
from ..plate.build3mf import Build, BuildItem
from ..plate.models import BuildConfig
from ..plate.placement import PlacementResult, place_fingers


def place_sets(build: Build, sets: SetsResult, config: BuildConfig) -> list[PlacementResult]:
    """Place every set's finger copies into the build, set after set.

    Set k's copies are named ``fcso-finger-<k>-<copy>``; the parts and the
    copies of the sets before it stay where they were placed.

    Returns
    -------
    list of PlacementResult
        One per set; the last one's items are the whole build.
    """
    results = []
    for number, design in enumerate(sets.designs, start=1):
        placed = place_fingers(
            build,
            design.finger,
            config,
            pad_normal=design.flat_finger.contact_normal,
            finger_name=f"fcso-finger-{number}",
        )
        for item in placed.items:
            if item.kind == "finger" and item.finger_set is None:
                item.finger_set = number
        results.append(placed)
        build = Build(
            items=[BuildItem(i.name, i.mesh, i.transform, i.kind, i.part_number, i.finger_set) for i in placed.items],
            source=build.source,
        )
    return results


def design_messages(prefix: str, cell: str, job_id: str, sets: SetsResult, files: dict[str, bytes]) -> list[BusMessage]:
    """Each set's finger STL on ``<prefix>/<cell>/jobs/<job_id>/design/<set>`` with its sha256 in the attachment."""
    messages = []
    for number in range(1, len(sets.designs) + 1):
        name = set_finger_path(number, sets.several)
        data = files[name]
        attachment = DesignAttachment(
            job_id=job_id, sha256=hashlib.sha256(data).hexdigest(), file=name, size_bytes=len(data), finger_set=number
        )
        topic = f"design/{number}"
        messages.append(
            BusMessage(
                job_id,
                topic,
                job_key(prefix, cell, job_id, topic),
                ENCODING_STL,
                data,
                attachment.model_dump_json().encode(),
            )
        )
    return messages


def plan_message(
    prefix: str, cell: str, job_id: str, sets: SetsResult, files: dict[str, bytes], copies: list[int]
) -> BusMessage:
    """The pick plan on ``<prefix>/<cell>/jobs/<job_id>/plan``.

    Parameters
    ----------
    prefix, cell, job_id : str
    sets : SetsResult
        With its report (``[finger_sets] max > 1``).
    files : dict
        The job's output files (the fingers' bytes).
    copies : list of int
        Finger copies of every set in ``build.3mf``.
    """
    report: FingerSetsReport = sets.report
    one = not sets.several
    plan = PlanMessage(
        job_id=job_id,
        sets=[
            PlanSet(
                set=step.set,
                finger_key=job_key(prefix, cell, job_id, "design" if one else f"design/{step.set}"),
                finger_file=set_finger_path(step.set, sets.several),
                finger_sha256=hashlib.sha256(files[set_finger_path(step.set, sets.several)]).hexdigest(),
                finger_copies=count,
                quality=entry.quality,
                quality_measure=sets.designs[0].report.settings.quality.measure,
                worst_retained=entry.worst_retained,
                parts=step.parts,
            )
            for step, entry, count in zip(report.pick_plan, report.sets, copies)
        ],
        min_retained=report.min_retained,
        min_retained_reached=report.min_retained_reached,
        worst_retained=report.worst_retained,
        ungraspable_parts=report.ungraspable_parts,
        partition=report.search.description,
    )
    return BusMessage.json_body(prefix, cell, "plan", plan)
