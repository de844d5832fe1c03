"""Parts built for the simulated grasp tests (METHOD §12), with manifold3d.

- :func:`featured_cube`: the paper's precision experiment part, a cube with
  a deep vertical V-notch in two opposite faces and a horizontal through
  hole between the other two, so a pad carved for it has a ridge that must
  enter the notch. (Shallow notches are not enough: METHOD §5 labels a
  pad box dominated by a flat face "bad" and the pad stays flat there.)
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


def upright_grasp_settings(mesh: trimesh.Trimesh, closing_axis_in_file=(1.0, 0.0, 0.0)) -> dict:
    """fcso settings that design a part resting on its file-frame bottom, closing along a file-frame axis.

    Returns
    -------
    dict
        ``{"poses": {"count": 1, "select": [index]}, "sampler": {"yaw_deg": [angle]}}`` for
        :meth:`fcso.DesignConfig.updated`.
    """
    from fcso.poses import stable_poses

    transforms, _ = stable_poses(mesh)
    index = next(k for k, t in enumerate(transforms) if t[2, 2] > 0.999)
    axis = transforms[index][:3, :3] @ np.asarray(closing_axis_in_file, dtype=float)
    yaw = float(np.degrees(np.arctan2(axis[1], axis[0]))) % 180.0
    return {"poses": {"count": 1, "select": [index]}, "sampler": {"yaw_deg": [round(yaw, 6)]}}
