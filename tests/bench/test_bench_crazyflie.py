"""The Crazyflie firmware bench (composed_sim/bench/crazyflie_firmware.py): a row per size and situation."""
import json

from composed_sim.bench import crazyflie_firmware


def test_a_row_per_size_and_situation(tmp_path):
    out = tmp_path / "firmware.json"
    assert crazyflie_firmware.main(["--drones", "3,20", "--ticks", "2", "--warmup", "1", "--out", str(out)]) == 0
    rows = json.loads(out.read_text())["rows"]
    assert [(r["drones"], r["situation"]) for r in rows] == [
        (n, s) for n in (3, 20) for s in ("hovering", "going to", "figure eight", "streaming", "on the floor")]
    assert all(r["us_per_drone_tick"] > 0 for r in rows)


def test_the_situations_are_what_they_say():
    """Hovering at 1 m, half-way through a go-to, on the figure eight, streamed, on the floor."""
    from composed_sim.devices.crazyflie.commander import HIGH_LEVEL, OFF, POSITION
    kinds = {}
    for situation in ("hovering", "going to", "figure eight", "streaming", "on the floor"):
        fleet, t, before = crazyflie_firmware.fleet_in(situation, 4)
        before(t + 0.01)
        fleet.advance(t + 0.01, 0.01)
        kinds[situation] = set(fleet.setpoints.kind.tolist())
        speed = abs(fleet.state.vel).max()
        if situation in ("hovering", "on the floor", "streaming"):
            assert speed < 1e-9, situation
        else:
            assert speed > 0.05, situation
    assert kinds == {"hovering": {HIGH_LEVEL}, "going to": {HIGH_LEVEL}, "figure eight": {HIGH_LEVEL},
                     "streaming": {POSITION}, "on the floor": {OFF}}
