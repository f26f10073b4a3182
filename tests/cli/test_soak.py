"""Soak: a long run keeps flat memory, in the main process and in every worker: nothing grows per
tick (the trajectories, metrics and violations go to --out as the run goes: outputs/stream.py).
Behind the ``slow`` marker (about 3 minutes here): ``pytest -m slow tests/cli/test_soak.py``."""
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
ROBOTS, TICKS = 320, 6000
FROM_TICK = 600          # allocator pools and caches are warm
BAR_MB = 5.0             # growth allowed over the rest of the run, per process


@pytest.mark.slow
def test_memory_is_flat_over_a_long_run(tmp_path):
    r = subprocess.run([sys.executable, "-m", "composed_sim.cli", "run", str(ROOT / "worlds" / "flocking.yaml"),
                        "--robots", str(ROBOTS), "--ticks", str(TICKS), "--out", str(tmp_path), "--no-progress",
                        "--no-picture", "--workers", "2", "--json"],
                       cwd=ROOT, capture_output=True, text=True, timeout=3600)
    assert r.returncode == 0, r.stderr[-3000:]
    summary = json.loads(r.stdout)
    assert summary["ticks"] == TICKS and summary["violations"] == 0
    main = summary["rss_mb_by_tick"]
    workers = summary["workers_rss_mb_by_tick"]
    assert main[-1][0] == workers[-1][0] == TICKS and len(workers[-1][1]) == 2
    growth = {"main": _growth(main)}
    growth.update({f"worker {k}": _growth([(t, mbs[k]) for t, mbs in workers]) for k in range(2)})
    print(f"{ROBOTS} robots, ticks {FROM_TICK}..{TICKS}: growth "
          + ", ".join(f"{who} {mb:.1f} MB ({1000 * mb / (TICKS - FROM_TICK):.2f} per 1000 ticks)"
                      for who, mb in growth.items()))
    assert all(mb < BAR_MB for mb in growth.values()), (growth, main, workers)


def _growth(samples) -> float:
    """Resident MB at the end less the first sample from FROM_TICK on."""
    (_, start), (_, end) = next(s for s in samples if s[0] >= FROM_TICK), samples[-1]
    return end - start
