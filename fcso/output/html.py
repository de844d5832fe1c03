"""Building blocks of the report pages: escaped text, embedded pictures, tables, the page itself."""

from __future__ import annotations

import base64
import html
import json


def closing_sections(warnings: list[str], settings_json: str, timings_s: dict) -> list[str]:
    """The warnings, settings and timings that end every report page (HTML fragments)."""
    return [
        "<h2>Warnings</h2>",
        "<ul>" + "".join(f"<li>{text(w)}</li>" for w in warnings) + "</ul>" if warnings else "<p>None.</p>",
        "<h2>Settings and timings</h2>",
        f"<details><summary>settings</summary><pre>{text(settings_json)}</pre></details>",
        f"<pre>{text(json.dumps(timings_s, indent=2))}</pre>",
    ]


def html_page(title: str, body: list[str]) -> str:
    """A whole report page: ``title`` (plain text) and the ``body`` fragments, with the reports' style."""
    return (
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        f"<title>{text(title)}</title>\n<style>{STYLE}</style>\n</head>\n"
        "<body>\n" + "\n".join(body) + "\n</body>\n</html>\n"
    )


#: Markers around the verdict that opens a design's page (METHOD §12b), so a verification replaces it.
VERDICT_BEGIN, VERDICT_END = "<!-- fcso verdict -->", "<!-- /fcso verdict -->"


def unverified_verdict() -> str:
    """The verdict block of a design not verified in simulation (``fcso verify`` replaces it)."""
    return (
        f'{VERDICT_BEGIN}<div class="verdict unverified"><b>Not verified in simulation.</b> '
        "<code>fcso verify DIR</code> (or <code>fcso design --verify</code>) tests the finger against flat fingers: "
        "designed k/10, flat k/10, the weakest hold.</div>"
        f"{VERDICT_END}"
    )


def insert_verdict(page: str, verdict: str) -> str:
    """``page`` with its verdict block replaced by ``verdict``, or ``verdict`` put first: after the page's heading, or
    at the start of its body."""
    if VERDICT_BEGIN in page and VERDICT_END in page:
        head, _, rest = page.partition(VERDICT_BEGIN)
        return head + verdict + rest.partition(VERDICT_END)[2]
    for anchor in ("</h1>", "<body>"):
        head, marker, tail = page.partition(anchor)
        if marker:
            return head + marker + "\n" + verdict + tail
    return verdict + page


#: The report pages' style sheet.
STYLE = """
body { font-family: sans-serif; max-width: 1240px; margin: 1em auto; color: #222; }
img { display: block; max-width: 100%; margin: 0.5em 0; }
.poses { display: flex; flex-wrap: wrap; gap: 0.5em; }
table { border-collapse: collapse; margin: 0.5em 0; font-size: 0.85em; }
th, td { border: 1px solid #bbb; padding: 2px 6px; text-align: right; }
th { background: #eef; }
td.text, th.text { text-align: left; }
tr.chosen td { background: #ffe4a8; font-weight: bold; }
#fcso-3d canvas { display: block; max-width: 100%; border: 1px solid #bbb; margin: 0.5em 0; cursor: grab; }
#fcso-3d .controls { font-size: 0.9em; }
pre { background: #f6f6f6; padding: 0.5em; overflow-x: auto; font-size: 0.8em; }
.verdict { border: 2px solid #bbb; padding: 0.4em 0.8em; margin: 0.5em 0; }
.verdict.passed { border-color: #2a8a3a; background: #eef8ef; }
.verdict.failed { border-color: #c0392b; background: #fbeeee; }
.verdict table { font-size: 1em; }
"""


def text(value) -> str:
    """``value`` as HTML text (escaped)."""
    return html.escape(str(value))


def image(png: bytes, kind: str, alt: str) -> str:
    """An ``<img>`` with ``png`` embedded (base64); ``kind`` goes to its ``data-kind``, ``alt`` is plain text."""
    data = base64.b64encode(png).decode("ascii")
    return f'<img data-kind="{kind}" alt="{text(alt)}" src="data:image/png;base64,{data}">'


def key_value_table(rows) -> str:
    """A two-column table of ``(key, value)`` rows, both plain text."""
    cells = (f'<tr><th class="text">{text(key)}</th><td class="text">{text(value)}</td></tr>' for key, value in rows)
    return "<table>" + "".join(cells) + "</table>"
