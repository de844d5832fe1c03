"""Mesh helpers: areas beyond a plane without cutting, height bands, Embree ray hits."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import trimesh

from fcso import load_part
from fcso.geometry import box, clip_to_box, half_space_area, ray_hits, to_trimesh, triangle_areas_normals, volume_about
from fcso.sampler import Bands
from tests.conftest import data_path

INF = np.inf


def bunny_surface() -> tuple[np.ndarray, np.ndarray]:
    mesh = load_part(data_path("stanford_bunny_closed.ply"), scale_to_mm=65.0).mesh
    return np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64)


def block_surface() -> tuple[np.ndarray, np.ndarray]:
    """A 30 x 20 x 15 mm block from (0, 0, 0): surface area 2700 mm²."""
    mesh = to_trimesh(box((0.0, 0.0, 0.0), (30.0, 20.0, 15.0)))
    return np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64)


def clipped_area(vertices, faces, axis, sign, level) -> float:
    lower, upper = [-INF] * 3, [INF] * 3
    if sign > 0:
        lower[axis] = level
    else:
        upper[axis] = -level
    kept_vertices, kept_faces = clip_to_box(vertices, faces, lower, upper)
    return float(triangle_areas_normals(kept_vertices, kept_faces)[0].sum())


def test_area_beyond_a_plane_is_the_area_the_clip_keeps():
    vertices, faces = bunny_surface()
    areas = triangle_areas_normals(vertices, faces)[0]
    rng = np.random.default_rng(3)
    for _ in range(60):
        axis, sign = int(rng.integers(3)), float(rng.choice([-1.0, 1.0]))
        level = sign * rng.uniform(vertices[:, axis].min(), vertices[:, axis].max())
        assert half_space_area(vertices, faces, areas, axis, sign, level) == pytest.approx(
            clipped_area(vertices, faces, axis, sign, level), rel=1e-9, abs=1e-9
        )


def test_area_beyond_a_plane_of_a_block_by_hand():
    vertices, faces = block_surface()
    areas = triangle_areas_normals(vertices, faces)[0]
    # above z = 5: the top and 10 mm of the 100 mm perimeter
    assert half_space_area(vertices, faces, areas, 2, 1.0, 5.0) == pytest.approx(600.0 + 100.0 * 10.0)
    # a face in the plane goes with the solid it bounds: the bottom to z >= 0, nothing to z <= 0
    assert half_space_area(vertices, faces, areas, 2, 1.0, 0.0) == pytest.approx(2700.0)
    assert half_space_area(vertices, faces, areas, 2, -1.0, 0.0) == pytest.approx(0.0)
    assert half_space_area(vertices, faces, areas, 0, -1.0, -12.0) == pytest.approx(
        300.0 + 2 * 12.0 * 15.0 + 2 * 12.0 * 20.0
    )


@pytest.mark.parametrize(
    "surface, levels",
    [
        (bunny_surface, np.arange(1.0, 60.0, 4.0)),
        (bunny_surface, np.array([0.0, 7.3, 7.3 + 1e-5, 30.0, 64.0])),
        # the block's side triangles span every level, its top and bottom lie in one
        (block_surface, np.array([0.0, 1.5, 3.0, 4.5, 7.5, 9.0, 15.0])),
    ],
)
def test_height_bands_hold_the_surface_a_cut_between_their_levels_holds(surface, levels):
    vertices, faces = surface()
    bands = Bands(vertices, faces, levels)
    ordered = np.unique(levels)
    for low, high in zip(ordered[:-1], ordered[1:]):
        band_vertices, band_faces, band_areas, (a_min, a_max) = bands.between(low, high)
        cut_vertices, cut_faces = clip_to_box(vertices, faces, (-INF, -INF, low), (INF, INF, high))
        assert band_areas.sum() == pytest.approx(
            triangle_areas_normals(cut_vertices, cut_faces)[0].sum(), rel=1e-12, abs=1e-12
        )
        if len(cut_faces):
            used = cut_vertices[np.unique(cut_faces)]
            assert (a_min, a_max) == pytest.approx((used[:, 0].min(), used[:, 0].max()), abs=1e-12)
            assert band_vertices[np.unique(band_faces), 2].min() >= low - 1e-7
            assert band_vertices[np.unique(band_faces), 2].max() <= high + 1e-7


def test_rays_report_every_crossing_once_in_order():
    vertices, faces = block_surface()
    origins = np.array([[-20.0, 5.0, 5.0], [-20.0, 10.0, 7.5], [15.0, 10.0, 30.0], [-20.0, 50.0, 5.0]])
    directions = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
    rays, distances = ray_hits(vertices, faces, origins, directions)
    # the second ray runs along the diagonal shared by two triangles of each face it crosses
    assert rays.tolist() == [0, 0, 1, 1, 2, 2]
    assert distances == pytest.approx([20.0, 50.0, 20.0, 50.0, 15.0, 30.0], abs=1e-5)


def test_volume_about_a_closed_box_and_a_flap():
    cube = to_trimesh(box((1.0, 2.0, 3.0), (3.0, 4.0, 5.0)))
    # a closed surface encloses the same volume about any origin
    assert volume_about(cube, np.zeros(3)) == pytest.approx(8.0)
    assert volume_about(cube, np.array([10.0, -4.0, 7.0])) == pytest.approx(8.0)
    # a two-triangle flap of zero thickness (what float32 rounding leaves beside a written finger) encloses nothing;
    # trimesh's own volume divides by it for the centre of mass and warns
    flap = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 1]], process=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        assert volume_about(flap, flap.vertices.mean(axis=0)) == 0.0
        with pytest.raises(RuntimeWarning):
            float(flap.volume)
