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
