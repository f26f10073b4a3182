"""What a run leaves behind in its output directory.

summary.json     figures of the run (sizes, times per phase, real-time factor, violations count,
                 swarm metrics) plus what reproduces it (seed, versions)
world.yaml       the resolved world, loadable as is to re-run the same experiment
trajectories.npz positions [T+1, n, 2], headings [T+1, n], led_colors [T+1, n, 3] (each robot's
                 display colour), names [n], tick_s
violations.csv   tick, robot, reason for each watchdog or contract violation
arena.png        the arena: trails, final poses, lights, obstacles
"""
from __future__ import annotations

import csv
import json
import platform
import resource
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from composed_sim.hosts.lockstep import LoopResult, Trajectories
from composed_sim.world.loader import dump_world
from composed_sim.world.schema import World

SUMMARY = "summary.json"
TRAJECTORIES = "trajectories.npz"
VIOLATIONS = "violations.csv"
PICTURE = "arena.png"
WORLD = "world.yaml"


def versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for dist in ("composed_sim", "ros-jazzy-rclpy", "ros-rclpy", "ros-rmw-fastrtps-cpp", "numpy", "pymunk", "scipy"):
        try:
            out[dist] = version(dist)
        except PackageNotFoundError:
            pass
    return out


def peak_rss_mb() -> float:
    """Peak resident set of this process (Linux reports kB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def swarm_metrics(world: World, positions: np.ndarray) -> dict:
    """Flocking figures at the first and the last recorded tick. positions: [T+1, n, 2]."""
    def at(p: np.ndarray) -> dict:
        m: dict = {"centroid": [float(v) for v in p.mean(axis=0)]}
        if len(p) > 1:
            d, _ = cKDTree(p).query(p, k=2)
            m["mean_nearest_neighbour_m"] = float(d[:, 1].mean())
            m["min_pair_distance_m"] = float(d[:, 1].min())
        if world.lights:
            light = np.asarray(world.lights[0].position)
            m["centroid_to_light_m"] = float(np.linalg.norm(p.mean(axis=0) - light))
        return m
    if positions.shape[0] == 0 or positions.shape[1] == 0:
        return {}
    return {"initial": at(positions[0]), "final": at(positions[-1])}


def summarize(world: World, result: LoopResult, *, setup_s: float, mode: str, executor: str,
              phases: dict[str, float]) -> dict:
    t = result.trajectories
    sim_time_s = t.ticks_done * world.tick_s
    wall = result.times.ticks_wall_s
    return {
        "world": world.name,
        "mode": mode,
        "executor": executor,
        "robots": len(t.names),
        "ticks": t.ticks_done,
        "ticks_requested": world.length_ticks,
        "interrupted": result.interrupted,
        "seed": world.seed,
        "sim_time_s": sim_time_s,
        "setup_s": setup_s,
        "ticks_wall_s": wall,
        "real_time_factor": sim_time_s / wall if wall > 0 else None,
        "per_robot_tick_us": 1e6 * wall / (t.ticks_done * len(t.names)) if t.ticks_done and t.names else None,
        "phases_s": {**phases, "ros_exchange_s": result.times.ros_exchange_s},
        "violations": len(result.violations),
        "peak_rss_mb": peak_rss_mb(),
        "swarm": swarm_metrics(world, t.positions),
        "versions": versions(),
    }


def write_results(out_dir: Path, world: World, result: LoopResult, summary: dict,
                  picture: bool = True) -> None:
    """Write every file of a run; each file is complete on its own, the picture last."""
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / WORLD).write_text(dump_world(world))
    t = result.trajectories
    extra = {} if t.led_colors is None else {"led_colors": t.led_colors}
    np.savez_compressed(out_dir / TRAJECTORIES, positions=t.positions, headings=t.headings,
                        names=np.asarray(t.names), tick_s=world.tick_s, **extra)
    with open(out_dir / VIOLATIONS, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["tick", "robot", "reason"])
        w.writerows((v.tick, v.robot, v.reason) for v in result.violations)
    (out_dir / SUMMARY).write_text(json.dumps(summary, indent=2) + "\n")
    if picture:
        render_arena(world, t, out_dir / PICTURE)


def load_trajectories(path: Path) -> Trajectories:
    with np.load(path) as data:
        positions = data["positions"]
        leds = data["led_colors"] if "led_colors" in data else None
        return Trajectories(list(data["names"]), positions, data["headings"], len(positions) - 1, leds)


def render_arena(world: World, t: Trajectories, path: Path) -> None:
    """A top view: each robot's trail faded, its final pose as a disc with a heading tick."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection, PatchCollection
    from matplotlib.patches import Circle, Polygon

    from composed_sim.core.robot_models import get_model

    radius = get_model(world.robots[0].model).body_radius_m if world.robots else 0.085
    pos, head = t.positions, t.headings
    fig, ax = plt.subplots(figsize=(8, 8), dpi=120)
    if pos.shape[1]:
        # Trails: at most ~200 points per robot keeps big swarms quick to draw.
        stride = max(1, len(pos) // 200)
        trails = np.transpose(pos[::stride], (1, 0, 2))          # [n, T', 2]
        ax.add_collection(LineCollection(trails, colors="tab:blue", alpha=0.25, linewidths=0.6))
        final, yaw = pos[-1], head[-1]
        ax.add_collection(PatchCollection([Circle(p, radius) for p in final], facecolor="tab:red",
                                          edgecolor="black", linewidths=0.3))
        tips = final + 2 * radius * np.stack([np.cos(yaw), np.sin(yaw)], axis=1)
        ax.add_collection(LineCollection(np.stack([final, tips], axis=1), colors="black", linewidths=0.6))
        ax.plot(*pos[0].T, ".", color="grey", markersize=1.5, label="start")
    for light in world.lights:
        ax.plot(*light.position, marker="*", markersize=18, color="gold", markeredgecolor="black",
                label=f"light (intensity {light.intensity:g})")
    for ob in world.obstacles:
        if ob.type == "cylinder":
            ax.add_patch(Circle(ob.position, ob.radius_m, color="dimgrey"))
        else:
            c, s = np.cos(ob.yaw_rad), np.sin(ob.yaw_rad)
            hx, hy = ob.size[0] / 2, ob.size[1] / 2
            corners = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]]) @ np.array([[c, s], [-s, c]])
            ax.add_patch(Polygon(corners + ob.position, color="dimgrey"))
    if world.arena.walls and world.arena.size:
        (cx, cy), (sx, sy) = world.arena.center, world.arena.size
        ax.add_patch(plt.Rectangle((cx - sx / 2, cy - sy / 2), sx, sy, fill=False, lw=2, color="black"))
    # A square view around everything drawn, with a margin: tall or wide swarms stay readable.
    ax.set_aspect("equal")
    ax.autoscale_view()
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    half = max(x1 - x0, y1 - y0) / 2 * 1.08
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    ax.set_xlim(cx - half, cx + half)
    ax.set_ylim(cy - half, cy + half)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"{world.name}: {pos.shape[1]} robots, tick {t.ticks_done} "
                 f"({t.ticks_done * world.tick_s:.1f} s sim time)")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
