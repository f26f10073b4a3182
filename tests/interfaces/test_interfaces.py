"""A user's interface package, written as ROS users write one, built with the pip-installed rosidl
toolchain (composed_sim/interfaces/): imported, published and taken with rclpy, cached by
content, recorded in a bag that rosbags reads back, and its mistakes reported by file and line."""
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from composed_sim.interfaces import InterfaceError, activate, build_package
from composed_sim.interfaces import toolchain

PACKAGE = "cs_test_msgs"     # a name no installed package has

PACKAGE_XML = """<?xml version="1.0"?>
<package format="3">
  <name>{name}</name>
  <version>0.1.0</version>
  <description>Test interfaces</description>
  <maintainer email="test@example.com">test</maintainer>
  <license>Apache-2.0</license>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <buildtool_depend>rosidl_default_generators</buildtool_depend>
  <depend>std_msgs</depend>
  <exec_depend>rosidl_default_runtime</exec_depend>
  <member_of_group>rosidl_interface_packages</member_of_group>
</package>
"""

OPINION = """\
# A robot's opinion, as a voter-model package would broadcast it
std_msgs/Header header
int32 robot
float32[3] weights
float64[] history
string note
"""

ASK = """\
int32 robot
---
std_msgs/Header header
bool agrees
"""


def make_package(root: Path, files: dict[str, str], name: str = PACKAGE) -> Path:
    root.mkdir(parents=True)
    (root / "package.xml").write_text(PACKAGE_XML.format(name=name))
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    return root


@pytest.fixture(scope="session")
def xdg_cache(tmp_path_factory) -> Path:
    """$XDG_CACHE_HOME for the session: activate() finds the session's build there."""
    return tmp_path_factory.mktemp("xdg_cache")


@pytest.fixture(scope="session")
def cache(xdg_cache) -> Path:
    return xdg_cache / "composed_sim" / "interfaces"


@pytest.fixture(scope="session")
def built(tmp_path_factory, cache):
    """The test package, built once for the session (about 3 s); a message and a service share a
    name, as in ROS 2's own test_msgs (msg/Empty beside srv/Empty)."""
    source = make_package(tmp_path_factory.mktemp("src") / PACKAGE,
                          {"msg/Opinion.msg": OPINION, "srv/Ask.srv": ASK, "msg/Ask.msg": "string question\n"})
    package = build_package(source, cache=cache)
    assert not package.cached
    return package


@pytest.fixture
def activated(built, xdg_cache, monkeypatch):
    """The test package activated in this process (found in the session's cache); sys.path and
    the environment restored after."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(xdg_cache))
    for variable in ("PYTHONPATH", "AMENT_PREFIX_PATH"):
        monkeypatch.setenv(variable, os.environ.get(variable, ""))
    monkeypatch.setattr(sys, "path", list(sys.path))
    [package] = activate([built.source])
    assert package.cached and package.prefix == built.prefix
    return package


def test_a_second_build_is_found_in_the_cache(built, cache):
    marker = built.prefix / "build.json"
    before = marker.stat().st_mtime_ns
    again = build_package(built.source, cache=cache)
    assert again.cached and again.prefix == built.prefix
    assert marker.stat().st_mtime_ns == before            # nothing was rebuilt
    assert [p.name for p in cache.iterdir()] == [built.prefix.name]     # no temporary folder left
    info = json.loads(marker.read_text())
    assert info["name"] == PACKAGE and set(info["dependencies"]) >= {"std_msgs", "service_msgs"}


def test_its_messages_import_and_serialise_in_a_new_process(built):
    """A child process needs only PYTHONPATH: the libraries are found without LD_LIBRARY_PATH."""
    code = textwrap.dedent(f"""
        from rclpy.serialization import deserialize_message, serialize_message
        from {PACKAGE}.msg import Opinion
        from {PACKAGE}.srv import Ask
        m = Opinion(robot=7, weights=[0.5, 0.25, 0.125], history=[1.0, 2.0], note="yes")
        m.header.frame_id = "bot7"
        back = deserialize_message(serialize_message(m), Opinion)
        assert back == m, back
        assert deserialize_message(serialize_message(Ask.Response(agrees=True)), Ask.Response).agrees
        from {PACKAGE}.msg import Ask as AskMessage
        assert deserialize_message(serialize_message(AskMessage(question="why")), AskMessage).question == "why"
        print("ok")
    """)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(built.python_path), os.environ.get("PYTHONPATH", "")]))
    for variable in ("LD_LIBRARY_PATH", "_ROS_WHEELS_BOOTSTRAP_COMPLETE"):    # as a fresh process starts
        env.pop(variable, None)
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and r.stdout.strip() == "ok", r.stderr[-2000:]


def test_activated_messages_publish_and_take_with_rclpy(activated, ros_context):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from cs_test_msgs.msg import Opinion

    assert str(activated.python_path) == os.environ["PYTHONPATH"].split(os.pathsep)[0]
    assert str(activated.prefix) == os.environ["AMENT_PREFIX_PATH"].split(os.pathsep)[0]
    node = rclpy.create_node("opinions", context=ros_context, start_parameter_services=False,
                             enable_rosout=False)
    executor = SingleThreadedExecutor(context=ros_context)
    try:
        heard = []
        node.create_subscription(Opinion, "/swarm_opinion", heard.append, 10)
        publisher = node.create_publisher(Opinion, "/swarm_opinion", 10)
        executor.add_node(node)
        sent = Opinion(robot=3, weights=[1.0, 2.0, 3.0], history=[0.5] * 4, note="left")
        sent.header.frame_id = "bot3"
        for _ in range(50):
            publisher.publish(sent)
            executor.spin_once(timeout_sec=0.1)
            if heard:
                break
        assert heard and heard[0] == sent
        assert list(heard[0].weights) == [1.0, 2.0, 3.0] and heard[0].header.frame_id == "bot3"
    finally:
        executor.shutdown()
        node.destroy_node()


def test_recorded_messages_carry_their_definition_for_rosbags(activated, tmp_path):
    """The bag's schema is the package's .msg (found on AMENT_PREFIX_PATH): rosbags reads the
    message back from the bag alone."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    from composed_sim.outputs.recording import BagRecorder
    from cs_test_msgs.msg import Opinion

    sent = Opinion(robot=5, weights=[0.0, 1.0, 0.0], history=[3.0], note="right")
    with BagRecorder(tmp_path / "bag", robot_names=["bot0"], tick_s=0.1, topics_globs=["/bot0/*"]) as bag:
        assert bag.write_message("/bot0/opinion", sent, 100_000_000)
    with Reader(tmp_path / "bag") as reader:
        [conn] = [c for c in reader.connections if c.topic == "/bot0/opinion"]
        assert conn.msgtype == f"{PACKAGE}/msg/Opinion"
        typestore = get_typestore(Stores.ROS2_JAZZY)
        typestore.register(get_types_from_msg(conn.msgdef.data, conn.msgtype))
        [(_, _, raw)] = list(reader.messages(connections=[conn]))
    back = typestore.deserialize_cdr(raw, conn.msgtype)
    assert (back.robot, back.note, list(back.weights), list(back.history)) == (5, "right", [0.0, 1.0, 0.0], [3.0])


def test_the_cli_builds_and_says_where_and_whether_cached(built, xdg_cache):
    env = dict(os.environ, XDG_CACHE_HOME=str(xdg_cache))
    r = subprocess.run([sys.executable, "-m", "composed_sim.cli", "interfaces", "build", str(built.source)],
                       env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert f"{PACKAGE}: cached" in r.stdout and str(built.prefix) in r.stdout


# --- mistakes: one error naming the file and line, the path, or the missing tool ---------------

def _error(tmp_path, files, name=PACKAGE) -> str:
    source = make_package(tmp_path / name, files, name=name)
    with pytest.raises(InterfaceError) as e:
        build_package(source, cache=tmp_path / "cache")
    return str(e.value)


def test_a_typo_in_a_field_type_names_the_file_and_line(tmp_path):
    text = _error(tmp_path, {"msg/Opinion.msg": "# comment\nint32 robot\nflaot32 x\n"})
    assert text.startswith(f"{tmp_path / PACKAGE / 'msg' / 'Opinion.msg'}:3: 'flaot32 x': ")
    assert "'flaot32' is an invalid message name" in text
    assert not (tmp_path / "cache").exists() or not any((tmp_path / "cache").iterdir())   # nothing half-built kept


def test_an_unknown_type_of_another_package_names_the_file_and_line(tmp_path):
    text = _error(tmp_path, {"msg/Vote.msg": "int32 robot\nnope_msgs/Ballot ballot\n"})
    assert text.startswith(f"{tmp_path / PACKAGE / 'msg' / 'Vote.msg'}:2: unknown type nope_msgs/msg/Ballot: "
                           "no interface package nope_msgs is installed")
    text = _error(tmp_path / "b", {"msg/Vote.msg": "geometry_msgs/Pointt p\n"})
    assert ":1: unknown type geometry_msgs/msg/Pointt: package geometry_msgs has no msg/Pointt" in text


def test_a_folder_without_package_xml_is_named(tmp_path):
    (tmp_path / "msg").mkdir()
    with pytest.raises(InterfaceError, match=rf"^{tmp_path}: not a ROS interface package \(no package.xml\)$"):
        build_package(tmp_path, cache=tmp_path / "cache")


def test_a_missing_compiler_is_named_with_what_to_do(tmp_path, monkeypatch, built, cache):
    monkeypatch.setenv("CC", "no-such-cc")
    text = _error(tmp_path, {"msg/Vote.msg": "int32 robot\n"})
    assert "no C compiler was found ($CC=no-such-cc not on PATH)" in text and "apt-get install gcc g++" in text
    assert build_package(built.source, cache=cache).cached     # a cached build needs no compiler


def test_a_missing_wheel_is_named_with_what_to_do(tmp_path, monkeypatch):
    real = toolchain.importlib.util.find_spec
    monkeypatch.setattr(toolchain.importlib.util, "find_spec",
                        lambda name, *a: None if name == "rosidl_generator_py" else real(name, *a))
    toolchain.find_toolchain.cache_clear()
    try:
        text = _error(tmp_path, {"msg/Vote.msg": "int32 robot\n"})
    finally:
        toolchain.find_toolchain.cache_clear()
    assert text == ("building interface packages needs the Python module rosidl_generator_py (wheel "
                    "ros-rosidl-generator-py), which is not installed: reinstall composed_sim's dependencies "
                    "(pip install -e . in its checkout) or pip install ros-rosidl-generator-py")


def test_the_world_file_names_packages_relative_to_itself(tmp_path, built):
    from composed_sim.world.loader import WorldFileError, load_world
    world_dir = tmp_path / "worlds"
    world_dir.mkdir()
    (world_dir / "w.yaml").write_text(f"interfaces: [{os.path.relpath(built.source, world_dir)}]\n"
                                      "robots: [{model: foot-bot, count: 1, controller: flocking}]\n")
    assert load_world(world_dir / "w.yaml").interfaces == [str(built.source)]
    (world_dir / "bad.yaml").write_text("robots: [{model: foot-bot, count: 1, controller: flocking}]\n"
                                        "interfaces:\n  - ../nowhere\n")
    with pytest.raises(WorldFileError, match=rf"bad.yaml:3: interfaces\[0\]: {tmp_path / 'nowhere'}: "
                                             "no such interface package folder"):
        load_world(world_dir / "bad.yaml")


def test_two_processes_build_a_package_using_another_at_once(built, xdg_cache, tmp_path):
    """A package that uses the test package's message, built by two processes at the same time
    (two workers starting): both get a working build, one folder is kept, nothing is corrupted."""
    user = make_package(tmp_path / "cs_test_votes", {"msg/Tally.msg": f"{PACKAGE}/Opinion[] opinions\nint32 total\n"},
                        name="cs_test_votes")
    code = textwrap.dedent(f"""
        import sys
        from composed_sim.interfaces import activate
        [_, votes] = activate([{str(built.source)!r}, {str(user)!r}])
        from cs_test_votes.msg import Tally
        from {PACKAGE}.msg import Opinion
        from rclpy.serialization import deserialize_message, serialize_message
        t = Tally(opinions=[Opinion(robot=1), Opinion(robot=2)], total=2)
        assert deserialize_message(serialize_message(t), Tally) == t
        print(votes.prefix, votes.cached)
    """)
    env = dict(os.environ, XDG_CACHE_HOME=str(xdg_cache))
    children = [subprocess.Popen([sys.executable, "-c", code], env=env, stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, text=True) for _ in range(2)]
    results = [child.communicate(timeout=120) + (child.returncode,) for child in children]
    assert all(rc == 0 for _, _, rc in results), [err[-1500:] for _, err, _ in results]
    prefixes = {out.split()[0] for out, _, _ in results}
    assert len(prefixes) == 1
    assert sorted(p.name for p in Path(xdg_cache, "composed_sim", "interfaces").iterdir()) == \
        sorted([built.prefix.name, Path(prefixes.pop()).name])
