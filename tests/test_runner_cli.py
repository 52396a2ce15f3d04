"""granflow run / summary / plot, resumable runs, sweeps (process pool and Dask)."""

import json
import subprocess
import sys

import granflow as gf
import polars as pl
import pytest
from granflow.cli import main
from granflow.runner import execute
from granflow.study import run_grid

GAS = {
    "scene": "gas",
    "seed": 3,
    "params": {"L": 7.0, "phi": 0.25, "kn": 1e4, "sample_every": 50},
    "run": {"steps": 600, "checkpoint_every": 200},
    "output": {"snapshot_every": 300, "snapshot_format": "xyz"},
}


def test_run_summary_and_resume(tmp_path, capsys):
    toml = tmp_path / "gas.toml"
    toml.write_text(
        'scene = "gas"\nseed = 3\n[params]\nL = 7.0\nphi = 0.25\nkn = 1e4\nsample_every = 50\n'
        "[run]\nsteps = 600\ncheckpoint_every = 200\n"
        '[output]\nsnapshot_every = 300\nsnapshot_format = "xyz"\n'
    )
    out = tmp_path / "run"
    assert main(["run", str(toml), "--out", str(out), "--quiet"]) == 0
    man = json.loads((out / "manifest.json").read_text())
    assert man["status"] == "finished" and man["steps_done"] == 600
    assert (out / "series.parquet").exists() and (out / "checkpoint.gfck").exists()
    assert len(list((out / "snapshots").glob("*.xyz"))) == 2
    series = pl.read_parquet(out / "series.parquet")
    assert series["step"].to_list() == list(range(50, 601, 50))
    assert gf.io.read_params(out / "series.parquet")["seed"] == 3
    assert main(["summary", str(out)]) == 0
    assert "ke_trans_mean" in capsys.readouterr().out
    # running again skips the finished run
    assert execute(GAS, out).status == "skipped"


def test_resume_after_interrupt_matches_uninterrupted(tmp_path):
    a = execute(GAS, tmp_path / "a", progress=False)
    # an interrupted run: stop at 400 by running a shorter spec, then extend it
    spec = json.loads(json.dumps(GAS))
    spec["run"]["steps"] = 400
    execute(spec, tmp_path / "b", progress=False)
    man = json.loads((tmp_path / "b" / "manifest.json").read_text())
    man["spec"] = GAS  # pretend the 600-step run stopped at its step-400 checkpoint
    man["status"] = "interrupted"
    (tmp_path / "b" / "manifest.json").write_text(json.dumps(man))
    b = execute(GAS, tmp_path / "b", progress=False)
    assert b.status == "finished"
    sa = pl.read_parquet(tmp_path / "a" / "series.parquet")
    sb = pl.read_parquet(tmp_path / "b" / "series.parquet")
    assert sa.equals(sb)
    assert a.summary["ke_trans_last"] == b.summary["ke_trans_last"]


def test_bad_spec_names_the_key(tmp_path):
    bad = json.loads(json.dumps(GAS))
    bad["params"]["kn_typo"] = 1.0
    with pytest.raises(gf.ParameterError, match="params.kn_typo"):
        execute(bad, tmp_path / "x")
    bad = json.loads(json.dumps(GAS))
    bad["run"]["steps"] = -1
    with pytest.raises(gf.ParameterError, match="run.steps"):
        execute(bad, tmp_path / "y")


def test_cli_help():
    r = subprocess.run([sys.executable, "-m", "granflow.cli", "run", "--help"],
                       capture_output=True, text=True)
    assert r.returncode == 0 and "--out" in r.stdout


def test_sweep_local_pool_and_skip(tmp_path):
    base = {**GAS, "run": {"steps": 200}, "output": {}}
    df = run_grid(base, {"mu": [0.0, 0.5]}, tmp_path, seeds=[1, 2], workers=2)
    assert df.height == 4 and set(df["status"]) == {"finished"}
    assert sorted(df["mu"].to_list()) == [0.0, 0.0, 0.5, 0.5]
    ds = pl.scan_parquet(str(tmp_path / "**/*.parquet"), hive_partitioning=True).collect()
    assert set(ds["seed"].unique()) == {1, 2}
    again = run_grid(base, {"mu": [0.0, 0.5]}, tmp_path, seeds=[1, 2], workers=2)
    assert set(again["status"]) == {"skipped"}


def test_sweep_on_dask_local_cluster(tmp_path):
    import distributed
    base = {**GAS, "run": {"steps": 100}, "output": {}}
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        with distributed.Client(cluster) as client:
            df = run_grid(base, {"mu": [0.0, 0.3]}, tmp_path, seeds=[1], scheduler=client)
    assert df.height == 2 and set(df["status"]) == {"finished"}


def test_channel_run_summary_and_plots(tmp_path, capsys):
    spec = {
        "scene": "channel",
        "seed": 1,
        "params": {"W": 8, "H": 12, "B": 4, "phi_bar": 0.6, "kn": 1e5, "dt": 3e-4,
                   "sample_every": 20, "window": 5, "preparation": "pour"},
        "run": {"steps": 2000, "checkpoint_every": 1000},
        "output": {},
    }
    r = execute(spec, tmp_path / "ch", progress=False)
    assert r.status == "finished"
    assert (tmp_path / "ch" / "bins.parquet").exists()
    bins = pl.read_parquet(tmp_path / "ch" / "bins.parquet")
    assert bins["window"].n_unique() == 2000 // 20 // 5
    assert main(["plot", str(tmp_path / "ch")]) == 0
    pngs = sorted(p.name for p in (tmp_path / "ch" / "plots").glob("*.png"))
    assert pngs == ["fields.png", "mu_phi_I.png", "series.png", "velocity.png"]
    assert all((tmp_path / "ch" / "plots" / p).stat().st_size > 1000 for p in pngs)
    # error against run time written beside the results
    assert (tmp_path / "ch" / "errors.txt").exists()
    if (tmp_path / "ch" / "errors.parquet").exists():
        errs = pl.read_parquet(tmp_path / "ch" / "errors.parquet")
        assert errs.height > 0


def test_example_toml_files_validate():
    from pathlib import Path

    from granflow.runner import load_spec, validate_spec
    from granflow.study import check_grid, expand

    root = Path(__file__).parent.parent / "examples"
    files = sorted(root.glob("*.toml"))
    assert {f.name for f in files} >= {"channel.toml", "cell.toml", "cell_sweep.toml"}
    for f in files:
        spec = load_spec(f)
        if "grid" in spec:  # a sweep file: a scene spec plus its grid and seeds
            grid, seeds = spec.pop("grid"), spec.pop("seeds")
            check_grid(validate_spec(spec), grid)
            assert expand(spec, grid, seeds)
        else:
            validate_spec(spec)


def test_sweep_records_a_failing_run_and_goes_on(tmp_path):
    base = {**GAS, "run": {"steps": 100}, "output": {}}
    # kn so small that the gas overlaps beyond the guard: that run fails, the other finishes
    df = run_grid(base, {"kn": [1e4, 1e-3]}, tmp_path, seeds=[1], workers=1)
    st = dict(zip(df["kn"].to_list(), df["status"].to_list(), strict=True))
    assert st[1e4] == "finished" and st[1e-3] == "failed"
    assert "Error" in df.filter(pl.col("kn") == 1e-3)["error"][0]


def test_failed_run_keeps_what_it_recorded(tmp_path, monkeypatch):
    spec = {**GAS, "params": {**GAS["params"], "sample_every": 10}, "run": {"steps": 100_000},
            "output": {}}
    from granflow.scenes._base import SampleTables

    orig = SampleTables.drain
    fired = []

    def boom(self, core):  # once, after a chunk of the run past step 200
        orig(self, core)
        if core.step >= 200 and not fired:
            fired.append(core.step)
            raise gf.InstabilityError(f"instability at step {core.step}: test")

    monkeypatch.setattr(SampleTables, "drain", boom)
    with pytest.raises(gf.InstabilityError):
        execute(spec, tmp_path / "f", progress=False)
    man = json.loads((tmp_path / "f" / "manifest.json").read_text())
    assert man["status"] == "failed" and man["steps_done"] >= 200
    assert pl.read_parquet(tmp_path / "f" / "series.parquet").height == man["steps_done"] // 10


def test_duckdb_and_polars_lazy_scan_read_a_sweeps_channel_tables(tmp_path):
    """A sweep's runs land in one hive-partitioned dataset (root/mu=../seed=../bins.parquet):
    DuckDB and polars' lazy scan read the kernel samplers' tables across the runs as one, with
    the partition keys as columns."""
    duckdb = pytest.importorskip("duckdb")
    base = {"scene": "channel",
            "params": {"W": 6.0, "H": 8.0, "B": 3.5, "phi_bar": 0.6, "kn": 1e5, "dt": 3e-4,
                       "sample_every": 10, "window": 5, "preparation": "pour"},
            "run": {"steps": 300}, "output": {}}
    df = run_grid(base, {"mu": [0.2, 0.5]}, tmp_path, seeds=[1], workers=2)
    assert set(df["status"]) == {"finished"}
    per_run = {
        mu: pl.read_parquet(tmp_path / f"mu={mu}" / "seed=1" / "bins.parquet")
        for mu in (0.2, 0.5)
    }
    glob = str(tmp_path / "**" / "bins.parquet")
    con = duckdb.connect()
    rows = con.execute(
        "SELECT mu, seed, count(*) AS n, max(\"window\") AS w, avg(phi) AS phi "
        f"FROM read_parquet('{glob}', hive_partitioning = true) GROUP BY mu, seed ORDER BY mu"
    ).fetchall()
    assert [(float(r[0]), int(r[1])) for r in rows] == [(0.2, 1), (0.5, 1)]
    for mu, _seed, n, w, phi in rows:
        t = per_run[float(mu)]
        assert n == t.height and w == t["window"].max() == 300 // 50 - 1
        assert phi == pytest.approx(t["phi"].mean(), rel=1e-12)
    lazy = (pl.scan_parquet(glob, hive_partitioning=True)
            .filter(pl.col("window") == 0).select("mu", "bin", "phi").collect())
    assert lazy.height == 2 * per_run[0.2].filter(pl.col("window") == 0).height
    assert set(lazy["mu"].to_list()) == {0.2, 0.5}


def test_sweep_cli_records_failures(tmp_path, capsys):
    toml = tmp_path / "grid.toml"
    toml.write_text(
        'scene = "gas"\nseeds = [1, 2]\n[params]\nL = 7.0\nphi = 0.25\nkn = 1e4\n'
        "sample_every = 50\n[run]\nsteps = 100\n[grid]\nmu = [0.0, -1.0]\n"
    )
    out = tmp_path / "sw"
    # mu = -1 fails at its runs (recorded, the others finish): exit status 1
    assert main(["sweep", str(toml), "--out", str(out), "--workers", "1"]) == 1
    df = pl.read_parquet(out / "sweep.parquet")
    assert df.height == 4
    assert df.filter(pl.col("mu") == 0.0)["status"].to_list() == ["finished"] * 2
    bad = df.filter(pl.col("mu") == -1.0)
    assert bad["status"].to_list() == ["failed"] * 2 and bad["error"].str.contains("mu").all()
    assert "2 failed" in capsys.readouterr().out


@pytest.mark.parametrize(
    "grid, name",
    [({}, "grid"), ({"mu": []}, "grid.mu"), ({"no_such": [1]}, "no_such"),
     ({"mu": 0.3}, "grid.mu")],
)
def test_sweep_refuses_a_bad_grid_before_running(tmp_path, grid, name):
    base = {**GAS, "run": {"steps": 100}, "output": {}}
    with pytest.raises(gf.ParameterError, match=name):
        run_grid(base, grid, tmp_path, seeds=[1])
    assert not any(tmp_path.iterdir())

