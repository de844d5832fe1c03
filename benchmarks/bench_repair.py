"""Repair benchmark: ``python -m benchmarks.bench_repair`` from the repository root (by hand; not a test).

Measures mesh repair candidates on real files as published (open or
non-manifold) and on real closed meshes broken the ways exporters break them
(:mod:`tests.broken_meshes`). For each file and candidate it prints: success
(closed, consistently wound, as many solids as the reference, volume within
1 % of it), volume change
against the reference, time and the repaired volume (file units³). The reference of a broken mesh is its
intact original (for ``overlap``, both intact bodies) read by fcso, closed
shells united with manifold3d; of a
file as published, its own triangles without zero-area slivers, shells
united.

Candidates:

- ``fcso``: :func:`fcso.load_parts` with ``repair=True`` on the file written
  to disk (libigl duplicates, MeshFix per open shell, manifold3d union);
- ``trimesh+manifold3d``, ``meshlib+manifold3d``: the same pipeline with
  trimesh's or meshlib's hole filling instead of MeshFix;
- ``pymeshfix whole``: MeshFix on the whole file, as its documentation uses it;
- ``libigl GWN``: generalised winding number on a grid (``--cells`` along the
  longest side), iso-surface 0.5 by marching cubes.

meshlib is not a dependency (its licence is non-commercial): it is measured
only when installed by hand (``pip install meshlib``).
"""

from __future__ import annotations

import argparse
import tempfile
import time
import warnings
from pathlib import Path

import igl
import numpy as np
import pymeshfix
import trimesh

from fcso import MeshError, load_parts
from fcso.parts import read_mesh
from fcso.repair import repair_shells
from fcso.solids import mesh_solids
from tests.broken_meshes import KINDS, break_mesh, intact_mesh

REPO = Path(__file__).resolve().parent.parent
#: A repair that changes the volume by more than this has lost or invented material.
MAX_VOLUME_CHANGE_PERCENT = 1.0
AS_PUBLISHED = ["tests/data/encoder.stl", "tests/data/microscopio.stl", "tests/data/microscopoio_telaio.stl"]
CLOSED = [
    "tests/data/DC-DC_case.stl",
    "tests/data/capsela200_plug.stl",
    "tests/data/solar_tracker.stl",
    "tests/data/busted.STL",
    "tests/data/idler_riser.STL",
    "examples/parts/stanford_bunny_closed.ply",
]


def fcso_repair(mesh: trimesh.Trimesh, folder: Path) -> trimesh.Trimesh:
    path = folder / "broken.stl"
    mesh.export(path)
    return trimesh.util.concatenate([part.mesh for part in load_parts(path, repair=True)])


def with_filler(fill):
    """The fcso pipeline with another hole filler, overlaps united with manifold3d."""

    def run(mesh: trimesh.Trimesh, folder: Path) -> trimesh.Trimesh:
        shells, _ = repair_shells(mesh, close_holes=fill)
        solids, _ = mesh_solids(trimesh.util.concatenate(shells), "benchmark")
        return trimesh.util.concatenate([s.mesh for s in solids])

    return run


def fill_trimesh(shell: trimesh.Trimesh) -> trimesh.Trimesh:
    trimesh.repair.fill_holes(shell)
    return shell


def fill_meshlib(shell: trimesh.Trimesh) -> trimesh.Trimesh:
    import meshlib.mrmeshnumpy as mn
    import meshlib.mrmeshpy as mr

    mesh = mn.meshFromFacesVerts(np.asarray(shell.faces, np.int32), np.asarray(shell.vertices, np.float64))
    for edge in mesh.topology.findHoleRepresentiveEdges():
        mr.fillHole(mesh, edge)
    closed = trimesh.Trimesh(mn.getNumpyVerts(mesh), mn.getNumpyFaces(mesh.topology), process=False)
    closed.merge_vertices()
    return closed


def pymeshfix_whole(mesh: trimesh.Trimesh, folder: Path) -> trimesh.Trimesh:
    merged = mesh.copy()
    merged.merge_vertices()
    fixer = pymeshfix.MeshFix(np.asarray(merged.vertices, float), np.asarray(merged.faces, np.int32))
    fixer.repair(joincomp=True, remove_smallest_components=False)
    return trimesh.Trimesh(fixer.points, fixer.faces, process=False)


def gwn_voxels(cells: int):
    def run(mesh: trimesh.Trimesh, folder: Path) -> trimesh.Trimesh:
        merged = mesh.copy()
        merged.merge_vertices()
        pitch = merged.extents.max() / cells
        lower = merged.bounds[0] - 2 * pitch
        counts = np.ceil((merged.extents + 4 * pitch) / pitch).astype(int) + 1
        axes = [lower[i] + pitch * np.arange(counts[i]) for i in range(3)]
        # libigl's grid order: x varies fastest
        z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
        grid = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
        winding = igl.fast_winding_number(np.asarray(merged.vertices, float), np.asarray(merged.faces, np.int64), grid)
        vertices, faces, _ = igl.marching_cubes(np.abs(winding), grid, *(int(c) for c in counts), 0.5)
        out = trimesh.Trimesh(vertices, faces)
        if out.volume < 0:
            out.invert()
        return out

    return run


def reference(mesh: trimesh.Trimesh) -> tuple[float, int]:
    """Volume (mm³) and solid count fcso reads from a closed mesh; NaN and 0 for open shells (no reference)."""
    try:
        solids, _ = mesh_solids(mesh, "reference")
    except MeshError:
        return float("nan"), 0
    return sum(float(s.mesh.volume) for s in solids), len(solids)


def outcome(mesh: trimesh.Trimesh | None) -> tuple[bool, float, int]:
    """Closed and consistently wound, its volume, its solids."""
    if mesh is None or len(mesh.faces) == 0:
        return False, float("nan"), 0
    if not mesh.is_watertight:
        # a triangle soup's corners are shared by position; a solid's by index
        # (two lobes of it may touch along an edge without sharing it)
        mesh = mesh.copy()
        mesh.merge_vertices()
    if not (mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0):
        return False, float("nan"), 0
    try:
        solids, _ = mesh_solids(mesh, "result")
    except MeshError:
        return False, float("nan"), 0
    return True, sum(float(s.mesh.volume) for s in solids), len(solids)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, default=96, help="GWN grid cells along the longest side")
    args = parser.parse_args()
    warnings.filterwarnings("ignore")
    candidates = {
        "fcso (MeshFix per shell)": fcso_repair,
        "trimesh+manifold3d": with_filler(fill_trimesh),
        "pymeshfix whole": pymeshfix_whole,
        f"libigl GWN {args.cells}": gwn_voxels(args.cells),
    }
    try:
        import meshlib.mrmeshpy  # noqa: F401

        candidates["meshlib+manifold3d"] = with_filler(fill_meshlib)
    except ImportError:
        print("meshlib not installed: not measured")
    cases = []
    for name in AS_PUBLISHED:
        mesh = read_mesh(REPO / name)
        slivers_out = trimesh.Trimesh(mesh.vertices, mesh.faces[mesh.nondegenerate_faces()], process=False)
        slivers_out.remove_unreferenced_vertices()
        cases.append((Path(name).name, "as published", mesh, *reference(slivers_out)))
    for name in CLOSED:
        mesh = read_mesh(REPO / name)
        cases.extend(
            (Path(name).name, kind, break_mesh(mesh, kind), *reference(intact_mesh(mesh, kind))) for kind in KINDS
        )
    totals = {name: [0, 0, []] for name in candidates}
    print(
        f"{'file':28s} {'broken':12s} {'candidate':26s} {'ok':5s} "
        f"{'solids':>6s} {'dV %':>8s} {'time s':>7s} {'volume':>10s}"
    )
    with tempfile.TemporaryDirectory() as folder:
        for file, kind, mesh, volume, solids in cases:
            for name, repair in candidates.items():
                start = time.perf_counter()
                try:
                    result = repair(mesh, Path(folder))
                except Exception:  # a candidate failing is a measured outcome
                    result = None
                seconds = time.perf_counter() - start
                closed, repaired_volume, count = outcome(result)
                change = 100 * (repaired_volume - volume) / volume
                ok = closed and (count == solids or solids == 0) and not abs(change) > MAX_VOLUME_CHANGE_PERCENT
                totals[name][0] += ok
                totals[name][1] += 1
                if ok and np.isfinite(change):
                    totals[name][2].append(abs(change))
                print(
                    f"{file:28s} {kind:12s} {name:26s} {ok!s:5s} "
                    f"{count:6d} {change:+8.3f} {seconds:7.2f} {repaired_volume:10.1f}",
                    flush=True,
                )
    print("\ncandidate                  success  median |dV| %  max |dV| % (successes)")
    for name, (good, total, changes) in totals.items():
        median = f"{np.median(changes):.3f}" if changes else "-"
        largest = f"{max(changes):.3f}" if changes else "-"
        print(f"{name:26s} {good:3d}/{total:<3d}  {median:>13s}  {largest:>9s}")


if __name__ == "__main__":
    main()
