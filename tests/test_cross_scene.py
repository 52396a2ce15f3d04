"""The cross-scene study (granflow.studies.cross_scene): the cell measured in the channel's
variables, the calibration's fits, and the whole chain on its --quick plan against the committed
channel dataset."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import polars as pl
import pyarrow as pa
import pytest
from granflow.analysis import replicas
from granflow.analysis import rheology as rh
from granflow.continuum import LocalLaw
from granflow.continuum import calibration as acal
from granflow.continuum import channel_model as cm
from granflow.continuum.constants import ModelConstants
from granflow.errors import ParameterError
from granflow.material import MATERIAL_000
from granflow.studies import cross_scene as cs
from granflow.studies import cross_scene_report as csr

CHANNEL = Path(__file__).resolve().parents[1] / "docs" / "data" / "reproduce_000"
CROSS = Path(__file__).resolve().parents[1] / "docs" / "data" / "cross_scene"
WIDTHS = Path(__file__).resolve().parents[1] / "docs" / "data" / "reproduce_000_widths"


def test_the_gradient_frame_is_the_channels_measure():
    # simple shear v_x = g y under p, tau and a gradient normal stress sigma_yy != p: the
    # cell's I = |D| a/sqrt(p/rho) = (g/2)/sqrt(p); the channel's is g/sqrt(sigma_yy)
    g, p, syy, tau = 0.01, 2e-4, 2.1e-4, 0.9e-4
    cell_i = (g / 2) / math.sqrt(p)
    s = pl.DataFrame({"I": [cell_i], "p": [p], "sigma_yy": [syy], "sigma_xy": [-tau]})
    out = rh.gradient_frame(s).row(0, named=True)
    assert out["I_g"] == pytest.approx(g / math.sqrt(syy), rel=1e-12)
    assert out["mu_g"] == pytest.approx(tau / syy, rel=1e-12)
    assert out["sigma_g_p"] == pytest.approx(syy / p, rel=1e-12)


def test_jop_fit_recovers_its_constants_and_their_errors():
    rng = np.random.default_rng(4)
    true = (0.37, 0.8, 0.5)
    ii = np.geomspace(0.05, 0.8, 9)
    se = np.full(ii.size, 0.002)
    fits = [rh.fit_jop(ii, rh.jop_value(ii, *true) + rng.normal(0, se), se) for _ in range(200)]
    assert all(f.success for f in fits)
    vals = np.array([list(f.params.values()) for f in fits])
    errs = np.array([list(f.errors.values()) for f in fits])
    # unbiased, and the covariance's errors are the scatter of the constants (to ~20 %)
    assert np.all(np.abs(vals.mean(0) - true) < 3 * vals.std(0) / math.sqrt(len(fits)) + 1e-3)
    assert np.allclose(errs.mean(0), vals.std(0), rtol=0.2)
    assert fits[0](0.2) == pytest.approx(float(rh.jop_value(0.2, *fits[0].params.values())))
    # chi^2 per degree of freedom ~ 1 for Gaussian noise of the stated SE
    assert 0.8 < np.mean([f.red_chi2 for f in fits]) < 1.2


def test_the_cell_takes_the_channels_material():
    mat = cs.channel_material()
    assert mat.sizes == MATERIAL_000.sizes
    assert mat.sizes.params == (0.9, 0.3, 1.0, 0.4, 1.1, 0.3)
    law = mat.law()
    assert law.kt / law.kn == pytest.approx(2 / 7) and law.e_n == 0.82 and law.mu == 0.5
    # the channel's dt per contact time: 1.2e-4 sqrt(1e6/kn) at the mean pair's collision time
    assert mat.dt_rule is not None and mat.dt_rule.kind == "tc_fraction"
    m = np.pi / 6 * (0.3 * 0.9**3 + 0.4 + 0.3 * 1.1**3)
    for kn in (1e5, 1e6, 1e7):
        dt = 1.2e-4 * math.sqrt(1e6 / kn)
        tc = math.sqrt(math.pi**2 + math.log(0.82) ** 2) / math.sqrt(kn / (m / 2))
        assert mat.dt_rule.value * tc == pytest.approx(dt)
        assert mat.with_(kn=kn).dt() == pytest.approx(dt)


def test_a_calibration_needs_five_steady_points():
    rows = [{"p_ext": 2e-4, "N": 2000, "tau_ratio": r, "seed": 1, "state": "flowing",
             "converged": True,
             "I_g": 0.1 * r, "I_g_se": 1e-3, "mu_g": r, "mu_g_se": 1e-3, "phi": 0.6 - r / 10,
             "phi_se": 1e-3, "sigma_g_p": 1.05, "sigma_g_p_se": 1e-3}
            for r in (0.45, 0.5, 0.6, 0.7)]
    with pytest.raises(ParameterError, match=r"p_ext = 0.0002: 4 steady points.*>= 5"):
        acal.calibrate(pl.DataFrame(rows))


def _runs(seeds: dict[float, int], n: int = 2000, spread: float = 0.0) -> pl.DataFrame:
    """Steady calibration runs at p = 2e-4: ``seeds[r]`` seeds at tau/p = r, seed s shifted by
    ``spread * s`` in every quantity, SE 1e-3."""
    rows = []
    for r, k in seeds.items():
        for s in range(1, k + 1):
            rows.append({"p_ext": 2e-4, "N": n, "tau_ratio": r, "seed": s, "state": "flowing",
                         "converged": True, **{
                             x: v + spread * s for x, v in (("I_g", 0.1 * r), ("mu_g", r),
                                                            ("phi", 0.6 - r / 10),
                                                            ("sigma_g_p", 1.05))},
                         **{f"{x}_se": 1e-3 for x in acal.POINT_OBSERVABLES}})
    return pl.DataFrame(rows)


def _law_points(b: float, noise: float = 2e-4, seed: int = 3) -> pl.DataFrame:
    """One run per point at p = 2e-4 on I_g = 1e-3 to 0.8: mu_g on Jop's form plus 0.1 I,
    phi = 0.591 - 0.15 I^0.9 - b I^2, Gaussian noise of the stated SE (noise)."""
    rng = np.random.default_rng(seed)
    ig = np.geomspace(1e-3, 0.8, 18)
    mu = rh.jop_value(ig, 0.36, 0.8, 0.5) + 0.1 * ig
    phi = 0.591 - 0.15 * ig**0.9 - b * ig**2
    return pl.DataFrame([
        {"p_ext": 2e-4, "N": 2000, "tau_ratio": 0.0, "inertial_number": float(i), "seed": 1,
         "state": "flowing", "converged": True, "I_g": float(i), "I_g_se": 0.0,
         "mu_g": float(m + rng.normal(0, noise)), "mu_g_se": noise,
         "phi": float(p + rng.normal(0, noise)), "phi_se": noise,
         "sigma_g_p": 1.05, "sigma_g_p_se": 1e-3} for i, m, p in zip(ig, mu, phi, strict=True)])


def test_the_form_comparison_tells_a_form_that_misses_from_one_that_fits():
    forms = acal.form_comparison(_law_points(b=0.1))
    models, three = 0, 1  # the models' four-constant forms, and the same less that constant

    def row(q: str, form: int, span: str = "all") -> dict:
        name = acal.FORMS[q][form]
        return forms.filter((pl.col("quantity") == q) & (pl.col("form") == name)
                            & (pl.col("range") == span)).row(0, named=True)

    def chi2(q: str, form: int, span: str = "all") -> float:
        return row(q, form, span)["red_chi2"]

    # the data's own forms fit to chi2 ~ 1; one power of I across 1e-3 to 0.8 does not
    assert chi2("phi", models) < 2.0 and chi2("mu_g", models) < 2.0
    assert chi2("phi", three) > 5.0 and chi2("mu_g", three) > 5.0
    # on the lower range the curvature at the top is gone: the three constants fit
    low = f"I_g <= {acal.FORM_I_MAX:g}"
    assert chi2("phi", three, low) < chi2("phi", three) / 3
    # the four-constant forms find the low-I constants the data were made with
    for q, truth in (("mu_g", 0.36), ("phi", 0.591)):
        r = row(q, models)
        assert abs(r["low_I"] - truth) < 3 * r["low_I_se"]
    # without the I^2 term (4.7) fits everywhere
    plain = acal.form_comparison(_law_points(b=0.0))
    assert plain.filter((pl.col("form") == acal.FORMS["phi"][three])
                        & (pl.col("range") == "all"))["red_chi2"].item() < 2.0


def test_the_calibrated_law_takes_the_fourth_constants_and_inverts():
    law = acal.calibrate(_law_points(b=0.1))[2e-4].law
    assert law.mu_form == "jop" and law.c_mu == pytest.approx(0.1, abs=0.03)
    assert law.B_phi == pytest.approx(0.1, abs=0.03)
    ii = np.geomspace(1e-4, law.I_max, 50)
    assert np.allclose(law.I_of_mu(law.mu(ii)), ii, rtol=1e-9)
    # (mu - mu_s) dI/dmu against a central difference of the inverse
    mu, h = law.mu(ii), 1e-7
    num = (law.I_of_mu(mu + h) - law.I_of_mu(mu - h)) / (2 * h) * (mu - law.mu_s)
    assert np.allclose(law.excess_dI_dmu(mu), num, rtol=1e-5)
    inner = ii[:-1]
    num_phi = (law.phi(inner * (1 + 1e-5)) - law.phi(inner * (1 - 1e-5))) / (2e-5 * inner)
    assert np.allclose(law.dphi_dI(inner), num_phi, rtol=1e-6)


def test_a_calibration_point_is_its_replicas_mean_with_both_ses():
    runs = pl.concat([_runs({0.5: 3, 0.6: 1}, spread=0.01), _runs({0.5: 1}, n=10_000)])
    # a run that did not converge is no replica
    runs = pl.concat([runs, runs.head(1).with_columns(
        seed=pl.lit(9, pl.Int64), converged=pl.lit(False), mu_g=pl.lit(99.0))])
    pts = acal.pooled_points(runs)
    # the cell sizes stay apart: three points
    assert pts.select("N", "tau_ratio", "replicas").rows() == [
        (2000, 0.5, 3), (2000, 0.6, 1), (10_000, 0.5, 1)]
    three = pts.row(0, named=True)
    assert three["mu_g"] == pytest.approx(0.5 + 0.02)
    assert three["mu_g_se_within"] == pytest.approx(math.sqrt(3) * 1e-3 / 3)
    # seeds 1-3 shifted by 0.01 each: SD 0.01, the Student factor of 3 replicas
    fac = replicas.small_sample_factor(3)
    assert three["mu_g_se_between"] == pytest.approx(fac * 0.01 / math.sqrt(3))
    assert three["mu_g_se"] == pytest.approx(max(three["mu_g_se_within"],
                                                 three["mu_g_se_between"]))
    one = pts.row(1, named=True)
    assert one["phi_se"] == pytest.approx(1e-3) and math.isnan(one["phi_se_between"])


def test_the_full_plan_runs_three_seeds_per_point():
    plan = cs.full_plan()
    seeds: dict[tuple[float, int, float], set[int]] = {}
    for pt in plan.points:
        seeds.setdefault((pt.p_ext, pt.N, pt.tau_ratio), set()).add(pt.seed)
    assert min(len(s) for s in seeds.values()) >= 3
    assert len(plan.points) == len(set(plan.points))


def test_the_coverage_section_is_computed_from_the_replicas(tmp_path):
    one = csr.coverage_lines(_runs({0.5: 1, 0.6: 1}), tmp_path)
    text = "\n".join(one)
    assert "2 calibration points with steady runs: 2 with 1 replica." in text
    assert "No point has two steady replicas" in text and "| observable |" not in text
    # SEs 1e-3, seeds 0.01 apart: pairs 0.01, 0.02, 0.01 (3 replicas) and 0.01 (2), over a
    # combined SE sqrt(2) 1e-3: rms z = sqrt(7/4) 7.07, far above 1
    many = "\n".join(csr.coverage_lines(_runs({0.5: 3, 0.6: 2}, spread=0.01), tmp_path))
    assert "1 with 2 replicas, 1 with 3 replicas" in many
    row = next(ln for ln in many.splitlines() if ln.startswith("| mu_g |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[1:4] == ["2", "4", "3"]
    assert float(cells[4]) == pytest.approx(math.sqrt(7 / 4) * 0.01 / math.sqrt(2e-6), abs=0.01)
    assert "The run SEs are too small for I_g, mu_g, phi (" in many
    assert f"python -m granflow.analysis.coverage {tmp_path} --by p_ext,N,tau_ratio" in many


def test_a_channel_dataset_without_steady_runs_is_refused(tmp_path):
    for f in ("points", "profiles"):
        pl.read_parquet(CHANNEL / f"{f}.parquet").head(0).write_parquet(tmp_path / f"{f}.parquet")
    with pytest.raises(ParameterError, match="no steady run"):
        cm.channel_cases(tmp_path)


def test_a_law_calibrated_below_the_channels_stress_is_refused():
    # the W = 60, phi_bar = 0.59 run needs a wall stress ratio of ~0.42: a law calibrated
    # only up to I = 0.05 (mu ~ 0.40) does not cover it, in either model
    case = next(c for c in cm.channel_cases(CHANNEL) if c.W == 60 and c.phi_bar == 0.59)
    short = LocalLaw(0.36, 0.47, 0.56, 0.59, 0.16, 1.0, 0.03, 0.05, mu_form="jop")
    for model in ("local", "nonlocal"):
        with pytest.raises(ParameterError, match=r"mu\(I_max\).*calibrate"):
            cm.solve(model, short, case, 0.5)


def test_a_missing_channel_dataset_is_named(tmp_path):
    with pytest.raises(ParameterError, match="no points.parquet, profiles.parquet"):
        cm.channel_cases(tmp_path)


def test_the_report_on_a_channel_dataset_without_wide_runs_says_so(tmp_path):
    # the widths campaign as it stood before its W >= 60 runs (the target's widths; its
    # phi_bar = 0.60 runs, so that later pieces of the campaign leave this test as it is): the
    # report is written from the committed calibration and says the target is not tested;
    # its tables go to --tables, the calibration's directory is left as it was
    channel, out, tables = tmp_path / "channel", tmp_path / "cross", tmp_path / "tables"
    channel.mkdir(), out.mkdir()
    for f in ("points", "profiles", "zones"):
        t = pl.read_parquet(WIDTHS / f"{f}.parquet")
        t.filter(pl.col("W") <= 40, (pl.col("phi_bar") - 0.60).abs() < 1e-9) \
            .write_parquet(channel / f"{f}.parquet")
    for f in CROSS.glob("*.parquet"):
        (out / f.name).write_bytes(f.read_bytes())
    report = tmp_path / "cross_scene_widths.md"
    cs.main(["--full", "--out", str(out), "--report", str(report), "--only-report",
             "--channel", str(channel), "--tables", str(tables)])
    assert {f.name: f.read_bytes() for f in out.glob("*.parquet")} == {
        f.name: f.read_bytes() for f in CROSS.glob("*.parquet")}
    cases = pl.read_parquet(tables / "cases.parquet")
    assert set(cases["W"].to_list()) == {20.0, 40.0}
    assert (tables / "model.parquet").exists() and (tables / "verdict.parquet").exists()
    text = report.read_text()
    assert f"--tables {tables}`" in text and f"`pl.read_parquet('{tables}/fits.parquet')`" in text
    assert "**No run at W >= 60**: the wide-channel target is not tested here." in text
    assert "Cannot tell: no run at W >= 60" in text
    # the held amplitude is tested on every run but the one it was fitted on: the reference
    # point's other replicas too, each point once with its replicas' range
    held = next(line for line in text.splitlines()
                if line.startswith("* **One amplitude, held, predicts"))
    assert "at W = 40, phi_bar = 0.6, 2 runs" in held
    assert "at W = 20, phi_bar = 0.6, 3 runs" in held
    local = next(line for line in text.splitlines()
                 if line.startswith("* **The local law cannot make"))
    assert "in W = 20, phi_bar = 0.6, 3 runs (" in local
    # a range whose ends print alike prints once; a trend over one phi_bar is not a NaN slope
    assert not re.search(r"(?<![\d.])(\d[\d.]*%?)-\1(?![\d.%])", text)
    assert "against phi_bar: one value of phi_bar only, no slope" in text
    assert "nan ± nan" not in text


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("cross")
    report = out / "cross_scene.md"
    cs.main(["--quick", "--out", str(out), "--report", str(report), "--workers", "1",
             "--channel", str(CHANNEL)])
    return out, report


@pytest.mark.slow
def test_the_quick_chain_writes_its_datasets_and_report(quick):
    out, report = quick
    pts = pl.read_parquet(out / "points.parquet")
    assert pts.height == len(cs.quick_plan().points)
    fits = pl.read_parquet(out / "fits.parquet")
    assert set(fits["law"].to_list()) == {"mu", "phi", "mu (Jop)", "phi (4.7)", "mu (4.2)"}
    # the models' laws carry four constants, the three-constant forms beside them three
    four = fits["law"].is_in(["mu", "phi"])
    assert fits.filter(four)["c3"].is_not_null().all()
    assert fits.filter(~four)["c3"].is_null().all()
    assert all(len(c) == (16 if f else 9) for c, f in zip(fits["cov"], four, strict=True))
    cases = pl.read_parquet(out / "cases.parquet")
    assert sorted(set(cases["W"].to_list())) == [20.0, 40.0, 60.0]
    # the local law cannot shear a channel whose wall stress ratio is below its yield ratio
    mu_s = fits.filter(pl.col("law") == "mu")["c0"][0]
    for r in cases.filter(pl.col("mu_wall") < mu_s).iter_rows(named=True):
        assert r["local_du"] < 0.05 * r["dem_du"]
    for col in ("local_du", "nonlocal_du", "nonlocal_u_rel", "A_best"):
        assert cases[col].is_finite().all(), col
    z = pl.read_parquet(out / "compare.parquet")
    assert set(z["model"].to_list()) == {"local", "nonlocal"}
    assert set(z["zone"].to_list()) <= set(cm.ZONES) and z["u_rel"].is_finite().all()
    dem = pl.read_parquet(out / "dem_phi.parquet")
    assert dem.height == cases.height and (dem["A_best"] > 0).all()
    assert dem["nonlocal_best_u_rel"].is_finite().all()
    b = pl.read_parquet(out / "boundary.parquet")
    assert sorted(set(b["bin"].to_list())) == list(cm.BOUNDARY_BINS)
    assert (b["A_best"] > 0).all() and b["u_rel_held"].is_finite().all()
    text = report.read_text()
    for key in ("Nonlocal amplitude: A =", "Misfit per zone", "core-hours", "## Time"):
        assert key in text, key
    figs = sorted((out / "cross_scene_figures").glob("*.png"))
    assert len(figs) == 6 and all(f"cross_scene_figures/{f.name}" in text for f in figs)
    # the amplitude read off each run's bulk, with its SE, beside the whole-profile fits
    bulk = pl.read_parquet(out / "bulk_amplitude.parquet")
    assert bulk.height == cases.height and "## The amplitude measured in the bulk" in text
    got = bulk.filter(pl.col("A").is_not_nan())
    assert got.height >= 3 and ((got["A"] > 0) & (got["A_se"] > 0)).all()
    assert ((bulk["wall_share"] > 0) & (bulk["wall_share"] <= 1)).all()
    layer = pl.read_parquet(out / "wall_layer.parquet")
    assert layer.height == cases.height and (layer["A_layer_best"] > 0).all()
    assert "### The wall layer with a law of its own" in text
    # the layer's local laws, fitted at the reference width, held for the others
    laws = pl.read_parquet(out / "layer_laws.parquet")
    assert laws.height == 4 and (laws["n"] > 0).all()
    layered = pl.read_parquet(out / "layered.parquet")
    assert layered.height == cases.height and layered["u_rel"].is_finite().all()
    assert "### The wall layer as local laws per distance" in text
    assert "| W | zone | runs | u - u_slip misfit (worst run) | u |" in text  # its verdicts


# ---------------------------------------------------------------------------------------------
# calibrate once, predict any channel run with the constants held (issue 37, item 4)
# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def constants():
    """The committed calibration's constants with an amplitude given (nothing refitted)."""
    cal = acal.calibrate(pl.read_parquet(CROSS / "points.parquet"))
    return cm.constants_of(cal, 0.5, 0.02, "given")


def test_constants_save_and_load_the_same_laws_covariances_and_amplitude(constants, tmp_path):
    f = constants.save(tmp_path / "model.parquet")
    back = ModelConstants.load(f)
    assert back.laws == constants.laws
    assert (back.A, back.A_se, back.A_from) == (0.5, 0.02, "given")
    for p, (mu_cov, phi_cov) in constants.covariances.items():
        assert np.array_equal(back.covariances[p][0], mu_cov)
        assert np.array_equal(back.covariances[p][1], phi_cov)
    # the bands' draws are the same from the loaded constants
    p = next(iter(constants.laws))
    assert back.sample(p, 3, seed=2) == constants.sample(p, 3, seed=2)


def test_a_constants_table_from_before_the_fourth_constants_still_loads(tmp_path):
    import pyarrow.parquet as pq

    three = ModelConstants({2e-4: _LAW}, 0.5, covariances={2e-4: (np.eye(3) * 1e-8,
                                                                  np.eye(3) * 1e-8)})
    f = three.save(tmp_path / "model.parquet")
    t = pq.read_table(f)
    old = t.drop_columns(["c_mu", "B_phi"]).replace_schema_metadata(t.schema.metadata)
    pq.write_table(old, f)
    back = ModelConstants.load(f)
    assert back.laws == three.laws and back.laws[2e-4].c_mu == 0.0
    assert back.covariances[2e-4][0].shape == (3, 3)
    assert back.sample(2e-4, 2, seed=1) == three.sample(2e-4, 2, seed=1)


def test_a_file_that_is_not_a_constants_table_is_refused(tmp_path):
    pl.DataFrame({"A": [0.5]}).write_parquet(tmp_path / "fits.parquet")
    with pytest.raises(ParameterError, match="not a model constants table"):
        ModelConstants.load(tmp_path / "fits.parquet")
    with pytest.raises(ParameterError, match="invalid path"):
        ModelConstants.load(tmp_path / "none.parquet")
    with pytest.raises(ParameterError, match="invalid A = 0"):
        ModelConstants({1e-4: _LAW}, 0.0)


_LAW = LocalLaw(0.36, 0.47, 0.56, 0.59, 0.16, 1.0, 0.03, 0.5, mu_form="jop")


def test_predict_channel_holds_the_given_amplitude(constants):
    case = next(c for c in cm.channel_cases(CHANNEL) if c.W == 60 and c.phi_bar == 0.61)
    runs = [cm.predict_channel(constants.with_amplitude(a), case, n_band=0,
                               models=("nonlocal",)) for a in (0.5, 0.25)]
    for pred, a in zip(runs, (0.5, 0.25), strict=True):
        row = pred.cases.row(0, named=True)
        assert row["A"] == a and row["seed"] == case.seed
        # the whole-channel misfit is the public one of the model's profile
        prof = cm.solve("nonlocal", constants.law_for(case.pressure())[1], case, a)
        assert row["nonlocal_u_rel"] == cm.velocity_misfit(case, prof)
    assert runs[0].cases["nonlocal_u_rel"][0] != runs[1].cases["nonlocal_u_rel"][0]


def test_predict_refuses_a_reference_run_the_dataset_does_not_have():
    cases = cm.channel_cases(CHANNEL)
    with pytest.raises(ParameterError, match=r"invalid reference = \(100.0, 0.6\).*\(40, 0.6\)"):
        cm.reference_case(cases, (100.0, 0.6))
    assert cm.reference_case(cases, (40.0, 0.6)).W == 40


def test_channel_cases_leave_out_unconverged_runs_and_say_so(tmp_path):
    pts = pl.read_parquet(CHANNEL / "points.parquet")
    pts.with_columns(converged=pl.col("W") != 60).write_parquet(tmp_path / "points.parquet")
    (tmp_path / "profiles.parquet").write_bytes((CHANNEL / "profiles.parquet").read_bytes())
    with pytest.warns(UserWarning, match="did not converge and are left out: W = 60"):
        kept = cm.channel_cases(tmp_path)
    assert kept and all(c.W != 60 for c in kept)
    assert len(cm.channel_cases(tmp_path, include_unconverged=True)) == len(
        cm.channel_cases(CHANNEL))


def test_a_channel_dataset_never_analysed_as_steady_is_named(tmp_path):
    pl.DataFrame({"W": [20.0], "phi_bar": [0.62], "kn": [1e5], "state": ["arrested"]}
                 ).write_parquet(tmp_path / "points.parquet")
    pl.DataFrame({"xi": [0.5]}).write_parquet(tmp_path / "profiles.parquet")
    with pytest.raises(ParameterError,
                       match=r"no steady run at kn = 100000 \(its states: arrested"):
        cm.channel_cases(tmp_path)


def _run_dir(path: Path, kind: str) -> Path:
    from granflow import io
    from test_analysis_channel import W as SYN_W
    from test_analysis_channel import synthetic_bins, synthetic_series

    path.mkdir()
    params = {"W": SYN_W, "phi_bar": 0.6, "kn": 1e5}
    io.write_parquet(synthetic_bins(t_first=0.0)[0], path / "bins.parquet", params, seed=7)
    io.write_parquet(pa.table(synthetic_series(kind)), path / "series.parquet", params, seed=7)
    return path


def test_one_runs_directory_is_a_case(tmp_path):
    case = cm.cases_of(_run_dir(tmp_path / "run", "steady"))[0]
    assert (case.W, case.phi_bar, case.kn, case.seed) == (40.0, 0.6, 1e5, 7)
    assert {"xi", "u", "gamma_dot", "mu", "phi", "I", "zone"} <= set(case.profile.columns)
    assert case.profile["xi"].is_sorted() and case.sigma_xx > 0
    with pytest.raises(ParameterError, match="its flow is accelerating"):
        cm.run_case(_run_dir(tmp_path / "acc", "accelerating"))
    with pytest.raises(ParameterError, match="no bins.parquet, series.parquet"):
        cm.run_case(tmp_path)


def test_the_dem_phi_variant_carries_the_runs_own_stress(constants):
    case = next(c for c in cm.channel_cases(CHANNEL) if c.W == 60 and c.phi_bar == 0.61)
    law = constants.law_for(case.pressure())[1]
    xi, phi = case.profile["xi"].to_numpy(), case.profile["phi"].to_numpy()
    # (B2) with the DEM's phi: the wall bin's stress is the DEM's solid above it (phi held
    # past the last bin centre)
    solid = float(np.sum(0.5 * (phi[1:] + phi[:-1]) * np.diff(xi))) + phi[-1] * (30.0 - xi[-1])
    for model in cm.MODELS:
        prof = cm.solve(model, law, case, 0.5, phi="dem")
        assert prof.sigma_xy[0] == pytest.approx(solid, rel=1e-6)
        np.testing.assert_allclose(prof.at(xi)["phi"], phi, rtol=0, atol=1e-4)
    own = cm.solve("nonlocal", law, case, 0.5)
    assert own.sigma_xy[0] < solid  # the model's plug packs looser than the DEM's
    with pytest.raises(ParameterError, match="invalid phi = 'cell'"):
        cm.solve("nonlocal", law, case, 0.5, phi="cell")
    pred = cm.predict_channel(constants, case, n_band=0, phi="dem")
    assert pred.cases["phi"][0] == "dem" and pred.cases["nonlocal_u_rel"].is_finite().all()


def test_the_bins_phi_slope_takes_its_se_from_bins_whose_stencils_do_not_overlap():
    from granflow.studies.cross_scene_report_bulk import _local_phi_slope

    phi = np.linspace(0.6, 0.64, 12)
    bins = pl.DataFrame({"W": [40.0] * 12, "phi_bar": [0.6] * 12, "seed": [1] * 12,
                         "phi": phi, "bulk": [True] * 12})
    slope, se = _local_phi_slope(bins.with_columns(pl.Series("A", 0.4 + 2.0 * (phi - 0.62))))
    assert slope == pytest.approx(2.0) and se < 1e-6
    # every third bin carries an offset of its own: pooled, the residuals look small beside
    # the disagreement of the three sets' slopes, which the SE must then carry
    tilt = np.array([3.0, 0.0, -3.0] * 4) * (phi - 0.62)
    _, se_tilted = _local_phi_slope(bins.with_columns(
        pl.Series("A", 0.4 + 2.0 * (phi - 0.62) + tilt)))
    assert se_tilted >= np.std([5.0, 2.0, -1.0], ddof=1) / np.sqrt(3) * 0.99


def _replicated(tmp_path: Path, shifts=(-0.2, 0.0, 0.5), depths=(20.0,)) -> Path:
    """The committed W = 40, phi_bar = 0.6 run as three replicas (u shifted by ``shifts``,
    the second's wall bin labelled 'loose') and as one run at each of ``depths``."""
    pts = pl.read_parquet(CHANNEL / "points.parquet").filter(
        (pl.col("W") == 40) & (pl.col("phi_bar") == 0.6))
    prof = pl.read_parquet(CHANNEL / "profiles.parquet")
    key = ["W", "phi_bar", "kn", "B", "H", "seed", "parent"]
    prof = prof.join(pts.select(key), on=key, how="semi")
    b0 = float(pts["B"][0])
    p_rows, f_rows = [], []
    for seed, du in enumerate(shifts, start=1):
        p_rows.append(pts.with_columns(seed=pl.lit(seed, dtype=pts["seed"].dtype),
                                       sigma_xx_mean=pl.col("sigma_xx_mean") + du))
        f = prof.with_columns(seed=pl.lit(seed, dtype=prof["seed"].dtype), u=pl.col("u") + du)
        if seed == 2:
            f = f.with_columns(zone=pl.when(pl.int_range(pl.len()) == 0).then(pl.lit("loose"))
                               .otherwise(pl.col("zone")))
        f_rows.append(f)
    for b in depths:
        p_rows.append(pts.with_columns(B=pl.lit(b)))
        f_rows.append(prof.with_columns(B=pl.lit(b), u=pl.col("u") + 3.0))
    pl.concat(p_rows).write_parquet(tmp_path / "points.parquet")
    pl.concat(f_rows).write_parquet(tmp_path / "profiles.parquet")
    assert b0 not in depths
    return tmp_path


def test_channel_cases_average_replicas_bin_by_bin_with_the_replica_se(tmp_path):
    d = _replicated(tmp_path)
    with pytest.warns(UserWarning, match=r"another depth than the main B = 10 .*B = 20"):
        apart = cm.channel_cases(d)
    assert [c.seed for c in apart] == [1, 2, 3]
    with pytest.warns(UserWarning, match="another depth"):
        (mean,) = cm.channel_cases(d, replicas="mean")
    assert mean.replicas == 3 and mean.seed is None and "3 replicas" in mean.name
    u = np.array([c.profile["u"].to_numpy() for c in apart])
    se = np.array([c.profile["u_se"].to_numpy() for c in apart])
    np.testing.assert_allclose(mean.profile["u"].to_numpy(), u.mean(axis=0), rtol=1e-12)
    within = np.sqrt((se**2).sum(axis=0)) / 3
    between = replicas.small_sample_factor(3) * u.std(axis=0, ddof=1) / math.sqrt(3)
    np.testing.assert_allclose(mean.profile["u_se"].to_numpy(), np.maximum(within, between),
                               rtol=1e-12)
    assert (mean.profile["u_se"].to_numpy() > se.max(axis=0)).all()  # the shifts dominate
    # the zone most replicas give; the bins' edges kept; the boundary data the means
    assert mean.profile["zone"].to_list() == apart[0].profile["zone"].to_list()
    np.testing.assert_array_equal(mean.profile["xi_lo"].to_numpy(),
                                  apart[0].profile["xi_lo"].to_numpy())
    assert mean.sigma_xx == pytest.approx(np.mean([c.sigma_xx for c in apart]), rel=1e-12)
    assert mean.problem().u_wall == pytest.approx(u[:, 0].mean(), rel=1e-12)
    # the other depth on request, alone
    (deep,) = cm.channel_cases(d, B=20)
    assert deep.profile["u"][0] == pytest.approx(apart[0].profile["u"][0] + 3.2, rel=1e-12)


def test_channel_cases_refuse_an_unknown_replica_mode_or_depth(tmp_path):
    d = _replicated(tmp_path)
    with pytest.raises(ParameterError, match=r"invalid replicas = 'median': allowed one of "
                                             r"'apart', 'mean'"):
        cm.channel_cases(d, replicas="median")
    with pytest.raises(ParameterError, match=r"invalid B = 30: no steady run at that depth; "
                                             r"allowed one of 10, 20"):
        cm.channel_cases(d, B=30)


def test_the_amplitudes_per_point_are_replica_means_and_their_trend_is_tested():
    from granflow.studies.cross_scene_report_bulk import (
        replica_amplitude_lines,
        replica_amplitudes,
    )

    # two widths, three replicas each: the whole-profile A falls with W well beyond its
    # replica spread; the bulk A is one value within its SEs
    best = pl.DataFrame({"W": [20.0] * 3 + [40.0] * 3, "phi_bar": 0.6,
                         "seed": [1, 2, 3] * 2, "A_best": [0.83, 0.84, 0.835, 0.50, 0.51, 0.505]})
    bulk = best.select("W", "phi_bar", "seed").with_columns(
        A=pl.Series([0.45, 0.46, 0.44, 0.46, 0.45, 0.44]), A_se=pl.lit(0.01))
    tab = replica_amplitudes(best, bulk)
    assert tab["replicas"].to_list() == [3, 3]
    assert tab["A_whole"].to_list() == pytest.approx([0.835, 0.505])
    # the whole-profile SE is the between-replica one (Student-scaled), the bulk's the larger
    between = replicas.small_sample_factor(3) * 0.005 / math.sqrt(3)
    assert tab["A_whole_se"].to_list() == pytest.approx([between, between])
    assert tab["A_se"][0] == pytest.approx(max(0.01 / math.sqrt(3),
                                               replicas.small_sample_factor(3) * 0.01
                                               / math.sqrt(3)))
    text = "\n".join(replica_amplitude_lines(best, bulk))
    assert "whole-profile own best A against W: -0.0165" in text
    assert "bulk A against W" in text and "does not trend measurably" in text
    assert "| 20 | 0.6 | 3 | 0.835 ± 0.004 | 0.450 ± 0.008 |" in text
    # one replica per point: nothing at the replica level
    assert replica_amplitude_lines(best.filter(pl.col("seed") == 1),
                                   bulk.filter(pl.col("seed") == 1)) == []


def test_the_trend_sentence_leaves_out_a_trend_over_one_value():
    from granflow.continuum.cooperativity import Trend
    from granflow.studies.cross_scene_report_bulk import _trends_sentence

    nan = math.nan
    tw = Trend("W", 0.004, 0.001, 4.0, 0.45, 0.01, 4.0)
    tp = Trend("phi_bar", nan, nan, nan, 0.45, 0.01, 4.0)
    text = _trends_sentence(tw, tp)
    assert "**trends** with W" in text and "phi_bar" not in text and "nan" not in text
    assert text.endswith("the z-values are 2.0")
    none = _trends_sentence(Trend("W", nan, nan, nan, 0.4, 0.01, 1.0), tp)
    assert none == "With one value of W and one of phi_bar the bulk amplitude has no trend to test"


def test_the_points_table_writes_a_dash_where_one_replica_has_no_between_se():
    cols = {"p_ext": [2e-4, 2e-4], "N": [2000, 2000], "inertial_number": [1e-4, 0.0],
            "tau_ratio": [0.0, 0.41], "replicas": [1, 3], "sigma_g_p": [1.05, 1.05]}
    for x in ("I_g", "mu_g", "phi"):
        cols |= {x: [2e-4, 1e-3], f"{x}_se": [3.1e-7, 2e-5],
                 f"{x}_se_within": [3.1e-7, 1e-5], f"{x}_se_between": [math.nan, 2e-5]}
    tab = csr._points_table(pl.DataFrame(cols))
    se = tab["I_g SE (within / between)"].to_list()
    assert se == ["3.1e-7 (3.1e-7 / -)", "0.00002 (0.00001 / 0.00002)"], se
    assert not any("NaN" in str(v) for row in tab.iter_rows() for v in row)
