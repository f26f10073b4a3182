"""What a user sees of their nodes' logs and exceptions (hosting/guard/node_logs.py): each robot's lines in
OUT/logs/<robot>.log stamped with sim time and tick, the console's share once per node class and
call site with a count, a failing callback's traceback (the user's file and line) in the robot's
log and once on the console, --fail-fast, and /rosout in a recording. The test node is
tests/plugin_pkg/chatty.py, named in the world file as ``chatty:Chatty``."""
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from composed_sim.hosting.guard.node_logs import INFO, WARN, LogSettings, NodeLogs

ROOT = Path(__file__).resolve().parents[2]
PLUGINS = ROOT / "tests" / "plugin_pkg"
RAISING_LINE = next(i for i, line in enumerate((PLUGINS / "chatty.py").read_text().splitlines(), 1)
                    if "RAISES HERE" in line)
WARNING_LINE = next(i for i, line in enumerate((PLUGINS / "chatty.py").read_text().splitlines(), 1)
                    if "battery low on" in line)


def chat_world(tmp_path, robots=4, ticks=12, **parameters) -> Path:
    world = {"name": "chat", "seed": 1, "length_ticks": ticks,
             "robots": [{"count": robots, "nodes": [{"node": "chatty:Chatty", "parameters": parameters}],
                         "placement": {"method": "grid", "spacing_m": 1.5}}]}
    path = tmp_path / "chat.yaml"
    path.write_text(yaml.safe_dump(world))
    return path


def cli(*args, timeout=300):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(PLUGINS), os.environ.get("PYTHONPATH")]))}
    return subprocess.run([sys.executable, "-m", "composed_sim.cli", *map(str, args)], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=timeout)


MODES = {"composed": ["--workers", "1"], "workers": ["--workers", "2"], "multi-process": ["--mode", "multi-process"]}


@pytest.mark.parametrize("mode", list(MODES))
def test_a_raising_node_shows_its_traceback_once_and_every_robot_keeps_its_log(tmp_path, mode, mp_domain):
    out = tmp_path / "out"
    world = chat_world(tmp_path, warn_from=3, raise_robots="bot1,bot2", raise_at=5)
    domain = ["--domain-id", str(mp_domain)] if mode == "multi-process" else []
    run = cli("run", world, "--out", out, "--no-progress", "--no-picture", *MODES[mode], *domain)
    assert run.returncode == 0, run.stderr
    err = run.stderr
    # The console: the traceback once, naming the user's file and line, then a count.
    assert err.count("Traceback (most recent call last)") == 1, err
    assert f'chatty.py", line {RAISING_LINE}, in ratio' in err
    assert re.search(r"composed-sim: bot[12]: a node \(chatty:Chatty\) raised ZeroDivisionError at tick 5", err), err
    assert re.search(r"composed-sim: ZeroDivisionError in chatty:Chatty: 1 more robot \(bot[12]\), "
                     rf"see {re.escape(str(out))}/logs/<robot>\.log", err), err
    assert f"controllers failed: 2 of 4 robots (ZeroDivisionError in chatty:Chatty: 2); see {out}/logs/" in run.stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["failed_robots"] == ["bot1", "bot2"]
    assert summary["failed_by"] == {"ZeroDivisionError in chatty:Chatty": 2}
    assert summary["logs"] == str(out / "logs")
    # Each failed robot's log: its lines, then the whole traceback.
    for robot in ("bot1", "bot2"):
        text = (out / "logs" / f"{robot}.log").read_text()
        assert f"[ERROR] [sim 0.500 s, tick 5] [{robot}.chatty]: callback raised ZeroDivisionError; {robot} is failed" \
            in text, text
        assert f'chatty.py", line {RAISING_LINE}, in ratio' in text
        assert text.rstrip().endswith("ZeroDivisionError: float division by zero")
    # Every robot's log lines, stamped; INFO is not on the console.
    for robot in ("bot0", "bot3"):
        lines = (out / "logs" / f"{robot}.log").read_text().splitlines()
        assert lines[0] == f"[INFO] [set-up] [{robot}.chatty]: {robot} ready"
        for tick in range(12):
            assert f"[INFO] [sim {tick / 10:.3f} s, tick {tick}] [{robot}.chatty]: scan {tick} of {robot}" in lines
        assert f"[WARN] [sim 0.300 s, tick 3] [{robot}.chatty]: battery low on {robot}" in lines
    assert "scan 3 of" not in err
    # The warning once (per node class and call site), its repeats counted at the end (a
    # controller process sends its part with its robot's part of the tick).
    assert len(re.findall(r"\[WARN\] \[bot\d\.chatty\] \(chatty:Chatty, sim 0\.300 s, tick 3\): battery low", err)) == 1
    # bot0 and bot3 warn at ticks 3 … 11, bot1 and bot2 at 3 … 5: 24 in all, one shown.
    assert re.search(rf"\[WARN\] chatty:Chatty at chatty\.py:{WARNING_LINE}: 23 more times from 4 robots after "
                     r"'battery low on bot\d'", err), err


@pytest.mark.parametrize("mode", list(MODES))
def test_a_traceback_starts_at_the_nodes_own_code(tmp_path, mode, mp_domain):
    """The host's frames before the node's (the callback guard, the sim timers, a controller
    process's executor loop) are left out, by the paths of the files they are in."""
    world = chat_world(tmp_path, robots=2, ticks=7, raise_robots="bot1", raise_at=5)
    domain = ["--domain-id", str(mp_domain)] if mode == "multi-process" else []
    run = cli("run", world, "--out", tmp_path / "out", "--no-progress", "--no-picture", *MODES[mode], *domain)
    assert run.returncode == 0, run.stderr
    for text in (run.stderr, (tmp_path / "out" / "logs" / "bot1.log").read_text()):
        first_frame = text.split("Traceback (most recent call last):\n", 1)[1].splitlines()[0]
        assert first_frame.strip().startswith(f'File "{PLUGINS / "chatty.py"}"'), text


def test_fail_fast_stops_at_the_first_failure_with_exit_1(tmp_path):
    out = tmp_path / "out"
    world = chat_world(tmp_path, ticks=30, raise_robots="bot2", raise_at=4, log_every_scan=False)
    run = cli("run", world, "--out", out, "--no-progress", "--no-picture", "--workers", "1", "--fail-fast")
    assert run.returncode == 1, run.stderr
    assert ("composed-sim: --fail-fast: bot2: controller failed: callback raised ZeroDivisionError: float division "
            f"by zero; stopped at tick 5, results so far in {out}/") in run.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["ticks"] == 5 and summary["failed_robots"] == ["bot2"]
    assert summary["stopped_by_fail_fast"].startswith("bot2: controller failed")
    assert f'chatty.py", line {RAISING_LINE}' in (out / "logs" / "bot2.log").read_text()


@pytest.mark.parametrize("mode", ["workers", "multi-process"])
def test_log_level_debug_and_rosout_in_the_recording(tmp_path, mode, mp_domain):
    out, bag = tmp_path / "out", tmp_path / "bag"
    world = chat_world(tmp_path, robots=2, ticks=4, child=True, warn_from=2)
    domain = ["--domain-id", str(mp_domain)] if mode == "multi-process" else []
    run = cli("run", world, "--out", out, "--no-progress", "--no-picture", *MODES[mode], *domain, "--log-level",
              "debug", "--record", bag)
    assert run.returncode == 0, run.stderr
    # The console shows each call site once per node class, debug included (child loggers too).
    assert len(re.findall(r"\[DEBUG\] \[bot\d\.chatty\.planner\] \(chatty:Chatty, sim 0\.000 s, tick 0\): planning 0",
                          run.stderr)) == 1, run.stderr
    assert len(re.findall(r"\): scan \d of bot\d", run.stderr)) == 1
    log = (out / "logs" / "bot1.log").read_text()
    assert "[DEBUG] [sim 0.200 s, tick 2] [bot1.chatty.planner]: planning 2" in log
    # /rosout: every line, as rcl_interfaces/msg/Log, stamped with sim time.
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        connections = [c for c in reader.connections if c.topic == "/rosout"]
        assert connections and connections[0].msgtype == "rcl_interfaces/msg/Log"
        logs = [(ns, reader.deserialize(raw, c.msgtype)) for c, ns, raw in reader.messages(connections=connections)]
    warnings = [(ns, m) for ns, m in logs if m.level == WARN]
    assert {(ns, m.name, m.msg) for ns, m in warnings} == {
        (t * 100_000_000, f"bot{r}.chatty", f"battery low on bot{r}") for r in (0, 1) for t in (2, 3)}
    assert all(m.file.endswith("chatty.py") and m.line == WARNING_LINE for _, m in warnings)
    assert sum(m.level == INFO and m.name == "bot0.chatty" for _, m in logs) == 5    # ready + 4 scans


class Node:       # stands for a node class in the logger's own tests
    pass


def test_the_logger_keeps_rclpy_semantics_levels_children_and_filters(tmp_path, capsys):
    from rclpy.logging import LoggingSeverity
    logs = NodeLogs(LogSettings(str(tmp_path)), 100_000_000)
    log = logs.logger("bot0", Node, "bot0.node")
    logs.tick = 7
    assert log.debug("hidden") is False and log.info("shown") is True
    child = log.get_child("sub")
    log.set_level(LoggingSeverity.WARN)
    assert child.get_effective_level() == LoggingSeverity.WARN and not child.is_enabled_for(LoggingSeverity.INFO)
    child.set_level(LoggingSeverity.DEBUG)
    child.debug("child debug")
    for _ in range(3):
        log.warn("once", once=True)
        log.warn("skipped first", skip_first=True)
    logs.flush()
    assert (tmp_path / "bot0.log").read_text().splitlines() == [
        "[INFO] [sim 0.700 s, tick 7] [bot0.node]: shown",
        "[DEBUG] [sim 0.700 s, tick 7] [bot0.node.sub]: child debug",
        "[WARN] [sim 0.700 s, tick 7] [bot0.node]: once",
        "[WARN] [sim 0.700 s, tick 7] [bot0.node]: skipped first",
        "[WARN] [sim 0.700 s, tick 7] [bot0.node]: skipped first"]
    err = capsys.readouterr().err      # the console: each call site once
    assert err.count("] [bot0.node] (test_node_logs:Node, sim 0.700 s, tick 7): once") == 1
    assert err.count("skipped first") == 1


def test_chatty_nodes_on_the_multi_threaded_executors_threads_keep_every_line(tmp_path):
    """rclpy's MultiThreadedExecutor runs the robots' callbacks on several threads at once, each
    logging through its child loggers: the host's logs take every line, from every thread."""
    out = tmp_path / "out"
    world = chat_world(tmp_path, robots=12, ticks=15, child=True)
    run = cli("run", world, "--out", out, "--no-progress", "--no-picture", "--executor", "multi-threaded",
              "--log-level", "info")
    assert run.returncode == 0, run.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["failed_robots"] == [] and summary["violations"] == 0, summary
    for robot in range(12):
        text = (out / "logs" / f"bot{robot}.log").read_text()
        # each tick: its scan line and its planner child's line, 15 ticks, none lost or torn
        assert [len(re.findall(rf"scan {k} of bot{robot}$", text, re.M)) for k in range(15)] == [1] * 15
        assert [len(re.findall(rf"planned {k}$", text, re.M)) for k in range(15)] == [1] * 15


def test_a_host_note_said_by_many_robots_closes_with_one_count_line(capsys):
    """The host's own notes (a node's rclpy.shutdown(), say) repeat by the robot; the closing
    report counts them instead of failing on their two-part key (it raised IndexError after the
    results were written, and the finished run exited 1)."""
    from composed_sim.hosting.guard.node_logs import Console
    logs = NodeLogs(LogSettings(None, INFO), tick_ns=100_000_000, console=Console())
    for robot in ("tb0", "tb1", "tb2"):
        logs.note(robot, "a node called rclpy.shutdown(): its robot stops")
    worker = NodeLogs(LogSettings(None, INFO), tick_ns=100_000_000, forward=True)
    for robot in ("tb3", "tb4"):
        worker.note(robot, "a node called rclpy.shutdown(): its robot stops")
    logs.merge(worker.drain())
    assert capsys.readouterr().err.count("rclpy.shutdown()") == 1
    assert logs.console.closing_lines() == [
        "composed-sim: a node called rclpy.shutdown(): its robot stops (4 more times from 5 robots)"]
