"""Configuration of the method as pydantic models, loadable from TOML.

Every length is in millimetres (suffix ``_mm``), every area in mm² (``_mm2``),
every angle in degrees (``_deg``). Defaults follow METHOD.md and the paper's
reference experiment (Robotiq Hand-E, L = W = 20, T = 5, D = 4).
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from .errors import ConfigError
from .verify_config import VerifyConfig


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


#: One pad dimension, mm, or a short list of them to design with each (METHOD §3b).
PadSize = (
    Annotated[float, Field(gt=0)] | Annotated[list[Annotated[float, Field(gt=0)]], Field(min_length=1, max_length=4)]
)


class SamplerConfig(_Section):
    """Pad box size and the sliding-window grasp sampler (METHOD §3)."""

    # small features need small pads: a 20 mm pad over an 8 mm slot sees mostly flat face, which METHOD §5's filter
    # labels bad, and the design stays flat; a 10 mm pad carves them. 20 mm stays for long rows of notches, where it
    # captures more, and 35 mm for features that lie at both ends of a face (a dovetail's flanks, a prism's edges),
    # which only a pad spanning the face reaches at once.
    length_mm: PadSize = Field(
        [10.0, 20.0, 35.0],
        description="Pad length L along the sliding axis b, mm; a short list: every length is designed and the best "
        "kept (METHOD §3b: small features need short pads, and a pad longer than the part's face wraps its edges)",
    )
    width_mm: PadSize = Field(
        20.0, description="Pad width W along the vertical axis, mm; a short list: as length_mm, every pair is designed"
    )
    thickness_mm: float = Field(5.0, gt=0, description="Pad thickness T along the closing axis, mm")
    penetration_mm: float = Field(4.0, gt=0, description="Penetration D of the pad into the part, 0 < D < T, mm")
    stride_mm: float | None = Field(None, gt=0, description="Sampling step along b and z, mm; default L/5")
    yaw_deg: list[float] = Field(
        default_factory=lambda: [0.0, 90.0],
        min_length=1,
        description="Yaw angles of the closing axis about the table normal, degrees, "
        "in the rested part's bounding-box frame",
    )
    table_clearance_mm: float = Field(
        1.0,
        ge=0,
        description="Lowest pad height above the table and the clearance the part needs between the open pads, mm",
    )
    min_contact_area_mm2: float | None = Field(
        None, ge=0, description="Least part surface inside each pad box, mm²; default 10 % of L x W"
    )
    feature_positions: bool = Field(
        True,
        description="Besides the stride, centre pads on the part's features: the concave intervals of its extent "
        "profile along b and along the height (METHOD §3b); false is the paper's sampler",
    )
    face_yaws: bool = Field(
        True,
        description="Besides yaw_deg, close square to the part's flat side faces that yaw_deg misses (a chamfer, a "
        "hexagon's face) and into the pockets of its outline the others miss (a notch off the bounding box's axes); "
        "at most one more yaw per scenario for each (fcso.closing_yaws.face_yaws, pocket_yaws); false: yaw_deg only, "
        "the paper's sampler",
    )

    @model_validator(mode="after")
    def _penetration_inside_pad(self) -> SamplerConfig:
        if not self.penetration_mm < self.thickness_mm:
            raise ValueError(
                f"penetration_mm ({self.penetration_mm}) must be smaller than thickness_mm ({self.thickness_mm})"
            )
        return self

    def pad_sizes(self) -> list[tuple[float, float]]:
        """Every (L, W) pair to design with, mm: one unless ``length_mm`` or ``width_mm`` is a list."""
        lengths = self.length_mm if isinstance(self.length_mm, list) else [self.length_mm]
        widths = self.width_mm if isinstance(self.width_mm, list) else [self.width_mm]
        return [(float(length), float(width)) for length in dict.fromkeys(lengths) for width in dict.fromkeys(widths)]

    @property
    def stride(self) -> float:
        """Sampling step in mm (``stride_mm`` or L/5)."""
        return self.stride_mm if self.stride_mm is not None else self.length_mm / 5.0

    @property
    def min_contact_area(self) -> float:
        """Least contact area per side in mm² (``min_contact_area_mm2`` or 0.1 L W)."""
        if self.min_contact_area_mm2 is not None:
            return self.min_contact_area_mm2
        return 0.1 * self.length_mm * self.width_mm


class GripperConfig(_Section):
    """Parallel-jaw gripper with linear closing (default: Robotiq Hand-E)."""

    max_opening_mm: float = Field(50.0, gt=0, description="Distance between the finger mounting faces fully open, mm")
    min_opening_mm: float = Field(0.0, ge=0, description="Distance between the finger mounting faces fully closed, mm")
    finger_height_mm: float = Field(
        25.0, ge=0, description="Height of the finger body above the pad, checked for collisions, mm"
    )

    @model_validator(mode="after")
    def _opening_order(self) -> GripperConfig:
        if self.min_opening_mm >= self.max_opening_mm:
            raise ValueError("min_opening_mm must be smaller than max_opening_mm")
        return self


class FilterConfig(_Section):
    """Good/bad geometry filter (METHOD §5)."""

    volume_ratio_threshold: float = Field(0.1, ge=0, le=1, description="Threshold th on R = (V_B - V_I)/V_B")
    block_factor: float = Field(1.5, gt=0, description="K: block depth d_B = K x min(d_n of good geometries)")
    cluster_angle_deg: float = Field(
        15.0, gt=0, lt=90, description="Angle for normal clustering and the flatness test, degrees"
    )
    full_cover_fraction: float = Field(
        0.99, gt=0, le=1, description="Fraction of the pad face a cross-section must cover to count as full"
    )
    # on by default: with drafted pockets whose clearance becomes depth (METHOD §9c) the wrapped end walls centre the
    # part instead of leaving it the clearance as play, and block-like parts whose only features are their own
    # edges (a boss's base, a shouldered block, a plain box) are caged where the paper's filter leaves them flat
    wrapped_faces: bool = Field(
        True,
        description="A face flat against the pad that ends inside the pad at both ends of its length is good: the "
        "pocket's end walls wrap the part's edges and capture it along the pads (METHOD §3b); false is the paper's "
        "filter, which labels every flat face bad",
    )


class PosesConfig(_Section):
    """Which stable poses of each part to plan for (METHOD §2)."""

    count: int = Field(2, ge=1, description="Number of stable poses per part, N_p")
    # A part on a table rests in its probable poses: a uniform draw over all
    # stable poses (the paper's wording, kept as "random") picked a tilted
    # pose of probability < 1 % on a notched cube and found no grasp there.
    # The most probable ones, not a probability-weighted draw: the same part
    # always gets the same poses, and no draw can land on a rare one.
    select: Literal["random", "most_probable"] | list[int] = Field(
        "most_probable",
        description="'most_probable' (the count most probable poses), "
        "'random' (uniform over all stable poses, seeded), "
        "or explicit pose indices (0 = most probable)",
    )
    seed: int = Field(0, description="Seed of the random pose selection (select = 'random')")


class ContactConfig(_Section):
    """Contact evaluation by seating (METHOD §6)."""

    eps_mm: float = Field(
        0.05, gt=0, description="Contact tolerance: part points within eps of the pad are in contact, mm"
    )
    sample_density_per_mm2: float = Field(
        4.0, gt=0, description="Surface samples per mm² of part surface inside a pad box"
    )
    seed: int = Field(0, description="Seed of the surface sampling")


class SearchConfig(_Section):
    """Candidate search (METHOD §8, §8b): screening ranks, the best are re-evaluated exactly."""

    max_exhaustive: int = Field(20000, ge=1, description="Screen every candidate when there are at most this many")
    max_evaluations: int = Field(
        4000,
        ge=1,
        description="Screened candidates beyond max_exhaustive: branch and bound, then coordinate ascent from seeds",
    )
    exact_top_k: int = Field(8, ge=8, description="Best screened candidates re-evaluated exactly (METHOD §8b: k >= 8)")
    pad_top_k: int = Field(
        32,
        ge=1,
        description="Best screened candidates screened again under the capture measure with every scenario's capture "
        "measured on the pad the whole candidate carves, as the exact evaluation measures it (METHOD §7b, §8b); the "
        "exact_top_k are chosen among them, and a finger set's screening keeps their best",
    )
    report_candidates: int = Field(
        1000, ge=1, description="Best screened candidates listed in report.json (exact ones always are)"
    )
    jobs: int = Field(0, ge=0, description="Worker processes; 0: every available core")


class PartsConfig(_Section):
    """How part files become parts (overlapping shells are always united)."""

    split_bodies: bool = Field(
        True, description="Separate solids in one file become separate parts <file>#<k>; false refuses such a file"
    )
    repair_max_volume_change_percent: float = Field(
        5.0,
        gt=0,
        description=(
            "A repair (--repair, fcsod's default) that changes the shells' volume by more than this, %, is refused "
            "(hole patches and dropped shells; overlaps united are not a change)"
        ),
    )
    repair_max_deviation_mm: float = Field(
        5.0, gt=0, description="A repair that puts a corner farther than this from the file's triangles is refused, mm"
    )


class FingerConfig(_Section):
    """The flat finger the pad is fused onto (METHOD §9).

    Without ``mesh`` the built-in parametric Hand-E-sized finger is used and
    the frame fields are ignored. With ``mesh``, ``contact_origin_mm`` is the
    centre of the pad's back face on the finger's contact face,
    ``contact_normal`` the face's inward normal (towards the gripped part) and
    ``up`` the finger's up direction (away from the fingertip), all in the
    mesh's own coordinates after unit scaling.
    """

    mesh: Path | None = Field(None, description="Flat finger mesh file; none: built-in parametric finger")
    units: Literal["mm", "inch", "m"] | float = Field(
        "mm", description="Unit of the finger mesh: mm, inch, m or a factor to mm"
    )
    contact_origin_mm: tuple[float, float, float] | None = Field(
        None, description="Centre of the contact face where the pad's back face goes, mm (finger mesh coordinates)"
    )
    contact_normal: tuple[float, float, float] | None = Field(
        None, description="Inward unit normal of the contact face (towards the part), finger mesh coordinates"
    )
    up: tuple[float, float, float] | None = Field(None, description="Up direction of the finger (away from the tip)")
    overlap_mm: float = Field(0.2, gt=0, description="Overlap of pad and finger so the union is one solid, mm")

    @model_validator(mode="after")
    def _frame_with_mesh(self) -> FingerConfig:
        if self.mesh is not None:
            missing = [k for k in ("contact_origin_mm", "contact_normal", "up") if getattr(self, k) is None]
            if missing:
                raise ValueError(
                    f"finger mesh {self.mesh} needs its contact-face frame: set {', '.join(missing)} in [finger]"
                )
        return self


#: Printer profiles of ``[print]``: the defaults each profile gives the keys left unset.
#: Sources (design guides read 2026-11; values per side of a fit, mm):
PRINT_PROFILES: dict[str, dict[str, float]] = {
    "mjf-pa12": {
        # HP Multi Jet Fusion design guidelines, "Connecting parts": a gap of at least
        # 0.4 mm between interface areas (+-0.2 mm of tolerance for each part)
        "clearance_mm": 0.4,
        # design value, the same for every profile (see README "Printed fit"): at D = 4 mm
        # a 15 degree draft opens the pocket by (D + c) tan 15 = 1.18 mm per side at the pad face (METHOD §9c)
        "lead_in_deg": 15.0,
        # HP MJF design guidelines, "Wall thickness": 0.5 mm for short walls along Z
        # (0.3 mm in the XY plane); the larger, orientation-free value
        "min_wall_mm": 0.5,
        # HP 3D High Reusability PA 12 data sheet, density of parts 1.01 g/cm3 (METHOD §12)
        "density_g_cm3": 1.01,
    },
    "fdm-pla": {
        # Original Prusa i3 MK3S user manual §10.3.5 "Tolerances": 0.10 very tight,
        # 0.15 tight, 0.20 mm loose; loose, so the part slides in without force
        "clearance_mm": 0.2,
        "lead_in_deg": 15.0,
        # two perimeters at PrusaSlicer's default 0.45 mm extrusion width for a 0.4 mm nozzle
        "min_wall_mm": 0.9,
        # Stratasys PLA spec sheet, specific gravity 1.264 (ASTM D792); PLA is 1.24-1.26
        "density_g_cm3": 1.25,
    },
    "sla-resin": {
        # stereolithography fits: tight 0.15 mm, loose 0.3 mm; Formlabs-style tolerance
        # +-0.15 mm; tight, since resin parts shrink on post-cure (0.05-0.1 mm)
        "clearance_mm": 0.15,
        "lead_in_deg": 15.0,
        # Formlabs SLA design rules: supported walls 0.4 mm, unsupported walls 0.6 mm
        "min_wall_mm": 0.6,
        # typical cured methacrylate photopolymer, 1.1-1.2 g/cm3: not from a data sheet
        # of a named resin; set density_g_cm3 for yours
        "density_g_cm3": 1.15,
    },
    # the exact pocket of METHOD §4: no clearance, no lead-in, no thin-wall removal
    "custom": {"clearance_mm": 0.0, "lead_in_deg": 0.0, "min_wall_mm": 0.0, "density_g_cm3": 1.01},
}


class PrintConfig(_Section):
    """How the finger is printed: clearance, lead-in and minimum wall of the pocket (``[print]``).

    ``profile`` gives every key a default (:data:`PRINT_PROFILES`); a key set
    explicitly overrides the profile. The default, ``mjf-pa12``, is the
    paper's printer and material (METHOD §9b); ``custom`` is the exact pocket
    of METHOD §4 (the paper's Table I, ``examples/paper.toml``). Read the
    effective values with :meth:`resolved`.
    """

    profile: Literal["mjf-pa12", "fdm-pla", "sla-resin", "custom"] = Field(
        "mjf-pa12",
        description="Printer profile giving the defaults; mjf-pa12: the paper's HP Multi Jet Fusion in PA12; "
        "custom: zero clearance, lead-in and minimum wall (the exact pocket)",
    )
    clearance_mm: float | None = Field(
        None,
        ge=0,
        description="Gap between the part and its pocket, mm: with a lead-in the drafted pocket is carved this much "
        "deeper and seats the part that much deeper on its drafted walls (METHOD §9c); without one the pocket is "
        "carved from the part grown by it",
    )
    lead_in_deg: float | None = Field(
        None,
        ge=0,
        lt=60,
        description="Draft of the pocket walls, wider at the pad face and exact at depth, degrees; 0 disables",
    )
    lead_in_alternatives_deg: list[Annotated[float, Field(gt=0, lt=60)]] = Field(
        [30.0, 45.0],
        description="Wider drafts printed instead of lead_in_deg when the chosen pad captures more of the start errors "
        "with one (METHOD §7b: by at least 2 of 20 starts; the widest capture, then the smallest angle), degrees; "
        "only when lead_in_deg > 0; [] always prints lead_in_deg",
    )
    min_wall_mm: float | None = Field(
        None,
        ge=0,
        description="Thinnest pad wall kept: thinner walls and slivers are removed after carving, mm; 0 disables",
    )
    density_g_cm3: float | None = Field(
        None, gt=0, description="Density of the printed part material, for the simulation's mass, g/cm³"
    )

    def resolved(self) -> dict[str, float]:
        """The effective ``clearance_mm``, ``lead_in_deg``, ``min_wall_mm`` and ``density_g_cm3``.

        Explicit keys over the profile's.
        """
        values = dict(PRINT_PROFILES[self.profile])
        values.update({k: v for k in values if (v := getattr(self, k)) is not None})
        return values


class QualityConfig(_Section):
    """How candidates are ranked (METHOD §7 and §7b).

    The capture measure predicts the simulated tests, so its start errors,
    tolerances, friction and forces are ``[verify]``'s (:data:`CAPTURE_CONDITIONS`).
    """

    measure: Literal["capture", "paper"] = Field(
        "capture",
        description="'capture': worst scenario of capture x min(1, holding / [verify] hold_force_n) in bands of 1/20, "
        "then E (METHOD §7b, fcso.measure); "
        "'paper': Q = worst E (METHOD §7, the paper's experiment)",
    )


class FingerSetsConfig(_Section):
    """How many finger sets a job may use and what each part must keep (METHOD §11, ``[finger_sets]``)."""

    max: Annotated[int, Field(ge=1)] | Literal["auto"] = Field(
        4,
        description="Most finger sets (fingers the cell changes between) for one job; "
        "1: one finger for every part, the paper's method; 'auto': the fewest sets that serve every part at "
        "min_retained (as many as the job's distinct parts at most), the report saying how many it needs",
    )
    min_retained: float = Field(
        0.5,
        ge=0,
        le=1,
        description="Least retained quality E / E* every graspable scenario should keep in its set "
        "(E*: its solo best E)",
    )
    screen_samples: int = Field(
        10,
        ge=1,
        description="Best samples per scenario (by solo screened E) that the partition search screens sets with",
    )
    screen_evaluations: int = Field(
        1000, ge=1, description="Screened candidates per set while the partition is searched (final sets use [search])"
    )
    exhaustive_parts: int = Field(
        5,
        ge=1,
        le=8,
        description="Jobs with at most this many distinct graspable parts try every partition (proof under screening)",
    )
    pairs_per_part: int = Field(
        8,
        ge=1,
        description="Beyond exhaustive_parts, pairs of parts quick-screened per part: every pair while there are at "
        "most 2 x this + 1 parts, else each part's this many nearest neighbours by what it carves (and the pairs of "
        "the 2 x max most dissimilar parts), so the pair screenings grow linearly with the parts",
    )
    unserved_fallback: Literal["flat_fingers", "manual"] = Field(
        "manual",
        description="Where the pick plan sends a part that no finger set serves (its set keeps less than "
        "min_retained of its solo quality): 'flat_fingers', the cell's plain flat fingers, or 'manual', picked by "
        "hand; never the set's finger",
    )

    truth_budget_s: float = Field(
        0.0,
        ge=0,
        description="Sets judged by truth: seconds the simulation ([verify], METHOD §12) of the delivered sets' "
        "fingers may take during the design, with the parts' own fingers designed for it. A shared finger that fails "
        "a scenario its part's own finger passes, or seats the part in fewer precision trials than flat pads, does "
        "not serve that part: the part gets a set of its own while max allows, else it is not_served. No "
        "simulation starts once this much time went into it; 0: off (sets judged by the measure alone)",
    )

    def sets_allowed(self, parts: int) -> int:
        """The most sets a job of ``parts`` distinct graspable parts may use: ``max``, or with ``"auto"`` one per
        part (every part alone keeps its solo quality)."""
        return max(1, parts) if self.max == "auto" else self.max


class ComputeConfig(_Section):
    """Where a design's parallel work runs (``[compute]``)."""

    scheduler: str | None = Field(
        None,
        description="Address of a Dask distributed scheduler, e.g. 'tcp://host:8786': the design's tasks run on its "
        "workers (each needs this fcso installed). None: forked worker processes on this machine ([search] jobs). "
        "The results are the same either way",
    )


class DesignConfig(_Section):
    """Every setting of ``fcso design``."""

    parts: PartsConfig = Field(default_factory=PartsConfig)
    sampler: SamplerConfig = Field(default_factory=SamplerConfig)
    gripper: GripperConfig = Field(default_factory=GripperConfig)
    filter: FilterConfig = Field(default_factory=FilterConfig)
    poses: PosesConfig = Field(default_factory=PosesConfig)
    contact: ContactConfig = Field(default_factory=ContactConfig)
    search: SearchConfig = Field(default_factory=SearchConfig)
    finger: FingerConfig = Field(default_factory=FingerConfig)
    print: PrintConfig = Field(default_factory=PrintConfig)
    finger_sets: FingerSetsConfig = Field(default_factory=FingerSetsConfig)
    quality: QualityConfig = Field(default_factory=QualityConfig)
    verify: VerifyConfig = Field(default_factory=VerifyConfig)
    # where the work runs changes no result: left out of dumps, so a report is the same on a cluster and locally
    compute: ComputeConfig = Field(default_factory=ComputeConfig, exclude=True)

    def pad_size_configs(self) -> list[DesignConfig]:
        """One copy of these settings per pad size of ``[sampler]`` (:meth:`SamplerConfig.pad_sizes`), each with a
        single length and width."""
        return [
            self.updated({"sampler": {"length_mm": length, "width_mm": width}})
            for length, width in self.sampler.pad_sizes()
        ]

    def updated(self, overrides: dict) -> DesignConfig:
        """Return a copy with ``{"section": {"key": value}}`` overrides applied and validated."""
        merged = dict(self.model_dump(), compute=self.compute.model_dump())
        for section, values in overrides.items():
            if isinstance(values, dict) and isinstance(merged.get(section), dict):
                merged[section].update(values)
            else:
                merged[section] = values
        return DesignConfig.model_validate(merged)


def format_validation_error(error: ValidationError) -> str:
    """One line per defect, each naming the dotted key, e.g. ``sampler.length_mm: ...``."""
    parts = []
    for item in error.errors():
        key = ".".join(str(p) for p in item["loc"]) or "(top level)"
        message = item["msg"]
        if item["type"] == "extra_forbidden":
            message = "unknown key"
        parts.append(f"{key}: {message}")
    return "; ".join(parts)


def read_toml(path: str | Path) -> dict:
    """Read a TOML file into a dict.

    Raises
    ------
    ConfigError
        Missing or unreadable file, or a TOML syntax error, naming the file.
    """
    path = Path(path)
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(path, "file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(path, f"cannot read: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(path, f"not valid TOML: {exc}") from None


def load_config(path: str | Path) -> DesignConfig:
    """Load a :class:`DesignConfig` from a TOML file.

    Parameters
    ----------
    path : str or Path
        TOML file with sections ``[parts] [sampler] [gripper] [filter] [poses]
        [contact] [search] [finger] [print] [finger_sets] [quality] [verify]``.

    Returns
    -------
    DesignConfig

    Raises
    ------
    ConfigError
        Unreadable file, TOML syntax error, unknown key or bad value; the
        message names the file and the key.
    """
    path = Path(path)
    data = read_toml(path)
    finger = data.get("finger")
    if isinstance(finger, dict) and isinstance(finger.get("mesh"), str):
        # a relative finger mesh is relative to the config file, not the cwd
        finger["mesh"] = (
            str((path.parent / finger["mesh"]).resolve()) if not Path(finger["mesh"]).is_absolute() else finger["mesh"]
        )
    try:
        return DesignConfig.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(path, format_validation_error(exc)) from None
