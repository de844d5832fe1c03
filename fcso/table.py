"""Plain-text quality tables (the paper's Table I layout)."""

from __future__ import annotations

from .report import DesignReport


def quality_table(report: DesignReport, limit: int | None = 20) -> str:
    """The candidates' RLES, contact area A and effective area E per scenario, and Q.

    Parameters
    ----------
    report : DesignReport
    limit : int or None
        Show at most this many candidates, best Q first; None: all, in index order
        (with two scenarios that is the paper's Table I).

    Returns
    -------
    str
        A fixed-width table; the chosen candidate is marked with ``*``.
    """
    labels = [f"{s.part[:10]}/p{s.pose_index}" for s in report.scenarios]
    rows = report.candidates
    if limit is not None:
        rows = sorted(rows, key=lambda c: (-c.quality, -c.mean_effective_area, c.index))[:limit]
    width = max(12, *(len(label) + 1 for label in labels))
    header = ["    i"]
    for name in ("RLES", "A mm2", "E"):
        header += [f"{name + ' ' + label:>{width + 6}}" for label in labels]
    header.append(f"{'Q':>10}")
    lines = [" ".join(header)]
    for row in rows:
        mark = "*" if row.index == report.best else " "
        cells = [f"{mark}{row.index:>4}"]
        cells += [f"{q.rles:>{width + 6}.4f}" for q in row.per_scenario]
        cells += [f"{q.contact_area_mm2:>{width + 6}.1f}" for q in row.per_scenario]
        cells += [f"{q.effective_area:>{width + 6}.1f}" for q in row.per_scenario]
        cells.append(f"{row.quality:>10.1f}")
        lines.append(" ".join(cells))
    shown = len(rows)
    total = len(report.candidates)
    lines.append(
        f"{shown} of {total} evaluated candidates shown ({report.search.kind}, C = {report.search.candidates_total}); "
        f"* = chosen, Q = {next(c.quality for c in report.candidates if c.index == report.best):.1f}"
    )
    return "\n".join(lines)
