"""The generated test parts (examples/part_families.py): closed solids of every family, and splits that keep the
held-out families out of development."""

from __future__ import annotations

import pytest

from examples import part_families


@pytest.mark.parametrize("family", sorted(part_families.FAMILIES))
def test_every_family_draws_one_closed_solid_a_parallel_gripper_can_reach(family):
    for seed in (*part_families.DEVELOPMENT_SEEDS, *part_families.TEST_SEEDS):
        part = part_families.draw(family, seed)
        mesh = part.mesh
        assert mesh.is_watertight and mesh.body_count == 1 and mesh.volume > 0, (family, seed)
        # resting on the table, centred; some horizontal extent fits between 5 mm pads of a 50 mm gripper
        assert abs(mesh.bounds[0][2]) < 1e-9
        assert min(mesh.extents[:2]) <= 40.0, (family, seed, mesh.extents)
        assert part.caging == (family not in part_families.CONTROL_FAMILIES)


def test_the_same_family_and_seed_draw_the_same_part_and_other_seeds_another():
    first, again = part_families.draw("spur-gear", 0), part_families.draw("spur-gear", 0)
    other = part_families.draw("spur-gear", 100)
    assert first.description == again.description and (first.mesh.vertices == again.mesh.vertices).all()
    assert other.description != first.description


def test_development_never_sees_a_held_out_family_and_test_holds_all_of_them():
    development = {p.family for p in part_families.split("development", 2)}
    test = {p.family for p in part_families.split("test", 1)}
    assert not development & set(part_families.HELD_OUT_FAMILIES)
    assert set(part_families.HELD_OUT_FAMILIES) <= test and set(part_families.CONTROL_FAMILIES) <= development
    seeds = {p.seed for p in part_families.split("development", 2)} & {p.seed for p in part_families.split("test", 2)}
    assert not seeds
