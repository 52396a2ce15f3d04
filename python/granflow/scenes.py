"""Scenes: the papers' set-ups with their defaults, built from a few parameters.

- :class:`granflow.channel.Channel` — vertical channel of 000 (Debnath, Kesava Rao & Kumaran).
- :class:`granflow.cell.ShearCell` — stress-controlled triclinic cell of 002 (Srivastava et al.).
- :class:`PeriodicGas` — a periodic box of spheres (kernel checks, benchmarks, quick tests).

Every scene follows one protocol, so the runner, the CLI and the study helpers treat them alike:
``from_spec(params, seed)``, ``run(steps, ...)``, ``tables()`` (pyarrow tables by name),
``summary()``, ``parameters()``, ``save_checkpoint(path)`` / ``from_checkpoint(path)``.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import pyarrow as pa

from granflow.errors import ParameterError
from granflow.simulation import Box, ContactLaw, Simulation, maxwell_velocities, random_packing
from granflow.sizes import uniform

SCENES: dict[str, type] = {}


def register(name: str):
    def deco(cls: type) -> type:
        SCENES[name] = cls
        cls.scene_name = name
        return cls

    return deco


def check_keys(section: str, given: Mapping[str, Any], allowed: Mapping[str, Any]) -> None:
    """Refuse unknown keys with a message naming the key and the allowed ones."""
    for k in given:
        if k not in allowed:
            raise ParameterError(
                f"invalid {section}.{k}: unknown key: allowed one of {sorted(allowed)}"
            )


def get_scene(name: str) -> type:
    # the papers' scenes register themselves on import
    if name == "channel":
        import granflow.channel  # noqa: F401
    elif name == "cell":
        import granflow.cell  # noqa: F401
    if name not in SCENES:
        raise ParameterError(f"invalid scene = {name!r}: allowed one of {sorted(SCENES)}")
    return SCENES[name]


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

    @property
    def _sim(self):
        return self.sim._sim

    @classmethod
    def from_spec(cls, params: Mapping[str, Any], seed: int = 0, threads: int | None = None):
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

    def run(self, steps: int, progress: bool | None = None, checkpoint: str | None = None,
            checkpoint_every: int | None = None) -> None:
        done = 0
        while done < steps:
            c = min(self.sample_every - self.sim.step % self.sample_every, steps - done)
            self.sim.run(c, progress=progress, checkpoint=checkpoint)
            done += c
            if self.sim.step % self.sample_every == 0:
                self._sample()
            if checkpoint and checkpoint_every and self.sim.step % checkpoint_every == 0:
                self.save_checkpoint(checkpoint)

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

    def save_checkpoint(self, path: str | os.PathLike) -> None:
        self.sim.save_checkpoint(path)

    def restore(self, path: str | os.PathLike) -> None:
        self.sim = Simulation.from_checkpoint(path, threads=self.threads)
