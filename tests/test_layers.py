"""The layers are checked, not hoped for: devices < world < core < ros < hosts < tools (docs/architecture.md)."""
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FLOCKING = ROOT / "worlds" / "flocking.yaml"


def test_the_import_contracts_hold():
    """import-linter's contracts in pyproject.toml: the layers, no cycles, a ROS-free core."""
    lint = Path(sys.executable).with_name("lint-imports")
    r = subprocess.run([str(lint)], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
    assert "0 broken" in r.stdout


# Run the command with rclpy made unimportable: it must not even try.
WITHOUT_RCLPY = ("import sys; sys.modules['rclpy'] = None; from composed_sim.cli import main; "
                 "sys.exit(main(sys.argv[1:]))")


@pytest.fixture(scope="module")
def recorded_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("run")
    out, bag = tmp / "out", tmp / "bag"
    r = subprocess.run([sys.executable, "-m", "composed_sim.cli", "run", str(FLOCKING), "--robots", "4",
                        "--ticks", "5", "--out", str(out), "--record", str(bag), "--no-progress", "--no-picture"],
                       cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    return tmp, out, bag


@pytest.mark.parametrize("command", ["render results", "render recording", "replay"])
def test_render_and_replay_do_not_load_ros(recorded_run, command):
    tmp, out, bag = recorded_run
    args = {"render results": ["render", str(out), "--out", str(tmp / "a.png")],
            "render recording": ["render", str(bag), "--out", str(tmp / "b.png")],
            "replay": ["replay", str(bag)]}[command]
    r = subprocess.run([sys.executable, "-c", WITHOUT_RCLPY, *args], cwd=ROOT, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]


def test_ruff_finds_nothing_and_every_noqa_says_why():
    """The linter as pyproject.toml configures it ([tool.ruff]); each `# noqa` names its rule and
    a reason ("# noqa: BLE001 - why"), so a silenced finding is a decision, not a habit."""
    import re
    ruff = Path(sys.executable).with_name("ruff")
    r = subprocess.run([str(ruff), "check", "--no-cache", "."], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
    bare = [f"{path.relative_to(ROOT)}:{n}" for folder in ("composed_sim", "controller_plugins",
                                                            "loop_function_plugins", "tests", "tools")
            for path in (ROOT / folder).rglob("*.py") if path != Path(__file__)     # its patterns are no noqa
            for n, line in enumerate(path.read_text().splitlines(), 1)
            if re.search(r"#\s*noqa(:|\s*$)", line) and not re.search(r"# noqa: [A-Z]+[0-9]+(, ?[A-Z]+[0-9]+)* [-(]", line)]
    assert bare == []
