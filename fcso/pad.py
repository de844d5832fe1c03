"""Pad geometries by Boolean intersection, the good/bad volume filter and the fingerpad (METHOD §4-5)."""

from __future__ import annotations

from dataclasses import dataclass, field

import manifold3d
import numpy as np

from .config import FilterConfig, SamplerConfig
from .errors import GeometryError
from .geometry import (
    affine_3x4,
    box,
    clip_to_box,
    mesh_arrays,
    rebuilt_from_mesh,
    solid_from_mesh_arrays,
    triangle_areas_normals,
)

# (u, v, w) -> (v, w, u): lets manifold3d's slice(z) cut across the pad thickness
_U_TO_Z = np.array([[0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [1.0, 0.0, 0.0, 0.0]])


@dataclass
class PadGeometry:
    """One intersection ``I_n = S ∩ G_n`` and its filter label.

    Attributes
    ----------
    intersection : manifold3d.Manifold
        ``I_n`` in the pad frame (mm).
    surface_vertices, surface_faces : ndarray
        The part's surface inside the pad box, pad frame.
    volume_mm3, bbox_volume_mm3 : float
        ``V_I`` and ``V_B``.
    ratio : float
        ``R = (V_B - V_I) / V_B``.
    depth_mm : float
        ``d_n``, depth of the geometry of interest.
    good : bool
        The filter's label.
    basis : str
        Why: ``"ratio"`` (R against th), ``"normals"`` (normal clustering, when d_n = D) or ``"wrapped"`` (a flat
        face that ends inside the pad at both ends of its length, ``[filter] wrapped_faces``).
    """

    intersection: manifold3d.Manifold
    surface_vertices: np.ndarray
    surface_faces: np.ndarray
    volume_mm3: float
    bbox_volume_mm3: float
    ratio: float
    depth_mm: float
    good: bool
    basis: str
    dominant_normal: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __getstate__(self) -> dict:
        # manifold3d solids do not pickle: worker processes send the mesh
        state = dict(self.__dict__)
        state["intersection"] = mesh_arrays(self.intersection)
        return state

    def __setstate__(self, state: dict) -> None:
        state["intersection"] = solid_from_mesh_arrays(*state["intersection"])
        self.__dict__.update(state)


def distinct_solids(solids: list[manifold3d.Manifold]) -> list[manifold3d.Manifold]:
    """The distinct meshes of ``solids`` (first of each, in order), each rebuilt from its mesh.

    manifold3d's Booleans triangulate by their operands' identities as well as
    their meshes (one object given twice is not two equal objects): rebuilt,
    the operands of a Boolean are the same whether they were made here, by a
    forked worker or on a Dask cluster, and a carving shared by several
    scenarios is subtracted once.
    """
    distinct: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}
    for solid in solids:
        vertices, triangles = mesh_arrays(solid)
        distinct.setdefault(vertices.tobytes() + triangles.tobytes(), (vertices, triangles))
    return [solid_from_mesh_arrays(vertices, triangles) for vertices, triangles in distinct.values()]


def pad_box(sampler: SamplerConfig) -> manifold3d.Manifold:
    """The pad box ``S = [0, T] x [0, L] x [0, W]`` in its own frame."""
    return box((0.0, 0.0, 0.0), (sampler.thickness_mm, sampler.length_mm, sampler.width_mm))


#: The least pad left beyond each end of a wrapped face, mm: the printed clearance (0.4 mm with MJF) and a printable
#: wall (0.5 mm) must fit between the part's edge and the pad's end, or the end wall prints as nothing.
WRAP_MARGIN_MM = 1.0


def _wrapped(start_mm: float, end_mm: float, length_mm: float) -> bool:
    """Whether a part section from ``start_mm`` to ``end_mm`` along the pad (v) ends inside it at both ends.

    The filter's flatness test sees a face flat against the pad and calls the pocket flat; but a face shorter than
    the pad leaves pad material beyond both its edges, and the carved pocket's end walls hold it along the pads: the
    sharp-edged 20 mm cube in a 35 mm pad is held 10/10 in simulation where the flat pocket holds it 1/10.
    """
    return start_mm >= WRAP_MARGIN_MM and end_mm <= length_mm - WRAP_MARGIN_MM


def pad_geometry(
    part: manifold3d.Manifold,
    part_vertices: np.ndarray,
    part_faces: np.ndarray,
    frame: np.ndarray,
    sampler: SamplerConfig,
    filter_config: FilterConfig,
) -> PadGeometry:
    """Intersect a part with one pad box and label the result (METHOD §4-5).

    Parameters
    ----------
    part : manifold3d.Manifold
        The part in its resting frame.
    part_vertices, part_faces : ndarray
        The same part as arrays (resting frame), for the surface inside the box.
    frame : (4, 4) float
        Resting frame to pad frame (:meth:`GraspSample.pad_frame`).
    sampler, filter_config
        Pad size and filter thresholds.

    Returns
    -------
    PadGeometry
    """
    length, width = sampler.length_mm, sampler.width_mm
    depth = sampler.penetration_mm
    intersection = part.transform(affine_3x4(frame)) ^ pad_box(sampler)
    if intersection.status() != manifold3d.Error.NoError:
        raise GeometryError(f"pad intersection is not manifold: {intersection.status()}")
    surface_vertices, surface_faces = surface_in_pad(part_vertices, part_faces, frame, sampler)
    volume = float(intersection.volume())
    lower_upper = np.asarray(intersection.bounding_box(), dtype=float)
    extent = np.clip(lower_upper[3:] - lower_upper[:3], 0.0, None) if volume > 0 else np.zeros(3)
    bbox_volume = float(np.prod(extent))
    ratio = (bbox_volume - volume) / bbox_volume if bbox_volume > 0 else 0.0
    geometry_depth = interest_depth(intersection, depth, length * width * filter_config.full_cover_fraction)
    dominant = dominant_normal(surface_vertices, surface_faces, filter_config.cluster_angle_deg)
    if geometry_depth < depth - 1e-9:
        good, basis = ratio >= filter_config.volume_ratio_threshold, "ratio"
    else:
        # R is not trusted: a face flat against the pad is bad whatever its box
        flat = abs(dominant[0]) >= np.cos(np.radians(filter_config.cluster_angle_deg))
        good, basis = not flat, "normals"
        if flat and filter_config.wrapped_faces and volume > 0 and _wrapped(lower_upper[1], lower_upper[4], length):
            good, basis = True, "wrapped"
    return PadGeometry(
        intersection=rebuilt_from_mesh(intersection),
        surface_vertices=surface_vertices,
        surface_faces=surface_faces,
        volume_mm3=volume,
        bbox_volume_mm3=bbox_volume,
        ratio=float(ratio),
        depth_mm=float(geometry_depth),
        good=bool(good),
        basis=basis,
        dominant_normal=dominant,
    )


def surface_in_pad(
    vertices: np.ndarray, faces: np.ndarray, frame: np.ndarray, sampler: SamplerConfig
) -> tuple[np.ndarray, np.ndarray]:
    """The part surface inside the pad box, in the pad frame.

    Parameters
    ----------
    vertices, faces : ndarray
        The part in its resting frame (mm).
    frame : (4, 4) float
        Resting frame to pad frame.
    sampler : SamplerConfig
        Pad size.

    Returns
    -------
    vertices, faces : ndarray
        Only the vertices the kept triangles use, in their order: every
        sample keeps its own surface, and a copy of the whole part's vertex
        array per sample grows memory with parts times samples.
    """
    local = vertices @ frame[:3, :3].T + frame[:3, 3]
    clipped, kept = clip_to_box(
        local, faces, (0.0, 0.0, 0.0), (sampler.thickness_mm, sampler.length_mm, sampler.width_mm)
    )
    used, inverse = np.unique(kept, return_inverse=True)
    return clipped[used], inverse.reshape(kept.shape).astype(kept.dtype)


def interest_depth(intersection: manifold3d.Manifold, depth: float, full_area: float, steps: int = 64) -> float:
    """``d_n = D - u_full`` (METHOD §5).

    ``u_full`` is the largest ``u`` in ``[0, D]`` whose cross-section of
    ``I_n`` covers at least ``full_area``. The cross-section area is scanned
    downward from ``u = D`` in ``steps`` steps, then the crossing is refined by
    bisection to ~1e-4 of D.

    Returns
    -------
    float
        ``d_n`` in mm; ``D`` when no cross-section covers the face.
    """
    turned = intersection.transform(_U_TO_Z.tolist())

    def covered(u: float) -> bool:
        return turned.slice(u).area() >= full_area

    grid = np.linspace(depth, 0.0, steps + 1)
    previous = None
    for u in grid:
        if covered(float(u)):
            if previous is None:
                return 0.0
            low, high = float(u), float(previous)
            for _ in range(14):
                middle = (low + high) / 2.0
                if covered(middle):
                    low = middle
                else:
                    high = middle
            return depth - low
        previous = u
    return depth


def dominant_normal(vertices: np.ndarray, faces: np.ndarray, angle_deg: float) -> np.ndarray:
    """Area-weighted mean normal of the largest cluster of face normals.

    Greedy clustering: the largest unassigned face seeds a cluster that takes
    every unassigned face within ``angle_deg`` of it; clusters compete by
    total area.

    Returns
    -------
    (3,) float
        Unit normal (pad frame), zeros when there is no surface.
    """
    if len(faces) == 0:
        return np.zeros(3)
    areas, normals = triangle_areas_normals(vertices, faces)
    keep = areas > 0
    areas, normals = areas[keep], normals[keep]
    if len(areas) == 0:
        return np.zeros(3)
    cosine = np.cos(np.radians(angle_deg))
    unassigned = np.ones(len(areas), dtype=bool)
    best_area, best_normal = -1.0, np.zeros(3)
    for seed in np.argsort(-areas, kind="stable"):
        if not unassigned[seed]:
            continue
        members = unassigned & (normals @ normals[seed] >= cosine)
        unassigned &= ~members
        cluster_area = float(areas[members].sum())
        if cluster_area > best_area:
            mean = (normals[members] * areas[members, None]).sum(axis=0)
            best_area, best_normal = cluster_area, mean / np.linalg.norm(mean)
        if not unassigned.any():
            break
    return best_normal


@dataclass
class Fingerpad:
    """The carved pad ``P`` of one candidate.

    Attributes
    ----------
    pad : manifold3d.Manifold
        ``P`` in the pad frame.
    case : {'good', 'bad', 'mixed'}
        Which of the three constructions of METHOD §5 was used.
    block_depth_mm : float or None
        ``d_B`` in the mixed case.
    """

    pad: manifold3d.Manifold
    case: str
    block_depth_mm: float | None


def _attached(pad: manifold3d.Manifold, thickness: float) -> manifold3d.Manifold:
    """Keep the pad material connected to the back face.

    Pad material enclosed by a part (inside a hole running along the pad
    face) is cut off from the back slab: it could neither be printed on the
    finger nor reach the part, so it is dropped.
    """
    pieces = pad.decompose()
    if len(pieces) <= 1:
        return pad
    attached = [p for p in pieces if p.bounding_box()[3] >= thickness - 1e-4]
    return manifold3d.Manifold.batch_boolean(attached, manifold3d.OpType.Add) if attached else pad


def build_fingerpad(geometries: list[PadGeometry], sampler: SamplerConfig, filter_config: FilterConfig) -> Fingerpad:
    """Carve the fingerpad from the labelled geometries of one candidate (METHOD §4-5).

    Returns
    -------
    Fingerpad
        only bad: the flat pad ``[D, T] x [0, L] x [0, W]``; only good:
        ``S - ∪ I_n``; mixed: ``S - (∪_good I_n ∪ B)`` with the block
        ``B = [0, D - d_B] x [0, L] x [0, W]``, ``d_B = K min d_n``.

    Raises
    ------
    GeometryError
        When a Boolean result is not a manifold.
    """
    thickness, length, width = sampler.thickness_mm, sampler.length_mm, sampler.width_mm
    depth = sampler.penetration_mm
    good = [g for g in geometries if g.good]
    if not good:
        pad = box((depth, 0.0, 0.0), (thickness, length, width))
        result = Fingerpad(pad=pad, case="bad", block_depth_mm=None)
    else:
        removed = manifold3d.Manifold.batch_boolean(
            distinct_solids([g.intersection for g in good]), manifold3d.OpType.Add
        )
        block_depth = None
        case = "good"
        if len(good) < len(geometries):
            case = "mixed"
            block_depth = min(g.depth_mm for g in good) * filter_config.block_factor
            if block_depth < depth:
                removed = removed + box((-1.0, -1.0, -1.0), (depth - block_depth, length + 1.0, width + 1.0))
        pad = _attached(pad_box(sampler) - removed, thickness)
        result = Fingerpad(pad=pad, case=case, block_depth_mm=block_depth)
    if result.pad.status() != manifold3d.Error.NoError or result.pad.is_empty():
        raise GeometryError(f"fingerpad Boolean failed: {result.pad.status()}")
    return result
