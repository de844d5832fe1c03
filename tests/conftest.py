"""Shared helpers: the fixture meshes copied into tests/data and small, fast settings."""

from __future__ import annotations

from pathlib import Path

import pytest

from fcso.config import DesignConfig

DATA = Path(__file__).parent / "data"
REPO = Path(__file__).parent.parent


def data_path(name: str) -> Path:
    """Path of a fixture mesh in tests/data (see tests/data/README.md for origins)."""
    path = DATA / name
    assert path.is_file(), path
    return path


def process_running(pid: int) -> bool:
    """Whether process ``pid`` exists and has not exited (a zombie has)."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def notched_cube_mesh():
    """A 30 mm cube with two 8 mm through holes and 45° notches along its four vertical edges, made with manifold3d.

    It has ten stable poses, four of them tilted ones of probability about 3 %.
    """
    import manifold3d
    import trimesh

    cube = manifold3d.Manifold.cube([30, 30, 30], center=True)
    hole = manifold3d.Manifold.cylinder(40, 4, 4, 48, center=True)
    cube = cube - hole - hole.rotate([90, 0, 0])
    notch = manifold3d.Manifold.cube([6, 6, 40], center=True).rotate([0, 0, 45])
    for x, y in ((-15, -15), (-15, 15), (15, -15), (15, 15)):
        cube = cube - notch.translate([x, y, 0])
    mesh = cube.to_mesh()
    return trimesh.Trimesh(mesh.vert_properties[:, :3], mesh.tri_verts)


def small_config(**sections) -> DesignConfig:
    """A 10 x 10 mm pad (T = 4, D = 3) with a coarse stride, so designs take seconds.

    ``sections`` are merged over it, e.g. ``small_config(poses={"select": [0, 1]})``.
    """
    base = {
        "sampler": {"length_mm": 10.0, "width_mm": 10.0, "thickness_mm": 4.0, "penetration_mm": 3.0, "stride_mm": 5.0},
        "poses": {"count": 1, "select": "most_probable"},
    }
    for section, values in sections.items():
        base.setdefault(section, {}).update(values)
    return DesignConfig().updated(base)


@pytest.fixture(scope="session")
def data_dir() -> Path:
    return DATA
