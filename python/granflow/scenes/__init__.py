"""Scenes: the papers' set-ups with their defaults, built from a few parameters.

- :class:`Channel` (:mod:`granflow.scenes.channel`) — vertical channel of 000 (Debnath,
  Kesava Rao & Kumaran).
- :class:`ShearCell` (:mod:`granflow.scenes.cell`) — stress-controlled triclinic cell of 002
  (Srivastava et al.).
- :class:`RateCell` (:mod:`granflow.scenes.rate_cell`) — the same cell sheared at an imposed
  rate with a normal stress held (the protocol LAMMPS runs).
- :class:`PeriodicGas` (:mod:`granflow.scenes.gas`) — a periodic box of spheres (kernel checks,
  benchmarks, quick tests).

Every scene keeps the :class:`Scene` protocol, so the runner, the CLI and the studies treat them
alike; :data:`SCENES` maps the TOML ``scene = ...`` names to the classes.

One vocabulary: what the scenes share has the same name and meaning in each, and one home,
:class:`SceneParameters` (every scene's base: ``material`` and its flat overrides ``sizes``,
``density``, ``kn``, ``kt_ratio``, ``e_n``, ``xi_t_ratio``, ``mu``, ``form``, ``tc_reading``,
``skin``; ``dt``, ``seed``, ``threads``, keywords only); ``sample_every`` is every scene's
sampling interval in steps.

Construction checks the parameters; :meth:`Scene.prepare` builds the kernel (every scene);
``core`` is the kernel simulation, ``prepared`` whether it exists. ``summary()`` says ``n``
(the particle count), ``state`` (a :class:`granflow.states.FlowState`) and values ``x`` with
``x_se``; every checkpoint carries one header layout (:func:`write_checkpoint`).
"""

from granflow.errors import ParameterError

from ._base import (
    MATERIAL_KEYS,
    SCENES,
    Scene,
    SceneParameters,
    check_keys,
    read_checkpoint_state,
    register,
    run_with_checkpoints,
    write_checkpoint,
)
from .cell import ShearCell
from .cell_energy import EnergyBalance, cell_energy_balance
from .channel import Channel
from .gas import PeriodicGas
from .rate_cell import RateCell


def get_scene(name: str) -> type[Scene]:
    """The scene class registered under ``name`` ('channel', 'cell', 'gas')."""
    if name not in SCENES:
        raise ParameterError(f"invalid scene = {name!r}: allowed one of {sorted(SCENES)}")
    cls: type[Scene] = SCENES[name]
    return cls


__all__ = [
    "MATERIAL_KEYS",
    "SCENES",
    "Channel",
    "EnergyBalance",
    "PeriodicGas",
    "RateCell",
    "Scene",
    "SceneParameters",
    "ShearCell",
    "cell_energy_balance",
    "check_keys",
    "get_scene",
    "read_checkpoint_state",
    "register",
    "run_with_checkpoints",
    "write_checkpoint",
]
