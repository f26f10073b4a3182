"""The machine a bench ran on, recorded with its figures (CPU model, cores, memory, load, the
versions that matter)."""
from __future__ import annotations

import os
import platform
import subprocess
import time
from pathlib import Path
from typing import Optional

CHECKOUT = Path(__file__).resolve().parents[2]     # the repository, when run from a checkout


def machine_info() -> dict:
    import psutil

    from composed_sim.outputs.results import versions
    model = None
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.lower().startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    vm = psutil.virtual_memory()
    try:
        load = [round(x, 2) for x in os.getloadavg()]
    except OSError:
        load = None
    return {
        "cpu_model": model or platform.processor() or platform.machine(),
        "logical_cores": psutil.cpu_count(),
        "physical_cores": psutil.cpu_count(logical=False),
        "memory_total_mb": round(vm.total / 2**20),
        "memory_available_mb_at_start": round(available_memory_mb()),
        "load_average_at_start": load,
        "os": platform.platform(),
        "versions": versions(),
        "commit": _git_commit(),
        "date": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }


def available_memory_mb() -> float:
    """Available memory, bounded by this process's cgroup limit when there is one."""
    import psutil
    avail = psutil.virtual_memory().available
    for limit_file, usage_file in (("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
                                   ("/sys/fs/cgroup/memory/memory.limit_in_bytes",
                                    "/sys/fs/cgroup/memory/memory.usage_in_bytes")):
        try:
            limit = Path(limit_file).read_text().strip()
            usage = int(Path(usage_file).read_text().strip())
        except (OSError, ValueError):
            continue
        if limit.isdigit() and int(limit) < 2**60:
            avail = min(avail, max(int(limit) - usage, 0))
        break
    return avail / 2**20


def _git_commit() -> Optional[str]:
    """HEAD of the checkout the package runs from, if it is one (read-only)."""
    root = CHECKOUT
    if not (root / ".git").exists():
        return None
    try:
        res = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"], capture_output=True,
                             text=True, timeout=10, env=dict(os.environ, GIT_OPTIONAL_LOCKS="0"))
    except (OSError, subprocess.SubprocessError):
        return None
    return res.stdout.strip() or None if res.returncode == 0 else None
