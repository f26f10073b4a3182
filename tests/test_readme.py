"""The README's two set-up commands, checked and run as a newcomer would (.ci/run runs the second
one verbatim in a fresh venv; here the first one's simulation command runs from the repo root)."""
import json
import re
import shlex
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def readme_commands() -> list[str]:
    blocks = re.findall(r"```bash\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.S)
    return [b.strip() for b in blocks[:2]]


def test_readme_opens_with_the_two_setup_commands():
    main_job, tests = readme_commands()
    for cmd in (main_job, tests):
        assert cmd.startswith("python3.11 -m venv .venv && .venv/bin/pip install"), cmd
        assert "\n" not in cmd
    assert ".venv/bin/composed-sim run worlds/flocking.yaml" in main_job
    assert "pytest" in tests and "'.[test]'" in tests
    ci = (ROOT / ".ci" / "run").read_text()
    assert "pytest" in ci and "README.md" in ci      # CI takes its test command from the README


def test_readme_main_job_writes_a_picture_and_a_summary(tmp_path):
    main_job, _ = readme_commands()
    run = shlex.split(main_job.split("&&")[-1])
    assert run[0] == ".venv/bin/composed-sim"
    out = tmp_path / "out"
    args = run[1:]
    args[args.index("--out") + 1] = str(out)
    # The same command with this interpreter's entry point; 20 ticks instead of 600 keeps it short.
    proc = subprocess.run([sys.executable, "-m", "composed_sim.cli", *args, "--ticks", "20", "--no-progress"],
                          cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["robots"] == int(args[args.index("--robots") + 1]) and summary["ticks"] == 20
    assert summary["violations"] == 0
    assert (out / "arena.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "real-time factor" in proc.stdout and "results in" in proc.stdout
