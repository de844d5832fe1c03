"""The finger library: same-geometry parts served with their grasps moved, wear limit, retiring, concurrent jobs."""

from __future__ import annotations

import multiprocessing

import numpy as np
import pytest
import trimesh

from fcso import load_part
from fcso.report.models import GraspReport
from fcsod.service.fingers import DeliveredFinger, DeliveredPart, FingerLibrary
from tests.fcsod_helpers import DATA

CUBE = DATA / "20mm-xyz-cube.stl"
#: Another geometry: a real print part of its own
ENCODER = DATA / "encoder.stl"


def _grasp(mesh: trimesh.Trimesh) -> GraspReport:
    """A grasp of ``mesh`` in its most probable resting pose (trimesh's quasi-static stable poses)."""
    transforms, _ = trimesh.poses.compute_stable_poses(mesh)
    return GraspReport(
        part="cube",
        pose_index=0,
        sample=3,
        rest_transform=transforms[0].tolist(),
        position_mm=[0.0, 0.0, 10.0],
        quaternion_wxyz=[0.0, 1.0, 0.0, 0.0],
        approach_direction=[0.0, 0.0, -1.0],
        closing_axis=[0.0, 1.0, 0.0],
        pad_gap_mm=14.0,
        closing_width_mm=20.0,
    )


@pytest.fixture
def delivered_grasp() -> GraspReport:
    return _grasp(load_part(CUBE).mesh)


@pytest.fixture
def library(tmp_path, delivered_grasp):
    cube = load_part(CUBE).mesh
    library = FingerLibrary(tmp_path / "fingers.sqlite3")
    library.add(
        "cell-a",
        DeliveredFinger(
            job_id="job-a",
            finger_set=1,
            finger_file="finger.stl",
            design_key="fcso/cell-a/jobs/job-a/design",
            finger_stl=CUBE.read_bytes(),
            quality_mm2=40.0,
            worst_retained=0.9,
            parts=[DeliveredPart("cube", cube, [delivered_grasp])],
        ),
    )
    yield library
    library.close()


def _rested(mesh: trimesh.Trimesh, grasp: GraspReport) -> np.ndarray:
    vertices = np.asarray(mesh.vertices)
    return vertices @ np.asarray(grasp.rest_transform)[:3, :3].T + np.asarray(grasp.rest_transform)[:3, 3]


def test_a_moved_copy_of_a_delivered_part_is_served_with_its_grasp_moved(library, delivered_grasp):
    cube = load_part(CUBE).mesh
    moved = cube.copy()
    moved.apply_translation([35.0, -12.5, 4.0])
    served = library.claim("cell-a", "job-a2", {"my-cube": moved}, reprint_after_jobs=10)
    (grasp,) = served["my-cube"].grasps
    # the moved part rests exactly where the delivered one rested
    assert np.allclose(_rested(moved, grasp), _rested(cube, delivered_grasp), atol=1e-9)
    assert grasp.part == "my-cube" and served["my-cube"].library_part == "cube"
    assert served["my-cube"].finger.finger_id == 1 and served["my-cube"].finger.jobs == 2
    assert library.entries()[0].jobs == 2


def test_other_parts_another_cell_a_retired_or_worn_finger_serve_nothing(library):
    cube, encoder = load_part(CUBE).mesh, load_part(ENCODER, repair=True).mesh
    assert library.claim("cell-a", "job-b", {"cube": cube, "encoder": encoder}, reprint_after_jobs=10) is None
    assert library.claim("cell-b", "job-c", {"cube": cube}, reprint_after_jobs=10) is None
    assert library.entries()[0].jobs == 1, "a job not served counts nothing"
    # worn: the delivering job and one reuse make two jobs
    assert library.claim("cell-a", "job-d", {"cube": cube}, reprint_after_jobs=2) is not None
    assert library.claim("cell-a", "job-e", {"cube": cube}, reprint_after_jobs=2) is None
    # the same job run again (a restart) keeps its claim
    assert library.claim("cell-a", "job-d", {"cube": cube}, reprint_after_jobs=2) is not None
    assert library.retire(1) and not library.retire(1)
    assert library.claim("cell-a", "job-f", {"cube": cube}, reprint_after_jobs=10) is None


def _claim_in_a_process(path: str, job_id: str) -> bool:
    library = FingerLibrary(path)
    try:
        return library.claim("cell-a", job_id, {"cube": load_part(CUBE).mesh}, reprint_after_jobs=2) is not None
    finally:
        library.close()


def test_concurrent_jobs_never_pass_the_wear_limit(library):
    # two workers claim at once; the limit leaves room for one reuse
    with multiprocessing.get_context("fork").Pool(2) as pool:
        served = pool.starmap(_claim_in_a_process, [(str(library.path), "job-x"), (str(library.path), "job-y")])
    assert sorted(served) == [False, True]
    assert library.entries()[0].jobs == 2
