"""The orders k >= 3 scattered on every other sun node (``TableSettings.orders_sun_stride = 2``;
kernels/multiple.cl: scatter's sun_stride and fill_between_suns; clsky.reference.fill_between_sun_nodes).

1. The fill against closed forms: an exponential along the sun axis is filled exactly (the geometric mean
   is exact for it), a node next to a zero takes the mean, the last node of an even axis is computed.
2. The kernels against their twins: the strided scatter and its fill (both modes, a ground, the azimuth
   harmonics, an odd and an even sun axis); the nodes it computes are those of the stride-1 scatter bit
   for bit (the same operations).
3. The orders loops (clsky.orders and clsky.azimuth): OpenCL against NumPy with the stride, order 2
   untouched by it, the orders after it changed a little and only there.
4. The settings: range, the parameters hash at 1, a table file's round trip, the quality levels.
"""

from __future__ import annotations

import numpy as np
import pyopencl.array as cla
import pytest
from numpy.testing import assert_allclose

from clsky import ScatteringTable, TableSettings, azimuth, preset, reference
from clsky.errors import ParameterError
from clsky.multiple import MultipleScatteringEngine
from clsky.orders import SUN_STRIDE_FROM_ORDER, compute_orders, scatter_sun_stride
from clsky.quality import QUALITY_LEVELS
from clsky.settings import computed_sun_nodes

from conftest import TOLERANCES, black_preset, require_dtype
import test_multiple
from test_source_stride import scatter_inputs     # a gathered table in [0.5, 2] and a ground radiance per sun node

#: The fixture ``multiple_engine(settings)`` (cached engines).
multiple_engine = test_multiple.multiple_engine
#: Small grids of an odd and an even number of sun nodes: 3 (one node filled), 7 and 8 (4 and 5 computed,
#: one work-item's SCATTER_SUN_NODES = 8), 18 (10 computed: a second work-item along the sun axis).
GRIDS = {depth: TableSettings(size=(9, 33, depth), gather_theta_steps=64, gather_phi_steps=32)
         for depth in (3, 7, 8, 18)}
#: The kernel tests' sun axes.
DEPTHS = (3, 8, 18)
#: The physical preset with a bright ground, so that the rays that end on it see it.
BRIGHT = preset("physical").replace(ground_albedo=0.3)
#: case -> (atmosphere, mode): the scatter's species combined in the physical mode, a ground seen in "ground".
CASES = {"atmosphere-plus": (black_preset("atmosphere-plus"), "atmosphere-plus"),
         "physical": (black_preset("physical"), "physical"),
         "ground": (BRIGHT, "physical")}


# 1. The fill's closed forms -------------------------------------------------------------------------

@pytest.mark.parametrize("depth", [2, 3, 7, 8])
def test_fill_is_exact_for_an_exponential_along_the_sun_axis(depth):
    """L(z) = A exp(-c z) per cell: the geometric mean of z - 1 and z + 1 is L(z) itself, to rounding: the
    values carry the rounding of their exponent c z (up to 21 here, so up to 21 eps relative), the fill two
    square roots and a product (2 eps): rtol 32 eps; the computed nodes (even, and the last) are untouched."""
    rng = np.random.default_rng(depth)
    amplitude = rng.uniform(0.1, 10.0, (1, 3, 4, 6))
    rate = rng.uniform(0.5, 3.0, (1, 3, 4, 6))
    exact = amplitude * np.exp(-rate * np.arange(depth)[:, None, None, None])
    table = exact.copy()
    table[1:depth - 1:2] = 7.0                               # what the fill must overwrite
    filled = reference.fill_between_sun_nodes(table, 2)
    assert filled is table
    assert_allclose(filled, exact, rtol=32 * np.finfo(float).eps, atol=0.0)
    computed = computed_sun_nodes(depth, 2)
    assert computed == sorted(set(range(0, depth, 2)) | {depth - 1})
    assert np.array_equal(filled[computed], exact[computed])


def test_fill_takes_the_mean_beside_a_zero_and_leaves_stride_one_alone():
    """A neighbour of 0 (no light there: the geometric mean's logarithm is undefined) gives the mean of the
    two, not 0; the channel pair (0, 0) stays 0; stride 1 returns the table unchanged."""
    table = np.zeros((5, 1, 1, 3))
    table[0] = (4.0, 0.0, 0.0)
    table[2] = (1.0, 6.0, 0.0)
    table[4] = (0.0, 2.0, 0.0)
    before = table.copy()
    assert reference.fill_between_sun_nodes(table, 1) is table and np.array_equal(table, before)
    filled = reference.fill_between_sun_nodes(table.copy(), 2)
    assert np.array_equal(filled[1, 0, 0], [2.0, 3.0, 0.0])       # sqrt(4 * 1); the mean beside a 0; 0
    assert np.array_equal(filled[3, 0, 0], [0.5, np.sqrt(6.0) * np.sqrt(2.0), 0.0])


@pytest.mark.parametrize("stride", [0, 3])
def test_another_stride_is_refused_by_the_twin(stride):
    with pytest.raises(ValueError, match=f"sun_stride must be 1 or 2, got {stride}"):
        reference.fill_between_sun_nodes(np.ones((5, 1, 1, 3)), stride)


def test_the_stride_starts_at_order_three():
    settings = TableSettings(orders_sun_stride=2)
    assert SUN_STRIDE_FROM_ORDER == 3
    assert [scatter_sun_stride(settings, k) for k in (2, 3, 7)] == [1, 2, 2]
    assert [scatter_sun_stride(settings.replace(orders_sun_stride=1), k) for k in (2, 3)] == [1, 1]


# 2. The kernels against their twins -------------------------------------------------------------------

def scattered(engine, case, gathered, radiance, sun_stride):
    atmosphere, mode = CASES[case]
    combine = mode == "physical"
    return engine.scatter(atmosphere, gathered, combine_species=combine, ground_radiance=radiance if combine else None,
                          sun_stride=sun_stride).get()


@pytest.mark.parametrize("depth", DEPTHS)
@pytest.mark.parametrize("case", sorted(CASES))
def test_strided_scatter_matches_twin(multiple_engine, case, depth):
    """The strided scatter and its fill against reference.scatter(sun_stride=2): the stride-1 scatter's
    tolerance (conftest.TOLERANCES' scatter; the fill adds two square roots and a product, 2 ulp); nothing
    negative, the padding 0."""
    settings = GRIDS[depth]
    gathered, radiance = scatter_inputs(settings, depth)
    atmosphere, mode = CASES[case]
    combine = mode == "physical"
    actual = scattered(multiple_engine(settings), case, gathered, radiance, 2)
    desired = reference.scatter(atmosphere, settings, gathered, combine, radiance if combine else None, sun_stride=2)
    test_multiple.assert_close_per_channel(actual[..., :6], desired, TOLERANCES["float64"]["scatter"],
                                           f"scatter sun stride 2, {case}, D={depth}")
    assert np.all(actual[..., 6:] == 0.0) and np.all(actual >= 0.0)


@pytest.mark.parametrize("dtype", ["float64", "float32"])
@pytest.mark.parametrize("depth", DEPTHS)
@pytest.mark.parametrize("case", sorted(CASES))
def test_strided_scatter_computes_the_same_nodes_bit_for_bit(cl_context, multiple_engine, case, depth, dtype):
    """The nodes it computes (even, and the last) are the stride-1 scatter's bit for bit, in float64 and
    float32: each is the same operations on the same values, only fewer of them launched; the nodes between
    are the fill's of the stride-1 scatter's nodes, to 4 eps in float64 (two square roots and a product) and
    8 in float32 (OpenCL lets a float sqrt be 3 ulp off), and differ from the stride-1 scatter's (by up to a
    few per cent on these coarse axes)."""
    require_dtype(cl_context, dtype)
    settings = GRIDS[depth].replace(dtype=dtype)
    gathered, radiance = scatter_inputs(settings, 10 + depth)
    engine = multiple_engine(settings)
    every = scattered(engine, case, gathered, radiance, 1)
    strided = scattered(engine, case, gathered, radiance, 2)
    computed = computed_sun_nodes(depth, 2)
    assert np.array_equal(strided[computed], every[computed])
    between = [z for z in range(depth) if z not in computed]
    filled = reference.fill_between_sun_nodes(every.copy(), 2)
    ulps = 4 if dtype == "float64" else 8
    assert_allclose(strided[between], filled[between], rtol=ulps * np.finfo(np.dtype(dtype)).eps, atol=0.0)
    assert not np.array_equal(strided[between], every[between])


def test_strided_scatter_with_harmonics_into_a_node_slab_matches_twin(cl_context):
    """With three azimuth harmonics of both signs, into the slabs of a stack (clsky.azimuth's nodes: the fill
    stays in its slab), against azimuth.scatter_nodes(sun_stride=2) (tests/test_azimuth.py's tolerance)."""
    settings = TableSettings(size=(9, 17, 8), mode="physical", orders=3, gather_theta_steps=32, gather_phi_steps=16,
                             sun_cos_range=(-0.3, 0.4), azimuth_harmonics=2)
    width, height, depth = settings.size
    rng = np.random.default_rng(3)
    gathered = rng.random((3, depth, height, width, 6))
    gathered[1:] = 1.2 * (gathered[1:] - 0.5)
    atmosphere = BRIGHT
    radiance = rng.uniform(0.1, 1.0, (depth, 3))
    expected = azimuth.scatter_nodes(atmosphere, settings, gathered, radiance, sun_stride=2)
    padded = np.zeros(gathered.shape[:-1] + (8,))
    padded[..., :6] = gathered
    engine = MultipleScatteringEngine(settings, ctx=cl_context)
    try:
        padded = cla.to_device(engine.queue, padded)
        nodes = cla.zeros(engine.queue, padded.shape, np.float64)
        for n, phi in enumerate(azimuth.azimuth_nodes(2)):
            engine.scatter(atmosphere, padded, combine_species=True, ground_radiance=radiance,
                           cos_azimuth=np.cos(phi), out=nodes, node=n, sun_stride=2)
        got = nodes.get()
    finally:
        engine.close()
    for n in range(3):
        test_multiple.assert_close_per_channel(got[n, ..., :3], expected[n], TOLERANCES["float64"]["scatter"],
                                               f"harmonics, node {n}")


def test_scatter_refuses_another_sun_stride(multiple_engine):
    settings = GRIDS[7]
    gathered, _ = scatter_inputs(settings, 0)
    with pytest.raises(ValueError, match="sun_stride must be 1 or 2, got 3"):
        multiple_engine(settings).scatter(black_preset("physical"), gathered, sun_stride=3)


# 3. The orders loops ---------------------------------------------------------------------------------

#: (loop, preset): the physical loop of clsky.orders (M = 0) with a ground, and clsky.azimuth's (M = 2).
LOOPS = {"orders, ground": (0, BRIGHT), "azimuth, M = 2": (2, black_preset("physical"))}


@pytest.fixture(scope="module")
def orders_builds(cl_context):
    """``orders_builds(loop, stride, backend)``: compute_orders of 4 orders on the 7-node grid, cached."""
    cache = {}

    def get(loop, stride, backend):
        if (loop, stride, backend) not in cache:
            harmonics, atmosphere = LOOPS[loop]
            settings = GRIDS[7].replace(mode="physical", orders=4, azimuth_harmonics=harmonics,
                                        sun_cos_range=(-0.3, 1.0), orders_sun_stride=stride)
            cache[loop, stride, backend] = compute_orders(atmosphere, settings, backend=backend, ctx=cl_context)
        return cache[loop, stride, backend]

    return get


@pytest.mark.parametrize("loop", sorted(LOOPS))
def test_strided_orders_backends_agree(orders_builds, loop):
    """OpenCL against NumPy with the stride: every order, the gathered sum and the ground's irradiance
    within test_multiple's orders tolerance (conftest.TOLERANCES: K x 1e-12 per order)."""
    kernel, twin = orders_builds(loop, 2, "opencl"), orders_builds(loop, 2, "numpy")
    assert len(kernel.orders) == len(twin.orders) == 4
    for k, (a, b) in enumerate(zip(kernel.orders, twin.orders), start=1):
        test_multiple.assert_close_per_channel(a, b, TOLERANCES["float64"]["orders"], f"{loop}, order {k}")
    test_multiple.assert_close_per_channel(kernel.gathered, twin.gathered, TOLERANCES["float64"]["orders"],
                                           f"{loop}, gathered")
    if kernel.ground_irradiance is not None:
        assert_allclose(kernel.ground_irradiance, twin.ground_irradiance, rtol=1e-10, atol=0.0)
    assert_allclose(kernel.record["relative_additions"], twin.record["relative_additions"], rtol=1e-10, atol=0)


#: Largest change of orders 3 and 4 by the stride on the 7-node grid over sun cosines -0.3 to 1 (relative to
#: that order's largest value; what the fill's guess costs on so coarse an axis): measured 2026-12-07 0.064 and
#: 0.084 (clsky.orders' loop, a ground), 0.260 and 0.258 (clsky.azimuth's, M = 2), doubled and rounded up.
#: The default and high levels' nodes are about 20 and 40 times closer: their frames moved by 3.4e-4 and 8.3e-5 at
#: most (docs/speed-log.md).
STRIDE_CHANGE = {"orders, ground": 0.2, "azimuth, M = 2": 0.6}


@pytest.mark.parametrize("loop", sorted(LOOPS))
def test_the_stride_leaves_order_two_and_changes_the_rest_a_little(orders_builds, loop):
    """Single scattering and order 2 are the stride-1 build's bit for bit (order 2 takes every node:
    SUN_STRIDE_FROM_ORDER); order 3's computed nodes too (its source, order 2's gathered table, is the same);
    the orders after it differ, by at most STRIDE_CHANGE of their largest value and not by nothing."""
    every, strided = orders_builds(loop, 1, "opencl"), orders_builds(loop, 2, "opencl")
    for k in (0, 1):
        assert np.array_equal(strided.orders[k], every.orders[k]), f"order {k + 1}"
    computed = computed_sun_nodes(every.orders[0].shape[0], 2)
    assert np.array_equal(strided.orders[2][computed], every.orders[2][computed])
    for k in (2, 3):
        change = np.max(np.abs(strided.orders[k] - every.orders[k])) / np.max(every.orders[k])
        assert 0.0 < change < STRIDE_CHANGE[loop], f"order {k + 1}: {change:.2e}"
    assert np.all(np.isfinite(strided.gathered)) and np.all(strided.orders[3] >= 0.0)


# 4. The settings -----------------------------------------------------------------------------------

@pytest.mark.parametrize("value", [0, 3, 1.5, "2", True, None])
def test_orders_sun_stride_out_of_range_is_refused(value):
    with pytest.raises(ParameterError, match="orders_sun_stride"):
        TableSettings(orders_sun_stride=value)


def test_orders_sun_stride_leaves_the_parameters_hash_at_one():
    """At 1 the field is absent from to_dict (tables saved before it keep their hash); at 2 it is there and
    round-trips."""
    assert "orders_sun_stride" not in TableSettings().to_dict()
    settings = TableSettings(orders_sun_stride=2)
    assert settings.to_dict()["orders_sun_stride"] == 2
    assert TableSettings.from_dict(settings.to_dict()) == settings


def test_a_strided_table_file_round_trips(cl_context, tmp_path):
    """A table built with the stride saves it and loads it back (the settings and every value)."""
    settings = GRIDS[7].replace(size=(5, 9, 7), mode="physical", orders=3, orders_sun_stride=2)
    table = ScatteringTable.build(black_preset("physical"), settings, ctx=cl_context)
    path = tmp_path / "strided.npz"
    table.save(path)
    loaded = ScatteringTable.load(path)
    assert loaded.settings.orders_sun_stride == 2
    assert np.array_equal(loaded.data, table.data)


def test_quality_levels_that_stride_the_orders_sun_axis():
    """'default' and 'high' (14-16 % less of their build's CPU time, frames moved by 3.4e-4 and 8.3e-5 at most);
    not 'draft' (no gain on its half-second build) nor the 'reference'."""
    assert {name: level.table.orders_sun_stride for name, level in QUALITY_LEVELS.items()} == \
        {"draft": 1, "default": 2, "high": 2, "reference": 1}
