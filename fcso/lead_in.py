"""The draft a candidate's pockets are printed with (METHOD §5b, §7b, §9c).

A pocket's lead-in bounds the start errors it guides in; a wider draft
(``[print] lead_in_alternatives_deg``) is taken only when the candidate's
worst scenario captures clearly more with it, since a wide draft also lets
a part ride up and out more easily.
"""

from __future__ import annotations

import numpy as np

from .capture import CandidateSqueeze, SqueezedPart
from .config import DesignConfig
from .grid import ScreenGrid
from .screen import ScreenGeometry

#: How much more of the start errors a pad must capture than flat pads to count as better (2 of 20 starts).
FLAT_MARGIN = 0.1


def wider_drafts(config: DesignConfig) -> list[float]:
    """The drafts :func:`printed_draft` may take instead of ``lead_in_deg``, ascending; none outside the capture
    measure or without a lead-in.
    """
    lead_in = config.print.resolved()["lead_in_deg"]
    if lead_in <= 0 or config.quality.measure != "capture":
        return []
    return sorted(a for a in config.print.lead_in_alternatives_deg if a > lead_in)


def printed_draft(
    screens: list[tuple[ScreenGeometry, ScreenGeometry]],
    centres_uv_mm: list[tuple[np.ndarray, np.ndarray]],
    widths_mm: list[float],
    sliding_axes: list[np.ndarray],
    config: DesignConfig,
    parts: list[SqueezedPart] | None = None,
    known: dict | None = None,
) -> tuple[float, list[float], str | None]:
    """The draft of a candidate's samples (:func:`fcso.evaluate.printed_lead_in_deg`) and its scenarios' captures.

    Parameters
    ----------
    screens, centres_uv_mm, widths_mm, sliding_axes : list
        Per scenario, its sample's two geometries, centres of mass, width and sliding axis, as
        :func:`fcso.capture.pad_landscapes`.
    config : DesignConfig
    parts : list of SqueezedPart, optional
        The scenarios' samples when already squeezed (:func:`fcso.capture.sample_part`).
    known : dict, optional
        Landscapes of other candidates with the same settings (:class:`fcso.capture.CandidateSqueeze`'s).

    Returns
    -------
    lead_in_deg : float
    captures : list of float
        Per scenario, its capture on the candidate's pad printed with that draft.
    why : str or None
    """
    lead_in = config.print.resolved()["lead_in_deg"]
    grid = ScreenGrid.for_config(config)
    squeezed = CandidateSqueeze(screens, centres_uv_mm, widths_mm, sliding_axes, grid, config, parts, known)
    default = [landscape.fraction for landscape in squeezed.landscapes(lead_in)]
    alternatives = wider_drafts(config)
    # a wider draft is taken only where its worst scenario captures FLAT_MARGIN more than the default's worst: one
    # scenario short of that rules it out (the scenarios worst under the default first, the likeliest), and with
    # every wider draft ruled out the default stands, as below
    threshold = min(default) + FLAT_MARGIN
    order = np.argsort(default, kind="stable")
    if all(any(squeezed.landscape(int(k), angle).fraction < threshold for k in order) for angle in alternatives):
        return lead_in, default, None
    captures = {
        angle: [landscape.fraction for landscape in squeezed.landscapes(angle)] for angle in [lead_in, *alternatives]
    }
    worst = {angle: min(values) for angle, values in captures.items()}
    widest = max(worst.values())
    if widest < worst[lead_in] + FLAT_MARGIN:
        return lead_in, captures[lead_in], None
    angle = min(a for a, capture in worst.items() if capture >= widest - 1e-9)
    return (
        angle,
        captures[angle],
        (
            f"pocket walls drafted by {angle:g}° instead of {lead_in:g}° ([print] lead_in_alternatives_deg): "
            f"the worst scenario's capture is {worst[angle]:.2f} against {worst[lead_in]:.2f}"
        ),
    )
