"""The FCSO pipeline: parts in, fingerpad, finger and report out (METHOD §1-9).

Its stages, each a module:

- :mod:`~fcso.pipeline.prepare`: parts loaded, posed and sampled, every sample's pad geometries (METHOD §1-5)
- :mod:`~fcso.pipeline.choose`: the candidate search and exact re-evaluation (METHOD §6-8)
- :mod:`~fcso.pipeline.pads`: the chosen candidates' printed pads, made side by side (METHOD §9b)
- :mod:`~fcso.pipeline.finish`: the fused finger and the design's report (METHOD §9)
- :mod:`~fcso.pipeline.design`: the whole, every pad size tried
- :mod:`~fcso.pipeline.report`: a design's ``report.json`` assembled from its results
- :mod:`~fcso.pipeline.sets_report`: a job's finger-sets report assembled from its sets' designs

A job's finger sets (:mod:`fcso.sets`) are designed with these stages.
"""

from .choose import ChosenCandidate, choose_candidate, choose_candidates, listed_screens
from .design import SizeScore, best_pad_size, design, design_prepared
from .finish import DesignResult, finish_design, finish_designs
from .pads import finish_candidate, finish_candidates, pad_key
from .prepare import Prepared, evaluate_exact, flat_finger, load_batch, prepare, screen_choice, subset

__all__ = [
    "ChosenCandidate",
    "DesignResult",
    "Prepared",
    "SizeScore",
    "best_pad_size",
    "choose_candidate",
    "choose_candidates",
    "design",
    "design_prepared",
    "evaluate_exact",
    "finish_candidate",
    "finish_candidates",
    "finish_design",
    "finish_designs",
    "flat_finger",
    "listed_screens",
    "load_batch",
    "pad_key",
    "prepare",
    "screen_choice",
    "subset",
]
