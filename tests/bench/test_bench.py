"""The benchmark command: a tiny real sweep through the CLI, the process-tree measurement on a
known tree, the skip rule, the domain blocks and the paper's results as shipped."""
import csv
import json
import statistics
import subprocess
import sys
import textwrap

import pytest

from composed_sim import bench
from composed_sim.cli import main

PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def tiny_sweep(tmp_path_factory):
    """3 and 5 robots, 20 ticks, 1 trial, composed mode, two executors: four real runs."""
    import os
    tmp = tmp_path_factory.mktemp("bench")
    out, report = tmp / "results", tmp / "docs" / "bench.md"
    code = main(["bench", "--sizes", "5,3", "--ticks", "20", "--trials", "1", "--modes", "composed",
                 "--executors", "multi-threaded,events", "--timeout", "120", "--out", str(out),
                 "--report", str(report), "--domain-id", os.environ["ROS_DOMAIN_ID"]])
    return code, out, report


def test_tiny_sweep_writes_csv_json_figures_and_report(tiny_sweep):
    code, out, report = tiny_sweep
    assert code == 0
    with open(out / "runs.csv", newline="") as f:
        reader = csv.DictReader(f)
        assert tuple(reader.fieldnames) == bench.COLUMNS
        rows = list(reader)
    assert bench.COLUMNS[:5] == ("Robots", "Repetition", "WallTime(s)", "CPU(%)", "MaxMem(kB)")
    assert [(r["Robots"], r["executor"]) for r in rows] == [
        ("3", "multi-threaded"), ("3", "events"), ("5", "multi-threaded"), ("5", "events")]
    for r in rows:
        assert r["status"] == "ok", r["reason"]
        assert r["mode"] == "composed" and r["ticks"] == "20" and r["Repetition"] == "1"
        wall, setup, ticks_wall = float(r["WallTime(s)"]), float(r["setup_s"]), float(r["ticks_wall_s"])
        assert 0 < setup + ticks_wall < wall == float(r["total_wall_s"])
        cpu = float(r["CPU(%)"])
        # CPU % is rounded to 0.1, cpu_core_s and the wall time to 1 ms: that much apart, no more.
        rounding = 0.05 + (100 + cpu) * 0.0005 / wall
        assert cpu == pytest.approx(100 * float(r["cpu_core_s"]) / wall, abs=rounding)
        assert 0 < float(r["cpu_core_s"])
        assert 50_000 < int(r["MaxMem(kB)"]) < 2_000_000         # an rclpy process: tens to hundreds of MB
        assert 0 < int(r["MaxPss(kB)"]) <= int(r["MaxMem(kB)"])  # shared pages split: at most the RSS
        assert r["workers"] == "auto" and r["workers_used"] == "1"   # 3 and 5 robots: one process
        assert float(r["real_time_factor"]) == pytest.approx(2.0 / ticks_wall, rel=1e-3)
        assert r["violations"] == "0"
    assert len({r["domain_id"] for r in rows[:2]}) == 2             # consecutive runs: other domains

    doc = json.loads((out / "runs.json").read_text())
    assert len(doc["rows"]) == len(rows)
    for j, c in zip(doc["rows"], rows):
        assert j["Robots"] == int(c["Robots"]) and j["executor"] == c["executor"] and j["status"] == c["status"]
        assert j["WallTime(s)"] == float(c["WallTime(s)"]) and j["MaxMem(kB)"] == int(c["MaxMem(kB)"])
    machine = doc["machine"]
    assert machine["cpu_model"] and machine["logical_cores"] >= 1 and machine["memory_total_mb"] > 0
    assert machine["versions"]["python"] and doc["command"].startswith("composed-sim bench --sizes 3,5 ")

    for name in ("wall_time.png", "cpu.png", "memory.png"):
        data = (out / name).read_bytes()
        assert data[:8] == PNG and len(data) > 5000, name
    text = report.read_text()
    assert "| N | host | executor |" in text and "peak tree PSS MB" in text
    assert "| 3 | composed, workers auto (1) | events | 1/1 |" in text
    assert "| 5 | composed, workers auto (1) | multi-threaded | 1/1 |" in text
    assert "AMD" in text or machine["cpu_model"] in text
    for name in ("bench_wall_time.png", "bench_cpu.png", "bench_memory.png"):
        assert f"](figures/{name})" in text
        assert (report.parent / "figures" / name).read_bytes()[:8] == PNG


def test_replot_redraws_from_the_stored_rows(tiny_sweep, tmp_path):
    _, out, _ = tiny_sweep
    report = tmp_path / "again.md"
    assert main(["bench", "--replot", str(out / "runs.json"), "--out", str(tmp_path / "figs"),
                 "--report", str(report)]) == 0
    assert (tmp_path / "figs" / "cpu.png").read_bytes()[:8] == PNG
    assert "| 5 | composed, workers auto (1) | events | 1/1 |" in report.read_text()


def test_replot_joins_sweeps_run_apart_and_refuses_different_tick_counts(tiny_sweep, tmp_path, capsys):
    _, out, _ = tiny_sweep
    doc = json.loads((out / "runs.json").read_text())
    parts = []
    for executor in ("multi-threaded", "events"):      # as if each executor had been swept apart
        part = {**doc, "command": f"composed-sim bench --executors {executor}",
                "settings": {**doc["settings"], "executors": [executor]},
                "rows": [r for r in doc["rows"] if r["executor"] == executor]}
        parts.append(tmp_path / f"{executor}.json")
        parts[-1].write_text(json.dumps(part))
    report = tmp_path / "joined.md"
    assert main(["bench", "--replot", *map(str, parts), "--out", str(tmp_path / "figs"), "--report", str(report)]) == 0
    text = report.read_text()
    assert "composed-sim bench --executors multi-threaded\ncomposed-sim bench --executors events" in text
    assert "| 5 | composed, workers auto (1) | multi-threaded | 1/1 |" in text
    assert "| 3 | composed, workers auto (1) | events | 1/1 |" in text
    joined = json.loads((tmp_path / "figs" / "runs.json").read_text())
    assert len(joined["rows"]) == len(doc["rows"]) and joined["settings"]["executors"] == ["multi-threaded", "events"]

    capsys.readouterr()
    other = json.loads(parts[1].read_text())
    other["settings"]["ticks"] = 600
    parts[1].write_text(json.dumps(other))
    assert main(["bench", "--replot", *map(str, parts), "--out", str(tmp_path / "figs2")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "different tick counts (20, 600)" in err[0]


def test_a_run_that_cannot_start_is_a_failed_row_not_a_crash(tmp_path, domain_id, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text(textwrap.dedent("""\
        name: no-such-controller
        robots:
          - model: foot-bot
            count: 2
            controller: not-a-plugin
        """))
    code = main(["bench", "--world", str(bad), "--sizes", "2", "--ticks", "5", "--trials", "1",
                 "--modes", "composed", "--executors", "events", "--out", str(tmp_path / "o"),
                 "--domain-id", str(domain_id)])
    assert code == 1
    (row,) = json.loads((tmp_path / "o" / "runs.json").read_text())["rows"]
    assert row["status"] == "failed" and row["exit_code"] == 2 and "not-a-plugin" in row["reason"]
    assert "failed" in capsys.readouterr().err


def test_bad_sizes_are_a_usage_error(capsys):
    with pytest.raises(SystemExit) as e:
        main(["bench", "--sizes", "3,x"])
    assert e.value.code == 2 and "'x'" in capsys.readouterr().err


def test_measure_tree_counts_children_cpu_and_memory(tmp_path):
    script = tmp_path / "tree.py"
    script.write_text(textwrap.dedent("""\
        import subprocess, sys
        CHILD = ("import time\\nb = bytearray(60 * 2**20)\\nfor i in range(0, len(b), 4096): b[i] = 1\\n"
                 "t = time.process_time()\\nwhile time.process_time() - t < 0.4: pass\\ntime.sleep(0.6)\\n")
        kids = [subprocess.Popen([sys.executable, "-c", CHILD]) for _ in range(3)]
        for k in kids:
            k.wait()
        print('{"ticks": 0}')
        """))
    m = bench.measure_tree([sys.executable, str(script)], env={}, timeout_s=30)
    assert m.exit_code == 0 and not m.timed_out and bench.parse_summary(m.stdout) == {"ticks": 0}
    assert m.max_processes == 4
    assert m.cpu_core_s >= 3 * 0.4                          # children's busy loops, exited before the root
    assert m.peak_others_rss_kb >= 3 * 60 * 1024            # three 60 MB children at once
    assert m.peak_tree_rss_kb >= m.peak_others_rss_kb + m.peak_root_rss_kb - 1024
    assert m.root_cpu_s < m.cpu_core_s


def test_measure_tree_stops_a_run_over_its_timeout_and_ends_leftovers(tmp_path):
    import psutil
    script = tmp_path / "linger.py"
    script.write_text("import subprocess, sys, time\n"
                      "child = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)'])\n"
                      "print(child.pid, flush=True)\n"
                      "time.sleep(60)\n")
    m = bench.measure_tree([sys.executable, str(script)], env={}, timeout_s=1.0, leftover_grace_s=0.5)
    assert m.timed_out and m.exit_code != 0 and m.wall_s < 10
    assert m.leftovers_killed == 1                          # the child outlived the root: ended by pid
    assert not psutil.pid_exists(int(m.stdout.split()[0])) or \
        psutil.Process(int(m.stdout.split()[0])).status() == psutil.STATUS_ZOMBIE


def test_skip_rule():
    assert bench.skip_reason(70.0, 160, 24_000) is None                 # 11.2 GB of 19.2 GB allowed
    reason = bench.skip_reason(70.0, 320, 24_000)                       # 22.4 GB > 0.8 × 24 GB
    assert reason and "320" in reason and "22400 MB" in reason and "24000 MB" in reason
    assert bench.skip_reason(70.0, 270, 24_000, base_mb=200) is None    # 19.1 GB ≤ 19.2 GB
    assert bench.skip_reason(70.0, 272, 24_000, base_mb=200) is not None
    assert bench.skip_reason(70.0, 100, 10_000, fraction=0.5) is not None
    with pytest.raises(ValueError):
        bench.skip_reason(70.0, 0, 24_000)


def test_domain_blocks_alternate_and_never_overlap_the_previous_run():
    alloc = bench.DomainAllocator(10)
    starts = [alloc.take(1) for _ in range(4)]
    assert starts == [10, 11, 10, 11]
    alloc = bench.DomainAllocator(0)
    blocks = [(alloc.take(w), w) for w in (1, 26, 26, 2, 26)]
    for (a, wa), (b, wb) in zip(blocks, blocks[1:]):
        assert not set(range(a, a + wa)) & set(range(b, b + wb))
    assert all(s + w - 1 <= bench.SAFE_DOMAIN_MAX for s, w in blocks)
    assert bench.DomainAllocator(90).take(26) is None                   # 90 + 26 > 101
    assert bench.domains_needed("multi-process", 1280, None) == 26
    assert bench.domains_needed("composed", 1280, None) == 1


def test_paper_results_ship_with_the_package_and_average_the_trials():
    single, multi = bench.load_paper_results("flocking.csv"), bench.load_paper_results("flocking_mt.csv")
    # The paper's CSVs at N = 1280, ten trials each (supplementary material of the paper).
    walls_1t = [6134.36, 6091.64, 6007.09, 6089.26, 6073.64, 6066.64, 6115.43, 6100.19, 6163.52, 6105.80]
    walls_12t = [2606.37, 2590.05, 2600.24, 2593.41, 2594.38, 2570.48, 2608.99, 2584.21, 2604.92, 2596.24]
    assert single[1280]["trials"] == 10 and single[1280]["WallTime(s)"] == pytest.approx(statistics.fmean(walls_1t))
    assert multi[1280]["WallTime(s)"] == pytest.approx(statistics.fmean(walls_12t))
    assert single[1280]["CPU(%)"] == pytest.approx(654.2)
    assert multi[1280]["MaxMem(kB)"] == pytest.approx(3_281_301.0)
    assert sorted(multi) == [10, 20, 40, 80, 160, 320, 640, 1280] and 160 not in single
    assert (bench.paper_results_dir() / "README.md").is_file()


def test_the_rclpy_floor_makes_the_exchange_calls_and_finds_every_message(domain_id):
    """python -m composed_sim.bench.rclpy_floor: the flocking exchange's rclpy calls alone, per size; it
    fails if a take comes back empty (then it would not be what composed mode does)."""
    r = subprocess.run([sys.executable, "-m", "composed_sim.bench.rclpy_floor", "--robots", "3,5", "--ticks", "5",
                        "--domain-id", str(domain_id)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    rows = [json.loads(line) for line in r.stdout.splitlines()]
    assert [(row["robots"], row["ticks"], row["blobs"]) for row in rows] == [(3, 5, 50), (5, 5, 50)]
    for row in rows:
        assert row["us_per_robot_tick"] > 0
        assert row["s_per_600_ticks"] == pytest.approx(600 * row["robots"] * row["us_per_robot_tick"] * 1e-6, abs=0.1)
