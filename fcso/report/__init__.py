"""The reports of fcso: their pydantic models (:mod:`~fcso.report.models`, ``report.json``)
and their assembly from a design's results (:mod:`~fcso.report.design`) and a job's
finger sets (:mod:`~fcso.report.sets`).

This ``__init__`` gives the models only, so reading a report loads no method code.
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
    chosen_candidate,
    ranked_candidates,
)

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
