"""The names of files and modules written as text, which a move would break silently: the paths
the docs link to and the code's comments cite, the modules child processes are launched with
(``python -m composed_sim....``), the dotted names tests patch, and the entry points."""
import builtins
import importlib
import importlib.util
import re
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = "|".join(p.name for p in (ROOT / "composed_sim").iterdir() if (p / "__init__.py").is_file())
# composed_sim/hosts/tick_loop.py, ../composed_sim/ros/contract.py, hosting/sim_time/timers.py, ros/test_cdr.py
CITED_PATH = re.compile(rf"(?<![\w./-])(?:\.\./)*((?:composed_sim/)?(?:{PACKAGES}|fidelity)/[\w/]+\.py)")
DOTTED = re.compile(r"[\"'`](composed_sim(?:\.\w+)+)[\"'`:]")
# Dotted names that are no module: the controller plugins' entry-point group, a recording's custom_data keys.
NOT_MODULES = {"controllers", "tick_s", "ticks", "robot_names", "executor"}


def texts() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), *sorted((ROOT / "composed_sim").rglob("*.py")),
            *sorted((ROOT / "tests").rglob("*.py")), *sorted((ROOT / "tools").rglob("*.py"))]


def test_every_cited_file_exists():
    missing = []
    for text in texts():
        for path in CITED_PATH.findall(text.read_text()):
            if not any((base / path).is_file() for base in (ROOT, ROOT / "composed_sim", ROOT / "tests", ROOT / "tools")):
                missing.append(f"{text.relative_to(ROOT)}: {path}")
    assert not missing, "\n".join(missing)


def _module_and_rest(dotted: str) -> tuple[str, list[str]]:
    """The longest importable prefix of ``dotted`` and the attribute names after it."""
    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):
        try:
            if importlib.util.find_spec(".".join(parts[:k])) is not None:
                return ".".join(parts[:k]), parts[k:]
        except ModuleNotFoundError:      # a parent is not a package
            continue
    return "", parts


def test_every_dotted_module_name_in_the_code_and_tests_resolves():
    """Launch strings (``[sys.executable, "-m", "composed_sim.hosts.workers.launcher", …]``), the
    names tests patch (``"composed_sim.hosts.workers.worker_host.usable_cores"``), plugins named in worlds."""
    bad = []
    for text in texts():
        for dotted in set(DOTTED.findall(text.read_text())):
            module, rest = _module_and_rest(dotted)
            if module in ("", "composed_sim"):
                if dotted.split(".")[1] not in NOT_MODULES:
                    bad.append(f"{text.relative_to(ROOT)}: {dotted}")
                continue
            if rest and rest[0] in dir(builtins):    # a builtin patched in a module (world.loader.open)
                continue
            obj = importlib.import_module(module)
            for name in rest:
                if not hasattr(obj, name):
                    bad.append(f"{text.relative_to(ROOT)}: {dotted} ({module} has no {'.'.join(rest)})")
                    break
                obj = getattr(obj, name)
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("group", ["scripts", "entry-points"])
def test_the_entry_points_resolve(group):
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    tables = [project["scripts"]] if group == "scripts" else list(project["entry-points"].values())
    for table in tables:
        for name, target in table.items():
            module, _, attribute = target.partition(":")
            assert hasattr(importlib.import_module(module), attribute), f"{name} = {target}"
