"""Tone mapping: HDR radiance to display values and 8-bit pixels.

The tone map is the one of ``docs/physics.md`` (Atmosphere Plus): an exponential exposure curve
followed by a pure power-law gamma of 2.2,

    display = (1 - exp(-exposure * hdr)) ** (1 / 2.2),

applied to each of r, g, b. The incident light I_I of clsky already contains the notes' exposure
(1.0); ``exposure`` here is an extra multiplier at display time (use it to look into twilight).

Examples
--------
>>> import numpy as np
>>> from clsky.anim.tonemap import tone_map, to_uint8, luminance
>>> [round(float(v), 5) for v in tone_map(np.array([0.0, 1.0, 100.0]))]
[0.0, 0.81181, 1.0]
>>> to_uint8(np.array([0.0, 0.5, 1.0]))
array([  0, 128, 255], dtype=uint8)
>>> float(luminance(np.array([1.0, 1.0, 1.0])))
1.0
"""

from __future__ import annotations

import numpy as np

from clsky.errors import check_flag, check_integer, short

__all__ = ["GAMMA", "REC709_LUMINANCE_WEIGHTS", "tone_map", "dither_noise", "to_uint8", "luminance"]

#: Display gamma of the tone map (physics.md): a pure power law, not the piecewise sRGB curve.
GAMMA = 2.2

#: Linear Rec. 709 / sRGB luminance weights (ITU-R BT.709, the Y row of the RGB -> XYZ matrix).
REC709_LUMINANCE_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])


def _check_rgb(name, values):
    """``values`` as float64 with a last axis of length 3, or ValueError naming ``name``."""
    values = np.asarray(values, dtype=np.float64)
    if values.ndim == 0 or values.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (..., 3) (r, g, b last), got shape {values.shape}")
    return values


def tone_map(hdr, exposure=1.0):
    """Map HDR radiance to display values in [0, 1].

    Parameters
    ----------
    hdr : array_like, shape (..., 3)
        Linear HDR r, g, b (radiance times the incident light, as clsky renders it) [arbitrary,
        >= 0]. +inf is allowed and maps to 1.
    exposure : float
        Display-time exposure multiplier [-], finite and > 0.

    Returns
    -------
    numpy.ndarray, float64, same shape as ``hdr``
        Gamma-2.2 encoded display values in [0, 1].

    Raises
    ------
    ValueError
        If ``hdr`` is not (..., 3), contains NaN or negative values, or ``exposure`` is not finite
        and positive.

    Notes
    -----
    display = (1 - exp(-exposure hdr))^(1/2.2) (docs/physics.md), computed as
    ``(-expm1(-exposure hdr)) ** (1/2.2)`` so that faint twilight values keep full relative
    precision. The curve is monotonic; display = 0 only for hdr = 0.

    Examples
    --------
    >>> import numpy as np
    >>> bool(abs(tone_map(np.array([1.0, 1.0, 1.0]))[0] - (1 - np.exp(-1.0)) ** (1 / 2.2)) < 1e-15)
    True
    """
    hdr = _check_rgb("hdr", hdr)
    if np.isnan(hdr).any():
        raise ValueError(f"hdr contains NaN ({int(np.isnan(hdr).sum())} values)")
    if (hdr < 0).any():
        raise ValueError(f"hdr contains negative values (minimum {hdr.min():.6g}); radiance must be >= 0")
    exposure = float(exposure)
    if not (np.isfinite(exposure) and exposure > 0):
        raise ValueError(f"exposure must be finite and > 0, got {short(exposure)}")
    return (-np.expm1(-exposure * hdr)) ** (1.0 / GAMMA)


def dither_noise(shape, seed=0):
    """The triangular-PDF noise n = u1 - u2 [LSB] that :func:`to_uint8` adds with ``dither`` and ``seed``
    (u1, u2 of ``numpy.random.default_rng(seed)``, in that order), of ``shape``: computed once for several
    images dithered alike (the frames of one sun position)."""
    rng = np.random.default_rng(seed)
    noise = rng.random(shape)
    noise -= rng.random(shape)
    return noise


def to_uint8(display, dither=False, seed=0, noise=None):
    """Quantise display values in [0, 1] to 8-bit code values, rounding to nearest.

    Parameters
    ----------
    display : array_like
        Display (gamma-encoded) values [-]; values outside [0, 1] are clipped.
    dither : bool
        Add triangular-PDF (TPDF) noise of +-1 LSB before rounding.
    seed : int or numpy.random.Generator
        Seed of the dither noise (ignored without ``dither``). The same seed gives the same noise
        pattern: reuse it across the frames of an animation for a static pattern (no temporal
        shimmer, smaller MP4), or pass the frame index for independent patterns.
    noise : numpy.ndarray, optional
        With ``dither``, the noise to add instead of drawing it from ``seed``: :func:`dither_noise` of the
        display's shape (the same values as ``seed`` gives, drawn once for several images).

    Returns
    -------
    numpy.ndarray of uint8, same shape as ``display``

    Raises
    ------
    ValueError
        If ``display`` contains NaN, ``dither`` is no bool, or (with ``dither``) ``seed`` is neither an
        integer >= 0 nor a Generator.

    Notes
    -----
    Without dither, code = floor(255 d + 1/2). A smooth sky gradient spanning a few code values then
    shows visible bands (Mach bands make the 1-LSB steps stand out in large, slowly varying areas).
    With dither, n = u1 - u2 (u1, u2 independent uniform on [0, 1)) is added to 255 d before
    rounding: n has a triangular PDF on (-1, 1) LSB. TPDF noise of this width makes both the mean
    and the variance of the quantisation error independent of the signal (Lipshitz, Wannamaker and
    Vanderkooy 1992), so local averages of the 8-bit image follow the true gradient instead of
    staircases, at the cost of a noise of 1/sqrt(6) LSB added to the 1/sqrt(12) LSB of plain
    rounding. Values clipped at 0 or 1 keep a small bias (the noise cannot go below 0 or above
    255). RPDF (uniform +-1/2 LSB) would decorrelate the mean only, leaving signal-dependent noise
    power ("noise modulation") that shows in smooth gradients.

    References
    ----------
    S. P. Lipshitz, R. A. Wannamaker, J. Vanderkooy, "Quantization and dither: a theoretical
    survey", J. Audio Eng. Soc. 40(5), 355-375 (1992).

    Examples
    --------
    >>> import numpy as np
    >>> flat = np.full((64, 64), 100.3 / 255)
    >>> float(to_uint8(flat).mean())
    100.0
    >>> abs(float(to_uint8(flat, dither=True).mean()) - 100.3) < 0.05
    True
    """
    if check_flag("dither", dither) and noise is None and not isinstance(seed, np.random.Generator):
        check_integer("seed", seed, 0, 2**63 - 1)    # 'no' dithered; NaN or -1 was NumPy's SeedSequence error
    display = np.asarray(display, dtype=np.float64)
    if np.isnan(display).any():
        raise ValueError(f"display contains NaN ({int(np.isnan(display).sum())} values)")
    scaled = np.clip(display, 0.0, 1.0) * 255.0
    if dither:
        if noise is None:
            noise = dither_noise(scaled.shape, seed)
        elif np.shape(noise) != scaled.shape:
            raise ValueError(f"noise must have the display's shape {scaled.shape}, got {np.shape(noise)}")
        scaled = scaled + noise
    return np.clip(np.floor(scaled + 0.5), 0, 255).astype(np.uint8)


def luminance(rgb):
    """Relative luminance Y of linear Rec. 709 / sRGB values.

    Parameters
    ----------
    rgb : array_like, shape (..., 3)
        Linear r, g, b (HDR radiance or linear display values) [any unit].

    Returns
    -------
    numpy.ndarray, float64, shape ``rgb.shape[:-1]``
        Y = 0.2126 r + 0.7152 g + 0.0722 b [same unit].

    Raises
    ------
    ValueError
        If ``rgb`` is not (..., 3).

    Notes
    -----
    Apply it to linear values only, never to gamma-encoded display values.

    Examples
    --------
    >>> import numpy as np
    >>> float(luminance(np.array([0.0, 1.0, 0.0])))
    0.7152
    """
    rgb = _check_rgb("rgb", rgb)
    return rgb @ REC709_LUMINANCE_WEIGHTS
