"""Ground-truth runs, cached per program: a program's events under rclpy depend only on the program
(its spec, the tick count, ``spec.HARNESS_VERSION``), so each is run once, as part of a batch,
and kept. A program is run twice; one whose two runs differ is marked unstable (what it does then
depends on timing the rig does not control) and is not compared.

Where: ``truth/`` beside this file (committed, for the default run's fixed programs; written by
``python -m differential.regenerate``), else ``$DIFFERENTIAL_CACHE`` or
``~/.cache/composed_sim/differential``.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Optional

from differential.events import compare
from differential.spec import program_hash

FIXTURES = Path(__file__).resolve().parent / "truth"
RUNS = 2


def cache_dir() -> Path:
    return Path(os.environ.get("DIFFERENTIAL_CACHE", Path.home() / ".cache" / "composed_sim" / "differential"))


def load(program: dict, ticks: int, recorded_only: bool = False) -> Optional[dict]:
    name = f"{program_hash(program, ticks)}.json"
    for folder in (FIXTURES,) if recorded_only else (FIXTURES, cache_dir()):
        if (folder / name).is_file():
            return json.loads((folder / name).read_text())
    return None


def store(record: dict, folder: Optional[Path] = None) -> Path:
    folder = folder or cache_dir()
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{program_hash(record['program'], record['ticks'])}.json"
    path.write_text(json.dumps(record, separators=(",", ":")) + "\n")
    return path


def run_truth(programs: list[dict], ticks: int, workdir: Path) -> list[dict]:
    """Run ``programs`` (one batch) ``RUNS`` times under rclpy; their records."""
    from composed_sim.hosts.domain_claim import claim_free_domain, run_identity
    from differential.ground_truth import run_ground_truth
    runs = []
    for attempt in range(RUNS):
        claim, domain = claim_free_domain(1, run_identity("differential ground truth"))
        try:
            folder = workdir / f"truth{attempt}"
            folder.mkdir(parents=True, exist_ok=True)
            runs.append(run_ground_truth(programs, ticks, folder, domain))
        finally:
            claim.release()
    records = []
    for i, program in enumerate(programs):
        first = runs[0].events.get(i, [])
        unstable = [d.tick for r in runs[1:] for d in compare(first, r.events.get(i, []), ticks)]
        records.append({"program": program, "ticks": ticks, "events": first, "stable": not unstable and not runs[0].notes,
                        "notes": runs[0].notes + [f"differs between runs at ticks {sorted(set(unstable))}"] * bool(unstable)})
    return records


def truths(programs: list[dict], ticks: int, workdir: Path, recorded_only: bool = False) -> list[dict]:
    """Each program's ground-truth record: cached, or run (the missing ones in one batch) and
    stored. ``recorded_only``: a program with no record is an error, not a run of rclpy."""
    found = [load(p, ticks, recorded_only) for p in programs]
    missing = [i for i, r in enumerate(found) if r is None]
    if missing and recorded_only:
        raise AssertionError(f"programs {missing} have no recorded rclpy run (their text and truth/ disagree): "
                             f"record it with python -m differential.regenerate (from tests/hosting)")
    if missing:
        for i, record in zip(missing, run_truth([programs[i] for i in missing], ticks, workdir)):
            store(record)
            found[i] = record
    return found
