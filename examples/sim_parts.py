"""Parts built for the simulated grasp tests (METHOD §12), with manifold3d.

- :func:`featured_cube`: the paper's precision experiment part, a cube with
  a deep vertical V-notch in two opposite faces and a horizontal through
  hole between the other two, so a pad carved for it has a ridge that must
  enter the notch. (Shallow notches are not enough: METHOD §5 labels a
  pad box dominated by a flat face "bad" and the pad stays flat there.)
- :func:`ribbed_block`: a cube with a rectangular rib on two opposite faces:
  an exact pocket for it has vertical walls, a drafted one lead-ins.
- :func:`ridged_block`: a block whose two ends are vertical 90-degree
  ridges; a pad carved for it has V-grooves that centre it along the pad,
  while a flat pad touches only the ridge lines and cannot.
"""

from __future__ import annotations

import manifold3d
import numpy as np
import trimesh


def _mesh(solid: manifold3d.Manifold) -> trimesh.Trimesh:
    mesh = solid.to_mesh()
    return trimesh.Trimesh(np.asarray(mesh.vert_properties[:, :3]), np.asarray(mesh.tri_verts), process=True)


def _v_prism(depth_mm: float, height_mm: float) -> manifold3d.Manifold:
    """A vertical prism with a right-angled triangular cross-section, apex at the origin pointing -x, base at x =
    depth.
    """
    triangle = [[0.0, 0.0], [depth_mm, -depth_mm], [depth_mm, depth_mm]]  # counter-clockwise
    return manifold3d.Manifold.extrude(manifold3d.CrossSection([triangle]), height_mm)


def featured_cube(size_mm: float = 30.0, notch_mm: float = 8.0, hole_mm: float = 8.0) -> trimesh.Trimesh:
    """A cube (corner at the origin) with a vertical 90-degree V-notch in its two x faces and a through hole along y.

    Parameters
    ----------
    size_mm : float
        Edge length.
    notch_mm : float
        Depth of each V-notch (its opening is twice as wide).
    hole_mm : float
        Diameter of the through hole (along y, at mid-height).
    """
    half = size_mm / 2.0
    solid = manifold3d.Manifold.cube([size_mm] * 3)
    # apex notch_mm inside the face x = half of a cube centred on the vertical axis, opening outward
    notch = _v_prism(notch_mm + 1.0, size_mm + 2.0).translate([half - notch_mm, 0.0, -1.0])
    centred = solid.translate([-half, -half, 0.0])
    for angle in (0.0, 180.0):
        centred = centred - notch.rotate([0.0, 0.0, angle])
    hole = manifold3d.Manifold.cylinder(size_mm + 2.0, hole_mm / 2.0, circular_segments=48, center=True)
    centred = centred - hole.rotate([90.0, 0.0, 0.0]).translate([0.0, 0.0, half])
    solid = centred.translate([half, half, 0.0])
    return _mesh(solid)


def ridged_block(
    length_mm: float = 20.0, width_mm: float = 20.0, height_mm: float = 14.0, ridge_mm: float = 6.0
) -> trimesh.Trimesh:
    """A block with a vertical 90-degree ridge on each end along x (corner of the block at the origin).

    Parameters
    ----------
    length_mm, width_mm, height_mm : float
        The block without its ridges (x, y, z).
    ridge_mm : float
        How far each ridge stands out (its base is 2 x ridge_mm wide).
    """
    block = manifold3d.Manifold.cube([length_mm, width_mm, height_mm])
    ridge = _v_prism(ridge_mm, height_mm)
    plus = ridge.rotate([0.0, 0.0, 180.0]).translate([length_mm + ridge_mm, width_mm / 2.0, 0.0])
    minus = ridge.translate([-ridge_mm, width_mm / 2.0, 0.0])
    return _mesh(block + plus + minus)


def two_ridge_block(
    length_mm: float = 20.0,
    width_mm: float = 20.0,
    low_mm: float = 20.0,
    gap_mm: float = 4.0,
    high_mm: float = 20.0,
    ridge_mm: float = 4.0,
) -> trimesh.Trimesh:
    """A block whose two x ends carry, low, a vertical 90-degree ridge and, high, two horizontal ones.

    The vertical ridge centres the part along the pads (y); the horizontal
    ridges have the same normals and twice the contact area, so a pad on
    them has the higher Q, but nothing stops the part sliding along them:
    the best candidate by Q does not capture a displaced part and a lower
    one does (what ``--verify-top`` is for).

    Parameters
    ----------
    length_mm, width_mm : float
        The block without its ridges (x, y).
    low_mm, gap_mm, high_mm : float
        Height of the vertical ridge, of the plain band above it, and of the band with the two horizontal ridges.
    ridge_mm : float
        How far each ridge stands out (its base is 2 x ridge_mm wide).
    """
    solid = manifold3d.Manifold.cube([length_mm, width_mm, low_mm + gap_mm + high_mm])
    vertical = _v_prism(ridge_mm, low_mm).translate([-ridge_mm, width_mm / 2.0, 0.0])
    # the prism turned to run along y
    horizontal = _v_prism(ridge_mm, width_mm).rotate([-90.0, 0.0, 0.0])
    pitch = high_mm / 2.0
    end = manifold3d.Manifold.batch_boolean(
        [vertical] + [horizontal.translate([-ridge_mm, 0.0, low_mm + gap_mm + pitch * (k + 0.5)]) for k in range(2)],
        manifold3d.OpType.Add,
    )
    other_end = end.rotate([0.0, 0.0, 180.0]).translate([length_mm, width_mm, 0.0])
    return _mesh(manifold3d.Manifold.batch_boolean([solid, end, other_end], manifold3d.OpType.Add))


def ribbed_block(size_mm: float = 30.0, rib_width_mm: float = 8.0, rib_mm: float = 3.0) -> trimesh.Trimesh:
    """A cube (corner at the origin) with a vertical rectangular rib standing out of the middle of each x face.

    A pad carved for it has a rectangular pocket with vertical walls: the
    exact pocket jams a displaced part on its rim, a drafted one guides it in.

    Parameters
    ----------
    size_mm : float
        Edge length of the cube.
    rib_width_mm, rib_mm : float
        Width of each rib along y and how far it stands out along x.
    """
    cube = manifold3d.Manifold.cube([size_mm] * 3)
    rib = manifold3d.Manifold.cube([rib_mm, rib_width_mm, size_mm])
    centre = (size_mm - rib_width_mm) / 2.0
    return _mesh(cube + rib.translate([size_mm, centre, 0.0]) + rib.translate([-rib_mm, centre, 0.0]))


def holed_notched_cube(size_mm: float = 30.0, hole_mm: float = 8.0, notch_mm: float = 6.0) -> trimesh.Trimesh:
    """A cube (centred) with two through holes (along z and along y) and a 45-degree notch along each vertical edge.

    It has ten stable poses, four of them tilted ones of probability about 3 %.
    """
    cube = manifold3d.Manifold.cube([size_mm] * 3, center=True)
    hole = manifold3d.Manifold.cylinder(size_mm + 10.0, hole_mm / 2.0, hole_mm / 2.0, 48, center=True)
    cube = cube - hole - hole.rotate([90.0, 0.0, 0.0])
    notch = manifold3d.Manifold.cube([notch_mm, notch_mm, size_mm + 10.0], center=True).rotate([0.0, 0.0, 45.0])
    half = size_mm / 2.0
    for x, y in ((-half, -half), (-half, half), (half, -half), (half, half)):
        cube = cube - notch.translate([x, y, 0.0])
    return _mesh(cube)


def upright_grasp_settings(mesh: trimesh.Trimesh, closing_axis_in_file=(1.0, 0.0, 0.0)) -> dict:
    """fcso settings that design a part resting on its file-frame bottom, closing along a file-frame axis.

    Returns
    -------
    dict
        ``{"poses": {"count": 1, "select": [index]}, "sampler": {"yaw_deg": [angle], "face_yaws": false}}`` for
        :meth:`fcso.DesignConfig.updated`.
    """
    from fcso.poses import stable_poses

    transforms, _ = stable_poses(mesh)
    index = next(k for k, t in enumerate(transforms) if t[2, 2] > 0.999)
    axis = transforms[index][:3, :3] @ np.asarray(closing_axis_in_file, dtype=float)
    yaw = float(np.degrees(np.arctan2(axis[1], axis[0]))) % 180.0
    return {"poses": {"count": 1, "select": [index]}, "sampler": {"yaw_deg": [round(yaw, 6)], "face_yaws": False}}


def zigzag_l_part(
    length_mm: float = 60.0, width_mm: float = 40.0, thickness_mm: float = 12.0, teeth: int = 5, tooth_mm: float = 3.0
) -> trimesh.Trimesh:
    """An L-shaped plate lying flat whose long outer edge is a zig-zag (the paper's surgical object, simplified).

    The L is ``length_mm`` along x and ``width_mm`` along y, its arms half as
    wide; the edge at y = 0 carries ``teeth`` 90-degree saw teeth of depth
    ``tooth_mm`` over its middle, the opposite edge of the long arm is straight.
    """
    arm = width_mm / 2.0
    plate = manifold3d.Manifold.cube([length_mm, arm, thickness_mm]) + manifold3d.Manifold.cube(
        [arm, width_mm, thickness_mm]
    )
    pitch = 2.0 * tooth_mm
    start = (length_mm - teeth * pitch) / 2.0
    # 90-degree grooves, apex tooth_mm inside the edge, touching at the edge: a saw-tooth edge
    groove = _v_prism(tooth_mm + 1.0, thickness_mm + 2.0).rotate([0.0, 0.0, -90.0])
    for k in range(teeth):
        plate = plate - groove.translate([start + pitch * (k + 0.5), tooth_mm, -1.0])
    return _mesh(plate)


def knurled_knob(
    radius_mm: float = 12.0, height_mm: float = 20.0, ridges: int = 24, ridge_mm: float = 1.2
) -> trimesh.Trimesh:
    """A cylinder standing on its base with ``ridges`` axial square ridges round its side (a knurled knob)."""
    body = manifold3d.Manifold.cylinder(height_mm, radius_mm, circular_segments=96)
    ridge = manifold3d.Manifold.cube([ridge_mm * 2.0, ridge_mm, height_mm]).translate(
        [radius_mm - ridge_mm, -ridge_mm / 2.0, 0.0]
    )
    parts = [body] + [ridge.rotate([0.0, 0.0, 360.0 * k / ridges]) for k in range(ridges)]
    return _mesh(manifold3d.Manifold.batch_boolean(parts, manifold3d.OpType.Add))


def spur_gear(
    teeth: int = 16, module_mm: float = 2.0, thickness_mm: float = 10.0, bore_mm: float = 8.0
) -> trimesh.Trimesh:
    """A spur gear lying flat: trapezoidal teeth (module ``module_mm``) and a central bore."""
    pitch_r = module_mm * teeth / 2.0
    root_r, tip_r = pitch_r - 1.25 * module_mm, pitch_r + module_mm
    outline = []
    for k in range(teeth):
        centre = 2.0 * np.pi * k / teeth
        half = np.pi / teeth
        for angle, radius in (
            (centre - half, root_r),
            (centre - 0.45 * half, root_r),
            (centre - 0.25 * half, tip_r),
            (centre + 0.25 * half, tip_r),
            (centre + 0.45 * half, root_r),
        ):
            outline.append([radius * np.cos(angle), radius * np.sin(angle)])
    gear = manifold3d.Manifold.extrude(manifold3d.CrossSection([outline]), thickness_mm)
    bore = manifold3d.Manifold.cylinder(thickness_mm + 2.0, bore_mm / 2.0, circular_segments=48).translate(
        [0.0, 0.0, -1.0]
    )
    return _mesh(gear - bore)


def hex_prism(across_flats_mm: float = 24.0, height_mm: float = 20.0) -> trimesh.Trimesh:
    """A hexagonal prism standing on one hexagonal face."""
    radius = across_flats_mm / np.sqrt(3.0)
    return _mesh(manifold3d.Manifold.cylinder(height_mm, radius, circular_segments=6))


def plain_box(x_mm: float = 30.0, y_mm: float = 30.0, z_mm: float = 30.0) -> trimesh.Trimesh:
    """A plain box (corner at the origin): no feature to cage."""
    return _mesh(manifold3d.Manifold.cube([x_mm, y_mm, z_mm]))


def plain_cylinder(radius_mm: float = 15.0, height_mm: float = 30.0) -> trimesh.Trimesh:
    """A plain cylinder standing on its base."""
    return _mesh(manifold3d.Manifold.cylinder(height_mm, radius_mm, circular_segments=96))
