"""Placing the finger copies into a job's build volume.

The search follows Spectral Packing (Cui et al., SIGGRAPH 2023): the build
volume is a voxel grid of forbidden positions, and for every allowed
orientation of an item one FFT correlation of its voxel kernel with that grid
counts the collisions at every translation at once. The item goes where the
build height grows least, then (for fingers) where its pad faces up best,
then lowest top, then lowest z, y, x. Every chosen position is then checked on
the meshes themselves (manifold3d's exact ``min_gap``).

Why the voxel test is conservative: an item's kernel holds every voxel (closed
cube) its solid may touch, found by covering its triangles with cells whose
boxes span at most one voxel per axis and filling what their voxels enclose. A voxel is
forbidden when its cube comes closer than ``spacing`` to a cube of a placed
solid: the solid's voxels grown by a Euclidean distance transform and one
3 x 3 x 3 dilation (cube-to-cube distance of voxels ``d`` apart is
``|max(|d| - 1, 0)|``). Any point of a placed item lies in a kernel voxel on a
free voxel, so it lies at least ``spacing`` from every placed solid. Each
mesh is voxelised once in its own frame; its axis-aligned rotations are
transposes and flips of those voxels.

Lengths are millimetres; the build volume spans ``origin_mm`` to
``origin_mm + volume_mm`` with z up.
"""

from __future__ import annotations

import dataclasses
import itertools
import time
from collections.abc import Sequence
from dataclasses import dataclass

import manifold3d
import numpy as np
import scipy.fft
import trimesh

from .build3mf import Build, BuildItem
from .gaps import clear_of, placed_item_reports, placed_solid, placed_vertices, solid_manifold, vertex_bounds
from .models import BuildConfig, PlacementReport
from .voxels import grow, mark_pad, solid_voxels


@dataclass
class PlacementResult:
    """What :func:`place_fingers` returns.

    Attributes
    ----------
    items : list of BuildItem
        Every placed item (parts, then fingers) with its transform: the
        content of ``build.3mf``.
    report : PlacementReport
        The placement section of report.json, MCAP and zenoh.
    """

    items: list[BuildItem]
    report: PlacementReport

    @property
    def fingers_fit(self) -> bool:
        """True when all required finger copies were placed."""
        return self.report.fingers_fit


@dataclass
class _Pose:
    """One allowed orientation of a movable item, voxelised.

    The item's mesh is rotated, then shifted by ``offset`` so that its voxel
    box starts at 0; its bounding box then spans ``lower`` to ``upper``.
    """

    rotation: np.ndarray  # (3, 3)
    offset: np.ndarray  # (3,) mm
    lower: np.ndarray  # (3,) mm
    upper: np.ndarray  # (3,) mm
    kernel: np.ndarray  # bool, voxels the rotated solid may touch
    mark: np.ndarray  # bool, voxels it forbids once placed, from kernel index -mark_pad
    mark_pad: int
    pad_penalty: float  # 1 - cos(angle of the pad normal to +z); 0 for parts


@dataclass
class _Grid:
    """The build volume as voxels; index i covers origin + [i, i + 1] * voxel."""

    origin: np.ndarray
    voxel: float
    shape: tuple[int, int, int]


def axis_aligned_rotations() -> np.ndarray:
    """The 24 proper rotations that map axes to axes, (24, 3, 3), identity first."""
    rotations = []
    for permutation in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            matrix = np.zeros((3, 3))
            matrix[np.arange(3), permutation] = signs
            if np.linalg.det(matrix) > 0:
                rotations.append(matrix)
    return np.array(rotations)


def z_rotations() -> np.ndarray:
    """The 4 quarter turns about z, (4, 3, 3), identity first."""
    return np.array(
        [trimesh.transformations.rotation_matrix(k * np.pi / 2.0, [0, 0, 1])[:3, :3].round() for k in range(4)]
    )


def finger_rotations(pad_normal: np.ndarray, mode: str) -> tuple[np.ndarray, np.ndarray]:
    """Allowed finger rotations and their pad penalties, best (pad face up) first.

    Parameters
    ----------
    pad_normal : (3,) float
        Outward normal of the pad's contact face in the finger's frame (the
        built-in finger's is -x).
    mode : {'axis_aligned', 'pad_up'}
        All 24 axis-aligned rotations, or only those turning the pad to +z.

    Returns
    -------
    rotations : (n, 3, 3) float
    penalties : (n,) float
        ``1 - (R @ pad_normal) . z``: 0 for pad up, 1 for pad sideways, 2 down.
    """
    normal = np.asarray(pad_normal, dtype=float)
    normal = normal / np.linalg.norm(normal)
    rotations = axis_aligned_rotations()
    penalties = 1.0 - (rotations @ normal)[:, 2]
    if mode == "pad_up":
        keep = penalties <= penalties.min() + 1e-9
        rotations, penalties = rotations[keep], penalties[keep]
    order = np.argsort(penalties, kind="stable")
    return rotations[order], penalties[order]


def _poses(
    mesh: trimesh.Trimesh, rotations: np.ndarray, penalties: np.ndarray, voxel: float, spacing: float
) -> list[_Pose]:
    """Voxelise ``mesh`` once and turn its kernel and mark into each rotation.

    The voxel box starts at the mesh's bounding-box corner; an axis-aligned
    rotation maps that box's voxels onto voxels, so each rotated kernel is a
    transpose and flip of the first, and so is the mark (the voxels the
    placed item forbids to others, which :func:`grow` keeps symmetric).
    Rotations giving the same kernel and penalty are dropped.
    """
    counts = np.maximum(np.ceil(mesh.extents / voxel - 1e-9).astype(int), 1)
    corner = mesh.bounds[0]
    pad = mark_pad(voxel, spacing)
    solid = solid_voxels(mesh.vertices, mesh.faces, corner - pad * voxel, voxel, counts + 2 * pad)
    base_mark = grow(solid, voxel, spacing)
    base = solid[pad:-pad, pad:-pad, pad:-pad]
    box = np.array([corner, corner + counts * voxel])
    poses: list[_Pose] = []
    seen: set[tuple] = set()
    for rotation, penalty in zip(rotations, penalties):
        # (R c)_a = sign_a * c_source_a for a signed permutation matrix R
        source = np.argmax(np.abs(rotation), axis=1)
        signs = rotation[np.arange(3), source]
        flips = tuple(int(a) for a in np.flatnonzero(signs < 0))
        kernel = np.flip(np.transpose(base, source), axis=flips)
        key = (round(float(penalty), 9), kernel.shape, kernel.tobytes())
        if key in seen:
            continue
        seen.add(key)
        offset = -(box @ rotation.T).min(axis=0)
        rotated_bounds = mesh.bounds @ rotation.T + offset
        poses.append(
            _Pose(
                rotation=rotation,
                offset=offset,
                lower=rotated_bounds.min(axis=0),
                upper=rotated_bounds.max(axis=0),
                kernel=np.ascontiguousarray(kernel),
                mark=np.flip(np.transpose(base_mark, source), axis=flips),
                mark_pad=pad,
                pad_penalty=float(penalty),
            )
        )
    return poses


def _allowed_range(grid: _Grid, pose: _Pose, volume: np.ndarray, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """First and last grid index (inclusive) keeping a pose inside the volume minus the margin."""
    low = np.ceil((margin - pose.lower) / grid.voxel - 1e-9).astype(int)
    low = np.maximum(low, 0)
    high = np.floor((volume - margin - pose.upper) / grid.voxel + 1e-9).astype(int)
    high = np.minimum(high, np.array(grid.shape) - np.array(pose.kernel.shape))
    return low, high


def _spectrum(block: np.ndarray, fft_shape: Sequence[int]) -> np.ndarray:
    """DFT of a bool block zero-padded to ``fft_shape``, halved along x.

    The axes go one at a time, each over the rows the padding leaves
    non-zero, so a small block (a kernel) costs little more than the last
    axis' transform.

    Returns
    -------
    (fft_shape[0] // 2 + 1, fft_shape[1], fft_shape[2]) complex64
    """
    spectrum = scipy.fft.rfft(block.astype(np.float32), n=fft_shape[0], axis=0, workers=-1)
    spectrum = scipy.fft.fft(spectrum, n=fft_shape[1], axis=1, workers=-1)
    return scipy.fft.fft(spectrum, n=fft_shape[2], axis=2, workers=-1)


def _correlation(
    forbidden_spectrum: np.ndarray,
    kernel_spectrum: np.ndarray,
    fft_shape: Sequence[int],
    low: np.ndarray,
    stop: np.ndarray,
) -> np.ndarray:
    """Circular correlation of two blocks from their :func:`_spectrum`, at indices ``low`` to ``stop`` (exclusive).

    The inverse goes z, y, then x, cropping each axis as soon as it is
    done, so a narrow z-range costs little more than the first stage.

    Returns
    -------
    float array of shape ``stop - low``: at index i, the overlap count of the
    kernel placed at ``low + i``.
    """
    product = forbidden_spectrum * np.conj(kernel_spectrum)
    counts = scipy.fft.ifft(product, axis=2, workers=-1)[:, :, low[2] : stop[2]]
    counts = scipy.fft.ifft(counts, axis=1, workers=-1)[:, low[1] : stop[1]]
    return scipy.fft.irfft(counts, n=fft_shape[0], axis=0, workers=-1)[low[0] : stop[0]]


def _lowest_position(
    forbidden: np.ndarray,
    poses: Sequence[_Pose],
    grid: _Grid,
    config: BuildConfig,
    build_height: float,
    rejected: set[tuple[int, tuple[int, int, int]]],
):
    """The best free grid position over all poses, or None.

    Poses are tried in the order of the best key they could reach; the search
    stops when the next pose cannot beat the best position found.

    Returns
    -------
    (pose index, (3,) int index) or None
    """
    volume = np.array(config.volume_mm)
    ranges = [_allowed_range(grid, pose, volume, config.wall_margin_mm) for pose in poses]
    occupied_layers = np.flatnonzero(forbidden.any(axis=(0, 1)))
    top_layer = int(occupied_layers[-1]) if len(occupied_layers) else -1
    # kernels only ever cover the region inside the wall margins, and above
    # the highest forbidden voxel every position is free, so the FFT only
    # needs that region up to the occupied layers (at least up to the floor
    # margin) plus one kernel height
    lowest_start = max(int(low[2]) for low, _ in ranges)
    crop = min(grid.shape[2], max(top_layer + 1, lowest_start) + max(pose.kernel.shape[2] for pose in poses))
    region_low = np.min([low for low, _ in ranges], axis=0)
    region_high = np.max([high + pose.kernel.shape for pose, (_, high) in zip(poses, ranges)], axis=0)
    region_high = np.minimum(region_high, (grid.shape[0], grid.shape[1], crop))
    region = tuple(slice(int(a), int(b)) for a, b in zip(region_low, region_high))
    # x is the halved (real) axis, so that y and z stay complex and the
    # inverse can drop unneeded z and y before its costlier stages
    fft_shape = [scipy.fft.next_fast_len(int(n), real=axis == 0) for axis, n in enumerate(region_high - region_low)]
    forbidden_spectrum = None

    def best_possible(index: int) -> tuple:
        pose, (low, _) = poses[index], ranges[index]
        top = low[2] * grid.voxel + pose.upper[2]
        return (round(max(build_height, top), 6), pose.pad_penalty, round(top, 6))

    best_key, best = None, None
    for index in sorted(range(len(poses)), key=best_possible):
        pose, (low, high) = poses[index], ranges[index]
        if best_key is not None and best_possible(index) > best_key[:3]:
            break
        high = np.minimum(high, region_high - pose.kernel.shape)
        if best_key is not None:
            # a position can only win with its top at most the best's top
            # (lower pad penalty: at most the best's build height)
            limit_top = best_key[2] if pose.pad_penalty >= best_key[1] else best_key[0]
            high[2] = min(high[2], int(np.floor((limit_top - pose.upper[2]) / grid.voxel + 1e-6)))
        if np.any(high < low) or np.any(region_high <= region_low):
            continue
        if forbidden_spectrum is None:
            forbidden_spectrum = _spectrum(forbidden[region], fft_shape)
        local_low, local_high = low - region_low, high - region_low
        counts = _correlation(
            forbidden_spectrum, _spectrum(pose.kernel, fft_shape), fft_shape, local_low, local_high + 1
        )
        free = counts < 0.5
        for pose_index, position in rejected:
            local = np.array(position) - low
            if pose_index == index and np.all(local >= 0) and np.all(local < free.shape):
                free[tuple(local)] = False
        while True:
            layers = np.flatnonzero(free.any(axis=(0, 1)))
            if not len(layers):
                break
            z = int(layers[0])
            y, x = np.argwhere(free[:, :, z].T)[0]
            position = np.array([x, y, z]) + low
            window = tuple(slice(p, p + n) for p, n in zip(position, pose.kernel.shape))
            # single-precision FFT rounding is settled on the voxels themselves
            if np.any(forbidden[window] & pose.kernel):
                free[x, y, z] = False
                continue
            top = position[2] * grid.voxel + pose.upper[2]
            key = (round(max(build_height, top), 6), pose.pad_penalty, round(top, 6), *position[::-1], index)
            if best_key is None or key < best_key:
                best_key, best = key, (index, tuple(int(p) for p in position))
            break
    return best


def _place_movables(
    fixed: Sequence[BuildItem],
    movables: Sequence[BuildItem],
    pose_sets: dict[int, list[_Pose]],
    solids: dict[int, manifold3d.Manifold],
    config: BuildConfig,
    volume_z_mm: float,
) -> tuple[list[BuildItem], list[str]]:
    """Place ``movables`` one by one among ``fixed`` in a volume ``volume_z_mm`` high.

    Parameters
    ----------
    fixed, movables : sequence of BuildItem
    pose_sets : dict
        Poses of each movable mesh, by ``id(mesh)``.
    solids : dict
        manifold3d solid of every mesh in its own frame, by ``id(mesh)``.
    config : BuildConfig
    volume_z_mm : float
        Height of the volume searched, mm.

    Returns
    -------
    placed : list of BuildItem
        Copies of the movables that fitted, with transforms.
    unplaced : list of str
        Names of those that did not.
    """
    search_config = config.model_copy(update={"volume_mm": (config.volume_mm[0], config.volume_mm[1], volume_z_mm)})
    origin = np.array(config.origin_mm)
    voxel = config.voxel_mm
    shape = tuple(int(np.ceil(size / voxel - 1e-9)) for size in search_config.volume_mm)
    grid = _Grid(origin=origin, voxel=voxel, shape=shape)
    forbidden = np.zeros(shape, dtype=bool)
    neighbours: list[tuple[np.ndarray, manifold3d.Manifold]] = []
    build_height = 0.0
    for item in fixed:
        vertices = placed_vertices(item)
        neighbours.append((vertex_bounds(vertices), placed_solid(solids[id(item.mesh)], item.transform)))
        pad = mark_pad(voxel, config.spacing_mm)
        start = np.floor((vertices.min(axis=0) - origin) / voxel).astype(int) - pad
        stop = np.ceil((vertices.max(axis=0) - origin) / voxel).astype(int) + pad
        solid = solid_voxels(vertices, item.mesh.faces, origin + start * voxel, voxel, stop - start)
        _mark(forbidden, start, grow(solid, voxel, config.spacing_mm))
        build_height = max(build_height, float(vertices[:, 2].max() - origin[2]))
    placed, unplaced = [], []
    for item in movables:
        poses = pose_sets[id(item.mesh)]
        rejected: set[tuple[int, tuple[int, int, int]]] = set()
        while True:
            choice = _lowest_position(forbidden, poses, grid, search_config, build_height, rejected)
            if choice is None:
                unplaced.append(item.name)
                break
            pose = poses[choice[0]]
            transform = np.eye(4)
            transform[:3, :3] = pose.rotation
            transform[:3, 3] = origin + np.array(choice[1]) * voxel + pose.offset
            candidate = dataclasses.replace(item, transform=transform)
            bounds = vertex_bounds(placed_vertices(candidate))
            solid = placed_solid(solids[id(item.mesh)], transform)
            if not clear_of(bounds, solid, neighbours, config.spacing_mm):
                rejected.add(choice)
                continue
            placed.append(candidate)
            neighbours.append((bounds, solid))
            _mark(forbidden, np.array(choice[1]) - pose.mark_pad, pose.mark)
            build_height = max(build_height, float(bounds[1, 2] - origin[2]))
            break
    return placed, unplaced


def _mark(forbidden: np.ndarray, start: np.ndarray, block: np.ndarray) -> None:
    """Forbid (in place) the voxels of ``block`` placed at grid index ``start``; what lies outside the grid is
    dropped.
    """
    low = np.maximum(start, 0)
    high = np.minimum(start + np.array(block.shape), forbidden.shape)
    if np.any(high <= low):
        return
    forbidden[tuple(slice(a, b) for a, b in zip(low, high))] |= block[
        tuple(slice(a, b) for a, b in zip(low - start, high - start))
    ]


def place_fingers(
    build: Build,
    finger: trimesh.Trimesh,
    config: BuildConfig,
    pad_normal: Sequence[float] = (-1.0, 0.0, 0.0),
    finger_name: str = "finger",
) -> PlacementResult:
    """Add the finger copies to a job's build.

    Placed parts stay where they are and the fingers go into the free space
    among them, lowest build height first; unplaced parts are packed together
    with the fingers, largest first.

    Parameters
    ----------
    build : Build
        The job's parts; items with a transform are placed.
    finger : trimesh.Trimesh
        The print-ready finger, closed, mm, in its own frame.
    config : BuildConfig
        Volume, spacing, wall margin, copies and orientations.
    pad_normal : (3,) float
        Outward normal of the pad's contact face in the finger's frame; the
        placer prefers orientations turning it to +z (pad printed face up)
        among those of equal build height. The built-in finger's is -x.
    finger_name : str
        Finger copies are named ``{finger_name}-1``, ``{finger_name}-2``...

    Returns
    -------
    PlacementResult
        The placed items for ``build.3mf`` and the report. When items do not
        fit, the result says so (``fingers_fit`` false, a message, the missing
        build height); it never raises for lack of room.
    """
    started = time.perf_counter()
    config_volume = np.array(config.volume_mm)
    fixed = [item for item in build.items if item.transform is not None]
    unplaced_parts = [item for item in build.items if item.transform is None]
    copies = config.finger_copies + config.spare_fingers
    fingers = [BuildItem(f"{finger_name}-{k + 1}", finger, None, "finger") for k in range(copies)]
    required = fingers[: config.finger_copies]
    spares = fingers[config.finger_copies :]

    finger_rots, finger_penalties = finger_rotations(np.asarray(pad_normal), config.finger_orientations)
    part_rots = {"as_given": np.eye(3)[None], "z_rotations": z_rotations(), "axis_aligned": axis_aligned_rotations()}[
        config.part_orientations
    ]
    pose_sets = {id(finger): _poses(finger, finger_rots, finger_penalties, config.voxel_mm, config.spacing_mm)}
    for item in unplaced_parts:
        pose_sets[id(item.mesh)] = _poses(
            item.mesh, part_rots, np.zeros(len(part_rots)), config.voxel_mm, config.spacing_mm
        )
    solids = {id(item.mesh): solid_manifold(item.mesh) for item in build.items}
    solids[id(finger)] = solid_manifold(finger)
    # largest first packs tighter; the spares come last so they never take a
    # required item's room
    movables = sorted(unplaced_parts + required, key=lambda item: (-float(np.prod(item.mesh.extents)), item.name))
    movables += spares

    placed, missing = _place_movables(fixed, movables, pose_sets, solids, config, config_volume[2])
    extra_height = extra_height_needed(fixed, movables, pose_sets, solids, config) if missing else None
    items = (
        fixed + [item for item in placed if item.kind == "part"] + [item for item in placed if item.kind == "finger"]
    )
    item_reports, warnings = placed_item_reports(items, {id(item) for item in fixed}, solids, config)
    lower = np.array(config.origin_mm)
    build_height = max((float(report.bounds_mm[1][2] - lower[2]) for report in item_reports), default=0.0)
    solid_volume = sum(abs(float(item.mesh.volume) * np.linalg.det(item.transform[:3, :3])) for item in items)
    density = solid_volume / (config_volume[0] * config_volume[1] * build_height) if build_height > 0 else 0.0
    fingers_placed = sum(1 for item in placed if item.kind == "finger")
    fingers_fit = all(item.name not in missing for item in required)
    missing_spares = [item.name for item in spares if item.name in missing]
    if missing_spares:
        warnings.append(f"no room for spare fingers: {', '.join(missing_spares)}")
    message = _message(fingers_fit, fingers_placed, missing, extra_height, build_height)
    report = PlacementReport(
        mode="pack" if unplaced_parts else "add_fingers",
        fingers_fit=fingers_fit,
        all_items_placed=not missing,
        finger_copies_requested=copies,
        finger_copies_placed=fingers_placed,
        volume_mm=config.volume_mm,
        spacing_mm=config.spacing_mm,
        wall_margin_mm=config.wall_margin_mm,
        voxel_mm=config.voxel_mm,
        build_height_mm=round(build_height, 3),
        packing_density=round(density, 4),
        extra_height_needed_mm=extra_height,
        items=item_reports,
        unplaced_items=missing,
        message=message,
        warnings=warnings,
        placement_seconds=round(time.perf_counter() - started, 3),
    )
    return PlacementResult(items=items, report=report)


def extra_height_needed(
    fixed: list[BuildItem],
    movables: list[BuildItem],
    pose_sets: dict[int, list[_Pose]],
    solids: dict[int, manifold3d.Manifold],
    config: BuildConfig,
) -> float | None:
    """The free build height missing for ``movables`` that did not all fit, mm: the same placement in a volume tall
    enough for everything; None when even that leaves some out."""
    volume_z = config.volume_mm[2]
    tall = volume_z + sum(float(item.mesh.extents.max()) + config.spacing_mm for item in movables)
    tall_placed, tall_missing = _place_movables(fixed, movables, pose_sets, solids, config, tall)
    if tall_missing:
        return None
    needed = max(float(placed_vertices(item)[:, 2].max() - config.origin_mm[2]) for item in tall_placed)
    return round(needed + config.wall_margin_mm - volume_z, 3)


def _message(
    fingers_fit: bool, fingers_placed: int, missing: list[str], extra_height: float | None, height: float
) -> str:
    """One sentence for the operator and the cell controller."""
    if not missing:
        return f"{fingers_placed} finger copies placed; build height {height:.1f} mm"
    what = "the fingers do not fit into the build volume" if not fingers_fit else f"no room for {', '.join(missing)}"
    if extra_height is None:
        return f"{what}, at any build height; the design is delivered without them in the build"
    return (
        f"{what}: {extra_height:.1f} mm more free build height needed; the design is delivered without them in the "
        f"build"
    )
