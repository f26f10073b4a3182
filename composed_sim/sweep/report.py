"""What a sweep writes: runs.csv (one row per run), metrics.csv (every run's per-tick metrics) and
one plot per final metric against each swept value, the mean and spread over seeds."""
from __future__ import annotations

import csv
import math
from pathlib import Path

RUNS = "runs.csv"
METRICS = "metrics.csv"


def write_tables(out_dir: Path, rows: list[dict], swept: list[str]) -> None:
    """runs.csv and metrics.csv, rows in the grid's order (by run name within equal values)."""
    rows = sorted(rows, key=lambda r: tuple(_key(r.get(k)) for k in swept))
    columns = list(dict.fromkeys(["run", *swept, *(k for r in rows for k in r if not k.startswith("_"))]))
    _write_csv(out_dir / RUNS, columns, rows)
    per_tick = [{"run": r["run"], **{k: r.get(k) for k in swept}, **m} for r in rows for m in r.get("_metrics", [])]
    if per_tick:
        _write_csv(out_dir / METRICS, list(dict.fromkeys(k for m in per_tick for k in m)), per_tick)


def _write_csv(path: Path, columns: list[str], rows: list[dict]) -> None:
    part = path.with_name(path.name + ".part")
    with open(part, "w", newline="") as f:
        w = csv.DictWriter(f, columns, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    part.replace(path)


def _key(value):
    return (0, value) if isinstance(value, (int, float)) else (1, str(value))


def final_metrics(rows: list[dict]) -> list[str]:
    return list(dict.fromkeys(k for r in rows for k in r if k.startswith("final_")))


def aggregate(rows: list[dict], metric: str, axis: str, others: list[str]) -> dict[tuple, list[tuple]]:
    """{values of the other swept fields: [(axis value, mean, standard deviation, runs), ...]} over the
    seeds of the successful runs."""
    groups: dict[tuple, dict] = {}
    for r in rows:
        value = r.get(metric)
        if r.get("status") != "ok" or not isinstance(value, (int, float)) or math.isnan(value):
            continue
        groups.setdefault(tuple(r.get(k) for k in others), {}).setdefault(r.get(axis), []).append(float(value))
    out = {}
    for label, by_x in groups.items():
        points = []
        for x in sorted(by_x, key=_key):
            v = by_x[x]
            mean = sum(v) / len(v)
            std = math.sqrt(sum((a - mean) ** 2 for a in v) / (len(v) - 1)) if len(v) > 1 else 0.0
            points.append((x, mean, std, len(v)))
        out[label] = points
    return out


def plot(out_dir: Path, rows: list[dict], swept: list[str]) -> list[Path]:
    """One PNG per final metric and swept field (seeds excepted: they are the spread), a line per
    combination of the other swept fields, mean ± one standard deviation over seeds."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    axes = [k for k in swept if k != "seed" and len({str(r.get(k)) for r in rows}) > 1]
    written = []
    for metric in final_metrics(rows):
        for axis in axes:
            others = [k for k in axes if k != axis]
            series = aggregate(rows, metric, axis, others)
            if not series:
                continue
            fig, ax = plt.subplots(figsize=(5, 3.5), dpi=100)
            numeric = all(isinstance(x, (int, float)) for pts in series.values() for x, *_ in pts)
            for label, pts in series.items():
                xs = [p[0] if numeric else str(p[0]) for p in pts]
                ax.errorbar(xs, [p[1] for p in pts], yerr=[p[2] for p in pts], marker="o", capsize=3,
                            label=", ".join(f"{k.rsplit('.', 1)[-1]}={v}" for k, v in zip(others, label)) or None)
            seeds = max(p[3] for pts in series.values() for p in pts)
            ax.set_xlabel(axis)
            ax.set_ylabel(metric.removeprefix("final_"))
            ax.set_title(f"{metric.removeprefix('final_')}: mean ± sd over {seeds} seed{'s' if seeds > 1 else ''}",
                         fontsize=10)
            if others:
                ax.legend(fontsize=8)
            fig.tight_layout()
            path = out_dir / f"{metric.removeprefix('final_')}_vs_{axis.rsplit('.', 1)[-1]}.png"
            fig.savefig(path)
            plt.close(fig)
            written.append(path)
    return written
