"""Stable poses and their selection (METHOD §2); configuration loading."""

import numpy as np
import pytest
from scipy.spatial import Delaunay

from fcso import ConfigError, load_config, load_part, stable_poses
from fcso.config import DesignConfig, PosesConfig
from fcso.poses import select_poses, toppling_poses
from fcso.sim.config import load_verify_config
from tests.conftest import REPO, data_path


@pytest.fixture(scope="module")
def bunny_poses():
    part = load_part(data_path("stanford_bunny_closed.ply"), scale_to_mm=65.0)
    return part, *stable_poses(part.mesh)


@pytest.mark.parametrize(
    "name, units, scale",
    [
        ("stanford_bunny_closed.ply", "mm", 65.0),
        ("20mm-xyz-cube.stl", "mm", None),
        ("busted.STL", "inch", None),
        ("featuretype.STL", "inch", None),
    ],
)
def test_toppling_poses_are_trimesh_stable_poses(name, units, scale):
    import trimesh

    mesh = load_part(data_path(name), units=units, scale_to_mm=scale).mesh
    expected_transforms, expected_probabilities = trimesh.poses.compute_stable_poses(mesh.copy())
    transforms, probabilities = toppling_poses(mesh)
    assert len(probabilities) == len(expected_probabilities) > 1
    assert np.array_equal(transforms, expected_transforms)
    # the same arithmetic in another order: trimesh 5 sums a pose's probability otherwise (1e-11 relative)
    assert probabilities == pytest.approx(expected_probabilities, rel=1e-9, abs=1e-15)


def test_poses_rest_on_the_table_centred(bunny_poses):
    part, transforms, probabilities = bunny_poses
    assert probabilities.sum() == pytest.approx(1.0)
    assert np.all(np.diff(probabilities) <= 0)
    for transform in transforms:
        assert np.allclose(transform[:3, :3] @ transform[:3, :3].T, np.eye(3), atol=1e-9)
        assert np.linalg.det(transform[:3, :3]) == pytest.approx(1.0)
        rested = part.mesh.copy()
        rested.apply_transform(transform)
        lower, upper = rested.bounds
        assert lower[2] == pytest.approx(0.0, abs=1e-9)
        assert (lower[:2] + upper[:2]) / 2 == pytest.approx([0.0, 0.0], abs=1e-9)
        assert rested.extents[0] >= rested.extents[1] - 1e-9
        # resting: the centre of mass lies above the support polygon
        support = rested.vertices[rested.vertices[:, 2] < 1e-6][:, :2]
        assert len(support) >= 3
        assert Delaunay(support).find_simplex(rested.center_mass[:2]) >= 0


def test_selection_random_seeded_most_probable_and_explicit():
    probabilities = np.array([0.4, 0.3, 0.2, 0.1])
    first, _ = select_poses(probabilities, PosesConfig(count=2, select="random", seed=5), 0, "p")
    again, _ = select_poses(probabilities, PosesConfig(count=2, select="random", seed=5), 0, "p")
    assert first == again and len(set(first)) == 2
    seen = {
        tuple(select_poses(probabilities, PosesConfig(count=2, select="random", seed=s), 0, "p")[0]) for s in range(20)
    }
    assert len(seen) > 1
    # the default: the most probable poses, whatever the seed
    assert {tuple(select_poses(probabilities, PosesConfig(count=2, seed=s), 0, "p")[0]) for s in range(20)} == {(0, 1)}
    assert select_poses(probabilities, PosesConfig(count=3, select="most_probable"), 0, "p")[0] == [0, 1, 2]
    assert select_poses(probabilities, PosesConfig(select=[3, 1]), 0, "p")[0] == [1, 3]
    chosen, warnings = select_poses(probabilities, PosesConfig(count=9, select="most_probable"), 0, "p")
    assert chosen == [0, 1, 2, 3] and "only 4 stable poses" in warnings[0]
    with pytest.raises(ConfigError, match="pose indices \\[7\\]"):
        select_poses(probabilities, PosesConfig(select=[7]), 0, "p")


def test_config_from_toml_and_defaults(tmp_path):
    paper = load_config(REPO / "examples" / "paper.toml")
    assert paper.poses.select == [1, 3] and paper.sampler.stride == 4.0
    defaults = DesignConfig()
    # the default pad sizes: 10, 20 and 35 mm long, 20 mm wide, each with its own stride and least contact
    sized = [one.sampler for one in defaults.pad_size_configs()]
    assert [(s.length_mm, s.width_mm) for s in sized] == [(10.0, 20.0), (20.0, 20.0), (35.0, 20.0)]
    assert [s.stride for s in sized] == [2.0, 4.0, 7.0]
    assert [s.min_contact_area for s in sized] == pytest.approx([0.1 * 10 * 20, 0.1 * 20 * 20, 0.1 * 35 * 20])
    bad = tmp_path / "bad.toml"
    bad.write_text("[gripper]\nmax_opening_mm = -3\n")
    with pytest.raises(ConfigError, match="gripper.max_opening_mm"):
        load_config(bad)
    bad.write_text("[sampler\n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_config(bad)
    with pytest.raises(ConfigError, match="file not found"):
        load_config(tmp_path / "missing.toml")
    relative = tmp_path / "finger.toml"
    relative.write_text(
        '[finger]\nmesh = "f.stl"\ncontact_origin_mm = [0, 0, 0]\ncontact_normal = [1, 0, 0]\nup = [0, 0, 1]\n'
    )
    assert load_config(relative).finger.mesh == tmp_path / "f.stl"


def test_the_capture_measure_reads_its_test_conditions_from_verify(tmp_path):
    # one home: the start errors, tolerances, friction and forces are [verify]'s, which the measure predicts
    path = tmp_path / "conditions.toml"
    path.write_text("[verify]\nposition_error_mm = 1.5\nforce_limit_n = 45\n")
    config = load_config(path)
    assert config.verify.position_error_mm == 1.5 and config.verify.force_limit_n == 45
    assert load_verify_config(path).force_limit_n == 45
    path.write_text("[quality]\ngrip_force_n = 45\n")
    with pytest.raises(ConfigError, match="quality.grip_force_n: unknown key"):
        load_config(path)
