"""Higher orders with azimuthal harmonics (clsky/azimuth.py), NumPy: checks that share no formula with it.

1. M = 0 is the physical mode of clsky.orders.compute_orders (backend 'numpy') to rounding.
2. The cosine series through the azimuth nodes interpolates them (DCT-I round trip).
3. The local azimuth along a ray against explicit 3D vectors.
4. The harmonic gather and first gather against a literal 2D (Theta, Phi) trapezoid of the
   azimuth-dependent field, projected on cos(m phi_V) over the same Phi grid (a discrete circular
   convolution: exact to rounding).
5. Orders are finite and non-negative; parameters are validated.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from clsky import TableSettings, azimuth, reference
from clsky.errors import ParameterError
from clsky.mapping import grid_coordinates
from clsky.multiple import _gather_parts, _phase, gather_quadrature
from clsky.orders import compute_orders
from clsky.twilight import black_ground_without_ozone

from conftest import TOLERANCES, max_error_report, require_dtype

TINY = TableSettings(size=(5, 12, 6), mode="physical", orders=4, gather_theta_steps=24, gather_phi_steps=16,
                     sun_cos_range=(-0.3, 0.4))


@pytest.fixture(scope="module")
def atmosphere():
    return black_ground_without_ozone()


@pytest.mark.parametrize("albedo", [0.0, 0.3])
def test_zero_harmonics_is_the_physical_mode(atmosphere, albedo):
    """M = 0: same single scattering, orders, gathered sum and ground irradiance as compute_orders, with
    a black and with a reflecting ground (rounding only: the first gather's products are associated
    differently, 1e-15 relative)."""
    atmosphere = atmosphere.replace(ground_albedo=albedo)
    expected = compute_orders(atmosphere, TINY, backend="numpy")
    result = azimuth.compute_orders(atmosphere, TINY)
    if albedo:
        assert_allclose(result.ground_irradiance, expected.ground_irradiance, rtol=1e-12, atol=0)
    assert_allclose(result.single, expected.orders[0], rtol=0, atol=0)
    for k, order in enumerate(result.orders):
        assert_allclose(order[0], expected.orders[k + 1], rtol=1e-12, atol=1e-14 * expected.orders[k + 1].max())
    assert_allclose(result.gathered[0], expected.gathered, rtol=1e-12, atol=1e-14 * expected.gathered.max())


@pytest.mark.parametrize("harmonics", [1, 2, 4, 7])
def test_series_interpolates_the_nodes(harmonics):
    rng = np.random.default_rng(harmonics)
    values = rng.random((harmonics + 1, 3))
    coefficients = azimuth.harmonic_transform(harmonics) @ values
    nodes = azimuth.azimuth_nodes(harmonics)
    series = np.cos(np.outer(nodes, np.arange(harmonics + 1))) @ coefficients
    assert_allclose(series, values, rtol=1e-13, atol=1e-14)     # rounding of an (M + 1)-term sum


@pytest.mark.parametrize("harmonics", [1, 2, 4, 7])
def test_azimuth_average_is_the_series_mean(harmonics):
    """azimuth_average: the mean over phi of the cosine series through the nodes, its m = 0 coefficient.
    Against a field a + sum_m b_m cos(m phi) sampled at the nodes (mean a, to the rounding of an
    (M + 1)-term sum), and against the first row of every harmonic: the same bits for M <= 2 (the default
    animation's tables, whose bits the faster average kept), and above within the rounding of two sums of
    M + 1 terms in other orders, (M + 1) eps of the largest node value each."""
    rng = np.random.default_rng(harmonics)
    a, b = rng.random((5, 3)), rng.random((harmonics, 5, 3))
    phi = azimuth.azimuth_nodes(harmonics)
    nodes = a + np.einsum("nm,m...->n...", np.cos(np.outer(phi, np.arange(1, harmonics + 1))), b)
    average = azimuth.azimuth_average(nodes)
    assert_allclose(average, a, rtol=1e-13, atol=1e-14)
    every = azimuth._to_harmonics(nodes)[0]
    if harmonics <= 2:
        assert np.array_equal(average, every)
    else:
        assert_allclose(average, every, rtol=0, atol=2 * (harmonics + 1) * np.finfo(float).eps * np.abs(nodes).max())


def test_chebyshev_is_cosine():
    phi = np.linspace(0.0, math.pi, 17)
    assert_allclose(azimuth.chebyshev(np.cos(phi), 6), np.cos(np.outer(phi, np.arange(7))), atol=1e-14)


def test_local_azimuth_against_vectors():
    """cos of the angle between the horizontal projections of V and Sun at points along a ray, from
    explicit vectors (observer at altitude 2 km, view 10 deg up at azimuth 130 deg, sun 3 deg below)."""
    rp = 6371e3
    r0 = rp + 2e3
    view = np.array([math.cos(math.radians(10)) * math.cos(math.radians(130)),
                     math.cos(math.radians(10)) * math.sin(math.radians(130)), math.sin(math.radians(10))])
    sun = np.array([math.cos(math.radians(-3)), 0.0, math.sin(math.radians(-3))])
    for s in (0.0, 5e3, 80e3, 400e3):
        p = np.array([0.0, 0.0, r0]) + s * view
        zenith = p / np.linalg.norm(p)
        hv = view - view @ zenith * zenith
        hs = sun - sun @ zenith * zenith
        expected = hv @ hs / (np.linalg.norm(hv) * np.linalg.norm(hs))
        got = azimuth.local_cos_azimuth(r0, s, view[2], sun[2], view @ sun)
        assert abs(got - expected) < 1e-12                  # closed form vs vectors: rounding of radii


def _scaled_phase(atmosphere, settings, species, cosines, phi_shift=0.0):
    """F_s(cos Theta_a c_i + sin Theta_a s_i cos(Phi_b - phi_shift)) (i, a, b) times the gather's
    energy rescaling of row i (a scalar per row, :func:`clsky.multiple._conserving`), written here:
    4 pi mean / (sum_a wT_a sin Theta_a sum_b wP_b F)."""
    theta, wt, phi, wp = gather_quadrature(settings.gather_theta_steps, settings.gather_phi_steps)
    sines = np.sqrt(np.maximum(1.0 - cosines**2, 0.0))
    cos_angle = (np.cos(theta)[None, :, None] * cosines[:, None, None]
                 + np.sin(theta)[None, :, None] * sines[:, None, None] * np.cos(phi[None, None, :] - phi_shift))
    phase = _phase(atmosphere, species)(cos_angle)
    unshifted = _phase(atmosphere, species)(np.cos(theta)[None, :, None] * cosines[:, None, None]
                                             + np.sin(theta)[None, :, None] * sines[:, None, None]
                                             * np.cos(phi)[None, None, :])
    integral = np.einsum("iab,a,b->i", unshifted, wt * np.sin(theta), wp)
    return phase * (4.0 * math.pi / integral)[:, None, None]          # both phases have mean 1


def _literal(atmosphere, settings, field, species):
    """G(phi_V) = sum_ab wT_a sin Theta_a wP_b F_s(omega_ab . V) field(..., a, b) at every phi_V of the Phi
    grid, for V at the grid's view cosines; field (D, W, Theta, Phi, C) -> (Phi, D, H, W, C)."""
    theta, wt, phi, wp = gather_quadrature(settings.gather_theta_steps, settings.gather_phi_steps)
    _, cos_view, _ = grid_coordinates(settings.size, atmosphere.atmosphere_height, settings.mapping,
                                      settings.sun_cos_range)
    weights = (wt * np.sin(theta))[:, None] * wp[None, :]
    return np.stack([np.einsum("iab,ab,zxabc->zixc", _scaled_phase(atmosphere, settings, species, cos_view, pv),
                               weights, field) for pv in phi])


def _project(values, m):
    """(eps_m / 2 pi) sum_c wP_c values(phi_c) cos(m phi_c) over the first axis (the Phi grid)."""
    _, _, phi, wp = gather_quadrature(TINY.gather_theta_steps, TINY.gather_phi_steps)
    eps = 1.0 if m == 0 else 2.0
    return eps / (2.0 * math.pi) * np.tensordot(wp * np.cos(m * phi), values, axes=(0, 0))


HARMONICS = 2


@pytest.mark.parametrize("species", ["rayleigh", "mie"])
def test_gather_against_literal_sphere_integral(atmosphere, species):
    """G_{s,m} of L(Theta, Phi) = sum_n L_n(Theta) cos(n Phi) (the table's L_n interpolated along Theta)
    against the literal 2D trapezoid at every phi_V of the Phi grid, projected on cos(m phi_V): a
    discrete circular convolution, so equal to rounding (1e-12 of the peak)."""
    operators = azimuth.HarmonicGather(atmosphere, TINY, HARMONICS)
    width, height, depth = TINY.size
    table = np.random.default_rng(5).random((HARMONICS + 1, depth, height, width, 3))
    _, _, phi, _ = gather_quadrature(TINY.gather_theta_steps, TINY.gather_phi_steps)
    p = _gather_parts(atmosphere, TINY)[0]
    field = np.einsum("aj,nzjxc,nb->zxabc", p, table, np.cos(np.outer(np.arange(HARMONICS + 1), phi)))
    literal = _literal(atmosphere, TINY, field, species)
    channels = slice(0, 3) if species == "rayleigh" else slice(3, 6)
    gathered = operators.gather(table)[..., channels]
    for m in range(HARMONICS + 1):
        expected = _project(literal, m)
        assert_allclose(gathered[m], expected, rtol=0, atol=1e-12 * np.abs(literal).max())


@pytest.mark.parametrize("species", ["rayleigh", "mie"])
def test_first_gather_against_literal_sphere_integral(atmosphere, species):
    """The first gather: single scattering Ibar_s'(Theta, Phi) = sum_n I_n(Theta) cos(n Phi) seen with
    the exact phase F_s'(omega . Sun) of both species, same literal check."""
    operators = azimuth.HarmonicGather(atmosphere, TINY, HARMONICS)
    width, height, depth = TINY.size
    single = np.random.default_rng(7).random((HARMONICS + 1, depth, height, width, 6))
    _, _, phi, _ = gather_quadrature(TINY.gather_theta_steps, TINY.gather_phi_steps)
    _, _, cos_sun = grid_coordinates(TINY.size, atmosphere.atmosphere_height, TINY.mapping, TINY.sun_cos_range)
    p = _gather_parts(atmosphere, TINY)[0]
    field = 0.0
    for index, other in enumerate(("rayleigh", "mie")):
        sun_phase = _scaled_phase(atmosphere, TINY, other, cos_sun)       # (D, Theta, Phi)
        field = field + np.einsum("aj,nzjxc,nb,zab->zxabc", p, single[..., 3 * index:3 * index + 3],
                                  np.cos(np.outer(np.arange(HARMONICS + 1), phi)), sun_phase)
    literal = _literal(atmosphere, TINY, field, species)
    channels = slice(0, 3) if species == "rayleigh" else slice(3, 6)
    # first_gather takes single scattering at the azimuth nodes: the series' values there
    series_at_nodes = np.cos(np.outer(azimuth.azimuth_nodes(HARMONICS), np.arange(HARMONICS + 1)))
    gathered = operators.first_gather(np.tensordot(series_at_nodes, single, axes=1))[..., channels]
    for m in range(HARMONICS + 1):
        assert_allclose(gathered[m], _project(literal, m), rtol=0, atol=1e-12 * np.abs(literal).max())


def test_operators_cached_per_grid_and_phase_functions(atmosphere):
    """harmonic_gather: one HarmonicGather per grid, quadrature, phase functions and M, whatever the
    coefficients or wavelengths (a spectral build's batches share it), read-only, the same values as a new
    one; a build computes it once for two builds of the same grid."""
    from clsky import spectrum
    first, second = spectrum.batch_atmospheres(atmosphere, 6)
    operators = azimuth.harmonic_gather(first, TINY, HARMONICS)
    assert azimuth.harmonic_gather(second, TINY, HARMONICS) is operators
    assert azimuth.harmonic_gather(first.replace(mie_g=-0.7), TINY, HARMONICS) is not operators
    assert azimuth.harmonic_gather(first, TINY, 1) is not operators
    assert azimuth.harmonic_gather(first, TINY.replace(gather_phi_steps=20), HARMONICS) is not operators
    fresh = azimuth.HarmonicGather(atmosphere, TINY, HARMONICS)
    for name in ("view", "sun"):
        for species in ("rayleigh", "mie"):
            array = getattr(operators, name)[species]
            assert_array_equal(array, getattr(fresh, name)[species])
            assert not array.flags.writeable
    assert not operators.p.flags.writeable and not operators.weights.flags.writeable
    azimuth._harmonic_gather.cache_clear()
    settings = TINY.replace(azimuth_harmonics=HARMONICS, orders=2)
    for _ in range(2):
        azimuth.compute_orders(atmosphere, settings)
    assert azimuth._harmonic_gather.cache_info()[:2] == (1, 1)          # (hits, misses)


def test_first_gather_sun_weighting_is_einsums_sum(atmosphere):
    """The first gather's weighting of the seen harmonics by C_{s',m,n}(z, a), done a few sun layers at a time
    (HarmonicGather._sun_weighted), is bit for bit the einsum it replaced: per species s' the sum over n
    in order, the second species' added to the first's (so that a harmonic table keeps its bits), whether
    each species' channels come together (the first gather's layout, (2, W, 3) a row) or as strided
    views. An odd number of sun layers (7) leaves a short last block."""
    settings = TINY.replace(size=(5, 12, 7))
    operators = azimuth.HarmonicGather(atmosphere, settings, HARMONICS)
    width, height, depth = settings.size
    seen = np.random.default_rng(11).random((HARMONICS + 1, depth, settings.gather_theta_steps + 1, width, 6))
    expected = None
    for index, species in enumerate(("rayleigh", "mie")):
        term = np.einsum("mnza,nzawc->mzawc", operators.sun[species], seen[..., 3 * index:3 * index + 3])
        expected = term if expected is None else expected + term
    assert depth % operators.SUN_LAYERS_PER_BLOCK != 0
    by_species = seen.reshape(seen.shape[:3] + (width, 2, 3)).transpose(0, 1, 2, 4, 3, 5)
    assert np.array_equal(operators._sun_weighted(np.ascontiguousarray(by_species)), expected)
    assert np.array_equal(operators._sun_weighted(by_species), expected)


def test_first_gather_in_blocks_of_sun_layers_is_the_whole_grids(atmosphere, monkeypatch):
    """The first gather, done HarmonicGather.FIRST_GATHER_LAYERS sun layers at a time (harmonics of the
    nodes, interpolation, sun weighting and gathers of a block, then the next), is bit for bit the same
    products over the whole grid at once (BLAS multiplies each layer's matrices on their own, and each
    cell's harmonics are the same three products and sums in any block): blocks of 2 with a short last
    block (7 layers), and of 3, against one block of all 7; and on 1, 2 and 3 host threads
    (HarmonicGather.FIRST_GATHER_THREADS), each block on whichever thread takes it. The one block of all
    layers is also the products of the harmonics of the whole grid taken first, with the interpolation's
    columns in the table's order, (W, 6) a row (what the first gather did before its blocks took the
    harmonics and before it put each species' columns together: BLAS computes each column on its own)."""
    settings = TINY.replace(size=(5, 12, 7))
    operators = azimuth.HarmonicGather(atmosphere, settings, HARMONICS)
    width, height, depth = settings.size
    single = np.random.default_rng(13).random((HARMONICS + 1, depth, height, width, 6))
    single *= np.exp(np.random.default_rng(14).normal(size=single.shape[:3] + (1, 1)) * 4.0)
    monkeypatch.setattr(azimuth.HarmonicGather, "FIRST_GATHER_LAYERS", depth)
    whole = operators.first_gather(single)
    harmonics = azimuth._to_harmonics(single).reshape(HARMONICS + 1, depth, height, width * 6)
    seen = np.matmul(operators.p, harmonics).reshape(HARMONICS + 1, depth, -1, width, 2, 3)
    weighted = operators._sun_weighted(seen.transpose(0, 1, 2, 4, 3, 5)).reshape(HARMONICS + 1, depth, -1, width * 3)
    for index, species in enumerate(("rayleigh", "mie")):
        products = np.matmul(operators.view[species][:, None], weighted).reshape(HARMONICS + 1, depth, height,
                                                                                 width, 3)
        assert_array_equal(whole[..., 3 * index:3 * index + 3], products)
    for layers in (2, 3):
        monkeypatch.setattr(azimuth.HarmonicGather, "FIRST_GATHER_LAYERS", layers)
        assert depth % layers != 0
        for threads in (1, 2, 3):
            monkeypatch.setattr(azimuth.HarmonicGather, "FIRST_GATHER_THREADS", threads)
            assert azimuth.HarmonicGather.first_gather_threads(depth) == threads
            assert np.array_equal(operators.first_gather(single), whole)


def test_first_gather_threads_at_most_one_a_block(monkeypatch):
    """The first gather's thread count: the host's cores unless set, never more than its blocks, at least 1."""
    monkeypatch.setattr(azimuth.HarmonicGather, "FIRST_GATHER_LAYERS", 2)
    monkeypatch.setattr(azimuth.HarmonicGather, "FIRST_GATHER_THREADS", 8)
    assert [azimuth.HarmonicGather.first_gather_threads(depth) for depth in (1, 2, 3, 7, 16, 17)] == [1, 1, 2, 4, 8, 8]
    monkeypatch.setattr(azimuth.HarmonicGather, "FIRST_GATHER_THREADS", None)
    monkeypatch.setattr(azimuth._cl, "host_cores", lambda: 2)
    assert azimuth.HarmonicGather.first_gather_threads(208) == 2


def test_orders_finite_and_non_negative(atmosphere):
    result = azimuth.compute_orders(atmosphere, TINY.replace(sun_cos_range=(-0.2, 0.1), azimuth_harmonics=3))
    for order in result.orders:
        assert np.isfinite(order).all() and order.min() >= 0.0
    assert result.orders[0].shape == (4,) + TINY.size[::-1] + (3,)


@pytest.mark.parametrize("case", ["tail", "fixed", "no-tail", "every-harmonic"])
def test_gathered_sum_is_every_orders_gathers(atmosphere, monkeypatch, case):
    """The gathered sum that the ray march reads, with the harmonics m >= 1 of the orders whose next
    order reads the azimuth average alone summed as nodes and gathered once ("Summed harmonics"), is the
    sum of every order's gathers as the orders define it, each order gathered on its own here: the
    first gather, G^(j) = A L^(j) of the orders j = 2..K-1, and with a geometric tail (1 + r / (1 - r))
    G^(K). Within 1e-13 of the largest value (rounding: measured 6e-16 on the default animation's
    table): orders 'auto' converged with a tail (ground 0.3, 5 or more orders), a fixed count (4; G^(4)
    never gathered), converged without a tail (no ratio; at order 3: G^(3) left out, its summed nodes
    with it), and HARMONIC_SOURCE_ORDERS None (every harmonic gathered every order, nothing summed)."""
    from clsky.orders import tail_factor

    settings = TINY.replace(azimuth_harmonics=2, orders="auto")
    if case == "fixed":
        settings = settings.replace(orders=4)
    elif case == "no-tail":          # no order ratio in (0, 1): converged at order 3 (estimated error 0.76)
        settings = settings.replace(order_tolerance=0.9)
        monkeypatch.setattr(azimuth, "geometric_ratio", lambda totals: None)
    elif case == "every-harmonic":
        monkeypatch.setattr(azimuth, "HARMONIC_SOURCE_ORDERS", None)
    atmosphere = atmosphere.replace(ground_albedo=0.3)
    result = azimuth.compute_orders(atmosphere, settings, backend="numpy", keep_nodes=True)
    operators = azimuth.HarmonicGather(atmosphere, settings, 2)
    expected = operators.first_gather(azimuth.single_scattering_nodes(atmosphere, settings))
    orders = result.orders                                            # L^(2) .. L^(K) at the nodes
    for order in orders[:-1]:
        expected = expected + operators.gather(azimuth._to_harmonics(order))
    tail = result.record["tail_ratio"]
    if tail is not None:
        scale = np.tile(1.0 + tail_factor(np.array(tail)), 2)
        expected = expected + operators.gather(azimuth._to_harmonics(orders[-1])) * scale
    assert (tail is not None) == (case in ("tail", "every-harmonic"))
    assert len(orders) + 1 == {"fixed": 4, "no-tail": 3}.get(case, len(orders) + 1)
    if case in ("tail", "every-harmonic"):
        assert result.record["converged"] and len(orders) + 1 >= 5
    assert_allclose(result.gathered, expected, rtol=0, atol=1e-13 * np.abs(expected).max())


def test_zero_harmonic_gathered_along_is_the_reference(atmosphere):
    """A gathered table with only the m = 0 harmonic: the integral along true rays is reference's."""
    rng = np.random.default_rng(11)
    width, height, depth = TINY.size
    gathered = np.zeros((3, depth, height, width, 6))
    gathered[0] = rng.random((depth, height, width, 6))
    h0, mu_v, mu_s = np.array([0.0, 3e3, 20e3]), np.array([0.1, -0.05, 0.8]), np.array([-0.1, 0.05, 0.3])
    nu = mu_v * mu_s + np.sqrt((1 - mu_v**2) * (1 - mu_s**2)) * np.array([-1.0, 0.2, 0.7])
    got = azimuth.gathered_along(atmosphere, TINY, gathered, TINY, h0, mu_v, mu_s, nu)
    expected = reference._gathered_along(atmosphere, TINY, gathered[0], TINY, h0, mu_v, mu_s, nu)
    assert_allclose(got, expected, rtol=1e-13, atol=0)


@pytest.mark.parametrize("value", [-1, 65, 1.5, "2", True])
def test_harmonics_validated(value):
    with pytest.raises(ParameterError, match="azimuth_harmonics"):
        azimuth.azimuth_nodes(value)


def test_settings_validated():
    with pytest.raises(ParameterError, match="azimuth_harmonics"):
        TableSettings(azimuth_harmonics=2)                  # mode atmosphere-plus
    for value in (-1, 65, 1.5, "2"):
        with pytest.raises(ParameterError, match="azimuth_harmonics"):
            TableSettings(mode="physical", azimuth_harmonics=value)
    # more harmonics than the gather's Phi steps sample twice a period alias (a probe: 8 steps, M = 8 was
    # 80 % off at -3 deg, p95, and 4D tables' kernel and twin parted by 4e-8)
    assert TableSettings(mode="physical", gather_phi_steps=8, azimuth_harmonics=4).azimuth_harmonics == 4
    with pytest.raises(ParameterError, match=r"^azimuth_harmonics must be at most gather_phi_steps / 2 = 4 "):
        TableSettings(mode="physical", gather_phi_steps=8, azimuth_harmonics=5)


def test_backend_validated(atmosphere):
    with pytest.raises(ParameterError, match="backend"):
        azimuth.compute_orders(atmosphere, TINY, backend="cuda")


# Kernels against their twins (float64; tolerances of conftest.TOLERANCES: the same formulas at the same
# nodes, differing by summation order and FMA contraction) ------------------------------------------

KERNEL_GRID = TableSettings(size=(9, 17, 7), mode="physical", orders=3, gather_theta_steps=32, gather_phi_steps=16,
                            sun_cos_range=(-0.3, 0.4), azimuth_harmonics=2)


def _assert_per_channel(actual, desired, tolerance, label):
    assert np.all(np.isfinite(actual))
    for c in range(desired.shape[-1]):
        print(max_error_report(actual[..., c], desired[..., c], f"{label} channel {c}"))
        assert_allclose(actual[..., c], desired[..., c], rtol=tolerance.rtol, atol=tolerance.atol(desired[..., c]),
                        err_msg=f"{label} channel {c}")


def test_single_at_azimuth_nodes_matches_twin(cl_context, atmosphere):
    from clsky.single import SingleScatteringEngine

    require_dtype(cl_context, "float64")
    engine = SingleScatteringEngine(KERNEL_GRID, ctx=cl_context)
    expected = azimuth.single_scattering_nodes(atmosphere, KERNEL_GRID)
    for n, phi in enumerate(azimuth.azimuth_nodes(2)):
        got = engine.compute(atmosphere, cos_azimuth=math.cos(phi))
        _assert_per_channel(got, expected[n], TOLERANCES["float64"]["single_scattering_table"], f"node {n}")
    # the canonical node is the 3D table's single scattering, bit for bit
    assert np.array_equal(engine.compute(atmosphere, cos_azimuth=1.0), engine.compute(atmosphere))
    # written into a given array (the nodes of a table go into one): the same bits, in it
    nodes = np.empty((2,) + expected.shape[1:])
    node = nodes[1]
    assert engine.compute(atmosphere, cos_azimuth=math.cos(phi), out=node) is node
    assert np.array_equal(nodes[1], got)
    single32 = SingleScatteringEngine(KERNEL_GRID.replace(dtype="float32"), ctx=cl_context)
    assert np.array_equal(single32.compute(atmosphere, out=node), single32.compute(atmosphere))


def _random_harmonics(seed, settings):
    """Gathered harmonics (M + 1, D, H, W, 6): m = 0 positive, m >= 1 of both signs and as large, so that
    the series goes negative at some azimuths and the clamp at 0 is exercised."""
    width, height, depth = settings.size
    rng = np.random.default_rng(seed)
    gathered = rng.random((settings.azimuth_harmonics + 1, depth, height, width, 6))
    gathered[1:] = 1.2 * (gathered[1:] - 0.5)
    return gathered * 1e-3


def test_scatter_at_azimuth_nodes_matches_twin(cl_context, atmosphere, dtype):
    """Both kernel dtypes against the float64 twin (conftest.TOLERANCES' scatter: the series adds M
    products of the same lookups, a few ulps more)."""
    from clsky.multiple import MultipleScatteringEngine

    engine = MultipleScatteringEngine(KERNEL_GRID.replace(dtype=dtype), ctx=cl_context)
    gathered = _random_harmonics(1, KERNEL_GRID)
    expected = azimuth.scatter_nodes(atmosphere, KERNEL_GRID, gathered)
    padded = np.zeros(gathered.shape[:-1] + (8,), dtype=dtype)
    padded[..., :6] = gathered
    import pyopencl.array as cla
    gathered_d = cla.to_device(engine.queue, padded)
    for n, phi in enumerate(azimuth.azimuth_nodes(2)):
        got = engine.scatter(atmosphere, gathered_d, combine_species=True, cos_azimuth=math.cos(phi)).get()
        _assert_per_channel(got[..., :3].astype(np.float64), expected[n], TOLERANCES[dtype]["scatter"],
                            f"scatter node {n} {dtype}")
        assert np.all(got >= 0.0)


@pytest.mark.parametrize("albedo", [0.0, 0.3])
def test_orders_backends_agree(cl_context, atmosphere, albedo):
    require_dtype(cl_context, "float64")
    atmosphere = atmosphere.replace(ground_albedo=albedo)
    kernel = azimuth.compute_orders(atmosphere, KERNEL_GRID, backend="opencl", ctx=cl_context)
    twin = azimuth.compute_orders(atmosphere, KERNEL_GRID, backend="numpy")
    assert kernel.record["orders"] == twin.record["orders"] == 3
    for k, (a, b) in enumerate(zip(kernel.orders, twin.orders)):
        _assert_per_channel(a, b, TOLERANCES["float64"]["orders"], f"order {k + 2}")
    _assert_per_channel(kernel.gathered, twin.gathered, TOLERANCES["float64"]["orders"], "gathered")
    if albedo:
        _assert_per_channel(kernel.ground_irradiance, twin.ground_irradiance, TOLERANCES["float64"]["orders"],
                            "ground irradiance")


@pytest.mark.parametrize("rectangular", [True, False], ids=["rectangular-reads", "packed-reads"])
def test_rectangular_transfers_move_the_channels_and_zero_the_padding(cl_context, atmosphere, monkeypatch,
                                                                     rectangular):
    """The OpenCL backend's copies: the first gather goes up (a rectangular write) as a padded table whose
    channels 0-5 are the host's, bit for bit, and whose padding (6, 7) is zero (the kernels read whole rows
    of 8) even in a reused buffer (every new device array filled with NaN here), in float64 and float32;
    and the gathered sum comes down as the device's channels 0-5, by rectangular reads (CPUs' way) and by
    the packing kernel and one read (GPUs' way, clsky._cl.RECTANGULAR_READS)."""
    import pyopencl.array as cla

    from clsky import _cl

    monkeypatch.setattr(_cl, "RECTANGULAR_READS", rectangular)

    empty = cla.empty

    def dirty_empty(*args, **kwargs):
        array = empty(*args, **kwargs)
        return array.fill(np.nan) if array.dtype.kind == "f" else array

    monkeypatch.setattr(cla, "empty", dirty_empty)
    operators = azimuth.HarmonicGather(atmosphere, KERNEL_GRID, KERNEL_GRID.azimuth_harmonics)
    width, height, depth = KERNEL_GRID.size
    gathered = np.random.default_rng(17).random((3, depth, height, width, 6)) + 0.5
    for dtype in ("float64", "float32"):
        require_dtype(cl_context, dtype)
        run = azimuth._opencl_backend(atmosphere, KERNEL_GRID.replace(dtype=dtype), lambda: operators, cl_context,
                                      False)
        gathered_d = run.upload(gathered)
        padded = gathered_d.get()
        assert padded.shape == gathered.shape[:-1] + (8,) and padded.dtype == np.dtype(dtype)
        assert_array_equal(padded[..., :6], gathered.astype(dtype))
        assert not padded[..., 6:].any()
        down = run.to_host(gathered_d)
        assert down.dtype == np.float64
        assert_array_equal(down, gathered.astype(dtype))


def nan_filled_queue(cl_context, monkeypatch, dtype):
    """A queue on ``cl_context`` (skipping where it lacks ``dtype``), with every pyopencl.array.empty from
    now on filled with NaN: an upload that leaves any value unwritten shows it."""
    import pyopencl as cl
    import pyopencl.array as cla

    require_dtype(cl_context, dtype)
    empty = cla.empty

    def dirty_empty(*args, **kwargs):
        return empty(*args, **kwargs).fill(np.nan)

    monkeypatch.setattr(cla, "empty", dirty_empty)
    return cl.CommandQueue(cl_context)


def share_queues(cl_context, count):
    """``count`` queues of their own on ``cl_context`` for upload_padded's ``queues`` (None for 0)."""
    import pyopencl as cl

    return [cl.CommandQueue(cl_context) for _ in range(count)] or None


@pytest.mark.parametrize("shares", [0, 2, 3])
@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_upload_padded_pads_every_table_shape_with_zeros(cl_context, monkeypatch, dtype, shares):
    """clsky._cl.upload_padded, which the harmonic build (above), MultipleScatteringEngine.to_device and
    the renderer's gathered sum go through: a host table (..., C) arrives as (..., 8) of the device's
    type, channels 0..C-1 the host's values (rounded to float32 as a cast rounds them), the rest zero in
    a buffer that held NaN, for 1, 3, 6 and 8 channels, a non-contiguous table and leading shapes of 1
    to 4 axes; a table of no channels, more than 8 or no values is refused before any transfer. The same
    with the rows shared among 2 or 3 queues of their own (``queues``, the harmonic build's on a CPU; rows
    that do not divide evenly, a queue without rows); that the shares wait for the array's queue, the
    next test but one."""
    from clsky import _cl

    queue = nan_filled_queue(cl_context, monkeypatch, dtype)
    queues = share_queues(cl_context, shares)
    rng = np.random.default_rng(23)
    for shape in ((5, 1), (4, 3), (2, 3, 5, 6), (3, 2, 3, 5, 6), (7, 8), (1, 6), (2, 6)):
        table = rng.random(shape) + 0.5
        padded = _cl.upload_padded(queue, table, dtype, queues=queues).get()
        assert padded.shape == shape[:-1] + (8,) and padded.dtype == np.dtype(dtype)
        assert_array_equal(padded[..., :shape[-1]], table.astype(dtype))
        assert not padded[..., shape[-1]:].any()
    strided = rng.random((4, 5, 12))[..., ::2]                              # (4, 5, 6), not contiguous
    assert_array_equal(_cl.upload_padded(queue, strided, dtype, queues=queues).get()[..., :6], strided.astype(dtype))
    nodes = rng.random((3, 4, 5, 3))                    # an order's nodes: channels 0-2 and 3-5 both hold them
    twice = _cl.upload_padded(queue, nodes, dtype, copies=2, queues=queues).get()
    assert_array_equal(twice[..., :3], nodes.astype(dtype))
    assert_array_equal(twice[..., 3:6], nodes.astype(dtype))
    assert not twice[..., 6:].any()
    for bad, copies in ((np.zeros(3), 1), (np.zeros((4, 9)), 1), (np.zeros((0, 6)), 1), (np.zeros((4, 0)), 1),
                        (np.zeros((4, 3)), 3), (np.zeros((4, 3)), 0)):
        with pytest.raises(ValueError, match=r"upload_padded: table must have shape \(\.\.\., C\)"):
            _cl.upload_padded(queue, bad, dtype, copies=copies)


def test_upload_share_queues_split_on_a_cpu_only(cl_context):
    """clsky._cl.upload_share_queues, which upload_gathered_source (the renderers' and the 4D table's) and
    the harmonic build pass to upload_padded: two queues of the queue's own context and device on a CPU (PoCL's copies side by side),
    the caller's own where it gives them (the build's copy queues), None on any other device (a stand-in
    GPU queue), with or without queues to reuse."""
    import types

    import pyopencl as cl

    from clsky import _cl

    queue = cl.CommandQueue(cl_context)
    queues = _cl.upload_share_queues(queue)
    if queue.device.type & cl.device_type.CPU:
        assert len(queues) == 2 and all(q.context == queue.context and q.device == queue.device for q in queues)
        assert all(q != queue for q in queues)
        assert _cl.upload_share_queues(queue, reuse=queues[::-1]) == queues[::-1]
    else:
        assert queues is None
    gpu = types.SimpleNamespace(device=types.SimpleNamespace(type=cl.device_type.GPU), context=cl_context)
    assert _cl.upload_share_queues(gpu) is None
    assert _cl.upload_share_queues(gpu, reuse=[queue, queue]) is None


def test_upload_padded_shares_start_after_the_queue(cl_context, monkeypatch):
    """With ``queues``, the shares' fills and writes wait for every command enqueued on the array's queue
    before them (a buffer from a pool may still be read there; here the queue's NaN fill of the new
    buffer, held back until a host thread releases the queue 0.2 s later): without that order the NaN
    fill lands after the writes."""
    import threading

    import pyopencl as cl

    from clsky import _cl

    queue = nan_filled_queue(cl_context, monkeypatch, "float64")
    release = cl.UserEvent(cl_context)
    cl.enqueue_marker(queue, wait_for=[release])               # the queue's later commands wait for it
    timer = threading.Timer(0.2, release.set_status, (cl.command_execution_status.COMPLETE,))
    timer.start()
    try:
        table = np.random.default_rng(31).random((4, 5, 6)) + 0.5
        padded = _cl.upload_padded(queue, table, "float64", queues=share_queues(cl_context, 2)).get()
    finally:
        timer.join()
    assert_array_equal(padded[..., :6], table)
    assert not padded[..., 6:].any()


@pytest.mark.parametrize("shares", [0, 2])
@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_upload_padded_interleaves_a_stack(cl_context, monkeypatch, dtype, shares):
    """clsky._cl.upload_padded with ``interleaved``, through which a renderer and the 4D table upload a
    gathered source with harmonics (transmittance.upload_gathered_source): a stack (N, ..., C) arrives as
    (..., N, 8) of the device's type, table n's values in row n of each cell, the rest zero in a buffer
    that held NaN, for stacks of 1 to 3 tables of 1 to 3 axes and a non-contiguous one;
    upload_gathered_source interleaves a stack of harmonics and pads a table without them; a stack of
    fewer than 3 axes is refused. The same with the rows shared among 2 queues of their own."""
    from clsky import _cl
    from clsky.transmittance import upload_gathered_source

    queue = nan_filled_queue(cl_context, monkeypatch, dtype)
    queues = share_queues(cl_context, shares)
    rng = np.random.default_rng(29)

    def assert_interleaved(device, stack):
        assert device.shape == stack.shape[1:-1] + (len(stack), 8) and device.dtype == np.dtype(dtype)
        channels = stack.shape[-1]
        assert_array_equal(device[..., :channels], np.moveaxis(stack, 0, -2).astype(dtype))
        assert not device[..., channels:].any()

    for shape in ((1, 5, 6), (3, 4, 6), (3, 2, 3, 5, 6), (2, 7, 1)):
        stack = rng.random(shape) + 0.5
        assert_interleaved(_cl.upload_padded(queue, stack, dtype, interleaved=True, queues=queues).get(), stack)
    strided = rng.random((3, 4, 12))[..., ::2]                              # (3, 4, 6), not contiguous
    assert_interleaved(_cl.upload_padded(queue, strided, dtype, interleaved=True, queues=queues).get(), strided)
    harmonics = rng.random((3, 2, 3, 4, 6))
    assert_interleaved(upload_gathered_source(queue, harmonics, dtype).get(), harmonics)
    average = upload_gathered_source(queue, harmonics[0], dtype).get()
    assert average.shape == (2, 3, 4, 8)
    assert_array_equal(average[..., :6], harmonics[0].astype(dtype))
    assert not average[..., 6:].any()
    with pytest.raises(ValueError, match=r"upload_padded: table must have a stack \(N, \.\.\., C\)"):
        _cl.upload_padded(queue, np.zeros((4, 6)), dtype, interleaved=True)


def test_add_into_the_first_slabs(cl_context):
    """MultipleScatteringEngine.add_into with ``slabs``: an order's gathered azimuth average (the first
    slab of its stack) into the gathered sum's first harmonic, with and without the tail's scale per
    wavelength, the other slabs untouched; slabs outside [1, N] or on a single table refused."""
    import pyopencl.array as cla

    from clsky.multiple import MultipleScatteringEngine

    require_dtype(cl_context, "float64")
    engine = MultipleScatteringEngine(KERNEL_GRID, ctx=cl_context)
    rng = np.random.default_rng(29)
    total, addend = rng.random((2, 3, 4, 5, 6, 8))
    total_d, addend_d = (cla.to_device(engine.queue, a) for a in (total, addend))
    engine.add_into(total_d, addend_d, slabs=1)
    expected = total.copy()
    expected[0] = total[0] + addend[0]
    assert_array_equal(total_d.get(), expected)
    scale = np.array([1.5, 2.0, 3.0])
    engine.add_into(total_d, addend_d, scale, slabs=2)
    weights = np.concatenate([scale, scale, [0.0, 0.0]])
    expected[:2] = expected[:2] + addend[:2] * weights
    assert_allclose(total_d.get(), expected, rtol=1e-15, atol=0)
    for slabs in (0, 4):
        with pytest.raises(ValueError, match="slabs must be in"):
            engine.add_into(total_d, addend_d, slabs=slabs)
    with pytest.raises(ValueError, match="slabs must be in"):
        engine.add_into(total_d[0], addend_d[0], slabs=1)


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_packed_reads_are_the_rectangular_reads_bit_for_bit(cl_context, atmosphere, monkeypatch, dtype):
    """The orders, their nodes' azimuth averages, the gathered harmonics and the ground irradiance of a
    build whose downloads are packed on the device and read at once (GPUs' way) are those of rectangular
    reads (CPUs' way), bit for bit: both copy the same device values (reflecting ground, 3 orders)."""
    from clsky import _cl

    from clsky.multiple import MultipleScatteringEngine

    require_dtype(cl_context, dtype)
    settings = KERNEL_GRID.replace(dtype=dtype)
    atmosphere = atmosphere.replace(ground_albedo=0.3)
    pack = MultipleScatteringEngine.pack_channels
    packs = []

    def counted(engine, padded, channels, out):
        packs.append(channels)
        return pack(engine, padded, channels, out)

    monkeypatch.setattr(MultipleScatteringEngine, "pack_channels", counted)
    results, packed_channels = {}, {}
    for rectangular in (True, False):
        monkeypatch.setattr(_cl, "RECTANGULAR_READS", rectangular)
        results[rectangular] = azimuth.compute_orders(atmosphere, settings, backend="opencl", ctx=cl_context,
                                                      keep_nodes=True)
        packed_channels[rectangular], packs[:] = list(packs), []
    packed, rectangle = results[False], results[True]
    assert packed.record["orders"] == rectangle.record["orders"] == 3
    # each way taken: no packing for rectangular reads; the 2 orders' nodes (3 channels), the gathered sum (6)
    assert packed_channels == {True: [], False: [3, 3, 6]}
    for a, b in zip(packed.orders + [packed.gathered, packed.ground_irradiance],
                    rectangle.orders + [rectangle.gathered, rectangle.ground_irradiance]):
        assert_array_equal(a, b)


def test_rectangular_reads_on_cpus_only(monkeypatch):
    """The default: rectangular reads on a CPU device, the packing kernel on a GPU or an accelerator (an
    H200 read rows of 3 of 8 doubles 13x slower than a contiguous whole); RECTANGULAR_READS overrides."""
    import types

    import pyopencl as cl

    from clsky import _cl

    def device(kind):
        return types.SimpleNamespace(type=kind)

    monkeypatch.setattr(_cl, "RECTANGULAR_READS", None)
    assert _cl.rectangular_reads(device(cl.device_type.CPU))
    assert not _cl.rectangular_reads(device(cl.device_type.GPU))
    assert not _cl.rectangular_reads(device(cl.device_type.ACCELERATOR))
    monkeypatch.setattr(_cl, "RECTANGULAR_READS", True)
    assert _cl.rectangular_reads(device(cl.device_type.GPU))
    monkeypatch.setattr(_cl, "RECTANGULAR_READS", False)
    assert not _cl.rectangular_reads(device(cl.device_type.CPU))


def test_pack_channels_copies_and_checks_its_arrays(cl_context):
    """MultipleScatteringEngine.pack_channels: padded[..., :channels] bit for bit for 1, 3, 6 and 8 channels
    (random doubles), and a ValueError naming the shapes when out does not fit."""
    import pyopencl.array as cla

    from clsky.multiple import MultipleScatteringEngine

    require_dtype(cl_context, "float64")
    engine = MultipleScatteringEngine(KERNEL_GRID, ctx=cl_context)
    padded = np.random.default_rng(5).random((2, 3, 5, 7, 8))
    padded_d = cla.to_device(engine.queue, padded)
    for channels in (1, 3, 6, 8):
        out = cla.empty(engine.queue, padded.shape[:-1] + (channels,), np.float64)
        engine.pack_channels(padded_d, channels, out).wait()
        assert_array_equal(out.get(), padded[..., :channels])
    wrong = cla.empty(engine.queue, padded.shape[:-1] + (4,), np.float64)
    with pytest.raises(ValueError, match=r"\(2, 3, 5, 7, 4\)"):
        engine.pack_channels(padded_d, 3, wrong)


def test_float32_build_close_to_float64(cl_context, atmosphere):
    """A float32 device build with harmonics (its nodes and gathered sum read into float32 host tables,
    then widened): every order and the gathered harmonics within 3e-6 of their maximum of the float64
    build's, the bound of the float32 tables of tests/test_extremes.py (measured 4.6e-7 here)."""
    require_dtype(cl_context, "float32")
    require_dtype(cl_context, "float64")
    atmosphere = atmosphere.replace(ground_albedo=0.3)
    double = azimuth.compute_orders(atmosphere, KERNEL_GRID, backend="opencl", ctx=cl_context)
    single = azimuth.compute_orders(atmosphere, KERNEL_GRID.replace(dtype="float32"), backend="opencl", ctx=cl_context)
    assert single.record["orders"] == double.record["orders"]
    for a, b in zip(single.orders + [single.gathered], double.orders + [double.gathered]):
        assert a.dtype == np.float64 and np.isfinite(a).all()
        assert np.abs(a - b).max() <= 3e-6 * np.abs(b).max()


def test_geometric_tail_with_harmonics(cl_context, atmosphere):
    """'auto' with two harmonics and a ground (albedo 0.3): the geometric tail (clsky.orders) as the twin
    computes it, and against the plain sum of 40 orders (the last added under 1e-16) within the tolerance
    (1e-4) in the bright part, for the table, the ray march's gathered harmonics and the ground's
    irradiance (measured 6.0e-5, 2.0e-5 and 5.7e-6 at 8 orders), the table at least 3x closer than the
    plain sum of the same orders (measured 17x)."""
    require_dtype(cl_context, "float64")
    from clsky.orders import OrdersResult, relative_addition

    atmosphere = atmosphere.replace(ground_albedo=0.3)
    settings = KERNEL_GRID.replace(orders="auto")
    kernel = azimuth.orders_result(atmosphere, settings, backend="opencl", ctx=cl_context)
    twin = azimuth.orders_result(atmosphere, settings, backend="numpy")
    assert kernel.record["converged"] and kernel.tail is not None
    assert kernel.record["orders"] == twin.record["orders"]
    assert_allclose(kernel.record["tail_ratio"], twin.record["tail_ratio"], rtol=1e-12, atol=0)
    for label, a, b in (("table", kernel.combined("physical"), twin.combined("physical")),
                        ("gathered", kernel.gathered, twin.gathered),
                        ("ground irradiance", kernel.ground_irradiance, twin.ground_irradiance)):
        _assert_per_channel(a, b, TOLERANCES["float64"]["orders"], label)

    many = azimuth.orders_result(atmosphere, settings.replace(orders=40), backend="opencl", ctx=cl_context)
    assert many.record["relative_additions"][-1] < 1e-16

    def error(actual, expected):
        return relative_addition(np.abs(actual - expected), expected)

    table_error = error(kernel.combined("physical"), many.combined("physical"))
    plain_error = error(OrdersResult(kernel.orders, {}).combined("physical"), many.combined("physical"))
    gathered_error = error(kernel.gathered, many.gathered)
    ground_error = error(kernel.ground_irradiance, many.ground_irradiance)
    print(f"{kernel.record['orders']} orders: table {table_error:.2e} (plain sum {plain_error:.2e}), gathered "
          f"{gathered_error:.2e}, ground {ground_error:.2e}")
    assert max(table_error, gathered_error, ground_error) < settings.order_tolerance
    assert 3 * table_error < plain_error


@pytest.mark.parametrize("albedo, harmonics", [(0.0, 2), (0.3, 2), (0.0, 1), (0.0, 5)])
def test_raymarch_matches_twin(cl_context, atmosphere, albedo, harmonics):
    """SkyRenderer.render_raymarch of a table with harmonics against reference.render_raymarch (single,
    and the ground) plus azimuth.raymarch_higher_orders, sun 3 deg below the horizon, views all around.
    M = 1, 2 and 5: the harmonics' strides in the interleaved source (kernels/view_ray.cl: add_lookups)."""
    atmosphere = atmosphere.replace(ground_albedo=albedo)
    from clsky import ScatteringTable
    from clsky.render import RAYMARCH_DEFAULTS, SkyRenderer

    require_dtype(cl_context, "float64")
    settings = KERNEL_GRID.replace(azimuth_harmonics=harmonics)
    table = ScatteringTable.build(atmosphere, settings, ctx=cl_context)
    assert table.gathered.shape == (harmonics + 1,) + settings.size[::-1] + (6,)
    ray = RAYMARCH_DEFAULTS.replace(view_steps=24, sun_steps=24)
    azimuths = np.radians(np.arange(0, 360, 30))
    elevations = np.radians([-5.0, 1.0, 4.0, 20.0, 60.0])
    a, e = np.meshgrid(azimuths, elevations)
    directions = np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], axis=-1)
    sun = np.array([math.cos(math.radians(-3.0)), 0.0, math.sin(math.radians(-3.0))])
    with SkyRenderer(table, ray, ctx=cl_context) as renderer:
        got = renderer.render_raymarch(directions, sun, 100.0)
    disc = np.zeros(3)
    expected = (reference.render_raymarch(atmosphere, ray, directions, sun, 100.0, disc, 2.0,
                                          grid_settings=table.settings, ground_irradiance=table.ground_irradiance)
                + azimuth.raymarch_higher_orders(atmosphere, ray, table.gathered, table.settings, directions, sun,
                                                 100.0))
    _assert_per_channel(got, expected, TOLERANCES["float64"]["scatter"], "ray march")


def test_table_file_round_trip_keeps_the_harmonics(cl_context, atmosphere, tmp_path):
    """A table with azimuth harmonics saves and loads its (M + 1, D, H, W, 6) gathered harmonics and its
    setting; a gathered array of the wrong shape is refused."""
    from clsky import ScatteringTable
    from clsky.table import TableFormatError

    require_dtype(cl_context, "float64")
    table = ScatteringTable.build(atmosphere, KERNEL_GRID, ctx=cl_context)
    table.save(tmp_path / "t.npz")
    loaded = ScatteringTable.load(tmp_path / "t.npz")
    assert loaded.settings.azimuth_harmonics == 2
    assert_allclose(loaded.gathered, table.gathered, rtol=1e-6, atol=0)   # float32 storage at most
    with pytest.raises(TableFormatError, match="gathered"):
        ScatteringTable(table.atmosphere, table.settings, table.data, table.metadata, table.orders,
                        table.orders_record, table.gathered[0], None)


def test_table_checks_the_harmonics_finite_of_either_sign(cl_context, atmosphere):
    """A table's gathered harmonics m >= 1 may be negative but not NaN, infinite or beyond 1e12 in size (each
    counted in the error, which names the array); the azimuth average m = 0 must also be >= 0. The harmonics are checked
    by their minimum and maximum (clsky.table.check_finite_signed), no array of their absolute values."""
    from clsky import ScatteringTable
    from clsky.table import TableFormatError

    require_dtype(cl_context, "float64")
    table = ScatteringTable.build(atmosphere, KERNEL_GRID, ctx=cl_context)

    def with_gathered(cell, value):
        gathered = table.gathered.copy()
        gathered[cell] = value
        return ScatteringTable(table.atmosphere, table.settings, table.data, table.metadata, table.orders,
                               table.orders_record, gathered, None)

    assert with_gathered((1, 0, 0, 0, 0), -1.0).gathered[1, 0, 0, 0, 0] == -1.0     # m >= 1: either sign
    assert with_gathered((2, 3, 2, 1, 5), -1e12).gathered.min() == -1e12          # down to the tables' bound
    with pytest.raises(TableFormatError, match="gathered holds 1 values beyond 1e\\+12"):
        with_gathered((2, 3, 2, 1, 5), -1e300)
    with pytest.raises(TableFormatError, match="gathered holds 1 NaN values"):
        with_gathered((2, 3, 2, 1, 5), np.nan)
    with pytest.raises(TableFormatError, match="gathered holds 1 infinite values"):
        with_gathered((1, 0, 0, 0, 0), -np.inf)
    with pytest.raises(TableFormatError, match="gathered holds 1 infinite values"):
        with_gathered((1, 0, 0, 0, 0), np.inf)
    with pytest.raises(TableFormatError, match="gathered holds 1 negative values"):
        with_gathered((0, 0, 0, 0, 0), -1.0)                                        # m = 0: >= 0


def test_raw_export_carries_the_harmonics(cl_context, atmosphere, tmp_path):
    """``export_raw`` of a table with harmonics: the table's values, then its gathered harmonics, in one
    float32 .bin, at the offset and in the layout its header states (float32: the export's precision)."""
    import json

    from clsky import ScatteringTable

    require_dtype(cl_context, "float64")
    table = ScatteringTable.build(atmosphere, KERNEL_GRID, ctx=cl_context)
    binary, header = table.export_raw(tmp_path / "sky")
    description = json.loads(header.read_text())
    block = description["azimuth_harmonics"]
    values = np.fromfile(binary, dtype="<f4")
    assert block["M"] == 2 and block["offset_values"] == table.data.size
    shape = block["shape"]
    assert (shape["harmonics"], shape["D"], shape["H"], shape["W"], shape["channels"]) == table.gathered.shape
    assert values.size == table.data.size + table.gathered.size
    assert np.array_equal(values[:table.data.size], table.data.astype("<f4").ravel())
    assert np.array_equal(values[block["offset_values"]:].reshape(table.gathered.shape), table.gathered.astype("<f4"))
    plain = ScatteringTable.build(atmosphere, KERNEL_GRID.replace(azimuth_harmonics=0), ctx=cl_context)
    binary, header = plain.export_raw(tmp_path / "plain")
    assert "azimuth_harmonics" not in json.loads(header.read_text())
    assert np.fromfile(binary, dtype="<f4").size == plain.data.size


def test_later_orders_read_the_azimuth_average_of_their_source(atmosphere):
    """``source_harmonics=0`` (the scatter of the orders k > HARMONIC_SOURCE_ORDERS) is the scatter of a
    source whose harmonics m >= 1 are zero, at every azimuth node (rounding only: the series of the
    zeroed harmonics is summed, the other path reads one table); and only order 2 reads them."""
    assert azimuth.HARMONIC_SOURCE_ORDERS == 2
    settings = TINY.replace(azimuth_harmonics=2)
    rng = np.random.default_rng(3)
    gathered = rng.random((3,) + settings.size[::-1] + (6,)) * 1e-3
    zeroed = gathered.copy()
    zeroed[1:] = 0.0
    got = azimuth.scatter_nodes(atmosphere, settings, gathered, source_harmonics=0)
    expected = azimuth.scatter_nodes(atmosphere, settings, zeroed)
    assert got.shape == expected.shape == (3,) + settings.size[::-1] + (3,)
    assert_allclose(got, expected, rtol=1e-12, atol=1e-15 * expected.max())
    full = azimuth.scatter_nodes(atmosphere, settings, gathered)
    assert np.abs(full - got).max() > 1e-3 * np.abs(full).max()      # the harmonics do matter to order 2


def test_single_scattering_alone_with_harmonics_and_a_ground(cl_context):
    """orders=1 with harmonics over a reflecting ground builds (it failed: 'ground_irradiance is
    missing'): its single scattering is bit for bit the M = 0 table's (the harmonics only change the
    orders k >= 2), and its ground irradiance E_1 is the azimuth-resolved one. That E_1 differs from
    the canonical-frame E_1 of M = 0 only by the azimuth dependence of the phase-less single
    scattering (measured 1.05 % of the largest E_1 on this grid); 3 % bounds it."""
    from clsky import ScatteringTable

    require_dtype(cl_context, "float64")
    settings = TableSettings(size=(4, 16, 6), mode="physical", orders=1)
    harmonic = ScatteringTable.build("physical", settings.replace(azimuth_harmonics=2), ctx=cl_context)
    plain = ScatteringTable.build("physical", settings, ctx=cl_context)
    assert np.array_equal(harmonic.data, plain.data)
    assert np.all(np.isfinite(harmonic.ground_irradiance)) and np.all(harmonic.ground_irradiance >= 0.0)
    scale = np.abs(plain.ground_irradiance).max()
    assert np.abs(harmonic.ground_irradiance - plain.ground_irradiance).max() <= 0.03 * scale


def test_orders_build_their_scatter_programs_while_single_scattering_runs(cl_context, monkeypatch):
    """The OpenCL orders, with azimuth harmonics (clsky.azimuth: both scatter engines, every harmonic and
    the azimuth average) and without (clsky.orders), build their multiple-scattering programs on a host
    thread of their own while single scattering runs, not on the main thread at the first gather or
    scatter (in a fresh process 40-60 ms each with the device idle; docs/speed-log.md); a build that fails
    there still fails the table build with its error. A context of its own, so that nothing is cached."""
    import threading

    import pyopencl as cl

    import clsky
    from clsky import _cl
    from clsky.multiple import MultipleScatteringEngine
    from conftest import SMALL_TABLE

    built = []
    build_program = _cl.build_program

    def recording(context, sources, options=()):
        if context.int_ptr == own.int_ptr and (context.int_ptr, tuple(sources), tuple(sorted(options))) \
                not in _cl._program_cache:
            built.append((sources[-1], threading.current_thread().name))
        return build_program(context, sources, options)

    monkeypatch.setattr(_cl, "build_program", recording)
    own = cl.Context(devices=[cl_context.devices[0]])
    physical = clsky.preset("physical")
    clsky.ScatteringTable.build(physical, SMALL_TABLE, ctx=own)                           # M = 2
    clsky.ScatteringTable.build(physical, SMALL_TABLE.replace(azimuth_harmonics=0, multiple_view_steps=12), ctx=own)
    scatter_builds = [thread for name, thread in built if name == "multiple.cl"]
    assert len(scatter_builds) == 3 and all(t.startswith("clsky-orders-setup") for t in scatter_builds), built
    assert all(thread == "MainThread" for name, thread in built if name == "single.cl"), built

    def failing(self, defines=()):
        raise _cl.KernelBuildError("building multiple.cl failed (test)")

    monkeypatch.setattr(MultipleScatteringEngine, "kernels_with", failing)
    for harmonics in (2, 0):
        with pytest.raises(_cl.KernelBuildError, match=r"multiple\.cl failed \(test\)"):
            clsky.ScatteringTable.build(physical, SMALL_TABLE.replace(azimuth_harmonics=harmonics), ctx=own)


def test_single_scatterings_total_and_copy_beside_the_stopping_tests_upload(atmosphere, monkeypatch):
    """compute_orders takes single scattering's total (the orders' first) and the copy of its canonical
    node on a host thread of their own while the stopping test sums and uploads its running sum (one after
    the other they held the first scatter back, the other core idle; docs/speed-log.md): the total is the one
    the main thread would take, and an error there still fails the build."""
    import threading

    seen = []
    total = azimuth._total

    def recording(order):
        seen.append((order.shape, threading.current_thread().name))
        return total(order)

    monkeypatch.setattr(azimuth, "_total", recording)
    settings = TINY.replace(azimuth_harmonics=HARMONICS, orders=3)
    result = azimuth.compute_orders(atmosphere, settings)
    nodes_shape = (HARMONICS + 1,) + tuple(reversed(settings.size)) + (6,)
    assert seen[0] == (nodes_shape, seen[0][1]) and seen[0][1].startswith("clsky-orders-totals"), seen
    assert all(thread == "MainThread" for _, thread in seen[1:]), seen          # the orders' own totals
    expected = azimuth.compute_orders(atmosphere, settings.replace(orders=1)).single
    assert_array_equal(result.single, expected)

    def failing(order):
        raise MemoryError("test")

    monkeypatch.setattr(azimuth, "_total", failing)
    with pytest.raises(MemoryError, match="test"):
        azimuth.compute_orders(atmosphere, settings)
