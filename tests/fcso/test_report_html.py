"""report.html: pictures that decode and are not blank, the quality table, ``fcso report``, progress."""

from __future__ import annotations

import base64
import io
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from fcso import design, load_config, load_part, write_outputs
from fcso.cli import ProgressLine, main
from fcso.output.design_page import load_report_inputs
from fcso.output.render import CONTACT_COLOUR, PICTURE_SIZES
from fcso.report import DesignReport, ranked_candidates
from tests.conftest import HANG_GUARD_S

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data"

# Two parts in one pose each: small pads and a coarse stride keep it to a few dozen candidates.
TWO_PART_TOML = """
[sampler]
length_mm = 10.0
width_mm = 10.0
thickness_mm = 4.0
penetration_mm = 3.0
stride_mm = 8.0

[poses]
count = 1
select = [0]

# one finger for both parts: the page of one design with two scenarios
[finger_sets]
max = 1
"""


@pytest.fixture(scope="module")
def bunny_dir(tmp_path_factory) -> Path:
    """The paper's bunny experiment (two poses) with a coarser stride (8 mm instead of 4 mm)."""
    config = load_config(ROOT / "examples" / "paper.toml").updated({"sampler": {"stride_mm": 8.0}})
    result = design([load_part(ROOT / "examples" / "parts" / "stanford_bunny_closed.ply", scale_to_mm=65.0)], config)
    out = tmp_path_factory.mktemp("bunny")
    write_outputs(result, out)
    return out


@pytest.fixture(scope="module")
def two_part_run(tmp_path_factory):
    """``fcso design`` on a cube and the solar tracker, run through the command line."""
    folder = tmp_path_factory.mktemp("two_parts")
    config = folder / "fast.toml"
    config.write_text(TWO_PART_TOML, encoding="utf-8")
    out = folder / "out"
    capture = pytest.MonkeyPatch()
    stdout, stderr = io.StringIO(), io.StringIO()
    capture.setattr("sys.stdout", stdout)
    capture.setattr("sys.stderr", stderr)
    try:
        parts = [str(DATA / "20mm-xyz-cube.stl"), str(DATA / "solar_tracker.stl")]
        code = main(["design", *parts, "--config", str(config), "--out", str(out)])
    finally:
        capture.undo()
    return code, out, stdout.getvalue(), stderr.getvalue()


class _Page(HTMLParser):
    """Images (kind, src) and tables (id -> rows of (class, cell texts)) of a page."""

    def __init__(self):
        super().__init__()
        self.images: list[tuple[str, str]] = []
        self.tables: dict[str, list[tuple[str, list[str]]]] = {}
        self._table = None
        self._cell: list[str] | None = None

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "img":
            self.images.append((attrs.get("data-kind", ""), attrs.get("src", "")))
        elif tag == "table":
            self._table = self.tables.setdefault(attrs.get("id") or f"table {len(self.tables)}", [])
        elif tag == "tr" and self._table is not None:
            self._table.append((attrs.get("class") or "", []))
        elif tag in ("td", "th") and self._table is not None:
            self._cell = []

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self._table[-1][1].append("".join(self._cell).strip())
            self._cell = None
        elif tag == "table":
            self._table = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)


def _page(out: Path) -> _Page:
    page = _Page()
    page.feed((out / "report.html").read_text(encoding="utf-8"))
    return page


def _report(out: Path) -> DesignReport:
    return DesignReport.model_validate_json((out / "report.json").read_text(encoding="utf-8"))


def _decode(src: str) -> Image.Image:
    prefix = "data:image/png;base64,"
    assert src.startswith(prefix), src[:40]
    image = Image.open(io.BytesIO(base64.b64decode(src[len(prefix) :])))
    image.load()
    return image


def _check_pictures(out: Path) -> dict[str, list[np.ndarray]]:
    """Every embedded picture is a PNG of its kind's size with visible content."""
    report = _report(out)
    page = _page(out)
    kinds = [kind for kind, _ in page.images]
    scenarios = len(report.scenarios)
    # a capture landscape per scenario under the capture measure (METHOD §7b), none under the paper's
    captures = sum(1 for s in report.scenarios if s.capture_landscape is not None)
    assert captures in (0, scenarios)
    expected = ["gripper", "finger", "fingerpad"] + ["grasp", "normals", "pose"] * scenarios + ["capture"] * captures
    assert sorted(kinds) == sorted(expected)
    pixels: dict[str, list[np.ndarray]] = {}
    for kind, src in page.images:
        image = _decode(src)
        assert image.format == "PNG"
        assert image.size == PICTURE_SIZES[kind], kind
        grey = np.asarray(image.convert("L"), dtype=float)
        assert grey.var() > 100.0, f"{kind} picture is nearly blank (variance {grey.var():.1f})"
        pixels.setdefault(kind, []).append(np.asarray(image.convert("RGB"), dtype=float) / 255.0)
    return pixels


def _check_quality_table(out: Path) -> None:
    """The sorted table holds every candidate once, best first, the chosen one (and only it) marked."""
    report = _report(out)
    tables = _page(out).tables
    body = tables["sorted"][2:]  # after the two header rows
    assert len(body) == len(report.candidates)
    marked = [cells for kind, cells in body if kind == "chosen"]
    assert len(marked) == 1 and marked[0][0] == f"\u2605 {report.best}"
    shown = [int(cells[0].split()[-1]) for _, cells in body]
    assert shown == [c.index for c in ranked_candidates(report)]
    assert shown[0] == report.best
    # Q is the last number of a row (the pad case follows it)
    best = next(c for c in report.candidates if c.index == report.best)
    assert float(marked[0][-2]) == pytest.approx(best.quality, abs=0.05)


def test_bunny_report_pictures_decode_and_are_not_blank(bunny_dir):
    pixels = _check_pictures(bunny_dir)
    # the contact patch is drawn in the contact colour on every grasp picture
    for grasp in pixels["grasp"]:
        near = np.linalg.norm(grasp - np.asarray(CONTACT_COLOUR), axis=2) < 0.25
        assert near.sum() > 200


def test_bunny_report_table_marks_chosen_and_has_table_i(bunny_dir):
    _check_quality_table(bunny_dir)
    report = _report(bunny_dir)
    assert len(report.scenarios) == 2
    table_i = _page(bunny_dir).tables["table-i"]
    assert table_i[0][1][:4] == ["i", "RLES", "contact area A (mm²)", "effective area E (mm²)"]
    assert [int(cells[0].split()[-1]) for _, cells in table_i[2:]] == [c.index for c in report.candidates]


def test_bunny_report_shows_sampler_rejections_and_poses(bunny_dir):
    report = _report(bunny_dir)
    text = (bunny_dir / "report.html").read_text(encoding="utf-8")
    assert "<h2>Grasp sampler</h2>" in text and "rejected: contact" in text
    for scenario in report.scenarios:
        assert f"{scenario.pose_probability:.4f}" in text
    # self-contained: nothing is fetched from elsewhere
    assert not re.search(r'(src|href)="(?!data:)', text)


def test_two_part_report_from_the_command_line(two_part_run):
    code, out, stdout, stderr = two_part_run
    assert code == 0
    assert len(_report(out).parts) == 2
    _check_pictures(out)
    _check_quality_table(out)
    assert "table-i" in _page(out).tables  # one pose per part: two scenarios
    # not a terminal: no progress, but the table and the list of files
    assert stderr == ""
    assert "report.html" in stdout and "* = chosen" in stdout


def test_the_page_names_each_measure_as_what_it_is(two_part_run):
    _, out, _, _ = two_part_run
    page = (out / "report.html").read_text()
    assert _report(out).settings.quality.measure == "capture"
    # the capture measure is not Q = min E; the pad's section and its printed wall are told apart
    assert "Q = min E" not in page and "quality: the capture measure" in page and "It is not min E" in page
    assert "thinnest pad section behind the pocket" in page
    # not verified: the page opens by saying so, before the 3D view
    assert page.index("Not verified in simulation") < page.index('id="fcso-3d"')


def test_fcso_report_rebuilds_the_page(bunny_dir, tmp_path, capsys):
    out = tmp_path / "copy"
    shutil.copytree(bunny_dir, out)
    (out / "report.html").unlink()
    assert main(["report", str(out), "--quiet"]) == 0
    assert capsys.readouterr().out == ""
    _check_pictures(out)
    _check_quality_table(out)
    assert _page(out).tables["sorted"] == _page(bunny_dir).tables["sorted"]


def test_rebuilt_contacts_match_the_report(bunny_dir):
    """Re-seating the chosen grasps against fingerpad.stl reproduces A, RLES and the seat offsets."""
    inputs = load_report_inputs(bunny_dir)
    report = inputs.report
    chosen = next(c for c in report.candidates if c.index == report.best)
    for grasp, quality in zip(inputs.grasps, chosen.per_scenario):
        area = sum(p.contact.sum() * p.samples.area_per_point_mm2 for p in grasp.placements)
        assert area == pytest.approx(quality.contact_area_mm2, rel=0.01)
        assert grasp.rles == pytest.approx(quality.rles, abs=0.01)
        assert [p.offset_mm for p in grasp.placements] == pytest.approx(quality.seat_offsets_mm, abs=0.01)


def test_fcso_report_names_a_missing_folder(tmp_path, capsys):
    assert main(["report", str(tmp_path / "nothing")]) == 2
    assert "report.json" in capsys.readouterr().err


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_line_shows_stages_and_candidates():
    stream = _Terminal()
    progress = ProgressLine(stream, enabled=True)
    for done in range(3):
        progress("sampling", done, 2)
    for done in range(1, 41):
        progress("candidates", done, 40)
    progress("pictures", 0, 5)
    progress.close()
    lines = stream.getvalue().split("\n")
    assert lines[0].split("\r")[-1].startswith("sampling") and "2/2" in lines[0]
    assert lines[1].split("\r")[-1].startswith("candidates") and "40/40" in lines[1]
    assert lines[2].split("\r")[-1].startswith("pictures")
    quiet = _Terminal()
    silent = ProgressLine(quiet, enabled=False)
    silent("candidates", 1, 2)
    silent.close()
    assert quiet.getvalue() == ""


def test_a_panel_draws_in_data_coordinates_inside_its_rectangle_only():
    from fcso.output.render import Panel, new_figure, png_bytes

    figure = new_figure("pose")  # 420 x 340 pixels
    panel = Panel(figure, (0.5, 0.0, 0.5, 1.0))
    panel.set_xlim(0.0, 1.0)
    panel.set_ylim(0.0, 1.0)
    panel.fill([-1.0, 2.0, 2.0, -1.0], [-1.0, -1.0, 2.0, 2.0], color=(1.0, 0.0, 0.0))
    panel.fill([0.0, 0.5, 0.5, 0.0], [0.0, 0.0, 0.5, 0.5], color=(0.0, 0.0, 1.0), zorder=2)
    pixels = np.asarray(Image.open(io.BytesIO(png_bytes(figure))).convert("RGB"))
    assert pixels.shape == (340, 420, 3)
    assert (pixels[:, :205] == 255).all()  # clipped to the right half
    assert tuple(pixels[50, 300]) == (255, 0, 0)
    # data (0.25, 0.25) is a quarter into the panel from its bottom-left corner
    assert tuple(pixels[340 - 85, 210 + 52]) == (0, 0, 255)


def chromium() -> str:
    """Debian's Chromium (``make test`` installs it); the test fails, not skips, without it."""
    found = shutil.which("chromium") or shutil.which("chromium-browser")
    assert found, "chromium is not installed: make test installs it (apt-get install chromium)"
    return found


def test_3d_view_renders_offline_in_headless_chromium(bunny_dir, tmp_path):
    """The page in a real browser with no network at all: the 3D view draws the part and the fingers, no errors."""
    page = bunny_dir / "report.html"
    assert page.stat().st_size < 3_000_000
    html = page.read_text(encoding="utf-8")
    # nothing is fetched: every script is inline, every mesh and picture a data: URI or embedded text
    assert not re.search(r"""(src|href)\s*=\s*["'](https?:)?//""", html)
    assert html.count("three.js authors") == 1, "the viewer library is bundled once"
    screenshot = tmp_path / "view.png"
    # a network namespace of its own (no interfaces but loopback, down) when the kernel lets us, and a proxy that
    # goes nowhere in any case
    isolate = ["unshare", "--net"] if subprocess.run(["unshare", "--net", "true"]).returncode == 0 else []
    run = subprocess.run(
        [
            *isolate,
            chromium(),
            "--headless=new",
            "--no-sandbox",
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",
            "--proxy-server=http://127.0.0.1:9",
            "--no-first-run",
            f"--user-data-dir={tmp_path / 'profile'}",
            "--enable-logging=stderr",
            "--v=0",
            "--window-size=1240,1000",
            "--virtual-time-budget=20000",
            f"--screenshot={screenshot}",
            page.as_uri(),
        ],
        capture_output=True,
        text=True,
        timeout=HANG_GUARD_S,
    )
    assert screenshot.is_file(), run.stderr[-3000:]
    # Chromium's own pages (chrome://, its omnibox popup) log to the console too: only the report's page counts
    console = [
        line
        for line in run.stderr.splitlines()
        if ("CONSOLE" in line and "source: chrome://" not in line) or "Uncaught" in line
    ]
    assert not console, "\n".join(console)
    pixels = np.asarray(Image.open(screenshot).convert("RGB")).astype(int)
    # the canvas is the only place with the view's background colour; inside it, the fingers' blue and the part's grey
    background = np.all(pixels == (0xF4, 0xF4, 0xF8), axis=2)
    rows, cols = np.nonzero(background)
    assert rows.size > 10_000, "no 3D canvas in the screenshot"
    canvas = pixels[rows.min() : rows.max() + 1, cols.min() : cols.max() + 1]
    drawn = ~np.all(canvas == (0xF4, 0xF4, 0xF8), axis=2)
    assert drawn.mean() > 0.03, "the canvas is blank"
    blue = (canvas[..., 2] > canvas[..., 0] + 30) & drawn
    assert blue.sum() > 500, "no finger drawn"


#: Appended to a copy of a page: once it has loaded, write where each text matching "designed k/n" or "flat k/n"
#: first appears (its box in CSS pixels from the page's top) into a <pre id="probe"> that --dump-dom prints.
FIRST_SCREEN_PROBE = """
<script>
window.addEventListener("load", () => {
  const found = {};
  const walker = document.createTreeWalker(document.body, NodeFilter.SHOW_TEXT);
  for (let node = walker.nextNode(); node; node = walker.nextNode()) {
    for (const match of node.data.matchAll(/(designed|flat) \\d+\\/\\d+/g)) {
      if (match[0] in found) continue;
      const range = document.createRange();
      range.setStart(node, match.index);
      range.setEnd(node, match.index + match[0].length);
      const box = range.getBoundingClientRect();
      if (box.height > 0) found[match[0]] = box.bottom + window.scrollY;
    }
  }
  const probe = document.createElement("pre");
  probe.id = "probe";
  probe.textContent = JSON.stringify(found);
  document.body.appendChild(probe);
});
</script>
"""


@pytest.fixture(scope="module")
def verified_dir(tmp_path_factory) -> Path:
    """``fcso design --verify-top 1`` on the ridged block, two trials per scenario."""
    from examples.sim_parts import ridged_block

    folder = tmp_path_factory.mktemp("verified")
    part = folder / "ridged.stl"
    ridged_block().export(part)
    config = folder / "design.toml"
    config.write_text(
        '[poses]\ncount = 1\nselect = "most_probable"\n\n[sampler]\nyaw_deg = [0]\nface_yaws = false\n\n'
        f'[verify]\ntrials = 2\ncache_dir = "{folder / "cache"}"\n'
    )
    out = folder / "out"
    code = main(["design", str(part), "--out", str(out), "--config", str(config), "--verify-top", "1", "--quiet"])
    assert code in (0, 3)
    return out


def test_the_first_screen_of_a_verified_report_is_its_verdict_in_headless_chromium(verified_dir, tmp_path):
    """What a quality engineer sees first, in a real browser at 1280 x 800: designed k/n against flat k/n, as in
    verification.json."""
    import json

    verification = json.loads((verified_dir / "verification.json").read_text())
    page = tmp_path / "report.html"
    page.write_text((verified_dir / "report.html").read_text().replace("</body>", FIRST_SCREEN_PROBE + "</body>"))
    run = subprocess.run(
        [
            chromium(),
            "--headless=new",
            "--no-sandbox",
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",
            "--proxy-server=http://127.0.0.1:9",
            "--no-first-run",
            f"--user-data-dir={tmp_path / 'profile'}",
            "--window-size=1280,800",
            "--virtual-time-budget=20000",
            "--dump-dom",
            page.as_uri(),
        ],
        capture_output=True,
        text=True,
        timeout=HANG_GUARD_S,
    )
    probe = re.search(r'<pre id="probe">(.*?)</pre>', run.stdout, re.S)
    assert probe, run.stderr[-3000:]
    found = json.loads(probe.group(1).replace("&quot;", '"'))
    scenario = verification["scenarios"][0]
    planned = verification["settings"]["trials"]
    designed = f"designed {sum(t['success'] for t in scenario['fcso']['trials'])}/{planned}"
    flat = f"flat {sum(t['success'] for t in scenario['flat']['trials'])}/{planned}"
    # both figures, as verification.json has them, within the first screen
    assert designed in found and flat in found, found
    assert found[designed] <= 800 and found[flat] <= 800, found
