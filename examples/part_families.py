"""Procedural test parts: families of printed-part shapes with random parameters (METHOD §7c's splits).

A farm's next part is new, and often of a family nobody drew. So the
parts the method is judged on are drawn, not chosen: each family below
makes a part from a :class:`numpy.random.Generator`, with its counts,
sizes, angles and feature profiles drawn within what a 50 mm parallel
gripper (40 mm between its 5 mm pads) can hold. The families are split:

- :data:`DEVELOPMENT_FAMILIES`: what the method may be tuned on (with
  :data:`DEVELOPMENT_SEEDS`);
- :data:`HELD_OUT_FAMILIES`: about a third of the families, never tuned on,
  reported only (with :data:`TEST_SEEDS`, as are the development families'
  other seeds);
- :data:`CONTROL_FAMILIES`: featureless parts in both splits, where the
  right answer is "flat is as good".

:func:`draw` makes one part; :func:`split` lists a split's parts. Every part
is built with manifold3d, so it is one closed, oriented solid, in mm, resting
on z = 0 in the pose it is drawn in (the design chooses its own poses).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import manifold3d
import numpy as np
import trimesh

Solid = manifold3d.Manifold


@dataclass(frozen=True)
class DrawnPart:
    """A drawn part.

    Attributes
    ----------
    name : str
        ``family-seed``, unique within a split.
    family : str
    seed : int
    mesh : trimesh.Trimesh
        Closed, in mm.
    caging : bool
        Whether the family has a feature that can cage the part between two pads (by construction).
    description : str
        The drawn parameters, for the benchmark's table.
    """

    name: str
    family: str
    seed: int
    mesh: trimesh.Trimesh
    caging: bool
    description: str


def _mesh(solid: Solid) -> trimesh.Trimesh:
    mesh = solid.to_mesh()
    return trimesh.Trimesh(np.asarray(mesh.vert_properties[:, :3]), np.asarray(mesh.tri_verts), process=True)


def _prism(outline: list[list[float]], height_mm: float) -> Solid:
    """A vertical prism over a counter-clockwise outline in the xy plane, from z = 0 to ``height_mm``."""
    return Solid.extrude(manifold3d.CrossSection([outline]), height_mm)


def _union(solids: list[Solid]) -> Solid:
    return Solid.batch_boolean(solids, manifold3d.OpType.Add)


def _uniform(rng: np.random.Generator, low: float, high: float) -> float:
    return round(float(rng.uniform(low, high)), 1)


def _groove(profile: str, depth_mm: float, width_mm: float, length_mm: float) -> Solid:
    """A groove cutter along z, its opening (``width_mm`` wide) on the plane x = 0, cutting to x = -depth_mm.

    ``profile`` is ``"v"`` (a triangle), ``"square"`` (a rectangle) or ``"round"`` (a half-cylinder whose
    radius is the half-width; ``depth_mm`` is then the radius).
    """
    half = width_mm / 2.0
    if profile == "v":
        # widened past the face so the cut leaves no skin
        spread = half * (depth_mm + 1.0) / depth_mm
        return _prism([[-depth_mm, 0.0], [1.0, -spread], [1.0, spread]], length_mm)
    if profile == "square":
        return Solid.cube([depth_mm + 1.0, width_mm, length_mm]).translate([-depth_mm, -half, 0.0])
    return Solid.cylinder(length_mm, half, circular_segments=32)


# ---- development families ------------------------------------------------------------------------------------------


def notched_bar(rng: np.random.Generator) -> tuple[Solid, str]:
    """A long bar lying flat whose one long edge carries a row of V-notches (the paper's zig-zag, simplified)."""
    length, width, thickness = _uniform(rng, 45, 70), _uniform(rng, 14, 24), _uniform(rng, 6, 12)
    notches, depth = int(rng.integers(3, 7)), _uniform(rng, 2.0, 4.0)
    opening = 2.0 * depth * np.tan(np.radians(_uniform(rng, 35, 50)))
    bar = Solid.cube([length, width, thickness])
    pitch = max(opening * 1.2, _uniform(rng, 5, 9))
    start = (length - notches * pitch) / 2.0 + pitch / 2.0
    groove = _groove("v", depth, opening, thickness + 2.0).rotate([0.0, 0.0, -90.0])
    cuts = [groove.translate([start + k * pitch, 0.0, -1.0]) for k in range(notches)]
    return bar - _union(cuts), f"{length:g}x{width:g}x{thickness:g} mm, {notches} V-notches {depth:g} mm deep"


def slotted_block(rng: np.random.Generator) -> tuple[Solid, str]:
    """A block with a vertical slot of a drawn profile in each of two opposite faces."""
    size = [_uniform(rng, 20, 34), _uniform(rng, 20, 34), _uniform(rng, 15, 30)]
    profile = str(rng.choice(["v", "square", "round"]))
    depth, width = _uniform(rng, 2.0, 5.0), _uniform(rng, 4.0, 10.0)
    if profile == "round":
        depth = width / 2.0
    block = Solid.cube(size)
    groove = _groove(profile, depth, width, size[2] + 2.0)
    offset = _uniform(rng, -0.2, 0.2) * size[1]
    cuts = [
        groove.translate([size[0], size[1] / 2 + offset, -1.0]),
        groove.rotate([0.0, 0.0, 180.0]).translate([0.0, size[1] / 2 - offset, -1.0]),
    ]
    text = f"{size[0]:g}x{size[1]:g}x{size[2]:g} mm, {profile} slots {width:g} mm wide, {depth:g} mm deep"
    return block - _union(cuts), text


def knurled_knob(rng: np.random.Generator) -> tuple[Solid, str]:
    """A cylinder standing on its base with axial ridges of a drawn profile round its side."""
    radius, height = _uniform(rng, 8, 16), _uniform(rng, 12, 28)
    ridges, ridge = int(rng.integers(10, 28)), _uniform(rng, 0.8, 2.0)
    profile = str(rng.choice(["square", "v", "round"]))
    body = Solid.cylinder(height, radius, circular_segments=96)
    if profile == "square":
        one = Solid.cube([ridge * 2.0, ridge, height]).translate([radius - ridge, -ridge / 2.0, 0.0])
    elif profile == "v":
        one = _prism([[radius - ridge, -ridge], [radius + ridge, 0.0], [radius - ridge, ridge]], height)
    else:
        one = Solid.cylinder(height, ridge / 1.5, circular_segments=24).translate([radius, 0.0, 0.0])
    parts = [body] + [one.rotate([0.0, 0.0, 360.0 * k / ridges]) for k in range(ridges)]
    return _union(parts), f"r {radius:g} mm, h {height:g} mm, {ridges} {profile} ridges {ridge:g} mm"


def spur_gear(rng: np.random.Generator) -> tuple[Solid, str]:
    """A gear lying flat with teeth of a drawn profile and a bore."""
    teeth, module = int(rng.integers(10, 22)), _uniform(rng, 1.2, 2.2)
    thickness, profile = _uniform(rng, 6, 14), str(rng.choice(["trapezoid", "square", "triangle"]))
    pitch_r = module * teeth / 2.0
    root_r, tip_r = pitch_r - 1.25 * module, pitch_r + module
    tip_share = {"trapezoid": 0.25, "square": 0.45, "triangle": 0.02}[profile]
    outline = []
    for k in range(teeth):
        centre, half = 2.0 * np.pi * k / teeth, np.pi / teeth
        for angle, r in (
            (centre - half, root_r),
            (centre - 0.45 * half, root_r),
            (centre - tip_share * half, tip_r),
            (centre + tip_share * half, tip_r),
            (centre + 0.45 * half, root_r),
        ):
            outline.append([r * np.cos(angle), r * np.sin(angle)])
    bore = _uniform(rng, 3, max(3.5, root_r))
    gear = _prism(outline, thickness) - Solid.cylinder(thickness + 2, bore / 2, circular_segments=48).translate(
        [0, 0, -1]
    )
    return gear, f"{teeth} {profile} teeth, module {module:g} mm, {thickness:g} mm thick"


def polygon_prism(rng: np.random.Generator) -> tuple[Solid, str]:
    """A regular prism of 5 to 8 sides standing on a polygon face."""
    sides, across, height = int(rng.integers(5, 9)), _uniform(rng, 16, 34), _uniform(rng, 10, 30)
    radius = across / 2.0 / np.cos(np.pi / sides)
    twist = float(rng.uniform(0, 360.0 / sides))
    return (
        Solid.cylinder(height, radius, circular_segments=sides).rotate([0, 0, twist]),
        f"{sides} sides, {across:g} mm across, h {height:g} mm",
    )


def dovetail_block(rng: np.random.Generator) -> tuple[Solid, str]:
    """A block with a vertical dovetail tongue on each of two opposite faces."""
    size = [_uniform(rng, 18, 30), _uniform(rng, 20, 34), _uniform(rng, 12, 28)]
    root, tip, depth = _uniform(rng, 5, 9), _uniform(rng, 8, 14), _uniform(rng, 2.5, 5)
    tongue = _prism([[0.0, -root / 2], [depth, -tip / 2], [depth, tip / 2], [0.0, root / 2]], size[2])
    solid = _union(
        [
            Solid.cube(size),
            tongue.translate([size[0] - 0.01, size[1] / 2, 0]),
            tongue.rotate([0, 0, 180]).translate([0.01, size[1] / 2, 0]),
        ]
    )
    return solid, f"{size[0]:g}x{size[1]:g}x{size[2]:g} mm, dovetails {root:g}-{tip:g} mm, {depth:g} mm out"


def holed_block(rng: np.random.Generator) -> tuple[Solid, str]:
    """A block with horizontal through holes near two opposite faces and chamfered vertical edges."""
    size = [_uniform(rng, 22, 34), _uniform(rng, 22, 34), _uniform(rng, 14, 28)]
    hole = _uniform(rng, 4, 9)
    inset = _uniform(rng, hole / 2 + 1.2, hole / 2 + 3.0)
    block = Solid.cube(size)
    drill = Solid.cylinder(size[1] + 2, hole / 2, circular_segments=32).rotate([-90, 0, 0])
    cuts = [drill.translate([x, -1, size[2] / 2]) for x in (inset, size[0] - inset)]
    chamfer = _uniform(rng, 1.5, 5)
    edge = Solid.cube([chamfer, chamfer, size[2] + 2], center=True).rotate([0, 0, 45])
    cuts += [edge.translate([x, y, size[2] / 2]) for x in (0, size[0]) for y in (0, size[1])]
    return block - _union(cuts), f"{size[0]:g}x{size[1]:g}x{size[2]:g} mm, holes {hole:g} mm at {inset:g} mm"


def boss_block(rng: np.random.Generator) -> tuple[Solid, str]:
    """A square base with a round boss on top (a knob's cap): the boss fixes no rotation, the base's flats do."""
    base, base_h = _uniform(rng, 18, 32), _uniform(rng, 6, 14)
    boss_r, boss_h = _uniform(rng, 4, base / 2 - 2), _uniform(rng, 6, 16)
    solid = Solid.cube([base, base, base_h]) + Solid.cylinder(boss_h + 0.5, boss_r, circular_segments=64).translate(
        [base / 2, base / 2, base_h - 0.5]
    )
    return solid, f"base {base:g} mm x {base_h:g} mm, boss r {boss_r:g} mm x {boss_h:g} mm"


def stepped_block(rng: np.random.Generator) -> tuple[Solid, str]:
    """A block whose two opposite faces carry a vertical step (a shoulder) each, off-centre."""
    size = [_uniform(rng, 16, 26), _uniform(rng, 24, 36), _uniform(rng, 14, 28)]
    step, share = _uniform(rng, 2, 5), _uniform(rng, 0.3, 0.6)
    ledge = Solid.cube([step, size[1] * share, size[2]])
    solid = _union(
        [
            Solid.cube(size),
            ledge.translate([size[0] - 0.01, 0, 0]),
            ledge.translate([-step + 0.01, size[1] * (1 - share), 0]),
        ]
    )
    return solid, f"{size[0]:g}x{size[1]:g}x{size[2]:g} mm, steps {step:g} mm over {share:.0%}"


# ---- held-out families ---------------------------------------------------------------------------------------------


def tslot_nut(rng: np.random.Generator) -> tuple[Solid, str]:
    """A T-slot nut lying on its flange: a T profile extruded, with a threaded-hole bore."""
    flange_w, flange_h = _uniform(rng, 16, 26), _uniform(rng, 3, 6)
    neck_w, neck_h, length = _uniform(rng, 7, flange_w - 5), _uniform(rng, 3, 7), _uniform(rng, 12, 30)
    outline = [
        [-flange_w / 2, 0],
        [flange_w / 2, 0],
        [flange_w / 2, flange_h],
        [neck_w / 2, flange_h],
        [neck_w / 2, flange_h + neck_h],
        [-neck_w / 2, flange_h + neck_h],
        [-neck_w / 2, flange_h],
        [-flange_w / 2, flange_h],
    ]
    body = _prism(outline, length).rotate([90, 0, 0])
    bore = Solid.cylinder(40, min(neck_w / 2 - 1, 3.0), circular_segments=32).translate([0, -length / 2, -5])
    body = body - bore
    return body, f"flange {flange_w:g}x{flange_h:g} mm, neck {neck_w:g}x{neck_h:g} mm, {length:g} mm long"


def d_shaft(rng: np.random.Generator) -> tuple[Solid, str]:
    """A short shaft standing on its end, with one flat (D) or two (double D) along its side."""
    radius, height = _uniform(rng, 6, 15), _uniform(rng, 12, 30)
    flats, cut = int(rng.integers(1, 3)), _uniform(rng, 0.15, 0.3)
    shaft = Solid.cylinder(height, radius, circular_segments=96)
    slab = Solid.cube([radius, 3 * radius, height + 2]).translate([radius * (1 - cut), -1.5 * radius, -1])
    cuts = [slab.rotate([0, 0, 180.0 * k]) for k in range(flats)]
    return shaft - _union(cuts), f"r {radius:g} mm, h {height:g} mm, {flats} flat(s) {cut:.0%} deep"


def cam(rng: np.random.Generator) -> tuple[Solid, str]:
    """A disc cam lying flat: a base circle and one lobe (a convex, non-round outline), with a bore."""
    base_r, lift, thickness = _uniform(rng, 8, 14), _uniform(rng, 3, 7), _uniform(rng, 5, 12)
    angles = np.linspace(0, 2 * np.pi, 120, endpoint=False)
    radius = base_r + lift * np.clip(np.cos(angles), 0, None) ** 2
    outline = np.column_stack([radius * np.cos(angles), radius * np.sin(angles)]).tolist()
    bore = Solid.cylinder(thickness + 2, 2.5, circular_segments=32).translate([0, 0, -1])
    return _prism(outline, thickness) - bore, f"base r {base_r:g} mm, lift {lift:g} mm, {thickness:g} mm thick"


def gusset_bracket(rng: np.random.Generator) -> tuple[Solid, str]:
    """An L bracket standing on one leg, with a triangular gusset between its legs."""
    width, leg, upright, wall = _uniform(rng, 14, 30), _uniform(rng, 20, 34), _uniform(rng, 18, 32), _uniform(rng, 3, 5)
    gusset_t = _uniform(rng, 2.5, 4)
    base = Solid.cube([leg, width, wall])
    wall_solid = Solid.cube([wall, width, upright])
    gusset = _prism([[wall - 0.1, 0], [leg * 0.8, 0], [wall - 0.1, upright * 0.8]], gusset_t).rotate([90, 0, 0])
    gusset = gusset.translate([0, width / 2 + gusset_t / 2, wall - 0.1])
    return _union([base, wall_solid, gusset]), f"legs {leg:g}/{upright:g} mm, {width:g} mm wide, wall {wall:g} mm"


def pipe_tee(rng: np.random.Generator) -> tuple[Solid, str]:
    """A pipe tee lying on its side: a run and a branch of one outer diameter, hollow."""
    outer, run, branch = _uniform(rng, 8, 16), _uniform(rng, 30, 50), _uniform(rng, 12, 22)
    wall = _uniform(rng, 1.6, 3)
    r = outer / 2
    run_solid = Solid.cylinder(run, r, circular_segments=48, center=True).rotate([0, 90, 0])
    branch_solid = Solid.cylinder(branch, r, circular_segments=48).rotate([-90, 0, 0])
    bore_run = Solid.cylinder(run + 2, r - wall, circular_segments=48, center=True).rotate([0, 90, 0])
    bore_branch = Solid.cylinder(branch + 1, r - wall, circular_segments=48).rotate([-90, 0, 0])
    solid = (run_solid + branch_solid) - bore_run - bore_branch
    return solid.translate([0, 0, r]), f"OD {outer:g} mm, run {run:g} mm, branch {branch:g} mm, wall {wall:g} mm"


# ---- featureless controls ------------------------------------------------------------------------------------------


def plain_box(rng: np.random.Generator) -> tuple[Solid, str]:
    """A plain box: nothing to cage."""
    size = [_uniform(rng, 15, 34), _uniform(rng, 15, 34), _uniform(rng, 10, 30)]
    return Solid.cube(size), f"{size[0]:g}x{size[1]:g}x{size[2]:g} mm"


def plain_cylinder(rng: np.random.Generator) -> tuple[Solid, str]:
    """A plain cylinder standing on its base: nothing to cage, round about the vertical."""
    radius, height = _uniform(rng, 7, 16), _uniform(rng, 10, 30)
    return Solid.cylinder(height, radius, circular_segments=96), f"r {radius:g} mm, h {height:g} mm"


Family = Callable[[np.random.Generator], tuple[Solid, str]]

#: Families the method may be tuned on.
DEVELOPMENT_FAMILIES: dict[str, Family] = {
    "notched-bar": notched_bar,
    "slotted-block": slotted_block,
    "knurled-knob": knurled_knob,
    "spur-gear": spur_gear,
    "polygon-prism": polygon_prism,
    "dovetail-block": dovetail_block,
    "holed-block": holed_block,
    "boss-block": boss_block,
    "stepped-block": stepped_block,
}
#: About a third of the families: never tuned on, reported only.
HELD_OUT_FAMILIES: dict[str, Family] = {
    "tslot-nut": tslot_nut,
    "d-shaft": d_shaft,
    "cam": cam,
    "gusset-bracket": gusset_bracket,
    "pipe-tee": pipe_tee,
}
#: Featureless parts, in both splits.
CONTROL_FAMILIES: dict[str, Family] = {"plain-box": plain_box, "plain-cylinder": plain_cylinder}
FAMILIES: dict[str, Family] = {**DEVELOPMENT_FAMILIES, **HELD_OUT_FAMILIES, **CONTROL_FAMILIES}

#: Seeds of the development split; the test split draws other seeds.
DEVELOPMENT_SEEDS = (0, 1)
TEST_SEEDS = (100, 101)


def draw(family: str, seed: int) -> DrawnPart:
    """One part of ``family`` drawn with ``seed``, rested on z = 0 and centred in x and y.

    Parameters
    ----------
    family : str
        A key of :data:`FAMILIES`.
    seed : int

    Returns
    -------
    DrawnPart
    """
    solid, description = FAMILIES[family](np.random.default_rng([seed, sum(map(ord, family))]))
    mesh = _mesh(solid)
    low, high = mesh.bounds
    mesh.apply_translation([-(low[0] + high[0]) / 2.0, -(low[1] + high[1]) / 2.0, -low[2]])
    return DrawnPart(
        name=f"{family}-{seed}",
        family=family,
        seed=seed,
        mesh=mesh,
        caging=family not in CONTROL_FAMILIES,
        description=description,
    )


def split(name: str, seeds_per_family: int = 1) -> list[DrawnPart]:
    """The parts of a split.

    Parameters
    ----------
    name : {"development", "test"}
        ``development``: the development families and controls with :data:`DEVELOPMENT_SEEDS`; ``test``: every
        family (the held-out ones included) with :data:`TEST_SEEDS`.
    seeds_per_family : int
        How many of the split's seeds each family draws (at most 2).

    Returns
    -------
    list of DrawnPart
    """
    if name == "development":
        families, seeds = [*DEVELOPMENT_FAMILIES, *CONTROL_FAMILIES], DEVELOPMENT_SEEDS
    elif name == "test":
        families, seeds = list(FAMILIES), TEST_SEEDS
    else:
        raise ValueError(f"unknown split {name!r}: development or test")
    return [draw(family, seed) for seed in seeds[:seeds_per_family] for family in families]
