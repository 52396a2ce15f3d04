"""Every scene keeps the Scene protocol, and its run honours every argument it takes:
``checkpoint`` is written every ``checkpoint_every`` steps, at the end and on an interrupt, and
restores to the same state."""

from __future__ import annotations

import granflow as gf
import numpy as np
import pytest
from granflow.scenes import Channel, PeriodicGas, RateCell, Scene, ShearCell

FACTORIES = {
    "gas": lambda: PeriodicGas(L=6.0, sample_every=50, seed=2),
    "cell": lambda: ShearCell(N=60, sample_every=50, seed=2),
    "rate_cell": lambda: RateCell(N=60, sample_every=50, seed=2),
    # (the soft pour: it packs phi_bar = 0.6 in this tiny channel, the rain does not)
    "channel": lambda: Channel(W=6, H=8, B=3.5, phi_bar=0.6, kn=1e5, dt=3e-4, seed=4,
                               sample_every=50, window=4, preparation="pour"),
}


@pytest.fixture(params=sorted(FACTORIES))
def scene_kind(request):
    return request.param


def _state(scene: Scene) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    c = scene.core
    return c.step, c.positions(), c.velocities(), c.angular_velocities()


def _same(a, b) -> bool:
    return a[0] == b[0] and all(np.array_equal(x, y) for x, y in zip(a[1:], b[1:], strict=True))


def _record_checkpoints(monkeypatch, scene) -> list[int]:
    steps: list[int] = []
    orig = scene.save_checkpoint

    def save(path):
        orig(path)
        steps.append(scene.core.step)

    monkeypatch.setattr(scene, "save_checkpoint", save)
    return steps


def test_scenes_keep_the_protocol(scene_kind):
    s = FACTORIES[scene_kind]()
    s.prepare()
    step0 = s.core.step  # (0 but for the cell's compaction)
    x = s.core.positions()
    s.prepare()  # idempotent
    assert s.core.step == step0 and np.array_equal(s.core.positions(), x)
    assert isinstance(s, Scene)
    assert s.scene_name == scene_kind


def test_core_needs_an_explicit_preparation(scene_kind):
    # the same construction rule for every scene: the kernel is built by prepare()
    sc = FACTORIES[scene_kind]()
    assert not sc.prepared
    with pytest.raises(gf.ConfigurationError, match="prepare"):
        sc.core  # noqa: B018
    sc.prepare()
    assert sc.prepared
    x = sc.core.positions()
    sc.prepare()  # a second call changes nothing
    assert np.array_equal(sc.core.positions(), x)


SHARED = {"mu": 0.2, "kt_ratio": 0.5, "e_n": 0.7, "sizes": [0.95, 1.05]}


def test_one_vocabulary_across_scenes(scene_kind):
    # the shared parameters have the same names and meanings in every scene: they reach the
    # kernel's law, and parameters() and summary() report them under the same keys
    cls = type(FACTORIES[scene_kind]())
    base = {"gas": {"L": 6.0}, "cell": {"N": 60}, "rate_cell": {"N": 60},
            "channel": {"W": 6, "H": 8, "B": 3.5, "kn": 1e5,
                        "preparation": "pour"}}[scene_kind]
    sc = cls(**base, **SHARED, dt=1e-4, sample_every=50, seed=3)
    sc.prepare()
    law = sc.core.law()
    assert law["mu"] == 0.2 and law["kt"] == pytest.approx(0.5 * law["kn"]) and law["e_n"] == 0.7
    d = sc.core.diameters()
    assert d.min() >= 0.95 and d.max() <= 1.05 and sc.core.dt == 1e-4
    p = sc.parameters()
    assert {k: p[k] for k in SHARED} == SHARED and p["seed"] == 3 and p["sample_every"] == 50
    sc.run(100, progress=False)
    assert sc.summary()["n"] == sc.core.n == p.get("n", sc.core.n)


def test_a_checkpoint_of_another_scene_is_refused(tmp_path):
    g = FACTORIES["gas"]()
    g.run(10, progress=False, checkpoint=tmp_path / "g.gfck")
    with pytest.raises(gf.ParameterError, match="'gas'.*allowed a 'cell' checkpoint"):
        FACTORIES["cell"]().restore(tmp_path / "g.gfck")
    # a checkpoint without a scene header (a bare Simulation's, or an older granflow's)
    sim = g.core
    sim.save_checkpoint(str(tmp_path / "bare.gfck"), "{}")
    with pytest.raises(gf.ParameterError, match="no scene header.*allowed a 'cell'"):
        FACTORIES["cell"]().restore(tmp_path / "bare.gfck")


def test_run_writes_checkpoints_every_n_steps_and_at_the_end(scene_kind, tmp_path, monkeypatch):
    s = FACTORIES[scene_kind]()
    s.prepare()
    step0 = s.core.step  # a multiple of 100: the cell compacts in stints of 2000 steps
    written = _record_checkpoints(monkeypatch, s)
    ck = tmp_path / "run.gfck"
    s.run(250, progress=False, checkpoint=ck, checkpoint_every=100)
    assert written == [step0 + 100, step0 + 200, step0 + 250]
    assert ck.exists()
    r = FACTORIES[scene_kind]()
    r.restore(ck)
    assert _same(_state(r), _state(s))
    # the restored scene continues as the original does
    s.run(100, progress=False)
    r.run(100, progress=False)
    assert _same(_state(r), _state(s))


def test_run_writes_a_checkpoint_at_the_end_without_checkpoint_every(scene_kind, tmp_path,
                                                                     monkeypatch):
    s = FACTORIES[scene_kind]()
    s.prepare()
    step0 = s.core.step
    written = _record_checkpoints(monkeypatch, s)
    s.run(120, progress=False, checkpoint=tmp_path / "end.gfck")
    assert written == [step0 + 120]


def test_run_writes_a_checkpoint_when_interrupted(tmp_path, monkeypatch):
    s = FACTORIES["gas"]()
    orig = s._tables.drain
    fired = []

    def interrupt(core) -> None:  # once, between two chunks of the run past step 150
        orig(core)
        if core.step >= 150 and not fired:
            fired.append(core.step)
            raise KeyboardInterrupt

    monkeypatch.setattr(s._tables, "drain", interrupt)
    ck = tmp_path / "stop.gfck"
    with pytest.raises(KeyboardInterrupt):
        s.run(1000, progress=False, checkpoint=ck, checkpoint_every=400)
    monkeypatch.setattr(s._tables, "drain", orig)
    r = FACTORIES["gas"]()
    r.restore(ck)
    assert 150 <= r.core.step < 400 and r.core.step == s.core.step
    assert _same(_state(r), _state(s))


@pytest.mark.parametrize("kind", ["gas", "cell"])
def test_checkpoint_every_without_a_checkpoint_is_refused(kind):
    s = FACTORIES[kind]()
    with pytest.raises(gf.ParameterError, match="checkpoint_every"):
        s.run(100, progress=False, checkpoint_every=50)
    with pytest.raises(gf.ParameterError, match="checkpoint_every"):
        s.run(100, progress=False, checkpoint="x.gfck", checkpoint_every=0)


def test_simulation_run_writes_its_checkpoint_at_the_end(gas, make_sim, tmp_path):
    s = make_sim(*gas)
    ck = tmp_path / "sim.gfck"
    s.run(30, progress=False, checkpoint=ck)
    r = gf.Simulation.from_checkpoint(ck)
    assert r.step == 30 and np.array_equal(r.get_positions(), s.get_positions())
    with pytest.raises(gf.ParameterError, match="checkpoint_every"):
        s.run(10, progress=False, checkpoint_every=5)


def test_the_scenes_with_an_error_report_are_the_reports_table():
    from granflow.analysis.report import REPORTS
    from granflow.scenes import SCENES

    assert {name for name, cls in SCENES.items() if cls.error_report} == set(REPORTS)
