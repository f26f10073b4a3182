"""The subcommands about files: ``worlds``, ``plugins``, ``export``, ``render`` and ``replay``."""
from __future__ import annotations

import sys
from pathlib import Path

from composed_sim.command_line import UserError, check_writable



def cmd_plugins() -> int:
    from composed_sim import plugins
    try:
        found = plugins.installed()
    except plugins.PluginError as e:
        raise UserError(str(e)) from None
    for name, ep in found.items():
        dist = getattr(ep, "dist", None)
        print(f"{name:20s} {ep.value}  ({dist.name} {dist.version})" if dist else f"{name:20s} {ep.value}")
    return 0


def cmd_export(args) -> int:
    from composed_sim.outputs.export import ExportError, export_table
    out = args.out or args.results / f"trajectories.{args.format}"
    try:
        rows = export_table(args.results, out, args.format)
    except ExportError as e:
        raise UserError(str(e)) from None
    print(f"{out}: {rows} rows")
    return 0


def cmd_render(args) -> int:
    from composed_sim.outputs.render import render
    out = _render_target(args.out)
    traj, world, leds, tick_s = _load_results_or_recording(args.source)
    frames = render(traj, world, out, led_colors=leds, fps=args.fps, size_px=args.size,
                    trail_ticks=args.trail, every=args.every, tick_s=tick_s)
    print(f"{out}: {frames} frame{'s' if frames != 1 else ''}")
    return 0


def cmd_bag_repair(args) -> int:
    from composed_sim.outputs.recording.repair import is_unfinished
    if not is_unfinished(args.recording) and (args.recording / "metadata.yaml").exists():
        rec = _read_recording(args.recording)
        print(f"{args.recording}: complete already (ticks 0…{rec.ticks_done}): nothing to repair")
        return 0
    print(_repair(args.recording))
    return 0


def _repair(path: Path):
    """What the repair of an unfinished recording recovered; a UserError when it cannot."""
    from composed_sim.outputs.recording.repair import repair
    from composed_sim.outputs.recording import RecordingError
    try:
        return repair(path)
    except RecordingError as e:
        raise UserError(str(e)) from None
    except OSError as e:
        raise UserError(f"{e.filename or path}: cannot repair the recording ({e.strerror or e})") from None


def cmd_replay(args) -> int:
    from composed_sim.outputs.recording.repair import is_unfinished
    from composed_sim.outputs.render import render
    out = _render_target(args.out) if args.out else None
    if is_unfinished(args.recording):       # its run was killed: what it left is repaired first
        print(f"composed-sim: {_repair(args.recording)} (the recording had not been closed: its run was killed)",
              file=sys.stderr)
    rec = _read_recording(args.recording)
    n = len(rec.names)
    print(f"{args.recording}: {rec.world.name if rec.world else 'unknown world'}, {n} robots, "
          f"{rec.ticks_done} ticks recorded ({rec.ticks_done * rec.tick_s:.1f} s sim time); "
          f"topics: {', '.join(sorted(rec.topics))}")
    if rec.world is not None and n and rec.world.lights:
        import numpy as np
        centroid = np.asarray(rec.positions[-1]).mean(axis=0)
        print(f"  final centroid to light: {np.linalg.norm(centroid - rec.world.lights[0].position):.2f} m")
    if out is not None:
        frames = render(rec, rec.world, out, led_colors=rec.led_colors, fps=args.fps, size_px=args.size,
                        trail_ticks=args.trail, every=args.every, tick_s=rec.tick_s)
        print(f"{out}: {frames} frames")
    if args.check:
        problem = _check_recording(rec)
        if problem:
            print(f"composed-sim: check failed: {problem}", file=sys.stderr)
            return 1
    return 0


def _check_recording(rec) -> str | None:
    """Re-simulate the recorded world (its seed, its executor) and compare every recorded tick's
    /swarm/state with the simulation, bit for bit. None when they agree; else the first gap or
    difference."""
    import numpy as np
    if rec.world is None:
        return "the recording holds no world to re-simulate"
    ticks = rec.ticks
    if len(ticks) == 0 or ticks[0] != 0:
        return f"the recording does not start at tick 0 (first: {ticks[0] if len(ticks) else 'none'})"
    gaps = np.flatnonzero(np.diff(ticks) != 1)
    if len(gaps):
        t = int(ticks[gaps[0]])
        return f"tick {t + 1} is missing (after tick {t}, the next recorded is {int(ticks[gaps[0] + 1])})"
    from composed_sim.hosting import DEFAULT_EXECUTOR
    from composed_sim.hosts.make import host_in_own_domains
    from composed_sim.hosts.settings import HostSettings
    executor = rec.executor or DEFAULT_EXECUTOR
    host, claim, _ = host_in_own_domains(HostSettings(workers=1, executor=executor), rec.world)
    try:
        with host:
            if host.sim.names != rec.names:
                return "the recorded robots are not the recorded world's"
            t = host.run(len(ticks) - 1).trajectories
    finally:
        claim.release()
    for name, recorded, simulated in (("position", rec.positions, t.positions), ("heading", rec.headings, t.headings),
                                      ("LED colour", rec.led_colors, t.led_colors)):
        differs = np.flatnonzero((recorded != simulated).reshape(len(ticks), len(rec.names), -1).any(axis=2).ravel())
        if len(differs):
            tick, robot = divmod(int(differs[0]), len(rec.names))
            return (f"tick {tick}, {rec.names[robot]}: the recorded {name} {recorded[tick, robot].tolist()} is not the "
                    f"re-simulated {simulated[tick, robot].tolist()} (world {rec.world.name!r}, seed {rec.world.seed}, "
                    f"{executor} executor)")
    print(f"  check: ticks 0…{len(ticks) - 1} re-simulated (seed {rec.world.seed}, {executor} executor): every "
          f"recorded pose and LED colour identical, bit for bit")
    return None


def _render_target(out: Path) -> Path:
    if out.suffix.lower() not in (".png", ".gif", ".mp4"):
        raise UserError(f"--out {out}: the file must end in .png, .gif or .mp4")
    parent = out.parent if str(out.parent) else Path(".")
    check_writable(parent)
    parent.mkdir(parents=True, exist_ok=True)      # the picture is drawn next, right away
    return out


def _read_recording(path: Path):
    from composed_sim.outputs.recording import RecordingError, read_recording
    try:
        return read_recording(path)
    except (RecordingError, FileNotFoundError, NotADirectoryError) as e:
        raise UserError(f"{path}: not a readable recording ({e})") from None


def _load_results_or_recording(source: Path):
    """(trajectories, world, led colours [T+1, n, 3] or None, tick_s) from either kind of directory."""
    from composed_sim.outputs.results import TRAJECTORIES, WORLD, has_trajectories, load_trajectories
    from composed_sim.world.loader import WorldFileError, load_world
    if (source / "metadata.yaml").exists():
        rec = _read_recording(source)
        return rec, rec.world, rec.led_colors, rec.tick_s
    if not has_trajectories(source):
        raise UserError(f"{source}: neither a results directory ({TRAJECTORIES}) nor a recording (metadata.yaml)")
    try:
        world = load_world(source / WORLD)
    except WorldFileError as e:
        raise UserError(str(e)) from None
    traj = load_trajectories(source)
    return traj, world, traj.led_colors, world.tick_s


def shipped_worlds() -> list[Path]:
    """worlds/*.yaml and *.argos next to the package (a source checkout or an editable install)."""
    from composed_sim.world.loader import SHIPPED_WORLDS
    return sorted(p for p in SHIPPED_WORLDS.glob("*") if p.suffix in (".yaml", ".argos")) if SHIPPED_WORLDS.is_dir() else []


def cmd_worlds() -> int:
    from composed_sim.argos_import import is_argos_file
    worlds = shipped_worlds()
    if not worlds:
        raise UserError("no shipped worlds found next to the package (install from a source checkout)")
    for path in worlds:
        first = next((line.lstrip("# ").strip() for line in path.read_text().splitlines()
                      if line.startswith("#") or line.startswith("<!--")), "")
        kind = "ARGoS" if is_argos_file(path) else "YAML"
        print(f"{path}  [{kind}]  {first.strip('<!- >')}")
    return 0
