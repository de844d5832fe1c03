"""Capture: the share of start errors from which closing the jaws seats the part (METHOD §7b).

The model is the quasi-static squeeze of Goldberg's squeeze function and of
Zhang and Goldberg's self-aligning jaws, on the ``(v, w)`` column heights of
the screening (METHOD §8b). For the part displaced on the table by ``δ =
(t, θ)`` (``t`` along the sliding axis ``b``, ``θ`` about the vertical through
its centre of mass), ``s(δ)`` is the jaw separation at which both pads first
touch it. A displacement along the closing axis moves one pad's contact in
and the other's out by the same amount, so it does not change ``s``: the
symmetric jaws absorb it. Closing lowers the separation, so the part slides
towards smaller ``s``, but a slide only where the slope of ``s`` beats
friction: each jaw pushes along the closing axis, and a contact surface
sloping by ``tan α`` turns that push sideways only when ``tan α > μ``. With
two jaws, ``Δs / (2 Δ) > μ`` along a slide of length ``Δ``. A turn pivots
the part about a contact and is taken whenever it lowers ``s``. A start is
captured when steepest descent of ``s`` from it ends within the success
tolerance of the seat.

In the pad frame of side ``σ`` (``u = σ a``, ``v = σ b``, :meth:`fcso.sampler.
GraspSample.pad_frame`), the displaced part is its outline turned by ``θ``
about its centre of mass ``(u_c, v_c)`` there, exactly (METHOD §7c: a
feature round about the vertical turns into itself and fixes no rotation),
then shifted by ``σ t`` along ``v``. The pad's heights stay. ``s`` then is
a minimum over cells of turned and shifted height maps: a landscape of a few
hundred ``δ`` costs a few milliseconds.

Printed fit is modelled on the heights as :mod:`fcso.printfit` carves it
(:mod:`fcso.printed_heights`): a drafted pocket is ``c`` deeper (METHOD §9c)
and every wall is drafted, ``H(x) = max_y H(y) - |x - y| cot α``.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from .config import DesignConfig, VerifyConfig
from .descent import descent
from .grid import ScreenGrid
from .jit import compiled
from .printed_heights import carved_heights, clearance_heights, drafted_heights
from .screen import ScreenGeometry, pad_case

#: Steps of the yaw grid of the landscape, degrees.
YAW_STEP_DEG = 0.5
#: How far the landscape reaches beyond the start error box, mm and degrees: a descent may leave it for the seat.
MARGIN_MM, MARGIN_DEG = 1.0, 1.0
#: Spacing of the rows across the pad width that the landscape reads, mm.
W_STEP_MM = 0.6


@dataclass
class CaptureLandscape:
    """The jaw separation over start errors and what it captures.

    Attributes
    ----------
    offsets_mm : (nt,) float
        Start errors along the sliding axis, mm.
    yaws_deg : (ny,) float
        Start errors about the vertical, degrees.
    separation_mm : (nt, ny) float
        ``s(δ) - s(0)``, mm; ``inf`` where a pad loses the part.
    captured : (nt, ny) bool
        Starts whose descent ends at the seat.
    in_box : (nt, ny) bool
        Starts inside the test's error box.
    fraction : float
        Captured share of the starts in the box, in [0, 1]; 0 when the pads meet before they squeeze the part.
    pads_gap_mm : float
        How far apart the two pads still are when, closing from the nominal seat, both first touch the part
        (METHOD §5b), mm; ``<= 0``: the printed pads meet each other first and the grasp does not hold.
    """

    offsets_mm: np.ndarray
    yaws_deg: np.ndarray
    separation_mm: np.ndarray
    captured: np.ndarray
    in_box: np.ndarray
    fraction: float
    pads_gap_mm: float


def capture_landscape(
    pad_mm: np.ndarray,
    part_mm: tuple[np.ndarray, np.ndarray],
    centres_uv_mm: tuple[np.ndarray, np.ndarray],
    cell_mm: float,
    depth_mm: float,
    width_mm: float,
    config: VerifyConfig,
    sliding_axis: np.ndarray | None = None,
) -> CaptureLandscape:
    """Squeeze one part between two pads from every start error of a grid and tell which starts are captured.

    Parameters
    ----------
    pad_mm : (count_v, count_w) float
        The pad's face heights (:func:`fitted_pad_heights`), shared by both fingers.
    part_mm : two (count_v, count_w) float
        The part's column heights in the "+" and "-" pad frames at its
        nominal grasp, mm; ``<= 0`` where the part is not in the pad box.
    centres_uv_mm : two (2,) float
        The part's centre of mass ``(u, v)`` in each pad frame, mm.
    cell_mm : float
        Grid cell, mm.
    depth_mm : float
        Penetration D: where the contact lies in ``u``.
    width_mm : float
        The part's extent along the closing axis in the pads' footprint (``a_max - a_min``), mm: the two pads'
        inner faces (``u = 0``) lie ``width - 2 D`` apart at the nominal seat.
    config : VerifyConfig
        Start error box, success tolerance, friction.
    sliding_axis : (2,) or (3,) float, optional
        ``b`` in the table's frame, whose start errors lie along its axes (:func:`sliding_error_weights`); None: a
        table axis.

    Returns
    -------
    CaptureLandscape
    """
    part = squeezed_part(part_mm, centres_uv_mm, cell_mm, depth_mm, width_mm, config, sliding_axis)
    return squeeze(pad_mm, part)


@dataclass
class SqueezedPart:
    """What a capture landscape needs of its part, whatever the pad (:func:`squeezed_part`): one scenario's sample
    is squeezed on the pads of many candidates and at every draft of :func:`fcso.lead_in.printed_draft`.

    Attributes
    ----------
    offsets_mm, yaws_deg : (nt,), (ny,) float
        The landscape's start errors, mm and degrees (:class:`CaptureLandscape`).
    rows_w : slice
        The rows of ``w`` the landscape reads.
    sides : list of ((columns,) bool, (ny, count_v, k) float, (nt,) int64, (nt,) float)
        Per pad ("+", "-"): the rows read that the part enters, its heights turned by every start yaw
        (:func:`_turned_heights`) on them, and every start's shift along ``v`` in whole cells and the rest.
    lever_mm : float
        The mean lever of a turn about the vertical at the contact, mm.
    width_mm, depth_mm, cell_mm : float
        As :func:`capture_landscape`'s.
    weights : (nt, ny) float
        How likely each start error is (0 outside the test's box).
    config : VerifyConfig
    """

    offsets_mm: np.ndarray
    yaws_deg: np.ndarray
    rows_w: slice
    sides: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]
    lever_mm: float
    width_mm: float
    depth_mm: float
    cell_mm: float
    weights: np.ndarray
    config: VerifyConfig


def squeezed_part(
    part_mm: tuple[np.ndarray, np.ndarray],
    centres_uv_mm: tuple[np.ndarray, np.ndarray],
    cell_mm: float,
    depth_mm: float,
    width_mm: float,
    config: VerifyConfig,
    sliding_axis: np.ndarray | None = None,
) -> SqueezedPart:
    """The pad-independent half of :func:`capture_landscape` (same parameters but the pad): the part turned by
    every start yaw, ready to be squeezed on any pad by :func:`squeeze`."""
    error_mm = config.position_error_mm
    axis = np.abs(np.asarray((0.0, 1.0) if sliding_axis is None else sliding_axis, dtype=np.float64)[:2])
    axis /= np.linalg.norm(axis)
    reach_mm = error_mm * float(axis.sum()) + MARGIN_MM
    reach_deg = config.yaw_error_deg + MARGIN_DEG
    steps = int(np.ceil(reach_mm / cell_mm))
    offsets = np.arange(-steps, steps + 1) * cell_mm
    turns = int(np.ceil(reach_deg / YAW_STEP_DEG))
    yaws_deg = np.arange(-turns, turns + 1) * YAW_STEP_DEG
    yaws = np.radians(yaws_deg)
    count_v = part_mm[0].shape[0]
    v_mm = (np.arange(count_v) + 0.5) * cell_mm
    # every few rows of w: the squeeze is decided along v, and a coarser w costs a fraction
    rows_w = slice(0, None, max(1, int(round(W_STEP_MM / cell_mm))))
    sides, levers = [], []
    for sign, heights, (u_c, v_c) in zip((1.0, -1.0), part_mm, centres_uv_mm):
        heights = np.asarray(heights, dtype=np.float64)[:, rows_w]
        # a row of w the part never enters leaves every gap infinite: only the others are read (at least one, so
        # a part outside the box still gives infinite gaps)
        entered = (heights > 0).any(axis=0)
        entered[np.argmax(entered)] = True
        part = np.where(heights[:, entered] > 0, heights[:, entered], -np.inf)
        # the part turned by every start yaw about its centre of mass, exactly (METHOD §7c): a feature round about
        # the vertical turns into itself and so fixes no rotation
        turned = _turned_heights(np.ascontiguousarray(part), v_mm, float(u_c), float(v_c), yaws)
        # the shift along v of every start in cells: the clearance per column is known for whole
        # cells and interpolated between them, so the landscape has no steps of a cell's rounding
        shift = sign * offsets / cell_mm
        whole = np.floor(shift).astype(np.int64)
        sides.append((entered, turned, whole, shift - whole))
        levers.append(abs(depth_mm - u_c))
    in_yaw = np.abs(yaws_deg) <= config.yaw_error_deg + 1e-9
    return SqueezedPart(
        offsets_mm=offsets,
        yaws_deg=yaws_deg,
        rows_w=rows_w,
        sides=sides,
        lever_mm=max(float(np.mean(levers)), cell_mm),
        width_mm=width_mm,
        depth_mm=depth_mm,
        cell_mm=cell_mm,
        weights=np.outer(sliding_error_weights(offsets, error_mm, axis), in_yaw),
        config=config,
    )


def squeeze(pad_mm: np.ndarray, part: SqueezedPart) -> CaptureLandscape:
    """The capture landscape of ``part`` between two pads of face heights ``pad_mm`` ((count_v, count_w) float, mm;
    :func:`capture_landscape`)."""
    config, cell_mm, offsets, yaws_deg = part.config, part.cell_mm, part.offsets_mm, part.yaws_deg
    pad_mm = np.asarray(pad_mm, dtype=np.float64)[:, part.rows_w]
    gap = np.zeros((len(offsets), len(yaws_deg)))
    for entered, turned, whole, fraction in part.sides:
        _add_side_gaps(np.ascontiguousarray(pad_mm[:, entered]), turned, whole, fraction, gap)
    centre = (len(offsets) // 2, len(yaws_deg) // 2)
    # a centre no pad touches has an infinite gap: every separation is then inf - inf, read as never seated
    with np.errstate(invalid="ignore"):
        separation = -(gap - gap[centre])
    separation[~np.isfinite(separation)] = np.inf
    # METHOD §5b: closing from the nominal seat, the pads must both touch the part before they touch each other.
    # The "-" pad is the "+" pad turned about the vertical: at the same column its face is the "+" pad's at the
    # mirrored v, and the faces lie H+ + H- + width - 2 D apart.
    pads_apart = float(np.min(pad_mm + pad_mm[::-1, :])) + part.width_mm - 2.0 * part.depth_mm
    pads_gap = pads_apart - float(gap[centre]) if np.isfinite(gap[centre]) else -np.inf
    successor = descent(separation, cell_mm, np.radians(YAW_STEP_DEG) * part.lever_mm, config.friction)
    seat = (np.abs(offsets)[:, None] <= config.success_mm + 1e-9) & (
        np.abs(yaws_deg)[None, :] <= config.success_deg + 1e-9
    )
    captured = seat.ravel()[successor].reshape(separation.shape) & np.isfinite(separation)
    weights = part.weights
    return CaptureLandscape(
        offsets_mm=offsets,
        yaws_deg=yaws_deg,
        separation_mm=separation,
        captured=captured,
        in_box=weights > 0,
        fraction=float((weights * captured).sum() / weights.sum()) if pads_gap > 0 else 0.0,
        pads_gap_mm=pads_gap,
    )


def squeeze_key(pad_mm: np.ndarray, part: SqueezedPart) -> tuple[bytes, float]:
    """What :func:`squeeze` reads of a pad ((count_v, count_w) float, mm) for ``part``: the :func:`digest` of the rows
    of ``w`` it enters on each side, and the least sum of the pad's heights and their mirror (mm), where pads meet."""
    pad_mm = np.asarray(pad_mm, dtype=np.float64)[:, part.rows_w]
    read = b"".join(np.ascontiguousarray(pad_mm[:, entered]).tobytes() for entered, *_ in part.sides)
    return digest(read), float(np.min(pad_mm + pad_mm[::-1, :]))


def digest(data: bytes) -> bytes:
    """A 256-bit BLAKE2b digest of ``data``, the key of heights in caches: two arrays of other bytes share one with
    probability 2^-256, and the arrays themselves (tens of kB each) held hundreds of MB in a large set's screening."""
    return hashlib.blake2b(data, digest_size=32).digest()


def sliding_error_weights(offsets_mm: np.ndarray, error_mm: float, sliding_axis: np.ndarray) -> np.ndarray:
    """How likely each start error along the sliding axis is, for errors drawn uniformly along the table's axes.

    ``t = b_x dx + b_y dy`` with ``dx, dy`` uniform in ``±error_mm``: a
    trapezoid, uniform over ``±error_mm`` for an axis along the table's.

    Parameters
    ----------
    offsets_mm : (n,) float
        Start errors along ``b``, mm.
    error_mm : float
        Half-width of the start error box along each table axis, mm.
    sliding_axis : (2,) float
        ``(|b_x|, |b_y|)``, a unit vector.

    Returns
    -------
    (n,) float
        Relative weights (the density at each offset); 0 outside the reachable range.
    """
    a, b = sorted(error_mm * np.asarray(sliding_axis, dtype=np.float64))
    t = np.abs(np.asarray(offsets_mm, dtype=np.float64))
    if a < 1e-6 * max(b, 1e-9):
        # along a table axis: uniform, the box's edge included
        return (t <= b + 1e-9).astype(np.float64)
    return np.clip(np.minimum(a + b - t, 2.0 * a), 0.0, None) / (4.0 * a * b)


@compiled("(float64[:, ::1], float64[::1], float64, float64, float64[::1])")
def _turned_heights(part, v_mm, u_c, v_c, yaws):
    """The part's column heights turned by each yaw about its centre of mass ``(u_c, v_c)`` in the pad frame.

    Each row of ``w`` is the part's outline ``u(v)`` towards the pad, a polyline through the cell centres where the
    part is in the box; turned exactly (``u' = u_c + (u - u_c) cos θ - (v - v_c) sin θ``, ``v' = v_c + (u - u_c)
    sin θ + (v - v_c) cos θ``) and read back on the cells as its upper envelope. A linear shift and tilt of the
    heights (``Δv = θ (D - u_c)`` for every column) moved a round boss's flanks as if turning moved the boss, so
    a boss captured every start yaw where the simulation keeps it.

    Parameters
    ----------
    part : (count_v, columns) float
        Column heights, mm; ``-inf`` where the part is not in the box.
    v_mm : (count_v,) float
        Cell centres along ``v``, mm.
    u_c, v_c : float
        Centre of mass in the pad frame, mm.
    yaws : (yaws,) float
        Radians.

    Returns
    -------
    (yaws, count_v, columns) float
        ``-inf`` where the turned part is not in the box.
    """
    count_v, columns = part.shape
    cell = v_mm[1] - v_mm[0] if count_v > 1 else 1.0
    turned = np.full((yaws.shape[0], count_v, columns), -np.inf)
    for k in range(yaws.shape[0]):
        cos, sin = np.cos(yaws[k]), np.sin(yaws[k])
        for column in range(columns):
            previous_v, previous_u, previous_in = 0.0, 0.0, False
            for v in range(count_v):
                height = part[v, column]
                if not np.isfinite(height):
                    previous_in = False
                    continue
                u_turned = u_c + (height - u_c) * cos - (v_mm[v] - v_c) * sin
                v_turned = v_c + (height - u_c) * sin + (v_mm[v] - v_c) * cos
                alone = not previous_in and (v + 1 == count_v or not np.isfinite(part[v + 1, column]))
                if alone:
                    # a lone column, on its nearest cell; the others are read where their segments span a cell
                    # centre (on the nearest cell, a sloping outline would be off by its slope over half a cell)
                    nearest = int(np.floor(v_turned / cell))
                    if 0 <= nearest < count_v and u_turned > turned[k, nearest, column]:
                        turned[k, nearest, column] = u_turned
                if previous_in:
                    # the segment from the previous point: every cell centre it spans, interpolated
                    low, high = min(previous_v, v_turned), max(previous_v, v_turned)
                    first = max(int(np.ceil(low / cell - 0.5)), 0)
                    last = min(int(np.floor(high / cell - 0.5)), count_v - 1)
                    for target in range(first, last + 1):
                        centre = (target + 0.5) * cell
                        share = 0.0 if high - low < 1e-12 else (centre - previous_v) / (v_turned - previous_v)
                        value = previous_u + share * (u_turned - previous_u)
                        if value > turned[k, target, column]:
                            turned[k, target, column] = value
                previous_v, previous_u, previous_in = v_turned, u_turned, True
    return turned


@compiled("(float64[:, ::1],)")
def _row_kinds(values):
    """Each row's kind, numbered from 0 in order of first appearance: rows alike bit for bit share one.

    Parameters
    ----------
    values : (rows, columns) float

    Returns
    -------
    (rows,) int64
    """
    rows, columns = values.shape
    bits = values.view(np.int64)
    kind = np.empty(rows, dtype=np.int64)
    # the first row of each kind
    first = np.empty(rows, dtype=np.int64)
    kinds = 0
    for row in range(rows):
        kind[row] = -1
        # the row before first, as neighbouring rows are the likeliest alike; then the first row of every kind
        for candidate in range(-1, kinds):
            other = row - 1 if candidate < 0 else first[candidate]
            if other < 0:
                continue
            alike = True
            for column in range(columns):
                if bits[row, column] != bits[other, column]:
                    alike = False
                    break
            if alike:
                kind[row] = kind[other]
                break
        if kind[row] < 0:
            kind[row] = kinds
            first[kinds] = row
            kinds += 1
    return kind


@compiled("(float64[:, ::1], float64[:, :, ::1], int64[::1], float64[::1], float64[:, ::1])")
def _add_side_gaps(pad, turned, whole, fraction, gap):
    """Add one pad's gap to ``gap`` ((offsets, yaws) float, mm) for every start of the grid.

    Parameters
    ----------
    pad : (count_v, columns) float
        The pad's face heights on the rows of ``w`` the part enters, mm.
    turned : (yaws, count_v, columns) float
        The part's column heights turned by each start yaw (:func:`_turned_heights`), ``-inf`` where it is not in
        the box, mm.
    whole, fraction : (offsets,) int64, float
        Each start's shift along ``v`` in cells: its whole cells and the rest.
    """
    count_v, columns = pad.shape
    lowest, highest = whole.min(), whole.max()
    # rows of v whose pad is alike bit for bit (most of a pad, as a pocket is often the same along v) meet each row
    # of the turned part with the same clearance: it is measured once per kind of pad row and turned row, for the
    # runs of rows of one kind
    kind = _row_kinds(pad)
    starts = np.flatnonzero(np.diff(kind)) + 1
    starts = np.concatenate((np.zeros(1, dtype=np.int64), starts, np.full(1, count_v, dtype=np.int64)))
    clearance = np.empty((kind.max() + 1, count_v))
    for yaw in range(turned.shape[0]):
        known = np.zeros(clearance.shape, dtype=np.bool_)
        # the clearance of every row of v against each row of the part: its least over the rows of w
        for run in range(starts.shape[0] - 1):
            first, end, alike = starts[run], starts[run + 1], kind[starts[run]]
            # the rows of the turned part this run meets at some whole shift (or the next one, interpolated to)
            low = min(max(first - highest - 1, 0), count_v - 1)
            high = min(max(end - 1 - lowest, 0), count_v - 1)
            for source in range(low, high + 1):
                if not known[alike, source]:
                    least = np.inf
                    for column in range(columns):
                        least = min(least, pad[first, column] - turned[yaw, source, column])
                    clearance[alike, source] = least
                    known[alike, source] = True
        for offset in range(whole.shape[0]):
            shift, share = whole[offset], fraction[offset]
            least = np.inf
            for v in range(count_v):
                # interpolated between whole cells, so the landscape has no steps of a cell's rounding; inf - inf
                # (no pad or no part on either side) is no contact
                here = clearance[kind[v], min(max(v - shift, 0), count_v - 1)]
                beyond = clearance[kind[v], min(max(v - shift - 1, 0), count_v - 1)]
                shifted = (1.0 - share) * here + share * beyond
                if np.isnan(shifted):
                    shifted = np.inf
                least = min(least, shifted)
            gap[offset, yaw] += least


def pad_landscapes(
    chosen: list[tuple[ScreenGeometry, ScreenGeometry]],
    centres_uv_mm: list[tuple[np.ndarray, np.ndarray]],
    widths_mm: list[float],
    sliding_axes: list[np.ndarray],
    grid: ScreenGrid,
    config: DesignConfig,
    flat: bool = False,
) -> list[CaptureLandscape]:
    """The capture landscape of every scenario on the pad these samples carve, printed with ``[print]``'s fit.

    Parameters
    ----------
    chosen : list of (ScreenGeometry, ScreenGeometry)
        One sample's "+" and "-" geometries per scenario: a candidate, or one sample alone.
    centres_uv_mm : list of two (2,) float
        Each scenario's centre of mass ``(u, v)`` in the "+" and "-" pad frames, mm.
    widths_mm : list of float
        Each scenario's part extent along the closing axis in the footprint (``a_max - a_min``), mm.
    sliding_axes : list of (3,) float
        Each scenario's sliding axis ``b`` in the resting frame (:attr:`fcso.sampler.GraspSample.sliding_axis`).
    grid : ScreenGrid
    config : DesignConfig
    flat : bool
        Squeeze between flat pads instead (face at ``D``): the control of METHOD §12.

    Returns
    -------
    list of CaptureLandscape, one per scenario.
    """
    return CandidateSqueeze(chosen, centres_uv_mm, widths_mm, sliding_axes, grid, config).landscapes(flat=flat)


def sample_part(
    screens: tuple[ScreenGeometry, ScreenGeometry],
    centres_uv_mm: tuple[np.ndarray, np.ndarray],
    width_mm: float,
    sliding_axis: np.ndarray,
    grid: ScreenGrid,
    config: DesignConfig,
) -> SqueezedPart:
    """One scenario's sample ready to be squeezed on any pad (:func:`squeezed_part`): its "+" and "-" geometries,
    centres of mass, width and sliding axis as :func:`pad_landscapes` takes them."""
    shape = (grid.count_v, grid.count_w)
    return squeezed_part(
        (screens[0].heights_mm.reshape(shape), screens[1].heights_mm.reshape(shape)),
        centres_uv_mm,
        grid.cell_mm,
        config.sampler.penetration_mm,
        width_mm,
        config.verify,
        sliding_axis,
    )


class CandidateSqueeze:
    """A candidate's scenarios squeezed on the pad it carves, printed with any draft (:func:`pad_landscapes`).

    The carving given its clearance and each part turned by every start yaw are the same at every draft, so they
    are made once for the drafts :func:`fcso.lead_in.printed_draft` compares, and each landscape once when asked
    again. Parameters as :func:`pad_landscapes`'s, and ``parts``: the scenarios' parts when already squeezed
    (:func:`sample_part`); ``known``: landscapes of other candidates with the same settings, used and filled here
    (:meth:`known_landscape`): a candidate whose carving is another's bit for bit, as when one scenario's sample lies
    under the others' pockets, or whose pad is where a part meets it, squeezes only its new samples.
    """

    def __init__(
        self,
        chosen: list[tuple[ScreenGeometry, ScreenGeometry]],
        centres_uv_mm: list[tuple[np.ndarray, np.ndarray]],
        widths_mm: list[float],
        sliding_axes: list[np.ndarray],
        grid: ScreenGrid,
        config: DesignConfig,
        parts: list[SqueezedPart] | None = None,
        known: dict | None = None,
    ):
        self.chosen, self.grid, self.config, self.known = chosen, grid, config, known
        self.parts = (
            parts
            if parts is not None
            else [
                sample_part(pair, centres, width, axis, grid, config)
                for pair, centres, width, axis in zip(chosen, centres_uv_mm, widths_mm, sliding_axes)
            ]
        )
        self.cleared: dict[bool, np.ndarray] = {}
        self.pads: dict[float, np.ndarray] = {}
        self.squeezed: dict[tuple[int, float], CaptureLandscape] = {}
        self.carving: tuple[np.ndarray, bytes, float] | None = None

    def carved(self) -> tuple[np.ndarray, bytes, float]:
        """The carving (:func:`carved_heights`, mm), its digest (:func:`digest`) and the pad's floor (:func:`pad_case`,
        mm), made once."""
        if self.carving is None:
            geometries = [g for pair in self.chosen for g in pair]
            carved = carved_heights(geometries, self.grid)
            self.carving = carved, digest(carved.tobytes()), pad_case(geometries, self.config)[1]
        return self.carving

    def pad(self, lead_in_deg: float) -> np.ndarray:
        """The pad's face heights printed with ``[print]``'s clearance and ``lead_in_deg`` (degrees), (count_v,
        count_w) mm (:func:`fitted_pad_heights`)."""
        if lead_in_deg not in self.pads:
            carved, _, floor = self.carved()
            cell = self.grid.cell_mm
            drafted = lead_in_deg > 0
            if drafted not in self.cleared:
                # the carving given its clearance is the same at every draft
                clearance = self.config.print.resolved()["clearance_mm"]
                self.cleared[drafted] = clearance_heights(carved, cell, clearance, drafted)
            self.pads[lead_in_deg] = drafted_heights(self.cleared[drafted], floor, cell, lead_in_deg)
        return self.pads[lead_in_deg]

    def landscape(self, number: int, lead_in_deg: float) -> CaptureLandscape:
        """Scenario ``number``'s landscape on the pad printed with ``lead_in_deg`` (degrees)."""
        key = (number, lead_in_deg)
        if key not in self.squeezed:
            part = self.parts[number]
            if self.known is None:
                self.squeezed[key] = squeeze(self.pad(lead_in_deg), part)
            else:
                self.squeezed[key] = self.known_landscape(part, lead_in_deg)
        return self.squeezed[key]

    def known_landscape(self, part: SqueezedPart, lead_in_deg: float) -> CaptureLandscape:
        """``part``'s landscape on the pad printed with ``lead_in_deg`` (degrees) from ``known``: squeezed before on
        the same carving, or on a pad that is this one bit for bit where the squeeze reads it (:func:`squeeze_key`),
        else squeezed now; the part is kept beside its landscape, so its id names no other part while they live."""
        _, carving, floor = self.carved()
        by_carving = (id(part), carving, floor, self.config.print.resolved()["clearance_mm"], lead_in_deg)
        entry = self.known.get(by_carving)
        if entry is None or entry[0] is not part:
            pad = self.pad(lead_in_deg)
            by_pad = (id(part), *squeeze_key(pad, part))
            entry = self.known.get(by_pad)
            if entry is None or entry[0] is not part:
                entry = self.known[by_pad] = (part, squeeze(pad, part))
            self.known[by_carving] = entry
        return entry[1]

    def landscapes(self, lead_in_deg: float | None = None, flat: bool = False) -> list[CaptureLandscape]:
        """One landscape per scenario, on the pad printed with ``lead_in_deg`` (degrees; None: ``[print]``'s), or
        between flat pads (face at ``D``) with ``flat``."""
        if flat:
            pad = np.full((self.grid.count_v, self.grid.count_w), self.config.sampler.penetration_mm)
            return [squeeze(pad, part) for part in self.parts]
        draft = self.config.print.resolved()["lead_in_deg"] if lead_in_deg is None else lead_in_deg
        return [self.landscape(number, draft) for number in range(len(self.parts))]
