"""The verification section of ``report.html`` (fcso.sim, METHOD §12): pictures and tables of ``verification.json``, and
writing both.
"""

from __future__ import annotations

import base64
import html
from pathlib import Path

import numpy as np
import trimesh
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ..geometry import transform_points
from ..layout import REPORT_HTML, VERIFICATION_JSON, write_atomic
from ..report.models import DesignReport
from ..sim.report import (
    RankedCandidate,
    ScenarioVerification,
    VerificationReport,
    better_than_flat,
    not_held,
    reused_note,
    successes,
    verdict_text,
    weakest_hold_n,
)
from ..sim.scene import pad_in_world
from ..sim.verify import DesignUnderTest, finger_hull, flat_pad, grasp_case
from .decimate import decimate
from .html import VERDICT_BEGIN, VERDICT_END, insert_verdict
from .read import read_design_folder
from .render import FINGER_COLOUR, PAD_COLOUR, PART_COLOUR, Layer, Panel, View, draw_layers, png_bytes

#: Markers around the section, so verifying again replaces it.
BEGIN, END = "<!-- fcso verify -->", "<!-- /fcso verify -->"
FCSO_COLOUR, FLAT_COLOUR = "#e8731a", "#4a6fa5"


def _figure(width_px: int, height_px: int) -> Figure:
    figure = Figure(figsize=(width_px / 100, height_px / 100), dpi=100, facecolor="white")
    FigureCanvasAgg(figure)
    return figure


def trial_picture(
    part: trimesh.Trimesh,
    pads: dict[str, trimesh.Trimesh],
    scenario: ScenarioVerification,
    pad_gap_mm: float,
    pad_size_mm,
) -> bytes:
    """The first perturbed trial at its start and after the lift, designed pads and flat ones (PNG).

    Parameters
    ----------
    part : trimesh.Trimesh
        The part in its resting frame, mm.
    pads : dict
        ``fcso`` and ``flat`` pad meshes in the pad frame, mm.
    scenario : ScenarioVerification
    pad_gap_mm : float
    pad_size_mm : (T, L, W)
    """
    vertices, faces = decimate(np.asarray(part.vertices), np.asarray(part.faces))
    figure = _figure(1300, 380)
    results = [(scenario.fcso, "designed pads"), (scenario.flat, "flat pads")]
    panels = [(r, name, moment) for r, name in results for moment in ("start", "end")]
    width = 1.0 / len(panels)
    for k, (result, name, moment) in enumerate(panels):
        snapshot = result.trial_start if moment == "start" else result.trial_end
        if snapshot is None:
            continue
        axes = Panel(figure, (k * width + 0.005, 0.02, width - 0.01, 0.80))
        layers = [Layer(transform_points(np.asarray(snapshot.part_pose), vertices), faces, PART_COLOUR)]
        pad = pads[result.kind]
        for side in (1, -1):
            placed = transform_points(pad_in_world(snapshot, side, pad_gap_mm, pad_size_mm), np.asarray(pad.vertices))
            layers.append(
                Layer(placed, np.asarray(pad.faces), PAD_COLOUR if result.kind == "fcso" else FINGER_COLOUR, alpha=0.55)
            )
        draw_layers(axes, layers, View((0.25, -0.35, 1.0), (0.0, 1.0, 0.0)))
        trial = result.trials[0]
        caption = f"{name.split()[0]}, {moment}" + (
            f": dx {trial.dx_mm:+.2f} mm, dy {trial.dy_mm:+.2f} mm, yaw {trial.yaw_deg:+.2f}°"
            if moment == "start"
            else f": error {trial.error_mm:.3f} mm, {trial.error_deg:.2f}°"
        )
        figure.text(k * width + width / 2.0, 0.86, caption, ha="center", fontsize=7)
    figure.suptitle(f"{scenario.part}, pose {scenario.pose_index}: first perturbed trial, seen from above", fontsize=10)
    return png_bytes(figure)


def error_picture(scenario: ScenarioVerification, success_mm: float, success_deg: float) -> bytes:
    """Final position and rotation errors of every trial, designed pads against flat ones (PNG)."""
    figure = _figure(1100, 300)
    for k, (field, limit, unit) in enumerate((("error_mm", success_mm, "mm"), ("error_deg", success_deg, "degrees"))):
        axes = figure.add_axes((0.08 + k * 0.48, 0.2, 0.40, 0.65))
        for row, (result, colour, label) in enumerate(
            ((scenario.fcso, FCSO_COLOUR, "designed"), (scenario.flat, FLAT_COLOUR, "flat"))
        ):
            values = np.array([getattr(t, field) for t in result.trials])
            jitter = np.linspace(-0.15, 0.15, len(values)) if len(values) > 1 else np.zeros(len(values))
            axes.scatter(np.maximum(values, 1e-4), row + jitter, color=colour, s=22, label=label)
        axes.axvline(limit, color="#c00", linestyle="--", linewidth=1)
        axes.set_xscale("log")
        axes.set_yticks([0, 1], ["designed", "flat"])
        axes.set_ylim(-0.6, 1.6)
        axes.set_xlabel(f"final error, {unit} (log; dashed: success limit {limit:g})", fontsize=8)
        axes.tick_params(labelsize=8)
    figure.suptitle(f"{scenario.part}, pose {scenario.pose_index}: precision trials", fontsize=10)
    return png_bytes(figure)


def holding_picture(scenario: ScenarioVerification, hold_force_n: float) -> bytes:
    """Slip force in six push directions, designed pads against flat ones (PNG); hatched bars held at the limit."""
    figure = _figure(800, 300)
    axes = figure.add_axes((0.08, 0.15, 0.9, 0.7))
    directions = list(scenario.fcso.holding_n)
    positions = np.arange(len(directions))
    for offset, (result, colour, label) in (
        (-0.2, (scenario.fcso, FCSO_COLOUR, "designed")),
        (0.2, (scenario.flat, FLAT_COLOUR, "flat")),
    ):
        values = [hold_force_n if result.holding_n[d] is None else result.holding_n[d] for d in directions]
        held = [result.holding_n[d] is None for d in directions]
        bars = axes.bar(positions + offset, values, width=0.4, color=colour, label=label)
        for bar, is_held in zip(bars, held):
            if is_held:
                bar.set_hatch("//")
    axes.axhline(hold_force_n, color="#c00", linestyle="--", linewidth=1)
    axes.set_xticks(positions, [f"{d} (gripper)" for d in directions])
    axes.set_ylabel("slip force, N", fontsize=8)
    axes.legend(fontsize=8, loc="lower right")
    axes.tick_params(labelsize=8)
    figure.suptitle(
        f"{scenario.part}, pose {scenario.pose_index}: holding test (hatched: held at {hold_force_n:g} N)", fontsize=10
    )
    return png_bytes(figure)


def _image(png: bytes, alt: str) -> str:
    return (
        f'<img data-kind="verification" alt="{html.escape(alt)}" '
        f'src="data:image/png;base64,{base64.b64encode(png).decode("ascii")}">'
    )


def _holding_text(value: float | None) -> str:
    return "held" if value is None else f"{value:.1f}"


def verdict_html(verification: VerificationReport) -> str:
    """The verdict that opens the page (METHOD §12b), between :data:`VERDICT_BEGIN` and :data:`VERDICT_END`: verified
    or not, then per scenario the designed finger's successful trials against flat fingers' and the weakest hold."""
    settings = verification.settings
    state = "passed" if verification.passed else "failed"
    flags = []
    if not verification.passed:
        flags.append("better than flat pads" if better_than_flat(verification) else "not better than flat pads")
    if missed := not_held(verification):
        flags.append("does NOT hold its part in " + ", ".join(missed))
    rows = []
    for s in verification.scenarios:
        planned = max(settings.trials, len(s.fcso.trials))
        weakest = weakest_hold_n(s.fcso, settings.hold_force_n)
        hold = (
            "not tested"
            if weakest is None
            else f"{weakest:g} N" + (" (held)" if weakest >= settings.hold_force_n else "")
        )
        rows.append(
            f'<tr><td class="text">{html.escape(s.part)} pose {s.pose_index}</td>'
            f"<td>designed {successes(s.fcso.trials)}/{planned}</td><td>flat {successes(s.flat.trials)}/{planned}</td>"
            f'<td>{hold}</td><td class="text">{"passed" if s.passed else "did not pass"}</td></tr>'
        )
    rows += [
        f'<tr><td class="text">{html.escape(name)}</td><td class="text" colspan="4">not simulated</td></tr>'
        for name in verification.unverified_scenarios
    ]
    return (
        f'{VERDICT_BEGIN}<div class="verdict {state}" title="{html.escape(verdict_text(verification))}">'
        f"<b>{'Verified' if verification.passed else 'Not verified'} in simulation</b>"
        + (f" ({html.escape('; '.join(flags))})" if flags else "")
        + f": {settings.trials} trials per scenario against flat fingers, holding up to {settings.hold_force_n:g} N "
        '(<a href="#verification">details below</a>)'
        '<table><tr><th class="text">scenario</th><th>designed finger</th><th>flat fingers</th>'
        '<th>weakest hold</th><th class="text">verdict</th></tr>' + "".join(rows) + f"</table></div>{VERDICT_END}"
    )


def section_html(verification: VerificationReport, pictures: dict[str, bytes], extra: str = "") -> str:
    """The verdict (:func:`verdict_html`) then the ``Verification in simulation`` section, between :data:`BEGIN` and
    :data:`END` (:func:`insert_section` puts the verdict first on the page).

    Parameters
    ----------
    verification : VerificationReport
    pictures : dict
        ``trial k``, ``errors k``, ``holding k`` PNGs per scenario k.
    extra : str
        HTML appended inside the section (e.g. the ranking of --verify-top).
    """
    settings = verification.settings
    verdict = "passed" if verification.passed else "did not pass"
    lines = [
        verdict_html(verification),
        BEGIN,
        '<h2 id="verification">Verification in simulation (METHOD §12)</h2>',
        f"<p><b>{html.escape(verdict_text(verification))}</b></p>",
        f"<p>MuJoCo {html.escape(verification.mujoco_version)}: {settings.trials} trials per scenario with the part "
        f"placed "
        f"±{settings.position_error_mm:g} mm and ±{settings.yaw_error_deg:g}° off, closing at "
        f"{settings.closing_speed_mm_s:g} mm/s "
        f"with {settings.force_limit_n:g} N per finger, friction {settings.friction:g}, lift {settings.lift_mm:g} mm. "
        f"A trial succeeds within {settings.success_mm:g} mm and {settings.success_deg:g}° of the unperturbed grasp's "
        f"seat. "
        f"The design <b>{verdict}</b> (a scenario passes at {settings.pass_success_rate:.0%} success). "
        f"{html.escape(reused_note(verification))}</p>",
        '<table><tr><th class="text">scenario</th><th>designed: success</th><th>median / worst mm</th><th>median / '
        "worst °</th>"
        "<th>flat: success</th><th>median / worst mm</th><th>median / worst °</th>"
        "<th>pieces part / pad</th><th>volume error part / pad</th>"
        "<th>seated overlap part / pad, pad / pad mm</th></tr>",
    ]
    for s in verification.scenarios:
        cells = [f'<td class="text">{html.escape(s.part)} pose {s.pose_index}</td>']
        for r in (s.fcso, s.flat):
            cells += [
                f"<td>{_success_text(r.trials, s.stopped_after_trials, settings.trials)}</td>",
                f"<td>{_number(r.median_error_mm)} / {_number(r.worst_error_mm)}</td>",
                f"<td>{_number(r.median_error_deg)} / {_number(r.worst_error_deg)}</td>",
            ]
        f = s.fidelity
        cells += [
            f"<td>{f.part_pieces} / {f.pad_pieces}</td>",
            f"<td>{_number(f.part_volume_error, '+.2%')} / {_number(f.pad_volume_error, '+.2%')}</td>",
            f"<td>{f.seated_penetration_mm:.3f} / {f.seated_pads_overlap_mm:.3f}</td>",
        ]
        lines.append("<tr>" + "".join(cells) + "</tr>")
    lines += [
        f'<tr><td class="text">{html.escape(name)}</td><td class="text" colspan="9">not verified: an earlier '
        "scenario had failed, so the design cannot pass</td></tr>"
        for name in verification.unverified_scenarios
    ]
    lines.append("</table>")
    for k, s in enumerate(verification.scenarios):
        title = f"{s.part}, pose {s.pose_index}"
        rows = "".join(
            f'<tr><td class="text">{name}</td>'
            + "".join(f"<td>{_holding_text(r.holding_n[d])}</td>" for d in r.holding_n)
            + "</tr>"
            for name, r in (("designed", s.fcso), ("flat", s.flat))
        )
        holding = (
            [
                _image(pictures[f"holding {k}"], f"holding of {title}"),
                '<table><tr><th class="text">slip force, N</th>'
                + "".join(f"<th>{d}</th>" for d in s.fcso.holding_n)
                + "</tr>"
                + rows
                + "</table>",
            ]
            if s.fcso.holding_n
            else ["<p>Holding test not run: the precision trials had already failed.</p>"]
        )
        lines += [
            f"<h3>{html.escape(title)}</h3>",
            _image(pictures[f"trial {k}"], f"trial of {title}"),
            _image(pictures[f"errors {k}"], f"errors of {title}"),
            *holding,
        ]
    if verification.warnings:
        lines.append("<ul>" + "".join(f"<li>{html.escape(w)}</li>" for w in verification.warnings) + "</ul>")
    lines += [extra, END]
    return "\n".join(lines)


def _success_text(trials: list, stopped_after: int | None, planned: int) -> str:
    """Success rate, or for trials stopped early the count of those run ("not run": the flat control of a designed
    finger stopped early)."""
    if stopped_after is not None and not trials:
        return "not run"
    if stopped_after is None:
        return f"{successes(trials) / len(trials):.0%}" if trials else "-"
    return f"{successes(trials)} of {len(trials)} (stopped; {planned} planned)"


def _number(value: float | None, spec: str = ".3f") -> str:
    """``value`` formatted by ``spec``; "-" for None (not measured)."""
    return "-" if value is None else f"{value:{spec}}"


def insert_section(page: str, section: str) -> str:
    """``page`` with the verification section replaced, or added before ``</body>``; the section's verdict block first
    on the page (:func:`fcso.output.html.insert_verdict`)."""
    if VERDICT_BEGIN in section:
        before, _, rest = section.partition(VERDICT_BEGIN)
        verdict, _, after = rest.partition(VERDICT_END)
        page, section = insert_verdict(page, VERDICT_BEGIN + verdict + VERDICT_END), before + after
    if BEGIN in page and END in page:
        head, _, rest = page.partition(BEGIN)
        _, _, tail = rest.partition(END)
        return head + section + tail
    head, marker, tail = page.rpartition("</body>")
    return head + section + "\n" + marker + tail if marker else page + section


def write_section(report_html: Path, section: str) -> None:
    """Insert the section into ``report.html`` (written under a temporary name, then renamed)."""
    page = (
        report_html.read_text(encoding="utf-8")
        if report_html.is_file()
        else "<!DOCTYPE html>\n<html><body>\n</body></html>\n"
    )
    write_atomic(report_html, insert_section(page, section).encode("utf-8"))


def verification_pictures(verification: VerificationReport, design: DesignUnderTest) -> dict[str, bytes]:
    """The section's pictures: per scenario k, ``trial k``, ``errors k`` and ``holding k`` (PNG)."""
    settings = verification.settings
    images = {}
    for k, (scenario, case) in enumerate(zip(verification.scenarios, design.cases)):
        pads = {"fcso": design.fingerpad, "flat": flat_pad(case.pad_size_mm, case.penetration_mm)}
        images[f"trial {k}"] = trial_picture(case.part, pads, scenario, case.pad_gap_mm, case.pad_size_mm)
        images[f"errors {k}"] = error_picture(scenario, settings.success_mm, settings.success_deg)
        if scenario.fcso.holding_n:
            images[f"holding {k}"] = holding_picture(scenario, settings.hold_force_n)
    return images


def write_verification(
    directory: str | Path,
    verification: VerificationReport,
    design: DesignUnderTest,
    extra_html: str = "",
    page_name: str = REPORT_HTML,
) -> list[Path]:
    """Write ``verification.json`` and the verification section of ``report.html`` (or of the page ``page_name``,
    made when missing) into a design's folder.

    Returns
    -------
    list of Path
        The files written.
    """
    directory = Path(directory)
    target = write_atomic(
        directory / VERIFICATION_JSON, (verification.model_dump_json(indent=2) + "\n").encode("utf-8")
    )
    page = directory / page_name
    write_section(page, section_html(verification, verification_pictures(verification, design), extra_html))
    return [target, page]


def read_verification(directory: str | Path) -> VerificationReport | None:
    """``verification.json`` of a design's folder, or None when there is none."""
    path = Path(directory) / VERIFICATION_JSON
    if not path.is_file():
        return None
    return VerificationReport.model_validate_json(path.read_text(encoding="utf-8"))


CHOSEN = ' class="chosen"'


def ranking_html(ranking: list[RankedCandidate], choice: str | None = None) -> str:
    """The verified candidates in the measure's order, which was delivered and why (``choice``), as an HTML fragment."""
    if not ranking:
        return ""
    rows = "".join(
        f"<tr{CHOSEN if r.chosen else ''}><td>{r.rank_by_quality}</td><td>{r.index}</td><td>{r.quality:.1f}</td>"
        f"<td>{' / '.join(f'{x:.0%}' for x in r.success_rates)}</td>"
        f"<td>{' / '.join('-' if x is None else f'{x:.0%}' for x in r.flat_success_rates)}</td>"
        f"<td>{' / '.join(str(n) for n in r.trials_run)}</td>"
        f"<td>{'yes' if r.passed else 'no'}</td><td>{'&#9733;' if r.chosen else ''}</td></tr>"
        for r in ranking
    )
    delivered = f"<p>Delivered: {html.escape(choice)}.</p>" if choice else ""
    return (
        "<h3>Choice by verification (--verify-top)</h3>"
        "<p>The best candidates by the design's measure, verified in that order until one passed every scenario "
        "(within top K and the time budget); the first that passed is delivered, or, when none did, the best of those "
        "tried by its worst scenario's successful trials. A candidate's trials stop as soon as it can no longer pass, "
        "and scenarios after a failed one are not verified.</p>"
        + delivered
        + "<table><tr><th>rank by measure</th><th>candidate</th><th>measure</th><th>designed success per scenario</th>"
        "<th>flat success</th><th>trials run</th><th>passed</th><th>delivered</th></tr>" + rows + "</table>"
    )


def load_design(directory: str | Path) -> tuple[DesignReport, DesignUnderTest]:
    """Read a design's output folder (``report.json``, ``finger.stl``, ``fingerpad.stl`` and the part files it names).

    Raises
    ------
    MeshError
        A file is missing or unreadable (named in the message).
    """
    folder = read_design_folder(directory)
    report = folder.report
    parts = {entry.name: part.mesh for entry, part in zip(report.parts, folder.parts)}
    cases = [grasp_case(report, g, parts[g.part]) for g in report.grasps]
    return report, DesignUnderTest(cases, folder.fingerpad, finger_hull(report, folder.finger))
