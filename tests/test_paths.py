"""The names of files and modules written as text, which a move would break silently: every path
the docs, the README and the code's comments cite (``hosting/dds/participants.py``, a folder
``hosts/workers/``, a module's name ``core/placement.place_robots``), the links between the docs
and the sections they name, the modules a package's docstring or the architecture's tables list,
the modules child processes are launched with (``python -m composed_sim....``), the dotted names
tests patch, and the entry points."""
import ast
import builtins
import importlib
import importlib.util
import re
import tomllib
from functools import cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = sorted(p.name for p in (ROOT / "composed_sim").iterdir() if (p / "__init__.py").is_file())
# A citation starts at one of these folders: the repository's own and composed_sim's packages (the
# code cites composed_sim/hosting/... as hosting/...); "fidelity" is tests/fidelity/ and tools/fidelity/.
CITED_ROOTS = ["composed_sim", "tests", "tools", "docs", "worlds", "controller_plugins", "loop_function_plugins",
               "fidelity", *PACKAGES]
BASES = (ROOT, ROOT / "composed_sim", ROOT / "tests", ROOT / "tools")
# composed_sim/hosts/tick_loop.py, ../composed_sim/ros/contract.py, hosts/workers/, core/placement.place_robots
CITATION = re.compile(rf"(?<![\w./<$-])(?:\.\./)*((?:{'|'.join(CITED_ROOTS)})/[\w./-]*)")
DOTTED = re.compile(r"[\"'`](composed_sim(?:\.\w+)+)[\"'`:]")
# Dotted names that are no module: the controller plugins' entry-point group, a recording's custom_data keys.
NOT_MODULES = {"controllers", "tick_s", "ticks", "robot_names", "executor"}
# A bare file name (``serving.py``), not part of a path (those are CITATION's) nor a string of the code.
BARE_FILE = re.compile(r"(?<![\w./<$\"'-])(\w+\.py)\b")
# Files named that are not the repository's: a user's package's set-up, the script docs/contract.md
# has a user write; a user's interface package's folders.
NOT_OURS = {"setup.py", "watch.py", "swap.py", "msg/", "srv/", "action/"}   # other projects' files the docs name
MD_LINK = re.compile(r"\]\(([^)\s]+)\)")
# docs/contract.md#a-robots-nodes, faults.md#memory-over-a-long-run
ANCHOR = re.compile(r"(?<![\w./-])([\w./-]*\w\.md)#([\w-]+)")
# docs/contract.md, "Frames"; fidelity.md "Regions"; (docs/contract.md), "Frames"
SECTION = re.compile(r"(?<![\w./-])([\w./-]*\w\.md)\)?,? \"([^\"]+)\"")
SKIPPED = {".git", ".venv", "__pycache__", ".hypothesis", "composed_sim.egg-info", ".grimp_cache",
           ".import_linter_cache"}


def texts() -> list[Path]:
    docs = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    code = [p for folder in ("composed_sim", "tests", "tools", "controller_plugins", "loop_function_plugins")
            for p in sorted((ROOT / folder).rglob("*")) if p.suffix in (".py", ".md") and p.is_file()]
    return [*docs, *code, ROOT / "pyproject.toml"]


def where(text: Path) -> str:
    return str(text.relative_to(ROOT))


@cache
def top_level_names(module: Path) -> dict[str, ast.AST]:
    """What a module defines at its top (functions, classes, names assigned or imported)."""
    names: dict[str, ast.AST] = {}
    for node in ast.parse(module.read_text()).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names[node.name] = node
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            for target in (node.targets if isinstance(node, ast.Assign) else [node.target]):
                names.update({n.id: node for n in ast.walk(target) if isinstance(n, ast.Name)})
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names.update({(a.asname or a.name).split(".")[0]: node for a in node.names})
    return names


def defines(module: Path, attributes: list[str]) -> bool:
    """Whether ``module`` defines ``attributes[0]``, and a class of it the rest (``Class.method``)."""
    node = top_level_names(module).get(attributes[0])
    for name in attributes[1:]:
        if not isinstance(node, ast.ClassDef):
            return node is not None          # an attribute of an instance or a module: not followed
        members = {n.name: n for n in node.body if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef,
                                                                   ast.ClassDef))}
        members.update({t.id: n for n in node.body if isinstance(n, (ast.Assign, ast.AnnAssign))
                        for t in ast.walk(n) if isinstance(t, ast.Name)})
        node = members.get(name)
    return node is not None


def citation_problem(cited: str) -> str | None:
    """None when ``cited`` names a file, a folder (``hosts/workers/``) or a module's name
    (``core/placement.place_robots``) that exists; else what is wrong."""
    if any((base / cited).exists() for base in BASES) and (not cited.endswith("/") or
                                                          any((base / cited).is_dir() for base in BASES)):
        return None
    folder, _, last = cited.rpartition("/")
    module_name, _, rest = last.partition(".")
    modules = [m for base in BASES if (m := base / folder / f"{module_name}.py").is_file()]
    if not rest or not modules or rest.split(".")[-1] in ("py", "md", "yaml", "json", "csv"):
        return "no such file or folder"
    if not any(defines(m, rest.split(".")) for m in modules):
        return f"{modules[0].relative_to(ROOT)} defines no {rest}"
    return None


def cited_paths(text: str) -> set[str]:
    """The paths ``text`` cites; C++ files only where they are ours (tools/): a comment naming
    a file of ARGoS's own source tree is not a citation of this repository."""
    cited = {m.rstrip(".-") for m in CITATION.findall(text)} - {""}
    return {c for c in cited if c.startswith("tools/") or Path(c).suffix not in (".cpp", ".h")}


def test_every_cited_file_folder_and_name_exists():
    missing = []
    for text in texts():
        for cited in sorted(cited_paths(text.read_text())):
            if (problem := citation_problem(cited)) is not None:
                missing.append(f"{where(text)}: {cited} ({problem})")
    assert not missing, "\n".join(missing)


def repository_files() -> set[str]:
    names = set()
    for path in ROOT.rglob("*"):
        if not SKIPPED.intersection(path.relative_to(ROOT).parts) and path.is_file():
            names.add(path.name)
    return names


def test_every_file_named_by_itself_is_a_file_of_the_repository():
    """``serving.py``, written without its folder, is still the name of some file here (a module
    renamed leaves none)."""
    outside = NOT_OURS | repository_files()
    bad = [f"{where(text)}: {name}" for text in texts()
           for name in sorted(set(BARE_FILE.findall(text.read_text()))) if name not in outside]
    assert not bad, "\n".join(bad)


def docstring_files(init: Path) -> list[str]:
    """The files and folders a package's docstring names: ``lockstep.py``, ``calls/`` in double
    backquotes, or a file at the start of a line (``grid.py     the grid: …``)."""
    doc = ast.get_docstring(ast.parse(init.read_text())) or ""
    return re.findall(r"``([\w/]+(?:\.py|/))``", doc) + re.findall(r"^(\w+\.py)\b", doc, flags=re.M)


def test_each_package_docstring_lists_files_of_its_own_folder():
    """A package's ``__init__`` that lists its modules (``tick_loop.py``, ``workers/``) lists files
    of that folder (or paths from the top, ``hosts/discovery.py``)."""
    bad = []
    for init in sorted((ROOT / "composed_sim").rglob("__init__.py")):
        for name in docstring_files(init):
            if name not in NOT_OURS and not (init.parent / name).exists() and citation_problem(name) is not None:
                bad.append(f"{where(init)}: {name}")
    assert not bad, "\n".join(bad)


def table_rows(doc: Path) -> list[str]:
    return [line for line in doc.read_text().splitlines() if line.startswith("|") and "`" in line]


def row_problems(row: str) -> list[str]:
    """A table row of docs/architecture.md names its folders (``composed_sim/hosting/``,
    ``hosts/workers/``); the modules and subfolders it names relatively (``lockstep.py``,
    ``executors/``) are in them."""
    names = re.findall(r"`([\w./]+)`", row)
    folders = [ROOT / base / n for n in names if n.endswith("/") for base in ("", "composed_sim")
               if (ROOT / base / n).is_dir()]
    folders += [ROOT / "composed_sim" / n for n in names if n.endswith(".py") and "/" in n
                and (ROOT / "composed_sim" / n).is_file() and not folders]
    if not folders:
        return []
    files = {str(p.relative_to(folder)) + ("/" if p.is_dir() else "") for folder in folders
             for p in folder.rglob("*") if "__pycache__" not in p.parts}
    relative = [n for n in names if re.fullmatch(r"[\w/]+(\.py|/)", n) and citation_problem(n) is not None]
    return [n for n in relative if not any(f == n or f.endswith("/" + n) for f in files)]


def test_the_architecture_tables_name_modules_of_their_folders():
    bad = [f"{problem} (row: {row[:80]}…)" for row in table_rows(ROOT / "docs" / "architecture.md")
           for problem in row_problems(row)]
    assert not bad, "\n".join(bad)


def slug(heading: str) -> str:
    """The anchor a markdown heading gets (GitHub's rule: lower case, punctuation dropped, spaces to dashes)."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def headings(doc: Path) -> list[str]:
    return [line.lstrip("#").strip() for line in doc.read_text().splitlines() if re.match(r"#+ ", line)]


def linked_doc(text: Path, cited: str) -> Path | None:
    """The markdown file ``cited`` names, from the citing file's folder or from the top."""
    for base in (text.parent, ROOT, ROOT / "docs"):
        if (base / cited).is_file():
            return base / cited
    return None


def test_every_markdown_link_leads_somewhere():
    bad = []
    for text in [t for t in texts() if t.suffix == ".md"]:
        for target in MD_LINK.findall(text.read_text()):
            if re.match(r"\w+:", target) or target.startswith("#"):
                continue
            path = target.split("#")[0]
            if not (text.parent / path).exists():
                bad.append(f"{where(text)}: ({target})")
    assert not bad, "\n".join(bad)


def test_every_anchor_and_section_named_exists():
    """``docs/contract.md#frames-simulator--anyone-with-devices-tf-`` and ``docs/contract.md, "Frames"`` name a section that the doc has
    (a quoted name is a heading's start: "The physics engine" for "The physics engine: one space…")."""
    bad = []
    for text in texts():
        content = text.read_text()
        for cited, anchor in ANCHOR.findall(content):
            doc = linked_doc(text, cited)
            if doc is None or anchor not in {slug(h) for h in headings(doc)}:
                bad.append(f"{where(text)}: {cited}#{anchor}")
        for cited, section in SECTION.findall(content):
            section = re.sub(r"\s*\n\s*#?\s*", " ", section)     # a name over two lines (of a comment)
            doc = linked_doc(text, cited)
            if doc is None or not any(h.lower().startswith(section.lower()) for h in headings(doc)):
                bad.append(f'{where(text)}: {cited}, "{section}"')
    assert not bad, "\n".join(bad)


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
                    bad.append(f"{where(text)}: {dotted}")
                continue
            if rest and rest[0] in dir(builtins):    # a builtin patched in a module (world.loader.open)
                continue
            obj = importlib.import_module(module)
            for name in rest:
                if not hasattr(obj, name):
                    bad.append(f"{where(text)}: {dotted} ({module} has no {'.'.join(rest)})")
                    break
                obj = getattr(obj, name)
    assert not bad, "\n".join(bad)


def test_every_test_module_imported_by_its_dotted_name_exists():
    """``from tests.hosting.test_robot_programs import PROGRAMS``: a test module moved leaves no
    import of its old place (no quotes around it, so the check above does not see it)."""
    bad = []
    for text in [t for t in texts() if t.suffix == ".py"]:
        for dotted in re.findall(r"^\s*(?:from|import) (tests(?:\.\w+)+)", text.read_text(), flags=re.M):
            path = ROOT.joinpath(*dotted.split("."))
            if not (path.with_suffix(".py").is_file() or (path / "__init__.py").is_file() or path.is_dir()):
                bad.append(f"{where(text)}: {dotted}")
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("group", ["scripts", "entry-points"])
def test_the_entry_points_resolve(group):
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    tables = [project["scripts"]] if group == "scripts" else list(project["entry-points"].values())
    for table in tables:
        for name, target in table.items():
            module, _, attribute = target.partition(":")
            assert hasattr(importlib.import_module(module), attribute), f"{name} = {target}"
