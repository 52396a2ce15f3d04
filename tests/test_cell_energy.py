"""Energy balance of the stress-controlled cell (002, src/prcell.rs) and the cell's
InstabilityError context (issue #5)."""

from __future__ import annotations

import numpy as np
import pytest
from granflow.errors import DilationError
from granflow.scenes import ShearCell, cell_energy_balance


@pytest.fixture(scope="module")
def sheared() -> ShearCell:
    # N = 200 from phi0 = 0.3 at p_ext = 1e-3, tau/p = 0.5: steady inertial shear after
    # ~400 t_c (20000 steps at dt = 0.02 t_c), ~1 s
    cell = ShearCell(N=200, phi0=0.3, p_ext=1e-3, tau_ratio=0.5, seed=0, threads=1)
    cell.run(20_000)
    return cell


def test_balance_closes_in_steady_shear(sheared):
    eb = cell_energy_balance(sheared, 5000, every=1)  # 100 t_c
    # the imposed shear stress does the work, the contacts dissipate it
    assert eb.work_tau > 0 and eb.dissipation_measured > 0
    # dE is small against the work in steady state; what is not stored is dissipated
    assert abs(eb.delta_energy) < 0.1 * eb.work
    # closure: ~4e-4 of D at dt = 0.02 t_c (first order in dt); tolerance 2e-3
    assert abs(eb.rel_residual) < 2e-3, eb.as_dict()
    # the inferred dissipation W - dE agrees with the measured one to the same accuracy
    assert eb.dissipation == pytest.approx(eb.dissipation_measured, rel=2e-3)
    # the shear work is not optional: without it the balance is off by ~100 %
    assert abs(eb.residual - eb.work_tau) > 0.5 * eb.dissipation_measured


def test_sparse_sampling_degrades_the_trapezoid(sheared):
    # the contact power oscillates at the contact frequency: sampling once per t_c (50 steps)
    # leaves a trapezoid error of order 1e-2 of D, every step ~4e-4
    fine = cell_energy_balance(sheared, 2500, every=1)
    coarse = cell_energy_balance(sheared, 2500, every=50)
    assert abs(fine.rel_residual) < 2e-3
    assert abs(coarse.rel_residual) > abs(fine.rel_residual)
    assert np.isfinite(coarse.rel_residual)


def test_without_damping_and_friction_energy_is_conserved():
    # e_n = 1 and mu = 0: the contacts store and return energy and dissipate none, so the
    # contact power integrates to minus the elastic energy's change and the imposed stress's
    # work goes into E (kinetic + elastic + cell) alone; the ledger's two estimates of the
    # dissipation (W - dE, and -contact work - dU) must both vanish against the energy the
    # contacts move back and forth
    cell = ShearCell(N=200, phi0=0.3, p_ext=1e-3, tau_ratio=0.3, seed=0, threads=1, e_n=1.0,
                     mu=0.0, start="dilute")
    cell.run(2000)
    eb = cell_energy_balance(cell, 2000, every=1)
    assert eb.contact_work_gross > 0 and abs(eb.work) > 0
    assert abs(eb.dissipation_measured) < 2e-3 * eb.contact_work_gross, eb.as_dict()
    assert abs(eb.dissipation - eb.skew_work + eb.mtk_work) < 2e-3 * max(
        eb.contact_work_gross, abs(eb.work)), eb.as_dict()


def test_above_yield_stops_with_the_cause():
    # tau/p = 1.2 from a dilute start: the cell shears and dilates without bound; the kernel
    # stops it (overlap guard at p a/kn = 1e-3), and the message names the runaway dilation;
    # the error is a DilationError (an InstabilityError), whichever guard fired
    cell = ShearCell(N=200, phi0=0.3, p_ext=1e-3, tau_ratio=1.2, seed=0, threads=1)
    with pytest.raises(DilationError, match="runaway dilation under shear") as ei:
        cell.run(20_000)
    assert "tau_ext/p_ext = 1.2" in str(ei.value)
