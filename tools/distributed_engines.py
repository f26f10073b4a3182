"""Which engine carries a distributed run's tick: DDS, Dask or Ray, measured the same way.

One "simulator" and one "machine" in two network namespaces joined by a bridge (as root; the
namespaces of composed_sim/bench/netns.py), the same lockstep exchange for each engine: per tick
the simulator sends the world state a machine needs (every robot's pose, 24 bytes; its half of
the robots' wheels and odometry, 72 bytes each) and waits for the answer (its robots' commands, 16
bytes each, and a few hundred bytes of the rest). Printed per engine and swarm size: start-up (the
machine's command started → first answer), the round trip per tick (median, 90th percentile) and
the bytes per tick through the simulator's link, both ways. docs/distributed.md has the figures.
Ray's start-up leaves out its head node (``ray start --head``, started first); each engine that is
not installed (``pip install ray``) fails its row.

    python tools/distributed_engines.py [--engines dds,dask,ray] [--robots 1280,10240] [--ticks 200]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ANSWER_EXTRA = 300          # bytes besides the commands: LEDs changed, violations, run-wide messages


def state_bytes(n: int, machines: int = 2) -> int:
    return n * 24 + (n // machines) * 72


def answer(blob: bytes) -> bytes:
    n = int.from_bytes(blob[:4], "little")
    return bytes((n // 2) * 16 + ANSWER_EXTRA)


def make_blob(n: int, tick: int) -> bytes:
    head = n.to_bytes(4, "little") + tick.to_bytes(4, "little")
    return head + np.random.default_rng(tick).bytes(state_bytes(n) - 8)


# --- the machine's side of each engine -------------------------------------------------------------

class Echo:
    """Dask's and Ray's actor: one call per tick."""

    def tick(self, blob: bytes) -> bytes:
        return answer(blob)


def dds_machine() -> None:
    import rclpy
    from rclpy.context import Context
    from rclpy.node import Node
    from std_msgs.msg import UInt8MultiArray
    context = Context()
    rclpy.init(context=context)
    node = Node("machine", context=context)
    pub = node.create_publisher(UInt8MultiArray, "/_probe/answer", 1)
    node.create_subscription(UInt8MultiArray, "/_probe/state",
                             lambda m: pub.publish(UInt8MultiArray(data=answer(bytes(m.data)))), 1)
    from rclpy.executors import SingleThreadedExecutor
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    executor.spin()


# --- the simulator's side ----------------------------------------------------------------------------

def dds_driver(sizes: list[int], start_machine) -> dict:
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from std_msgs.msg import UInt8MultiArray
    context = Context()
    rclpy.init(context=context)
    node = Node("simulator", context=context)
    pub = node.create_publisher(UInt8MultiArray, "/_probe/state", 1)
    got = []
    node.create_subscription(UInt8MultiArray, "/_probe/answer", lambda m: got.append(m), 1)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    t0 = time.perf_counter()
    start_machine()
    while pub.get_subscription_count() == 0 or node.count_publishers("/_probe/answer") == 0:
        executor.spin_once(timeout_sec=0.05)

    def round_trip(blob: bytes) -> None:
        got.clear()
        pub.publish(UInt8MultiArray(data=blob))
        while not got:
            executor.spin_once(timeout_sec=1.0)
    round_trip(make_blob(sizes[0], 0))
    return {"startup_s": time.perf_counter() - t0, "round_trip": round_trip}


def dask_driver(sizes: list[int], start_machine, address: str) -> dict:
    from distributed import Client, LocalCluster
    cluster = LocalCluster(n_workers=0, processes=False, protocol="tcp", host=address, scheduler_port=0, dashboard_address=None)
    client = Client(cluster)
    t0 = time.perf_counter()
    start_machine(cluster.scheduler_address)
    client.wait_for_workers(1)
    worker = next(iter(client.scheduler_info()["workers"]))
    actor = client.submit(Echo, actor=True, workers=[worker]).result()

    def round_trip(blob: bytes) -> None:
        actor.tick(blob).result()
    round_trip(make_blob(sizes[0], 0))
    return {"startup_s": time.perf_counter() - t0, "round_trip": round_trip}


def ray_driver(sizes: list[int], start_machine, address: str) -> dict:
    import ray
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy
    t0 = time.perf_counter()
    start_machine()
    ray.init(address=f"{address}:6379", logging_level="ERROR")
    while len([n for n in ray.nodes() if n["Alive"]]) < 2:
        time.sleep(0.05)
    other = next(n["NodeID"] for n in ray.nodes() if n["Alive"] and n["NodeManagerAddress"] != address)
    actor = ray.remote(Echo).options(scheduling_strategy=NodeAffinitySchedulingStrategy(other, soft=False)).remote()

    def round_trip(blob: bytes) -> None:
        ray.get(actor.tick.remote(blob))
    round_trip(make_blob(sizes[0], 0))
    return {"startup_s": time.perf_counter() - t0, "round_trip": round_trip}


def measure(engine: str, ticks: int, sizes: list[int], nets, env: dict) -> dict:
    sim_ip, machine_ip = nets.address["sim"], nets.address["m1"]
    started: list[subprocess.Popen] = []
    py = [sys.executable, str(Path(__file__).resolve())]

    def machine(cmd: list[str]) -> None:
        started.append(subprocess.Popen(nets.exec("m1", cmd), env=env, stdout=subprocess.DEVNULL,
                                        stderr=subprocess.DEVNULL))
    try:
        if engine == "dds":
            info = dds_driver(sizes, lambda: machine([*py, "--machine", "dds"]))
        elif engine == "dask":
            info = dask_driver(sizes, lambda address: machine(
                [str(Path(sys.executable).parent / "dask"), "worker", address, "--nthreads", "1", "--no-nanny",
                 "--host", machine_ip, "--no-dashboard"]), sim_ip)
        else:
            ray = str(Path(sys.executable).parent / "ray")
            subprocess.run([ray, "start", "--head", "--node-ip-address", sim_ip, "--port", "6379", "--num-cpus", "1",
                            "--include-dashboard=false"], env=env, check=True, capture_output=True)
            info = ray_driver(sizes, lambda: machine(
                [ray, "start", "--address", f"{sim_ip}:6379", "--node-ip-address", machine_ip, "--num-cpus", "1",
                 "--block"]), sim_ip)
        rows = {"engine": engine, "startup_s": round(info["startup_s"], 2)}
        for n in sizes:
            blobs = [make_blob(n, t) for t in range(ticks)]
            for blob in blobs[:5]:
                info["round_trip"](blob)         # warm
            before = nets.counters("sim")
            times = []
            for blob in blobs:
                t = time.perf_counter()
                info["round_trip"](blob)
                times.append((time.perf_counter() - t) * 1e3)
            after = nets.counters("sim")
            times.sort()
            rows[n] = {"state_bytes": len(blobs[0]), "rtt_ms_median": round(statistics.median(times), 2),
                       "rtt_ms_p90": round(times[int(0.9 * len(times))], 2),
                       "tx_bytes_per_tick": (after["tx_bytes"] - before["tx_bytes"]) // ticks,
                       "rx_bytes_per_tick": (after["rx_bytes"] - before["rx_bytes"]) // ticks}
        return rows
    finally:
        for p in started:
            p.kill()
            p.wait()


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--engines", default="dds,dask,ray")
    p.add_argument("--robots", default="1280,10240")
    p.add_argument("--ticks", type=int, default=200)
    p.add_argument("--machine", help=argparse.SUPPRESS)
    p.add_argument("--inside", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.machine == "dds":
        return dds_machine()
    sys.path.insert(0, str(HERE.parent))
    from composed_sim.bench.netns import Netns
    env = {**os.environ, "PYTHONPATH": f"{HERE}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
           "FASTDDS_BUILTIN_TRANSPORTS": "UDPv4", "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET",
           "ROS_DOMAIN_ID": str(200 + os.getpid() % 30), "RAY_USAGE_STATS_ENABLED": "0"}
    model = next((line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                  if line.startswith("model name")), platform.machine())
    print(json.dumps({"cpu": model, "cores": os.cpu_count(), "memory_gb": round(os.sysconf("SC_PAGE_SIZE") *
                      os.sysconf("SC_PHYS_PAGES") / 2**30, 1), "python": platform.python_version()}))
    for engine in args.engines.split(","):
        with Netns(["sim", "m1"]) as nets:
            # The simulator's side runs in its namespace too: this script again, inside it.
            cmd = nets.exec("sim", [sys.executable, str(Path(__file__).resolve()), "--inside", engine,
                                    "--robots", args.robots, "--ticks", str(args.ticks)])
            subprocess.run(cmd, env={**env, "PROBE_NETNS": json.dumps([nets.tag, nets.roles, nets.address])}, check=False)


def inside() -> None:
    """In the simulator's namespace: measure one engine and print its row."""
    p = argparse.ArgumentParser()
    p.add_argument("--inside")
    p.add_argument("--robots")
    p.add_argument("--ticks", type=int)
    args = p.parse_args()
    sys.path.insert(0, str(HERE.parent))
    from composed_sim.bench.netns import Netns
    tag, roles, address = json.loads(os.environ["PROBE_NETNS"])
    nets = Netns(roles)
    nets.tag, nets.address = tag, address
    sizes = [int(x) for x in args.robots.split(",")]
    print(json.dumps(measure(args.inside, args.ticks, sizes, nets, dict(os.environ))), flush=True)
    os._exit(0)        # not through the engines' own shutdown (Ray's and Dask's take seconds)


if __name__ == "__main__":
    if "--inside" in sys.argv:
        inside()
    else:
        main()
