"""A finger set is chosen by truth among every pad size of the job (METHOD §3b), as a job of its parts alone is."""

from __future__ import annotations

import fcso
from examples.part_families import draw
from fcso.parts import Part
from fcso.sets.other_sizes import OtherSizes
from fcso.sim.choose import verify_top
from fcso.sim.config import VerifyConfig


def test_a_sets_choice_by_truth_designs_the_pad_sizes_the_job_did_not_design_for_its_parts(tmp_path):
    # the notched bar of the development split at the 20 mm pads, as a finger set is designed at its job's size:
    # none of the measure's 3 best candidates passes there, and a 10 mm pad's candidate seats it 10/10 in both poses
    # (tests/fcso/test_sim_choose.py). A job whose other sizes grouped the bar with other parts designed no 10 mm
    # finger for it: the choice designs one when it gets there
    drawn = draw("notched-bar", 0)
    part = Part(name=drawn.name, path=drawn.name, mesh=drawn.mesh)
    config = fcso.DesignConfig()
    result = fcso.design([part], config.updated({"sampler": {"length_mm": 20.0}}))
    result.other_sizes = OtherSizes.of(result, [], [part], config, repair=False)
    assert [c.sampler.length_mm for c in result.other_sizes.to_design] == [10.0, 35.0]
    assert result.other_sizes.designed == []

    chosen, verification, _, _ = verify_top(result, 3, VerifyConfig(cache_dir=tmp_path))

    assert verification.passed and verification.choice.startswith("pad size 10 x 20 mm, candidate ")
    assert chosen.report.settings.sampler.length_mm == 10.0
    assert all(len(s.fcso.trials) == 10 and s.fcso.success_rate == 1.0 for s in verification.scenarios)
    # designed only as far as the choice went: the 35 mm pads were not needed
    assert [d.report.settings.sampler.length_mm for d in result.other_sizes.designed] == [10.0]
