"""What a run leaves behind in its output directory.

summary.json     figures of the run (sizes, times per phase, real-time factor, violations count,
                 the loop functions' first and final metrics) plus what reproduces it (seed, versions)
metrics.csv      the loop functions' metrics, one row per tick they were taken (only with loop functions)
world.yaml       the resolved world, loadable as is to re-run the same experiment
trajectories.npz positions [T+1, n, 2], headings [T+1, n], led_colors [T+1, n, 3] (each robot's
                 display colour), names [n], tick_s; with drones also altitudes [T+1, n] (m)
trajectories/    the same arrays as .npy files while the run goes, and after it was killed
                 (outputs/stream.py): appended each tick, whole up to the last checkpoint;
                 packed into trajectories.npz when the run ends
violations.csv   tick, robot, reason for each watchdog or contract violation
near_misses.csv  tick, first, second, distance_m: each approach of two drones (with drones only)
arena.png        the arena: whole-run trails, final poses with LED colours, lights, obstacles (outputs/render.py)
"""
from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import platform
import resource
import shutil
import zipfile
from collections import Counter
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Optional

import numpy as np

from composed_sim.core.violations import FAILED
from composed_sim.hosts.tick_loop import LoopResult, Trajectories
from composed_sim.world.loader import dump_world
from composed_sim.world.schema import World

SUMMARY = "summary.json"
TRAJECTORIES = "trajectories.npz"
VIOLATIONS = "violations.csv"
METRICS = "metrics.csv"
PICTURE = "arena.png"
WORLD = "world.yaml"
NEAR_MISSES = "near_misses.csv"


def versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for dist in ("composed_sim", "ros-jazzy-rclpy", "ros-rclpy", "ros-rmw-fastrtps-cpp", "ros-fastrtps",
                 "numpy", "pymunk", "scipy"):
        try:
            out[dist] = version(dist)
        except PackageNotFoundError:
            pass
    return out


def peak_rss_mb() -> float:
    """Peak resident set of this process (Linux reports kB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


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
        "phases_per_tick_ms": phase_table(result.times, t.ticks_done),
        # CPU per tick: this process's (its serial part, without waiting for a core) and all of the run's.
        "main_process_cpu_per_tick_ms": round(1e3 * result.times.main_cpu_s / t.ticks_done, 3) if t.ticks_done else None,
        "cpu_per_tick_ms": round(1e3 * result.times.cpu_s / t.ticks_done, 3) if t.ticks_done else None,
        **host_cost(result.times, t.ticks_done * len(t.names), in_host=mode == "composed"),
        "violations": len(result.violations),
        "violations_by_robot": dict(Counter(v.robot for v in result.violations).most_common()),
        "failed_robots": sorted({v.robot for v in result.violations if v.reason.startswith(FAILED)},
                                key=t.names.index),
        "peak_rss_mb": peak_rss_mb(),
        "rss_mb_by_tick": [[tick, round(mb, 1)] for tick, mb in result.memory],
        "ended_by_loop_functions": result.finished,     # is_finished ended the run before its length
        # Deprecated, kept for old readers until the next release: the same as the above, though it
        # read as "the run did not finish" when false (docs/experiments.md).
        "finished": result.finished,
        "metrics": {"initial": result.metrics[0], "final": result.metrics[-1]} if result.metrics else {},
        "versions": versions(),
    }


def phase_table(times, ticks: int) -> dict[str, float]:
    """The main process's wall time per tick, by phase (hosts/tick_loop.py's PHASES), in ms;
    ``serial``: all but ``waiting``, the part that more cores do not share."""
    if not ticks:
        return {}
    table = {phase: round(1e3 * s / ticks, 3) for phase, s in times.phases_s.items()}
    table["serial"] = round(sum(v for k, v in table.items() if k != "waiting"), 3)
    return table


def host_cost(times, robot_ticks: int, *, in_host: bool) -> dict[str, Optional[float]]:
    """Per robot-tick: the nodes' own code, and everything else the run's processes spent CPU on
    (the host's cost). Only where the host runs every node (composed mode): elsewhere the
    controllers' processes are not measured."""
    if not (robot_ticks and in_host):
        return {"node_code_per_robot_tick_us": None, "host_cost_per_robot_tick_us": None}
    return {"node_code_per_robot_tick_us": round(1e6 * times.node_code_s / robot_ticks, 2),
            "host_cost_per_robot_tick_us": round(1e6 * (times.cpu_s - times.node_code_s) / robot_ticks, 2)}


def _save_npz(f, compress: bool, **arrays: np.ndarray) -> None:
    """``np.savez`` into ``f``, with the arrays that shrink compressed (LED colours, names) and the
    floats stored as they are. Poses barely compress, and deflating them took a noticeable part of
    a large run's end (docs/speed.md); a checkpoint, written often and replaced, is not compressed
    at all."""
    with zipfile.ZipFile(f, "w", allowZip64=True) as z:
        for name, array in arrays.items():
            method = zipfile.ZIP_DEFLATED if compress and array.dtype.kind not in "fc" else zipfile.ZIP_STORED
            info = zipfile.ZipInfo(f"{name}.npy")
            info.compress_type = method
            with z.open(info, "w", force_zip64=True) as member:
                np.lib.format.write_array(member, np.asanyarray(array), allow_pickle=False)


def write_results(out_dir: Path, world: World, result: LoopResult, summary: dict,
                  picture: bool = True, checkpoint: bool = False, near_misses: Optional[list] = None) -> list[str]:
    """Write every file of a run; each file is complete on its own, the picture last. Each file
    replaces the one before in one step (written aside, then renamed): a run killed while writing
    leaves the previous checkpoint's file, never half a file. Trajectories streamed as the run
    went (outputs/stream.py) are flushed at a checkpoint and packed into trajectories.npz at the
    end. Returns the names written, in order (what the run says it wrote). ``near_misses``: the
    drones' (core/near_misses.py), None without drones."""
    from composed_sim.outputs.stream import TrajectoryStream
    out_dir.mkdir(parents=True, exist_ok=True)
    with _replacing(out_dir / WORLD) as f:
        f.write(dump_world(world).encode())
    t = result.trajectories
    if isinstance(t, TrajectoryStream):
        written = _write_stream(out_dir, t, result, checkpoint)
    else:
        written = _write_in_memory(out_dir, world, result, checkpoint)
    if near_misses is not None:
        written.append(NEAR_MISSES)
        _write_near_misses(out_dir / NEAR_MISSES, t.names, near_misses)
    with _replacing(out_dir / SUMMARY) as f:
        f.write((json.dumps(summary, indent=2) + "\n").encode())
    written.append(SUMMARY)
    if picture:
        from composed_sim.outputs.render import render
        # The whole run's trails: the picture summarises the run, not its last seconds.
        render(t, world, out_dir / PICTURE, led_colors=t.led_colors, trail_ticks=t.ticks_done,
               tick_s=world.tick_s)
        written.append(PICTURE)
    if isinstance(t, TrajectoryStream) and not checkpoint:
        shutil.rmtree(t.folder, ignore_errors=True)     # packed into trajectories.npz; drawn from
    return written


def _write_near_misses(path: Path, names: list[str], near_misses: list) -> None:
    with _replacing(path) as f:
        text = io.TextIOWrapper(f, newline="")
        w = csv.writer(text)
        w.writerow(["tick", "first", "second", "distance_m"])
        w.writerows((e.tick, names[e.first], names[e.second], f"{e.distance_m:.4f}") for e in near_misses)
        text.detach()


def _write_stream(out_dir: Path, t, result: LoopResult, checkpoint: bool) -> list[str]:
    """The streamed files brought up to date; at the end, the trajectories packed."""
    from composed_sim.outputs.stream import pack_folder
    t.write_violations(result.violations)
    if checkpoint:
        t.flush()
        written = [f"{t.folder.name}/", VIOLATIONS]
    else:
        t.close()
        with _replacing(out_dir / TRAJECTORIES) as f:
            pack_folder(t.folder, f)
        written = [TRAJECTORIES, VIOLATIONS]
    return [WORLD, *written] + ([METRICS] if t.metrics.first is not None else [])


def _write_in_memory(out_dir: Path, world: World, result: LoopResult, checkpoint: bool) -> list[str]:
    """Trajectories, violations and metrics of a result held in memory, each file whole."""
    written = [WORLD, TRAJECTORIES, VIOLATIONS]
    t = result.trajectories
    extra = {} if t.led_colors is None else {"led_colors": t.led_colors}
    if t.altitudes is not None:
        extra["altitudes"] = t.altitudes
    with _replacing(out_dir / TRAJECTORIES) as f:
        _save_npz(f, compress=not checkpoint, positions=t.positions, headings=t.headings,
                  names=np.asarray(t.names), tick_s=np.asarray(world.tick_s), **extra)
    with _replacing(out_dir / VIOLATIONS) as f:
        text = io.TextIOWrapper(f, newline="")
        w = csv.writer(text)
        w.writerow(["tick", "robot", "reason"])
        w.writerows((v.tick, v.robot, v.reason) for v in result.violations)
        text.detach()
    if result.metrics:
        written.append(METRICS)
        with _replacing(out_dir / METRICS) as f:
            text = io.TextIOWrapper(f, newline="")
            columns = list(dict.fromkeys(k for row in result.metrics for k in row))
            w = csv.DictWriter(text, columns)
            w.writeheader()
            w.writerows(result.metrics)
            text.detach()
    return written


@contextlib.contextmanager
def _replacing(path: Path):
    """A binary file to write that takes ``path``'s place once complete. A write that fails
    (a full disk) removes the part written, giving its space back, leaves the previous file and
    raises an OSError naming ``path``."""
    part = path.with_name(path.name + ".part")
    try:
        with open(part, "wb") as f:
            yield f
    except OSError as e:
        part.unlink(missing_ok=True)
        raise OSError(e.errno, e.strerror, str(path)) from None
    except BaseException:
        part.unlink(missing_ok=True)
        raise
    os.replace(part, path)


def load_trajectories(path: Path) -> Trajectories:
    """A run's trajectories: from ``trajectories.npz``, or from the ``trajectories/`` folder of a
    run that goes or was killed (outputs/stream.py), or from the results directory holding either."""
    from composed_sim.outputs.stream import FOLDER, load_folder
    path = Path(path)
    if path.is_dir() and (path / TRAJECTORIES).is_file():
        path = path / TRAJECTORIES
    elif path.is_dir() and (path / FOLDER).is_dir():
        path = path / FOLDER
    if path.is_dir():
        return load_folder(path)
    with np.load(path) as data:
        positions = data["positions"]
        leds = data["led_colors"] if "led_colors" in data else None
        altitudes = data["altitudes"] if "altitudes" in data else None
        return Trajectories(list(data["names"]), positions, data["headings"], len(positions) - 1, leds, altitudes)


def has_trajectories(results: Path) -> bool:
    """Does a results directory hold trajectories (packed, or streamed by a run that goes or was killed)?"""
    from composed_sim.outputs.stream import FOLDER
    return (Path(results) / TRAJECTORIES).is_file() or (Path(results) / FOLDER / "positions.npy").is_file()
