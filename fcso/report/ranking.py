"""A design report's candidates in the order the design chose them."""

from __future__ import annotations

from .models import CandidateReport, DesignReport


def chosen_candidate(report: DesignReport) -> CandidateReport:
    """The candidate the design chose."""
    return next(c for c in report.candidates if c.index == report.best)


def ranked_candidates(report: DesignReport, limit: int | None = None) -> list[CandidateReport]:
    """Candidates best first, at most ``limit``: the exactly evaluated ones, then the screened ones,
    each by larger Q, then larger mean E, then smaller index."""
    rows = sorted(
        report.candidates, key=lambda c: (c.evaluation != "exact", -c.quality, -c.mean_effective_area, c.index)
    )
    return rows if limit is None else rows[:limit]
