"""The bench's figures: wall time, CPU and memory against N on log-log axes, one set per
experiment, with the paper's means where the paper ran that experiment (its Figure 5)."""
from __future__ import annotations

from pathlib import Path

from composed_sim.bench.experiments import PAPER_LABELS, paper_files
from composed_sim.bench.rules import FIGURES, aggregate, host_label, load_paper_results, saturated


def figure_name(kind: str, experiment: str, experiments: list[str]) -> str:
    """wall_time.png for a sweep of one experiment (as before experiments), else
    synchronization_wall_time.png and so on."""
    return FIGURES[kind] if len(experiments) <= 1 else f"{experiment}_{FIGURES[kind]}"


def _series_style(mode: str, workers: str, executor: str) -> dict:
    """Colour by executor; composed in one process solid, with workers dash-dotted, multi-process dashed."""
    colors = {"multi-threaded": "tab:blue", "single-threaded": "tab:orange", "events": "tab:green",
              "lockstep": "tab:red"}
    one_process = mode == "composed" and workers in ("", "1")
    linestyle = "-" if one_process else "-." if mode == "composed" else "--"
    return {"color": colors.get(executor, "tab:purple"), "linestyle": linestyle,
            "marker": "o" if one_process else "D" if mode == "composed" else "s"}


def plot_figures(doc: dict, out: Path) -> dict[tuple[str, str], Path]:
    """(experiment, kind) → the figure written into ``out``: medians of our ok runs per host and
    executor and the paper's means, against N on log-log axes."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    settings, machine = doc.get("settings", {}), doc["machine"]
    agg = aggregate(doc["rows"], settings)
    experiments = list(dict.fromkeys(a["experiment"] for a in agg))
    ticks = settings.get("ticks", 600)
    sim_s = ticks * settings.get("tick_s", 0.1)
    cores = machine.get("logical_cores") or 0
    footer = (f"this machine: {machine.get('cpu_model')}, {machine.get('logical_cores')} logical cores, "
              f"{machine.get('memory_total_mb', 0) / 1024:.0f} GB, {machine.get('date', '')[:10]}; "
              f"{ticks} ticks per run; median of ok trials.  Paper: mean of 10 trials, 600 ticks, "
              f"12-core Ryzen 9 7900")
    specs = {
        "wall_time": ("WallTime(s)", 1.0, "wall time (s)", f"wall time of {sim_s:g} s of simulated time"),
        "cpu": ("CPU(%)", 1.0, "CPU (% of one core)", "CPU use of the whole process tree"),
        "memory": ("MaxPss(kB)", 1 / 1024, "peak PSS (MB)", "peak memory of the whole process tree (PSS)"),
    }
    written = {}
    for experiment in experiments:
        files = paper_files(experiment)
        paper = [load_paper_results(f) for f in files] if files else []
        rows = [a for a in agg if a["experiment"] == experiment]
        for key, (col, scale, ylabel, title) in specs.items():
            fig, ax = plt.subplots(figsize=(7.5, 5.2), dpi=110)
            for i, (means, label) in enumerate(zip(paper, PAPER_LABELS)):
                ns = sorted(means)
                paper_col = "MaxMem(kB)" if col == "MaxPss(kB)" else col     # the paper measured RSS
                ax.plot(ns, [means[n][paper_col] * scale for n in ns], color="black" if i == 0 else "dimgrey",
                        linestyle=":", marker="^" if i == 0 else "v", label=label)
            _plot_ours(ax, rows, col, scale, cores)
            if key == "wall_time":
                ax.axhline(sim_s, color="black", linestyle="--", linewidth=1, label=f"real time ({sim_s:g} s)")
            if key == "memory" and machine.get("memory_total_mb"):
                ax.axhline(machine["memory_total_mb"], color="firebrick", linestyle="-.", linewidth=0.8,
                           label="this machine's memory")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel("robots N")
            ax.set_ylabel(ylabel)
            ax.set_title(f"{experiment}: {title}")
            ax.grid(True, which="both", alpha=0.3)
            if ax.get_legend_handles_labels()[0]:      # nothing to name when no run of it completed
                ax.legend(fontsize=7, loc="upper left")
            fig.text(0.01, 0.005, footer, fontsize=5.5, color="dimgrey")
            fig.tight_layout(rect=(0, 0.03, 1, 1))
            path = out / figure_name(key, experiment, experiments)
            fig.savefig(path)
            plt.close(fig)
            written[(experiment, key)] = path
    return written


def _plot_ours(ax, agg: list[dict], col: str, scale: float, cores: int) -> None:
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
