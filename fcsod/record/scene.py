"""Foxglove scenes (``foxglove.SceneUpdate``, metres) of a job: its grasps, its placed build, a verification trial.

The messages are foxglove-sdk's own (``foxglove.messages``), protobuf-encoded
by the SDK under its schema: what the Foxglove app reads natively, recorded
into the job's MCAP by :meth:`Recorder.write_foxglove` and published live by
the daemon's Foxglove server (:mod:`fcsod.service.foxglove_live`).
"""

from __future__ import annotations

import base64
import time

import numpy as np
import trimesh
from foxglove.messages import (
    Color,
    CubePrimitive,
    Duration,
    KeyValuePair,
    Point3,
    Pose,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    Timestamp,
    TriangleListPrimitive,
    Vector3,
)

from fcso import DesignResult
from fcso.output.decimate import decimate
from fcso.sim.report import VerificationReport
from fcso.sim.scene import pad_in_world
from fcso.sim.verify import DesignUnderTest

from ..plate.build3mf import BuildItem
from ..plate.models import BuildConfig, PlacementReport

#: No rotation.
UNROTATED = Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)

#: The pose of a primitive whose points are already in the entity's frame.
IDENTITY = Pose(position=Vector3(x=0.0, y=0.0, z=0.0), orientation=UNROTATED)

#: An entity that stays until replaced.
FOREVER = Duration(sec=0, nsec=0)


def stamp(time_ns: int) -> Timestamp:
    """A Foxglove timestamp of ``time_ns`` (ns since the Unix epoch)."""
    return Timestamp(sec=time_ns // 1_000_000_000, nsec=time_ns % 1_000_000_000)


def metadata(pairs: dict[str, str]) -> list[KeyValuePair]:
    return [KeyValuePair(key=k, value=v) for k, v in pairs.items()]


def base64_text(data: bytes) -> str:
    """``data`` as base64 text."""
    return base64.b64encode(data).decode()


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
    """Foxglove SceneUpdate: per scenario the rested part, both seated pads and both fingers, in metres.

    Scenarios are laid side by side along x so they do not overlap; entity ids
    are ``<prefix>scenario-<n>`` (the prefix names a finger set).
    """
    now = stamp(time.time_ns())
    to_pad = np.linalg.inv(result.pad_to_finger)
    entities, offset_x = [], 0.0
    for number, (scenario, sample_index, evaluation) in enumerate(
        zip(result.scenarios, result.best.choice, result.best.scenarios)
    ):
        sample = scenario.samples[sample_index]
        bounds = scenario.mesh.bounds
        gap = 0.5 * float(np.ptp(bounds[:, 0])) + 60.0
        shift = np.eye(4)
        shift[0, 3] = offset_x - bounds[0, 0]
        drawn = [triangles(scenario.mesh, shift, (0.6, 0.6, 0.65, 1.0))]
        for frame, contact in zip(sample.frames, evaluation.contacts):
            seated = np.eye(4)
            seated[0, 3] = contact.offset_mm
            pad_to_rest = shift @ np.linalg.inv(frame) @ seated
            drawn.append(triangles(result.fingerpad, pad_to_rest, (0.9, 0.45, 0.1, 1.0)))
            drawn.append(triangles(result.finger, pad_to_rest @ to_pad, (0.2, 0.4, 0.8, 0.35)))
        entities.append(
            SceneEntity(
                timestamp=now,
                frame_id="fcso_rest",
                id=f"{prefix}scenario-{number}",
                lifetime=FOREVER,
                frame_locked=False,
                metadata=metadata({"part": scenario.part.name, "pose_index": str(scenario.pose_index)}),
                triangles=drawn,
            )
        )
        offset_x += float(np.ptp(bounds[:, 0])) + gap
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
