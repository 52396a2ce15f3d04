"""A periodic box of polydisperse spheres with random velocities (no walls, no gravity): kernel
checks, benchmarks and quick tests of the runner and the CLI (``scene = "gas"``).

Its material, :data:`GAS_MATERIAL`, is 000's law at a softer kn = 1e5 and e_n = 0.8, diameters
uniform in [0.9, 1.1], with the kernel's default dt (t_c/50 of the lightest pair)."""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any, ClassVar

import numpy as np
import pyarrow as pa

from granflow import _core
from granflow.errors import ConfigurationError, ParameterError
from granflow.material import MATERIAL_000, Material
from granflow.simulation import (
    Box,
    Simulation,
    maxwell_velocities,
    random_packing,
    run_chunked,
)
from granflow.sizes import uniform

from ._base import (
    SampleTables,
    SceneParameters,
    check_run_keys,
    read_checkpoint_state,
    register,
    run_with_checkpoints,
    write_checkpoint,
)

#: The gas's material: 000's law softened (kn = 1e5, e_n = 0.8), sizes uniform in [0.9, 1.1],
#: the kernel's default dt.
GAS_MATERIAL = MATERIAL_000.with_(sizes=uniform(0.9, 1.1), kn=1e5, e_n=0.8, dt_rule=None)


@register("gas")
@dataclass
class PeriodicGas(SceneParameters):
    """A periodic box of polydisperse spheres with random velocities (no walls, no gravity).

    The material (default :data:`GAS_MATERIAL`) and its flat overrides, ``dt`` (None: the
    material's rule), ``seed`` and ``threads`` are every scene's
    (:class:`~granflow.scenes.SceneParameters`). Samples (every ``sample_every`` steps) a ``series``
    table: step, t, ke_trans, ke_rot, elastic, n_contacts, max_overlap. The kernel is built by
    :meth:`prepare`.

    Args:
        L: The side of the cubic periodic box.
        phi: The volume fraction of the random insertion.
        temperature: The velocity variance per component of the Maxwell start.
        sample_every: Steps between two rows of the ``series`` table.
    """

    L: float = 10.0
    phi: float = 0.3
    temperature: float = 1.0
    sample_every: int = 100

    scene_name: ClassVar[str]
    default_material: ClassVar[Material] = GAS_MATERIAL
    #: no statistical-error report (the gas has no steady figures)
    error_report: ClassVar[bool] = False

    def __post_init__(self) -> None:
        if not (isinstance(self.sample_every, int) and self.sample_every >= 1):
            raise ParameterError(
                f"invalid sample_every = {self.sample_every!r}: allowed an integer >= 1")
        self._resolve_material()
        self._sim: Simulation | None = None
        self._tables = SampleTables()
        self.pbc = (True, True, True)

    def _add_samplers(self, core: _core.Sim) -> None:
        # the series is taken inside the kernel's step loop
        core.add_sampler("series", int(self.sample_every))

    def _simulation(self) -> Simulation:
        if self._sim is None:
            raise ConfigurationError(
                "gas not prepared: call prepare() (or run(), or restore()) first")
        return self._sim

    @property
    def prepared(self) -> bool:
        """Whether the kernel simulation exists."""
        return self._sim is not None

    @property
    def core(self) -> _core.Sim:
        """The kernel simulation (after :meth:`prepare`, :meth:`run` or :meth:`restore`;
        before, a :class:`granflow.ConfigurationError`)."""
        return self._simulation().core

    def prepare(self, progress: bool | None = None) -> None:
        """Build the gas: random insertion at ``phi``, Maxwell velocities (idempotent)."""
        if self._sim is not None:
            return
        mat = self.mat
        box = Box(length=(self.L,) * 3)
        x, d = random_packing(mat.sizes, box, self.phi, seed=self.seed)
        v = maxwell_velocities(len(d), np.sqrt(self.temperature), seed=self.seed)
        dt = self.dt if self.dt is not None else mat.dt(d)
        self._sim = Simulation(x, d, box, mat.law(d), density=mat.density, velocities=v, dt=dt,
                               skin=mat.skin, threads=self.threads)
        self._add_samplers(self._sim.core)

    @classmethod
    def from_spec(cls, params: Mapping[str, Any], seed: int = 0,
                  threads: int | None = None) -> PeriodicGas:
        """A gas from a TOML spec's ``params`` (the field names)."""
        check_run_keys(params, cls)
        return cls(**{**params, "seed": seed, "threads": threads})

    def parameters(self) -> dict[str, Any]:
        """Every parameter (the material's fields flat, ``law`` as the kernel resolves it) and,
        once prepared, the particle count ``n`` and the run's ``dt``."""
        out = {f.name: getattr(self, f.name) for f in fields(self)
               if f.name not in ("threads", "material")}
        out.update(self.mat.parameters())
        out["law"] = self.mat.law().as_dict()
        if self._sim is not None:
            out.update(n=self._sim.n, dt=self._sim.timestep)
        return out

    def run(self, steps: int, progress: bool | None = None,
            checkpoint: str | os.PathLike[str] | None = None,
            checkpoint_every: int | None = None) -> None:
        """Advance ``steps`` steps (preparing first if needed), sampling every
        ``sample_every`` steps; ``checkpoint`` and ``checkpoint_every`` as
        :class:`granflow.scenes.Scene` says."""
        self.prepare(progress)
        sim = self._simulation()

        def advance(steps: int) -> None:
            run_chunked(sim.core, steps, progress, sim,
                        after_chunk=lambda: self._tables.drain(sim.core))

        run_with_checkpoints(self, steps, advance, checkpoint, checkpoint_every)

    def tables(self) -> dict[str, pa.Table]:
        """The sample tables by name (``series``)."""
        if self._sim is not None:
            self._tables.drain(self._sim.core)
        return self._tables.tables()

    def load_tables(self, tables: Mapping[str, pa.Table]) -> None:
        """Start from tables written earlier (a resumed run)."""
        self._tables.load(tables)

    def summary(self) -> dict[str, Any]:
        """``n``, ``steps`` and the translational kinetic energy's mean and last value."""
        t = self.tables().get("series")
        out: dict[str, Any] = {"n": None if self._sim is None else self._sim.n}
        if t is None or self._sim is None:
            return out
        ke = t["ke_trans"].to_numpy()
        out.update(steps=self._sim.step, ke_trans_mean=float(ke.mean()),
                   ke_trans_last=float(ke[-1]))
        return out

    def save_checkpoint(self, path: str | os.PathLike[str]) -> None:
        """The kernel state (:func:`write_checkpoint`)."""
        sim = self._simulation()
        self._tables.drain(sim.core)
        write_checkpoint(self, path, {}, sim)

    def restore(self, path: str | os.PathLike[str]) -> None:
        """The state of a checkpoint written by :meth:`save_checkpoint`."""
        read_checkpoint_state(path, "gas")
        self._sim = Simulation.from_checkpoint(path, threads=self.threads,
                                               configure=self._add_samplers)
