"""What every scene shares: the scene table, the key check, the :class:`Scene` protocol, the
sample tables drained from the kernel's samplers and the run loop that honours ``checkpoint`` /
``checkpoint_every``.

The scene modules (:mod:`granflow.scenes.channel`, :mod:`granflow.scenes.cell`,
:mod:`granflow.scenes.gas`) import from here and :mod:`granflow.scenes` imports them, so the
imports run one way.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from typing import Any, ClassVar, Protocol, TypeVar, runtime_checkable

import pyarrow as pa

from granflow import _core
from granflow.errors import ParameterError
from granflow.simulation import check_checkpoint_args, to_table

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
    * ``prepare()`` makes the kernel simulation (a scene with a preparation protocol, like the
      channel's fill and release or the cell's compaction, runs it here); it is idempotent, and
      ``run`` calls it. The kernel's step count may not be 0 after it (the cell's compaction is
      part of its series); the runner counts a spec's ``steps`` from there.
    * ``core`` is the kernel simulation (:class:`granflow._core.Sim`) of a prepared scene.
    * ``run(steps, progress, checkpoint, checkpoint_every)`` advances ``steps`` steps; with
      ``checkpoint`` set it writes the scene's checkpoint there every ``checkpoint_every``
      steps (at multiples of it in the step count), at the end, and when interrupted (Ctrl-C,
      SIGTERM) before the interrupt propagates.
    * ``tables()`` are the sample tables by name; ``load_tables`` takes them back on a restart;
      ``summary()`` is the scene's analysis flattened to scalars (with standard errors).
    * ``save_checkpoint(path)`` / ``restore(path)``: the kernel state, bitwise.
    """

    scene_name: ClassVar[str]
    #: periodic axes (x, y, z), for snapshots
    pbc: tuple[bool, bool, bool]

    @classmethod
    def from_spec(cls, params: Mapping[str, Any], seed: int = 0,
                  threads: int | None = None) -> Scene: ...

    def parameters(self) -> dict[str, Any]: ...

    def prepare(self, progress: bool | None = None) -> None: ...

    @property
    def core(self) -> _core.Sim: ...

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
