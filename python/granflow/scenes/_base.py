"""What every scene shares: the scene table, the key check, the material and its flat
overrides, the :class:`Scene` protocol, the sample tables drained from the kernel's samplers, the
checkpoint header and the run loop that honours ``checkpoint`` / ``checkpoint_every``.

The scene modules (:mod:`granflow.scenes.channel`, :mod:`granflow.scenes.cell`,
:mod:`granflow.scenes.gas`) import from here and :mod:`granflow.scenes` imports them, so the
imports run one way.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields
from typing import Any, ClassVar, Protocol, TypeVar, runtime_checkable

import numpy as np
import pyarrow as pa

from granflow import _core
from granflow.errors import ParameterError
from granflow.material import MATERIALS, Material
from granflow.simulation import Simulation, check_checkpoint_args, to_table

SCENES: dict[str, type] = {}

_T = TypeVar("_T", bound=type)


def register(name: str) -> Callable[[_T], _T]:
    """Class decorator: enter a scene class in the scene table under ``name`` (the TOML
    ``scene = ...`` key) and set its ``scene_name``."""

    def deco(cls: _T) -> _T:
        SCENES[name] = cls
        cls.scene_name = name  # type: ignore[attr-defined]  # declared as a ClassVar on scenes
        return cls

    return deco


def check_keys(section: str, given: Mapping[str, Any], allowed: Mapping[str, Any] | set[str]
               ) -> None:
    """Refuse unknown keys with a message naming the key and the allowed ones."""
    for k in given:
        if k not in allowed:
            raise ParameterError(
                f"invalid {section}.{k}: unknown key: allowed one of {sorted(allowed)}"
            )


#: The material's fields a scene takes as flat overrides (same names and meanings in every
#: scene; None leaves the material's value).
MATERIAL_KEYS = ("sizes", "density", "kn", "kt_ratio", "e_n", "xi_t_ratio", "mu", "form",
                 "tc_reading", "skin")


@dataclass(kw_only=True)
class SceneParameters:
    """The parameters every scene shares, with one name and meaning in each (keywords only).

    Args:
        material: A :class:`granflow.material.Material`, or the name of one ("000", "002"; a
            TOML spec's ``material = "..."``); None is the scene's own (the channel
            :data:`~granflow.material.MATERIAL_000`, the cell
            :data:`~granflow.material.MATERIAL_002`, the gas :data:`gas.GAS_MATERIAL`).
        sizes: Override of the material's size distribution: a ``{d: fraction}`` mapping,
            ``[lo, hi]`` (uniform) or a :class:`~granflow.sizes.SizeDist`.
        density: Override of the particle density.
        kn: Override of the normal stiffness.
        kt_ratio: Override of the tangential over normal stiffness, k_t/k_n.
        e_n: Override of the normal restitution.
        xi_t_ratio: Override of the tangential over normal damping.
        mu: Override of the friction coefficient.
        form: Override of the normal force law, "hooke" or "hertz".
        tc_reading: Override of how the mean pair's contact time reads 002 ("collision" or
            "printed").
        skin: Override of the neighbour-list skin.
        dt: The time step, absolute; None is the material's rule (:meth:`Material.dt`).
        seed: The seed of every random draw of the scene (sizes, positions, velocities).
        threads: Kernel threads (None: all cores); results do not depend on it.

    An override left at None keeps the material's value; scenes take both a material and the
    overrides so that a TOML spec or a sweep grid can vary one field (``mu = [0.1, 0.3]``) and
    code can pass a whole material.
    """

    material: Material | str | None = None
    sizes: Any = None
    density: float | None = None
    kn: float | None = None
    kt_ratio: float | None = None
    e_n: float | None = None
    xi_t_ratio: float | None = None
    mu: float | None = None
    form: str | None = None
    tc_reading: str | None = None
    skin: float | None = None
    dt: float | None = None
    seed: int = 0
    threads: int | None = None

    #: the scene's own material, when ``material`` is None
    default_material: ClassVar[Material]

    def _resolve_material(self) -> Material:
        """Set ``material`` to the scene's material: ``material`` (a :class:`Material`, a name
        of :data:`granflow.material.MATERIALS`, or None for ``default_material``) with the
        flat overrides that are not None applied (:meth:`Material.with_`); returns it."""
        given = self.material
        if given is None:
            base = self.default_material
        elif isinstance(given, Material):
            base = given
        elif isinstance(given, str) and given in MATERIALS:
            base = MATERIALS[given]
        else:
            raise ParameterError(f"invalid material = {given!r}: allowed a Material or one of "
                                 f"{sorted(MATERIALS)}")
        overrides = {k: getattr(self, k) for k in MATERIAL_KEYS if getattr(self, k) is not None}
        self.material = base.with_(**overrides) if overrides else base
        return self.material

    @property
    def mat(self) -> Material:
        """The scene's material (``material`` with the flat overrides applied)."""
        assert isinstance(self.material, Material), "the scene has not resolved its material"
        return self.material


def check_run_keys(params: Mapping[str, Any], cls: type) -> None:
    """Refuse a spec's ``params`` key that is not a field of the scene class ``cls`` (seed and
    threads come from the spec's top level)."""
    check_keys("params", params, {f.name for f in fields(cls)} - {"seed", "threads"})


def _jsonable(v: Any) -> Any:
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, Material):
        return v.parameters()
    return str(v)


def write_checkpoint(scene: Scene, path: str | os.PathLike[str], state: Mapping[str, Any],
                     sim: Simulation | None = None) -> None:
    """Write ``scene``'s checkpoint: the kernel state with one JSON header layout for every
    scene, ``{"scene": {"scene": name, "parameters": scene.parameters(), "state": state}}``
    (``state``: what the scene needs back on :meth:`Scene.restore`, e.g. the channel's
    preparation record or the cell's shear start), beside what rebuilds ``sim`` when the scene
    runs on a :class:`~granflow.simulation.Simulation`."""
    head = {"scene": scene.scene_name, "parameters": scene.parameters(), "state": dict(state)}
    head = json.loads(json.dumps(head, default=_jsonable))
    if sim is not None:
        sim.save_checkpoint(path, scene=head)
    else:
        scene.core.save_checkpoint(os.fspath(path), json.dumps({"scene": head}))


def read_checkpoint_state(path: str | os.PathLike[str], scene_name: str) -> dict[str, Any]:
    """The ``state`` a scene's checkpoint holds (:func:`write_checkpoint`); a checkpoint of
    another scene, or none, is refused."""
    params = _core.read_checkpoint_header(os.fspath(path))[1]
    head = json.loads(params or "{}").get("scene")
    if not isinstance(head, dict):
        raise ParameterError(
            f"invalid checkpoint {os.fspath(path)!r}: it has no scene header (written by a "
            "bare Simulation, or by a granflow older than the scenes' one checkpoint layout, "
            f"which cannot be resumed): allowed a {scene_name!r} scene's checkpoint")
    if head.get("scene") != scene_name:
        raise ParameterError(f"invalid checkpoint {os.fspath(path)!r}: written by scene "
                             f"{head.get('scene')!r}: allowed a {scene_name!r} checkpoint")
    return dict(head.get("state", {}))


class SampleTables:
    """A scene's sample tables: the Arrow batches its kernel samplers close (one per window,
    or a series' rows since the last drain), collected by table name as they are drained
    (the kernel then holds only its open windows)."""

    def __init__(self) -> None:
        self._parts: dict[str, list[pa.Table]] = {}

    def drain(self, core: _core.Sim) -> None:
        """Take the tables the kernel's samplers closed since the last drain."""
        for batch in core.take_tables():
            self._parts.setdefault(batch.name, []).append(to_table(batch))

    def tables(self) -> dict[str, pa.Table]:
        """Every table by name (the parts joined once, then kept joined)."""
        out = {}
        for name, parts in self._parts.items():
            if len(parts) > 1:
                parts[:] = [pa.concat_tables(parts, promote_options="permissive")
                            .combine_chunks()]
            if parts and parts[0].num_rows:
                out[name] = parts[0]
        return out

    def load(self, tables: Mapping[str, pa.Table]) -> None:
        """Start from tables written earlier (a resumed run), dropping any drained rows."""
        self._parts = {k: [t] for k, t in tables.items()}

    def last(self, table: str) -> dict[str, Any] | None:
        """The newest row of ``table`` (None before the first), without joining the parts."""
        parts = self._parts.get(table)
        if not parts or not parts[-1].num_rows:
            return None
        t = parts[-1]
        return t.slice(t.num_rows - 1).to_pylist()[0]


@runtime_checkable
class Scene(Protocol):
    """The contract every scene keeps, so the runner, the CLI and the studies treat them alike.

    * ``from_spec(params, seed, threads)`` builds a scene from the ``params`` of a TOML spec;
      ``parameters()`` gives back every parameter (defaults included) for the tables' metadata.
    * Construction only checks the parameters; ``prepare()`` makes the kernel simulation (a
      scene with a preparation protocol, like the channel's fill and release or the cell's
      compaction, runs it here); it is idempotent, and ``run`` calls it. The kernel's step
      count may not be 0 after it (the cell's compaction is part of its series); the runner
      counts a spec's ``steps`` from there.
    * ``core`` is the kernel simulation (:class:`granflow._core.Sim`) of a prepared scene (the
      one accessor: before ``prepare``, ``restore`` or ``run`` it raises
      :class:`granflow.ConfigurationError`); ``prepared`` says whether it exists.
    * ``run(steps, progress, checkpoint, checkpoint_every)`` advances ``steps`` steps; with
      ``checkpoint`` set it writes the scene's checkpoint there every ``checkpoint_every``
      steps (at multiples of it in the step count), at the end, and when interrupted (Ctrl-C,
      SIGTERM) before the interrupt propagates.
    * ``tables()`` are the sample tables by name; ``load_tables`` takes them back on a restart;
      ``summary()`` is the scene's analysis flattened to scalars: ``n`` (the particle count),
      ``state`` (a :class:`granflow.states.FlowState`, where the scene classifies its flow)
      and each value ``x`` with its standard error ``x_se``.
    * ``save_checkpoint(path)`` / ``restore(path)``: the kernel state, bitwise, with the
      header :func:`write_checkpoint` writes.
    """

    scene_name: ClassVar[str]
    #: whether the runner writes the statistical-error report (granflow.analysis.report)
    error_report: ClassVar[bool]
    #: periodic axes (x, y, z), for snapshots
    pbc: tuple[bool, bool, bool]

    @classmethod
    def from_spec(cls, params: Mapping[str, Any], seed: int = 0,
                  threads: int | None = None) -> Scene: ...

    def parameters(self) -> dict[str, Any]: ...

    def prepare(self, progress: bool | None = None) -> None: ...

    @property
    def core(self) -> _core.Sim: ...

    @property
    def prepared(self) -> bool: ...

    def run(self, steps: int, progress: bool | None = None,
            checkpoint: str | os.PathLike[str] | None = None,
            checkpoint_every: int | None = None) -> None: ...

    def tables(self) -> dict[str, pa.Table]: ...

    def load_tables(self, tables: Mapping[str, pa.Table]) -> None: ...

    def summary(self) -> dict[str, Any]: ...

    def save_checkpoint(self, path: str | os.PathLike[str]) -> None: ...

    def restore(self, path: str | os.PathLike[str]) -> None: ...


def run_with_checkpoints(
    scene: Scene,
    steps: int,
    advance: Callable[[int], None],
    checkpoint: str | os.PathLike[str] | None,
    checkpoint_every: int | None,
) -> None:
    """Advance a prepared ``scene`` by ``steps`` steps with ``advance(n)`` (the scene's own
    stepping and sampling) and write its checkpoint as :class:`Scene` says: every
    ``checkpoint_every`` steps, at the end and on an interrupt."""
    steps = int(steps)
    if steps < 0:
        raise ParameterError(f"invalid steps = {steps}: allowed >= 0")
    check_checkpoint_args(checkpoint, checkpoint_every)
    if checkpoint is None:
        advance(steps)
        return
    every = int(checkpoint_every) if checkpoint_every is not None else 0
    core = scene.core
    target = core.step + steps
    try:
        while core.step < target:
            n = target - core.step
            if every:
                n = min(n, every - core.step % every)
            advance(n)
            if every and core.step % every == 0 and core.step < target:
                scene.save_checkpoint(checkpoint)
    except (KeyboardInterrupt, SystemExit):
        scene.save_checkpoint(checkpoint)
        raise
    scene.save_checkpoint(checkpoint)
