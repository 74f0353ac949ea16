"""Multiple scattering: kernels against their twins, the orders on both backends, and physics checks.

1. MultipleScatteringEngine.gather / .scatter against reference.gather / reference.scatter (float64
   and float32 kernels, float64 twin; tolerances in conftest.TOLERANCES).
2. compute_orders with backend='opencl' against backend='numpy': every order and the record.
3. The gather operator against expectations built here without the library's formulas: an isotropic
   field gathers to 4 pi mean(F) (with the trapezoid's own Euler-Maclaurin error term), a literal 2D
   trapezoid per cell, energy conservation, and the physical mode's first gather (literal azimuth
   average, reciprocity, energy); the scatter of a uniform radiance against 1 - T.
4. Sanity of the orders: no Mie, geometric decrease, finite and non-negative tables.
5. The stopping rule: convergence of a thick atmosphere, max_orders, relative_addition.
6. ScatteringTable round trip with its orders, and the 9-channel lookup.
"""

from __future__ import annotations

import math

import numpy as np
import pyopencl.array as cla
import pytest
from numpy.testing import assert_allclose

from clsky import ScatteringTable, TableSettings, preset, reference
from clsky._cl import memory_pool
from clsky.lookup import TableLookupEngine
from clsky.multiple import (SPECIES, MultipleScatteringEngine, first_gather_matrices, gather_matrices, gather_matrix,
                            gather_quadrature, phase_azimuth_integrals)
from clsky.orders import BRIGHT_FRACTION, OrdersResult, compute_orders, relative_addition

from conftest import black_preset, TOLERANCES, max_error_report, require_dtype

SMALL = TableSettings(size=(9, 33, 7), gather_theta_steps=64, gather_phi_steps=32)

SETTINGS_VARIANTS = {
    "default": SMALL,
    "linear": SMALL.replace(mapping="linear"),
    "keller_bohn": SMALL.replace(sampling="keller_bohn"),
    "ground_end": SMALL.replace(sampling="ground_end"),
    "few_steps": SMALL.replace(view_steps=3, multiple_view_steps=None),
    "single_step": SMALL.replace(view_steps=1, multiple_view_steps=None, size=(8, 17, 5)),
    # a scene's sub-range of the sun axis: the scatter looks Gbar up at the nodes' local sun angles,
    # which leave the range near its ends (clamped alike in kernel and twin)
    "sun_range": SMALL.replace(sun_cos_range=(-0.35, 0.35)),
}
PRESETS = ("atmosphere-plus", "physical")
MODES = ("atmosphere-plus", "physical")


def thick(atmosphere):
    """20x the Rayleigh and Mie scattering: vertical optical depth ~3.7 (blue) instead of 0.18."""
    return atmosphere.replace(rayleigh_scattering=tuple(20 * np.array(atmosphere.rayleigh_scattering)),
                              mie_scattering=20 * atmosphere.mie_scattering)


# Phase functions and the table's view axis, written here from physics.md (not imported) --------------

def rayleigh_phase(c):
    return 0.75 * (1.0 + c * c)


def modified_rayleigh_phase(c):
    return 0.8 * (1.4 + 0.5 * c * c)


def cornette_shanks_phase(g):
    return lambda c: 1.5 * (1.0 - g * g) / (2.0 + g * g) * (1.0 + c * c) / (1.0 + g * g + 2.0 * g * c) ** 1.5


def phase_and_mean(atmosphere, species):
    """The species' phase function of ``atmosphere`` and its mean over the sphere (physics.md)."""
    if species == "mie":
        return cornette_shanks_phase(atmosphere.mie_g), 1.0
    if atmosphere.rayleigh_phase == "rayleigh":
        return rayleigh_phase, 1.0
    return modified_rayleigh_phase, 0.8 * (1.4 + 1.0 / 6.0)     # 1.2533: the notes' artistic phase


def view_cosines(height, mapping):
    """Zenith cosines of the view nodes y / (H - 1) (physics.md inverse mappings)."""
    t = 2.0 * np.arange(height) / (height - 1) - 1.0
    return t**3 if mapping == "nonlinear" else t


def interpolate_column(column, cosine, mapping):
    """Linear interpolation of a view column at zenith cosines, in texture space v (as the lookup does)."""
    c = np.clip(cosine, -1.0, 1.0)
    v = 0.5 * (1.0 + np.sign(c) * np.abs(c) ** (1.0 / 3.0)) if mapping == "nonlinear" else 0.5 * (1.0 + c)
    f = v * (column.size - 1)
    lower = np.clip(np.floor(f).astype(np.int64), 0, column.size - 2)
    alpha = f - lower
    return (1.0 - alpha) * column[lower] + alpha * column[lower + 1]


def sphere_trapezoid(theta_steps, phi_steps):
    """2D trapezoid over (Theta, Phi) in [0, pi] x [0, 2 pi] of f sin(Theta): weights (1/4 at corners,
    1/2 on edges, 1 inside) x dTheta dPhi x sin(Theta), and the unit vectors omega, each (T + 1, P + 1)."""
    theta = np.linspace(0.0, math.pi, theta_steps + 1)[:, None]
    phi = np.linspace(0.0, 2.0 * math.pi, phi_steps + 1)[None, :]
    weights = np.ones((theta_steps + 1, phi_steps + 1))
    weights[[0, -1], :] *= 0.5
    weights[:, [0, -1]] *= 0.5
    weights *= (math.pi / theta_steps) * (2.0 * math.pi / phi_steps) * np.sin(theta)
    omega = (np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta) + 0.0 * phi)
    return weights, omega


def channel_totals(order):
    """Sum over all cells per wavelength (r, g, b): Rayleigh + Mie for factored orders."""
    per_wavelength = order[..., :3] + order[..., 3:6] if order.shape[-1] == 6 else order
    return per_wavelength.reshape(-1, 3).sum(axis=0)


# Fixtures and helpers -----------------------------------------------------------------------------

@pytest.fixture(scope="module")
def multiple_engine(cl_context):
    """``multiple_engine(settings)``: a cached MultipleScatteringEngine (keyed by what it compiles in
    or reads from its settings: the scatter's view steps, sun steps, sampling, sun transmittance,
    dtype, mapping, sun range and source stride)."""
    cache = {}

    def get(settings: TableSettings) -> MultipleScatteringEngine:
        require_dtype(cl_context, settings.dtype)
        s = settings.scatter_settings
        key = (s.view_steps, s.sun_steps, s.sampling, s.sun_transmittance, s.dtype, s.mapping, s.sun_cos_range,
               s.source_stride)
        if key not in cache:
            cache[key] = MultipleScatteringEngine(settings, ctx=cl_context)
        return cache[key]

    yield get
    for engine in cache.values():
        engine.close()


@pytest.fixture(scope="module")
def twin_inputs():
    """``twin_inputs(preset_name, variant)``: single scattering (twin), the gather matrices, and the
    twin's gathered table, computed once."""
    cache = {}

    def get(preset_name, variant):
        key = (preset_name, variant)
        if key not in cache:
            atmosphere, settings = black_preset(preset_name), SETTINGS_VARIANTS[variant]
            single = reference.single_scattering(atmosphere, settings)
            same = gather_matrices(atmosphere, settings)
            first = first_gather_matrices(atmosphere, settings)
            matrices = np.stack([same[s] for s in SPECIES])
            cache[key] = {"single": single, "matrices": matrices,
                          "direct": np.stack([first[("rayleigh", "rayleigh")], first[("mie", "mie")]]),
                          "crossed": np.stack([first[("rayleigh", "mie")], first[("mie", "rayleigh")]]),
                          "gathered": reference.gather(matrices, single)}
        return cache[key]

    return get


@pytest.fixture(scope="module")
def orders_of(cl_context):
    """``orders_of(atmosphere, settings, backend='opencl')``: compute_orders, computed once."""
    cache = {}

    def get(atmosphere, settings, backend="opencl"):
        key = (atmosphere, settings, backend)
        if key not in cache:
            cache[key] = compute_orders(atmosphere, settings, backend=backend, ctx=cl_context)
        return cache[key]

    return get


def assert_close_per_channel(actual, desired, tolerance, label):
    """assert_allclose channel by channel (last axis), atol scaled to each channel's maximum (Mie and
    Rayleigh differ in scale); the largest error is logged."""
    assert actual.shape == desired.shape
    assert np.all(np.isfinite(actual))
    for c in range(desired.shape[-1]):
        print(max_error_report(actual[..., c], desired[..., c], f"{label} channel {c}"))
        assert_allclose(actual[..., c], desired[..., c], rtol=tolerance.rtol, atol=tolerance.atol(desired[..., c]),
                        err_msg=f"{label} channel {c}")


# 1. Kernels against their twins -------------------------------------------------------------------

@pytest.mark.parametrize("preset_name", PRESETS)
@pytest.mark.parametrize("variant", ["default", "linear", "sun_range"])    # the gather depends on the grid only
def test_gather_kernel_matches_twin(multiple_engine, twin_inputs, dtype, variant, preset_name):
    settings = SETTINGS_VARIANTS[variant].replace(dtype=dtype)
    engine = multiple_engine(settings)
    inputs = twin_inputs(preset_name, variant)
    single = inputs["single"]
    tolerance = TOLERANCES[dtype]["gather"]
    label = f"gather {variant} {preset_name} {dtype}"

    # (2, H, H) matrices: one per species
    out = engine.gather(inputs["matrices"], single).get()
    assert out.shape == single.shape[:3] + (8,)
    assert_close_per_channel(out[..., :6], reference.gather(inputs["matrices"], single), tolerance, label)
    assert np.all(out[..., 6:] == 0.0)

    # (2, D, H, H) per-sun-node matrices, then accumulate the crossed terms (the physical mode's first gather)
    swapped = np.concatenate([single[..., 3:], single[..., :3]], axis=-1)
    out_d = engine.gather(inputs["direct"], single)
    engine.gather(inputs["crossed"], swapped, out=out_d, accumulate=True)
    expected = reference.gather(inputs["direct"], single) + reference.gather(inputs["crossed"], swapped)
    out = out_d.get()
    assert_close_per_channel(out[..., :6], expected, tolerance, label + " per node + accumulate")
    assert np.all(out[..., 6:] == 0.0)


def test_gather_device_input_and_overwritten_output(multiple_engine, twin_inputs):
    """A padded device table gives the same result as the host table; ``out`` without accumulate is
    overwritten (stale contents ignored); wrong matrix shapes are refused."""
    engine = multiple_engine(SMALL)
    inputs = twin_inputs("physical", "default")
    host = engine.gather(inputs["matrices"], inputs["single"]).get()
    out = engine.to_device(np.full(inputs["single"].shape, 1e300))
    result = engine.gather(inputs["matrices"], engine.to_device(inputs["single"]), out=out, accumulate=False)
    assert result is out
    assert np.array_equal(out.get(), host)
    with pytest.raises(ValueError, match="matrices must have shape"):
        engine.gather(inputs["matrices"][:, :-1], inputs["single"])


def test_gather_into_a_slab_of_a_stack(multiple_engine, twin_inputs):
    """``out``/``node``: the gather writes slab ``node`` of a (N, D, H, W, 8) stack (clsky.azimuth's
    harmonics), exactly what it returns on its own, and leaves the other slabs as they were; a slab past
    N, a table of another shape or dtype is refused before any launch."""
    engine = multiple_engine(SMALL)
    inputs = twin_inputs("physical", "default")
    alone = engine.gather(inputs["matrices"], inputs["single"]).get()
    stack = cla.to_device(engine.queue, np.full((3,) + alone.shape, 7.0))
    assert engine.gather(inputs["matrices"], inputs["single"], out=stack, node=1) is stack
    got = stack.get()
    assert np.array_equal(got[1], alone) and np.all(got[[0, 2]] == 7.0)
    for node, shape, dtype in ((3, stack.shape, np.float64), (-1, stack.shape, np.float64),
                               (0, (3,) + alone.shape[:-1] + (6,), np.float64), (0, stack.shape, np.float32)):
        with pytest.raises(ValueError, match="out must be a padded float64 table"):
            engine.gather(inputs["matrices"], inputs["single"], out=cla.empty(engine.queue, shape, dtype), node=node)


def test_scatter_into_a_node_slab(multiple_engine, twin_inputs):
    """``out``/``node``: the scatter writes slab ``node`` of a (N, D, H, W, 8) buffer, exactly what it
    returns on its own, and leaves the other slabs as they were; a slab past N or a wrong shape is
    refused before any launch."""
    engine = multiple_engine(SMALL)
    atmosphere = black_preset("physical")
    gathered = twin_inputs("physical", "default")["gathered"]
    alone = engine.scatter(atmosphere, gathered).get()
    out = cla.to_device(engine.queue, np.full((3,) + alone.shape, -1.0, dtype=alone.dtype))
    assert engine.scatter(atmosphere, gathered, out=out, node=1) is out
    slabs = out.get()
    assert np.array_equal(slabs[1], alone)
    assert np.all(slabs[[0, 2]] == -1.0)
    for node, shape, dtype in ((3, out.shape, alone.dtype), (-1, out.shape, alone.dtype),
                               (0, (3,) + alone.shape[:-1] + (6,), alone.dtype), (0, out.shape, np.float32)):
        with pytest.raises(ValueError, match="out must be a padded float64 table"):
            engine.scatter(atmosphere, gathered, out=cla.empty(engine.queue, shape, dtype), node=node)


@pytest.mark.parametrize("count", [1, 3, 5])
def test_combine_nodes_and_add_into_match_pyopencl_elementwise(multiple_engine, dtype, count):
    """combine_nodes and add_into replace chains of PyOpenCL's elementwise kernels (clsky/azimuth.py,
    clsky/orders.py) and claim their exact roundings: sum_n w_n L_n as L_0 * w_0 then mul_add(1, L_n, w_n),
    and total + addend, compared bit for bit on values with full mantissas; NumPy's sum within 4 ulp
    (at most 4 roundings of a sum of 5 terms of one sign, with or without fused multiply-adds)."""
    engine = multiple_engine(SMALL.replace(dtype=dtype))
    rng = np.random.default_rng(7)
    real = np.dtype(dtype).type
    nodes = rng.uniform(0.0, 2.0, (count, 5, 6, 7, 8)).astype(dtype)
    weights = rng.uniform(0.1, 1.0, count)
    nodes_d = cla.to_device(engine.queue, nodes)
    combined = engine.combine_nodes(nodes_d, weights, cla.empty(engine.queue, nodes.shape[1:], dtype)).get()
    chain = cla.to_device(engine.queue, nodes[0]) * real(weights[0])
    for weight, node in zip(weights[1:], nodes[1:]):
        chain = chain.mul_add(1.0, cla.to_device(engine.queue, node), real(weight))
    assert np.array_equal(combined, chain.get())
    # the weights already on the device (how clsky.azimuth enqueues a chain of gathers): the same bits
    on_device = engine.combine_nodes(nodes_d, engine.upload_matrices(weights),
                                     cla.empty(engine.queue, nodes.shape[1:], dtype)).get()
    assert np.array_equal(on_device, combined)
    expected = np.einsum("n,n...->...", weights, nodes.astype(np.float64))
    assert_allclose(combined, expected, rtol=4 * np.finfo(dtype).eps, atol=0.0)
    total, addend = cla.to_device(engine.queue, nodes[0]), cla.to_device(engine.queue, nodes[-1])
    assert engine.add_into(total, addend) is total
    assert np.array_equal(total.get(), (cla.to_device(engine.queue, nodes[0]) + addend).get())
    with pytest.raises(ValueError, match="must agree"):
        engine.combine_nodes(nodes_d, np.ones(count + 1), cla.empty(engine.queue, nodes.shape[1:], dtype))
    other = np.float32 if np.dtype(dtype) == np.float64 else np.float64
    with pytest.raises(ValueError, match="must agree"):        # device weights of the other precision
        engine.combine_nodes(nodes_d, cla.to_device(engine.queue, np.ones(count, other)),
                             cla.empty(engine.queue, nodes.shape[1:], dtype))
    with pytest.raises(ValueError, match="one shape"):
        engine.add_into(total, cla.empty(engine.queue, (5, 6, 7, 4), dtype))


def test_engines_share_a_queue_and_a_pool(cl_context):
    """``queue`` and ``allocator``: an engine on another's queue runs in its order and takes its arrays
    from the pool; a buffer its array drops is handed to the next array of that size (no new memory)."""
    first = MultipleScatteringEngine(SMALL, ctx=cl_context)
    pool = memory_pool(first.queue)
    second = MultipleScatteringEngine(SMALL.replace(mode="physical", azimuth_harmonics=1), queue=first.queue,
                                      allocator=pool)
    assert second.queue is first.queue and second.ctx == first.ctx
    table = second.to_device(np.ones((7, 33, 9, 6)))
    assert table.allocator is pool and pool.active_blocks == 1
    managed = pool.managed_bytes
    del table
    assert pool.held_blocks == 1
    again = second.to_device(np.ones((7, 33, 9, 6)))
    assert pool.managed_bytes == managed and pool.held_blocks == 0 and again.allocator is pool


@pytest.mark.parametrize("preset_name", PRESETS)
@pytest.mark.parametrize("variant", sorted(SETTINGS_VARIANTS))
def test_scatter_kernel_matches_twin(multiple_engine, twin_inputs, dtype, variant, preset_name):
    settings = SETTINGS_VARIANTS[variant].replace(dtype=dtype)
    atmosphere = black_preset(preset_name)
    gathered = twin_inputs(preset_name, variant)["gathered"]
    out = multiple_engine(settings).scatter(atmosphere, gathered).get()
    expected = reference.scatter(atmosphere, SETTINGS_VARIANTS[variant], gathered)
    assert_close_per_channel(out[..., :6], expected, TOLERANCES[dtype]["scatter"],
                             f"scatter {variant} {preset_name} {dtype}")
    assert np.all(out[..., 6:] == 0.0)
    assert np.all(out >= 0.0)


@pytest.mark.parametrize("preset_name", PRESETS)
def test_scatter_combine_species(multiple_engine, twin_inputs, dtype, preset_name):
    """combine_species: channels 0-2 and 3-5 both hold Rayleigh + Mie of the plain scatter; 6, 7 zero."""
    engine = multiple_engine(SMALL.replace(dtype=dtype))
    atmosphere = black_preset(preset_name)
    gathered = twin_inputs(preset_name, "default")["gathered"]
    plain = engine.scatter(atmosphere, gathered).get()
    combined = engine.scatter(atmosphere, gathered, combine_species=True).get()
    both = plain[..., 0:3] + plain[..., 3:6]
    # one addition of the same two products (an FMA contraction in the kernel may move it by 1 ulp)
    ulp = np.finfo(np.dtype(dtype)).eps
    assert_allclose(combined[..., 0:3], both, rtol=ulp, atol=0)
    assert np.array_equal(combined[..., 3:6], combined[..., 0:3])
    assert np.all(combined[..., 6:] == 0.0)


# 2. compute_orders: OpenCL against NumPy ------------------------------------------------------------

@pytest.mark.parametrize("orders", [4, "auto"])
@pytest.mark.parametrize("mode", MODES)
def test_compute_orders_backends_agree(orders_of, mode, orders):
    atmosphere = black_preset("physical")
    settings = SMALL.replace(mode=mode, orders=orders)
    kernel = orders_of(atmosphere, settings, "opencl")
    twin = orders_of(atmosphere, settings, "numpy")
    assert len(kernel.orders) == len(twin.orders) == kernel.record["orders"] == twin.record["orders"]
    if orders == 4:
        assert len(kernel.orders) == 4
    for k, (a, b) in enumerate(zip(kernel.orders, twin.orders), start=1):
        assert_close_per_channel(a, b, TOLERANCES["float64"]["orders"], f"order {k} {mode}")
    for field in ("mode", "orders", "requested", "tolerance", "max_orders", "converged"):
        assert kernel.record[field] == twin.record[field], field
    # relative additions: ratios over bright cells (>= 1 % of the max), where the orders agree to 1e-13
    assert_allclose(kernel.record["relative_additions"], twin.record["relative_additions"], rtol=1e-10, atol=0)
    assert_allclose(kernel.record["estimated_errors"], twin.record["estimated_errors"], rtol=1e-8, atol=0)
    assert (kernel.tail is None) == (twin.tail is None) == (orders == 4)
    if orders == "auto":      # ratios of sums over the whole table, of orders that agree to 1e-13
        assert_allclose(kernel.record["tail_ratio"], twin.record["tail_ratio"], rtol=1e-12, atol=0)
    assert_allclose(kernel.record["shares"], twin.record["shares"], rtol=1e-10, atol=0)
    assert_allclose(kernel.combined(mode), twin.combined(mode), rtol=1e-10,
                    atol=1e-14 * np.max(twin.combined(mode)))


# 3. The gather operator, checked independently ----------------------------------------------------

ISOTROPIC_CASES = {
    # name: (atmosphere, per species: (bound on the raw error, bound after the leading trapezoid term))
    # The trapezoid over Theta of f = sin(Theta) K(Theta) has the Euler-Maclaurin error
    # (h^2 / 12) (f'(pi) - f'(0)) + O(h^4), f'(0) = K(0) = 2 pi F(mu), f'(pi) = -2 pi F(-mu); the Phi
    # trapezoid is periodic (spectrally accurate). Measured at 256 x 128 steps: smooth phases 1.9e-5 raw,
    # 1.9e-10 after the term (O(h^4)); Cornette-Shanks g = -0.85, whose forward lobe (F(1) = 90.6) sits
    # on the endpoint, 5.7e-4 raw (not 1e-4: the lobe enlarges f'(0)), 4.9e-7 after the term.
    "physical": (black_preset("physical"), {"rayleigh": (1e-4, 1e-9), "mie": (1e-3, 2e-6)}),
    "physical_g0": (black_preset("physical").replace(mie_g=0.0), {"rayleigh": (1e-4, 1e-9), "mie": (1e-4, 1e-9)}),
    "atmosphere-plus": (black_preset("atmosphere-plus"), {"rayleigh": (1e-4, 1e-9), "mie": (1e-3, 2e-6)}),
}


@pytest.mark.parametrize("case", sorted(ISOTROPIC_CASES))
def test_isotropic_field_gathers_to_4pi_mean_phase(multiple_engine, case):
    """A table of ones gathered (OpenCL) with a phase of mean m gives 4 pi m at every node: 4 pi for the
    true Rayleigh and Cornette-Shanks (g = -0.85 and 0), 4 pi x 1.2533 for the modified Rayleigh.

    The gather rescales each row of the raw trapezoid to conserve energy, so the result is exact up to
    rounding (257 terms: 1e-13). The rescaling only removes the raw trapezoid's known error: that error,
    checked here too, is the Euler-Maclaurin leading term up to O(h^4) (bounds in ISOTROPIC_CASES)."""
    atmosphere, bounds = ISOTROPIC_CASES[case]
    settings = TableSettings(size=(3, 33, 3))                       # default 256 x 128 gather steps
    ones = np.ones((3, 33, 3, 6))
    matrices = np.stack([gather_matrix(atmosphere, settings, s) for s in SPECIES])
    gathered = multiple_engine(settings).gather(matrices, ones).get()
    mu = view_cosines(33, settings.mapping)
    h = math.pi / settings.gather_theta_steps
    theta, theta_weights, phi, phi_weights = gather_quadrature(settings.gather_theta_steps, settings.gather_phi_steps)
    for index, species in enumerate(SPECIES):
        phase, mean = phase_and_mean(atmosphere, species)
        exact = gathered[..., 3 * index:3 * index + 3] / (4.0 * math.pi * mean) - 1.0
        assert np.abs(exact).max() <= 1e-13
        raw = phase_azimuth_integrals(phase, mu, theta, phi, phi_weights) @ (theta_weights * np.sin(theta))
        relative = raw / (4.0 * math.pi * mean) - 1.0
        leading = -(h * h / 12.0) * (phase(mu) + phase(-mu)) / (2.0 * mean)
        raw_bound, remainder_bound = bounds[species]
        print(f"{case} {species}: raw {np.abs(relative).max():.3g}, after the h^2 term "
              f"{np.abs(relative - leading).max():.3g}, gathered {np.abs(exact).max():.3g}")
        assert np.abs(relative).max() <= raw_bound
        assert np.abs(relative - leading).max() <= remainder_bound


def literal_gather(phase, mu_view, column, mapping, theta_steps, phi_steps):
    """Integral F(dot(omega, V)) Ibar(cos Theta) d omega by the literal 2D trapezoid, V = (sin, 0, cos)."""
    weights, (ox, _, oz) = sphere_trapezoid(theta_steps, phi_steps)
    cos_angle = ox * math.sqrt(max(1.0 - mu_view * mu_view, 0.0)) + oz * mu_view
    return np.sum(weights * phase(cos_angle) * interpolate_column(column, oz, mapping))


@pytest.mark.parametrize("mapping", ["nonlinear", "linear"])
@pytest.mark.parametrize("preset_name", PRESETS)
def test_gather_matrix_equals_literal_2d_trapezoid(preset_name, mapping):
    """M @ Ibar equals a direct 2D trapezoid over (Theta, Phi) per cell, rescaled so that a uniform field
    gathers to 4 pi mean(F) (literal(Ibar) x 4 pi mean / literal(1)). Same nodes and weights, summed in
    another order (the matrix factors the Phi sums): ~1e3 terms x u -> 1e-13; rtol 1e-12."""
    atmosphere = black_preset(preset_name)
    settings = TableSettings(size=(3, 17, 2), mapping=mapping, gather_theta_steps=48, gather_phi_steps=20)
    rng = np.random.default_rng(7)
    mu = view_cosines(17, mapping)
    for species in SPECIES:
        phase, mean = phase_and_mean(atmosphere, species)
        matrix = gather_matrix(atmosphere, settings, species)
        for _ in range(3):
            column = rng.uniform(0.1, 2.0, 17)
            for i in (0, 3, 8, 13, 16):
                literal = literal_gather(phase, mu[i], column, mapping, 48, 20)
                scale = 4.0 * math.pi * mean / literal_gather(phase, mu[i], np.ones(17), mapping, 48, 20)
                assert matrix[i] @ column == pytest.approx(literal * scale, rel=1e-12, abs=0)


ENERGY_PROFILES = {
    # Ibar(mu) and the bound on |relative error|, at 129 linear view nodes and 256 x 128 steps.
    # 1 + mu: G(mu) is exactly linear in mu (4 pi (mean F + mu mean(c F))), so only the Theta
    # trapezoid's h^2 / 12 = 1.26e-5 remains (measured 1.26e-5 Rayleigh, 1.37e-5 Mie): 3e-5.
    "linear": (lambda mu: 1.0 + mu, 3e-5),
    # exp(2 mu): plus the view trapezoid of G over 129 nodes, (2/128)^2 / 12 x |G''| / G <= 8e-5.
    # Measured 2.5e-5 (Rayleigh), 1.3e-5 (Mie): 1e-4.
    "exponential": (lambda mu: np.exp(2.0 * mu), 1e-4),
}


@pytest.mark.parametrize("profile", sorted(ENERGY_PROFILES))
@pytest.mark.parametrize("preset_name", PRESETS)
def test_gather_conserves_energy(multiple_engine, preset_name, profile):
    """For Ibar depending only on the view cosine, Integral_V Gbar dV = 4 pi mean(F) Integral Ibar d omega:
    since Integral_V F(dot(omega, V)) dV = 4 pi mean(F) for every omega, the energy scattered out of the
    incoming field is what the gathered field holds over all view directions."""
    atmosphere = black_preset(preset_name)
    function, bound = ENERGY_PROFILES[profile]
    settings = TableSettings(size=(2, 129, 2), mapping="linear")
    mu = view_cosines(129, "linear")
    table = np.broadcast_to(function(mu)[None, :, None, None], (2, 129, 2, 6)).copy()
    matrices = np.stack([gather_matrix(atmosphere, settings, s) for s in SPECIES])
    gathered = multiple_engine(settings).gather(matrices, table).get()
    # the gather sees the interpolant, piecewise linear in mu here: its sphere integral is the trapezoid
    incoming = 2.0 * math.pi * np.trapezoid(function(mu), mu)
    for index, species in enumerate(SPECIES):
        _, mean = phase_and_mean(atmosphere, species)
        outgoing = 2.0 * math.pi * np.trapezoid(gathered[..., 3 * index:3 * index + 3], mu, axis=1)
        relative = outgoing / (4.0 * math.pi * mean * incoming) - 1.0
        print(f"{preset_name} {profile} {species}: relative energy error {np.abs(relative).max():.3g}")
        assert np.abs(relative).max() <= bound


def literal_first_gather(phase_view, phase_sun, mu_view, mu_sun, column, mapping, theta_steps, phi_steps):
    """(1 / 2 pi) Integral dpsi Integral F_s(dot(omega, V(psi))) F_s'(dot(omega, Sun)) Ibar d omega: the
    azimuth psi of V averaged on the Phi grid, Sun = (sin, 0, cos)."""
    weights, (ox, oy, oz) = sphere_trapezoid(theta_steps, phi_steps)
    sun = phase_sun(ox * math.sqrt(1.0 - mu_sun * mu_sun) + oz * mu_sun)
    interpolated = interpolate_column(column, oz, mapping)
    sine = math.sqrt(1.0 - mu_view * mu_view)
    total = 0.0
    for psi in 2.0 * math.pi * np.arange(phi_steps) / phi_steps:
        view = phase_view((ox * math.cos(psi) + oy * math.sin(psi)) * sine + oz * mu_view)
        total += np.sum(weights * view * sun * interpolated)
    return total / phi_steps


def sun_cosines(depth, sun_cos_range):
    """Zenith cosines of the sun nodes of a non-linear table whose sun axis spans sun_cos_range: evenly
    spaced in w = (1 + cbrt(c)) / 2 between the ends (physics.md mapping; clsky/mapping.py)."""
    w_low, w_high = (0.5 * (1.0 + np.cbrt(c)) for c in sun_cos_range)
    t = 2.0 * (w_low + (w_high - w_low) * np.arange(depth) / (depth - 1)) - 1.0
    return t**3


@pytest.mark.parametrize("sun_cos_range", [(-1.0, 1.0), (-0.3, 0.6)])
@pytest.mark.parametrize("preset_name", PRESETS)
def test_first_gather_matrices_equal_literal_azimuth_average(preset_name, sun_cos_range):
    """M_{s,s'}(z) @ Ibar equals the literal 2D trapezoid with both phases at their true angles,
    averaged over the azimuth of V, each phase's discrete integral rescaled to 4 pi x its mean (as the
    gather does). With psi on the Phi grid the discrete average separates exactly into K_s K_s' / (2 pi)
    (a periodic convolution), so only the summation order differs: rtol 1e-12."""
    atmosphere = black_preset(preset_name)
    settings = TableSettings(size=(2, 17, 9), gather_theta_steps=48, gather_phi_steps=20, sun_cos_range=sun_cos_range)
    first = first_gather_matrices(atmosphere, settings)
    mu_view, mu_sun = view_cosines(17, "nonlinear"), sun_cosines(9, sun_cos_range)
    column = np.random.default_rng(3).uniform(0.1, 2.0, 17)
    ones = np.ones(17)
    for (s, s2), matrices in first.items():
        phase_view, mean_view = phase_and_mean(atmosphere, s)
        phase_sun, mean_sun = phase_and_mean(atmosphere, s2)
        for z, i in ((0, 8), (2, 0), (4, 12), (6, 16), (8, 5)):
            literal = literal_first_gather(phase_view, phase_sun, mu_view[i], mu_sun[z], column, "nonlinear", 48, 20)
            scale = (4.0 * math.pi * mean_view / literal_gather(phase_view, mu_view[i], ones, "nonlinear", 48, 20)
                     * 4.0 * math.pi * mean_sun / literal_gather(phase_sun, mu_sun[z], ones, "nonlinear", 48, 20))
            assert matrices[z, i] @ column == pytest.approx(literal * scale, rel=1e-12, abs=0), (s, s2, z, i)


def test_sun_sub_range_table_matches_the_whole_axis():
    """A table whose sun axis covers 34.9 to 90 deg only (24 nodes) against one over the whole axis with
    the same node spacing there (256 nodes): looked up at a 45 deg sun, single scattering and every
    order agree to the interpolation error between their different nodes (measured: 1.2e-6 and 1.2e-5,
    95th percentile). This is the test that caught the first gather's sun nodes taken from the
    whole axis (2 % too bright)."""
    base = TableSettings(mode="physical", size=(16, 64, 256))
    sub_range = dict(size=(16, 64, 24), sun_cos_range=(math.sin(math.radians(34.9)), 1.0))
    rng = np.random.default_rng(0)
    n = 2000
    altitude, cos_view = rng.uniform(0.0, 2e4, n), rng.uniform(-0.2, 1.0, n)
    cos_sun = np.full(n, math.sin(math.radians(45.0)))
    cos_scatter = np.clip(cos_view * cos_sun + np.sqrt((1 - cos_view**2) * (1 - cos_sun**2))
                          * np.cos(rng.uniform(0.0, np.pi, n)), -1.0, 1.0)
    for orders in (1, "auto"):
        whole = ScatteringTable.build(black_preset("physical"), base.replace(orders=orders))
        part = ScatteringTable.build(black_preset("physical"), base.replace(orders=orders, **sub_range))
        ratio = part.radiance(altitude, cos_view, cos_sun, cos_scatter) / whole.radiance(altitude, cos_view, cos_sun,
                                                                                        cos_scatter)
        assert np.percentile(np.abs(ratio - 1.0), 95) < 1e-4, orders


def test_first_gather_reciprocity():
    """With an isotropic table, light scattered by s toward V after s' from the sun equals light scattered
    by s' toward the sun after s from V: rowsum M_{s,s'}[z, i] = rowsum M_{s',s}[i, z] (D = H, same
    mapping; exact in the discrete form up to rounding: rtol 1e-13)."""
    atmosphere = black_preset("physical")
    settings = TableSettings(size=(2, 17, 17), gather_theta_steps=64, gather_phi_steps=32)
    first = first_gather_matrices(atmosphere, settings)
    for s in SPECIES:
        for s2 in SPECIES:
            assert_allclose(first[(s, s2)].sum(axis=2), first[(s2, s)].sum(axis=2).T, rtol=1e-13, atol=0)


FIRST_GATHER_ENERGY_BOUNDS = {
    # view-sphere average of the isotropic first gather / (4 pi): 257 linear view nodes, 256 x 128 steps.
    ("rayleigh", "rayleigh"): 5e-5,     # Theta trapezoid h^2/12 = 1.3e-5 + view trapezoid; measured 1.8e-5
    ("mie", "rayleigh"): 5e-5,          # measured 1.3e-5
    ("rayleigh", "mie"): 1e-3,          # the Mie lobe on the Theta endpoint (sun at a pole), as in the
                                        # isotropic test: measured 5.6e-4
    ("mie", "mie"): 3e-3,               # two lobes: the view trapezoid over 257 nodes resolves the
                                        # product poorly when the sun is at a pole: measured 1.4e-3
}


@pytest.mark.parametrize("pair", sorted(FIRST_GATHER_ENERGY_BOUNDS))
def test_first_gather_energy(pair):
    """Averaged over all view directions, the first gather of an isotropic table is 4 pi mean(F_s)
    mean(F_s') = 4 pi for mean-1 phases, at every sun node (Integral_V F_s(dot(omega, V)) dV = 4 pi for
    every omega, then Integral F_s'(dot(omega, Sun)) d omega = 4 pi)."""
    settings = TableSettings(size=(2, 257, 5), mapping="linear")
    matrices = first_gather_matrices(black_preset("physical"), settings)[pair]
    mu = view_cosines(257, "linear")
    average = np.trapezoid(matrices.sum(axis=2), mu, axis=1) / 2.0 / (4.0 * math.pi)
    print(f"{pair}: |average / 4 pi - 1| per sun node {np.abs(average - 1.0)}")
    assert np.abs(average - 1.0).max() <= FIRST_GATHER_ENERGY_BOUNDS[pair]


def path_optical_depth(atmosphere, altitude, mu, steps=20000):
    """tau (..., 3) from altitude along mu to the top or the ground, by a fine trapezoid (own geometry)."""
    rp, ra = atmosphere.planet_radius, atmosphere.top_radius
    r0 = rp + altitude
    below = r0 * r0 * mu * mu - altitude * (2.0 * rp + altitude)     # ray-ground discriminant / 4
    hits_ground = (mu < 0.0) & (below > 0.0)
    length = np.where(hits_ground, -r0 * mu - np.sqrt(np.maximum(below, 0.0)),
                      -r0 * mu + np.sqrt(r0 * r0 * mu * mu + ra * ra - r0 * r0))
    s = length[..., None] * np.linspace(0.0, 1.0, steps + 1)
    h = np.maximum(np.sqrt(r0[..., None] ** 2 + s * s + 2.0 * r0[..., None] * mu[..., None] * s) - rp, 0.0)
    step = (length / steps)[..., None]
    column_r = np.sum(np.exp(-h / atmosphere.rayleigh_scale_height)[..., 1:-1], axis=-1, keepdims=True) * step
    column_r += 0.5 * step * (np.exp(-h[..., :1] / atmosphere.rayleigh_scale_height)
                              + np.exp(-h[..., -1:] / atmosphere.rayleigh_scale_height))
    column_m = np.sum(np.exp(-h / atmosphere.mie_scale_height)[..., 1:-1], axis=-1, keepdims=True) * step
    column_m += 0.5 * step * (np.exp(-h[..., :1] / atmosphere.mie_scale_height)
                              + np.exp(-h[..., -1:] / atmosphere.mie_scale_height))
    return np.asarray(atmosphere.rayleigh_scattering) * column_r + atmosphere.mie_extinction * column_m


def scatter_of_unit_radiance(engine, atmosphere, size):
    """I_R + I_M / ratio after scattering a uniform isotropic radiance 1 (Gbar = 4 pi in every channel),
    per cell (D, H, W, 3), and the exact value 1 - T(Pa, Pb) = Integral (beta_R rho_R + beta_M^e rho_M) T ds."""
    width, height, depth = size
    out = engine.scatter(atmosphere, np.full((depth, height, width, 6), 4.0 * math.pi)).get()
    total = out[..., 0:3] + out[..., 3:6] / atmosphere.mie_extinction_ratio
    u = np.arange(width) / (width - 1)
    altitude, mu = np.meshgrid(u * u * atmosphere.atmosphere_height, view_cosines(height, "nonlinear"))
    return total, np.broadcast_to(1.0 - np.exp(-path_optical_depth(atmosphere, altitude, mu)), total.shape)


def test_scatter_of_uniform_radiance_matches_extinction(multiple_engine):
    """Scattering a uniform isotropic radiance 1 returns 1 - T along each view ray (no kernel formula
    shared: own geometry and optical depth). With 300 uniform view steps the trapezoid error is
    O(dtau^2), dtau <= 0.09 per step on the ground's horizontal ray: measured 7.9e-4; bound 2e-3.
    Without ozone: the identity needs every extinction but Mie's to scatter (ozone only absorbs)."""
    atmosphere = black_preset("physical").replace(ozone_column_du=0.0)
    total, exact = scatter_of_unit_radiance(multiple_engine(SMALL.replace(view_steps=300, multiple_view_steps=None)), atmosphere, (9, 33, 7))
    print(max_error_report(total, exact, "unit radiance, 300 steps"))
    assert np.abs(total - exact).max() <= 2e-3


@pytest.mark.parametrize("atmosphere_name, scatter_steps, bound", [
    ("default", 20, 1.1),
    ("thick", 30, 1.1),
    # the default 20 scatter steps in the x20 atmosphere: measured 1.154; the orders still converge
    # (test_thick_atmosphere_converges_with_default_sampling)
    ("thick", 20, 1.2),
])
def test_scatter_does_not_amplify_uniform_radiance(multiple_engine, atmosphere_name, scatter_steps, bound):
    """Keller & Bohn steps (the default): the scattered fraction of a uniform radiance 1 stays <= 1 up to
    the coarse quadrature's error (10 % at 30 steps). With 30 *uniform* steps the x20 atmosphere's
    horizontal rays have steps of optical depth ~17 whose first node the trapezoid weights dtau/2:
    radiance 1 scattered into 9.5 (see test_uniform_sampling_on_thick_atmosphere_is_reported_diverging)."""
    atmosphere = black_preset("physical")
    if atmosphere_name == "thick":
        atmosphere = thick(atmosphere)
    settings = SMALL.replace(multiple_view_steps=scatter_steps)
    total, exact = scatter_of_unit_radiance(multiple_engine(settings), atmosphere, (9, 33, 7))
    print(f"{atmosphere_name}: max scattered fraction {total.max():.4g} (exact max {exact.max():.4g})")
    assert total.max() <= bound


# 4. Sanity of the orders --------------------------------------------------------------------------

@pytest.mark.parametrize("backend", ["opencl", "numpy"])
@pytest.mark.parametrize("mode", MODES)
def test_no_mie_gives_zero_mie_channels(orders_of, mode, backend):
    """mie_scattering = 0: the Mie channels of every order are exactly 0. In the physical mode the higher
    orders (Rayleigh + Mie together) then cannot depend on the Mie phase at all: bit-identical for
    another g."""
    atmosphere = black_preset("physical").replace(mie_scattering=0.0)
    settings = SMALL.replace(mode=mode, orders=4)
    result = orders_of(atmosphere, settings, backend)
    assert np.all(result.orders[0][..., 3:6] == 0.0)
    assert result.orders[0][..., 0:3].max() > 0.0
    if mode == "atmosphere-plus":
        for order in result.orders[1:]:
            assert np.all(order[..., 3:6] == 0.0)
            assert order[..., 0:3].max() > 0.0
    else:
        assert np.all(result.combined(mode)[..., 3:6] == 0.0)
        other = orders_of(atmosphere.replace(mie_g=0.5), settings, backend)
        for a, b in zip(result.orders[1:], other.orders[1:]):
            assert np.array_equal(a, b)


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("preset_name", PRESETS)
def test_orders_decrease_geometrically(orders_of, preset_name, mode):
    """Conservative atmosphere (mie_extinction_ratio = 1), black ground: each order holds less light than
    the previous one (ratio < 1 per wavelength), and from order 3 on the ratio is that of the operator's
    dominant mode: constant within 5 % (measured spread 1.2-2.5 %; ratios 0.10-0.13 r, 0.21-0.27 g,
    0.26-0.32 b)."""
    atmosphere = black_preset(preset_name).replace(mie_extinction_ratio=1.0)
    result = orders_of(atmosphere, SMALL.replace(mode=mode, orders=10))
    totals = np.array([channel_totals(order) for order in result.orders])
    ratios = totals[1:] / totals[:-1]
    print(f"{preset_name} {mode} ratios:\n{np.array2string(ratios, precision=4)}")
    assert np.all(ratios < 1.0) and np.all(ratios > 0.0)
    from_order_3 = ratios[1:]                       # T3 / T2, T4 / T3, ...
    assert np.all(from_order_3.max(axis=0) / from_order_3.min(axis=0) <= 1.05)


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("preset_name", PRESETS)
def test_orders_are_finite_and_non_negative(orders_of, preset_name, mode):
    result = orders_of(black_preset(preset_name), SMALL.replace(mode=mode))
    assert result.record["converged"]
    for order in result.orders:
        assert np.all(np.isfinite(order)) and np.all(order >= 0.0)
    combined = result.combined(mode)
    assert combined.shape == (7, 33, 9, 6 if mode == "atmosphere-plus" else 9)
    assert np.all(np.isfinite(combined)) and np.all(combined >= 0.0)


def test_default_size_orders_are_finite_and_non_negative(cl_context):
    """The full default 32 x 256 x 32 grid and 256 x 128 gather, physical mode, OpenCL (~3 s)."""
    result = compute_orders(black_preset("physical"), TableSettings(mode="physical"), ctx=cl_context)
    assert result.record["converged"]
    combined = result.combined("physical")
    assert combined.shape == (32, 256, 32, 9)
    assert np.all(np.isfinite(combined)) and np.all(combined >= 0.0)
    assert combined[..., 6:].max() > 0.0


# 5. Stopping rule ---------------------------------------------------------------------------------

THICK_SETTINGS = SMALL.replace(sampling="keller_bohn")   # resolves the optically thick first steps


@pytest.mark.parametrize("mode", MODES)
def test_thick_atmosphere_converges(orders_of, mode):
    """x20 scattering, Keller & Bohn sampling: 'auto' converges, with many more orders than the default
    atmosphere (measured 73 / 68 orders with the geometric tail against 8, and 77 / 72 against 10 by the
    plain sum before it; the ratio per order is ~0.89 blue). It stops at the first order whose estimated
    error falls below the tolerance."""
    atmosphere = black_preset("physical")
    thick_result = orders_of(thick(atmosphere), THICK_SETTINGS.replace(mode=mode))
    default_result = orders_of(atmosphere, THICK_SETTINGS.replace(mode=mode))
    record = thick_result.record
    print(f"{mode}: thick {record['orders']} orders, default {default_result.record['orders']}")
    assert record["converged"] and default_result.record["converged"]
    assert record["reason"].startswith("converged")
    assert record["orders"] == len(thick_result.orders) < record["max_orders"]
    assert record["orders"] >= 3 * default_result.record["orders"]
    errors = record["estimated_errors"]
    assert errors[-1] < record["tolerance"] <= min(errors[:-1])
    assert record["tail_ratio"] is not None and thick_result.tail is not None


def test_uniform_sampling_on_thick_atmosphere_is_reported_diverging(cl_context):
    """30 uniform view steps on the x20 atmosphere: the orders grow (a quadrature artefact); the
    orchestrator stops early and says why instead of running to max_orders."""
    result = compute_orders(thick(black_preset("physical")), SMALL.replace(sampling="uniform", max_orders=50),
                            ctx=cl_context)
    record = result.record
    print(record["reason"])
    assert record["converged"] is False and record["reason"].startswith("diverging")
    assert record["orders"] < 50


def test_thick_atmosphere_converges_with_default_sampling(cl_context):
    result = compute_orders(thick(black_preset("physical")), SMALL, ctx=cl_context)
    totals = np.array([channel_totals(order) for order in result.orders])
    print(f"per-order ratios:\n{np.array2string(totals[1:] / totals[:-1], precision=3)}")
    assert np.all(totals[2:] < totals[1:-1])
    assert result.record["converged"]


@pytest.mark.parametrize("mode", MODES)
def test_max_orders_stops_without_converging(orders_of, mode):
    """max_orders = 3 on the thick atmosphere: stops after 3 orders, converged False, and says why."""
    result = orders_of(thick(black_preset("physical")), THICK_SETTINGS.replace(mode=mode, max_orders=3))
    record = result.record
    assert len(result.orders) == record["orders"] == 3
    assert record["converged"] is False
    assert "max_orders" in record["reason"] and "not converged" in record["reason"]
    assert len(record["relative_additions"]) == 2
    assert record["relative_additions"][-1] >= record["tolerance"]
    assert result.tail is None and record["tail_ratio"] is None     # no tail without convergence


def test_relative_addition_on_hand_made_arrays():
    """max over channels and bright cells (running sum >= 1 % of the channel max, > 0) of added / running."""
    assert BRIGHT_FRACTION == 1e-2
    running = np.array([[100.0, 1e-3],
                        [1.0, 5e-6],         # channel 0: exactly 1 % of its max (bright); channel 1: dark
                        [0.99, 2e-5],        # channel 0: just below 1 % (dark)
                        [50.0, 0.0]])
    added = np.array([[1.0, 1e-4],           # ratios 0.01, 0.1
                      [0.5, 1e-4],           # 0.5 (counted), 20 (dark: ignored)
                      [0.9, 2e-6],           # 0.909 (dark: ignored), 0.1
                      [0.0, 0.0]])
    assert relative_addition(added, running) == 0.5
    brighter = running.copy()
    brighter[2, 0] = 1.0                     # now bright: its 0.9 counts
    assert relative_addition(added, brighter) == 0.9
    # any shape with channels last, e.g. (D, H, W, C)
    assert relative_addition(added.reshape(2, 1, 2, 2), running.reshape(2, 1, 2, 2)) == 0.5
    # nothing bright (all zero): 0
    assert relative_addition(np.ones((3, 2)), np.zeros((3, 2))) == 0.0
    # a channel whose running sum is zero everywhere has no bright cell (0 >= 1 % of 0 is not enough)
    assert relative_addition(np.array([[0.1, 5.0]]), np.array([[1.0, 0.0]])) == 0.1


def own_relative_addition(added, running):
    """The module docstring's definition, channel by channel."""
    ratios = [0.0]
    for c in range(running.shape[-1]):
        bright = (running[..., c] >= 0.01 * running[..., c].max()) & (running[..., c] > 0.0)
        if bright.any():
            ratios.append(np.max(added[..., c][bright] / running[..., c][bright]))
    return max(ratios)


def test_relative_addition_and_check_finite_over_many_blocks():
    """Tables of several BLOCK_CELLS blocks (the stopping test and the finiteness check work block by block,
    to keep their temporaries small): the same value as the definition over the whole table, exactly (max is
    exact in any grouping), wherever the largest ratio and the channel maxima lie; a NaN in any block
    carries through / is refused."""
    from clsky.errors import NumericalError
    from clsky.orders import BLOCK_CELLS, check_finite

    rng = np.random.default_rng(7)
    cells = 7 * ((3 * BLOCK_CELLS + 120) // 7)          # three full blocks and a partial one
    running = rng.uniform(0.0, 1.0, (cells, 3)) ** 4   # many dark cells (below 1 % of the channel max)
    added = rng.uniform(0.0, 0.01, (cells, 3)) * running
    running[2 * BLOCK_CELLS + 5, 1], added[2 * BLOCK_CELLS + 5, 1] = 0.5, 0.15   # the largest ratio, 3rd block
    running[-1, 2] = 10.0                                                        # a channel maximum, last block
    expected = own_relative_addition(added, running)
    assert expected == 0.3                  # every other ratio is below 0.01
    assert relative_addition(added, running) == expected
    assert relative_addition(added.reshape(-1, 7, 3), running.reshape(-1, 7, 3)) == expected
    added[BLOCK_CELLS + 1, 0], running[BLOCK_CELLS + 1, 0] = np.nan, 1.0
    assert np.isnan(relative_addition(added, running))
    settings, atmosphere = TableSettings(), black_preset("physical")
    assert check_finite(running[:-2], 2, atmosphere, settings) is not None
    order = np.ones((cells, 3))
    order[-1, 2] = np.inf                                # only in the last, partial block
    with pytest.raises(NumericalError, match="order 2 of the table has"):
        check_finite(order, 2, atmosphere, settings)


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("orders", [5, "auto"])
def test_record_follows_the_definitions(orders_of, mode, orders):
    """relative_additions, shares and (for 'auto') the geometric tail's ratio, estimated errors and
    combination, recomputed from the orders with own code."""
    result = orders_of(black_preset("physical"), SMALL.replace(mode=mode, orders=orders))
    single = result.orders[0]
    running = single.copy() if mode == "atmosphere-plus" else single[..., :3] + single[..., 3:]
    totals = np.array([channel_totals(order) for order in result.orders])
    for k, new in enumerate(result.orders[1:]):
        running = running + new
        assert result.record["relative_additions"][k] == pytest.approx(own_relative_addition(new, running),
                                                                      rel=1e-15, abs=0)
        if orders == "auto" and k >= 1:      # from order 3 on: |L_k - r L_(k-1)| / (1 - r)^2 over the sum
            r = np.tile(totals[k + 1] / totals[k], new.shape[-1] // 3)
            estimate = np.abs(new - r * result.orders[k]) / (1.0 - r) ** 2
            assert result.record["estimated_errors"][k] == pytest.approx(own_relative_addition(estimate, running),
                                                                            rel=1e-13, abs=0)
    assert_allclose(result.record["shares"], totals / totals.sum(axis=0), rtol=1e-14, atol=1e-17)
    assert_allclose(np.sum(result.record["shares"], axis=0), 1.0, rtol=1e-14)
    if orders == "auto":
        r = totals[-1] / totals[-2]
        # sums of the same positive values in another order (ours and clsky's _total): 1e-13
        assert_allclose(result.record["tail_ratio"], r, rtol=1e-13)
        tail = result.orders[-1] * np.tile(r / (1.0 - r), result.orders[-1].shape[-1] // 3)
        plain = sum(result.orders) if mode == "atmosphere-plus" else np.concatenate(
            [single, sum(result.orders[1:])], axis=-1)
        expected = plain + (tail if mode == "atmosphere-plus" else np.concatenate([0 * single, tail], axis=-1))
        assert_allclose(result.combined(mode), expected, rtol=1e-13, atol=0)
    else:
        assert result.tail is None and result.record["tail_ratio"] is None
        assert result.record["estimated_errors"] == result.record["relative_additions"]


def test_relative_addition_with_the_geometric_tail_on_hand_made_arrays():
    """With previous and ratio: max over bright cells of |added - r previous| / (1 - r)^2 / running, r per
    wavelength, both species' channels of a wavelength alike."""
    running = np.array([[10.0, 10.0, 10.0, 10.0, 10.0, 10.0],
                        [0.01, 10.0, 10.0, 10.0, 10.0, 10.0]])    # cell 1, channel 0: dark (0.1 % of the max)
    previous = np.full((2, 6), 1.0)
    added = np.array([[0.5, 0.25, 0.1, 0.5, 0.25, 0.1],           # exactly r previous: no error
                      [0.9, 0.25, 0.1, 0.5, 0.25, 0.125]])       # dark 0.9 ignored; Mie b: 0.025 off r
    ratio = np.array([0.5, 0.25, 0.1])
    assert relative_addition(added[:1], running[:1], previous[:1], ratio) == 0.0
    expected = 0.025 / 0.9 ** 2 / 10.0
    assert relative_addition(added, running, previous, ratio) == pytest.approx(expected, rel=1e-14)
    # three channels: one per wavelength
    assert relative_addition(added[:, 3:], running[:, 3:], previous[:, 3:], ratio) == pytest.approx(expected,
                                                                                                    rel=1e-14)


def test_geometric_ratio_and_tail_factor():
    from clsky.orders import geometric_ratio, tail_factor

    single, second, third = np.array([10.0, 10.0, 10.0]), np.array([4.0, 5.0, 6.0]), np.array([1.0, 2.5, 3.0])
    assert geometric_ratio([single, second]) is None                 # needs two higher orders
    assert_allclose(geometric_ratio([single, second, third]), [0.25, 0.5, 0.5], rtol=0, atol=0)
    assert geometric_ratio([single, second, np.array([1.0, 5.0, 3.0])]) is None     # r = 1 in g
    assert geometric_ratio([single, np.array([4.0, 0.0, 6.0]), third]) is None      # no light in g
    assert_allclose(tail_factor(np.array([0.25, 0.5, 0.9])), [1 / 3, 1.0, 9.0], rtol=1e-15)


TAIL_CASES = {     # (atmosphere, settings): a black ground, an optically thick one (r ~ 0.89), a ground
    "physical": (lambda: black_preset("physical"), SMALL.replace(mode="physical")),
    "thick atmosphere-plus": (lambda: thick(black_preset("physical")),
                              THICK_SETTINGS.replace(mode="atmosphere-plus")),
    "ground": (lambda: preset("physical"), SMALL.replace(mode="physical")),
}


@pytest.mark.parametrize("case", TAIL_CASES)
def test_geometric_tail_against_many_orders(orders_of, case):
    """'auto' with its geometric tail against the plain sum of so many orders that the last added
    1e-10 or less: the table, the ray march's gathered source and the ground's irradiance within the
    tolerance (1e-4) in the bright part, which the stopping rule's error estimate aims at (measured
    2.9e-5, 7.8e-5 and 2.2e-5 for the tables, 7.6e-5 at most elsewhere), and the tail at least 3x closer
    than the plain sum of the same orders (measured 9x, 16x and 9x): the tail adds the light of the
    orders left out, where a wrong tail would add error."""
    make_atmosphere, settings = TAIL_CASES[case]
    atmosphere = make_atmosphere()
    result = orders_of(atmosphere, settings)
    many = orders_of(atmosphere, settings.replace(orders=200 if "thick" in case else 40))
    assert many.record["relative_additions"][-1] < 1e-10
    assert result.record["converged"] and result.tail is not None
    tolerance = settings.order_tolerance
    mode = settings.mode
    expected = many.combined(mode)
    with_tail = result.combined(mode)
    plain = OrdersResult(result.orders, {}).combined(mode)
    error, plain_error = own_relative_addition(np.abs(with_tail - expected), expected), \
        own_relative_addition(np.abs(plain - expected), expected)
    print(f"{case}: {result.record['orders']} orders, table error {error:.2e} (plain sum {plain_error:.2e})")
    assert error < tolerance and 3 * error < plain_error
    assert own_relative_addition(np.abs(result.gathered - many.gathered), many.gathered) < tolerance
    if atmosphere.has_ground:
        assert own_relative_addition(np.abs(result.ground_irradiance - many.ground_irradiance),
                                     many.ground_irradiance) < tolerance


# 6. Table round trip with orders --------------------------------------------------------------------

def test_table_round_trip_with_orders(cl_context, tmp_path):
    settings = SMALL.replace(mode="physical")
    table = ScatteringTable.build(black_preset("physical"), settings, ctx=cl_context)
    assert table.data.shape == (7, 33, 9, 9)
    record = table.orders_record
    assert record["converged"] and len(table.orders) == record["orders"]
    loaded = ScatteringTable.load(table.save(tmp_path / "physical.npz"))

    assert len(loaded.orders) == len(table.orders) == loaded.orders_record["orders"]
    assert loaded.orders_record == record
    assert loaded.data.dtype == np.float64 and np.array_equal(loaded.data, table.data)
    assert loaded.settings == table.settings and loaded.atmosphere == table.atmosphere
    for k, (stored, built) in enumerate(zip(loaded.orders, table.orders), start=1):
        assert stored.shape == built.shape == (7, 33, 9, 6 if k == 1 else 3)
        assert np.array_equal(stored, built.astype(np.float32))          # orders are kept as float32
    # the data: single scattering factored, then the sum of the phased higher orders and their geometric
    # tail (the record's ratio r per wavelength: r / (1 - r) times the last order)
    assert np.array_equal(loaded.data[..., :6], table.orders[0])
    r = np.array(record["tail_ratio"])
    assert_allclose(loaded.data[..., 6:], np.sum(table.orders[1:], axis=0) + table.orders[-1] * (r / (1 - r)),
                    rtol=1e-15, atol=0)

    rng = np.random.default_rng(5)
    n = 5000
    altitude = rng.uniform(0.0, 1.5e5, n)
    cos_view, cos_sun = rng.uniform(-1.0, 1.0, n), rng.uniform(-1.0, 1.0, n)
    cos_scatter = np.clip(cos_view * cos_sun + np.sqrt((1 - cos_view**2) * (1 - cos_sun**2))
                          * np.cos(rng.uniform(0.0, math.pi, n)), -1.0, 1.0)
    queries = (altitude, cos_view, cos_sun, cos_scatter)
    twin = reference.lookup(loaded.atmosphere, loaded.data, *queries, mapping=settings.mapping)
    kernel = loaded.radiance(*queries, engine=TableLookupEngine(ctx=cl_context))
    print(max_error_report(kernel, twin, "9-channel lookup"))
    # same trilinear weights and phases (test_lookup.py): a few ulps of the largest radiance
    assert_allclose(kernel, twin, rtol=1e-12, atol=1e-14 * twin.max())
    assert np.array_equal(loaded.radiance(*queries, backend="numpy"), table.radiance(*queries, backend="numpy"))


def test_uniform_sampling_on_thick_atmosphere_is_reported_diverging_with_harmonics(cl_context):
    """The harmonic orders loop (clsky/azimuth.py), which every planned twilight table takes, had no
    divergence stop: on the x20 atmosphere it ran to max_orders and said 'not converged'. It now stops
    as the azimuth-average loop does, with the same reason, and its record has the same form."""
    settings = SMALL.replace(sampling="uniform", max_orders=50, mode="physical")
    plain = compute_orders(thick(black_preset("physical")), settings, ctx=cl_context).record
    record = compute_orders(thick(black_preset("physical")), settings.replace(azimuth_harmonics=2),
                            ctx=cl_context).record
    assert record["converged"] is False and record["reason"].startswith("diverging: orders "), record["reason"]
    assert record["orders"] < 50
    assert set(record) == set(plain) | {"azimuth_harmonics"}
    assert len(record["relative_additions"]) == len(record["estimated_errors"]) == record["orders"] - 1
