"""Checkpoint and restart: bitwise continuation, atomic files, survival of SIGKILL."""

import os
import signal
import subprocess
import sys
import textwrap
import time

import granflow as gf
import numpy as np
import pytest


def _sim(gas, make_sim, **kw):
    box, x, d, v = gas
    return make_sim(box, x, d, v, **kw)


def test_restart_continues_bitwise(gas, make_sim, tmp_path):
    a = _sim(gas, make_sim)
    a.run(600)
    b = _sim(gas, make_sim)
    b.run(250)
    ck = tmp_path / "state.gfck"
    b.save_checkpoint(ck)
    assert not (tmp_path / "state.tmp").exists()
    c = gf.Simulation.from_checkpoint(ck, threads=1)  # other thread count, same bits
    assert c.step == 250
    c.run(350)
    assert np.array_equal(a.get_positions(), c.get_positions())
    assert np.array_equal(a.get_angular_velocities(), c.get_angular_velocities())


def test_corrupt_checkpoint_is_refused(gas, make_sim, tmp_path):
    s = _sim(gas, make_sim)
    ck = tmp_path / "s.gfck"
    s.save_checkpoint(ck)
    raw = bytearray(ck.read_bytes())
    raw[len(raw) // 2] ^= 0xFF
    bad = tmp_path / "bad.gfck"
    bad.write_bytes(bytes(raw))
    with pytest.raises(gf.GranflowError, match="checkpoint"):
        gf.Simulation.from_checkpoint(bad)


SCRIPT = textwrap.dedent(
    """
    import sys, numpy as np, granflow as gf
    box = gf.Box(length=(8.0, 8.0, 8.0))
    x, d = gf.random_packing(gf.sizes.uniform(0.9, 1.1), box, 0.3, seed=3)
    v = gf.maxwell_velocities(len(d), 1.0, seed=3)
    s = gf.Simulation(x, d, box, gf.ContactLaw(kn=1e5, e_n=0.8, mu=0.5), velocities=v)
    print("ready", flush=True)
    s.run(10_000_000, progress=False, checkpoint=sys.argv[1], checkpoint_every=200)
    """
)


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_killed_run_keeps_a_usable_checkpoint(tmp_path, sig):
    ck = tmp_path / "run.gfck"
    p = subprocess.Popen([sys.executable, "-c", SCRIPT, str(ck)], stdout=subprocess.PIPE)
    assert p.stdout.readline().strip() == b"ready"
    t0 = time.time()
    while not ck.exists() and time.time() - t0 < 60:
        time.sleep(0.05)
    time.sleep(0.7)
    os.kill(p.pid, sig)
    p.wait(timeout=60)
    s = gf.Simulation.from_checkpoint(ck)
    if sig == signal.SIGKILL:
        assert s.step > 0 and s.step % 200 == 0  # only complete periodic checkpoints
    else:
        assert s.step > 0  # SIGTERM writes a final checkpoint between steps
    s.run(10)
    assert np.isfinite(s.get_positions()).all()
