"""One contact law, one home: the kernel's LawSpec holds the defaults and the validation; a law
given from Python and the law a simulation built with no damping uses are the same."""

import granflow as gf
import numpy as np
import pytest
from granflow import _core

# the documented defaults (granflow::contact::LawSpec), written out
DEFAULTS = {"kn": 1e6, "kt": 2 / 7 * 1e6, "e_n": 0.82, "xi_t_ratio": 0.5, "mu": 0.5}


def _pair(law: dict) -> _core.Sim:
    x = np.array([[2.0, 2.0, 2.0], [3.5, 2.0, 2.0]])
    return _core.box_sim(x, np.ones(2), 1.0, (0.0, 0.0, 0.0), (5.0, 5.0, 5.0), (True,) * 3,
                         "hooke", law)


def test_kernel_resolves_the_documented_defaults():
    assert _core.resolve_law({}) == DEFAULTS
    kn = 3.5e5
    r = _core.resolve_law({"kn": kn})
    assert r == {"kn": kn, "kt": 2 / 7 * kn, "e_n": 0.82, "xi_t_ratio": 0.5, "mu": 0.5}
    # a rate instead of a restitution: no e_n at all
    assert "e_n" not in _core.resolve_law({"xi_n": 10.0})
    assert _core.resolve_law({"e_n": None, "kt": 1.0})["kt"] == 1.0


def test_python_law_without_damping_is_the_kernel_law():
    kn = 2e5
    py_law = gf.ContactLaw(kn=kn)  # no damping given
    # a Sim built straight from the binding with no damping (formerly e_n = 1 there)
    raw = _pair({"kn": kn}).law()
    # a Sim built through the Python package
    box = gf.Box(length=(5.0, 5.0, 5.0))
    x = np.array([[2.0, 2.0, 2.0], [3.5, 2.0, 2.0]])
    sim = gf.Simulation(x, np.ones(2), box, py_law)
    assert raw == py_law.as_dict() == sim._sim.law()
    assert raw["e_n"] == 0.82 and raw["kt"] == 2 / 7 * kn and raw["mu"] == 0.5
    assert sim._sim.wall_law() is None


def test_contact_law_fields_show_the_resolved_law():
    law = gf.ContactLaw(kn=1e5)
    assert (law.kn, law.kt, law.e_n, law.xi_n, law.xi_t_ratio, law.mu) == (
        1e5, 2 / 7 * 1e5, 0.82, None, 0.5, 0.5)
    assert gf.ContactLaw() == gf.ContactLaw(**_core.resolve_law({}))
    rate = gf.ContactLaw(kn=1e5, xi_n=30.0, mu=0.0)
    assert rate.e_n is None and rate.as_dict() == {
        "kn": 1e5, "kt": 2 / 7 * 1e5, "xi_n": 30.0, "xi_t_ratio": 0.5, "mu": 0.0}
    with pytest.raises(AttributeError):
        law.kn = 2.0  # type: ignore[misc]


def test_wall_law_is_resolved_by_the_kernel_too():
    x = np.array([[1.0, 2.0, 2.0], [3.0, 2.0, 2.0]])
    box = gf.Box(length=(5.0, 5.0, 5.0), periodic=(False, True, True))
    walls = [gf.Wall(0, 0.0, 1.0), gf.Wall(0, 5.0, -1.0)]
    sim = gf.Simulation(x, np.ones(2), box, gf.ContactLaw(kn=1e5), walls=walls,
                        wall_law=gf.ContactLaw(kn=4e5, mu=0.0))
    assert sim._sim.wall_law() == {"kn": 4e5, "kt": 2 / 7 * 4e5, "e_n": 0.82,
                                   "xi_t_ratio": 0.5, "mu": 0.0}
    # no wall law given: the walls use the particles' law
    sim = gf.Simulation(x, np.ones(2), box, gf.ContactLaw(kn=1e5), walls=walls)
    assert sim._sim.wall_law() == sim._sim.law()


@pytest.mark.parametrize(
    "law, needle",
    [
        ({"kn": -1.0}, "kn"),
        ({"e_n": 0.0}, "e_n"),
        ({"e_n": 0.8, "xi_n": 1.0}, "e_n/xi_n"),
        ({"mu": -0.1}, "mu"),
        ({"kt": float("nan")}, "kt"),
        ({"spring": 1.0}, "spring"),
    ],
)
def test_invalid_laws_are_refused_by_the_kernel(law, needle):
    with pytest.raises(gf.ParameterError, match=needle):
        _core.resolve_law(law)
    with pytest.raises(gf.ParameterError, match=needle):
        _pair(law)
    if "spring" not in law:
        bad = gf.ContactLaw(**law)  # kept as given ...
        with pytest.raises(gf.ParameterError, match=needle):
            bad.as_dict()  # ... and refused when used


def test_channel_wall_law_takes_the_kernel_kt():
    # the channel's wall law leaves kt to the law: 2/7 of the wall's kn, as the kernel resolves it
    from granflow.scenes.channel import Channel

    ch = Channel(kn=2e5, wall_kn=3e5)
    assert ch.wall_law.as_dict() == _core.resolve_law({"kn": 3e5, "e_n": ch.law.e_n,
                                                       "mu": ch.law.mu})
    assert ch.wall_law.kt == 2 / 7 * 3e5 and ch.law.kt == 2 / 7 * 2e5
    assert Channel(kn=2e5).wall_law == ch.law
