"""The physical mode against the independent Monte Carlo path tracer (issue 3's physics check).

The table is built at converged quadrature (bench/bench_montecarlo.py: halving every count changes
these radiances by at most 0.11 %), so what remains is the physics: the canonical frame, the azimuth
average of the higher orders, the grid. The Monte Carlo shares no code with the table.
"""

import numpy as np
import pytest

import clsky
from clsky import montecarlo

CONVERGED = dict(view_steps=200, multiple_view_steps=None, sun_steps=600, sun_transmittance="table",
                 transmittance_size=(128, 512),
                 sampling="keller_bohn")
#: (altitude [m], cos view zenith, sun zenith [deg]), sun and view in one vertical plane (azimuth 0).
#: The default suite checks the zenith, the horizon under a low sun and a view down from 5 km; the other
#: three (2.5-6 s each on two busy cores) run in .ci/run's slow set.
CASES = [(0.0, 1.0, 30.0), pytest.param(0.0, 0.5, 60.0, marks=pytest.mark.slow), (0.0, 0.1, 80.0),
         pytest.param(0.0, 0.7, 0.0, marks=pytest.mark.slow), (5000.0, -0.3, 45.0),
         pytest.param(0.0, 0.2, 70.0, marks=pytest.mark.slow)]


@pytest.fixture(scope="module")
def physical_table():
    return clsky.ScatteringTable.build("physical", clsky.TableSettings(mode="physical", **CONVERGED))


@pytest.mark.parametrize("altitude, cos_view, sun_zenith", CASES)
def test_physical_mode_agrees_with_monte_carlo(physical_table, altitude, cos_view, sun_zenith):
    atmosphere = physical_table.atmosphere
    cos_sun = np.cos(np.radians(sun_zenith))
    nu = cos_view * cos_sun + np.sqrt((1 - cos_view**2) * (1 - cos_sun**2))
    table = physical_table.radiance(altitude, cos_view, cos_sun, nu) / atmosphere.incident_light
    mc, standard_error = montecarlo.sky_radiance(atmosphere, altitude, cos_view, cos_sun, 0.0,
                                                 photons=200_000, seed=1)
    # issue 3's bar: 3 standard errors (statistics) plus 2 % (the table's azimuth average of the higher
    # orders and its grid); measured deviations are within 1.1 % (README, Monte Carlo table)
    bound = 3 * standard_error + 0.02 * mc
    print(f"deviation {(table / mc - 1) * 100} %, bound {bound / mc * 100} %")
    assert np.all(np.abs(table - mc) <= bound)


# Views from altitude (issue 10, item 6) -------------------------------------------------------------

#: (altitude [m], cos view zenith, cos sun zenith, azimuth [rad]): looking down to the black ground.
#: The default suite checks one view from each altitude; the steeper two run in .ci/run's slow set.
ALTITUDE_CASES = [(10e3, -0.3, float(np.cos(np.radians(30.0))), 0.0),
                  pytest.param((10e3, -0.8, 0.5, 2.0), marks=pytest.mark.slow),
                  (100e3, -0.5, 1.0, 0.0),
                  pytest.param((100e3, -0.9, float(np.cos(np.radians(45.0))), 0.0), marks=pytest.mark.slow)]


@pytest.fixture(scope="module")
def altitude_tables():
    """Physical-mode tables (16 x 128 x 32, orders until 1e-4, default 30 / 20 view steps) per sampling."""
    # the black ground of the cases: a lit ground (the preset's 0.1) outshines the haze looking down and
    # would hide the error of Keller & Bohn's nodes that the last assertion shows
    black = clsky.preset("physical").replace(ground_albedo=0.0)
    return {sampling: clsky.ScatteringTable.build(black, clsky.TableSettings(size=(16, 128, 32), mode="physical",
                                                                             sampling=sampling))
            for sampling in ("keller_bohn", "ground_end")}


@pytest.mark.parametrize("case", ALTITUDE_CASES, ids=lambda c: f"{c[0] / 1e3:g}km-mu{c[1]:g}")
def test_views_from_altitude_agree_with_monte_carlo(altitude_tables, case):
    """All orders, per-pixel ray march (30 view steps, ground_end nodes, higher orders from the
    ground_end table) within 2 % + 3 standard errors of the tracer (300 000 paths per channel,
    standard errors 0.3-0.8 %). Measured: within 1.5 %; Keller & Bohn's nodes are 6.6 % (100 km, view
    cosine -0.5, sun at the zenith) and 9.2 % (-0.9) high in red, beyond the bound."""
    from clsky.render import RAYMARCH_DEFAULTS, SkyRenderer

    altitude, cos_view, cos_sun, azimuth = case
    atmosphere = altitude_tables["ground_end"].atmosphere
    mc, standard_error = montecarlo.sky_radiance(atmosphere, *case, photons=300_000, seed=23)
    bound = 3 * standard_error + 0.02 * mc
    view = np.array([[np.sqrt(1 - cos_view**2), 0.0, cos_view]])
    sun = np.array([np.sqrt(1 - cos_sun**2) * np.cos(azimuth), np.sqrt(1 - cos_sun**2) * np.sin(azimuth), cos_sun])
    marched = {}
    for sampling, table in altitude_tables.items():
        with SkyRenderer(table, RAYMARCH_DEFAULTS.replace(view_steps=30, sampling=sampling)) as renderer:
            marched[sampling] = renderer.render_raymarch(view, sun, altitude)[0] / atmosphere.incident_light
    print({s: (v / mc - 1) * 100 for s, v in marched.items()}, "standard error [%]", standard_error / mc * 100)
    assert np.all(np.abs(marched["ground_end"] - mc) <= bound)
    if altitude == 100e3:
        assert np.any(np.abs(marched["keller_bohn"] - mc) > bound)
