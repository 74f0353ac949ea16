"""The 4D table (clsky/table4d.py): mappings, kernels against their NumPy twins, the horizon seam,
agreement with the 3D table where the two must agree, extremes and validation.

Checks that share no formula with the code under test: the mapping round trips go through explicit
ray lengths (the quadratic |P + d V| = R solved here); the 3D table (orders loop and single
scattering kernels of the 3D grid) stands for the 4D table at the zenith, where the view mapping of
both has a node and the azimuth does not exist.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from clsky import ScatteringTable, TableSettings, reference
from clsky.atmosphere import preset
from clsky.errors import ParameterError
from clsky.lookup4d import TableLookup4DEngine
from clsky.mapping import (azimuth4d_nodes, azimuth4d_to_a, cos_azimuth, scatter_cos, view4d_to_y,
                           y_to_view4d)
from clsky.render import SkyRenderer, sun_disc_radiance
from clsky.table4d import compute_data

TINY4D = TableSettings(size=(6, 8, 6), mode="physical", parameterization="4d", azimuth_size=5,
                       azimuth_harmonics=2, view_steps=8, sun_steps=8, gather_theta_steps=16, gather_phi_steps=16,
                       transmittance_size=(16, 32), multiple_view_steps=None)


@pytest.fixture(scope="module")
def atmosphere():
    return preset("atmosphere-plus")


@pytest.fixture(scope="module")
def table4d(atmosphere):
    return ScatteringTable.build(atmosphere, TINY4D)


def _length_to(r, mu, radius, far):
    """Distance along mu from radius r to the sphere of ``radius``: the larger root of the quadratic
    d^2 + 2 r mu d + r^2 - radius^2 = 0 (``far``, the top) or the smaller (the ground)."""
    root = np.sqrt(np.maximum(r * r * (mu * mu - 1.0) + radius * radius, 0.0))
    return -r * mu + root if far else -r * mu - root


@pytest.mark.parametrize("altitude", [50.0, 3000.0, 40e3, 100e3])
def test_view_mapping_round_trip_and_ray_lengths(atmosphere, altitude):
    """Nodes -> cosines -> nodes, and every node's ray length is the linear one of the mapping (explicit
    quadratic here). The horizon nodes sit HORIZON_MARGIN = 1e-14 off the horizon, which moves their ray
    length by r sqrt(2 |mu_h| 1e-14) (<= 0.4 km of >= 25 km): 2e-3 of a node at most (measured 1.3e-4)."""
    rp, ra, height = atmosphere.planet_radius, atmosphere.top_radius, 16
    y = np.arange(height)
    mu = y_to_view4d(altitude, y, height, rp, ra)
    assert np.all(np.diff(mu) > 0)
    got = view4d_to_y(altitude, mu, height, rp, ra)
    horizon = (y == height // 2 - 1) | (y == height // 2)
    assert_allclose(got[~horizon], y[~horizon], rtol=0, atol=1e-9)   # rounding of d near tangents: 1e-12 measured
    assert_allclose(got[horizon], y[horizon], rtol=0, atol=2e-3)
    r = rp + altitude
    rho, k = math.sqrt(altitude * (2 * rp + altitude)), math.sqrt(ra * ra - rp * rp)
    half = height // 2
    ground = y < half
    lengths = np.where(ground, _length_to(r, mu, rp, False), _length_to(r, mu, ra, True))
    x = np.where(ground, y / (half - 1), 1.0 - (y - half) / (half - 1))
    expected = np.where(ground, altitude + x * (rho - altitude), (ra - r) + x * (rho + k - (ra - r)))
    # the plain quadratic loses |r^2 mu^2| u / root near the tangent: 1e-6 relative measured at the horizon nodes
    assert_allclose(lengths[~horizon], expected[~horizon], rtol=1e-6, atol=1e-3)   # 1 mm: d = 0 at the top


def test_view_mapping_is_continuous_within_each_side(atmosphere):
    """Random cosines away from the horizon (1e-6 in mu) go to nodes and back within 1e-9."""
    rng = np.random.default_rng(4)
    rp, ra = atmosphere.planet_radius, atmosphere.top_radius
    h = rng.uniform(1.0, 1e5, 4000)
    mu = rng.uniform(-1.0, 1.0, 4000)
    mu = mu[np.abs(mu - reference.horizon_cos(h[:mu.size], rp)) > 1e-6]
    h = h[:mu.size]
    y = view4d_to_y(h, mu, 64, rp, ra)
    back = y_to_view4d(h, y, 64, rp, ra)
    assert_allclose(back, mu, rtol=0, atol=1e-9)


def test_azimuth_mapping_round_trip():
    """phi nodes -> nu -> node coordinate; acos near cos phi = +-1 loses sqrt(u): 1e-7 of a node."""
    size = 9
    mu_v, mu_s = np.meshgrid(np.linspace(-0.95, 0.95, 7), np.linspace(-0.9, 0.9, 5))
    for a, phi in enumerate(azimuth4d_nodes(size)):
        fa = azimuth4d_to_a(mu_v, mu_s, scatter_cos(mu_v, mu_s, phi), size)
        assert_allclose(fa, a, rtol=0, atol=1e-6)
    assert cos_azimuth(1.0, 0.3, 0.3) == 1.0          # a vertical view has no azimuth: node 0


def _random_queries(rng, n):
    h = rng.choice([0.0, 10.0, 3e3, 5e4, 1e5, 2e5], n)
    mu_v, mu_s = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)
    nu = scatter_cos(mu_v, mu_s, rng.uniform(0, math.pi, n))
    keep = np.abs(cos_azimuth(mu_v, mu_s, nu)) < 1 - 1e-6
    return h[keep], mu_v[keep], mu_s[keep], nu[keep]


def test_lookup4d_kernel_matches_twin(atmosphere, cl_context):
    """Random table values and queries: same coordinates and weights, 1e-12 (conftest's float64 lookup
    tolerance). Queries with |cos phi| > 1 - 1e-6 are left out: there acos turns a rounding of cos phi
    into 1/sqrt(2e-6) = 700 times as much of phi (measured 8e-12 at 1 - 2e-7); the exact ends are
    tested in test_lookup4d_extremes."""
    rng = np.random.default_rng(1)
    data = rng.random((5, 6, 8, 7, 9))
    queries = _random_queries(rng, 20000)
    engine = TableLookup4DEngine(ctx=cl_context)
    got = engine.radiance(atmosphere, data, *queries)
    expected = reference.lookup4d(atmosphere, data, *queries)
    assert_allclose(got, expected, rtol=1e-12, atol=1e-14 * np.abs(expected).max())


def test_table4d_cells_kernel_matches_twin(atmosphere, table4d, cl_context):
    """OpenCL against backend='numpy' (clsky.reference.table4d_cells), per channel. Rows off the horizon:
    conftest's 'scatter' tolerance (1e-12, atol 1e-14 of the channel max). The ground-side horizon row
    is a ray within 1e-14 of the tangent: its length -r mu - sqrt(r^2 mu^2 - (r^2 - Rp^2)) comes from a
    square root of a difference that cancels to 1e-14 of its terms, so a rounding of 1e-16 changes it by
    ~1e-10 relative (measured 3e-9 on the Mie channel): 1e-7 there."""
    _assert_cells_match_twin(atmosphere, table4d)


def _assert_cells_match_twin(atmosphere, table):
    """The tolerances of test_table4d_cells_kernel_matches_twin, for ``table`` (built with TINY4D)."""
    numpy_data = compute_data(atmosphere, TINY4D, table.gathered, backend="numpy",
                              ground_irradiance=table.ground_irradiance)
    scale = np.abs(numpy_data).reshape(-1, 9).max(axis=0)
    off = np.arange(TINY4D.size[1]) != TINY4D.size[1] // 2 - 1
    error = np.abs(table.data - numpy_data)
    assert np.all(error[:, :, off] <= 1e-12 * np.abs(numpy_data[:, :, off]) + 1e-14 * scale)
    assert np.all(error[:, :, ~off] <= 1e-7 * np.abs(numpy_data[:, :, ~off]) + 1e-14 * scale)


def test_render_lut4d_matches_twin(atmosphere, table4d, cl_context):
    """render_lut4d (host slice + bilinear kernel, or the full table from space) against
    reference.render_table4d (quadrilinear): conftest's 'render_table' tolerance (association of the
    weights; measured 0.17 of it at most)."""
    rng = np.random.default_rng(2)
    directions = rng.normal(size=(3000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    with SkyRenderer(table4d, ctx=cl_context) as renderer:
        for altitude in (0.0, 3000.0, 150e3):
            for zenith in (30.0, 89.0, 95.0):
                sun = np.array([math.sin(math.radians(zenith)), 0.0, math.cos(math.radians(zenith))])
                got = renderer.render_lut4d(directions, sun, altitude)
                expected = reference.render_table4d(atmosphere, table4d.data, TINY4D.mapping, directions, sun, altitude,
                                                    sun_disc_radiance(atmosphere, sun, altitude),
                                                    renderer._cos_sun_radius, TINY4D.sun_cos_range)
                sky = np.abs(expected[directions @ sun < renderer._cos_sun_radius]).max()
                assert_allclose(got, expected, rtol=1e-12, atol=1e-14 * sky)


def test_no_seam_across_the_horizon(atmosphere, cl_context):
    """A table whose ground-side nodes hold 1 and space-side nodes 2 (every channel): a lookup just below
    the horizon reads exactly the ground side, just above exactly the space side, at every altitude,
    from either direction (the kernel never interpolates across nodes H/2 - 1 and H/2)."""
    data = np.ones((5, 6, 8, 7, 9))
    data[:, :, 4:] = 2.0
    engine = TableLookup4DEngine(ctx=cl_context)
    h = np.array([0.0, 10.0, 2000.0, 30e3, 99e3])
    horizon = reference.horizon_cos(h, atmosphere.planet_radius)
    for offset, side in ((-1e-9, 1.0), (-1e-3, 1.0), (1e-9, 2.0), (1e-3, 2.0)):
        mu = np.clip(horizon + offset, -1, 1)
        if offset < 0:
            mu, heights = mu[h > 0], h[h > 0]       # nothing lies below the horizon on the ground
        else:
            heights = h
        ones = np.ones_like(mu)
        got = engine.radiance(atmosphere, data, heights, mu, 0.3 * ones, 0.1 * ones)
        flat = np.full((5, 6, 8, 7, 9), side)
        expected = engine.radiance(atmosphere, flat, heights, mu, 0.3 * ones, 0.1 * ones)
        assert_allclose(got, expected, rtol=1e-15, atol=0)


def test_horizon_limits_of_a_real_table(atmosphere, table4d, cl_context):
    """On the built table: at node altitudes, sun cosines and azimuth 0, a lookup 1e-9 below (above) the
    horizon reads the ground-side (space-side) horizon node's channels, within the fraction of a node
    such an offset moves (<= 1e-3 of a node times the step to the next node)."""
    from clsky.mapping import grid4d_coordinates

    altitudes, _, cos_sun, _ = grid4d_coordinates(TINY4D, atmosphere.planet_radius, atmosphere.top_radius)
    half = TINY4D.size[1] // 2
    for x in range(1, len(altitudes)):
        for z in range(len(cos_sun)):
            h, mu_s = altitudes[x], cos_sun[z]
            horizon = reference.horizon_cos(h, atmosphere.planet_radius)
            for offset, node, neighbour in ((-1e-9, half - 1, half - 2), (1e-9, half, half + 1)):
                mu_v = horizon + offset
                nu = scatter_cos(mu_v, mu_s, 0.0)
                got = reference.lookup4d(atmosphere, table4d.data, h, mu_v, mu_s, nu)
                cell = table4d.data[0, z, node, x]
                step = np.abs(table4d.data[0, z, neighbour, x] - cell)
                expected = reference._radiance_of_channels(atmosphere, cell[None], np.array([nu]))[0]
                bound = reference._radiance_of_channels(atmosphere, (step * 1e-3 + 1e-14 * cell.max())[None],
                                                        np.array([nu]))[0]
                assert np.all(np.abs(got - expected) <= bound), (x, z, offset)


@pytest.mark.parametrize("orders", [6, "auto"])
@pytest.mark.parametrize("harmonics", [0, 2])
def test_zenith_agrees_with_the_3d_table(atmosphere, harmonics, orders):
    """At the zenith (node H - 1 of both view mappings) the azimuth does not exist: every azimuth node of
    the 4D table holds the 3D physical table's single scattering and higher orders (same altitude and
    sun nodes, same quadrature; multiple_view_steps None, so that the 3D orders are integrated with the
    same view steps). With a fixed number of orders the two differ by the order of summation over the
    orders (the 3D table sums the scattered orders, the 4D integrates their gathered sum: linear, 1e-12),
    and for M > 0 by the harmonic transform's rounding (the nodes of a vertical ray are equal). With
    'auto', also by their geometric tails (clsky.orders): the 3D table adds r / (1 - r) times the last
    order L^(K), the 4D table integrates the next order's source G^(K+1) / (1 - r); both estimate the
    orders after K, and differ by about the tail's error, which the stopping rule keeps below the
    tolerance (1e-4) in the bright part: here within the tolerance times the channel's largest value
    (measured 2.3e-7 of it for M = 0 and 1.5e-7 for M = 2); single scattering as with fixed orders."""
    settings = TINY4D.replace(azimuth_harmonics=harmonics, orders=orders)
    four = ScatteringTable.build(atmosphere, settings)
    three = ScatteringTable.build(atmosphere, settings.replace(parameterization="elek3d"))
    assert three.data.shape == (6, 8, 6, 9)
    assert (three.orders_record["tail_ratio"] is not None) == (orders == "auto")
    expected = np.broadcast_to(three.data[:, -1], four.data[:, :, -1].shape)
    scale = np.abs(three.data).reshape(-1, 9).max(axis=0)
    error = np.abs(four.data[:, :, -1] - expected)
    if orders == "auto":
        print(f"largest difference {np.max(error / scale):.2e} of the channel's largest value")
        assert np.all(error[..., :6] <= 1e-10 * np.abs(expected[..., :6]) + 1e-13 * scale[:6])   # single
        assert np.all(error <= settings.order_tolerance * scale)
    else:
        worst = np.max(error / (1e-10 * np.abs(expected) + 1e-13 * scale))
        assert worst <= 1.0, worst


def test_toward_the_sun_agrees_with_the_3d_table(atmosphere):
    """In the sun's vertical plane toward the sun (phi = 0, the 3D table's canonical frame), at the
    altitude and sun nodes of both tables, single scattering of the two differs only by their view
    interpolation: both within 1 % of the exact ray integral (reference.table4d_cells, no
    interpolation) for views 2 to 60 deg high with 64 view nodes, and so within 2 % of each other."""
    from clsky.mapping import grid_coordinates

    settings = TINY4D.replace(size=(6, 64, 6), orders=1, view_steps=16)
    three = ScatteringTable.build(atmosphere, settings.replace(parameterization="elek3d"))
    four = ScatteringTable.build(atmosphere, settings)
    _, _, cos_sun = grid_coordinates(settings.size, atmosphere.atmosphere_height, settings.mapping)
    mu_v = np.sin(np.radians(np.linspace(2, 60, 30)))
    for mu_s in cos_sun[cos_sun > 0.05]:
        nu = scatter_cos(mu_v, mu_s, 0.0)
        exact = reference.table4d_cells(atmosphere, settings, None, np.zeros_like(mu_v), mu_v, np.full_like(mu_v, mu_s),
                                        nu)
        exact = reference._radiance_of_channels(atmosphere, exact, nu)
        a = three.radiance(0.0, mu_v, mu_s, nu, backend="numpy")
        b = four.radiance(0.0, mu_v, mu_s, nu, backend="numpy")
        assert_allclose(a, exact, rtol=0.01)
        assert_allclose(b, exact, rtol=0.01)


def test_lookup4d_extremes(atmosphere, table4d, cl_context):
    """No NaN, Inf or negative radiance at the ends of every axis, on the horizon, from space."""
    values = []
    for h in (0.0, 1e-3, atmosphere.atmosphere_height, 2e5, 1e9):
        for mu_v in (-1.0, -1e-17, 0.0, reference.horizon_cos(h if h < 1e5 else 1e5, atmosphere.planet_radius), 1.0):
            for mu_s in (-1.0, -0.3, 0.0, 1.0):
                for phi in (0.0, math.pi / 2, math.pi):
                    values.append((h, mu_v, mu_s, float(scatter_cos(mu_v, mu_s, phi))))
    h, mu_v, mu_s, nu = (np.array(v) for v in zip(*values))
    for backend in ("opencl", "numpy"):
        radiance = table4d.radiance(h, mu_v, mu_s, nu, backend=backend)
        assert np.all(np.isfinite(radiance)) and np.all(radiance >= 0)


@pytest.mark.parametrize("changes, name", [
    (dict(parameterization="5d"), "parameterization"),
    (dict(azimuth_size=1), "azimuth_size"),
    (dict(azimuth_size=2.5), "azimuth_size"),
    (dict(mode="atmosphere-plus", azimuth_harmonics=0), "parameterization"),
    (dict(size=(6, 9, 6)), "size"),
    (dict(size=(6, 2, 6)), "size"),
    (dict(mie_layout="notes"), "mie_layout"),
])
def test_bad_settings_name_the_parameter(changes, name):
    with pytest.raises(ParameterError) as error:
        TINY4D.replace(**changes)
    assert error.value.field == name


def test_reflecting_ground_needs_the_higher_orders(atmosphere):
    with pytest.raises(ParameterError, match="orders"):
        ScatteringTable.build(atmosphere.replace(ground_albedo=0.2), TINY4D.replace(orders=1))


def test_reflecting_ground_kernel_matches_twin(atmosphere, cl_context):
    """With a ground of albedo 0.3: the channels against the twin (the ground-reflection term shares the
    ray march's code; tolerance as test_table4d_cells_kernel_matches_twin), and every ground-seeing node
    of the lowest altitude holds more higher-order light than over a black ground."""
    ground = atmosphere.replace(ground_albedo=0.3)
    table = ScatteringTable.build(ground, TINY4D)
    _assert_cells_match_twin(ground, table)
    half = TINY4D.size[1] // 2
    black = ScatteringTable.build(atmosphere, TINY4D)
    assert np.all(table.data[:, :, :half - 1, 0, 6:] > black.data[:, :, :half - 1, 0, 6:])   # the ground is seen


def test_3d_settings_keep_their_json():
    """The new settings enter the JSON (and so the parameters hash of every saved 3D table) only away
    from their defaults."""
    assert "parameterization" not in TableSettings().to_dict()
    assert "azimuth_size" not in TableSettings().to_dict()
    assert TableSettings.from_dict(TINY4D.to_dict()) == TINY4D


def test_save_load_round_trip(table4d, tmp_path):
    path = table4d.save(tmp_path / "t.npz")
    loaded = ScatteringTable.load(path)
    assert loaded.settings == TINY4D
    assert np.array_equal(loaded.data, table4d.data)


def test_animation_4d_methods():
    """--method lut4d / compare4d: the table is the 4D one (physical, >= 2 harmonics, at most 16 x 128
    altitude and view nodes, an even view count: a plan's grid reduced to that, a table_size asked for
    built as asked or refused, naming it: 32 x 255 was silently built as 16 x 128); refused, naming
    'method', with the atmosphere-plus mode or with wavelengths."""
    from clsky.anim.animate import LUT4D_HARMONICS, AnimationConfig, _base, _with_lookup

    config = AnimationConfig(method="compare4d", quality="default", table_size=(16, 128, 20))
    assert config.compares and config.lookup4d
    _, settings = _base(config, None)
    assert settings.is_4d and settings.size == (16, 128, 20) and settings.azimuth_harmonics == LUT4D_HARMONICS
    planned = _with_lookup(TableSettings(size=(32, 255, 20), mode="physical"), config)      # a plan's grid
    assert planned.is_4d and planned.size == (16, 128, 20)
    for size in ((32, 128, 20), (16, 130, 20), (8, 31, 8), (8, 2, 8)):
        with pytest.raises(ParameterError, match=r"^table_size must be W <= 16 altitude nodes and an even number H "
                                                 r"in \[4, 128\] of view nodes with method 'compare4d'"):
            AnimationConfig(method="compare4d", table_size=size)
    assert not AnimationConfig(method="lut").lookup4d and not AnimationConfig(method="lut4d").compares
    for bad in (dict(mode="atmosphere-plus", preset="atmosphere-plus"), dict(wavelengths=12)):
        with pytest.raises(ParameterError) as error:
            AnimationConfig(method="lut4d", **bad)
        assert error.value.field == "method"


def test_float32_table_keeps_its_horizon_nodes_on_their_side(atmosphere, cl_context):
    """A float32 build (single scattering) against the float64 twin at its nodes: every view row off the
    horizon within conftest's float32 'scatter' tolerance (2e-5 relative, atol 1e-7 of the channel max),
    the ground-side horizon row within 1e-3: its nodes sit HORIZON_MARGIN_FLOAT32 = 1e-5 off the
    horizon, so that float32 rounding cannot move them across (at 1e-14 that row became rays to space:
    27 times the float64 value)."""
    from clsky.mapping import HORIZON_MARGIN_FLOAT32

    settings = TINY4D.replace(dtype="float32", orders=1)
    single = ScatteringTable.build(atmosphere, settings)
    # the float64 twin at the float32 table's nodes (backend 'numpy' computes in float64 at the nodes of
    # the settings, whose dtype sets the horizon margin)
    expected = compute_data(atmosphere, settings, backend="numpy")
    assert HORIZON_MARGIN_FLOAT32 == 1e-5
    scale = np.abs(expected).reshape(-1, 6).max(axis=0)
    error = np.abs(single.data - expected) / (2e-5 * np.abs(expected) + 1e-7 * scale)
    half = settings.size[1] // 2
    off = np.arange(settings.size[1]) != half - 1
    assert error[:, :, off].max() <= 1.0
    # the ground-side horizon row is a ray 1e-5 from the tangent, whose length comes from a square root
    # of a difference that cancels to ~1e-5 of its terms: float32 rounding of mu (6e-8) becomes ~1e-4 of
    # it (measured 5.8e-5 relative); rays that reach space instead would be 27 times off
    assert np.all(np.abs(single.data - expected)[:, :, ~off] <= 1e-3 * np.abs(expected[:, :, ~off]) + 1e-7 * scale)


def test_cli_builds_and_describes_a_4d_table(tmp_path):
    """clsky table --parameterization 4d writes a 4D table (and its raw export with the 4D layout);
    clsky info names its four axes; a bad combination exits 2 naming the option typed."""
    import json
    import subprocess
    import sys

    run = [sys.executable, "-m", "clsky"]
    output = tmp_path / "t.npz"
    done = subprocess.run(run + ["table", "--preset", "physical", "--mode", "physical", "--parameterization", "4d",
                                 "--size", "6", "8", "6", "--azimuth-size", "5", "--orders", "2", "--view-steps", "8",
                                 "--sun-steps", "8", "--gather-steps", "16", "16", "--progress", "none",
                                 "-o", str(output), "--raw", str(tmp_path / "raw")], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("table 6x8x6x5 float64 ")          # the azimuth axis too (it said 6x8x6)
    assert ScatteringTable.load(output).data.shape == (5, 6, 8, 6, 9)
    header = json.loads((tmp_path / "raw.json").read_text())
    assert header["size"]["A"] == 5 and (tmp_path / "raw.bin").stat().st_size == 5 * 6 * 8 * 6 * 9 * 4
    info = subprocess.run(run + ["info", str(output)], capture_output=True, text=True)
    assert "6 x 8 x 6 x 5 (altitude x view zenith x sun zenith x azimuth, 4D)" in info.stdout
    bad = subprocess.run(run + ["table", "--parameterization", "4d", "--size", "6", "8", "6", "-o",
                                str(tmp_path / "u.npz")], capture_output=True, text=True)
    assert bad.returncode == 2 and "--parameterization" in bad.stderr and "Traceback" not in bad.stderr


def test_raw_export_of_a_4d_table_says_what_its_channels_and_harmonics_are(table4d, tmp_path):
    """The raw header of a 4D table with harmonics described it as a 3D table's: multiple_* channels "the
    azimuth average" (they vary by ~1000x across the azimuth axis of a dusk table) and the harmonics on "the
    table's nodes" (they lie on the 3D grid, its view mapping not view_4d); its nodes' formula gave the 3D
    view axis, v = y/(H-1)."""
    import json

    _, header = table4d.export_raw(tmp_path / "sky")
    description = json.loads(header.read_text())
    # its nodes' formula said v = y/(H-1) beside view_4d: y follows view_4d, the 3D v the harmonics' grid alone
    assert "y: view_4d (not v)" in description["mapping_formulas"]["nodes"]
    assert "3D grid of azimuth_harmonics only" in description["mapping_formulas"]["nodes"]
    block = description["azimuth_harmonics"]
    assert "the nodes of the 3D grid of the same W x H x D" in block["layout"]
    assert description["radiance"].startswith("I = I_I * (F_R(c) * Ibar_R + F_M(c) * Ibar_M + multiple), c = ")
    # without harmonics there is no azimuth_harmonics block for the node formula to point to
    plain = ScatteringTable.build(preset("atmosphere-plus"), TINY4D.replace(azimuth_harmonics=0))
    _, header = plain.export_raw(tmp_path / "plain")
    plain_description = json.loads(header.read_text())
    assert "azimuth_harmonics" not in plain_description
    assert plain_description["mapping_formulas"]["nodes"].endswith("a: azimuth_4d")
    assert "integrated along each 4D node's own ray" in block["radiance"]
    assert "are the azimuth average" not in block["radiance"]
    multiple = table4d.data[..., 6:9]
    assert np.ptp(multiple, axis=0).max() > 0          # they do vary with the azimuth


def test_shape_messages_name_the_4d_axes(table4d):
    """A 5-axis array's shape error labelled its axes '(D, H, W, C)'."""
    import dataclasses

    from clsky.table import TableFormatError

    with pytest.raises(TableFormatError, match=r"data has shape .*, the settings need \(5, 6, 8, 6, 9\) "
                                               r"\(A, D, H, W, C\)$"):
        dataclasses.replace(table4d, data=table4d.data[..., :6]).validate()
    with pytest.raises(TableFormatError, match=r"gathered has shape \(6, 8, 6, 6\), the settings need "
                                               r"\(3, 6, 8, 6, 6\) \(M \+ 1, D, H, W, C\)$"):
        dataclasses.replace(table4d, gathered=table4d.gathered[0]).validate()
