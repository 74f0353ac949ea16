"""Texture mappings of the 3D scattering table (NumPy), mirroring ``kernels/mapping.cl``.

Non-linear (Atmosphere Plus, default): u = sqrt(h / Ha), v = (1 + sign(c) |c|^(1/3)) / 2;
inverses h = u^2 Ha, c = (2v - 1)^3. Linear (Elek 2009): u = h / Ha, v = (c + 1) / 2.
The same formula maps the view-zenith cosine (v) and the sun-zenith cosine (w).

The sun axis may cover a sub-range of sun cosines only (``TableSettings.sun_cos_range``, chosen by
:mod:`clsky.planner` for a scene): its D nodes are then spread evenly in w between the range's ends,
and a sun cosine outside it reads the nearest end. The altitude and view axes always cover their whole
range: the gather integrates over every view direction, and view rays cross every altitude.
"""

from __future__ import annotations

import numpy as np

from .errors import check_choice
from .settings import MAPPINGS

__all__ = ["altitude_to_u", "u_to_altitude", "cos_to_v", "v_to_cos", "grid_coordinates", "FULL_SUN_RANGE",
           "sun_w_range", "cos_to_sun_t"]

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
