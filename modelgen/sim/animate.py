"""See the motion: a simulation as an animated GIF or MP4 and a self-contained 3D HTML viewer.

Input: a :class:`~modelgen.sim.result.Result`, the
:class:`~modelgen.model.spec.ModelSpec` it was run on (a scene's reduced
model, ``scene.spec.model``) and, optionally, its
:class:`~modelgen.sim.runtime.CompiledModel`.  Output: a :class:`Motion`
(plain data: the frames' times, every point's position, every body's pose)
and the files drawn from it.

What is drawn, per frame:

* each body's frame: three short axes at its centre of mass G, x red, y green,
  z blue (from ``CompiledModel.body_poses``, the C, when a compiled model is
  given; else from the symbolic kinematics);
* the model's points as a stick figure along the tree: each point joined to
  the point it is defined ``from`` (absolute points, ``from O`` in base ``E``,
  are drawn as dots only);
* the trace of chosen points (default: the moving points at the ends of the
  longest branches of the point tree).

Point positions are not computed by the C: they are the symbolic positions of
:func:`modelgen.derive.kinematics.derive_kinematics`, expanded and turned
into one numpy function of (q, p) per model.

The view is chosen from the motion: a motion in a plane (or along a line) is
drawn in that plane, "up" against gravity; a 3D motion in an isometric view.
Playback is real time (``speed=1``) with at most ``max_frames`` frames.

``Result`` stays free of model knowledge: the model comes as an argument, or
through :meth:`modelgen.sim.scene.Scene.animate`.

>>> scene = modelgen.load_scene("models/scenes/dp_free.yaml")     # doctest: +SKIP
>>> res = scene.run()                                             # doctest: +SKIP
>>> animate(res, scene.spec.model, "dp_free.gif", compiled=scene.model)   # doctest: +SKIP
>>> write_html(motion(res, scene.spec.model, compiled=scene.model), "dp_free.html")  # doctest: +SKIP
"""
from __future__ import annotations

import functools
import json
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence

import jinja2
import numpy as np
import sympy
from markupsafe import Markup

from modelgen.derive.kinematics import derive_kinematics
from modelgen.errors import ArgumentTypeError, ModelError, ModelgenError, TemplateError
from modelgen.model.spec import CANONICAL_BASE, CANONICAL_POINT, ModelSpec, symbol
from modelgen.sim.result import replacing
from modelgen.version import __version__

#: default cap on the number of frames of an animation
MAX_FRAMES = 200
#: frames per second aimed at (fewer when max_frames caps a long run)
FPS = 25.0
#: body frame axes' colours: x, y, z
AXIS_COLOURS = ("#d62728", "#2ca02c", "#1f77b4")
#: length of a body frame's axes, as a fraction of the motion's extent
AXIS_FRACTION = 0.1
#: relative spread below which a direction of the motion counts as flat
FLAT = 1e-9


@dataclass(frozen=True)
class Motion:
    """What an animation draws: plain data, one row per frame.

    ``positions`` (n_frames, n_points, 3) in E, ``poses`` (n_frames, n_bodies,
    4, 4) as ``CompiledModel.body_poses``; ``segments`` are index pairs into
    ``points`` (parent, child); ``trace`` indices of traced points;
    ``view`` is the camera basis (right, up, toward the viewer), rows in E,
    and ``planar`` says whether the motion lies in the view's plane.
    ``interval`` is the real-time duration of one frame [s] at ``speed``.
    """
    name: str
    t: np.ndarray
    points: tuple
    segments: tuple
    positions: np.ndarray
    bodies: tuple
    poses: np.ndarray
    trace: tuple
    view: np.ndarray
    planar: bool
    axis_length: float
    interval: float
    speed: float

    @property
    def n_frames(self) -> int:
        return len(self.t)


# -- positions of the points ---------------------------------------------------------

@functools.lru_cache(maxsize=16)
def point_function(spec: ModelSpec):
    """``f(q, p) -> (n_points, 3)`` (or ``(n_frames, n_points, 3)`` for ``q`` of
    shape (n_frames, n)): the position in E of ``O`` and of every point of the
    model, in the order ``("O", *spec points)``; ``p`` the parameter vector in
    declaration order.  One numpy function per model (lambdified once).

    >>> from modelgen.model.api import load_model                     # doctest: +SKIP
    >>> f = point_function(load_model("models/double_pendulum.yaml"))  # doctest: +SKIP
    >>> f([0.0, 0.0], [1, 1, 1, 1, 9.81])[1]        # P1 at (l1, 0, 0)    # doctest: +SKIP
    """
    kin = derive_kinematics(spec)
    names = (CANONICAL_POINT, *(p.name for p in spec.points))
    exprs = [kin.graph.expand(c) for name in names for c in kin.points[name].r]
    return _lambdify(spec, exprs, (len(names), 3))


@functools.lru_cache(maxsize=16)
def pose_function(spec: ModelSpec):
    """``f(q, p) -> (n_bodies, 4, 4)``: the bodies' poses from the symbolic
    kinematics (the same layout as ``CompiledModel.body_poses``)."""
    kin = derive_kinematics(spec)
    exprs = []
    for b in spec.bodies:
        R, r = kin.bases[b.base].R, kin.points[b.G].r
        for i in range(3):
            exprs += [kin.graph.expand(R[i][j]) for j in range(3)] + [kin.graph.expand(r[i])]
        exprs += [0, 0, 0, 1]
    return _lambdify(spec, exprs, (len(spec.bodies), 4, 4))


def _lambdify(spec: ModelSpec, exprs: list, shape: tuple):
    q = [symbol(c) for c in spec.coordinates]
    p = [symbol(name) for name in spec.parameter_names]
    exprs = [sympy.sympify(e) for e in exprs]
    extra = set().union(*(e.free_symbols for e in exprs)) - set(q) - set(p)
    if extra:
        raise ModelgenError(f"model {spec.name}: positions depend on "
                            f"{', '.join(sorted(map(str, extra)))}, which are neither "
                            f"coordinates nor parameters; they cannot be animated")
    f = sympy.lambdify([q, p], exprs, modules="numpy", cse=True)

    def evaluate(qv, pv):
        qv = np.asarray(qv, dtype=float)
        frames = qv.shape[:-1]
        values = f(np.moveaxis(qv, -1, 0), np.asarray(pv, dtype=float))
        out = np.stack([np.broadcast_to(np.asarray(v, dtype=float), frames) for v in values],
                       axis=-1)
        return out.reshape(frames + shape)
    return evaluate


# -- what to draw --------------------------------------------------------------------

def frame_indices(t: np.ndarray, *, max_frames: int = MAX_FRAMES, fps: float = FPS,
                  speed: float = 1.0) -> np.ndarray:
    """Indices of the samples shown: about ``fps`` frames per second of playback at
    ``speed`` times real time, at most ``max_frames``, never more than the samples.

    >>> frame_indices(np.linspace(0, 10, 1001)).size     # 10 s at 25 fps > 200
    200
    >>> frame_indices(np.linspace(0, 1, 101)).tolist()[:3]
    [0, 4, 8]
    """
    t = np.asarray(t, dtype=float)
    if max_frames < 2 or not fps > 0 or not speed > 0:
        raise ModelgenError(f"animation: max_frames must be >= 2 and fps, speed > 0; got "
                            f"{max_frames}, {fps}, {speed}")
    if len(t) < 2 or not t[-1] > t[0]:
        return np.arange(len(t))
    wanted = int(np.ceil((t[-1] - t[0]) * fps / speed)) + 1
    count = max(2, min(max_frames, wanted, len(t)))
    times = np.linspace(t[0], t[-1], count)
    idx = np.clip(np.searchsorted(t, times), 1, len(t) - 1)
    idx -= (times - t[idx - 1]) < (t[idx] - times)         # the nearest sample
    return np.unique(idx)


def default_trace(spec: ModelSpec, moving: Sequence[bool]) -> tuple:
    """Points traced by default: the moving leaves of the point tree of greatest depth
    (the double pendulum's G2, the arm's flange, each mass of a spring chain)."""
    parents = {p.name: p.parent for p in spec.points}
    names = [p.name for p in spec.points]
    depth = {CANONICAL_POINT: 0}
    for p in spec.points:                       # parents first
        depth[p.name] = depth[p.parent] + 1
    leaves = [n for n, m in zip(names, moving) if m and n not in parents.values()]
    if not leaves:
        return ()
    deepest = max(depth[n] for n in leaves)
    return tuple(n for n in leaves if depth[n] == deepest)


def choose_view(positions: np.ndarray, up: np.ndarray) -> tuple:
    """Camera basis rows (right, up, toward the viewer) in E, and whether the motion
    is planar: a motion in a plane (or along a line) is seen face on with ``up`` as
    vertical as the plane allows; otherwise an isometric view with ``up`` vertical."""
    pts = positions.reshape(-1, 3)
    centred = pts - pts.mean(axis=0)
    _, s, vt = np.linalg.svd(centred, full_matrices=True)
    s = np.concatenate([s, np.zeros(3 - len(s))])
    scale = max(s[0], 1e-300)
    up = up / np.linalg.norm(up)
    if s[1] <= FLAT * scale:                       # a line (or a point)
        toward = np.cross(vt[0], up) if s[0] > 0 else np.zeros(3)
        if np.linalg.norm(toward) < 1e-6:
            toward = _perpendicular(up)
        return _basis(toward, up), True
    if s[2] <= FLAT * scale:                       # a plane
        toward = vt[2] * (1.0 if vt[2].sum() >= 0 else -1.0)
        return _basis(toward, up), True
    h1 = _perpendicular(up)
    h2 = np.cross(up, h1)
    return _basis(h1 + h2 + up, up), False


def _perpendicular(v: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to ``v``: the E axis least aligned with it, made
    perpendicular."""
    e = np.eye(3)[int(np.argmin(np.abs(v)))]
    w = e - v * np.dot(e, v) / np.dot(v, v)
    return w / np.linalg.norm(w)


def _basis(toward: np.ndarray, up: np.ndarray) -> np.ndarray:
    toward = toward / np.linalg.norm(toward)
    screen_up = up - toward * np.dot(up, toward)
    if np.linalg.norm(screen_up) < 1e-6:           # looking along up: any vertical
        screen_up = _perpendicular(toward)
    screen_up /= np.linalg.norm(screen_up)
    right = np.cross(screen_up, toward)
    return np.array([right, screen_up, toward])


def motion(result, spec: ModelSpec, *, compiled=None, p=None, trace: Optional[Sequence] = None,
           max_frames: int = MAX_FRAMES, fps: float = FPS, speed: float = 1.0) -> Motion:
    """The :class:`Motion` of a run of ``spec`` (a scene's reduced model, ``scene.spec.model``).

    ``compiled`` (the CompiledModel) gives the bodies' poses from the C;
    ``p`` the parameters of the run (a mapping of overrides or a full vector;
    default the model's); ``trace`` names the points to trace (default
    :func:`default_trace`).

    >>> m = motion(res, scene.spec.model, compiled=scene.model)   # doctest: +SKIP
    >>> m.positions.shape                # (frames, points incl. O, 3)  # doctest: +SKIP
    """
    n = spec.nq
    if not (hasattr(result, "t") and hasattr(result, "y")):
        raise ArgumentTypeError(f"animation: the result must be the Result of a run (with t "
                                f"and y), got {type(result).__name__}")
    if result.y.shape[0] < n:
        raise ModelgenError(f"animation: the result has {result.y.shape[0]} states, "
                            f"model {spec.name} has {n} coordinates")
    pv = _parameters(spec, p)
    idx = frame_indices(result.t, max_frames=max_frames, fps=fps, speed=speed)
    t = np.asarray(result.t, dtype=float)[idx]
    q = np.asarray(result.y, dtype=float)[:n, idx].T                   # (frames, n)
    names = (CANONICAL_POINT, *(pt.name for pt in spec.points))
    positions = point_function(spec)(q, pv)
    if compiled is not None:
        poses = np.array([compiled.body_poses(qi, pv) for qi in q]).reshape(
            len(t), len(spec.bodies), 4, 4)
    else:
        poses = pose_function(spec)(q, pv)
    moving = np.ptp(positions, axis=0).max(axis=1) > 0 if len(t) else np.zeros(len(names), bool)
    if trace is None:
        traced = default_trace(spec, moving[1:])
    else:
        traced = tuple(trace)
        for name in traced:
            if name not in names:
                raise ModelError(f"unknown point {name!r} to trace", key="trace",
                                 fix=f"use one of {', '.join(names)}")
    segments = tuple((names.index(pt.parent), i + 1) for i, pt in enumerate(spec.points)
                     if not (pt.parent == CANONICAL_POINT and pt.base == CANONICAL_BASE))
    every = np.concatenate([positions.reshape(-1, 3), poses[:, :, :3, 3].reshape(-1, 3)])
    extent = float(np.max(np.ptp(every, axis=0))) if len(every) else 0.0
    extent = extent if extent > 0 else 1.0
    up = -_gravity(spec, pv) if spec.gravity is not None else np.array([0.0, 0.0, 1.0])
    if not np.linalg.norm(up) > 0:
        up = np.array([0.0, 0.0, 1.0])
    view, planar = choose_view(every, up)
    interval = float((t[-1] - t[0]) / (len(t) - 1) / speed) if len(t) > 1 else 1.0 / fps
    return Motion(spec.name, t, names, segments, positions, tuple(b.name for b in spec.bodies),
                  poses, tuple(names.index(n) for n in traced), view, planar,
                  AXIS_FRACTION * extent, interval, float(speed))


def _parameters(spec: ModelSpec, p) -> np.ndarray:
    values = np.array(spec.parameter_defaults, dtype=float)
    if p is None:
        return values
    if isinstance(p, dict):
        for name, value in p.items():
            if name not in spec.parameter_names:
                raise ModelgenError(f"animation: unknown parameter {name!r}; parameters are "
                                    f"{', '.join(spec.parameter_names) or 'none'}")
            values[spec.parameter_names.index(name)] = float(value)
        return values
    values = np.asarray(p, dtype=float).reshape(-1)
    if len(values) != len(spec.parameters):
        raise ModelgenError(f"animation: p has {len(values)} values, model {spec.name} has "
                            f"{len(spec.parameters)} parameters")
    return values


def _gravity(spec: ModelSpec, pv: np.ndarray) -> np.ndarray:
    subs = {symbol(name): v for name, v in zip(spec.parameter_names, pv)}
    return np.array([float(sympy.sympify(c).subs(subs)) for c in spec.gravity])


# -- GIF and MP4 ---------------------------------------------------------------------

def animate(result, spec: ModelSpec, path, *, compiled=None, p=None, trace=None,
            max_frames: int = MAX_FRAMES, fps: float = FPS, speed: float = 1.0) -> Path:
    """Write the animation of a run to ``path``: ``.gif`` (Pillow), ``.mp4`` (ffmpeg)
    or ``.html`` (the 3D viewer of :func:`write_html`).

    The arguments are those of :func:`motion`.  Figures are built on
    ``matplotlib.figure.Figure`` with the Agg canvas: pyplot's state and
    backend are never touched.

    >>> animate(res, scene.spec.model, "out/dp_free.gif", compiled=scene.model)  # doctest: +SKIP
    PosixPath('out/dp_free.gif')
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".gif", ".mp4", ".html"):
        raise ModelgenError(f"animation {path}: the file must end in .gif, .mp4 or .html")
    m = motion(result, spec, compiled=compiled, p=p, trace=trace, max_frames=max_frames,
               fps=fps, speed=speed)
    return write_html(m, path) if suffix == ".html" else write_movie(m, path)


def animate_files(result, spec: ModelSpec, stem, *, movie: str = "gif", **options) -> tuple:
    """Write ``<stem>.gif`` (or ``.mp4``) and ``<stem>.html`` from one :class:`Motion`;
    ``options`` are those of :func:`motion`.  Returns the two paths.

    >>> animate_files(res, scene.spec.model, "out/dp_free", compiled=scene.model)  # doctest: +SKIP
    (PosixPath('out/dp_free.gif'), PosixPath('out/dp_free.html'))
    """
    if movie not in ("gif", "mp4"):
        raise ModelgenError(f"animation format {movie!r}: use gif or mp4")
    stem = Path(stem)
    m = motion(result, spec, **options)
    movie_path = stem.with_name(f"{stem.name}.{movie}")
    write_movie(m, movie_path)
    return movie_path, write_html(m, stem.with_name(f"{stem.name}.html"))


def write_movie(m: Motion, path, *, dpi: int = 80) -> Path:
    """Render a :class:`Motion` frame by frame into a GIF (Pillow, one shared
    64-colour palette) or an MP4 (matplotlib's ``FFMpegWriter``)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    path = Path(path)
    mp4 = path.suffix.lower() == ".mp4"
    if mp4 and shutil.which("ffmpeg") is None:
        raise ModelgenError(f"animation {path}: writing MP4 needs ffmpeg on PATH; fix: "
                            f"install ffmpeg or write a .gif")
    _make_parent(path)
    fig = Figure(figsize=(5, 5), dpi=dpi)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_axes((0.02, 0.02, 0.96, 0.9))
    draw = _Drawing(m, ax)
    title = fig.suptitle("", fontsize=10)

    def frames():
        for k in range(m.n_frames):
            draw.frame(k)
            title.set_text(f"{m.name}    t = {m.t[k]:.3f} s")
            yield k
    fps = 1.0 / m.interval if m.interval > 0 else FPS
    if mp4:
        from matplotlib.animation import FFMpegWriter
        writer = FFMpegWriter(fps=fps, codec="libx264", extra_args=["-pix_fmt", "yuv420p"])
        # the file appears only once complete: an interrupt leaves no cut movie
        with replacing(path) as part, writer.saving(fig, str(part), dpi):
            for _ in frames():
                writer.grab_frame()
        return path
    from PIL import Image
    images = []
    for _ in frames():
        canvas.draw()
        images.append(Image.fromarray(np.asarray(canvas.buffer_rgba())[:, :, :3]))
    # one palette from the first, middle and last frames: fast, and no flicker
    strip = Image.new("RGB", (images[0].width, 3 * images[0].height))
    for i, k in enumerate((0, len(images) // 2, len(images) - 1)):
        strip.paste(images[k], (0, i * images[0].height))
    palette = strip.quantize(64, dither=Image.Dither.NONE)
    frames_p = [im.quantize(palette=palette, dither=Image.Dither.NONE) for im in images]
    with replacing(path) as part:
        frames_p[0].save(part, save_all=True, append_images=frames_p[1:], loop=0,
                         duration=max(20, int(round(1000 * m.interval))), optimize=False)
    return path


class _Drawing:
    """The artists of one axes, updated frame by frame (2D projection by ``m.view``)."""

    def __init__(self, m: Motion, ax):
        self.m = m
        V = m.view[:2]
        self.xy = m.positions @ V.T                                   # (frames, points, 2)
        G = m.poses[:, :, :3, 3]
        tips = G[:, :, None, :] + m.axis_length * np.swapaxes(m.poses[:, :, :3, :3], 2, 3)
        self.G = G @ V.T                                              # (frames, bodies, 2)
        self.tips = tips @ V.T                                        # (frames, bodies, 3, 2)
        every = np.concatenate([self.xy.reshape(-1, 2), self.tips.reshape(-1, 2),
                                self.G.reshape(-1, 2)])
        lo, hi = every.min(axis=0), every.max(axis=0)
        centre, half = (lo + hi) / 2, max(float(np.max(hi - lo)) / 2 * 1.08, 1e-9)
        ax.set_xlim(centre[0] - half, centre[0] + half)
        ax.set_ylim(centre[1] - half, centre[1] + half)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.text(0.01, 0.01, "planar view" if m.planar else "isometric view",
                transform=ax.transAxes, fontsize=7, color="0.5")
        self.traces = [ax.plot([], [], lw=1, color="tab:purple", alpha=0.6)[0]
                       for _ in m.trace]
        self.sticks = [ax.plot([], [], lw=2.5, color="0.25", solid_capstyle="round")[0]
                       for _ in m.segments]
        self.axes = [[ax.plot([], [], lw=1.5, color=c)[0] for c in AXIS_COLOURS]
                     for _ in m.bodies]
        self.dots = ax.plot([], [], "o", ms=4, color="k")[0]

    def frame(self, k: int) -> None:
        m, xy = self.m, self.xy
        for line, i in zip(self.traces, m.trace):
            line.set_data(xy[: k + 1, i, 0], xy[: k + 1, i, 1])
        for line, (i, j) in zip(self.sticks, m.segments):
            line.set_data(xy[k, [i, j], 0], xy[k, [i, j], 1])
        for b, lines in enumerate(self.axes):
            for a, line in enumerate(lines):
                line.set_data([self.G[k, b, 0], self.tips[k, b, a, 0]],
                              [self.G[k, b, 1], self.tips[k, b, a, 1]])
        self.dots.set_data(xy[k, :, 0], xy[k, :, 1])


# -- the HTML viewer -----------------------------------------------------------------

@functools.lru_cache(maxsize=None)
def _environment() -> jinja2.Environment:
    return jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(Path(__file__).resolve().parent / "templates")),
        trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True,
        undefined=jinja2.StrictUndefined, autoescape=True)


def script_json(value) -> Markup:
    """JSON safe inside ``<script>``: ``<``, ``>``, ``&`` and the JS line separators
    are written as ``\\uXXXX`` escapes, so no string can close the script element.

    >>> str(script_json({"name": "</script><script>alert(1)</script>"}))
    '{"name": "\\\\u003c/script\\\\u003e\\\\u003cscript\\\\u003ealert(1)\\\\u003c/script\\\\u003e"}'
    """
    text = json.dumps(value, allow_nan=False)
    for char, escape in (("<", "\\u003c"), (">", "\\u003e"), ("&", "\\u0026"),
                         ("\u2028", "\\u2028"), ("\u2029", "\\u2029")):
        text = text.replace(char, escape)
    return Markup(text)


def viewer_data(m: Motion) -> dict:
    """The JSON the viewer plays: rounded to 6 significant digits of the motion's size."""
    digits = max(0, 5 - int(np.floor(np.log10(m.axis_length / AXIS_FRACTION))))

    def r(a):
        return np.round(np.nan_to_num(a), digits).tolist()
    return {"name": m.name, "t": r(m.t), "points": list(m.points),
            "segments": [list(s) for s in m.segments], "positions": r(m.positions),
            "bodies": list(m.bodies),
            "origins": r(m.poses[:, :, :3, 3]),
            "axes": r(np.swapaxes(m.poses[:, :, :3, :3], 2, 3)),   # rows: the x, y, z axes
            "trace": list(m.trace), "view": r(m.view), "planar": m.planar,
            "axis_length": m.axis_length, "interval": m.interval, "speed": m.speed,
            "colours": list(AXIS_COLOURS)}


def _make_parent(path: Path) -> None:
    """Create the directory of ``path`` (with its parents), or say why it cannot be."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        what = "is under a file, not a directory" if isinstance(
            exc, (FileExistsError, NotADirectoryError)) \
            else f"cannot be created ({exc.strerror or exc})"
        raise ModelgenError(f"animation {path}: its directory {path.parent} {what}; fix: "
                            f"choose a path in a writable directory") from None


def write_html(m: Motion, path) -> Path:
    """Write the self-contained 3D viewer of a :class:`Motion`: one HTML file, no
    network access at view time (data as JSON, a small canvas renderer inline).

    Drag to rotate, wheel to zoom, space or the button to play/pause, the slider
    to scrub.

    >>> write_html(motion(res, scene.spec.model), "dp_free.html")   # doctest: +SKIP
    """
    path = Path(path)
    try:
        text = _environment().get_template("viewer.html.j2").render(
            name=m.name, version=__version__, data=script_json(viewer_data(m)))
    except jinja2.TemplateError as exc:
        raise TemplateError(f"template viewer.html.j2 failed: {exc}") from exc
    _make_parent(path)
    with replacing(path) as part:
        part.write_text(text, encoding="utf-8")
    return path
