"""Bond-orientational order (granflow.analysis.order): fcc, rotated and polycrystalline fcc,
random dense packings, the bin profile of a crystal slab next to a random region, bonds along
periodic and bounded axes, bad input."""

import numpy as np
import pytest
from granflow import ParameterError
from granflow.analysis import order
from granflow.packing import dense_periodic_packing
from granflow.sizes import mono, uniform
from scipy import special
from scipy.spatial.transform import Rotation

Q6_FCC = 0.57452  # Steinhardt, Nelson & Ronchetti 1983, Table I (12 nearest neighbours)


def fcc(cells: int, nn: float = 1.0) -> tuple[np.ndarray, float]:
    """An fcc crystal of cells^3 cubic unit cells with nearest-neighbour distance nn; returns
    (positions, the cube's side)."""
    a = nn * np.sqrt(2)
    basis = np.array([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]])
    g = np.stack(np.meshgrid(*[np.arange(cells)] * 3, indexing="ij"), -1).reshape(-1, 3)
    return ((g[:, None, :] + basis[None]).reshape(-1, 3)) * a, cells * a


@pytest.fixture(scope="module")
def random_packing():
    """A dense amorphous packing: 1500 spheres, diameters uniform in [0.9, 1.1], phi = 0.62,
    compressed by the project's own tool (frictionless, quenched)."""
    return dense_periodic_packing(uniform(0.9, 1.1), 1500, phi=0.62, seed=1, threads=1)


def test_harmonics_match_scipy():
    rng = np.random.default_rng(3)
    u = rng.normal(size=(200, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    theta, phi = np.arccos(u[:, 2]), np.arctan2(u[:, 1], u[:, 0])
    ours = order._full(np.stack(order._ylm6_nonneg(u), axis=1))
    if hasattr(special, "sph_harm_y"):  # scipy >= 1.15
        ref = np.stack([special.sph_harm_y(6, m, theta, phi) for m in range(-6, 7)], axis=1)
    else:  # scipy < 1.15: azimuth before polar angle
        ref = np.stack([special.sph_harm(m, 6, phi, theta) for m in range(-6, 7)], axis=1)
    np.testing.assert_allclose(ours, ref, atol=1e-13)


def test_fcc_periodic_q6_and_crystal_fraction():
    x, side = fcc(6)
    b = order.find_bonds(x, np.ones(len(x)), (side,) * 3, (True,) * 3)
    assert len(x) == 864
    assert np.all(b.coordination() == 12)
    assert order.global_q6(b) == pytest.approx(Q6_FCC, abs=1e-3)
    assert np.all(order.crystal_like(b))
    # every particle's own q6 is the crystal's
    q = order.q6_vectors(b)
    q6_i = np.sqrt(4 * np.pi / 13 * np.sum(np.abs(q) ** 2, axis=1))
    np.testing.assert_allclose(q6_i, order.global_q6(b), rtol=1e-12)


def _interior(x: np.ndarray, margin: float) -> np.ndarray:
    c = x.mean(axis=0)
    half = (x.max(axis=0) - x.min(axis=0)) / 2
    return np.all(np.abs(x - c) < half - margin, axis=1)


def test_rotated_fcc_same_q6_and_all_crystal_like():
    """A crystal cluster (no periodicity, so any orientation fits): its interior, more than
    1.5 d from the free surfaces, has Q6 = 0.5745 and crystal fraction 1 in any orientation."""
    x, _ = fcc(8)
    inner = _interior(x, 1.5)
    assert inner.sum() >= 400
    rot = Rotation.random(random_state=11)
    results = []
    for pos in (x, rot.apply(x - x.mean(axis=0))):
        box = np.ptp(pos, axis=0) + 5.0
        b = order.find_bonds(pos, np.ones(len(pos)), box, (False,) * 3)
        assert np.all(b.coordination()[inner] == 12)
        results.append((order.global_q6(b, inner), order.crystal_like(b)))
    (q_plain, xtal_plain), (q_rot, xtal_rot) = results
    assert q_rot == pytest.approx(Q6_FCC, abs=1e-3)
    assert q_rot == pytest.approx(q_plain, abs=1e-12)
    assert np.all(xtal_plain[inner]) and np.all(xtal_rot[inner])


def test_polycrystal_lowers_q6_not_crystal_fraction():
    """Two grains of different orientations, apart: each particle stays crystal-like, while
    the Q6 over both grains drops below a single grain's (the reason to offer both)."""
    x, _ = fcc(6)
    x = x - x.mean(axis=0)
    a = Rotation.random(random_state=1).apply(x)
    b_ = Rotation.random(random_state=2).apply(x) + np.array([30.0, 0, 0])
    pos = np.vstack([a, b_])
    inner = np.tile(_interior(x, 1.5), 2)  # in the grains' own frame
    bonds = order.find_bonds(pos, np.ones(len(pos)), np.ptp(pos, axis=0) + 5, (False,) * 3)
    assert np.all(order.crystal_like(bonds)[inner])
    n = len(a)
    assert order.global_q6(bonds, np.flatnonzero(inner[:n])) == pytest.approx(Q6_FCC, abs=1e-3)
    assert order.global_q6(bonds, inner) < 0.9 * Q6_FCC


def test_random_dense_packing_is_disordered(random_packing):
    x, d, box = random_packing
    b = order.find_bonds(x, d, box.length, box.periodic)
    z = b.coordination()
    assert 8 < z.mean() < 11  # the first shell of a dense packing
    assert order.global_q6(b) < 0.05
    assert np.mean(order.crystal_like(b)) < 0.05


def test_monodisperse_random_packing_is_disordered():
    x, d, box = dense_periodic_packing(mono(1.0), 1500, phi=0.62, seed=2, threads=1)
    b = order.find_bonds(x, d, box.length, box.periodic)
    assert order.global_q6(b) < 0.05
    assert np.mean(order.crystal_like(b)) < 0.05


def test_uniform_random_gas_is_disordered():
    rng = np.random.default_rng(5)
    side = 14.0
    x = rng.uniform(0, side, (3000, 3))
    b = order.find_bonds(x, np.ones(len(x)), (side,) * 3, (True,) * 3)
    assert order.global_q6(b) < 0.05
    assert np.mean(order.crystal_like(b)) < 0.05


def test_bin_profile_crystal_slab_next_to_random_region(random_packing):
    """A random region at x in [0, S), a gap of 1, an fcc slab (y, z periods fitted to the
    random box's, so its nearest neighbours are ~1) beyond; x bounded, y and z periodic. Bins
    well inside the crystal read ~1, bins well inside the random region ~0."""
    xr, dr, box = random_packing
    side = np.asarray(box.length)
    assert np.allclose(side, side[0])
    s = side[0]
    cells = int(round(s / np.sqrt(2)))
    xc, _ = fcc(cells, nn=s / (cells * np.sqrt(2)))
    assert 0.9 < s / (cells * np.sqrt(2)) < 1.1
    xr = np.mod(xr, s)
    xc = xc + np.array([s + 1.0, 0.0, 0.0])
    pos = np.vstack([xr, xc])
    diam = np.concatenate([dr, np.ones(len(xc))])
    lx = float(xc[:, 0].max() + 1.0)
    edges = np.linspace(0.0, lx, int(lx // 1.5) + 1)
    prof = order.bin_profile(pos, diam, edges, (lx, s, s), (False, True, True))
    assert prof.columns == ["bin", "x_lo", "x_hi", "x", "particles", "bonds", "Q6",
                            "crystal_fraction", "Z"]
    assert int(prof["particles"].sum()) == len(pos)
    crystal = prof.filter((prof["x_lo"] > s + 2.5) & (prof["x_hi"] < xc[:, 0].max() - 1.5))
    amorph = prof.filter((prof["x_lo"] > 1.5) & (prof["x_hi"] < s - 1.5))
    assert len(crystal) >= 2 and len(amorph) >= 2
    assert crystal["crystal_fraction"].min() > 0.95
    assert crystal["Q6"].min() > 0.5
    assert amorph["crystal_fraction"].max() < 0.1
    assert amorph["Q6"].max() < 0.1
    # the bonds column is the sum of the bin's coordination numbers
    np.testing.assert_allclose(prof["bonds"].to_numpy(),
                               prof["Z"].to_numpy() * prof["particles"].to_numpy())


def test_empty_bin_reads_nan():
    x, side = fcc(4)
    prof = order.bin_profile(x, np.ones(len(x)), [0.0, side, side + 5], (side + 10, side, side),
                             (False, True, True))
    assert prof["particles"].to_list() == [len(x), 0]
    assert np.isnan(prof["Q6"][1]) and np.isnan(prof["crystal_fraction"][1])
    assert prof["crystal_fraction"][0] > 0  # the slab's inner layers


def test_bonds_cross_periodic_axes_only():
    x = np.array([[0.2, 3.0, 3.0], [5.8, 3.0, 3.0]])
    d = np.ones(2)
    box = (6.0, 6.0, 6.0)
    b = order.find_bonds(x, d, box, (True, True, True))
    assert (b.i.tolist(), b.j.tolist()) == ([0], [1])
    np.testing.assert_allclose(b.r[0], [-0.4, 0.0, 0.0], atol=1e-12)
    assert len(order.find_bonds(x, d, box, (False, True, True)).i) == 0
    # the same along y, bounded; and positions beyond the box on a bounded axis
    assert len(order.find_bonds(x[:, [1, 0, 2]], d, box, (True, False, True)).i) == 0
    far = x + np.array([100.0, 0, 0])
    assert len(order.find_bonds(far, d, box, (False, True, True)).i) == 0
    assert len(order.find_bonds(far, d, box, (True, True, True)).i) == 1
    # the cutoff is per pair: (d_i + d_j) / 2
    y = np.array([[1.0, 1, 1], [2.3, 1, 1]])
    assert len(order.find_bonds(y, np.array([1.0, 1.0]), box, (False,) * 3).i) == 0
    assert len(order.find_bonds(y, np.array([1.2, 1.2]), box, (False,) * 3).i) == 1


def test_channel_like_wall_layers_do_not_bond_across():
    """An fcc slab filling a box that is bounded in x: the layers at x = 0 and x = W are
    1 nn apart through the periodic image, but are not bonded."""
    x, side = fcc(4)
    gap = side - x[:, 0].max()  # periodic: the next layer at the image distance
    b_per = order.find_bonds(x, np.ones(len(x)), (side,) * 3, (True,) * 3)
    b_wall = order.find_bonds(x, np.ones(len(x)), (side,) * 3, (False, True, True))
    assert gap == pytest.approx(np.sqrt(2) / 2)
    assert np.all(b_per.coordination() == 12)
    edge = (x[:, 0] == 0) | (x[:, 0] == x[:, 0].max())
    assert np.all(b_wall.coordination()[edge] == 8) and np.all(b_wall.coordination()[~edge] == 12)


@pytest.mark.parametrize("kwargs, name", [
    ({"positions": np.zeros((4, 2))}, "positions"),
    ({"positions": np.full((4, 3), np.nan)}, "positions"),
    ({"diameters": np.ones(3)}, "diameters"),
    ({"diameters": -np.ones(4)}, "diameters"),
    ({"box_lengths": (10.0, 0.0, 10.0)}, "box_lengths"),
    ({"box_lengths": (10.0, 10.0)}, "box_lengths"),
    ({"box_lengths": (10.0, 2.0, 10.0)}, "box_lengths"),  # periodic and < 2 cutoff d_max
    ({"periodic": (True, True)}, "periodic"),
    ({"cutoff": 1.0}, "cutoff"),
    ({"cutoff": 2.5}, "cutoff"),
    ({"edges": [0.0, 5.0, 5.0]}, "edges"),
    ({"edges": [5.0, 0.0]}, "edges"),
    ({"edges": [1.0]}, "edges"),
    ({"axis": 3}, "axis"),
])
def test_bad_input_names_parameter(kwargs, name):
    args = {"positions": np.random.default_rng(0).uniform(0, 10, (4, 3)),
            "diameters": np.ones(4), "edges": [0.0, 5.0, 10.0], "box_lengths": (10.0,) * 3,
            "periodic": (False, True, True), "axis": 0, "cutoff": 1.2}
    args.update(kwargs)
    with pytest.raises(ParameterError, match=name):
        order.bin_profile(**args)


def test_coincident_particles_refused():
    x = np.array([[1.0, 1, 1], [1.0, 1, 1], [3.0, 3, 3]])
    with pytest.raises(ParameterError, match="positions"):
        order.find_bonds(x, np.ones(3), (10.0,) * 3, (True,) * 3)


def test_channel_order_profile():
    """The channel's convenience: its bins, every particle in one, and the poured bed (random
    insertion, then a pour) is far from a crystal. Before preparation: a ConfigurationError."""
    from granflow import ConfigurationError
    from granflow.scenes.channel import Channel

    c = Channel(W=8, H=8, B=4, phi_bar=0.6, kn=1e5, dt=3e-4, seed=4, sample_every=None,
                preparation="pour", threads=1)
    with pytest.raises(ConfigurationError):
        c.order_profile()
    c.prepare(progress=False)
    prof = c.order_profile()
    edges = c.bin_edges()
    np.testing.assert_array_equal(prof["x_lo"].to_numpy(), edges[:-1])
    assert int(prof["particles"].sum()) == len(c.core.diameters())
    assert prof["crystal_fraction"].mean() < 0.2
    coarse = c.order_profile(edges=[0.0, 4.0, 8.0], cutoff=1.3)
    assert coarse["particles"].to_list() == [
        int(np.sum(c.core.positions()[:, 0] < 4.0)), int(np.sum(c.core.positions()[:, 0] >= 4.0))]
