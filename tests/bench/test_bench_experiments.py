"""``composed-sim bench --experiments``: a tiny real sweep of two experiments, the report's parts
per experiment (the paper's synchronization figures, the per-tick phases, the host cost), a
runs.json of an older bench replotted, bad input, and the plain-nodes world at the bench's sizes."""
import json
import os
from pathlib import Path

import pytest

from composed_sim import bench
from composed_sim.bench.report import render_report
from composed_sim.bench.sweep import summary_columns
from composed_sim.cli import main

ROOT = Path(__file__).resolve().parents[2]
PNG = b"\x89PNG\r\n\x1a\n"
MACHINE = {"cpu_model": "test cpu", "logical_cores": 2, "memory_total_mb": 1024, "date": "2026-11-25T00:00:00"}


@pytest.fixture(scope="module")
def two_experiments(tmp_path_factory):
    """10 robots (a size of the paper's), 10 ticks, one trial, composed in one process: two runs."""
    tmp = tmp_path_factory.mktemp("bench-experiments")
    out, report = tmp / "results", tmp / "docs" / "bench.md"
    code = main(["bench", "--experiments", "synchronization,plain-nodes", "--sizes", "10", "--ticks", "10",
                 "--trials", "1", "--modes", "composed", "--executors", "lockstep", "--workers", "1",
                 "--timeout", "120", "--out", str(out), "--report", str(report),
                 "--domain-id", os.environ["ROS_DOMAIN_ID"]])
    return code, out, report


def test_each_experiment_runs_its_world_and_gets_its_part_of_the_report(two_experiments):
    code, out, report = two_experiments
    assert code == 0
    doc = json.loads((out / "runs.json").read_text())
    assert [(r["experiment"], r["Robots"], r["status"]) for r in doc["rows"]] == [
        ("synchronization", 10, "ok"), ("plain-nodes", 10, "ok")]
    assert {k: Path(v["world"]).name for k, v in doc["settings"]["experiments"].items()} == {
        "synchronization": "firefly.yaml", "plain-nodes": "plain_nodes.yaml"}
    assert "--experiments synchronization,plain-nodes" in doc["command"]
    assert "experiment" in (out / "runs.csv").read_text().splitlines()[0].split(",")

    text = report.read_text()
    sync, plain = text.index("## synchronization"), text.index("## plain-nodes")
    assert sync < plain
    sync_part, plain_part = text[sync:plain], text[plain:text.index("## What is measured")]
    for part in (sync_part, plain_part):
        assert "| 10 | composed, 1 process | lockstep | 1/1 |" in part
        assert "### Main process, per tick" in part and "### Host cost per robot-tick" in part
    # The paper ran synchronization, not plain nodes: only the first is compared with it.
    assert "### Ours / the paper" in sync_part and "synchronization.csv" in sync_part
    assert "### Ours / the paper" not in plain_part
    paper_10 = bench.load_paper_results("synchronization.csv")[10]["WallTime(s)"]
    (row,) = [ln for ln in sync_part.splitlines() if ln.startswith("| 10 | composed, 1 process | lockstep | ")
              and "×" in ln]
    assert f"| {paper_10:,.1f} |" in row
    for name in ("synchronization_wall_time.png", "plain-nodes_memory.png"):
        assert (out / name).read_bytes()[:8] == PNG
        assert f"](figures/bench_{name})" in text


def _row(experiment, n, mode="composed", wall=10.0, **extra):
    row = {c: None for c in bench.COLUMNS}
    row.update({"experiment": experiment, "Robots": n, "Repetition": 1, "mode": mode, "executor": "lockstep",
                "workers": "1" if mode == "composed" else None, "status": "ok", "ticks": 600,
                "WallTime(s)": wall, "total_wall_s": wall, "ticks_wall_s": wall - 1, "setup_s": 1.0,
                "CPU(%)": 100.0, "MaxMem(kB)": 200_000, "cpu_core_s": wall}, **extra)
    return row


def _render(rows, tmp_path, settings=None):
    doc = {"machine": MACHINE, "settings": settings or {"ticks": 600, "modes": ["composed", "multi-process"]},
           "rows": rows}
    return render_report(doc, {}, raw=(Path("figures/r.csv"), Path("figures/r.json")), report=tmp_path / "r.md")


def test_synchronization_rows_give_the_paper_its_wall_time_and_the_speed_up(tmp_path):
    paper = bench.load_paper_results("synchronization.csv")
    paper_mt = bench.load_paper_results("synchronization_mt.csv")
    text = _render([_row("synchronization", 80, wall=4.0), _row("synchronization", 7, wall=1.0)], tmp_path)
    part = text[text.index("### Ours / the paper"):]
    (line,) = [ln for ln in part.splitlines() if ln.startswith("| 80 | composed")]
    cells = [c.strip() for c in line.strip("|").split("|")]
    assert cells[3:8] == ["4.0", f"{paper[80]['WallTime(s)']:,.1f}", f"{paper_mt[80]['WallTime(s)']:,.1f}",
                          f"{paper[80]['WallTime(s)'] / 4.0:,.1f}×", f"{paper_mt[80]['WallTime(s)'] / 4.0:,.1f}×"]
    assert not [ln for ln in part.splitlines() if ln.startswith("| 7 | composed")]   # not a size of the paper's
    assert "| 1280 |" in part                                                   # the paper's own table


def test_phases_and_host_cost_show_where_summaries_have_them(tmp_path):
    phases = {f"phase_{p}_ms": float(i) for i, p in enumerate(bench.PHASES)}
    new = _row("flocking", 80, host_cost_per_robot_tick_us=50.0, node_code_per_robot_tick_us=100.0, **phases)
    old = _row("flocking", 160)
    multi = _row("flocking", 80, mode="multi-process", wall=40.0)
    text = _render([new, old, multi], tmp_path)
    tick = text[text.index("### Main process, per tick"):text.index("### Host cost")]
    assert "| N | host | executor | physics | sensing | sending_frames | waiting | gathering_answers | " \
           "loop_functions | recording | other | serial |" in tick
    assert "| 80 | composed, 1 process | lockstep | 0.00 | 1.00 | 2.00 | 3.00 | 4.00 | 5.00 | 6.00 | 7.00 | 8.00 |" in tick
    assert "| 160 | composed, 1 process | lockstep | – | – |" in tick
    assert "multi-process" not in tick.split("\n\n", 2)[-1]     # the main-process table: composed runs only
    cost = text[text.index("### Host cost"):]
    assert "| 80 | composed, 1 process | lockstep | – | 50.0 | 100.0 | 0.50 |" in cost
    modes = text[text.index("### Composed / multi-process"):]
    assert "| 80 | composed, 1 process | lockstep | 0.25 |" in modes


def test_summary_fields_are_read_when_present_and_empty_when_not():
    newer = {"setup_s": 1.0, "ticks_wall_s": 2.0, "host_cost_per_robot_tick_us": 12.3456,
             "node_code_per_robot_tick_us": 40.0,
             "phases_per_tick_ms": {"physics": 1.5, "waiting": 3.0, "serial": 4.5}}
    cols = summary_columns(newer, "composed")
    assert cols["host_cost_per_robot_tick_us"] == 12.346 and cols["node_code_per_robot_tick_us"] == 40.0
    assert (cols["phase_physics_ms"], cols["phase_waiting_ms"], cols["phase_serial_ms"]) == (1.5, 3.0, 4.5)
    assert cols["phase_sensing_ms"] is None
    older = summary_columns({"setup_s": 1.0, "ticks_wall_s": 2.0}, "composed")
    assert all(older[c] is None for c in bench.PHASE_COLUMNS + ("host_cost_per_robot_tick_us",))


def test_an_older_runs_json_replots_as_one_flocking_experiment(tmp_path):
    # A sweep's runs.json from before experiments existed (docs/figures' of 2026-11-23).
    path = Path(__file__).parent / "data" / "runs_before_experiments.json"
    old = json.loads(path.read_text())
    assert "experiment" not in old["rows"][0] and "experiments" not in old["settings"]
    report = tmp_path / "docs" / "old.md"
    assert main(["bench", "--replot", str(path),
                 "--out", str(tmp_path / "figs"), "--report", str(report)]) == 0
    text = report.read_text()
    assert text.count("\n## flocking") == 1 and "### Against the design budget" in text
    assert "| 80 | composed, 1 process | lockstep | 1/1 | 1.18 |" in text
    assert "The runs' summaries have no per-tick phases" in text
    for name in ("wall_time.png", "cpu.png", "memory.png"):      # one experiment: the names of before
        assert (tmp_path / "figs" / name).read_bytes()[:8] == PNG


def test_an_unknown_experiment_is_one_line_naming_it_and_the_known_ones(capsys):
    with pytest.raises(SystemExit) as e:
        main(["bench", "--experiments", "flocking,swarming"])
    err = capsys.readouterr().err
    assert e.value.code == 2
    (line,) = [ln for ln in err.splitlines() if "error:" in ln]
    assert "'swarming'" in line and "flocking, synchronization, plain-nodes" in line


def test_world_and_experiments_together_are_refused(tmp_path, capsys):
    code = main(["bench", "--world", str(ROOT / "worlds" / "flocking.yaml"), "--experiments", "flocking",
                 "--out", str(tmp_path)])
    assert code == 2 and "--world and --experiments" in capsys.readouterr().err


@pytest.mark.parametrize("robots", [4, 1280])
def test_the_plain_nodes_world_places_the_bench_sizes(robots):
    from composed_sim.core.simulation import Simulation
    from composed_sim.world.loader import load_world
    world = load_world(ROOT / "worlds" / bench.EXPERIMENTS["plain-nodes"].world, robots=robots)
    assert len(Simulation(world).names) == robots
