"""Independent reference for single scattering along one view ray: adaptive quadrature, no clsky code.

Computes the tables' factored single-scattering quantity (``docs/physics.md``, "Scattering equations")

    Ibar_s^(1)(lambda) = beta_s(lambda) / (4 pi) Integral_{Pa}^{Pb} rho_s(h(P)) T(Pc, P) T(P, Pa) ds,

s in {Rayleigh, Mie}, for one ray: observer at altitude h0 [m] inside the atmosphere, view zenith
cosine mu_v, sun zenith cosine mu_s, nu = dot(V, Sun). It is the yardstick for the node placement
along view rays (TableSettings.sampling): like :mod:`clsky.montecarlo` it imports nothing from
``clsky``, and it shares no formula with ``kernels/`` or :mod:`clsky.reference`:

* Geometry in Cartesian vectors: P(s) = P0 + s V, h = |P| - Rp; the ray ends where it meets the
  sphere Ra or, if it dips below the planet's horizon, the ground (from the quadratic |P0 + s V| = R).
* The view integral is one adaptive ODE solve (``scipy.integrate.solve_ivp``, DOP853, relative
  tolerance 1e-10) of the state (C_R, C_M, C_O, J_R[3], J_M[3]) with dC_s/ds = rho_s and
  dJ_s/ds = rho_s T: the columns from the observer and the integrals come out of the same adaptive
  steps. The ray is cut at the planet's shadow cylinder (|P|^2 - (P.Sun)^2 < Rp^2 with P.Sun < 0),
  solved in closed form, so that no adaptive step straddles the jump of T to zero.
* T(Pc, P), the sun leg, is a composite 8-point Gauss-Legendre rule over panels that grow
  geometrically (first 20 m, ratio 1.4) away from the leg's lowest point (the point itself, or the
  tangent point of a sun ray that first descends), so the e-folding of the haze (1.2 km) is resolved
  wherever it lies; the ozone tent's kinks (10, 25, 40 km) are panel edges too.
* Ozone (absorbing only): tau += sigma_O3 n_O3 with n_O3 = n_max max(0, 1 - |h - h_peak| / w) and
  n_max = column [DU] 2.687e20 m^-2 / w (physics.md).

Checks (tests/test_view_nodes.py): a 100x tighter ODE tolerance with finer sun-leg panels (first 5 m,
ratio 1.2) changes the result by < 1e-7 relative (3e-12 without ozone); the closed form of a haze
column seen straight down from the top holds to 1e-8; the Monte Carlo tracer agrees within its
standard error from 100 km.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["single_scattering_ray", "sun_columns"]

_DOBSON_UNIT = 2.687e20          # molecules per m^2
_GAUSS_X, _GAUSS_W = np.polynomial.legendre.leggauss(8)


def _ozone_extinction(atmosphere):
    """sigma_O3 n_max per channel [1/m] (zeros without ozone)."""
    column = float(getattr(atmosphere, "ozone_column_du", 0.0))
    sigma = np.asarray(getattr(atmosphere, "ozone_cross_section", (0.0, 0.0, 0.0)), dtype=np.float64)
    return sigma * column * _DOBSON_UNIT / float(getattr(atmosphere, "ozone_half_width", 15e3))


def _densities(atmosphere, h):
    """(rho_R, rho_M, ozone tent) at altitudes h [m]."""
    tent = np.maximum(1.0 - np.abs(h - float(getattr(atmosphere, "ozone_peak_altitude", 25e3)))
                      / float(getattr(atmosphere, "ozone_half_width", 15e3)), 0.0)
    return np.exp(-h / atmosphere.rayleigh_scale_height), np.exp(-h / atmosphere.mie_scale_height), tent


def _panels(length, first=20.0, ratio=1.4):
    """Breakpoints 0 < ... < length growing geometrically from 0 (first panel ``first`` m)."""
    points = [0.0]
    width = first
    while points[-1] + width < length:
        points.append(points[-1] + width)
        width *= ratio
    points.append(length)
    return np.asarray(points)


def _kinks(atmosphere, start, direction, length):
    """Distances in (0, length) along start + t direction where the ozone tent has a kink (altitudes
    h_peak and h_peak -+ w): panel edges there keep the Gauss-Legendre rule on smooth pieces."""
    peak = float(getattr(atmosphere, "ozone_peak_altitude", 25e3))
    width = float(getattr(atmosphere, "ozone_half_width", 15e3))
    b, c0 = float(start @ direction), float(start @ start)
    found = []
    for h in (peak - width, peak, peak + width):
        radius = atmosphere.planet_radius + h
        disc = b * b - (c0 - radius * radius)              # |start + t d| = radius
        if disc > 0.0:
            found += [t for t in (-b - math.sqrt(disc), -b + math.sqrt(disc)) if 0.0 < t < length]
    return np.asarray(found)


def _leg_columns(atmosphere, start, direction, lowest, length, first, ratio):
    """Columns (3,) [m] along start + t direction, t in [0, length], panels clustered at t = lowest
    (0 or length)."""
    if length <= 0.0:
        return np.zeros(3)
    edges = _panels(length, first, ratio)
    if lowest > 0.0:                                  # cluster at the far end
        edges = (length - edges)[::-1]
    edges = np.union1d(edges, _kinks(atmosphere, start, direction, length))
    a, b = edges[:-1, None], edges[1:, None]
    t = (0.5 * (a + b) + 0.5 * (b - a) * _GAUSS_X).ravel()
    w = (0.5 * (b - a) * _GAUSS_W).ravel()
    h = np.linalg.norm(start + t[:, None] * direction, axis=1) - atmosphere.planet_radius
    return np.array([np.dot(w, rho) for rho in _densities(atmosphere, h)])


def sun_columns(atmosphere, point, sun, first=20.0, ratio=1.4):
    """Column densities (C_R, C_M, C_O) [m] from ``point`` (3,) toward ``sun`` (unit 3-vector) to the
    top of the atmosphere, or None when the ray meets the planet."""
    rp, ra = atmosphere.planet_radius, atmosphere.top_radius
    b = float(point @ sun)
    rr = float(point @ point)
    if b < 0.0 and rr - b * b < rp * rp:
        return None
    length = -b + math.sqrt(max(b * b + ra * ra - rr, 0.0))
    if b >= 0.0:
        return _leg_columns(atmosphere, point, sun, 0.0, length, first, ratio)
    tangent = min(-b, length)                       # the sun ray descends to its tangent point first
    down = _leg_columns(atmosphere, point, sun, tangent, tangent, first, ratio)
    up = _leg_columns(atmosphere, point + tangent * sun, sun, 0.0, length - tangent, first, ratio)
    return down + up


def _view_length(r0, mu, rp, ra):
    """(length [m], hits_ground) of the ray from radius r0 along zenith cosine mu."""
    b = r0 * mu
    ground = b * b - (r0 * r0 - rp * rp)
    if mu < 0.0 and ground >= 0.0 and r0 > rp:
        return (r0 * r0 - rp * rp) / (-b + math.sqrt(ground)), True
    return -b + math.sqrt(b * b + ra * ra - r0 * r0), False


def _shadow_cuts(p0, view, sun, rp, length):
    """Distances in (0, length) where the ray crosses the boundary of the planet's shadow cylinder."""
    pv, ps, vs = float(p0 @ view), float(p0 @ sun), float(view @ sun)
    a = 1.0 - vs * vs
    b = 2.0 * (pv - ps * vs)
    c = float(p0 @ p0) - ps * ps - rp * rp
    cuts = []
    if a > 1e-15:
        disc = b * b - 4.0 * a * c
        if disc > 0.0:
            cuts += [(-b - math.sqrt(disc)) / (2.0 * a), (-b + math.sqrt(disc)) / (2.0 * a)]
    if vs != 0.0:
        cuts.append(-ps / vs)                         # P.Sun changes sign
    return sorted(s for s in cuts if 0.0 < s < length)


def single_scattering_ray(atmosphere, altitude, cos_view, cos_sun, cos_scatter, rtol=1e-10, first=20.0,
                          ratio=1.4):
    """Ibar^(1) [1/sr] of one ray by adaptive quadrature: Rayleigh r, g, b, Mie r, g, b (shape (6,)).

    Parameters
    ----------
    atmosphere : AtmosphereParameters (or any object with its fields)
    altitude : float
        Observer altitude [m] in [0, Ha].
    cos_view, cos_sun, cos_scatter : float
        mu_v = dot(V, zenith), mu_s = dot(Sun, zenith), nu = dot(V, Sun); nu must be compatible with
        the two zenith cosines.
    rtol : float
        Relative tolerance of the ODE solver.
    first, ratio : float
        First panel [m] and growth of the sun legs' Gauss-Legendre panels.
    """
    from scipy.integrate import solve_ivp

    rp, ra = float(atmosphere.planet_radius), float(atmosphere.top_radius)
    r0 = rp + float(altitude)
    sin_v = math.sqrt(max(1.0 - cos_view * cos_view, 0.0))
    view = np.array([sin_v, 0.0, cos_view])
    if sin_v > 1e-12:
        sun_x = (cos_scatter - cos_view * cos_sun) / sin_v
    else:
        sun_x = math.sqrt(max(1.0 - cos_sun * cos_sun, 0.0))
    sun = np.array([sun_x, math.sqrt(max(1.0 - cos_sun * cos_sun - sun_x * sun_x, 0.0)), cos_sun])
    sun /= np.linalg.norm(sun)
    p0 = np.array([0.0, 0.0, r0])
    length, _ = _view_length(r0, cos_view, rp, ra)
    beta_r = np.asarray(atmosphere.rayleigh_scattering, dtype=np.float64)
    beta_m = _mie_scattering(atmosphere)
    beta_o = _ozone_extinction(atmosphere)
    extinction = np.stack([beta_r, beta_m / float(atmosphere.mie_extinction_ratio), beta_o])  # (species, channel)

    def rhs(s, y, lit):
        p = p0 + s * view
        h = max(float(np.linalg.norm(p)) - rp, 0.0)
        rho = np.array(_densities(atmosphere, np.array(h)), dtype=np.float64)
        out = np.zeros(9)
        out[:3] = rho
        if lit:
            columns = sun_columns(atmosphere, p, sun, first, ratio)
            if columns is not None:
                t = np.exp(-(y[:3] + columns) @ extinction)
                out[3:6] = rho[0] * t
                out[6:9] = rho[1] * t
        return out

    y = np.zeros(9)
    edges = [0.0] + _shadow_cuts(p0, view, sun, rp, length) + [length]
    for a, b in zip(edges[:-1], edges[1:]):
        if b <= a:
            continue
        middle = p0 + 0.5 * (a + b) * view
        ms = float(middle @ sun)
        lit = not (ms < 0.0 and float(middle @ middle) - ms * ms < rp * rp)
        solution = solve_ivp(rhs, (a, b), y, method="DOP853", rtol=rtol, atol=1e-12, args=(lit,),
                             max_step=max((b - a) / 20.0, 1.0))
        y = solution.y[:, -1]
    scale = 1.0 / (4.0 * math.pi)
    return np.concatenate([beta_r * scale * y[3:6], beta_m * scale * y[6:9]])


def _mie_scattering(atmosphere) -> np.ndarray:
    """beta_M per channel [1/m]: Angstrom's law beta_M (lambda / lambda_0)^-alpha from the fields
    ``mie_angstrom_exponent`` alpha (0: every channel beta_M) and ``mie_reference_wavelength``."""
    beta = float(atmosphere.mie_scattering)
    alpha = float(getattr(atmosphere, "mie_angstrom_exponent", 0.0))
    if alpha == 0.0:
        return np.full(3, beta)
    wavelengths = np.asarray(atmosphere.wavelengths, dtype=np.float64)
    return beta * np.power(wavelengths / float(atmosphere.mie_reference_wavelength), -alpha)
