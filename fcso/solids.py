"""The solids of a mesh as a slicer prints it: shells that overlap or touch are one solid (manifold3d union), a shell
nested inside another (an internal void, or a piece inside that void) stays with its outer solid.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import manifold3d
import trimesh

from .errors import MeshError
from .geometry import to_manifold, to_trimesh


@dataclass
class Solid:
    """One solid of a mesh as a slicer prints it.

    Attributes
    ----------
    mesh : trimesh.Trimesh
        Closed mesh of the solid, with its internal voids, mm.
    shells : int
        Shells of the input mesh that went into it.
    """

    mesh: trimesh.Trimesh
    shells: int


def mesh_solids(mesh: trimesh.Trimesh, source: str | Path) -> tuple[list[Solid], int]:
    """Split a closed mesh into the solids a slicer would print, largest first.

    Shells that overlap or touch are united (manifold3d); an inward shell (a
    void) and any shell inside a void stay with the outermost solid that
    encloses them.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        A validated closed, oriented mesh.
    source : str or Path
        Names the file in errors.

    Returns
    -------
    solids : list of Solid
        Largest volume first. With one shell, the mesh itself.
    shells : int
        Number of shells of ``mesh``.

    Raises
    ------
    MeshError
        A shell manifold3d cannot take as a closed manifold.
    """
    shells = mesh.split(only_watertight=False)
    if len(shells) <= 1:
        return [Solid(mesh=mesh, shells=1)], 1
    return unite_shells(shells, source), len(shells)


def unite_shells(shells: list[trimesh.Trimesh], source: str | Path) -> list[Solid]:
    """The solids of closed, oriented shells (see :func:`mesh_solids`), largest first."""
    manifolds = []
    for number, shell in enumerate(shells):
        if shell.volume < 0:
            shell = shell.copy()
            shell.invert()
        try:
            manifolds.append(to_manifold(shell))
        except Exception as exc:
            raise MeshError(source, f"shell {number + 1} of {len(shells)} is not a closed manifold ({exc})") from None
    outward = [shell.volume > 0 for shell in shells]
    voids = [m for m, out in zip(manifolds, outward) if not out]
    void_union = manifold3d.Manifold.batch_boolean(voids, manifold3d.OpType.Add) if voids else None
    # a shell inside a void is a piece in that cavity: added back after the voids are cut
    islands = [
        out and void_union is not None and (m ^ void_union).volume() >= m.volume() * (1 - 1e-6)
        for m, out in zip(manifolds, outward)
    ]
    solid = manifold3d.Manifold.batch_boolean(
        [m for m, out, island in zip(manifolds, outward, islands) if out and not island], manifold3d.OpType.Add
    )
    if void_union is not None:
        solid = solid - void_union
    if any(islands):
        solid = manifold3d.Manifold.batch_boolean(
            [solid] + [m for m, island in zip(manifolds, islands) if island], manifold3d.OpType.Add
        )
    components = [to_trimesh(c) for c in solid.decompose()]
    outer = [c for c in components if c.volume > 0]
    owners = [outermost_container(c, outer) for c in components]
    solids = []
    for index, component in enumerate(components):
        if owners[index] is not None:
            continue
        members = [c for c, owner in zip(components, owners) if owner is component or c is component]
        whole = trimesh.util.concatenate(members) if len(members) > 1 else component
        filled = to_manifold(component)
        count = sum(1 for m, out in zip(manifolds, outward) if (m ^ filled).volume() > 1e-9 * abs(filled.volume()))
        solids.append(Solid(mesh=whole, shells=max(count, 1)))
    solids.sort(key=lambda s: -s.mesh.volume)
    return solids


def outermost_container(component: trimesh.Trimesh, outer: list[trimesh.Trimesh]) -> trimesh.Trimesh | None:
    """The largest outward shell other than ``component`` that encloses it, or None."""
    probe = component.triangles_center[:1]
    containers = [o for o in outer if o is not component and o.contains(probe)[0]]
    return max(containers, key=lambda o: o.volume) if containers else None
