"""The ``[verify]`` settings (METHOD §12): the simulated precision and holding tests, whose conditions the capture
measure predicts too (a section of :class:`fcso.config.DesignConfig`).
"""

from __future__ import annotations

import os
from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field

#: Candidates verified in the measure's order before one is delivered (the daemon's [verify] top_k and
#: ``fcso design --verify``): the choice stops each at its first failed trial, so a few cost little more than one.
DEFAULT_TOP_K = 3


#: The ``[verify]`` settings the capture measure predicts the tests with: its start errors, success tolerances,
#: friction, grip force and holding push.
CAPTURE_CONDITIONS = (
    "position_error_mm",
    "yaw_error_deg",
    "success_mm",
    "success_deg",
    "friction",
    "force_limit_n",
    "hold_force_n",
)


class VerifyConfig(BaseModel):
    """``[verify]``: physics, trials and thresholds of the simulated precision and holding tests (METHOD §12).

    The capture measure (``[quality]``) predicts these tests under the same conditions (:data:`CAPTURE_CONDITIONS`).
    """

    model_config = ConfigDict(extra="forbid")

    trials: int = Field(10, ge=0, description="Perturbed precision trials per scenario and finger")
    seed: int = Field(0, description="Seed of the trial perturbations")
    position_error_mm: float = Field(
        2.0, ge=0, description="Start position error, uniform in -x..x along each table axis, mm"
    )
    yaw_error_deg: float = Field(
        3.0, ge=0, description="Start rotation error about the vertical, uniform in -x..x, degrees"
    )
    closing_speed_mm_s: float = Field(20.0, gt=0, description="Finger closing speed, mm/s")
    force_limit_n: float = Field(60.0, gt=0, description="Grip force limit per finger, N")
    friction: float = Field(0.4, ge=0, description="Coulomb friction coefficient of every contact")
    density_g_cm3: float = Field(1.01, gt=0, description="Part material density (PA12: 1.01), g/cm³")
    descent_speed_mm_s: float = Field(100.0, gt=0, description="Approach speed of the gripper, mm/s")
    lift_mm: float = Field(100.0, ge=0, description="Lift after closing, mm")
    lift_speed_mm_s: float = Field(100.0, gt=0, description="Lift speed, mm/s")
    hold_force_n: float = Field(30.0, gt=0, description="Largest push of the holding test, N")
    hold_ramp_n_s: float = Field(60.0, gt=0, description="Rate of the holding push, N/s")
    slip_mm: float = Field(
        1.0, gt=0, description="Holding test: the part slipped when it moved this far in the gripper, mm"
    )
    slip_deg: float = Field(2.0, gt=0, description="... or turned this far, degrees")
    success_mm: float = Field(0.3, gt=0, description="Precision trial succeeds within this position error, mm")
    success_deg: float = Field(1.0, gt=0, description="... and this rotation error, degrees")
    pass_success_rate: float = Field(
        1.0,
        ge=0,
        le=1,
        description="A scenario passes when the designed finger's success rate reaches this (paper: 10 of 10) "
        "and it holds as well as flat pads",
    )
    stop_early: bool = Field(
        True,
        description="Choosing among candidates: stop a candidate's precision trials once it can no longer reach "
        "pass_success_rate (with 10 trials and rate 1.0: at its first failed trial), skip its holding test and its "
        "further scenarios: the verdict is that of the full run, the trials that ran keep their results (the flat "
        "control runs the same trials). The delivered candidate always runs every trial and the holding test "
        "(METHOD §12b); false runs every trial of every candidate too",
    )
    hold_tolerance_n: float = Field(
        1.0,
        ge=0,
        description="The designed finger holds as well as flat pads when, pushed in each direction, it slips at most "
        "this much earlier, N (the ramp's overshoot between a slip's start and its detection)",
    )
    timestep_s: float = Field(0.001, gt=0, description="Physics time step, s")
    open_margin_mm: float = Field(
        5.0,
        gt=0,
        description="How far each pad's face clears the part's outermost point in its footprint as the gripper "
        "descends, before it closes (at most the gripper's full opening), mm: a flat pad's face is at that point at "
        "the seated grasp and a carved pad's is the penetration D inside it, so the designed finger opens D further "
        "than the flat control and both clear the part alike (opening both by this much would leave a carved "
        "pocket's rims D closer to the part than the flat pads)",
    )
    part_shell_mm: float = Field(
        1.0,
        gt=0,
        description="Depth of the part's collision prisms under its surface where the pads reach it (less where the "
        "part is thinner), mm: a pad pushed deeper than half of it into the part would be pushed out the wrong side; "
        "the contacts sink about 0.1-0.25 mm at 60 N and the pads move at most 0.1 mm per 1 ms time step",
    )
    max_seated_penetration_mm: float = Field(
        0.2,
        gt=0,
        description="Largest overlap of part and pad pieces at the nominal seated grasp without a warning, mm",
    )
    arena_mb: float | None = Field(
        None,
        gt=0,
        description="MuJoCo's memory (arena) for one simulation's contacts, constraints and solver, MB; null: sized "
        "from the part's and the pads' collision pieces (16 MiB and 32 KiB per piece, fcso.sim.scene)",
    )
    arena_retry_factor: float = Field(
        4.0,
        ge=1,
        description="A scenario whose simulation runs out of its arena is simulated again once with this many times "
        "the arena; if it runs out again, or with 1 (no retry), the scenario fails with the reason",
    )
    choice_budget_s: float = Field(
        600.0,
        gt=0,
        description="Choosing among candidates (--verify-top, the daemon's top_k): no further candidate is verified "
        "once this much time went into the choice, s",
    )
    jobs: int = Field(
        0,
        ge=0,
        description="Worker processes of the grasps and holding pushes (forked; 0: every available core, as the "
        "design's [search] jobs); the results do not depend on it",
    )
    cache_dir: Path | None = Field(
        None,
        description="Where collision pieces and the outcomes of simulations are cached; default $FCSO_CACHE_DIR or "
        "~/.cache/fcso",
    )
    reuse_simulations: bool = Field(
        True,
        description="Read a grasp's or holding push's outcome from the cache when the same simulation ran before "
        "(the same collision geometry, start pose, settings, trial code, library versions and processor "
        "architecture: MuJoCo repeats it to the last bit), e.g. a verification restarted after a kill, or the same "
        "parts verified again; false simulates every one again (and stores it)",
    )

    def cache_path(self) -> Path:
        """The collision pieces' cache folder."""
        if self.cache_dir is not None:
            return Path(self.cache_dir)
        return Path(os.environ.get("FCSO_CACHE_DIR") or Path.home() / ".cache" / "fcso")
