"""The interactive 3D view of ``report.html``: the part in each grasp with both fingers, the finger with its pocket.

Self-contained and offline: three.js (r111, MIT, vendored in
``fcso/output/viewer/`` with its licence) and the small viewer script are
inlined once per page; the meshes are embedded as binary glTF (GLB, from
trimesh) in base64, decimated for the screen, the contact samples as
float32 triples. The static pictures stay beside it (they print and they
email).
"""

from __future__ import annotations

import base64
import json
from pathlib import Path

import numpy as np
import trimesh

from .decimate import decimate
from .html import text

#: The vendored viewer files, inlined into the page in this order.
VIEWER_DIR = Path(__file__).with_name("viewer")
VIEWER_SCRIPTS = ("three.min.js", "OrbitControls.js", "GLTFLoader.js", "viewer.js")

#: Most triangles of a mesh in the view, so the page stays small (the demo job's pages are under 2 MB): "parts" is
#: shared by all the grasps' parts (each part in its pose is a mesh of its own), at least "part" each.
VIEW_FACES = {"parts": 36_000, "part": 3_000, "finger": 16_000, "fingerpad": 6_000}


def glb_base64(mesh: trimesh.Trimesh, max_faces: int) -> str:
    """``mesh`` (mm) decimated to at most ``max_faces`` triangles, as base64 GLB without normals (the viewer
    computes them).
    """
    vertices, faces = decimate(np.asarray(mesh.vertices), np.asarray(mesh.faces), max_faces)
    glb = trimesh.Trimesh(vertices, faces, process=False).export(file_type="glb", include_normals=False)
    return base64.b64encode(glb).decode("ascii")


def points_base64(points: np.ndarray) -> str:
    """(n, 3) points (mm) as base64 little-endian float32 triples."""
    return base64.b64encode(np.asarray(points, dtype="<f4").tobytes()).decode("ascii")


def column_major(matrix: np.ndarray) -> list[float]:
    """A 4x4 transform as three.js's ``Matrix4.fromArray`` takes it (column-major), rounded to µm."""
    return [round(float(v), 6) for v in np.asarray(matrix, dtype=float).T.reshape(-1)]


def grasp_view(title: str, part_key: str, finger_transforms: list[np.ndarray], contact_key: str | None) -> dict:
    """A view of one grasp: the part (resting frame), the fingers at ``finger_transforms`` (finger frame to resting
    frame) and the contact samples.
    """
    items = [{"mesh": part_key, "group": "part"}]
    items += [{"mesh": "finger", "matrix": column_major(t), "group": "fingers"} for t in finger_transforms]
    if contact_key is not None:
        items.append({"points": contact_key, "group": "contact"})
    return {"title": title, "items": items}


def viewer_section(scene: dict, heading: str = "Interactive 3D view") -> list[str]:
    """HTML fragments of the view: the heading, the canvas with its controls, the data and the scripts.

    Parameters
    ----------
    scene : dict
        ``{"meshes": {key: GLB base64}, "points": {key: float32 base64}, "views": [{"title", "items"}]}``; an item
        draws ``mesh`` (with an optional column-major ``matrix``) or ``points`` in a ``group`` (part, fingers,
        pad, contact) that a check box shows and hides.
    """
    licence = (VIEWER_DIR / "LICENSE-three.js.txt").read_text(encoding="utf-8")
    scripts = f"<script>/*\n{licence}*/</script>\n" + "".join(
        f"<script>{(VIEWER_DIR / name).read_text(encoding='utf-8')}</script>\n" for name in VIEWER_SCRIPTS
    )
    data = json.dumps(scene, separators=(",", ":")).replace("</", "<\\/")
    return [
        f"<h2>{text(heading)}</h2>",
        "<p>Drag to turn, wheel to zoom, right-drag to pan; pick a view and show or hide its parts. "
        "Part grey, fingers blue, pocket orange, contact red.</p>",
        '<div id="fcso-3d"><div class="controls"><select id="fcso-3d-view"></select> '
        '<span id="fcso-3d-groups"></span></div>'
        '<canvas id="fcso-3d-canvas" width="960" height="560"></canvas></div>',
        f'<script type="application/json" id="fcso-3d-data">{data}</script>',
        scripts,
    ]
