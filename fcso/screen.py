"""Screening evaluation: a candidate's quality in about a millisecond (METHOD §8b).

The exact evaluation (METHOD §6-7) carves the fingerpad with manifold3d,
seats every part by Euclidean signed distance and computes RLES exactly; it
takes tens of milliseconds per candidate. Screening ranks candidates with
the same contact samples and the same rules, on a representation prepared
once per sample:

- **Column heights.** Every pad lives in the one frame ``S = [0,T] x [0,L] x
  [0,W]``. Along each ray in ``u`` through the centre of a cell of a
  ``(v, w)`` grid, ``I_n`` is kept as its top ``H_n`` (the largest ``u`` of the
  part surface on that ray; 0 where the part does not enter the pad). The
  pad is then ``P = {u >= H}`` with ``H = max`` of the carved geometries'
  heights and the block ``D - d_B``, so carving a candidate is an element-wise
  maximum. The cell is ``4 eps`` (0.2 mm by default): a face sloping by up
  to 1:2 moves less than ``eps`` inside a cell, so the flat and gently
  sloping faces that decide seating and burial are resolved to the contact
  tolerance; steep walls are handled by the next rule, not by the grid.
- **Contact.** A contact sample of a good geometry lies on its own carved
  surface, so it touches the pad unless another geometry's carving (or the
  block) buries it: it is in contact when ``u >= H_others - eps`` at its cell,
  which holds on steep walls too. A bad geometry is not carved: its part is
  seated along ``-u`` by the smallest ``t`` that puts no sample more than
  ``eps`` inside ``P``, and its samples within ``eps`` of ``P``'s surface are in
  contact.
- **Walls between columns.** A column test is vertical, the exact test
  Euclidean: a sample on a face parallel to ``u`` (a part's top face inside
  the pad box) lies on the side wall of a neighbouring carving, not inside
  it. So each height map is kept also eroded and dilated by one cell (3 x 3
  minimum and maximum): burial uses the eroded heights (buried only when
  the cell's whole neighbourhood is deeper), seating the dilated ones, and
  a bad geometry's contact accepts any height between the two.
- **RLES.** Contact normals (grasp frame) are quantised once to the nearest
  of a Fibonacci lattice of :data:`NORMAL_BINS` directions, and RLES is
  computed exactly on the lattice points that occur: from their convex
  hull (every facet bounds an empty cap), cached by that set.

The screened quality ranks candidates; the ``k`` best are re-evaluated
exactly and only exact numbers choose the design. ``benchmarks/bench_fidelity``
measures the rank correlation against exact evaluation of every candidate.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import maximum_filter, minimum_filter
from scipy.spatial import ConvexHull, QhullError, cKDTree

from .config import DesignConfig
from .grid import ScreenGrid
from .jit import compiled
from .measure import scenario_measure
from .rles import fibonacci_sphere, rles

#: Lattice directions normals are quantised to (no more than 0.084 apart in chord
#: from their lattice point; 250 to 4000 gave the same rank correlation on the
#: paper experiment, and fewer occupied directions make RLES cheaper).
NORMAL_BINS = 1000

#: The eroded and dilated maps of a bad geometry (never carved, so never read).
_NO_MAP = np.zeros((0, 0), dtype=np.float32)
_NO_MAP.flags.writeable = False


@dataclass
class ScreenGeometry:
    """One pad geometry ``I_n`` of a sample, prepared for screening.

    Its column heights and their eroded and dilated maps are 0 outside the
    cells the part enters, grown by one cell (about half the pad face on a
    job of mixed parts): they are kept on that window of the grid only, so a
    sample's maps take about a third of three whole grids.

    Attributes
    ----------
    grid_shape : (int, int)
        ``(count_v, count_w)`` of the grid.
    window : (int, int, int, int)
        ``(first row, row stop, first column, column stop)`` of the window (rows along v, columns along w); all 0
        when the part enters no cell.
    window_heights_mm : (rows, columns) float32
        Column heights of ``I_n`` (:func:`column_heights`) in the window.
    window_low_mm, window_high_mm : (rows, columns) float32
        The same eroded and dilated by one cell (3 x 3 minimum and maximum over the whole grid), in the window;
        empty for a bad geometry, which is never carved.
    good : bool
        The filter's label.
    depth_mm : float
        ``d_n``.
    point_u_mm : (n,) float32
        ``u`` of the contact samples (the exact evaluator's samples).
    point_cell : (n,) int32
        Their grid cells.
    point_bin : (n,) int32
        Lattice bin of their normals in the grasp frame.
    area_per_point_mm2 : float
    capture : float
        Capture of the sample's pads alone (METHOD §7b), shared by its two
        geometries; 1 under the paper's measure.
    """

    grid_shape: tuple[int, int]
    window: tuple[int, int, int, int]
    window_heights_mm: np.ndarray
    window_low_mm: np.ndarray
    window_high_mm: np.ndarray
    good: bool
    depth_mm: float
    point_u_mm: np.ndarray
    point_cell: np.ndarray
    point_bin: np.ndarray
    area_per_point_mm2: float
    capture: float = 1.0

    @property
    def cells(self) -> tuple[slice, slice]:
        """The window as slices of the ``(count_v, count_w)`` grid."""
        first_row, row_stop, first_column, column_stop = self.window
        return slice(first_row, row_stop), slice(first_column, column_stop)

    @property
    def heights_mm(self) -> np.ndarray:
        """Column heights of ``I_n`` over the whole grid, ``(cells,)`` float32 (a new array)."""
        heights = np.zeros(self.grid_shape, dtype=np.float32)
        heights[self.cells] = self.window_heights_mm
        return heights.ravel()


@dataclass
class NormalLattice:
    """Quantisation of unit normals and a cache of RLES per set of occupied bins.

    Attributes
    ----------
    directions : (NORMAL_BINS, 3) float
        The Fibonacci lattice.
    """

    directions: np.ndarray = field(default_factory=lambda: fibonacci_sphere(NORMAL_BINS))
    _tree: cKDTree | None = None
    _cache: dict = field(default_factory=dict)

    def bins(self, normals: np.ndarray) -> np.ndarray:
        """Index of the nearest lattice direction of each unit normal."""
        if self._tree is None:
            self._tree = cKDTree(self.directions)
        if len(normals) == 0:
            return np.zeros(0, dtype=np.int32)
        # samples repeat their triangle's normal: query each distinct normal once
        rows = np.ascontiguousarray(normals, dtype=np.float64)
        distinct, inverse = np.unique(rows.view(np.dtype((np.void, rows.itemsize * 3))).ravel(), return_inverse=True)
        nearest = self._tree.query(distinct.view(np.float64).reshape(-1, 3))[1].astype(np.int32)
        return nearest[inverse.ravel()]

    def rles(self, occupied: np.ndarray) -> float:
        """RLES of the lattice directions ``occupied`` (a ``(NORMAL_BINS,)`` bool mask), cached by the mask."""
        key = occupied.tobytes()
        value = self._cache.get(key)
        if value is None:
            value = _hull_rles(self.directions[occupied]) if occupied.any() else 2.0
            self._cache[key] = value
        return value


def _hull_rles(directions: np.ndarray) -> float:
    """RLES of unit vectors from their convex hull, falling back to :func:`fcso.rles.rles`.

    Every point lies on the sphere, so each hull facet's plane ``n . x = d``
    bounds a cap beyond it that holds no point, of chord radius
    ``sqrt(2 - 2 d)``, and the largest empty cap is one of these. Qhull gives
    ``n . x + offset <= 0`` inside, so ``d = -offset``. Fewer than four
    directions, or all of them on one plane, have no hull: the exact
    function handles those.
    """
    if len(directions) >= 4:
        try:
            offsets = ConvexHull(directions).equations[:, 3]
            return float(np.sqrt(min(max(2.0 + 2.0 * offsets.max(), 0.0), 4.0)))
        except QhullError:
            pass
    return rles(directions)


def prepare_geometry(
    heights_mm, good, depth_mm, points, normals_grasp, area_per_point_mm2, grid: ScreenGrid, lattice: NormalLattice
) -> ScreenGeometry:
    """Bundle one geometry's screening data.

    Parameters
    ----------
    heights_mm : (cells,) float32
        :func:`column_heights` of the geometry.
    good : bool
    depth_mm : float
    points : (n, 3) float
        Contact samples, pad frame, mm.
    normals_grasp : (n, 3) float
        Their part normals in the grasp frame.
    area_per_point_mm2 : float
    grid : ScreenGrid
    lattice : NormalLattice
    """
    square = np.asarray(heights_mm, dtype=np.float32).reshape(grid.count_v, grid.count_w)
    rows, columns = np.flatnonzero(square.any(axis=1)), np.flatnonzero(square.any(axis=0))
    # the dilation reaches one cell beyond the footprint; heights are never negative, so all maps are 0 outside
    window = (
        (
            max(int(rows[0]) - 1, 0),
            min(int(rows[-1]) + 2, grid.count_v),
            max(int(columns[0]) - 1, 0),
            min(int(columns[-1]) + 2, grid.count_w),
        )
        if len(rows)
        else (0, 0, 0, 0)
    )
    cells = (slice(window[0], window[1]), slice(window[2], window[3]))
    return ScreenGeometry(
        grid_shape=(grid.count_v, grid.count_w),
        window=window,
        window_heights_mm=square[cells].copy(),
        # only good geometries are carved: a bad one's maps would be two thirds of its memory, never read
        window_low_mm=minimum_filter(square, size=3, mode="nearest")[cells].copy() if good else _NO_MAP,
        window_high_mm=maximum_filter(square, size=3, mode="nearest")[cells].copy() if good else _NO_MAP,
        good=bool(good),
        depth_mm=float(depth_mm),
        point_u_mm=np.asarray(points[:, 0], dtype=np.float32),
        point_cell=grid.cells(points[:, 1], points[:, 2]),
        point_bin=lattice.bins(normals_grasp),
        area_per_point_mm2=float(area_per_point_mm2),
    )


def screened_bound(geometries: tuple[ScreenGeometry, ScreenGeometry], lattice: NormalLattice) -> float:
    """Upper bound on a sample's screened E: all its samples in contact, over the RLES of all their bins.

    Contact is a subset of the samples and a subset of bins has an RLES no
    smaller, so no candidate screens this sample higher.
    """
    area = sum(len(g.point_u_mm) * g.area_per_point_mm2 for g in geometries)
    occupied = np.zeros(NORMAL_BINS, dtype=bool)
    occupied[np.concatenate([g.point_bin for g in geometries])] = True
    return float(area / lattice.rles(occupied)) if occupied.any() else 0.0


@dataclass
class ScreenedScenario:
    """Screened quality of one scenario of a candidate; ``measure`` is what ranks it (E, or capture x E)."""

    rles: float
    contact_area_mm2: float
    effective_area: float
    seat_offsets_mm: tuple[float, float]
    capture: float
    measure: float


@dataclass
class ScreenedCandidate:
    """Screened quality of a candidate: the worst scenario's measure and the mean, per scenario values, pad case.

    Under the paper's measure that is ``Q = min E`` (METHOD §7); under the
    capture measure each scenario's E is scaled by the capture of its
    sample's pads alone while the search ranks, by its capture on the whole
    candidate's pad and its screened contacts' holding when the best are
    screened again (METHOD §7b,
    :func:`fcso.evaluate.screen_on_pad`; the exact stage measures the whole pad).
    """

    quality: float
    mean_effective_area: float
    scenarios: list[ScreenedScenario]
    case: str


@dataclass
class Carving:
    """The carved geometries of part of a candidate, as column heights (before the block's floor).

    The pad's floor (its face where nothing is carved, :func:`pad_case`) is
    never below 0 and every use of these heights takes the larger of them and
    the floor, so a cell no geometry carves holds 0, as one carved to 0 does.

    Attributes
    ----------
    top_mm : (cells,) float32
        Largest eroded height of the carved geometries; 0 where none.
    owner : (cells,) int32
        Which geometry gives ``top_mm`` where it is above 0 (its position in
        the candidate, ``2 * scenario + side``); -1 where none.
    second_mm : (cells,) float32
        Largest eroded height of the others (0 where none): a geometry's own
        carving does not bury its own samples.
    top_high_mm : (cells,) float32
        Largest dilated height.
    pairs : frozenset of int
        Scenarios whose geometries are carved in.
    """

    top_mm: np.ndarray
    owner: np.ndarray
    second_mm: np.ndarray
    top_high_mm: np.ndarray
    pairs: frozenset


@compiled(
    "(float32[:, ::1], int32[:, ::1], float32[:, ::1], float32[:, ::1], int64, int64, "
    "float32[:, ::1], float32[:, ::1], int64)"
)
def _carve_window(top, owner, second, top_high, row, column, low, high, index):
    """Carve one geometry's maps into a :class:`Carving`'s (``(count_v, count_w)`` arrays, changed in place) on its
    window, whose first cell is ``(row, column)``; ``index`` is its position in the candidate."""
    for r in range(low.shape[0]):
        for c in range(low.shape[1]):
            v, w = row + r, column + c
            # ties keep the earlier owner: equal heights bury the same samples either way
            if low[r, c] > top[v, w]:
                second[v, w] = top[v, w]
                owner[v, w] = index
                top[v, w] = low[r, c]
            else:
                second[v, w] = max(second[v, w], low[r, c])
            top_high[v, w] = max(top_high[v, w], high[r, c])


def carve_heights(chosen: list[tuple[ScreenGeometry, ScreenGeometry]], pairs, base: Carving | None = None) -> Carving:
    """Carve the good geometries of some scenarios of a candidate into ``base`` (a new Carving).

    A coordinate move changes one scenario, so the search carves the other
    scenarios once and each move adds two geometries: the screening of a
    move costs a few height maps instead of all of them, and each on its
    window only (outside it a geometry's maps are 0 and change nothing).

    Parameters
    ----------
    chosen : list of (ScreenGeometry, ScreenGeometry)
        The candidate's geometries, one pair per scenario.
    pairs : iterable of int
        Scenarios to carve in (not already in ``base``).
    base : Carving, optional
        Carving to extend; an empty pad when None.
    """
    pairs = list(pairs)
    shape = chosen[0][0].grid_shape
    if base is None:
        top = np.zeros(shape, dtype=np.float32)
        owner = np.full(shape, -1, dtype=np.int32)
        second = np.zeros(shape, dtype=np.float32)
        top_high = np.zeros(shape, dtype=np.float32)
        done = frozenset()
    else:
        top, owner, second, top_high = (
            a.reshape(shape).copy() for a in (base.top_mm, base.owner, base.second_mm, base.top_high_mm)
        )
        done = base.pairs
    for pair in pairs:
        for side, g in enumerate(chosen[pair]):
            if not g.good:
                continue
            _carve_window(
                top,
                owner,
                second,
                top_high,
                g.window[0],
                g.window[2],
                g.window_low_mm,
                g.window_high_mm,
                2 * pair + side,
            )
    return Carving(top.ravel(), owner.ravel(), second.ravel(), top_high.ravel(), done | frozenset(pairs))


@compiled(
    "(float32[::1], int32[::1], float32[::1], float32[::1], float32, float64, int64[::1], "
    "boolean[::1], int32[::1], float32[::1], int32[::1], int64)"
)
def _contacts(top, owner, second, top_high, floor, eps, lengths, good, cells, point_u, point_bins, pairs):
    """Which contact samples of a candidate's geometries touch the pad, in one pass over every point.

    A good geometry's sample touches where it reaches the pad the others
    carve (its own carving buries none of its samples); a bad one is
    seated where its highest sample meets the pad's high map and touches
    between the low and high maps. Heights in float32, as the maps are
    (``eps`` rounded to float32 where it meets them), so the figures are
    those of the same comparisons on arrays.

    Parameters
    ----------
    top, second, top_high : (cells,) float32
        The :class:`Carving`'s maps; ``owner`` its (cells,) int32 owners.
    floor : float32
        The pad's face where nothing is carved (:func:`pad_case`).
    eps : float
        Contact tolerance, mm.
    lengths : (geometries,) int64
        Samples per geometry, in the candidate's order (``2 * scenario + side``).
    good : (geometries,) bool
    cells, point_u, point_bins : (samples,) int32, float32, int32
        Every geometry's samples in turn: cell, height ``u`` (mm) and normal bin.
    pairs : int
        Scenarios.

    Returns
    -------
    contact : (samples,) bool
    counts : (geometries,) int64
        Samples in contact.
    offsets : (geometries,) float
        A bad geometry's seat offset, mm (0 for a good one).
    occupied : (pairs, NORMAL_BINS) bool
        The normal bins of each scenario's contacts.
    """
    contact = np.zeros(point_u.shape[0], dtype=np.bool_)
    counts = np.zeros(lengths.shape[0], dtype=np.int64)
    offsets = np.zeros(lengths.shape[0], dtype=np.float64)
    occupied = np.zeros((pairs, NORMAL_BINS), dtype=np.bool_)
    tolerance = np.float32(eps)
    start = 0
    for geometry in range(lengths.shape[0]):
        end = start + lengths[geometry]
        if good[geometry]:
            for i in range(start, end):
                cell = cells[i]
                others = max(second[cell], floor) if owner[cell] == geometry else max(top[cell], floor)
                contact[i] = point_u[i] >= others - tolerance
        elif end > start:
            highest = point_u[start] - max(top_high[cells[start]], floor)
            for i in range(start + 1, end):
                highest = max(highest, point_u[i] - max(top_high[cells[i]], floor))
            offset = max(np.float64(highest) - eps, 0.0)
            offsets[geometry] = offset
            seat = np.float32(offset)
            for i in range(start, end):
                cell = cells[i]
                seated = point_u[i] - seat
                contact[i] = (seated >= max(top[cell], floor) - tolerance) and (
                    seated <= max(top_high[cell], floor) + tolerance
                )
        for i in range(start, end):
            if contact[i]:
                counts[geometry] += 1
                occupied[geometry // 2, point_bins[i]] = True
        start = end
    return contact, counts, offsets, occupied


def pad_case(geometries: list[ScreenGeometry], config: DesignConfig) -> tuple[str, float]:
    """The pad's case (METHOD §5) and the height of its face where nothing is carved, mm.

    Only good geometries: carved, face at 0; only bad ones: a flat pad, face
    at D; both: the block B of depth ``K min d_n`` over the good ones, face
    at ``D - K min d_n``.
    """
    depth = config.sampler.penetration_mm
    good = [g for g in geometries if g.good]
    if not good:
        return "bad", depth
    if len(good) == len(geometries):
        return "good", 0.0
    return "mixed", max(depth - min(g.depth_mm for g in good) * config.filter.block_factor, 0.0)


def screen(
    chosen: list[tuple[ScreenGeometry, ScreenGeometry]],
    config: DesignConfig,
    lattice: NormalLattice,
    carved: Carving | None = None,
    captures: Sequence[float] | None = None,
    holding: Callable[[int, tuple[np.ndarray, np.ndarray]], float] | None = None,
) -> ScreenedCandidate:
    """Screen one candidate: one sample's two geometries per scenario.

    Parameters
    ----------
    chosen : list of (ScreenGeometry, ScreenGeometry)
        The "+" and "-" geometries of the chosen sample of every scenario.
    config : DesignConfig
        Penetration D, block factor K, eps.
    lattice : NormalLattice
        Normal quantisation and RLES cache.
    carved : Carving, optional
        :func:`carve_heights` of some of these scenarios' geometries, shared by
        candidates that agree on them; the rest are carved here.
    captures : sequence of float, optional
        Under the capture measure, every scenario's capture on the pad the
        whole candidate carves (:func:`fcso.evaluate.screen_on_pad`); by default
        the capture of each sample's pads alone (cheap, for the search).
    holding : callable, optional
        Under the capture measure, ``holding(scenario, (contact+, contact-))``:
        the holding share of a scenario held by these screened contacts (masks
        over each geometry's contact samples); by default 1.

    Returns
    -------
    ScreenedCandidate
    """
    eps = config.contact.eps_mm
    geometries = [g for pair in chosen for g in pair]
    case, floor = pad_case(geometries, config)
    done = carved.pairs if carved is not None else frozenset()
    carving = carve_heights(chosen, [p for p in range(len(chosen)) if p not in done], carved)
    lengths = np.array([len(g.point_u_mm) for g in geometries], dtype=np.int64)
    contact, counts, offsets, occupied = _contacts(
        carving.top_mm,
        carving.owner,
        carving.second_mm,
        carving.top_high_mm,
        np.float32(floor),
        float(eps),
        lengths,
        np.array([g.good for g in geometries], dtype=np.bool_),
        np.concatenate([g.point_cell for g in geometries]),
        np.concatenate([g.point_u_mm for g in geometries]),
        np.concatenate([g.point_bin for g in geometries]),
        len(chosen),
    )
    ends = np.cumsum(lengths)
    results = []
    for pair_number in range(len(chosen)):
        areas = 0.0
        for index in (2 * pair_number, 2 * pair_number + 1):
            areas += float(counts[index]) * geometries[index].area_per_point_mm2
        radius = lattice.rles(occupied[pair_number])
        effective = areas / radius if areas > 0 else 0.0
        if config.quality.measure != "capture":
            capture = 1.0
        elif captures is None:
            capture = geometries[2 * pair_number].capture
        else:
            capture = float(captures[pair_number])
        share = (
            1.0
            if holding is None or config.quality.measure != "capture"
            else holding(
                pair_number,
                tuple(contact[ends[i] - lengths[i] : ends[i]] for i in (2 * pair_number, 2 * pair_number + 1)),
            )
        )
        measure = scenario_measure(capture, share, effective, config)
        offset_pair = (float(offsets[2 * pair_number]), float(offsets[2 * pair_number + 1]))
        results.append(ScreenedScenario(radius, areas, effective, offset_pair, capture, measure))
    measures = [r.measure for r in results]
    return ScreenedCandidate(float(min(measures)), float(np.mean(measures)), results, case)
