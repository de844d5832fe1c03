"""Foxglove scenes (``foxglove.SceneUpdate``, metres) of a job: its grasps, its placed build, a verification trial."""

from __future__ import annotations

import base64
import time

import numpy as np
import trimesh

from fcso import DesignResult
from fcso.output.render import decimate
from fcso.sim.report import VerificationReport
from fcso.sim.scene import pad_in_world
from fcso.sim.verify import DesignUnderTest

from ..build.build3mf import BuildItem
from ..build.models import BuildConfig, PlacementReport
from ..bus.messages import FoxgloveTime, SceneEntity, SceneUpdate, TriangleListPrimitive


def base64_text(data: bytes) -> str:
    """``data`` as base64 text."""
    return base64.b64encode(data).decode()


def triangles(
    mesh: trimesh.Trimesh, transform: np.ndarray, color: tuple[float, float, float, float]
) -> TriangleListPrimitive:
    """``mesh`` moved by ``transform`` (mm) as a Foxglove triangle list in metres, coloured RGBA 0..1."""
    vertices = trimesh.transformations.transform_points(np.asarray(mesh.vertices), transform)
    return TriangleListPrimitive.model_validate(
        {
            "pose": {
                "position": {"x": 0.0, "y": 0.0, "z": 0.0},
                "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
            },
            "points": [{"x": x, "y": y, "z": z} for x, y, z in (vertices / 1000.0).tolist()],
            "color": dict(zip("rgba", color)),
            "indices": np.asarray(mesh.faces).reshape(-1).tolist(),
        }
    )


def scene_update(result: DesignResult, prefix: str = "") -> SceneUpdate:
    """Foxglove SceneUpdate: per scenario the rested part, both seated pads and both fingers, in metres.

    Scenarios are laid side by side along x so they do not overlap; entity ids
    are ``<prefix>scenario-<n>`` (the prefix names a finger set).
    """
    now = time.time_ns()
    stamp = FoxgloveTime(sec=now // 1_000_000_000, nsec=now % 1_000_000_000)
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
                timestamp=stamp,
                frame_id="fcso_rest",
                id=f"{prefix}scenario-{number}",
                lifetime=FoxgloveTime(sec=0, nsec=0),
                frame_locked=False,
                metadata=[
                    {"key": "part", "value": scenario.part.name},
                    {"key": "pose_index", "value": str(scenario.pose_index)},
                ],
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
    now = time.time_ns()
    stamp = FoxgloveTime(sec=now // 1_000_000_000, nsec=now % 1_000_000_000)
    identity = {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}

    def box(lower, upper, color: tuple[float, float, float, float]) -> dict:
        lower, upper = np.asarray(lower, dtype=float) / 1000.0, np.asarray(upper, dtype=float) / 1000.0
        centre = (lower + upper) / 2.0
        return {
            "pose": {**identity, "position": dict(zip("xyz", centre.tolist()))},
            "size": dict(zip("xyz", (upper - lower).tolist())),
            "color": dict(zip("rgba", color)),
        }

    origin = np.asarray(config.origin_mm, dtype=float)
    cubes = [box(origin, origin + np.asarray(config.volume_mm), (0.5, 0.5, 0.5, 0.08))]
    cubes += [box(*placed.bounds_mm, (0.6, 0.6, 0.65, 0.8)) for placed in report.items if placed.kind == "part"]
    fingers = [triangles(item.mesh, item.transform, (0.2, 0.4, 0.8, 1.0)) for item in items if item.kind == "finger"]
    entity = SceneEntity(
        timestamp=stamp,
        frame_id="fcso_build",
        id="build",
        lifetime=FoxgloveTime(sec=0, nsec=0),
        frame_locked=False,
        metadata=[
            {"key": "fingers_fit", "value": str(report.fingers_fit).lower()},
            {"key": "build_height_mm", "value": f"{report.build_height_mm:g}"},
            {"key": "message", "value": report.message},
        ],
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
        stamp = FoxgloveTime(sec=at // 1_000_000_000, nsec=at % 1_000_000_000)
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
            timestamp=stamp,
            frame_id="fcso_verify",
            id="trial",
            lifetime=FoxgloveTime(sec=0, nsec=0),
            frame_locked=False,
            metadata=[{"key": "part", "value": scenario.part}, {"key": "time_s", "value": f"{snapshot.time_s:.3f}"}],
            triangles=drawn,
        )
        yield SceneUpdate(entities=[entity]), at
