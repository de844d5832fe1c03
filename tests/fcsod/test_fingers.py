"""The finger library: same-geometry parts served with their grasps moved, wear limit, retiring, concurrent jobs."""

from __future__ import annotations

import multiprocessing
import sqlite3

import numpy as np
import pytest
import trimesh

from fcso import load_part
from fcso.config import DesignConfig
from fcso.report.models import GraspReport
from fcsod.job.fingers import DeliveredFinger, DeliveredPart, FingerLibrary, FittedPart
from fcsod.job.reuse import finger_settings, settings_difference
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


#: The settings a finger is kept with (any JSON: the library compares them as text)
SETTINGS = '{"gripper": {"max_opening_mm": 50.0}, "sampler": {"length_mm": 20.0}}'


def _library_with_job_a(folder, grasp: GraspReport, **pad) -> FingerLibrary:
    """A library holding job A's finger for the cube in cell-a (``pad``: its kept pad, when given)."""
    library = FingerLibrary(folder / "fingers.sqlite3")
    library.add(
        "cell-a",
        DeliveredFinger(
            job_id="job-a",
            finger_set=1,
            finger_file="finger.stl",
            design_key="fcso/cell-a/jobs/job-a/design",
            finger_stl=CUBE.read_bytes(),
            quality=0.9,
            quality_measure="capture",
            worst_retained=0.9,
            parts=[DeliveredPart("cube", load_part(CUBE).mesh, [grasp])],
            design_settings=SETTINGS,
            **pad,
        ),
    )
    return library


@pytest.fixture
def library(tmp_path, delivered_grasp):
    library = _library_with_job_a(tmp_path, delivered_grasp)
    yield library
    library.close()


def _rested(mesh: trimesh.Trimesh, grasp: GraspReport) -> np.ndarray:
    vertices = np.asarray(mesh.vertices)
    return vertices @ np.asarray(grasp.rest_transform)[:3, :3].T + np.asarray(grasp.rest_transform)[:3, 3]


def test_a_moved_copy_of_a_delivered_part_is_served_with_its_grasp_moved(library, delivered_grasp):
    cube = load_part(CUBE).mesh
    moved = cube.copy()
    moved.apply_translation([35.0, -12.5, 4.0])
    served = library.claim("cell-a", "job-a2", {"my-cube": moved}, reprint_after_jobs=10, design_settings=SETTINGS)
    (grasp,) = served["my-cube"].grasps
    # the moved part rests exactly where the delivered one rested
    assert np.allclose(_rested(moved, grasp), _rested(cube, delivered_grasp), atol=1e-9)
    assert grasp.part == "my-cube" and served["my-cube"].library_part == "cube"
    assert served["my-cube"].finger.finger_id == 1 and served["my-cube"].finger.jobs == 2
    assert library.entries()[0].jobs == 2


def test_other_parts_another_cell_a_retired_or_worn_finger_serve_nothing(library):
    cube, encoder = load_part(CUBE).mesh, load_part(ENCODER, repair=True).mesh
    assert (
        library.claim(
            "cell-a", "job-b", {"cube": cube, "encoder": encoder}, reprint_after_jobs=10, design_settings=SETTINGS
        )
        is None
    )
    assert library.claim("cell-b", "job-c", {"cube": cube}, reprint_after_jobs=10, design_settings=SETTINGS) is None
    assert library.entries()[0].jobs == 1, "a job not served counts nothing"
    # worn: the delivering job and one reuse make two jobs
    assert library.claim("cell-a", "job-d", {"cube": cube}, reprint_after_jobs=2, design_settings=SETTINGS) is not None
    assert library.claim("cell-a", "job-e", {"cube": cube}, reprint_after_jobs=2, design_settings=SETTINGS) is None
    # the same job run again (a restart) keeps its claim
    assert library.claim("cell-a", "job-d", {"cube": cube}, reprint_after_jobs=2, design_settings=SETTINGS) is not None
    assert library.retire(1) and not library.retire(1)
    assert library.claim("cell-a", "job-f", {"cube": cube}, reprint_after_jobs=10, design_settings=SETTINGS) is None


def test_the_same_part_with_other_settings_is_not_served_and_the_difference_is_named(library):
    cube = load_part(CUBE).mesh
    wider = '{"gripper": {"max_opening_mm": 85.0}, "sampler": {"length_mm": 20.0}}'
    assert library.claim("cell-a", "job-b", {"cube": cube}, reprint_after_jobs=10, design_settings=wider) is None
    assert library.entries()[0].jobs == 1, "a job not served counts nothing"
    # the finger holding the part is found, with the settings it was designed with, and what differs is named
    assert library.other_settings("cell-a", "job-b", {"cube": cube}, 10, wider) == {1: SETTINGS}
    assert library.other_settings("cell-a", "job-b", {"cube": cube}, 10, SETTINGS) == {}
    assert settings_difference(SETTINGS, wider) == "settings differ: gripper.max_opening_mm 50.0 -> 85.0"
    assert settings_difference(None, wider).startswith("it was kept before the library recorded the settings")


def test_finger_settings_cover_the_gripper_the_pad_the_poses_and_the_measures_test_conditions():
    base = DesignConfig()
    for section, change in (
        ("gripper", {"max_opening_mm": 85.0}),
        ("sampler", {"length_mm": 10.0, "width_mm": 10.0}),
        ("poses", {"count": 1}),
        ("print", {"min_wall_mm": 1.0}),
        # a test condition the capture measure ranks candidates under
        ("verify", {"force_limit_n": 40.0}),
    ):
        other = base.updated({section: change})
        assert finger_settings(other) != finger_settings(base), section
        assert settings_difference(finger_settings(base), finger_settings(other)).startswith(
            "settings differ: " + section
        )
    # the compute section (where the design runs) and how many trials verification runs shape nothing
    assert finger_settings(base.updated({"compute": {"scheduler": "tcp://elsewhere:8786"}})) == finger_settings(base)
    assert finger_settings(base.updated({"verify": {"trials": 3}})) == finger_settings(base)


def _claim_in_a_process(path: str, job_id: str) -> bool:
    library = FingerLibrary(path)
    try:
        return (
            library.claim(
                "cell-a", job_id, {"cube": load_part(CUBE).mesh}, reprint_after_jobs=2, design_settings=SETTINGS
            )
            is not None
        )
    finally:
        library.close()


def test_concurrent_jobs_never_pass_the_wear_limit(library):
    # two workers claim at once; the limit leaves room for one reuse
    with multiprocessing.get_context("fork").Pool(2) as pool:
        served = pool.starmap(_claim_in_a_process, [(str(library.path), "job-x"), (str(library.path), "job-y")])
    assert sorted(served) == [False, True]
    assert library.entries()[0].jobs == 2


@pytest.fixture
def library_with_pad(tmp_path, delivered_grasp):
    # any closed mesh stands for the pad: the library keeps it as it is given
    pad_stl = trimesh.creation.box([5.0, 20.0, 20.0]).export(file_type="stl")
    library = _library_with_job_a(tmp_path, delivered_grasp, pad_stl=pad_stl)
    yield library
    library.close()


def _scaled(factor: float) -> trimesh.Trimesh:
    mesh = load_part(CUBE).mesh.copy()
    mesh.apply_scale(factor)
    return mesh


def test_a_part_of_about_a_delivered_parts_size_is_evaluated_on_its_pad_and_served_when_fitted(
    library_with_pad, delivered_grasp
):
    library = library_with_pad
    near = {"near": _scaled(0.99)}
    # 1 % smaller: every side and the volume (3 % smaller) within 5 %; not within 2 % (the volume)
    assert library.near_fingers("cell-a", "job-b", near, 10, SETTINGS, 5.0) == {"near": [1]}
    assert library.near_fingers("cell-a", "job-b", near, 10, SETTINGS, 2.0) is None
    # 10 % smaller is beyond 5 %; a finger designed with other pad settings is not evaluated
    assert library.near_fingers("cell-a", "job-b", {"far": _scaled(0.9)}, 10, SETTINGS, 5.0) is None
    assert library.near_fingers("cell-a", "job-b", near, 10, '{"sampler": {}}', 5.0) is None
    # a part of the delivered geometry needs no evaluation
    same = {"cube": load_part(CUBE).mesh, "near": _scaled(0.99)}
    assert library.near_fingers("cell-a", "job-b", same, 10, SETTINGS, 5.0) == {"near": [1]}
    pad = library.pad(1)
    assert pad.is_watertight and np.isclose(pad.volume, 5.0 * 20.0 * 20.0)

    # unfitted, the near part is not served; fitted, it is, with its own grasps, and counts the job
    assert library.claim("cell-a", "job-b", same, 10, SETTINGS) is None
    fitted = {"near": FittedPart(1, 0.8, [delivered_grasp])}
    served = library.claim("cell-a", "job-b", same, 10, SETTINGS, fitted)
    assert served["near"].library_part is None and served["near"].worst_retained == 0.8
    assert served["near"].grasps == [delivered_grasp.model_copy(update={"part": "near"})]
    assert served["cube"].library_part == "cube" and served["cube"].worst_retained is None
    assert library.entries()[0].jobs == 2
    # a fit to a finger retired since is no claim
    assert library.retire(1)
    assert library.claim("cell-a", "job-c", same, 10, SETTINGS, fitted) is None


def test_a_library_written_before_pads_and_settings_were_kept_gains_the_columns_and_serves_nothing(tmp_path):
    path = tmp_path / "fingers.sqlite3"
    old = sqlite3.connect(path)
    # the fingers table as the first library release wrote it
    old.executescript(
        "CREATE TABLE fingers (finger_id INTEGER PRIMARY KEY AUTOINCREMENT, cell TEXT NOT NULL, job_id TEXT NOT NULL, "
        "finger_set INTEGER NOT NULL, finger_file TEXT NOT NULL, design_key TEXT NOT NULL, sha256 TEXT NOT NULL, "
        "finger_stl BLOB NOT NULL, quality_mm2 REAL NOT NULL, worst_retained REAL NOT NULL, created_at TEXT NOT NULL, "
        "retired_at TEXT, UNIQUE (job_id, finger_set));"
        "INSERT INTO fingers VALUES (1, 'cell-a', 'job-a', 1, 'finger.stl', 'k', 'ab', x'00', 40.0, 0.9, 't', NULL);"
    )
    old.commit()
    old.close()
    library = FingerLibrary(path)
    try:
        assert [e.finger_id for e in library.entries()] == [1]
        # its quality_mm2 column was the design's measure under another name: the default one's then
        entry = library.entries()[0]
        assert (entry.quality, entry.quality_measure) == (40.0, "capture")
        assert library.near_fingers("cell-a", "job-b", {"near": _scaled(0.99)}, 10, SETTINGS, 5.0) is None
        # its settings are unknown: it serves not even its own parts, and says so
        assert library.claim("cell-a", "job-b", {"cube": load_part(CUBE).mesh}, 10, SETTINGS) is None
    finally:
        library.close()
