"""Writing a job's finger sets: one folder per set, one ``report.json`` / ``report.html`` for the job.

With one finger set the layout is today's single design: ``finger.stl``,
``fingerpad.stl``, ``report.json`` and ``report.html`` in the output folder
(``report.json`` then carries ``finger_sets`` when the sets were searched).
With two or more::

    out/report.json          JobReport: sets, E, E*, retained, pick plan
    out/report.html          the same for people, with every set's finger
    out/set-1/finger.stl     set 1's finger (both gripper fingers are this part)
    out/set-1/fingerpad.stl
    out/set-1/report.json    set 1's own design report (DesignReport)
    out/set-1/report.html
    out/set-2/...
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import trimesh

from .design import Progress
from .errors import MeshError
from .finger import load_finger, pad_to_finger, parametric_finger
from .html_report import DrawPictures, _image, _text, closing_sections, html_page, read_stl, rebuild_report
from .output import output_files
from .sets import SetsResult
from .sets_report import FingerSetsReport, JobReport


def sets_output_files(result: SetsResult, progress: Progress | None = None, draw: DrawPictures | None = None) -> dict[str, bytes]:
    """The files of a job's finger sets: relative path -> bytes (see the module's layout).

    ``draw`` draws each design page's pictures (:func:`fcso.html_report.pictures` when None).
    """
    if result.job_report is None:
        return output_files(result.designs[0], progress, draw)
    files = {
        f"set-{k}/{name}": data
        for k, design in enumerate(result.designs, start=1)
        for name, data in output_files(design, progress, draw).items()
    }
    files["report.json"] = (result.job_report.model_dump_json(indent=2) + "\n").encode("utf-8")
    files["report.html"] = job_html(result.job_report, [d.finger for d in result.designs]).encode("utf-8")
    return files


def write_set_outputs(
    result: SetsResult, out_dir: str | Path, progress: Progress | None = None, draw: DrawPictures | None = None
) -> list[Path]:
    """Write :func:`sets_output_files` into ``out_dir``, each under a temporary name renamed into place; return the paths."""
    out_dir = Path(out_dir)
    written = []
    for name, data in sets_output_files(result, progress, draw).items():
        target = out_dir / name
        target.parent.mkdir(parents=True, exist_ok=True)
        temporary = target.parent / f".{target.name}.tmp"
        temporary.write_bytes(data)
        os.replace(temporary, target)
        written.append(target)
    return written


def job_html(report: JobReport, fingers: list[trimesh.Trimesh]) -> str:
    """``report.html`` of a job with several finger sets: the sets with their fingers, the scenarios and the pick plan.

    Parameters
    ----------
    report : JobReport
    fingers : list of trimesh.Trimesh
        Every set's finger (mm), set order.
    """
    from .render import finger_picture  # matplotlib loads only where pictures are drawn

    sets = report.finger_sets
    config = report.settings
    pad_size = (config.sampler.thickness_mm, config.sampler.length_mm, config.sampler.width_mm)
    flat = load_finger(config.finger) if config.finger.mesh else parametric_finger(config.sampler, config.gripper)
    transform = pad_to_finger(flat, config.sampler)
    body = ["<h1>FCSO job report: finger sets</h1>", *finger_sets_section(sets), "<h2>The fingers</h2>"]
    for entry, finger in zip(sets.sets, fingers):
        body += [
            f'<h3>Set {entry.set}: {_text(", ".join(entry.parts))} (<a href="{entry.folder}/report.html">design report</a>)</h3>',
            _image(finger_picture(finger, transform, pad_size, f"set {entry.set}: finger with its fingerpad (orange)"), "finger", f"finger of set {entry.set}"),
        ]
    body += closing_sections(report.warnings, config.model_dump_json(indent=2), report.timings_s)
    return html_page(f"FCSO job: {len(sets.sets)} finger sets", body)


def is_job_folder(directory: str | Path) -> bool:
    """Whether ``directory`` holds the output of a job with several finger sets (its ``report.json`` is a JobReport)."""
    path = Path(directory) / "report.json"
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(data, dict) and "finger_sets" in data and "best" not in data


def rebuild_job_report(directory: str | Path, progress: Progress | None = None) -> list[Path]:
    """Rebuild every set's ``report.html`` and the job's from the files of a job folder.

    Returns
    -------
    list of Path
        The pages written, the job's last.

    Raises
    ------
    MeshError
        A report or finger file is missing or unreadable (named in the message).
    """
    directory = Path(directory)
    path = directory / "report.json"
    try:
        report = JobReport.model_validate_json(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise MeshError(path, f"not a job report: {str(exc).splitlines()[0]}") from None
    written = [rebuild_report(directory / entry.folder, progress) for entry in report.finger_sets.sets]
    fingers = [read_stl(directory / entry.folder / "finger.stl") for entry in report.finger_sets.sets]
    target = directory / "report.html"
    temporary = directory / ".report.html.tmp"
    temporary.write_text(job_html(report, fingers), encoding="utf-8")
    os.replace(temporary, target)
    return written + [target]


def finger_sets_section(sets: FingerSetsReport) -> list[str]:
    """HTML of the finger sets, the pick plan, every scenario's E, E* and retained, and how the split was found."""
    reached = "reached" if sets.min_retained_reached else "<b>not reached</b>"
    rows = "".join(
        f'<tr><td>{s.set}</td><td class="text">{_text(", ".join(s.parts))}</td><td>{s.quality:.1f}</td>'
        f'<td>{s.worst_retained:.3f}</td><td>{s.mean_retained:.3f}</td><td class="text">{s.pad_case}</td><td class="text">{_text(s.folder)}</td></tr>'
        for s in sets.sets
    )
    plan = "".join(
        f'<tr><td>{step.set}</td><td class="text">{_text(step.finger)}</td><td class="text">{_text(part.part)}</td>'
        f'<td class="text">{_text(", ".join(part.copies))}</td><td>{part.quantity}</td>'
        f'<td class="text">{_text("; ".join(f"pose {g.pose_index}: TCP {_vector(g.position_mm)} mm, width {g.closing_width_mm:.2f} mm" for g in part.grasps))}</td></tr>'
        for step in sets.pick_plan
        for part in step.parts
    )
    scenarios = "".join(
        f'<tr><td class="text">{_text(s.part)}</td><td>{s.pose_index}</td><td>{s.set if s.set is not None else "-"}</td>'
        f"<td>{s.effective_area:.1f}</td><td>{s.solo_effective_area:.1f}</td><td>{_number(s.retained)}</td><td>{_number(s.screened_retained)}</td></tr>"
        for s in sets.scenarios
    )
    search = sets.search
    section = [
        "<h2>Finger sets</h2>",
        f"<p>{len(sets.sets)} finger set(s) of at most {sets.max_sets}. Every graspable scenario should keep "
        f"retained = E / E* &ge; {sets.min_retained:g} of its solo quality E* (the best E of a finger designed for it alone): "
        f"{reached}; worst retained {_number(sets.worst_retained)}, median {_number(sets.median_retained)}.</p>",
        '<table><tr><th>set</th><th class="text">parts</th><th>Q (mm&sup2;)</th><th>worst retained</th><th>mean retained</th>'
        f'<th class="text">pad</th><th class="text">folder</th></tr>{rows}</table>',
        "<h2>Pick plan</h2>",
        "<p>Mount the sets in this order; with each, pick its parts (all their copies). Grasps are in the part's resting frame.</p>",
        '<table><tr><th>set</th><th class="text">finger</th><th class="text">part</th><th class="text">copies</th><th>quantity</th>'
        f'<th class="text">grasps</th></tr>{plan}</table>',
        "<h2>Scenarios</h2>",
        '<table><tr><th class="text">part</th><th>pose</th><th>set</th><th>E (mm&sup2;)</th><th>E* (mm&sup2;)</th>'
        f"<th>retained</th><th>screened retained</th></tr>{scenarios}</table>",
        "<h2>How the sets were found</h2>",
        f"<p>{_text(search.description)}.</p>",
        f"<p>Lower bound: {search.lower_bound_sets} set(s)"
        + (f" (pairwise conflicting: {_text(', '.join(search.conflict_clique))})" if len(search.conflict_clique) > 1 else "")
        + (f"; no partition into {sets.max_sets} sets keeps a worst retained above {search.worst_retained_bound:.3f}" if search.worst_retained_bound is not None else "")
        + ".</p>",
    ]
    if search.explanation:
        section.append(f"<p><b>Why min_retained is not reached:</b> {_text(search.explanation)}.</p>")
    if search.blocking_pairs:
        pairs = "".join(
            f'<tr><td class="text">{_text(p.parts[0])}</td><td class="text">{_text(p.parts[1])}</td><td>{p.retained[0]:.3f}</td><td>{p.retained[1]:.3f}</td></tr>'
            for p in search.blocking_pairs
        )
        section.append(
            "<h3>Parts that cannot share a finger</h3>"
            '<table><tr><th class="text">part a</th><th class="text">part b</th><th>retained a</th><th>retained b</th></tr>'
            f"{pairs}</table>"
        )
    if sets.identical_parts:
        section.append(
            "<h3>Identical parts, designed once</h3><ul>"
            + "".join(f"<li>{_text(g.part)}: {_text(', '.join(g.copies))} ({g.quantity} pieces)</li>" for g in sets.identical_parts)
            + "</ul>"
        )
    if sets.ungraspable_parts:
        section.append(
            "<h3>Parts no set can grasp</h3><ul>"
            + "".join(f"<li>{_text(u.part)} in stable pose {u.pose_index}: {_text(u.reason)}</li>" for u in sets.ungraspable if u.part in sets.ungraspable_parts)
            + "</ul>"
        )
    return section


def _number(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f}"


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
        lines.append(f"set {entry.set}: mount {step.finger} (Q = {entry.quality:.1f} mm², worst retained {entry.worst_retained:.3f})")
        for part in step.parts:
            poses = ", ".join(str(g.pose_index) for g in part.grasps)
            lines.append(f"  pick {part.quantity} x {part.part} (poses {poses})")
    if sets.ungraspable_parts:
        lines.append("not picked (no set can grasp them): " + ", ".join(sets.ungraspable_parts))
    if sets.search.explanation:
        lines.append(f"min_retained not reached: {sets.search.explanation}")
    return "\n".join(lines)
