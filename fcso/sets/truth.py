"""Finger sets judged by truth (issue 48): a set's finger simulated (METHOD §12) against each part's own finger.

A set whose verified finger fails a scenario that its part's solo finger
would pass is not a serving set for that part, nor is one that seats the part
in fewer precision trials than flat pads do. The delivered sets' fingers are
simulated within ``[finger_sets] truth_budget_s``; where a set of two or more
parts fails a scenario, the part's own finger (the set of that part alone,
designed as any set is, chosen by truth as the job would deliver it) is simulated, and a part it passes is named
(:meth:`SetsTruth.unserved`) for the partition search to move
(:func:`fcso.sets.judged.search_judged_exactly`), as is a part the set's
finger seats less often than flat pads. A set's finger is delivered with flat
pads only when flat pads beat it on every part (:func:`fcso.sim.choose.verify_top`);
a shared finger that beats them on one part and loses on another would
otherwise reach the cell for both.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass

from ..config import VerifyConfig
from ..pipeline import DesignResult
from ..report.models import SetsTruthReport, VerifiedSet, VerifiedSetScenario
from ..verify_config import DEFAULT_TOP_K
from .partition import PartitionOutcome

#: ``made(set_of_parts)``: the set's finished design (its finger made), or None when it cannot be made.
MadeSet = Callable[[frozenset[int]], DesignResult | None]


@dataclass
class SetsTruth:
    """The simulated verdicts of a job's sets, within a time budget.

    Attributes
    ----------
    made : callable
        A set's finished design (:data:`MadeSet`); a part's own finger is its set alone.
    names : list of str
        Every part's name (a set's members are indices into it), as its scenarios name it.
    budget_s : float
        Time allowed, s (simulations and the parts' own fingers designed for them): no verification starts once it
        is spent.
    verify_config : VerifyConfig
        The ``[verify]`` settings of the simulation (the design's, with its print profile's density).
    verified : dict
        Set of parts -> per scenario ``(part, pose_index) -> VerifiedSetScenario``, every set simulated (a part's
        set alone as its choice by truth delivers it, once the part was judged against its own finger).
    solo_passes : dict
        ``(part, part name, pose_index)`` -> whether the part's own finger passes that scenario (None: MuJoCo refused
        its scene).
    unsimulated : dict
        Set of parts -> why MuJoCo could not simulate its finger (the set is judged by the measure).
    reasons : dict
        Part -> why the last set judged for it does not serve it, as the report tells it.
    spent_s : float
        Time spent so far, s: the simulations and the parts' own fingers designed for them.
    """

    made: MadeSet
    names: list[str]
    budget_s: float
    verify_config: VerifyConfig
    verified: dict[frozenset[int], dict[tuple[str, int], VerifiedSetScenario]] = dataclasses.field(default_factory=dict)
    solo_passes: dict[tuple[int, str, int], bool | None] = dataclasses.field(default_factory=dict)
    unsimulated: dict[frozenset[int], str] = dataclasses.field(default_factory=dict)
    reasons: dict[int, str] = dataclasses.field(default_factory=dict)
    spent_s: float = 0.0

    def left(self) -> bool:
        return self.spent_s < self.budget_s

    def unserved(self, members: frozenset[int]) -> list[int]:
        """Parts of set ``members`` its simulated finger does not serve: those it seats in fewer precision trials than
        flat pads in a scenario, and those it fails in a scenario their own finger passes; empty for a set of one part
        (its own choice by truth delivers flat pads where they beat it), and for whatever the budget leaves
        unsimulated. Why, per part: :attr:`reasons`."""
        if len(members) < 2:
            return []
        verdicts = self._verified(members)
        failing: dict[int, list[tuple[str, int]]] = {}
        unserved: list[int] = []
        for part in sorted(members):
            mine = {key: s for key, s in (verdicts or {}).items() if key[0] == self.names[part]}
            below_flat = [s for s in mine.values() if s.successes < s.flat_successes]
            if below_flat:
                unserved.append(part)
                self.reasons[part] = (
                    "verified: seats it less often than flat pads ("
                    + ", ".join(
                        f"pose {s.pose_index} {s.successes}/{s.trials} against flat {s.flat_successes}/{s.flat_trials}"
                        for s in below_flat
                    )
                    + ")"
                )
            elif failed := [key for key, s in mine.items() if not s.passed]:
                failing[part] = failed
        for part, keys in failing.items():
            passes = self._solo_passes(part, keys)
            for key in keys:
                verdicts[key] = verdicts[key].model_copy(update={"solo_passed": passes.get(key)})
            if any(passes.values()):
                unserved.append(part)
                self.reasons[part] = "verified: fails where its own finger passes"
        return sorted(unserved)

    def report(self, outcome: PartitionOutcome) -> SetsTruthReport:
        """The report of the delivered partition's sets (set order) as simulated, with what moved and what is left
        unserved; the rest of the budget goes to the sets not yet simulated (a set of one part is simulated only for
        the report)."""
        delivered = [
            frozenset(p for p, a in enumerate(outcome.assignment) if a == label)
            for label in range(max(outcome.assignment) + 1)
        ]
        for members in delivered:
            self._verified(members)
        return SetsTruthReport(
            budget_s=self.budget_s,
            spent_s=round(self.spent_s, 3),
            sets=[
                VerifiedSet(set=label, scenarios=list(self.verified[members].values()))
                for label, members in enumerate(delivered, start=1)
                if members in self.verified
            ],
            unverified_sets=[label for label, m in enumerate(delivered, start=1) if m not in self.verified],
            moved_parts=[self.names[p] for p in outcome.moved_by_truth],
            not_served_parts=[self.names[p] for p in outcome.unserved_by_truth],
            notes=[
                f"{' + '.join(self.names[p] for p in sorted(m))}: not simulated: {why}"
                for m, why in self.unsimulated.items()
            ],
        )

    def _verified(self, members: frozenset[int]) -> dict[tuple[str, int], VerifiedSetScenario] | None:
        """Every scenario of set ``members`` simulated in full (every trial and the holding test, designed and flat:
        what the verification after the job repeats from the simulation cache), once; None when the budget is
        spent or its finger cannot be made."""
        if members in self.verified or members in self.unsimulated or not self.left():
            return self.verified.get(members)
        from ..sim.verify import design_under_test, verify_delivered

        clock = time.perf_counter()
        design = self.made(members)
        verification = None if design is None else self._simulated(verify_delivered, design_under_test(design), members)
        if verification is not None:
            self.verified[members] = _verdicts(verification)
        self.spent_s += time.perf_counter() - clock
        return self.verified.get(members)

    def _solo_passes(self, part: int, keys: list[tuple[str, int]]) -> dict[tuple[str, int], bool]:
        """Whether ``part``'s own finger passes each of its scenarios ``keys``: the finger the choice by truth delivers
        for the set of that part alone (:func:`fcso.sim.choose.verify_top` over its :data:`DEFAULT_TOP_K` best
        candidates and its other pad sizes, within what is left of the budget), as the job would deliver it there.
        Judging only the measure's best candidate would keep a part on a shared finger that fails it where the
        choice for it alone passes. Missing when the budget is spent."""
        todo = [key for key in keys if (part, *key) not in self.solo_passes]
        if todo and self.left():
            from ..sim.choose import verify_top

            clock = time.perf_counter()
            design = self.made(frozenset([part]))
            if design is not None:
                verification = self._simulated(
                    lambda result, config: verify_top(result, DEFAULT_TOP_K, config)[1],
                    design,
                    frozenset([part]),
                    stop_early=True,
                    choice_budget_s=max(self.budget_s - self.spent_s, 1e-3),
                )
                if verification is None:
                    self.solo_passes.update({(part, *key): None for key in todo})
                else:
                    # the part's set alone is judged by the finger its choice delivers, not its measure's candidate
                    self.verified[frozenset([part])] = _verdicts(verification)
                    self.solo_passes.update({(part, s.part, s.pose_index): s.passed for s in verification.scenarios})
            self.spent_s += time.perf_counter() - clock
        return {key: self.solo_passes[(part, *key)] for key in keys if (part, *key) in self.solo_passes}

    def _simulated(self, run, design, members: frozenset[int], **settings):
        """``run(design, [verify] settings)``, or None when MuJoCo refuses the scene (a compile error of its
        collision pieces): the set is then judged by the measure, and the report says why (``notes``)."""
        try:
            return run(design, self.verify_config.model_copy(update=settings))
        except ValueError as error:  # MuJoCo's model compiler: e.g. "mesh volume is too small"
            self.unsimulated[members] = str(error).splitlines()[0]
            return None


def _verdicts(verification) -> dict[tuple[str, int], VerifiedSetScenario]:
    """Per scenario ``(part, pose_index)``, the verdict of a complete :class:`fcso.sim.report.VerificationReport`."""
    from ..sim.report import successes

    return {
        (s.part, s.pose_index): VerifiedSetScenario(
            part=s.part,
            pose_index=s.pose_index,
            trials=len(s.fcso.trials),
            successes=successes(s.fcso.trials),
            flat_trials=len(s.flat.trials),
            flat_successes=successes(s.flat.trials),
            passed=s.passed,
        )
        for s in verification.scenarios
    }
