"""The pictures of report.html (PNG): the finger, the fingerpad, each grasp with its contact patch, the gripper,
a pose, the contact normals."""

from __future__ import annotations

import numpy as np
import trimesh
from matplotlib import colormaps
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize
from scipy.spatial import cKDTree

from ..contact import PadPlacement
from ..geometry import clip_to_box, transform_points
from ..parallel import WorkerPool
from ..progress import Progress
from .decimate import decimate
from .render import (
    CAP_COLOUR,
    CONTACT_COLOUR,
    FINGER_COLOUR,
    MAX_DRAWN_NORMALS,
    NORMAL_COLOUR,
    PAD_COLOUR,
    PART_COLOUR,
    TABLE_COLOUR,
    Layer,
    Panel,
    View,
    caption,
    draw_layers,
    fit_axes,
    mesh_arrays,
    new_figure,
    panels,
    png_bytes,
)


def finger_picture(
    finger: trimesh.Trimesh, pad_to_finger: np.ndarray, pad_size: tuple[float, float, float], title: str = ""
) -> bytes:
    """The finger with its fingerpad, from three views.

    Parameters
    ----------
    finger : trimesh.Trimesh
        The fused finger, finger frame (mm).
    pad_to_finger : (4, 4) float
        Pad frame to finger frame; its columns give the pad's outward ``u``,
        length ``v`` and up ``w`` directions in the finger frame.
    pad_size : (T, L, W)
        Pad thickness, length and width (mm).
    title : str

    Returns
    -------
    bytes
        PNG of ``PICTURE_SIZES["finger"]``.
    """
    vertices, faces = decimate(*mesh_arrays(finger))
    colours = _finger_colours(transform_points(np.linalg.inv(pad_to_finger), vertices), faces, pad_size)
    outward, along, up = (pad_to_finger[:3, k] for k in range(3))
    views = [
        View(tuple(-outward - 0.9 * along + 0.6 * up), tuple(up), "finger"),
        View(tuple(-outward), tuple(up), "pad side (faces the part)"),
        View(tuple(along), tuple(up), "side"),
    ]
    figure = new_figure("finger")
    if title:
        figure.suptitle(title, fontsize=11)
    for axes, view in zip(panels(figure, 3), views):
        draw_layers(axes, [Layer(vertices, faces, colours)], view)
        caption(axes, view.title)
    return png_bytes(figure)


def _finger_colours(pad_frame_vertices: np.ndarray, faces: np.ndarray, pad_size) -> np.ndarray:
    """Pad faces orange, the rest of the finger grey-blue.

    A face belongs to the pad when its centroid (pad frame) is inside the
    pad box and short of the finger's contact face ``u = T``.
    """
    thickness, length, width = pad_size
    centroids = pad_frame_vertices[faces].mean(axis=1)
    tolerance = 1e-3
    on_pad = (
        (centroids[:, 0] < thickness - tolerance)
        & (centroids[:, 1] > -tolerance)
        & (centroids[:, 1] < length + tolerance)
        & (centroids[:, 2] > -tolerance)
        & (centroids[:, 2] < width + tolerance)
    )
    return np.where(on_pad[:, None], PAD_COLOUR, FINGER_COLOUR)


def fingerpad_picture(pad: trimesh.Trimesh, pad_size: tuple[float, float, float], title: str = "") -> bytes:
    """The fingerpad alone, coloured by depth ``u`` so carving shows, from two views.

    Parameters
    ----------
    pad : trimesh.Trimesh
        The fingerpad in its pad frame (mm): inner face towards ``u = 0``.
    pad_size : (T, L, W)
    title : str

    Returns
    -------
    bytes
        PNG of ``PICTURE_SIZES["fingerpad"]``.
    """
    vertices, faces = decimate(*mesh_arrays(pad))
    thickness = pad_size[0]
    scale = Normalize(0.0, thickness)
    colourmap = colormaps["viridis"]
    colours = colourmap(scale(vertices[faces][:, :, 0].mean(axis=1)))[:, :3]
    views = [
        View((-1.0, 0.0, 0.0), (0.0, 0.0, 1.0), "face (seen from the part)"),
        View((-1.0, -0.8, 0.7), (0.0, 0.0, 1.0), "oblique"),
    ]
    figure = new_figure("fingerpad")
    if title:
        figure.suptitle(title, fontsize=11)
    for axes, view in zip(panels(figure, 2, right_margin=0.1), views):
        draw_layers(axes, [Layer(vertices, faces, colours)], view)
        caption(axes, view.title)
    bar_axes = figure.add_axes((0.91, 0.12, 0.02, 0.7))
    figure.colorbar(ScalarMappable(scale, colourmap), cax=bar_axes, label="u (mm): 0 = pad face, T = back")
    return png_bytes(figure)


def contact_patch(
    mesh_vertices: np.ndarray, mesh_faces: np.ndarray, placement: PadPlacement, pad_size, max_edge_mm: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The part's surface inside one pad box, split into touching and free triangles.

    Parameters
    ----------
    mesh_vertices, mesh_faces : ndarray
        The full part in its resting frame (mm).
    placement : PadPlacement
    pad_size : (T, L, W)
    max_edge_mm : float
        Triangles are split to this edge length so the patch follows the samples.

    Returns
    -------
    vertices : (n, 3) float
        Resting frame.
    faces : (m, 3) int
    touching : (m,) bool
        Each triangle takes the contact label of the surface sample nearest its centroid.
    """
    local = transform_points(placement.frame, mesh_vertices)
    vertices, faces = clip_to_box(local, mesh_faces, (0.0, 0.0, 0.0), pad_size)
    if len(faces) == 0 or len(placement.samples.points) == 0:
        return vertices[:0], faces[:0], np.zeros(0, dtype=bool)
    vertices, faces = trimesh.remesh.subdivide_to_size(vertices, faces, max_edge_mm)
    nearest = cKDTree(placement.samples.points).query(vertices[faces].mean(axis=1))[1]
    return transform_points(np.linalg.inv(placement.frame), vertices), faces, np.asarray(placement.contact)[nearest]


def _inside_box(points: np.ndarray, frame: np.ndarray, pad_size) -> np.ndarray:
    local = transform_points(frame, points)
    return np.all((local >= 0.0) & (local <= np.asarray(pad_size)), axis=1)


def _table(vertices: np.ndarray) -> Layer:
    """A square of the table plane z = 0 around a part's footprint."""
    lower, upper = vertices[:, :2].min(axis=0), vertices[:, :2].max(axis=0)
    centre, half = (lower + upper) / 2.0, 0.65 * float((upper - lower).max())
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float) * half + centre
    return Layer(np.column_stack([corners, np.zeros(4)]), np.array([[0, 1, 2], [0, 2, 3]]), TABLE_COLOUR)


def grasp_picture(
    part: trimesh.Trimesh,
    pad: trimesh.Trimesh,
    placements: list[PadPlacement],
    pad_size: tuple[float, float, float],
    closing_axis: np.ndarray,
    title: str = "",
) -> bytes:
    """A part in its resting pose, the two seated pads and the contact patches.

    Parameters
    ----------
    part : trimesh.Trimesh
        The part in its resting frame (mm), table at z = 0.
    pad : trimesh.Trimesh
        The fingerpad in its pad frame (mm).
    placements : list of PadPlacement
        The "+" and "-" pads.
    pad_size : (T, L, W)
    closing_axis : (3,) float
        The grasp's closing axis ``a`` (resting frame).
    title : str

    Returns
    -------
    bytes
        PNG of ``PICTURE_SIZES["grasp"]``: the part seen from each pad's side
        and a close-up of the pads, pads translucent, the touching surface red.
    """
    full_vertices, full_faces = mesh_arrays(part)
    vertices, faces = decimate(full_vertices, full_faces)
    max_edge = min(pad_size[1:]) / 20.0
    keep = np.ones(len(faces), dtype=bool)
    layers = []
    for placement in placements:
        # drawn faces wholly inside the pad box give way to the exact patch
        keep &= ~_inside_box(vertices, placement.frame, pad_size)[faces].all(axis=1)
        patch_vertices, patch_faces, touching = contact_patch(full_vertices, full_faces, placement, pad_size, max_edge)
        layers.append(Layer(patch_vertices, patch_faces, np.where(touching[:, None], CONTACT_COLOUR, PART_COLOUR)))
    layers.insert(0, Layer(vertices, faces[keep], PART_COLOUR))
    pad_vertices, pad_faces = decimate(*mesh_arrays(pad))
    seated_pads = []
    for placement in placements:
        seated = transform_points(np.linalg.inv(placement.frame), pad_vertices + [placement.offset_mm, 0.0, 0.0])
        layers.append(Layer(seated, pad_faces, PAD_COLOUR, alpha=0.35))
        seated_pads.append(seated)
    closing = np.asarray(closing_axis, dtype=float)
    sliding = np.cross([0.0, 0.0, 1.0], closing)
    views = [
        View(tuple(side * closing + 0.7 * sliding + (0.0, 0.0, 0.8)), (0.0, 0.0, 1.0), f"from the {name} pad")
        for side, name in ((1.0, "+"), (-1.0, "-"))
    ]
    views.append(
        View(tuple(0.35 * closing + sliding + (0.0, 0.0, 0.5)), (0.0, 0.0, 1.0), "close-up, part cut around the pads")
    )
    # the close-up leaves out the part away from the pads, which would hide them
    pads = np.vstack(seated_pads)
    margin = 0.5 * max(pad_size)
    near = np.all((vertices >= pads.min(axis=0) - margin) & (vertices <= pads.max(axis=0) + margin), axis=1)[faces].all(
        axis=1
    )
    close_layers = [Layer(vertices, faces[keep & near], PART_COLOUR)] + layers[1:]
    figure = new_figure("grasp")
    if title:
        figure.suptitle(title, fontsize=11)
    for axes, view, drawn, focus in zip(panels(figure, 3), views, (layers, layers, close_layers), (None, None, pads)):
        draw_layers(axes, drawn, view, background=[_table(full_vertices)], focus=focus)
        caption(axes, view.title)
    return png_bytes(figure)


def gripper_picture(
    part: trimesh.Trimesh,
    finger: trimesh.Trimesh,
    pad_to_finger: np.ndarray,
    placements: list[PadPlacement],
    pad_size: tuple[float, float, float],
    closing_axis: np.ndarray,
    title: str = "",
) -> bytes:
    """Both fingers closed on a part resting on the table.

    Parameters
    ----------
    part : trimesh.Trimesh
        The part in its resting frame (mm).
    finger : trimesh.Trimesh
        The fused finger, finger frame (mm).
    pad_to_finger : (4, 4) float
        Pad frame to finger frame.
    placements : list of PadPlacement
        The seated "+" and "-" pads; each finger follows its pad.
    pad_size : (T, L, W)
    closing_axis : (3,) float
    title : str

    Returns
    -------
    bytes
        PNG of ``PICTURE_SIZES["gripper"]``, seen along the pads' length.
    """
    vertices, faces = decimate(*mesh_arrays(part))
    # long plate triangles sort badly against the part: split them for drawing
    finger_vertices, finger_faces = trimesh.remesh.subdivide_to_size(
        *decimate(*mesh_arrays(finger)), float(finger.extents.max()) / 12.0
    )
    in_pad_frame = transform_points(np.linalg.inv(pad_to_finger), finger_vertices)
    colours = _finger_colours(in_pad_frame, finger_faces, pad_size)
    layers = [Layer(vertices, faces, PART_COLOUR)]
    for placement in placements:
        seated = transform_points(np.linalg.inv(placement.frame), in_pad_frame + [placement.offset_mm, 0.0, 0.0])
        layers.append(Layer(seated, finger_faces, colours))
    closing = np.asarray(closing_axis, dtype=float)
    view = View(tuple(0.45 * closing + np.cross([0.0, 0.0, 1.0], closing) + (0.0, 0.0, 0.55)), (0.0, 0.0, 1.0))
    figure = new_figure("gripper")
    axes = Panel(figure, (0.02, 0.02, 0.96, 0.88))
    draw_layers(axes, layers, view, background=[_table(vertices)])
    caption(axes, title)
    return png_bytes(figure)


def pose_picture(part: trimesh.Trimesh, title: str = "") -> bytes:
    """A part resting on the table in one stable pose.

    Parameters
    ----------
    part : trimesh.Trimesh
        The part in its resting frame (mm), table at z = 0.
    title : str

    Returns
    -------
    bytes
        PNG of ``PICTURE_SIZES["pose"]``.
    """
    vertices, faces = decimate(*mesh_arrays(part))
    figure = new_figure("pose")
    axes = Panel(figure, (0.02, 0.02, 0.96, 0.84))
    draw_layers(
        axes,
        [Layer(vertices, faces, PART_COLOUR)],
        View((1.0, -1.2, 0.9), (0.0, 0.0, 1.0)),
        background=[_table(vertices)],
    )
    caption(axes, title)
    return png_bytes(figure)


def capture_picture(landscape, title: str = "") -> bytes:
    """The capture landscape of one scenario (METHOD §7b): jaw separation over start errors, and what is seated.

    Parameters
    ----------
    landscape : CaptureLandscapeReport
        From a scenario of ``report.json``.
    title : str

    Returns
    -------
    bytes
        PNG of ``PICTURE_SIZES["capture"]``: the separation as colour (yaw
        across, offset along the pads up), the starts the chosen pad seats
        hatched, those flat pads seat outlined in black dashes, the test's
        error box in grey.
    """
    offsets, yaws = np.asarray(landscape.offsets_mm), np.asarray(landscape.yaws_deg)
    separation = np.array([[np.nan if x is None else x for x in row] for row in landscape.separation_mm])
    figure = new_figure("capture")
    axes = figure.add_axes((0.08, 0.12, 0.72, 0.76))
    extent = (yaws[0], yaws[-1], offsets[0], offsets[-1])
    shown = axes.imshow(
        separation, origin="lower", aspect="auto", extent=extent, cmap="viridis", interpolation="nearest"
    )
    colourbar = figure.colorbar(shown, ax=axes, fraction=0.05, pad=0.02)
    colourbar.set_label("jaw separation at first contact - seat's, mm", fontsize=8)
    grid_yaw, grid_offset = np.meshgrid(yaws, offsets)
    captured = np.asarray(landscape.captured, dtype=float)
    axes.contourf(grid_yaw, grid_offset, captured, levels=[0.5, 1.5], colors="none", hatches=["///"])
    axes.contour(grid_yaw, grid_offset, captured, levels=[0.5], colors="white", linewidths=1.5)
    flat = np.asarray(landscape.flat_captured, dtype=float)
    if flat.any():
        axes.contour(grid_yaw, grid_offset, flat, levels=[0.5], colors="black", linewidths=1.2, linestyles="dashed")
    box_mm, box_deg = landscape.position_error_mm, landscape.yaw_error_deg
    axes.plot(
        [-box_deg, box_deg, box_deg, -box_deg, -box_deg], [-box_mm, -box_mm, box_mm, box_mm, -box_mm], color="0.6"
    )
    axes.set_xlabel("start error about the vertical, degrees", fontsize=8)
    axes.set_ylabel("start error along the pads, mm", fontsize=8)
    axes.tick_params(labelsize=7)
    axes.set_title(title, fontsize=9)
    return png_bytes(figure)


def _cap_circle(centre: np.ndarray, angle: float, count: int = 181) -> np.ndarray:
    """Points on the boundary of the spherical cap of angular radius ``angle`` around ``centre``."""
    first = np.cross(centre, [1.0, 0.0, 0.0] if abs(centre[0]) < 0.9 else [0.0, 1.0, 0.0])
    first /= np.linalg.norm(first)
    second = np.cross(centre, first)
    phi = np.linspace(0.0, 2.0 * np.pi, count)
    return np.cos(angle) * centre + np.sin(angle) * (np.outer(np.cos(phi), first) + np.outer(np.sin(phi), second))


def _draw_curve(axes, points: np.ndarray, basis: np.ndarray, colour, width: float, zorder: float) -> None:
    """A curve on the unit sphere: solid in front, dotted behind."""
    screen = points @ basis.T
    front = screen[:, 2] >= 0.0
    for visible, style, z in ((front, "-", zorder), (~front, ":", 1.5)):
        masked = np.where(visible[:, None], screen[:, :2], np.nan)
        axes.plot(masked[:, 0], masked[:, 1], style, color=colour, linewidth=width, zorder=z)


def normals_picture(normals: np.ndarray, radius: float, centre: np.ndarray, title: str = "") -> bytes:
    """Contact normals on the unit sphere with the largest empty cap.

    Parameters
    ----------
    normals : (n, 3) float
        Contact normals (unit vectors, resting frame).
    radius : float
        RLES: chord radius of the largest empty cap.
    centre : (3,) float
        Unit centre of the cap.
    title : str

    Returns
    -------
    bytes
        PNG of ``PICTURE_SIZES["normals"]``: the sphere seen from the cap's
        centre and from the opposite side; normals behind the sphere faint.
    """
    normals = np.asarray(normals, dtype=float).reshape(-1, 3)
    if len(normals):
        normals = np.unique(np.round(normals / np.linalg.norm(normals, axis=1)[:, None], 3), axis=0)
        normals = normals[np.linspace(0, len(normals) - 1, min(len(normals), MAX_DRAWN_NORMALS)).astype(int)]
    centre = np.asarray(centre, dtype=float)
    centre = centre / np.linalg.norm(centre)
    angle = 2.0 * np.arcsin(np.clip(radius / 2.0, 0.0, 1.0))
    boundary = _cap_circle(centre, angle)
    up = (0.0, 0.0, 1.0) if abs(centre[2]) < 0.95 else (1.0, 0.0, 0.0)
    views = [View(tuple(centre), up, "looking at the empty cap"), View(tuple(-centre), up, "opposite side")]
    figure = new_figure("normals")
    if title:
        figure.suptitle(title, fontsize=11)
    circle = np.linspace(0.0, 2.0 * np.pi, 181)
    for axes, view in zip(panels(figure, 2), views):
        basis = view.basis()
        axes.fill(np.cos(circle), np.sin(circle), color=(0.93, 0.94, 0.97), zorder=1)
        axes.plot(np.cos(circle), np.sin(circle), color="0.5", linewidth=0.8, zorder=1.2)
        for latitude in np.radians([-60, -30, 0, 30, 60]):
            ring = _cap_circle(np.array([0.0, 0.0, 1.0]), np.pi / 2.0 - latitude, 121)
            _draw_curve(axes, ring, basis, "0.75", 0.5, 1.4)
        for longitude in np.radians(np.arange(0, 180, 30)):
            meridian = _cap_circle(np.array([np.cos(longitude), np.sin(longitude), 0.0]), np.pi / 2.0, 121)
            _draw_curve(axes, meridian, basis, "0.75", 0.5, 1.4)
        screen_boundary = boundary @ basis.T
        if screen_boundary[:, 2].min() >= -1e-9:  # the whole cap faces the camera
            axes.fill(screen_boundary[:, 0], screen_boundary[:, 1], color=CAP_COLOUR, alpha=0.35, zorder=2)
        elif centre @ basis[2] > 0.0 and angle > np.pi / 2.0:  # the cap covers the visible half
            axes.fill(np.cos(circle), np.sin(circle), color=CAP_COLOUR, alpha=0.35, zorder=2)
        _draw_curve(axes, boundary, basis, CAP_COLOUR, 2.0, 3)
        if len(normals):
            screen = normals @ basis.T
            front = screen[:, 2] >= 0.0
            axes.scatter(
                screen[~front, 0], screen[~front, 1], s=3, color=NORMAL_COLOUR, alpha=0.15, linewidths=0, zorder=1.6
            )
            axes.scatter(screen[front, 0], screen[front, 1], s=5, color=NORMAL_COLOUR, linewidths=0, zorder=4)
        for axis, name in ((0, "x"), (1, "y"), (2, "z")):
            tip = np.eye(3)[axis] @ basis.T
            if tip[2] >= 0.0:
                axes.annotate(name, (1.08 * tip[0], 1.08 * tip[1]), fontsize=8, color="0.3", ha="center", va="center")
        fit_axes(axes, np.array([[-1.12, -1.12], [1.12, 1.12]]), margin=0.0)
        caption(axes, view.title)
    return png_bytes(figure)


def draw_pictures(drawings: list[tuple[str, tuple]], jobs: int, progress: Progress | None = None) -> dict[str, bytes]:
    """Draw pictures on ``jobs`` forked workers.

    Parameters
    ----------
    drawings : list of (str, tuple)
        Each picture's name, its kind first (``"grasp 0"``: a
        :func:`grasp_picture`; the kinds are :data:`_DRAW`'s keys), and the
        arguments of its kind's function
        (:meth:`fcso.output.design_page.ReportInputs.drawings`).
    jobs : int
        Worker processes.
    progress : callable, optional
        ``progress(stage, done, total)``.

    Returns
    -------
    dict
        Name -> PNG bytes.
    """
    report_progress = progress or (lambda stage, done, total: None)
    report_progress("pictures", 0, len(drawings))
    # the workers inherit the drawings: only PNG bytes come back
    with WorkerPool(drawings, jobs) as pool:
        images = pool.map(_draw, list(range(len(drawings))))
    report_progress("pictures", len(drawings), len(drawings))
    return {name: image for (name, _), image in zip(drawings, images)}


#: The function that draws each kind of picture.
_DRAW = {
    "gripper": gripper_picture,
    "finger": finger_picture,
    "fingerpad": fingerpad_picture,
    "grasp": grasp_picture,
    "normals": normals_picture,
    "pose": pose_picture,
    "capture": capture_picture,
}


def _draw(drawings: list[tuple[str, tuple]], index: int) -> bytes:
    name, arguments = drawings[index]
    return _DRAW[name.split()[0]](*arguments)
