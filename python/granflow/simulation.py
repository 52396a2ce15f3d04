"""The Python face of a simulation: build from particles, a box and a contact law; run; read
state as numpy arrays; take sample tables as pyarrow tables.

Everything heavy happens in the Rust kernel with the GIL released. ``run`` advances in chunks of
about a quarter of a second so that a progress bar can update and Ctrl-C stops cleanly between
steps, leaving the simulation usable.
"""

from __future__ import annotations

import json
import os
import signal
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, ClassVar

import numpy as np
import pyarrow as pa

from granflow import _core
from granflow._progress import Progress
from granflow.errors import ParameterError
from granflow.sizes import SizeDist


@dataclass(frozen=True)
class ContactLaw:
    """Spring–dashpot law with tangential history and Coulomb friction.

    000 App. A (A1–A3), 002 §2.4 (2.17–2.19). ``form`` is 'hooke' (a = 0) or 'hertz' (a = 1/2).
    Damping: give ``e_n`` (restitution, the damping is derived per pair) or ``xi_n`` (rate, as
    LAMMPS ``gamma_n``), not both. A field left at None takes the kernel's default
    (``granflow::contact::LawSpec``, the one home of the defaults): ``kn = 1e6``, ``kt = 2/7 kn``,
    ``e_n = 0.82`` (000's value) when neither e_n nor xi_n is given, ``xi_t_ratio = 1/2``,
    ``mu = 0.5``. The defaults are filled on construction (so the fields and ``as_dict()`` show
    the law the kernel uses); an invalid law keeps its fields as given and raises
    :class:`granflow.ParameterError` from ``as_dict()`` (and so when a simulation is built).
    With ``mu = 0`` the law carries no tangential history at all.
    """

    kn: float | None = None
    e_n: float | None = None
    mu: float | None = None
    kt: float | None = None
    xi_n: float | None = None
    xi_t_ratio: float | None = None
    form: str = "hooke"

    _LAW_FIELDS: ClassVar[tuple[str, ...]] = ("kn", "kt", "e_n", "xi_n", "xi_t_ratio", "mu")

    def _given(self) -> dict[str, float]:
        return {k: getattr(self, k) for k in self._LAW_FIELDS if getattr(self, k) is not None}

    def __post_init__(self) -> None:
        try:
            resolved = _core.resolve_law(self._given())
        except ParameterError:
            return  # kept as given: as_dict() raises the kernel's error
        for k in self._LAW_FIELDS:
            object.__setattr__(self, k, resolved.get(k))

    def as_dict(self) -> dict[str, float]:
        """The law as the kernel resolves it: kn, kt, e_n or xi_n, xi_t_ratio, mu."""
        return dict(_core.resolve_law(self._given()))


@dataclass(frozen=True)
class Box:
    """Orthogonal box [lo, lo + length) with a periodic flag per axis."""

    length: tuple[float, float, float]
    lo: tuple[float, float, float] = (0.0, 0.0, 0.0)
    periodic: tuple[bool, bool, bool] = (True, True, True)

    @property
    def volume(self) -> float:
        return float(np.prod(self.length))


@dataclass(frozen=True)
class Wall:
    """A flat wall: the plane x[axis] = position; particles live on the side ``sign`` (+1/-1)."""

    axis: int
    position: float
    sign: float = 1.0


@dataclass
class Simulation:
    """A DEM simulation in an orthogonal box (see ``granflow.scenes`` for the papers' scenes).

    Parameters are validated by the kernel; errors are :class:`granflow.ParameterError` naming
    the parameter and its allowed range. ``dt`` None is the kernel's default (t_c/50 of the
    stiffest, lightest pair); ``skin`` None the kernel's default neighbour-list skin.
    """

    positions: np.ndarray
    diameters: np.ndarray
    box: Box
    law: ContactLaw = field(default_factory=ContactLaw)
    density: float = 1.0
    velocities: np.ndarray | None = None
    angular_velocities: np.ndarray | None = None
    walls: Sequence[Wall] = ()
    wall_law: ContactLaw | None = None
    gravity: tuple[float, float, float] | None = None
    dt: float | None = None
    skin: float | None = None
    threads: int | None = None
    _sim: _core.Sim = field(init=False, repr=False)

    def __post_init__(self) -> None:
        x = np.ascontiguousarray(self.positions, dtype=np.float64)
        d = np.ascontiguousarray(self.diameters, dtype=np.float64)
        if x.ndim != 2 or x.shape[1] != 3 or x.shape[0] == 0:
            raise ParameterError(
                f"invalid positions: shape {x.shape}: allowed an (N, 3) array with N >= 1"
            )
        if d.shape != (x.shape[0],):
            raise ParameterError(
                f"invalid diameters: shape {d.shape}: allowed one per particle ({x.shape[0]},)"
            )
        if self.law.form not in ("hooke", "hertz"):
            raise ParameterError(f"invalid form = {self.law.form!r}: allowed 'hooke' or 'hertz'")
        self._sim = _core.box_sim(
            x,
            d,
            float(self.density),
            tuple(map(float, self.box.lo)),
            tuple(map(float, self.box.length)),
            tuple(map(bool, self.box.periodic)),
            self.law.form,
            self.law.as_dict(),
            walls=[(w.axis, float(w.position), float(w.sign)) for w in self.walls] or None,
            wall_law=self.wall_law.as_dict() if self.wall_law else None,
            gravity=tuple(map(float, self.gravity)) if self.gravity is not None else None,
            dt=self.dt,
            v=None if self.velocities is None else np.ascontiguousarray(self.velocities, float),
            omega=None
            if self.angular_velocities is None
            else np.ascontiguousarray(self.angular_velocities, float),
            skin=None if self.skin is None else float(self.skin),  # None: the kernel's default
        )
        if self.threads is not None:
            self._sim.threads = int(self.threads)
        self.wall_seconds = 0.0

    # -- running -------------------------------------------------------------------------
    def run(
        self,
        steps: int,
        progress: bool | None = None,
        checkpoint: str | os.PathLike | None = None,
        checkpoint_every: int | None = None,
    ) -> None:
        """Advance ``steps`` steps.

        Ctrl-C (or SIGTERM) stops between steps: the state stays consistent and usable, a
        checkpoint is written if ``checkpoint`` is set, and ``KeyboardInterrupt`` is re-raised.
        With ``checkpoint`` set a checkpoint is also written at the end of the run and, with
        ``checkpoint_every = n``, every n steps (at multiples of n in the step count;
        atomically: a crash loses at most the steps since the last one)."""
        hook: Callable[[], None] | None = None
        if checkpoint is not None:
            path = os.fspath(checkpoint)

            def hook() -> None:
                self.save_checkpoint(path)

        check_checkpoint_args(checkpoint, checkpoint_every)
        run_chunked(self._sim, steps, progress, self, every=checkpoint_every, on_every=hook,
                    on_stop=hook)
        if hook is not None and not (checkpoint_every and self.step % checkpoint_every == 0
                                     and steps > 0):
            hook()

    # -- checkpoints ---------------------------------------------------------------------
    def _rebuild_params(self) -> dict:
        return {
            "class": "Simulation",
            "law": asdict(self.law),
            "wall_law": asdict(self.wall_law) if self.wall_law else None,
            "box": asdict(self.box),
            "walls": [asdict(w) for w in self.walls],
            "gravity": list(self.gravity) if self.gravity is not None else None,
            "density": self.density,
            "dt": self.timestep,
            "skin": self.skin,
        }

    def save_checkpoint(self, path: str | os.PathLike, scene: dict[str, Any] | None = None
                        ) -> None:
        """Write the complete state (particles, contact histories, step, time) atomically;
        ``scene`` is a scene's record in the header (:func:`granflow.scenes.write_checkpoint`),
        kept beside what rebuilds the simulation."""
        head = self._rebuild_params()
        if scene is not None:
            head["scene"] = scene
        self._sim.save_checkpoint(os.fspath(path), json.dumps(head))

    @classmethod
    def from_checkpoint(cls, path: str | os.PathLike, threads: int | None = None,
                        configure: Callable[[_core.Sim], None] | None = None) -> Simulation:
        """Rebuild a simulation from a checkpoint; it continues bitwise identically.
        ``configure(core)`` runs before the state is loaded (a scene adds its samplers there,
        so that their open windows are restored too)."""
        scene, params, x, d = _core.read_checkpoint_header(os.fspath(path))
        p = json.loads(params)
        if p.get("class") != "Simulation":
            raise ParameterError(
                f"invalid checkpoint: written by {p.get('class')!r}: allowed a Simulation "
                "checkpoint (use the scene's from_checkpoint)"
            )
        b = p["box"]
        sim = cls(
            x,
            d,
            Box(length=tuple(b["length"]), lo=tuple(b["lo"]), periodic=tuple(b["periodic"])),
            ContactLaw(**p["law"]),
            density=p["density"],
            walls=[Wall(**w) for w in p["walls"]],
            wall_law=ContactLaw(**p["wall_law"]) if p["wall_law"] else None,
            gravity=tuple(p["gravity"]) if p["gravity"] else None,
            dt=p["dt"],
            skin=p["skin"],
            threads=threads,
        )
        if configure is not None:
            configure(sim._sim)
        sim._sim.load_checkpoint(os.fspath(path))
        return sim

    # -- state ---------------------------------------------------------------------------
    @property
    def core(self) -> _core.Sim:
        """The kernel simulation (:class:`granflow._core.Sim`): every array and diagnostic of
        the state, for analysis code that needs more than this class shows."""
        return self._sim

    @property
    def n(self) -> int:
        return self._sim.n

    @property
    def step(self) -> int:
        return self._sim.step

    @property
    def time(self) -> float:
        return self._sim.time

    @property
    def timestep(self) -> float:
        return self._sim.dt

    @property
    def contact_time(self) -> float:
        """Contact duration t_c of the stiffest, lightest pair (linear law)."""
        return self._sim.contact_time

    def set_threads(self, n: int) -> None:
        self._sim.threads = int(n)

    def get_positions(self) -> np.ndarray:
        return self._sim.positions()

    def get_velocities(self) -> np.ndarray:
        return self._sim.velocities()

    def get_angular_velocities(self) -> np.ndarray:
        return self._sim.angular_velocities()

    def get_forces(self) -> np.ndarray:
        return self._sim.forces()

    def get_torques(self) -> np.ndarray:
        return self._sim.torques()

    def set_velocities(self, v: np.ndarray) -> None:
        self._sim.set_velocities(np.ascontiguousarray(v, dtype=np.float64))

    def set_angular_velocities(self, w: np.ndarray) -> None:
        self._sim.set_angular_velocities(np.ascontiguousarray(w, dtype=np.float64))

    def energies(self) -> dict[str, float]:
        et, er, ee = self._sim.energies()
        return {"kinetic_translational": et, "kinetic_rotational": er, "elastic": ee}

    def components(self) -> list[str]:
        """The parts this simulation is composed of (what its step executes)."""
        return self._sim.components()

    def memory(self) -> dict[str, int]:
        """Bytes held by each part."""
        return dict(self._sim.memory())

    def diagnostics(self) -> dict:
        """The last step's ``max_overlap`` (overlap / pair mean diameter), ``contacts``,
        ``wall_force`` (per wall, on the particles), ``virial_colmajor`` (sum r_ij (x) f_ij),
        and the neighbour-list ``list_builds`` and ``list_prunes`` since the start."""
        return self._sim.diagnostics()

    def parameters(self) -> dict:
        return {
            "law": asdict(self.law),
            "wall_law": asdict(self.wall_law) if self.wall_law else None,
            "box": asdict(self.box),
            "density": self.density,
            "gravity": self.gravity,
            "dt": self.timestep,
            "skin": self.skin,
            "n": self.n,
        }


class _Terminated(BaseException):
    """Raised inside a run when SIGTERM arrives, so the run stops between steps."""


def check_checkpoint_args(checkpoint: str | os.PathLike | None,
                          checkpoint_every: int | None) -> None:
    """The checks of a run's ``checkpoint`` / ``checkpoint_every`` arguments (every ``run`` of
    the package takes them): ``checkpoint_every`` >= 1, and only with a checkpoint path."""
    if checkpoint_every is not None and int(checkpoint_every) < 1:
        raise ParameterError(f"invalid checkpoint_every = {checkpoint_every}: allowed >= 1")
    if checkpoint is None and checkpoint_every is not None:
        raise ParameterError(
            f"invalid checkpoint_every = {checkpoint_every} without checkpoint: allowed "
            "with a checkpoint path")


def run_chunked(
    sim: _core.Sim,
    steps: int,
    progress: bool | None,
    owner: Any = None,
    every: int | None = None,
    on_every: Callable[[], None] | None = None,
    on_stop: Callable[[], None] | None = None,
    after_chunk: Callable[[], None] | None = None,
) -> None:
    """Run ``steps`` steps in chunks of ~0.25 s (progress bar, Ctrl-C between chunks).

    ``on_every`` runs whenever the step count crosses a multiple of ``every``; ``on_stop`` runs
    when the run is interrupted (Ctrl-C or SIGTERM) before the interrupt propagates;
    ``after_chunk`` after every chunk (e.g. to drain sample tables)."""
    steps = int(steps)
    if steps < 0:
        raise ParameterError(f"invalid steps = {steps}: allowed >= 0")
    if every is not None and every <= 0:
        raise ParameterError(f"invalid checkpoint_every = {every}: allowed >= 1")
    if steps == 0:
        sim.compute_forces()
        return
    bar = Progress(steps, sim.n, sim.dt, enabled=progress)
    done = 0
    chunk = max(1, min(steps, 10))
    t_start = time.perf_counter()
    old_term = None
    if threading.current_thread() is threading.main_thread():

        def _term(signum, frame):  # noqa: ARG001
            raise _Terminated()

        old_term = signal.signal(signal.SIGTERM, _term)
    try:
        while done < steps:
            c = min(chunk, steps - done)
            if every:
                c = min(c, every - sim.step % every)
            t0 = time.perf_counter()
            sim.run(c)
            el = time.perf_counter() - t0
            done += c
            if after_chunk is not None:
                after_chunk()
            if every and on_every is not None and sim.step % every == 0:
                on_every()
            bar.update(done, sim.time)
            if el > 0:
                chunk = int(min(max(1, c * 0.25 / el), 2 * c + 1, 1_000_000))
    except (KeyboardInterrupt, _Terminated) as exc:
        if after_chunk is not None:
            after_chunk()
        if on_stop is not None:
            on_stop()
        if isinstance(exc, _Terminated):
            raise SystemExit(128 + signal.SIGTERM) from None
        raise
    finally:
        if old_term is not None:
            signal.signal(signal.SIGTERM, old_term)
        bar.close()
        if owner is not None:
            owner.wall_seconds = getattr(owner, "wall_seconds", 0.0) + (
                time.perf_counter() - t_start
            )


def to_table(batch: _core.ArrowBatch) -> pa.Table:
    """Import a kernel batch through the Arrow C data interface (no copy of the buffers)."""
    rb = pa.record_batch(batch)
    return pa.Table.from_batches([rb])


def random_packing(
    sizes: SizeDist,
    box: Box,
    phi: float,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """Non-overlapping random spheres filling ``box`` to volume fraction ``phi`` (random
    sequential addition; jams near phi ~ 0.38). Returns (positions, diameters)."""
    if not (0 < phi < 0.45):
        raise ParameterError(
            f"invalid phi = {phi}: allowed 0 < phi < 0.45 for random insertion "
            "(denser states: compress, or use a scene's preparation)"
        )
    d = sizes.diameters_for_volume(phi * box.volume, seed)
    lo = np.asarray(box.lo, float)
    hi = lo + np.asarray(box.length, float)
    x = _core.insert_spheres(d, tuple(lo), tuple(hi), tuple(box.periodic), int(seed))
    return np.asarray(x), d


def maxwell_velocities(n: int, scale: float, seed: int = 0) -> np.ndarray:
    """Gaussian velocities with zero total momentum (equal-mass approximation)."""
    rng = np.random.default_rng(seed)
    v = rng.normal(0.0, scale, size=(n, 3))
    return v - v.mean(axis=0)


__all__ = [
    "Box",
    "ContactLaw",
    "Simulation",
    "Wall",
    "maxwell_velocities",
    "random_packing",
    "check_checkpoint_args",
    "run_chunked",
    "to_table",
]

