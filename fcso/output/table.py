"""Quality tables (the paper's Table I layout): shared columns, and the plain-text table."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from ..measure import quality_decimals, quality_title, quality_words
from ..report.models import CandidateReport, DesignReport
from ..report.ranking import chosen_candidate, ranked_candidates

#: Column groups of the quality table: title, ScenarioQuality field, decimals.
SCENARIO_GROUPS = (("RLES", "rles", 4), ("A mm2", "contact_area_mm2", 1), ("E", "effective_area", 1))


@dataclass(frozen=True)
class QualityColumn:
    """One numeric column of the quality table.

    Attributes
    ----------
    group : str
        ``"RLES"``, ``"A mm2"``, ``"E"`` or ``"Q"``.
    scenario : str or None
        Label of the grasp scenario (part/pose); None for Q.
    decimals : int
        Digits after the decimal point.
    value : callable
        ``value(candidate) -> float``.
    """

    group: str
    scenario: str | None
    decimals: int
    value: Callable[[CandidateReport], float]

    @property
    def title(self) -> str:
        return self.group if self.scenario is None else f"{self.group} {self.scenario}"


def scenario_labels(report: DesignReport) -> list[str]:
    """Short ``part/p<pose>`` label of each grasp scenario."""
    return [
        f"{s.part if len(s.part) <= 10 else s.part[:6] + '~' + s.part[-3:]}/p{s.pose_index}" for s in report.scenarios
    ]


def quality_columns(report: DesignReport) -> list[QualityColumn]:
    """RLES, A and E per scenario (grouped by quantity), then Q."""
    labels = scenario_labels(report)
    columns = [
        QualityColumn(group, label, decimals, lambda c, m=m, name=name: getattr(c.per_scenario[m], name))
        for group, name, decimals in SCENARIO_GROUPS
        for m, label in enumerate(labels)
    ]
    columns.append(
        QualityColumn(
            quality_title(report.settings.quality.measure),
            None,
            quality_decimals(report.settings.quality.measure),
            lambda c: c.quality,
        )
    )
    return columns


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
    columns = quality_columns(report)
    rows = report.candidates if limit is None else ranked_candidates(report, limit)
    width = max(12, *(len(label) + 1 for label in scenario_labels(report)))
    widths = [10 if column.scenario is None else width + 6 for column in columns]
    header = ["    i", "eval"] + [f"{column.title:>{w}}" for column, w in zip(columns, widths)]
    lines = [" ".join(header)]
    for row in rows:
        mark = "*" if row.index == report.best else " "
        cells = [f"{mark}{row.index:>4}", f"{row.evaluation[:5]:>4}"]
        cells += [f"{column.value(row):>{w}.{column.decimals}f}" for column, w in zip(columns, widths)]
        lines.append(" ".join(cells))
    lines.append(
        f"{len(rows)} of {len(report.candidates)} listed candidates shown ({report.search.kind}: "
        f"{report.search.screened} screened "
        f"of C = {report.search.candidates_total}, the best {report.search.exact} re-evaluated exactly); * = chosen, "
        f"{quality_words(chosen_candidate(report).quality, report.settings.quality.measure)}, {_gap(report)}"
    )
    return "\n".join(lines)


def _gap(report: DesignReport) -> str:
    """The chosen Q against the search's upper bound, in words."""
    if report.search.quality_upper_bound is None:
        return "no upper bound"
    bound = quality_words(report.search.quality_upper_bound, report.settings.quality.measure)
    return f"upper bound {bound} (the chosen is {report.search.gap:.0%} of it)"
