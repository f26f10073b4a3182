"""Pictures and videos of a run: a PNG of one tick, an animated GIF or an MP4 of the whole run.

``render(trajectories, world, out, ...)`` picks the format from ``out``'s suffix
(``.png``: the final tick; ``.gif``, ``.mp4``: every ``every``-th tick and the last one).

Each frame shows the arena (its walls, or its floor rectangle dashed when it has none), the
floor's painted circles and rectangles (not a floor image), boxes
(with their yaw), cylinders, lights (a star, and a dotted circle where the foot-bot light sensor
still sees it: 2.5 × intensity m), every robot as a disc in its display LED colour (the beacon
when lit, else the first lit ring LED: ``composed_sim.world.robot_models.display_colors``;
``DEFAULT_COLOR`` when no LED is lit or no colours are given) with a black heading line, each
robot's trail over the last ``trail_ticks`` ticks (fading with age), and a caption with the tick
and the sim time. The view is fixed for the whole video: a square around the robots (at every
tick), walls, obstacles and lights; a PNG is drawn at 3× and averaged down (anti-aliased).

How it stays fast at 1280 robots × 600 ticks: matplotlib (Agg, headless) draws the static scene
and the axes once; per frame only the caption is redrawn (blitting), and the robots and trails
are rasterised with numpy into a copy of that image (each disc is a precomputed pixel stencil
placed at every robot at once; trails are alpha-blended points sampled along each tick's
segment). Encoding (``video_encoding.py``) through PyAV (FFmpeg; imageio's video plugin wraps
the same library but exposes no encoder options): MP4 as H.264 (x264 preset veryfast, crf 23, yuv420p); GIF by the GIF
encoder with one fixed 256-colour palette for the whole animation (taken from the first and the
last frame), streamed, so memory does not grow with the number of frames.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Callable, Optional

import numpy as np

from composed_sim.outputs.video_encoding import write_gif, write_mp4
from composed_sim.world.schema import World

SUFFIXES = (".png", ".gif", ".mp4")
DEFAULT_COLOR = (31, 119, 180)          # matplotlib's tab:blue: robots with every LED off
OUTLINE_COLOR = (34, 34, 34)
HEADING_COLOR = (0, 0, 0)
TRAIL_ALPHA = 0.45                      # opacity of the newest trail point; the oldest fades to 0
_SUPERSAMPLE_PNG = 3                    # a still picture is drawn at 3× and averaged down (anti-aliasing)


def render(trajectories: Any, world: World, out: str | Path, *, led_colors: Optional[np.ndarray] = None,
           fps: float = 10, size_px: int = 800, trail_ticks: int = 50, every: int = 1,
           tick_s: Optional[float] = None, title: Optional[str] = None,
           progress: Optional[Callable[[int], None]] = None) -> int:
    """Draw a run into ``out`` (.png, .gif or .mp4); returns the number of frames written.

    trajectories: anything with ``positions`` [T+1, n, 2] m and ``headings`` [T+1, n] rad
    (row t = tick t): ``hosts/tick_loop.Trajectories``, ``results.load_trajectories(...)``,
    ``recording.read_recording(...)``. led_colors: [T+1, n, 3] or [T+1, n, L, 3] uint8, or
    None. fps: video frame rate. size_px: the square frame's side (rounded up to even, as
    H.264 needs). trail_ticks: trail length in ticks (0: none). every: draw every k-th tick.
    tick_s: seconds per tick (default: the world's). title: the caption's first part (default:
    "<world name>: <n> robots"). progress: called with 1 after each frame.
    """
    out = Path(out)
    suffix = out.suffix.lower()
    if suffix not in SUFFIXES:
        raise ValueError(f"output must end in {', '.join(SUFFIXES)} (got {str(out)!r})")
    positions, headings, colors = _checked_inputs(trajectories, led_colors, size_px, fps,
                                                  trail_ticks, every)
    tick_s = world.tick_s if tick_s is None else float(tick_s)
    size_px += size_px % 2

    last = len(positions) - 1
    ticks = [last] if suffix == ".png" else list(range(0, last + 1, every))
    if ticks[-1] != last:
        ticks.append(last)
    n = positions.shape[1]
    title = f"{world.name}: {n} robot{'s' if n != 1 else ''}" if title is None else title
    scale = _SUPERSAMPLE_PNG if suffix == ".png" else 1
    out.parent.mkdir(parents=True, exist_ok=True)

    # Figure + FigureCanvasAgg directly: headless, and the caller's pyplot backend is untouched.
    canvas = _Canvas(world, positions, headings, colors, size_px, scale, trail_ticks, title,
                     _robot_radii(world, n))

    def frames():
        for t in ticks:
            frame = canvas.frame(t, f"tick {t}/{last}   {t * tick_s:.1f} s")
            if progress is not None:
                progress(1)
            yield frame

    if suffix == ".png":
        import imageio.v3 as iio
        iio.imwrite(out, next(frames()), extension=".png")
    elif suffix == ".mp4":
        write_mp4(out, frames(), fps)
    else:
        write_gif(out, frames(), fps, palette_from=[canvas.frame(ticks[0], "tick 0"),
                                                    canvas.frame(ticks[-1], "tick 0")])
    return len(ticks)


# --- inputs --------------------------------------------------------------------------

def _checked_inputs(trajectories: Any, led_colors: Optional[np.ndarray], size_px: int, fps: float,
                    trail_ticks: int, every: int) -> tuple[np.ndarray, np.ndarray, Optional[np.ndarray]]:
    """(positions, headings, display colours) of ``render``'s arguments, each checked with an
    error that names it."""
    positions = np.asarray(trajectories.positions, dtype=float)
    headings = np.asarray(trajectories.headings, dtype=float)
    if positions.ndim != 3 or positions.shape[2] != 2 or len(positions) == 0:
        raise ValueError(f"positions must be [T+1, n, 2] with T >= 0, got shape {positions.shape}")
    if headings.shape != positions.shape[:2]:
        raise ValueError(f"headings must be {list(positions.shape[:2])} like positions, "
                         f"got shape {headings.shape}")
    colors = _frame_colors(led_colors, positions.shape[:2])
    if not (isinstance(size_px, int) and 64 <= size_px <= 8192):
        raise ValueError(f"size_px must be a whole number of pixels in 64..8192 (got {size_px!r})")
    if not (isinstance(fps, (int, float)) and 0 < fps <= 1000):
        raise ValueError(f"fps must be in (0, 1000] (got {fps!r})")
    if not (isinstance(trail_ticks, int) and trail_ticks >= 0):
        raise ValueError(f"trail_ticks must be a whole number >= 0 (got {trail_ticks!r})")
    if not (isinstance(every, int) and every >= 1):
        raise ValueError(f"every must be a whole number >= 1 (got {every!r})")
    return positions, headings, colors


def _frame_colors(led_colors: Optional[np.ndarray], shape: tuple[int, int]) -> Optional[np.ndarray]:
    """[T+1, n, 3] uint8 display colours, or None."""
    if led_colors is None:
        return None
    from composed_sim.world.robot_models import display_colors
    c = np.asarray(led_colors)
    if c.shape[:2] != shape or c.shape[-1] != 3 or c.ndim not in (3, 4):
        raise ValueError(f"led_colors must be [{shape[0]}, {shape[1]}, 3] or "
                         f"[{shape[0]}, {shape[1]}, L, 3], got shape {c.shape}")
    if c.ndim == 4:
        c = np.stack([display_colors(frame) for frame in c])
    return c.astype(np.uint8, copy=False)


def _robot_radii(world: World, n: int) -> np.ndarray:
    """[n] body radius of each robot (m), from its group's model."""
    from composed_sim.world.robot_models import get_model
    if world.robot_count == n and world.robots:
        return np.array([get_model(world.robots[g].model).body_radius_m for g in world.group_of_robot()])
    model = world.robots[0].model if world.robots else "foot-bot"
    return np.full(n, get_model(model).body_radius_m)


# --- drawing -------------------------------------------------------------------------

class _Canvas:
    """The static scene drawn once by matplotlib; robots rasterised per frame with numpy.

    Pixels are addressed by flat index (row * width + column) into a buffer with one spare
    pixel at the end: anything outside the axes is sent there, so no per-point masking is
    needed in the per-frame paths.
    """

    def __init__(self, world: World, positions: np.ndarray, headings: np.ndarray,
                 colors: Optional[np.ndarray], size_px: int, scale: int, trail_ticks: int,
                 title: str, radii: np.ndarray):
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        self.scale, self.trail_ticks, self.colors = scale, trail_ticks, colors
        side = self.side = size_px * scale
        fig = Figure(figsize=(size_px / 100, size_px / 100), dpi=100 * scale, facecolor="white")
        self.agg = FigureCanvasAgg(fig)
        k = size_px / 800                                   # font sizes follow the frame size
        ax = fig.add_axes((0.09, 0.06, 0.88, 0.86))
        (x0, x1), (y0, y1) = _view(world, positions, radii)
        _draw_scene(ax, world, k)
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.set_aspect("equal", adjustable="box")
        ax.tick_params(labelsize=8 * k, length=3 * k, width=0.6 * k)
        ax.set_xlabel("x (m)", fontsize=9 * k, labelpad=2 * k)
        ax.set_ylabel("y (m)", fontsize=9 * k, labelpad=2 * k)
        ax.grid(True, color="0.88", lw=0.5 * k)
        ax.set_axisbelow(True)
        for spine in ax.spines.values():
            spine.set_linewidth(0.6 * k)
        fig.text(0.09, 0.955, title, fontsize=11 * k, ha="left", va="center")
        self.caption = fig.text(0.97, 0.955, "", fontsize=11 * k, ha="right", va="center",
                                family="monospace", animated=True)
        self.agg.draw()
        self.background = self.agg.copy_from_bbox(fig.bbox)
        self.fig = fig
        self.buf = np.empty((side * side + 1, 3), dtype=np.uint8)   # the frame + one spare pixel
        self.base = np.asarray(self.agg.buffer_rgba())[..., :3].reshape(-1, 3).copy()
        # data → pixel (column, row from the top), both axis-aligned and linear
        (ox, oy), (px1, py1) = ax.transData.transform([(0.0, 0.0), (1.0, 1.0)])
        sx, sy = px1 - ox, py1 - oy
        b = ax.bbox.extents                                 # display x0, y0, x1, y1
        self.clip = (int(math.ceil(b[0])) + 1, int(math.ceil(side - b[3])) + 1,
                     int(math.floor(b[2])) - 1, int(math.floor(side - b[1])) - 1)  # c0, r0, c1, r1
        self.band = max(0, self.clip[1] - 2)               # rows above the axes: the caption band
        self.cols = (ox + sx * positions[..., 0]).astype(np.float32)        # [T+1, n]
        self.rows = ((side - oy) - sy * positions[..., 1]).astype(np.float32)
        self.headings = headings
        self.valid = np.isfinite(self.cols) & np.isfinite(self.rows)
        self.cols[~self.valid] = -1.0                       # outside every clip box
        self.rows[~self.valid] = -1.0
        self.flat = self._flat(self.rows.astype(np.int32), self.cols.astype(np.int32))  # [T+1, n]
        # One pair of disc stencils (outline, fill) per distinct radius.
        r_px = np.maximum(radii * sx, 1.2 * scale)
        self.radius_px = r_px
        self.groups = [(np.flatnonzero(r_px == r), _disc(r),
                        _disc(r - 1.0 * scale) if r > 2.5 * scale else None)
                       for r in np.unique(r_px)]
        self.default = np.array(DEFAULT_COLOR, dtype=np.uint8)
        self.outline = np.array(OUTLINE_COLOR, dtype=np.uint8)

    def frame(self, t: int, caption: str) -> np.ndarray:
        """The picture at tick t → [size_px, size_px, 3] uint8 (a new array)."""
        buf = self.buf
        buf[:-1] = self.base
        img = buf[:-1].reshape(self.side, self.side, 3)
        if caption and self.band:       # redraw only the caption, copy only the band above the axes
            self.agg.restore_region(self.background)
            self.caption.set_text(caption)
            self.fig.draw_artist(self.caption)
            img[:self.band] = np.asarray(self.agg.buffer_rgba())[:self.band, :, :3]
        colors = self._colors(t)
        if self.trail_ticks and t > 0:
            self._trails(t, colors)
        self._bodies(img, t, colors)
        if self.scale > 1:
            s, side = self.scale, self.side // self.scale
            return (img.reshape(side, s, side, s, 3).sum(axis=(1, 3), dtype=np.uint32)
                    // (s * s)).astype(np.uint8)
        return img.copy()

    def _flat(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Flat pixel indices; the spare pixel for anything outside the axes."""
        c0, r0, c1, r1 = self.clip
        inside = (cols >= c0) & (cols < c1) & (rows >= r0) & (rows < r1)
        return np.where(inside, rows * self.side + cols, self.side * self.side).astype(np.int64)

    def _colors(self, t: int) -> np.ndarray:
        n = self.cols.shape[1]
        if self.colors is None:
            return np.broadcast_to(self.default, (n, 3))
        c = self.colors[t]
        return np.where((c != 0).any(axis=1, keepdims=True), c, self.default)

    def _trails(self, t: int, colors: np.ndarray) -> None:
        t0 = max(0, t - self.trail_ticks)
        k = t - t0
        # Samples per segment so that consecutive ones are < 1 output pixel apart (at most 16);
        # at 800 px a foot-bot moves well under a pixel per tick, so one (the segment's start).
        dc = np.diff(self.cols[t0:t + 1], axis=0)
        dr = np.diff(self.rows[t0:t + 1], axis=0)
        ok = self.valid[t0:t] & self.valid[t0 + 1:t + 1]
        longest = float(np.max(np.abs(dc) + np.abs(dr), where=ok, initial=0.0))
        samples = int(min(16, max(1, math.ceil(longest / (0.75 * self.scale)))))
        age = (t - (t0 + np.arange(k)))                     # [k] ticks behind the current one
        alpha = (TRAIL_ALPHA * (1.0 - (age - 1) / self.trail_ticks)).astype(np.float32)
        if samples == 1 and self.scale == 1:
            idx = self.flat[t0:t][:, None, :]               # [k, 1, n]
        else:
            f = (np.arange(samples, dtype=np.float32) / samples)[None, :, None]
            cols = self.cols[t0:t][:, None, :] + f * dc[:, None, :]   # [k, samples, n]
            rows = self.rows[t0:t][:, None, :] + f * dr[:, None, :]
            cols[~np.broadcast_to(ok[:, None, :], cols.shape)] = -1.0
            idx = self._flat(rows.astype(np.int32), cols.astype(np.int32))
        brush = [(r, c) for r in range(self.scale) for c in range(self.scale)]
        shift = np.array([r * self.side + c for r, c in brush])
        spare = self.side * self.side
        col = colors.astype(np.float32)[None, None, :, :]  # [1, 1, n, 3]
        a = alpha[:, None, None, None]                      # [k, 1, 1, 1], oldest first
        for d in shift:                                     # a 1-px line at the output size
            j = np.where(idx == spare, spare, idx + d) if d else idx
            under = self.buf[j].astype(np.float32)          # [k, samples, n, 3]
            self.buf[j] = (under + a * (col - under)).astype(np.uint8)

    def _bodies(self, img: np.ndarray, t: int, colors: np.ndarray) -> None:
        c0, r0, c1, r1 = self.clip
        ci = np.floor(self.cols[t]).astype(np.int32)
        ri = np.floor(self.rows[t]).astype(np.int32)
        for members, outline, fill in self.groups:
            cc, rr = ci[members], ri[members]
            if fill is None:          # too small for an outline: the disc in its colour only
                _stamp(img, rr, cc, outline, colors[members], self.clip)
            else:
                _stamp(img, rr, cc, outline, np.broadcast_to(self.outline, (len(members), 3)), self.clip)
                _stamp(img, rr, cc, fill, colors[members], self.clip)
        # Heading: a line from the centre to 1.3 radii ahead, so its tip shows past the rim.
        h = self.headings[t]
        length = 1.3 * self.radius_px                              # [n] px
        steps = int(math.ceil(length.max())) + 1
        f = np.linspace(0.0, 1.0, steps, dtype=np.float32)[None, :]
        lc = self.cols[t][:, None] + f * (length * np.cos(h))[:, None]
        lr = self.rows[t][:, None] - f * (length * np.sin(h))[:, None]
        lc[~self.valid[t]] = -1.0
        c, r = lc.astype(np.int32).ravel(), lr.astype(np.int32).ravel()
        for dr in range(self.scale):
            for dc in range(self.scale):
                cc, rr = c + dc - self.scale // 2, r + dr - self.scale // 2
                keep = (cc >= c0) & (cc < c1) & (rr >= r0) & (rr < r1)
                img[rr[keep], cc[keep]] = HEADING_COLOR


def _disc(radius_px: float) -> tuple[np.ndarray, np.ndarray]:
    """(row offsets, column offsets) of the pixels whose centres lie within the radius,
    around a centre at the middle of pixel (0, 0)."""
    r = int(math.ceil(radius_px))
    dr, dc = np.mgrid[-r:r + 1, -r:r + 1]
    inside = dr ** 2 + dc ** 2 <= radius_px ** 2
    return dr[inside].astype(np.int32), dc[inside].astype(np.int32)


def _stamp(img: np.ndarray, rows: np.ndarray, cols: np.ndarray, stencil, colors: np.ndarray,
           clip: tuple[int, int, int, int]) -> None:
    """Paint ``stencil`` at every (rows[i], cols[i]) in colors[i]; [n] centres, [n, 3] colours."""
    dr, dc = stencil
    r = rows[:, None] + dr[None, :]                                  # [n, m]
    c = cols[:, None] + dc[None, :]
    c0, r0, c1, r1 = clip
    keep = (c >= c0) & (c < c1) & (r >= r0) & (r < r1)
    img[r[keep], c[keep]] = np.broadcast_to(colors[:, None, :], r.shape + (3,))[keep]


def _view(world: World, positions: np.ndarray, radii: np.ndarray) -> tuple[tuple[float, float], tuple[float, float]]:
    """Square x and y limits around robots (at every tick), walls, obstacles and lights."""
    xs, ys = [], []
    finite = positions[np.isfinite(positions).all(axis=2)]           # [m, 2]
    if len(finite):
        r = float(radii.max()) if len(radii) else 0.0
        xs += [finite[:, 0].min() - r, finite[:, 0].max() + r]
        ys += [finite[:, 1].min() - r, finite[:, 1].max() + r]
    if world.arena.walls:        # an open arena's size only bounds the lights: not worth the room
        (cx, cy), (sx, sy) = world.arena.center, world.arena.size
        xs += [cx - sx / 2, cx + sx / 2]
        ys += [cy - sy / 2, cy + sy / 2]
    for ob in world.obstacles:
        reach = ob.radius_m if ob.type == "cylinder" else math.hypot(*ob.size) / 2
        xs += [ob.position[0] - reach, ob.position[0] + reach]
        ys += [ob.position[1] - reach, ob.position[1] + reach]
    for light in world.lights:
        xs += [light.position[0] - 0.3, light.position[0] + 0.3]
        ys += [light.position[1] - 0.3, light.position[1] + 0.3]
    if not xs:
        xs, ys = [-1.0, 1.0], [-1.0, 1.0]
    cx, cy = (min(xs) + max(xs)) / 2, (min(ys) + max(ys)) / 2
    half = max(max(xs) - min(xs), max(ys) - min(ys), 0.5) / 2 * 1.06
    return (cx - half, cx + half), (cy - half, cy + half)


def _draw_scene(ax, world: World, k: float) -> None:
    """Arena, walls, obstacles and lights as matplotlib artists (drawn once)."""
    from matplotlib.patches import Circle, Polygon, Rectangle

    # The floor's painted shapes, as the ground sensors see them (the nest and food of foraging,
    # the dark patch of aggregation), under everything else; the page's white is the floor colour.
    for shape in world.floor.shapes:
        color = np.array(shape.color) / 255.0
        if shape.type == "circle":
            ax.add_patch(Circle(shape.position, shape.radius_m, fc=color, ec="0.75", lw=0.4 * k, zorder=0))
        else:
            ax.add_patch(Polygon(_box_corners(shape), closed=True, fc=color, ec="0.75", lw=0.4 * k, zorder=0))
    if world.arena.size is not None and not world.arena.walls:
        (cx, cy), (sx, sy) = world.arena.center, world.arena.size
        ax.add_patch(Rectangle((cx - sx / 2, cy - sy / 2), sx, sy, fill=False, ls="--",
                               lw=0.8 * k, ec="0.55"))
    for wall in world.arena.wall_boxes():
        ax.add_patch(Polygon(_box_corners(wall), closed=True, fc="0.30", ec="none"))
    for ob in world.obstacles:
        if ob.type == "cylinder":
            ax.add_patch(Circle(ob.position, ob.radius_m, fc="0.55", ec="0.25", lw=0.6 * k))
        else:
            ax.add_patch(Polygon(_box_corners(ob), closed=True, fc="0.55", ec="0.25", lw=0.6 * k))
    for light in world.lights:
        color = np.array(light.color) / 255.0
        if light.intensity > 0:     # the foot-bot light sensor reads 0 beyond 2.5 × intensity
            ax.add_patch(Circle(light.position, 2.5 * light.intensity, fill=False, ls=":",
                                lw=0.8 * k, ec=color * 0.8))
        ax.plot(*light.position, marker="*", markersize=16 * k, color=color, mec="black",
                mew=0.6 * k)


def _box_corners(box) -> np.ndarray:
    """[4, 2] corners of a (yawed) box of the world file, in world coordinates."""
    from composed_sim.devices.common.geometry import box_corners
    return box_corners(box.position, box.size, box.yaw_rad)
