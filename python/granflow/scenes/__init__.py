"""Scenes: the papers' set-ups with their defaults, built from a few parameters.

- :class:`Channel` (:mod:`granflow.scenes.channel`) — vertical channel of 000 (Debnath,
  Kesava Rao & Kumaran).
- :class:`ShearCell` (:mod:`granflow.scenes.cell`) — stress-controlled triclinic cell of 002
  (Srivastava et al.).
- :class:`PeriodicGas` (:mod:`granflow.scenes.gas`) — a periodic box of spheres (kernel checks,
  benchmarks, quick tests).

Every scene keeps the :class:`Scene` protocol, so the runner, the CLI and the studies treat them
alike; :data:`SCENES` maps the TOML ``scene = ...`` names to the classes.

One vocabulary
--------------
What the scenes share has the same name and meaning in each:

* ``material``: a :class:`granflow.material.Material` (or the name of one, "000" or "002", in a
  TOML spec); None is the scene's own (the channel :data:`~granflow.material.MATERIAL_000`,
  the cell :data:`~granflow.material.MATERIAL_002`, the gas :data:`gas.GAS_MATERIAL`).
* flat overrides of one field of that material, None leaving it: ``sizes`` (a ``{d:
  fraction}`` mapping, ``[lo, hi]`` or a :class:`~granflow.sizes.SizeDist`), ``density``,
  ``kn``, ``kt_ratio`` (k_t/k_n), ``e_n``, ``xi_t_ratio``, ``mu`` (the friction coefficient),
  ``form``, ``tc_reading``, ``skin``. Scenes take both, so a TOML spec or a sweep grid can vary
  one field (``mu = [0.1, 0.3]``) and code can pass a whole material.
* ``dt``: the time step, absolute; None is the material's rule (:meth:`Material.dt`).
* ``sample_every`` (steps between samples), ``seed``, ``threads``.

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
    "Scene",
    "ShearCell",
    "cell_energy_balance",
    "check_keys",
    "get_scene",
    "read_checkpoint_state",
    "register",
    "run_with_checkpoints",
    "write_checkpoint",
]
