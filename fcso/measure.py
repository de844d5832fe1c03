"""The number a scenario is ranked by: the paper's E, or METHOD §7b's capture measure.

Under ``[quality] measure = "capture"`` a scenario ranks first by the share
of start errors its pads capture times its holding share, in bands of
1/:data:`BANDS`, and by E within a band. Folded into one number::

    m = (floor(BANDS · c · min(1, h / F)) + E / (E + L W)) / BANDS

``E / (E + L W)`` grows with E and stays below 1, so it orders a band and
never lifts a scenario into the next. The measure has no unit and the same
scale on every part; the product ``c · h · E`` it replaces ranked the
simulation's outcomes across a suite of parts no better than E's scale
between parts (Spearman 0.31 over 22 verified candidates, ``bench_truth``).
"""

from __future__ import annotations

import numpy as np

from .config import DesignConfig

#: Bands of capture x holding share; within one band, E ranks (METHOD §7b).
BANDS = 20


def capture_measure(capture: float, holding_share: float, effective_area_mm2: float, pad_area_mm2: float) -> float:
    """METHOD §7b's measure of one scenario.

    Parameters
    ----------
    capture : float
        Share of start errors captured, in [0, 1].
    holding_share : float
        ``min(1, h / F)``: the weakest holding force over the test's force, in [0, 1].
    effective_area_mm2 : float
        E of the scenario, mm².
    pad_area_mm2 : float
        ``L · W``, the pad's face: E's scale, mm².

    Returns
    -------
    float
        In ``[0, 1 + 1/BANDS)``, no unit.
    """
    band = np.floor(BANDS * capture * holding_share + 1e-9)
    return float((band + effective_area_mm2 / (effective_area_mm2 + pad_area_mm2)) / BANDS)


def scenario_measure(capture: float, holding_share: float, effective_area_mm2: float, config: DesignConfig) -> float:
    """The measure ``[quality] measure`` names: E under "paper", :func:`capture_measure` under "capture"."""
    if config.quality.measure == "paper":
        return effective_area_mm2
    pad_area = config.sampler.length_mm * config.sampler.width_mm
    return capture_measure(capture, holding_share, effective_area_mm2, pad_area)


def quality_words(quality: float, measure: str) -> str:
    """A design's quality in words: ``Q = 179.4 mm²`` or ``measure 0.951`` (no unit).

    Parameters
    ----------
    quality : float
        The design's quality: E in mm² under the paper's measure, no unit under the capture measure.
    measure : {"capture", "paper"}
        ``[quality] measure`` of the design.
    """
    if measure == "paper":
        return f"Q = {quality:.1f} mm²"
    return f"measure {quality:.3f}"


def quality_title(measure: str) -> str:
    """A table heading for a design's quality under ``measure``: ``Q (mm²)``, or ``measure`` (no unit)."""
    return "Q (mm²)" if measure == "paper" else "measure"


def quality_decimals(measure: str) -> int:
    """Decimals that show a quality under ``measure``: 1 for Q in mm², 3 for the capture measure."""
    return 1 if measure == "paper" else 3
