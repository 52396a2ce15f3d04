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
from granflow.simulation import Box, ContactLaw, Simulation, maxwell_velocities, random_packing
from granflow.sizes import uniform

from ._base import check_keys, register, run_with_checkpoints


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
        self._rows: list[dict[str, float]] = []
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

    def _sample(self) -> None:
        e = self.sim.energies()
        dg = self.sim.diagnostics()
        self._rows.append({
            "step": self.sim.step, "t": self.sim.time,
            "ke_trans": e["kinetic_translational"], "ke_rot": e["kinetic_rotational"],
            "elastic": e["elastic"], "n_contacts": dg["contacts"],
            "max_overlap": dg["max_overlap"],
        })

    def run(self, steps: int, progress: bool | None = None,
            checkpoint: str | os.PathLike[str] | None = None,
            checkpoint_every: int | None = None) -> None:
        """Advance ``steps`` steps, sampling every ``sample_every`` steps; ``checkpoint`` and
        ``checkpoint_every`` as :class:`granflow.scenes.Scene` says."""

        def advance(steps: int) -> None:
            done = 0
            while done < steps:
                c = min(self.sample_every - self.sim.step % self.sample_every, steps - done)
                self.sim.run(c, progress=progress)
                done += c
                if self.sim.step % self.sample_every == 0:
                    self._sample()

        run_with_checkpoints(self, steps, advance, checkpoint, checkpoint_every)

    def tables(self) -> dict[str, pa.Table]:
        if not self._rows:
            return {}
        return {"series": pa.Table.from_pylist(self._rows)}

    def load_tables(self, tables: Mapping[str, pa.Table]) -> None:
        if "series" in tables:
            self._rows = tables["series"].to_pylist()

    def summary(self) -> dict[str, Any]:
        if not self._rows:
            return {}
        ke = np.array([r["ke_trans"] for r in self._rows])
        return {"n": self.sim.n, "steps": self.sim.step, "ke_trans_mean": float(ke.mean()),
                "ke_trans_last": float(ke[-1])}

    def save_checkpoint(self, path: str | os.PathLike[str]) -> None:
        self.sim.save_checkpoint(path)

    def restore(self, path: str | os.PathLike[str]) -> None:
        self.sim = Simulation.from_checkpoint(path, threads=self.threads)
