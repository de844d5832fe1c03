"""Foxglove scenes (``foxglove.SceneUpdate``, metres) of a job: its grasps, its placed build, a verification trial;
and its frames (``foxglove.FrameTransforms``) in one tree.

The messages are foxglove-sdk's own (``foxglove.messages``), protobuf-encoded
by the SDK under its schema: what the Foxglove app reads natively, recorded
into the job's MCAP by :meth:`Recorder.write_foxglove` and published live by
the daemon's Foxglove server (:mod:`fcsod.service.foxglove_live`).

The frame tree (:func:`design_transforms`, :func:`build_transforms`)::

    world
    ├── fcso_<part>_rest<k>          a part in resting pose k (the ROS 2 PoseArrays' frame), laid side by side
    │   └── <rest>_grasp             the TCP of its grasp (z: approach, y: closing axis)
    │       ├── <rest>_finger_plus   the finger mesh's frame, seated on the "+" side
    │       └── <rest>_finger_minus  and on the "-" side
    └── fcso_build                   the build volume's frame, beside the parts
        └── fcso_build_<item>        each placed part and finger copy (its mesh frame)
"""

from __future__ import annotations

import base64
import time

import numpy as np
import trimesh
from foxglove.messages import (
    ArrowPrimitive,
    Color,
    CubePrimitive,
    Duration,
    FrameTransform,
    FrameTransforms,
    KeyValuePair,
    Point3,
    Pose,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    TextPrimitive,
    Timestamp,
    TriangleListPrimitive,
    Vector3,
)

from fcso import DesignResult
from fcso.output.decimate import decimate
from fcso.sim.report import VerificationReport
from fcso.sim.scene import pad_in_world
from fcso.sim.verify import DesignUnderTest

from ..bus.messages import rest_frame_id
from ..plate.build3mf import BuildItem
from ..plate.models import BuildConfig, PlacementReport

#: No rotation.
UNROTATED = Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)

#: The pose of a primitive whose points are already in the entity's frame.
IDENTITY = Pose(position=Vector3(x=0.0, y=0.0, z=0.0), orientation=UNROTATED)

#: An entity that stays until replaced.
FOREVER = Duration(sec=0, nsec=0)

#: The root of the frame tree.
WORLD_FRAME = "world"

#: The build volume's frame.
BUILD_FRAME = "fcso_build"

#: An arrow along +z: the rotation taking a Foxglove arrow's +x onto +z (-90 degrees about y).
ALONG_Z = Quaternion(x=0.0, y=-(0.5**0.5), z=0.0, w=0.5**0.5)

#: Length of a grasp's approach arrow, m.
ARROW_M = 0.04


def stamp(time_ns: int) -> Timestamp:
    """A Foxglove timestamp of ``time_ns`` (ns since the Unix epoch)."""
    return Timestamp(sec=time_ns // 1_000_000_000, nsec=time_ns % 1_000_000_000)


def metadata(pairs: dict[str, str]) -> list[KeyValuePair]:
    return [KeyValuePair(key=k, value=v) for k, v in pairs.items()]


def base64_text(data: bytes) -> str:
    """``data`` as base64 text."""
    return base64.b64encode(data).decode()


def frame_transform(parent: str, child: str, matrix: np.ndarray, time_ns: int) -> FrameTransform:
    """The Foxglove transform of frame ``child`` in ``parent``: ``matrix`` (4x4, rigid, mm) maps child to parent."""
    w, x, y, z = trimesh.transformations.quaternion_from_matrix(matrix)
    return FrameTransform(
        timestamp=stamp(time_ns),
        parent_frame_id=parent,
        child_frame_id=child,
        translation=Vector3(**dict(zip("xyz", (np.asarray(matrix)[:3, 3] / 1000.0).tolist()))),
        rotation=Quaternion(x=float(x), y=float(y), z=float(z), w=float(w)),
    )


def grasp_frames(rest: str) -> tuple[str, str, str]:
    """The frames below a part's resting frame ``rest``: its grasp's TCP, the "+" finger's and the "-" finger's."""
    return f"{rest}_grasp", f"{rest}_finger_plus", f"{rest}_finger_minus"


def tcp_matrix(position_mm, quaternion_wxyz) -> np.ndarray:
    """4x4 of a grasp's TCP in its resting frame (mm) from a grasp report's position and orientation."""
    matrix = trimesh.transformations.quaternion_matrix(quaternion_wxyz)
    matrix[:3, 3] = position_mm
    return matrix


def _layout(result: DesignResult):
    """Per scenario (in order): the scenario, its evaluation, its sample and its shift along x in the side-by-side
    layout (4x4, mm).
    """
    offset_x = 0.0
    for scenario, sample_index, evaluation in zip(result.scenarios, result.best.choice, result.best.scenarios):
        bounds = scenario.mesh.bounds
        shift = np.eye(4)
        shift[0, 3] = offset_x - bounds[0, 0]
        yield scenario, evaluation, scenario.samples[sample_index], shift
        offset_x += 1.5 * float(np.ptp(bounds[:, 0])) + 60.0


def _finger_matrices(result: DesignResult, sample, evaluation) -> list[np.ndarray]:
    """The "+" and "-" fingers' mesh frames in the resting frame (4x4, mm), seated as evaluated."""
    to_pad = np.linalg.inv(result.pad_to_finger)
    fingers = []
    for frame, contact in zip(sample.frames, evaluation.contacts):
        seated = np.eye(4)
        seated[0, 3] = contact.offset_mm
        fingers.append(np.linalg.inv(frame) @ seated @ to_pad)
    return fingers


def design_transforms(result: DesignResult, time_ns: int) -> FrameTransforms:
    """The frames of a design (module docstring): each part's resting frame in ``world`` as :func:`scene_update` lays
    them out, its grasp's TCP in it (the grasp report's pose) and both fingers' frames in the TCP's.
    """
    grasps = {(g.part, g.pose_index): g for g in result.report.grasps}
    transforms = []
    for scenario, evaluation, sample, shift in _layout(result):
        rest = rest_frame_id(scenario.part.name, scenario.pose_index)
        grasp = grasps[(scenario.part.name, scenario.pose_index)]
        tcp = tcp_matrix(grasp.position_mm, grasp.quaternion_wxyz)
        tcp_frame, *finger_frames = grasp_frames(rest)
        transforms.append(frame_transform(WORLD_FRAME, rest, shift, time_ns))
        transforms.append(frame_transform(rest, tcp_frame, tcp, time_ns))
        for frame, finger in zip(finger_frames, _finger_matrices(result, sample, evaluation)):
            transforms.append(frame_transform(tcp_frame, frame, np.linalg.inv(tcp) @ finger, time_ns))
    return FrameTransforms(transforms=transforms)


def build_transforms(items: list[BuildItem], config: BuildConfig, time_ns: int) -> FrameTransforms:
    """The build's frames (module docstring): the build volume beside the parts (its depth and 100 mm along -y) and each
    placed item's mesh frame in it.
    """
    beside = np.eye(4)
    beside[1, 3] = -(float(config.volume_mm[1]) + 100.0)
    transforms = [frame_transform(WORLD_FRAME, BUILD_FRAME, beside, time_ns)]
    transforms += [
        frame_transform(BUILD_FRAME, f"{BUILD_FRAME}_{item.name}", item.transform, time_ns)
        for item in items
        if item.transform is not None
    ]
    return FrameTransforms(transforms=transforms)


def triangles(
    mesh: trimesh.Trimesh, transform: np.ndarray, color: tuple[float, float, float, float]
) -> TriangleListPrimitive:
    """``mesh`` moved by ``transform`` (mm) as a Foxglove triangle list in metres, coloured RGBA 0..1."""
    vertices = trimesh.transformations.transform_points(np.asarray(mesh.vertices), transform)
    return TriangleListPrimitive(
        pose=IDENTITY,
        points=[Point3(x=x, y=y, z=z) for x, y, z in (vertices / 1000.0).tolist()],
        color=Color(**dict(zip("rgba", color))),
        indices=np.asarray(mesh.faces).reshape(-1).tolist(),
    )


def scene_update(result: DesignResult, prefix: str = "") -> SceneUpdate:
    """Foxglove SceneUpdate: per scenario the rested part, both seated pads and both fingers, and its grasp: an arrow
    along the approach onto the TCP and a label; in metres.

    Each scenario is drawn in its part's resting frame, the grasp in its TCP frame (:func:`design_transforms` places
    them); entity ids are ``<prefix>scenario-<n>`` and ``<prefix>grasp-<n>`` (the prefix names a finger set).
    """
    now = stamp(time.time_ns())
    grasps = {(g.part, g.pose_index): g for g in result.report.grasps}
    entities = []
    for number, (scenario, evaluation, sample, _) in enumerate(_layout(result)):
        rest = rest_frame_id(scenario.part.name, scenario.pose_index)
        grasp = grasps[(scenario.part.name, scenario.pose_index)]
        drawn = [triangles(scenario.mesh, np.eye(4), (0.6, 0.6, 0.65, 1.0))]
        for frame, contact, finger in zip(
            sample.frames, evaluation.contacts, _finger_matrices(result, sample, evaluation)
        ):
            seated = np.eye(4)
            seated[0, 3] = contact.offset_mm
            drawn.append(triangles(result.fingerpad, np.linalg.inv(frame) @ seated, (0.9, 0.45, 0.1, 1.0)))
            drawn.append(triangles(result.finger, finger, (0.2, 0.4, 0.8, 0.35)))
        about = {"part": scenario.part.name, "pose_index": str(scenario.pose_index)}
        entities.append(
            SceneEntity(
                timestamp=now,
                frame_id=rest,
                id=f"{prefix}scenario-{number}",
                lifetime=FOREVER,
                frame_locked=True,
                metadata=metadata(about),
                triangles=drawn,
            )
        )
        arrow = ArrowPrimitive(
            pose=Pose(position=Vector3(x=0.0, y=0.0, z=-ARROW_M), orientation=ALONG_Z),
            shaft_length=0.8 * ARROW_M,
            shaft_diameter=0.002,
            head_length=0.2 * ARROW_M,
            head_diameter=0.005,
            color=Color(r=0.1, g=0.7, b=0.2, a=1.0),
        )
        label = TextPrimitive(
            pose=Pose(position=Vector3(x=0.0, y=0.0, z=-1.2 * ARROW_M), orientation=UNROTATED),
            billboard=True,
            font_size=14.0,
            scale_invariant=True,
            color=Color(r=1.0, g=1.0, b=1.0, a=1.0),
            text=f"{scenario.part.name} pose {scenario.pose_index}: closing width {grasp.closing_width_mm:g} mm",
        )
        entities.append(
            SceneEntity(
                timestamp=now,
                frame_id=grasp_frames(rest)[0],
                id=f"{prefix}grasp-{number}",
                lifetime=FOREVER,
                frame_locked=True,
                metadata=metadata({**about, "sample": str(grasp.sample)}),
                arrows=[arrow],
                texts=[label],
            )
        )
    return SceneUpdate(entities=entities)


def build_scene_update(items: list[BuildItem], report: PlacementReport, config: BuildConfig) -> SceneUpdate:
    """Foxglove SceneUpdate of the placed build in metres: the build volume, each part's bounding box and the finger
    copies.

    Parts are drawn as their boxes (a build may hold many large meshes); the
    fingers, small and the job's design, as triangles.

    Parameters
    ----------
    items : list of BuildItem
        The placed items (``PlacementResult.items``).
    report : PlacementReport
        Their bounding boxes and the placement's outcome.
    config : BuildConfig
        The build volume.
    """

    def box(lower, upper, color: tuple[float, float, float, float]) -> CubePrimitive:
        lower, upper = np.asarray(lower, dtype=float) / 1000.0, np.asarray(upper, dtype=float) / 1000.0
        centre = (lower + upper) / 2.0
        return CubePrimitive(
            pose=Pose(position=Vector3(**dict(zip("xyz", centre.tolist()))), orientation=UNROTATED),
            size=Vector3(**dict(zip("xyz", (upper - lower).tolist()))),
            color=Color(**dict(zip("rgba", color))),
        )

    origin = np.asarray(config.origin_mm, dtype=float)
    cubes = [box(origin, origin + np.asarray(config.volume_mm), (0.5, 0.5, 0.5, 0.08))]
    cubes += [box(*placed.bounds_mm, (0.6, 0.6, 0.65, 0.8)) for placed in report.items if placed.kind == "part"]
    fingers = [triangles(item.mesh, item.transform, (0.2, 0.4, 0.8, 1.0)) for item in items if item.kind == "finger"]
    entity = SceneEntity(
        timestamp=stamp(time.time_ns()),
        frame_id="fcso_build",
        id="build",
        lifetime=FOREVER,
        frame_locked=False,
        metadata=metadata(
            {
                "fingers_fit": str(report.fingers_fit).lower(),
                "build_height_mm": f"{report.build_height_mm:g}",
                "message": report.message,
            }
        ),
        cubes=cubes,
        triangles=fingers,
    )
    return SceneUpdate(entities=[entity])


#: Most part triangles drawn per scene frame.
SCENE_FACES = 1500


def scene_updates(verification: VerificationReport, design: DesignUnderTest, start_ns: int):
    """Foxglove SceneUpdates (metres) of the first scenario's unperturbed grasp with the designed pads; yields (update,
    log time ns).
    """
    if not verification.scenarios:
        return
    scenario, case = verification.scenarios[0], design.cases[0]
    vertices, faces = decimate(np.asarray(case.part.vertices), np.asarray(case.part.faces), SCENE_FACES)
    part = trimesh.Trimesh(vertices, faces, process=False)
    for snapshot in scenario.frames:
        at = start_ns + int(snapshot.time_s * 1e9)
        drawn = [triangles(part, np.asarray(snapshot.part_pose), (0.6, 0.6, 0.65, 1.0))]
        for side in (1, -1):
            drawn.append(
                triangles(
                    design.fingerpad,
                    pad_in_world(snapshot, side, case.pad_gap_mm, case.pad_size_mm),
                    (0.9, 0.45, 0.1, 1.0),
                )
            )
        entity = SceneEntity(
            timestamp=stamp(at),
            frame_id="fcso_verify",
            id="trial",
            lifetime=FOREVER,
            frame_locked=False,
            metadata=metadata({"part": scenario.part, "time_s": f"{snapshot.time_s:.3f}"}),
            triangles=drawn,
        )
        yield SceneUpdate(entities=[entity]), at
