"""Twilight against the independent Monte Carlo (issue 11, item 1): what is true today, pinned.

Ground observer, the zenith and 4 deg up toward, across and away from the sun, the sun at +5 ... -6 deg
(clsky/twilight.py), black ground and no ozone (issue 11's case). The yardsticks share no code with the
tables or the renderer: the path tracer clsky/montecarlo.py and its deterministic single-scattering
quadrature (montecarlo.single_scattering, same module, imports nothing from clsky).

What holds (README, "Twilight against Monte Carlo"): the ray march's single scattering agrees down to
-6 deg. Its full radiance, with the tables the scene planner builds (azimuth harmonics M = 2 for a sun
below +30 deg, clsky/planner.py), meets the bars issue 11 sets (2 % at 0 deg and above, 5 % from -2 to
-6 deg, each + 3 standard errors of the tracer). The azimuth average (M = 0, the planner's choice
before) is asserted to miss them by far at -6 deg, so that a planner falling back to it fails here.
"""

import ast
import math
import pathlib
import re

import numpy as np
import pytest

from clsky import montecarlo, twilight


@pytest.fixture(scope="module")
def atmosphere():
    return twilight.black_ground_without_ozone()


@pytest.fixture(scope="module")
def single_marched(atmosphere):
    """{sun elevation: (4, 3)} single scattering of the ray march at the default level (planner's table
    without higher orders: 32 x 256 x 4 nodes, 48 Keller & Bohn samples per ray); ~1.5 s each."""
    return {e: twilight.ray_march(atmosphere, e, single=True)[0] for e in twilight.SUN_ELEVATIONS_DEG}


# The deterministic yardstick -------------------------------------------------------------------------

def test_the_yardstick_imports_nothing_from_clsky():
    """clsky/montecarlo.py (tracer and quadrature) imports only the standard library and NumPy, so it
    shares no code with the tables and the renderer it checks."""
    tree = ast.parse(pathlib.Path(montecarlo.__file__).read_text())
    imported = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            imported |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            imported.add("." if node.level else node.module.split(".")[0])
    assert imported == {"__future__", "dataclasses", "decimal", "math", "numpy"}, imported


def test_single_scattering_quadrature_is_converged(atmosphere):
    """Halving the panels and raising the Gauss-Legendre nodes from 8 to 12 changes the quadrature by
    < 1e-9 relative (measured 2e-14 ... 7e-14), at a sunlit and at a half-shadowed twilight view: the
    shadow edge is a panel edge, so the integrand is smooth on every panel."""
    for sun, (elevation, azimuth) in ((5.0, twilight.VIEWS["toward"]), (-6.0, twilight.VIEWS["across"])):
        args = (atmosphere, 0.0, math.sin(math.radians(elevation)), math.sin(math.radians(sun)), math.radians(azimuth))
        coarse = montecarlo.single_scattering(*args)
        fine = montecarlo.single_scattering(*args, step=50.0, nodes=12)
        assert np.all(coarse > 0)
        np.testing.assert_allclose(coarse, fine, rtol=1e-9, atol=0)


@pytest.mark.parametrize("call, name", [
    (lambda a: twilight.monte_carlo(a, 5.0, "north"), "view"),
    (lambda a: twilight.single_scattering(a, 95.0, "zenith"), "sun_elevation_deg"),
    (lambda a: twilight.monte_carlo(a, 5.0, "zenith", target=1.5), "target"),
    (lambda a: twilight.monte_carlo(a, 5.0, "zenith", batch=1), "batch"),
    # a first batch above the cap spent more paths than it (100 for max_photons = 10)
    (lambda a: twilight.monte_carlo(a, 5.0, "zenith", batch=100, max_photons=10), "batch"),
    (lambda a: twilight.monte_carlo(a, 5.0, "zenith", seed=-5), "seed"),
    (lambda a: twilight.monte_carlo(a, 5.0, "zenith", max_orders=0), "max_orders"),
    (lambda a: twilight.monte_carlo(3, 5.0, "zenith"), "atmosphere"),                  # an AttributeError
    (lambda a: twilight.black_ground_without_ozone(3), "atmosphere"),
    (lambda a: twilight.single_scattering(3, 5.0, "zenith"), "atmosphere"),              # an AttributeError
    (lambda a: twilight.monte_carlo("bogus", 5.0, "zenith"), "atmosphere"),               # named 'preset'
    (lambda a: twilight.view_directions(["zenith", "up"]), "view"),
])
def test_bad_input_names_the_parameter(atmosphere, call, name):
    with pytest.raises(ValueError, match=f"^{name} must be"):
        call(atmosphere)


def test_the_default_batch_follows_a_smaller_max_photons(atmosphere):
    """max_photons below the default batch (200 000): the batch is max_photons, where the default batch was
    refused as a batch the caller never gave ('batch must be an integer in [2, 20], got 200000')."""
    pooled = twilight.monte_carlo(atmosphere, 5.0, "zenith", max_photons=20)
    assert pooled.photons == 20 and pooled.batches == 1


def test_single_scattering_takes_a_preset_name():
    from clsky import preset

    np.testing.assert_array_equal(twilight.single_scattering("physical", 5.0, "zenith"),
                                  twilight.single_scattering(preset("physical"), 5.0, "zenith"))


def test_monte_carlo_takes_a_preset_name(atmosphere):
    """monte_carlo, like black_ground_without_ozone, takes a preset's name (it failed with an
    AttributeError): the same paths as with the preset's parameters."""
    from clsky import preset

    by_name = twilight.monte_carlo("physical", 5.0, "zenith", batch=20, max_photons=20)
    by_value = twilight.monte_carlo(preset("physical"), 5.0, "zenith", batch=20, max_photons=20)
    assert by_name.photons == by_value.photons == 20
    np.testing.assert_array_equal(by_name.radiance, by_value.radiance)


def test_single_scattering_quadrature_rejects_rays_into_the_ground(atmosphere):
    """Refused naming cos_view, the horizon's cosine at that altitude and the value (the message said only
    that the view ray hits the ground)."""
    horizon = -math.sqrt(1.0 - (atmosphere.planet_radius / (atmosphere.planet_radius + 1000.0)) ** 2)
    with pytest.raises(ValueError, match=re.escape(f"cos_view must be above the horizon's {horizon:.6g} at "
                                                   f"altitude 1000 m (single_scattering integrates rays that reach "
                                                   f"the top, not the ground's reflection), got -0.5")):
        montecarlo.single_scattering(atmosphere, 1000.0, -0.5, 0.5)


def test_few_contributing_paths_are_flagged_not_taken_at_their_standard_error(atmosphere):
    """At -6 deg, zenith, 2000 paths: red came out 0 +- 0 (no path reached the sunlit air) and green
    3.4e-5 +- 2.4e-5 against an exact 9.1e-6; over 40 seeds the 95 % interval held the exact value in 38 to
    58 % of them (probe of the tracer, 2026-12-07). The result counts each channel's contributing paths,
    below MIN_CONTRIBUTING_PATHS its error is flagged as no measure (not reliable), twilight's pooled
    estimate keeps going (its relative error infinite) and the deviation in standard errors is NaN."""
    cos_sun = math.sin(math.radians(-6.0))
    result = montecarlo.simulate(atmosphere, 0.0, 1.0, cos_sun, photons=2000, seed=0, max_orders=1)
    assert result.contributing_paths.tolist() == [0, 2, 2]           # two paths each in green and blue
    assert not result.reliable.any() and result.radiance[0] == 0.0 and result.standard_error[0] == 0.0
    pooled = twilight.monte_carlo(atmosphere, -6.0, "zenith", target=0.5, batch=2000, max_photons=4000,
                                  max_orders=1)
    assert pooled.batches == 2 and np.all(np.isinf(pooled.relative_error))     # no early stop on 3 paths
    relative, sigmas = twilight.deviation(montecarlo.single_scattering(atmosphere, 0.0, 1.0, cos_sun), pooled)
    assert np.isnan(sigmas).all() and np.isfinite(relative).all()    # a deviation, with no SE to scale it
    day = montecarlo.simulate(atmosphere, 0.0, 1.0, 0.5, photons=2000, seed=0, max_orders=1)
    assert day.reliable.all() and (day.contributing_paths > 100).all()    # the paths that scatter, by day


def test_single_only_is_a_flag_and_agrees_with_max_orders(atmosphere):
    """single_only='no' ran single scattering, and max_orders=5 with single_only=True became 1 silently."""
    with pytest.raises(ValueError, match=r"^single_only must be True or False, got 'no' \(str\)"):
        montecarlo.simulate(atmosphere, 0.0, 1.0, 0.5, photons=10, single_only="no")
    with pytest.raises(ValueError, match="single_only=True counts order 1 alone: max_orders must be None or 1"):
        montecarlo.simulate(atmosphere, 0.0, 1.0, 0.5, photons=10, single_only=True, max_orders=5)
    assert montecarlo.simulate(atmosphere, 0.0, 1.0, 0.5, photons=10, single_only=True, max_orders=1).max_orders == 1
    with pytest.raises(ValueError, match=r"seed must be None or an integer in \[0, 18446744073709551615\], got "
                                         r"18446744073709551616$"):         # not '1e+19', as if inside
        montecarlo.simulate(atmosphere, 0.0, 1.0, 0.5, photons=10, seed=2**64)


#: (sun elevation [deg], view): sunlit cases where 150 000 paths give the tracer's single scattering a
#: standard error of 0.1-1 % (measured), one per regime: day zenith, sunset horizon, twilight toward the sun.
TRACER_CASES = [(5.0, "zenith"), (0.0, "across"), (-4.0, "toward")]


@pytest.mark.parametrize("sun, view", TRACER_CASES)
def test_quadrature_and_ray_march_agree_with_the_tracer_on_single_scattering(atmosphere, single_marched, sun, view):
    """The tracer (max_orders=1) against its quadrature: only the tracer's noise separates them, so
    4 standard errors (a false alarm has probability 6e-5 per channel; measured within 1.7 SE at +5 and
    0 deg). The ray march's single scattering against the tracer: issue 11's bar, 2 % (the ray march's
    48-sample quadrature; measured within 0.5 % of the quadrature here) + 3 standard errors."""
    pooled = twilight.monte_carlo(atmosphere, sun, view, batch=150_000, max_photons=150_000, seed=17,
                                  max_orders=1)
    exact = twilight.single_scattering(atmosphere, sun, view)
    marched = single_marched[sun][list(twilight.VIEWS).index(view)]
    print(f"tracer {pooled.radiance} +- {pooled.standard_error}, quadrature {exact}, ray march {marched}")
    assert np.all(np.abs(pooled.radiance - exact) <= 4 * pooled.standard_error)
    assert np.all(np.abs(marched - pooled.radiance) <= 0.02 * pooled.radiance + 3 * pooled.standard_error)


@pytest.mark.parametrize("sun", twilight.SUN_ELEVATIONS_DEG)
def test_ray_march_single_scattering_agrees_with_quadrature_down_to_minus_6(atmosphere, single_marched, sun):
    """Every view, every channel within 2 % of the converged quadrature (no noise to allow for): the
    single scattering is right through civil twilight, so the excess of issue 11 lies in the higher
    orders. Measured: within 0.42 % by day, 1.7 % at worst (sun -2 deg, away, red: the lit layer is
    a few of the 48 Keller & Bohn samples). A view whose whole ray lies in the planet's shadow (away
    from the sun at -4 and -6 deg) has no single scattering: both give 0 there."""
    marched = single_marched[sun]
    for i, view in enumerate(twilight.VIEWS):
        exact = twilight.single_scattering(atmosphere, sun, view)
        if not np.any(exact > 0):
            assert np.all(marched[i] == 0.0), (view, marched[i])
            continue
        deviation = marched[i] / exact - 1.0
        print(f"sun {sun:+g} {view}: {100 * deviation} %")
        assert np.all(np.abs(deviation) <= 0.02), (view, deviation)


# All orders ------------------------------------------------------------------------------------------

def full_deviation(atmosphere, sun, views, quality, photons, seed=5, azimuth_harmonics=None, harmonics_used=None):
    """[(view, relative deviation (3,), standard errors (3,))] of the ray march's full radiance;
    ``harmonics_used``: the azimuth harmonics its table must have (checked)."""
    marched, settings = twilight.ray_march(atmosphere, sun, views, quality=quality, azimuth_harmonics=azimuth_harmonics)
    if harmonics_used is not None:
        assert settings.azimuth_harmonics == harmonics_used, settings
    out = []
    for i, view in enumerate(views):
        pooled = twilight.monte_carlo(atmosphere, sun, view, batch=photons, max_photons=photons, seed=seed + i)
        relative, _ = twilight.deviation(marched[i], pooled)
        out.append((view, relative, pooled.relative_error))
        print(f"sun {sun:+g} {view}: {100 * relative} % (SE {100 * pooled.relative_error} %)")
    return out


def within(rows, bar):
    """Every channel of every row within bar + 3 standard errors (relative)."""
    return all(np.all(np.abs(relative) <= bar + 3 * error) for _, relative, error in rows)


def test_draft_ray_march_at_minus_6_within_the_fix_bar(atmosphere):
    """Issue 11's bar from -2 to -6 deg, 5 % + 3 standard errors, at the 'draft' level as the planner
    sets it (16 x 128 x 48 table with M = 2 azimuth harmonics) in the two views the azimuth average
    misses most; 100 000 paths (standard errors 5-17 %). Measured: -0.8 to +4.7 % across and +8 to
    +10 % away against a 2 % Monte Carlo (the draft grid's own error, inside its 10 % promise and
    inside 5 % + 3 SE here; at the default level M = 2 is within 2 % in every view)."""
    assert within(full_deviation(atmosphere, -6.0, ("across", "away"), "draft", 100_000, harmonics_used=2), 0.05)


@pytest.mark.slow
def test_draft_azimuth_average_at_minus_6_is_far_too_bright(atmosphere):
    """The same case with the azimuth average (azimuth_harmonics = 0, the planner's choice before the
    harmonics): every channel at least 50 % too bright even after 3 standard errors are taken off
    (measured +160 to +230 % across, +230 to +290 % away): what M = 2 removes."""
    rows = full_deviation(atmosphere, -6.0, ("across", "away"), "draft", 100_000, azimuth_harmonics=0)
    assert all(np.all(relative - 3 * error >= 0.5) for _, relative, error in rows)


@pytest.fixture(scope="module")
def plus_5_rows(atmosphere):
    """The sun at +5 deg, default level (32 x 128 x N table, ~20 s), every view; 400 000 paths
    (standard errors 0.1-0.9 %)."""
    return full_deviation(atmosphere, 5.0, tuple(twilight.VIEWS), "default", 400_000, harmonics_used=2)


@pytest.mark.slow
def test_default_ray_march_at_plus_5_within_5_percent(plus_5_rows):
    """Every view and channel within 5 % + 3 standard errors at +5 deg (the azimuth average's worst was
    +3.7 %, across, blue; issue 11's 3.5 %)."""
    assert within(plus_5_rows, 0.05)


@pytest.mark.slow
def test_default_ray_march_at_plus_5_within_the_day_bar(plus_5_rows):
    """Issue 11's bar at 0 deg and above: 2 % (+ 3 standard errors), default level as the planner sets
    it (M = 2 below +30 deg), +5 deg. The azimuth average was +2.4 to +3.7 % across the sun here (16
    standard errors); M = 2 measured within 1.2 % of a 2 % Monte Carlo (README)."""
    assert within(plus_5_rows, 0.02)


@pytest.mark.slow
@pytest.mark.parametrize("sun", [-4.0, -6.0])
def test_default_ray_march_in_twilight_within_the_fix_bar(atmosphere, sun):
    """Issue 11's bar from -2 to -6 deg, 5 % + 3 standard errors, at the default level as the planner
    sets it (M = 2), every view; 300 000 paths (standard errors up to ~10 % in the shadowed views).
    The azimuth average was +5 to +253 % here; M = 2 measured within 2.2 % of a 2 % Monte Carlo."""
    assert within(full_deviation(atmosphere, sun, tuple(twilight.VIEWS), "default", 300_000, harmonics_used=2), 0.05)
