"""Tests of the independent Monte Carlo sky (clsky.montecarlo).

Statistical tolerances: a Monte Carlo estimate is compared with an exact or deterministic value within
Z = 4.5 standard errors (two-sided normal tail 7e-6 per comparison; with ~40 comparisons here the chance
of a false failure is < 3e-4, and the seeds are fixed, so the outcome is reproducible). Deterministic
references carry their own (much smaller) error, added to the tolerance where it is not negligible.
Histogram tests use Pearson's chi-square with the p-value threshold 1e-4.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate, stats

from clsky.atmosphere import AtmosphereParameters
from clsky.montecarlo import (
    cornette_shanks_phase,
    henyey_greenstein_phase,
    optical_depth_to_top,
    phase_mean,
    rayleigh_phase,
    sample_cornette_shanks_cosine,
    sample_henyey_greenstein_cosine,
    sample_rayleigh_cosine,
    simulate,
    sky_radiance,
    transmittance_to_top,
)

from conftest import black_preset

Z = 4.5
RP, RA = 6_371_000.0, 6_471_000.0


# Phase functions and samplers -----------------------------------------------------------------------

def _chi_square_pvalue(samples, density, bins=60):
    """Pearson chi-square p-value of samples on [-1, 1] against a density on [-1, 1]."""
    edges = np.linspace(-1.0, 1.0, bins + 1)
    observed, _ = np.histogram(samples, edges)
    prob = np.array([integrate.quad(density, a, b, epsabs=0, epsrel=1e-12)[0]
                     for a, b in zip(edges[:-1], edges[1:])])
    assert abs(prob.sum() - 1.0) < 1e-9
    expected = prob * samples.size
    chi2 = np.sum((observed - expected) ** 2 / expected)
    return stats.chi2.sf(chi2, bins - 1)


@pytest.mark.parametrize("kind, mean", [("rayleigh", 1.0), ("modified_atmosphereplus", 0.8 * (1.4 + 1 / 6))])
def test_rayleigh_phase_mean_and_sampler(kind, mean):
    assert phase_mean(kind) == pytest.approx(mean, rel=1e-14)
    assert integrate.quad(lambda c: rayleigh_phase(c, kind), -1, 1)[0] / 2 == pytest.approx(mean, rel=1e-12)
    rng = np.random.default_rng(1)
    samples = sample_rayleigh_cosine(rng.random(400_000), kind)
    assert np.all(np.abs(samples) <= 1)
    assert _chi_square_pvalue(samples, lambda c: rayleigh_phase(c, kind) / (2 * mean)) > 1e-4
    # Inverse CDF exactly: the end points and the median (symmetric density).
    np.testing.assert_allclose(sample_rayleigh_cosine([0.0, 0.5, 1.0 - 1e-16], kind), [-1, 0, 1], atol=1e-7)


@pytest.mark.parametrize("g", [-0.85, -0.3, 0.0, 0.6, -0.99])
def test_cornette_shanks_normalised_and_sampled(g):
    assert integrate.quad(lambda c: cornette_shanks_phase(c, g), -1, 1, points=[1 - 1e-3, 1],
                          epsrel=1e-12, limit=200)[0] / 2 == pytest.approx(1.0, rel=1e-9)
    rng = np.random.default_rng(2)
    samples = sample_cornette_shanks_cosine(rng, 400_000, g)
    assert np.all(np.abs(samples) <= 1)
    assert _chi_square_pvalue(samples, lambda c: cornette_shanks_phase(c, g) / 2) > 1e-4
    # Mean cosine of Cornette-Shanks (exact integral) within Z standard errors.
    mean_cos = integrate.quad(lambda c: c * cornette_shanks_phase(c, g) / 2, -1, 1, points=[1 - 1e-3],
                              epsrel=1e-12, limit=200)[0]
    assert abs(samples.mean() - mean_cos) < Z * samples.std() / math.sqrt(samples.size)


def test_cornette_shanks_sampler_resolves_the_forward_spike():
    """g = -0.99: bins in the HG-uniformising variable, where the CS density is smooth."""
    g = -0.99
    rng = np.random.default_rng(3)
    samples = sample_cornette_shanks_cosine(rng, 400_000, g)
    # c(u) of HG with textbook g' = -g maps bins of equal HG probability; compare with CS probabilities.
    edges_u = np.linspace(0, 1, 61)
    edges_c = np.sort(sample_henyey_greenstein_cosine(edges_u, -g))
    edges_c[0], edges_c[-1] = -1.0, 1.0
    observed, _ = np.histogram(samples, edges_c)
    prob = np.array([integrate.quad(lambda c: cornette_shanks_phase(c, g) / 2, a, b, epsrel=1e-12)[0]
                     for a, b in zip(edges_c[:-1], edges_c[1:])])
    expected = prob * samples.size
    chi2 = np.sum((observed - expected) ** 2 / expected)
    assert stats.chi2.sf(chi2, 59) > 1e-4


def test_cornette_shanks_sign_convention_peaks_toward_the_sun():
    """Notes' convention: negative g, '+2gc' form, forward lobe at c = dot(Sun, V) = 1."""
    assert cornette_shanks_phase(1.0, -0.85) > 50 * cornette_shanks_phase(-1.0, -0.85)
    # Equals the textbook form with (1 + g^2 - 2 g c) and g = +0.85.
    c = np.linspace(-1, 1, 11)
    textbook = 3 * (1 - 0.85**2) / (2 * (2 + 0.85**2)) * (1 + c**2) / (1 + 0.85**2 - 2 * 0.85 * c) ** 1.5
    np.testing.assert_allclose(cornette_shanks_phase(c, -0.85), textbook, rtol=1e-14)
    assert np.mean(sample_cornette_shanks_cosine(np.random.default_rng(4), 10_000, -0.85)) > 0.6


def test_henyey_greenstein_sampler():
    rng = np.random.default_rng(5)
    samples = sample_henyey_greenstein_cosine(rng.random(400_000), 0.7)
    assert _chi_square_pvalue(samples, lambda c: henyey_greenstein_phase(c, 0.7) / 2) > 1e-4


# Transmittance quadrature ---------------------------------------------------------------------------

@pytest.mark.parametrize("height", [8000.0, 1200.0, 300.0, 60_000.0])
@pytest.mark.parametrize("altitude", [0.0, 2000.0, 50_000.0])
def test_vertical_column_closed_form(height, altitude):
    """Straight up from altitude h: Integral exp(-z/H) dz = H (exp(-h/H) - exp(-Ha/H))."""
    ha = RA - RP
    cols, blocked = optical_depth_to_top(RP + altitude, 1.0, RP, RA, [height])
    exact = height * (math.exp(-altitude / height) - math.exp(-ha / height))
    assert not blocked[0]
    assert cols[0, 0] == pytest.approx(exact, rel=1e-10)
    # Straight down from altitude h > 0 hits the planet.
    assert optical_depth_to_top(RP + altitude + 1.0, -1.0, RP, RA, [height])[1][0]


def _chord_to_top(r, mu, ra):
    b = r * mu
    return -b + math.sqrt(b * b + ra * ra - r * r)


@pytest.mark.parametrize("altitude", [0.0, 500.0, 30_000.0, 99_000.0])
@pytest.mark.parametrize("mu", [1.0, 0.3, 0.01, 0.0, -0.02, -0.2, -0.9])
def test_uniform_medium_transmittance(altitude, mu):
    """Huge scale heights: rho = 1, T = exp(-beta L) with L the chord to the top (Ra >> Rp here too)."""
    rp, ra = 1_000.0, 101_000.0  # small planet: downward rays that miss it exist
    r = rp + altitude
    sin_zenith = math.sqrt(1 - mu * mu)
    if mu < 0 and r * sin_zenith < rp:
        assert optical_depth_to_top(r, mu, rp, ra, [1e20])[1][0]
        return
    atmosphere = AtmosphereParameters(planet_radius=rp, top_radius=ra, rayleigh_scale_height=1e20,
                                      mie_scale_height=1e20, rayleigh_scattering=(1e-6, 1e-5, 3e-5),
                                      mie_scattering=2e-6, mie_extinction_ratio=0.5)
    length = _chord_to_top(r, mu, ra)
    beta = np.array([1e-6, 1e-5, 3e-5]) + 4e-6
    np.testing.assert_allclose(transmittance_to_top(atmosphere, r, mu)[0], np.exp(-beta * length),
                               rtol=1e-10)


@pytest.mark.parametrize("altitude, mu", [
    (0.0, 0.0), (0.0, 1e-4), (0.0, 0.05), (10.0, -1e-3), (3000.0, -0.03), (3000.0, -0.0306),
    (20_000.0, -0.07), (60_000.0, -0.1), (80_000.0, -0.1569), (1200.0, 0.5)])
def test_grazing_columns_against_adaptive_quadrature(altitude, mu):
    """Rays near the horizon and past a low tangent point: |error| in tau < 1e-9 for the default air.

    The requirement is 1e-4 relative in the transmittance, i.e. 1e-4 absolute in tau.
    """
    r = RP + altitude
    length = _chord_to_top(r, mu, RA)
    points = [-r * mu] if mu < 0 else None
    for height, beta in ((8000.0, 2.3e-5), (1200.0, 2e-6 / 0.9)):
        def density(s):
            return math.exp(-(math.sqrt(r * r + s * s + 2 * r * mu * s) - RP) / height)
        ref = integrate.quad(density, 0, length, points=points, epsabs=0, epsrel=1e-12, limit=500)[0]
        cols, blocked = optical_depth_to_top(r, mu, RP, RA, [height])
        assert not blocked[0]
        assert abs(cols[0, 0] - ref) * beta < 1e-9
        assert cols[0, 0] == pytest.approx(ref, rel=1e-8)


def test_shadow_decision():
    r = RP + 5000.0
    mu_horizon = -math.sqrt(1 - (RP / r) ** 2)
    _, blocked = optical_depth_to_top([r, r, r, r], [mu_horizon * 0.999, mu_horizon * 1.001, -1.0, 0.0],
                                      RP, RA, [8000.0])
    assert blocked.tolist() == [False, True, True, False]


# Single scattering against closed forms in a uniform medium -----------------------------------------

def _uniform(rp, ra, beta_r, beta_m, ratio=0.9, g=-0.85, rayleigh_phase="rayleigh"):
    return AtmosphereParameters(planet_radius=rp, top_radius=ra, rayleigh_scale_height=1e20,
                                mie_scale_height=1e20, rayleigh_scattering=beta_r, mie_scattering=beta_m,
                                mie_extinction_ratio=ratio, mie_g=g, rayleigh_phase=rayleigh_phase)


def _phase_sum(atmosphere, c):
    return (np.asarray(atmosphere.rayleigh_scattering) * rayleigh_phase(c, atmosphere.rayleigh_phase)
            + atmosphere.mie_scattering * cornette_shanks_phase(c, atmosphere.mie_g))


def test_thin_uniform_layer_single_scattering():
    """Optically thin: L = sum_s beta_s F_s(cos theta) / (4 pi) * l, l the view path length.

    Derivation: L = Integral_0^l sum_s beta_s F_s / (4 pi) T_view(s) T_sun(s) ds, with
    1 >= T_view T_sun = exp(-beta_e (s + d_sun(s))) >= 1 - tau_max, tau_max = beta_e (l + max d_sun).
    So L_thin (1 - tau_max) <= L <= L_thin: a rigorous bracket, widened by Z standard errors.
    """
    rp, ra = RP, RP + 10_000.0
    atmosphere = _uniform(rp, ra, (4e-7, 1e-6, 2e-6), 5e-7)
    altitude, cos_view, cos_sun, azimuth = 2000.0, 0.6, 0.8, 1.0
    result = simulate(atmosphere, altitude, cos_view, cos_sun, azimuth, photons=1_000_000, seed=11,
                      single_only=True)
    r0 = rp + altitude
    length = _chord_to_top(r0, cos_view, ra)
    cos_theta = (math.sqrt(1 - cos_view**2) * math.sqrt(1 - cos_sun**2) * math.cos(azimuth)
                 + cos_view * cos_sun)
    thin = _phase_sum(atmosphere, cos_theta) / (4 * math.pi) * length
    beta_e = np.asarray(atmosphere.rayleigh_scattering) + atmosphere.mie_extinction
    max_sun_chord = _chord_to_top(r0, cos_sun, ra)  # the lowest point of the path is the observer
    tau_max = beta_e * (length + max_sun_chord)
    assert np.all(tau_max < 0.1)
    tol = Z * result.standard_error
    assert np.all(result.radiance <= thin + tol)
    assert np.all(result.radiance >= thin * (1 - tau_max) - tol)
    assert np.all(result.standard_error < 0.02 * thin)


def _uniform_single_scattering(atmosphere, altitude, cos_view, cos_sun, azimuth, nodes=20001):
    """sum_s beta_s F_s / (4 pi) Integral_0^l exp(-beta_e (s + d_sun(s))) ds, exact chords, Simpson in s."""
    rp, ra = atmosphere.planet_radius, atmosphere.top_radius
    sv, ss = math.sqrt(1 - cos_view**2), math.sqrt(1 - cos_sun**2)
    view = np.array([sv, 0.0, cos_view])
    sun = np.array([ss * math.cos(azimuth), ss * math.sin(azimuth), cos_sun])
    p0 = np.array([0.0, 0.0, rp + altitude])
    length = _chord_to_top(rp + altitude, cos_view, ra)
    s = np.linspace(0.0, length, nodes)
    p = p0 + s[:, None] * view
    b = p @ sun
    d_sun = -b + np.sqrt(b * b + ra * ra - np.einsum("ij,ij->i", p, p))
    assert np.all(b >= 0)  # the sun is above every point's horizon: no shadow in these cases
    beta_e = np.asarray(atmosphere.rayleigh_scattering) + atmosphere.mie_extinction
    integrand = np.exp(-beta_e[:, None] * (s + d_sun)[None, :])
    integral = integrate.simpson(integrand, x=s, axis=1)
    return _phase_sum(atmosphere, view @ sun) / (4 * math.pi) * integral


@pytest.mark.parametrize("case", [
    # sun along the view: T_view T_sun = exp(-beta_e l) is constant, L = beta F(1)/(4 pi) l exp(-beta_e l)
    dict(altitude=1000.0, cos_view=0.4, cos_sun=0.4, azimuth=0.0),
    dict(altitude=0.0, cos_view=0.2, cos_sun=0.9, azimuth=2.5),
    dict(altitude=5000.0, cos_view=0.05, cos_sun=0.3, azimuth=math.pi, rayleigh_phase="modified_atmosphereplus"),
])
def test_uniform_medium_single_scattering(case):
    """Moderate optical depth (tau ~ 0.05-0.6) against exact chords, with absorption (ratio 0.5)."""
    case = dict(case)
    kind = case.pop("rayleigh_phase", "rayleigh")
    atmosphere = _uniform(RP, RP + 20_000.0, (3e-6, 1e-5, 2.5e-5), 3e-6, ratio=0.5, rayleigh_phase=kind)
    result = simulate(atmosphere, **case, photons=300_000, seed=12, single_only=True)
    reference = _uniform_single_scattering(atmosphere, **case)
    if case["cos_view"] == case["cos_sun"] and case["azimuth"] == 0.0:
        length = _chord_to_top(RP + case["altitude"], case["cos_view"], atmosphere.top_radius)
        beta_e = np.asarray(atmosphere.rayleigh_scattering) + atmosphere.mie_extinction
        closed = _phase_sum(atmosphere, 1.0) / (4 * math.pi) * length * np.exp(-beta_e * length)
        np.testing.assert_allclose(reference, closed, rtol=1e-10)
    assert np.all(np.abs(result.radiance - reference) < Z * result.standard_error), (
        result.radiance, reference, result.standard_error)
    assert np.all(result.standard_error < 0.01 * reference)


# Single scattering in the real atmosphere against a deterministic quadrature ------------------------

def _ozone_density(atmosphere, h):
    """The ozone tent n_O3 / n_max = max(0, 1 - |h - peak| / half width) (0 without ozone)."""
    if atmosphere.ozone_column_du == 0:
        return np.zeros_like(h)
    return np.maximum(1.0 - np.abs(h - atmosphere.ozone_peak_altitude) / atmosphere.ozone_half_width, 0.0)


def _ozone_extinction(atmosphere):
    """sigma_O3 n_max per channel [1/m], n_max = column * 2.687e20 / half width."""
    return np.asarray(atmosphere.ozone_cross_section) * atmosphere.ozone_column_du * 2.687e20 / atmosphere.ozone_half_width


def _simpson_column(points, direction, length, atmosphere, nodes=1601):
    """Density columns (Rayleigh, Mie, ozone tent) [m] from points along a direction over a length
    (uniform Simpson)."""
    rp = atmosphere.planet_radius
    t = np.linspace(0.0, 1.0, nodes)
    q = points[:, None, :] + (length[:, None] * t[None, :])[:, :, None] * direction
    h = np.linalg.norm(q, axis=2) - rp
    cols = []
    for height in (atmosphere.rayleigh_scale_height, atmosphere.mie_scale_height):
        cols.append(integrate.simpson(np.exp(-h / height), x=t, axis=1) * length)
    cols.append(integrate.simpson(_ozone_density(atmosphere, h), x=t, axis=1) * length)
    return cols


def _shadow_interval(p0, view, sun, rp):
    """Interval of s where p0 + s view is in the planet's shadow cylinder (p.sun < 0, |p_perp| < Rp)."""
    # |p_perp|^2 = |p|^2 - (p.sun)^2 = A s^2 + B s + C
    pv, ps, vs = p0 @ view, p0 @ sun, view @ sun
    a = 1 - vs * vs
    b = 2 * (pv - ps * vs)
    c = p0 @ p0 - ps * ps - rp * rp
    disc = b * b - 4 * a * c
    if a <= 0 or disc <= 0:
        return None
    lo, hi = (-b - math.sqrt(disc)) / (2 * a), (-b + math.sqrt(disc)) / (2 * a)
    # p.sun = ps + s vs < 0
    if vs > 0:
        hi = min(hi, -ps / vs)
    elif vs < 0:
        lo = max(lo, -ps / vs)
    elif ps >= 0:
        return None
    return (lo, hi) if hi > lo else None


def _single_scattering_reference(atmosphere, altitude, cos_view, cos_sun, azimuth, nodes=6001):
    """Ibar = sum_s beta_s F_s(cos theta) / (4 pi) Integral rho_s T_sun T_view ds by brute-force quadrature.

    View ray split at the exact shadow-cylinder boundary; Simpson on each lit piece; T_view by a
    cumulative Simpson/trapezoid of the columns from the observer; T_sun by a 1601-node Simpson along
    each sun chord. Independent of clsky.montecarlo (only the phase functions are shared, and they are
    tested separately against the notes' formulas). Ozone (the physical preset's) absorbs along both.
    """
    rp, ra = atmosphere.planet_radius, atmosphere.top_radius
    sv, ss = math.sqrt(1 - cos_view**2), math.sqrt(1 - cos_sun**2)
    view = np.array([sv, 0.0, cos_view])
    sun = np.array([ss * math.cos(azimuth), ss * math.sin(azimuth), cos_sun])
    p0 = np.array([0.0, 0.0, rp + altitude])
    r0 = rp + altitude
    b = r0 * cos_view
    if b < 0 and b * b - (r0 * r0 - rp * rp) >= 0:
        length = -b - math.sqrt(b * b - (r0 * r0 - rp * rp))  # hits the ground
    else:
        length = _chord_to_top(r0, cos_view, ra)
    pieces = [(0.0, length)]
    shadow = _shadow_interval(p0, view, sun, rp)
    if shadow is not None:
        lo, hi = max(shadow[0], 0.0), min(shadow[1], length)
        if hi > lo:
            pieces = [(a, c) for a, c in ((0.0, lo), (hi, length)) if c - a > 0]
    beta_r = np.asarray(atmosphere.rayleigh_scattering)
    beta_me = atmosphere.mie_extinction
    beta_o = _ozone_extinction(atmosphere)
    integral_r = np.zeros(3)
    integral_m = np.zeros(3)
    for a, c in pieces:
        # T_view at the nodes of [a, c]: cumulative trapezoid on a 4x finer grid from 0 to c.
        fine = np.linspace(0.0, c, 4 * nodes)
        h = np.linalg.norm(p0 + fine[:, None] * view, axis=1) - rp
        cum_r = integrate.cumulative_trapezoid(np.exp(-h / atmosphere.rayleigh_scale_height), fine, initial=0)
        cum_m = integrate.cumulative_trapezoid(np.exp(-h / atmosphere.mie_scale_height), fine, initial=0)
        cum_o = integrate.cumulative_trapezoid(_ozone_density(atmosphere, h), fine, initial=0)
        s = np.linspace(a, c, nodes)
        col_r = np.interp(s, fine, cum_r)
        col_m = np.interp(s, fine, cum_m)
        col_o = np.interp(s, fine, cum_o)
        p = p0 + s[:, None] * view
        h = np.linalg.norm(p, axis=1) - rp
        bs = p @ sun
        d_sun = -bs + np.sqrt(bs * bs + ra * ra - np.einsum("ij,ij->i", p, p))
        sun_r, sun_m, sun_o = [], [], []
        for k in range(0, nodes, 500):
            cr, cm, co = _simpson_column(p[k:k + 500], sun, d_sun[k:k + 500], atmosphere)
            sun_r.append(cr)
            sun_m.append(cm)
            sun_o.append(co)
        sun_r, sun_m, sun_o = np.concatenate(sun_r), np.concatenate(sun_m), np.concatenate(sun_o)
        transmit = np.exp(-beta_r[:, None] * (col_r + sun_r) - beta_me * (col_m + sun_m)
                          - beta_o[:, None] * (col_o + sun_o))
        integral_r += integrate.simpson(np.exp(-h / atmosphere.rayleigh_scale_height) * transmit, x=s, axis=1)
        integral_m += integrate.simpson(np.exp(-h / atmosphere.mie_scale_height) * transmit, x=s, axis=1)
    cos_theta = view @ sun
    return (beta_r * rayleigh_phase(cos_theta, atmosphere.rayleigh_phase) * integral_r
            + atmosphere.mie_scattering * cornette_shanks_phase(cos_theta, atmosphere.mie_g) * integral_m
            ) / (4 * math.pi)


REAL_CASES = [
    ("physical", dict(altitude=0.0, cos_view=0.5, cos_sun=0.7, azimuth=0.5)),
    # sun 1.7 degrees above the horizon, looking 6 degrees up, 17 degrees of azimuth from it (Mie lobe)
    ("atmosphere-plus", dict(altitude=0.0, cos_view=0.1, cos_sun=0.03, azimuth=0.3)),
    # from 8 km, looking down to the ground, sun 1.7 degrees below the horizon: the low part of the
    # view ray is in the planet's shadow
    ("physical", dict(altitude=8000.0, cos_view=-0.2, cos_sun=-0.03, azimuth=2.5)),
    # views from altitude down to the ground (issue 10, item 6): from 10 km, and from the top (100 km)
    ("physical", dict(altitude=10e3, cos_view=-0.8, cos_sun=0.5, azimuth=2.0)),
    ("atmosphere-plus", dict(altitude=100e3, cos_view=-0.5, cos_sun=0.7, azimuth=0.5)),
]


@pytest.mark.parametrize("name, case", REAL_CASES)
def test_single_scattering_matches_quadrature_in_the_default_atmosphere(name, case):
    atmosphere = black_preset(name)
    reference = _single_scattering_reference(atmosphere, **case)
    radiance, error = sky_radiance(atmosphere, **case, photons=200_000, seed=21, single_only=True)
    assert np.all(reference > 0)
    assert np.all(np.abs(radiance - reference) < Z * error), (radiance, reference, error,
                                                             (radiance - reference) / error)
    assert np.all(error < 0.02 * reference)


def test_reference_quadrature_is_converged():
    """The test's deterministic reference changes by < 2e-4 relative when its grid is halved."""
    atmosphere = black_preset("physical")
    case = REAL_CASES[2][1]
    fine = _single_scattering_reference(atmosphere, **case)
    coarse = _single_scattering_reference(atmosphere, **case, nodes=3001)
    np.testing.assert_allclose(coarse, fine, rtol=2e-4)


# Whole-sky properties -------------------------------------------------------------------------------

def test_multiple_scattering_adds_a_positive_amount():
    atmosphere = black_preset("physical")
    case = dict(altitude=0.0, cos_view=0.5, cos_sun=0.7, azimuth=0.5)
    single, single_error = sky_radiance(atmosphere, **case, photons=200_000, seed=31, single_only=True)
    full = simulate(atmosphere, **case, photons=200_000, seed=32)
    assert np.all(np.isfinite(full.radiance)) and np.all(full.radiance >= 0)
    assert np.all(np.isfinite(full.standard_error)) and np.all(full.standard_error >= 0)
    diff_error = np.hypot(single_error, full.standard_error)
    assert np.all(full.radiance - single > Z * diff_error)
    # Orders sum to the total, decrease, and the order cap truncates nothing.
    np.testing.assert_allclose(full.orders.sum(axis=0), full.radiance, rtol=1e-12)
    assert np.all(full.orders[1] > 0) and np.all(full.orders[1] < full.orders[0])
    assert np.all(full.truncated_paths == 0)
    # max_orders=2 keeps orders 1 and 2 only.
    two = simulate(atmosphere, **case, photons=200_000, seed=32, max_orders=2)
    assert np.all(two.radiance < full.radiance + Z * np.hypot(two.standard_error, full.standard_error))
    assert np.all(two.radiance > single - Z * diff_error)


def test_radiance_finite_nonnegative_in_various_geometries():
    atmosphere = black_preset("atmosphere-plus")
    for altitude, cos_view, cos_sun, azimuth in [(0.0, -0.3, 0.5, 0.0), (0.0, 0.0, 0.0, 0.0),
                                                 (100_000.0, 0.5, 0.5, 1.0), (100_000.0, -0.5, 0.5, 3.0),
                                                 (50_000.0, 1.0, -1.0, 0.0), (0.0, 1.0, 1.0, 0.0)]:
        radiance, error = sky_radiance(atmosphere, altitude, cos_view, cos_sun, azimuth, photons=5_000)
        assert radiance.shape == (3,) and error.shape == (3,)
        assert np.all(np.isfinite(radiance)) and np.all(radiance >= 0)
        assert np.all(np.isfinite(error)) and np.all(error >= 0)
    # Looking at the ground from the ground and straight up from the top: nothing on the way.
    assert np.all(sky_radiance(atmosphere, 0.0, -0.3, 0.5, photons=1000)[0] == 0)
    assert np.all(sky_radiance(atmosphere, 100_000.0, 0.5, 0.5, photons=1000)[0] == 0)
    with pytest.raises(ValueError):
        sky_radiance(atmosphere, -1.0, 0.5, 0.5)


def test_sun_far_below_the_horizon_is_dark():
    atmosphere = black_preset("physical")
    day, _ = sky_radiance(atmosphere, 0.0, 0.5, 0.5, photons=20_000, seed=41)
    night, error = sky_radiance(atmosphere, 0.0, 0.5, -0.5, photons=200_000, seed=42)
    assert np.all(night >= 0)
    assert np.all(night < 1e-6 * day)


def test_seed_reproducibility_and_independence():
    atmosphere = black_preset("physical")
    a = sky_radiance(atmosphere, 0.0, 0.3, 0.6, 1.0, photons=20_000, seed=7)
    b = sky_radiance(atmosphere, 0.0, 0.3, 0.6, 1.0, photons=20_000, seed=7)
    c = sky_radiance(atmosphere, 0.0, 0.3, 0.6, 1.0, photons=20_000, seed=8)
    np.testing.assert_array_equal(a[0], b[0])
    assert not np.array_equal(a[0], c[0])
    assert np.all(np.abs(a[0] - c[0]) < Z * np.hypot(a[1], c[1]))


# Argument checks ------------------------------------------------------------------------------------

@pytest.mark.parametrize("arguments, options, message", [
    ((0.0, 0.5, math.nan), {}, r"^cos_sun must be a number in \[-1, 1\], got nan$"),          # was NaN radiance
    ((0.0, 0.5, 0.5, math.nan), {}, r"^azimuth must be a finite number \(radians\), got nan$"),
    # 'math domain error'
    ((0.0, 0.5, 0.5, math.inf), {}, r"^azimuth must be a finite number \(radians\), got inf$"),
    ((0.0, math.nan, 0.5), {}, r"^cos_view must be a number in \[-1, 1\], got nan$"),         # was a silent 0
    ((0.0, 5.0, 0.5), {}, r"^cos_view must be a number in \[-1, 1\], got 5$"),                # was taken as 1
    ((-10.0, 0.5, 0.5), {}, r"^altitude must be a number in \[0, 100000\] m, got -10$"),
    ((0.0, 0.5, 0.5), dict(photons=2.7), r"^photons must be an integer in \[2, 10000000000\], got 2.7 \(float\)$"),
    ((0.0, 0.5, 0.5), dict(photons="10"), r"^photons must be an integer in \[2, 10000000000\], got '10' \(str\)$"),
    ((0.0, 0.5, 0.5), dict(max_orders=1.9),
     r"^max_orders must be None or an integer in \[1, 1000000\], got 1.9 \(float\)$"),
    ((0.0, 0.5, 0.5), dict(max_orders=True),
     r"^max_orders must be None or an integer in \[1, 1000000\], got True \(bool\)$"),
    ((0.0, 0.5, 0.5), dict(seed=-1), r"^seed must be None or an integer in \[0, 18446744073709551615\], got -1$"),
    ((0.0, 0.5, 0.5), dict(seed=1.5),
     r"^seed must be None or an integer in \[0, 18446744073709551615\], got 1.5 \(float\)$"),
    ((0.0, 0.5, 0.5), dict(chunk=0), r"^chunk must be an integer in \[1, 2147483647\], got 0$"),
])
def test_simulate_refuses_bad_arguments_by_name(arguments, options, message):
    """Every argument of simulate (and so sky_radiance) is checked before any path is traced: NaN
    cosines or azimuths gave NaN radiance or a silent 0, a view cosine of 5 was taken as 1, and 2.7
    photons ran as 2."""
    with pytest.raises(ValueError, match=message):
        simulate(black_preset("physical"), *arguments, **{"photons": 10, **options})


@pytest.mark.parametrize("arguments, options, message", [
    ((0.0, 0.5, 0.5), dict(step=0.0), r"^step must be a number in \(0, 100000\] m, got 0$"),   # ZeroDivisionError
    ((0.0, 0.5, 0.5), dict(step=-100.0), r"^step must be a number in \(0, 100000\] m, got -100$"),   # ran
    ((0.0, 0.5, 0.5), dict(nodes=0), r"^nodes must be an integer in \[1, 1000\], got 0$"),
    ((-10.0, 0.5, 0.5), {}, r"^altitude must be a number in \[0, 100000\] m, got -10$"),    # ran under the ground
    ((200e3, 0.5, 0.5), {}, r"^altitude must be a number in \[0, 100000\] m, got 200000$"),    # gave 0
    ((0.0, math.nan, 0.5), {}, r"^cos_view must be a number in \[-1, 1\], got nan$"),
])
def test_single_scattering_quadrature_refuses_bad_arguments_by_name(arguments, options, message):
    from clsky.montecarlo import single_scattering

    with pytest.raises(ValueError, match=message):
        single_scattering(black_preset("physical"), *arguments, **options)


@pytest.mark.parametrize("arguments, message", [
    ((0.0, 1.0000001, 0.5), r"^cos_view must be a number in \[-1, 1\], got 1.0000001$"),    # printed as its bound 1
    ((10**400, 0.5, 0.5), r"^altitude must be a number in \[0, 100000\] m, got 1e\+400$"),  # OverflowError
])
def test_the_tracers_messages_show_the_value_typed(arguments, message):
    with pytest.raises(ValueError, match=message):
        simulate(black_preset("physical"), *arguments, photons=10)


def test_the_tracer_takes_0d_arrays_and_a_seed_of_none():
    """0-d arrays (float() took them before the checks) and seed=None (fresh entropy, as default_rng) stay
    valid arguments."""
    atmosphere = black_preset("physical")
    result = simulate(atmosphere, np.array(0.0), np.array(0.5), 0.5, photons=np.array(10), seed=None)
    assert np.all(np.isfinite(result.radiance))
