"""Soak: a long run keeps flat memory; nothing grows per tick except the trajectory buffer.
Behind the ``slow`` marker (about 10 minutes here): ``pytest -m slow tests/cli/test_soak.py``."""
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
ROBOTS, TICKS = 320, 6000
# positions [T+1, n, 2] and headings [T+1, n] float64, LED colours [T+1, n, 3] uint8: pages of the
# preallocated buffer become resident as the rows are written.
BUFFER_BYTES_PER_ROBOT_TICK = 2 * 8 + 8 + 3


@pytest.mark.slow
def test_memory_is_flat_over_a_long_run(tmp_path):
    r = subprocess.run([sys.executable, "-m", "composed_sim.cli", "run", str(ROOT / "worlds" / "flocking.yaml"),
                        "--robots", str(ROBOTS), "--ticks", str(TICKS), "--out", str(tmp_path), "--no-progress",
                        "--no-picture", "--json"], cwd=ROOT, capture_output=True, text=True, timeout=3600)
    assert r.returncode == 0, r.stderr[-3000:]
    summary = json.loads(r.stdout)
    assert summary["ticks"] == TICKS and summary["violations"] == 0
    samples = summary["rss_mb_by_tick"]
    # From tick 600 on (allocator pools and caches are warm) to the end.
    (t0, mb0), (t1, mb1) = next(s for s in samples if s[0] >= 600), samples[-1]
    buffer_mb = (t1 - t0) * ROBOTS * BUFFER_BYTES_PER_ROBOT_TICK / 2**20
    growth_mb = mb1 - mb0 - buffer_mb
    print(f"{ROBOTS} robots, ticks {t0}..{t1}: RSS {mb0:.1f} -> {mb1:.1f} MB, trajectory buffer {buffer_mb:.1f} MB, "
          f"other growth {growth_mb:.1f} MB ({1000 * growth_mb / (t1 - t0):.2f} MB per 1000 ticks)")
    assert growth_mb < 10.0, samples
