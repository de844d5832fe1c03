"""Off-screen pictures for report.html: meshes, grasps and contact normals as PNG.

Everything is drawn with matplotlib's Agg canvas (no display, no GPU): the
meshes are projected orthographically by hand, back faces are culled, the
rest is flat-shaded and painted far to near as one 2D polygon collection.
Large meshes are decimated by vertex clustering for drawing only; every
number in the report comes from the full meshes.
"""

from __future__ import annotations

import io
import zlib
from dataclasses import dataclass

import numpy as np
import trimesh
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.collections import PathCollection, PolyCollection
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.markers import MarkerStyle
from matplotlib.patches import Polygon
from matplotlib.text import Text
from matplotlib.transforms import Bbox, BboxTransformFrom, BboxTransformTo, IdentityTransform, TransformedBbox
from PIL import Image
from scipy.spatial import cKDTree

from ..contact import PadPlacement
from ..geometry import clip_to_box, transform_points, triangle_areas_normals

#: Pixels per inch of every figure (sizes below are in pixels).
DPI = 100
#: Pixel size (width, height) of each kind of picture.
PICTURE_SIZES = {
    "finger": (1200, 420),
    "fingerpad": (900, 420),
    "grasp": (1350, 460),
    "normals": (900, 460),
    "pose": (420, 340),
    "gripper": (900, 560),
    "capture": (900, 420),
}
#: Most triangles drawn per mesh; more are decimated for drawing.
MAX_DRAWN_FACES = 6000
#: Most contact normals drawn on the sphere.
MAX_DRAWN_NORMALS = 4000

PART_COLOUR = (0.78, 0.76, 0.70)
FINGER_COLOUR = (0.55, 0.62, 0.72)
PAD_COLOUR = (0.95, 0.55, 0.15)
CONTACT_COLOUR = (0.85, 0.10, 0.10)
TABLE_COLOUR = (0.90, 0.90, 0.90)
NORMAL_COLOUR = (0.10, 0.30, 0.80)
CAP_COLOUR = (0.95, 0.65, 0.10)


@dataclass(frozen=True)
class View:
    """An orthographic view.

    Attributes
    ----------
    direction : (3,) float
        From the scene towards the camera (need not be unit length).
    up : (3,) float
        Direction that appears upward on the screen (not parallel to ``direction``).
    title : str
        Caption of the panel.
    """

    direction: tuple[float, float, float]
    up: tuple[float, float, float]
    title: str = ""

    def basis(self) -> np.ndarray:
        """Rows: screen right, screen up, towards the camera (unit vectors)."""
        towards = np.asarray(self.direction, dtype=float)
        towards = towards / np.linalg.norm(towards)
        right = np.cross(np.asarray(self.up, dtype=float), towards)
        if np.linalg.norm(right) < 1e-9:  # looking along up: any right will do
            right = np.cross([0.0, 1.0, 0.0] if abs(towards[1]) < 0.9 else [1.0, 0.0, 0.0], towards)
        right = right / np.linalg.norm(right)
        return np.vstack([right, np.cross(towards, right), towards])


@dataclass
class Layer:
    """Triangles drawn with one colour (or one per face) and opacity.

    Attributes
    ----------
    vertices : (n, 3) float
    faces : (m, 3) int
        Outward-wound triangles (back faces are not drawn).
    colours : (3,) or (m, 3) float
        RGB in [0, 1].
    alpha : float
        Opacity.
    """

    vertices: np.ndarray
    faces: np.ndarray
    colours: tuple | np.ndarray
    alpha: float = 1.0


def decimate(
    vertices: np.ndarray, faces: np.ndarray, max_faces: int = MAX_DRAWN_FACES
) -> tuple[np.ndarray, np.ndarray]:
    """Fewer triangles for drawing, by vertex clustering on a grid.

    Vertices in one grid cell merge into their mean; triangles that collapse
    or repeat are dropped. The cell grows until at most ``max_faces`` remain.

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (m, 3) int
    max_faces : int

    Returns
    -------
    vertices, faces : ndarray
        The input itself when it is small enough.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if len(faces) <= max_faces:
        return vertices, faces
    area = float(triangle_areas_normals(vertices, faces)[0].sum())
    # a surface of area A meshed on a grid of cell c has about 2 A / c² triangles
    cell = np.sqrt(2.0 * area / max_faces)
    lower = vertices.min(axis=0)
    while True:
        keys = np.floor((vertices - lower) / cell).astype(np.int64)
        _, cluster, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
        cluster = cluster.ravel()
        merged = np.zeros((len(counts), 3))
        np.add.at(merged, cluster, vertices)
        merged /= counts[:, None]
        remapped = cluster[faces]
        whole = (
            (remapped[:, 0] != remapped[:, 1]) & (remapped[:, 1] != remapped[:, 2]) & (remapped[:, 0] != remapped[:, 2])
        )
        remapped = remapped[whole]
        _, first = np.unique(np.sort(remapped, axis=1), axis=0, return_index=True)
        remapped = remapped[np.sort(first)]
        if len(remapped) <= max_faces:
            return merged, remapped
        cell *= 1.25


def draw_layers(
    axes, layers: list[Layer], view: View, background: list[Layer] | None = None, focus: np.ndarray | None = None
) -> None:
    """Paint triangle layers into 2D axes, far to near, flat-shaded.

    Parameters
    ----------
    axes : Panel
        Its limits are set to fit the drawn triangles.
    layers : list of Layer
        Depth-sorted together.
    view : View
    background : list of Layer, optional
        Drawn first and never over ``layers`` (e.g. the table under a part).
    focus : (n, 3) float, optional
        Fit the limits to these points instead of to everything drawn.
    """
    basis = view.basis()
    light = basis[2] + 0.45 * basis[1] - 0.25 * basis[0]
    light /= np.linalg.norm(light)
    groups = [(background or [], 1), (layers, 2)]
    corners = []
    for group, zorder in groups:
        polygons, colours, depths = [], [], []
        for layer in group:
            if len(layer.faces) == 0:
                continue
            triangles = np.asarray(layer.vertices, dtype=float)[layer.faces]
            normals = triangle_areas_normals(layer.vertices, layer.faces)[1]
            facing = normals @ basis[2] > 0.0
            if not facing.any():
                continue
            screen = triangles[facing] @ basis.T
            shade = 0.35 + 0.65 * np.clip(normals[facing] @ light, 0.0, 1.0)
            base = np.broadcast_to(np.asarray(layer.colours, dtype=float), (len(layer.faces), 3))[facing]
            rgba = np.column_stack([np.clip(base * shade[:, None], 0.0, 1.0), np.full(len(shade), layer.alpha)])
            polygons.append(screen[:, :, :2])
            colours.append(rgba)
            depths.append(screen[:, :, 2].mean(axis=1))
        if not polygons:
            continue
        polygons, colours = np.concatenate(polygons), np.concatenate(colours)
        order = np.argsort(np.concatenate(depths), kind="stable")
        # opaque faces get edges in their own colour to close the seams
        # antialiasing leaves; on translucent ones edges would show as lines
        edges = colours.copy()
        edges[edges[:, 3] < 1.0, 3] = 0.0
        axes.add_collection(
            PolyCollection(
                polygons[order], facecolors=colours[order], edgecolors=edges[order], linewidths=0.8, zorder=zorder
            ),
            autolim=False,
        )
        corners.append(polygons.reshape(-1, 2))
    if focus is not None:
        corners = [(np.asarray(focus, dtype=float) @ basis.T)[:, :2]]
    _fit(axes, np.concatenate(corners) if corners else np.zeros((1, 2)))


class Panel:
    """A rectangle of a figure that draws in data coordinates: the part of an Axes the pictures use.

    An Axes builds ticks, spines and title machinery these pictures never
    show, a tenth of their drawing time. Artists go straight onto the
    figure, clipped to the rectangle, through a data-to-figure transform
    whose data limits :meth:`set_xlim` and :meth:`set_ylim` set.

    Parameters
    ----------
    figure : Figure
    rectangle : (x0, y0, width, height)
        In figure fractions.
    """

    def __init__(self, figure: Figure, rectangle: tuple[float, float, float, float]):
        self.figure = figure
        self._position = Bbox.from_bounds(*rectangle)
        self._limits = Bbox.unit()
        self._clip = TransformedBbox(self._position, figure.transFigure)
        self.transData = BboxTransformFrom(self._limits) + BboxTransformTo(self._clip)

    def get_position(self) -> Bbox:
        return self._position

    def set_xlim(self, low: float, high: float) -> None:
        self._limits.intervalx = (low, high)

    def set_ylim(self, low: float, high: float) -> None:
        self._limits.intervaly = (low, high)

    def add_collection(self, collection, autolim: bool = False) -> None:
        self._add(collection)

    def fill(self, x, y, color, alpha: float | None = None, zorder: float = 1.0) -> None:
        self._add(
            Polygon(np.column_stack([x, y]), closed=True, facecolor=color, edgecolor="none", alpha=alpha, zorder=zorder)
        )

    def plot(self, x, y, style: str = "-", color="k", linewidth: float = 1.0, zorder: float = 2.0) -> None:
        self._add(Line2D(x, y, linestyle=style, color=color, linewidth=linewidth, zorder=zorder))

    def scatter(
        self, x, y, s: float, color, alpha: float | None = None, linewidths: float = 0.0, zorder: float = 1.0
    ) -> None:
        marker = MarkerStyle("o")
        points = PathCollection(
            [marker.get_path().transformed(marker.get_transform())],
            sizes=[s],
            offsets=np.column_stack([x, y]),
            offset_transform=self.transData,
            facecolors=color,
            alpha=alpha,
            linewidths=linewidths,
            zorder=zorder,
        )
        points.set_transform(IdentityTransform())
        points.set_clip_box(self._clip)
        self.figure.add_artist(points)

    def annotate(self, text: str, xy, fontsize: float, color, ha: str, va: str) -> None:
        self._add(
            Text(xy[0], xy[1], text, fontsize=fontsize, color=color, horizontalalignment=ha, verticalalignment=va)
        )

    def _add(self, artist) -> None:
        artist.set_transform(self.transData)
        artist.set_clip_box(self._clip)
        self.figure.add_artist(artist)


def _fit(axes, points: np.ndarray, margin: float = 0.04) -> None:
    """Equal-scale limits around ``points`` that fill the panel."""
    lower, upper = points.min(axis=0), points.max(axis=0)
    centre, size = (lower + upper) / 2.0, np.maximum(upper - lower, 1e-9) * (1.0 + 2.0 * margin)
    box = axes.get_position()
    figure_width, figure_height = axes.figure.get_size_inches()
    aspect = (box.height * figure_height) / (box.width * figure_width)
    width = max(size[0], size[1] / aspect)
    axes.set_xlim(centre[0] - width / 2.0, centre[0] + width / 2.0)
    axes.set_ylim(centre[1] - width * aspect / 2.0, centre[1] + width * aspect / 2.0)


def new_figure(kind: str) -> Figure:
    """An empty figure of the size of a ``kind`` of picture (:data:`PICTURE_SIZES`), drawn off screen."""
    width, height = PICTURE_SIZES[kind]
    figure = Figure(figsize=(width / DPI, height / DPI), dpi=DPI, facecolor="white")
    FigureCanvasAgg(figure)
    return figure


def _panels(figure: Figure, count: int, right_margin: float = 0.0) -> list[Panel]:
    """``count`` side-by-side panels with room for a title above each."""
    width = (1.0 - right_margin) / count
    return [Panel(figure, (k * width + 0.01, 0.02, width - 0.02, 0.86)) for k in range(count)]


def _caption(axes, text: str) -> None:
    """Text centred above a panel (a figure text: axes titles cost a tick layout)."""
    box = axes.get_position()
    axes.figure.text((box.x0 + box.x1) / 2.0, box.y1 + 0.02, text, ha="center", va="bottom", fontsize=9)


def png_bytes(figure: Figure) -> bytes:
    """A figure drawn on its Agg canvas, as PNG bytes of the figure's pixel size.

    The figures are opaque and mostly flat colour: RGB with zlib's run-length
    strategy encodes in a third of the time matplotlib's RGBA default takes,
    into fewer bytes.
    """
    canvas = figure.canvas if isinstance(figure.canvas, FigureCanvasAgg) else FigureCanvasAgg(figure)
    canvas.draw()
    buffer = io.BytesIO()
    Image.fromarray(np.asarray(canvas.buffer_rgba())[:, :, :3]).save(buffer, format="png", compress_type=zlib.Z_RLE)
    return buffer.getvalue()


def _mesh_arrays(mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)


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
    vertices, faces = decimate(*_mesh_arrays(finger))
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
    for axes, view in zip(_panels(figure, 3), views):
        draw_layers(axes, [Layer(vertices, faces, colours)], view)
        _caption(axes, view.title)
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
    vertices, faces = decimate(*_mesh_arrays(pad))
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
    for axes, view in zip(_panels(figure, 2, right_margin=0.1), views):
        draw_layers(axes, [Layer(vertices, faces, colours)], view)
        _caption(axes, view.title)
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
    full_vertices, full_faces = _mesh_arrays(part)
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
    pad_vertices, pad_faces = decimate(*_mesh_arrays(pad))
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
    for axes, view, drawn, focus in zip(_panels(figure, 3), views, (layers, layers, close_layers), (None, None, pads)):
        draw_layers(axes, drawn, view, background=[_table(full_vertices)], focus=focus)
        _caption(axes, view.title)
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
    vertices, faces = decimate(*_mesh_arrays(part))
    # long plate triangles sort badly against the part: split them for drawing
    finger_vertices, finger_faces = trimesh.remesh.subdivide_to_size(
        *decimate(*_mesh_arrays(finger)), float(finger.extents.max()) / 12.0
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
    _caption(axes, title)
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
    vertices, faces = decimate(*_mesh_arrays(part))
    figure = new_figure("pose")
    axes = Panel(figure, (0.02, 0.02, 0.96, 0.84))
    draw_layers(
        axes,
        [Layer(vertices, faces, PART_COLOUR)],
        View((1.0, -1.2, 0.9), (0.0, 0.0, 1.0)),
        background=[_table(vertices)],
    )
    _caption(axes, title)
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
    for axes, view in zip(_panels(figure, 2), views):
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
        _fit(axes, np.array([[-1.12, -1.12], [1.12, 1.12]]), margin=0.0)
        _caption(axes, view.title)
    return png_bytes(figure)
