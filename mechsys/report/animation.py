"""Animated GIFs of planar mechanisms: link sketches from the model's points, drawn over a simulation's output."""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import sympy as sp

from mechsys.errors import InputError

if TYPE_CHECKING:
    from mechsys.analysis.motion.simulate import SimulationResult
    from mechsys.mechanics.model import MechanicalModel

MAX_FRAMES = 200
GROUND_JOINTS = {"revolute", "prismatic", "cylindrical", "universal", "spherical"}  # joints that are supports
PLANE_AXES = {"z": ((0, "x"), (1, "y")), "y": ((2, "z"), (0, "x")), "x": ((1, "y"), (2, "z"))}
REL_TOL = 1e-6


@dataclass
class LinkSketch:
    """How one link is drawn: segments from its joint point ``points[0]`` to each other point."""

    name: str
    points: list[int]  # indices into Geometry.labels; the first is the link's origin (its joint point)
    com: int | None  # index of the centre of mass, when the link has mass
    particle: bool
    joint: str  # joint type (the marker drawn at the joint point)


@dataclass
class Geometry:
    """World positions (3 x N, in t, q, u and parameters) of the points drawn, and the angular velocities
    (3 x L, ground axes) of the links used to decide whether the motion is planar."""

    labels: list[str]
    positions: sp.Matrix
    omegas: sp.Matrix
    links: list[LinkSketch] = field(default_factory=list)
    ground: list[int] = field(default_factory=list)  # indices of fixed supports and named ground points


@dataclass
class Frames:
    """Sampled output of a run, projected onto the plane of motion: xy has shape (frames, points, 2)."""

    t: np.ndarray
    xy: np.ndarray
    geometry: Geometry
    axis_labels: tuple[str, str]


def _same(a: sp.Matrix, b: sp.Matrix) -> bool:
    return all(sp.expand(x - y) == 0 for x, y in zip(a, b))


def geometry(model: MechanicalModel) -> Geometry:
    """The points of every link (origin, centre of mass, named points, child joints, rod ends) and the ground's
    supports and named points, as symbolic world positions."""
    from mechsys.mechanics.build import Builder
    from mechsys.mechanics.kinematics import AXES

    doc, kin = model.doc, model.kin
    builder = Builder(doc)
    labels: list[str] = []
    columns: list[sp.Matrix] = []

    def add(label: str, world: sp.Matrix) -> int:
        labels.append(label)
        columns.append(world)
        return len(labels) - 1

    links = doc.spec.links
    massive = {b.name for b in kin.bodies if b.mass != 0}
    sketches: list[LinkSketch] = []
    for name, spec in links.items():
        frame = kin.frames[name]
        local: list[tuple[str, sp.Matrix]] = [(f"{name}.origin", sp.zeros(3, 1)),
                                              (f"{name}.com", builder.local_point(name, "com", ("links", name)))]
        local += [(f"{name}.{p}", builder.local_point(name, p, ("links", name))) for p in spec.points]
        for child, cspec in links.items():
            if cspec.joint.parent == name:
                o = cspec.joint.origin
                path = ("links", child, "joint", "origin")
                vec = builder.local_point(name, o, path) if isinstance(o, str) else doc.parse_vec(o, path)
                local.append((f"{name}.joint({child})", vec))
        if spec.shape is not None and spec.shape.rod is not None:
            rod = spec.shape.rod
            half = sp.Matrix(AXES[rod.axis]) * doc.parse(rod.length, ("links", name, "shape", "rod", "length"),
                                                         "parameter") / 2
            com = local[1][1]
            local += [(f"{name}.rod_end1", com - half), (f"{name}.rod_end2", com + half)]
        index: dict[str, int] = {}  # every label -> the drawn point (points at the same place drawn once)
        kept: list[tuple[sp.Matrix, int]] = []
        for label, vec in local:
            match = next((i for v, i in kept if _same(vec, v)), None)
            if match is None:
                match = add(label, frame.point(vec))
                kept.append((vec, match))
            index[label] = match
        com_index = index[f"{name}.com"] if name in massive or spec.particle else None
        sketches.append(LinkSketch(name, [i for _v, i in kept], com_index, spec.particle, spec.joint.type))
    ground: list[int] = []
    seen: list[sp.Matrix] = []
    for name, spec in links.items():
        j = spec.joint
        if j.parent == "ground" and j.type in GROUND_JOINTS:
            path = ("links", name, "joint", "origin")
            vec = builder.local_point("ground", j.origin, path) if isinstance(j.origin, str) else \
                doc.parse_vec(j.origin, path)
            if not any(_same(vec, v) for v in seen):
                seen.append(vec)
                ground.append(add(f"ground.joint({name})", vec))
    for p in doc.spec.ground.points:
        vec = builder.local_point("ground", p, ("ground", "points", p))
        if not any(_same(vec, v) for v in seen):
            seen.append(vec)
            ground.append(add(f"ground.{p}", vec))
    omegas = [kin.frames[n].omega_ground for n in links]
    return Geometry(labels, sp.Matrix.hstack(*columns) if columns else sp.zeros(3, 0),
                    sp.Matrix.hstack(*omegas) if omegas else sp.zeros(3, 0), sketches, ground)


def sample_indices(n: int, max_frames: int = MAX_FRAMES) -> np.ndarray:
    """At most ``max_frames`` evenly spread output rows, the first and last included."""
    if n <= max_frames:
        return np.arange(n)
    return np.unique(np.round(np.linspace(0, n - 1, max_frames)).astype(int))


def evaluate(model: MechanicalModel, geo: Geometry, t: np.ndarray, q: np.ndarray,
             u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World positions (frames, points, 3) and link angular velocities (frames, links, 3) at the given states."""
    from mechsys.numeric.parameters import parameter_values
    from mechsys.numeric.lambdify import compile_matrix

    p = parameter_values(model)
    pos = compile_matrix(geo.positions, model.t, model.q, model.u, model.parameter_symbols)
    omg = compile_matrix(geo.omegas, model.t, model.q, model.u, model.parameter_symbols)
    xyz = np.array([pos(ti, qi, ui, p).T for ti, qi, ui in zip(t, q, u)]).reshape(len(t), geo.positions.shape[1], 3)
    w = np.array([omg(ti, qi, ui, p).T for ti, qi, ui in zip(t, q, u)]).reshape(len(t), geo.omegas.shape[1], 3)
    return xyz, w


def plane_of_motion(xyz: np.ndarray, omega: np.ndarray) -> np.ndarray | None:
    """The unit normal of the plane the motion stays parallel to, or None for a motion in three dimensions.

    Planar means: every link turns about one fixed direction n (its angular velocity stays parallel to n) and no
    point moves along n. n is that direction; for a motion without rotation, the normal of the displacements
    (the ground z axis when it fits, so a pure translation in x-y is drawn in x-y)."""
    w = omega.reshape(-1, 3)
    d = (xyz - xyz[:1]).reshape(-1, 3)
    w_scale = float(np.max(np.linalg.norm(w, axis=1))) if len(w) else 0.0
    d_scale = max(float(np.max(np.ptp(xyz.reshape(-1, 3), axis=0))) if xyz.size else 0.0, 1e-300)
    if w_scale > 1e-12:
        n = w[int(np.argmax(np.linalg.norm(w, axis=1)))] / w_scale
        if np.max(np.linalg.norm(np.cross(w, n), axis=1)) > REL_TOL * w_scale:
            return None
    else:
        candidates = [np.eye(3)[k] for k in (2, 1, 0)]
        if len(d) and np.max(np.abs(d)) > 0:
            candidates.append(np.linalg.svd(d, full_matrices=False)[2][-1])
        fits = [c for c in candidates if not len(d) or np.max(np.abs(d @ c)) <= REL_TOL * d_scale]
        n = fits[0] if fits else candidates[-1]
    if len(d) and np.max(np.abs(d @ n)) > REL_TOL * d_scale:
        return None
    return n


def plane_basis(n: np.ndarray) -> tuple[np.ndarray, tuple[str, str]]:
    """Two in-plane unit vectors and their axis labels: the world axes seen from the positive side when n is
    along a world axis (x-y for z, z-x for y, y-z for x), else a basis right-handed with n."""
    for axis, ((i, a), (j, b)) in PLANE_AXES.items():
        k = "xyz".index(axis)
        if abs(abs(n[k]) - 1.0) <= REL_TOL:
            e1, e2 = np.eye(3)[i], np.eye(3)[j]
            return np.vstack([e1, e2]), (f"{a} [m]", f"{b} [m]")
    e1 = np.eye(3)[int(np.argmin(np.abs(n)))]
    e1 = e1 - (e1 @ n) * n
    e1 /= np.linalg.norm(e1)
    return np.vstack([e1, np.cross(n, e1)]), ("in-plane axis 1 [m]", "in-plane axis 2 [m]")


def animation_frames(model: MechanicalModel, result: SimulationResult, source: str | os.PathLike | None = None,
                     max_frames: int = MAX_FRAMES) -> Frames:
    """Sample a run, check that it is planar and project the drawn points onto its plane."""
    geo = geometry(model)
    if not geo.labels or not len(result.t):
        raise InputError(f"--animate: {model.name} has no links (or the run no output) to draw")
    rows = sample_indices(len(result.t), max_frames)
    t = np.asarray(result.t)[rows]
    xyz, w = evaluate(model, geo, t, np.asarray(result.q)[rows], np.asarray(result.u)[rows])
    n = plane_of_motion(xyz, w)
    if n is None:
        where = Path(source).name if source is not None else model.name
        raise InputError(f"--animate supports planar systems; {where} moves in three dimensions "
                         "(its links do not all turn about one fixed axis within one plane); write an .html file "
                         "for a 3-D view")
    basis, labels = plane_basis(n)
    return Frames(t, xyz @ basis.T, geo, labels)


def link_polyline(xy: np.ndarray, link: LinkSketch) -> np.ndarray:
    """The drawn segments of a link at one frame: (M, 2) with NaN rows between segments origin -> point."""
    origin = xy[link.points[0]]
    parts = []
    for i in link.points[1:]:
        parts += [origin, xy[i], np.array([np.nan, np.nan])]
    return np.array(parts) if parts else np.empty((0, 2))


def default_fps(t: np.ndarray) -> float:
    """Real time: one output interval of the sampled run per frame (10 frames per second for a single frame)."""
    span = float(t[-1] - t[0]) if len(t) > 1 else 0.0
    return (len(t) - 1) / span if span > 0 else 10.0


def gif_delay_ms(fps: float) -> int:
    """The GIF frame delay for a frame rate: a whole multiple of 10 ms (the format's unit), at least 20 ms
    (viewers slow shorter delays down to 100 ms) and at most 5 s."""
    return int(min(5000, max(20, 10 * round(100.0 / fps))))


def write_animation(model: MechanicalModel, result: SimulationResult, path: str | os.PathLike, fps: float | None = None,
                    source: str | os.PathLike | None = None, max_frames: int = MAX_FRAMES) -> int:
    """Write the animated GIF of a planar run atomically; returns the number of frames."""
    path = Path(path)
    check_animation_path(path, fps)
    frames = animation_frames(model, result, source, max_frames)
    _render(frames, path, fps or default_fps(frames.t), model.name)
    return len(frames.t)


def check_animation_path(path: str | os.PathLike, fps: float | None = None) -> None:
    """An animation is written as .gif, into a folder that exists, at a positive frame rate."""
    path = Path(path)
    if fps is not None and not (np.isfinite(fps) and fps > 0):
        raise InputError(f"--fps {fps}: must be a positive number")
    if path.suffix.lower() != ".gif":
        raise InputError(f"--animate {path}: write the animation as a .gif file")
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise InputError(f"--animate {path}: directory {directory} does not exist")


def _render(frames: Frames, path: Path, fps: float, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import PillowWriter

    from mechsys.report.files import atomic_write

    xy, geo = frames.xy, frames.geometry
    lo, hi = np.nanmin(xy.reshape(-1, 2), axis=0), np.nanmax(xy.reshape(-1, 2), axis=0)
    span = float(max(np.max(hi - lo), 1e-3))
    centre = (lo + hi) / 2
    half = 0.55 * span
    fig, ax = plt.subplots(figsize=(5, 5), dpi=80)
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_aspect("equal")
    ax.grid(True, alpha=0.3)
    ax.set_xlabel(frames.axis_labels[0])
    ax.set_ylabel(frames.axis_labels[1])
    ax.set_title(title)
    if geo.ground:
        g = xy[0, geo.ground]
        ax.plot(g[:, 0], g[:, 1], linestyle="none", marker="^", ms=11, color="0.45", zorder=1)
    artists = []
    for k, link in enumerate(geo.links):
        color = f"C{k % 10}"
        (line,) = ax.plot([], [], "-", lw=3, color=color, solid_capstyle="round", zorder=2)
        (joint,) = ax.plot([], [], linestyle="none", marker="s" if link.joint == "prismatic" else "o", ms=6,
                           mfc="white", mec="black", zorder=3)
        (com,) = ax.plot([], [], linestyle="none", marker="o", ms=9 if link.particle else 4, color="black"
                         if not link.particle else color, zorder=4)
        artists.append((link, line, joint, com))
    clock = ax.text(0.02, 0.96, "", transform=ax.transAxes, va="top")

    def update(k: int):
        out = []
        for link, line, joint, com in artists:
            seg = link_polyline(xy[k], link)
            line.set_data(seg[:, 0], seg[:, 1])
            o = xy[k, link.points[0]]
            joint.set_data([o[0]], [o[1]])
            if link.com is not None:
                c = xy[k, link.com]
                com.set_data([c[0]], [c[1]])
            out += [line, joint, com]
        clock.set_text(f"t = {frames.t[k]:.3f} s")
        return out + [clock]

    def write(tmp: str) -> None:
        gif = tmp + ".gif"  # Pillow picks the format from the file name
        writer = PillowWriter(fps=1000.0 / (gif_delay_ms(fps) + 0.5))  # the writer truncates 1000/fps to ms
        try:
            with writer.saving(fig, gif, dpi=fig.dpi):  # one draw per frame (FuncAnimation.save draws twice)
                for k in range(len(frames.t)):
                    update(k)
                    writer.grab_frame()
            os.replace(gif, tmp)
        finally:
            if os.path.exists(gif):
                os.unlink(gif)

    try:
        atomic_write(path, write)
    finally:
        plt.close(fig)
