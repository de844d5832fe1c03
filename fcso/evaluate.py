"""Exact evaluation of a candidate (METHOD §4-7): its pads carved, the parts seated, the quality scored.

Also the data every stage after sampling shares: a scenario (a part in a
stable pose) with its valid samples, each sample's pad geometries and
contact samples, and a candidate's evaluation.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import manifold3d
import numpy as np
import trimesh

from .capture import CandidateSqueeze, CaptureLandscape, SqueezedPart, pad_landscapes, sample_part
from .config import DesignConfig
from .contact import PadContact, SurfaceSamples, contact_seed, sample_surface, seat
from .geometry import rebuilt_from_mesh, to_manifold
from .grid import ScreenGrid, column_heights
from .holding import holding_forces_n
from .lead_in import FLAT_MARGIN, printed_draft, wider_drafts
from .measure import scenario_measure
from .pad import Fingerpad, PadGeometry, build_fingerpad, pad_geometry
from .parts import Part
from .printfit import carve, closing_travel_mm, open_thin_walls
from .rles import rles
from .sampler import SIDES, GraspSample, SamplerResult
from .screen import (
    NormalLattice,
    ScreenedCandidate,
    ScreenGeometry,
    prepare_geometry,
    screen,
    screened_bound,
)
from .verify_config import CAPTURE_CONDITIONS

#: Samples a process keeps squeezed (:meth:`SampleGeometry.squeezed_part`), 0.5-1.6 MB each (a 35 mm pad's part
#: turned by every start yaw): more than a set screening's candidates share, and a bound however many parts a job has.
SQUEEZED_KEPT = 160
#: Those samples by (id, key), the one squeezed last last.
_SQUEEZED_ORDER: dict[tuple[int, tuple], SampleGeometry] = {}


@dataclass
class SampleGeometry:
    """A valid sample with everything candidate evaluation needs from it.

    Its contact samples (:attr:`surfaces`) are drawn again from each pad
    geometry's surface whenever asked, with the seeds they were first drawn
    with (:func:`contact_seed`): the same points, and a job of thousands
    of samples does not keep them (a third of a sample's arrays), as only
    the candidates evaluated exactly and the holding of screened finalists
    read them.
    """

    sample: GraspSample
    frames: tuple[np.ndarray, np.ndarray]
    geometries: tuple[PadGeometry, PadGeometry]
    #: Each geometry's :func:`contact_seed`, and the density of its samples, per mm².
    surface_seeds: tuple[tuple[int, ...], tuple[int, ...]]
    surface_density_per_mm2: float
    effective_area_bound: float
    screen: tuple[ScreenGeometry, ScreenGeometry]
    screened_bound: float
    centres_uv_mm: tuple[np.ndarray, np.ndarray]
    #: Printed-fit carvings of ``geometries`` by (pad size, D, clearance, lead-in): a scenario chosen with the same
    #: sample in several designs of one job (its finger sets, the one finger they are compared with) is carved once.
    fitted: dict[tuple, list[PadGeometry]] = field(default_factory=dict, repr=False, compare=False)
    #: Holding shares of screened contacts by (the contact masks, [quality] and density): a part keeps the same
    #: contacts in most sets it is screened in, and holding costs six linear programs (:func:`screen_on_pad`).
    held: dict[tuple, float] = field(default_factory=dict, repr=False, compare=False)
    #: This sample squeezed for any pad by (grid, D, [verify]): a part's best samples are screened on many sets' pads.
    squeezed: dict[tuple, SqueezedPart] = field(default_factory=dict, repr=False, compare=False)
    #: The six holding forces (N) measured in this process, by the key of ``held``: a finalist's exact contacts are
    #: often its screened ones, and screenings and exact evaluations run in the same workers.
    forces: dict[tuple, np.ndarray] = field(default_factory=dict, repr=False, compare=False)

    def holding_n(self, scenario: Scenario, surfaces, contacts, normals_rest: np.ndarray, config: DesignConfig):
        """:func:`holding_n` of this sample's contacts (N), measured once per process and contacts."""
        key = holding_key(contacts, config)
        if key not in self.forces:
            self.forces[key] = holding_n(scenario, self, surfaces, contacts, normals_rest, config)
        return self.forces[key].copy()

    def squeezed_part(self, grid: ScreenGrid, config: DesignConfig) -> SqueezedPart:
        """:func:`fcso.capture.sample_part` of this sample on ``grid`` (cells in mm), made once per process while it is
        among the :data:`SQUEEZED_KEPT` samples squeezed last."""
        key = (grid.cell_mm, grid.count_v, grid.count_w, config.sampler.penetration_mm, config.verify.model_dump_json())
        if key not in self.squeezed:
            axis = self.sample.sliding_axis
            self.squeezed[key] = sample_part(self.screen, self.centres_uv_mm, self.width_mm, axis, grid, config)
        # the latest last; the earliest beyond the bound forgotten (the registry holds the sample: its id stays its)
        _SQUEEZED_ORDER[(id(self), key)] = _SQUEEZED_ORDER.pop((id(self), key), self)
        while len(_SQUEEZED_ORDER) > SQUEEZED_KEPT:
            (_, earliest), sample = next(iter(_SQUEEZED_ORDER.items()))
            del _SQUEEZED_ORDER[(id(sample), earliest)]
            sample.squeezed.pop(earliest, None)
        return self.squeezed[key]

    @property
    def width_mm(self) -> float:
        """The part's extent along the closing axis in the pads' footprint (``a_max - a_min``), mm."""
        return self.sample.a_max_mm - self.sample.a_min_mm

    @property
    def surfaces(self) -> tuple[SurfaceSamples, SurfaceSamples]:
        """The contact samples of the "+" and "-" geometries, pad frames (drawn anew: read once per use)."""
        return tuple(
            sample_surface(g.surface_vertices, g.surface_faces, self.surface_density_per_mm2, list(seed))
            for g, seed in zip(self.geometries, self.surface_seeds)
        )


@dataclass
class Scenario:
    """A part in one chosen stable pose, with its valid samples."""

    part_index: int
    part: Part
    pose_index: int
    probability: float
    rest_transform: np.ndarray
    mesh: trimesh.Trimesh
    sampler_result: SamplerResult
    samples: list[SampleGeometry] = field(default_factory=list)
    made_solid: manifold3d.Manifold | None = field(default=None, init=False, repr=False, compare=False)

    def solid(self) -> manifold3d.Manifold:
        """``mesh`` as a manifold3d solid, made once per process: every pad geometry of the scenario intersects it."""
        if self.made_solid is None:
            self.made_solid = to_manifold(self.mesh)
        return self.made_solid

    def __getstate__(self) -> dict:
        # a solid does not pickle: a process the scenario is sent to (a Dask worker) makes its own
        return {**self.__dict__, "made_solid": None}


@dataclass
class ScenarioEvaluation:
    """One candidate in one scenario: seating of both pads and the quality.

    ``capture`` (the pad as printed), ``holding_n`` (the six pushes) and
    ``measure`` follow METHOD §7b; under the paper's measure the first two
    are None and ``measure`` is E.
    """

    contacts: tuple[PadContact, PadContact]
    contact_normals: np.ndarray
    rles: float
    contact_area_mm2: float
    effective_area: float
    measure: float
    capture: CaptureLandscape | None = None
    holding_n: np.ndarray | None = None


@dataclass
class CandidateEvaluation:
    """A candidate evaluated exactly (METHOD §6-7); ``fingerpad`` only when asked to keep it.

    ``quality`` is the worst scenario's measure and ``mean_effective_area``
    the mean measure: Q and the mean E under the paper's measure.
    """

    choice: tuple[int, ...]
    scenarios: list[ScenarioEvaluation]
    quality: float
    mean_effective_area: float
    case: str
    block_depth_mm: float | None
    fingerpad: Fingerpad | None = None


def sample_geometry(
    part_manifold: manifold3d.Manifold,
    mesh: trimesh.Trimesh,
    sample: GraspSample,
    config: DesignConfig,
    seed,
    grid: ScreenGrid,
    lattice: NormalLattice,
) -> SampleGeometry:
    """A valid sample's pad geometries, contact samples, screening geometry and bounds (METHOD §4-5, §8b).

    ``seed`` is ``(scenario_number, sample_index)`` (see :func:`contact_samples`).
    """
    frames = tuple(sample.pad_frame(side, config.sampler) for side in SIDES)
    vertices, faces = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    geometries = tuple(pad_geometry(part_manifold, vertices, faces, f, config.sampler, config.filter) for f in frames)
    seeds = tuple(contact_seed(config, *seed, side_number) for side_number in range(len(geometries)))
    surfaces = tuple(
        sample_surface(g.surface_vertices, g.surface_faces, config.contact.sample_density_per_mm2, list(s))
        for g, s in zip(geometries, seeds)
    )
    # contact points and normals are subsets of these samples, so A <= the sampled
    # area and RLES >= the RLES of all sampled normals: E can never exceed this
    area = sum(len(s.points) * s.area_per_point_mm2 for s in surfaces)
    normals = np.vstack([s.normals @ f[:3, :3] for s, f in zip(surfaces, frames)])
    bound = area / rles(normals) if len(normals) else 0.0
    centres = tuple((f @ np.append(mesh.center_mass, 1.0))[:2] for f in frames)
    screens = tuple(
        prepare_geometry(
            column_heights(g.surface_vertices, g.surface_faces, grid),
            g.good,
            g.depth_mm,
            s.points,
            s.normals @ f[:3, :3],
            s.area_per_point_mm2,
            grid,
            lattice,
        )
        for g, s, f in zip(geometries, surfaces, frames)
    )
    if config.quality.measure == "capture":
        # screening ranks by the capture of this sample's pads alone; the exact stage measures the whole pad
        capture = printed_draft(
            [screens], [centres], [sample.a_max_mm - sample.a_min_mm], [sample.sliding_axis], config
        )[1][0]
        screens = tuple(dataclasses.replace(g, capture=capture) for g in screens)
    return SampleGeometry(
        sample=sample,
        frames=frames,
        geometries=geometries,
        surface_seeds=seeds,
        surface_density_per_mm2=config.contact.sample_density_per_mm2,
        effective_area_bound=float(bound),
        screen=screens,
        screened_bound=scenario_measure(screens[0].capture, 1.0, screened_bound(screens, lattice), config),
        centres_uv_mm=centres,
    )


def evaluate_candidate(
    scenarios: list[Scenario],
    choice: tuple[int, ...],
    config: DesignConfig,
    keep_pad: bool,
    fitted: bool = False,
    flat: bool = False,
    fingerpad: Fingerpad | None = None,
) -> CandidateEvaluation:
    """Carve, seat and score one candidate (METHOD §4-7).

    ``fitted`` (the chosen candidate) carves with the clearance and lead-in
    of ``[print]``, removes thin walls and lets the pads close the clearance
    (:mod:`fcso.printfit`); the search ranks candidates on exact pockets.
    ``flat`` carves nothing: flat pads (the case "bad") on the candidate's
    grasps, the pad delivered where no carving captures better (METHOD §7b).
    ``fingerpad``: the candidate's pad when already made so
    (:func:`candidate_fingerpad`, its thin walls opened when ``fitted``).
    """
    chosen = [scenario.samples[k] for scenario, k in zip(scenarios, choice)]
    fit = config.print.resolved()
    if fingerpad is None:
        fingerpad = candidate_fingerpad(scenarios, choice, config, fitted, flat)
        if fitted:
            fingerpad = dataclasses.replace(fingerpad, pad=opened_pad(fingerpad.pad, config))
    pad_mesh = fingerpad.pad.to_mesh()
    vertices = np.asarray(pad_mesh.vert_properties[:, :3], dtype=np.float64)
    faces = np.asarray(pad_mesh.tri_verts, dtype=np.int64)
    travel = closing_travel_mm(fit["clearance_mm"]) if fitted else 0.0
    drawn = [sample.surfaces for sample in chosen]
    seated = iter(seat([s for pair in drawn for s in pair], vertices, faces, config.contact.eps_mm, travel_mm=travel))
    by_capture = config.quality.measure == "capture"
    if by_capture:
        grid = ScreenGrid.for_config(config)
        # pad_landscapes with each sample squeezed once per process (SampleGeometry.squeezed_part)
        landscapes = CandidateSqueeze(
            [s.screen for s in chosen],
            [s.centres_uv_mm for s in chosen],
            [s.width_mm for s in chosen],
            [s.sample.sliding_axis for s in chosen],
            grid,
            config,
            [s.squeezed_part(grid, config) for s in chosen],
        ).landscapes(flat=flat)
    results = []
    for number, (scenario, sample, surfaces) in enumerate(zip(scenarios, chosen, drawn)):
        contacts = (next(seated), next(seated))
        normals = np.vstack([s.normals[c.contact] @ f[:3, :3] for s, c, f in zip(surfaces, contacts, sample.frames)])
        area = float(sum(c.contact_area_mm2 for c in contacts))
        radius = rles(normals) if len(normals) else 2.0
        effective = area / radius if area > 0 else 0.0
        if not by_capture:
            results.append(ScenarioEvaluation(contacts, normals, radius, area, effective, measure=effective))
            continue
        holding = sample.holding_n(scenario, surfaces, [c.contact for c in contacts], normals, config)
        holding_share = min(1.0, float(holding.min()) / config.verify.hold_force_n)
        # METHOD §5b: pads that meet each other before they squeeze the part hold nothing, whatever else it scores;
        # and a good geometry seats at t = 0 (§5): a good pad that stops short of that on a side is blocked there by
        # another geometry's pocket (each pad carries both sides' geometries, mirrored), so its nominal grasp leaves
        # the part off the pose the design gives the cell (a slotted block: 0 and 2.3 mm, 1.8 mm and 5 deg off)
        blocked = fingerpad.case == "good" and max(c.offset_mm for c in contacts) > config.verify.success_mm
        holds = landscapes[number].pads_gap_mm > 0 and not blocked
        measure = scenario_measure(landscapes[number].fraction, holding_share, effective, config) if holds else 0.0
        results.append(
            ScenarioEvaluation(contacts, normals, radius, area, effective, measure, landscapes[number], holding)
        )
    measures = [r.measure for r in results]
    return CandidateEvaluation(
        choice=choice,
        scenarios=results,
        quality=float(min(measures)),
        mean_effective_area=float(np.mean(measures)),
        case=fingerpad.case,
        block_depth_mm=fingerpad.block_depth_mm,
        fingerpad=fingerpad if keep_pad else None,
    )


def candidate_fingerpad(
    scenarios: list[Scenario], choice: tuple[int, ...], config: DesignConfig, fitted: bool = False, flat: bool = False
) -> Fingerpad:
    """A candidate's pad (METHOD §4-5) as :func:`evaluate_candidate` carves it, before any thin-wall opening.

    ``fitted`` carves the printed-fit pockets (made and kept with the samples when missing); ``flat`` carves
    nothing.
    """
    chosen = [scenario.samples[k] for scenario, k in zip(scenarios, choice)]
    if flat:
        geometries = []
    elif fitted:
        geometries = fitted_geometries(scenarios, chosen, config)
    else:
        geometries = [g for sample in chosen for g in sample.geometries]
    return build_fingerpad(geometries, config.sampler, config.filter)


def opened_pad(pad: manifold3d.Manifold, config: DesignConfig) -> manifold3d.Manifold:
    """``pad`` without the walls thinner than ``[print]``'s minimum (:func:`fcso.printfit.open_thin_walls`)."""
    sampler = config.sampler
    minimum = config.print.resolved()["min_wall_mm"]
    return open_thin_walls(pad, sampler.thickness_mm, sampler.length_mm, sampler.width_mm, minimum)


def screen_on_pad(
    scenarios: list[Scenario],
    choice: tuple[int, ...],
    config: DesignConfig,
    lattice: NormalLattice,
    holding: bool = False,
    captures: list[float] | None = None,
    squeezed: dict[tuple[int, int], SqueezedPart] | None = None,
    landscapes: dict | None = None,
) -> ScreenedCandidate:
    """Screen a candidate as its exact evaluation measures it: capture on the pad the whole candidate carves.

    The search screens with the capture of each sample's pads alone and full
    holding; on the candidate's pad another scenario's pocket may take a part
    off its seat and bury its contacts. Here every scenario's capture comes
    from the landscapes :func:`evaluate_candidate` measures (the same
    :func:`fcso.capture.pad_landscapes`, a few milliseconds), and with
    ``holding`` its holding from its screened contacts (the same
    :func:`holding_n`: six linear programs per scenario, tenths of a second).
    Under the paper's measure this is :func:`fcso.screen.screen`.

    Parameters
    ----------
    scenarios : list of Scenario
        With their samples.
    choice : tuple of int
        One sample index per scenario.
    config : DesignConfig
    lattice : NormalLattice
    holding : bool
        Measure holding too (default: full holding, as the search assumes).
    captures : list of float, optional
        Every scenario's capture on this candidate's pad when already known (the same candidate screened on its pad
        before, without holding): its landscapes are not measured again.
    squeezed : dict, optional
        Filled with the samples squeezed (:func:`fcso.capture.sample_part`) by scenario position and sample index;
        each sample keeps its own (:meth:`SampleGeometry.squeezed_part`), so candidates sharing it squeeze it once.
    landscapes : dict, optional
        Landscapes of other candidates with the same ``config`` (:class:`fcso.capture.CandidateSqueeze`'s ``known``).

    Returns
    -------
    ScreenedCandidate
    """
    chosen = [scenario.samples[k] for scenario, k in zip(scenarios, choice)]
    screens = [sample.screen for sample in chosen]
    if config.quality.measure != "capture":
        return screen(screens, config, lattice)
    if captures is None:
        # under the draft the candidate would be printed with: ranked under the default lead-in only, a pad that
        # captures fully once drafted wider lost to one that captures half at any draft (METHOD §5b)
        # each sample squeezed once per process (SampleGeometry.squeezed_part), whichever candidates share it
        grid = ScreenGrid.for_config(config)
        parts = [sample.squeezed_part(grid, config) for sample in chosen]
        if squeezed is not None:
            squeezed.update(zip(enumerate(choice), parts))
        _, captures, _ = printed_draft(
            screens,
            [s.centres_uv_mm for s in chosen],
            [s.width_mm for s in chosen],
            [s.sample.sliding_axis for s in chosen],
            config,
            parts,
            landscapes,
        )

    def holding_share(number: int, contacts: tuple[np.ndarray, np.ndarray]) -> float:
        sample = chosen[number]
        key = holding_key(contacts, config)
        if key not in sample.held:
            surfaces = sample.surfaces
            normals = np.vstack([s.normals[c] @ f[:3, :3] for s, c, f in zip(surfaces, contacts, sample.frames)])
            held = (
                sample.holding_n(scenarios[number], surfaces, contacts, normals, config)
                if len(normals)
                else np.zeros(1)
            )
            sample.held[key] = min(1.0, float(held.min()) / config.verify.hold_force_n)
        return sample.held[key]

    return screen(screens, config, lattice, captures=captures, holding=holding_share if holding else None)


def holding_key(contacts, config: DesignConfig) -> tuple:
    """What a sample's holding forces depend on beside the sample: its contact masks per pad, the test's conditions
    and the print's density (the key of :attr:`SampleGeometry.held` and :attr:`SampleGeometry.forces`)."""
    conditions = tuple(getattr(config.verify, name) for name in CAPTURE_CONDITIONS)
    return (*(np.packbits(c).tobytes() for c in contacts), conditions, config.print.resolved()["density_g_cm3"])


def holding_n(
    scenario: Scenario,
    sample: SampleGeometry,
    surfaces: tuple[SurfaceSamples, SurfaceSamples],
    contacts,
    normals_rest: np.ndarray,
    config: DesignConfig,
) -> np.ndarray:
    """The six holding forces of one seated grasp (METHOD §7b), N.

    ``surfaces``: the sample's contact samples (:attr:`SampleGeometry.surfaces`); ``contacts``: per pad, the mask of
    its contact samples in contact; ``normals_rest``: theirs, stacked.
    """
    points = np.vstack(
        [
            (np.linalg.inv(f) @ np.column_stack([s.points[c], np.ones(int(c.sum()))]).T).T[:, :3]
            for s, c, f in zip(surfaces, contacts, sample.frames)
        ]
    )
    pads = np.concatenate([np.full(int(c.sum()), side) for side, c in enumerate(contacts)])
    density = config.print.resolved()["density_g_cm3"]
    conditions = config.verify
    return holding_forces_n(
        points,
        -normals_rest,
        pads,
        sample.sample.closing_axis,
        np.asarray(scenario.mesh.center_mass),
        float(scenario.mesh.volume) * density * 1e-6,
        conditions.friction,
        conditions.force_limit_n,
        conditions.hold_force_n,
    )


@dataclass
class VersusFlat:
    """One scenario's chosen pad against flat pads on the same grasp (METHOD §7b, §12).

    Attributes
    ----------
    capture, flat : CaptureLandscape
        The chosen pad's landscape as printed, and flat pads'.
    beats_flat : bool
        Some pad screened or evaluated captures more than flat pads by :data:`FLAT_MARGIN`.
    """

    capture: CaptureLandscape
    flat: CaptureLandscape
    beats_flat: bool


def versus_flat(
    scenarios: list[Scenario], best: CandidateEvaluation, finalists, config: DesignConfig
) -> list[VersusFlat | None]:
    """Every scenario's chosen pad against flat pads; None each under the paper's measure."""
    if best.scenarios[0].capture is None:
        return [None] * len(scenarios)
    grid = ScreenGrid.for_config(config)
    compared = []
    for number, scenario in enumerate(scenarios):
        chosen = best.scenarios[number].capture
        sample = scenario.samples[best.choice[number]]
        flat = pad_landscapes(
            [sample.screen],
            [sample.centres_uv_mm],
            [sample.width_mm],
            [sample.sample.sliding_axis],
            grid,
            config,
            flat=True,
        )[0]
        tried = max(
            [chosen.fraction]
            + [e.scenarios[number].capture.fraction for e in finalists]
            + [g.screen[0].capture for g in scenario.samples]
        )
        compared.append(VersusFlat(chosen, flat, tried > flat.fraction + FLAT_MARGIN))
    return compared


def printed_lead_in_deg(scenarios: list[Scenario], choice, config: DesignConfig) -> tuple[float, str | None]:
    """The draft a candidate is printed with: ``lead_in_deg``, or a wider one that captures more (METHOD §7b).

    A pocket's lead-in bounds the start errors it guides in: at depth D and
    clearance c a draft opens the pocket by (D + c) tan(angle) per side
    (METHOD §9c), 1.18 mm at 15°, D = 4 mm and c = 0.4 mm, under the ±2 mm
    of the precision test (measured with the earlier pocket: a ribbed block
    seated 5/10 with 15°, 10/10 with 30° and 45°). A wider draft also lets a
    part ride up and out more easily, so it is taken only when its worst
    scenario's capture gains at least :data:`FLAT_MARGIN`; among equal
    captures the smallest angle.

    Parameters
    ----------
    scenarios : list of Scenario
    choice : sequence of int
        The candidate: one sample per scenario.
    config : DesignConfig

    Returns
    -------
    lead_in_deg : float
        Degrees.
    why : str or None
        A sentence when a wider draft was taken.
    """
    if not wider_drafts(config):
        # nothing to choose among: the captures printed_draft would measure (a landscape per scenario) go unused
        return config.print.resolved()["lead_in_deg"], None
    samples = [scenario.samples[number] for scenario, number in zip(scenarios, choice)]
    angle, _, why = printed_draft(
        [s.screen for s in samples],
        [s.centres_uv_mm for s in samples],
        [s.width_mm for s in samples],
        [s.sample.sliding_axis for s in samples],
        config,
        [s.squeezed_part(ScreenGrid.for_config(config), config) for s in samples],
    )
    return angle, why


def fit_key(config: DesignConfig) -> tuple | None:
    """What a printed-fit carving depends on besides its sample: (pad size, D, clearance, lead-in); None without a
    fit (the exact ``I_n`` are carved).
    """
    fit, sampler = config.print.resolved(), config.sampler
    if fit["clearance_mm"] <= 0 and fit["lead_in_deg"] <= 0:
        return None
    size = (sampler.thickness_mm, sampler.length_mm, sampler.width_mm)
    return size, sampler.penetration_mm, fit["clearance_mm"], fit["lead_in_deg"]


def fitted_sample(scenario: Scenario, sample: SampleGeometry, config: DesignConfig) -> list[PadGeometry]:
    """A sample's geometries with each good one's ``I_n`` replaced by its printed-fit carving (``fit_key`` not None).

    Each carving is rebuilt from its mesh (:func:`fcso.geometry.rebuilt_from_mesh`): the same solid whether it was
    carved here or by a worker.
    """
    sampler, fit = config.sampler, config.print.resolved()
    size = (sampler.thickness_mm, sampler.length_mm, sampler.width_mm)
    part = scenario.solid()
    made = []
    for geometry, frame in zip(sample.geometries, sample.frames):
        if geometry.good:
            carved = carve(part, frame, size, sampler.penetration_mm, fit["clearance_mm"], fit["lead_in_deg"])
            geometry = dataclasses.replace(geometry, intersection=rebuilt_from_mesh(carved))
        made.append(geometry)
    return made


def fitted_geometries(
    scenarios: list[Scenario], chosen: list[SampleGeometry], config: DesignConfig
) -> list[PadGeometry]:
    """The chosen samples' geometries with each good one's ``I_n`` replaced by its printed-fit carving.

    Carvings already made for a sample (:attr:`SampleGeometry.fitted`) are reused, new ones kept there.
    """
    key = fit_key(config)
    if key is None:
        return [g for sample in chosen for g in sample.geometries]
    fitted = []
    for scenario, sample in zip(scenarios, chosen):
        if key not in sample.fitted:
            sample.fitted[key] = fitted_sample(scenario, sample, config)
        fitted.extend(sample.fitted[key])
    return fitted
