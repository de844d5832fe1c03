"""Finger sets: a job's parts split over a few fingers (METHOD §11).

A finger designed for every part of a batch carves every part's pocket into
one pad and can bury one part's contact under another's carving. Here the
distinct parts of a job are partitioned into at most ``[finger_sets] max``
sets, each served by its own finger designed by METHOD §1-9 for that set
alone, so that every graspable scenario keeps ``retained = E / E*`` of its
solo quality ``E*``.

Sampling and pad geometries depend on a scenario alone, so they are made
once for the whole job (:func:`fcso.pipeline.prepare`); the partition search
only screens candidate sets (:func:`screen_set`) and the chosen sets are
designed exactly (:func:`fcso.pipeline.design_prepared`). Every quality is an
effective area E in mm²; retained qualities are ratios (0..1).
"""

from .design import design_sets
from .identity import SAME_GEOMETRY_TOLERANCE_MM, identical_groups, same_geometry
from .judged import PartitionAttempt, search_judged_exactly
from .partition import (
    PartitionOutcome,
    canonical_assignment,
    max_clique,
    partition_key,
    restricted_growth,
    search_partition,
)
from .result import SetsResult
from .screening import SetScreener, SetScreening, SoloQuality, screen_set, screening_pools, solo_quality

__all__ = [
    "PartitionAttempt",
    "PartitionOutcome",
    "SAME_GEOMETRY_TOLERANCE_MM",
    "SetScreener",
    "SetScreening",
    "SetsResult",
    "SoloQuality",
    "canonical_assignment",
    "design_sets",
    "identical_groups",
    "max_clique",
    "partition_key",
    "restricted_growth",
    "same_geometry",
    "screen_set",
    "screening_pools",
    "search_judged_exactly",
    "search_partition",
    "solo_quality",
]
