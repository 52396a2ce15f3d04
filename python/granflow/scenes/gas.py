"""A periodic box of polydisperse spheres with random velocities (no walls, no gravity): kernel
checks, benchmarks and quick tests of the runner and the CLI (``scene = "gas"``)."""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import pyarrow as pa

from granflow import _core
from granflow.errors import ParameterError
from granflow.simulation import (
    Box,
    ContactLaw,
    Simulation,
    maxwell_velocities,
    random_packing,
    run_chunked,
)
from granflow.sizes import uniform

from ._base import SampleTables, check_keys, register, run_with_checkpoints


@register("gas")
@dataclass
class PeriodicGas:
    """A periodic box of polydisperse spheres with random velocities (no walls, no gravity).

    Samples (every ``sample_every`` steps) a ``series`` table: step, t, ke_trans, ke_rot,
    elastic, n_contacts, max_overlap."""

    L: float = 10.0
    phi: float = 0.3
    d_min: float = 0.9
    d_max: float = 1.1
    kn: float = 1e5
    e_n: float = 0.8
    mu: float = 0.5
    temperature: float = 1.0
    sample_every: int = 100
    seed: int = 0
    threads: int | None = None

    scene_name: ClassVar[str]

    def __post_init__(self) -> None:
        box = Box(length=(self.L,) * 3)
        x, d = random_packing(uniform(self.d_min, self.d_max), box, self.phi, seed=self.seed)
        v = maxwell_velocities(len(d), np.sqrt(self.temperature), seed=self.seed)
        self.sim = Simulation(
            x, d, box, ContactLaw(kn=self.kn, e_n=self.e_n, mu=self.mu), velocities=v,
            threads=self.threads,
        )
        if not (isinstance(self.sample_every, int) and self.sample_every >= 1):
            raise ParameterError(
                f"invalid sample_every = {self.sample_every!r}: allowed an integer >= 1")
        self._tables = SampleTables()
        # the series is taken inside the kernel's step loop
        self.sim.core.add_sampler("series", int(self.sample_every))
        self.pbc = (True, True, True)

    @property
    def core(self) -> _core.Sim:
        """The kernel simulation."""
        return self.sim.core

    def prepare(self, progress: bool | None = None) -> None:
        """Nothing to do: the gas is ready when built."""

    @classmethod
    def from_spec(cls, params: Mapping[str, Any], seed: int = 0,
                  threads: int | None = None) -> PeriodicGas:
        check_keys("params", params, cls.__dataclass_fields__)
        return cls(**{**params, "seed": seed, "threads": threads})

    def parameters(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__ if k != "threads"}

    def run(self, steps: int, progress: bool | None = None,
            checkpoint: str | os.PathLike[str] | None = None,
            checkpoint_every: int | None = None) -> None:
        """Advance ``steps`` steps, sampling every ``sample_every`` steps; ``checkpoint`` and
        ``checkpoint_every`` as :class:`granflow.scenes.Scene` says."""

        def advance(steps: int) -> None:
            core = self.sim.core
            run_chunked(core, steps, progress, self.sim,
                        after_chunk=lambda: self._tables.drain(core))

        run_with_checkpoints(self, steps, advance, checkpoint, checkpoint_every)

    def tables(self) -> dict[str, pa.Table]:
        self._tables.drain(self.sim.core)
        return self._tables.tables()

    def load_tables(self, tables: Mapping[str, pa.Table]) -> None:
        self._tables.load(tables)

    def summary(self) -> dict[str, Any]:
        t = self.tables().get("series")
        if t is None:
            return {}
        ke = t["ke_trans"].to_numpy()
        return {"n": self.sim.n, "steps": self.sim.step, "ke_trans_mean": float(ke.mean()),
                "ke_trans_last": float(ke[-1])}

    def save_checkpoint(self, path: str | os.PathLike[str]) -> None:
        self._tables.drain(self.sim.core)
        self.sim.save_checkpoint(path)

    def restore(self, path: str | os.PathLike[str]) -> None:
        self.sim = Simulation.from_checkpoint(
            path, threads=self.threads,
            configure=lambda core: core.add_sampler("series", int(self.sample_every)))
