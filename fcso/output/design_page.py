"""``report.html``: one self-contained page of pictures and tables per design.

The page is built from :class:`ReportInputs`, which come either from a
fresh :class:`~fcso.pipeline.DesignResult` (:func:`report_inputs`) or from an
output folder (:func:`load_report_inputs`: ``report.json``, the part files it
names, ``finger.stl`` and ``fingerpad.stl``), so ``fcso report DIR`` redraws
the same page without designing again.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from ..finger import pad_to_finger
from ..layout import REPORT_HTML, write_atomic
from ..measure import quality_decimals, quality_title, quality_words
from ..parallel import resolve_jobs
from ..pipeline import DesignResult, flat_finger
from ..progress import Progress
from ..report.models import DesignReport
from ..report.ranking import chosen_candidate, ranked_candidates
from ..sampler import REJECTION_REASONS
from .grasp_scenes import GraspScene, chosen_grasp_scenes, reseat_grasps
from .html import closing_sections, html_page, image, key_value_table, text, unverified_verdict
from .read import read_design_folder
from .sets_page import finger_sets_section, pad_sizes_section
from .table import SCENARIO_GROUPS, quality_columns, scenario_labels
from .viewer import VIEW_FACES, column_major, glb_base64, grasp_view, points_base64, viewer_section

#: ``draw(inputs, progress)``: a page's pictures, name -> PNG bytes (:func:`pictures`).
DrawPictures = Callable[["ReportInputs", "Progress | None"], dict[str, bytes]]

#: A picture to draw: its name (its kind, then its scenario's number if it has one) and the arguments of its kind's
#: function (:func:`fcso.output.pictures.draw_pictures`).
Drawing = tuple[str, tuple]


#: Headers of the quality table's column groups (keys: :data:`fcso.output.table.SCENARIO_GROUPS`).
GROUP_TITLES = {"RLES": "RLES", "A mm2": "contact area A (mm²)", "E": "effective area E (mm²)"}


#: Index-ordered tables longer than this start folded.
FOLDED_ROWS = 40


#: Kinds of picture, longest to draw first (the bunny: grasp 0.2 s, pose 0.05 s).
_DRAWING_ORDER = ("grasp", "gripper", "normals", "capture", "fingerpad", "finger", "pose")


@dataclass
class ReportInputs:
    """Everything ``report.html`` is drawn from.

    Attributes
    ----------
    report : DesignReport
    finger : trimesh.Trimesh
        The fused finger, finger frame (mm).
    fingerpad : trimesh.Trimesh
        The chosen pad, pad frame (mm).
    pad_to_finger : (4, 4) float
        Pad frame to finger frame.
    grasps : list of GraspScene
        One per scenario, in the report's scenario order.
    """

    report: DesignReport
    finger: trimesh.Trimesh
    fingerpad: trimesh.Trimesh
    pad_to_finger: np.ndarray
    grasps: list[GraspScene]

    def drawings(self) -> list[Drawing]:
        """The page's pictures as :func:`fcso.output.pictures.draw_pictures` draws them, longest to draw first.

        The arguments are meshes, arrays, numbers, strings and report models,
        so a picture process unpickles them without the method's modules.
        """
        report = self.report
        settings = report.settings.sampler
        pad_size = (settings.thickness_mm, settings.length_mm, settings.width_mm)
        labels = _scenario_titles(report)
        first = self.grasps[0]
        drawings: list[Drawing] = [
            (
                "gripper",
                (
                    first.mesh,
                    self.finger,
                    self.pad_to_finger,
                    first.placements,
                    pad_size,
                    first.sample.closing_axis,
                    labels[0],
                ),
            ),
            ("finger", (self.finger, self.pad_to_finger, pad_size, "finger with its fingerpad (orange)")),
            ("fingerpad", (self.fingerpad, pad_size, f"fingerpad ({chosen_candidate(report).pad_case} case)")),
        ]
        reported = chosen_candidate(report).per_scenario
        for m, grasp in enumerate(self.grasps):
            drawings += [
                (
                    f"grasp {m}",
                    (grasp.mesh, self.fingerpad, grasp.placements, pad_size, grasp.sample.closing_axis, labels[m]),
                ),
                (
                    f"normals {m}",
                    (
                        grasp.normals,
                        grasp.rles,
                        grasp.cap_centre,
                        normals_title(labels[m], reported[m].rles, grasp.rles),
                    ),
                ),
                (f"pose {m}", (grasp.mesh, labels[m])),
            ]
            scenario = report.scenarios[m]
            if scenario.capture_landscape is not None:
                title = f"{labels[m]}: capture {scenario.capture:.0%} (flat pads {scenario.flat_capture:.0%})"
                drawings.append((f"capture {m}", (scenario.capture_landscape, title)))
        # longest drawings first, so no worker is left with a long one at the end
        drawings.sort(key=lambda drawing: _DRAWING_ORDER.index(drawing[0].split()[0]))
        return drawings


def report_inputs(result: DesignResult) -> ReportInputs:
    """The page's inputs from a design that was just run."""
    return ReportInputs(
        result.report,
        result.finger,
        result.fingerpad,
        result.pad_to_finger,
        chosen_grasp_scenes(result.scenarios, result.best),
    )


def load_report_inputs(directory: str | Path) -> ReportInputs:
    """The page's inputs from an output folder, re-seating the chosen grasps.

    The parts are reloaded with the recorded scale and moved into their
    recorded resting poses; each chosen sample's pad frames are rebuilt, the
    part surface inside each pad box is sampled with the design's seeds and
    seated against ``fingerpad.stl`` (METHOD §6).

    Parameters
    ----------
    directory : str or Path
        Holds ``report.json``, ``finger.stl`` and ``fingerpad.stl``.

    Returns
    -------
    ReportInputs

    Raises
    ------
    MeshError
        A file is missing or unreadable (named in the message).
    """
    folder = read_design_folder(directory)
    report, finger, fingerpad = folder.report, folder.finger, folder.fingerpad
    grasps = reseat_grasps(report, folder.parts, fingerpad)
    flat = flat_finger(report.settings)
    return ReportInputs(report, finger, fingerpad, pad_to_finger(flat, report.settings.sampler), grasps)


def pictures(inputs: ReportInputs, progress: Progress | None = None) -> dict[str, bytes]:
    """Render every picture of the page.

    Returns
    -------
    dict
        ``"gripper"`` (both fingers on the first scenario's part), ``"finger"``,
        ``"fingerpad"`` and ``"grasp <m>"``, ``"normals <m>"``, ``"pose <m>"``
        (and ``"capture <m>"`` under the capture measure) for each scenario
        ``m``: PNG bytes.
    """
    # matplotlib loads only where pictures are drawn (0.4 s): a command that
    # has them drawn by a picture process (fcso.output.picture_process) never loads it
    from .pictures import draw_pictures

    return draw_pictures(inputs.drawings(), resolve_jobs(inputs.report.settings.search.jobs), progress)


def _scenario_titles(report: DesignReport) -> list[str]:
    return [f"{s.part} / pose {s.pose_index} (p = {s.pose_probability:.3f})" for s in report.scenarios]


def render_html(inputs: ReportInputs, progress: Progress | None = None, draw: DrawPictures | None = None) -> str:
    """The whole page, images embedded as base64 PNG; ``draw`` draws them (:func:`pictures` when None)."""
    report = inputs.report
    images = (draw or pictures)(inputs, progress)
    chosen = chosen_candidate(report)
    titles = _scenario_titles(report)
    body = [
        "<h1>FCSO design report</h1>",
        # the verdict first (METHOD §12b): a verification puts its own here
        unverified_verdict(),
        _summary(report, chosen),
        *viewer_section(viewer_scene(inputs, titles)),
        image(images["gripper"], "gripper", "both fingers closed on the first part"),
        "<h2>Finger and fingerpad</h2>",
        image(images["finger"], "finger", "the finger with its fingerpad"),
        image(images["fingerpad"], "fingerpad", "the fingerpad coloured by depth"),
        "<h2>Grasps of the chosen candidate</h2>",
        "<p>Each part in its resting pose with the two seated pads (translucent orange); "
        "the part surface touching a pad is red. Below, the contact normals on the unit sphere "
        "and the largest empty cap (orange), whose chord radius is the RLES.</p>",
    ]
    for m, grasp in enumerate(inputs.grasps):
        body += [
            f"<h3>{text(titles[m])}</h3>",
            _grasp_table(report, m, grasp),
            image(images[f"grasp {m}"], "grasp", f"grasp of {titles[m]}"),
            image(images[f"normals {m}"], "normals", f"contact normals of {titles[m]}"),
        ]
        if f"capture {m}" in images:
            body += [
                "<p>Capture (METHOD §7b): the part started off its grasp along the pads and turned about the "
                "vertical; colour is how far apart the jaws first touch it, closing slides it down that slope "
                "where the slope beats friction. Hatched: the starts the chosen pad seats within 0.3 mm and 1°; "
                "dashed: those flat pads seat; grey: the precision test's error box.</p>",
                image(images[f"capture {m}"], "capture", f"capture landscape of {titles[m]}"),
            ]
    body += [
        "<h2>Stable poses used</h2>",
        _poses_table(report),
        '<div class="poses">'
        + "".join(image(images[f"pose {m}"], "pose", titles[m]) for m in range(len(inputs.grasps)))
        + "</div>",
        "<h2>Quality of all evaluated candidates</h2>",
        f"<p>{quality_legend(report.settings.quality.measure)}</p>",
        _folded(quality_table_html(report, ranked_candidates(report), "sorted"), len(report.candidates)),
    ]
    if len(report.scenarios) == 2:
        table = quality_table_html(report, report.candidates, "table-i")
        body += ["<h3>The paper's Table I layout (index order)</h3>", _folded(table, len(report.candidates))]
    body += pad_sizes_section(report.pad_sizes)
    if report.print_fit is not None:
        body += _print_fit_section(report)
    if report.placement is not None:
        body += _placement_section(report.placement)
    if report.finger_sets is not None:
        body += finger_sets_section(report.finger_sets)
    body += [
        "<h2>Grasp sampler</h2>",
        _sampler_table(report),
        *closing_sections(report.warnings, report.settings.model_dump_json(indent=2), report.timings_s),
    ]
    return html_page(f"FCSO report: {', '.join(p.name for p in report.parts)}", body)


def _folded(table: str, rows: int) -> str:
    """A table of ``rows`` candidates, folded (``<details>``) beyond :data:`FOLDED_ROWS` rows."""
    return f"<details><summary>{rows} candidates</summary>{table}</details>" if rows > FOLDED_ROWS else table


def quality_legend(measure: str) -> str:
    """The quality table's legend (HTML) under the design's ``[quality] measure``: each column named as what it is."""
    common = (
        "the chosen candidate is marked &#9733;. RLES: radius of the largest empty sphere of contact normals (chord, "
        "smaller is better); A: contact area of both pads (mm&sup2;); E = A / RLES (mm&sup2;)"
    )
    if measure == "paper":
        return f"Best first (Q, then mean E, then index); {common}; Q = min E over scenarios (the paper's measure)."
    return (
        f"Best first (the capture measure, then its mean, then index); {common}; quality: the capture measure "
        "(METHOD §7b, no unit): the worst scenario's capture x min(1, holding / hold force) in bands of 1/20, then E "
        "within a band. It is not min E."
    )


def normals_title(label: str, reported_rles: float, drawn_rles: float) -> str:
    """The contact-normals picture's title: the RLES of report.json, and the drawn normals' own when they differ (the
    page draws the printed pad's contacts, the report measures the design's)."""
    title = f"{label}: RLES = {reported_rles:.4f}"
    if abs(reported_rles - drawn_rles) > 5e-5:
        title += f" (drawn contacts: {drawn_rles:.4f})"
    return title


def viewer_scene(inputs: ReportInputs, titles: list[str]) -> dict:
    """The interactive view's data (:func:`fcso.output.viewer.viewer_section`): each grasp of the chosen candidate with
    both fingers seated and the contact samples, then the finger alone with its pocket.
    """
    to_pad = np.linalg.inv(inputs.pad_to_finger)
    part_faces = max(VIEW_FACES["part"], VIEW_FACES["parts"] // len(inputs.grasps))
    scene = {
        "meshes": {
            "finger": glb_base64(inputs.finger, VIEW_FACES["finger"]),
            "fingerpad": glb_base64(inputs.fingerpad, VIEW_FACES["fingerpad"]),
        },
        "points": {},
        "views": [],
    }
    for m, grasp in enumerate(inputs.grasps):
        scene["meshes"][f"part-{m}"] = glb_base64(grasp.mesh, part_faces)
        fingers, contact = [], []
        for placement in grasp.placements:
            to_rest = np.linalg.inv(placement.frame)
            seated = np.eye(4)
            seated[0, 3] = placement.offset_mm
            fingers.append(to_rest @ seated @ to_pad)
            contact.append(trimesh.transform_points(placement.samples.points[placement.contact], to_rest))
        scene["points"][f"contact-{m}"] = points_base64(np.concatenate(contact))
        scene["views"].append(grasp_view(f"grasp: {titles[m]}", f"part-{m}", fingers, f"contact-{m}"))
    scene["views"].append(
        {
            "title": "finger with its pocket",
            "items": [
                {"mesh": "finger", "group": "fingers"},
                {"mesh": "fingerpad", "matrix": column_major(inputs.pad_to_finger), "group": "pad"},
            ],
        }
    )
    return scene


def _placement_section(placement: dict) -> list[str]:
    """Where the finger copies go in the job's build (set by fcsod): a summary and one row per item."""
    summary = [(key, value) for key, value in placement.items() if not isinstance(value, (list, dict))]
    header = "".join(
        f"<th>{name}</th>" for name in ("item", "kind", "placed by", "bounds (mm)", "nearest gap (mm)", "nearest item")
    )
    rows = []
    for item in placement.get("items", []):
        bounds = item.get("bounds_mm")
        bounds_text = (
            " – ".join("(" + ", ".join(f"{x:.1f}" for x in corner) + ")" for corner in bounds) if bounds else ""
        )
        gap = item.get("nearest_distance_mm")
        cells = (
            item.get("name"),
            item.get("kind"),
            item.get("placed_by"),
            bounds_text,
            "" if gap is None else f"{gap:.2f}",
            item.get("nearest_item") or "",
        )
        rows.append("<tr>" + "".join(f'<td class="text">{text(c)}</td>' for c in cells) + "</tr>")
    return [
        "<h2>Build placement</h2>",
        key_value_table(summary),
        f"<table><tr>{header}</tr>{''.join(rows)}</table>",
    ]


def _print_fit_section(report: DesignReport) -> list[str]:
    """[print] as used and the chosen candidate carved exactly (METHOD §4-6) and as printed."""
    fit = report.print_fit
    settings = [
        ("profile", fit.profile),
        ("clearance", f"{fit.clearance_mm:g} mm"),
        ("lead-in", f"{fit.lead_in_deg:g}°"),
        ("minimum wall", f"{fit.min_wall_mm:g} mm"),
        ("material density", f"{fit.density_g_cm3:g} g/cm³"),
        (
            "thinnest free pad wall (printed, fused side excluded)",
            "none" if fit.thinnest_wall_mm is None else f"{fit.thinnest_wall_mm:.2f} mm",
        ),
    ]
    titles = _scenario_titles(report)
    header = (
        '<tr><th class="text">chosen candidate</th><th>pocket volume (mm³)</th>'
        + f"<th>{text(quality_title(report.settings.quality.measure))}</th>"
        + "".join(f"<th>A {text(t)} (mm²)</th><th>seat offsets {text(t)} (mm)</th>" for t in titles)
        + "</tr>"
    )
    rows = []
    for label, effect in (
        ("exact pocket (METHOD §4-6)", fit.exact),
        ("as printed (clearance, lead-in, walls)", fit.fitted),
    ):
        cells = "".join(
            f"<td>{a:.1f}</td><td>{', '.join(f'{t:+.3f}' for t in offsets)}</td>"
            for a, offsets in zip(effect.contact_area_mm2, effect.seat_offsets_mm)
        )
        rows.append(
            f'<tr><td class="text">{label}</td><td>{effect.pocket_volume_mm3:.1f}</td>'
            f"<td>{effect.quality:.{quality_decimals(report.settings.quality.measure)}f}</td>{cells}</tr>"
        )
    return [
        "<h2>Printed fit</h2>",
        "<p>The finger is carved with the clearance and lead-in of <code>[print]</code>, and pad walls thinner than "
        "the "
        "minimum are removed; as the gripper closes, the pads travel on toward the part until contact (negative seat "
        "offsets), so a clearance costs quality only where it changes how the part seats.</p>",
        key_value_table(settings),
        f"<table>{header}{''.join(rows)}</table>",
    ]


def _summary(report: DesignReport, chosen) -> str:
    measure = report.settings.quality.measure
    rows = [
        ("parts", ", ".join(f"{p.name} ({p.file}, x{p.scale_to_mm:g} to mm, {p.faces} faces)" for p in report.parts)),
        ("scenarios", len(report.scenarios)),
        (
            "search",
            f"{report.search.kind}: {report.search.screened} of C = {report.search.candidates_total} candidates "
            f"screened, "
            f"the best {report.search.exact} re-evaluated exactly on {report.search.jobs} worker(s)"
            f"{'' if report.search.proven_optimal else ' (not proven optimal)'}; "
            f"upper bound {quality_words(report.search.quality_upper_bound or 0, measure)}, "
            f"the chosen is {report.search.gap or 0:.0%} of it",
        ),
        (
            "chosen candidate",
            f"{chosen.index} (samples {chosen.samples}), {quality_words(chosen.quality, measure)}, "
            f"{chosen.pad_case} pad"
            + ("; delivered with flat pads: no carving captures a part better" if report.finger.flat_pads else ""),
        ),
        (
            "finger",
            f"{report.finger.source}, {report.finger.volume_mm3:.0f} mm³, thinnest pad section behind the pocket "
            f"(along the closing axis, to the fused back) {report.finger.min_pad_thickness_mm:.2f} mm, watertight: "
            f"{report.finger.watertight}",
        ),
        ("fcso", report.fcso_version),
    ]
    return key_value_table(rows)


def _grasp_table(report: DesignReport, m: int, grasp: GraspScene) -> str:
    chosen = chosen_candidate(report)
    quality = chosen.per_scenario[m]
    sample = report.scenarios[m].samples[chosen.samples[m]]
    robot = report.grasps[m]
    rows = [
        ("sample", f"{chosen.samples[m]}: yaw {sample.yaw_deg:g}°, s = {sample.s_mm:.2f} mm, h = {sample.h_mm:.2f} mm"),
        (
            "filter labels (+, -)",
            ", ".join(
                f"{label} (R = {r:.3f}, d = {d:.2f} mm)"
                for label, r, d in zip(sample.labels, sample.ratio, sample.depth_mm)
            ),
        ),
        ("seat offsets t (+, -)", ", ".join(f"{t:.3f} mm" for t in quality.seat_offsets_mm)),
        ("contact area A", f"{quality.contact_area_mm2:.1f} mm²"),
        ("RLES", f"{quality.rles:.4f} (drawn: {grasp.rles:.4f}, {len(grasp.normals)} contact normals)"),
        ("effective area E", f"{quality.effective_area:.1f} mm²"),
        (
            "TCP (resting frame)",
            f"position {robot.position_mm} mm, quaternion wxyz {robot.quaternion_wxyz}, "
            f"closing width {robot.closing_width_mm:.2f} mm",
        ),
    ]
    return key_value_table(rows)


def _poses_table(report: DesignReport) -> str:
    header = '<tr><th class="text">part</th><th>pose index</th><th>probability</th><th>valid samples</th></tr>'
    rows = "".join(
        f'<tr><td class="text">{text(s.part)}</td><td>{s.pose_index}</td>'
        f"<td>{s.pose_probability:.4f}</td><td>{s.valid_samples}</td></tr>"
        for s in report.scenarios
    )
    return f"<table>{header}{rows}</table>"


def _sampler_table(report: DesignReport) -> str:
    reasons = list(REJECTION_REASONS) + sorted(
        {r for s in report.scenarios for r in s.rejected} - set(REJECTION_REASONS)
    )
    header = (
        '<tr><th class="text">scenario</th><th>tried</th><th>valid</th>'
        + "".join(f"<th>rejected: {text(r)}</th>" for r in reasons)
        + "</tr>"
    )
    rows = "".join(
        f'<tr><td class="text">{text(label)}</td><td>{s.tried_samples}</td><td>{s.valid_samples}</td>'
        + "".join(f"<td>{s.rejected.get(r, 0)}</td>" for r in reasons)
        + "</tr>"
        for label, s in zip(_scenario_titles(report), report.scenarios)
    )
    return f"<table>{header}{rows}</table>"


def quality_table_html(report: DesignReport, rows: list, table_id: str) -> str:
    """The quality table as HTML, headers grouped as in the paper's Table I.

    Parameters
    ----------
    report : DesignReport
    rows : list of CandidateReport
        In the order to show.
    table_id : str
        ``id`` of the table element.

    Returns
    -------
    str
        A ``<table>``; the chosen candidate's row has class ``chosen`` and a star.
    """
    columns = quality_columns(report)
    count = len(scenario_labels(report))
    top = (
        '<tr><th rowspan="2">i</th>'
        + "".join(f'<th colspan="{count}">{text(GROUP_TITLES[g])}</th>' for g, _, _ in SCENARIO_GROUPS)
        + f'<th rowspan="2">{text(quality_title(report.settings.quality.measure))}</th>'
        + '<th rowspan="2" class="text">pad</th></tr>'
    )
    second = "<tr>" + "".join(f"<th>{text(c.scenario)}</th>" for c in columns if c.scenario is not None) + "</tr>"
    lines = [f'<table id="{table_id}" class="quality">', top, second]
    for row in rows:
        chosen = row.index == report.best
        cells = [f"{'&#9733; ' if chosen else ''}{row.index}"] + [f"{c.value(row):.{c.decimals}f}" for c in columns]
        attributes = ' class="chosen"' if chosen else ""
        lines.append(
            f"<tr{attributes}>"
            + "".join(f"<td>{cell}</td>" for cell in cells)
            + f'<td class="text">{text(row.pad_case)}</td></tr>'
        )
    lines.append("</table>")
    return "\n".join(lines)


def report_html(result: DesignResult, progress: Progress | None = None, draw: DrawPictures | None = None) -> bytes:
    """``report.html`` of a design that was just run, UTF-8 (``draw`` as for :func:`render_html`)."""
    return render_html(report_inputs(result), progress, draw).encode("utf-8")


def rebuild_report(directory: str | Path, progress: Progress | None = None) -> Path:
    """Rebuild ``report.html`` in an output folder from its other files.

    Parameters
    ----------
    directory : str or Path
        Output folder of ``fcso design`` (``report.json``, ``finger.stl``,
        ``fingerpad.stl``); the part files named in the report must exist.
    progress : callable, optional
        ``progress(stage, done, total)``.

    Returns
    -------
    Path
        The written ``report.html``.
    """
    directory = Path(directory)
    page = render_html(load_report_inputs(directory), progress).encode("utf-8")
    return write_atomic(directory / REPORT_HTML, page)
