"""Thread counts and simultaneous simulations give the same bits.

Stretches of plain steps run in one team of threads (a spin barrier between the passes, one
team per process; see ``src/engine/team.rs``). These tests run the bindings' own thread pools:
one and two threads, and two simulations stepping at once from two Python threads (one of
them steps without the team while the other holds it).
"""

from __future__ import annotations

import threading

import granflow as gf
import numpy as np
import pytest


def _walled(threads: int) -> gf.Simulation:
    """A frictional gas between walls at x = 0 and x = 8 with gravity towards the first."""
    box = gf.Box(length=(8.0, 8.0, 8.0), periodic=(False, True, True))
    x, d = gf.random_packing(
        gf.sizes.uniform(0.9, 1.1), gf.Box(length=(8.0, 8.0, 8.0)), 0.3, seed=5
    )
    x[:, 0] = 0.6 + x[:, 0] * (6.8 / 8.0)  # clear of the walls
    v = gf.maxwell_velocities(len(d), 1.0, seed=5)
    law = gf.ContactLaw(kn=1e5, e_n=0.7, mu=0.5)
    return gf.Simulation(x, d, box, law, velocities=v, walls=[gf.Wall(0, 0.0, 1.0),
                         gf.Wall(0, 8.0, -1.0)], wall_law=law, gravity=(-2.0, -1.0, 0.0),
                         threads=threads)  # fmt: skip


def _state(s: gf.Simulation) -> tuple[np.ndarray, np.ndarray]:
    return s.get_positions(), s.get_angular_velocities()


def test_one_and_two_threads_same_bits() -> None:
    a, b = _walled(1), _walled(2)
    a.run(800, progress=False)
    b.run(800, progress=False)
    assert a.diagnostics()["contacts"] > 0
    for u, w in zip(_state(a), _state(b), strict=True):
        assert np.array_equal(u, w)


def test_simultaneous_simulations_same_bits() -> None:
    alone = _walled(2)
    alone.run(800, progress=False)
    want = _state(alone)
    sims = [_walled(2), _walled(2)]
    errors: list[BaseException] = []

    def go(s: gf.Simulation) -> None:
        try:
            s.run(800, progress=False)
        except BaseException as e:  # noqa: BLE001 (reported below)
            errors.append(e)

    threads = [threading.Thread(target=go, args=(s,)) for s in sims]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert not any(t.is_alive() for t in threads), "a simulation did not finish (deadlock?)"
    assert not errors, errors
    for s in sims:
        for u, w in zip(_state(s), want, strict=True):
            assert np.array_equal(u, w)


def _large_walled(threads: int) -> gf.Simulation:
    """A frictional gas of 70 560 particles (past the size from which a team step is one
    fused sweep, ``FUSE_N`` in ``src/engine/mod.rs``) between walls, with gravity."""
    nx, ny, nz = 42, 42, 40
    g = np.stack(np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"), -1)
    x = 0.8 + 1.12 * g.reshape(-1, 3).astype(float)
    n = len(x)
    d = np.random.default_rng(7).uniform(0.9, 1.1, n)
    lx, ly, lz = 1.12 * nx + 0.5, 1.12 * ny, 1.12 * nz
    box = gf.Box(length=(lx, ly, lz), periodic=(False, True, True))
    v = gf.maxwell_velocities(n, 1.0, seed=7)
    law = gf.ContactLaw(kn=1e5, e_n=0.7, mu=0.5)
    return gf.Simulation(x, d, box, law, velocities=v, walls=[gf.Wall(0, 0.0, 1.0),
                         gf.Wall(0, lx, -1.0)], wall_law=law, gravity=(-2.0, -1.0, 0.0),
                         threads=threads)  # fmt: skip


def test_fused_sweep_one_and_two_threads_same_bits() -> None:
    a, b = _large_walled(1), _large_walled(2)
    assert a.n >= 65536
    a.run(600, progress=False)
    b.run(600, progress=False)
    assert a.diagnostics()["contacts"] > 0
    for u, w in zip(_state(a), _state(b), strict=True):
        assert np.array_equal(u, w)


def test_sheared_cell_one_and_two_threads_same_bits() -> None:
    """The stress-controlled cell: its half-kicks and drift run in parallel over chunks and
    its kinetic stress is summed per chunk, then over the chunks in order; 2000 particles
    are four chunks, and the run builds and prunes its lists many times."""
    from granflow.scenes.cell import ShearCell

    runs = []
    for threads in (1, 2):
        cell = ShearCell(N=2000, phi0=0.3, p_ext=1e-3, tau_ratio=0.5, seed=3, threads=threads)
        cell.run(3000, progress=False)
        core = cell.core
        d = core.diagnostics()
        assert d["list_builds"] > 5 and d["list_prunes"] > d["list_builds"]
        runs.append((core.positions(), core.velocities(), np.asarray(core.cell()[0])))
    for u, w in zip(*runs, strict=True):
        assert np.array_equal(u, w)


def test_core_round_trip_probe() -> None:
    # the benchmarks' machine probe: a positive, finite time; a bad count is a granflow error
    import math

    from granflow import _core

    t = _core.core_round_trip_ns(2000)
    assert math.isfinite(t) and t > 0.0
    with pytest.raises(gf.ParameterError, match="iters"):
        _core.core_round_trip_ns(0)
