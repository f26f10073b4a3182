"""One run over two "machines" of this host (two `composed-sim join` beside the simulator, on
localhost), over mutual TLS or with --insecure: for timing the link's cost, e.g.
    farm-bench -n 3 --timeout 1800 -- python tools/distributed/two_machines.py tls \\
        --vs 'python tools/distributed/two_machines.py insecure'
It writes the run's trajectories to OUT/<guard>/trajectories.npz (compare the two with numpy)."""
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
guard, robots, ticks = sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 1280, \
    int(sys.argv[3]) if len(sys.argv) > 3 else 200
out = Path("/tmp/two_machines") / guard
out.mkdir(parents=True, exist_ok=True)
cli = [sys.executable, "-m", "composed_sim.cli"]
log = open(out / "sim.log", "w")
sim = subprocess.Popen([*cli, "run", str(ROOT / "worlds/flocking.yaml"), "--robots", str(robots), "--ticks",
                        str(ticks), "--seed", "1", "--machines", "2", "--listen", "127.0.0.1:0", "--out", str(out),
                        "--no-progress", "--no-picture", *(["--insecure"] if guard == "insecure" else [])],
                       stdout=log, stderr=subprocess.STDOUT)
command = None
while command is None and sim.poll() is None:
    time.sleep(0.1)
    for line in (out / "sim.log").read_text().splitlines():
        if "on each: " in line:
            command = line.split("on each: ", 1)[1].split()[2:]
joins = [subprocess.Popen([*cli, "join", *command, "--workers", "1"], stdout=subprocess.DEVNULL,
                          stderr=subprocess.DEVNULL) for _ in range(2)]
code = sim.wait()
for j in joins:
    j.wait(timeout=60)
sys.exit(code)
