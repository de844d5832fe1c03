"""A job's finger sets for people: the sections of the report pages, the job's own page, and the pick plan for a
terminal.
"""

from __future__ import annotations

import trimesh

from ..finger import pad_to_finger
from ..pipeline import flat_finger
from ..report.models import FingerSetsReport, JobReport, PadSizeReport
from .html import closing_sections, html_page, image, text
from .viewer import VIEW_FACES, glb_base64, viewer_section


def job_html(report: JobReport, fingers: list[trimesh.Trimesh]) -> str:
    """``report.html`` of a job with several finger sets: the sets with their fingers, the scenarios and the pick plan.

    Parameters
    ----------
    report : JobReport
    fingers : list of trimesh.Trimesh
        Every set's finger (mm), set order.
    """
    from .pictures import finger_picture  # matplotlib loads only where pictures are drawn

    sets = report.finger_sets
    config = report.settings
    pad_size = (config.sampler.thickness_mm, config.sampler.length_mm, config.sampler.width_mm)
    flat = flat_finger(config)
    transform = pad_to_finger(flat, config.sampler)
    body = ["<h1>FCSO job report: finger sets</h1>", *finger_sets_section(sets), "<h2>The fingers</h2>"]
    for entry, finger in zip(sets.sets, fingers):
        body += [
            f'<h3>Set {entry.set}: {text(", ".join(entry.parts))} (<a href="{entry.folder}/report.html">design '
            f"report</a>)</h3>",
            image(
                finger_picture(finger, transform, pad_size, f"set {entry.set}: finger with its fingerpad (orange)"),
                "finger",
                f"finger of set {entry.set}",
            ),
        ]
    # each set's design report turns its grasps; this page turns the fingers side by side
    scene = {
        "meshes": {f"finger-{e.set}": glb_base64(f, VIEW_FACES["finger"]) for e, f in zip(sets.sets, fingers)},
        "points": {},
        "views": [
            {"title": f"set {e.set}: finger", "items": [{"mesh": f"finger-{e.set}", "group": "fingers"}]}
            for e in sets.sets
        ],
    }
    body += viewer_section(scene, "The fingers in 3D")
    body += closing_sections(report.warnings, config.model_dump_json(indent=2), report.timings_s)
    return html_page(f"FCSO job: {len(sets.sets)} finger sets", body)


def pad_sizes_section(sizes: list[PadSizeReport]) -> list[str]:
    """HTML of the pad sizes (METHOD §3b), the delivered one marked, why a size gave no design; nothing for a single
    size."""
    if len(sizes) < 2:
        return []
    rows = "".join(
        f"<tr><td>{'&#9733; ' if entry.chosen else ''}{entry.length_mm:g} x {entry.width_mm:g}</td>"
        + (
            f'<td>{entry.quality:.3g}</td><td class="text">{"flat pads" if entry.flat_pads else "carved"}</td>'
            if entry.quality is not None
            else f'<td></td><td class="text">{text(entry.note or "")}</td>'
        )
        + "</tr>"
        for entry in sizes
    )
    return [
        "<h2>Pad sizes</h2>",
        "<p>Each size of <code>[sampler] length_mm</code> x <code>width_mm</code> was designed in full, except for "
        "finger sets the sizes whose screened partition could not compete with another's; the best by the quality "
        "measure is delivered (&#9733;).</p>",
        f'<table><tr><th>L x W (mm)</th><th>quality</th><th class="text">pads</th></tr>{rows}</table>',
    ]


def pad_sizes_line(sizes: list[PadSizeReport]) -> str | None:
    """One line of text on the pad sizes, or None for a single size."""
    if len(sizes) < 2:
        return None
    return "pad sizes: " + ", ".join(
        f"{e.length_mm:g} x {e.width_mm:g} mm "
        + (f"quality {e.quality:.3g}" if e.quality is not None else "screened out" if e.screened_out else "no grasp")
        + (" (delivered)" if e.chosen else "")
        for e in sizes
    )


def finger_sets_section(sets: FingerSetsReport) -> list[str]:
    """HTML of the finger sets, the pick plan, every scenario's E, E* and retained, and how the split was found."""
    reached = "reached" if sets.min_retained_reached else "<b>not reached</b>"
    rows = "".join(
        f'<tr><td>{s.set}</td><td class="text">{text(", ".join(s.parts))}</td><td>{s.quality:.3g}</td>'
        f'<td>{s.worst_retained:.3f}</td><td>{s.mean_retained:.3f}</td><td class="text">{s.pad_case}</td><td '
        f'class="text">{text(s.folder)}</td></tr>'
        for s in sets.sets
    )
    plan = "".join(
        f'<tr><td>{step.set}</td><td class="text">{text(step.finger)}</td><td class="text">{text(part.part)}</td>'
        f'<td class="text">{text(", ".join(part.copies))}</td><td>{part.quantity}</td>'
        f'<td class="text">{text("; ".join(_grasp_text(g) for g in part.grasps))}</td></tr>'
        for step in sets.pick_plan
        for part in step.parts
    )
    scenarios = "".join(
        f'<tr><td class="text">{text(s.part)}</td><td>{s.pose_index}</td><td>{s.set if s.set is not None else "-"}</td>'
        f"<td>{s.quality:.3g}</td><td>{s.solo_quality:.3g}</td><td>{_number(s.retained)}</td><td>{_number(s.screened_retained)}</td></tr>"
        for s in sets.scenarios
    )
    search = sets.search
    section = [
        "<h2>Finger sets</h2>",
        f"<p>{len(sets.sets)} finger set(s) of at most {sets.max_sets}. Every graspable scenario should keep "
        f"retained = E / E* &ge; {sets.min_retained:g} of its solo quality E* (the best E of a finger designed for it "
        f"alone; E is the scenario's quality: E in mm² under the paper's measure, METHOD §7b's measure otherwise): "
        f"{reached}; worst retained {_number(sets.worst_retained)}, median {_number(sets.median_retained)}.</p>",
        '<table><tr><th>set</th><th class="text">parts</th><th>quality</th><th>worst retained</th><th>mean '
        "retained</th>"
        f'<th class="text">pad</th><th class="text">folder</th></tr>{rows}</table>',
        "<h2>Pick plan</h2>",
        "<p>Mount the sets in this order; with each, pick its parts (all their copies). Grasps are in the part's "
        "resting frame.</p>",
        '<table><tr><th>set</th><th class="text">finger</th><th class="text">part</th><th '
        'class="text">copies</th><th>quantity</th>'
        f'<th class="text">grasps</th></tr>{plan}</table>',
        "<h2>Scenarios</h2>",
        '<table><tr><th class="text">part</th><th>pose</th><th>set</th><th>E (quality)</th><th>E* (solo)</th>'
        f"<th>retained</th><th>screened retained</th></tr>{scenarios}</table>",
        "<h2>How the sets were found</h2>",
        f"<p>{text(search.description)}.</p>",
        f"<p>Lower bound: {search.lower_bound_sets} set(s)"
        + (
            f" (pairwise conflicting: {text(', '.join(search.conflict_clique))})"
            if len(search.conflict_clique) > 1
            else ""
        )
        + (
            f"; no partition into {sets.max_sets} sets keeps a worst retained above {search.worst_retained_bound:.3f}"
            if search.worst_retained_bound is not None
            else ""
        )
        + ".</p>",
    ]
    section += _search_sections(search)
    if sets.identical_parts:
        section.append(
            "<h3>Identical parts, designed once</h3><ul>"
            + "".join(
                f"<li>{text(g.part)}: {text(', '.join(g.copies))} ({g.quantity} pieces)</li>"
                for g in sets.identical_parts
            )
            + "</ul>"
        )
    if sets.ungraspable_parts:
        section.append(
            "<h3>Parts no set can grasp</h3><ul>"
            + "".join(
                f"<li>{text(u.part)} in stable pose {u.pose_index}: {text(u.reason)}</li>"
                for u in sets.ungraspable
                if u.part in sets.ungraspable_parts
            )
            + "</ul>"
        )
    if sets.not_served:
        section.append(
            "<h3>Parts no set serves (picked with the fallback)</h3><ul>"
            + "".join(
                f"<li>{text(n.part)} ({n.quantity} pieces): {text(n.fallback.replace('_', ' '))}; {text(n.reason)}</li>"
                for n in sets.not_served
            )
            + "</ul>"
        )
    if sets.truth is not None:
        section.append(
            "<h3>Judged by truth</h3><p>The delivered sets' fingers simulated during the design ([finger_sets] "
            "truth_budget_s): successful precision trials per scenario, the set's finger (flat pads).</p><pre>"
            + text("\n".join(_truth_lines(sets)))
            + "</pre>"
        )
    section += pad_sizes_section(sets.pad_sizes)
    return section


def _search_sections(search) -> list[str]:
    """HTML of how the split was found beyond its bound: why ``min_retained`` is not reached, the partitions judged
    exactly, the parts that cannot share a finger."""
    section: list[str] = []
    if search.explanation:
        section.append(f"<p><b>Why min_retained is not reached:</b> {text(search.explanation)}.</p>")
    if search.attempts:
        tried = "".join(
            f"<tr><td>{a.sets}</td><td>{_number(a.screened_worst_retained)}</td><td>{a.exact_worst_retained:.3f}</td>"
            f'<td class="text">{text(_attempt_source(a))}</td><td class="text">{"chosen" if a.chosen else ""}'
            f'</td><td class="text">{text(" | ".join(", ".join(p) for p in a.parts))}</td></tr>'
            for a in search.attempts
        )
        section.append(
            "<h3>Partitions judged exactly</h3>"
            "<p>Screening proposes a partition; the exact evaluation of each set's screened best candidate judges it, "
            "and the best proposal's sets are designed (METHOD &sect;11 revision 3); &ldquo;designed&rdquo;: the "
            "exact figure is that of the designed fingers.</p>"
            '<table><tr><th>sets</th><th>screened worst retained</th><th>exact worst retained</th><th class="text">'
            'from</th><th class="text"></th><th class="text">sets</th></tr>'
            f"{tried}</table>"
        )
    if search.blocking_pairs:
        pairs = "".join(
            f'<tr><td class="text">{text(p.parts[0])}</td><td '
            f'class="text">{text(p.parts[1])}</td><td>{p.retained[0]:.3f}</td><td>{p.retained[1]:.3f}</td></tr>'
            for p in search.blocking_pairs
        )
        section.append(
            "<h3>Parts that cannot share a finger</h3>"
            '<table><tr><th class="text">part a</th><th class="text">part b</th><th>retained a</th><th>retained '
            "b</th></tr>"
            f"{pairs}</table>"
        )
    return section


def _attempt_source(attempt) -> str:
    source = attempt.source.replace("_", " ") + (", designed" if attempt.designed else "")
    return f"{source}: not made, {attempt.failure}" if attempt.failure else source


def _number(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f}"


def _grasp_text(grasp) -> str:
    return f"pose {grasp.pose_index}: TCP {_vector(grasp.position_mm)} mm, width {grasp.closing_width_mm:.2f} mm"


def _vector(values) -> str:
    return "(" + ", ".join(f"{v:.1f}" for v in values) + ")"


def pick_plan_text(sets: FingerSetsReport) -> str:
    """The finger sets and the pick plan as lines for a terminal."""
    lines = [
        f"{len(sets.sets)} finger set(s) of at most {sets.max_sets} ({sets.search.method}); worst retained E/E* "
        f"{_number(sets.worst_retained)}, median {_number(sets.median_retained)}, min_retained {sets.min_retained:g} "
        + ("reached" if sets.min_retained_reached else "NOT reached")
    ]
    for entry, step in zip(sets.sets, sets.pick_plan):
        lines.append(
            f"set {entry.set}: mount {step.finger} (quality {entry.quality:.3g}, worst retained "
            f"{entry.worst_retained:.3f})"
        )
        for part in step.parts:
            poses = ", ".join(str(g.pose_index) for g in part.grasps)
            lines.append(f"  pick {part.quantity} x {part.part} (poses {poses})")
    for entry in sets.not_served:
        lines.append(
            f"not served: {entry.quantity} x {entry.part} to {entry.fallback.replace('_', ' ')} ({entry.reason})"
        )
    if sets.ungraspable_parts:
        lines.append("not picked (no set can grasp them): " + ", ".join(sets.ungraspable_parts))
    lines.append(
        f"sets used {len(sets.sets)} of {sets.sets_allowed} allowed; "
        + (
            f"the job needs {sets.sets_needed}"
            if sets.sets_needed is not None
            else f"{len(sets.not_served)} not served"
        )
    )
    for attempt in sets.search.attempts:
        lines.append(
            f"{attempt.sets} set(s) ({attempt.source.replace('_', ' ')}): worst retained screened "
            f"{_number(attempt.screened_worst_retained)}, exact {attempt.exact_worst_retained:.3f}"
            + (" (designed)" if attempt.designed else "")
            + (" (chosen)" if attempt.chosen else "")
            + (f"; not made: {attempt.failure}" if attempt.failure else "")
        )
    if sets.search.explanation:
        lines.append(f"min_retained not reached: {sets.search.explanation}")
    lines.extend(_truth_lines(sets))
    return "\n".join(lines)


def _truth_lines(sets: FingerSetsReport) -> list[str]:
    """The sets judged by truth (``finger_sets.truth``) as lines: each delivered set's verified success per scenario,
    designed and flat, and what moved; none when the sets were judged by the measure alone."""
    truth = sets.truth
    if truth is None:
        return []
    lines = [
        f"judged by truth: {truth.spent_s:.0f} s of {truth.budget_s:g} s simulated; moved to a set of their own: "
        f"{', '.join(truth.moved_parts) or 'none'}"
        + (f"; not served: {', '.join(truth.not_served_parts)}" if truth.not_served_parts else "")
    ]
    for verified in truth.sets:
        lines.append(
            f"  set {verified.set} verified: "
            + ", ".join(
                f"{s.part} pose {s.pose_index} {s.successes}/{s.trials} (flat {s.flat_successes}/{s.flat_trials})"
                + ("" if s.passed else " failed")
                for s in verified.scenarios
            )
        )
    if truth.unverified_sets:
        lines.append(f"  not verified (budget spent, or see below): set {', '.join(map(str, truth.unverified_sets))}")
    return lines + [f"  {note}" for note in truth.notes]
