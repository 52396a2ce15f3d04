"""The kernel's samplers (src/sampling/): the same numbers as the Python reference samplers
(tests/reference_samplers.py), the same bits for any thread count, bit-identical tables after
a kill mid-window and a resume, bounded memory, and clear errors for bad input.

Tolerance against the references: the kernel sums in another order than numpy (per force-loop
chunk, then chunks in order; numpy pairwise), its contacts' branch vectors come from the force
loop's image shifts rather than a minimum-image recomputation, and a few formulas are
rearranged (a kinetic sum kept on its upper triangle, caps beyond a sphere's reach taken as 0
or whole): each step of that is a rounding of ~1e-16 relative, summed over ~1e4 particles and
contacts, so 1e-11 of each column's scale leaves room without hiding a wrong term (a term
missing or misplaced shows up at >= 1e-4).
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest
from granflow import ParameterError
from granflow.scenes.cell import ShearCell
from granflow.scenes.channel import Channel
from granflow.simulation import Box, Simulation, Wall
from reference_samplers import ChannelReference, cell_observe

RTOL = 1e-11


def small_channel(**kw) -> Channel:
    # (the soft pour: it packs phi_bar = 0.61 in this small channel, the rain does not)
    base = dict(W=8, H=12, B=4, phi_bar=0.61, kn=1e5, dt=3e-4, seed=2, sample_every=5,
                window=4, preparation="pour")
    return Channel(**{**base, **kw})


def assert_tables_close(got: pa.Table, want: pa.Table, skip: tuple[str, ...] = ()) -> None:
    assert got.column_names == want.column_names
    assert got.num_rows == want.num_rows > 0
    for name in want.column_names:
        if name in skip:
            continue
        a = np.asarray(got[name].to_numpy(), float)
        b = np.asarray(want[name].to_numpy(), float)
        scale = max(float(np.abs(b).max()), 1e-300)
        err = float(np.abs(a - b).max()) / scale
        assert err <= RTOL, f"column {name}: relative difference {err:.2e}"


@pytest.fixture(scope="module")
def flowing_channel() -> Channel:
    c = small_channel(threads=1)
    c.run(3000, progress=False)
    return c


def test_channel_tables_equal_the_reference(flowing_channel):
    c = flowing_channel
    c.tables()
    c.load_tables({})  # keep only what follows
    ref = ChannelReference(c)
    core = c.core
    for _ in range(40):  # 10 windows of 4 samples, aligned with the kernel's
        core.run(4)
        core.request_stats()
        core.run(1)
        ref.sample()
    got, want = c.tables(), ref.tables()
    assert_tables_close(got["bins"], want["bins"], skip=("window",))
    assert_tables_close(got["series"], want["series"])
    w = got["bins"]["window"].to_numpy()
    assert np.array_equal(np.unique(w), np.arange(w[0], w[0] + 10))


def test_cell_series_equals_the_reference():
    c = ShearCell(N=200, p_ext=1e-3, tau_ratio=0.4, sample_every=50, seed=3, threads=1)
    c.run(6000, progress=False)
    c.tables()
    c.load_tables({})
    core = c.core
    rows = []
    for _ in range(12):
        core.run(49)
        core.request_stats()
        core.run(1)
        rows.append(cell_observe(c))
    got = c.tables()["series"]
    want = pa.Table.from_pylist(rows)
    assert got.column_names == want.column_names
    for name in want.column_names:
        a = np.asarray(got[name].to_numpy(), float)
        b = np.asarray(want[name].to_numpy(), float)
        # near-zero columns (d2, theta_c in a symmetric state) compare on their group's scale
        scale = max(float(np.abs(b).max()), 1e-300)
        if name.startswith(("A_", "theta", "d")):
            scale = max(scale, 1.0 if name.startswith(("A_", "theta")) else 1e-30)
        assert float(np.abs(a - b).max()) <= RTOL * scale, name
    # a flowing packing with contacts, not an empty table
    assert got["Z2"].to_numpy().min() > 2.0 and got["n_contacts"].to_numpy().min() > 50


@pytest.mark.parametrize("kind", ["channel", "cell"])
def test_same_bits_for_one_and_two_threads(kind):
    def run(threads: int) -> dict[str, pa.Table]:
        if kind == "channel":
            s = small_channel(threads=threads)
            s.run(1000, progress=False)
        else:
            s = ShearCell(N=200, p_ext=1e-3, tau_ratio=0.4, sample_every=10, seed=3,
                          threads=threads)
            s.run(2000, progress=False)
        return s.tables()

    a, b = run(1), run(2)
    assert a.keys() == b.keys() and a
    for name in a:
        assert a[name].num_rows > 0
        assert a[name].equals(b[name]), name


def _channel_run(tmp_path, kill_at: int | None) -> dict[str, pa.Table]:
    """A channel run of 900 steps (windows of 4 samples every 5 steps: a window every 20
    steps), optionally checkpointed at ``kill_at`` (mid-window) and resumed by a new scene
    from the checkpoint and the tables saved with it."""
    c = small_channel()
    if kill_at is None:
        c.run(900, progress=False)
        return c.tables()
    c.run(kill_at, progress=False)
    ck = tmp_path / "k.gfck"
    c.save_checkpoint(ck)
    saved = c.tables()
    del c  # the process "dies" here
    r = small_channel()
    r.restore(ck)
    r.load_tables(saved)
    r.run(900 - kill_at, progress=False)
    return r.tables()


def test_kill_mid_window_and_resume_is_bit_identical(tmp_path):
    whole = _channel_run(tmp_path, None)
    # 455: 91 samples, three into a window of four
    resumed = _channel_run(tmp_path, 455)
    for name in ("bins", "series"):
        assert whole[name].equals(resumed[name]), name
    assert whole["bins"]["window"].to_numpy().max() == 900 // 20 - 1


def test_cell_kill_mid_run_and_resume_is_bit_identical(tmp_path):
    def make() -> ShearCell:
        return ShearCell(N=80, p_ext=1e-3, tau_ratio=0.5, sample_every=30, seed=5)

    a = make()
    a.run(1000, progress=False)
    whole = a.tables()["series"]
    b = make()
    b.run(500, progress=False)
    b.save_checkpoint(tmp_path / "c.gfck")
    saved = b.tables()
    c = make()
    c.restore(tmp_path / "c.gfck")
    c.load_tables(saved)
    c.run(500, progress=False)
    assert c.tables()["series"].equals(whole)


def test_the_kernel_holds_only_the_open_window(flowing_channel):
    """Closed windows leave the kernel when they are taken; the kernel's memory does not grow
    with the run's length."""
    core = flowing_channel.core
    flowing_channel.tables()
    before = dict(core.memory())
    core.run(2000)  # 100 windows close (a window every 20 steps)
    batches = core.take_tables()
    assert sum(len(b) for b in batches if b.name == "bins") == 100 * 7
    assert core.take_tables() == []
    core.run(2000)
    core.take_tables()
    after = dict(core.memory())
    assert after["samplers"] == before["samplers"]


def test_a_scene_without_samplers_pays_nothing(gas, make_sim):
    s = make_sim(*gas)
    assert s.core.samplers() == []
    s.run(20)
    assert s.core.take_tables() == []


@pytest.mark.parametrize("kw, needle", [
    (dict(kind="channel_bins", every=0, window=4), "channel_bins.every"),
    (dict(kind="channel_bins", every=5, window=0), "channel_bins.window"),
    (dict(kind="channel_bins", every=5, window=4, edges=[0.0, 3.0, 2.0, 8.0]),
     "channel_bins.edges"),
    (dict(kind="channel_bins", every=5, window=4, edges=[0.0, 4.0, 9.0]), "channel_bins.edges"),
    (dict(kind="channel_bins", every=5, window=4, edges=[]), "channel_bins.edges"),
    (dict(kind="histogram", every=5), "sampler"),
    (dict(kind="channel_series", every=5, columns=["vcm_x", "speed"]), "channel_series.columns"),
    (dict(kind="cell_series", every=5), "cell_series"),
])
def test_bad_sampler_input_names_the_parameter(flowing_channel, kw, needle):
    core = flowing_channel.core
    with pytest.raises(ParameterError, match=needle.replace(".", r"\.")):
        core.add_sampler(**kw)


def test_bad_scene_sampling_input_is_refused():
    with pytest.raises(ParameterError, match="sample_every"):
        small_channel(sample_every=0)
    with pytest.raises(ParameterError, match="window"):
        small_channel(window=0)
    with pytest.raises(ParameterError, match="bin_width"):
        small_channel(bin_width=-1.0)
    with pytest.raises(ParameterError, match="sample_every"):
        ShearCell(N=80, sample_every=0)


def test_one_sampler_per_table_and_selected_columns():
    c = small_channel()
    c.prepare(progress=False)
    with pytest.raises(ParameterError, match="one sampler per table"):
        c.core.add_sampler("channel_series", 3)
    # a bare simulation of the same channel, with a series of two columns
    sim = Simulation(np.array(c.core.positions()), np.array(c.core.diameters()),
                     Box(length=(c.W, c.H, c.B), periodic=(False, True, True)), c.law,
                     walls=[Wall(0, 0.0, 1.0), Wall(0, c.W, -1.0)], gravity=(0.0, -1.0, 0.0),
                     dt=c.dt)
    sim.core.add_sampler("channel_series", 2, columns=["step", "vcm_y"])
    assert sim.core.samplers() == [("channel_series", "series")]
    sim.run(10)
    t = pa.Table.from_batches([pa.record_batch(b) for b in sim.core.take_tables()])
    assert t.column_names == ["step", "vcm_y"]
    assert t["step"].to_pylist() == [2, 4, 6, 8, 10]
    assert t.schema.field("vcm_y").metadata[b"unit"] == b"sqrt(g d)"
