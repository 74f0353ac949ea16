"""Table lookup: the OpenCL kernel against its NumPy twin, and the lookup's own invariants."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from clsky import ScatteringTable, TableSettings, reference
from clsky.lookup import TableLookupEngine
from clsky.table import to_layout

from conftest import black_preset

SIZE = (9, 33, 7)


@pytest.fixture(scope="module")
def lookup_engines():
    return {dtype: TableLookupEngine(dtype=dtype) for dtype in ("float64", "float32")}


@pytest.fixture(scope="module", params=["atmosphere-plus", "physical"])
def table(request):
    return ScatteringTable.build(black_preset(request.param), TableSettings(size=SIZE))


def random_queries(n, seed=1, max_altitude=2.5e5):
    """Valid geometry: the scattering cosine is built from the two zeniths and a random azimuth."""
    rng = np.random.default_rng(seed)
    altitude = rng.uniform(0.0, max_altitude, n)      # inside and above the atmosphere (Ha = 1e5 m)
    cos_view = rng.uniform(-1.0, 1.0, n)
    cos_sun = rng.uniform(-1.0, 1.0, n)
    azimuth = rng.uniform(0.0, np.pi, n)
    cos_scatter = cos_view * cos_sun + np.sqrt((1 - cos_view**2) * (1 - cos_sun**2)) * np.cos(azimuth)
    return altitude, cos_view, cos_sun, np.clip(cos_scatter, -1.0, 1.0)


@pytest.mark.parametrize("sun_cos_range", [(-1.0, 1.0), (-0.35, 0.35)])
@pytest.mark.parametrize("layout", ["per-wavelength", "notes"])
@pytest.mark.parametrize("mapping", ["nonlinear", "linear"])
def test_kernel_matches_twin_float64(lookup_engines, table, layout, mapping, sun_cos_range):
    data = to_layout(table.data, layout)
    queries = random_queries(20000)
    kernel = lookup_engines["float64"].radiance(table.atmosphere, data, *queries, mapping=mapping,
                                                sun_cos_range=sun_cos_range)
    twin = reference.lookup(table.atmosphere, data, *queries, mapping=mapping, sun_cos_range=sun_cos_range)
    # Same trilinear weights and phase formulas; only the order of 8 products and FMA contraction
    # differ: a few ulps of the largest radiance.
    assert_allclose(kernel, twin, rtol=1e-12, atol=1e-14 * twin.max())


def test_kernel_float32_close_to_float64_twin(lookup_engines, table):
    queries = random_queries(20000, seed=2)
    kernel = lookup_engines["float32"].radiance(table.atmosphere, table.data, *queries)
    twin = reference.lookup(table.atmosphere, table.data, *queries)
    # float32 rounds the table (rel. 6e-8), the texture coordinates (~1e-7 times up to 32 cells per
    # unit) and the Mie phase near its peak (g = -0.85, relative slope ~30 per unit of cos theta).
    # Measured: max abs error 4e-6 of the largest radiance, max relative error 1.3e-4 on values
    # above 1e-3 of it; the bound 1e-4 rtol + 1e-4 of the max keeps a 25x margin on the absolute part.
    assert_allclose(kernel, twin, rtol=1e-4, atol=1e-4 * twin.max())


@pytest.mark.parametrize("sun_cos_range", [(-1.0, 1.0), (-0.35, 0.35)])
@pytest.mark.parametrize("backend", ["numpy", "opencl"])
def test_lookup_at_nodes_returns_node_values(table, backend, sun_cos_range):
    """At a grid node, trilinear interpolation returns the stored value, times I_I and phase (the table's
    data relabelled as covering ``sun_cos_range``: the lookup must find the nodes there)."""
    import dataclasses

    from clsky.mapping import grid_coordinates

    settings = table.settings.replace(sun_cos_range=sun_cos_range)
    table = dataclasses.replace(table, settings=settings)
    altitudes, cos_views, cos_suns = grid_coordinates(SIZE, table.atmosphere.atmosphere_height,
                                                      sun_cos_range=sun_cos_range)
    x, y, z = 4, 20, 5
    nu = 0.3
    rgb = table.radiance(altitudes[x], cos_views[y], cos_suns[z], nu, backend=backend)
    from clsky.phase import mie_phase, rayleigh_phase

    cell = table.data[z, y, x]
    expected = table.atmosphere.incident_light * (rayleigh_phase(table.atmosphere, nu) * cell[:3]
                                                  + mie_phase(table.atmosphere, nu) * cell[3:])
    # node coordinates round-trip to 1e-15 (test_analytic); the kernel adds a few ulps of FMA
    assert_allclose(rgb, expected, rtol=1e-12)


def test_from_space_missing_the_atmosphere_is_black(lookup_engines, table):
    h = 2 * table.atmosphere.atmosphere_height
    rgb = lookup_engines["float64"].radiance(table.atmosphere, table.data, [h, h], [0.5, -0.05], 0.5, 0.5)
    # looking up, and looking down past the limb (the limb from 200 km is at cos = -0.17): no sky
    assert (rgb == 0).all()


def test_from_space_equals_lookup_at_entry_point(lookup_engines, table):
    """An observer above the atmosphere sees what an observer at the entry point sees."""
    atmosphere = table.atmosphere
    ra, rp = atmosphere.top_radius, atmosphere.planet_radius
    r = ra + 50e3
    mu = -0.6
    d = -r * mu - np.sqrt((r * mu) ** 2 - (r * r - ra * ra))        # entry distance, textbook root
    mu_entry = (r * mu + d) / ra
    cos_sun, nu = 0.4, 0.1
    cos_sun_entry = (r * cos_sun + d * nu) / ra
    engine = lookup_engines["float64"]
    space = engine.radiance(atmosphere, table.data, r - rp, mu, cos_sun, nu)
    entry = engine.radiance(atmosphere, table.data, ra - rp, mu_entry, cos_sun_entry, nu)
    assert_allclose(space, entry, rtol=1e-9)   # the textbook root loses ~1e-10 to cancellation


@pytest.mark.parametrize("name,value", [("altitude", -1.0), ("cos_view", 1.5), ("cos_sun", np.nan),
                                        ("cos_scatter", -2.0)])
def test_invalid_queries_name_the_parameter(table, name, value):
    queries = dict(altitude=0.0, cos_view=0.5, cos_sun=0.5, cos_scatter=0.5)
    queries[name] = value
    with pytest.raises(ValueError, match=name):
        table.radiance(**queries)


def test_bad_table_shape_is_refused(lookup_engines):
    with pytest.raises(ValueError, match="shape"):
        lookup_engines["float64"].radiance(black_preset("physical"), np.zeros((4, 4, 4, 5)), 0, 0, 0, 0)


def _lookups(four_d):
    """The two engines' radiance and their NumPy twins, for a 3D or 4D table's data."""
    from clsky.lookup4d import TableLookup4DEngine

    engine = TableLookup4DEngine() if four_d else TableLookupEngine()
    return [engine.radiance, reference.lookup4d if four_d else reference.lookup]


@pytest.mark.parametrize("four_d", [False, True], ids=["3d", "4d"])
@pytest.mark.parametrize("change, message", [
    (dict(sun_cos_range=(0.2, 0.2)), r"^sun_cos_range must be two cosines -1 <= low < high <= 1"),
    (dict(sun_cos_range=(0.5, 0.2)), r"^sun_cos_range must be two cosines"),        # reversed: accepted
    (dict(sun_cos_range=(-5, 5)), r"^sun_cos_range must be two cosines"),            # beyond [-1, 1]: accepted
    (dict(sun_cos_range=(np.nan, 1)), r"^sun_cos_range must be two cosines"),        # 1e-12 and NaN
    (dict(sun_cos_range="ab"), r"^sun_cos_range must be two cosines"),               # numpy's message
    (dict(data=np.inf), r"^data holds \d+ infinite values"),                          # NaN radiance
    (dict(data=-1.0), r"^data holds \d+ negative values"),                            # negative radiance
    (dict(cos_view=np.nan), r"^cos_view must be finite and in \[-1, 1\], got nan"),   # twin: NaN radiance
])
def test_lookups_and_their_twins_refuse_what_a_table_cannot_be(four_d, change, message):
    """The lookup engines and their NumPy twins took any sun_cos_range (equal, reversed, NaN, beyond [-1, 1]:
    the engine returned 1e-12 where the twin gave NaN) and any data (infinite data gave NaN radiance,
    negated data negative radiance): both refuse them alike, naming the parameter."""
    shape = (3, 4, 8, 4, 9) if four_d else (4, 8, 4, 9)
    arguments = dict(data=np.full(shape, 0.5), altitude=0.0, cos_view=0.5, cos_sun=0.2, cos_scatter=0.5,
                     sun_cos_range=(-1.0, 1.0))
    if "data" in change:
        arguments["data"] = arguments["data"] * change["data"]
    else:
        arguments.update(change)
    atmosphere = black_preset("physical")
    for radiance in _lookups(four_d):
        with pytest.raises(ValueError, match=message):
            radiance(atmosphere, arguments["data"],
                     *(arguments[k] for k in ("altitude", "cos_view", "cos_sun", "cos_scatter")), "nonlinear",
                     arguments["sun_cos_range"])


def test_a_validated_tables_lookup_does_not_scan_its_values_again(table, monkeypatch):
    """ScatteringTable.radiance's table was checked when it was made: its lookups (both backends) pass
    table_checked and do not scan every value again (39 ms of a 41 ms point query on a 300 MB table); a raw
    array's lookup does."""
    import clsky.lookup

    scans = []
    monkeypatch.setattr(clsky.lookup, "check_table_values", lambda name, array, **_: scans.append(name))
    for backend in ("opencl", "numpy"):
        table.radiance(0.0, 0.5, 0.5, 0.5, backend=backend)
    assert scans == []
    reference.lookup(table.atmosphere, table.data, 0.0, 0.5, 0.5, 0.5)
    assert scans == ["data"]
