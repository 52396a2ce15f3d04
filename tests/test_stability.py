"""granflow.studies.stability: the fast (CI) cases of the stability suite."""

from __future__ import annotations

import math

import polars as pl
import pytest
from granflow.studies import stability as st

KERNEL = [c for c in st.select("fast") if c.scene is None]
SCENE_FAST = [c for c in st.select("fast") if c.scene is not None]


@pytest.fixture(scope="module")
def kernel_table() -> pl.DataFrame:
    return st.run_suite(names=[c.name for c in KERNEL])


def test_registry_covers_the_issue():
    names = set(st.CASES)
    for kn in ("1e+05", "1e+06", "1e+07", "1e+08", "1e+09", "1e+10"):
        assert f"collision_kn_{kn}" in names
    for e in ("0.05", "0.2", "0.5", "0.82", "1"):
        assert f"collision_e_n_{e}" in names
    assert {"collision_overdamped_xi_n", "gas_mu_0", "gas_mu_0.001", "gas_mu_10",
            "gas_poly_mono", "gas_poly_0.9-1.1", "gas_poly_ratio_3", "overlap_0.4",
            "channel_jammed_0.66", "channel_free_fall_0.05"} <= names
    assert {f"channel_kn_{k}" for k in ("1e+05", "1e+06", "1e+07", "1e+08")} <= names
    assert {"cell_p_1e-06_tau_0", "cell_p_1e-06_tau_1.2", "cell_p_1e-03_tau_0",
            "cell_p_1e-03_tau_1.2", "cell_energy_balance"} <= names
    # above yield the cell must stop with the kernel's InstabilityError, not finish
    for p in ("1e-06", "1e-03"):
        c = st.CASES[f"cell_p_{p}_tau_1.2"]
        assert c.expect == "unstable" and c.refuse_with == (st.InstabilityError,)
    assert st.CASES["cell_energy_balance"].kind == "fast"
    assert all(c.kind in ("fast", "long") for c in st.CASES.values())


def test_kernel_cases_finish_cleanly_or_are_refused(kernel_table):
    t = kernel_table
    assert t.height == len(KERNEL)
    for r in t.iter_rows(named=True):
        assert r["passed"] is True, (r["case"], r["status"], r["error"])
        if r["finished"]:
            assert r["nan_free"] and r["max_overlap"] < 0.25, r["case"]
            assert r["energy_ok"] is True and r["dissipation"] >= -1e-3 * max(
                abs(r["work"]), 1.0), r["case"]
            assert r["error"] == ""
        else:
            case = st.CASES[r["case"]]
            assert r["status"] == "refused (expected)"
            assert r["error"].split(":")[0] in {e.__name__ for e in case.refuse_with}


def test_refusals_name_the_problem(kernel_table):
    err = {r["case"]: r["error"] for r in kernel_table.iter_rows(named=True)}
    assert "xi_n" in err["collision_overdamped_xi_n"] and "over-damped" in err[
        "collision_overdamped_xi_n"]
    assert "e_n" in err["collision_e_n_0"]
    assert "overlap" in err["overlap_0.4"]


def test_collisions_measure_e_n_and_dissipate_1_minus_e2(kernel_table):
    for r in kernel_table.filter(pl.col("case").str.starts_with("collision_")).iter_rows(
            named=True):
        if not r["finished"]:
            continue
        case = st.CASES[r["case"]]
        e = float(r["measured"].split("e_n=")[1].split(",")[0])
        assert abs(e - case.e_n) < 2e-3, r["case"]
        # closed system: D = -dE = (1 - e^2) E0 (head-on, no rotation)
        assert r["work"] == 0.0
        assert r["energy_balance"] == pytest.approx(1 - e * e, abs=1e-6), r["case"]


def test_scene_fast_cases_or_not_available(tmp_path):
    t = st.run_suite(names=[c.name for c in SCENE_FAST], out=tmp_path)
    assert pl.read_parquet(tmp_path / "stability.parquet").height == t.height
    for r in t.iter_rows(named=True):
        if r["status"] == "scene not available":
            assert r["passed"] is None  # never counted as passing
        else:
            assert r["passed"] is True, (r["case"], r["status"], r["error"])
    row = {r["case"]: r for r in t.iter_rows(named=True)}
    ff = row["channel_free_fall_0.05"]
    if ff["finished"]:
        assert "flow_state=accelerating" in ff["measured"]
        assert ff["energy_balance"] > -2e-2 and ff["work"] > 0
    cb = row["cell_energy_balance"]
    if cb["finished"]:
        # the imposed stress does work, the contacts dissipate it, the ledger closes
        assert cb["work"] > 0 and cb["dissipation"] > 0 and cb["energy_ok"] is True
        assert abs(cb["energy_residual"]) <= st.CASES["cell_energy_balance"].closure_tol
        assert cb["dissipation"] == pytest.approx(cb["work"], rel=0.1)  # steady: W ~ D
        assert 0 < cb["energy_balance"] <= 1.0 + 1e-9


def test_energy_balance_from_a_trace():
    # free fall of unit mass from rest: P = g^2 t, W = g^2 T^2 / 2, E = v^2 / 2
    ts = [0.1 * k for k in range(11)]
    tr = st.Trace(t=ts, energy=[0.5 * s * s for s in ts], power=list(ts),
                  max_overlap=[0.0] * 11, vcm=[(0.0, -s, 0.0) for s in ts])
    eb = st.energy_balance(tr)
    assert eb["work"] == pytest.approx(0.5) and eb["dissipation"] == pytest.approx(0.0, abs=1e-12)
    # energy created: flagged through a negative balance
    tr.energy[-1] *= 1.1
    assert st.energy_balance(tr)["energy_balance"] < -0.05


def test_cli_list_and_unknown_case(capsys):
    assert st.main(["--list"]) == 0
    assert "collision_kn_1e+10" in capsys.readouterr().out
    with pytest.raises(Exception, match="invalid case"):
        st.select(names=["nope"])
    assert math.isfinite(st.MAX_OVERLAP)
