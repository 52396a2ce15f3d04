"""Python API of the kernel: creation, arrays, determinism, threads, errors, Ctrl-C."""

import signal
import threading

import granflow as gf
import numpy as np
import pytest


def test_create_run_and_read_arrays(gas, make_sim):
    box, x, d, v = gas
    s = make_sim(box, x, d, v)
    n = len(d)
    assert s.n == n
    np.testing.assert_allclose(s.get_velocities(), v)
    s.run(200)
    assert s.step == 200
    for arr in (s.get_positions(), s.get_velocities(), s.get_angular_velocities(),
                s.get_forces(), s.get_torques()):
        assert arr.shape == (n, 3) and np.isfinite(arr).all()
    # positions stay in the periodic box
    x1 = s.get_positions()
    assert (x1 >= 0).all() and (x1 < 8.0).all()
    # default timestep is t_c / 50
    assert s.timestep == pytest.approx(s.contact_time / 50, rel=1e-12)


def test_same_seed_same_numbers_any_thread_count(gas, make_sim):
    box, x, d, v = gas
    out = []
    for threads in (1, 2, 1):
        s = make_sim(box, x, d, v, threads=threads)
        s.run(500)
        out.append(s.get_positions())
    assert np.array_equal(out[0], out[1])
    assert np.array_equal(out[0], out[2])


def test_frictionless_law_has_no_history(gas, make_sim):
    box, x, d, v = gas
    s0 = make_sim(box, x, d, v, law=gf.ContactLaw(kn=1e5, e_n=0.8, mu=0.0))
    s1 = make_sim(box, x, d, v, law=gf.ContactLaw(kn=1e5, e_n=0.8, mu=0.5))
    for s in (s0, s1):
        s.run(300)
    assert s0.memory()["tangential history"] == 0
    # histories are stored per closed contact (24 B each), not per listed pair
    nc = s1.diagnostics()["contacts"]
    assert nc > 0
    assert s1.memory()["tangential history"] >= 24 * nc
    assert "tangential history: none" in s0.components()


@pytest.mark.parametrize(
    "kw, needle",
    [
        ({"law": gf.ContactLaw(kn=-1.0)}, "kn"),
        ({"law": gf.ContactLaw(kn=1e5, e_n=1.5)}, "e_n"),
        ({"law": gf.ContactLaw(kn=1e5, e_n=0.0)}, "e_n"),
        ({"law": gf.ContactLaw(kn=1e5, mu=-0.1)}, "mu"),
        ({"law": gf.ContactLaw(kn=1e5, form="spring")}, "form"),
        ({"dt": 1.0}, "dt"),
        ({"skin": -1.0}, "skin"),
    ],
)
def test_bad_parameters_raise_parameter_error(gas, make_sim, kw, needle):
    box, x, d, v = gas
    with pytest.raises(gf.ParameterError, match=needle) as ei:
        make_sim(box, x, d, v, **kw)
    assert "allowed" in str(ei.value)


def test_bad_particles():
    box = gf.Box(length=(5.0, 5.0, 5.0))
    with pytest.raises(gf.ParameterError, match="positions"):
        gf.Simulation(np.zeros((0, 3)), np.zeros(0), box)
    with pytest.raises(gf.ParameterError, match="diameter"):
        gf.Simulation(np.ones((2, 3)), np.array([1.0, -1.0]), box)
    # two spheres overlapping by half a diameter
    with pytest.raises(gf.ConfigurationError, match="overlap"):
        gf.Simulation(np.array([[1.0, 1, 1], [1.5, 1, 1]]), np.ones(2), box)
    # a periodic box smaller than the particles
    with pytest.raises(gf.ParameterError, match="box"):
        gf.Simulation(np.array([[0.5, 0.5, 0.5]]), np.array([3.0]), box)
    assert issubclass(gf.ParameterError, gf.GranflowError)


def test_ctrl_c_stops_between_steps_and_leaves_sim_usable(gas, make_sim):
    box, x, d, v = gas
    s = make_sim(box, x, d, v)
    # A shell starting the suite in the background (`cmd &` without job control) hands it
    # SIGINT ignored, and Python keeps that: install Python's own handler for this test.
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(0.5, lambda: signal.raise_signal(signal.SIGINT))
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            s.run(10_000_000, progress=False)
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, old)
    stopped = s.step
    assert 0 < stopped < 10_000_000
    assert np.isfinite(s.get_positions()).all()
    s.run(10)
    assert s.step == stopped + 10


def test_momentum_conserved_without_gravity(gas, make_sim):
    box, x, d, v = gas
    s = make_sim(box, x, d, v)
    m = s.core.masses()
    p0 = (m[:, None] * s.get_velocities()).sum(0)
    s.run(1000)
    p1 = (m[:, None] * s.get_velocities()).sum(0)
    scale = (m * np.linalg.norm(v, axis=1)).sum()
    assert np.abs(p1 - p0).max() < 1e-12 * scale


def test_damping_given_twice_is_refused():
    # e_n equal to the default and xi_n: still two damping specifications
    with pytest.raises(gf.ParameterError, match="e_n"):
        gf.ContactLaw(e_n=0.82, xi_n=100.0).as_dict()
    assert gf.ContactLaw().as_dict()["e_n"] == 0.82
    assert gf.ContactLaw().e_n == 0.82
    assert "e_n" not in gf.ContactLaw(xi_n=100.0).as_dict()


def test_contact_time_without_a_simulation(gas, make_sim):
    # the material's lightest-pair contact time is the kernel's, without building a simulation
    from granflow.material import Material

    box, x, d, v = gas
    mat = Material(sizes=gf.sizes.uniform(0.9, 1.1), kn=1e5, e_n=0.7, mu=0.5)
    s = make_sim(box, x, d, v, law=mat.law())
    assert mat.contact_time("lightest", d) == pytest.approx(s.contact_time, rel=1e-12)
    with pytest.raises(gf.ParameterError, match="pair"):
        mat.contact_time("heaviest", d)
