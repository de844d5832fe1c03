"""The reports of fcso: their pydantic models (:mod:`~fcso.report.models`, ``report.json``).

They are assembled by the pipeline (:mod:`fcso.pipeline.report`, :mod:`fcso.pipeline.sets_report`); this package
holds the models only, so reading a report loads no method code.
"""

from .models import (
    CandidateReport,
    DesignReport,
    FingerReport,
    FingerSetReport,
    FingerSetsReport,
    GraspReport,
    IdenticalPartsReport,
    JobReport,
    NotServedPart,
    PairConflictReport,
    PartitionAttemptReport,
    PartitionSearchReport,
    PartReport,
    PickPart,
    PickStep,
    PrintFitEffect,
    PrintFitReport,
    ReportModel,
    SampleReport,
    ScenarioQuality,
    ScenarioReport,
    SearchReport,
    SetScenarioReport,
    UngraspableReport,
)
from .ranking import chosen_candidate, ranked_candidates

__all__ = [
    "CandidateReport",
    "DesignReport",
    "FingerReport",
    "FingerSetReport",
    "FingerSetsReport",
    "GraspReport",
    "IdenticalPartsReport",
    "JobReport",
    "PairConflictReport",
    "PartitionAttemptReport",
    "PartitionSearchReport",
    "PartReport",
    "NotServedPart",
    "PickPart",
    "PickStep",
    "PrintFitEffect",
    "PrintFitReport",
    "ReportModel",
    "SampleReport",
    "ScenarioQuality",
    "ScenarioReport",
    "SearchReport",
    "SetScenarioReport",
    "UngraspableReport",
    "chosen_candidate",
    "ranked_candidates",
]
