"""The sweep's outputs: runs.csv and runs.json, the figures (log-log against N, with the paper's
means) and the markdown report with the budget and workers sections."""
from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Optional

from composed_sim.bench.rules import (COLUMNS, DEFAULT_MEMORY_FRACTION, FIGURES, PAPER_VARIANTS, aggregate, as_number,
                                      host_label, load_paper_results)
from composed_sim.bench.tree import PSS_SAMPLE_S, SAMPLE_S


def write_outputs(doc: dict, out: Path, report: Optional[Path]) -> None:
    out.mkdir(parents=True, exist_ok=True)
    write_csv(doc["rows"], out / "runs.csv")
    (out / "runs.json").write_text(json.dumps(doc, indent=2) + "\n")
    figures = plot_figures(doc, out)
    if report is not None:
        import shutil
        fig_dir = report.parent / "figures"
        fig_dir.mkdir(parents=True, exist_ok=True)
        stem = report.stem
        copied = {}
        for key, path in figures.items():
            target = fig_dir / f"{stem}_{path.name}"
            shutil.copyfile(path, target)
            copied[key] = target
        shutil.copyfile(out / "runs.csv", fig_dir / f"{stem}_runs.csv")
        shutil.copyfile(out / "runs.json", fig_dir / f"{stem}_runs.json")
        report.write_text(render_report(doc, {k: p.relative_to(report.parent) for k, p in copied.items()},
                                        raw=(Path("figures") / f"{stem}_runs.csv", Path("figures") / f"{stem}_runs.json"),
                                        report=report))


def write_csv(rows: list[dict], path: Path) -> None:
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(COLUMNS), extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in COLUMNS})


def _series_style(mode: str, workers: str, executor: str) -> dict:
    """Colour by executor; composed in one process solid, with workers dash-dotted, multi-process dashed."""
    colors = {"multi-threaded": "tab:blue", "single-threaded": "tab:orange", "events": "tab:green",
              "lockstep": "tab:red"}
    one_process = mode == "composed" and workers in ("", "1")
    linestyle = "-" if one_process else "-." if mode == "composed" else "--"
    return {"color": colors.get(executor, "tab:purple"), "linestyle": linestyle,
            "marker": "o" if one_process else "D" if mode == "composed" else "s"}


def plot_figures(doc: dict, out: Path) -> dict[str, Path]:
    """wall_time.png, cpu.png, memory.png: medians of our ok runs per mode/executor and the paper's
    means, against N on log-log axes."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    agg = aggregate(doc["rows"])
    settings, machine = doc.get("settings", {}), doc["machine"]
    ticks = settings.get("ticks", 600)
    sim_s = ticks * settings.get("tick_s", 0.1)
    paper = {k: load_paper_results(f) for k, (f, _) in PAPER_VARIANTS.items()}
    cores = machine.get("logical_cores") or 0
    footer = (f"this machine: {machine.get('cpu_model')}, {machine.get('logical_cores')} logical cores, "
              f"{machine.get('memory_total_mb', 0) / 1024:.0f} GB, {machine.get('date', '')[:10]}; "
              f"{ticks} ticks per run; median of ok trials.  Paper: mean of 10 trials, 600 ticks, "
              f"12-core Ryzen 9 7900")
    specs = {
        "wall_time": ("WallTime(s)", 1.0, "wall time (s)", f"Wall time of {sim_s:g} s of simulated time"),
        "cpu": ("CPU(%)", 1.0, "CPU (% of one core)", "CPU use of the whole process tree"),
        "memory": ("MaxPss(kB)", 1 / 1024, "peak PSS (MB)", "Peak memory of the whole process tree (PSS)"),
    }
    written = {}
    for key, (col, scale, ylabel, title) in specs.items():
        fig, ax = plt.subplots(figsize=(7.5, 5.2), dpi=110)
        for pkey, (_, label) in PAPER_VARIANTS.items():
            ns = sorted(paper[pkey])
            paper_col = "MaxMem(kB)" if col == "MaxPss(kB)" else col     # the paper measured RSS
            ax.plot(ns, [paper[pkey][n][paper_col] * scale for n in ns], color="black" if pkey == "single" else "dimgrey",
                    linestyle=":", marker="^" if pkey == "single" else "v", label=label)
        series: dict[tuple, list] = {}
        for a in agg:
            value = a[col] if a[col] is not None or col != "MaxPss(kB)" else a["MaxMem(kB)"]   # older rows: RSS
            if value is not None:
                series.setdefault((a["mode"], a["workers"], a["executor"]), []).append(
                    (a["Robots"], value * scale, saturated(a, cores)))
        any_saturated = False
        for (mode, workers, executor), pts in series.items():
            xs, ys, sat = zip(*sorted(pts))
            style = _series_style(mode, workers, executor)
            label = host_label({"mode": mode, "workers": workers})
            ax.plot(xs, ys, label=f"{label}, {executor}", **style)
            hollow = [(x, y) for x, y, s in zip(xs, ys, sat) if s]
            if hollow:          # the machine was saturated: times are upper bounds
                any_saturated = True
                ax.plot(*zip(*hollow), linestyle="none", marker=style["marker"], markerfacecolor="white",
                        markeredgecolor=style["color"], markersize=7)
        if any_saturated:
            ax.plot([], [], linestyle="none", marker="o", markerfacecolor="white", markeredgecolor="grey",
                    label="hollow: machine saturated during the run")
        if key == "wall_time":
            ax.axhline(sim_s, color="black", linestyle="--", linewidth=1, label=f"real time ({sim_s:g} s)")
        if key == "memory" and machine.get("memory_total_mb"):
            ax.axhline(machine["memory_total_mb"], color="firebrick", linestyle="-.", linewidth=0.8,
                       label="this machine's memory")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("robots N")
        ax.set_ylabel(ylabel)
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, loc="upper left")
        fig.text(0.01, 0.005, footer, fontsize=5.5, color="dimgrey")
        fig.tight_layout(rect=(0, 0.03, 1, 1))
        path = out / FIGURES[key]
        fig.savefig(path)
        plt.close(fig)
        written[key] = path
    return written


def _f(v, digits: int = 1, scale: float = 1.0) -> str:
    x = as_number(v)
    return "–" if x is None else f"{x * scale:,.{digits}f}"


def _ratio(a, b, digits: int = 2) -> str:
    x, y = as_number(a), as_number(b)
    return "–" if x is None or y is None or y == 0 else f"{x / y:.{digits}g}" if x / y < 0.01 else f"{x / y:.{digits}f}"


# The performance budget for composed mode (docs/speed.md), 600 ticks of the flocking world:
# N -> limits (None: no limit stated; the run must complete).
BUDGET = {1280: {"ticks_wall_s": 60.0, "MaxMem(kB)": 1.5 * 2**20, "setup_s": 15.0},
          10240: {"ticks_wall_s": None, "MaxMem(kB)": 12 * 2**20, "setup_s": 120.0}}
# … and linear scaling: the cost per robot-tick at the larger N within this factor of the smaller's.
SCALING = (80, 1280, 1.5)


SATURATED = 0.95   # share of the machine's cores busy (the run's + others') above which a run is flagged


def saturated(rec: dict, cores: int) -> bool:
    """Whether the machine's cores were all busy during a run (or the median of runs): its CPU % of
    one core / 100 + the other load >= SATURATED × cores."""
    cpu, other = as_number(rec.get("CPU(%)")), as_number(rec.get("other_load_cores"))
    if cpu is None or other is None or cores < 1:
        return False
    return cpu / 100 + other >= SATURATED * cores


def _budget_section(agg: list[dict], rows: list[dict]) -> list[str]:
    lines = ["", "## Against the design budget (composed mode, 600 ticks)", ""]
    checked = [a for a in agg if a["mode"] == "composed" and a["Robots"] in BUDGET]
    if not checked:
        return lines + ["The budget is stated at N = " + " and ".join(map(str, BUDGET)) +
                        "; this sweep ran neither."]
    lines += ["| N | host | executor | ticks wall s | limit | setup s | limit | peak PSS MB | limit | verdict |",
              "|---:|---|---|---:|---:|---:|---:|---:|---:|---|"]
    for a in checked:
        limits = BUDGET[a["Robots"]]
        ticks_ok = {r.get("ticks") for r in rows if r["Robots"] == a["Robots"]} == {600}
        misses = []
        if not a["ok"]:
            misses.append("did not complete")
        # The ticks limit is for 600 ticks: a shorter sweep is judged on set-up and memory only.
        for key, label in ((("ticks_wall_s", "ticks wall"),) if ticks_ok else ()) + (
                ("setup_s", "setup"), ("MaxMem(kB)", "peak memory")):
            lim, val = limits[key], as_number(a[key] if key != "MaxMem(kB)" else a["MaxPss(kB)"] or a[key])
            if lim is not None and val is not None and val > lim:
                misses.append(label)
        verdict = "over: " + ", ".join(misses) if misses else (
            "within budget" if ticks_ok else "set-up and memory within budget")
        if not ticks_ok:
            verdict += "; ticks not judged (not 600 ticks)"
        lim = lambda k, d, sc=1.0: "–" if limits[k] is None else f"≤ {limits[k] * sc:,.{d}f}"
        lines.append(f"| {a['Robots']} | {host_label(a)} | {a['executor']} | {_f(a['ticks_wall_s'], 1)} "
                     f"| {lim('ticks_wall_s', 0)} | {_f(a['setup_s'], 1)} | {lim('setup_s', 0)} "
                     f"| {_f(a['MaxPss(kB)'] or a['MaxMem(kB)'], 0, 1 / 1024)} "
                     f"| {lim('MaxMem(kB)', 0, 1 / 1024)} | {verdict} |")
    small, large, factor = SCALING
    for workers, executor in dict.fromkeys((a["workers"], a["executor"]) for a in agg if a["mode"] == "composed"):
        cost = {a["Robots"]: as_number(a["per_robot_tick_us"]) for a in agg if a["mode"] == "composed"
                and a["executor"] == executor and a["workers"] == workers and a["ok"]}
        if cost.get(small) and cost.get(large):
            ratio = cost[large] / cost[small]
            label = host_label({"mode": "composed", "workers": workers})
            lines.append(f"\nScaling, {label}, {executor}: a robot-tick costs {cost[large]:.0f} µs at N = {large} and "
                         f"{cost[small]:.0f} µs at N = {small}: {ratio:.2f}× (limit ≤ {factor}×, "
                         f"{'within' if ratio <= factor else 'over'}).")
    return lines


def _workers_section(by: dict) -> list[str]:
    """Worker processes against one process: same N and executor, this run."""
    pairs = sorted((n, w, e) for (n, mode, w, e) in by
                   if mode == "composed" and w not in ("", "1") and (n, "composed", "1", e) in by
                   and by[(n, mode, w, e)]["ok"] and by[(n, "composed", "1", e)]["ok"])
    if not pairs:
        return []
    lines = ["", "## Worker processes / one process (same executor, this run)", "",
             "Below 1 means the workers need less. CPU: % of one core during the whole run.", "",
             "| N | workers | executor | ticks wall | total wall | setup s (1 → K) | CPU % (1 → K) | peak PSS MB (1 → K) |",
             "|---:|---|---|---:|---:|---:|---:|---:|"]
    for n, w, e in pairs:
        k, one = by[(n, "composed", w, e)], by[(n, "composed", "1", e)]
        lines.append(f"| {n} | {host_label(k).removeprefix('composed, ')} | {e} | {_ratio(k['ticks_wall_s'], one['ticks_wall_s'])} "
                     f"| {_ratio(k['total_wall_s'], one['total_wall_s'])} | {_f(one['setup_s'], 1)} → {_f(k['setup_s'], 1)} "
                     f"| {_f(one['CPU(%)'], 0)} → {_f(k['CPU(%)'], 0)} "
                     f"| {_f(one['MaxPss(kB)'], 0, 1 / 1024)} → {_f(k['MaxPss(kB)'], 0, 1 / 1024)} |")
    return lines


def render_report(doc: dict, figures: dict[str, Path], raw: tuple[Path, Path], report: Path) -> str:
    """The markdown report; ``figures`` and ``raw`` (csv, json) are paths relative to its folder."""
    m, s = doc["machine"], doc.get("settings", {})
    rows = doc["rows"]
    agg = aggregate(rows)
    ticks = s.get("ticks", 600)
    sim_s = ticks * s.get("tick_s", 0.1)
    v = m.get("versions", {})
    load = m.get("load_average_at_start")
    lines = [
        "# Benchmarks",
        "",
        f"Generated by `composed-sim bench` on {m.get('date')} from the runs below; do not edit by hand, "
        "re-run the command to regenerate it.",
        *(["", "Where a tick's time goes, profiled, and the speed work behind these figures: [speed.md](speed.md)."]
          if (report.parent / "speed.md").exists() else []),
        "",
        "## Machine",
        "",
        f"- CPU: {m.get('cpu_model')}, {m.get('logical_cores')} logical cores ({m.get('physical_cores')} physical)",
        f"- memory: {m.get('memory_total_mb', 0) / 1024:.1f} GB, {m.get('memory_available_mb_at_start', 0) / 1024:.1f} GB "
        "available at the start",
        f"- load average at the start: {', '.join(map(str, load)) if load else 'unknown'} (the machine is shared: "
        "compare ratios within this run, not absolute numbers across runs)",
        f"- {m.get('os')}; Python {v.get('python')}, rclpy {v.get('ros-jazzy-rclpy') or v.get('ros-rclpy')}, "
        f"rmw_fastrtps_cpp {v.get('ros-rmw-fastrtps-cpp')}, composed_sim {v.get('composed_sim')}"
        + (f", commit {m['commit']} (the tree may hold uncommitted changes)" if m.get("commit") else ""),
        "",
        "## Command",
        "",
        "```bash",
        doc.get("command", "composed-sim bench"),
        "```",
        "",
        f"{len(rows)} runs in {doc.get('elapsed_s', 0):.0f} s, each a `composed-sim run {Path(s.get('world', 'world')).name} "
        f"--ticks {ticks} --json` subprocess on its own ROS domain; raw rows: [{raw[0].name}]({raw[0].as_posix()}), "
        f"[{raw[1].name}]({raw[1].as_posix()}); `composed-sim bench --replot "
        f"{(report.parent / raw[1]).as_posix()} --report {report.as_posix()}` redraws the figures and this report from them.",
        "",
        f"## Results (median over the ok trials; {ticks} ticks = {sim_s:g} s simulated)",
        "",
        "| N | host | executor | ok/trials | setup s | ticks wall s | total wall s | real-time factor "
        "| µs / robot-tick | CPU % of one core | CPU core-s | peak tree PSS MB | peak tree RSS MB | violations "
        "| other load (cores) |",
        "|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    cores = m.get("logical_cores") or 0
    any_saturated = False
    for a in agg:
        mark = " †" if saturated(a, cores) else ""
        any_saturated = any_saturated or bool(mark)
        lines.append(
            f"| {a['Robots']} | {host_label(a)} | {a['executor']} | {a['ok']}/{a['trials']} | {_f(a['setup_s'], 2)} "
            f"| {_f(a['ticks_wall_s'], 1)} | {_f(a['total_wall_s'], 1)}{mark} | {_f(a['real_time_factor'], 2)} "
            f"| {_f(a['per_robot_tick_us'], 0)} | {_f(a['CPU(%)'], 0)} | {_f(a['cpu_core_s'], 1)} "
            f"| {_f(a['MaxPss(kB)'], 0, 1 / 1024)} | {_f(a['MaxMem(kB)'], 0, 1 / 1024)} "
            f"| {'–' if a['violations'] is None else a['violations']} "
            f"| {_f(a['other_load_cores'], 2)} |")
    if any_saturated:
        lines += ["", f"† the machine was saturated during the run: its own CPU plus the other load reached "
                      f"{SATURATED:.0%} of the {cores} cores, so the run may have waited for a core and its times "
                      "are upper bounds."]
    odd = [r for r in rows if r["status"] != "ok"]
    if odd:
        lines += ["", "Runs skipped or not completed:", ""]
        for r in odd:
            lines.append(f"- N={r['Robots']} {host_label(r)} {r['executor']} trial {r['Repetition']}: "
                         f"**{r['status']}** — {str(r.get('reason') or '').replace('|', '/')[:400]}")
    est = doc.get("memory_estimate")
    if "multi-process" in s.get("modes", []) and est:
        lines += ["", f"Multi-process skip rule: predicted memory = simulator {est['base_mb']:.0f} MB + N × "
                      f"{est['per_process_mb']:.1f} MB per controller process ({est['source']}); a run is skipped "
                      f"when that exceeds {s.get('memory_fraction', DEFAULT_MEMORY_FRACTION):.0%} of the available memory."]

    # composed / multi-process, same executor, same sweep
    by = {(a["Robots"], a["mode"], a["workers"], a["executor"]): a for a in agg}
    pairs = [(n, w, e) for (n, mode, w, e) in by if mode == "composed" and (n, "multi-process", "", e) in by
             and by[(n, "multi-process", "", e)]["ok"] and by[(n, mode, w, e)]["ok"]]
    lines += _budget_section(agg, rows)
    lines += _workers_section(by)
    lines += ["", "## Composed / multi-process (same executor, this run)", ""]
    if pairs:
        lines += ["Below 1 means the composed host needs less. Memory: peak PSS of each whole process tree.", "",
                  "| N | composed host | executor | total wall | ticks wall | CPU core-s | peak memory |",
                  "|---:|---|---|---:|---:|---:|---:|"]
        for n, w, e in sorted(pairs):
            c, p = by[(n, "composed", w, e)], by[(n, "multi-process", "", e)]
            lines.append(f"| {n} | {host_label(c)} | {e} | {_ratio(c['total_wall_s'], p['total_wall_s'])} | "
                         f"{_ratio(c['ticks_wall_s'], p['ticks_wall_s'])} | {_ratio(c['cpu_core_s'], p['cpu_core_s'])} | "
                         f"{_ratio(c['MaxPss(kB)'] or c['MaxMem(kB)'], p['MaxPss(kB)'] or p['MaxMem(kB)'])} |")
    elif "multi-process" not in s.get("modes", []):
        lines.append("Multi-process mode was not part of this sweep.")
    else:
        lines.append("No swarm size where both modes completed in this sweep.")

    # composed / paper
    paper = {k: load_paper_results(f) for k, (f, _) in PAPER_VARIANTS.items()}
    lines += ["", "## Ours / the paper", "",
              "The paper's means over 10 trials (ARGoS with the ROS 2 bridge, one process per controller, "
              "Ryzen 9 7900 with 12 cores; columns WallTime(s), CPU(%), MaxMem(kB) of its CSVs) against our "
              "medians. ÷1t: ours / paper single-threaded; ÷12t: ours / paper multi-threaded. Below 1 means we need less."]
    if ticks != 600:
        lines.append(f"**These runs had {ticks} ticks, the paper's 600: the wall-time and CPU ratios are not comparable.**")
    lines += ["", "| N | host | executor | wall s | ÷1t | ÷12t | CPU % | ÷1t | ÷12t | peak RSS MB | ÷1t | ÷12t |",
              "|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    any_paper = False
    for a in agg:
        p1, p12 = paper["single"].get(a["Robots"], {}), paper["multi"].get(a["Robots"], {})
        if not a["ok"] or not (p1 or p12):
            continue
        any_paper = True
        cells = []
        for col, digits, scale in (("WallTime(s)", 1, 1.0), ("CPU(%)", 0, 1.0), ("MaxMem(kB)", 0, 1 / 1024)):
            cells += [_f(a[col], digits, scale), _ratio(a[col], p1.get(col)), _ratio(a[col], p12.get(col))]
        lines.append(f"| {a['Robots']} | {host_label(a)} | {a['executor']} | " + " | ".join(cells) + " |")
    if not any_paper:
        lines.append("| – | no swarm size of this sweep is in the paper's results | | | | | | | | | | |")
    lines += ["", "The paper's own numbers, for reference:", "",
              "| N | wall s 1t | wall s 12t | CPU % 1t | CPU % 12t | peak MB 1t | peak MB 12t |",
              "|---:|---:|---:|---:|---:|---:|---:|"]
    for n in sorted(set(paper["single"]) | set(paper["multi"])):
        p1, p12 = paper["single"].get(n, {}), paper["multi"].get(n, {})
        lines.append(f"| {n} | {_f(p1.get('WallTime(s)'), 1)} | {_f(p12.get('WallTime(s)'), 1)} | "
                     f"{_f(p1.get('CPU(%)'), 0)} | {_f(p12.get('CPU(%)'), 0)} | {_f(p1.get('MaxMem(kB)'), 0, 1 / 1024)} | "
                     f"{_f(p12.get('MaxMem(kB)'), 0, 1 / 1024)} |")

    lines += ["", "## Figures", "",
              f"Medians of our ok runs per host and executor (composed in one process solid, with worker processes "
              f"dash-dotted, multi-process dashed; memory as PSS), the paper's "
              f"means (dotted), log-log against N; the wall-time plot has the real-time line at {sim_s:g} s.", ""]
    for key, label in (("wall_time", "wall time"), ("cpu", "CPU"), ("memory", "memory")):
        if key in figures:
            lines.append(f"![{label} against N]({figures[key].as_posix()})")
            lines.append("")
    lines += [
        "## What is measured",
        "",
        "- **total wall** (`WallTime(s)`): from spawning `composed-sim run` to its exit: interpreter start, imports, "
        "setup, the ticks, writing the results, as the paper timed a whole run. **setup** and **ticks wall** come from "
        "the run's own summary; **real-time factor** = simulated time / ticks wall.",
        "- **CPU** (`CPU(%)`): core-seconds of the whole process tree / total wall × 100, so 100 % is one core busy "
        "(the paper's convention); processes that exit between samples count up to their last sample, and the "
        "root's exact times and those of the children it reaped are read at its exit.",
        f"- **peak memory** (`MaxMem(kB)`): the largest sum of the resident sets of every process of the tree over "
        f"samples every {SAMPLE_S:g} s (pages shared between processes count once per process, so multi-process "
        "totals are upper bounds).",
        "- **peak PSS** (`MaxPss(kB)`): the same peak over the proportional set sizes (each shared page divided "
        f"among the processes mapping it, sampled every {PSS_SAMPLE_S:g} s): what the tree really occupies; the "
        "multi-process skip rule predicts with it.",
        "- **other load**: core-seconds the machine spent busy outside the run's process tree during it, / total "
        "wall: how much a neighbour (including the bench itself) competed for the cores.",
        "- The paper's `MaxMem` is `ArgosMem + Ros2Mem`, and its `Ros2Mem` stays between 37 MB (10 robots) and "
        "108 MB (1280 robots): it cannot hold every controller process's memory, so it likely counts one process "
        "of the ROS side, and the paper's memory curve leaves most of its controller processes out.",
    ]
    return "\n".join(lines) + "\n"
