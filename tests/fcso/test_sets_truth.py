"""Finger sets judged by truth (issue 48): a set whose simulated finger fails a scenario that its part's own finger
passes does not serve that part.

The parts: a hexagonal prism and a plain cylinder standing on their bases
(examples/sim_parts.py). Alone, the prism's finger seats it in every precision
trial (6 of 6, flat pads 0 of 6, measured once); on the finger designed for
both, the cylinder's round groove takes the prism off its V pocket's seat and
it fails trials. With ``min_retained = 0`` the measure lets them share one
finger; the simulation does not.
"""

from __future__ import annotations

import pytest

import fcso
from examples.sim_parts import hex_prism, plain_cylinder
from fcso.config import VerifyConfig
from fcso.output.sets_page import pick_plan_text
from fcso.parts import Part
from fcso.report.models import VerifiedSetScenario
from fcso.sets import design_sets
from fcso.sets.truth import SetsTruth

HEX = Part(name="hex", path="hex.stl", mesh=hex_prism())
CYLINDER = Part(name="cylinder", path="cylinder.stl", mesh=plain_cylinder(12.0, 30.0))


@pytest.fixture(scope="module")
def truth_cache(tmp_path_factory):
    """The module's cache of collision pieces and simulation outcomes. Both tests simulate the prism's and the
    cylinder's fingers (the same designs, the same [verify] settings): outcomes are stored under the hash of all
    that determines them (:mod:`fcso.sim.outcomes`), so the second reads them with the same results instead of
    simulating them again."""
    return tmp_path_factory.mktemp("sets-truth-cache")


def truth_config(cache_dir, **finger_sets) -> fcso.DesignConfig:
    return fcso.DesignConfig().updated(
        {
            "poses": {"count": 1, "select": "most_probable"},
            # one pad size: the sets are designed, and simulated, once
            "sampler": {"length_mm": 20.0},
            # a budget no machine spends: the outcome must not depend on how fast the simulations run
            "finger_sets": {"min_retained": 0.0, "truth_budget_s": 1.0e9, **finger_sets},
            "verify": {"trials": 6, "cache_dir": str(cache_dir)},
        }
    )


def test_a_part_its_shared_finger_fails_where_its_own_passes_gets_its_own_set(truth_cache):
    sets = design_sets([HEX, CYLINDER], truth_config(truth_cache, max=2)).report
    attempts = sets.search.attempts
    # the premise: by the measure alone one finger serves both (min_retained 0), and its simulated finger fails the
    # prism where the prism's own finger passes
    shared = next(a for a in attempts if a.source == "search")
    assert shared.sets == 1 and shared.designed and not shared.chosen
    moved = next(a for a in attempts if a.source == "moved_by_truth")
    assert moved.chosen and moved.parts == [["hex"], ["cylinder"]]
    truth = sets.truth
    assert truth.moved_parts == ["hex"] and truth.not_served_parts == [] and truth.unverified_sets == []
    assert [s.parts for s in sets.sets] == [["hex"], ["cylinder"]]
    # the delivered sets as simulated: the prism on its own finger passes every trial, flat pads fail
    hex_set = truth.sets[0].scenarios[0]
    assert hex_set.part == "hex" and hex_set.passed and hex_set.successes == hex_set.trials == 6
    assert hex_set.flat_successes < hex_set.flat_trials
    assert 0 < truth.spent_s and sets.not_served == [] and sets.sets_needed == 2
    # the terminal and the page tell it
    told = pick_plan_text(sets)
    assert "moved to a set of their own: hex" in told and "set 1 verified: hex pose 0 6/6" in told


#: A smaller hexagonal prism: on a finger shared with the cylinder it fails too (measured once, checked below).
HEX_22 = Part(name="hex-22", path="hex-22.stl", mesh=hex_prism(22.0))


def test_a_part_its_shared_finger_fails_with_no_set_left_is_not_served(truth_cache):
    # the paper's filter: with wrapped faces the finger the smaller prism shares with the cylinder wraps its ends
    # and passes it
    config = truth_config(truth_cache, max=2, unserved_fallback="manual").updated({"filter": {"wrapped_faces": False}})
    sets = design_sets([HEX, HEX_22, CYLINDER], config).report
    # the premise: by the measure one finger serves all three; truth moves the first part it fails (hex) to the one
    # set left, and the smaller prism, failing on the finger it shares with the cylinder, has no set left
    shared = next(a for a in sets.search.attempts if a.source == "search")
    assert shared.sets == 1 and not shared.chosen
    assert [s.parts for s in sets.sets] == [["hex"], ["hex-22", "cylinder"]]
    truth = sets.truth
    assert truth.moved_parts == ["hex"] and truth.not_served_parts == ["hex-22"]
    # named in the report and routed to the fallback in the pick plan, never to the finger that fails it
    [entry] = sets.not_served
    assert entry.part == "hex-22" and entry.fallback == "manual" and entry.best_set == 2
    assert entry.reason.startswith("verified: fails where its own finger passes")
    assert sorted(p.part for step in sets.pick_plan for p in step.parts) == ["cylinder", "hex"]
    assert sets.sets_needed is None
    assert "not served: 1 x hex-22 to manual (verified: fails where its own finger passes" in pick_plan_text(sets)


def _simulated(part: str, successes: int, flat_successes: int) -> VerifiedSetScenario:
    return VerifiedSetScenario(
        part=part,
        pose_index=0,
        trials=10,
        successes=successes,
        flat_trials=10,
        flat_successes=flat_successes,
        passed=successes == 10,
    )


def test_a_part_its_shared_finger_seats_less_often_than_flat_pads_is_not_served_by_it():
    # the verdicts of bench_sets' 12-part job (set 2, simulated at 91605b6): the shared finger beats flat pads on the
    # solar tracker and loses to them on the knob; the after-job choice keeps a finger that flat pads do not beat on
    # every part, so the set's verdict must name the knob. No simulation runs here (budget 0): the rule is judged on
    # the verdicts as the simulation gave them, and the part's own finger is not needed to judge it.
    shared, knob_alone = frozenset({0, 1}), frozenset({1})
    truth = SetsTruth(
        made=lambda members: pytest.fail(f"no finger is made for {members}: the verdicts are known"),
        names=["solar_tracker", "knob-narrowing-1"],
        budget_s=0.0,
        verify_config=VerifyConfig(),
        verified={
            shared: {
                ("solar_tracker", 0): _simulated("solar_tracker", 1, 0),
                ("knob-narrowing-1", 0): _simulated("knob-narrowing-1", 0, 4),
            },
            knob_alone: {("knob-narrowing-1", 0): _simulated("knob-narrowing-1", 2, 4)},
        },
    )
    assert truth.unserved(shared) == [1]
    assert truth.reasons == {1: "verified: seats it less often than flat pads (pose 0 0/10 against flat 4/10)"}
    # alone, the part is its own design's: its choice by truth delivers flat pads where they beat it
    assert truth.unserved(knob_alone) == []


def test_a_job_of_one_distinct_part_is_not_judged_by_truth_during_its_design(tmp_path):
    # one part, as many copies as the job likes, has no finger to share: its set is its own finger, which the choice
    # by truth after the design verifies. Simulating it during the design too ran every trial and push of each pad
    # size's finger for the report alone (three sizes of a shipped daemon's plain block: 79 s)
    copies = [HEX, Part(name="hex-copy", path="hex-copy.stl", mesh=hex_prism())]
    sets = design_sets(copies, truth_config(tmp_path / "cache", max=2)).report
    assert [s.parts for s in sets.sets] == [["hex"]] and sets.truth is None
    # nothing was simulated: no collision piece, no outcome in the cache
    assert not (tmp_path / "cache").exists() or not any((tmp_path / "cache").iterdir())
