"""What a job's finger sets design returns (:func:`fcso.sets.design_sets`), and the job after the choice by truth
delivered another finger for one of its sets."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from ..pipeline import DesignResult
from ..pipeline.sets_report import delivered_set_report
from ..report.models import DesignReport, FingerSetsReport, JobReport


@dataclass
class SetsResult:
    """What :func:`design_sets` returns.

    Attributes
    ----------
    designs : list of DesignResult
        One finger design per set, set order.
    report : FingerSetsReport or None
        The sets and the pick plan; None with ``[finger_sets] max = 1``.
    job_report : JobReport or None
        The job's ``report.json`` with two or more sets; with one, the
        design's own report (``designs[0].report``, whose ``finger_sets`` is ``report``).
    size_reports : dict
        Pad length and width in mm -> the sets' report of each pad size designed in full, the delivered one's
        included: what a set delivered on another size (:meth:`delivered`) keeps of its solo quality there.
    """

    designs: list[DesignResult]
    report: FingerSetsReport | None
    job_report: JobReport | None
    size_reports: dict[tuple[float, float], FingerSetsReport] = dataclasses.field(default_factory=dict)

    @property
    def several(self) -> bool:
        """Whether two or more finger sets serve the job: its outputs then go into ``set-<k>`` folders."""
        return self.job_report is not None

    def job(self) -> DesignReport | JobReport:
        """The job's ``report.json``: the job report with several sets, the one design's report with one."""
        return self.job_report if self.several else self.designs[0].report

    def delivered(self, number: int, design: DesignResult, why: str) -> SetsResult:
        """The job with set ``number`` (1 = first) delivered as ``design``, another candidate or pad size of it chosen
        by truth for ``why`` (:func:`fcso.sim.choose.verify_top`): the sets' report and pick plan follow its finger
        (:func:`fcso.pipeline.sets_report.delivered_set_report`)."""
        designs = [design if k == number else d for k, d in enumerate(self.designs, start=1)]
        if self.report is None:
            return dataclasses.replace(self, designs=designs)
        size = design.report.settings.sampler.length_mm, design.report.settings.sampler.width_mm
        solo = self.size_reports[size].scenarios if size in self.size_reports else None
        report = delivered_set_report(self.report, number, design, why, solo)
        if self.several:
            job_report = self.job_report.model_copy(update={"finger_sets": report})
            return dataclasses.replace(self, designs=designs, report=report, job_report=job_report)
        designs[0] = dataclasses.replace(design, report=design.report.model_copy(update={"finger_sets": report}))
        return dataclasses.replace(self, designs=designs, report=report)
