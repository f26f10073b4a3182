"""docs/figures/foxglove_scene.png: the scene a Foxglove viewer receives, drawn from the served
messages. There is no Foxglove app on the machine this was made on, so a client of the protocol
(tests/foxglove_client.py) subscribes to /swarm/markers of a live run, and matplotlib draws the
last MarkerArray it received, seen from above as the 3D panel's top view shows it.

    .venv/bin/python docs/foxglove/screenshot.py [WORLD] [TICKS]
"""
import math
import subprocess
import sys
from pathlib import Path

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.patches import Circle, Rectangle
from matplotlib.transforms import Affine2D
from rclpy.serialization import deserialize_message
from visualization_msgs.msg import Marker, MarkerArray

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests"))
from foxglove_client import channels, free_port, open_connection, receive_until_closed, subscribe  # noqa: E402


def served_scene(world: Path, ticks: int) -> MarkerArray:
    port = free_port()
    run = subprocess.Popen([sys.executable, "-m", "composed_sim.cli", "run", str(world), "--ticks", str(ticks),
                            "--out", "/tmp/foxglove_screenshot", "--no-progress", "--no-picture",
                            "--foxglove", f"127.0.0.1:{port}", "--wait-for-viewer", "60"], cwd=ROOT)
    try:
        with open_connection(port) as ws:
            scene = channels(ws, {"/swarm/markers"})["/swarm/markers"]
            sub, = subscribe(ws, [scene["id"]])
            got = receive_until_closed(ws)[sub]
        run.wait(timeout=300)
    finally:
        run.kill()
    return deserialize_message(got[-1][1], MarkerArray)


def draw(msg: MarkerArray, out: Path, title: str) -> None:
    fig, ax = plt.subplots(figsize=(6, 6), dpi=120)
    ax.set_facecolor("white")
    for m in msg.markers:
        rgba = (m.color.r, m.color.g, m.color.b, m.color.a)
        x, y = m.pose.position.x, m.pose.position.y
        yaw = 2 * math.atan2(m.pose.orientation.z, m.pose.orientation.w)
        if m.type == Marker.CUBE:
            patch = Rectangle((-m.scale.x / 2, -m.scale.y / 2), m.scale.x, m.scale.y, color=rgba,
                              zorder=0 if m.scale.z < 0.01 else 2)
            patch.set_transform(Affine2D().rotate(yaw).translate(x, y) + ax.transData)
            ax.add_patch(patch)
        elif m.type in (Marker.CYLINDER, Marker.SPHERE):
            ax.add_patch(Circle((x, y), m.scale.x / 2, color=rgba, zorder=0 if m.scale.z < 0.01 else 2))
        elif m.type == Marker.SPHERE_LIST:
            for p, c in zip(m.points, m.colors):
                ax.add_patch(Circle((p.x, p.y), m.scale.x / 2, facecolor=(c.r, c.g, c.b, c.a),
                                    edgecolor="black", linewidth=0.5, zorder=3))
        elif m.type == Marker.LINE_LIST:
            for a, b in zip(m.points[::2], m.points[1::2]):
                ax.plot([a.x, b.x], [a.y, b.y], color="black", linewidth=1.0, zorder=4)
    ax.autoscale_view()
    ax.set_aspect("equal")
    ax.set_xlabel("x (m), frame world")
    ax.set_ylabel("y (m)")
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(out)


if __name__ == "__main__":
    world = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "worlds" / "heterogeneous.yaml"
    ticks = int(sys.argv[2]) if len(sys.argv) > 2 else 100
    msg = served_scene(world, ticks)
    stamp = msg.markers[0].header.stamp
    draw(msg, ROOT / "docs" / "figures" / "foxglove_scene.png",
         f"/swarm/markers served live: {world.name}, t = {stamp.sec + stamp.nanosec * 1e-9:.1f} s\n"
         f"(the received MarkerArray drawn with matplotlib, not the Foxglove app)")
