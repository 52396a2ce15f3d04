"""One prepared channel packing run at several kn (Channel.prepare_from) and the profile
comparison of benchmarks/channel_stiffness.py (issue #5)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from granflow.errors import ParameterError
from granflow.scenes.channel import Channel

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "channel_stiffness.py"


def _bench():
    spec = importlib.util.spec_from_file_location("channel_stiffness", BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_prepare_from_reuses_the_packing():
    geo = {"W": 10.0, "H": 10.0, "B": 4.0, "phi_bar": 0.58, "preparation": "pour"}
    src = Channel(**geo, kn=1e6, seed=0, threads=1)
    src.prepare()
    soft = Channel(**geo, kn=1e5, dt=3.8e-4, seed=5, threads=1)
    soft.prepare_from(src)
    assert np.array_equal(soft.core.positions(), src.core.positions())
    assert soft.core.dt == pytest.approx(3.8e-4) and soft.law.kn == 1e5
    assert soft.prep_info["prepared_with_kn"] == 1e6
    assert soft.prep_info["n"] == src.prep_info["n"]
    soft.run(200)
    assert soft.core.step == 200
    with pytest.raises(ParameterError, match="W"):
        Channel(**{**geo, "W": 12.0}, kn=1e5, threads=1).prepare_from(src)
    # a run packing is not a prepared one
    with pytest.raises(ParameterError, match="step"):
        Channel(**geo, kn=1e7, dt=3.79e-5, threads=1).prepare_from(soft)


def test_bench_compare_bin_by_bin():
    mod = _bench()
    assert mod.dt_for(1e6) == pytest.approx(1.2e-4) and mod.dt_for(1e8) == pytest.approx(1.2e-5)

    def run(kn, u, u_se, phi):
        n = len(u)
        return {"label": f"{kn:.0e}", "kn": kn, "u": u, "u_se": u_se, "phi": phi,
                "phi_se": [0.01] * n,
                "u_slip": {"value": u[0], "se": u_se[0]}, "u_max": {"value": u[-1], "se": u_se[-1]},
                "u_max_over_u_slip": {"value": u[-1] / u[0], "se": 0.0}}

    a = run(1e5, [1.0, 2.0, 3.0, 4.0], [0.1] * 4, [0.55, 0.58, 0.60, 0.62])
    b = run(1e6, [1.0, 2.0, 3.5, 4.0], [0.1] * 4, [0.55, 0.58, 0.60, 0.70])
    c = mod.compare(a, b, phi_claimed=False)
    z = np.asarray(c["u"]["z"])
    assert z[2] == pytest.approx(-0.5 / np.hypot(0.1, 0.1))
    assert c["u"]["frac_2sigma"] == pytest.approx(0.75) and c["u"]["frac_3sigma"] == 0.75
    assert c["phi"]["max_abs_z"] == pytest.approx(0.08 / np.hypot(0.01, 0.01))
    assert c["u"]["paper_claims_equal"] and not c["phi"]["paper_claims_equal"]
    assert c["u_slip"]["z"] == 0.0
