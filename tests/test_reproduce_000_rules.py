"""The error rules of the 000 campaign (issue 34), fast, on synthetic channel tables: no
jackknife SE from fewer than 10 blocks, a drifting channel is "drifting" and a stationary one
is not, no stop before the minimum length, 3 seeds per point, and the report regenerated from
a tiny dataset with replica means, "not enough data" and the coverage audit."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
import polars as pl
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from granflow.analysis import channel as ch
from granflow.analysis import channel_profiles as cp
from granflow.analysis.stats import MIN_SE_BLOCKS, jackknife_se
from granflow.studies import reproduce_000 as rp
from granflow.studies.reproduce_000_report import write_report
from granflow.studies.reproduce_000_report_values import POINT_BY, main_steady, refuse_few_blocks

W = 20.0
#: window duration and sample interval of the synthetic tables (the campaign's)
WIN, DT = 2.0, 0.04


def channel_tables(nw: int = 150, drift: float = 0.0, seed: int = 0) -> tuple[pa.Table, pa.Table]:
    """``bins`` and ``series`` of a channel whose flow grows by the fraction ``drift`` over
    the run (0: stationary), with independent noise in every window."""
    rng = np.random.default_rng(seed)
    edges = np.concatenate([[0.0], np.arange(1.5, W - 1.5 + 0.01, 1.0), [W]])
    x_lo, x_hi = edges[:-1], edges[1:]
    x = 0.5 * (x_lo + x_hi)
    nb = x.size
    xi = np.minimum(x, W - x)
    u = ch.velocity_profile_31(xi, 3.0, 4.2, 4.0)
    phi = 0.63 - 0.1 * np.exp(-xi / 3.0)
    T = 0.01 + 0.5 * np.exp(-xi)
    sxy = -0.6 * (x - W / 2)
    cols: dict[str, list[np.ndarray]] = {}

    def add(k: str, v: Any) -> None:
        cols.setdefault(k, []).append(np.broadcast_to(np.asarray(v), (nb,)).copy())

    for w in range(nw):
        f = 1.0 + drift * w / nw
        uy = -u * f + 0.02 * rng.normal(size=nb)
        for k, v in (("window", w), ("t0", WIN * w), ("t1", WIN * (w + 1)), ("n_samples", 50),
                     ("bin", np.arange(nb)), ("x_lo", x_lo), ("x_hi", x_hi), ("x", x)):
            add(k, v)
        add("phi", phi + 0.001 * rng.normal(size=nb))
        add("u_y", uy)
        add("w_z", 0.5 * np.gradient(uy, x))
        add("T", T * (1 + 0.01 * rng.normal(size=nb)))
        add("sigma_xx", 20.0 * (1 + 0.01 * rng.normal(size=nb)))
        add("sigma_xy", sxy + 0.01 * rng.normal(size=nb))
        add("Gamma", 5.0 * T**1.5 * (1 + 0.01 * rng.normal(size=nb)))
        add("shear_production", sxy * np.gradient(uy, x))
    tab = {k: np.concatenate(v) for k, v in cols.items()}
    for k in ("window", "bin", "n_samples"):
        tab[k] = tab[k].astype(np.int64)
    t = np.arange(round(nw * WIN / DT)) * DT
    v = 3.5 * (1.0 + drift * t / (nw * WIN)) * (1 + 0.001 * rng.normal(size=t.size))
    series = pa.table({"step": np.arange(t.size), "t": t, "vcm_x": 0 * t, "vcm_y": -v,
                       "vcm_z": 0 * t})
    return pa.table(tab), series


def test_no_jackknife_se_from_fewer_than_10_blocks():
    assert MIN_SE_BLOCKS == 10
    reps = np.random.default_rng(1).normal(size=10)
    assert math.isnan(jackknife_se(0.0, reps[:9])) and math.isfinite(jackknife_se(0.0, reps))
    bins, series = channel_tables()
    few = cp.profiles(bins, series, n_blocks=5)
    enough = cp.profiles(bins, series, n_blocks=10)
    assert not few.enough_blocks and enough.enough_blocks
    assert few.table()["u_se"].is_nan().all() and enough.table()["u_se"].is_finite().all()
    # the values do not need the SEs; the section 3 numbers and the plug do
    s = ch.summary(bins, series, n_blocks=4)
    assert math.isfinite(s["u_slip"].value) and math.isnan(s["u_slip"].se)
    assert math.isnan(s["sigma_xx_mean"].se) and math.isnan(s["zones"]["xi_plug"])
    assert math.isfinite(ch.summary(bins, series)["u_slip"].se)


def test_the_report_refuses_the_committed_few_block_ses():
    pts = pl.DataFrame({"W": [40.0, 20.0], "phi_bar": [0.59, 0.6], "kn": [1e5, 1e5],
                        "B": [10.0, 10.0], "H": [20.0, 20.0], "seed": [1, 1],
                        "n_blocks": [2, 13], "sigma_xx_mean": [29.5, 19.0],
                        "sigma_xx_mean_se": [0.0007, 0.17], "xi_plug": [20.0, 8.5],
                        "phi_plug": [0.62, 0.645], "phi_plug_se": [0.0002, 0.0001]})
    d = refuse_few_blocks(pts)
    assert math.isnan(d["sigma_xx_mean_se"][0]) and d["sigma_xx_mean_se"][1] == 0.17
    assert math.isnan(d["xi_plug"][0]) and d["xi_plug"][1] == 8.5
    assert d["sigma_xx_mean"].to_list() == [29.5, 19.0]


@pytest.fixture(scope="module")
def rows():
    """point_row of three replicas of a stationary point and of a drifting one."""
    plan = rp.full_plan()
    out = {}
    for s in (1, 2, 3):
        p = rp.Point(20.0, 0.59, seed=s)
        out[p] = rp.point_row(p, plan, *channel_tables(seed=s))
    p = rp.Point(40.0, 0.6, seed=1)
    out[p] = rp.point_row(p, plan, *channel_tables(drift=0.05, seed=7))
    return out


def test_a_drifting_channel_is_drifting_and_a_stationary_one_is_not(rows):
    for p, r in rows.items():
        assert r["drift_tested"], r["drift_z"]
        if p.W == 40.0:
            assert r["state"] == "drifting" and r["drift_z"] > 3.0 and not r["converged"]
        else:
            assert r["state"] in ("steady", "fluctuating") and r["drift_z"] <= 3.0
            assert math.isfinite(r["tau_max"]) and r["n_blocks"] >= MIN_SE_BLOCKS


def test_no_stop_before_the_minimum_length():
    plan, p = rp.full_plan(), rp.Point(20.0, 0.59)
    row = {"state": "steady", "drift_tested": True, "T_avg": 300.0, "tau_max": 10.0,
           "u_slip": 10.0, "u_slip_se": 0.01, "u_max": 13.0, "u_max_se": 0.01}
    assert rp.converged(row, plan, p)
    # SEs on target, but 300 < 20 x 20 correlation times: it runs on
    assert not rp.converged({**row, "tau_max": 20.0}, plan, p)
    assert not rp.converged({**row, "T_avg": 150.0, "tau_max": 1.0}, plan, p)  # min_average
    assert not rp.converged({**row, "state": "drifting"}, plan, p)
    assert not rp.converged({**row, "drift_tested": False}, plan, p)
    assert not rp.converged({**row, "u_slip_se": math.nan}, plan, p)  # too few blocks


def test_the_widths_campaign_runs_the_widest_first_rained_and_000s_2000_plus_600():
    plan = rp.widths_plan()
    allp = [*plan.points, *plan.branches]
    assert len({p.key for p in allp}) == len(allp)
    assert all(p.prep == "rain" and p.H == rp.RAIN_H and p.key.endswith(f"_rain_s{p.seed}")
               for p in allp)
    # phi_bar = 0.60 across every width first, the widest first: a partial campaign still
    # answers the width question
    first = [(p.W, p.phi_bar) for p in plan.points[:11]]
    assert first[:2] == [(150.0, 0.60), (100.0, 0.60)]
    assert {p for _, p in first} == {0.60} and [w for w, _ in first] == sorted(
        (w for w, _ in first), reverse=True)
    assert {w for w, _ in first} == {150.0, 100.0, 60.0, 40.0, 20.0}
    seeds: dict[tuple[float, float, float], set[int]] = {}
    for p in plan.points:
        seeds.setdefault((p.W, p.phi_bar, p.B), set()).add(p.seed)
    assert all(len(s) == 1 for (w, _, b), s in seeds.items() if w >= 100 or b != 10.0)
    assert all(len(s) == rp.REPLICAS for (w, _, b), s in seeds.items() if w <= 60 and b == 10)
    assert {(w, p) for (w, p, _) in seeds} >= {(w, p) for w in (20.0, 40.0, 60.0, 100.0, 150.0)
                                              for p in (0.59, 0.60, 0.61)} | {(60.0, 0.62)}
    assert {b for (w, p, b) in seeds if (w, p) == (60.0, 0.60)} == {10.0, 20.0, 40.0}
    assert {(b.kn, b.seed) for b in plan.branches} == {(k, s) for k in rp.STIFF_KN
                                                       for s in rp.SEEDS}
    # 000's protocol: nothing averaged before t = 2000, 600 averaged at least, so every run
    # to 2600 at least; on where 600 is under 20 correlation times
    p = plan.points[0]
    assert (plan.t_dev_of(p), plan.t_least(p)) == (2000.0, 2600.0)
    assert plan.limits(p)[0] == rp.WIDTHS_T_MAX > 2600.0
    row = {"state": "steady", "drift_tested": True, "T_avg": 600.0, "tau_max": 10.0,
           "u_slip": 10.0, "u_slip_se": 0.01, "u_max": 13.0, "u_max_se": 0.01,
           "t_start": 1999.0, "t_end": 2599.99}
    assert not rp.converged(row, plan, p)  # however good the SEs
    assert rp.converged({**row, "t_start": 2000.0}, plan, p)
    assert not rp.converged({**row, "t_start": 2000.0, "t_end": 2590.0}, plan, p)
    # tau 37.6 (W = 40, s1): 600 holds 16 of the 20 correlation times, so it runs on
    assert not rp.converged({**row, "t_start": 2000.0, "tau_max": 37.6}, plan, p)
    assert rp.converged({**row, "t_start": 2000.0, "tau_max": 37.6, "T_avg": 760.0,
                         "t_end": 2760.0}, plan, p)
    # a branch's parent developed its flow: its average may start at once
    assert plan.t_dev_of(plan.branches[0]) == 0.0
    # and the report says so
    from granflow.studies.reproduce_000_report import stop_rule

    text = stop_rule(plan)
    assert "from t = 2000" in text and "reaches t = 3600" in text
    assert "every run that flows is 2600 long" in stop_rule(rp.paper_plan())
    assert "MSER start" in stop_rule(rp.full_plan())


def test_the_steady_part_starts_after_the_development_time():
    """A flow that develops (creeps up by 10 % over its first half, stationary after): MSER
    alone may start the average in the creep; with t_dev the average starts at t_dev (000's
    protocol), and nothing is averaged before t_dev + min_average."""
    bins, series = channel_tables(nw=200, seed=3)
    # the first half creeps: scale the flow of windows < 100 (t < 200) by 0.9 -> 1.0
    t0 = np.asarray(bins.column("t0").to_numpy())
    f = np.where(t0 < 200.0, 0.9 + 0.1 * t0 / 200.0, 1.0)
    bins = bins.set_column(bins.schema.get_field_index("u_y"), "u_y",
                           pa.array(np.asarray(bins.column("u_y").to_numpy()) * f))
    t = np.asarray(series.column("t").to_numpy())
    # (|v_cm| as noisy as a W = 20 run's, 4 %: MSER cannot see so slow a creep)
    noise = 1.0 + 0.04 * np.random.default_rng(5).normal(size=t.size)
    v = np.asarray(series.column("vcm_y").to_numpy()) * noise * np.where(
        t < 200.0, 0.9 + 0.1 * t / 200.0, 1.0)
    series = series.set_column(series.schema.get_field_index("vcm_y"), "vcm_y", pa.array(v))
    plan = rp.Plan("dev", (), t_dev=200.0, min_average=150.0, t_max=400.0, min_taus=1.0,
                   se_target=0.05)
    p = rp.Point(20.0, 0.59)
    row = rp.point_row(p, plan, bins, series)
    assert row["t_start"] == pytest.approx(200.0) and row["T_avg"] <= 200.0 + 1e-9
    assert rp.converged(row, plan, p)
    # the same run cut at t = 340 < t_dev + min_average: not averaged yet, runs on
    cut = rp.point_row(p, plan, bins.filter(pa.array(np.asarray(bins.column("t1").to_numpy())
                                                     <= 340.0)),
                       series.filter(pa.array(t <= 340.0)))
    assert "T_avg" not in cut and not cut["converged"] and cut["state"] == "fluctuating"
    # a run that ran to exactly t_dev + min_average: its blocks start at a window from t_dev
    # (whole blocks: some windows later) and its last sample is one sample short
    exact = replace(plan, t_dev=201.0, min_average=199.0)
    assert exact.t_least(p) == 400.0 and t[-1] < 400.0
    r = rp.point_row(p, exact, bins, series)
    assert r["t_start"] >= 202.0 and r["T_avg"] < 199.0 and rp.converged(r, exact, p)
    # without a development time the same tables are averaged from MSER's start
    free = rp.point_row(p, replace(plan, t_dev=0.0), bins, series)
    assert free["t_start"] < 200.0


@pytest.mark.parametrize("make", [rp.full_plan, rp.paper_plan])
def test_every_point_has_three_seeds(make):
    plan = make()
    allp = [*plan.points, *plan.branches, *plan.later]
    seeds: dict[tuple[Any, ...], set[int]] = {}
    for p in allp:
        seeds.setdefault((*(getattr(p, k) for k in POINT_BY), bool(p.parent)),
                         set()).add(p.seed)
    assert rp.REPLICAS >= 3 and all(len(s) >= rp.REPLICAS for s in seeds.values())
    assert len({p.key for p in allp}) == len(allp)
    # a branch starts from its own seed's parent
    assert all(b.parent.endswith(f"_s{b.seed}") for b in plan.branches)


def test_the_report_regenerates_from_a_tiny_dataset(rows, tmp_path):
    pts, extra = [], {"profile_rows": [], "zone_rows": [], "se_rows": []}
    for r in rows.values():
        r = dict(r)
        for k in extra:
            extra[k] += r.pop(k)
        r.update(n=4000, steps=1_000_000, prep_seconds=10.0, wall_seconds=100.0,
                 t_run=r["t_end"], phi_bar_achieved=r["phi_bar"], settle_time=1.0)
        pts.append(r)
    # a fourth point with one replica whose SEs rest on 2 blocks (as the committed W = 60)
    few = {**pts[0], "W": 60.0, "n_blocks": 2}
    pts.append(few)
    extra["profile_rows"] += [{**r, "W": 60.0} for r in extra["profile_rows"][:11]]
    pl.from_dicts(pts, infer_schema_length=None).write_parquet(tmp_path / "points.parquet")
    for k in extra:  # (no order.parquet: a dataset from before the snapshot's order)
        pl.from_dicts(extra[k], infer_schema_length=None).write_parquet(
            tmp_path / f"{rp.ROW_TABLES[k]}.parquet")
    text = write_report(tmp_path, tmp_path / "r.md", rp.full_plan(), rp.paper_plan()
                        ).read_text()
    assert "§3.3" not in text and "§3.2" in text
    # the replicas' mean: 3 replicas, within and between SEs both shown
    assert "| 20 | 0.59 | 3 |" in text
    u = [r for r in rows.values() if r["W"] == 20.0]
    between = np.std([r["u_slip"] for r in u], ddof=1) / math.sqrt(3) * 1.32
    assert f"/ {between:.2g} |" in text
    # the 2-block point: values, no SE
    assert "not enough data (2 blocks)" in text
    # the drifting point is listed and left out
    assert "Drifting runs (left out of the tables and fits): W = 40" in text
    assert "| 40 | 0.6 |" not in text.split("## Fig. 5")[1].split("## The profile's shape")[0]
    # but its shape, stationary while its level grows, counts on its own correlation time
    shape = text.split("## The profile's shape")[1].split("## Figures")[0]
    assert "| 40 | 0.6 | 1e+05 | 1 | drifting |" in shape, shape
    # the coverage audit: 3 replicas give 3 pairs, 2 degrees of freedom
    cov = text.split("## Coverage audit")[1]
    assert "| u_slip | 1 | 3 | 2 |" in cov and "No pairs" not in cov


def test_stiffness_zone_means_are_replica_means_with_both_ses():
    from granflow.analysis.replicas import small_sample_factor
    from granflow.studies.reproduce_000_report import stiffness_zone_means

    rows = [{"W": 20.0, "phi_bar": 0.59, "kn": kn, "B": 10.0, "H": 20.0, "seed": s,
             "zone": "dense", "n_bins": 6, "phi": 0.63, "phi_se": 5e-4, "u": 13.0 + 0.1 * s,
             "u_se": 0.05, "abs_dudx": 0.02, "abs_dudx_se": 1e-3, "T": 0.014, "T_se": 1e-4}
            for kn in (1e5, 1e6) for s in (1, 2, 3)]
    t = stiffness_zone_means(pl.DataFrame(rows), 20.0, 0.59)
    cell = t.filter(pl.col("quantity") == "u")["k_n = 1e+05 (bins)"][0]
    between = small_sample_factor(3) * 0.1 / math.sqrt(3)
    assert cell == (f"13.20 ± {between:.2f} (6) [within {0.05 / math.sqrt(3):.2g} / "
                    f"between {between:.2g}]")


def test_the_fluctuation_threshold_scales_with_the_particle_count():
    """000's 1 % (set for 1.7e5 particles) scaled as N^-1/2: a 3.9 % amplitude (W = 20,
    4500 particles) is steady there, fluctuating against the bare 1 %."""
    from granflow.analysis.channel_profiles import N_REF_000, flow_state
    from granflow.errors import ParameterError

    t = np.linspace(0.0, 400.0, 4001)
    v = 5.0 * (1.0 + 0.039 * np.sin(2 * np.pi * t / 7.0))
    series = {"t": t, "vcm_y": v}
    assert flow_state(series).state.value == "fluctuating"
    small = flow_state(series, n_particles=4500)
    assert small.state.value == "steady"
    assert small.thresholds["max_rel_amplitude"] == pytest.approx(
        0.01 * np.sqrt(N_REF_000 / 4500))
    assert flow_state(series, n_particles=int(N_REF_000)).state.value == "fluctuating"
    with pytest.raises(ParameterError, match="invalid n_particles = 0"):
        flow_state(series, n_particles=0)


def _claims_values(ratio: float, exponent: float = 0.5) -> pl.DataFrame:
    rows = []
    for w in (60.0, 100.0, 150.0):
        for phi in (0.59, 0.60):
            u = 2.0 * w**exponent
            r = {"W": w, "phi_bar": phi, "kn": 1e5, "B": 10.0, "H": 20.0, "branch": False,
                 "u_slip": u, "u_max": ratio * u, "delta_095": 0.3 * w,
                 "u_max_over_u_slip": ratio, "phi_plug": 0.63, "l_c": 11.5,
                 "omega_ratio_shearing": 0.5, "wall_friction": 0.3}
            rows.append({**r, **{f"{k}_se": 1e-3 * abs(v) for k, v in r.items()
                                 if isinstance(v, float) and k not in ("W", "phi_bar", "kn",
                                                                        "B", "H")}})
    return pl.DataFrame(rows)


def test_the_verdicts_on_000s_claims():
    from granflow.studies.reproduce_000_report_claims import drift_reasons, verdicts

    values = _claims_values(1.385)
    points = values.select("W", "phi_bar").with_columns(parent=pl.lit(""),
                                                        state=pl.lit("steady"))
    tab = verdicts(points, values)
    got = dict(zip(tab["claim (000)"].to_list(), tab["verdict"].to_list(), strict=True))
    assert all(v == "holds" for v in got.values()), tab
    # u ~ W^0.6 and a ratio of 1.34: those claims do not hold; a fluctuating run neither
    bad = _claims_values(1.34, 0.6)
    tab = verdicts(points.with_columns(state=pl.lit("fluctuating")), bad)
    got = dict(zip(tab["claim (000)"].to_list(), tab["verdict"].to_list(), strict=True))
    assert got["u_slip ∝ √W (W ≥ 100)"] == "does not hold"
    assert got["u_max/u_slip = 1.37-1.40 for every W, φ̄"] == "does not hold"
    assert got["δ0.95 ∝ W (W ≥ 100)"] == "holds"
    assert got["states: steady at φ̄ 0.59-0.61, fluctuating at 0.62, jammed above"] == \
        "does not hold"
    # 000's states are v_cm's: a run whose mean drifts is judged by its v_cm state, and a
    # drifting row without one (from before vcm_state) is not judged
    states = "states: steady at φ̄ 0.59-0.61, fluctuating at 0.62, jammed above"
    drift = points.with_columns(state=pl.lit("drifting"), vcm_state=pl.lit("steady"))
    tab = verdicts(drift, values).filter(pl.col("claim (000)") == states)
    assert tab["verdict"][0] == "holds" and tab["measured here"][0] == "6 of 6 runs as 000"
    tab = verdicts(drift.with_columns(vcm_state=pl.lit("fluctuating")), values)
    assert tab.filter(pl.col("claim (000)") == states)["verdict"][0] == "does not hold"
    tab = verdicts(drift.drop("vcm_state"), values).filter(pl.col("claim (000)") == states)
    assert tab["verdict"][0] == "cannot tell at this scale", tab
    # no channel at 000's widths: nothing can be told
    narrow = values.with_columns(pl.col("W") / 10)
    tab = verdicts(points.with_columns(pl.col("W") / 10), narrow)
    assert (tab["verdict"] == "cannot tell at this scale").all(), tab
    # a wide run that ran but drifts is named in the reason, its measure once below the table
    ran = pl.DataFrame({"W": [100.0], "phi_bar": [0.6], "parent": [""], "state": ["drifting"],
                        "t_end": [3200.0], "drift_z": [6.0], "drift_quantity": ["u_slip"],
                        "tau_max": [589.0], "T_avg": [1200.0], "seed": [1]})
    both = pl.concat([points.with_columns(pl.col("W") / 10), ran], how="diagonal_relaxed")
    tab = verdicts(both, narrow)
    why = tab.filter(pl.col("claim (000)") == "u_slip ∝ √W (W ≥ 100)")["why"][0]
    assert why == ("the widest steady channel here is W = 15; W = 100 (φ̄ = 0.6) drifts (below "
                   "the table) (two steady widths >= 100 needed)"), why
    assert drift_reasons(both, narrow) == [
        "- W = 100 (φ̄ = 0.6) ran to t = 3200 but drifts (u_slip: |z| = 6.0 by the thirds "
        "test; its slowest correlation time 589 against 1200 averaged)."]
    # (a drifting run narrower than a steady one is not a reason)
    assert drift_reasons(both.with_columns(W=pl.lit(1.0)), narrow) == []


def test_phi_ad_holds_only_at_000s_widths_and_where_the_fit_resolves_its_002():
    from granflow.studies.reproduce_000_report_claims import verdicts

    values = _claims_values(1.385)
    points = values.select("W", "phi_bar").with_columns(parent=pl.lit(""),
                                                        state=pl.lit("steady"))
    claim = "φ_ad: the kinetic coefficients diverge at 0.59 ± 0.002 (fig. 13)"

    def loose(W: float, rel_se: float, phi_ad: float = 0.59) -> pl.DataFrame:
        phi = np.array([0.50, 0.53, 0.55, 0.57, 0.58])
        y = 0.1 / (phi_ad - phi)  # an exact divergence (000's at the default)
        return pl.DataFrame({"W": W, "zone": "loose", "parent": "", "phi": phi,
                             **{c: y for c in ("p_phi", "mu_phi", "D_phi")},
                             **{f"{c}_se": rel_se * y for c in ("p_phi", "mu_phi", "D_phi")}})

    def verdict(profiles: pl.DataFrame) -> tuple[str, str]:
        r = verdicts(points, values, profiles).filter(pl.col("claim (000)") == claim)
        return r["verdict"][0], r["why"][0]

    assert verdict(loose(60.0, 1e-3))[0] == "holds"
    # the same divergence with 50 % SEs per bin: consistent with 0.59, but so is much else
    v, why = verdict(loose(60.0, 0.5))
    assert v == "cannot tell at this scale" and "exceeds 000's ± 0.002" in why
    # only narrower channels: not 000's widths
    v, why = verdict(loose(40.0, 1e-3))
    assert v == "cannot tell at this scale" and "W >= 60" in why
    # far off with a wide SE still does not hold
    assert verdict(loose(60.0, 0.02, phi_ad=0.62))[0] == "does not hold"


def test_a_claim_without_a_point_se_takes_its_replicas_that_have_one_and_never_prints_nan():
    """W = 60's point has no SE where one replica gave fewer than 10 blocks: the verdicts take
    the replicas that have one ("1 of 2 runs"), or print the value alone and cannot tell."""
    from granflow.studies.reproduce_000_report_claims import verdicts

    values = _claims_values(1.385).filter(pl.col("phi_bar") == 0.60)
    blind = values.with_columns(*(pl.when(pl.col("W") == 60.0).then(float("nan"))
                                  .otherwise(pl.col(f"{c}_se")).alias(f"{c}_se")
                                  for c in ("wall_friction", "omega_ratio_shearing")),
                                wall_friction=pl.when(pl.col("W") == 60.0).then(0.25)
                                .otherwise(pl.col("wall_friction")))
    base = {"W": 60.0, "phi_bar": 0.60, "kn": 1e5, "B": 10.0, "H": 20.0, "parent": "",
            "state": "steady"}
    runs = pl.DataFrame([
        {**base, "seed": 1, "wall_friction": 0.25, "wall_friction_se": 0.001,
         "omega_ratio_shearing": 0.418, "omega_ratio_shearing_se": 0.001},
        {**base, "seed": 2, "wall_friction": 0.26, "wall_friction_se": float("nan"),
         "omega_ratio_shearing": 0.419, "omega_ratio_shearing_se": float("nan")}])
    points = pl.concat([values.filter(pl.col("W") > 60).select(*POINT_BY).with_columns(
        parent=pl.lit(""), state=pl.lit("steady"), seed=pl.lit(1)), runs],
        how="diagonal_relaxed")
    tab = verdicts(points, blind)
    assert not any("nan" in str(c).lower() for c in tab.rows() for c in c), tab
    got = {r["claim (000)"]: r for r in tab.iter_rows(named=True)}
    mw = got["μ_wall independent of W"]
    # (0.3 at W = 150 against 0.25 at W = 60: 0.05 over an SE of 1e-3 -- does not hold)
    assert mw["measured here"] == "φ̄ = 0.6, W 60 → 150: +0.0500 ± 0.0010 (1 of 2 runs)", mw
    assert mw["verdict"] == "does not hold"
    om = got["Ω/ω → 1/2 in the shear zones"]
    assert om["verdict"] == "does not hold" and "W = 60: 0.4180 ± 0.0010 (1 of 2 runs)" in \
        om["measured here"], om
    assert "SEs from 1/2 exactly" in om["why"]
    # the replica's run SE takes the coverage audit's shortfall, as a one-replica point does
    mw = verdicts(points, blind, factors={"wall_friction": 2.0}).filter(
        pl.col("claim (000)") == "μ_wall independent of W").row(0, named=True)
    assert mw["measured here"] == ("φ̄ = 0.6, W 60 → 150: +0.0500 ± 0.0020 (1 of 2 runs, "
                                   "SE × 2.00 by the audit)"), mw
    # without a replica that has an SE: the value alone, no NaN, and cannot tell
    tab = verdicts(points.with_columns(wall_friction_se=pl.lit(float("nan"))), blind)
    mw = tab.filter(pl.col("claim (000)") == "μ_wall independent of W").row(0, named=True)
    assert mw["measured here"] == "φ̄ = 0.6, W 60 → 150: +0.0500", mw
    assert mw["verdict"] == "cannot tell at this scale" and "not enough data" in mw["why"]
    # 1/2 within 000's "close to": 0.52 holds, though it is resolvably above 1/2 exactly
    near = values.with_columns(omega_ratio_shearing=pl.lit(0.52))
    om = verdicts(points, near).filter(pl.col("claim (000)") == "Ω/ω → 1/2 in the shear zones")
    assert om["verdict"][0] == "holds", om


def test_a_channel_without_a_plug_says_what_its_centre_shears_and_a_misfit_form_fails():
    from granflow.studies.reproduce_000_report_claims import verdicts

    values = _claims_values(1.385).filter(pl.col("phi_bar") == 0.60)
    # W = 150: no plug bin (xi_plug at the centre), the centre shears of either sign
    values = values.with_columns(
        xi_plug=pl.when(pl.col("W") == 150.0).then(75.0).otherwise(10.0),
        phi_plug=pl.when(pl.col("W") == 150.0).then(float("nan")).otherwise(0.63))
    points = values.select("W", "phi_bar").with_columns(parent=pl.lit(""),
                                                        state=pl.lit("steady"))
    xi = np.arange(0.0, 75.0)
    gd = np.where(np.arange(xi.size) % 2 == 0, 1e-3, -1e-3)
    prof = pl.DataFrame({"W": 150.0, "parent": "", "xi": xi, "gamma_dot": gd,
                         "gamma_dot_se": 1e-4, "zone": "dense", "phi": 0.63,
                         **{c: 1.0 for c in ("p_phi", "mu_phi", "D_phi")},
                         **{f"{c}_se": 0.1 for c in ("p_phi", "mu_phi", "D_phi")}})
    tab = verdicts(points, values, prof)
    plug = tab.filter(pl.col("claim (000)") == "plug φ ≈ 0.63").row(0, named=True)
    assert plug["verdict"] == "cannot tell at this scale", plug
    assert "W = 150: no plug: the central 37.5 d shear at |du/dx| ~ 1.0e-03 (10 SEs, " \
        "median), of either sign" in plug["why"], plug
    # loose-zone coefficients that a divergence does not describe (a power 2, tiny SEs)
    phi = np.linspace(0.45, 0.58, 12)
    y = 0.1 / (0.59 - phi) ** 2
    loose = pl.DataFrame({"W": 60.0, "zone": "loose", "parent": "", "phi": phi,
                          **{c: y for c in ("p_phi", "mu_phi", "D_phi")},
                          **{f"{c}_se": 1e-3 * y for c in ("p_phi", "mu_phi", "D_phi")}})
    r = verdicts(points, values, loose).filter(
        pl.col("claim (000)") == "φ_ad: the kinetic coefficients diverge at 0.59 ± 0.002 "
        "(fig. 13)").row(0, named=True)
    assert r["verdict"] == "does not hold" and "misfits its 12 bins" in r["why"], r


def test_the_per_width_ratio_says_which_side_of_000s_range_it_lies():
    from granflow.studies.reproduce_000_report import ratio_by_width

    values = _claims_values(1.385).filter(pl.col("phi_bar") == 0.60).with_columns(
        ratio_how=pl.lit(""), u_max_over_u_slip=pl.Series([1.30, 1.385, 1.45]))
    gap = ratio_by_width(values)["outside 1.37-1.40 by"].to_list()
    assert gap == pytest.approx([-0.07, 0.0, 0.05])


def test_the_report_of_a_campaign_not_yet_begun(tmp_path):
    path = write_report(tmp_path, tmp_path / "r.md", rp.widths_plan(), rp.paper_plan())
    text = path.read_text()
    assert "No finished point yet" in text and "--widths" in text and "44 planned" in text


def test_the_depth_check_is_its_own_table_and_stays_out_of_the_width_analyses():
    from granflow.studies.reproduce_000_report import depth_table
    from granflow.studies.reproduce_000_report_values import main_depth

    values = _claims_values(1.385).with_columns(replicas=pl.lit(3))
    deep = values.filter((pl.col("W") == 60.0) & (pl.col("phi_bar") == 0.60))
    both = pl.concat([values, deep.with_columns(B=pl.lit(20.0)),
                      deep.with_columns(B=pl.lit(40.0), u_slip=pl.col("u_slip") * 1.05)])
    assert main_depth(both).equals(values)
    tab = depth_table(both)
    assert tab["B"].to_list() == [10.0, 20.0, 40.0]
    z = tab["u_slip vs B = 10 (SEs)"].to_list()
    assert z[0] is None and abs(z[1]) < 1e-9 and z[2] > 20
    assert not depth_table(values).height  # one depth: no check


def _row(lines: list[str], w: str) -> list[float]:
    """runs, core-hours least and cap, longest run of a width's row (its rate: _rate)."""
    row = next(ln for ln in "\n".join(lines).splitlines()
               if ln.startswith(f"| {w} | 1e+05 | 10 |"))
    cells = row.strip("|").split("|")
    return [float(c) for c in (cells[3], *cells[6:])]


def _rate(lines: list[str], w: str) -> tuple[float, str]:
    row = next(ln for ln in "\n".join(lines).splitlines()
               if ln.startswith(f"| {w} | 1e+05 | 10 |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    return float(cells[4]), cells[5]


def test_remaining_costs_the_plans_runs_less_what_a_started_run_has_done(tmp_path):
    from granflow.studies.reproduce_000_report_cost import remaining

    plan = rp.widths_plan()
    fresh = remaining(tmp_path, plan, 4e6)
    n = len(plan.points) + len(plan.branches)
    assert f"{n} runs of the widths plan" in "\n".join(fresh)
    assert _rate(fresh, "150") == (4e6, "W = 150 stints")
    # the piece the plan runs first: phi_bar = 0.60 at every width, B = 10
    assert "φ̄ = 0.6 at every width (B = 10), which the plan runs first, 11 runs" in "\n".join(
        fresh)
    runs, least, cap, longest = _row(fresh, "150")
    # 000's protocol: every run at least 2000 + 600 long, at most the cap
    assert runs == 3 and least < cap and longest < cap
    # each W = 150 run is 33,770 spheres (phi_bar 0.60) for t = 2600 at dt 3.79e-4
    w150 = next(p for p in plan.points if p.W == 150 and p.phi_bar == 0.60)
    one = 33770 * 2600 / w150.dt / 4e6 / 3600
    to_cap = rp.WIDTHS_T_MAX / 2600
    assert least == pytest.approx(1.8 / 0.6 * one, rel=0.02)
    assert cap == pytest.approx(to_cap * least, rel=0.02)
    assert longest == pytest.approx(0.61 / 0.6 * one * to_cap, rel=0.02)
    # a branch must run its minimum average, and may run to its cap
    b = plan.branches[0]
    b_least, b_cap = plan.t_least(b), plan.limits(b)[0]
    assert 0 < b_least < b_cap
    # the phi_bar = 0.60 run has reached t = 1000: 1000 of its 2600 are done (read from the
    # committed copy of its tables, so a fresh clone reports the same; its work directory is
    # ahead of it here, by a stint not yet kept)
    for d, t in (("progress", 1000.0), ("work", 1050.0)):
        (tmp_path / d / w150.key).mkdir(parents=True)
        pl.DataFrame({"t": [0.0, t]}).write_parquet(tmp_path / d / w150.key / "series.parquet")
    runs2, least2, cap2, _ = _row(remaining(tmp_path, plan, 4e6), "150")
    assert runs2 == 3
    assert least - least2 == pytest.approx(one * 1000 / 2600, abs=0.15)
    assert cap - cap2 == pytest.approx(least - least2, abs=0.15)
    assert remaining(tmp_path, rp.Plan("none", ()), 4e6) == []


def test_runs_left_are_costed_at_their_widths_measured_rate_or_a_wider_ones(tmp_path):
    from granflow.studies.reproduce_000_report_cost import particles, remaining

    plan = rp.widths_plan()
    done = next(p for p in plan.points if p.W == 20 and p.phi_bar == 0.6 and p.seed == 1)
    # a finished W = 20 point: 4503 spheres x 1e6 steps in 500 core-s, 100 of its 600 wall
    # seconds the preparation: 4503e6 / (500 x 5/6) particle-steps per core-second
    row = {**{k: getattr(done, k) for k in ("W", "phi_bar", "seed", "kn", "B", "H", "parent",
                                             "prep")},
           "state": "steady", "n": 4503, "steps": 1_000_000, "wall_seconds": 600.0,
           "prep_seconds": 100.0, "cpu_seconds": 500.0}
    pl.DataFrame([row]).write_parquet(tmp_path / "points.parquet")
    lines = remaining(tmp_path, plan, 4e6)
    r20 = 4503e6 / (500 * 5 / 6)
    assert _rate(lines, "20")[0] == pytest.approx(r20, rel=1e-3)
    assert _rate(lines, "20")[1] == "W = 20"
    # wider, unmeasured widths: the default (a narrower channel's rate bounds nothing)
    assert _rate(lines, "40") == (4e6, "W = 150 stints")
    # a W = 60 point measured: W = 40 is costed at it (the nearest wider), W = 100 is not
    w60 = {**row, "W": 60.0, "n": 13508, "cpu_seconds": 2000.0}
    pl.DataFrame([row, w60]).write_parquet(tmp_path / "points.parquet")
    lines = remaining(tmp_path, plan, 4e6)
    r60 = 13508e6 / (2000 * 5 / 6)
    assert _rate(lines, "40")[0] == pytest.approx(r60, rel=1e-3)
    assert _rate(lines, "40")[1] == "W = 60"
    assert _rate(lines, "100") == (4e6, "W = 150 stints")
    # the W = 20 rows' hours at the W = 20 rate: 8 runs left, from t = 0 to the cap at most
    runs, _, cap, _ = _row(lines, "20")
    assert runs == 8 and cap == pytest.approx(
        sum(particles(p) / p.dt * rp.WIDTHS_T_MAX / r20 / 3600 for p in plan.points
            if p.W == 20 and p.key != done.key), rel=0.01)


def test_runs_still_to_do_and_the_paper_scale_are_costed_at_the_slower_rate():
    from granflow.studies.reproduce_000_report_cost import (
        UNMEASURED_RATE,
        cost_section,
        planning_rate,
    )

    assert planning_rate(None)[0] == UNMEASURED_RATE
    assert planning_rate(0.5 * UNMEASURED_RATE) == (0.5 * UNMEASURED_RATE,
                                                    "measured on this dataset")
    fast, why = planning_rate(2 * UNMEASURED_RATE)
    assert fast == UNMEASURED_RATE and "slower than this dataset" in why
    # a dataset of W = 20 runs (the widths campaign's first, at ~1.4e7) steps faster than a
    # wide channel: its paper-scale estimate is costed at the wide rate, as its runs left are
    points = pl.DataFrame({"W": [20.0, 20.0], "kn": [1e5, 1e5], "n": [4500, 4500],
                           "steps": [3_000_000, 2_000_000], "wall_seconds": [1000.0, 700.0],
                           "cpu_seconds": [990.0, 690.0], "prep_seconds": [10.0, 8.0]})
    text, rate = cost_section(points, rp.paper_plan())
    assert rate > UNMEASURED_RATE
    paper = next(ln for ln in text if ln.startswith("000 runs W = 60-150"))
    assert f"at {UNMEASURED_RATE:.3g} particle-steps per core-second" in paper
    hours = float(paper.split("about ")[1].split(" core-hours")[0].replace(",", ""))
    steps = float(paper.split("runs to t = 2600, ")[1].split(" particle-steps")[0])
    assert hours == pytest.approx(steps / UNMEASURED_RATE / 3600, rel=2e-3)


def test_the_committed_pour_dataset_resumes_though_its_rows_predate_point_prep():
    from pathlib import Path

    from granflow.studies._campaign import done_keys

    d = Path(__file__).resolve().parents[1] / "docs" / "data" / "reproduce_000"
    assert "prep" not in pl.read_parquet(d / "points.parquet").columns
    plan = rp.full_plan()
    keys = done_keys(d, rp.Point)
    # its runs are the full plan's pour points (prep's default), not new ones to run again
    assert keys and keys <= {p.key for p in (*plan.points, *plan.branches, *plan.later)}
    assert not any("_rain" in k for k in keys)


def test_the_pour_plans_runs_left_name_the_campaign_that_carries_it_on(tmp_path):
    from granflow.studies.reproduce_000_report_cost import remaining

    text = "\n".join(remaining(tmp_path, rp.full_plan(), 4e6))
    assert "The widths (`--widths`" in text and "carries this one's question on" in text
    assert "carries" not in "\n".join(remaining(tmp_path, rp.widths_plan(), 4e6))
    # (the full plan runs width by width: no phi_bar piece comes first)
    assert "which the plan runs first" not in text


def test_the_runs_left_say_where_the_cap_cannot_hold_the_rules_correlation_times():
    from granflow.studies.reproduce_000_report_cost import tau_floor

    plan = rp.widths_plan()  # t = 2000-3600: 1600 of averaging, 20 correlation times
    pts = pl.DataFrame({"W": [20.0, 20.0, 100.0], "parent": ["", "", ""],
                        "tau_max": [7.0, 13.0, 589.0]})
    text = "\n".join(tau_floor(pts, plan))
    assert "at most 1600 time units (t = 2000-3600)" in text
    assert "W = 20: τ 7-13 (20 τ = 140-260, 2 runs); W = 100: τ 589 (20 τ = 11780, 1 run)" \
        in text
    assert "At W = 100 that is more than the cap allows" in text
    assert "more than the cap" not in "\n".join(tau_floor(pts.head(2), plan))
    assert tau_floor(pts.drop("tau_max"), plan) == []
    # a depth branch at a width is its own line, named by its B where the runs' B differ
    deep = pts.with_columns(B=pl.Series([10.0, 40.0, 10.0]))
    text = "\n".join(tau_floor(deep, plan))
    assert "W = 20, B = 10: τ 7 (20 τ = 140, 1 run); W = 20, B = 40: τ 13" in text, text
    assert "At W = 100, B = 10 that is more" in text
    # (a stiffness branch, named by its k_n where only k_n differs)
    stiff = pts.with_columns(kn=pl.Series([1e5, 1e6, 1e5]))
    text = "\n".join(tau_floor(stiff, plan))
    assert "W = 20, k_n = 100000: τ 7 (20 τ = 140, 1 run); W = 20, k_n = 1e+06: τ 13" in text, \
        text


def test_the_plug_order_section_tells_an_amorphous_plug_from_a_crystal():
    from granflow.studies.reproduce_000_report_order import order_lines, run_order

    run = {"W": 20.0, "phi_bar": 0.6, "kn": 1e5, "B": 10.0, "H": 20.0}
    xi = [0.75, 2.0, 3.0, 4.0]
    zone = ["wall", "dense", "plug", "plug"]
    prof = pl.DataFrame([{**run, "seed": s, "xi": x, "zone": z}
                         for s in (1, 2) for x, z in zip(xi, zone, strict=True)])
    # both halves of a W = 8 stand-in: x and W - x fold onto the same xi
    def order(xtal: float) -> pl.DataFrame:
        return pl.DataFrame([{**run, "seed": s, "t": 100.0, "x": x, "xi": x, "particles": 100,
                              "bonds": 1000, "Q6": 0.05 if z != "wall" else 0.12,
                              "crystal_fraction": xtal if z == "plug" else 0.0, "Z": 10.0}
                             for s in (1, 2) for x, z in zip(xi, zone, strict=True)
                             for _ in (0, 1)])
    values = pl.DataFrame([{**run, "phi_plug": 0.647, "phi_plug_se": 0.002}])
    r = run_order(order(0.0), prof, POINT_BY)
    plug = r.filter(pl.col("zone") == "plug")
    assert plug.height == 2 and (plug["spheres"] == 400).all()
    assert plug["Q6_random"][0] == pytest.approx(1 / math.sqrt(4000))
    text = "\n".join(order_lines(order(0.0), prof, values, POINT_BY))
    assert "The plug is amorphous in every run" in text and "0.6470 ± 0.0020" in text
    text = "\n".join(order_lines(order(0.9), prof, values, POINT_BY))
    assert "2 of 2 runs have an ordered plug" in text and "seed 1: 90.0%" in text
    assert order_lines(order(0.0).head(0), prof, values, POINT_BY) == []


def test_the_coverage_audit_says_which_run_ses_are_too_small():
    from granflow.studies.reproduce_000_report import coverage_verdicts

    tab = pl.DataFrame({"observable": ["u_slip", "phi_plug", "sigma_xx_mean", "wall_friction",
                                       "delta_095"],
                        "pairs": [3, 3, 3, 3, 0], "rms_z": [2.9, 4.3, 0.8, 0.2, None],
                        "rms_z_lo": [1.5, 2.2, 0.4, 0.1, None],
                        "rms_z_hi": [18.0, 27.0, 4.9, 0.9, None]})
    text = "\n".join(coverage_verdicts(tab))
    assert "**The run SEs are too small** for u_slip (2.90), phi_plug (4.30):" in text
    assert "too large for wall_friction (0.20)." in text
    assert "honest SEs (rms z within its 95 % interval of 1): sigma_xx_mean (0.80)." in text
    assert "delta_095" not in text


def test_unconverged_ses_are_blamed_on_the_rule_only_where_the_runs_predate_it(tmp_path):
    from granflow.studies.reproduce_000_report import _se_section

    run = {"W": 20.0, "phi_bar": 0.6, "kn": 1e5, "B": 10.0, "H": 20.0, "seed": 1}
    # the quarter's SE as large as the whole part's: not converged (T^-1/2 gives 2)
    se = pl.DataFrame([{**run, "fraction": f, "T_avg": 400 * f, "u_slip": 7.0, "u_max": 9.0,
                        "u_slip_se": 0.1, "u_max_se": 0.1,
                        "n_blocks": 10 + int(20 * f)} for f in (0.25, 0.5, 1.0)])
    old = "\n".join(_se_section(se, tmp_path)[0])
    new = "\n".join(_se_section(se, tmp_path, ruled=True)[0])
    assert "had not converged" in old and "this dataset predates them" in old
    assert "had not converged" in new and "predates" not in new
    assert "coverage audit below" in new
    # a quarter too short for 10 blocks (000's 600 averaged): judged on the half
    nan_q = se.with_columns(pl.when(pl.col("fraction") == 0.25).then(float("nan"))
                            .otherwise(pl.col("u_slip_se")).alias("u_slip_se"),
                            pl.when(pl.col("fraction") == 0.25).then(float("nan"))
                            .otherwise(pl.col("u_max_se")).alias("u_max_se"))
    half = "\n".join(_se_section(nan_q, tmp_path, ruled=True)[0])
    assert "first 0.5 of a steady part is 1.00 (u_slip)" in half
    none = "\n".join(_se_section(nan_q.filter(pl.col("fraction") != 0.5), tmp_path)[0])
    assert "No stretch shorter than a whole steady part has" in none


def test_the_creep_of_a_steady_part_is_its_relative_trend_per_1000_time_units():
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 1500.0, 0.5)
    noise = rng.normal(0.0, 0.2, t.size)
    # |v_cm| rising 5 % per 1000 time units from t = 500, flat before (the transient)
    v = 10.0 * (1 + 0.05 * np.clip(t - 500.0, 0, None) / 1000) + noise
    ser = pa.table({"t": t, "vcm_y": -v})
    c = rp.creep_row(ser, 500.0)
    mean = float(v[t >= 500].mean())
    # (slope 10 x 0.05 / 1000 per time unit: 0.5 per 1000, relative to the mean)
    assert c["creep"] == pytest.approx(0.5 / mean, rel=0.1)
    assert c["creep_z"] > 10
    flat = rp.creep_row(pa.table({"t": t, "vcm_y": -(10.0 + noise)}), 500.0)
    assert abs(flat["creep_z"]) < 4 and abs(flat["creep"]) < 0.01


def test_the_report_pools_the_creep_over_replicas_and_names_the_creeping_points():
    from granflow.studies.reproduce_000_report_creep import creep_lines, creep_table

    base = {"W": 20.0, "phi_bar": 0.6, "kn": 1e5, "B": 10.0, "H": 20.0, "parent": "",
            "state": "steady", "converged": True, "t_start": 500.0, "t_end": 1500.0}
    rows = [{**base, "seed": s, "creep": c, "creep_se": se, "creep_z": c / se}
            for s, c, se in ((1, 0.04, 0.01), (2, 0.07, 0.03), (3, 0.06, 0.02))]
    rows += [{**base, "W": 40.0, "seed": s, "creep": c, "creep_se": 0.02,
              "creep_z": c / 0.02} for s, c in ((1, 0.01), (2, -0.01))]
    tab = creep_table(pl.DataFrame(rows), POINT_BY)
    w = np.array([1e4, 1 / 9e-4, 2.5e3])
    want = float((w * [0.04, 0.07, 0.06]).sum() / w.sum())
    r20 = tab.filter(pl.col("W") == 20).row(0, named=True)
    assert r20["creep per 1000 t"] == pytest.approx(want)
    assert r20["SE"] == pytest.approx(w.sum() ** -0.5) and r20["replicas"] == 3
    assert tab.filter(pl.col("W") == 40)["creep per 1000 t"][0] == pytest.approx(0.0)
    text = "\n".join(creep_lines(pl.DataFrame(rows), POINT_BY))
    assert "**1 of 2 points creep**" in text and f"W = 20, φ̄ = 0.6: {want:+.1%} per 1000" in text
    # replicas that stop together (000's fixed length) are biased alike, not spread
    assert "stopped apart" not in text
    rows[0]["t_end"] = 1050.0
    text = "\n".join(creep_lines(pl.DataFrame(rows), POINT_BY))
    assert "the replicas of W = 20, φ̄ = 0.6 stopped apart" in text
    assert creep_lines(pl.DataFrame([{k: v for k, v in r.items() if "creep" not in k}
                                     for r in rows]), POINT_BY) == []


def test_a_one_replica_point_takes_the_audits_shortfall_on_its_run_ses():
    from granflow.studies.reproduce_000_report import _se_note, coverage_table
    from granflow.studies.reproduce_000_report_values import audit_factors, point_values

    def run(W: float, seed: int, u: float, ratio: float) -> dict[str, Any]:
        return {"W": W, "phi_bar": 0.6, "kn": 1e5, "B": 10.0, "H": 20.0, "seed": seed,
                "parent": "", "state": "steady", "n_blocks": 20, "xi_plug": 5.0,
                "xi_wall": 1.0, "l_c_at_bound": False, "u_slip": u, "u_slip_se": 0.1,
                "u_max_over_u_slip": ratio, "u_max_over_u_slip_se": 0.01}

    # W = 20: three replicas whose u_slip spread far beyond their SEs (pairs differ by 0.5,
    # 1.0 and 0.5 against a combined SE of 0.1414: rms z 5.0) but whose ratios agree
    narrow = [run(20.0, 1, 7.0, 1.28), run(20.0, 2, 7.5, 1.29), run(20.0, 3, 8.0, 1.28)]
    points = pl.DataFrame([*narrow, run(40.0, 1, 20.0, 1.33)])
    f = audit_factors(coverage_table(points))
    assert set(f) == {"u_slip"} and f["u_slip"] == pytest.approx(5.0)
    v = point_values(points, f).sort("W")
    one, three = v.row(1, named=True), v.row(0, named=True)
    # the one-replica point's u_slip SE carries the shortfall; its ratio (audited honest) not
    assert one["u_slip_se"] == pytest.approx(0.1 * f["u_slip"])
    assert one["u_slip_se_within"] == pytest.approx(0.1)
    assert one["u_max_over_u_slip_se"] == pytest.approx(0.01)
    assert one["audit_scaled"] and "run SEs × the audit's rms z" in _se_note(one)
    # the replicated point keeps the larger of its within and between SEs
    assert three["u_slip_se"] == pytest.approx(point_values(points).sort("W")["u_slip_se"][0])
    assert not three["audit_scaled"] and "audit" not in _se_note(three)
    # a one-replica point without the scaled SEs (too few blocks) is not said to be scaled
    bare = points.with_columns(pl.when(pl.col("W") == 40.0).then(None).otherwise(
        pl.col("u_slip_se")).cast(pl.Float64).alias("u_slip_se"))
    assert point_values(bare, f).sort("W").row(1, named=True)["audit_scaled"] is False
    # without pairs (one replica everywhere) nothing is scaled
    assert audit_factors(coverage_table(points.filter(pl.col("seed") == 1))) == {}


def test_runs_stopped_by_an_earlier_cap_are_named():
    from granflow.studies.reproduce_000_report import _earlier_cap_line

    plan = rp.widths_plan()
    base = {"phi_bar": 0.6, "kn": 1e5, "B": 10.0, "H": 20.0, "parent": "", "seed": 1}
    pts = pl.DataFrame([
        {**base, "W": 60.0, "seed": 2, "state": "steady", "converged": False, "t_end": 3200.0},
        {**base, "W": 100.0, "state": "drifting", "converged": False, "t_end": 3199.97},
        {**base, "W": 60.0, "state": "steady", "converged": True, "t_end": 3100.0},
        {**base, "W": 20.0, "state": "arrested", "converged": False, "t_end": 900.0},
        {**base, "W": 150.0, "state": "steady", "converged": False,
         "t_end": plan.t_max - 0.01}])
    assert _earlier_cap_line(pts, plan) == (
        " Ended at an earlier cap (t = 3200), unconverged, where the cap is now t = 3600: "
        "W = 60, φ̄ = 0.6, seed 2 (steady); W = 100, φ̄ = 0.6, seed 1 (drifting).")
    assert _earlier_cap_line(pts.filter(pl.col("converged")), plan) == ""


def test_a_run_that_never_settles_is_named_with_its_trend():
    from granflow.studies.reproduce_000_report import unsettled_lines

    base = {"phi_bar": 0.6, "kn": 1e5, "B": 10.0, "H": 20.0, "parent": "", "t_end": 3200.0}
    flow = pl.DataFrame([{**base, "W": 150.0, "seed": 1, "state": "accelerating",
                          "rel_drift": 0.031},
                         {**base, "W": 40.0, "seed": 2, "state": "decelerating",
                          "rel_drift": -0.012},
                         {**base, "W": 20.0, "seed": 1, "state": "steady", "rel_drift": 0.001}])
    lines = unsettled_lines(flow)
    assert lines == [
        "- W = 40, φ̄ = 0.6, seed 2: still decelerating at t = 3200, |v_cm| -1.2% over its "
        "last half (t = 1600-3200): no steady value, so in no table, fit or verdict.",
        "- W = 150, φ̄ = 0.6, seed 1: still accelerating at t = 3200, |v_cm| +3.1% over its "
        "last half (t = 1600-3200): no steady value, so in no table, fit or verdict."]
    assert unsettled_lines(flow.filter(pl.col("state") == "steady")) == []


@pytest.mark.slow
def test_a_committed_copy_keeps_what_the_rows_read_and_a_run_goes_on_from_it(tmp_path):
    from granflow.studies._campaign import progress

    # the quick plan's channel with a development time: the bins before it are not read
    plan = replace(rp.quick_plan(), t_dev=10.0, min_average=20.0, t_max=60.0)
    point = plan.points[0]
    whole = rp.STUDY.scene(point, plan, 1)
    rp.STUDY.start(whole, point, plan, tmp_path)
    whole.run(round(35.0 / point.dt), progress=False)
    tabs = whole.tables()
    kept = rp.STUDY.kept_tables(point, plan, tabs)
    assert kept["bins"].num_rows < tabs["bins"].num_rows
    # before the development time, the last window alone (a restored scene has a bins table)
    early = rp.STUDY.kept_tables(point, replace(plan, t_dev=1000.0), tabs)["bins"]
    assert early.num_rows and set(early["window"].to_pylist()) == {
        max(tabs["bins"]["window"].to_pylist())}
    assert np.isnan(kept["series"].column("ke_trans").to_numpy()).all()

    def row(t: dict[str, pa.Table] | Any) -> dict[str, Any]:
        return rp.point_row(point, plan, t["bins"], t["series"], 100)

    def same(a: dict[str, Any], b: dict[str, Any]) -> None:
        assert a.keys() == b.keys()
        for k in a:
            assert a[k] == b[k] or (isinstance(a[k], float) and math.isnan(a[k])
                                    and math.isnan(b[k])), k

    assert row(tabs)["state"] != "short"  # (measured: its steady part is averaged)
    same(row(tabs), row(kept))
    # a run restored from the copy (on a new machine) goes on to the same row
    work = tmp_path / "work"
    work.mkdir()
    whole.save_checkpoint(work / "checkpoint.gfck")
    (work / "meta.json").write_text("{}")
    progress.keep(work, tmp_path / "progress", kept)
    moved = tmp_path / "moved"
    assert progress.restore(tmp_path / "progress", moved)
    resumed = rp.STUDY.scene(point, plan, 1)
    resumed.restore(moved / "checkpoint.gfck")
    resumed.load_tables({f.stem: pq.read_table(f) for f in moved.glob("*.parquet")})
    for s in (whole, resumed):
        s.run(round(10.0 / point.dt), progress=False)
    same(row(whole.tables()), row(resumed.tables()))


def test_the_findings_give_a_drifting_runs_vcm_state():
    from pathlib import Path

    from granflow.studies.reproduce_000_report import findings
    from granflow.studies.reproduce_000_report_values import point_values

    # the widths campaign's W = 100 run: drifting, its v_cm steady
    d = Path(__file__).resolve().parents[1] / "docs" / "data" / "reproduce_000_widths"
    points = pl.read_parquet(d / "points.parquet")
    wide = points.filter(pl.col("W") == 100)
    assert wide["state"].to_list() == ["drifting"] and wide["vcm_state"][0] is not None
    text = "\n".join(findings(points, point_values(points)))
    assert f"- W = 100: φ̄ 0.6: drifting (v_cm {wide['vcm_state'][0]}) (000" in text
    # (rows from before vcm_state: their state as it is)
    text = "\n".join(findings(points.drop("vcm_state"), point_values(points)))
    assert "- W = 100: φ̄ 0.6: drifting (000" in text


def test_the_ratio_is_judged_on_its_own_correlation_time_where_the_level_leaves_no_se():
    from granflow.studies.reproduce_000_report_claims import verdicts
    from granflow.studies.reproduce_000_report_shape import own_values, shape_lines

    claim = "u_max/u_slip = 1.37-1.40 for every W, φ̄"
    values = _claims_values(1.385).filter(pl.col("W") == 60.0)
    # (the W = 60 points' level has a slow mode: no SE of anything from their blocks)
    blind = values.with_columns(u_max_over_u_slip_se=pl.lit(float("nan")))
    base = {"W": 60.0, "phi_bar": 0.6, "kn": 1e5, "B": 10.0, "H": 20.0, "parent": "",
            "tau_max": 250.0, "u_max_over_u_slip_own_tau": 1.5, "u_max_over_u_slip_own_blocks": 32,
            "delta_095_own": 5.5, "delta_095_own_se": 0.02, "delta_095_own_tau": 2.3,
            "delta_095_own_blocks": 32}
    runs = pl.DataFrame([
        {**base, "seed": 1, "state": "drifting", "vcm_state": "steady",
         "u_max_over_u_slip_own": 1.3640, "u_max_over_u_slip_own_se": 0.0006},
        {**base, "seed": 2, "state": "steady", "vcm_state": "steady",
         "u_max_over_u_slip_own": 1.3630, "u_max_over_u_slip_own_se": 0.0006},
        # (an arrested run does not count, whatever its shape)
        {**base, "seed": 3, "state": "arrested", "vcm_state": "arrested",
         "u_max_over_u_slip_own": 1.20, "u_max_over_u_slip_own_se": 0.0006}])
    tab = verdicts(runs, blind).filter(pl.col("claim (000)") == claim)
    assert tab["verdict"][0] == "does not hold", tab
    assert tab["measured here"][0] == "W = 60: 1.3635 ± 0.0009 (own τ, 2 runs)", tab
    # without runs that carry it, the width cannot be told (and is still named)
    tab = verdicts(runs.drop(c for c in runs.columns if "_own" in c), blind)
    tab = tab.filter(pl.col("claim (000)") == claim)
    assert tab["verdict"][0] == "cannot tell at this scale" and "W = 60" in tab["why"][0]
    # where the points' own SEs exist they are used, not the shape's
    tab = verdicts(runs, values).filter(pl.col("claim (000)") == claim)
    assert tab["verdict"][0] == "holds" and "own τ" not in tab["measured here"][0], tab
    # the section: the point's mean over its two flowing runs, their pair z
    ov = own_values(runs, POINT_BY)
    assert ov["replicas"].to_list() == [2]
    text = "\n".join(shape_lines(runs, POINT_BY))
    assert "1.3635 ± 0.0009" in text and "u_max/u_slip z = +1.2" in text, text
    # the per-width ratio (findings, fig. 5's table and the extrapolation) takes it alike
    from granflow.studies.reproduce_000_report import ratio_by_width
    from granflow.studies.reproduce_000_report_claims import with_own_ratio

    at = pl.col("phi_bar") == 0.6  # (the point the runs belong to; 0.59 keeps no SE)
    st = with_own_ratio(main_steady(blind), runs)
    assert st.sort("phi_bar")["ratio_how"].to_list() == ["", " (own τ, 2 runs)"]
    row = ratio_by_width(st.filter(at)).row(0, named=True)
    assert row["u_max/u_slip"] == "1.3635 ± 0.0009 (own τ, 2 runs)" and not row["SE"]
    assert with_own_ratio(main_steady(values), runs)["ratio_how"].to_list() == ["", ""]


def test_a_row_carries_the_shape_on_its_own_correlation_time(rows):
    for r in rows.values():
        if r["state"] in ("steady", "fluctuating", "drifting"):
            assert r["u_max_over_u_slip_own_blocks"] >= 2
            assert math.isfinite(r["u_max_over_u_slip_own"])
            assert abs(r["u_max_over_u_slip_own"] - r["u_max_over_u_slip"]) < 0.01
