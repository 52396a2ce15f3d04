"""The channel's default preparation, 000's rain (granflow.scenes.channel, module docstring):
the particle count from phi_bar to one particle, the floor gone and the bed at rest before the
flow starts, a phi_bar the rain cannot pack refused before anything runs (naming phi_bar and
the largest that fits), the same bits for a seed on any thread count; and the former
preparation, ``preparation = "pour"``, bit for bit as on main (2cbeea6). Small channels, about
a second each."""

from __future__ import annotations

import hashlib
import re

import numpy as np
import pytest
from granflow.errors import ParameterError
from granflow.scenes.channel import Channel

# W = 8, H = 12, B = 4 at kn = 1e5, rain_phi = 0.05 (a shorter fall than the default 0.02's):
# the rain packs ~0.53-0.54 up to the bed's top (seeds 1, 2), its level holds ~0.59
RAIN = {"W": 8.0, "H": 12.0, "B": 4.0, "kn": 1e5, "dt": 3.79e-4, "sample_every": None,
        "threads": 1, "rain_phi": 0.05}


@pytest.fixture(scope="module")
def rained() -> Channel:
    c = Channel(**RAIN, phi_bar=0.5, seed=2)
    c.prepare(progress=False)
    return c


def test_rain_is_the_default_and_is_recorded(rained):
    assert Channel().preparation == "rain"
    assert rained.prep_info["preparation"] == "rain"
    p = rained.parameters()
    assert p["preparation"] == "rain" and p["prep_preparation"] == "rain"
    assert p["rain_phi"] == rained.rain_phi == p["prep_rain_phi"]


def test_rain_reaches_the_target_phi_bar_to_one_particle(rained):
    c = rained
    vol = c.W * c.B * c.H
    n = c.core.n
    assert c.prep_info["n"] == n
    assert abs(n - 0.5 * vol / c.mat.sizes.mean_volume) <= 1
    d = c.core.diameters()
    assert c.achieved_phi_bar == pytest.approx(np.sum(np.pi * d**3 / 6) / vol, rel=1e-14)
    assert abs(c.achieved_phi_bar - 0.5) <= np.pi * d.max() ** 3 / 6 / vol
    # the bed fills H - Delta H to its level, Delta H >= 0 empty above it; its rough top is
    # below H here (no sphere across the seam)
    top = float(np.max(c.core.positions()[:, 1] + d / 2))
    assert c.prep_info["bed_top"] == top <= c.H and c.prep_info["seam_spheres"] == 0
    level = c.prep_info["bed_level"]
    assert c.prep_info["delta_H"] == pytest.approx(c.H - level) and 0 <= c.prep_info["delta_H"]
    assert level < top < level + 2
    assert c.prep_info["phi_bed"] == pytest.approx(c.achieved_phi_bar * c.H / top)
    assert c.achieved_phi_bar < c.prep_info["phi_bed"] < c.prep_info["phi_bed_core"] < 0.66


def test_floor_gone_and_bed_at_rest_before_the_flow_starts(rained):
    c = rained
    core = c.core
    assert core.step == 0 and core.time == 0.0
    # the run's simulation: the two side walls only (no floor), periodic in y with period H
    assert "walls: 2 planes" in core.components()
    assert len(core.wall_forces()) == 2
    x, d = core.positions(), core.diameters()
    assert np.all(x[:, 1] >= 0) and np.all(x[:, 1] + d / 2 <= c.H)
    # at rest: settled below settle_ke (kinetic energy per particle, m g d) and released with
    # zero velocities, on the run's own law (no stored elastic burst at the release)
    assert c.prep_info["settle_ke"] < c.settle_ke
    assert not np.any(core.velocities()) and not np.any(core.angular_velocities())
    law = core.law()
    assert law["kn"] == c.law.kn and law["mu"] == c.law.mu and law["e_n"] == c.law.e_n
    # the first step starts from rest; then the whole bed starts to fall (the floor is gone)
    m = core.masses()
    c.run(1, progress=False)
    v = core.velocities()
    assert 0.5 * np.sum(m[:, None] * v**2) / len(m) / np.mean(m) < c.settle_ke
    c.run(20, progress=False)
    assert np.mean(core.velocities()[:, 1]) < 0
    assert core.diagnostics()["max_overlap"] < 0.01


def test_a_phi_bar_the_rain_cannot_pack_is_refused_naming_the_largest_that_fits():
    c = Channel(**RAIN, phi_bar=0.6, seed=2)
    with pytest.raises(ParameterError) as err:
        c.prepare(progress=False)
    msg = str(err.value)
    assert re.search(r"invalid phi_bar = 0\.6\b", msg)
    fits = float(re.search(r"allowed phi_bar <= (0\.\d{3})", msg).group(1))
    assert 0.5 < fits < 0.6 and "level" in msg
    assert not c.prepared  # refused before the run's simulation exists: nothing ran
    # the largest that fits does fit here (an estimate within the rain's randomness, ~0.01)
    ok = Channel(**RAIN, phi_bar=fits, seed=2)
    ok.prepare(progress=False)
    assert ok.prep_info["bed_level"] <= ok.H


def test_a_rough_top_across_the_seam_is_closed_over_the_bed():
    """phi_bar above what the bed holds to its highest sphere, below what it holds to its
    level: the spheres above H cross the seam and are grown back into place there."""
    c = Channel(**RAIN, phi_bar=0.575, seed=2)
    c.prepare(progress=False)
    info = c.prep_info
    assert info["bed_top"] > c.H >= info["bed_level"] and info["seam_spheres"] > 0
    x = c.core.positions()
    assert np.all((x[:, 1] >= 0) & (x[:, 1] < c.H))
    assert c.core.diagnostics()["max_overlap"] < 0.01
    # a local closure: no sphere moved by more than a diameter
    assert 0 < info["seam_shift"] < 1.0
    assert not np.any(c.core.velocities())
    c.run(50, progress=False)
    assert np.mean(c.core.velocities()[:, 1]) < 0


def _digest(c: Channel) -> str:
    return hashlib.sha256(np.ascontiguousarray(c.core.positions()).tobytes()).hexdigest()


def test_rain_same_bits_for_a_seed_on_one_and_two_threads():
    kw = {**RAIN, "W": 6.0, "H": 8.0, "B": 3.5, "phi_bar": 0.4, "seed": 3, "rain_phi": 0.2}
    runs = [Channel(**{**kw, "threads": t}) for t in (1, 1, 2)]
    for c in runs:
        c.prepare(progress=False)
    x = [c.core.positions() for c in runs]
    assert np.array_equal(x[0], x[1]) and np.array_equal(x[0], x[2])
    assert runs[0].prep_info["settle_time"] == runs[2].prep_info["settle_time"]
    other = Channel(**{**kw, "seed": 4})
    other.prepare(progress=False)
    assert _digest(other) != _digest(runs[0])


# positions after prepare() with the former default, the pour, from main at 2cbeea6 (run there
# with PYTHONPATH=/work/main/python): a relaxed bed, a squeezed bed and one left as poured
POUR = [
    ({"W": 6, "H": 8, "B": 3.5, "phi_bar": 0.6, "kn": 1e5, "dt": 3e-4, "seed": 4},
     189, "3a26f65848ef48bff0bad13fe7c739af4fe9cd57e1aff1eb5e35cd606f7c8707"),
    ({"W": 10.0, "H": 8.0, "B": 5.0, "phi_bar": 0.62, "kn": 1e5, "dt": 3.79e-4, "seed": 1},
     465, "94b36ede8f41dd4bad7b003e0aca274fa0770cfbcad4fd45d0581b41358c7c02"),
    ({"W": 8, "H": 12, "B": 4, "phi_bar": 0.5, "kn": 1e5, "dt": 3e-4, "seed": 3},
     360, "bca90401288c4e61c7e5dda522c1b069229422a85d5a6380de0d3756bea15321"),
]


@pytest.mark.parametrize("kw, n, digest", POUR)
def test_pour_is_bit_for_bit_the_former_preparation(kw, n, digest):
    c = Channel(**kw, sample_every=None, threads=1, preparation="pour")
    c.prepare(progress=False)
    assert c.core.n == n and c.prep_info["preparation"] == "pour"
    assert _digest(c) == digest


def test_rain_record_survives_a_checkpoint(rained, tmp_path):
    rained.save_checkpoint(tmp_path / "c.gfck")
    b = Channel(**RAIN, phi_bar=0.5, seed=2)
    b.restore(tmp_path / "c.gfck")
    assert b.prep_info == rained.prep_info and b.prep_info["preparation"] == "rain"
    assert np.array_equal(b.core.positions(), rained.core.positions())


def test_a_soft_rain_is_stiffened_to_the_runs_laws_before_the_release(rained):
    c = Channel(**RAIN, phi_bar=0.5, seed=2, rain_kn=4e4)
    c.prepare(progress=False)
    assert c.prep_info["rain_kn"] == 4e4 and rained.prep_info["rain_kn"] == 1e5
    # released at rest on the run's laws, without the overlaps of the soft bed (load/1e4)
    law = c.core.law()
    assert law["kn"] == 1e5 and law["e_n"] == c.law.e_n and law["mu"] == c.law.mu
    assert c.prep_info["settle_ke"] < c.settle_ke
    assert c.core.diagnostics()["max_overlap"] < 2e-3
    assert 0 <= c.prep_info["delta_H"] and c.prep_info["bed_top"] <= c.H
    # the same rain, softer: a bed as dense as the run's own-law rain within the rain's
    # randomness (docs/channel.md, "Preparation", measures it over seeds at W = 20)
    assert abs(c.prep_info["phi_bed"] - rained.prep_info["phi_bed"]) < 0.02
    assert c.achieved_phi_bar == rained.achieved_phi_bar


@pytest.mark.parametrize("value", [0.0, -1.0, float("nan"), 2e5])
def test_a_rain_stiffer_than_the_run_or_not_positive_is_refused(value):
    with pytest.raises(ParameterError, match=r"invalid rain_kn = .*allowed 0 < rain_kn <= kn"):
        Channel(**RAIN, phi_bar=0.5, rain_kn=value)


def test_a_rain_too_soft_for_its_impacts_is_refused():
    # here the rain lands at up to 15.6 sqrt(g d): below 3.4e4, deeper than 0.05 d
    with pytest.raises(ParameterError, match=r"invalid rain_kn = 10000\.0: allowed rain_kn >= "
                                             r"3\.41e\+04 \(the rain lands at up to 15\.6"):
        Channel(**RAIN, phi_bar=0.5, rain_kn=1e4)
    # the same rain at the run's own kn is 000's protocol, whatever its impacts
    Channel(**RAIN, phi_bar=0.5, rain_kn=1e5)


def test_a_tiled_rain_repeats_one_slab_along_z():
    kw = {**RAIN, "W": 8.0, "H": 12.0, "B": 16.0, "phi_bar": 0.45, "seed": 1}
    c = Channel(**kw, rain_tiles=2)
    c.prepare(progress=False)
    x, d = c.core.positions(), c.core.diameters()
    half = len(d) // 2
    assert len(d) == 2 * half and c.prep_info["rain_tiles"] == 2
    assert np.array_equal(d[half:], d[:half])
    assert np.allclose(x[half:], x[:half] + np.array([0.0, 0.0, 8.0]), rtol=0, atol=1e-12)
    # phi_bar to rain_tiles particles; the copies join without a seam (z periodic)
    vol = c.W * c.H * c.B
    assert abs(c.achieved_phi_bar - 0.45) <= 2 * np.pi * d.max() ** 3 / 6 / vol
    assert c.core.diagnostics()["max_overlap"] < 2e-3
    c.run(20, progress=False)
    assert np.isfinite(c.core.positions()).all()


@pytest.mark.parametrize("tiles", [0, 1.5, True, 3])
def test_rain_tiles_not_a_count_or_too_thin_is_refused(tiles):
    # B = 16: 3 tiles would be 5.3 d thin
    with pytest.raises(ParameterError, match=r"invalid rain_tiles = .*allowed an integer >= 1"):
        Channel(**{**RAIN, "B": 16.0}, phi_bar=0.45, rain_tiles=tiles)
