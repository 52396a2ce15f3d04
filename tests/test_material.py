"""The Material: the papers' two materials, variations with validation, the contact time of
both pairs, the time-step rules and the mean particle volume (no simulation runs)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from granflow import _core
from granflow.errors import ParameterError
from granflow.material import (
    MATERIAL_000,
    MATERIAL_002,
    DtRule,
    Material,
    kernel_default_skin,
)
from granflow.sizes import CHANNEL_MIX, as_size_dist, discrete, mono, uniform


def test_000_takes_the_kernels_law_defaults():
    # nothing restated: the law is the kernel's default law, the sizes the channel's mix
    assert MATERIAL_000.law().as_dict() == _core.resolve_law({})
    assert MATERIAL_000.sizes is CHANNEL_MIX and MATERIAL_000.skin is None
    assert MATERIAL_000.kn_value == 1e6 and MATERIAL_000.mu_value == 0.5
    # 000's dt = 1.2e-4 at kn = 1e6, scaled as t_c ~ kn^-1/2
    assert MATERIAL_000.dt() == 1.2e-4
    for kn in (1e5, 1e7):
        assert MATERIAL_000.with_(kn=kn).dt() == 1.2e-4 * np.sqrt(1e6 / kn)


def test_002_damping_follows_the_contact_time():
    d = uniform(0.9, 1.1).diameters_for_volume(200.0, seed=1)
    t_c = MATERIAL_002.contact_time("mean", d)
    law = MATERIAL_002.law(d).as_dict()
    assert law["xi_n"] == 0.5 / t_c and law["kt"] == law["kn"] == 1.0 and law["mu"] == 0.3
    assert MATERIAL_002.dt(d) == 0.02 * t_c
    # the collision reading makes 002's e_n = exp(-gamma_n t_c / 2) = exp(-1/4) the restitution
    m_e = MATERIAL_002.mean_mass(d) / 2
    g = law["xi_n"]
    assert t_c == pytest.approx(np.pi / np.sqrt(1.0 / m_e - g * g / 4), rel=1e-12)
    assert math.exp(-g * t_c / 2) == pytest.approx(math.exp(-0.25), rel=1e-12)


def test_lightest_pair_is_shorter_than_the_mean_pair():
    lo = MATERIAL_000.contact_time("lightest")
    mean = MATERIAL_000.contact_time("mean")
    assert lo < mean
    # t_c ~ sqrt(m): the lightest (d = 0.9) and the mean particle's mass
    ratio = math.sqrt(0.9**3 / (MATERIAL_000.sizes.mean_volume / (math.pi / 6)))
    assert lo / mean == pytest.approx(ratio, rel=1e-12)


def test_mean_volume():
    assert uniform(0.9, 1.1).mean_volume == pytest.approx(np.pi / 6 * (1.1**4 - 0.9**4) / 0.8,
                                                          rel=1e-12)
    assert CHANNEL_MIX.mean_volume == pytest.approx(
        np.pi / 6 * (0.3 * 0.9**3 + 0.4 + 0.3 * 1.1**3), rel=1e-12)
    assert mono(2.0).mean_volume == pytest.approx(np.pi / 6 * 8, rel=1e-15)


def test_variations_are_validated_naming_the_parameter():
    m = MATERIAL_002.with_(mu=0.1, kt_ratio=2 / 7, sizes={0.9: 0.5, 1.1: 0.5})
    assert m.mu == 0.1 and m.kt_ratio == 2 / 7 and m.sizes == discrete({0.9: 0.5, 1.1: 0.5})
    assert MATERIAL_002.mu == 0.3  # frozen: the original is unchanged
    # a restitution replaces 002's rate damping
    r = MATERIAL_002.with_(e_n=0.8)
    assert r.gamma_n_tc is None and r.law().as_dict()["e_n"] == 0.8
    for kw, name in [({"mu": -1.0}, "mu"), ({"kt_ratio": 0.0}, "kt_ratio"),
                     ({"kn": math.inf}, "kn"), ({"e_n": 1.5}, "e_n"),
                     ({"density": 0.0}, "density"), ({"skin": -0.1}, "skin"),
                     ({"form": "linear"}, "form"), ({"tc_reading": "x"}, "tc_reading"),
                     ({"sizes": [1.1, 0.9]}, "sizes"), ({"sizes": {1.0: 0.5}}, "sizes"),
                     ({"friction": 0.3}, "friction"), ({"xi_t_ratio": -1.0}, "xi_t_ratio"),
                     ({"e_n": 0.8, "gamma_n_tc": 0.5}, "e_n")]:
        with pytest.raises(ParameterError, match=rf"invalid [\w ]*\b{name}\b.*allowed"):
            MATERIAL_002.with_(**kw)
    with pytest.raises(ParameterError, match="dt_rule"):
        DtRule.tc_fraction(0.5)
    with pytest.raises(ParameterError, match="pair"):
        MATERIAL_000.contact_time("heavy")


def test_sizes_forms_round_trip():
    for sd in (CHANNEL_MIX, uniform(0.9, 1.1), mono(1.0)):
        assert as_size_dist(sd.to_spec()) == sd
    assert as_size_dist({"0.9": 0.5, "1.1": 0.5}) == discrete({0.9: 0.5, 1.1: 0.5})


def test_skin_unset_is_the_kernels():
    assert kernel_default_skin() > 0
    assert Material(sizes=mono()).skin is None
