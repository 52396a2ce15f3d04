import granflow as gf
import numpy as np
import pytest


@pytest.fixture
def gas():
    """A small periodic frictional gas (phi = 0.3) with random velocities."""
    box = gf.Box(length=(8.0, 8.0, 8.0))
    x, d = gf.random_packing(gf.sizes.uniform(0.9, 1.1), box, 0.3, seed=3)
    v = gf.maxwell_velocities(len(d), 1.0, seed=3)
    return box, x, d, v


def make(box, x, d, v, **kw):
    law = kw.pop("law", gf.ContactLaw(kn=1e5, e_n=0.8, mu=0.5))
    return gf.Simulation(x, d, box, law, velocities=v, **kw)


@pytest.fixture
def make_sim():
    return make


def pytest_configure(config):
    np.seterr(all="raise")
