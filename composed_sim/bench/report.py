"""The sweep's outputs: runs.csv and runs.json, the figures (bench/figures.py) and the markdown
report: the machine and the command, then one part per experiment (results, budget, workers,
composed / multi-process, the main process's phases, the host cost, the paper)."""
from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Optional

from composed_sim.bench.cells import number, ratio
from composed_sim.bench.experiments import EXPERIMENTS, experiment_name
from composed_sim.bench.figures import plot_figures
from composed_sim.bench.rules import (COLUMNS, DEFAULT_MEMORY_FRACTION, SATURATED, aggregate, as_number, host_label,
                                      saturated)
from composed_sim.bench.sections import host_cost_section, paper_section, phases_section
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


# The performance budget for composed mode (docs/speed.md), 600 ticks of the flocking world:
# N -> limits (None: no limit stated; the run must complete).
BUDGET = {1280: {"ticks_wall_s": 60.0, "MaxMem(kB)": 1.5 * 2**20, "setup_s": 15.0},
          10240: {"ticks_wall_s": None, "MaxMem(kB)": 12 * 2**20, "setup_s": 120.0}}
# … and linear scaling: the cost per robot-tick at the larger N within this factor of the smaller's.
SCALING = (80, 1280, 1.5)



def _budget_section(agg: list[dict], rows: list[dict]) -> list[str]:
    lines = ["", "### Against the design budget (composed mode, 600 ticks)", ""]
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
        def lim(k, d, sc=1.0, limits=limits):
            return "–" if limits[k] is None else f"≤ {limits[k] * sc:,.{d}f}"
        lines.append(f"| {a['Robots']} | {host_label(a)} | {a['executor']} | {number(a['ticks_wall_s'], 1)} "
                     f"| {lim('ticks_wall_s', 0)} | {number(a['setup_s'], 1)} | {lim('setup_s', 0)} "
                     f"| {number(a['MaxPss(kB)'] or a['MaxMem(kB)'], 0, 1 / 1024)} "
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
    lines = ["", "### Worker processes / one process (same executor, this run)", "",
             "Below 1 means the workers need less. CPU: % of one core during the whole run.", "",
             "| N | workers | executor | ticks wall | total wall | setup s (1 → K) | CPU % (1 → K) | peak PSS MB (1 → K) |",
             "|---:|---|---|---:|---:|---:|---:|---:|"]
    for n, w, e in pairs:
        k, one = by[(n, "composed", w, e)], by[(n, "composed", "1", e)]
        lines.append(f"| {n} | {host_label(k).removeprefix('composed, ')} | {e} | {ratio(k['ticks_wall_s'], one['ticks_wall_s'])} "
                     f"| {ratio(k['total_wall_s'], one['total_wall_s'])} | {number(one['setup_s'], 1)} → {number(k['setup_s'], 1)} "
                     f"| {number(one['CPU(%)'], 0)} → {number(k['CPU(%)'], 0)} "
                     f"| {number(one['MaxPss(kB)'], 0, 1 / 1024)} → {number(k['MaxPss(kB)'], 0, 1 / 1024)} |")
    return lines


def render_report(doc: dict, figures: dict[tuple[str, str], Path], raw: tuple[Path, Path], report: Path) -> str:
    """The markdown report; ``figures`` ((experiment, kind) → path) and ``raw`` (csv, json) are
    paths relative to its folder."""
    s = doc.get("settings", {})
    rows = doc["rows"]
    agg = aggregate(rows, s)
    experiments = list(dict.fromkeys(a["experiment"] for a in agg))
    lines = [*_title_part(doc, report), *_machine_part(doc["machine"]), *_command_part(doc, experiments, raw, report)]
    for experiment in experiments:
        lines += _experiment_part(experiment, [a for a in agg if a["experiment"] == experiment],
                                  [r for r in rows if experiment_name(r, s) == experiment], doc,
                                  {kind: path for (e, kind), path in figures.items() if e == experiment})
    lines += _what_is_measured_part()
    return "\n".join(lines) + "\n"


def _title_part(doc: dict, report: Path) -> list[str]:
    """The title, where the report comes from, and the link to speed.md when it is beside it."""
    return [
        "# Benchmarks",
        "",
        f"Generated by `composed-sim bench` on {doc['machine'].get('date')} from the runs below; do not edit by "
        "hand, re-run the command to regenerate it.",
        *(["", "Where a tick's time goes, profiled, and the speed work behind these figures: [speed.md](speed.md)."]
          if (report.parent / "speed.md").exists() else []),
    ]


def _machine_part(m: dict) -> list[str]:
    """The machine the runs ran on: CPU, memory, load, versions."""
    v = m.get("versions", {})
    load = m.get("load_average_at_start")
    return [
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
    ]


def _command_part(doc: dict, experiments: list[str], raw: tuple[Path, Path], report: Path) -> list[str]:
    """The bench's command, what each run was, where the raw rows are, and the multi-process skip rule."""
    s = doc.get("settings", {})
    ticks = s.get("ticks", 600)
    worlds = {name: Path(w["world"]).name for name, w in s.get("experiments", {}).items()}
    ran = ", ".join(f"`{worlds.get(e) or Path(s.get('world', 'world')).name}` ({e})" for e in experiments) or "nothing"
    lines = [
        "",
        "## Command",
        "",
        "```bash",
        doc.get("command", "composed-sim bench"),
        "```",
        "",
        f"{len(doc['rows'])} runs in {doc.get('elapsed_s', 0):.0f} s, each a `composed-sim run WORLD --ticks {ticks} "
        f"--json` subprocess on its own ROS domain, WORLD one of {ran}; raw rows: [{raw[0].name}]({raw[0].as_posix()}), "
        f"[{raw[1].name}]({raw[1].as_posix()}); `composed-sim bench --replot "
        f"{(report.parent / raw[1]).as_posix()} --report {report.as_posix()}` redraws the figures and this report from them.",
    ]
    est = doc.get("memory_estimate")
    if "multi-process" in s.get("modes", []) and est:
        lines += ["", f"Multi-process skip rule: predicted memory = simulator {est['base_mb']:.0f} MB + N × "
                      f"{est['per_process_mb']:.1f} MB per controller process ({est['source']}); a run is skipped "
                      f"when that exceeds {s.get('memory_fraction', DEFAULT_MEMORY_FRACTION):.0%} of the available memory."]
    return lines


def _what_is_measured_part() -> list[str]:
    """What each column means, and how the paper's memory figure compares."""
    return [
        "",
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


def _experiment_part(experiment: str, agg: list[dict], rows: list[dict], doc: dict,
                     figures: dict[str, Path]) -> list[str]:
    """One experiment's part of the report."""
    m, s = doc["machine"], doc.get("settings", {})
    ticks = s.get("ticks", 600)
    sim_s = ticks * s.get("tick_s", 0.1)
    known = EXPERIMENTS.get(experiment)
    lines = ["", f"## {experiment}" + (f": {known.about}" if known else ""), "",
             f"### Results (median over the ok trials; {ticks} ticks = {sim_s:g} s simulated)", "",
             "| N | host | executor | ok/trials | setup s | ticks wall s | total wall s | real-time factor "
             "| µs / robot-tick | CPU % of one core | CPU core-s | peak tree PSS MB | peak tree RSS MB | violations "
             "| other load (cores) |",
             "|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    cores = m.get("logical_cores") or 0
    any_saturated = False
    for a in agg:
        mark = " †" if saturated(a, cores) else ""
        any_saturated = any_saturated or bool(mark)
        lines.append(
            f"| {a['Robots']} | {host_label(a)} | {a['executor']} | {a['ok']}/{a['trials']} | {number(a['setup_s'], 2)} "
            f"| {number(a['ticks_wall_s'], 1)} | {number(a['total_wall_s'], 1)}{mark} | {number(a['real_time_factor'], 2)} "
            f"| {number(a['per_robot_tick_us'], 0)} | {number(a['CPU(%)'], 0)} | {number(a['cpu_core_s'], 1)} "
            f"| {number(a['MaxPss(kB)'], 0, 1 / 1024)} | {number(a['MaxMem(kB)'], 0, 1 / 1024)} "
            f"| {'–' if a['violations'] is None else a['violations']} "
            f"| {number(a['other_load_cores'], 2)} |")
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

    by = {(a["Robots"], a["mode"], a["workers"], a["executor"]): a for a in agg}
    if experiment == "flocking":          # the budget is stated for the flocking world
        lines += _budget_section(agg, rows)
    lines += _workers_section(by)
    lines += _modes_section(by, s)
    lines += phases_section(agg)
    lines += host_cost_section(agg)
    lines += paper_section(experiment, agg, ticks)
    if figures:
        paper = " and the paper's means (dotted)" if known and known.paper else ""
        lines += ["", "### Figures", "",
                  f"Medians of our ok runs per host and executor (composed in one process solid, with worker processes "
                  f"dash-dotted, multi-process dashed; memory as PSS){paper}, log-log against N; the wall-time plot "
                  f"has the real-time line at {sim_s:g} s.", ""]
        for key, label in (("wall_time", "wall time"), ("cpu", "CPU"), ("memory", "memory")):
            if key in figures:
                lines += [f"![{experiment}: {label} against N]({figures[key].as_posix()})", ""]
    return lines


def _modes_section(by: dict, settings: dict) -> list[str]:
    """Composed against multi-process mode: same N and executor, this sweep."""
    pairs = [(n, w, e) for (n, mode, w, e) in by if mode == "composed" and (n, "multi-process", "", e) in by
             and by[(n, "multi-process", "", e)]["ok"] and by[(n, mode, w, e)]["ok"]]
    lines = ["", "### Composed / multi-process (same executor, this run)", ""]
    if pairs:
        lines += ["Below 1 means the composed host needs less. Memory: peak PSS of each whole process tree.", "",
                  "| N | composed host | executor | total wall | ticks wall | setup | CPU core-s | peak memory |",
                  "|---:|---|---|---:|---:|---:|---:|---:|"]
        for n, w, e in sorted(pairs):
            c, p = by[(n, "composed", w, e)], by[(n, "multi-process", "", e)]
            lines.append(f"| {n} | {host_label(c)} | {e} | {ratio(c['total_wall_s'], p['total_wall_s'])} | "
                         f"{ratio(c['ticks_wall_s'], p['ticks_wall_s'])} | {ratio(c['setup_s'], p['setup_s'])} | "
                         f"{ratio(c['cpu_core_s'], p['cpu_core_s'])} | "
                         f"{ratio(c['MaxPss(kB)'] or c['MaxMem(kB)'], p['MaxPss(kB)'] or p['MaxMem(kB)'])} |")
    elif "multi-process" not in settings.get("modes", []):
        lines.append("Multi-process mode was not part of this sweep.")
    else:
        lines.append("No swarm size where both modes completed in this sweep.")
    return lines
