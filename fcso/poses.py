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
    transforms, probabilities = toppling_poses(mesh)
    order = np.argsort(-np.asarray(probabilities), kind="stable")
    rested = np.array([rest_transform(mesh, transforms[i]) for i in order])
    probabilities = np.asarray(probabilities, dtype=float)[order]
    return rested, probabilities / probabilities.sum()


def toppling_poses(mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    """Quasi-static stable poses: :func:`trimesh.poses.compute_stable_poses` at its defaults, without networkx.

    The same algorithm step for step (Goldberg et al.'s toppling graph on
    the convex hull, the centre of mass of a uniform solid): every hull face
    gets the probability of landing on it first, an unstable face topples
    over the first neighbour (in ``face_adjacency`` order) whose edge the
    centre of mass projects across, else the last, and the probabilities
    flow along the toppling edges in trimesh's breadth-first waves. Faces
    whose normals agree to 3 decimals are one pose. The graph library's
    per-face Python made this 0.2 s of a 3 s command.

    Returns
    -------
    transforms : (k, 4, 4) float
        Rotation onto the table (new z up) with the hull just touching it.
    probabilities : (k,) float
        Most probable first, as trimesh orders them.
    """
    hull = mesh.convex_hull
    com = mesh.center_mass
    triangles, normals, count = hull.triangles, hull.face_normals, len(hull.faces)
    # probability of landing on each face first: its solid angle from the centre of mass (L'Huilier)
    rays = triangles - com
    rays = rays / np.sqrt((rays**2).sum(axis=2))[:, :, None]
    side = [np.arccos(np.clip((rays[:, i] * rays[:, (i + 1) % 3]).sum(axis=1), -1.0, 1.0)) for i in range(3)]
    half = (side[0] + side[1] + side[2]) / 2.0
    with np.errstate(invalid="ignore"):
        probability = (
            np.arctan(
                np.sqrt(
                    np.tan(half / 2)
                    * np.tan((half - side[0]) / 2)
                    * np.tan((half - side[1]) / 2)
                    * np.tan((half - side[2]) / 2)
                )
            )
            / np.pi
        )
    # a face is unstable when the centre of mass projects outside it
    distances = trimesh.util.diagonal_dot(normals, com - triangles[:, 0])
    projected = com - distances[:, None] * normals
    unstable = np.flatnonzero(np.any(trimesh.triangles.points_to_barycentric(triangles, projected) < 0, axis=1))
    # every hull face has three neighbours, in the order face_adjacency lists them
    pairs, edges = hull.face_adjacency, hull.face_adjacency_edges
    owners = np.concatenate([pairs[:, 0], pairs[:, 1]])
    rows = np.concatenate([np.arange(len(pairs)), np.arange(len(pairs))])
    by_face = np.lexsort((rows, owners))
    neighbour = np.concatenate([pairs[:, 1], pairs[:, 0]])[by_face].reshape(count, 3)
    edge = np.concatenate([edges, edges])[by_face].reshape(count, 3, 2)
    v1, v2 = hull.vertices[edge[:, :, 0]], hull.vertices[edge[:, :, 1]]
    centre, normal, point = hull.triangles_center[:, None, :], normals[:, None, :], projected[:, None, :]
    flip = (np.cross(v1 - centre, v2 - centre) * normal).sum(axis=2) < 0
    v1, v2 = np.where(flip[:, :, None], v2, v1), np.where(flip[:, :, None], v1, v2)
    crosses = (_orientation(centre, v1, v1 + normal, point) >= 0) & (_orientation(centre, v2 + normal, v2, point) >= 0)
    # the first neighbour whose edge the centre of mass projects across, else the last
    target = np.where(crosses.any(axis=1), np.argmax(crosses, axis=1), 2)
    successor = np.full(count, -1)
    successor[unstable] = neighbour[unstable, target[unstable]]
    probability = probability.tolist()
    incoming = np.bincount(successor[successor >= 0], minlength=count)
    wave = [face for face in range(count) if incoming[face] == 0]
    waves = 0
    while wave and waves <= len(mesh.faces):
        following = []
        for face in wave:
            if successor[face] < 0:
                continue
            probability[successor[face]] += probability[face]
            probability[face] = 0.0
            following.append(successor[face])
        wave = following
        waves += 1
    poses: dict[tuple, list] = {}
    for face in range(count):
        if probability[face] > 0.0:
            key = tuple(np.around(normals[face], decimals=3))
            if key in poses:
                poses[key][0] += probability[face]
            else:
                poses[key] = [probability[face], normals[face]]
    transforms, probabilities = [], []
    for total, normal in poses.values():
        z = -normal
        x = np.array([-z[1], z[0], 0.0])
        x = np.array([1.0, 0.0, 0.0]) if np.linalg.norm(x) == 0.0 else x / np.linalg.norm(x)
        y = np.cross(z, x)
        transform = np.eye(4)
        transform[:3, :3] = [x, y / np.linalg.norm(y), z]
        transform[2, 3] = -trimesh.transform_points(hull.vertices, transform)[:, 2].min()
        transforms.append(transform)
        probabilities.append(total)
    order = np.argsort(-np.array(probabilities))
    return np.array(transforms)[order], np.array(probabilities)[order]


def _orientation(a: np.ndarray, b: np.ndarray, c: np.ndarray, point: np.ndarray) -> np.ndarray:
    """Positive where ``point`` lies above the plane through ``a, b, c`` (trimesh's orient3dfast; last axis xyz)."""
    ad, bd, cd = a - point, b - point, c - point
    return (
        ad[..., 0] * (bd[..., 1] * cd[..., 2] - bd[..., 2] * cd[..., 1])
        + bd[..., 0] * (cd[..., 1] * ad[..., 2] - cd[..., 2] * ad[..., 1])
        + cd[..., 0] * (ad[..., 1] * bd[..., 2] - ad[..., 2] * bd[..., 1])
    )


def select_poses(
    probabilities: np.ndarray, config: PosesConfig, part_index: int, part_name: str
) -> tuple[list[int], list[str]]:
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
            raise ConfigError(
                "poses.select", f"pose indices {bad} do not exist for {part_name} ({available} stable poses)"
            )
        return sorted(set(config.select)), warnings
    count = config.count
    if count > available:
        warnings.append(f"{part_name}: {count} poses asked for, only {available} stable poses exist")
        count = available
    if config.select == "most_probable":
        return list(range(count)), warnings
    rng = np.random.default_rng([config.seed, part_index])
    return sorted(int(i) for i in rng.choice(available, size=count, replace=False)), warnings
