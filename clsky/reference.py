"""NumPy twins of the OpenCL kernels: the same equations, vectorised, in float64.

Each public function here computes what one kernel entry point computes, with the same quadrature
nodes and the same cancellation-free formulas (``kernels/geometry.cl``), so that kernel and twin agree
to rounding (about 1e-12 relative in float64). They are library code: ``backend="numpy"`` paths use
them, and the tests compare every kernel with its twin.

Shapes: a ray or segment is described by broadcastable arrays; quadrature nodes go on a new last
axis. Large tables are computed in chunks of cells (whole-array operations inside each chunk) so
that memory stays bounded.
"""

from __future__ import annotations

import math

import numpy as np

from .atmosphere import AtmosphereParameters
from .mapping import grid_coordinates
from .settings import TableSettings

__all__ = [
    "horizon_cos", "distance_to_top", "distance_to_ground", "altitude_along",
    "quadrature_nodes", "column_density", "optical_depth", "transmittance",
    "transmittance_table", "column_density_from_table", "single_scattering",
]

_TINY = np.finfo(np.float64).tiny
#: Upper bound on the elements of one chunk's largest temporary (cells x view nodes x sun nodes).
CHUNK_ELEMENTS = 2**22


# Geometry (kernels/geometry.cl) -------------------------------------------------------------------

def horizon_cos(r, planet_radius):
    """Cosine of the horizon's zenith angle seen from radius r [m]: -sqrt((r - Rp)(r + Rp)) / r."""
    return -np.sqrt(np.maximum((r - planet_radius) * (r + planet_radius), 0.0)) / r


def distance_to_top(r, mu, top_radius):
    """Length [m] from radius r <= Ra along direction cosine mu to the sphere Ra."""
    inside = np.maximum((top_radius - r) * (top_radius + r), 0.0)
    root = np.sqrt(inside + r * mu * r * mu)
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):   # in the discarded branch
        return np.where(mu > 0.0, inside / np.maximum(r * mu + root, _TINY), root - r * mu)


def distance_to_ground(r, mu, planet_radius):
    """Length [m] from radius r along mu (below the horizon) to the sphere Rp."""
    above = np.maximum((r - planet_radius) * (r + planet_radius), 0.0)
    root = np.sqrt(np.maximum(r * mu * r * mu - above, 0.0))
    with np.errstate(over="ignore"):   # only where mu is above the horizon, which callers discard
        return above / np.maximum(root - r * mu, _TINY)


def altitude_along(h0, r0, mu, s, planet_radius):
    """Altitude [m] at distance s [m] along mu from altitude h0 (radius r0), never negative."""
    excess = np.maximum(h0 * (2.0 * planet_radius + h0) + s * (2.0 * r0 * mu + s), 0.0)
    return excess / (np.sqrt(planet_radius * planet_radius + excess) + planet_radius)


# Quadrature ---------------------------------------------------------------------------------------

def quadrature_nodes(steps, sampling="uniform", power=2):
    """Trapezoid nodes in [0, 1]: j / n, or (j / n)^power for Keller & Bohn sampling."""
    x = np.arange(steps + 1) / steps
    return x**power if sampling == "keller_bohn" else x


def _trapezoid(values, half_steps):
    """Sum over the last axis of (f_{j-1} + f_j) * half_step_j."""
    return np.sum((values[..., :-1] + values[..., 1:]) * half_steps, axis=-1)


def column_density(atmosphere: AtmosphereParameters, altitude, cos_zenith, length, steps=30,
                   sampling="uniform"):
    """Column densities (C_R, C_M) [m] of segments by the trapezoidal rule (``kernels/column.cl``).

    Parameters
    ----------
    altitude, cos_zenith, length : array_like
        Start altitude [m], direction cosine and length [m] of each segment (broadcast together).
    steps : int
        Trapezoid steps (nodes t_j = d f(j / steps), f(x) = x or x^2 for ``keller_bohn``).

    Returns
    -------
    (C_R, C_M) : two arrays of the broadcast shape [m]
    """
    rp = atmosphere.planet_radius
    h0, mu, d = (np.asarray(a, dtype=np.float64)[..., None] for a in (altitude, cos_zenith, length))
    nodes = quadrature_nodes(steps, sampling, power=2)
    h = altitude_along(h0, rp + h0, mu, d * nodes, rp)
    half_steps = 0.5 * d * np.diff(nodes)
    return (_trapezoid(np.exp(-h / atmosphere.rayleigh_scale_height), half_steps),
            _trapezoid(np.exp(-h / atmosphere.mie_scale_height), half_steps))


def _optical_depth_of(atmosphere, column_r, column_m):
    """tau per wavelength (last axis: r, g, b) of column densities."""
    beta = np.asarray(atmosphere.rayleigh_scattering)
    return beta * column_r[..., None] + atmosphere.mie_extinction * column_m[..., None]


def optical_depth(atmosphere: AtmosphereParameters, altitude, cos_zenith, length, steps=30,
                  sampling="uniform"):
    """Optical depth per wavelength of segments; twin of ``TransmittanceEngine.optical_depth``.

    Returns an array of the broadcast shape + (3,): tau for r, g, b.
    """
    return _optical_depth_of(atmosphere, *column_density(atmosphere, altitude, cos_zenith, length,
                                                         steps, sampling))


def transmittance(atmosphere, altitude, cos_zenith, length, steps=30, sampling="uniform"):
    """exp(-optical_depth) per wavelength."""
    return np.exp(-optical_depth(atmosphere, altitude, cos_zenith, length, steps, sampling))


# 2D column-density table (kernels/transmittance_table.cl) -----------------------------------------

def transmittance_table_nodes(atmosphere, size):
    """Altitude [m] and zenith cosine of every node of the 2D table, each of shape (TH, TW)."""
    tw, th = size
    u = np.arange(tw) / (tw - 1)
    v = (np.arange(th) / (th - 1))[:, None]
    h = np.broadcast_to(u * u * atmosphere.atmosphere_height, (th, tw))
    mu_h = horizon_cos(atmosphere.planet_radius + h, atmosphere.planet_radius)
    return h, mu_h + (1.0 - mu_h) * (v * v)


def transmittance_table(atmosphere: AtmosphereParameters, size=(64, 256), steps=30, sampling="uniform"):
    """Column densities (C_R, C_M) [m] from each node to the top; shape (TH, TW, 2).

    Twin of ``TransmittanceEngine.column_density_table``.
    """
    h, mu = transmittance_table_nodes(atmosphere, size)
    length = distance_to_top(atmosphere.planet_radius + h, mu, atmosphere.top_radius)
    return np.stack(column_density(atmosphere, h, mu, length, steps, sampling), axis=-1)


def column_density_from_table(atmosphere, table, altitude, cos_zenith):
    """Bilinear lookup of (C_R, C_M) in a table from :func:`transmittance_table`."""
    th, tw, _ = table.shape
    h = np.asarray(altitude, dtype=np.float64)
    mu_h = horizon_cos(atmosphere.planet_radius + h, atmosphere.planet_radius)
    fx = np.sqrt(np.clip(h / atmosphere.atmosphere_height, 0.0, 1.0)) * (tw - 1)
    fy = np.sqrt(np.clip((cos_zenith - mu_h) / (1.0 - mu_h), 0.0, 1.0)) * (th - 1)
    x0 = np.minimum(fx.astype(np.int64), tw - 2)
    y0 = np.minimum(fy.astype(np.int64), th - 2)
    ax = (fx - x0)[..., None]
    ay = (fy - y0)[..., None]
    return tuple(np.moveaxis(
        ((1.0 - ax) * table[y0, x0] + ax * table[y0, x0 + 1]) * (1.0 - ay)
        + ((1.0 - ax) * table[y0 + 1, x0] + ax * table[y0 + 1, x0 + 1]) * ay, -1, 0))


# Single scattering (kernels/single.cl) -----------------------------------------------------------

def _trapezoid_along_view(values, half_steps):
    """Trapezoid over axis 1 (the view nodes) of values (n, nodes, 3) with half_steps (n, nodes - 1, 1)."""
    return np.sum((values[:, :-1] + values[:, 1:]) * half_steps, axis=1)


def _single_scattering_cells(atmosphere, settings, h0, mu_v, mu_s, sun_table):
    """Ibar^(1) of the cells given by 1D arrays (h0, mu_v, mu_s); returns (n, 6)."""
    rp, ra = atmosphere.planet_radius, atmosphere.top_radius
    h0, mu_v, mu_s = (a[:, None] for a in (h0, mu_v, mu_s))
    r0 = rp + h0
    nu = mu_v * mu_s + np.sqrt(np.maximum(1.0 - mu_v * mu_v, 0.0) * np.maximum(1.0 - mu_s * mu_s, 0.0))
    hits_ground = mu_v < horizon_cos(r0, rp)
    length = np.where(hits_ground, distance_to_ground(r0, mu_v, rp), distance_to_top(r0, mu_v, ra))

    nodes = quadrature_nodes(settings.view_steps, settings.sampling, power=3)
    s = length * nodes                                          # (n, N_VIEW + 1)
    h = altitude_along(h0, r0, mu_v, s, rp)
    h[:, -1] = np.where(hits_ground[:, 0], 0.0, h[:, -1])     # last node of a ground hit: on the ground
    r = rp + h
    mu_sun_here = (r0 * mu_s + s * nu) / r
    lit = mu_sun_here >= horizon_cos(r, rp)
    density_r = np.exp(-h / atmosphere.rayleigh_scale_height)
    density_m = np.exp(-h / atmosphere.mie_scale_height)

    half_steps = 0.5 * length * np.diff(nodes)                  # (n, N_VIEW)
    cumulative = np.zeros_like(h)
    view_r = cumulative.copy()
    view_m = cumulative.copy()
    np.cumsum((density_r[:, :-1] + density_r[:, 1:]) * half_steps, axis=1, out=view_r[:, 1:])
    np.cumsum((density_m[:, :-1] + density_m[:, 1:]) * half_steps, axis=1, out=view_m[:, 1:])

    if sun_table is None:
        sun_length = np.where(lit, distance_to_top(r, mu_sun_here, ra), 0.0)
        sun_r, sun_m = column_density(atmosphere, h, mu_sun_here, sun_length, settings.sun_steps,
                                      settings.sampling)
    else:
        sun_r, sun_m = column_density_from_table(atmosphere, sun_table, h, mu_sun_here)

    transmittance = np.exp(-_optical_depth_of(atmosphere, view_r + sun_r, view_m + sun_m))
    transmittance *= lit[..., None]                             # (n, N_VIEW + 1, 3)
    half_steps = half_steps[..., None]
    sum_r = _trapezoid_along_view(density_r[..., None] * transmittance, half_steps)
    sum_m = _trapezoid_along_view(density_m[..., None] * transmittance, half_steps)
    beta = np.asarray(atmosphere.rayleigh_scattering)
    return np.concatenate([beta * (1.0 / (4.0 * math.pi)) * sum_r,
                           (atmosphere.mie_scattering / (4.0 * math.pi)) * sum_m], axis=1)


def single_scattering(atmosphere: AtmosphereParameters, settings: TableSettings = TableSettings()):
    """The single-scattering table; twin of ``SingleScatteringEngine.compute``.

    Returns
    -------
    numpy.ndarray, shape (D, H, W, 6)
        Ibar^(1) [1/sr]: Rayleigh r, g, b, Mie r, g, b, per cell (see ``kernels/single.cl``).
    """
    width, height, depth = settings.size
    altitudes, cos_view, cos_sun = grid_coordinates(settings.size, atmosphere.atmosphere_height,
                                                    settings.mapping)
    sun_table = None
    if settings.sun_transmittance == "table":
        sun_table = transmittance_table(atmosphere, settings.transmittance_size, settings.sun_steps,
                                        settings.sampling)
    cells = width * height * depth
    index = np.arange(cells)
    x, y, z = index % width, (index // width) % height, index // (width * height)
    per_cell = (settings.view_steps + 1) * (settings.sun_steps + 1)
    chunk = max(1, CHUNK_ELEMENTS // per_cell)
    out = np.empty((cells, 6))
    for start in range(0, cells, chunk):
        part = slice(start, start + chunk)
        out[part] = _single_scattering_cells(atmosphere, settings, altitudes[x[part]], cos_view[y[part]],
                                             cos_sun[z[part]], sun_table)
    return out.reshape(depth, height, width, 6)


# Table lookup (kernels/lookup.cl) ----------------------------------------------------------------

def enter_atmosphere(atmosphere, altitude, cos_view, cos_sun, cos_scatter):
    """Moves observers above the atmosphere to where their view ray enters it.

    Returns (altitude, cos_view, cos_sun, inside) with ``inside`` False where the ray misses the
    atmosphere.
    """
    ra = atmosphere.top_radius
    r = atmosphere.planet_radius + altitude
    above = r > ra
    outside = (r - ra) * (r + ra)
    discriminant = r * cos_view * r * cos_view - outside
    inside = ~above | ((cos_view < 0.0) & (discriminant >= 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        d = outside / (np.sqrt(np.maximum(discriminant, 0.0)) - r * cos_view)
    return (np.where(above, atmosphere.atmosphere_height, altitude),
            np.where(above, np.clip((r * cos_view + d) / ra, -1.0, 1.0), cos_view),
            np.where(above, np.clip((r * cos_sun + d * cos_scatter) / ra, -1.0, 1.0), cos_sun),
            inside)


def lookup(atmosphere: AtmosphereParameters, data, altitude, cos_view, cos_sun, cos_scatter,
           mapping="nonlinear"):
    """Radiance from a table; twin of ``TableLookupEngine.radiance`` (same parameters and result)."""
    from .mapping import altitude_to_u, cos_to_v
    from .phase import mie_phase, rayleigh_phase

    depth, height, width, channels = data.shape
    altitude, cos_view, cos_sun, cos_scatter = np.broadcast_arrays(
        *(np.asarray(a, dtype=np.float64) for a in (altitude, cos_view, cos_sun, cos_scatter)))
    nu = np.clip(cos_scatter, -1.0, 1.0)
    h, mu_v, mu_s, inside = enter_atmosphere(atmosphere, altitude, cos_view, cos_sun, nu)
    position = []
    for coordinate, n in ((altitude_to_u(h, atmosphere.atmosphere_height, mapping), width),
                          (cos_to_v(mu_v, mapping), height), (cos_to_v(mu_s, mapping), depth)):
        f = coordinate * (n - 1)
        lower = np.clip(f.astype(np.int64), 0, n - 2)
        position.append((lower, f - lower))
    (x0, ax), (y0, ay), (z0, az) = position
    ibar = np.zeros(h.shape + (channels,))
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                weight = (ax if dx else 1 - ax) * (ay if dy else 1 - ay) * (az if dz else 1 - az)
                ibar += weight[..., None] * data[z0 + dz, y0 + dy, x0 + dx]
    ibar *= inside[..., None]
    mie = ibar[..., 3:6] if channels == 6 else ibar[..., 3:4]
    return np.asarray(atmosphere.incident_light) * (rayleigh_phase(atmosphere, nu)[..., None] * ibar[..., 0:3]
                                                    + mie_phase(atmosphere, nu)[..., None] * mie)
