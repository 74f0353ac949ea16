"""A Lambertian ground of albedo a: the irradiance on the horizontal ground, order by order, and the
radiance it reflects into the next order (issue 10, item 2).

A Lambertian ground reflects the radiance L_g = a / pi E, E the irradiance on the horizontal ground
(physics.md). Per order, at altitude 0, per wavelength and sun node z of the table, in units of the
incident light I_I:

* the direct sun, E_0(mu_s) = mu_s T_sun(0, mu_s) (0 when the sun is below the horizon), with T_sun
  as single scattering computes it (``settings.sun_transmittance``, ``sun_steps``, ``sampling``);
* the sky of order k, E_k(mu_s) = Integral_{upper hemisphere} L^(k)(omega) cos(Theta) d omega, with the
  gather's (Theta, Phi) trapezoid and interpolation matrix P (:mod:`clsky.multiple`):

  - a factored order (single scattering: its light is F_s(dot(omega, Sun)) Ibar_s), whose azimuth
    integral of the phase is the gather's K_s at the sun node:
    E = sum_s sum_a wT_a sin(Theta_a) max(cos(Theta_a), 0) K_s(z, a) (P Ibar_s(z, ., h = 0))[a];
  - a phased order (physical mode, k >= 2), whose azimuth integral is 2 pi:
    E = 2 pi sum_a wT_a sin(Theta_a) max(cos(Theta_a), 0) (P L^(k)(z, ., h = 0))[a].

Bookkeeping (clsky/orders.py): order k's scatter adds, along each ray that ends on the ground, T L_g
of the ground lit by E_0 + ... + E_(k-1) not yet added (so the ground lit by the sun and by single
scattering joins order 2, since order 1 is stored factored without phase); the sum over orders is
the full series. The ray march adds T a / pi (E_0 at the ground point's true sun cosine + E_sky),
E_sky = sum_{k >= 1} E_k, stored with the table as ``ground_irradiance``.

Only the physical scheme supports a ground: the atmosphere-plus scheme applies the first event's
phase function to every order, which light reflected by the ground does not have.

Both backends compute these small (D, 3) arrays here on the host from the orders' host copies.
"""

from __future__ import annotations

import math

import numpy as np

from . import reference
from .atmosphere import AtmosphereParameters
from .errors import ParameterError
from .mapping import grid_coordinates
from .settings import TableSettings

__all__ = ["check_ground_mode", "default_settings", "direct_irradiance", "sky_irradiance", "reflected_radiance", "padded4",
           "interpolate_sun_axis"]


def default_settings(atmosphere: AtmosphereParameters) -> TableSettings:
    """The default TableSettings for ``atmosphere``: the physical scheme for a reflecting ground (which
    the atmosphere-plus scheme refuses: :func:`check_ground_mode`), else the plain defaults."""
    return TableSettings(mode="physical") if atmosphere.has_ground else TableSettings()


def check_ground_mode(atmosphere: AtmosphereParameters, mode: str, origin: str = ""):
    """ParameterError naming ``ground_albedo`` for a reflecting ground with the atmosphere-plus scheme
    (the scheme applies the first event's phase to every order; the ground's light has none).

    Parameters
    ----------
    atmosphere : AtmosphereParameters
    mode : str
        The scheme of the higher orders (``TableSettings.mode``).
    origin : str
        Where the ground comes from, when the user did not give it (e.g. "the physical preset's
        ground"): appended to the message.
    """
    if atmosphere.has_ground and mode != "physical":
        raise ParameterError("ground_albedo", f"0 with mode {mode!r} (the notes' scheme applies the first event's "
                                              f"phase to every order, which light reflected by the ground does "
                                              f"not have: use mode 'physical'" + (f"; here {origin}" if origin else "")
                             + ")", atmosphere.ground_albedo)


def direct_irradiance(atmosphere: AtmosphereParameters, settings: TableSettings) -> np.ndarray:
    """E_0 (D, 3): mu_s T_sun(0, mu_s) per sun node and wavelength [units of I_I], 0 below the horizon.

    T_sun as single scattering computes it: from the 2D column-density table when
    ``settings.sun_transmittance`` is 'table', else re-marched with ``sun_steps`` and ``sampling``.
    """
    _, _, cos_sun = grid_coordinates(settings.size, atmosphere.atmosphere_height, settings.mapping,
                                     settings.sun_cos_range)
    lit = cos_sun >= 0.0
    h = np.zeros_like(cos_sun)
    if settings.sun_transmittance == "table":
        table = reference.transmittance_table(atmosphere, settings.transmittance_size, settings.sun_steps,
                                              settings.sampling)
        columns = reference.column_density_from_table(atmosphere, table, h, cos_sun)
    else:
        length = np.where(lit, reference.distance_to_top(h, cos_sun, atmosphere.planet_radius,
                                                         atmosphere.top_radius), 0.0)
        columns = reference.column_density(atmosphere, h, cos_sun, length, settings.sun_steps, settings.sampling)
    transmittance = np.exp(-reference._optical_depth_of(atmosphere, *columns))
    return np.where(lit[:, None], np.maximum(cos_sun, 0.0)[:, None] * transmittance, 0.0)


def sky_irradiance(atmosphere: AtmosphereParameters, settings: TableSettings, order, factored: bool) -> np.ndarray:
    """E_k (D, 3) on the ground of one order's table [units of I_I] (module docstring).

    Parameters
    ----------
    order : array (D, H, W, 6) if ``factored`` (Rayleigh r, g, b, Mie r, g, b without phase), else
        (D, H, W, 3) or more channels of which the first 3 hold L^(k) r, g, b, phase applied.
    """
    from .multiple import SPECIES, _gather_parts, _quadrature_key, gather_quadrature

    p, weights, _, sun = _gather_parts(atmosphere, _quadrature_key(settings))
    theta = gather_quadrature(settings.gather_theta_steps, settings.gather_phi_steps)[0]
    hemisphere = weights * np.maximum(np.cos(theta), 0.0)          # wT sin(Theta) max(cos(Theta), 0)
    ground = np.asarray(order, dtype=np.float64)[:, :, 0, :]       # (D, H, C): altitude node 0, h = 0
    seen = np.matmul(p, ground)                                    # (D, Theta + 1, C): P along the view axis
    if not factored:
        return 2.0 * math.pi * np.einsum("a,zac->zc", hemisphere, seen[..., :3])
    total = 0.0
    for index, species in enumerate(SPECIES):
        total = total + np.einsum("a,za,zac->zc", hemisphere, sun[species], seen[..., 3 * index:3 * index + 3])
    return total


def reflected_radiance(atmosphere: AtmosphereParameters, irradiance) -> np.ndarray:
    """L_g = a / pi E: the radiance of the Lambertian ground lit by ``irradiance`` (same shape)."""
    return atmosphere.ground_albedo / math.pi * np.asarray(irradiance, dtype=np.float64)


def padded4(values, dtype=np.float64) -> np.ndarray:
    """(D, 3) values as the kernels read them: (D, 4) contiguous, the fourth column 0."""
    values = np.asarray(values)
    out = np.zeros(values.shape[:-1] + (4,), dtype=dtype)
    out[..., :3] = values
    return out


def interpolate_sun_axis(values, cos_sun, settings: TableSettings) -> np.ndarray:
    """``values`` (D, C) per sun node interpolated linearly in the sun axis' texture coordinate at
    ``cos_sun`` (...,): (..., C); twin of ``sun_axis_lookup`` (kernels/view_ray.cl)."""
    from .mapping import cos_to_sun_t

    depth = values.shape[0]
    fz = cos_to_sun_t(cos_sun, settings.mapping, settings.sun_cos_range) * (depth - 1)
    z0 = np.clip(fz.astype(np.int64), 0, depth - 2)
    az = (fz - z0)[..., None]
    return (1.0 - az) * values[z0] + az * values[z0 + 1]
