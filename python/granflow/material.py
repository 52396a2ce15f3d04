"""The material of a simulation: sizes, density, the contact law, the neighbour-list skin, the
contact time and the time-step rule, in one place.

Every scene takes a :class:`Material` (``material=``); the two papers' materials are
:data:`MATERIAL_000` (the channel of 000) and :data:`MATERIAL_002` (the cell of 002). A law
field left at None is the kernel's default (``granflow::contact::LawSpec``, the one home of the
defaults, read through :func:`granflow._core.resolve_law`); a skin left at None is the kernel's
default skin. Variations: ``MATERIAL_002.with_(mu=0.1)``.

The contact time (:meth:`Material.contact_time`) has two pairs:

* ``pair="lightest"``: the stiffest, lightest pair of the particles (the kernel's
  ``Sim.contact_time`` and its default dt = t_c/50, and the bound dt <= t_c/10);
* ``pair="mean"``: two particles of the mean mass, as 002 (§2.5) defines its time unit, read
  as ``reading`` says ("collision": the force law's binary collision, pi (kn/m_e -
  gamma_n^2/4)^(-1/2); "printed": 002's formula as printed, with 2 kn/m_e; docs/cell.md).

The time-step rule (:class:`DtRule`): 000 gives dt = 1.2e-4 sqrt(d/g) at kn = 1e6 m g/d, scaled
as t_c ~ kn^(-1/2) (``DtRule.kn_scaled(1.2e-4, 1e6)``); 002 gives dt = 0.02 t_c, t_c of the mean
pair (``DtRule.tc_fraction(0.02)``); None is the kernel's default (t_c/50, lightest pair).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from granflow import _core
from granflow.errors import ParameterError
from granflow.simulation import ContactLaw
from granflow.sizes import CHANNEL_MIX, SizeDist, as_size_dist, uniform

#: How 002's contact time is read (``tc_reading``, docs/cell.md).
TC_READINGS = ("collision", "printed")
#: The pairs :meth:`Material.contact_time` knows.
PAIRS = ("mean", "lightest")
#: The forms of the normal force.
FORMS = ("hooke", "hertz")


@dataclass(frozen=True)
class DtRule:
    """How a material's time step follows from its law: ``kind`` "kn_scaled" (dt = ``value``
    sqrt(``kn_ref``/kn)) or "tc_fraction" (dt = ``value`` t_c, t_c of the mean pair)."""

    kind: str
    value: float
    kn_ref: float | None = None

    def __post_init__(self) -> None:
        if self.kind not in ("kn_scaled", "tc_fraction"):
            raise ParameterError(f"invalid dt_rule kind = {self.kind!r}: allowed 'kn_scaled' "
                                 "or 'tc_fraction'")
        if self.kind == "tc_fraction" and not (0 < self.value <= 0.1):
            raise ParameterError(f"invalid dt_rule = {self.value!r} t_c: allowed 0 < dt/t_c "
                                 "<= 0.1")
        if self.kind == "kn_scaled" and not (
                self.value > 0 and self.kn_ref is not None and self.kn_ref > 0):
            raise ParameterError(f"invalid dt_rule = ({self.value!r}, kn_ref = "
                                 f"{self.kn_ref!r}): allowed dt > 0 at kn_ref > 0")

    @classmethod
    def kn_scaled(cls, dt: float, kn_ref: float) -> DtRule:
        """dt at ``kn_ref``, scaled as the contact time, kn^(-1/2) (000's rule)."""
        return cls("kn_scaled", float(dt), float(kn_ref))

    @classmethod
    def tc_fraction(cls, frac: float) -> DtRule:
        """dt = ``frac`` t_c, t_c of the mean pair (002's rule, 0.02)."""
        return cls("tc_fraction", float(frac))

    def to_spec(self) -> dict[str, Any]:
        """The rule as a JSON-able mapping."""
        return dataclasses.asdict(self)


def kernel_default_skin() -> float:
    """The kernel's default neighbour-list skin (``granflow::scene::DEFAULT_SKIN``): the value
    a simulation gets when no skin is passed."""
    return float(_core.DEFAULT_SKIN)


def law_contact_time(law: ContactLaw, diameters: np.ndarray, density: float = 1.0) -> float:
    """The contact time of the lightest pair of ``diameters`` under ``law`` (any law, a rate
    damping ``xi_n`` included), as the kernel computes it (``Sim.contact_time``: linear law,
    reduced mass m_min/2): what :meth:`Material.contact_time` gives for ``pair="lightest"``."""
    d = np.asarray(diameters, dtype=float)
    _need(d.size > 0, "diameters", d.tolist(), "at least one particle")
    m_min = density * np.pi / 6.0 * float(np.min(d)) ** 3
    return float(_core.contact_time(law.as_dict(), 0.5 * m_min))


def _need(cond: bool, name: str, value: Any, allowed: str) -> None:
    if not cond:
        raise ParameterError(f"invalid {name} = {value!r}: allowed {allowed}")


def _real(v: Any) -> bool:
    return (isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
            and bool(np.isfinite(v)))


@dataclass(frozen=True)
class Material:
    """Particles and their contact law (000 App. A, 002 §2.4–2.5).

    A law field left at None is the kernel's default (kn = 1e6, k_t = 2/7 kn, e_n = 0.82,
    xi_t_ratio = 1/2, mu = 0.5).

    Args:
        sizes: The size distribution (:mod:`granflow.sizes`; a scene's ``sizes`` also takes a
            ``{d: fraction}`` mapping or ``[lo, hi]``).
        density: Particle density (1: masses in units of rho_p d^3).
        kn: Normal stiffness.
        kt_ratio: Tangential over normal stiffness, k_t/k_n.
        e_n: Normal restitution (the damping derived per pair). Not with ``gamma_n_tc``.
        gamma_n_tc: 002's damping instead of a restitution: gamma_n = ``gamma_n_tc`` / t_c
            (rate form, t_c of the mean pair by ``tc_reading``; 002: 0.5).
        xi_t_ratio: Tangential over normal damping.
        mu: Coulomb friction coefficient.
        form: The normal force, "hooke" (linear) or "hertz".
        tc_reading: How the mean pair's contact time reads 002's formula: "collision" or
            "printed" (:meth:`contact_time`).
        skin: Neighbour-list skin (None: the kernel's default).
        dt_rule: The time step when a scene is given none (:class:`DtRule`; None: the
            kernel's default, t_c/50 of the lightest pair).
    """

    sizes: SizeDist
    density: float = 1.0
    kn: float | None = None
    kt_ratio: float | None = None
    e_n: float | None = None
    gamma_n_tc: float | None = None
    xi_t_ratio: float | None = None
    mu: float | None = None
    form: str = "hooke"
    tc_reading: str = "collision"
    skin: float | None = None
    dt_rule: DtRule | None = None

    def __post_init__(self) -> None:
        _need(isinstance(self.sizes, SizeDist), "sizes", self.sizes, "a SizeDist")
        _need(_real(self.density) and self.density > 0, "density", self.density,
              "a finite number > 0")
        _need(self.kn is None or (_real(self.kn) and self.kn > 0), "kn", self.kn,
              "a finite number > 0, or None for the kernel's default")
        _need(self.kt_ratio is None or (_real(self.kt_ratio) and 0 < self.kt_ratio <= 10),
              "kt_ratio", self.kt_ratio, "0 < kt/kn <= 10, or None for the kernel's default")
        _need(self.e_n is None or (_real(self.e_n) and 0 < self.e_n <= 1), "e_n", self.e_n,
              "0 < e_n <= 1, or None for the kernel's default (or gamma_n_tc's damping)")
        _need(self.gamma_n_tc is None or (_real(self.gamma_n_tc) and self.gamma_n_tc > 0),
              "gamma_n_tc", self.gamma_n_tc, "a finite number > 0, or None")
        _need(self.e_n is None or self.gamma_n_tc is None, "e_n", self.e_n,
              f"None with gamma_n_tc = {self.gamma_n_tc} (one damping: give e_n or gamma_n_tc)")
        _need(self.mu is None or (_real(self.mu) and self.mu >= 0), "mu", self.mu,
              "a finite number >= 0, or None for the kernel's default")
        _need(self.form in FORMS, "form", self.form, "'hooke' or 'hertz'")
        _need(self.tc_reading in TC_READINGS, "tc_reading", self.tc_reading,
              f"one of {TC_READINGS}")
        _need(self.skin is None or (_real(self.skin) and self.skin > 0), "skin", self.skin,
              "a finite number > 0, or None for the kernel's default")
        _need(self.dt_rule is None or isinstance(self.dt_rule, DtRule), "dt_rule", self.dt_rule,
              "a DtRule, or None for the kernel's default")
        self._kernel_law()  # kt, xi_t_ratio: the kernel's own checks, naming the field

    # -- variations -----------------------------------------------------------------------
    def with_(self, **changes: Any) -> Material:
        """A copy with ``changes`` (any field; ``sizes`` as :func:`granflow.sizes.as_size_dist`
        reads it), validated. Giving ``e_n`` drops 002's ``gamma_n_tc`` damping unless
        ``gamma_n_tc`` is given too (a restitution replaces the rate damping)."""
        names = {f.name for f in dataclasses.fields(self)}
        for k in changes:
            if k not in names:
                raise ParameterError(f"invalid {k}: not a material field: allowed one of "
                                     f"{sorted(names)}")
        if "sizes" in changes:
            changes["sizes"] = as_size_dist(changes["sizes"])
        if changes.get("e_n") is not None and "gamma_n_tc" not in changes:
            changes["gamma_n_tc"] = None
        return dataclasses.replace(self, **changes)

    # -- the law ---------------------------------------------------------------------------
    def _kernel_law(self) -> dict[str, float]:
        """The law's fields the kernel resolves (kn, kt, xi_t_ratio, mu, e_n unless 002's
        damping): the kernel's defaults for those left at None."""
        kn = float(_core.resolve_law({} if self.kn is None else {"kn": self.kn})["kn"])
        given = {"kn": self.kn, "kt": None if self.kt_ratio is None else self.kt_ratio * kn,
                 "e_n": self.e_n, "xi_t_ratio": self.xi_t_ratio, "mu": self.mu}
        if self.gamma_n_tc is not None:
            given["xi_n"] = 1.0  # a placeholder rate: the real one needs the particles' t_c
        return dict(_core.resolve_law({k: v for k, v in given.items() if v is not None}))

    @property
    def kn_value(self) -> float:
        """The normal stiffness in effect (``kn``, or the kernel's default)."""
        return float(self._kernel_law()["kn"])

    @property
    def mu_value(self) -> float:
        """The friction coefficient in effect (``mu``, or the kernel's default)."""
        return float(self._kernel_law()["mu"])

    def law(self, diameters: np.ndarray | None = None) -> ContactLaw:
        """The contact law as a :class:`~granflow.simulation.ContactLaw` (with 002's damping
        gamma_n = gamma_n_tc / t_c, t_c of the mean pair of ``diameters``, or of the size
        distribution's mean particle when None)."""
        kn = self.kn_value
        damping: dict[str, float | None] = {"e_n": self.e_n}
        if self.gamma_n_tc is not None:
            damping = {"xi_n": self.gamma_n_tc / self.contact_time("mean", diameters)}
        return ContactLaw(kn=self.kn, kt=None if self.kt_ratio is None else self.kt_ratio * kn,
                          xi_t_ratio=self.xi_t_ratio, mu=self.mu, form=self.form, **damping)

    # -- contact time and time step --------------------------------------------------------
    def mean_mass(self, diameters: np.ndarray | None = None) -> float:
        """The mean particle mass of ``diameters`` (of the size distribution when None)."""
        if diameters is None:
            return float(self.density * self.sizes.mean_volume)
        d = np.asarray(diameters, dtype=float)
        return float(np.mean(self.density * np.pi * d**3 / 6))

    def contact_time(self, pair: str = "mean", diameters: np.ndarray | None = None,
                     reading: str | None = None) -> float:
        """The contact time t_c.

        ``pair="lightest"``: the duration of a contact of the stiffest, lightest pair of
        ``diameters`` (the smallest size of the distribution when None), linear law, as the
        kernel computes it (``Sim.contact_time``).

        ``pair="mean"``: 002's t_c for two particles of the mean mass of ``diameters`` (the
        distribution's mean particle when None), reduced mass m_e = m/2. The force law (2.17a)
        makes a binary collision last pi (kn/m_e - gamma_n^2/4)^(-1/2) (``reading="collision"``,
        the default ``tc_reading``); 002 prints pi (2 kn/m_e - gamma_n^2/4)^(-1/2)
        (``"printed"``: t_c 1/sqrt(2) of the collision's). Solved together with the damping:
        t_c^2 (c kn/m_e) = pi^2 + (ln e_n)^2, c = 2 (printed) or 1 (collision), where ln e_n =
        -gamma_n_tc/2 for 002's gamma_n = gamma_n_tc/t_c, or the restitution's (the kernel's
        default when e_n is None).
        """
        _need(pair in PAIRS, "pair", pair, f"one of {PAIRS}")
        reading = self.tc_reading if reading is None else reading
        _need(reading in TC_READINGS, "tc_reading", reading, f"one of {TC_READINGS}")
        if pair == "lightest":
            d = np.array([self.sizes.min]) if diameters is None else diameters
            return law_contact_time(self.law(diameters), d, self.density)
        kn = self.kn_value
        m_e = self.mean_mass(diameters) / 2
        if self.gamma_n_tc is not None and reading == "printed":
            # 002's formula as printed, by fixed point (t_c and gamma_n = gamma_n_tc / t_c)
            tc = np.pi / np.sqrt(2 * kn / m_e)
            for _ in range(100):
                g = self.gamma_n_tc / tc
                tc = np.pi / np.sqrt(2 * kn / m_e - g * g / 4)
            return float(tc)
        c = 2.0 if reading == "printed" else 1.0
        if self.gamma_n_tc is not None:
            log_e = -self.gamma_n_tc / 2
        else:
            log_e = float(np.log(self._kernel_law()["e_n"]))
        return float(np.sqrt(np.pi**2 + log_e**2) / np.sqrt(c * kn / m_e))

    def dt(self, diameters: np.ndarray | None = None) -> float | None:
        """The time step of the rule ``dt_rule`` (None: the kernel's default, t_c/50 of the
        lightest pair); a "tc_fraction" rule takes t_c of the mean pair of ``diameters``."""
        rule = self.dt_rule
        if rule is None:
            return None
        if rule.kind == "kn_scaled":
            assert rule.kn_ref is not None
            return float(rule.value * np.sqrt(rule.kn_ref / self.kn_value))
        return float(rule.value * self.contact_time("mean", diameters))

    # -- records ---------------------------------------------------------------------------
    def parameters(self) -> dict[str, Any]:
        """Every field as JSON-able values (``sizes`` in its TOML form, ``dt_rule`` a
        mapping)."""
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        out["sizes"] = self.sizes.to_spec()
        out["dt_rule"] = None if self.dt_rule is None else self.dt_rule.to_spec()
        return out


#: 000's material (the channel): the mix 30 % 0.9 d, 40 % 1.0 d, 30 % 1.1 d, the kernel's law
#: defaults (kn = 1e6 m g/d, k_t = 2/7 kn, e_n = 0.82, xi_t = xi_n/2, mu = 0.5), dt = 1.2e-4
#: sqrt(d/g) at kn = 1e6, scaled as t_c.
MATERIAL_000 = Material(sizes=CHANNEL_MIX,
                        dt_rule=DtRule.kn_scaled(1.2e-4, 1e6))

#: 002's material (the cell): diameters uniform in [0.9, 1.1] a, kn = kt = 1 (the stress unit),
#: gamma_n = 0.5/t_c (t_c by the "collision" reading), gamma_t = gamma_n/2, mu = 0.3,
#: dt = 0.02 t_c.
MATERIAL_002 = Material(sizes=uniform(0.9, 1.1), kn=1.0, kt_ratio=1.0, gamma_n_tc=0.5, mu=0.3,
                        dt_rule=DtRule.tc_fraction(0.02))

#: The named materials, by the name a TOML spec's ``material = "..."`` gives.
MATERIALS: dict[str, Material] = {"000": MATERIAL_000, "002": MATERIAL_002}

__all__ = [
    "DtRule",
    "MATERIAL_000",
    "MATERIAL_002",
    "MATERIALS",
    "Material",
    "PAIRS",
    "TC_READINGS",
    "kernel_default_skin",
    "law_contact_time",
]
