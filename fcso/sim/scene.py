"""The MuJoCo scene: table, part and a parallel gripper with two fingers (METHOD §12).

Frames. The world is the part's resting frame (table at z = 0, mm in
Python, metres in MuJoCo). The gripper body sits at the grasp's
tool-centre point (TCP z: approach, down; TCP y: closing axis). Each
finger body is that side's pad frame (u across the pad towards its back,
v along it, w up), so its slide joint runs along u: q = 0 is the seated
pad of the design, q > 0 opens. The two joints are coupled (q+ = q-) like
the Robotiq Hand-E's rack and pinion; each finger has a position actuator
whose force is clipped at the force limit.

The gripper's vertical motion is prescribed by its velocity (set at every
step, with a small correction towards the planned height) on a heavy,
gravity-compensated body with a vertical slide joint. Neither a mocap body
nor overwriting positions works: both teleport the fingers with zero
velocity, and friction, which MuJoCo computes from relative velocity, then
lets the part creep down the pads.
"""

from __future__ import annotations

import dataclasses
import hashlib
from dataclasses import dataclass, field

import mujoco
import numpy as np
import trimesh

from .config import VerifyConfig
from .report import PoseSnapshot

#: mm to MuJoCo's metres.
M = 1e-3
#: Position gain of the finger actuators: the force limit is reached 1 mm behind the target.
GAIN_N_PER_MM = 60.0
#: Mass of each finger, kg (a Hand-E finger with its pad).
FINGER_MASS_KG = 0.05
#: Mass of the gripper body, kg: heavy, so contacts barely disturb its prescribed motion.
GRIPPER_MASS_KG = 100.0
#: Pad frame to TCP frame rotation of the "+" and "-" fingers (columns: u, v, w in TCP coordinates).
PAD_AXES = {
    1: np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]).T,
    -1: np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]).T,
}
#: Which geoms collide (MuJoCo's contype/conaffinity bits): the part's pieces meet the fingers; the fingers each
#: other and the table; the part meets the table by its hull alone, which is exact against a plane and one geom
#: instead of the many pieces under its surface (each of which would add contacts with the table).
COLLIDES = {
    "part": 'contype="1" conaffinity="0"',
    "finger": 'contype="2" conaffinity="3"',
    "table": 'contype="4" conaffinity="2"',
    "part_hull": 'contype="8" conaffinity="4"',
}
#: Soft-contact parameters: a 2 ms time constant (>= 2 time steps) and a stiff impedance.
CONTACT_SOLREF = "0.002 1"
CONTACT_SOLIMP = "0.95 0.99 0.0005"
#: MuJoCo's arena (contacts, constraints and the solver's stack) of a scene whatever its pieces, bytes: MuJoCo's own
#: default for these scenes (14 MiB) and some.
ARENA_BASE_BYTES = 16 * 2**20
#: ... and per convex piece of the part and of a pad, bytes: a contact with its four constraint rows (elliptic cone,
#: condim 4) and its share of the solver takes about 2.2 kB (14 MiB ran out at 25933 rows, 6483 contacts), and a piece
#: touches a few others at up to four contacts each (multiccd).
ARENA_BYTES_PER_PIECE = 32 * 2**10


@dataclass
class GraspCase:
    """One grasp to simulate: a part in its resting pose and the two pads.

    Attributes
    ----------
    name : str
        Shown in reports.
    part : trimesh.Trimesh
        Closed part mesh in its resting frame, mm (table at z = 0).
    tcp : (4, 4) float
        TCP pose in the resting frame at the seated grasp, mm.
    pad_gap_mm : float
        Distance between the two pad frames' u = 0 planes at the seated grasp.
    pad_size_mm : (T, L, W)
    penetration_mm : float
        D: a flat pad's front face is at u = D.
    opening_mm : (min, max)
        Gripper opening range between the flat fingers' contact faces.
    part_file : trimesh.Trimesh or None
        The same part in its file frame (mm), so that one decomposition
        serves every pose of it; None: ``part`` is decomposed as it is.
    rest_transform : (4, 4) float
        File frame to resting frame (with ``part_file``).
    """

    name: str
    part: trimesh.Trimesh
    tcp: np.ndarray
    pad_gap_mm: float
    pad_size_mm: tuple[float, float, float]
    penetration_mm: float
    opening_mm: tuple[float, float]
    part_file: trimesh.Trimesh | None = None
    rest_transform: np.ndarray = field(default_factory=lambda: np.eye(4))

    @property
    def joint_range_mm(self) -> tuple[float, float]:
        """Finger joint range: q = (opening - (pad gap + 2 T)) / 2."""
        closing_width = self.pad_gap_mm + 2.0 * self.pad_size_mm[0]
        return ((self.opening_mm[0] - closing_width) / 2.0, (self.opening_mm[1] - closing_width) / 2.0)

    def pad_origin(self, side: int) -> np.ndarray:
        """Origin of a side's pad frame in the TCP frame at q = 0, mm."""
        length, width = self.pad_size_mm[1], self.pad_size_mm[2]
        return np.array([-side * length / 2.0, side * self.pad_gap_mm / 2.0, width / 2.0])


@dataclass
class Scene:
    """A compiled scene and the indices the trials need."""

    model: mujoco.MjModel
    part_body: int
    part_com_mm: np.ndarray
    lift_joint: int
    joints: tuple[int, int]
    actuators: tuple[int, int]
    part_geoms: np.ndarray
    pad_geoms: np.ndarray
    #: Content hash of the model's source (hex sha256): the same hash, the same physics (:mod:`fcso.sim.outcomes`).
    model_sha256: str
    #: How far the pads' faces lie inside the part's outermost point at the seated grasp (q = 0), mm: the penetration
    #: D for carved pads, 0 for flat ones (whose face is there).
    pad_inset_mm: float = 0.0
    #: The model's source without its arena size (the hash's, so that the arena leaves the outcomes' cache alone).
    xml: str = ""
    #: MuJoCo's arena of each simulation of the model, bytes (:func:`scene_arena_bytes`, :func:`with_arena`).
    arena_bytes: int = ARENA_BASE_BYTES
    #: Unit vector (world) along which the lift joint raises the gripper.
    lift_axis: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    #: Address of the part's free joint in qpos and in qvel.
    part_qpos: int = 0
    part_dof: int = 0


def _vec(values) -> str:
    return " ".join(f"{float(x):.9g}" for x in np.ravel(values))


def _quat(rotation: np.ndarray) -> str:
    quaternion = np.zeros(4)
    mujoco.mju_mat2Quat(quaternion, np.ascontiguousarray(rotation, dtype=np.float64).ravel())
    return _vec(quaternion)


def build_scene(
    case: GraspCase,
    part_pieces: list[tuple[np.ndarray, np.ndarray]],
    pad_pieces: list[tuple[np.ndarray, np.ndarray]] | None,
    finger_hull_mm: np.ndarray,
    config: VerifyConfig,
) -> Scene:
    """Compile the MuJoCo model of one grasp case.

    Parameters
    ----------
    case : GraspCase
    part_pieces : list of (vertices, faces)
        Convex pieces of the part, resting frame, mm.
    pad_pieces : list of (vertices, faces) or None
        Convex pieces of the carved pad, pad frame, mm; None for the flat
        control (a plain pad of thickness T - D, a box).
    finger_hull_mm : (n, 3) float
        Finger body behind the pad (pad frame, mm); may be empty.
    config : VerifyConfig

    Returns
    -------
    Scene
    """
    xml = scene_xml(case, part_pieces, pad_pieces, finger_hull_mm, config)
    arena = scene_arena_bytes(len(part_pieces), len(pad_pieces or []), config)
    model = _compiled(xml, arena)
    part_body = model.body("part").id
    pad_geoms = np.array([g for g in range(model.ngeom) if model.geom(g).name.startswith("pad_")])
    return Scene(
        model=model,
        part_body=part_body,
        part_com_mm=np.asarray(case.part.center_mass, dtype=float),
        lift_joint=model.joint("lift").id,
        joints=(model.joint("plus").id, model.joint("minus").id),
        actuators=(model.actuator("plus").id, model.actuator("minus").id),
        part_geoms=np.array([model.geom(f"part{k}").id for k in range(len(part_pieces))]),
        pad_geoms=pad_geoms,
        lift_axis=-np.asarray(case.tcp, dtype=float)[:3, 2],
        part_qpos=int(model.jnt_qposadr[model.joint("part").id]),
        part_dof=int(model.jnt_dofadr[model.joint("part").id]),
        model_sha256=hashlib.sha256(xml.encode()).hexdigest(),
        pad_inset_mm=0.0 if pad_pieces is None else float(case.penetration_mm),
        xml=xml,
        arena_bytes=arena,
    )


def scene_xml(
    case: GraspCase,
    part_pieces: list[tuple[np.ndarray, np.ndarray]],
    pad_pieces: list[tuple[np.ndarray, np.ndarray]] | None,
    finger_hull_mm: np.ndarray,
    config: VerifyConfig,
) -> str:
    """The MuJoCo model's source of one grasp case, without its arena size (:func:`build_scene`'s parameters)."""
    mass_kg = case.part.volume * config.density_g_cm3 * 1e-6
    com = np.asarray(case.part.center_mass, dtype=float)
    # trimesh's inertia is for unit density in mm^5: kg/mm^3 and mm^2 -> m^2
    inertia = np.asarray(case.part.moment_inertia) * config.density_g_cm3 * 1e-6 * 1e-6
    full_inertia = _vec([inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1], inertia[0, 2], inertia[1, 2]])
    tcp = np.asarray(case.tcp, dtype=float)
    assets, part_geoms = [], []
    for k, (vertices, _) in enumerate(part_pieces):
        assets.append(f'<mesh name="part{k}" vertex="{_vec(np.asarray(vertices) * M)}"/>')
        part_geoms.append(f'<geom name="part{k}" type="mesh" mesh="part{k}" class="contact" {COLLIDES["part"]}/>')
    hull = case.part.convex_hull
    assets.append(f'<mesh name="part_hull" vertex="{_vec(np.asarray(hull.vertices) * M)}"/>')
    part_geoms.append(f'<geom name="part_hull" type="mesh" mesh="part_hull" class="contact" {COLLIDES["part_hull"]}/>')
    if len(finger_hull_mm):
        assets.append(f'<mesh name="finger_body" vertex="{_vec(np.asarray(finger_hull_mm) * M)}"/>')
    for k, (vertices, _) in enumerate(pad_pieces or []):
        assets.append(f'<mesh name="pad{k}" vertex="{_vec(np.asarray(vertices) * M)}"/>')
    fingers = finger_bodies_xml(case, pad_pieces, finger_hull_mm)
    kp = GAIN_N_PER_MM / M
    force = config.force_limit_n
    return f"""<mujoco model="fcso-verify">
  <compiler angle="radian" inertiafromgeom="false"/>
  <option timestep="{config.timestep_s}" gravity="0 0 -9.81" cone="elliptic" impratio="10" integrator="implicitfast">
    <flag multiccd="enable"/>
  </option>
  <default>
    <default class="contact">
      <geom condim="4" friction="{config.friction} 0.002 0.0001" solref="{CONTACT_SOLREF}" solimp="{CONTACT_SOLIMP}"/>
    </default>
  </default>
  <asset>{"".join(assets)}</asset>
  <worldbody>
    <geom name="table" type="plane" size="1 1 0.01" class="contact" {COLLIDES["table"]}/>
    <body name="part">
      <freejoint name="part"/>
      <inertial pos="{_vec(com * M)}" mass="{mass_kg:.9g}" fullinertia="{full_inertia}"/>
      {"".join(part_geoms)}
    </body>
    <body name="gripper" gravcomp="1" pos="{_vec(tcp[:3, 3] * M)}" quat="{_quat(tcp[:3, :3])}">
      <inertial pos="0 0 0" mass="{GRIPPER_MASS_KG}" diaginertia="1e-3 1e-3 1e-3"/>
      <joint name="lift" type="slide" axis="0 0 -1"/>
      {"".join(fingers)}
    </body>
  </worldbody>
  <equality>
    <joint joint1="plus" joint2="minus" polycoef="0 1 0 0 0" solref="{CONTACT_SOLREF}"/>
  </equality>
  <actuator>
    <position name="plus" joint="plus" kp="{kp:.9g}" forcelimited="true" forcerange="{-force} {force}"/>
    <position name="minus" joint="minus" kp="{kp:.9g}" forcelimited="true" forcerange="{-force} {force}"/>
  </actuator>
</mujoco>"""


def finger_bodies_xml(
    case: GraspCase, pad_pieces: list[tuple[np.ndarray, np.ndarray]] | None, finger_hull_mm: np.ndarray
) -> list[str]:
    """The MuJoCo bodies of the "+" and "-" fingers, each on its slide joint with its pad's geoms (the carved pad's
    meshes ``pad<k>``, or the flat control's box when ``pad_pieces`` is None) and the finger body behind it
    (mesh ``finger_body``, when ``finger_hull_mm`` is not empty)."""
    thickness, length, width = case.pad_size_mm
    depth = case.penetration_mm
    q_min, q_max = case.joint_range_mm
    fingers = []
    for side, name in ((1, "plus"), (-1, "minus")):
        if pad_pieces is not None:
            geoms = [
                f'<geom name="pad_{name}{k}" type="mesh" mesh="pad{k}" class="contact" {COLLIDES["finger"]}/>'
                for k in range(len(pad_pieces))
            ]
        else:
            geoms = [
                f'<geom name="pad_{name}0" type="box" class="contact" {COLLIDES["finger"]} '
                f'pos="{_vec(np.array([(thickness + depth) / 2, length / 2, width / 2]) * M)}" '
                f'size="{_vec(np.array([(thickness - depth) / 2, length / 2, width / 2]) * M)}"/>'
            ]
        if len(finger_hull_mm):
            geoms.append(
                f'<geom name="finger_{name}" type="mesh" mesh="finger_body" class="contact" {COLLIDES["finger"]}/>'
            )
        fingers.append(
            f'<body name="finger_{name}" gravcomp="1" pos="{_vec(case.pad_origin(side) * M)}" '
            f'quat="{_quat(PAD_AXES[side])}">'
            f'<inertial pos="{_vec(np.array([thickness, length / 2, width / 2]) * M)}" mass="{FINGER_MASS_KG}" '
            f'diaginertia="1e-5 1e-5 1e-5"/>'
            f'<joint name="{name}" type="slide" axis="1 0 0" range="{q_min * M:.9g} {q_max * M:.9g}" damping="100" '
            f'armature="0.01"/>' + "".join(geoms) + "</body>"
        )
    return fingers


def scene_arena_bytes(part_pieces: int, pad_pieces: int, config: VerifyConfig) -> int:
    """MuJoCo's arena of a scene's simulations, bytes: ``config.arena_mb`` when set, else sized from its convex
    pieces (the part's and both pads')."""
    if config.arena_mb is not None:
        return int(config.arena_mb * 2**20)
    return ARENA_BASE_BYTES + ARENA_BYTES_PER_PIECE * (part_pieces + 2 * pad_pieces)


def with_arena(scene: Scene, arena_bytes: int) -> Scene:
    """``scene`` compiled again with an arena of ``arena_bytes`` (the same bodies, joints and geoms)."""
    return dataclasses.replace(scene, model=_compiled(scene.xml, arena_bytes), arena_bytes=arena_bytes)


def _compiled(xml: str, arena_bytes: int) -> mujoco.MjModel:
    """The model of ``xml`` (no ``<size>`` element) with an arena of ``arena_bytes``."""
    head, _, body = xml.partition("\n")
    return mujoco.MjModel.from_xml_string(f'{head}\n  <size memory="{arena_bytes}"/>\n{body}')


def pad_in_world(snapshot: PoseSnapshot, side: int, pad_gap_mm: float, pad_size_mm) -> np.ndarray:
    """4x4 pad frame -> world of one finger at a snapshot, mm."""
    thickness, length, width = pad_size_mm
    in_tcp = np.eye(4)
    in_tcp[:3, :3] = PAD_AXES[side]
    in_tcp[:3, 3] = [-side * length / 2.0, side * pad_gap_mm / 2.0, width / 2.0]
    opened = np.eye(4)
    opened[0, 3] = snapshot.opening_mm
    return np.asarray(snapshot.gripper_pose) @ in_tcp @ opened


def out_of_arena(error: mujoco.FatalError) -> bool:
    """Whether MuJoCo's fatal ``error`` is its arena running out (too many contacts and constraints)."""
    return "out of memory" in str(error)
