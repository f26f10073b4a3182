"""Report sections of one experiment that read the runs' own timing breakdown (the main process's
phases per tick, the host's cost against the nodes' own time) and compare with the paper."""
from __future__ import annotations

from composed_sim.bench.cells import MISSING, number, ratio
from composed_sim.bench.experiments import paper_files
from composed_sim.bench.rules import PHASE_COLUMNS, PHASES, as_number, host_label, load_paper_results


def phases_section(agg: list[dict]) -> list[str]:
    """The main process's milliseconds per tick by phase, for each composed run."""
    composed = [a for a in agg if a["mode"] == "composed" and a["ok"]]
    lines = ["", "### Main process, per tick", "",
             "Milliseconds per tick of the main process, by phase (the run's `phases_per_tick_ms`); **serial** is "
             "everything but waiting for the nodes' answers: the part more cores do not shorten.", ""]
    if not any(as_number(a.get(col)) is not None for a in composed for col in PHASE_COLUMNS):
        return lines + ["The runs' summaries have no per-tick phases (a composed-sim from before they were "
                        "recorded, or no composed run completed)."]
    lines += ["| N | host | executor | " + " | ".join(PHASES) + " |",
              "|---:|---|---|" + "---:|" * len(PHASES)]
    for a in composed:
        lines.append(f"| {a['Robots']} | {host_label(a)} | {a['executor']} | "
                     + " | ".join(number(a.get(col), 2) for col in PHASE_COLUMNS) + " |")
    return lines


def host_cost_section(agg: list[dict]) -> list[str]:
    """What hosting costs per robot-tick against what the robots' own node callbacks take."""
    done = [a for a in agg if a["ok"]]
    lines = ["", "### Host cost per robot-tick", "",
             "Microseconds per robot and tick: the whole tick (µs / robot-tick), the host's share (sensing, "
             "sending, gathering, everything but the nodes' callbacks: `host_cost_per_robot_tick_us`) and the "
             "nodes' own code (`node_code_per_robot_tick_us`, CPU time); host ÷ nodes below 1 means hosting "
             "costs less than the controllers themselves.", ""]
    if not any(as_number(a.get("host_cost_per_robot_tick_us")) is not None for a in done):
        return lines + ["The runs' summaries have no host cost (a composed-sim from before it was recorded, "
                        "or no run completed)."]
    lines += ["| N | host | executor | µs / robot-tick | host µs | nodes µs | host ÷ nodes |",
              "|---:|---|---|---:|---:|---:|---:|"]
    for a in done:
        host, nodes = a.get("host_cost_per_robot_tick_us"), a.get("node_code_per_robot_tick_us")
        lines.append(f"| {a['Robots']} | {host_label(a)} | {a['executor']} | {number(a['per_robot_tick_us'], 0)} "
                     f"| {number(host, 1)} | {number(nodes, 1)} | {ratio(host, nodes)} |")
    return lines


def paper_section(experiment: str, agg: list[dict], ticks: int) -> list[str]:
    """Ours against the paper's means for this experiment: wall time and the speed-up, CPU and
    memory; then the paper's own figures. Nothing for an experiment the paper did not run."""
    files = paper_files(experiment)
    if files is None:
        return []
    single, multi = (load_paper_results(f) for f in files)
    lines = ["", "### Ours / the paper", "",
             f"The paper's means over 10 trials ({files[0]}, {files[1]}: ARGoS with the ROS 2 bridge, one "
             "process per controller, Ryzen 9 7900 with 12 cores; columns WallTime(s), CPU(%), MaxMem(kB)) "
             "against our medians. **speed-up** = the paper's wall time / ours (above 1: we are faster), "
             "against its single-threaded (1t) and 12-thread (12t) ARGoS; ÷1t, ÷12t: ours / the paper's "
             "(below 1: we need less)."]
    if ticks != 600:
        lines.append(f"**These runs had {ticks} ticks, the paper's 600: the wall-time and CPU ratios are not comparable.**")
    lines += ["", "| N | host | executor | wall s | paper 1t s | paper 12t s | speed-up 1t | speed-up 12t "
              "| CPU % | ÷1t | ÷12t | peak RSS MB | ÷1t | ÷12t |",
              "|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    compared = 0
    for a in agg:
        p1, p12 = single.get(a["Robots"], {}), multi.get(a["Robots"], {})
        if not a["ok"] or not (p1 or p12):
            continue
        compared += 1
        wall = a["WallTime(s)"]
        cells = [number(wall, 1), number(p1.get("WallTime(s)"), 1), number(p12.get("WallTime(s)"), 1),
                 speed_up(p1.get("WallTime(s)"), wall), speed_up(p12.get("WallTime(s)"), wall)]
        for col, digits, scale in (("CPU(%)", 0, 1.0), ("MaxMem(kB)", 0, 1 / 1024)):
            cells += [number(a[col], digits, scale), ratio(a[col], p1.get(col)), ratio(a[col], p12.get(col))]
        lines.append(f"| {a['Robots']} | {host_label(a)} | {a['executor']} | " + " | ".join(cells) + " |")
    if not compared:
        lines.append("| – | no swarm size of this sweep is in the paper's results |" + " |" * 12)
    lines += ["", "The paper's own numbers, for reference:", "",
              "| N | wall s 1t | wall s 12t | CPU % 1t | CPU % 12t | peak MB 1t | peak MB 12t |",
              "|---:|---:|---:|---:|---:|---:|---:|"]
    for n in sorted(set(single) | set(multi)):
        p1, p12 = single.get(n, {}), multi.get(n, {})
        lines.append(f"| {n} | {number(p1.get('WallTime(s)'), 1)} | {number(p12.get('WallTime(s)'), 1)} | "
                     f"{number(p1.get('CPU(%)'), 0)} | {number(p12.get('CPU(%)'), 0)} | "
                     f"{number(p1.get('MaxMem(kB)'), 0, 1 / 1024)} | {number(p12.get('MaxMem(kB)'), 0, 1 / 1024)} |")
    return lines


def speed_up(theirs, ours) -> str:
    """The paper's time / ours, as "12.3×"."""
    x, y = as_number(theirs), as_number(ours)
    return MISSING if x is None or not y else f"{x / y:,.1f}×"
