"""The map in README.md is the house: its layout block names every folder of composed_sim/ and of
the repository, only folders that exist, and the controllers that pyproject.toml registers; the
tests mirror the packages they test."""
import fnmatch
import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def layout_block() -> dict[str, str]:
    """README.md's layout block under "What it is": each folder it names, with its description
    (continuation lines included)."""
    section = (ROOT / "README.md").read_text().split("## What it is", 1)[1]
    block = re.search(r"```\n(.*?)```", section, flags=re.S).group(1)
    entries: dict[str, str] = {}
    folder = None
    for line in block.splitlines():
        if line and not line[0].isspace():
            folder, _, text = line.partition(" ")
            entries[folder] = text.strip()
        elif folder is not None:
            entries[folder] += " " + line.strip()
    return entries


def ignored(name: str) -> bool:
    """A top-level folder git ignores (.gitignore's patterns), or a hidden one."""
    patterns = [p.strip().strip("/") for p in (ROOT / ".gitignore").read_text().splitlines()
                if p.strip() and not p.startswith("#")]
    return name.startswith(".") or any(fnmatch.fnmatch(name, p) for p in patterns)


def test_the_layout_names_folders_that_exist():
    missing = [folder for folder in layout_block() if not folder.endswith("/") or not (ROOT / folder).is_dir()]
    assert not missing, f"README.md's layout block names what is no folder: {missing}"


def test_the_layout_names_every_folder_of_the_repository_and_of_composed_sim():
    named = set(layout_block())
    top = {f"{p.name}/" for p in ROOT.iterdir() if p.is_dir() and not ignored(p.name) and p.name != "composed_sim"}
    inside = {f"composed_sim/{p.name}/" for p in (ROOT / "composed_sim").iterdir()
              if p.is_dir() and not ignored(p.name) and p.name != "__pycache__"}
    assert not (top | inside) - named, f"README.md's layout block leaves out {sorted((top | inside) - named)}"


def test_the_layout_lists_every_registered_controller():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    registered = set(project["entry-points"]["composed_sim.controllers"])
    listed = re.search(r"\(([^)]*)\)", layout_block()["controller_plugins/"]).group(1)
    assert {name.strip() for name in listed.split(",")} == registered


def test_every_package_has_its_tests_folder():
    """tests/ mirrors composed_sim/: a package's tests are in the folder of its name."""
    packages = {p.name for p in (ROOT / "composed_sim").iterdir() if (p / "__init__.py").is_file()}
    without = sorted(name for name in packages if not list((ROOT / "tests" / name).glob("test_*.py")))
    assert not without, f"packages with no tests/<package>/: {without}"
