"""The LAMMPS side of the rate-controlled comparison (benchmarks/lammps_rate_cell.py) without
LAMMPS: its box slip taken out of sigma_xx (measured per sample where the series has it), and
thinning that keeps the full series' steady start."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import polars as pl
import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "lammps_rate_cell.py"


@pytest.fixture(scope="module")
def lrc():
    spec = importlib.util.spec_from_file_location("lammps_rate_cell", BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


HANDOFF = {"rate": 0.003, "H": [[12.0, 0.0, 0.0], [0.0, 11.0, 0.0], [0.0, 0.0, 12.0]],
           "density": 1.9, "p_ext": 1e-4}


def _series(n: int = 4000, seed: int = 0) -> pl.DataFrame:
    """A stress series with a transient in phi over its first ~15 % (time 0-600 of 4000)."""
    rng = np.random.default_rng(seed)
    t = np.arange(1, n + 1, dtype=float)
    noise = rng.normal(0.0, 1.0, (5, n))
    phi = 0.58 - 0.01 * np.exp(-t / 150.0) + 2e-4 * noise[0]
    syy = -1e-4 * (1 + 0.01 * noise[1])
    return pl.DataFrame({"t": t, "phi": phi, "sigma_xx": -1e-4 * (1 + 0.01 * noise[2]),
                         "sigma_yy": syy, "sigma_zz": -1e-4 * (1 + 0.01 * noise[3]),
                         "sigma_xy": 0.3 * syy * (1 + 0.01 * noise[4]),
                         "ly": 11.0 + 0.5 * (1 - np.exp(-t / 150.0))})


def test_the_box_slip_is_the_measured_one_where_the_series_has_it(lrc):
    s = _series(10)
    formula = lrc.without_slip(s, HANDOFF)
    dv = HANDOFF["rate"] * (s["ly"] - 11.0) / 2
    assert np.allclose(s["sigma_xx"] - formula["sigma_xx"], 1.9 * s["phi"] * dv**2)
    measured = lrc.without_slip(s.with_columns(slip_vx=pl.lit(0.01)), HANDOFF)
    assert np.allclose(s["sigma_xx"] - measured["sigma_xx"], 1.9 * s["phi"] * 1e-4)


def test_thinning_keeps_the_full_series_steady_start(lrc, tmp_path):
    d = tmp_path / "series"
    d.mkdir()
    full = _series()
    full.write_parquet(d / "granflow_mu0_I0.15_s1.parquet")
    (d / "granflow_mu0_I0.15_s1.json").write_text(json.dumps({"every": 10,
                                                              "handoff": HANDOFF}))
    t_full, settled = lrc.mser_start(full, 1e-4)
    assert 200 < t_full < 1500 and settled  # (the transient is found)
    assert lrc.thin_series(tmp_path, 7) == 1 and lrc.thin_series(tmp_path, 7) == 0
    meta = json.loads((d / "granflow_mu0_I0.15_s1.json").read_text())
    assert meta["mser_start_full"] == [t_full, settled] and meta["every"] == 70
    thinned = pl.read_parquet(d / "granflow_mu0_I0.15_s1.parquet")
    assert thinned.height == -(-full.height // 7)
    row = lrc.run_stats(thinned, 1e-4, 0.1, tuple(meta["mser_start_full"]))
    assert row["t_steady"] == thinned["t"].filter(thinned["t"] >= t_full)[0]
    runs, _ = lrc.build_tables(tmp_path, [0.0], [0.15], [1], 0.1)
    assert runs["t_steady"][0] == row["t_steady"]
