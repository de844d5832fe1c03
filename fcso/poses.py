"""Stable resting poses of a part on the table (METHOD §2)."""

from __future__ import annotations

import numpy as np
import trimesh

from .config import PosesConfig
from .errors import ConfigError


def rest_transform(mesh: trimesh.Trimesh, transform: np.ndarray) -> np.ndarray:
    """Complete a stable-pose rotation into the resting frame.

    After ``transform`` the part is turned about the table normal so that its
    smallest-area bounding rectangle in x-y is axis-aligned with the longer
    side along x (the "bounding-box frame" of the yaw angles), then moved so
    that min z = 0 and the bounding-box centre in x and y is at the origin.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The part in its file frame (mm).
    transform : (4, 4) float
        A stable pose from :func:`trimesh.poses.compute_stable_poses`.

    Returns
    -------
    (4, 4) float
        File frame to resting frame.
    """
    vertices = trimesh.transform_points(mesh.convex_hull.vertices, transform)
    planar, extents = trimesh.bounds.oriented_bounds_2D(vertices[:, :2])
    turn = np.eye(4)
    turn[:2, :2] = planar[:2, :2]
    turn[:2, 3] = planar[:2, 2]
    if extents[1] > extents[0] + 1e-9:
        quarter = np.array([[0.0, -1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
        turn = quarter @ turn
    rested = turn @ transform
    points = trimesh.transform_points(vertices, turn)
    lower, upper = points.min(axis=0), points.max(axis=0)
    shift = np.eye(4)
    shift[:3, 3] = [-(lower[0] + upper[0]) / 2.0, -(lower[1] + upper[1]) / 2.0, -lower[2]]
    return shift @ rested


def stable_poses(mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    """Quasi-static stable poses with their probabilities, most probable first.

    Returns
    -------
    transforms : (k, 4, 4) float
        File frame to resting frame (see :func:`rest_transform`).
    probabilities : (k,) float
        Probability of landing in each pose; they sum to 1.
    """
    transforms, probabilities = trimesh.poses.compute_stable_poses(mesh)
    order = np.argsort(-np.asarray(probabilities), kind="stable")
    rested = np.array([rest_transform(mesh, transforms[i]) for i in order])
    probabilities = np.asarray(probabilities, dtype=float)[order]
    return rested, probabilities / probabilities.sum()


def select_poses(probabilities: np.ndarray, config: PosesConfig, part_index: int, part_name: str) -> tuple[list[int], list[str]]:
    """Choose which stable poses of one part to plan for.

    Parameters
    ----------
    probabilities : (k,) float
        From :func:`stable_poses` (most probable first).
    config : PosesConfig
        ``count``, ``select`` ('random', 'most_probable' or indices), ``seed``.
    part_index : int
        Position of the part in the batch; mixed into the seed so that two
        identical parts do not always get the same random poses.
    part_name : str
        For messages.

    Returns
    -------
    indices : list of int
        Ascending pose indices.
    warnings : list of str
    """
    available = len(probabilities)
    warnings = []
    if isinstance(config.select, list):
        bad = [i for i in config.select if not 0 <= i < available]
        if bad:
            raise ConfigError("poses.select", f"pose indices {bad} do not exist for {part_name} ({available} stable poses)")
        return sorted(set(config.select)), warnings
    count = config.count
    if count > available:
        warnings.append(f"{part_name}: {count} poses asked for, only {available} stable poses exist")
        count = available
    if config.select == "most_probable":
        return list(range(count)), warnings
    rng = np.random.default_rng([config.seed, part_index])
    return sorted(int(i) for i in rng.choice(available, size=count, replace=False)), warnings
