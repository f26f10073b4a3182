"""Test-wide isolation: ROS traffic stays on this host and in a domain of this test process only,
so parallel test runs on one machine never hear each other; plotting is headless."""
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

os.environ["ROS_DOMAIN_ID"] = str(1 + os.getpid() % 100)   # 1 … 100; multi-process tests use others
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.pop("ROS_LOCALHOST_ONLY", None)                   # deprecated in Jazzy, conflicts with the above
os.environ["MPLBACKEND"] = "Agg"

PLUGIN_SOURCE = Path(__file__).parent / "plugin_pkg"


@pytest.fixture
def processes():
    """Started processes; whatever is still running at the end is killed (a failing test too)."""
    started: list[subprocess.Popen] = []
    yield started
    for p in started:
        if p.poll() is None:
            p.kill()
        p.wait()


def importable(monkeypatch, folder: Path):
    """For a fixture to ``yield from``: the test package in ``folder`` (its module has the folder's
    name) importable here and in the hosts' child processes, as an installed one is; its modules
    forgotten afterwards."""
    monkeypatch.syspath_prepend(str(folder))
    monkeypatch.setenv("PYTHONPATH", str(folder))
    yield
    for name in [m for m in sys.modules if m.split(".")[0] == folder.name]:
        del sys.modules[name]


def network_namespaces(names: list[str]):
    """Network namespaces ``names`` for a test's "machines" (a generator for a fixture to yield
    from); the test is skipped where they cannot be made (no iproute2, no privileges)."""
    from composed_sim.bench.netns import Netns
    if shutil.which("ip") is None:
        pytest.skip("network namespaces: the `ip` command (iproute2) is not installed")
    nets = Netns(names)
    try:
        nets.create()
    except OSError as e:
        nets.destroy()
        pytest.skip(f"network namespaces cannot be created here: {e}")
    try:
        yield nets
    finally:
        nets.destroy()


def start(cmd, log: Path, env=None) -> subprocess.Popen:
    """``cmd`` in a process of its own, its output added to the file ``log``."""
    with open(log, "ab") as out:
        return subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT, env=env)


@pytest.fixture
def domain_id() -> int:
    return int(os.environ["ROS_DOMAIN_ID"])


@pytest.fixture
def ros_context(domain_id):
    """An rclpy context of its own in this test process's domain, shut down after the test."""
    import rclpy
    from rclpy.context import Context
    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    yield context
    rclpy.shutdown(context=context)


@pytest.fixture
def mp_domain() -> int:
    """First of up to 4 domains for this test process, outside the 1 … 100 of ROS_DOMAIN_ID, so
    the composed run of a comparison never shares a domain with a multi-process run's children."""
    return 101 + 4 * (os.getpid() % 32)


def install_plugin(tmp_path, monkeypatch, module: str, entry_point: str | dict[str, str],
                   names: tuple[str, ...] = (), dist: str = "", group: str = "composed_sim.controllers") -> str:
    """Install a test package's controller (or loop functions: ``group``) the way pip would: a
    module plus a dist-info with entry points in ``group`` (named ``names``, by default the module's
    name with dashes), on sys.path and PYTHONPATH (for child processes). Returns the first name.
    ``entry_point``: the class, or {entry-point name: class} for several classes of the module."""
    dist = dist or module
    site = tmp_path / f"site_{dist}"
    site.mkdir()
    shutil.copy(PLUGIN_SOURCE / f"{module}.py", site / f"{module}.py")
    classes = entry_point if isinstance(entry_point, dict) else \
        {n: entry_point for n in (names or (module.replace("_", "-"),))}
    names = tuple(classes)
    info = site / f"{dist}_plugin-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist.replace('_', '-')}-plugin\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(
        f"[{group}]\n" + "".join(f"{n} = {module}:{cls}\n" for n, cls in classes.items()))
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(site), os.environ.get("PYTHONPATH")])))
    return names[0]


@pytest.fixture
def third_party_plugin(tmp_path, monkeypatch):
    """A plain-Node controller from another package (tests/plugin_pkg/plain_forward.py)."""
    yield install_plugin(tmp_path, monkeypatch, "plain_forward", "PlainForward")
    sys.modules.pop("plain_forward", None)


@pytest.fixture
def faulty_plugin(tmp_path, monkeypatch):
    """The fault-injecting controller (tests/plugin_pkg/faulty.py)."""
    yield install_plugin(tmp_path, monkeypatch, "faulty", "Faulty")
    sys.modules.pop("faulty", None)


@pytest.fixture
def rab_echo_plugin(tmp_path, monkeypatch):
    """A still robot that broadcasts (its index, the tick) and keeps what it hears (tests/plugin_pkg/rab_echo.py)."""
    yield install_plugin(tmp_path, monkeypatch, "rab_echo", "RabEcho")
    sys.modules.pop("rab_echo", None)
