"""OpenCL kernels against their NumPy twins (clsky.reference), for float64 and float32 kernels.

SingleScatteringEngine.compute vs reference.single_scattering, TransmittanceEngine.optical_depth vs
reference.optical_depth and TransmittanceEngine.column_density_table vs reference.transmittance_table,
on small grids and for each settings variant. float32 kernels are compared with the float64 twin;
the tolerances (and what was measured) are in conftest.TOLERANCES.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl
import pytest
from numpy.testing import assert_allclose

from clsky import TableSettings, preset
from clsky import reference

from conftest import black_preset, TOLERANCES, compute_single, max_error_report, require_dtype

SMALL = TableSettings(size=(9, 33, 7))

SETTINGS_VARIANTS = {
    "default": SMALL,
    "keller_bohn": SMALL.replace(sampling="keller_bohn"),
    "ground_end": SMALL.replace(sampling="ground_end"),
    "ground_end_table": SMALL.replace(sampling="ground_end", sun_transmittance="table", transmittance_size=(16, 33)),
    "sun_table": SMALL.replace(sun_transmittance="table"),
    "linear": SMALL.replace(mapping="linear"),
    "few_steps": SMALL.replace(view_steps=4, sun_steps=3),
    "keller_bohn_table_few_steps": SMALL.replace(sampling="keller_bohn", sun_transmittance="table",
                                                 view_steps=5, sun_steps=4, transmittance_size=(16, 33)),
    "single_step": SMALL.replace(view_steps=1, sun_steps=1, size=(8, 17, 5)),
    # a scene's sub-range of the sun axis (clsky/planner.py): nodes from 69.5 deg to 110.5 deg zenith
    "sun_range": SMALL.replace(sun_cos_range=(-0.35, 0.35)),
}


def dense_atmosphere():
    """The default atmosphere with 20x its Rayleigh scattering: optical depths up to ~240 near the horizon."""
    base = black_preset("atmosphere-plus")
    return base.replace(rayleigh_scattering=tuple(20 * np.array(base.rayleigh_scattering)))


ATMOSPHERES = {
    "atmosphere-plus": black_preset("atmosphere-plus"),
    "physical": black_preset("physical"),
    "dense": dense_atmosphere(),
}


@pytest.fixture(scope="module")
def single_reference():
    """``single_reference(atmosphere_name, variant)``: the float64 twin's table, computed once."""
    cache = {}

    def get(atmosphere_name, variant):
        key = (atmosphere_name, variant)
        if key not in cache:
            cache[key] = reference.single_scattering(ATMOSPHERES[atmosphere_name], SETTINGS_VARIANTS[variant])
        return cache[key]

    return get


def assert_close_to_twin(actual, desired, tolerance, label):
    """assert_allclose with the tolerance-table entry; the largest error is logged either way."""
    print(max_error_report(actual, desired, label))
    assert actual.shape == desired.shape
    assert np.all(np.isfinite(actual))
    assert_allclose(actual, desired, rtol=tolerance.rtol, atol=tolerance.atol(desired))


# Single scattering --------------------------------------------------------------------------------

@pytest.mark.parametrize("atmosphere_name", sorted(ATMOSPHERES))
@pytest.mark.parametrize("variant", sorted(SETTINGS_VARIANTS))
def test_single_scattering_kernel_matches_twin(single_engine, single_reference, dtype, variant, atmosphere_name):
    settings = SETTINGS_VARIANTS[variant].replace(dtype=dtype)
    table = compute_single(single_engine, ATMOSPHERES[atmosphere_name], settings)
    expected = single_reference(atmosphere_name, variant)
    key = "single_scattering_table" if settings.sun_transmittance == "table" else "single_scattering"
    assert_close_to_twin(table, expected, TOLERANCES[dtype][key], f"{variant} {atmosphere_name} {dtype}")
    assert table.dtype == np.float64                   # returned as float64 whatever the kernel precision
    # where the twin is exactly zero (planet shadow, empty paths) the kernel is exactly zero too
    assert np.all(table[expected == 0.0] == 0.0)
    assert np.all(table >= 0.0)


def test_single_scattering_does_not_depend_on_the_phase_functions(single_engine):
    """Ibar^(1) carries no phase function (physics.md): both presets give the same table (the physical
    preset without its ozone, the presets' other difference)."""
    artistic = compute_single(single_engine, black_preset("atmosphere-plus"), SMALL)
    physical = compute_single(single_engine, black_preset("physical").replace(ozone_column_du=0.0), SMALL)
    assert np.array_equal(artistic, physical)


def test_one_engine_serves_any_size_and_mapping(single_engine):
    """Size and mapping are per-call values: an engine built for another size gives the same table."""
    engine = single_engine(TableSettings(size=(32, 256, 32)))
    atmosphere = black_preset("atmosphere-plus")
    for settings in (SMALL, SMALL.replace(mapping="linear", size=(5, 9, 3))):
        table = engine.compute(atmosphere, size=settings.size, mapping=settings.mapping)
        expected = reference.single_scattering(atmosphere, settings)
        assert_close_to_twin(table, expected, TOLERANCES["float64"]["single_scattering"],
                             f"per-call {settings.size} {settings.mapping}")


@pytest.mark.parametrize("sun_transmittance", ["table", "march"])
def test_sun_nodes_per_work_item_change_no_bit(cl_context, dtype, sun_transmittance, monkeypatch):
    """A work-item marches a view ray once for SINGLE_SUN_NODES sun nodes (kernels/single.cl): each node's
    sums are the operations of a ray marched for it alone, so the table is the one of one sun node per
    work-item bit for bit, also across launch slabs that end inside a work-item's block of nodes (depth
    27: slabs of 16 and 11 layers), on an ozone atmosphere with a ground (its columns and densities);
    and progress is reported once per slab.

    Bit for bit on CPUs (PoCL, Intel's runtime) in both precisions. On an NVIDIA H200 with the sun table
    not quite: in double8 float32 differed (847 of 23166 values, by at most 0.84 float32 epsilon of the
    maximum), in the scalar form, a GPU's default, float64 (1382 values, 0.84 float64 epsilon); the march
    was bit for bit. The cause is NVIDIA's compiler contracting products and sums into FMAs, which OpenCL
    allows by default: with ``#pragma OPENCL FP_CONTRACT OFF`` before every kernel file all eight cases
    (two widths, two precisions, table and march) were bit for bit there (2026-12-04). So on devices other
    than CPUs both precisions are held to 2 epsilon of the maximum."""
    from clsky import single

    require_dtype(cl_context, dtype)
    settings = TableSettings(size=(11, 13, 27), dtype=dtype, sun_transmittance=sun_transmittance, view_steps=12,
                             sun_steps=6, transmittance_size=(16, 33))
    atmosphere = preset("physical")
    assert single.SINGLE_SUN_NODES == 8 and single.SLAB_LAYERS == 16
    calls = []
    shared = single.SingleScatteringEngine(settings, ctx=cl_context).compute(
        atmosphere, progress=lambda done, total: calls.append((done, total)))
    assert calls == [(1, 2), (2, 2)]
    monkeypatch.setattr(single, "SINGLE_SUN_NODES", 1)
    monkeypatch.setattr(single, "SLAB_LAYERS", 4)
    alone = single.SingleScatteringEngine(settings, ctx=cl_context).compute(atmosphere)
    if cl_context.devices[0].type & cl.device_type.CPU:
        assert np.array_equal(shared, alone)
    else:
        assert np.abs(shared - alone).max() <= 2 * np.finfo(dtype).eps * alone.max()
    assert np.all(shared >= 0) and shared.max() > 0


@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_near_ground_grid_matches_twin(single_engine, cl_context, precision):
    """The default grid's altitude nodes (W = 32: 104 m, 416 m, ...) with 64 view directions, sun at the
    nadir and the zenith: rays that graze the ground are ill-conditioned, a stress test of the geometry.
    (float32 failed here while the helpers took radii r = Rp + h, which rounds h to 0.5 m; they now
    take the altitude.)"""
    require_dtype(cl_context, precision)
    settings = TableSettings(size=(32, 64, 2), dtype=precision)
    atmosphere = black_preset("atmosphere-plus")
    table = compute_single(single_engine, atmosphere, settings)
    expected = reference.single_scattering(atmosphere, settings.replace(dtype="float64"))
    assert_close_to_twin(table, expected, TOLERANCES[precision]["single_scattering"],
                         f"near-ground grid {precision}")


@pytest.mark.parametrize("preset_name", ["atmosphere-plus", "physical"])
def test_default_size_table_is_finite_and_non_negative(single_engine, preset_name):
    """The full default 32 x 256 x 32 table (OpenCL only; ~0.7 s)."""
    table = compute_single(single_engine, black_preset(preset_name), TableSettings())
    assert table.shape == (32, 256, 32, 6)
    assert np.all(np.isfinite(table))
    assert np.all(table >= 0.0)
    assert table.max() > 0.0


# Transmittance ------------------------------------------------------------------------------------

def random_segments(atmosphere, count=3000, seed=0):
    """Segments inside the atmosphere (altitude, cos zenith, length), with the edge cases appended."""
    rng = np.random.default_rng(seed)
    rp, ra = atmosphere.planet_radius, atmosphere.top_radius
    altitude = rng.uniform(0.0, atmosphere.atmosphere_height, count)
    altitude[: count // 3] = rng.uniform(0.0, 3000.0, count // 3)           # near the ground, where Mie lives
    cos_zenith = rng.uniform(-1.0, 1.0, count)
    hits_ground = cos_zenith < reference.horizon_cos(altitude, rp)
    full = np.where(hits_ground, reference.distance_to_ground(altitude, cos_zenith, rp),
                    reference.distance_to_top(altitude, cos_zenith, rp, ra))
    length = full * rng.uniform(0.0, 1.0, count)
    length[: count // 10] = full[: count // 10]                                 # whole paths
    edges_altitude = [0.0, 0.0, 0.0, atmosphere.atmosphere_height, atmosphere.atmosphere_height, 50_000.0]
    edges_cos = [1.0, 0.0, -1.0, -1.0, 0.0, 1.0]
    edges_length = [atmosphere.atmosphere_height, reference.distance_to_top(0.0, 0.0, rp, ra), 0.0,
                    atmosphere.atmosphere_height, reference.distance_to_top(ra - rp, 0.0, rp, ra), 0.0]
    return (np.concatenate([altitude, edges_altitude]), np.concatenate([cos_zenith, edges_cos]),
            np.concatenate([length, edges_length]))


@pytest.mark.parametrize("atmosphere_name", ["atmosphere-plus", "dense"])
@pytest.mark.parametrize("steps, sampling", [(30, "uniform"), (30, "keller_bohn"), (4, "uniform"), (1, "uniform")])
def test_optical_depth_kernel_matches_twin(transmittance_engine, dtype, steps, sampling, atmosphere_name):
    atmosphere = ATMOSPHERES[atmosphere_name]
    altitude, cos_zenith, length = random_segments(atmosphere)
    tau = transmittance_engine(steps, sampling, dtype).optical_depth(atmosphere, altitude, cos_zenith, length)
    expected = reference.optical_depth(atmosphere, altitude, cos_zenith, length, steps, sampling)
    assert_close_to_twin(tau, expected, TOLERANCES[dtype]["optical_depth"],
                         f"optical depth {steps} {sampling} {atmosphere_name} {dtype}")
    transmittance = transmittance_engine(steps, sampling, dtype).transmittance(atmosphere, altitude, cos_zenith,
                                                                               length)
    assert_allclose(transmittance, np.exp(-tau), rtol=1e-15, atol=0)     # the same exp in NumPy


def test_optical_depth_keeps_the_broadcast_shape(transmittance_engine):
    atmosphere = black_preset("atmosphere-plus")
    engine = transmittance_engine()
    altitude = np.array([[0.0], [1000.0]])
    tau = engine.optical_depth(atmosphere, altitude, np.array([0.0, 0.5, 1.0]), 10_000.0)
    assert tau.shape == (2, 3, 3)
    assert engine.optical_depth(atmosphere, 0.0, 1.0, 1000.0).shape == (3,)
    assert engine.optical_depth(atmosphere, np.zeros(0), 1.0, 1.0).shape == (0, 3)
    expected = reference.optical_depth(atmosphere, altitude, np.array([0.0, 0.5, 1.0]), 10_000.0)
    assert_allclose(tau, expected, rtol=TOLERANCES["float64"]["optical_depth"].rtol, atol=0)


@pytest.mark.parametrize("name, value", [("altitude", np.nan), ("altitude", -1.0), ("altitude", 1e6),
                                         ("cos_zenith", 1.5), ("cos_zenith", np.inf), ("length", -5.0),
                                         ("length", np.nan)])
def test_optical_depth_rejects_bad_segments(transmittance_engine, name, value):
    segment = {"altitude": 1000.0, "cos_zenith": 0.5, "length": 1000.0, name: value}
    with pytest.raises(ValueError, match=name):
        transmittance_engine().optical_depth(black_preset("atmosphere-plus"), **segment)


@pytest.mark.parametrize("size", [(9, 17), (64, 256), (2, 2)])
@pytest.mark.parametrize("steps, sampling", [(30, "uniform"), (30, "keller_bohn"), (4, "keller_bohn")])
def test_column_density_table_kernel_matches_twin(transmittance_engine, dtype, steps, sampling, size):
    atmosphere = black_preset("atmosphere-plus")
    table = transmittance_engine(steps, sampling, dtype).column_density_table(atmosphere, size)
    expected = reference.transmittance_table(atmosphere, size, steps, sampling)
    assert table.shape == (size[1], size[0], 2)
    tolerance = TOLERANCES[dtype]["column_density_table"]
    for channel, name in enumerate(("C_R", "C_M")):     # the two columns differ in scale by ~10x
        assert_close_to_twin(table[..., channel], expected[..., channel], tolerance,
                             f"column table {size} {steps} {sampling} {dtype} {name}")
    # nodes at the top looking up (or along the horizontal): nothing left to cross, exactly
    _, mu = reference.transmittance_table_nodes(atmosphere, size)
    assert np.all(table[:, -1][mu[:, -1] >= 0] == 0.0)
    assert np.all(table[expected == 0.0] == 0.0)


@pytest.mark.parametrize("change, message", [
    (dict(length=-50_000.0), r"^length must be finite and in \[0, 1.2942e\+07\] m, got -50000$"),   # T was 3.5
    (dict(altitude=np.nan), r"^altitude must be finite and in \[0, 100000\] m, got nan$"),           # T was NaN
    (dict(steps=0), r"^steps must be an integer in \[1, 1000000\], got 0$"),              # T was 1
    (dict(sampling="bogus"), r"^sampling must be one of "),                               # taken as uniform
])
def test_the_transmittance_twin_checks_its_segments_as_the_kernel_does(change, message):
    """reference.transmittance (and optical_depth, column_density) took what TransmittanceEngine refuses."""
    arguments = dict(altitude=0.0, cos_zenith=0.5, length=1000.0, steps=30, sampling="uniform") | change
    with pytest.raises(ValueError, match=message):
        reference.transmittance(preset("physical"), **arguments)
