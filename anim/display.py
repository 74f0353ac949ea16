"""Colour-true display: HDR frames to 8-bit sRGB through white balance, exposure and a hue-preserving curve.

The pipeline (issue 10, item 5), one frame at a time::

    frame (CIE XYZ or linear Rec. 709)  -> linear sRGB (IEC 61966-2-1, clsky.colorimetry.XYZ_TO_SRGB)
      -> white balance: D65 (none) or the sun's colour adapted to D65 (von Kries, CAT02)
      -> exposure: x 2^EV, EV fixed or metered from the frame and smoothed over time
      -> tone curve (:data:`TONE_CURVES`): display-linear sRGB in [0, 1]
      -> sRGB transfer function (IEC 61966-2-1 piecewise, ``colour.cctf_encoding``) -> 8 bits

``atmosphere-plus`` is the notes' curve ``(1 - exp(-x))^(1/2.2)`` (:func:`clsky.anim.tonemap.tone_map`,
which keeps it): with it, D65 and a fixed EV the pipeline *is* ``tone_map(frame, 2^EV)``, the same
code and the same bits as before this module (EV 0 is exposure 1). Its power law 2.2 replaces the sRGB
function, as in the notes.

Units. EV is relative to the frame's own units: EV 0 shows the frame's values as they are, EV +1 doubles
them. The animation's frames are linear sRGB in cd/m^2 for every preset but atmosphere-plus (a day sky
has a mean Y of about 3600: EV -13 shows it), and the notes' relative I_I units for atmosphere-plus
(a day sky has Y of about 0.5: EV 0). Auto-exposure meters the
log-average luminance (Reinhard et al. 2002) and aims it at ``key`` (0.36: a sky is a high-key scene), so it works in
any unit, absolute luminance [cd/m^2] included.

Hue. The per-channel curves (``atmosphere-plus``, ``reinhard``, ``aces-fit``) compress each of r, g, b
on its own: a bright blue, whose b saturates first, drifts toward grey-white and turns its hue. The
``luminance-*`` curves compress the luminance Y and scale r, g, b by Y_out / Y, which keeps the
chromaticity exactly; where that leaves the sRGB gamut (a channel above 1 or below 0) the chroma is
reduced in Oklab at constant lightness and hue (Ottosson 2020) until it fits, so the brightest
highlights (the sun) go to white without turning hue. README section "Display" measures them.

References
----------
IEC 61966-2-1:1999, sRGB. CIE 159:2004 (CIECAM02, CAT02 matrix). E. Reinhard, M. Stark, P. Shirley,
J. Ferwerda, "Photographic tone reproduction for digital images", SIGGRAPH 2002,
doi:10.1145/566654.566575. K. Narkowicz, "ACES filmic tone mapping curve" (2016, blog; the fit of the
ACES RRT + ODT). B. Ottosson, "A perceptual color space for image processing" (Oklab, 2020).

Examples
--------
>>> import numpy as np
>>> from clsky.anim.display import Display
>>> display = Display(tone_map="atmosphere-plus")
>>> frame = np.full((2, 2, 3), 0.5)
>>> from clsky.anim.tonemap import tone_map
>>> bool((display.encode(frame, 0.0) == tone_map(frame)).all())
True
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

from clsky import colorimetry, colour_constants
from clsky.errors import ParameterError

from . import tonemap
from .pixels import set_valid_pixels, valid_pixels
from clsky.errors import check_real

__all__ = ["TONE_CURVES", "DEFAULT_TONE_MAP", "WHITE_BALANCES", "SOURCES", "AutoExposure", "Display",
           "meter_ev", "smoothed_ev", "white_balance_matrix", "linear_srgb_to_oklab", "oklab_to_linear_srgb",
           "srgb_encode"]

#: Fraction of the frame's 99th-percentile luminance below which the meter counts a pixel as that
#: floor: black ground and the night side weigh as a dark grey, not as log(0).
METER_FLOOR_FRACTION = 1e-3

#: Bisection steps of the Oklab gamut mapping: the chroma factor to 2^-16, far below an 8-bit step.
GAMUT_STEPS = 16


# Colour-science constants (clsky.colour_constants: kept on disk, as ``import colour`` costs about 1 s) --

@functools.lru_cache(maxsize=None)
def _matrices():
    """(sRGB -> XYZ, XYZ -> sRGB, sRGB -> Oklab LMS, Oklab LMS' -> Lab, and inverses): clsky's sRGB
    matrix (:data:`clsky.colorimetry.SRGB_TO_XYZ` and its inverse) and colour-science's Oklab matrices."""
    xyz_to_lms, lms_to_lab = colour_constants.oklab_matrices()
    to_xyz, to_rgb = colorimetry.SRGB_TO_XYZ, colorimetry.XYZ_TO_SRGB
    to_lms = xyz_to_lms @ to_xyz
    to_lab = np.array(lms_to_lab)
    # the inverses to double precision (colour-science prints them to fewer digits: a round trip
    # through its printed inverses moves L by 1e-5 and the hue by 1e-3 deg)
    from_lab = np.linalg.inv(to_lab)
    from_lms = np.linalg.inv(to_lms)
    return {"rgb_to_xyz": to_xyz, "xyz_to_rgb": to_rgb, "rgb_to_lms": to_lms, "lms_to_lab": to_lab,
            "lab_to_lms": from_lab, "lms_to_rgb": from_lms}


def _luminance(rgb):
    """Y of linear sRGB (the Y row of :data:`clsky.colorimetry.SRGB_TO_XYZ`: 0.2126, 0.7152, 0.0722 to 4 digits)."""
    return rgb @ _matrices()["rgb_to_xyz"][1]


def _luminance_of(values, source):
    """Y of three values of ``source`` ('xyz': the Y itself)."""
    return float(values[1]) if source == "xyz" else float(_luminance(values))


def linear_srgb_to_oklab(rgb):
    """Oklab L, a, b of linear sRGB (Ottosson 2020, colour-science's matrices). L = 1 for white."""
    m = _matrices()
    return np.cbrt(np.asarray(rgb, dtype=np.float64) @ m["rgb_to_lms"].T) @ m["lms_to_lab"].T


def oklab_to_linear_srgb(lab):
    """Inverse of :func:`linear_srgb_to_oklab`."""
    m = _matrices()
    lms = np.asarray(lab, dtype=np.float64) @ m["lab_to_lms"].T
    return (lms * lms * lms) @ m["lms_to_rgb"].T


def srgb_encode(linear):
    """IEC 61966-2-1 transfer function (piecewise: 12.92 x below 0.0031308, else 1.055 x^(1/2.4) -
    0.055); input clipped to [0, 1].

    The expression of colour-science's ``eotf_inverse_sRGB`` (``colour.cctf_encoding(..., function='sRGB')``),
    which tests/test_display.py holds it to bit for bit, without that function's domain-range scaling
    and signed power (whose signs are 1 on clipped values): 9 against 20 ms a 512 x 512 frame, twice a
    frame in the default animation. The same operations on each value, in place (two full-frame arrays
    fewer than ``np.where`` of both branches: 6.8 against 10.7 ms a frame)."""
    x = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    encoded = np.power(x, 1 / 2.4, out=np.empty_like(x))        # an array for a scalar too (out= below)
    encoded *= 1.055
    encoded -= 0.055
    np.multiply(x, 12.92, out=encoded, where=x <= 0.0031308)
    return encoded


# Tone curves: exposed linear sRGB (>= 0 after gamut mapping) -> display-linear sRGB in [0, 1] -------

#: Largest exposed value a curve sees [-]: every curve is 1 there to double precision, and no product
#: of the curves' arithmetic overflows (an overflowed exposure, frame x 2^40, would give inf / inf).
EXPOSED_MAX = 1e100


def _per_channel(function):
    def curve(rgb):
        return np.clip(function(np.clip(rgb, 0.0, EXPOSED_MAX)), 0.0, 1.0)
    return curve


def _reinhard(x):
    """x / (1 + x) (Reinhard et al. 2002, eq. 3)."""
    return x / (1.0 + x)


def _aces_narkowicz(x):
    """Narkowicz's fit of ACES RRT + ODT: x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14)."""
    return x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14)


def _exponential(x):
    """The notes' curve before its gamma: 1 - exp(-x)."""
    return -np.expm1(-x)


def _into_gamut(rgb, copy=True):
    """``rgb`` with the chroma of out-of-gamut pixels reduced in Oklab at constant L and hue until all
    channels lie in [0, 1] (bisection on the chroma factor t in [0, 1]; t = 0 is the grey of the same
    lightness, in gamut for L <= 1). ``copy=False``: a float64 ``rgb`` is changed in place and returned
    (the tone curve's own array)."""
    rgb = np.array(rgb, dtype=np.float64) if copy else np.asarray(rgb, dtype=np.float64)
    out_of_range = (rgb < 0.0) | (rgb > 1.0)
    # a pixel with any channel out of range: the three columns or-ed, the same mask as .any(axis=-1),
    # which NumPy reduces row by row (rows of 3) and took 5x longer (about 5 ms a 512 x 512 frame)
    outside = out_of_range[..., 0] | out_of_range[..., 1] | out_of_range[..., 2]
    if not outside.any():
        return rgb
    lightness, a, b = linear_srgb_to_oklab(valid_pixels(rgb, outside)).T
    lightness = np.minimum(lightness, 1.0)
    shown = np.empty((a.size, 3))
    for start in range(0, a.size, GAMUT_BLOCK):
        block = slice(start, start + GAMUT_BLOCK)
        shown[block] = _chroma_bisection(lightness[block], a[block], b[block]).T
    set_valid_pixels(rgb, outside, shown)
    return np.clip(rgb, 0.0, 1.0, out=rgb)


#: Pixels per block of the gamut mapping's bisection (:func:`_chroma_bisection`): its dozen work arrays
#: (128 kB each) then stay in the cache through the block's 16 steps, where over a whole frame's pixels
#: they went through memory at every operation: a quarter less time on the default animation's frames
#: (29-36 against 40-46 ms a frame, four alternating runs; blocks of 4096 and 65536 gained less).
GAMUT_BLOCK = 16384


def _chroma_bisection(lightness, a, b):
    """Linear sRGB (3, n: red, green, blue) of Oklab (L, t a, t b) at the largest chroma factor t of the
    bisection (:data:`GAMUT_STEPS` halvings of [0, 1], t = 0 kept if no other) whose channels all lie in
    [0, 1]; ``lightness``, ``a``, ``b`` 1-D arrays of the pixels.

    Every value is the bisection's as written with whole-array expressions, bit for bit: a channel is
    ((m0 L + m1 (t a)) + m2 (t b)) cubed as (c c) c, then mixed the same way (m0 L is the same product at
    every step, computed once); the midpoint 0.5 (low + high) is low + 2^-(k+1) exactly (both are
    multiples of 2^-16 in [0, 1]); min(r, g, b) >= 0 and max(r, g, b) <= 1 is the six comparisons' test
    (NaN fails both). The arrays are allocated once per block and reused (``out=``)."""
    m = _matrices()
    to_lms, to_rgb = m["lab_to_lms"], m["lms_to_rgb"]
    lightness_terms = [to_lms[i, 0] * lightness for i in range(3)]
    ta, tb, term, smallest, largest = np.empty((5, a.size))
    lms, channels = np.empty((3, a.size)), np.empty((3, a.size))
    inside, below_one = np.empty((2, a.size), dtype=bool)

    def shown(t):
        np.multiply(t, a, out=ta)
        np.multiply(t, b, out=tb)
        for i, c in enumerate(lms):
            np.multiply(to_lms[i, 1], ta, out=c)
            np.add(lightness_terms[i], c, out=c)
            c += np.multiply(to_lms[i, 2], tb, out=term)
            np.multiply(np.multiply(c, c, out=term), c, out=c)
        for i, channel in enumerate(channels):
            np.multiply(to_rgb[i, 0], lms[0], out=channel)
            channel += np.multiply(to_rgb[i, 1], lms[1], out=term)
            channel += np.multiply(to_rgb[i, 2], lms[2], out=term)
        return channels

    low, middle = np.zeros(a.size), np.empty(a.size)
    half_width = 0.5
    for _ in range(GAMUT_STEPS):
        red, green, blue = shown(np.add(low, half_width, out=middle))
        np.minimum(np.minimum(red, green, out=smallest), blue, out=smallest)
        np.maximum(np.maximum(red, green, out=largest), blue, out=largest)
        np.logical_and(np.greater_equal(smallest, 0.0, out=inside), np.less_equal(largest, 1.0, out=below_one),
                       out=inside)
        np.copyto(low, middle, where=inside)
        half_width *= 0.5
    return shown(low)


def _luminance_curve(function):
    """A hue-preserving curve: Y_out = function(Y), r, g, b scaled by Y_out / Y, then into the gamut."""
    def curve(rgb):
        rgb = np.minimum(rgb, EXPOSED_MAX)
        y = _luminance(rgb)
        positive = y > 0.0
        # where(positive, function(y') / y', 0) with y' = where(positive, y, 1), in place
        safe = np.where(positive, y, 1.0)
        scale = np.asarray(function(safe), dtype=np.float64)
        scale /= safe
        np.copyto(scale, 0.0, where=~positive)
        rgb *= scale[..., None]
        return _into_gamut(rgb, copy=False)
    return curve


@dataclasses.dataclass(frozen=True)
class ToneCurve:
    """A tone curve: ``function`` maps exposed linear sRGB (..., 3) to display-linear sRGB in [0, 1];
    ``hue_preserving`` tells whether it keeps the chromaticity (up to the gamut mapping)."""

    function: object
    hue_preserving: bool
    description: str


#: Tone curves by name (``--tone-map``). ``atmosphere-plus`` has no entry's function: the pipeline calls
#: :func:`clsky.anim.tonemap.tone_map` for it (its own gamma 2.2 instead of the sRGB function).
TONE_CURVES = {
    "atmosphere-plus": ToneCurve(None, False, "the notes' (1 - exp(-x))^(1/2.2) per channel"),
    "reinhard": ToneCurve(_per_channel(_reinhard), False, "x / (1 + x) per channel"),
    "aces-fit": ToneCurve(_per_channel(_aces_narkowicz), False, "Narkowicz's ACES fit per channel"),
    "luminance-exponential": ToneCurve(_luminance_curve(_exponential), True,
                                       "1 - exp(-Y) on luminance, chroma kept, Oklab gamut mapping"),
    "luminance-reinhard": ToneCurve(_luminance_curve(_reinhard), True,
                                    "Y / (1 + Y) on luminance, chroma kept, Oklab gamut mapping"),
}

#: The new pipeline's curve (chosen by the saturation it keeps: README "Display").
DEFAULT_TONE_MAP = "luminance-reinhard"

#: White balances: 'd65' (none: sRGB's own white) or 'sun' (the sun's colour adapted to D65).
WHITE_BALANCES = ("d65", "sun")

#: What a frame's three channels are.
SOURCES = ("rec709", "xyz")


def white_balance_matrix(source_white_xyz, transform="CAT02"):
    """Linear-sRGB matrix that adapts ``source_white_xyz`` to D65 of the same luminance (von Kries).

    Parameters
    ----------
    source_white_xyz : array_like, shape (3,)
        CIE XYZ of the light to show as white (e.g. the sun's) [any unit, Y > 0].
    transform : str
        Cone space of the von Kries scaling (colour-science: 'CAT02', 'Bradford', 'Von Kries', ...).

    Returns
    -------
    numpy.ndarray, shape (3, 3)
        M with rgb_out = M @ rgb_in: M maps the source white to sRGB white times Y_source.

    Notes
    -----
    M = XYZ->sRGB . M_cat . sRGB->XYZ, M_cat = C^-1 diag(C w_D65 / C w_source) C with C the transform's
    cone response matrix (:func:`clsky.colour_constants.adaptation_transform`): the operations of
    ``colour.adaptation.matrix_chromatic_adaptation_VonKries`` (colour-science 0.4.7, in its default
    division mode: a cone response of 0 gives a factor of 0), the same bits (tests/test_colour_constants.py),
    without importing colour-science. CIE 159:2004 for CAT02.
    """
    source = np.asarray(source_white_xyz, dtype=np.float64)
    if source.shape != (3,) or not np.isfinite(source).all() or not source[1] > 0 or (source < 0).any():
        raise ParameterError("source_white_xyz", "three finite XYZ values >= 0 with Y > 0", source.tolist())
    cones = colour_constants.adaptation_transform(transform)
    m = _matrices()
    white = m["rgb_to_xyz"].sum(axis=1)           # sRGB white (1, 1, 1): D65 as the matrix has it
    target = white * source[1] / white[1]
    with np.errstate(divide="ignore", invalid="ignore"):
        gains = np.nan_to_num(np.matmul(cones, target[:, None])[:, 0] / np.matmul(cones, source[:, None])[:, 0],
                              nan=0, posinf=0, neginf=0)
    cat = np.matmul(np.matmul(np.linalg.inv(cones), np.eye(3) * gains[None, :]), cones)
    return m["xyz_to_rgb"] @ cat @ m["rgb_to_xyz"]


# Exposure --------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class AutoExposure:
    """Auto-exposure: meter each frame, smooth in EV over time.

    Parameters
    ----------
    key : float
        Scene luminance, after exposure, that the log-average of the frame is mapped to [-], in (0, 1].
        Reinhard et al. 2002 use 0.18 for average scenes and up to 0.72 for high-key ones; 0.36 (one
        stop above mid-grey) shows a day sky about as bright as the notes' display showed its relative
        values at EV 0 (the relative day sky meters at EV -0.2) and lifts twilight.
    smoothing : float
        Fraction of the difference between the metered and the current EV corrected per frame, in
        (0, 1] (1: no smoothing).
    max_step_ev : float
        Most the EV changes from one frame to the next [EV], in (0, 40] (default 2).
    min_ev, max_ev : float
        Range of the metered EV [EV], each in [-60, 60], ``max_ev`` at least ``min_ev`` (default -20 and
        20; a black frame meters at ``max_ev``).
    """

    key: float = 0.36
    smoothing: float = 0.5
    max_step_ev: float = 2.0
    min_ev: float = -20.0
    max_ev: float = 20.0

    def __post_init__(self):
        check_real("key", self.key, 0.0, 1.0, low_open=True)
        check_real("smoothing", self.smoothing, 0.0, 1.0, low_open=True)
        check_real("max_step_ev", self.max_step_ev, 0.0, 40.0, low_open=True)
        check_real("min_ev", self.min_ev, -60.0, 60.0)
        check_real("max_ev", self.max_ev, self.min_ev, 60.0)


def meter_ev(luminance, key=0.36, min_ev=-20.0, max_ev=20.0):
    """EV that maps the log-average of ``luminance`` to ``key``: log2(key / exp(mean log max(Y, floor))).

    Parameters
    ----------
    luminance : array_like
        Y of the pixels that count [frame units, >= 0].
    key : float
        Target display-linear luminance [-], in (0, 1].
    min_ev, max_ev : float
        Clamp of the result [EV], each in [-60, 60], ``max_ev`` at least ``min_ev``.

    Returns
    -------
    float
        The metered EV [EV], in [min_ev, max_ev].

    Notes
    -----
    The log-average (geometric mean; Reinhard et al. 2002, eq. 1) follows the bulk of the sky, not
    the sun disc. floor = 1e-3 P99(Y) (:data:`METER_FLOOR_FRACTION`) keeps black ground from pulling
    it to 0.
    """
    check_real("key", key, 0.0, 1.0, low_open=True)          # NaN gave NaN, 0 a math domain error
    check_real("min_ev", min_ev, -60.0, 60.0)
    check_real("max_ev", max_ev, min_ev, 60.0)
    y = np.asarray(luminance, dtype=np.float64).ravel()
    if y.size == 0:
        raise ValueError("luminance is empty: no pixel to meter")
    if not np.isfinite(y).all() or (y < 0).any():
        raise ValueError("luminance contains NaN, infinite or negative values")
    scale = float(np.percentile(y, 99))
    if scale <= 0.0:
        return float(max_ev)
    average = math.exp(float(np.mean(np.log(np.maximum(y, METER_FLOOR_FRACTION * scale)))))
    return float(np.clip(math.log2(key / average), min_ev, max_ev))


def smoothed_ev(previous, metered, smoothing=0.5, max_step_ev=2.0):
    """The next frame's EV: previous + clip(smoothing (metered - previous), +-max_step_ev); the first
    frame (``previous`` None) takes the metered EV.

    Raises
    ------
    ValueError
        An EV that is no finite number, ``smoothing`` outside (0, 1] or ``max_step_ev`` outside (0, 40]
        (:class:`AutoExposure`'s ranges: a NaN passed on, a negative step moved the wrong way).
    """
    check_real("metered", metered)
    check_real("previous", previous, optional=True)
    check_real("smoothing", smoothing, 0.0, 1.0, low_open=True)
    check_real("max_step_ev", max_step_ev, 0.0, 40.0, low_open=True)
    if previous is None:
        return float(metered)
    step = float(np.clip(smoothing * (metered - previous), -max_step_ev, max_step_ev))
    return float(previous) + step


# The pipeline ----------------------------------------------------------------------------------------

class Display:
    """HDR frames to display values: see the module docstring.

    Parameters
    ----------
    tone_map : str
        A name of :data:`TONE_CURVES` (default :data:`DEFAULT_TONE_MAP`).
    exposure_ev : float
        Fixed exposure [EV], in [-40, 40]; with ``auto_exposure``, a compensation added to the metered EV.
    auto_exposure : AutoExposure or None
        Meter each frame (:meth:`exposure`) instead of the fixed EV.
    white_balance : {'d65', 'sun'}
    sun_white : array_like, shape (3,), optional
        The sun's colour in the frame's ``source`` space (needed for ``white_balance='sun'``).
    source : {'rec709', 'xyz'}
        What the frames' channels are: linear Rec. 709 / sRGB, or CIE XYZ.

    Raises
    ------
    ValueError
        (:class:`clsky.errors.ParameterError`) naming the parameter.

    Notes
    -----
    :meth:`exposure` is stateful (the smoothing remembers the last EV): one Display per sequence,
    frames in order; :meth:`reset` starts a new sequence.
    """

    def __init__(self, tone_map=DEFAULT_TONE_MAP, exposure_ev=0.0, auto_exposure=None, white_balance="d65",
                 sun_white=None, source="rec709"):
        if not isinstance(tone_map, str) or tone_map not in TONE_CURVES:
            raise ParameterError("tone_map", f"one of {list(TONE_CURVES)}", tone_map)
        if not isinstance(white_balance, str) or white_balance not in WHITE_BALANCES:
            raise ParameterError("white_balance", f"one of {list(WHITE_BALANCES)}", white_balance)
        if not isinstance(source, str) or source not in SOURCES:
            raise ParameterError("source", f"one of {list(SOURCES)}", source)
        if auto_exposure is not None and not isinstance(auto_exposure, AutoExposure):
            raise ParameterError("auto_exposure", "None or an AutoExposure", auto_exposure)
        self.tone_map, self.white_balance, self.source = tone_map, white_balance, source
        self.exposure_ev = check_real("exposure_ev", exposure_ev, -40.0, 40.0)
        self.auto_exposure = auto_exposure
        self._to_srgb = None                      # None: the identity (no arithmetic at all)
        if source == "xyz":
            self._to_srgb = _matrices()["xyz_to_rgb"]
        if white_balance == "sun":
            if sun_white is None:
                raise ParameterError("sun_white", "the sun's colour (3 values) for white_balance='sun'", None)
            sun = np.asarray(sun_white, dtype=np.float64) if np.ndim(sun_white) == 1 else np.zeros(0)
            if sun.shape != (3,) or not np.isfinite(sun).all() or (sun < 0).any() or not _luminance_of(sun, source) > 0:
                raise ParameterError("sun_white", "three finite values >= 0 of positive luminance", sun_white)
            balance = white_balance_matrix(sun if source == "xyz" else _matrices()["rgb_to_xyz"] @ sun)
            self._to_srgb = balance if self._to_srgb is None else balance @ self._to_srgb
        self._last_ev = None

    def describe(self) -> dict:
        """The settings, JSON-serialisable (for the metrics record)."""
        auto = None if self.auto_exposure is None else dataclasses.asdict(self.auto_exposure)
        return {"tone_map": self.tone_map, "exposure_ev": self.exposure_ev, "auto_exposure": auto,
                "white_balance": self.white_balance, "source": self.source}

    def reset(self):
        """Forget the smoothing state: the next :meth:`exposure` starts a new sequence."""
        self._last_ev = None

    def _check(self, frame):
        frame = np.asarray(frame, dtype=np.float64)
        if frame.ndim == 0 or frame.shape[-1] != 3:
            raise ValueError(f"frame must have shape (..., 3), got shape {frame.shape}")
        return frame

    def linear_srgb(self, frame):
        """The frame in white-balanced linear sRGB, before exposure [frame units]."""
        frame = self._check(frame)
        return frame if self._to_srgb is None else frame @ self._to_srgb.T

    def exposure(self, frame, valid=None):
        """The EV of the next frame of the sequence: the fixed EV, or (auto-exposure) the metered EV
        of ``frame`` over the ``valid`` pixels plus the compensation, smoothed (:func:`smoothed_ev`):
        :meth:`next_ev` of :meth:`metered_ev`."""
        if self.auto_exposure is None:
            return self.exposure_ev
        return self.next_ev(self.metered_ev(frame, valid))

    def metered_ev(self, frame, valid=None):
        """Auto-exposure's metered EV of ``frame`` over the ``valid`` pixels plus the compensation [EV],
        before smoothing; stateless, so that frames may be metered anywhere (a frame farm's workers,
        :mod:`clsky.anim.farm`) and smoothed in order by :meth:`next_ev`. None without auto-exposure."""
        if self.auto_exposure is None:
            return None
        rgb = self.linear_srgb(frame)
        if valid is not None and np.shape(valid) != rgb.shape[:2]:      # NumPy's IndexError otherwise
            raise ValueError(f"valid must be a mask of the frame's shape {rgb.shape[:2]}, got shape "
                             f"{np.shape(valid)}")
        pixels = valid_pixels(rgb, valid) if valid is not None else rgb.reshape(-1, 3)
        a = self.auto_exposure
        return meter_ev(np.maximum(_luminance(pixels), 0.0), a.key, a.min_ev, a.max_ev) + self.exposure_ev

    def next_ev(self, metered):
        """The EV of the next frame of the sequence from its :meth:`metered_ev`: the fixed EV, or the
        metered EV smoothed against the last frame's (:func:`smoothed_ev`; the state this keeps)."""
        if self.auto_exposure is None:
            return self.exposure_ev
        a = self.auto_exposure
        self._last_ev = smoothed_ev(self._last_ev, metered, a.smoothing, a.max_step_ev)
        return self._last_ev

    def encode(self, frame, ev):
        """Encoded display values in [0, 1] of ``frame`` at exposure ``ev`` [EV].

        For ``atmosphere-plus`` with D65 this is ``tonemap.tone_map(frame, 2**ev)`` itself."""
        ev = check_real("ev", ev, -100.0, 100.0)
        if self.tone_map == "atmosphere-plus":
            if self._to_srgb is None:             # the notes' pipeline exactly
                return tonemap.tone_map(self._check(frame), 2.0 ** ev)
            # a converted frame (XYZ, white balance) may leave the gamut: its negative channels show as 0
            return tonemap.tone_map(np.maximum(self.linear_srgb(frame), 0.0), 2.0 ** ev)
        return srgb_encode(self.linear(frame, ev))

    def linear(self, frame, ev):
        """Display-linear sRGB in [0, 1]: what the screen emits, relative to its white (for Delta E)."""
        if self.tone_map == "atmosphere-plus":
            return np.clip(self.encode(frame, ev), 0.0, 1.0) ** tonemap.GAMMA
        ev = check_real("ev", ev, -100.0, 100.0)
        rgb = self.linear_srgb(frame)
        if not np.isfinite(rgb).all():
            raise ValueError(f"frame contains {int((~np.isfinite(rgb)).sum())} NaN or infinite values")
        if (_luminance(rgb) < 0).any():
            raise ValueError("frame contains pixels of negative luminance; radiance must be >= 0")
        with np.errstate(over="ignore"):          # beyond EXPOSED_MAX the curves are 1 anyway
            exposed = rgb * 2.0 ** ev
        return TONE_CURVES[self.tone_map].function(exposed)

    def encode_and_linear(self, frame, ev):
        """(:meth:`encode`, :meth:`linear`) of ``frame`` at ``ev`` from one evaluation of the tone curve
        (and gamut mapping): the same values as the two calls, at half the cost."""
        if self.tone_map == "atmosphere-plus":
            encoded = self.encode(frame, ev)
            return encoded, np.clip(encoded, 0.0, 1.0) ** tonemap.GAMMA
        linear = self.linear(frame, ev)
        return srgb_encode(linear), linear

    def to_uint8(self, frame, ev, dither=False, seed=0):
        """8-bit display values (:func:`clsky.anim.tonemap.to_uint8` of :meth:`encode`)."""
        return tonemap.to_uint8(self.encode(frame, ev), dither=dither, seed=seed)
