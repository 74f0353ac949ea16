"""Image metrics: a table-lookup render against the per-pixel ray-marched reference.

- :func:`compare_frames`: one frame, HDR RMSE, relative HDR luminance errors (median, 95th
  percentile, maximum) and the mean CIELAB Delta E of the tone-mapped images
  (:func:`frame_comparison`: the same, with the error map and both frames' mean luminances).
- :func:`relative_error_map` and :func:`error_image`: where the errors are, as a colour image with
  a legend; :func:`composite` puts panels side by side (table | ray march | error).
- :func:`temporal_jumps`: frame-to-frame jumps of a sequence that the reference does not have (the
  "jumpy in time" twilight of table renders).

Colour conversions (:func:`display_to_lab`, :func:`linear_srgb_to_xyz`, :func:`xyz_to_lab`,
:func:`delta_e_cie76`) follow IEC 61966-2-1 (sRGB primaries and D65 white) and CIE 15 (CIELAB).

Examples
--------
>>> import numpy as np
>>> from clsky.anim.metrics import compare_frames
>>> reference = np.full((4, 4, 3), 0.5)
>>> result = compare_frames(reference, 1.1 * reference)
>>> round(result["median_rel"], 12), round(result["max_rel"], 12)
(0.1, 0.1)
"""

from __future__ import annotations

import dataclasses

import numpy as np

from clsky import colorimetry
from clsky.errors import check_integer, check_real, short

from .pixels import set_valid_pixels, valid_pixels
from .tonemap import GAMMA, luminance, tone_map

__all__ = ["compare_frames", "frame_comparison", "FrameComparison", "relative_error_map", "relative_error_floor",
           "display_to_lab", "linear_srgb_to_xyz", "xyz_to_lab", "delta_e_cie76", "SRGB_TO_XYZ", "D65_WHITE_XYZ",
           "mean_luminance", "relative_jumps", "frame_changes", "display_floor", "temporal_jumps",
           "colormap_viridis", "error_image", "composite", "INVALID_COLOUR", "BLACK_FRAME_FLOOR"]

#: Fraction of the reference's 99th-percentile luminance below which relative errors are measured
#: against that floor instead of the pixel's own luminance.
RELATIVE_FLOOR_FRACTION = 1e-3

#: Floor [HDR units] when the reference frame is black (its 99th percentile and maximum are 0): far
#: below anything the tone map can show (half an 8-bit code value is hdr ~ 1.1e-6 at exposure 1),
#: and large enough that |Y_test - Y_ref| / floor stays finite in float64.
BLACK_FRAME_FLOOR = 1e-30

#: Largest HDR value [HDR units] a compared frame may hold: squares and sums of a frame's values stay
#: finite in float64 up to about 1e154 a value; 1e100 leaves room for any pixel count and is far above
#: any sky (the sun's disc is about 1.6e9 cd/m^2). Beyond it the metrics were NaN (an RMSE of inf / inf).
MAX_HDR_VALUE = 1e100


# Colour science -------------------------------------------------------------------------------------

#: Linear sRGB -> CIE XYZ and the XYZ of its D65 white (Y = 1, (0.95046, 1, 1.08906)): clsky's one sRGB
#: matrix, derived at full precision from the IEC 61966-2-1 primaries and D65
#: (:data:`clsky.colorimetry.SRGB_TO_XYZ`; its docstring says why this one and not the printed one).
SRGB_TO_XYZ, D65_WHITE_XYZ = colorimetry.SRGB_TO_XYZ, colorimetry.D65_WHITE_XYZ


def linear_srgb_to_xyz(rgb):
    """CIE XYZ of linear sRGB values (IEC 61966-2-1, D65).

    Parameters
    ----------
    rgb : array_like, shape (..., 3)
        Linear sRGB r, g, b [-] (1 = display white).

    Returns
    -------
    numpy.ndarray, shape (..., 3)
        X, Y, Z with Y = 1 for white.
    """
    rgb = np.asarray(rgb, dtype=np.float64)
    if rgb.ndim == 0 or rgb.shape[-1] != 3:
        raise ValueError(f"rgb must have shape (..., 3), got shape {rgb.shape}")
    return rgb @ SRGB_TO_XYZ.T


def xyz_to_lab(xyz, white=D65_WHITE_XYZ):
    """CIE 1976 L*a*b* of XYZ values (CIE 15:2004, eq. 8.3).

    Parameters
    ----------
    xyz : array_like, shape (..., 3)
        CIE XYZ [-].
    white : array_like, shape (3,)
        XYZ of the reference white (default D65 of sRGB, Y = 1).

    Returns
    -------
    numpy.ndarray, shape (..., 3)
        L* [0, 100], a*, b*.

    Notes
    -----
    f(t) = t^(1/3) for t > (6/29)^3, else t / (3 (6/29)^2) + 4/29;
    L* = 116 f(Y/Yn) - 16, a* = 500 (f(X/Xn) - f(Y/Yn)), b* = 200 (f(Y/Yn) - f(Z/Zn)).
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    if xyz.ndim == 0 or xyz.shape[-1] != 3:
        raise ValueError(f"xyz must have shape (..., 3), got shape {xyz.shape}")
    t = xyz / np.asarray(white, dtype=np.float64)
    delta = 6.0 / 29.0
    # f = where(t > delta^3, cbrt(t), t / (3 delta^2) + 4/29), each branch's operations on each value, in
    # place: a third fewer full-frame passes than np.where of both branches and a stack (the animation's
    # Delta E takes it for two frames a frame)
    f = np.cbrt(t)
    linear = ~(t > delta ** 3)
    np.copyto(f, t / (3.0 * delta * delta) + 4.0 / 29.0, where=linear)
    lab = np.empty_like(f)
    np.multiply(116.0, f[..., 1], out=lab[..., 0])
    lab[..., 0] -= 16.0
    np.multiply(500.0, np.subtract(f[..., 0], f[..., 1], out=lab[..., 1]), out=lab[..., 1])
    np.multiply(200.0, np.subtract(f[..., 1], f[..., 2], out=lab[..., 2]), out=lab[..., 2])
    return lab


def display_to_lab(display, gamma=GAMMA):
    """L*a*b* (D65) of gamma-encoded display values, as :func:`clsky.anim.tonemap.tone_map` returns them.

    Decodes ``display ** gamma`` -> linear sRGB -> XYZ -> L*a*b*. The tone map's gamma is a pure
    power law of 2.2 (physics.md), so the decoding is the same power law, not the piecewise sRGB
    curve.

    Parameters
    ----------
    display : array_like, shape (..., 3)
        Display values in [0, 1].
    gamma : float
        Decoding exponent [-].

    Returns
    -------
    numpy.ndarray, shape (..., 3)
    """
    display = np.asarray(display, dtype=np.float64)
    return xyz_to_lab(linear_srgb_to_xyz(np.clip(display, 0.0, 1.0) ** gamma))


def delta_e_cie76(lab_1, lab_2):
    """CIE76 colour difference: the Euclidean distance in L*a*b*.

    About 2.3 is a just-noticeable difference. CIEDE2000 (CIE 142-2001) corrects the
    non-uniformities of CIELAB (saturated blues in particular) and would be a possible refinement.

    Parameters
    ----------
    lab_1, lab_2 : array_like, shape (..., 3)

    Returns
    -------
    numpy.ndarray, shape (...)
    """
    difference = np.asarray(lab_1, dtype=np.float64) - np.asarray(lab_2, dtype=np.float64)
    squared = difference * difference
    # the three terms added in order, as np.sum(..., axis=-1) adds them (the same values), without its
    # reduction over rows of 3, 5x slower
    return np.sqrt(squared[..., 0] + squared[..., 1] + squared[..., 2])


# One frame ------------------------------------------------------------------------------------------

def _check_valid(valid, shape):
    if valid is None:
        return np.ones(shape, dtype=bool)
    valid = np.asarray(valid)
    if valid.dtype != bool:
        raise TypeError(f"valid must be a bool mask, got dtype {valid.dtype}")
    if valid.shape != tuple(shape):
        raise ValueError(f"valid must have shape {tuple(shape)}, got {valid.shape}")
    if not valid.any():
        raise ValueError("valid selects no pixel")
    return valid


def _checked_values(name, frames, valid):
    """``frames`` (..., H, W, 3) with its valid pixels checked (finite, >= 0, at most
    :data:`MAX_HDR_VALUE`), invalid ones zeroed.

    Invalid pixels may hold anything (NaN outside a fisheye circle, say): they never count.
    """
    checked = np.where(valid[..., None], frames, 0.0)
    # the zeroed invalid pixels change neither test: NaN propagates through min and max, +-inf shows in
    # one of them, and a negative value in the minimum (two passes, instead of four with copies)
    low, high = checked.min(initial=0.0), checked.max(initial=0.0)
    if not (np.isfinite(low) and np.isfinite(high)):
        values = frames[..., valid, :]
        raise ValueError(f"{name} contains {int((~np.isfinite(values)).sum())} NaN or infinite values "
                         f"on valid pixels")
    if low < 0:
        raise ValueError(f"{name} contains negative values on valid pixels (minimum {low:.6g})")
    if high > MAX_HDR_VALUE:
        raise ValueError(f"{name} contains values above {MAX_HDR_VALUE:g} on valid pixels (maximum {high:.6g}): "
                         f"their squares overflow the metrics")
    return checked


def _check_pair(reference, test, valid):
    reference = np.asarray(reference, dtype=np.float64)
    test = np.asarray(test, dtype=np.float64)
    for name, frame in (("reference", reference), ("test", test)):
        if frame.ndim != 3 or frame.shape[-1] != 3:
            raise ValueError(f"{name} must be an HDR frame of shape (H, W, 3), got shape {frame.shape}")
    if reference.shape != test.shape:
        raise ValueError(f"reference and test differ in shape: {reference.shape} and {test.shape}")
    valid = _check_valid(valid, reference.shape[:2])
    return _checked_values("reference", reference, valid), _checked_values("test", test, valid), valid


def relative_error_floor(reference_luminance):
    """Floor of the denominator of the relative luminance error.

    Parameters
    ----------
    reference_luminance : array_like
        Y of the reference over the pixels that count (the valid ones).

    Returns
    -------
    float
        1e-3 times the 99th percentile of Y_ref (its maximum when the percentile is 0), or
        :data:`BLACK_FRAME_FLOOR` when the reference is black.

    Notes
    -----
    A relative error |dY| / Y_ref is unbounded where Y_ref -> 0: pixels below the horizon (black
    ground), the dark side of a twilight sky, or a whole night frame. The floor, a fixed fraction of
    the frame's own bright level, keeps such pixels from dominating the statistics while staying
    scale invariant (a night frame 1e-6 as bright as day gets a floor 1e-6 as large: its relative
    errors still count). The 99th percentile rather than the maximum ignores the sun disc and a few
    hot pixels. Pixels darker than the floor are measured in units of the floor (an absolute error).
    """
    values = np.asarray(reference_luminance, dtype=np.float64).ravel()
    scale = float(np.percentile(values, 99)) if values.size else 0.0
    if scale <= 0.0 and values.size:
        scale = float(values.max())
    return RELATIVE_FLOOR_FRACTION * scale if scale > 0.0 else BLACK_FRAME_FLOOR


def _relative_error(reference, test, valid):
    """(error map, Y of the reference, Y of the test, floor) of checked frames."""
    y_reference, y_test = luminance(reference), luminance(test)
    floor = relative_error_floor(y_reference[valid])
    error = np.abs(y_test - y_reference) / np.maximum(y_reference, floor)
    error[~valid] = 0.0
    return error, y_reference, y_test, floor


def relative_error_map(reference, test, valid=None):
    """Per-pixel relative HDR luminance error of ``test`` against ``reference``.

    Parameters
    ----------
    reference : array_like, shape (H, W, 3)
        Reference HDR frame (per-pixel ray march) [HDR units, >= 0].
    test : array_like, shape (H, W, 3)
        Frame under test (table lookup) [same units].
    valid : array_like of bool, shape (H, W), optional
        Pixels that count (default: all).

    Returns
    -------
    numpy.ndarray, float64, shape (H, W)
        e = |Y_test - Y_ref| / max(Y_ref, floor) [-] (floor: :func:`relative_error_floor`), 0 on
        invalid pixels; never NaN.

    Raises
    ------
    ValueError
        Shapes differ or are not (H, W, 3); NaN, infinite or negative values on valid pixels
        (invalid pixels may hold anything); ``valid`` selects no pixel.
    TypeError
        ``valid`` is not boolean.
    """
    reference, test, valid = _check_pair(reference, test, valid)
    return _relative_error(reference, test, valid)[0]


@dataclasses.dataclass(frozen=True)
class FrameComparison:
    """What :func:`frame_comparison` computes of a pair of frames.

    Attributes
    ----------
    numbers : dict
        :func:`compare_frames`' numbers.
    error_map : numpy.ndarray, shape (H, W)
        The relative error map they are taken of (:func:`relative_error_map`'s values).
    mean_luminance : tuple of float
        The reference's and the test's mean luminance over the valid pixels [HDR units]: the values of
        :func:`mean_luminance`, from the luminance the comparison takes anyway.
    """

    numbers: dict
    error_map: np.ndarray
    mean_luminance: tuple


def compare_frames(reference, test, valid=None, exposure=1.0, display=None, return_error_map=False):
    """Compare a table-lookup frame with the ray-marched reference.

    Parameters
    ----------
    reference : array_like, shape (H, W, 3)
        Reference HDR frame (per-pixel ray march) [HDR units, >= 0].
    test : array_like, shape (H, W, 3)
        Frame under test (table lookup) [same units].
    valid : array_like of bool, shape (H, W), optional
        Pixels that count (default: all), e.g. the inside of a fisheye circle.
    exposure : float
        Exposure of the tone map applied to both frames for Delta E [-] (without ``display``).
    display : callable or (array_like, array_like), optional
        HDR pixels (N, 3) -> display-linear sRGB in [0, 1] (N, 3): the display pipeline the frames are
        shown with, e.g. ``lambda pixels: clsky.anim.display.Display(...).linear(pixels, ev)`` at one EV for
        both frames; or that pipeline's values already computed for the whole frames, (reference,
        test), each (H, W, 3) (:func:`clsky.anim.animate.display_frames`): the same numbers without a second
        evaluation. Default: the notes' tone map at ``exposure``, decoded with its gamma 2.2.
    return_error_map : bool
        Also return the per-pixel relative error map that the statistics are taken of (what
        :func:`relative_error_map` returns for the same frames), computed once for both.

    Returns
    -------
    dict of str -> float (JSON-serialisable; ``pixels`` is an int), or (that dict, error map (H, W)) with
    ``return_error_map``
        ``rmse``: sqrt(mean over valid pixels and channels of (test - ref)^2) [HDR units];
        ``rmse_relative``: rmse / max(mean(Y_ref), floor) [-] (the floor of :func:`relative_error_floor`);
        ``median_rel``, ``p95_rel``, ``max_rel``: statistics of the relative luminance error e of
        :func:`relative_error_map` over the valid pixels [-];
        ``mean_delta_e``: mean CIE76 Delta E between the displayed frames;
        ``floor``: the luminance floor of e [HDR units]; ``pixels``: number of valid pixels.

    Raises
    ------
    ValueError, TypeError
        As :func:`relative_error_map`, and for a bad ``exposure``.

    Notes
    -----
    Y = 0.2126 r + 0.7152 g + 0.0722 b on the linear HDR values. e = |Y_test - Y_ref| / max(Y_ref,
    floor), floor = 1e-3 * P99(Y_ref) (see :func:`relative_error_floor`: without it, black ground
    and night pixels, where Y_ref -> 0, would make e unbounded). The percentiles are NumPy's
    (linear interpolation).

    Delta E: both frames are tone mapped with the same ``exposure``
    (:func:`clsky.anim.tonemap.tone_map`), decoded with the power law 2.2 back to linear sRGB, converted
    to XYZ (IEC 61966-2-1, D65) and L*a*b* (D65 white), and compared with CIE76 (Euclidean
    distance; about 2.3 is just noticeable). It measures what a viewer sees: errors in saturated
    (hdr >> 1) or black pixels count little. CIEDE2000 would be a possible refinement. The display
    values are not quantised to 8 bits first. With ``display``, Delta E is that of what the display
    pipeline shows (its display-linear sRGB -> XYZ -> L*a*b*); every other number is of the HDR values.

    Examples
    --------
    >>> import numpy as np
    >>> frame = np.full((2, 2, 3), 0.25)
    >>> compare_frames(frame, frame)["mean_delta_e"]
    0.0
    """
    comparison = frame_comparison(reference, test, valid, exposure, display)
    return (comparison.numbers, comparison.error_map) if return_error_map else comparison.numbers


def frame_comparison(reference, test, valid=None, exposure=1.0, display=None) -> FrameComparison:
    """:func:`compare_frames` of ``reference`` and ``test`` (the same parameters and errors), with the error
    map and both frames' :func:`mean_luminance` from one check and one luminance of each frame (an
    animation's temporal jumps take the means: about 8 CPU-ms a 512 x 512 frame pair when taken apart).

    Examples
    --------
    >>> import numpy as np
    >>> comparison = frame_comparison(np.full((2, 2, 3), 0.5), np.full((2, 2, 3), 0.25))
    >>> comparison.numbers["median_rel"], comparison.mean_luminance
    (0.5, (0.5, 0.25))
    """
    reference, test, valid = _check_pair(reference, test, valid)
    error, y_reference, y_test, floor = _relative_error(reference, test, valid)
    difference = valid_pixels(test - reference, valid)
    rmse = float(np.sqrt(np.mean(difference * difference)))
    mean_luminance = float(y_reference[valid].mean())
    errors = error[valid]
    if display is None:
        delta_e = delta_e_cie76(display_to_lab(tone_map(valid_pixels(reference, valid), exposure)),
                                display_to_lab(tone_map(valid_pixels(test, valid), exposure)))
    else:
        if callable(display):
            shown = display(valid_pixels(reference, valid)), display(valid_pixels(test, valid))
        else:
            shown = [np.asarray(frame, dtype=np.float64) for frame in display]
            if len(shown) != 2 or any(frame.shape != reference.shape for frame in shown):
                raise ValueError(f"display must be a callable or two display-linear frames of shape "
                                 f"{reference.shape}, got {[np.shape(frame) for frame in display]}")
            shown = [valid_pixels(frame, valid) for frame in shown]
        delta_e = delta_e_cie76(xyz_to_lab(linear_srgb_to_xyz(np.clip(shown[0], 0.0, 1.0))),
                                xyz_to_lab(linear_srgb_to_xyz(np.clip(shown[1], 0.0, 1.0))))
    numbers = {
        "rmse": rmse,
        "rmse_relative": rmse / max(mean_luminance, floor),
        "median_rel": float(np.median(errors)),
        "p95_rel": float(np.percentile(errors, 95)),
        "max_rel": float(errors.max()),
        "mean_delta_e": float(delta_e.mean()),
        "floor": float(floor),
        "pixels": int(valid.sum()),
    }
    return FrameComparison(numbers, error, (mean_luminance, float(y_test[valid].mean())))


# Sequences ------------------------------------------------------------------------------------------

def display_floor(exposure=1.0):
    """HDR value that the tone map shows as half an 8-bit code value [HDR units].

    Solves (1 - exp(-exposure x))^(1/2.2) = 0.5 / 255: x = -ln(1 - (0.5/255)^2.2) / exposure,
    about 1.1e-6 at exposure 1. Changes between values below it are invisible on an 8-bit display.
    """
    exposure = check_real("exposure", exposure, 0.0, low_open=True)
    with np.errstate(over="ignore"):
        floor = float(-np.log1p(-(0.5 / 255.0) ** GAMMA) / exposure)
    if not np.isfinite(floor):                 # 1e-320: an infinite floor, and every jump 0
        raise ValueError(f"exposure must be large enough for a finite floor, got {short(exposure)}")
    return floor


def _as_frames(name, frames, valid):
    """(frames with invalid pixels zeroed, valid mask) after checking shapes and values."""
    frames = np.asarray(frames, dtype=np.float64)
    if frames.ndim != 4 or frames.shape[-1] != 3:
        raise ValueError(f"{name} must be frames of shape (N, H, W, 3), got shape {frames.shape}")
    valid = _check_valid(valid, frames.shape[1:3])
    return _checked_values(name, frames, valid), valid


def mean_luminance(frames, valid=None):
    """Mean HDR luminance of each frame over the valid pixels.

    Parameters
    ----------
    frames : array_like, shape (N, H, W, 3)
        HDR frames [HDR units].
    valid : array_like of bool, shape (H, W), optional

    Returns
    -------
    numpy.ndarray, shape (N,)
    """
    frames, valid = _as_frames("frames", frames, valid)
    return luminance(frames)[:, valid].mean(axis=1)


def relative_jumps(means, floor):
    """Relative jump of a per-frame quantity between consecutive frames.

    j_0 = 0 and j_k = |m_k - m_(k-1)| / max(m_k, m_(k-1), floor) for k >= 1 (in [0, 1] for m >= 0).

    Parameters
    ----------
    means : array_like, shape (N,)
        Per-frame values, e.g. mean luminances [HDR units, >= 0].
    floor : float
        Denominator floor [same units, > 0].

    Returns
    -------
    numpy.ndarray, shape (N,)
    """
    means = np.asarray(means, dtype=np.float64)
    if means.ndim != 1:
        raise ValueError(f"means must be one value per frame, shape (N,), got {means.shape}")
    if not np.isfinite(means).all() or (means < 0).any():
        raise ValueError("means contains NaN, infinite or negative values")
    floor = check_real("floor", floor, 0.0, low_open=True)
    jumps = np.zeros_like(means)
    jumps[1:] = np.abs(np.diff(means)) / np.maximum(np.maximum(means[1:], means[:-1]), floor)
    return jumps


def frame_changes(frames, valid=None, floor=None, exposure=1.0):
    """Mean absolute per-pixel relative luminance change between consecutive frames.

    c_0 = 0 and c_k = mean over valid pixels of |Y_k - Y_(k-1)| / max(Y_k, Y_(k-1), floor).

    Unlike the jump of the frame means, this sees changes that cancel in the mean (one part of the
    sky brightening while another darkens, a band sweeping across the image).

    Parameters
    ----------
    frames : array_like, shape (N, H, W, 3)
        HDR frames [HDR units].
    valid : array_like of bool, shape (H, W), optional
    floor : float, optional
        Denominator floor [HDR units]; default :func:`display_floor` of ``exposure``.
    exposure : float

    Returns
    -------
    numpy.ndarray, shape (N,)
    """
    frames, valid = _as_frames("frames", frames, valid)
    floor = display_floor(exposure) if floor is None else float(floor)
    if not floor > 0:
        raise ValueError(f"floor must be > 0, got {short(floor)}")
    y = luminance(frames)[:, valid]
    changes = np.zeros(len(frames))
    if len(frames) > 1:
        changes[1:] = np.mean(np.abs(np.diff(y, axis=0)) / np.maximum(np.maximum(y[1:], y[:-1]), floor),
                              axis=1)
    return changes


def temporal_jumps(table, raymarch, valid=None, floor=None, exposure=1.0, per_pixel=False, worst=5):
    """Frame-to-frame jumps of a table render that the ray-marched reference does not have.

    Table renders of a sun sweep can be "jumpy in time" in twilight: when the sun crosses a node of
    the table's sun-zenith axis, the interpolation weights change slope and the sky brightness
    changes by a step the smooth reference does not show. This measures, per frame k >= 1, the
    relative jump of each render (:func:`relative_jumps` of the mean luminance, or with
    ``per_pixel`` :func:`frame_changes`) and the excess jump, table minus ray march; the worst
    frames are those with the largest excess.

    Parameters
    ----------
    table, raymarch : array_like, shape (N,) or (N, H, W, 3)
        Per-frame mean luminances [HDR units] or the HDR frames themselves, both alike.
    valid : array_like of bool, shape (H, W), optional
        Pixels that count (frames only).
    floor : float, optional
        Denominator floor [HDR units]; default :func:`display_floor` of ``exposure`` (frames darker
        than half an 8-bit code value do not count as jumping).
    exposure : float
        Exposure for the default floor [-].
    per_pixel : bool
        Use the mean per-pixel relative change (:func:`frame_changes`; needs frames) instead of the
        jump of the frame means.
    worst : int
        How many worst frames to return.

    Returns
    -------
    dict
        ``table_jumps``, ``raymarch_jumps``, ``excess`` (numpy arrays of shape (N,), index = frame,
        entry 0 is 0); ``worst_frames``: list of up to ``worst`` frame indices k >= 1 by decreasing
        excess (whatever its sign: check ``excess``); ``floor`` (float).

    Raises
    ------
    ValueError
        Inputs of different or unsupported shapes, fewer than 2 frames, ``per_pixel`` without
        frames, bad values.

    Examples
    --------
    >>> import numpy as np
    >>> reference = np.linspace(1.0, 0.5, 8)
    >>> table = reference.copy()
    >>> table[5] *= 0.8                         # a dip at frame 5
    >>> temporal_jumps(table, reference)["worst_frames"][0]
    5
    """
    worst = check_integer("worst", worst, 0, 10**9)           # -1 and 2.5 were taken, None a TypeError
    table = np.asarray(table, dtype=np.float64)
    raymarch = np.asarray(raymarch, dtype=np.float64)
    if table.shape != raymarch.shape:
        raise ValueError(f"table and raymarch differ in shape: {table.shape} and {raymarch.shape}")
    if table.ndim not in (1, 4):
        raise ValueError(f"table and raymarch must be per-frame means (N,) or frames (N, H, W, 3), "
                         f"got shape {table.shape}")
    if len(table) < 2:
        raise ValueError(f"need at least 2 frames, got {len(table)}")
    floor = display_floor(exposure) if floor is None else check_real("floor", floor, 0.0, low_open=True)
    if per_pixel:
        if table.ndim != 4:
            raise ValueError("per_pixel=True needs the frames (N, H, W, 3), not per-frame means")
        table_jumps = frame_changes(table, valid, floor)
        raymarch_jumps = frame_changes(raymarch, valid, floor)
    else:
        if table.ndim == 4:
            table, raymarch = mean_luminance(table, valid), mean_luminance(raymarch, valid)
        elif valid is not None:
            raise ValueError("valid applies to frames, not to per-frame means")
        table_jumps = relative_jumps(table, floor)
        raymarch_jumps = relative_jumps(raymarch, floor)
    excess = table_jumps - raymarch_jumps
    order = np.argsort(-excess[1:], kind="stable") + 1
    return {"table_jumps": table_jumps, "raymarch_jumps": raymarch_jumps, "excess": excess,
            "worst_frames": [int(k) for k in order[:max(int(worst), 0)]], "floor": floor}


# Images ---------------------------------------------------------------------------------------------

#: Viridis (van der Walt and Smith, matplotlib, CC0), every 8th entry of its 256-entry table plus
#: the last: piecewise-linear interpolation of these 33 points stays within 1.7 LSB (8 bit) of the
#: full table. Perceptually uniform, monotonic in lightness, readable by colour-blind viewers.
_VIRIDIS_POINTS = np.array([
    (0.267004, 0.004874, 0.329415), (0.277018, 0.050344, 0.375715), (0.282327, 0.094955, 0.417331),
    (0.282884, 0.135920, 0.453427), (0.278826, 0.175490, 0.483397), (0.270595, 0.214069, 0.507052),
    (0.258965, 0.251537, 0.524736), (0.244972, 0.287675, 0.537260), (0.229739, 0.322361, 0.545706),
    (0.214298, 0.355619, 0.551184), (0.199430, 0.387607, 0.554642), (0.185556, 0.418570, 0.556753),
    (0.172719, 0.448791, 0.557885), (0.160665, 0.478540, 0.558115), (0.149039, 0.508051, 0.557250),
    (0.137770, 0.537492, 0.554906), (0.127568, 0.566949, 0.550556), (0.120565, 0.596422, 0.543611),
    (0.120638, 0.625828, 0.533488), (0.132268, 0.655014, 0.519661), (0.157851, 0.683765, 0.501686),
    (0.196571, 0.711827, 0.479221), (0.246070, 0.738910, 0.452024), (0.304148, 0.764704, 0.419943),
    (0.369214, 0.788888, 0.382914), (0.440137, 0.811138, 0.340967), (0.515992, 0.831158, 0.294279),
    (0.595839, 0.848717, 0.243329), (0.678489, 0.863742, 0.189503), (0.762373, 0.876424, 0.137064),
    (0.845561, 0.887322, 0.099702), (0.926106, 0.897330, 0.104071), (0.993248, 0.906157, 0.143936),
])
_VIRIDIS_NODES = np.append(np.arange(0, 256, 8), 255) / 255.0

#: Colour of invalid pixels in error images (dark grey; viridis never gets this dark and grey).
INVALID_COLOUR = (64, 64, 64)
_LEGEND_BACKGROUND = (24, 24, 24)
_TEXT_COLOUR = (235, 235, 235)
_GUTTER_COLOUR = (16, 16, 16)
_GUTTER = 4


def colormap_viridis(values):
    """Viridis colours (uint8 RGB) of values in [0, 1] (clipped), shape ``values.shape + (3,)``."""
    values = np.clip(np.asarray(values, dtype=np.float64), 0.0, 1.0)
    channels = [np.interp(values, _VIRIDIS_NODES, _VIRIDIS_POINTS[:, c]) for c in range(3)]
    return np.floor(np.stack(channels, axis=-1) * 255.0 + 0.5).astype(np.uint8)


def _font():
    """PIL's built-in bitmap font: no FreeType needed, the same pixels everywhere."""
    from PIL import ImageFont      # the anim extra's Pillow: imported where drawn, so that clsky's CLI runs without it

    if hasattr(ImageFont, "load_default_imagefont"):        # Pillow >= 10.1 (load_default: FreeType)
        return ImageFont.load_default_imagefont()
    return ImageFont.load_default()


def _fitted_label(font, label, width, height):
    """``label`` as drawn on a panel of ``width`` x ``height`` pixels: whole where its box fits the panel,
    else cut to the letters that do and ending in '.', none where not two letters fit (a 16-pixel frame
    was all label; at 64 pixels 'sky-view map' ran into the next panel)."""
    if not label:
        return None
    text = str(label)

    def fits(candidate):
        left, top, right, bottom = font.getbbox(candidate)
        return 3 + right + 1 <= width and 2 + bottom <= height

    if fits(text):
        return text
    for end in range(len(text) - 1, 1, -1):
        if fits(text[:end].rstrip() + "."):
            return text[:end].rstrip() + "."
    return None


def _percent(value):
    return f"{100.0 * value:.3g}%"


def _draw_legend(height, vmax):
    """Legend panel (height, width, 3): title 'rel. error', vertical colour bar, 3 tick labels."""
    font = _font()
    labels = [_percent(0.0), _percent(vmax / 2.0), _percent(vmax)]
    text_width = max(font.getbbox(text)[2] for text in labels)
    text_height = max(font.getbbox(text)[3] for text in labels + ["rel. error"])
    title_width = font.getbbox("rel. error")[2]
    margin, bar_width, tick, gap = 5, 10, 3, 2
    width = 2 * margin + max(title_width, bar_width + tick + gap + text_width)
    panel = np.empty((height, width, 3), dtype=np.uint8)
    panel[...] = _LEGEND_BACKGROUND
    half = text_height // 2 + 1
    top = margin + text_height + 3 + half                  # bar rows [top, bottom], 0 at the bottom
    bottom = height - margin - half
    ticks = []
    if bottom - top >= 2:
        rows = np.arange(top, bottom + 1)
        colours = colormap_viridis((bottom - rows) / (bottom - top))
        panel[top:bottom + 1, margin:margin + bar_width] = colours[:, None, :]
        for fraction, text in zip((0.0, 0.5, 1.0), labels):
            row = int(round(bottom - fraction * (bottom - top)))
            panel[row, margin + bar_width:margin + bar_width + tick] = _TEXT_COLOUR
            ticks.append((row, text))
    from PIL import Image, ImageDraw

    image = Image.fromarray(panel)
    draw = ImageDraw.Draw(image)
    draw.text((margin, margin), "rel. error", fill=_TEXT_COLOUR, font=font)
    for row, text in ticks:
        draw.text((margin + bar_width + tick + gap, row - text_height // 2), text, fill=_TEXT_COLOUR,
                  font=font)
    return np.asarray(image)


def error_image(error_map, valid=None, vmax=0.1, legend=True):
    """Colour image of a relative error map, with a legend.

    Parameters
    ----------
    error_map : array_like, shape (H, W)
        Relative errors [-], >= 0 (e.g. :func:`relative_error_map`).
    valid : array_like of bool, shape (H, W), optional
        Pixels drawn in colour; the others are dark grey :data:`INVALID_COLOUR`.
    vmax : float
        Error shown with the top colour of the scale [-] (0.1 = 10 %); larger errors saturate.
    legend : bool
        Append a legend panel on the right (the image is not covered).

    Returns
    -------
    numpy.ndarray of uint8, shape (H, W + legend width, 3), or (H, W, 3) without legend

    Raises
    ------
    ValueError
        Bad shapes, ``vmax`` <= 0, NaN or negative errors on valid pixels.

    Notes
    -----
    Colour = viridis(min(e / vmax, 1)), a perceptually uniform map whose lightness grows with the
    error (:func:`colormap_viridis`). The legend is a vertical colour bar titled 'rel. error' with
    ticks at 0, vmax/2 and vmax as percentages (e.g. '0%', '5%', '10%'), in PIL's bitmap font. It
    needs a height of about 40 pixels to show the bar; below, only the title is drawn.

    Examples
    --------
    >>> import numpy as np
    >>> image = error_image(np.zeros((60, 80)))
    >>> image.dtype, image.shape[0], image.shape[1] > 80
    (dtype('uint8'), 60, True)
    """
    error_map = np.asarray(error_map, dtype=np.float64)
    if error_map.ndim != 2:
        raise ValueError(f"error_map must have shape (H, W), got {error_map.shape}")
    if valid is None:
        valid = np.ones(error_map.shape, dtype=bool)
    else:
        valid = np.asarray(valid)
        if valid.dtype != bool or valid.shape != error_map.shape:
            raise ValueError(f"valid must be a bool mask of shape {error_map.shape}, got {valid.dtype} "
                             f"{valid.shape}")
    vmax = float(vmax)
    if not (np.isfinite(vmax) and vmax > 0):
        raise ValueError(f"vmax must be finite and > 0, got {short(vmax)}")
    shown = error_map[valid]
    if np.isnan(shown).any() or (shown < 0).any():
        raise ValueError("error_map has NaN or negative values on valid pixels")
    image = np.empty(error_map.shape + (3,), dtype=np.uint8)
    image[...] = INVALID_COLOUR
    set_valid_pixels(image, valid, colormap_viridis(shown / vmax))
    if legend:
        image = np.concatenate([image, _draw_legend(error_map.shape[0], vmax)], axis=1)
    return image


def composite(panels, labels=None):
    """Side-by-side composite of same-height uint8 RGB panels, each labelled at its top-left.

    Parameters
    ----------
    panels : sequence of numpy.ndarray of uint8, shape (H, W_i, 3)
        E.g. table | ray march | error image.
    labels : sequence of str or None, optional
        One label per panel (None or '' for none), drawn in PIL's bitmap font on a dark box.

    Returns
    -------
    numpy.ndarray of uint8, shape (H, sum W_i + 4 (n - 1), 3)
        Panels separated by 4-pixel dark gutters.

    Examples
    --------
    >>> import numpy as np
    >>> a = np.zeros((20, 30, 3), np.uint8)
    >>> composite([a, a], ["table", "ray march"]).shape
    (20, 64, 3)
    """
    panels = list(panels)
    if not panels:
        raise ValueError("panels is empty")
    labels = [None] * len(panels) if labels is None else list(labels)
    if len(labels) != len(panels):
        raise ValueError(f"{len(panels)} panels but {len(labels)} labels")
    for index, panel in enumerate(panels):
        if not isinstance(panel, np.ndarray) or panel.dtype != np.uint8 or panel.ndim != 3 \
                or panel.shape[2] != 3:
            raise ValueError(f"panel {index} must be a uint8 array of shape (H, W, 3), got "
                             f"{getattr(panel, 'dtype', type(panel))} {getattr(panel, 'shape', '')}")
    heights = [panel.shape[0] for panel in panels]
    if len(set(heights)) != 1:
        raise ValueError(f"panels must have the same height, got heights {heights}")
    from PIL import Image, ImageDraw

    font = _font()
    pieces = []
    for index, (panel, label) in enumerate(zip(panels, labels)):
        if index:
            gutter = np.empty((heights[0], _GUTTER, 3), dtype=np.uint8)
            gutter[...] = _GUTTER_COLOUR
            pieces.append(gutter)
        label = _fitted_label(font, label, panel.shape[1], panel.shape[0])
        if label:
            image = Image.fromarray(np.ascontiguousarray(panel))
            draw = ImageDraw.Draw(image)
            left, top, right, bottom = draw.textbbox((3, 2), label, font=font)
            draw.rectangle((left - 2, top - 1, right + 1, bottom), fill=(0, 0, 0))
            draw.text((3, 2), label, fill=_TEXT_COLOUR, font=font)
            panel = np.asarray(image)
        pieces.append(panel)
    return np.concatenate(pieces, axis=1)
