"""The grasps of a design's chosen candidate as the report page shows them: from the design just run, or re-seated
from a design folder's report.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from ..contact import PadPlacement, contact_samples, seat
from ..evaluate import CandidateEvaluation, Scenario
from ..pad import surface_in_pad
from ..parts import Part
from ..printfit import closing_travel_mm
from ..report.models import DesignReport
from ..report.ranking import chosen_candidate
from ..rles import largest_empty_cap
from ..sampler import SIDES, GraspSample


@dataclass
class GraspScene:
    """What the page shows of one grasp scenario of the chosen candidate.

    Attributes
    ----------
    mesh : trimesh.Trimesh
        The part in its resting frame (mm).
    sample : GraspSample
        The chosen sample.
    placements : list of PadPlacement
        The seated "+" and "-" pads with their contact masks.
    normals : (n, 3) float
        Contact normals, resting frame.
    rles : float
        Chord radius of the largest empty cap of ``normals``.
    cap_centre : (3,) float
        Its centre.
    """

    mesh: trimesh.Trimesh
    sample: GraspSample
    placements: list[PadPlacement]
    normals: np.ndarray
    rles: float
    cap_centre: np.ndarray


def chosen_grasp_scenes(scenarios: list[Scenario], best: CandidateEvaluation) -> list[GraspScene]:
    """The grasps of a design's chosen candidate, one per scenario, from the design just run."""
    grasps = []
    for scenario, index, evaluation in zip(scenarios, best.choice, best.scenarios):
        chosen = scenario.samples[index]
        placements = [
            PadPlacement(frame, contact.offset_mm, surface, contact.contact)
            for frame, contact, surface in zip(chosen.frames, evaluation.contacts, chosen.surfaces)
        ]
        radius, centre = largest_empty_cap(evaluation.contact_normals)
        grasps.append(GraspScene(scenario.mesh, chosen.sample, placements, evaluation.contact_normals, radius, centre))
    return grasps


def reseat_grasps(report: DesignReport, parts: list[Part], fingerpad: trimesh.Trimesh) -> list[GraspScene]:
    """The grasps of a reported design's chosen candidate, re-seated (METHOD §6).

    The parts are moved into their recorded resting poses; each chosen
    sample's pad frames are rebuilt, the part surface inside each pad box is
    sampled with the design's seeds and seated against ``fingerpad``.

    Parameters
    ----------
    report : DesignReport
    parts : list of Part
        The report's parts, in its order, mm.
    fingerpad : trimesh.Trimesh
        The chosen pad, pad frame (mm), with merged vertices.
    """
    config = report.settings
    pad_vertices, pad_faces = np.asarray(fingerpad.vertices), np.asarray(fingerpad.faces)
    part_number = 0
    grasps = []
    for number, (scenario, index) in enumerate(zip(report.scenarios, chosen_candidate(report).samples)):
        # scenarios come part by part, in the order of the parts
        while parts[part_number].name != scenario.part:
            part_number += 1
        mesh = parts[part_number].mesh.copy()
        mesh.apply_transform(np.asarray(scenario.rest_transform, dtype=float))
        reported = scenario.samples[index]
        sample = GraspSample(
            yaw_deg=reported.yaw_deg,
            s_mm=reported.s_mm,
            h_mm=reported.h_mm,
            a_max_mm=reported.a_max_mm,
            a_min_mm=reported.a_min_mm,
            area_plus_mm2=reported.surface_area_mm2[0],
            area_minus_mm2=reported.surface_area_mm2[1],
        )
        frames = [sample.pad_frame(side, config.sampler) for side in SIDES]
        surfaces = [
            contact_samples(
                *surface_in_pad(mesh.vertices, mesh.faces, frame, config.sampler), config, number, index, side_number
            )
            for side_number, frame in enumerate(frames)
        ]
        travel = closing_travel_mm(config.print.resolved()["clearance_mm"])
        contacts = seat(surfaces, pad_vertices, pad_faces, config.contact.eps_mm, travel_mm=travel)
        placements = [PadPlacement(f, c.offset_mm, s, c.contact) for f, c, s in zip(frames, contacts, surfaces)]
        normals = np.vstack([s.normals[c.contact] @ f[:3, :3] for f, c, s in zip(frames, contacts, surfaces)])
        radius, centre = largest_empty_cap(normals)
        grasps.append(GraspScene(mesh, sample, placements, normals, radius, centre))
    return grasps
