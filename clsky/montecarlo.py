"""Independent Monte Carlo check of sky radiance: a small vectorised NumPy path tracer.

The atmosphere is a spherical shell (planet radius Rp, top radius Ra) of two exponential species,
rho_s(h) = exp(-h / H_s): Rayleigh (extinction = scattering, beta_R per channel) and Mie (scattering
beta_M per channel by Angstrom's law beta_M (lambda / lambda_0)^-alpha, extinction beta_M / ratio,
Cornette-Shanks phase), and, when ``atmosphere.ozone_column_du`` > 0,
ozone, which only absorbs: extinction sigma_O3 n_O3(h) per channel with the tent
n_O3 = n_max max(0, 1 - |h - h_peak| / w), n_max = column [DU] * 2.687e20 / w. The ground is a Lambertian reflector of albedo
``atmosphere.ground_albedo`` (0, black, when the field is absent or 0), there is no refraction,
and the sun is a directional source of irradiance 1 per channel, so :func:`sky_radiance` returns radiance
per unit incident light, comparable with ``table radiance / atmosphere.incident_light``
(:func:`absolute_sky_radiance` multiplies by ``incident_light``).

This module deliberately shares no code with the table computation (it imports nothing from
``clsky``): ray-sphere intersections, phase functions, phase sampling and transmittance are written
here again, from ``docs/physics.md``, so that it is an independent check of the physics.

Conventions (``docs/physics.md``)
-----------------------------------
* Observer P0 = (0, 0, Rp + altitude); zenith = +z. V is the view direction (from the observer
  outward); radiance measured along V arrives travelling along -V. Sun points at the sun.
  V = (sin phi, 0, cos phi), Sun = (sin delta cos omega, sin delta sin omega, cos delta).
* Phase functions F(c) carry no 1/(4 pi): F / (4 pi) is the probability density per steradian when F
  averages to 1 over the sphere. c is the cosine of the angle between the direction the light travels
  before and after the scattering event, c = dot(L, -V) = dot(Sun, V) for single scattering seen along V:
  c = 1 is forward scattering (looking straight at the sun).
* Cornette-Shanks with the notes' sign: F_M(c) = 3(1-g^2)/(2(2+g^2)) (1+c^2) / (1+g^2+2gc)^(3/2);
  negative g (default -0.85) peaks at c = 1.

Estimator
---------
Backward path tracing from the observer, one scalar-extinction simulation per channel (the three
channels are independent photon populations, processed together in one vectorised batch):

1. Free flight by delta (Woodcock) tracking with the constant majorant mu_bar = beta_R + beta_M^e
   (+ sigma_O3 n_max with ozone), the sum of each species' largest extinction (densities are <= 1
   in the shell, the ozone tent <= n_max). A tentative collision at x is real
   with probability mu_t(x) / mu_bar, else null (the path continues unchanged). Ozone is part of
   mu_t: a real collision absorbs with probability mu_O3 / mu_t, which the weight below accounts for. Leaving through the top
   of the atmosphere, or hitting a black ground, ends the path. Real collisions are distributed with
   density mu_t(x) T(x0, x) along the path, so no transmittance weight is needed.
   A path that reaches a ground of albedo a > 0 before its tentative collision (probability T(x0, x_g))
   has a ground event there, counted as an order: next-event estimation toward the sun with the
   Lambertian BRDF, w a / pi max(dot(n, Sun), 0) T_sun(x_g) (n the ground's normal; 0 when the planet
   shadows the sun), then the path continues from x_g into a cosine-weighted direction about n
   (density cos / pi, so that BRDF * cos / density = a: w *= a).
2. Next-event estimation toward the sun at every real collision (order k = number of real collisions):
   contribution = w * sum_s mu_s(x) / mu_t(x) * F_s(dot(Sun, d)) / (4 pi) * T_sun(x), with d the current
   (backward) direction and T_sun from :func:`optical_depth_to_top` and :func:`ozone_column_to_top`
   (0 if the sun ray hits the planet).
3. Continuation: species s chosen with probability mu_s / (mu_R + mu_M), new backward direction d'
   with dot(d, d') drawn from F_s / (4 pi mean F_s) (exact samplers), weight
   w *= (mu_R + mu_M) / mu_t * mean(F_s) (the single-scattering albedo; mean F_s = 1 except for the
   notes' modified Rayleigh phase, whose mean 1.2533 adds energy, as the notes' phase does).

:func:`single_scattering` is the deterministic counterpart of ``max_orders=1``: the same phases and
transmittances integrated along the view ray by Gauss-Legendre quadrature (no noise; the planet's
shadow edge located and made a panel edge).

The per-photon sum of contributions is an unbiased estimate of the radiance per unit irradiance; the
standard error is the sample standard deviation over photons / sqrt(photons). The only bias is the
truncation at ``max_orders`` (default :data:`DEFAULT_MAX_ORDERS` = 64 when ``max_orders`` is None):
:func:`simulate` reports how many paths and how much weight were still alive at the cap (in the default
atmosphere, none of 200 000 paths per channel survives 30 orders).
"""

from __future__ import annotations

import dataclasses
import decimal
import math

import numpy as np

__all__ = [
    "DEFAULT_MAX_ORDERS",
    "MonteCarloResult",
    "rayleigh_phase",
    "cornette_shanks_phase",
    "henyey_greenstein_phase",
    "phase_mean",
    "sample_rayleigh_cosine",
    "sample_henyey_greenstein_cosine",
    "sample_cornette_shanks_cosine",
    "ray_sphere_exit",
    "ray_sphere_entry",
    "optical_depth_to_top",
    "ozone_column_to_top",
    "transmittance_to_top",
    "simulate",
    "sky_radiance",
    "absolute_sky_radiance",
    "single_scattering",
]

#: Scattering-order cap used when ``max_orders`` is None (truncation reported by :func:`simulate`).
DEFAULT_MAX_ORDERS = 64
#: Largest ``max_orders`` and ``photons`` (paths per channel) :func:`simulate` takes: far beyond any use
#: (the tracer's orders die out long before; 1e10 paths would take days and 240 GB of path state).
MAX_ORDERS_LIMIT, MAX_PHOTONS = 1_000_000, 10**10
#: Largest seed :func:`simulate` takes (any 64-bit unsigned integer; None: fresh entropy from the system).
MAX_SEED = 2**64 - 1
#: Gauss-Legendre nodes per leg of the sun-ray optical depth (error < 1e-9 relative, see tests).
QUADRATURE_NODES = 20
#: Integrate a species' density only up to K scale heights above the lowest point of a leg
#: (the neglected tail is < exp(-K) = 2e-16 of the column).
DENSITY_CUTOFF_SCALE_HEIGHTS = 36.0

#: 1 Dobson unit [molecules / m^2] (written here again: this module imports nothing from clsky).
_DOBSON_UNIT = 2.687e20

_FOUR_PI = 4.0 * math.pi
_MODIFIED_RAYLEIGH = (0.8 * 7.0 / 5.0, 0.8 * 0.5)  # F = a + b c^2 of the notes' modified phase
_TRUE_RAYLEIGH = (0.75, 0.75)


# Phase functions -------------------------------------------------------------------------------------

def _rayleigh_coefficients(kind: str) -> tuple[float, float]:
    if kind == "rayleigh":
        return _TRUE_RAYLEIGH
    if kind == "modified_atmosphereplus":
        return _MODIFIED_RAYLEIGH
    raise ValueError(f"unknown Rayleigh phase {kind!r}: expected 'rayleigh' or 'modified_atmosphereplus'")


def rayleigh_phase(cos_theta, kind: str = "rayleigh"):
    """Rayleigh phase function F_R(c) (no 1/(4 pi) factor), dimensionless.

    Parameters
    ----------
    cos_theta : array_like
        Cosine of the scattering angle c = dot(Sun, V) (1 = forward).
    kind : {"rayleigh", "modified_atmosphereplus"}
        ``"rayleigh"``: 3/4 (1 + c^2), mean 1 over the sphere. ``"modified_atmosphereplus"``:
        the notes' artistic 0.8 (7/5 + c^2 / 2), mean 1.2533.

    Returns
    -------
    numpy.ndarray
        F_R(c).
    """
    a, b = _rayleigh_coefficients(kind)
    c = np.asarray(cos_theta, dtype=np.float64)
    return a + b * c * c


def cornette_shanks_phase(cos_theta, g: float):
    """Cornette-Shanks phase function F_M(c) in the notes' sign convention, dimensionless.

    F_M(c) = 3 (1 - g^2) / (2 (2 + g^2)) * (1 + c^2) / (1 + g^2 + 2 g c)^(3/2); mean 1 over the sphere.

    Parameters
    ----------
    cos_theta : array_like
        c = dot(Sun, V) (1 = forward, looking at the sun).
    g : float
        Asymmetry in the notes' convention, |g| < 1: negative g peaks forward (c = 1).

    Returns
    -------
    numpy.ndarray
        F_M(c).
    """
    c = np.asarray(cos_theta, dtype=np.float64)
    g = float(g)
    return (3.0 * (1.0 - g * g) / (2.0 * (2.0 + g * g)) * (1.0 + c * c)
            / (1.0 + g * g + 2.0 * g * c) ** 1.5)


def henyey_greenstein_phase(cos_theta, g: float):
    """Henyey-Greenstein phase function, textbook sign (g > 0 forward), dimensionless, mean 1.

    Parameters
    ----------
    cos_theta : array_like
        Cosine of the scattering angle (1 = forward).
    g : float
        Textbook asymmetry, |g| < 1 (mean cosine).

    Returns
    -------
    numpy.ndarray
        (1 - g^2) / (1 + g^2 - 2 g c)^(3/2).
    """
    c = np.asarray(cos_theta, dtype=np.float64)
    g = float(g)
    return (1.0 - g * g) / (1.0 + g * g - 2.0 * g * c) ** 1.5


def phase_mean(kind: str, g: float = 0.0) -> float:
    """Mean of a phase function over the sphere, (1/2) Integral_{-1}^{1} F(c) dc (dimensionless).

    Parameters
    ----------
    kind : {"rayleigh", "modified_atmosphereplus", "cornette_shanks"}
        Phase function.
    g : float, optional
        The Mie asymmetry, which no mean here depends on (Cornette-Shanks and Rayleigh are normalised for
        every g): kept so that a caller states the phase it means, as the samplers take it.

    Returns
    -------
    float
        1 for the normalised phases, 0.8 * (7/5 + 1/6) = 1.2533 for the notes' modified Rayleigh.
    """
    if kind == "cornette_shanks":
        return 1.0
    a, b = _rayleigh_coefficients(kind)
    return a + b / 3.0


# Phase samplers -------------------------------------------------------------------------------------

def sample_rayleigh_cosine(u, kind: str = "rayleigh"):
    """Exact inverse-CDF sample of the scattering cosine from a Rayleigh-type phase a + b c^2.

    Solves CDF(c) = u, i.e. the depressed cubic c^3 + p c + q = 0 with p = 3 a / b > 0 (one real root,
    Cardano's formula, no cancellation since p > 0).

    Parameters
    ----------
    u : array_like
        Uniform deviates in [0, 1).
    kind : {"rayleigh", "modified_atmosphereplus"}
        Phase function (see :func:`rayleigh_phase`).

    Returns
    -------
    numpy.ndarray
        Cosines in [-1, 1] distributed with density F(c) / (2 mean F) on [-1, 1].
    """
    a, b = _rayleigh_coefficients(kind)
    u = np.asarray(u, dtype=np.float64)
    # CDF(c) = (a (c + 1) + b (c^3 + 1) / 3) / (2 a + 2 b / 3)
    p = 3.0 * a / b
    q = 3.0 * (a + b / 3.0 - u * (2.0 * a + 2.0 * b / 3.0)) / b
    disc = np.sqrt(0.25 * q * q + p ** 3 / 27.0)
    c = np.cbrt(-0.5 * q + disc) + np.cbrt(-0.5 * q - disc)
    return np.clip(c, -1.0, 1.0)


def sample_henyey_greenstein_cosine(u, g: float):
    """Exact inverse-CDF sample of the Henyey-Greenstein cosine (textbook sign: g > 0 forward).

    Parameters
    ----------
    u : array_like
        Uniform deviates in [0, 1).
    g : float
        Textbook asymmetry, |g| < 1.

    Returns
    -------
    numpy.ndarray
        Cosines with density henyey_greenstein_phase(c, g) / 2 on [-1, 1].
    """
    u = np.asarray(u, dtype=np.float64)
    g = float(g)
    if abs(g) < 1e-6:
        return 2.0 * u - 1.0
    s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u)
    return np.clip((1.0 + g * g - s * s) / (2.0 * g), -1.0, 1.0)


def sample_cornette_shanks_cosine(rng: np.random.Generator, n: int, g: float):
    """Exact sample of the Cornette-Shanks cosine (notes' sign of g) by rejection from Henyey-Greenstein.

    With g_hg = -g (textbook sign), F_CS(c) = 3 / (2 (2 + g^2)) (1 + c^2) F_HG(c; g_hg), so a
    Henyey-Greenstein proposal accepted with probability (1 + c^2) / 2 is exactly Cornette-Shanks
    (acceptance rate (2 + g^2) / 3 >= 2/3).

    Parameters
    ----------
    rng : numpy.random.Generator
        Random source.
    n : int
        Number of samples.
    g : float
        Asymmetry in the notes' convention (negative: forward peak).

    Returns
    -------
    numpy.ndarray
        n cosines with density cornette_shanks_phase(c, g) / 2 on [-1, 1].
    """
    out = np.empty(n, dtype=np.float64)
    todo = np.arange(n)
    while todo.size:
        c = sample_henyey_greenstein_cosine(rng.random(todo.size), -g)
        accept = 2.0 * rng.random(todo.size) < 1.0 + c * c
        out[todo[accept]] = c[accept]
        todo = todo[~accept]
    return out


def _scatter_directions(d, cos_theta, rng):
    """Rotate unit vectors d (n, 3) by polar cosine cos_theta and a uniform azimuth."""
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    # Branchless orthonormal basis (Duff et al. 2017).
    sign = np.where(z >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + z)
    b = x * y * a
    t1 = np.stack([1.0 + sign * x * x * a, sign * b, -sign * x], axis=1)
    t2 = np.stack([b, sign + y * y * a, -y], axis=1)
    phi = 2.0 * math.pi * rng.random(d.shape[0])
    sin_theta = np.sqrt(np.maximum(0.0, 1.0 - cos_theta * cos_theta))
    new = (cos_theta[:, None] * d + (sin_theta * np.cos(phi))[:, None] * t1
           + (sin_theta * np.sin(phi))[:, None] * t2)
    return new / np.linalg.norm(new, axis=1)[:, None]


# Geometry ------------------------------------------------------------------------------------------

def ray_sphere_exit(r, mu, radius):
    """Distance from a point inside a sphere to where a ray leaves it, in metres.

    Parameters
    ----------
    r : array_like
        Distance of the point from the centre [m], r <= radius.
    mu : array_like
        Cosine between the ray and the local vertical (outward radial direction).
    radius : float
        Sphere radius [m].

    Returns
    -------
    numpy.ndarray
        t >= 0 [m] with |x + t d| = radius; computed without cancellation
        (t = (R^2 - r^2) / (b + sqrt(b^2 + R^2 - r^2)) when b = r mu > 0).
    """
    r = np.asarray(r, dtype=np.float64)
    b = r * np.asarray(mu, dtype=np.float64)
    gap = np.maximum((radius - r) * (radius + r), 0.0)  # R^2 - r^2 >= 0
    root = np.sqrt(b * b + gap)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(b > 0.0, gap / (b + root), root - b)
    return np.where((b > 0.0) & (b + root == 0.0), 0.0, t)


def ray_sphere_entry(r, mu, radius):
    """Distance from a point outside (or on) a sphere to where a ray first hits it, in metres.

    Parameters
    ----------
    r : array_like
        Distance of the point from the centre [m], r >= radius.
    mu : array_like
        Cosine between the ray and the local vertical.
    radius : float
        Sphere radius [m].

    Returns
    -------
    numpy.ndarray
        Distance t >= 0 [m], or +inf where the ray misses the sphere (going up, or passing above it).
    """
    r = np.asarray(r, dtype=np.float64)
    b = r * np.asarray(mu, dtype=np.float64)
    excess = np.maximum((r - radius) * (r + radius), 0.0)  # r^2 - R^2 >= 0
    disc = b * b - excess
    hit = (b < 0.0) & (disc >= 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = excess / (-b + np.sqrt(np.maximum(disc, 0.0)))
    t = np.where(excess == 0.0, 0.0, t)
    return np.where(hit, t, np.inf)


# Transmittance -------------------------------------------------------------------------------------

def _leg_columns(r_t, v_lo, v_hi, planet_radius, scale_height, nodes, weights):
    """Integral of exp(-h/H) ds over the ray part where sqrt(r - r_t) runs from v_lo to v_hi."""
    half = 0.5 * (v_hi - v_lo)
    v = 0.5 * (v_hi + v_lo)[:, None] + half[:, None] * nodes
    v2 = v * v
    rt = r_t[:, None]
    # s = v sqrt(v^2 + 2 r_t) from the tangent point, ds/dv = 2 r / sqrt(r + r_t): smooth, no singularity.
    f = np.exp(-((rt - planet_radius) + v2) / scale_height) * (2.0 * (rt + v2) / np.sqrt(v2 + 2.0 * rt))
    return half * (f @ weights)


def _ray_legs(r, mu, planet_radius):
    """The geometry both column integrals start from, for rays from radii ``r`` [m] at cosines ``mu``
    to the local vertical: (r, r_t, r - r_t, going down, hitting the planet), flattened; r_t = r sin(zenith)
    is the closest approach (impact parameter), r - r_t computed without cancellation."""
    r = np.atleast_1d(np.asarray(r, dtype=np.float64))
    mu = np.clip(np.atleast_1d(np.asarray(mu, dtype=np.float64)), -1.0, 1.0)
    r, mu = (a.ravel() for a in np.broadcast_arrays(r, mu))
    sin_zenith = np.sqrt(np.maximum(0.0, (1.0 - mu) * (1.0 + mu)))
    r_t = r * sin_zenith
    above_tangent = r * mu * mu / (1.0 + sin_zenith)
    down = mu < 0.0
    return r, r_t, above_tangent, down, down & (r_t < planet_radius)


def optical_depth_to_top(r, mu, planet_radius, top_radius, scale_heights, nodes=QUADRATURE_NODES):
    """Density columns Integral rho_s ds from points to the top of the atmosphere along a ray [m].

    Deterministic Gauss-Legendre quadrature in the variable v = sqrt(r(s) - r_t), where r_t is the
    closest-approach radius of the ray (impact parameter). In v the path element is
    ds = 2 r / sqrt(r + r_t) dv (smooth even at the tangent point) and the density becomes a Gaussian
    or an exponential in v, which Gauss-Legendre integrates to ~1e-10 relative with 16-20 nodes.
    A ray going down (mu < 0) is split at its tangent point into a descending and an ascending leg.
    Each leg is cut DENSITY_CUTOFF_SCALE_HEIGHTS scale heights above its lowest point.

    Parameters
    ----------
    r : array_like
        Radii of the start points [m], planet_radius <= r <= top_radius.
    mu : array_like
        Cosine between the ray and the local vertical at the start point.
    planet_radius, top_radius : float
        Rp and Ra [m].
    scale_heights : sequence of float
        Scale heights H_s [m] of the species (densities exp(-h / H_s)).
    nodes : int, optional
        Gauss-Legendre nodes per leg.

    Returns
    -------
    columns : numpy.ndarray
        Shape (len(scale_heights), n): Integral exp(-h/H_s) ds [m] to the top of the atmosphere
        (the value is meaningless where ``blocked``).
    blocked : numpy.ndarray of bool
        Shape (n,): the ray hits the planet (mu < 0 and r_t < Rp).
    """
    r, r_t, above_tangent, down, blocked = _ray_legs(r, mu, planet_radius)
    x, w = np.polynomial.legendre.leggauss(int(nodes))
    columns = np.zeros((len(scale_heights), r.size))
    ok = ~blocked
    idx_up = np.flatnonzero(ok)
    idx_down = np.flatnonzero(ok & down)
    for k, height in enumerate(scale_heights):
        height = float(height)
        # Ascending leg: from the start point (mu >= 0) or from the tangent point (mu < 0) to the top.
        rt = r_t[idx_up]
        low_r = np.where(down[idx_up], rt, r[idx_up])
        v_lo = np.where(down[idx_up], 0.0, np.sqrt(above_tangent[idx_up]))
        v_hi = np.sqrt(np.maximum(np.minimum(top_radius, low_r + DENSITY_CUTOFF_SCALE_HEIGHTS * height) - rt,
                                  0.0))
        v_hi = np.maximum(v_hi, v_lo)
        columns[k, idx_up] = _leg_columns(rt, v_lo, v_hi, planet_radius, height, x, w)
        if idx_down.size:
            # Descending leg: from the start point down to the tangent point.
            rt = r_t[idx_down]
            v_hi = np.sqrt(np.maximum(np.minimum(r[idx_down], rt + DENSITY_CUTOFF_SCALE_HEIGHTS * height) - rt,
                                      0.0))
            columns[k, idx_down] += _leg_columns(rt, np.zeros_like(rt), v_hi, planet_radius, height, x, w)
    return columns, blocked


def _tent(h, peak, half_width):
    """Ozone tent max(0, 1 - |h - peak| / half_width), 1 at the peak."""
    return np.clip(1.0 - np.abs(h - peak) / half_width, 0.0, None)


def _tent_leg(r_t, v_lo, v_hi, planet_radius, peak, half_width, nodes, weights):
    """Integral of the tent ds over the ray part where sqrt(r - r_t) runs from v_lo to v_hi, split at the
    tent's three kinks (r = Rp + peak -/+ half_width and Rp + peak) so that each piece is smooth."""
    kinks = [np.clip(np.sqrt(np.maximum(planet_radius + a - r_t, 0.0)), v_lo, v_hi)
             for a in (peak - half_width, peak, peak + half_width)]
    edges = [v_lo] + kinks + [v_hi]
    total = np.zeros_like(r_t)
    for a, b in zip(edges[:-1], edges[1:]):
        half = 0.5 * (b - a)
        v = 0.5 * (b + a)[:, None] + half[:, None] * nodes
        v2 = v * v
        rt = r_t[:, None]
        f = _tent((rt - planet_radius) + v2, peak, half_width) * (2.0 * (rt + v2) / np.sqrt(v2 + 2.0 * rt))
        total += half * (f @ weights)
    return total


def ozone_column_to_top(r, mu, planet_radius, top_radius, peak, half_width, nodes=QUADRATURE_NODES):
    """Column of the ozone tent, Integral max(0, 1 - |h - peak| / half_width) ds, from points to the top
    of the atmosphere along a ray [m] (times n_max: molecules / m^2).

    Same variable v = sqrt(r(s) - r_t) as :func:`optical_depth_to_top`; in it h = r_t - Rp + v^2, so the
    tent is a piecewise quadratic in v, and each leg is split at the kinks and integrated piece by
    piece by Gauss-Legendre (exact up to the smooth path element 2 r / sqrt(r + r_t)).

    Parameters
    ----------
    r, mu : array_like
        Radii [m] of the start points and cosines between the ray and the local vertical.
    planet_radius, top_radius : float
        Rp and Ra [m].
    peak, half_width : float
        The tent's peak altitude and half width [m].
    nodes : int, optional
        Gauss-Legendre nodes per piece.

    Returns
    -------
    columns : numpy.ndarray
        Shape (n,) [m] (meaningless where ``blocked``).
    blocked : numpy.ndarray of bool
        Shape (n,): the ray hits the planet.
    """
    r, r_t, above_tangent, down, blocked = _ray_legs(r, mu, planet_radius)
    x, w = np.polynomial.legendre.leggauss(int(nodes))
    columns = np.zeros(r.size)
    ok = np.flatnonzero(~blocked)
    rt = r_t[ok]
    v_start = np.sqrt(above_tangent[ok])
    v_top = np.sqrt(np.maximum(top_radius - rt, 0.0))
    is_down = down[ok]
    # Ascending leg (from the start, or from the tangent point when going down), then the descending one.
    columns[ok] = _tent_leg(rt, np.where(is_down, 0.0, v_start), np.maximum(v_top, v_start), planet_radius,
                            peak, half_width, x, w)
    columns[ok] += np.where(is_down, _tent_leg(rt, np.zeros_like(rt), v_start, planet_radius, peak, half_width,
                                               x, w), 0.0)
    return columns, blocked


def _ozone(atmosphere):
    """(beta_O3 at the tent's peak per channel [1/m], peak [m], half width [m]); beta = 0 without ozone."""
    column = float(getattr(atmosphere, "ozone_column_du", 0.0))
    peak = float(getattr(atmosphere, "ozone_peak_altitude", 25_000.0))
    half_width = float(getattr(atmosphere, "ozone_half_width", 15_000.0))
    sigma = np.asarray(getattr(atmosphere, "ozone_cross_section", (0.0, 0.0, 0.0)), dtype=np.float64)
    return sigma * (column * _DOBSON_UNIT / half_width), peak, half_width


def transmittance_to_top(atmosphere, r, mu, nodes=QUADRATURE_NODES):
    """Transmittance from points to the top of the atmosphere along a ray, per channel.

    Parameters
    ----------
    atmosphere : AtmosphereParameters
        Planet and air (radii [m], scale heights [m], beta_R [1/m], beta_M^e [1/m], ozone).
    r : array_like
        Radii of the start points [m].
    mu : array_like
        Cosine between the ray and the local vertical.
    nodes : int, optional
        Gauss-Legendre nodes per leg (see :func:`optical_depth_to_top`).

    Returns
    -------
    numpy.ndarray
        Shape (n, 3): exp(-(beta_R col_R + beta_M^e col_M + beta_O3 col_O3)) per channel (r, g, b); 0
        where the ray hits the planet.
    """
    columns, blocked = optical_depth_to_top(
        r, mu, atmosphere.planet_radius, atmosphere.top_radius,
        (atmosphere.rayleigh_scale_height, atmosphere.mie_scale_height), nodes)
    beta_r = np.asarray(atmosphere.rayleigh_scattering, dtype=np.float64)
    tau = columns[0][:, None] * beta_r[None, :] + columns[1][:, None] * _mie_extinction(atmosphere)[None, :]
    beta_o, peak, half_width = _ozone(atmosphere)
    if np.any(beta_o > 0.0):
        ozone, _ = ozone_column_to_top(r, mu, atmosphere.planet_radius, atmosphere.top_radius, peak, half_width,
                                       nodes)
        tau = tau + ozone[:, None] * beta_o[None, :]
    return np.where(blocked[:, None], 0.0, np.exp(-tau))


def _mie_scattering(atmosphere) -> np.ndarray:
    """beta_M per channel [1/m]: Angstrom's law beta_M (lambda / lambda_0)^-alpha, written here again
    from the field definitions (``mie_angstrom_exponent`` alpha, default 0: every channel beta_M)."""
    beta = float(atmosphere.mie_scattering)
    alpha = float(getattr(atmosphere, "mie_angstrom_exponent", 0.0))
    if alpha == 0.0:
        return np.full(3, beta)
    reference = float(getattr(atmosphere, "mie_reference_wavelength", 550.0))
    wavelengths = np.asarray(atmosphere.wavelengths, dtype=np.float64)
    return beta * np.power(wavelengths / reference, -alpha)


def _mie_extinction(atmosphere) -> np.ndarray:
    """beta_M^e per channel [1/m]: beta_M / ratio."""
    return _mie_scattering(atmosphere) / float(atmosphere.mie_extinction_ratio)


# Path tracer ---------------------------------------------------------------------------------------

#: Contributing paths a channel needs before its standard error is taken as its error
#: (:attr:`MonteCarloResult.reliable`): a mean of fewer heavy-tailed values has a spread its sample
#: deviation does not see (the usual floor of the central limit theorem's use).
MIN_CONTRIBUTING_PATHS = 30


@dataclasses.dataclass(frozen=True)
class MonteCarloResult:
    """Outcome of :func:`simulate`; radiances are per unit solar irradiance [1/sr].

    Attributes
    ----------
    radiance, standard_error : numpy.ndarray
        Shape (3,): estimate and its standard error, per channel (r, g, b).
    orders : numpy.ndarray
        Shape (max_orders, 3): contribution of each scattering order 1..max_orders (sums to radiance).
    max_orders : int
        Highest order counted.
    truncated_paths : numpy.ndarray
        Shape (3,): paths per channel still alive when the order cap stopped them (with an explicit
        ``max_orders`` or ``single_only`` this is the intended cut, not an error).
    truncated_weight : numpy.ndarray
        Shape (3,): sum of their weights / photons (the per-photon mean throughput cut off; the
        neglected radiance is about this times the mean NEE factor of one more order).
    photons : int
        Paths per channel.
    real_collisions, null_collisions : int
        Event counts over all channels.
    contributing_paths : numpy.ndarray
        Shape (3,): paths per channel that brought any light to the eye. With fewer than
        :data:`MIN_CONTRIBUTING_PATHS` the standard error is no measure of the error (:attr:`reliable`):
        the estimate rests on a few heavy-tailed values (at -6 deg, 2000 paths, the 95 % interval held the
        exact single scattering in 38 to 58 % of the seeds), and where none contributed the result is
        0 +- 0 for a radiance these paths cannot resolve, not one that is 0.
    """

    radiance: np.ndarray
    standard_error: np.ndarray
    orders: np.ndarray
    max_orders: int
    truncated_paths: np.ndarray
    truncated_weight: np.ndarray
    photons: int
    real_collisions: int
    null_collisions: int
    contributing_paths: np.ndarray

    @property
    def reliable(self) -> np.ndarray:
        """Shape (3,) bool: the channels whose standard error measures their error (at least
        :data:`MIN_CONTRIBUTING_PATHS` contributing paths)."""
        return self.contributing_paths >= MIN_CONTRIBUTING_PATHS


def _sun_transmittance(r, mu, channel, rp, ra, beta_r, beta_me, scale_heights, beta_o, ozone_peak, ozone_half_width,
                       chunk):
    """Transmittance toward the sun from points at radii r [m] along cosines mu, each in its channel
    (0 where the planet blocks the sun); beta_r, beta_me (and beta_o, None without ozone) per channel.
    Computed ``chunk`` points at a time."""
    t_sun = np.empty(r.size)
    for start in range(0, r.size, chunk):
        block = slice(start, start + chunk)
        cols, blocked = optical_depth_to_top(r[block], mu[block], rp, ra, scale_heights)
        tau = cols[0] * beta_r[channel[block]] + cols[1] * beta_me[channel[block]]
        if beta_o is not None:
            ozone, _ = ozone_column_to_top(r[block], mu[block], rp, ra, ozone_peak, ozone_half_width)
            tau = tau + ozone * beta_o[channel[block]]
        t_sun[block] = np.where(blocked, 0.0, np.exp(-tau))
    return t_sun


# Argument checks: the messages of clsky.errors' checks ('{name} must be ..., got {value}'), written here
# because the tracer imports nothing from clsky (it shares no code with what it checks).

def _check_real(name, value, low=-math.inf, high=math.inf, low_open=False, unit=""):
    """``value`` as a float if it is a finite real number (not a bool or a string; a 0-d array of one
    too) in [low, high] (or (low, high] with ``low_open``); ValueError naming ``name`` otherwise."""
    value = _scalar(value)
    real = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))
    number = _as_float(value) if real else math.nan
    if math.isfinite(number) and (low < number if low_open else low <= number) and number <= high:
        return number
    if math.isinf(low) and math.isinf(high):
        bounds = "a finite number"
    elif math.isinf(high):
        bounds = f"a finite number {'>' if low_open else '>='} {low:g}"
    else:
        bounds = f"a number in {'(' if low_open else '['}{low:g}, {high:g}]"
    raise ValueError(f"{name} must be {bounds}{unit}, got {_shown(value)}")


def _check_integer(name, value, low, high, optional=False):
    """``value`` as an int if it is an integer (not a bool; a 0-d array of one too) in [low, high], or None
    with ``optional``; ValueError naming ``name`` otherwise."""
    if optional and value is None:
        return None
    value = _scalar(value)
    integer = isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))
    if integer and low <= value <= high:
        return int(value)
    shown = _shown(value)
    if isinstance(value, (float, np.floating)):             # a number of the wrong kind: its type too
        shown += f" ({type(value).__name__})"
    raise ValueError(f"{name} must be {'None or ' if optional else ''}an integer in [{low}, {high}], got {shown}")


def _scalar(value):
    """A 0-d NumPy array's value (``float()`` took them before the checks), anything else as it is."""
    return value.item() if isinstance(value, np.ndarray) and value.ndim == 0 else value


def _as_float(value) -> float:
    """``float(value)``, or an infinity of its sign for an integer beyond float64 (10**400)."""
    try:
        return float(value)
    except OverflowError:
        return math.inf if value > 0 else -math.inf


def _shown(value) -> str:
    """A value as the messages show it: a number by %g where that is the number itself, else by every
    digit it takes (1.0000001 is not its bound 1), an integer by %g where that is the integer itself, else
    whole up to 100 bits and rounded beyond (10**400 - 1 is 1e+400), anything
    else by its repr and type (clsky.errors.short's rule, written here: the tracer imports nothing from
    clsky)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        return f"{value!r:.40} ({type(value).__name__})"
    if isinstance(value, (int, np.integer)):
        value = int(value)
        if abs(value) < 10**7:
            return str(value)
        try:
            text = f"{float(value):g}"
        except OverflowError:
            text = None
        if text is not None and int(float(text)) == value:
            return text
        if abs(value).bit_length() <= 100:          # whole where %g would round it (2**64 is not 1e+19)
            return str(value)
        if abs(value).bit_length() > 14000:         # beyond str()'s 4300 digits: from its logarithm
            exponent = math.floor(math.log10(abs(value)))
            mantissa = f"{10 ** (math.log10(abs(value)) - exponent):.5g}"
            return f"{'-' if value < 0 else ''}{mantissa}e+{exponent}"
        mantissa, exponent = format(decimal.Decimal(value), ".5e").split("e")
        return f"{mantissa.rstrip('0').rstrip('.')}e{exponent}"
    text = f"{float(value):g}"
    return text if not math.isfinite(value) or float(text) == float(value) else repr(float(value))


def _checked_observer(atmosphere, altitude, cos_view, cos_sun, azimuth):
    """(altitude, V, Sun) after checking the geometry: the altitude in [0, Ha] m, the cosines in [-1, 1],
    the azimuth a finite number [rad]. A NaN cosine or azimuth gave NaN radiance (a NaN view cosine a
    silent 0), a view cosine of 5 was taken as 1."""
    top = float(atmosphere.top_radius) - float(atmosphere.planet_radius)
    altitude = _check_real("altitude", altitude, 0.0, top, unit=" m")
    cos_view = _check_real("cos_view", cos_view, -1.0, 1.0)
    cos_sun = _check_real("cos_sun", cos_sun, -1.0, 1.0)
    azimuth = _check_real("azimuth", azimuth, unit=" (radians)")
    return (altitude,) + _observer_frame(cos_view, cos_sun, azimuth)


def _observer_frame(cos_view, cos_sun, azimuth):
    """V and Sun in the canonical frame (zenith +z, V in the x-z plane)."""
    cv = float(np.clip(cos_view, -1.0, 1.0))
    cs = float(np.clip(cos_sun, -1.0, 1.0))
    sv = math.sqrt(max(0.0, 1.0 - cv * cv))
    ss = math.sqrt(max(0.0, 1.0 - cs * cs))
    view = np.array([sv, 0.0, cv])
    sun = np.array([ss * math.cos(azimuth), ss * math.sin(azimuth), cs])
    return view, sun


def simulate(atmosphere, altitude, cos_view, cos_sun, azimuth=0.0, *, photons=200_000, seed=0,
             max_orders=None, single_only=False, chunk=1 << 16):
    """Monte Carlo sky radiance with diagnostics (see the module docstring for the estimator).

    Parameters
    ----------
    atmosphere : AtmosphereParameters
        Planet, air and phase functions (lengths [m], coefficients [1/m]).
    altitude : float
        Observer altitude [m], 0 <= altitude <= Ha.
    cos_view : float
        Cosine of the view zenith angle (dot(V, zenith)).
    cos_sun : float
        Cosine of the sun zenith angle (dot(Sun, zenith)).
    azimuth : float, optional
        Angle [rad] between the horizontal projections of V and Sun (0: sun on the view side).
    photons : int, optional
        Paths per channel (the three channels are independent simulations).
    seed : int, optional
        Seed of :func:`numpy.random.default_rng`.
    max_orders : int or None, optional
        Count only scattering orders <= max_orders (None: DEFAULT_MAX_ORDERS, a cap whose truncation
        is reported).
    single_only : bool, optional
        Same as max_orders=1 (with max_orders None or 1).
    chunk : int, optional
        Points per block of the sun-transmittance quadrature (memory bound).

    Returns
    -------
    MonteCarloResult

    Raises
    ------
    ValueError
        Naming an argument outside its range: the altitude in [0, Ha] m, the cosines in [-1, 1], a finite
        azimuth, integer photons in [2, :data:`MAX_PHOTONS`], max_orders in [1, :data:`MAX_ORDERS_LIMIT`] or
        None, seed in [0, :data:`MAX_SEED`] or None, chunk >= 1 (0-d arrays of them too), single_only a
        bool, and True only with max_orders None or 1.
    """
    rp = float(atmosphere.planet_radius)
    ra = float(atmosphere.top_radius)
    altitude, view, sun = _checked_observer(atmosphere, altitude, cos_view, cos_sun, azimuth)
    # integers as integers: 2.7 photons ran as 2, max_orders=True as 1
    max_orders = _check_integer("max_orders", max_orders, 1, MAX_ORDERS_LIMIT, optional=True)
    if not isinstance(single_only, (bool, np.bool_)):      # 'no' ran single scattering
        raise ValueError(f"single_only must be True or False, got {_shown(single_only)}")
    if single_only and max_orders not in (None, 1):        # max_orders=5 became 1 without a word
        raise ValueError(f"single_only=True counts order 1 alone: max_orders must be None or 1 with it, got "
                         f"{max_orders}")
    if single_only:
        max_orders = 1
    if max_orders is None:
        max_orders = DEFAULT_MAX_ORDERS
    photons = _check_integer("photons", photons, 2, MAX_PHOTONS)
    seed = _check_integer("seed", seed, 0, MAX_SEED, optional=True)
    chunk = _check_integer("chunk", chunk, 1, 2**31 - 1)

    rng = np.random.default_rng(seed)
    beta_r = np.asarray(atmosphere.rayleigh_scattering, dtype=np.float64)
    beta_ms = _mie_scattering(atmosphere)          # per channel
    beta_me = _mie_extinction(atmosphere)
    h_r = float(atmosphere.rayleigh_scale_height)
    h_m = float(atmosphere.mie_scale_height)
    g = float(atmosphere.mie_g)
    beta_o, ozone_peak, ozone_half_width = _ozone(atmosphere)
    has_ozone = bool(np.any(beta_o > 0.0))
    albedo = float(getattr(atmosphere, "ground_albedo", 0.0))
    rayleigh_kind = atmosphere.rayleigh_phase
    mean_r = phase_mean(rayleigh_kind)
    mean_m = phase_mean("cornette_shanks", g)

    n_total = 3 * photons
    # Per-path state (compacted as paths die); `ids` maps to the photon's accumulator slot.
    ids = np.arange(n_total)
    channel = ids // photons
    pos = np.tile(np.array([0.0, 0.0, rp + altitude]), (n_total, 1))
    dirn = np.tile(view, (n_total, 1))
    weight = np.ones(n_total)
    order = np.zeros(n_total, dtype=np.int64)
    majorant = beta_r + beta_me + beta_o  # per channel: each species' largest extinction (rho, tent <= 1)

    contrib = np.zeros(n_total)
    orders = np.zeros((max_orders, 3))
    trunc_paths = np.zeros(3, dtype=np.int64)
    trunc_weight = np.zeros(3)
    real_count = 0
    null_count = 0

    while ids.size:
        r = np.linalg.norm(pos, axis=1)
        mu = np.einsum("ij,ij->i", pos, dirn) / r
        t_top = ray_sphere_exit(r, mu, ra)
        t_ground = ray_sphere_entry(np.maximum(r, rp), mu, rp)
        t_bound = np.minimum(t_top, t_ground)
        with np.errstate(divide="ignore"):      # a zero majorant (vacuum) never collides: t = inf
            t = -np.log1p(-rng.random(ids.size)) / majorant[channel]
        inside = t < t_bound
        reflected = ~inside & (t_ground <= t_top) if albedo > 0.0 else np.zeros(ids.size, dtype=bool)
        if np.any(reflected):
            # Ground events: NEE with the Lambertian BRDF, then a cosine-weighted bounce (module docstring).
            sel = np.flatnonzero(reflected)
            order[sel] += 1
            hit = pos[sel] + t_ground[sel, None] * dirn[sel]
            normal = hit / np.linalg.norm(hit, axis=1)[:, None]
            pos[sel] = rp * normal
            mus = normal @ sun
            t_sun = _sun_transmittance(np.full(sel.size, rp), mus, channel[sel], rp, ra, beta_r, beta_me,
                                       (h_r, h_m), beta_o if has_ozone else None, ozone_peak, ozone_half_width,
                                       chunk)
            value = weight[sel] * albedo / math.pi * np.maximum(mus, 0.0) * t_sun
            contrib[ids[sel]] += value
            np.add.at(orders, (order[sel] - 1, channel[sel]), value)
            go_on = order[sel] < max_orders
            cont = sel[go_on]
            weight[cont] *= albedo
            dirn[cont] = _scatter_directions(normal[go_on], np.sqrt(rng.random(cont.size)), rng)
            stop = sel[~go_on]
            np.add.at(trunc_paths, channel[stop], 1)
            np.add.at(trunc_weight, channel[stop], weight[stop] * albedo)
            inside[cont] = True
            t[cont] = 0.0                 # the bounced path starts its next flight from the ground
        # Leaving through the top or hitting a black ground (or the order cap) ends the path.
        ids, channel, pos, dirn, weight, order, t, reflected = (
            a[inside] for a in (ids, channel, pos, dirn, weight, order, t, reflected))
        if not ids.size:
            break
        pos = pos + t[:, None] * dirn
        h = np.linalg.norm(pos, axis=1) - rp
        rho_r = np.exp(-h / h_r)
        rho_m = np.exp(-h / h_m)
        mu_r = beta_r[channel] * rho_r
        mu_ms = beta_ms[channel] * rho_m
        mu_t = mu_r + beta_me[channel] * rho_m
        if has_ozone:   # absorption only: in mu_t, not in the scattering coefficients
            mu_t = mu_t + beta_o[channel] * _tent(h, ozone_peak, ozone_half_width)
        # a path bounced off the ground this round has no collision yet: it flies on in the next one
        real = (rng.random(ids.size) * majorant[channel] < mu_t) & ~reflected
        null_count += int(ids.size - np.count_nonzero(real) - np.count_nonzero(reflected))
        if not np.any(real):
            continue
        sel = np.flatnonzero(real)
        real_count += sel.size
        order[sel] += 1
        # Next-event estimation toward the sun.
        p = pos[sel]
        rs = np.linalg.norm(p, axis=1)
        mus = (p @ sun) / rs
        cos_theta = dirn[sel] @ sun  # angle between the light's travel before (-Sun) and after (-d)
        t_sun = _sun_transmittance(rs, mus, channel[sel], rp, ra, beta_r, beta_me, (h_r, h_m),
                                   beta_o if has_ozone else None, ozone_peak, ozone_half_width, chunk)
        phase = (mu_r[sel] * rayleigh_phase(cos_theta, rayleigh_kind)
                 + mu_ms[sel] * cornette_shanks_phase(cos_theta, g))
        value = weight[sel] * phase / (mu_t[sel] * _FOUR_PI) * t_sun
        contrib[ids[sel]] += value
        np.add.at(orders, (order[sel] - 1, channel[sel]), value)

        # Continue the path: species, direction and weight; stop at the order cap.
        go_on = order[sel] < max_orders
        cont = sel[go_on]
        if cont.size:
            mu_sc = mu_r[cont] + mu_ms[cont]
            is_rayleigh = rng.random(cont.size) * mu_sc < mu_r[cont]
            cos_new = np.empty(cont.size)
            n_r = int(np.count_nonzero(is_rayleigh))
            cos_new[is_rayleigh] = sample_rayleigh_cosine(rng.random(n_r), rayleigh_kind)
            cos_new[~is_rayleigh] = sample_cornette_shanks_cosine(rng, cont.size - n_r, g)
            weight[cont] *= mu_sc / mu_t[cont] * np.where(is_rayleigh, mean_r, mean_m)
            dirn[cont] = _scatter_directions(dirn[cont], cos_new, rng)
        stop = sel[~go_on]
        if stop.size:
            keep = np.ones(ids.size, dtype=bool)
            keep[stop] = False
            # Paths cut by the order cap, with the weight they would carry into the next order.
            np.add.at(trunc_paths, channel[stop], 1)
            np.add.at(trunc_weight, channel[stop], weight[stop] * (mu_r[stop] + mu_ms[stop]) / mu_t[stop])
            ids, channel, pos, dirn, weight, order = (
                a[keep] for a in (ids, channel, pos, dirn, weight, order))

    per_channel = contrib.reshape(3, photons)
    radiance = per_channel.mean(axis=1)
    standard_error = per_channel.std(axis=1, ddof=1) / math.sqrt(photons)
    return MonteCarloResult(radiance=radiance, standard_error=standard_error, orders=orders / photons,
                            max_orders=max_orders, truncated_paths=trunc_paths,
                            truncated_weight=trunc_weight / photons, photons=photons,
                            real_collisions=real_count, null_collisions=null_count,
                            contributing_paths=np.count_nonzero(per_channel > 0.0, axis=1))


def sky_radiance(atmosphere, altitude, cos_view, cos_sun, azimuth=0.0, *, photons=200_000, seed=0,
                 max_orders=None, single_only=False):
    """Returns (radiance, standard_error), each an array of 3 (r, g, b), per unit solar irradiance.

    Observer at altitude [m] (0 <= altitude <= Ha), view zenith cosine cos_view, sun zenith cosine cos_sun,
    azimuth [rad] between the horizontal projections of view and sun (0: same vertical plane, sun on the
    view side). max_orders: count only scattering orders <= max_orders; single_only = max_orders 1.

    Parameters
    ----------
    atmosphere : AtmosphereParameters
        Planet, air and phase functions.
    altitude : float
        Observer altitude [m].
    cos_view, cos_sun : float
        Cosines of the view and sun zenith angles.
    azimuth : float, optional
        Sun-view azimuth [rad].
    photons : int, optional
        Paths per channel.
    seed : int, optional
        Random seed (results are reproducible for a given seed).
    max_orders : int or None, optional
        Highest scattering order counted (None: all, up to the cap DEFAULT_MAX_ORDERS).
    single_only : bool, optional
        Single scattering only.

    Returns
    -------
    radiance : numpy.ndarray
        Shape (3,), radiance per unit solar irradiance [1/sr]: compare with
        ``table radiance / atmosphere.incident_light``.
    standard_error : numpy.ndarray
        Shape (3,), its Monte Carlo standard error [1/sr].
    """
    result = simulate(atmosphere, altitude, cos_view, cos_sun, azimuth, photons=photons, seed=seed,
                      max_orders=max_orders, single_only=single_only)
    return result.radiance, result.standard_error


def absolute_sky_radiance(atmosphere, altitude, cos_view, cos_sun, azimuth=0.0, **options):
    """:func:`sky_radiance` times ``atmosphere.incident_light`` (the table's units).

    Parameters
    ----------
    atmosphere, altitude, cos_view, cos_sun, azimuth
        As for :func:`sky_radiance`.
    **options
        Keyword options of :func:`sky_radiance` (photons, seed, max_orders, single_only).

    Returns
    -------
    radiance, standard_error : numpy.ndarray
        Shape (3,) each: I_I * estimate and I_I * standard error.
    """
    radiance, error = sky_radiance(atmosphere, altitude, cos_view, cos_sun, azimuth, **options)
    light = np.asarray(atmosphere.incident_light, dtype=np.float64)
    return radiance * light, error * light


# Deterministic single scattering -------------------------------------------------------------------

def _sun_blocked(points, sun, rp, ra):
    """True where the planet blocks the sun ray from ``points`` (n, 3) [m] (same test as the tracer's NEE)."""
    radii = np.linalg.norm(points, axis=1)
    _, blocked = optical_depth_to_top(radii, (points @ sun) / radii, rp, ra, (1.0, 1.0), nodes=2)
    return blocked


def single_scattering(atmosphere, altitude, cos_view, cos_sun, azimuth=0.0, *, step=100.0, nodes=8):
    """Single-scattering radiance per unit solar irradiance [1/sr] by deterministic quadrature.

    L1 = Integral_0^L sum_s beta_s rho_s(x) F_s(dot(Sun, V)) / (4 pi) T(x0, x) T_sun(x) ds along the
    view ray (x0 the observer, L its distance to the top), with the tracer's phase functions and
    transmittances (:func:`transmittance_to_top`; T(x0, x) = T_top(x0) / T_top(x)): the quantity the
    tracer estimates with ``max_orders=1``, without its noise. Gauss-Legendre with ``nodes`` nodes on
    panels of ``step`` metres along the ray; T_sun jumps to 0 where the planet shadows the ray, and
    the jump is located by bisection (to 1e-6 m) and made a panel edge, so every panel's integrand is
    smooth.

    Parameters
    ----------
    atmosphere : AtmosphereParameters
    altitude : float
        Observer altitude [m].
    cos_view, cos_sun : float
        Cosines of the view and sun zenith angles.
    azimuth : float, optional
        Sun-view azimuth [rad].
    step : float, optional
        Panel length [m] (100 m: 12 panels per Mie scale height of 1.2 km).
    nodes : int, optional
        Gauss-Legendre nodes per panel.

    Returns
    -------
    numpy.ndarray
        Shape (3,) [1/sr].

    Raises
    ------
    ValueError
        If the view ray hits the ground (the ground's reflection is not integrated here), or naming an
        argument outside its range (as :func:`simulate`; step in (0, Ha] m, nodes in [1, 1000]).
    """
    rp = float(atmosphere.planet_radius)
    ra = float(atmosphere.top_radius)
    altitude, view, sun = _checked_observer(atmosphere, altitude, cos_view, cos_sun, azimuth)
    step = _check_real("step", step, 0.0, ra - rp, low_open=True, unit=" m")
    nodes = _check_integer("nodes", nodes, 1, 1000)
    r0 = rp + altitude
    if np.isfinite(ray_sphere_entry(np.array([r0]), np.array([view[2]]), rp)[0]):
        horizon = 0.0 - math.sqrt(max(0.0, 1.0 - (rp / r0) ** 2))     # the horizon's cos_view here ('0', not '-0')
        raise ValueError(f"cos_view must be above the horizon's {horizon:.6g} at altitude {_shown(altitude)} m "
                         f"(single_scattering integrates rays that reach the top, not the ground's reflection), "
                         f"got {_shown(float(view[2]))}")
    length = float(ray_sphere_exit(np.array([r0]), np.array([view[2]]), ra)[0])
    origin = np.array([0.0, 0.0, r0])
    edges = np.linspace(0.0, length, max(2, int(math.ceil(length / float(step))) + 1))
    blocked = _sun_blocked(origin + edges[:, None] * view, sun, rp, ra)
    jumps = []
    for i in np.flatnonzero(blocked[1:] != blocked[:-1]):
        lo, hi = edges[i], edges[i + 1]
        while hi - lo > 1e-6:
            mid = 0.5 * (lo + hi)
            if _sun_blocked((origin + mid * view)[None, :], sun, rp, ra)[0] == blocked[i]:
                lo = mid
            else:
                hi = mid
        jumps.append(0.5 * (lo + hi))
    edges = np.unique(np.concatenate([edges, jumps]))
    x, w = np.polynomial.legendre.leggauss(int(nodes))
    half = 0.5 * np.diff(edges)
    s = (0.5 * (edges[1:] + edges[:-1]))[:, None] + half[:, None] * x
    weights = (half[:, None] * w).ravel()
    points = origin + s.ravel()[:, None] * view
    radii = np.linalg.norm(points, axis=1)
    h = radii - rp
    t_sun = transmittance_to_top(atmosphere, radii, (points @ sun) / radii)
    t_view = (transmittance_to_top(atmosphere, np.array([r0]), np.array([view[2]]))
              / transmittance_to_top(atmosphere, radii, (points @ view) / radii))
    c = float(view @ sun)
    beta_r = np.asarray(atmosphere.rayleigh_scattering, dtype=np.float64)
    scatter = (np.exp(-h / float(atmosphere.rayleigh_scale_height))[:, None] * beta_r
               * rayleigh_phase(c, atmosphere.rayleigh_phase)
               + np.exp(-h / float(atmosphere.mie_scale_height))[:, None] * _mie_scattering(atmosphere)
               * cornette_shanks_phase(c, float(atmosphere.mie_g)))
    return (weights[:, None] * scatter * t_view * t_sun).sum(axis=0) / _FOUR_PI
