"""Drawing meshes off screen for report.html: views, layers, panels, PNG (the pictures: :mod:`fcso.output.pictures`).

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
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import PathCollection, PolyCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.markers import MarkerStyle
from matplotlib.patches import Polygon
from matplotlib.text import Text
from matplotlib.transforms import Bbox, BboxTransformFrom, BboxTransformTo, IdentityTransform, TransformedBbox
from PIL import Image

from ..geometry import triangle_areas_normals

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
    fit_axes(axes, np.concatenate(corners) if corners else np.zeros((1, 2)))


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


def fit_axes(axes, points: np.ndarray, margin: float = 0.04) -> None:
    """Limits of ``axes`` around ``points`` (2D) with a relative ``margin``, equal aspect."""
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


def panels(figure: Figure, count: int, right_margin: float = 0.0) -> list[Panel]:
    """``count`` panels side by side across ``figure``, leaving ``right_margin`` (a fraction) free."""
    width = (1.0 - right_margin) / count
    return [Panel(figure, (k * width + 0.01, 0.02, width - 0.02, 0.86)) for k in range(count)]


def caption(axes, text: str) -> None:
    """A panel's title: a figure text centred above it (an axes title would cost a tick layout)."""
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


def mesh_arrays(mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of ``mesh`` as arrays."""
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)
