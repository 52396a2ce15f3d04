"""Bad input to the vertical channel (000) is refused as ParameterError naming the parameter and
its allowed range: on construction, before anything runs (issue 22), and, for a phi_bar the
fill and release cannot pack in this channel, by prepare() before any run step. Allowed edge
values are accepted. Construction only, plus two tiny preparations (~1 s each)."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from granflow.errors import ParameterError
from granflow.material import MATERIAL_000
from granflow.scenes.channel import RCP, Channel

INF, NAN = math.inf, math.nan

REFUSED = [
    # geometry
    ({"W": 5.0}, "W"),  # < 5 d_max = 5.5
    ({"W": INF}, "W"),
    ({"W": NAN}, "W"),
    ({"H": 5.0}, "H"),
    ({"H": -30.0}, "H"),
    ({"H": INF}, "H"),
    ({"H": 6.0, "skin": 2.0}, "H"),  # < 2 (d_max + skin) = 6.2: the kernel's periodic minimum
    ({"B": 3.0}, "B"),
    ({"B": NAN}, "B"),
    # bins: the two wall bins and at least one interior bin of ~bin_width must fit
    ({"W": 6.0, "wall_bin": 2.6}, "wall_bin"),  # interior 0.8 < bin_width: one narrow bin
    ({"W": 6.0, "wall_bin": 2.9}, "W"),  # interior 0.2: bin_edges() would make no interior bin
    ({"W": 20.0, "bin_width": 17.5}, "bin_width"),  # > W - 2 wall_bin = 17
    ({"bin_width": 0.0}, "bin_width"),
    ({"bin_width": INF}, "bin_width"),
    ({"wall_bin": -1.0}, "wall_bin"),
    # volume fraction and the particle count
    ({"phi_bar": RCP + 0.01}, "phi_bar"),
    ({"phi_bar": 0.0}, "phi_bar"),
    ({"phi_bar": NAN}, "phi_bar"),
    ({"W": 5.5, "H": 5.5, "B": 3.4, "phi_bar": 0.005}, "phi_bar"),  # one particle
    # material and contact law
    ({"density": 0.0}, "density"),
    ({"density": INF}, "density"),
    ({"kn": 0.0}, "kn"),
    ({"kn": -1e5}, "kn"),
    ({"kn": NAN}, "kn"),
    ({"e_n": 0.0}, "e_n"),
    ({"e_n": 1.2}, "e_n"),
    ({"e_n": NAN}, "e_n"),
    ({"mu": -0.1}, "mu"),
    ({"mu": INF}, "mu"),
    ({"kt_ratio": -1.0}, "kt_ratio"),
    ({"kt_ratio": 20.0}, "kt_ratio"),
    ({"xi_t_ratio": -0.5}, "xi_t_ratio"),
    ({"wall_kn": 0.0}, "wall_kn"),
    ({"wall_e_n": 0.0}, "wall_e_n"),
    ({"wall_mu": -1.0}, "wall_mu"),
    ({"sizes": {1.0: 0.5, INF: 0.5}}, "sizes"),
    ({"sizes": [1.1, 0.9]}, "sizes"),
    ({"form": "linear"}, "form"),
    ({"tc_reading": "mass"}, "tc_reading"),
    ({"material": "001"}, "material"),
    # time step: finite, > 0, and <= t_c/10 as the kernel demands at the release
    ({"dt": 0.0}, "dt"),
    ({"dt": -1e-4}, "dt"),
    ({"dt": NAN}, "dt"),
    ({"dt": INF}, "dt"),
    ({"dt": 2e-4}, "dt"),  # t_c/10 = 1.375e-4 at kn = 1e6, e_n = 0.82, d_min = 0.9
    ({"kn": 1e7, "dt": 1.2e-4}, "dt"),  # 000's dt at kn = 1e6 against t_c/10 = 4.35e-5
    # preparation and sampling
    ({"settle_ke": 0.0}, "settle_ke"),
    ({"settle_ke": NAN}, "settle_ke"),
    ({"prep_kn": -1.0}, "prep_kn"),
    ({"preparation": "drop"}, "preparation"),
    ({"preparation": None}, "preparation"),
    ({"skin": 0.0}, "skin"),
    ({"skin": INF}, "skin"),
    ({"seed": -1}, "seed"),
    ({"seed": 1.5}, "seed"),
    ({"seed": True}, "seed"),
    ({"sample_every": 0}, "sample_every"),
    ({"window": 0}, "window"),
]


@pytest.mark.parametrize("kw, name", REFUSED, ids=[f"{k}" for k, _ in REFUSED])
def test_bad_input_is_refused_on_construction_naming_the_parameter(kw, name):
    with pytest.raises(ParameterError, match=rf"invalid [\w/]*\b{re.escape(name)}\b.*allowed"):
        Channel(**kw)


def t_c(kn: float = 1e6, e_n: float = 0.82) -> float:
    # the lightest pair of 000's mix (d_min = 0.9)
    return MATERIAL_000.with_(kn=kn, e_n=e_n).contact_time("lightest")


ACCEPTED = [
    {},  # the defaults
    {"W": 5.5, "H": 5.5},  # 5 d_max
    {"W": 5.5, "wall_bin": 2.25, "bin_width": 1.0},  # W = 2 wall_bin + bin_width exactly
    {"W": 20.0, "bin_width": 17.0},  # bin_width = W - 2 wall_bin: one interior bin
    {"phi_bar": RCP},  # construction; prepare() decides whether this channel can pack it
    {"W": 5.5, "H": 5.5, "B": 3.4, "phi_bar": 0.011},  # two particles
    {"e_n": 1.0, "mu": 0.0, "wall_mu": 0.0, "wall_e_n": 1.0, "seed": 0},
    {"dt": t_c() / 10},
    {"preparation": "pour"},
    {"kn": 1e5, "dt": t_c(1e5) / 10, "form": "hertz"},
    # the step the repository uses: 1.2e-4 sqrt(1e6/kn) ~ t_c/11.5
    *({"kn": kn, "dt": 1.2e-4 * math.sqrt(1e6 / kn)} for kn in (1e5, 1e6, 1e7, 1e8)),
    # ... which is the material's rule when dt is not given
    *({"kn": kn} for kn in (1e5, 1e7, 1e8)),
    {"material": "002", "kn": 1e6, "W": 8, "H": 12, "B": 4},  # a material by name
    {"W": 8, "H": 12, "B": 4, "phi_bar": 0.6, "kn": 1e5, "dt": 3e-4, "seed": 2},
]


@pytest.mark.parametrize("kw", ACCEPTED)
def test_allowed_edge_values_are_accepted(kw):
    c = Channel(**kw)
    assert not c.prepared  # nothing ran
    if "dt" not in kw and c.mat.dt_rule is not None and c.mat.dt_rule.kind == "kn_scaled":
        assert c.timestep == 1.2e-4 * math.sqrt(1e6 / c.mat.kn_value)
    e = c.bin_edges()
    assert e[0] == 0 and e[-1] == c.W and len(e) >= 4  # two wall bins and an interior bin
    assert np.isclose(e[1], c.wall_bin) and np.isclose(c.W - e[-2], c.wall_bin)


# the preparation (docs/channel.md, "Input checks"): W = 10, H = 8, B = 5 at kn = 1e5 pours to
# ~0.57 up to the bed's top; squeezed to 0.62 it relaxes to max overlap 0.007 (seed 1), to 0.64
# it keeps 0.020 d
SMALL = {"W": 10.0, "H": 8.0, "B": 5.0, "kn": 1e5, "dt": 3.79e-4, "sample_every": None,
         "threads": 1, "seed": 1, "preparation": "pour"}


def test_prepare_refuses_a_phi_bar_this_channel_cannot_pack():
    c = Channel(**SMALL, phi_bar=0.64)
    with pytest.raises(ParameterError, match=r"invalid phi_bar = 0\.64: allowed .*overlaps"):
        c.prepare(progress=False)
    assert not c.prepared  # refused before the run's simulation exists


def test_prepare_accepts_a_dense_phi_bar_it_can_pack():
    c = Channel(**SMALL, phi_bar=0.62)
    c.prepare(progress=False)
    assert c.prep_info["compressed"]
    assert c.prep_info["phi_bar_achieved"] == pytest.approx(0.62, abs=2e-3)
    c.run(1, progress=False)
    assert c.prepared and c.core.diagnostics()["max_overlap"] < 0.01
