"""Production 3MF: ``build.3mf`` read back by lib3mf (the 3MF consortium's library) in strict mode.

A real design's finger (fcso on the test cube) and real part meshes are
written by :func:`fcsod.plate.build3mf.export_build_3mf`, and a daemon job's own
``build.3mf`` is checked the same way.
"""

from __future__ import annotations

import io
import uuid
import zipfile

import lib3mf
import numpy as np
import pytest
import trimesh
from lxml import etree

from fcso import DesignConfig, design, load_part
from fcsod.plate.build3mf import BuildItem, export_build_3mf
from tests.fcsod_helpers import DATA, drop_job, finished, free_port, start_daemon, start_subscriber, write_config

CUBE = DATA / "20mm-xyz-cube.stl"
ANGLE_BLOCK = DATA / "angle_block.STL"
FCSO_NS = "urn:fcsod:3mf:2026"
FAST = {
    "sampler": {"length_mm": 10, "width_mm": 10, "thickness_mm": 4, "penetration_mm": 3, "stride_mm": 5},
    "poses": {"count": 1, "select": "most_probable"},
}


def _read_strict(data: bytes):
    """The lib3mf model of ``data``, read in strict mode; asserts zero warnings."""
    wrapper = lib3mf.get_wrapper()
    model = wrapper.CreateModel()
    reader = model.QueryReader("3mf")
    reader.SetStrictModeActive(True)
    reader.ReadFromBuffer(bytearray(data))
    warnings = [reader.GetWarning(index) for index in range(reader.GetWarningCount())]
    assert warnings == [], warnings
    return model


def _metadata(group) -> dict[tuple[str, str], str]:
    entries = (group.GetMetaData(index) for index in range(group.GetMetaDataCount()))
    return {(entry.GetNameSpace(), entry.GetName()): entry.GetValue() for entry in entries}


def _items(model) -> list[dict]:
    """Every build item as lib3mf reads it: part number, UUID, object name/part number/UUID, manifoldness, metadata."""
    items, iterator = [], model.GetBuildItems()
    while iterator.MoveNext():
        item = iterator.GetCurrent()
        obj = item.GetObjectResource()
        mesh = model.GetMeshObjectByID(obj.GetResourceID())
        items.append(
            {
                "partnumber": item.GetPartNumber(),
                "uuid": item.GetUUID()[1],
                "object_name": obj.GetName(),
                "object_partnumber": obj.GetPartNumber(),
                "object_uuid": obj.GetUUID()[1],
                "manifold_and_oriented": mesh.IsManifoldAndOriented(),
                "triangles": mesh.GetTriangleCount(),
                "metadata": _metadata(item.GetMetaDataGroup()),
            }
        )
    return items


@pytest.fixture(scope="module")
def finger() -> trimesh.Trimesh:
    """The finger fcso designs for the test cube (fast settings)."""
    return design([load_part(CUBE)], DesignConfig().updated(FAST)).finger


def _placed(mesh: trimesh.Trimesh, x_mm: float) -> np.ndarray:
    transform = np.eye(4)
    transform[:3, 3] = [x_mm, 0.0, 10.0]
    return transform


def test_production_3mf_round_trips_through_lib3mf_strict(finger):
    cube, block = load_part(CUBE).mesh, load_part(ANGLE_BLOCK, units="inch").mesh
    items = [
        BuildItem("cube", cube, _placed(cube, 10), "part", "20mm-xyz-cube"),
        BuildItem("cube_2", cube, _placed(cube, 40), "part", "20mm-xyz-cube"),
        BuildItem("angle_block", block, _placed(block, 80), "part", "angle_block"),
        BuildItem("fcso-finger-1-1", finger, _placed(finger, 140), "finger"),
        BuildItem("fcso-finger-1-2", finger, _placed(finger, 200), "finger"),
    ]
    data = export_build_3mf(
        items, job_id="cubes-0123abcd", application="fcsod 0.1.0", creation_date="2026-11-29T01:02:03.000+00:00"
    )
    model = _read_strict(data)
    assert model.GetUnit() == lib3mf.ModelUnit.MilliMeter
    assert _metadata(model.GetMetaDataGroup()) == {
        ("", "Title"): "cubes-0123abcd",
        ("", "Application"): "fcsod 0.1.0",
        ("", "CreationDate"): "2026-11-29T01:02:03.000+00:00",
    }
    read = _items(model)
    assert [i["partnumber"] for i in read] == ["cube", "cube_2", "angle_block", "fcso-finger-1-1", "fcso-finger-1-2"]
    assert [i["object_name"] for i in read] == ["20mm-xyz-cube"] * 2 + ["angle_block"] + ["fcso-finger-1"] * 2
    assert [i["object_partnumber"] for i in read] == [i["object_name"] for i in read]
    assert all(i["manifold_and_oriented"] for i in read)
    assert [i["triangles"] for i in read] == [len(m.faces) for m in (cube, cube, block, finger, finger)]
    finger_metadata = {(FCSO_NS, "job_id"): "cubes-0123abcd", (FCSO_NS, "finger_set"): "1"}
    assert [i["metadata"] for i in read] == [{}] * 3 + [finger_metadata] * 2

    # UUIDs: lib3mf reads the ones written, each a valid UUID, one per item, one per object, one for the build
    build_uuid = model.GetBuildUUID()[1]
    item_uuids = [i["uuid"] for i in read]
    object_uuids = list(dict.fromkeys(i["object_uuid"] for i in read))
    assert len(set(item_uuids)) == 5 and len(object_uuids) == 3 and build_uuid not in item_uuids + object_uuids
    for value in [build_uuid, *item_uuids, *object_uuids]:
        assert str(uuid.UUID(value)) == value
    root = etree.fromstring(zipfile.ZipFile(io.BytesIO(data)).read("3D/3dmodel.model"))
    p_uuid = "{http://schemas.microsoft.com/3dmanufacturing/production/2015/06}UUID"
    assert [e.get(p_uuid) for e in root.iter("{*}item")] == item_uuids
    assert [e.get(p_uuid) for e in root.iter("{*}object")] == object_uuids
    # the same job writes the same file; another job other UUIDs
    assert (
        export_build_3mf(
            items, job_id="cubes-0123abcd", application="fcsod 0.1.0", creation_date="2026-11-29T01:02:03.000+00:00"
        )
        == data
    )
    other = _items(_read_strict(export_build_3mf(items, job_id="other-job")))
    assert not {i["uuid"] for i in other} & set(item_uuids)


def test_inward_wound_mesh_is_written_outward():
    cube = load_part(CUBE).mesh
    inverted = trimesh.Trimesh(cube.vertices, cube.faces[:, ::-1], process=False)
    assert inverted.volume < 0
    data = export_build_3mf([BuildItem("cube", inverted, _placed(inverted, 10), "part", "cube")], job_id="j")
    (item,) = _items(_read_strict(data))
    assert item["manifold_and_oriented"]
    scene = trimesh.load(trimesh.util.wrap_as_stream(data), file_type="3mf", force="scene")
    (mesh,) = scene.geometry.values()
    assert mesh.volume == pytest.approx(cube.volume, rel=1e-9)


def test_daemon_build_3mf_is_a_strict_production_3mf(tmp_path):
    config = write_config(tmp_path, free_port())
    daemon = start_daemon(config)
    try:
        subscriber = start_subscriber(config)
        drop_job(
            tmp_path / "watch" / "cubes", {"job.toml": '[[parts]]\nfile = "cube.stl"\nquantity = 2\n', "cube.stl": CUBE}
        )
        done = finished(subscriber, "cubes")
        subscriber.stop()
    finally:
        assert daemon.stop() == 0
    assert done["body"]["state"] == "done", done
    job_id = done["job_id"]
    model = _read_strict((tmp_path / "out" / job_id / "build.3mf").read_bytes())
    metadata = _metadata(model.GetMetaDataGroup())
    assert metadata[("", "Title")] == job_id and metadata[("", "Application")] == "fcsod 0.1.0"
    assert metadata[("", "CreationDate")].startswith(done["body"]["finished_at"][:10])
    read = _items(model)
    assert [i["partnumber"] for i in read] == ["cube", "cube_2", "fcso-finger-1-1", "fcso-finger-1-2"]
    assert [i["object_name"] for i in read] == ["cube", "cube", "fcso-finger-1", "fcso-finger-1"]
    assert all(i["manifold_and_oriented"] for i in read)
    assert [i["metadata"].get((FCSO_NS, "job_id")) for i in read] == [None, None, job_id, job_id]
