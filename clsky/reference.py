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
from .ozone import tent
from .mapping import FULL_SUN_RANGE, grid_coordinates
from .settings import TableSettings, computed_sun_nodes

__all__ = [
    "horizon_cos", "distance_to_top", "distance_to_ground", "altitude_along",
    "quadrature_nodes", "view_nodes", "densities", "column_density", "optical_depth", "transmittance",
    "transmittance_table", "column_density_from_table", "single_scattering", "enter_atmosphere",
    "lookup", "gather", "trilinear", "scatter", "render_table", "render_raymarch", "render_skyview",
    "interpolate4d", "lookup4d", "table4d_cells", "render_table4d",
]

_TINY = np.finfo(np.float64).tiny
#: A node's sun cosine this close below its horizon's is lit: ties of exact arithmetic, where the sun ray
#: grazes the ground, decided by the limit of the rays just above, not by rounding noise (kernels/view_ray.cl,
#: SHADOW_TIE, 8 float64 ulps of 1 in either precision).
SHADOW_TIE = 8.0 * np.finfo(np.float64).eps
#: Upper bound on the elements of one chunk's largest temporary (cells x view nodes x sun nodes).
CHUNK_ELEMENTS = 2**22


# Geometry (kernels/geometry.cl) -------------------------------------------------------------------

def horizon_cos(h, planet_radius):
    """Cosine of the horizon's zenith angle seen from altitude h [m]: -sqrt(h (2 Rp + h)) / (Rp + h)."""
    return -np.sqrt(np.maximum(h * (2.0 * planet_radius + h), 0.0)) / (planet_radius + h)


def distance_to_top(h, mu, planet_radius, top_radius):
    """Length [m] from altitude h <= Ha along direction cosine mu to the sphere Ra."""
    r = planet_radius + h
    inside = np.maximum(((top_radius - planet_radius) - h) * (top_radius + r), 0.0)
    root = np.sqrt(inside + r * mu * r * mu)
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):   # in the discarded branch
        return np.where(mu > 0.0, inside / np.maximum(r * mu + root, _TINY), root - r * mu)


def distance_to_ground(h, mu, planet_radius):
    """Length [m] from altitude h along mu (below the horizon) to the sphere Rp."""
    r = planet_radius + h
    above = np.maximum(h * (2.0 * planet_radius + h), 0.0)
    root = np.sqrt(np.maximum(r * mu * r * mu - above, 0.0))
    with np.errstate(over="ignore"):   # only where mu is above the horizon, which callers discard
        return above / np.maximum(root - r * mu, _TINY)


def altitude_along(h0, r0, mu, s, planet_radius):
    """Altitude [m] at distance s [m] along mu from altitude h0 (radius r0), never negative."""
    excess = np.maximum(h0 * (2.0 * planet_radius + h0) + s * (2.0 * r0 * mu + s), 0.0)
    return excess / (np.sqrt(planet_radius * planet_radius + excess) + planet_radius)


# Quadrature ---------------------------------------------------------------------------------------

def quadrature_nodes(steps, sampling="uniform", power=2):
    """Trapezoid nodes in [0, 1]: j / n, or (j / n)^power for Keller & Bohn sampling (and for the
    sun rays of ``ground_end``, which keep Keller & Bohn's)."""
    x = np.arange(steps + 1) / steps
    return x**power if sampling in ("keller_bohn", "ground_end") else x


def view_nodes(steps, sampling, hits_ground):
    """Nodes f(i / N) in [0, 1] along view rays (``view_node_at`` of ``kernels/view_ray.cl``).

    uniform: x; keller_bohn: x^3, clustered at the observer; ground_end: x^3, except 1 - (1 - x)^3,
    clustered at the ground, on rays that hit it (``hits_ground``, shape (cells, 1)). Shape (N + 1,),
    or (cells, N + 1) for ground_end.
    """
    keller_bohn = quadrature_nodes(steps, sampling, power=3)
    if sampling != "ground_end":
        return keller_bohn
    y = 1.0 - np.arange(steps + 1) / steps
    return np.where(hits_ground, 1.0 - y * y * y, keller_bohn)     # keller_bohn's bits elsewhere


def _trapezoid(values, half_steps):
    """Sum over the last axis of (f_{j-1} + f_j) * half_step_j."""
    return np.sum((values[..., :-1] + values[..., 1:]) * half_steps, axis=-1)


def densities(atmosphere: AtmosphereParameters, h):
    """The species' densities at altitudes h [m] (``densities_at`` of ``kernels/column.cl``): a tuple
    (rho_R, rho_M), plus the ozone tent f_O (:func:`clsky.ozone.tent_profile`) with ozone."""
    species = (np.exp(-h / atmosphere.rayleigh_scale_height), np.exp(-h / atmosphere.mie_scale_height))
    if atmosphere.has_ozone:
        species += (tent(h, atmosphere.ozone_peak_altitude, atmosphere.ozone_half_width),)
    return species


def column_density(atmosphere: AtmosphereParameters, altitude, cos_zenith, length, steps=30,
                   sampling="uniform"):
    """Column densities (C_R, C_M[, C_O]) [m] of segments by the trapezoidal rule (``kernels/column.cl``).

    Parameters
    ----------
    altitude, cos_zenith, length : array_like
        Start altitude [m], direction cosine and length [m] of each segment (broadcast together).
    steps : int
        Trapezoid steps (nodes t_j = d f(j / steps), f(x) = x or x^2 for ``keller_bohn``).

    Returns
    -------
    (C_R, C_M) or, with ozone, (C_R, C_M, C_O) : arrays of the broadcast shape [m]
        C_O is the column of the ozone tent f_O (1 at its peak): the ozone column is n_max C_O.

    Raises
    ------
    ValueError
        As the kernels' entry point (:class:`clsky.transmittance.TransmittanceEngine`) checks them: the
        segments (:func:`clsky.transmittance.check_segments`: a negative length gave a transmittance of 3.5,
        a NaN altitude NaN), ``steps`` in [1, 1e6] (0 gave T = 1; the kernels take at most 4096, the twin
        serves as a finer reference too) and ``sampling`` (an unknown one was taken as uniform).
    """
    from .errors import check_choice, check_integer
    from .settings import SAMPLINGS
    from .transmittance import check_segments

    altitude, cos_zenith, length = check_segments(atmosphere, altitude, cos_zenith, length)
    steps = check_integer("steps", steps, 1, 1_000_000)
    sampling = check_choice("sampling", sampling, SAMPLINGS)
    return _column_density(atmosphere, altitude, cos_zenith, length, steps, sampling)


def _column_density(atmosphere, altitude, cos_zenith, length, steps, sampling):
    """:func:`column_density` of checked segments (the twins' own sun rays and table nodes)."""
    rp = atmosphere.planet_radius
    h0, mu, d = (np.asarray(a, dtype=np.float64)[..., None] for a in (altitude, cos_zenith, length))
    nodes = quadrature_nodes(steps, sampling, power=2)
    h = altitude_along(h0, rp + h0, mu, d * nodes, rp)
    half_steps = 0.5 * d * np.diff(nodes)
    return tuple(_trapezoid(density, half_steps) for density in densities(atmosphere, h))


def _optical_depth_of(atmosphere, column_r, column_m, column_o=None):
    """tau per wavelength (last axis: r, g, b) of column densities (``optical_depth_of`` of
    ``kernels/column.cl``): beta_R C_R + beta_M^e C_M (both per channel), plus sigma_O3 n_max C_O with ozone."""
    beta = np.asarray(atmosphere.rayleigh_scattering)
    tau = beta * column_r[..., None] + atmosphere.mie_extinction_channels * column_m[..., None]
    if atmosphere.has_ozone:
        tau = tau + atmosphere.ozone_extinction * column_o[..., None]
    return tau


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
    mu_h = horizon_cos(h, atmosphere.planet_radius)
    return h, mu_h + (1.0 - mu_h) * (v * v)


def transmittance_table(atmosphere: AtmosphereParameters, size=(64, 256), steps=30, sampling="uniform"):
    """Column densities (C_R, C_M[, C_O]) [m] from each node to the top; shape (TH, TW, 2), or
    (TH, TW, 3) with ozone.

    Twin of ``TransmittanceEngine.column_density_table``.
    """
    h, mu = transmittance_table_nodes(atmosphere, size)
    length = distance_to_top(h, mu, atmosphere.planet_radius, atmosphere.top_radius)
    return np.stack(_column_density(atmosphere, h, mu, length, steps, sampling), axis=-1)


def column_density_from_table(atmosphere, table, altitude, cos_zenith):
    """Bilinear lookup of (C_R, C_M[, C_O]) in a table from :func:`transmittance_table`."""
    th, tw, _ = table.shape
    h = np.asarray(altitude, dtype=np.float64)
    mu_h = horizon_cos(h, atmosphere.planet_radius)
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


class _ViewRays:
    """Nodes along view rays (h0, mu_v, mu_s, nu), as in view_ray.cl (nu defaults to the table's
    canonical cos(phi - delta)).

    Arrays have shape (cells, N_VIEW + 1): the nodes' placement in [0, 1] (:func:`view_nodes`: (N_VIEW + 1,)
    unless it differs between rays), distance s, altitude h, radius r, the sun and view cosines
    at each node, densities, the column densities from the observer, and the trapezoid half steps
    (cells, N_VIEW). ``density`` and ``view`` are tuples over the species (R, M, and O with ozone;
    :func:`densities`); ``density_r``, ``density_m`` name the scatterers'.
    """

    def __init__(self, atmosphere, settings, h0, mu_v, mu_s, nu=None):
        rp, ra = atmosphere.planet_radius, atmosphere.top_radius
        h0, mu_v, mu_s = (np.asarray(a, dtype=np.float64)[:, None] for a in (h0, mu_v, mu_s))
        r0 = rp + h0
        if nu is None:   # the canonical frame of the 3D table: cos(phi - delta)
            nu = mu_v * mu_s + np.sqrt(np.maximum(1.0 - mu_v * mu_v, 0.0) * np.maximum(1.0 - mu_s * mu_s, 0.0))
        else:
            nu = np.asarray(nu, dtype=np.float64)[:, None]
        hits_ground = mu_v < horizon_cos(h0, rp)
        self.hits_ground = hits_ground[:, 0]
        length = np.where(hits_ground, distance_to_ground(h0, mu_v, rp), distance_to_top(h0, mu_v, rp, ra))
        nodes = view_nodes(settings.view_steps, settings.sampling, hits_ground)
        self.nodes = nodes
        self.s = length * nodes
        self.h = altitude_along(h0, r0, mu_v, self.s, rp)
        self.h[:, -1] = np.where(hits_ground[:, 0], 0.0, self.h[:, -1])   # a ground hit ends on the ground
        self.r = rp + self.h
        self.mu_sun = (r0 * mu_s + self.s * nu) / self.r                   # dot(P, Sun) / |P|
        self.mu_view = (r0 * mu_v + self.s) / self.r                       # dot(P, V) / |P|
        self.density = densities(atmosphere, self.h)
        self.density_r, self.density_m = self.density[:2]
        self.half_steps = 0.5 * length * np.diff(nodes, axis=-1)
        self.view = tuple(np.zeros_like(self.h) for _ in self.density)
        for density, view in zip(self.density, self.view):
            np.cumsum((density[:, :-1] + density[:, 1:]) * self.half_steps, axis=1, out=view[:, 1:])

    def integrate(self, atmosphere, transmittance, weight_r, weight_m):
        """beta_s / (4 pi) * trapezoid of rho_s * transmittance * weight_s: (cells, 6).

        transmittance: (cells, nodes, 3); weight_r, weight_m: broadcastable to it.
        """
        half_steps = self.half_steps[..., None]
        sum_r = _trapezoid_along_view(self.density_r[..., None] * transmittance * weight_r, half_steps)
        sum_m = _trapezoid_along_view(self.density_m[..., None] * transmittance * weight_m, half_steps)
        beta = np.asarray(atmosphere.rayleigh_scattering)
        return np.concatenate([beta * (1.0 / (4.0 * math.pi)) * sum_r,
                               (atmosphere.mie_scattering_channels / (4.0 * math.pi)) * sum_m], axis=1)


def _sun_columns(atmosphere, settings, h, mu_sun, sun_table):
    """Column densities toward the sun from altitudes h along sun cosines mu_sun (``sun_column`` of
    ``kernels/view_ray.cl``): from ``sun_table`` or re-marched; returns (columns, lit). A sun cosine within
    :data:`SHADOW_TIE` of the horizon's is lit (``sun_lit``)."""
    lit = mu_sun >= horizon_cos(h, atmosphere.planet_radius) - SHADOW_TIE
    if sun_table is None:
        sun_length = np.where(lit, distance_to_top(h, mu_sun, atmosphere.planet_radius, atmosphere.top_radius), 0.0)
        return _column_density(atmosphere, h, mu_sun, sun_length, settings.sun_steps, settings.sampling), lit
    return column_density_from_table(atmosphere, sun_table, h, mu_sun), lit


def _single_scattering_cells(atmosphere, settings, h0, mu_v, mu_s, sun_table, nu=None):
    """Ibar^(1) along the rays given by 1D arrays (h0, mu_v, mu_s[, nu]); returns (n, 6)."""
    rays = _ViewRays(atmosphere, settings, h0, mu_v, mu_s, nu)
    sun, lit = _sun_columns(atmosphere, settings, rays.h, rays.mu_sun, sun_table)
    transmittance = np.exp(-_optical_depth_of(atmosphere, *(v + s for v, s in zip(rays.view, sun))))
    transmittance *= lit[..., None]                             # (n, N_VIEW + 1, 3)
    return rays.integrate(atmosphere, transmittance, 1.0, 1.0)


def _cells_in_chunks(settings, per_cell, function, channels=6):
    """Evaluate function(x, y, z) -> (n, channels) over every cell, in chunks; returns (D, H, W, channels)."""
    width, height, depth = settings.size
    cells = width * height * depth
    index = np.arange(cells)
    x, y, z = index % width, (index // width) % height, index // (width * height)
    chunk = max(1, CHUNK_ELEMENTS // per_cell)
    out = np.empty((cells, channels))
    for start in range(0, cells, chunk):
        part = slice(start, start + chunk)
        out[part] = function(x[part], y[part], z[part])
    return out.reshape(depth, height, width, channels)


def single_scattering(atmosphere: AtmosphereParameters, settings: TableSettings = TableSettings()):
    """The single-scattering table; twin of ``SingleScatteringEngine.compute``.

    Returns
    -------
    numpy.ndarray, shape (D, H, W, 6)
        Ibar^(1) [1/sr]: Rayleigh r, g, b, Mie r, g, b, per cell (see ``kernels/single.cl``).
    """
    altitudes, cos_view, cos_sun = grid_coordinates(settings.size, atmosphere.atmosphere_height,
                                                    settings.mapping, settings.sun_cos_range)
    sun_table = None
    if settings.sun_transmittance == "table":
        sun_table = transmittance_table(atmosphere, settings.transmittance_size, settings.sun_steps,
                                        settings.sampling)
    return _cells_in_chunks(settings, (settings.view_steps + 1) * (settings.sun_steps + 1),
                            lambda x, y, z: _single_scattering_cells(atmosphere, settings, altitudes[x],
                                                                     cos_view[y], cos_sun[z], sun_table))


# Table lookup (kernels/lookup.cl) ----------------------------------------------------------------

def enter_atmosphere(atmosphere, altitude, cos_view, cos_sun, cos_scatter):
    """Moves observers above the atmosphere to where their view ray enters it.

    Returns (altitude, cos_view, cos_sun, inside) with ``inside`` False where the ray misses the
    atmosphere; a ray that misses keeps its cosines (finite values the caller zeroes). As
    kernels/geometry.cl, "above" is decided from the altitude: ``r > ra`` missed an altitude an ulp
    above the top, where Rp + h rounds to Ra.
    """
    ra = atmosphere.top_radius
    r = atmosphere.planet_radius + altitude
    above = altitude > atmosphere.atmosphere_height
    outside = np.maximum((r - ra) * (r + ra), 0.0)
    discriminant = r * cos_view * r * cos_view - outside
    inside = ~above | ((cos_view < 0.0) & (discriminant >= 0.0))
    entered = above & inside         # there the denominator is >= -r cos_view > 0: d is finite
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):   # the rays that miss
        d = outside / (np.sqrt(np.maximum(discriminant, 0.0)) - r * cos_view)
        entry_view = np.clip((r * cos_view + d) / ra, -1.0, 1.0)
        entry_sun = np.clip((r * cos_sun + d * cos_scatter) / ra, -1.0, 1.0)
    return (np.where(above, atmosphere.atmosphere_height, altitude), np.where(entered, entry_view, cos_view),
            np.where(entered, entry_sun, cos_sun), inside)


def lookup(atmosphere: AtmosphereParameters, data, altitude, cos_view, cos_sun, cos_scatter,
           mapping="nonlinear", sun_cos_range=FULL_SUN_RANGE, *, table_checked=False):
    """Radiance from a table; twin of ``TableLookupEngine.radiance`` (same parameters, checks and result)."""
    from .lookup import check_lookup
    from .mapping import altitude_to_u, cos_to_sun_t, cos_to_v
    from .phase import mie_phase, rayleigh_phase

    data, queries, sun_cos_range = check_lookup(data, (altitude, cos_view, cos_sun, cos_scatter), sun_cos_range,
                                                table_checked=table_checked)
    depth, height, width, channels = data.shape
    altitude, cos_view, cos_sun, cos_scatter = (np.asarray(a, dtype=np.float64) for a in queries)
    nu = np.clip(cos_scatter, -1.0, 1.0)
    h, mu_v, mu_s, inside = enter_atmosphere(atmosphere, altitude, cos_view, cos_sun, nu)
    position = []
    for coordinate, n in ((altitude_to_u(h, atmosphere.atmosphere_height, mapping), width),
                          (cos_to_v(mu_v, mapping), height),
                          (cos_to_sun_t(mu_s, mapping, sun_cos_range), depth)):
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
    factored = channels - 3 if channels in (7, 9) else channels
    mie = ibar[..., 3:6] if factored == 6 else ibar[..., 3:4]
    multiple = ibar[..., factored:factored + 3] if factored < channels else 0.0
    return np.asarray(atmosphere.incident_light) * (rayleigh_phase(atmosphere, nu)[..., None] * ibar[..., 0:3]
                                                    + mie_phase(atmosphere, nu)[..., None] * mie + multiple)


# 4D table lookup (kernels/lookup4d.cl) -------------------------------------------------------------

def _node4d(f, n):
    """Lower node and weight along an axis of n nodes (``node4d``; one node: 0 and 0)."""
    if n < 2:
        return np.zeros(np.shape(f), dtype=np.int64), np.zeros(np.shape(f))
    lower = np.clip(np.asarray(f).astype(np.int64), 0, n - 2)
    return lower, f - lower


def interpolate4d(data, fx, fy, fz, fa):
    """Quadrilinear interpolation of data (A, D, H, W, C) at node coordinates (..., C), the view axis'
    lower node kept on the query's side of the horizon (``interpolate4d`` of lookup4d.cl)."""
    azimuths, depth, height, width, channels = data.shape
    half = height // 2
    (x0, ax), (z0, az), (a0, aa) = _node4d(fx, width), _node4d(fz, depth), _node4d(fa, azimuths)
    fy = np.asarray(fy, dtype=np.float64)
    lower = fy.astype(np.int64)
    y0 = np.where(fy < half, np.clip(lower, 0, half - 2), np.clip(lower, half, height - 2))
    ay = fy - y0
    ibar = np.zeros(np.shape(fy) + (channels,))
    for da in range(1 + (azimuths > 1)):
        for dz in range(1 + (depth > 1)):
            for dy in (0, 1):
                for dx in range(1 + (width > 1)):
                    weight = ((aa if da else 1 - aa) * (az if dz else 1 - az) * (ay if dy else 1 - ay)
                              * (ax if dx else 1 - ax))
                    ibar += weight[..., None] * data[a0 + da, z0 + dz, y0 + dy, x0 + dx]
    return ibar


def _radiance_of_channels(atmosphere, ibar, nu):
    """I_I (F_R Ibar_R + F_M Ibar_M [+ Lbar]) of 6 or 9 per-wavelength channels (``radiance_of_channels``)."""
    from .phase import mie_phase, rayleigh_phase

    multiple = ibar[..., 6:9] if ibar.shape[-1] == 9 else 0.0
    return np.asarray(atmosphere.incident_light) * (rayleigh_phase(atmosphere, nu)[..., None] * ibar[..., 0:3]
                                                    + mie_phase(atmosphere, nu)[..., None] * ibar[..., 3:6] + multiple)


def _coordinates4d(atmosphere, shape, h, mu_v, mu_s, nu, mapping, sun_cos_range):
    from .mapping import altitude_to_u, azimuth4d_to_a, cos_to_sun_t, view4d_to_y

    azimuths, depth, height, width = shape
    fx = altitude_to_u(h, atmosphere.atmosphere_height, mapping) * (width - 1) if width > 1 else np.zeros(np.shape(h))
    fz = cos_to_sun_t(mu_s, mapping, sun_cos_range) * (depth - 1) if depth > 1 else np.zeros(np.shape(h))
    return (fx, view4d_to_y(h, mu_v, height, atmosphere.planet_radius, atmosphere.top_radius), fz,
            azimuth4d_to_a(mu_v, mu_s, nu, azimuths))


def lookup4d(atmosphere: AtmosphereParameters, data, altitude, cos_view, cos_sun, cos_scatter,
             mapping="nonlinear", sun_cos_range=FULL_SUN_RANGE, *, table_checked=False):
    """Radiance (..., 3) from a 4D table (A, D, H, W, C); twin of ``TableLookup4DEngine.radiance`` (same checks)."""
    from .lookup import check_lookup
    from .lookup4d import check_table4d_data

    data, queries, sun_cos_range = check_lookup(data, (altitude, cos_view, cos_sun, cos_scatter), sun_cos_range,
                                                check_table4d_data, table_checked)
    altitude, cos_view, cos_sun, cos_scatter = (np.asarray(a, dtype=np.float64) for a in queries)
    nu = np.clip(cos_scatter, -1.0, 1.0)
    with np.errstate(invalid="ignore"):      # rays that miss the atmosphere from above: discarded
        h, mu_v, mu_s, inside = enter_atmosphere(atmosphere, altitude, cos_view, cos_sun, nu)
    h, mu_v, mu_s = np.where(inside, h, 0.0), np.where(inside, mu_v, 1.0), np.where(inside, mu_s, 1.0)
    ibar = interpolate4d(data, *_coordinates4d(atmosphere, data.shape[:4], h, mu_v, mu_s, nu, mapping, sun_cos_range))
    return _radiance_of_channels(atmosphere, np.where(inside[..., None], ibar, 0.0), nu)


def table4d_cells(atmosphere: AtmosphereParameters, settings: TableSettings, gathered, h0, mu_v, mu_s, nu,
                  ground_irradiance=None):
    """The 4D table's channels (n, 9) (or (n, 6) without ``gathered``) along the rays (h0, mu_v, mu_s, nu);
    twin of the ``table4d_cells`` kernel: Ibar_R, Ibar_M of single scattering (no phase; the
    quadrature of ``settings``) and the higher orders sum_s beta_s / (4 pi) Integral rho_s T G_s ds
    of the gathered cosine series (M + 1, D, H, W, 6) on the 3D grid of ``settings`` (clsky/azimuth.py),
    plus, with a reflecting ground, what the ray sees of it (``ground_irradiance`` (D, 3) E_sky)."""
    from .azimuth import gathered_along

    sun_table = None
    if settings.sun_transmittance == "table":
        sun_table = transmittance_table(atmosphere, settings.transmittance_size, settings.sun_steps,
                                        settings.sampling)
    single = _single_scattering_cells(atmosphere, settings, h0, mu_v, mu_s, sun_table, nu)
    if gathered is None:
        return single
    gathered = np.asarray(gathered)
    more = gathered_along(atmosphere, settings, gathered if gathered.ndim == 5 else gathered[None], settings,
                          h0, mu_v, mu_s, nu)
    multiple = more[:, :3] + more[:, 3:]
    if atmosphere.has_ground:
        multiple = multiple + _ground_reflection(atmosphere, settings, settings, ground_irradiance, sun_table, h0, mu_v,
                                                 mu_s, nu)
    return np.concatenate([single, multiple], axis=1)


# Multiple scattering (kernels/multiple.cl) ---------------------------------------------------------

def gather(matrices, table_in):
    """Gbar[z, i, x, c] = sum_j M[c // 3][(z,) i, j] Ibar[z, j, x, c]; twin of ``MultipleScatteringEngine.gather``.

    matrices: (2, H, H) or (2, D, H, H), the Rayleigh and Mie operators; table_in: (D, H, W, 6).
    """
    depth, height, width, _ = table_in.shape
    out = np.empty_like(table_in)
    for species, channels in enumerate((slice(0, 3), slice(3, 6))):
        columns = table_in[..., channels].reshape(depth, height, width * 3)
        out[..., channels] = np.matmul(matrices[species], columns).reshape(depth, height, width, 3)
    return out


def trilinear(table, fx, fy, fz):
    """Trilinear interpolation of table (D, H, W, C) at node coordinates (fx, fy, fz): (..., C)."""
    depth, height, width, _ = table.shape
    x0 = np.clip(fx.astype(np.int64), 0, width - 2)
    y0 = np.clip(fy.astype(np.int64), 0, height - 2)
    z0 = np.clip(fz.astype(np.int64), 0, depth - 2)
    ax, ay, az = (fx - x0)[..., None], (fy - y0)[..., None], (fz - z0)[..., None]
    value = 0.0
    for dx, wx in ((0, 1.0 - ax), (1, ax)):
        for dy, wy in ((0, 1.0 - ay), (1, ay)):
            for dz, wz in ((0, 1.0 - az), (1, az)):
                value = value + wx * wy * wz * table[z0 + dz, y0 + dy, x0 + dx]
    return value


def source_at_stride(source, nodes, stride):
    """A gathered source ``source`` (cells, N_VIEW + 1, channels) at a ray's nodes as the kernels' integrals
    take it with ``TableSettings.source_stride`` (``integrate_gathered`` of ``kernels/view_ray.cl``): itself
    for 1; for 2, at each odd node i < N_VIEW linear in distance between its neighbours,
    (1 - w_i) G_(i-1) + w_i G_(i+1), w_i = (x_i - x_(i-1)) / (x_(i+1) - x_(i-1)) of the nodes' placement
    ``nodes`` (:attr:`_ViewRays.nodes`)."""
    if stride == 1:
        return source
    odd = np.arange(1, source.shape[1] - 1, 2)
    nodes = np.asarray(nodes, dtype=np.float64)
    w = ((nodes[..., odd] - nodes[..., odd - 1]) / (nodes[..., odd + 1] - nodes[..., odd - 1]))[..., None]
    source = source.copy()
    source[:, odd] = (1.0 - w) * source[:, odd - 1] + w * source[:, odd + 1]
    return source


def _gathered_along(atmosphere, ray_settings, gathered, grid_settings, h0, mu_v, mu_s, nu=None):
    """beta_s / (4 pi) Integral rho_s T(P, Pa) Gbar_s(P) ds along rays (n, 6); Gbar on grid_settings' grid,
    taken at the nodes as ``ray_settings.source_stride`` says (:func:`source_at_stride`)."""
    from .mapping import altitude_to_u, cos_to_sun_t, cos_to_v

    width, height, depth = grid_settings.size
    rays = _ViewRays(atmosphere, ray_settings, h0, mu_v, mu_s, nu)
    g = trilinear(gathered,
                  altitude_to_u(rays.h, atmosphere.atmosphere_height, grid_settings.mapping) * (width - 1),
                  cos_to_v(rays.mu_view, grid_settings.mapping) * (height - 1),
                  cos_to_sun_t(rays.mu_sun, grid_settings.mapping, grid_settings.sun_cos_range) * (depth - 1))
    g = source_at_stride(g, rays.nodes, ray_settings.source_stride)
    transmittance = np.exp(-_optical_depth_of(atmosphere, *rays.view))
    return rays.integrate(atmosphere, transmittance, g[..., 0:3], g[..., 3:6])


def _ground_seen(atmosphere, rays):
    """What rays see of the ground (``ground_view`` of ``kernels/view_ray.cl``): T(Pa, Pb) (n, 3), 0
    where a ray does not end on the ground, and the sun cosine at the last node (n,)."""
    transmittance = np.exp(-_optical_depth_of(atmosphere, *(view[:, -1] for view in rays.view)))
    return transmittance * rays.hits_ground[:, None], np.clip(rays.mu_sun[:, -1], -1.0, 1.0)


def fill_between_sun_nodes(table, stride=1):
    """``table`` (..., D, H, W, C) with each sun node that a scatter of sun stride 2 left between two computed
    ones (z odd, z < D - 1) set, per channel, to the geometric mean of nodes z - 1 and z + 1, their mean where
    either is not positive; in place, and returned (stride 1: unchanged). Twin of kernels/multiple.cl's
    fill_between_suns (``TableSettings.orders_sun_stride``): the orders' radiance falls off about exponentially
    along the sun axis into the night, where the geometric mean, linear in the logarithm, is the closer guess
    (docs/speed-log.md)."""
    if len(computed_sun_nodes(table.shape[-4], stride)) == table.shape[-4]:
        return table
    depth = table.shape[-4]
    below, above = table[..., 0:depth - 2:2, :, :, :], table[..., 2:depth:2, :, :, :]
    with np.errstate(invalid="ignore"):
        geometric = np.sqrt(below) * np.sqrt(above)
    table[..., 1:depth - 1:2, :, :, :] = np.where((below > 0.0) & (above > 0.0), geometric, 0.5 * (below + above))
    return table


def scatter(atmosphere: AtmosphereParameters, settings: TableSettings, gathered, combine_species=False,
            ground_radiance=None, sun_stride=1):
    """Next order from a gathered table; twin of ``MultipleScatteringEngine.scatter``.

    Ibar_s^(k)(lambda) = beta_s / (4 pi) Integral Gbar_s(P) rho_s(h(P)) T(P, Pa) ds, channels Rayleigh
    r, g, b and Mie r, g, b in and out; shape (D, H, W, 6). With ``combine_species`` both channel sets
    hold Rayleigh + Mie; a reflecting ground (``atmosphere.has_ground``, ``ground_radiance`` L_g (D, 3)
    per sun node, combine_species only) adds T(Pa, Pb) L_g(mu_sun(Pb)) to both along rays that end
    on the ground (:mod:`clsky.ground`). ``sun_stride`` 2: the nodes between every other one and the last
    filled by :func:`fill_between_sun_nodes` (computed here, then overwritten).
    """
    from .ground import interpolate_sun_axis

    altitudes, cos_view, cos_sun = grid_coordinates(settings.size, atmosphere.atmosphere_height,
                                                    settings.mapping, settings.sun_cos_range)
    ground = atmosphere.has_ground and combine_species

    def cells(x, y, z):
        h0, mu_v, mu_s = altitudes[x], cos_view[y], cos_sun[z]
        value = _gathered_along(atmosphere, settings.scatter_settings, gathered, settings, h0, mu_v, mu_s)
        if combine_species:
            value = np.concatenate([value[:, :3] + value[:, 3:]] * 2, axis=1)
        if ground:
            rays = _ViewRays(atmosphere, settings.scatter_settings, h0, mu_v, mu_s)
            transmittance, mu_ground = _ground_seen(atmosphere, rays)
            seen = transmittance * interpolate_sun_axis(np.asarray(ground_radiance), mu_ground, settings)
            value = value + np.concatenate([seen, seen], axis=1)
        return value

    return fill_between_sun_nodes(_cells_in_chunks(settings, (settings.view_steps + 1) * 8 * 6, cells), sun_stride)


# Per-pixel rendering (kernels/render.cl) ---------------------------------------------------------

def _pixel_geometry(atmosphere, directions, sun_direction, altitude):
    """Flattened (mu_v, nu), the entered (h, mu_v, mu_s), the inside mask and the observer's mu_v."""
    directions = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    mu_v = np.clip(directions[:, 2], -1.0, 1.0)
    nu = np.clip(directions @ np.asarray(sun_direction, dtype=np.float64), -1.0, 1.0)
    h = np.full(mu_v.shape, float(altitude))
    mu_s = np.full(mu_v.shape, float(sun_direction[2]))
    h_in, mu_v_in, mu_s_in, inside = enter_atmosphere(atmosphere, h, mu_v, mu_s, nu)
    return mu_v, nu, h_in, mu_v_in, mu_s_in, inside


def _sun_disc(atmosphere, mu_v, nu, altitude, sun_radiance, cos_sun_radius):
    visible = (nu >= cos_sun_radius) & (mu_v >= horizon_cos(float(altitude), atmosphere.planet_radius))
    return visible[:, None] * np.asarray(sun_radiance, dtype=np.float64)


def _render_lookup(table_lookup, atmosphere, data, mapping, directions, sun_direction, altitude, sun_radiance,
                   cos_sun_radius, sun_cos_range):
    """``table_lookup`` (:func:`lookup` or :func:`lookup4d`) radiance per direction plus the sun disc; (..., 3)."""
    shape = np.shape(directions)[:-1]
    mu_v, nu, h, mu_v_in, mu_s_in, inside = _pixel_geometry(atmosphere, directions, sun_direction, altitude)
    sky = table_lookup(atmosphere, data, h, mu_v_in, mu_s_in, nu, mapping, sun_cos_range) * inside[:, None]
    return (sky + _sun_disc(atmosphere, mu_v, nu, altitude, sun_radiance, cos_sun_radius)).reshape(shape + (3,))


def render_table(atmosphere, data, mapping, directions, sun_direction, altitude, sun_radiance, cos_sun_radius,
                 sun_cos_range=FULL_SUN_RANGE):
    """Twin of ``SkyRenderer.render_table``: lookup radiance per direction plus the sun disc; (..., 3)."""
    return _render_lookup(lookup, atmosphere, data, mapping, directions, sun_direction, altitude, sun_radiance,
                          cos_sun_radius, sun_cos_range)


def render_table4d(atmosphere, data, mapping, directions, sun_direction, altitude, sun_radiance, cos_sun_radius,
                   sun_cos_range=FULL_SUN_RANGE):
    """Twin of ``SkyRenderer.render_lut4d``: 4D lookup radiance per direction plus the sun disc; (..., 3)."""
    return _render_lookup(lookup4d, atmosphere, data, mapping, directions, sun_direction, altitude, sun_radiance,
                          cos_sun_radius, sun_cos_range)


def _ground_reflection(atmosphere, ray_settings, grid_settings, ground_irradiance, sun_table, h0, mu_v, mu_s, nu):
    """What rays (n,) see of a Lambertian ground [units of I_I] (n, 3): T(Pa, Pb) a / pi (mu_sun T_sun +
    E_sky(mu_sun)) at the ground point, 0 for rays that do not end on it (``add_ground_reflection`` of
    kernels/view_ray.cl); E_sky ``ground_irradiance`` (D, 3) on the sun axis of ``grid_settings``."""
    from .ground import interpolate_sun_axis

    rays = _ViewRays(atmosphere, ray_settings, h0, mu_v, mu_s, nu)
    transmittance, mu_ground = _ground_seen(atmosphere, rays)
    columns, lit = _sun_columns(atmosphere, ray_settings, np.zeros_like(mu_ground), mu_ground, sun_table)
    direct = (lit * np.maximum(mu_ground, 0.0))[:, None] * np.exp(-_optical_depth_of(atmosphere, *columns))
    irradiance = direct + interpolate_sun_axis(np.asarray(ground_irradiance), mu_ground, grid_settings)
    return transmittance * (atmosphere.ground_albedo / math.pi) * irradiance


def render_raymarch(atmosphere, ray_settings, directions, sun_direction, altitude, sun_radiance, cos_sun_radius,
                    gathered=None, grid_settings=None, physical=True, ground_irradiance=None):
    """Twin of ``SkyRenderer.render_raymarch``; (..., 3).

    Single scattering along each pixel's ray with the true nu (quadrature of ``ray_settings``), plus,
    with ``gathered`` (D, H, W, 6) on the grid of ``grid_settings``, the higher orders: the phase is
    inside Gbar in the physical mode, applied per species here in the atmosphere-plus mode. With a
    reflecting ground (``atmosphere.has_ground``; ``ground_irradiance`` E_sky (D, 3) on the sun axis of
    ``grid_settings``), rays that end on the ground add T(Pa, Pb) a / pi (mu_sun T_sun + E_sky(mu_sun))
    at the ground point (:mod:`clsky.ground`).
    """
    from .phase import mie_phase, rayleigh_phase

    shape = np.shape(directions)[:-1]
    mu_v, nu, h, mu_v_in, mu_s_in, inside = _pixel_geometry(atmosphere, directions, sun_direction, altitude)
    sun_table = None
    if ray_settings.sun_transmittance == "table":
        sun_table = transmittance_table(atmosphere, ray_settings.transmittance_size, ray_settings.sun_steps,
                                        ray_settings.sampling)
    f_r = rayleigh_phase(atmosphere, nu)[:, None]
    f_m = mie_phase(atmosphere, nu)[:, None]
    per_pixel = (ray_settings.view_steps + 1) * max(ray_settings.sun_steps + 1, 48)
    chunk = max(1, CHUNK_ELEMENTS // per_pixel)
    sky = np.empty((mu_v.size, 3))
    for start in range(0, mu_v.size, chunk):
        part = slice(start, start + chunk)
        ibar = _single_scattering_cells(atmosphere, ray_settings, h[part], mu_v_in[part], mu_s_in[part], sun_table,
                                        nu[part])
        value = f_r[part] * ibar[:, :3] + f_m[part] * ibar[:, 3:]
        if gathered is not None:
            more = _gathered_along(atmosphere, ray_settings, gathered, grid_settings, h[part], mu_v_in[part],
                                   mu_s_in[part], nu[part])
            value += (more[:, :3] + more[:, 3:]) if physical else (f_r[part] * more[:, :3] + f_m[part] * more[:, 3:])
        if atmosphere.has_ground:
            value += _ground_reflection(atmosphere, ray_settings, grid_settings, ground_irradiance, sun_table, h[part],
                                        mu_v_in[part], mu_s_in[part], nu[part])
        sky[part] = value
    sky *= np.asarray(atmosphere.incident_light) * inside[:, None]
    return (sky + _sun_disc(atmosphere, mu_v, nu, altitude, sun_radiance, cos_sun_radius)).reshape(shape + (3,))


def render_skyview(sky_map, sky_rows, azimuth_mapping, directions, sun_direction, altitude, horizon_cos_value,
                   horizon_angle, sun_radiance, cos_sun_radius):
    """Twin of ``SkyRenderer.render_skyview``'s kernel (``kernels/skyview.cl``): the sky-view map
    ``sky_map`` (H, W, 3) (``sky_rows`` sky rows, then ground rows; :mod:`clsky.skyview`) read bilinearly
    per direction within the direction's half (mu_v >= ``horizon_cos_value`` or below), plus the sun disc;
    (..., 3). ``azimuth_mapping``: 'linear' or 'sun'; ``horizon_angle`` = acos(horizon_cos_value) [rad]."""
    shape = np.shape(directions)[:-1]
    v = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    sun = np.asarray(sun_direction, dtype=np.float64)
    sky_map = np.asarray(sky_map, dtype=np.float64)
    height, width = sky_map.shape[:2]
    ground_rows = height - sky_rows
    mu_v = np.clip(v[:, 2], -1.0, 1.0)
    nu = np.clip(v @ sun, -1.0, 1.0)
    theta = np.arctan2(np.sqrt(v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1]), v[:, 2])
    sun_horizontal = math.sqrt(sun[0] * sun[0] + sun[1] * sun[1])
    sun_unit = sun[:2] / sun_horizontal if sun_horizontal > 0.0 else np.array([1.0, 0.0])
    horizontal = np.sqrt(v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1])[:, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        view = np.where(horizontal > 0.0, v[:, :2] / horizontal, sun_unit)
    chord = np.linalg.norm(view - sun_unit, axis=-1)          # 2 sin(phi / 2)
    if azimuth_mapping == "sun":
        u = np.minimum(0.5 * chord, 1.0)
    else:
        u = 2.0 * np.arctan2(chord, np.linalg.norm(view + sun_unit, axis=-1)) / math.pi

    def node(f, n):
        g = np.clip(f, 0.0, n - 1.0)
        i = np.clip(g.astype(np.int64), 0, n - 2)
        return i, g - i

    x0, ax = node(u * (width - 1), width)
    sky = mu_v >= horizon_cos_value
    t_sky = 1.0 - np.sqrt(np.maximum(1.0 - theta / horizon_angle, 0.0))
    t_ground = np.sqrt(np.maximum((theta - horizon_angle) / (math.pi - horizon_angle), 0.0))
    y_sky, a_sky = node(t_sky * (sky_rows - 1), sky_rows)
    y_ground, a_ground = node(t_ground * (ground_rows - 1), ground_rows)
    y0 = np.where(sky, y_sky, sky_rows + y_ground)
    ay = np.where(sky, a_sky, a_ground)[:, None]
    ax = ax[:, None]
    value = ((1.0 - ay) * ((1.0 - ax) * sky_map[y0, x0] + ax * sky_map[y0, x0 + 1])
             + ay * ((1.0 - ax) * sky_map[y0 + 1, x0] + ax * sky_map[y0 + 1, x0 + 1]))
    disc = ((nu >= cos_sun_radius) & (mu_v >= horizon_cos_value))[:, None] * np.asarray(sun_radiance, np.float64)
    return (value + disc).reshape(shape + (3,))
