"""The physics-only bench (composed_sim/bench/physics_step.py): a row per engine and size."""
import json

from composed_sim.bench import physics_step


def test_the_physics_bench_reports_each_engine_per_size(tmp_path, capsys):
    out = tmp_path / "physics.json"
    assert physics_step.main(["--robots", "40,3000", "--regions", "1,2", "--processes", "2", "--ticks", "1",
                              "--warmup", "0",
                              "--single-space-up-to", "40", "--out", str(out)]) == 0
    doc = json.loads(out.read_text())
    rows = [(r["robots"], r["engine"], r["cells"], r["regions"]) for r in doc["rows"]]
    assert rows == [(40, "one space", 1, 1), (40, "cells, one process", 1, 1), (40, "2 regions", 2, 2),
                    (40, "cells, 2 processes", 1, 1),
                    (3000, "cells, one process", 4, 1), (3000, "2 regions", 2, 2), (3000, "cells, 2 processes", 4, 1)]
    assert all(r["ms_per_tick"] > 0 and r["us_per_robot"] > 0 for r in doc["rows"])
    assert doc["machine"]["cpu_model"] and "| 3000 | 2 regions | 2 |" in capsys.readouterr().out
