"""3-D views of any model as one self-contained, offline HTML file (plotly, WebGL), for a run or one configuration.

Bodies are drawn from their ``shape`` (rod, disk, cylinder, sphere, box) turned with their link frame, particles
as small spheres, every link as segments between its points (animation.py's sketch, in 3-D), the joint frames as
axes triads and the ground as a grid normal to gravity. The positions and the frame orientations are the model's
own kinematics, compiled and evaluated at the sampled output rows; a page reads ``#frame=N`` to open at frame N.
"""
from __future__ import annotations

import html
import importlib.util
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import sympy as sp

from mechsys.errors import AnalysisError, InputError
from mechsys.report.animation import (MAX_FRAMES, Geometry, LinkSketch, check_animation_path, default_fps, geometry,
                                      sample_indices, write_animation)

if TYPE_CHECKING:
    from mechsys.analysis.motion.simulate import SimulationResult
    from mechsys.mechanics.model import MechanicalModel
    from mechsys.model.load import Document

HTML_SUFFIXES = (".html", ".htm")
DIV_ID = "mechsys-view"
PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22",
           "#17becf")  # matplotlib's tab10: the GIF's colours, link by link
SHAPES = ("rod", "disk", "cylinder", "sphere", "box")
SECTORS = 32  # facets around a rod, disk or cylinder
ROD_RADIUS = 0.012  # drawn radius of a rod, as a fraction of the scene's size (a rod has no thickness)
DISK_THICKNESS = 0.1  # drawn thickness of a disk, as a fraction of its radius (a disk has none)
PARTICLE_RADIUS = 0.015  # drawn radius of a particle, as a fraction of the scene's size
TRIAD_SIZE = 0.06  # length of the joint frames' axes, as a fraction of the scene's size
GRID_LINES = 11


@dataclass
class Solid:
    """A body drawn as a closed triangle mesh fixed in its link frame: ``kind`` is a shape or ``particle``."""

    link: str
    index: int  # the link's position in Scene.links
    kind: str
    centre: np.ndarray  # centre of mass in link axes
    axis: int  # symmetry axis (0, 1, 2 for x, y, z) of a rod, disk or cylinder
    size: tuple[float, ...]  # rod (length,), disk (radius,), cylinder (radius, length), sphere (radius,), box (a, b, c)


@dataclass
class Scene:
    """What is drawn, symbolically: the sketch points, and each link frame's origin and rotation matrix (link
    axes to ground axes), as expressions of t, q, u and the parameters."""

    geometry: Geometry
    links: list[str]
    origins: sp.Matrix  # 3 x L
    rotations: sp.Matrix  # 3 x 3L, the matrices side by side
    solids: list[Solid]
    up: np.ndarray  # unit vector against gravity (ground z without gravity)


@dataclass
class Motion:
    """The scene evaluated at sampled states: points (F, N, 3), origins (F, L, 3), rotations (F, L, 3, 3)."""

    t: np.ndarray
    points: np.ndarray
    origins: np.ndarray
    rotations: np.ndarray


@dataclass
class Mesh:
    vertices: np.ndarray  # (V, 3)
    triangles: np.ndarray  # (F, 3) vertex indices
    shades: np.ndarray  # (F,) 0 or 1: alternate faces are lighter, so a turning body is seen to turn


# ----------------------------------------------------------------------------------------- options
def plotly_available() -> bool:
    return importlib.util.find_spec("plotly") is not None


def is_html(path: str | os.PathLike) -> bool:
    return Path(path).suffix.lower() in HTML_SUFFIXES


def check_html_path(path: str | os.PathLike, option: str, fps: float | None = None) -> None:
    """An HTML view is written to a .html file that can be written, at a positive frame rate, with plotly
    installed; otherwise one line (exit 2) before any work."""
    from mechsys.report.files import output_target

    if fps is not None and not (np.isfinite(fps) and fps > 0):
        raise InputError(f"--fps {fps}: must be a positive number")
    if not is_html(path):
        raise InputError(f"{option} {os.fspath(path)}: write the 3-D view as an .html file")
    if not plotly_available():
        raise InputError(f"{option} {os.fspath(path)}: the 3-D view needs plotly, which is not installed "
                         "(pip install 'mechsys[view]')")
    output_target(path)


def check_animate(path: str | os.PathLike, fps: float | None = None) -> None:
    """``simulate --animate``: the suffix chooses, .html for the 3-D view of any model, .gif for planar ones."""
    suffix = Path(path).suffix.lower()
    if is_html(path):
        check_html_path(path, "--animate", fps)
    elif suffix == ".gif":
        check_animation_path(path, fps)
    else:
        raise InputError(f"--animate {os.fspath(path)}: write the animation as a .gif file (planar mechanisms) "
                         "or as an .html file (3-D view of any model)")


def write_animate(model: MechanicalModel, result: SimulationResult, path: str | os.PathLike, fps: float | None = None,
                  source: str | os.PathLike | None = None, max_frames: int = MAX_FRAMES) -> int:
    """Write ``simulate --animate``'s file, chosen by its suffix; returns the number of frames."""
    if is_html(path):
        return write_run_view(model, result, path, fps, max_frames)
    return write_animation(model, result, path, fps, source, max_frames)


def default_view_path(file: str | os.PathLike) -> Path:
    """``mechsys view FILE`` without -o: FILE's name with .html, in the current folder."""
    return Path(Path(file).stem + ".html")


# ----------------------------------------------------------------------------------------- the scene
def _value(doc, value, path: tuple) -> float:
    """An expression of parameters (a shape dimension, a centre of mass) at the parameter values."""
    expr = doc.parse(value, path, "parameter")
    values = {sym: sp.Float(doc.parameter_values[name]) for name, sym in doc.parameters.items()}
    x = sp.sympify(expr.xreplace(values)).evalf()
    if not (x.is_number and x.is_real and x.is_finite):
        raise doc.error(path, f"must be a finite real number to be drawn, got {x}")
    return float(x)


def solid_of(doc: Document, name: str, index: int) -> Solid | None:
    """The drawn body of a link: its shape, a particle, or None (drawn as segments only)."""
    spec = doc.spec.links[name]
    path = ("links", name)
    centre = np.array([_value(doc, c, path + ("center_of_mass", i))
                       for i, c in enumerate(spec.center_of_mass)])
    if spec.particle:
        return Solid(name, index, "particle", centre, 2, ())
    if spec.shape is None:
        return None
    kind = next(k for k in SHAPES if getattr(spec.shape, k) is not None)
    s = getattr(spec.shape, kind)
    p = path + ("shape", kind)
    axis = "xyz".index(getattr(s, "axis", "z").lstrip("-"))
    if kind == "box":
        size = tuple(abs(_value(doc, v, p + ("size", i))) for i, v in enumerate(s.size))
    else:
        size = tuple(abs(_value(doc, getattr(s, key), p + (key,))) for key in ("radius", "length") if hasattr(s, key))
    return Solid(name, index, kind, centre, axis, size)


def up_direction(doc: Document) -> np.ndarray:
    """The unit vector against the (first, constant) gravity of the model; ground z when there is none."""
    values = {sym: sp.Float(doc.parameter_values[n]) for n, sym in doc.parameters.items()}
    for i, force in enumerate(doc.spec.forces):
        if force.type != "gravity":
            continue
        g = doc.parse_vec(force.acceleration, ("forces", i, "acceleration"), "force").xreplace(values)
        if all(sp.sympify(c).is_number for c in g):
            vec = np.array([float(c) for c in g])
            norm = float(np.linalg.norm(vec))
            if np.isfinite(norm) and norm > 0:
                return -vec / norm
    return np.array([0.0, 0.0, 1.0])


def scene(model: MechanicalModel) -> Scene:
    """The symbolic scene of a model: sketch points, link frames and drawn bodies."""
    links = list(model.doc.spec.links)
    frames = [model.kin.frames[n] for n in links]
    geo = geometry(model)
    if not links:
        raise InputError(f"{model.name} has no links to draw")
    origins = sp.Matrix.hstack(*[f.origin for f in frames])
    rotations = sp.Matrix.hstack(*[f.R for f in frames])
    solids = [s for i, n in enumerate(links) if (s := solid_of(model.doc, n, i)) is not None]
    return Scene(geo, links, origins, rotations, solids, up_direction(model.doc))


def evaluate_scene(model: MechanicalModel, sc: Scene, t: np.ndarray, q: np.ndarray, u: np.ndarray) -> Motion:
    """Points, frame origins and rotations at the given states (one compiled function for all of them)."""
    from mechsys.numeric.parameters import parameter_values
    from mechsys.numeric.lambdify import compile_matrix

    n, links = sc.geometry.positions.shape[1], len(sc.links)
    stacked = sp.Matrix.hstack(sc.geometry.positions, sc.origins, sc.rotations)
    f = compile_matrix(stacked, model.t, model.q, model.u, model.parameter_symbols)
    p = parameter_values(model)
    with np.errstate(all="ignore"):
        values = np.array([np.asarray(f(ti, qi, ui, p), dtype=float).reshape(3, -1) for ti, qi, ui in zip(t, q, u)])
    bad = ~np.all(np.isfinite(values), axis=(1, 2))
    if np.any(bad):
        raise AnalysisError(f"the positions to draw are not finite at t = {float(t[np.argmax(bad)]):g}")
    frames = len(t)
    points = values[:, :, :n].transpose(0, 2, 1)
    origins = values[:, :, n:n + links].transpose(0, 2, 1)
    rotations = values[:, :, n + links:].reshape(frames, 3, links, 3).transpose(0, 2, 1, 3)
    return Motion(np.asarray(t, dtype=float), points, origins, rotations)


# ----------------------------------------------------------------------------------------- meshes
def _axial(coords: np.ndarray, axis: int) -> np.ndarray:
    """Columns (a, b, axial) placed so that the axial one is ``axis`` (a right-handed cyclic order)."""
    out = np.empty_like(coords)
    out[:, (axis + 1) % 3], out[:, (axis + 2) % 3], out[:, axis] = coords[:, 0], coords[:, 1], coords[:, 2]
    return out


def cylinder_mesh(radius: float, length: float, axis: int, sectors: int = SECTORS) -> Mesh:
    """A closed cylinder about ``axis`` centred at the origin: two rings, two cap centres (the last vertices)."""
    phi = 2 * np.pi * np.arange(sectors) / sectors
    ring = np.column_stack([radius * np.cos(phi), radius * np.sin(phi)])
    h = length / 2
    local = np.vstack([np.column_stack([ring, np.full(sectors, -h)]), np.column_stack([ring, np.full(sectors, h)]),
                       [[0.0, 0.0, -h], [0.0, 0.0, h]]])
    s = np.arange(sectors)
    nxt = (s + 1) % sectors
    lo, hi = 2 * sectors, 2 * sectors + 1
    tris = np.vstack([np.column_stack([s, nxt, s + sectors]), np.column_stack([nxt, nxt + sectors, s + sectors]),
                      np.column_stack([np.full(sectors, lo), nxt, s]),
                      np.column_stack([np.full(sectors, hi), s + sectors, nxt + sectors])])
    quarter = (s * 4 // sectors) % 2
    return Mesh(_axial(local, axis), tris, np.concatenate([quarter] * 4))


def sphere_mesh(radius: float, rings: int = 12, sectors: int = 24) -> Mesh:
    """A UV sphere about z centred at the origin: poles, then ``rings - 1`` latitude rings."""
    theta = np.pi * np.arange(1, rings) / rings
    phi = 2 * np.pi * np.arange(sectors) / sectors
    tt, pp = np.meshgrid(theta, phi, indexing="ij")
    body = np.column_stack([np.sin(tt).ravel() * np.cos(pp).ravel(), np.sin(tt).ravel() * np.sin(pp).ravel(),
                            np.cos(tt).ravel()])
    verts = radius * np.vstack([[[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]], body])
    idx = lambda r, s: 2 + r * sectors + s % sectors  # noqa: E731
    tris, shades = [], []
    for s in range(sectors):
        shade = (s * 4 // sectors) % 2
        tris.append((0, idx(0, s), idx(0, s + 1)))
        tris.append((1, idx(rings - 2, s + 1), idx(rings - 2, s)))
        shades += [shade, shade]
        for r in range(rings - 2):
            tris += [(idx(r, s), idx(r + 1, s), idx(r + 1, s + 1)), (idx(r, s), idx(r + 1, s + 1), idx(r, s + 1))]
            shades += [shade ^ (r * 2 // (rings - 2)), shade ^ (r * 2 // (rings - 2))]
    return Mesh(verts, np.array(tris), np.array(shades))


def box_mesh(size: tuple[float, ...]) -> Mesh:
    """A box of edges ``size`` (x, y, z) centred at the origin; opposite faces share a shade."""
    corners = np.array([[i, j, k] for i in (-0.5, 0.5) for j in (-0.5, 0.5) for k in (-0.5, 0.5)]) * np.array(size)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    shades = [face // 2 % 2 for face in range(6) for _ in range(2)]
    return Mesh(corners, np.array(tris), np.array(shades))


def solid_mesh(solid: Solid, span: float) -> Mesh:
    """The mesh of a solid in its link axes (centred at its centre of mass); ``span`` sizes what has no size of
    its own (a rod's thickness, a particle)."""
    kind, size = solid.kind, solid.size
    if kind == "rod":
        mesh = cylinder_mesh(ROD_RADIUS * span, size[0], solid.axis, 12)
    elif kind == "disk":
        mesh = cylinder_mesh(size[0], DISK_THICKNESS * size[0], solid.axis)
    elif kind == "cylinder":
        mesh = cylinder_mesh(size[0], size[1], solid.axis)
    elif kind == "box":
        mesh = box_mesh(size)
    else:
        mesh = sphere_mesh(size[0] if kind == "sphere" else PARTICLE_RADIUS * span)
    return Mesh(mesh.vertices + solid.centre, mesh.triangles, mesh.shades)


def placed(vertices: np.ndarray, origin: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """Link-axes vertices (V, 3) in ground axes for a frame at ``origin`` turned by ``rotation``."""
    return origin + vertices @ rotation.T


def solid_vertices(motion: Motion, solid: Solid, mesh: Mesh) -> np.ndarray:
    """(F, V, 3): the mesh placed in every frame."""
    return np.array([placed(mesh.vertices, o[solid.index], r[solid.index])
                     for o, r in zip(motion.origins, motion.rotations)])


# ----------------------------------------------------------------------------------------- lines
def link_segments(points: np.ndarray, link: LinkSketch) -> np.ndarray:
    """A link's sketch at one frame: (M, 3), segments origin -> each other point, NaN rows between them."""
    gap = np.full(3, np.nan)
    origin = points[link.points[0]]
    return np.array([row for i in link.points[1:] for row in (origin, points[i], gap)]).reshape(-1, 3)


def triad(origins: np.ndarray, rotations: np.ndarray, axis: int, size: float) -> np.ndarray:
    """The ``axis`` arrows of every frame at one instant: (3L, 3), origin -> origin + size e, NaN between."""
    gap = np.full(3, np.nan)
    return np.array([row for o, r in zip(origins, rotations) for row in (o, o + size * r[:, axis], gap)])


def _plane_basis(up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors spanning the ground plane normal to ``up`` (world axes when up is one)."""
    k = int(np.argmax(np.abs(up)))
    if abs(abs(up[k]) - 1.0) < 1e-12:
        return np.eye(3)[(k + 1) % 3], np.eye(3)[(k + 2) % 3]
    e1 = np.eye(3)[int(np.argmin(np.abs(up)))]
    e1 = e1 - (e1 @ up) * up
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(up, e1)


# ----------------------------------------------------------------------------------------- the figure
@dataclass
class Drawing:
    """Everything placed in ground axes, frame by frame, before it becomes plotly traces."""

    motion: Motion
    meshes: list[tuple[Solid, Mesh, np.ndarray]]  # solid, local mesh, (F, V, 3) world vertices
    span: float
    lo: np.ndarray  # bounding box of everything drawn over the run
    hi: np.ndarray


def drawing(sc: Scene, motion: Motion) -> Drawing:
    """Place every solid in every frame; the scene's size sizes rods' thickness, particles and triads."""
    coords = [motion.points.reshape(-1, 3), motion.origins.reshape(-1, 3)]
    lo, hi = np.min(np.vstack(coords), axis=0), np.max(np.vstack(coords), axis=0)
    sized = [s.size[0] for s in sc.solids if s.kind in ("disk", "sphere", "cylinder")] + \
        [max(s.size) for s in sc.solids if s.kind in ("rod", "box")]
    span = float(max(np.max(hi - lo), max(sized, default=0.0), 1e-3))
    meshes = []
    for solid in sc.solids:
        mesh = solid_mesh(solid, span)
        world = solid_vertices(motion, solid, mesh)
        meshes.append((solid, mesh, world))
        lo, hi = np.minimum(lo, world.reshape(-1, 3).min(axis=0)), np.maximum(hi, world.reshape(-1, 3).max(axis=0))
    return Drawing(motion, meshes, float(max(np.max(hi - lo), 1e-3)), lo, hi)


def _lighter(color: str, amount: float = 0.45) -> str:
    rgb = np.array([int(color[i:i + 2], 16) for i in (1, 3, 5)], dtype=float)
    mixed = np.round(rgb + (255 - rgb) * amount).astype(int)
    return "#" + "".join(f"{c:02x}" for c in mixed)


def _xyz(rows: np.ndarray) -> dict:
    return {"x": rows[:, 0], "y": rows[:, 1], "z": rows[:, 2]}


def ground_traces(sc: Scene, d: Drawing) -> list[dict]:
    """A grid and a faint plane normal to ``up``, at the lowest height drawn (or 0 when everything is above),
    under the whole motion; the fixed supports as grey diamonds."""
    up = sc.up
    e1, e2 = _plane_basis(up)
    corners = np.array([[x, y, z] for x in (d.lo[0], d.hi[0]) for y in (d.lo[1], d.hi[1]) for z in (d.lo[2], d.hi[2])])
    level = min(0.0, float(np.min(corners @ up)))
    pad = 0.05 * d.span  # within the axes' margin (_axis_ranges)
    a = np.linspace(np.min(corners @ e1) - pad, np.max(corners @ e1) + pad, GRID_LINES)
    b = np.linspace(np.min(corners @ e2) - pad, np.max(corners @ e2) + pad, GRID_LINES)
    base = level * up
    gap = np.full(3, np.nan)
    rows = [r for x in a for r in (base + x * e1 + b[0] * e2, base + x * e1 + b[-1] * e2, gap)] + \
           [r for y in b for r in (base + a[0] * e1 + y * e2, base + a[-1] * e1 + y * e2, gap)]
    plane = np.array([base + x * e1 + y * e2 for x in (a[0], a[-1]) for y in (b[0], b[-1])])
    traces = [dict(type="mesh3d", name="ground", legendgroup="ground", showlegend=False, color="#b0b0b0",
                   opacity=0.15, i=[0, 1], j=[1, 3], k=[2, 2], hoverinfo="skip", **_xyz(plane)),
              dict(type="scatter3d", mode="lines", name="ground", legendgroup="ground",
                   line=dict(color="#c8c8c8", width=1), hoverinfo="skip", **_xyz(np.array(rows)))]
    supports = d.motion.points[0, sc.geometry.ground] if sc.geometry.ground else np.empty((0, 3))
    if len(supports):
        labels = [sc.geometry.labels[i] for i in sc.geometry.ground]
        traces.append(dict(type="scatter3d", mode="markers", name="supports", legendgroup="ground",
                           marker=dict(symbol="diamond", size=5, color="#6e6e6e"), text=labels,
                           hoverinfo="text", **_xyz(supports)))
    return traces


def moving_traces(sc: Scene, d: Drawing, k: int, full: bool) -> list[dict]:
    """The traces that move, at frame k: link sketches, bodies, points, joint frames. ``full`` adds what does not
    change between frames (colours, triangles, names), for the first frame."""
    m, geo = d.motion, sc.geometry
    traces: list[dict] = []
    for i, link in enumerate(geo.links):
        if len(link.points) > 1:
            trace = dict(type="scatter3d", **_xyz(link_segments(m.points[k], link)))
            if full:
                color = PALETTE[i % len(PALETTE)]
                trace.update(mode="lines", name=link.name, legendgroup=link.name, line=dict(color=color, width=5),
                             hoverinfo="name")
            traces.append(trace)
    for solid, mesh, world in d.meshes:
        trace = dict(type="mesh3d", **_xyz(world[k]))
        if full:
            color = PALETTE[solid.index % len(PALETTE)]
            faces = np.where(mesh.shades == 1, _lighter(color), color).tolist()
            trace.update(name=f"{solid.link} ({solid.kind})", legendgroup=solid.link, showlegend=True,
                         i=mesh.triangles[:, 0], j=mesh.triangles[:, 1], k=mesh.triangles[:, 2], facecolor=faces,
                         flatshading=solid.kind == "box", hoverinfo="name",
                         lighting=dict(ambient=0.75, diffuse=0.5, specular=0.15, roughness=0.6))
        traces.append(trace)
    fixed = set(geo.ground)
    moving = [i for i in range(len(geo.labels)) if i not in fixed]
    trace = dict(type="scatter3d", **_xyz(m.points[k, moving] if moving else np.empty((0, 3))))
    if full:
        trace.update(mode="markers", name="points", marker=dict(size=3, color="#222222"),
                     text=[geo.labels[i] for i in moving], hoverinfo="text")
    traces.append(trace)
    for axis, color in enumerate(("#e41a1c", "#4daf4a", "#377eb8")):
        trace = dict(type="scatter3d", **_xyz(triad(m.origins[k], m.rotations[k], axis, TRIAD_SIZE * d.span)))
        if full:
            trace.update(mode="lines", name="joint frames", legendgroup="joint frames", showlegend=axis == 0,
                         line=dict(color=color, width=4), hoverinfo="skip")
        traces.append(trace)
    return traces


def _axis_ranges(sc: Scene, d: Drawing) -> tuple[list[list[float]], dict]:
    """Fixed axis ranges holding the whole run and the ground grid, at one scale on all three axes."""
    pad = 0.08 * d.span
    lo, hi = d.lo - pad, d.hi + pad
    level = min(0.0, float(np.min(np.array([d.lo, d.hi]) @ sc.up)))  # the grid may lie below everything drawn
    lo = np.minimum(lo, level * sc.up - pad * np.abs(sc.up))
    centre, half = (lo + hi) / 2, np.maximum((hi - lo) / 2, 0.15 * d.span)
    ranges = [[float(c - h), float(c + h)] for c, h in zip(centre, half)]
    ratio = half / np.max(half)
    return ranges, dict(x=float(ratio[0]), y=float(ratio[1]), z=float(ratio[2]))


def _camera(sc: Scene, d: Drawing) -> dict:
    """Look at the broad side of the motion from slightly above: the eye is mostly along the ground direction in
    which the scene is thinnest."""
    e1, e2 = _plane_basis(sc.up)
    extent = d.hi - d.lo
    thin, broad = (e1, e2) if abs(extent @ e1) <= abs(extent @ e2) else (e2, e1)
    eye = thin + 0.35 * broad + 0.45 * sc.up
    eye = 1.6 * eye / np.linalg.norm(eye)
    vec = lambda v: dict(x=float(v[0]), y=float(v[1]), z=float(v[2]))  # noqa: E731
    return dict(up=vec(sc.up), eye=vec(eye), center=dict(x=0, y=0, z=0))


def _controls(t: np.ndarray, fps: float) -> dict:
    """Play/pause buttons and a time slider over the frames (named 0, 1, ...)."""
    step = dict(mode="immediate", frame=dict(duration=0, redraw=True), transition=dict(duration=0))
    play = dict(frame=dict(duration=1000.0 / fps, redraw=True), transition=dict(duration=0), fromcurrent=True,
                mode="immediate")
    return dict(
        updatemenus=[dict(type="buttons", direction="left", x=0.0, y=0.0, xanchor="left", yanchor="top",
                          pad=dict(t=40, r=10), showactive=False,
                          buttons=[dict(label="Play", method="animate", args=[None, play]),
                                   dict(label="Pause", method="animate", args=[[None], step])])],
        sliders=[dict(active=0, x=0.16, y=0.0, len=0.82, xanchor="left", yanchor="top", pad=dict(t=30),
                      currentvalue=dict(prefix="t = ", suffix=" s", font=dict(color="#2a3f5f")),
                      font=dict(color="rgba(0, 0, 0, 0)"),  # one label per step would overlap: only the value
                      steps=[dict(label=f"{ti:.6g}", method="animate", args=[[str(k)], step])
                             for k, ti in enumerate(t)])])


def figure(sc: Scene, motion: Motion, title: str, fps: float) -> dict:
    """The plotly figure (a plain dict): static ground, moving traces of frame 0, one frame per time."""
    d = drawing(sc, motion)
    static = ground_traces(sc, d)
    first = moving_traces(sc, d, 0, True)
    moving = list(range(len(static), len(static) + len(first)))
    ranges, ratio = _axis_ranges(sc, d)
    scene_layout = dict(aspectmode="manual", aspectratio=ratio, camera=_camera(sc, d),
                        **{f"{a}axis": dict(range=r, autorange=False, title=dict(text=f"{a} [m]"))
                           for a, r in zip("xyz", ranges)})
    layout = dict(title=dict(text=html.escape(title), x=0.02), scene=scene_layout,
                  margin=dict(l=0, r=0, t=40, b=90 if len(motion.t) > 1 else 0), legend=dict(itemsizing="constant"),
                  uirevision="view")
    frames = []
    if len(motion.t) > 1:
        layout.update(_controls(motion.t, fps))
        frames = [dict(name=str(k), traces=moving, data=moving_traces(sc, d, k, False)) for k in range(len(motion.t))]
    return dict(data=static + first, layout=layout, frames=frames)


# ----------------------------------------------------------------------------------------- the page
def _jump_script(frames: int) -> str:
    """Open at the frame of the URL's ``#frame=N`` (clamped to the last), and follow later changes of the hash;
    the div's data-frame attribute tells which frame is shown (set once it is drawn, kept while playing)."""
    return """
var gd = document.getElementById('{plot_id}');
var last = %d;
function mechsysShown(k) { gd.setAttribute('data-frame', String(k)); }
function mechsysJump() {
  var m = /(?:^#|&)frame=(\\d+)/.exec(window.location.hash);
  var k = m ? Math.min(parseInt(m[1], 10), last) : 0;
  if (last < 1) { mechsysShown(0); return; }
  Plotly.animate(gd, [String(k)], {mode: 'immediate', frame: {duration: 0, redraw: true},
                                   transition: {duration: 0}})
    .then(function () { mechsysShown(k); });
}
var pending = 0;  // the frame being drawn: plotly announces it before drawing, then reports each drawing
gd.on('plotly_animatingframe', function (e) { pending = e.name; });
gd.on('plotly_afterplot', function () { mechsysShown(pending); });
if (/(?:^#|&)frame=/.test(window.location.hash)) { mechsysJump(); } else { mechsysShown(0); }
window.addEventListener('hashchange', mechsysJump);
""" % (frames - 1)


def page(fig: dict, title: str) -> str:
    """One self-contained HTML page: plotly.js inlined (no network), the figure, the #frame=N reader."""
    import plotly.io as pio

    fig = dict(fig, layout=dict(fig["layout"], template=pio.templates["plotly_white"].to_plotly_json()))
    div = pio.to_html(fig, include_plotlyjs=True, full_html=False, auto_play=False, validate=False,
                      div_id=DIV_ID, default_width="100%", default_height="100%",
                      post_script=_jump_script(max(len(fig["frames"]), 1)),
                      config={"displaylogo": False, "responsive": True})
    return ("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
            f"<title>{html.escape(title)}</title>\n"
            "<style>html, body { margin: 0; height: 100%; overflow: hidden; background: #ffffff; }</style>\n"
            f"</head>\n<body>\n{div}\n</body>\n</html>\n")


def write_page(path: str | os.PathLike, sc: Scene, motion: Motion, title: str, fps: float) -> None:
    from mechsys.report.files import write_text_atomic

    write_text_atomic(path, page(figure(sc, motion, title, fps), title))


def write_run_view(model: MechanicalModel, result: SimulationResult, path: str | os.PathLike, fps: float | None = None,
                   max_frames: int = MAX_FRAMES) -> int:
    """The 3-D animation of a run (at most ``max_frames`` evenly spread output rows, first and last included),
    written atomically; returns the number of frames."""
    check_html_path(path, "--animate", fps)
    if not len(result.t):
        raise InputError(f"--animate: the run of {model.name} has no output to draw")
    rows = sample_indices(len(result.t), max_frames)
    t = np.asarray(result.t, dtype=float)[rows]
    sc = scene(model)
    motion = evaluate_scene(model, sc, t, np.asarray(result.q)[rows], np.asarray(result.u)[rows])
    write_page(path, sc, motion, model.name, fps or default_fps(t))
    return len(t)


def initial_configuration(model: MechanicalModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, q, u) of the file's initial state, as `simulate` starts it: assembled onto the holonomic constraints
    (loop closures) when there are any, as the file gives it otherwise."""
    from mechsys.analysis.motion.simulate import check_on_manifold, file_state, initial_state

    if any(row.kind == "holonomic" for row in model.kin.constraints):
        c, p, y0 = initial_state(model)
        q0, u0 = y0[:len(model.q)], y0[len(model.q):]
        check_on_manifold(c, p, 0.0, q0, u0)
    else:
        q0, u0 = file_state(model)
    return np.zeros(1), q0[None, :], u0[None, :]


def write_initial_view(model: MechanicalModel, path: str | os.PathLike) -> None:
    """`mechsys view`: the initial configuration as a one-frame 3-D view, written atomically."""
    check_html_path(path, "--output")
    sc = scene(model)
    motion = evaluate_scene(model, sc, *initial_configuration(model))
    write_page(path, sc, motion, f"{model.name} (initial configuration)", 10.0)

