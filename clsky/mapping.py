"""Texture mappings of the 3D scattering table (NumPy), mirroring ``kernels/mapping.cl``.

Non-linear (Atmosphere Plus, default): u = sqrt(h / Ha), v = (1 + sign(c) |c|^(1/3)) / 2;
inverses h = u^2 Ha, c = (2v - 1)^3. Linear (Elek 2009): u = h / Ha, v = (c + 1) / 2.
The same formula maps the view-zenith cosine (v) and the sun-zenith cosine (w).
"""

from __future__ import annotations

import numpy as np

from .settings import MAPPINGS, _check_choice

__all__ = ["altitude_to_u", "u_to_altitude", "cos_to_v", "v_to_cos", "grid_coordinates"]


def altitude_to_u(altitude, atmosphere_height, mapping="nonlinear"):
    """Texture coordinate u in [0, 1] of altitude [m] (clamped to [0, Ha])."""
    x = np.clip(np.asarray(altitude, dtype=np.float64) / atmosphere_height, 0.0, 1.0)
    return np.sqrt(x) if _check_choice("mapping", mapping, MAPPINGS) == "nonlinear" else x


def u_to_altitude(u, atmosphere_height, mapping="nonlinear"):
    """Altitude [m] of texture coordinate u in [0, 1]."""
    u = np.asarray(u, dtype=np.float64)
    return (u * u if _check_choice("mapping", mapping, MAPPINGS) == "nonlinear" else u) * atmosphere_height


def cos_to_v(cosine, mapping="nonlinear"):
    """Texture coordinate v (or w) in [0, 1] of a zenith cosine (clamped to [-1, 1])."""
    c = np.clip(np.asarray(cosine, dtype=np.float64), -1.0, 1.0)
    return 0.5 * (1.0 + (np.cbrt(c) if _check_choice("mapping", mapping, MAPPINGS) == "nonlinear" else c))


def v_to_cos(v, mapping="nonlinear"):
    """Zenith cosine of texture coordinate v (or w) in [0, 1]."""
    t = 2.0 * np.asarray(v, dtype=np.float64) - 1.0
    return t * t * t if _check_choice("mapping", mapping, MAPPINGS) == "nonlinear" else t


def grid_coordinates(size, atmosphere_height, mapping="nonlinear"):
    """Node values of the table axes.

    Returns
    -------
    altitude [m] (W,), cos view zenith (H,), cos sun zenith (D,)
        At texture coordinates x / (W - 1), y / (H - 1), z / (D - 1).
    """
    width, height, depth = size
    return (u_to_altitude(np.arange(width) / (width - 1), atmosphere_height, mapping),
            v_to_cos(np.arange(height) / (height - 1), mapping),
            v_to_cos(np.arange(depth) / (depth - 1), mapping))
