"""A run over machines lets in only who holds its credentials: mutual TLS with Dask's own Security,
a throwaway CA per run. The intruders are real Dask clients and a raw TCP peer, with no file of the
run: over tcp://, over tls:// with a certificate of their own, and garbage bytes. None may run code
in the simulator; the run goes on, and says who was refused."""
import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import start
from composed_sim.hosting import HostError
from composed_sim.hosts.machines import credentials
from composed_sim.hosts.machines.remote_host import RemoteWorkerHost
from composed_sim.hosts.settings import LinkSecurity
from composed_sim.world.loader import load_world

pytest.importorskip("distributed", reason="remote workers need Dask distributed (the cluster extra)")

ROOT = Path(__file__).resolve().parents[3]
FLOCKING = ROOT / "worlds" / "flocking.yaml"
JOIN = [sys.executable, "-m", "composed_sim.cli", "join"]

# Each intruder writes a file in the simulator's process if it gets to run anything there.
INTRUDERS = r'''
import socket, sys
from distributed import Client
from distributed.security import Security
address, proof = sys.argv[1], sys.argv[2]
def plant():
    open(proof, "w").write("ran in the simulator")
for url, security in ((f"tcp://{address}", None), (f"tls://{address}", Security.temporary())):
    try:
        with Client(url, timeout=5, security=security) as client:
            client.run_on_scheduler(plant)
        print("IN", url)
    except Exception as e:
        print("refused", url, type(e).__name__)
host, port = address.rsplit(":", 1)
with socket.create_connection((host, int(port)), timeout=5) as peer:
    peer.sendall(b"\x16\x03\x01 not a handshake " * 64)
    peer.settimeout(5)
    try:
        peer.recv(1024)
    except OSError:
        pass
'''


def test_credentials_are_the_owners_only_a_ca_of_their_own_and_one_certificate(tmp_path):
    made = credentials.make(tmp_path / "c" / credentials.FILE_NAME)
    assert stat.S_IMODE(os.stat(made.path).st_mode) == 0o600
    from cryptography import x509
    ca = x509.load_pem_x509_certificate(made.ca.encode())
    member = x509.load_pem_x509_certificate(made.certificate.encode())
    assert ca.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    assert member.issuer == ca.subject != member.subject
    member.verify_directly_issued_by(ca)
    assert credentials.load(made.path) == made
    again = credentials.make(tmp_path / "d" / credentials.FILE_NAME)
    assert again.ca != made.ca and again.key != made.key      # a new run: new ones


def test_a_credentials_file_others_can_read_or_that_is_not_one_is_refused_by_name(tmp_path):
    made = credentials.make(tmp_path / credentials.FILE_NAME)
    os.chmod(made.path, 0o644)
    with pytest.raises(HostError, match=r"credentials\.pem: readable by others \(mode 644\).*chmod 600"):
        credentials.load(made.path)
    other = tmp_path / "other.pem"
    other.write_text("hello")
    other.chmod(0o600)
    with pytest.raises(HostError, match="other.pem: not a composed-sim credentials file"):
        credentials.load(other)


def test_no_intruder_runs_code_in_the_simulator_and_the_invited_machine_still_runs(tmp_path, processes, domain_id):
    world = load_world(FLOCKING, robots=4, ticks=20, seed=1)
    proof, lines = tmp_path / "planted", []
    intruders_done = []

    def announce(line: str) -> None:
        lines.append(line)
        if "on each: " not in line:
            return
        command = line.split("on each: ", 1)[1].split()
        address = command[2].split("://", 1)[1]
        intruders_done.append(subprocess.run([sys.executable, "-c", INTRUDERS, address, str(proof)],
                                             capture_output=True, text=True, timeout=120))
        processes.append(start([*JOIN, *command[2:], "--workers", "1"], tmp_path / "join.log"))

    with RemoteWorkerHost(world, machines=1, listen="127.0.0.1:0", domain_id=domain_id, join_timeout_s=60,
                          link=LinkSecurity(fresh_into=str(tmp_path)), announce=announce) as host:
        result = host.run()
    assert not proof.exists(), "an intruder ran code in the simulator"
    out = intruders_done[0].stdout
    assert "IN " not in out and out.count("refused") == 2, out + intruders_done[0].stderr
    assert processes[0].wait(timeout=30) == 0, (tmp_path / "join.log").read_text()
    assert result.trajectories.ticks_done == 20 and not result.violations
    refused = [line for line in lines if "refused a connection from" in line]
    assert len(refused) >= 3, lines          # the tcp:// client, the tls:// one with its own CA, the garbage
    assert all("no credentials of this run" in line for line in refused)
    assert sum("machine joined from tls://127.0.0.1:" in line for line in lines) == 1, lines


def reachable_ports(pid: int, children: bool) -> set[int]:
    """The ports process ``pid`` (and its children) listen on beyond the loopback."""
    import psutil
    found = set()
    for process in (psutil.Process(pid), *(psutil.Process(pid).children(recursive=True) if children else ())):
        for conn in process.net_connections(kind="inet"):
            if conn.status == psutil.CONN_LISTEN and not conn.laddr.ip.startswith(("127.", "::1")):
                found.add(conn.laddr.port)
    return found


def test_every_port_other_machines_reach_is_the_runs_tls_one(tmp_path, processes, domain_id):
    # Listening on every interface, as by default: the simulator's only port beyond the loopback is
    # its scheduler's, a machine's only one its worker's, both TLS (Dask's HTTP servers, plain
    # HTTP with the run's state, listened on every interface: the scheduler's on 8787).
    world = load_world(FLOCKING, robots=2, ticks=10, seed=1)
    seen = {}

    def announce(line: str) -> None:
        if "on each: " in line:
            command = line.split("on each: ", 1)[1].split()
            seen["address"] = command[2]
            processes.append(start([*JOIN, *command[2:], "--workers", "1"], tmp_path / "join.log"))

    def progress(tick: int) -> None:
        if tick == 1:
            seen["simulator"] = reachable_ports(os.getpid(), children=False)    # the machine is a child here
            seen["machine"] = reachable_ports(processes[0].pid, children=True)

    with RemoteWorkerHost(world, machines=1, listen="0.0.0.0:0", domain_id=domain_id, join_timeout_s=60,
                          link=LinkSecurity(fresh_into=str(tmp_path)), announce=announce) as host:
        result = host.run(progress=progress)
    assert result.trajectories.ticks_done == 10 and not result.violations
    assert seen["address"].startswith("tls://")
    assert seen["simulator"] == {int(seen["address"].rsplit(":", 1)[1])}, seen
    assert len(seen["machine"]) == 1, seen      # its worker's tls:// listener, which the simulator calls


def test_a_machine_refuses_a_simulator_that_holds_other_credentials(tmp_path, processes, domain_id):
    world = load_world(FLOCKING, robots=2, ticks=5, seed=1)
    ours = credentials.make(tmp_path / "ours" / credentials.FILE_NAME)
    lines = []
    with pytest.raises(HostError, match="did not join"):
        with RemoteWorkerHost(world, machines=1, listen="127.0.0.1:0", domain_id=domain_id, join_timeout_s=3,
                              link=LinkSecurity(fresh_into=str(tmp_path / "impostor")), announce=lines.append):
            command = lines[0].split("on each: ", 1)[1].split()
            done = subprocess.run([*JOIN, command[2], "--credentials", str(ours.path), "--timeout", "5"],
                                  capture_output=True, text=True, timeout=60)
            assert done.returncode == 2, done.stderr
            assert "no simulator of this run at tls://127.0.0.1:" in done.stderr, done.stderr
            assert "Traceback" not in done.stderr


@pytest.mark.parametrize("args, message", [
    (["tls://127.0.0.1:1"], "needs --credentials FILE"),
    (["tcp://127.0.0.1:1"], "plain tcp:// and --insecure go together"),
    (["tls://127.0.0.1:1", "--insecure"], "plain tcp:// and --insecure go together"),
    (["10.0.0.1:8786", "--credentials", "x.pem"], "expected tls://HOST:PORT"),
    (["tls://127.0.0.1:1", "--credentials", "missing.pem"], "--credentials missing.pem: No such file"),
])
def test_a_join_with_the_wrong_guard_is_one_line_and_exit_2(args, message, capsys, tmp_path, monkeypatch):
    from composed_sim import cli
    monkeypatch.chdir(tmp_path)
    assert cli.main(["join", *args, "--timeout", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("composed-sim: error: ") and message in err and "\n" not in err, err


def test_insecure_is_asked_for_by_name_and_says_what_it_opens(tmp_path, processes, domain_id):
    world = load_world(FLOCKING, robots=2, ticks=5, seed=1)
    lines = []

    def announce(line: str) -> None:
        lines.append(line)
        if "on each: " in line:
            command = line.split("on each: ", 1)[1].split()
            assert command[2].startswith("tcp://") and command[-1] == "--insecure", command
            processes.append(start([*JOIN, *command[2:], "--workers", "1"], tmp_path / "join.log"))

    with RemoteWorkerHost(world, machines=1, listen="127.0.0.1:0", domain_id=domain_id, join_timeout_s=60,
                          link=LinkSecurity(insecure=True), announce=announce) as host:
        assert host.run().trajectories.ticks_done == 5
    assert any("--insecure: the run listens on plain tcp://" in line and "can run code" in line for line in lines)
    assert processes[0].wait(timeout=30) == 0
    assert "--insecure: plain tcp://" in (tmp_path / "join.log").read_text()


def test_credentials_make_writes_a_file_a_run_and_its_machines_share(tmp_path, capsys):
    from composed_sim import cli
    assert cli.main(["credentials", "make", str(tmp_path / "job")]) == 0
    path = Path(capsys.readouterr().out.strip())
    assert path == tmp_path / "job" / credentials.FILE_NAME
    assert credentials.load(path).security().require_encryption
