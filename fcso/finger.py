"""Flat fingers and fusing the fingerpad onto one (METHOD §9)."""

from __future__ import annotations

import io
from dataclasses import dataclass

import manifold3d
import numpy as np
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from .config import FingerConfig, GripperConfig, SamplerConfig
from .errors import ConfigError, GeometryError, UnwritableSolidError
from .geometry import affine_3x4, box, clip_to_box, ray_hits, to_manifold, to_trimesh, transform_points, volume_about
from .parts import read_mesh, unit_factor, validate_mesh
from .printfit import SIMPLIFY_TOLERANCE_MM
from .sampler import FingerPlate

#: Built-in finger: plate thickness and mounting flange, mm (Robotiq Hand-E sized).
PLATE_THICKNESS_MM = 8.0
FLANGE_THICKNESS_MM = 18.0
FLANGE_HEIGHT_MM = 12.0
MOUNT_HOLE_DIAMETER_MM = 4.5
MOUNT_HOLE_PITCH_MM = 12.0
MIN_PLATE_WIDTH_MM = 20.0


@dataclass
class FlatFinger:
    """A flat finger and the frame of its contact face.

    Attributes
    ----------
    mesh : trimesh.Trimesh
        Watertight finger in mm.
    contact_origin : (3,) float
        Where the centre of the pad's back face goes, mm.
    contact_normal : (3,) float
        Inward unit normal of the contact face (towards the gripped part).
    up : (3,) float
        Unit direction from the fingertip towards the gripper.
    source : str
        ``"built-in"`` or the mesh file.
    repairs : list of str
        What repair changed on a finger mesh.
    """

    mesh: trimesh.Trimesh
    contact_origin: np.ndarray
    contact_normal: np.ndarray
    up: np.ndarray
    source: str
    repairs: list[str]


def parametric_finger(sampler: SamplerConfig, gripper: GripperConfig) -> FlatFinger:
    """The built-in flat finger, sized like a Robotiq Hand-E finger.

    A plate whose lower end carries the pad (its tip flush with the pad's
    bottom edge), ``finger_height_mm`` of plate above the pad, and a mounting
    flange with two through holes at the top.

    Returns
    -------
    FlatFinger
        Frame: x across the plate (contact face at x = 0, inward normal -x),
        y along the pad length, z up from the fingertip.
    """
    width = max(sampler.length_mm + 4.0, MIN_PLATE_WIDTH_MM)
    plate_height = sampler.width_mm + gripper.finger_height_mm
    plate = box((0.0, -width / 2.0, 0.0), (PLATE_THICKNESS_MM, width / 2.0, plate_height))
    flange = box(
        (0.0, -width / 2.0, plate_height),
        (FLANGE_THICKNESS_MM, width / 2.0, plate_height + FLANGE_HEIGHT_MM),
    )
    body = plate + flange
    for offset in (-MOUNT_HOLE_PITCH_MM / 2.0, MOUNT_HOLE_PITCH_MM / 2.0):
        hole = (
            manifold3d.Manifold.cylinder(FLANGE_THICKNESS_MM + 2.0, MOUNT_HOLE_DIAMETER_MM / 2.0, circular_segments=32)
            .rotate([0.0, 90.0, 0.0])
            .translate([-1.0, offset, plate_height + FLANGE_HEIGHT_MM / 2.0])
        )
        body = body - hole
    return FlatFinger(
        mesh=to_trimesh(body),
        contact_origin=np.array([0.0, 0.0, sampler.width_mm / 2.0]),
        contact_normal=np.array([-1.0, 0.0, 0.0]),
        up=np.array([0.0, 0.0, 1.0]),
        source="built-in",
        repairs=[],
    )


def load_finger(config: FingerConfig, repair: bool = False) -> FlatFinger:
    """Load a user's flat finger mesh with its contact-face frame.

    Raises
    ------
    MeshError
        The finger mesh is unreadable or not a closed volume.
    ConfigError
        The frame is not usable (zero or non-perpendicular vectors).
    """
    path = config.mesh
    mesh = read_mesh(path)
    mesh, changes = validate_mesh(mesh, path, repair=repair)
    factor = unit_factor(config.units, path)
    mesh.apply_scale(factor)
    normal = _unit(config.contact_normal, path, "finger.contact_normal")
    up = _unit(config.up, path, "finger.up")
    if abs(float(normal @ up)) > 1e-3:
        raise ConfigError(path, "finger.up must be perpendicular to finger.contact_normal")
    return FlatFinger(
        mesh=mesh,
        contact_origin=np.asarray(config.contact_origin_mm, dtype=float),
        contact_normal=normal,
        up=up,
        source=str(path),
        repairs=changes,
    )


def _unit(vector, path, key: str) -> np.ndarray:
    vector = np.asarray(vector, dtype=float)
    norm = float(np.linalg.norm(vector))
    if not np.isfinite(norm) or norm < 1e-9:
        raise ConfigError(path, f"{key} must be a non-zero direction")
    return vector / norm


def pad_to_finger(finger: FlatFinger, sampler: SamplerConfig) -> np.ndarray:
    """4x4 transform from the pad frame to the finger's frame.

    The pad's back face (u = T) lands on the contact face, centred on the
    contact origin; u (outward) goes to ``-contact_normal``, w to ``up`` and
    v to ``up x u`` so the map is a rotation, never a mirror.
    """
    outward = -finger.contact_normal
    up = finger.up
    along = np.cross(up, outward)
    matrix = np.eye(4)
    matrix[:3, 0], matrix[:3, 1], matrix[:3, 2] = outward, along, up
    matrix[:3, 3] = finger.contact_origin - (
        sampler.thickness_mm * outward + sampler.length_mm / 2.0 * along + sampler.width_mm / 2.0 * up
    )
    return matrix


def finger_plate(finger: FlatFinger, sampler: SamplerConfig, gripper: GripperConfig) -> FingerPlate:
    """The finger's body behind its pad, as the sampler's collision checks need it.

    Measured on the finger mesh itself (the built-in plate or a user's
    finger): the part of the finger behind the contact face (``u >= T`` in
    the pad frame) between the pad's bottom edge and ``W + finger_height_mm``.

    Returns
    -------
    FingerPlate
        Thickness behind the pad's back face and extent along the pad
        length, mm; thickness 0 when the finger has nothing there.
    """
    to_pad = np.linalg.inv(pad_to_finger(finger, sampler))
    vertices = transform_points(to_pad, np.asarray(finger.mesh.vertices, dtype=np.float64))
    # just below the top so a flange starting at that height is not counted
    top = sampler.width_mm + gripper.finger_height_mm - 1e-6
    inside_v, inside_f = clip_to_box(
        vertices, finger.mesh.faces, (sampler.thickness_mm, -np.inf, 0.0), (np.inf, np.inf, top)
    )
    if len(inside_f) == 0:
        return FingerPlate(thickness_mm=0.0, v_min_mm=0.0, v_max_mm=sampler.length_mm)
    used = inside_v[inside_f].reshape(-1, 3)
    return FingerPlate(
        thickness_mm=float(used[:, 0].max() - sampler.thickness_mm),
        v_min_mm=float(min(used[:, 1].min(), 0.0)),
        v_max_mm=float(max(used[:, 1].max(), sampler.length_mm)),
    )


#: Faces of a written mesh with less area than this are zero-area faces, mm².
ZERO_AREA_MM2 = 1e-12


@dataclass
class WrittenMesh:
    """A solid as its STL file holds it: float32 coordinates, coincident vertices merged (METHOD §9b).

    Attributes
    ----------
    mesh : trimesh.Trimesh
        The file read back (mm); exporting it writes the same solid.
    watertight : bool
        Every edge shared by exactly two faces.
    zero_area_faces : int
        Faces with area under :data:`ZERO_AREA_MM2`.
    bodies : int
        Connected components.
    volume_mm3 : float
    """

    mesh: trimesh.Trimesh
    watertight: bool
    zero_area_faces: int
    bodies: int
    volume_mm3: float

    def defects(self) -> list[str]:
        """What keeps the written mesh from being one print-ready body, in words (empty when it is)."""
        found = []
        if not self.watertight:
            found.append("not watertight")
        if self.zero_area_faces:
            found.append(f"{self.zero_area_faces} zero-area faces")
        if self.bodies != 1:
            found.append(f"{self.bodies} bodies")
        if not self.volume_mm3 > 0:
            found.append(f"volume {self.volume_mm3:.3f} mm³")
        return found


def as_written(solid: manifold3d.Manifold) -> WrittenMesh:
    """The solid as a binary STL stores it, snapped to float32 by manifold3d first, and measured.

    manifold3d computes in double precision; an STL holds float32. Vertices
    that Booleans left closer together than float32 resolution (slivers of
    near-coincident faces, :mod:`fcso.printfit`) would merge when the file is
    read, leaving zero-area faces and a surface in pieces. So the solid is
    rebuilt by manifold3d from its float32 mesh (pinched vertices kept
    apart, :func:`float32_apart`), which collapses the faces
    that rounding made degenerate, and simplified to
    :data:`fcso.printfit.SIMPLIFY_TOLERANCE_MM`, which removes sheets of
    zero thickness at float32 resolution (a solar tracker's and a DC-DC
    case's finger kept a two-triangle flap near its pocket floor); simplification keeps a
    subset of the vertices, so the coordinates stay exactly the file's. The
    result is the written file read back with trimesh.
    """
    mesh = solid.to_mesh64()
    snapped = manifold3d.Manifold(
        manifold3d.Mesh(
            vert_properties=float32_apart(np.asarray(mesh.vert_properties)[:, :3], np.asarray(mesh.tri_verts)),
            tri_verts=np.array(np.asarray(mesh.tri_verts), dtype=np.uint32, order="C"),
        )
    )
    snapped = snapped.as_original().simplify(SIMPLIFY_TOLERANCE_MM)
    if snapped.status() != manifold3d.Error.NoError:
        raise GeometryError(f"manifold3d refused the solid snapped to float32: {snapped.status()}")
    data = to_trimesh(snapped).export(file_type="stl")
    written = trimesh.load(io.BytesIO(data), file_type="stl", process=True)
    written = without_zero_area_faces(_without_flaps(_without_collapsed_clusters(written)))
    return WrittenMesh(
        mesh=written,
        watertight=bool(written.is_watertight),
        zero_area_faces=int((written.area_faces < ZERO_AREA_MM2).sum()),
        bodies=len(written.split(only_watertight=False)) if len(written.faces) else 0,
        volume_mm3=float(written.volume),
    )


def float32_apart(exact: np.ndarray, faces: np.ndarray, passes: int = 4) -> np.ndarray:
    """Vertices rounded to float32, kept apart where distinct vertices would be one point in the file.

    A Boolean can leave a pinch: two sheets of the solid touching along an
    edge, with distinct vertices at one position, or closer than float32
    resolution (the two-ridge block's fused finger). Merged when the STL is
    read, they give edges of four faces: not watertight. Each later vertex of
    such a pair is put one float32 step from the other, on its own side (where
    its exact position lies, or else where its neighbours lie), so the file
    keeps the sheets apart as the solid does; no vertex moves more than one
    float32 step (under 2e-6 of its coordinate) from where rounding puts it.

    Parameters
    ----------
    exact : (n, 3) float
        The solid's vertices in double precision, mm.
    faces : (m, 3) int
        Its triangles.
    passes : int
        Rounds of steps (three vertices at one point need two).

    Returns
    -------
    (n, 3) float32, C-ordered
    """
    rounded = np.array(exact, dtype=np.float32, order="C")
    for _ in range(passes):
        _, first, inverse = np.unique(rounded, axis=0, return_index=True, return_inverse=True)
        holder = first[inverse.ravel()]
        shared = np.flatnonzero(holder != np.arange(len(rounded)))
        if not len(shared):
            break
        for vertex in shared:
            other = holder[vertex]
            gap = exact[vertex] - exact[other]
            if not gap.any():
                gap = _neighbours_centre(vertex, exact, faces) - _neighbours_centre(other, exact, faces)
            axis = int(np.argmax(np.abs(gap)))
            toward = np.float32(np.inf if gap[axis] > 0 else -np.inf)
            rounded[vertex, axis] = np.nextafter(rounded[other, axis], toward)
    return rounded


def _neighbours_centre(vertex: int, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Mean position of the vertices that share a triangle with ``vertex``."""
    fan = faces[(faces == vertex).any(axis=1)].ravel()
    return vertices[fan[fan != vertex]].mean(axis=0)


#: A piece of a written mesh enclosing less than this is a flap of zero thickness, not material, mm³.
FLAP_VOLUME_MM3 = 1e-6


def _without_flaps(written: trimesh.Trimesh) -> trimesh.Trimesh:
    """The written mesh without flaps: pieces of zero volume beside one watertight body.

    Two vertices manifold3d keeps apart can round to one float32 point; a
    sheet between them then reads back as a separate two-triangle flap of
    zero area and volume (the demo's cube and solar tracker on one finger,
    10 mm pads). It holds no material, so it is left out of the file; a
    piece with volume is never dropped.
    """
    pieces = written.split(only_watertight=False)
    if len(pieces) < 2:
        return written
    solids = [p for p in pieces if abs(volume_about(p, p.vertices.mean(axis=0))) >= FLAP_VOLUME_MM3]
    if len(solids) != 1 or not solids[0].is_watertight:
        return written
    data = solids[0].export(file_type="stl")
    return trimesh.load(io.BytesIO(data), file_type="stl", process=True)


#: Vertices of a written mesh closer than this are one point, mm (tens of float32 steps at 100 mm).
CLUSTER_MM = 1e-5


def _without_collapsed_clusters(written: trimesh.Trimesh) -> trimesh.Trimesh:
    """The written mesh with each cluster of vertices closer than :data:`CLUSTER_MM` merged into one, and the faces
    that then have no area left out, where that leaves it watertight with its volume.

    A gear's pocket floor met a drafted wall in a fan of six vertices within 7e-7 mm: manifold3d keeps them apart
    and float32 keeps them distinct, but their faces have no area, and no edge flip
    (:func:`without_zero_area_faces`) mends a fan whose edges have no length either.
    """
    needles = written.area_faces < ZERO_AREA_MM2
    if not needles.any():
        return written
    count = len(written.vertices)
    pairs = cKDTree(written.vertices).query_pairs(CLUSTER_MM, output_type="ndarray")
    if not len(pairs):
        return written
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(count, count))
    _, labels = connected_components(graph, directed=False)
    # each cluster with a vertex of a face of no area becomes its lowest-numbered vertex, a point of the file
    first = np.full(labels.max() + 1, count)
    np.minimum.at(first, labels, np.arange(count))
    mended = np.isin(labels, labels[written.faces[needles].ravel()])
    faces = np.where(mended, first[labels], np.arange(count))[written.faces]
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])]
    # two faces over the same three vertices (opposite ways round) are a fin of no volume once merged: both go
    _, group, count_of = np.unique(np.sort(faces, axis=1), axis=0, return_inverse=True, return_counts=True)
    merged = trimesh.Trimesh(written.vertices, faces[count_of[group.ravel()] == 1], process=False)
    merged.remove_unreferenced_vertices()
    # a merge within CLUSTER_MM moves faces by less than that: the volume changes by far less than a print resolves
    if merged.is_watertight and abs(merged.volume - written.volume) < CLUSTER_MM * written.area:
        return merged
    return written


def without_zero_area_faces(mesh: trimesh.Trimesh, passes: int = 4) -> trimesh.Trimesh:
    """``mesh`` with each zero-area face's longest edge flipped with the face across it.

    Rounding to float32 can put a vertex on the edge between two others: the
    face they make has no area though the surface stays closed (a 41-part
    finger set's pad of a 200-part job was refused for one such face). The
    flip turns that face and its neighbour into two faces of positive area
    over the same surface, so the mesh stays watertight and its volume
    unchanged. A face the flips cannot mend is left (:func:`print_ready`
    refuses it).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Closed, consistently oriented (mm).
    passes : int
        Rounds of flips (a flip can leave a new zero-area face beside another).

    Returns
    -------
    trimesh.Trimesh
        ``mesh`` itself when it has no zero-area face.
    """
    vertices, faces = mesh.vertices, mesh.faces.copy()
    changed = False
    for _ in range(passes):
        corners = vertices[faces]
        areas = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
        needles = np.flatnonzero(areas < ZERO_AREA_MM2)
        if not len(needles):
            break
        across = {(int(a), int(b)): f for f, face in enumerate(faces) for a, b in zip(face, np.roll(face, -1))}
        flipped: set[int] = set()
        for f in needles:
            face = faces[f]
            # the longest edge a -> c; b, the vertex opposite it, lies on it
            lengths = np.linalg.norm(vertices[np.roll(face, -1)] - vertices[face], axis=1)
            i = int(np.argmax(lengths))
            a, c, b = int(face[i]), int(face[(i + 1) % 3]), int(face[(i + 2) % 3])
            g = across.get((c, a))
            if g is None or g == f or f in flipped or g in flipped:
                continue
            y = next(int(v) for v in faces[g] if v not in (a, c))
            faces[f], faces[g] = (b, a, y), (b, y, c)
            flipped.update((f, g))
            changed = True
    return trimesh.Trimesh(vertices, faces, process=False) if changed else mesh


def print_ready(solid: manifold3d.Manifold, what: str) -> WrittenMesh:
    """:func:`as_written`, refused unless it is one watertight body without zero-area faces.

    Raises
    ------
    UnwritableSolidError
        Naming ``what`` and the defects.
    """
    written = as_written(solid)
    if written.defects():
        raise UnwritableSolidError(
            f"{what} is not one watertight body as written to STL: {', '.join(written.defects())}"
        )
    return written


@dataclass
class FusedFinger:
    """The print-ready finger: the flat finger with the fingerpad fused on, measured as written (:func:`as_written`)."""

    mesh: trimesh.Trimesh
    bodies: int
    watertight: bool
    volume_mm3: float
    min_pad_thickness_mm: float


def fuse(finger: FlatFinger, pad: manifold3d.Manifold, sampler: SamplerConfig, overlap_mm: float) -> FusedFinger:
    """Fuse a fingerpad onto a flat finger with manifold3d.

    The pad is extended ``overlap_mm`` behind its back face into the finger so
    that the union is one solid while the pad keeps its full thickness T in
    front of the contact face.

    Raises
    ------
    GeometryError
        When the result, as written to STL, is not one watertight body of positive volume.
    """
    thickness, length, width = sampler.thickness_mm, sampler.length_mm, sampler.width_mm
    backing = box((thickness - 0.5 * overlap_mm, 0.0, 0.0), (thickness + overlap_mm, length, width))
    pad_in_finger = (pad + backing).transform(affine_3x4(pad_to_finger(finger, sampler)))
    fused = to_manifold(finger.mesh) + pad_in_finger
    if fused.status() != manifold3d.Error.NoError:
        raise GeometryError(f"{finger.source}: finger union failed: {fused.status()}")
    bodies = len(fused.decompose())
    if bodies != 1:
        # a pad whose pockets cut it apart is as undeliverable as one that falls apart as written: the next
        # candidate is tried (fcso.pipeline.finish)
        raise UnwritableSolidError(
            f"{finger.source}: fused finger is not one body (bodies: {bodies}); "
            "check the finger's contact_origin_mm and contact_normal"
        )
    written = print_ready(fused, f"{finger.source}: fused finger")
    return FusedFinger(
        mesh=written.mesh,
        bodies=written.bodies,
        watertight=written.watertight,
        volume_mm3=written.volume_mm3,
        min_pad_thickness_mm=pad_thickness(pad, sampler),
    )


def pad_thickness(pad: manifold3d.Manifold, sampler: SamplerConfig, samples_per_side: int = 40) -> float:
    """Thinnest section of the pad along u (mm), from rays across its face.

    Each ray enters the pad at its carved surface; the section there runs to
    the back face u = T.
    """
    mesh = to_trimesh(pad)
    v = (np.arange(samples_per_side) + 0.5) / samples_per_side * sampler.length_mm
    w = (np.arange(samples_per_side) + 0.5) / samples_per_side * sampler.width_mm
    grid_v, grid_w = np.meshgrid(v, w)
    origins = np.column_stack([np.full(grid_v.size, -1.0), grid_v.ravel(), grid_w.ravel()])
    directions = np.tile([1.0, 0.0, 0.0], (len(origins), 1))
    rays, distances = ray_hits(mesh.vertices, mesh.faces, origins, directions)
    if len(rays) == 0:
        return 0.0
    first_hit = np.full(len(origins), np.inf)
    np.minimum.at(first_hit, rays, origins[rays, 0] + distances)
    hit = np.isfinite(first_hit)
    return float(sampler.thickness_mm - first_hit[hit].max())
