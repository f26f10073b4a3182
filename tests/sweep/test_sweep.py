"""composed-sim sweep: the table equals single runs of the same specs, a resumed sweep runs
nothing again, a failed run is a row, bad --set values stop it before any run, and a Dask
cluster started here gives the local pool's results."""
import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from composed_sim.cli import main
from composed_sim.sweep.grid import Grid
from composed_sim.sweep.runner import dask_cluster, local_pool
from tests.conftest import install_plugin

ROOT = Path(__file__).resolve().parents[2]
FLOCKING = ROOT / "worlds" / "flocking.yaml"
GRID = ["--seeds", "1-2", "--robots", "3", "--set", "robots.0.params.gain=500", "--ticks", "10"]
FINAL = ["final_centroid_to_light_m", "final_mean_nearest_neighbour_m", "final_lattice_order"]


def _rows(path: Path) -> dict[str, dict]:
    return {r["run"]: r for r in csv.DictReader(open(path))}


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep")
    assert main(["sweep", str(FLOCKING), *GRID, "--jobs", "2", "--out", str(out)]) == 0
    return out


def test_the_table_equals_single_runs_of_the_same_specs(swept, tmp_path):
    rows = _rows(swept / "runs.csv")
    assert sorted(rows) == ["seed=1_robots=3_gain=500.0", "seed=2_robots=3_gain=500.0"]
    for seed in (1, 2):
        row = rows[f"seed={seed}_robots=3_gain=500.0"]
        assert row["status"] == "ok" and row["exit_code"] == "0" and row["ticks"] == "10"
        world = yaml.safe_load(FLOCKING.read_text())
        world["robots"][0]["params"]["gain"] = 500.0
        (tmp_path / "w.yaml").write_text(yaml.safe_dump(world))
        r = subprocess.run([sys.executable, "-m", "composed_sim.cli", "run", str(tmp_path / "w.yaml"), "--robots", "3",
                            "--seed", str(seed), "--ticks", "10", "--no-picture", "--no-progress",
                            "--out", str(tmp_path / f"single{seed}")], cwd=ROOT, capture_output=True, text=True, timeout=120)
        assert r.returncode == 0, r.stderr[-2000:]
        final = json.loads((tmp_path / f"single{seed}" / "summary.json").read_text())["metrics"]["final"]
        for column in FINAL:
            assert float(row[column]) == final[column.removeprefix("final_")], column
    per_tick = list(csv.DictReader(open(swept / "metrics.csv")))
    assert len(per_tick) == 2 * 2 and {r["tick"] for r in per_tick} == {"0", "10"}
    assert (swept / "lattice_order_vs_seed.png").exists() is False    # seeds are the spread, not an axis


def test_a_resumed_sweep_runs_nothing_again(swept, capsys):
    assert main(["sweep", str(FLOCKING), *GRID, "--jobs", "2", "--out", str(swept)]) == 0
    assert "2 runs (0 failed, 2 reused)" in capsys.readouterr().out
    assert all(r["reused"] == "True" for r in _rows(swept / "runs.csv").values())


def test_a_dask_cluster_gives_the_local_pool_results(swept, tmp_path):
    distributed = pytest.importorskip("distributed")
    specs = Grid(FLOCKING, seeds=[1, 2], robots=[3], sets={"robots.0.params.gain": [500.0]}, ticks=10).specs()
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        rows = {r["run"]: r for r in dask_cluster(specs, str(tmp_path), cluster.scheduler_address)}
    local = _rows(swept / "runs.csv")
    assert sorted(rows) == sorted(local)
    for name, row in rows.items():
        assert row["status"] == "ok" and not row["reused"]
        for column in FINAL:
            assert row[column] == float(local[name][column])


def test_a_sweep_on_a_tls_cluster_takes_its_files_and_a_client_without_them_is_refused(swept, tmp_path, capsys):
    distributed = pytest.importorskip("distributed")
    from composed_sim.hosts.machines import credentials
    files = credentials.make(tmp_path / "tls" / credentials.FILE_NAME)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None,
                                  protocol="tls", security=files.security()) as cluster:
        address = cluster.scheduler_address
        assert address.startswith("tls://")
        out = tmp_path / "on_tls"
        assert main(["sweep", str(FLOCKING), *GRID, "--cluster", address, "--cluster-security", str(files.path),
                     "--out", str(out)]) == 0
        assert main(["sweep", str(FLOCKING), *GRID, "--cluster", address, "--out", str(tmp_path / "refused")]) == 2
        assert "needs its files" in capsys.readouterr().err
        other = credentials.make(tmp_path / "other" / credentials.FILE_NAME)
        assert main(["sweep", str(FLOCKING), *GRID, "--cluster", address, "--cluster-security", str(other.path),
                     "--out", str(tmp_path / "impostor")]) == 2
    rows, local = _rows(out / "runs.csv"), _rows(swept / "runs.csv")
    assert sorted(rows) == sorted(local)
    for name, row in rows.items():
        assert row["status"] == "ok"
        for column in FINAL:
            assert float(row[column]) == float(local[name][column])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("composed-sim sweep: error: --cluster tls://"), err


@pytest.mark.parametrize("security, message", [
    ("a.pem,b.pem", "expected CA,CERT,KEY (three files) or one credentials file"),
    ("ca.pem,c.pem,k.pem", "--cluster-security ca.pem: no such file (the CA)"),
    ("missing.pem", "--cluster-security missing.pem: No such file"),
])
def test_bad_cluster_security_is_one_line(security, message, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["sweep", str(FLOCKING), *GRID, "--cluster", "tls://127.0.0.1:1", "--cluster-security", security,
                 "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err, err


def test_a_failed_run_is_a_row_and_the_sweep_goes_on(tmp_path, monkeypatch):
    name = install_plugin(tmp_path, monkeypatch, "raising_loop", "RaisingLoopFunctions", ("raising",),
                          group="composed_sim.loop_functions")
    world = yaml.safe_load(FLOCKING.read_text())
    world["loop_functions"] = {"name": name, "params": {"raise_at_tick": 3}}
    (tmp_path / "w.yaml").write_text(yaml.safe_dump(world))
    specs = Grid(tmp_path / "w.yaml", robots=[3], sets={"loop_functions.params.raise_at_tick": [3, 100]},
                 ticks=5).specs()
    rows = {r["run"]: r for r in local_pool(specs, str(tmp_path / "out"), 2)}
    failed, ok = rows["robots=3_raise_at_tick=3"], rows["robots=3_raise_at_tick=100"]
    assert failed["status"] == "failed" and failed["exit_code"] == 1 and failed["ticks"] == 3
    assert "Traceback" in failed["error"] and "RuntimeError: the experiment's own bug at tick 3" in failed["error"]
    assert ok["status"] == "ok" and ok["ticks"] == 5 and ok["final_mean_x"] == ok["_metrics"][-1]["mean_x"]
    assert ok["ended_by_loop_functions"] is False and ok["finished"] is False     # ran its length


@pytest.mark.parametrize("given, says", [
    ("robots.0.params.gain=fast", "--set robots.0.params.gain='fast': the field is float or int or str or bool or "
                                  "list[float] or list[str] or list[bool] and holds float 1000.0; 'fast' is str"),
    ("lights.0.intensty=1", "--set lights.0.intensty: unknown field lights.0.intensty (lights.0 has: position, "
                            "height_m, intensity, color)"),
    ("physics.substeps=0,5", "--set physics.substeps=0: the field is int >= 1 <= 100; must be >= 1 (got 0)"),
])
def test_a_bad_set_is_one_line_before_any_run(tmp_path, capsys, given, says):
    assert main(["sweep", str(FLOCKING), "--seeds", "1", "--set", given, "--out", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err.strip() == f"composed-sim sweep: error: {says}"
    assert not (tmp_path / "out").exists()


def test_the_shipped_sweep_file_is_the_done_when_grid():
    """worlds/sweeps/flocking_gain.yaml holds the grid of docs/experiments.md's command line."""
    import argparse
    from composed_sim.sweep.command import grid_from
    cli = argparse.Namespace(spec=FLOCKING, seeds="1-5", robots="20,80", set=["robots.0.params.gain=500,1000"], ticks=None)
    file = argparse.Namespace(spec=ROOT / "worlds" / "sweeps" / "flocking_gain.yaml", seeds=None, robots=None, set=[],
                              ticks=None)
    from_cli, from_file = grid_from(cli).specs(), grid_from(file).specs()
    assert len(from_file) == 20 and [s.name for s in from_file] == [s.name for s in from_cli]
    assert [s.world for s in from_file] == [s.world for s in from_cli]
