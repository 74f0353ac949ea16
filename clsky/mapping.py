"""Texture mappings of the 3D scattering table (NumPy), mirroring ``kernels/mapping.cl``.

Non-linear (Atmosphere Plus, default): u = sqrt(h / Ha), v = (1 + sign(c) |c|^(1/3)) / 2;
inverses h = u^2 Ha, c = (2v - 1)^3. Linear (Elek 2009): u = h / Ha, v = (c + 1) / 2.
The same formula maps the view-zenith cosine (v) and the sun-zenith cosine (w).

The sun axis may cover a sub-range of sun cosines only (``TableSettings.sun_cos_range``, chosen by
:mod:`clsky.planner` for a scene): its D nodes are then spread evenly in w between the range's ends,
and a sun cosine outside it reads the nearest end. The altitude and view axes always cover their whole
range: the gather integrates over every view direction, and view rays cross every altitude.

The 4D table (``parameterization='4d'``, clsky/table4d.py) keeps the altitude and sun axes above and
adds its own view mapping, split at the horizon, and an azimuth axis (functions ``*4d*`` below; OpenCL
twin kernels/mapping4d.cl).
"""

from __future__ import annotations

import math

import numpy as np

from .errors import check_choice
from .settings import MAPPINGS

__all__ = ["altitude_to_u", "u_to_altitude", "cos_to_v", "v_to_cos", "grid_coordinates", "FULL_SUN_RANGE",
           "sun_w_range", "cos_to_sun_t", "view4d_to_y", "y_to_view4d", "azimuth4d_nodes", "azimuth4d_to_a",
           "cos_azimuth", "scatter_cos", "grid4d_coordinates", "HORIZON_MARGIN",
           "HORIZON_MARGIN_FLOAT32"]

_TINY = np.finfo(np.float64).tiny

#: The sun-cosine range of a table whose sun axis is whole.
FULL_SUN_RANGE = (-1.0, 1.0)


def altitude_to_u(altitude, atmosphere_height, mapping="nonlinear"):
    """Texture coordinate u in [0, 1] of altitude [m] (clamped to [0, Ha])."""
    x = np.clip(np.asarray(altitude, dtype=np.float64) / atmosphere_height, 0.0, 1.0)
    return np.sqrt(x) if check_choice("mapping", mapping, MAPPINGS) == "nonlinear" else x


def u_to_altitude(u, atmosphere_height, mapping="nonlinear"):
    """Altitude [m] of texture coordinate u in [0, 1]."""
    u = np.asarray(u, dtype=np.float64)
    return (u * u if check_choice("mapping", mapping, MAPPINGS) == "nonlinear" else u) * atmosphere_height


def cos_to_v(cosine, mapping="nonlinear"):
    """Texture coordinate v (or w) in [0, 1] of a zenith cosine (clamped to [-1, 1])."""
    c = np.clip(np.asarray(cosine, dtype=np.float64), -1.0, 1.0)
    return 0.5 * (1.0 + (np.cbrt(c) if check_choice("mapping", mapping, MAPPINGS) == "nonlinear" else c))


def v_to_cos(v, mapping="nonlinear"):
    """Zenith cosine of texture coordinate v (or w) in [0, 1]."""
    t = 2.0 * np.asarray(v, dtype=np.float64) - 1.0
    return t * t * t if check_choice("mapping", mapping, MAPPINGS) == "nonlinear" else t


def sun_w_range(mapping="nonlinear", sun_cos_range=FULL_SUN_RANGE):
    """(w_low, w_high): the texture coordinates the sun axis spans; (0, 1) for the whole axis.

    This pair is the ``sun_range`` argument of the kernels (mapping.cl).
    """
    low, high = cos_to_v(np.asarray(sun_cos_range, dtype=np.float64), mapping)
    return float(low), float(high)


def cos_to_sun_t(cosine, mapping="nonlinear", sun_cos_range=FULL_SUN_RANGE):
    """Position in [0, 1] along the sun axis of a sun cosine (clamped to the axis' range); times
    (D - 1) it is the node coordinate. Twin of MAPPING_SUN_T."""
    low, high = sun_w_range(mapping, sun_cos_range)
    return np.clip((cos_to_v(cosine, mapping) - low) / (high - low), 0.0, 1.0)


def grid_coordinates(size, atmosphere_height, mapping="nonlinear", sun_cos_range=FULL_SUN_RANGE):
    """Node values of the table axes.

    Returns
    -------
    altitude [m] (W,), cos view zenith (H,), cos sun zenith (D,)
        At texture coordinates x / (W - 1), y / (H - 1), and w_low + (w_high - w_low) z / (D - 1)
        (:func:`sun_w_range`).
    """
    width, height, depth = size
    low, high = sun_w_range(mapping, sun_cos_range)
    return (u_to_altitude(np.arange(width) / (width - 1), atmosphere_height, mapping),
            v_to_cos(np.arange(height) / (height - 1), mapping),
            v_to_cos(low + (high - low) * (np.arange(depth) / (depth - 1)), mapping))


# The 4D table (clsky/table4d.py; twin: kernels/mapping4d.cl) ---------------------------------------
#
# View zenith, split at the horizon (after Bruneton 2017, precomputed_atmospheric_scattering,
# atmosphere/functions.glsl: GetScatteringTextureUvwzFromRMuMuSNu; our own node-centred form). From
# radius r = Rp + h, with rho = sqrt(r^2 - Rp^2) (distance to the horizon) and K = sqrt(Ra^2 - Rp^2):
#   a ray that hits the ground (mu < mu_horizon(h)) travels d = distance_to_ground in [h, rho]:
#       x = (d - h) / (rho - h),             node coordinate fy = (H/2 - 1) x           in [0, H/2 - 1]
#   a ray that reaches space travels d = distance_to_top in [Ha - h, rho + K]:
#       x = (d - (Ha - h)) / (rho + K - (Ha - h)),  fy = H/2 + (H/2 - 1)(1 - x)       in [H/2, H - 1]
# so straight down is node 0, the horizon seen from below node H/2 - 1, from above node H/2, the zenith
# node H - 1 at every altitude; the lookup never interpolates between nodes H/2 - 1 and H/2 (no seam:
# the two sides of the horizon differ by a ground hit). Inverses: mu = -(rho^2 + d^2) / (2 r d)
# (ground), mu = (Ra^2 - r^2 - d^2) / (2 r d) (space). Nodes linear in d cluster, in mu, at the horizon.
# Azimuth: phi in [0, pi] between the horizontal projections of view and sun, nodes pi a / (A - 1),
# cos phi = (nu - mu_v mu_s) / sqrt((1 - mu_v^2)(1 - mu_s^2)) (0 where view or sun is vertical).

#: Margin [in mu] that keeps a 4D node on its side of the horizon whatever the rounding of
#: horizon_cos (kernels/view_ray.cl decides a ground hit by mu < horizon_cos(h)).
HORIZON_MARGIN = 1e-14
#: The same for a float32 table, whose kernels see the node cosines rounded to float32 (ulp 1.5e-8 at the
#: horizon cosine of 100 km, -0.175) and compute horizon_cos in float32: 1e-5 is several hundred ulps.
HORIZON_MARGIN_FLOAT32 = 1e-5


def _view4d_geometry(altitude, planet_radius, top_radius):
    """(r, rho, K, Ha - h) of altitudes [m] (clamped to [0, Ha])."""
    ha = top_radius - planet_radius
    h = np.clip(np.asarray(altitude, dtype=np.float64), 0.0, ha)
    rho = np.sqrt(h * (2.0 * planet_radius + h))
    return planet_radius + h, rho, math.sqrt(ha * (2.0 * planet_radius + ha)), ha - h


def view4d_to_y(altitude, cos_view, height, planet_radius, top_radius):
    """Node coordinate fy in [0, H - 1] of view cosines at altitudes [m] (module comment above);
    twin of ``view4d_coordinate`` (mapping4d.cl)."""
    from .reference import distance_to_ground, distance_to_top, horizon_cos

    h = np.clip(np.asarray(altitude, dtype=np.float64), 0.0, top_radius - planet_radius)
    mu = np.clip(np.asarray(cos_view, dtype=np.float64), -1.0, 1.0)
    _, rho, k, to_top = _view4d_geometry(h, planet_radius, top_radius)
    half = height // 2
    ground = mu < horizon_cos(h, planet_radius)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_ground = (distance_to_ground(h, mu, planet_radius) - h) / np.maximum(rho - h, _TINY)
        x_sky = (distance_to_top(h, mu, planet_radius, top_radius) - to_top) / np.maximum(rho + k - to_top, _TINY)
    x_ground, x_sky = np.clip(x_ground, 0.0, 1.0), np.clip(x_sky, 0.0, 1.0)
    return np.where(ground, (half - 1) * x_ground, half + (half - 1) * (1.0 - x_sky))


def y_to_view4d(altitude, y, height, planet_radius, top_radius, margin=HORIZON_MARGIN):
    """View cosines of node coordinates y in [0, H - 1] at altitudes [m], each on its side of the
    horizon by ``margin`` (:data:`HORIZON_MARGIN`; inverse of :func:`view4d_to_y`)."""
    from .reference import horizon_cos

    h = np.clip(np.asarray(altitude, dtype=np.float64), 0.0, top_radius - planet_radius)
    y = np.asarray(y, dtype=np.float64)
    r, rho, k, to_top = _view4d_geometry(h, planet_radius, top_radius)
    half = height // 2
    horizon = horizon_cos(h, planet_radius)
    ground = y < half
    x_ground = np.clip(y / (half - 1), 0.0, 1.0)
    x_sky = np.clip(1.0 - (y - half) / (half - 1), 0.0, 1.0)
    d_ground = h + x_ground * (rho - h)
    d_sky = to_top + x_sky * (rho + k - to_top)
    with np.errstate(divide="ignore", invalid="ignore"):
        mu_ground = np.where(d_ground > 0.0, -(rho * rho + d_ground * d_ground) / (2.0 * r * d_ground), -1.0)
        mu_sky = np.where(d_sky > 0.0, (to_top * (top_radius + r) - d_sky * d_sky) / (2.0 * r * d_sky), 1.0)
    mu_ground = np.minimum(np.clip(mu_ground, -1.0, 1.0), horizon - margin)
    mu_sky = np.maximum(np.clip(mu_sky, -1.0, 1.0), horizon + margin)
    return np.where(ground, np.maximum(mu_ground, -1.0), np.minimum(mu_sky, 1.0))


def azimuth4d_nodes(size):
    """The A azimuths [rad] pi a / (A - 1), a = 0..A - 1, of the 4D table."""
    return np.arange(size) * (math.pi / (size - 1))


def cos_azimuth(cos_view, cos_sun, cos_scatter):
    """cos phi = (nu - mu_v mu_s) / sqrt((1 - mu_v^2)(1 - mu_s^2)) in [-1, 1]; 1 where the view or the
    sun is vertical (the azimuth is then arbitrary)."""
    mu_v, mu_s, nu = (np.asarray(a, dtype=np.float64) for a in (cos_view, cos_sun, cos_scatter))
    denominator = np.sqrt(np.maximum(1.0 - mu_v * mu_v, 0.0) * np.maximum(1.0 - mu_s * mu_s, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        value = np.where(denominator > _TINY, (nu - mu_v * mu_s) / denominator, 1.0)
    return np.clip(value, -1.0, 1.0)


def azimuth4d_to_a(cos_view, cos_sun, cos_scatter, size):
    """Node coordinate fa in [0, A - 1] of the azimuth of (mu_v, mu_s, nu); twin of ``azimuth4d_coordinate``."""
    return np.arccos(cos_azimuth(cos_view, cos_sun, cos_scatter)) * ((size - 1) / math.pi)


def scatter_cos(cos_view, cos_sun, azimuth):
    """nu = mu_v mu_s + sqrt(1 - mu_v^2) sqrt(1 - mu_s^2) cos(phi) of a view at azimuth phi [rad] from the sun."""
    mu_v, mu_s = np.asarray(cos_view, dtype=np.float64), np.asarray(cos_sun, dtype=np.float64)
    return np.clip(mu_v * mu_s + np.sqrt(np.maximum(1.0 - mu_v * mu_v, 0.0) * np.maximum(1.0 - mu_s * mu_s, 0.0))
                   * np.cos(azimuth), -1.0, 1.0)


def grid4d_coordinates(settings, planet_radius, top_radius):
    """Node values of the 4D table of ``settings`` (size (W, H, D), mapping, sun_cos_range, azimuth_size).

    Returns
    -------
    altitude [m] (W,), cos view zenith (W, H) (the view nodes depend on the altitude; the horizon nodes
    :data:`HORIZON_MARGIN` off it, :data:`HORIZON_MARGIN_FLOAT32` for a float32 table), cos sun zenith
    (D,), azimuth [rad] (A,)
    """
    width, height, _ = settings.size
    altitudes, _, cos_sun = grid_coordinates(settings.size, top_radius - planet_radius, settings.mapping,
                                             settings.sun_cos_range)
    margin = HORIZON_MARGIN if settings.dtype == "float64" else HORIZON_MARGIN_FLOAT32
    cos_view = y_to_view4d(altitudes[:, None], np.arange(height)[None, :], height, planet_radius, top_radius, margin)
    return altitudes, cos_view, cos_sun, azimuth4d_nodes(settings.azimuth_size)
