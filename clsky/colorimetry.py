"""Colorimetry: spectral radiance -> CIE 1931 XYZ -> linear sRGB, and the three-wavelength conversion.

Spectral radiance L(lambda) [W m^-2 sr^-1 nm^-1] sampled at wavelengths lambda_i becomes CIE 1931 XYZ by

    (X, Y, Z) = K_m sum_i L(lambda_i) (xbar, ybar, zbar)(lambda_i) dlambda_i,   K_m = 683 lm/W,

with the 2-degree colour-matching functions of colour-science (``colour.MSDS_CMFS['CIE 1931 2 Degree
Standard Observer']``, 1 nm from 360 to 830 nm, linearly interpolated, zero outside) and dlambda_i the
width of each sample's cell (half-way to its neighbours; the end cells as wide as their neighbour's
half-spacing on both sides, so a uniform grid gets its spacing everywhere: the midpoint rule). Y is
then the luminance [cd/m^2]. Linear sRGB (Rec. 709 primaries, D65 white; IEC 61966-2-1) is
M_sRGB (X, Y, Z) (:data:`XYZ_TO_SRGB`), in the same photometric units (cd/m^2 scale).

One sRGB matrix. :data:`SRGB_TO_XYZ` is derived at full precision from the primaries' and D65's
chromaticities (:func:`rgb_to_xyz_matrix`), and :data:`XYZ_TO_SRGB` is its inverse; the display
(anim/display.py) and the metrics' Delta E (anim/metrics.py) use these two. The 4-digit matrices
printed in IEC 61966-2-1 (colour-science's ``RGB_COLOURSPACE_sRGB`` carries them) differ from them by
up to 5e-5 and are not exact inverses of each other. The chromaticity-derived one is kept because the
atmosphere-plus preset's pinned metrics (tests/test_display.py: its Delta E, bit for bit) were written
with it. The one other set of sRGB numbers is :data:`clsky.anim.tonemap.REC709_LUMINANCE_WEIGHTS`, BT.709's
printed Y row (0.2126, 0.7152, 0.0722), 4e-5 from this matrix's: the relative luminance errors of the
same pinned metrics were written with it, so it stays.

Three wavelengths carry too little to integrate; :func:`three_wavelength_to_xyz` reconstructs the
spectrum between them from three radiances (L_1, L_2, L_3) in one of four documented ways (the last two
are 3 x 3 matrices, :func:`three_wavelength_to_xyz_matrix`):

``solar_power_law`` (default)
    The spectrum follows the sun's times a power law: L(lambda) = E_sun(lambda) r(lambda), with log r
    linear in log lambda between the samples (r = r_c (lambda / lambda_c)^p, p from the two neighbouring
    samples) and beyond them with the end segment's exponent (clipped to +-8), integrated against the
    CMFs at 1 nm. Exact for any E_sun lambda^p: the sun (p = 0), Rayleigh light (p = -4) and
    everything between. Not linear in L (a 0 channel is floored at 1e-12 of the pixel's largest).
``solar_power_law_tabulated``
    The same reconstruction at about the cost of a matrix (what the animation's frames use): the
    spectrum splits at the middle sample into two sums, each the anchor's ratio r_k times a function
    of one number, q_k = log r_(k+1) - log r_k: B_k(q) = sum W e^(q a / Delta_k) between the samples
    (a = log lambda - log lambda_k, Delta_k = log lambda_(k+1) - log lambda_k, W = K_m cmf E_sun at
    1 nm) and O_k(p) = sum W e^(p a) beyond them (p = q / Delta_k clipped to +-8). B_k is tabulated
    at steps of 1/512 in q over |q| <= log 1e12 (the floor bounds q), O_k at steps of 1/256 in p; all
    terms are positive, so linear interpolation is off by at most h_q^2 / 8 (B_k: a / Delta_k in
    [0, 1]) and h_p^2 max a^2 / 8 (O_k) relative: 5e-7 at 650 / 510 / 475 nm (tested against
    ``solar_power_law``).
``solar_interpolation``
    The same with r interpolated linearly between the three samples and held constant beyond them: a
    3 x 3 matrix. Exact for E_sun times a function linear between the samples and flat beyond.
``bruneton2017``
    Bruneton's luminance factors (``ComputeSpectralRadianceToLuminanceFactors``, atmosphere/model.cc):
    the spectrum of each channel is assumed to be E_sun(lambda) (lambda / lambda_c)^p / E_sun(lambda_c) times
    its radiance (p = -3 for the sky), and each channel becomes one sRGB channel (the longest wavelength
    red, the shortest blue): sRGB_c = K_m sum_lambda cbar_sRGB(lambda) E_sun(lambda) / E_sun(lambda_c)
    (lambda / lambda_c)^p L_c, a diagonal matrix in sRGB.

colour-science's CMFs come through :mod:`clsky.colour_constants`, which keeps them on disk after the
first run (``import colour`` costs 0.9-1.0 s of one core a process on the 2-core machine).

References
----------
CIE 015:2018 Colorimetry, 4th ed., doi:10.25039/TR.015.2018 (the CMFs, K_m = 683 lm/W).
IEC 61966-2-1:1999 (sRGB). Bruneton, E. (2017). A qualitative and quantitative evaluation of 8 clear
sky models. IEEE TVCG 23(12), doi:10.1109/TVCG.2016.2622272, section 14.3; code:
github.com/ebruneton/precomputed_atmospheric_scattering (atmosphere/model.cc).
"""

from __future__ import annotations

import functools

import numpy as np

from . import colour_constants
from .errors import as_real_array
from .solar import solar_irradiance_astm_g173

__all__ = ["MAX_LUMINOUS_EFFICACY", "SRGB_PRIMARIES_XY", "D65_WHITE_XY", "SRGB_TO_XYZ", "XYZ_TO_SRGB",
           "D65_WHITE_XYZ", "rgb_to_xyz_matrix", "CMFS_NAME", "THREE_WAVELENGTH_METHODS", "LINEAR_METHODS",
           "DEFAULT_THREE_WAVELENGTH_METHOD", "colour_matching_functions",
           "band_widths", "spectral_to_xyz", "spectral_frame_to_xyz", "MAX_RADIANCE", "xyz_to_linear_srgb",
           "linear_srgb_to_xyz", "luminance",
           "three_wavelength_to_xyz_matrix", "three_wavelength_to_xyz", "three_wavelength_frame_to_xyz"]

#: K_m, the maximum luminous efficacy of photopic vision [lm/W].
MAX_LUMINOUS_EFFICACY = 683.0
#: The colour-matching functions used (colour-science's name).
CMFS_NAME = colour_constants.CMFS_NAME
#: Exponent p of Bruneton's sky factors (lambda / lambda_c)^p (model.cc: -3 for the sky, 0 for the sun).
BRUNETON_SKY_POWER = -3.0
#: The three-wavelength reconstruction used unless another is asked for (chosen by bench/bench_spectral.py).
DEFAULT_THREE_WAVELENGTH_METHOD = "solar_power_law"


def _cmfs():
    """(wavelengths [nm], values (n, 3)) of the CIE 1931 2-degree CMFs from colour-science, read-only
    (:func:`clsky.colour_constants.cie_1931_cmfs`: kept on disk after the first run)."""
    return colour_constants.cie_1931_cmfs()


#: Chromaticities (x, y) of the sRGB / Rec. 709 primaries r, g, b and of its D65 white (IEC 61966-2-1).
SRGB_PRIMARIES_XY, D65_WHITE_XY = ((0.64, 0.33), (0.30, 0.60), (0.15, 0.06)), (0.3127, 0.3290)


def rgb_to_xyz_matrix(primaries_xy, white_xy):
    """RGB -> XYZ matrix of an RGB space from its primaries' and white's chromaticities (Y_white = 1):
    the columns are the primaries' XYZ (x/y, 1, (1 - x - y)/y), each scaled so that they sum to the white's.

    Examples
    --------
    >>> rgb_to_xyz_matrix(SRGB_PRIMARIES_XY, D65_WHITE_XY)[1].round(4).tolist()     # the luminance row
    [0.2126, 0.7152, 0.0722]
    """
    columns = np.array([[x / y, 1.0, (1.0 - x - y) / y] for x, y in primaries_xy]).T
    x, y = white_xy
    white = np.array([x / y, 1.0, (1.0 - x - y) / y])
    return columns * np.linalg.solve(columns, white)


#: Linear sRGB -> CIE XYZ, derived at full precision from :data:`SRGB_PRIMARIES_XY` and
#: :data:`D65_WHITE_XY`: clsky's one sRGB matrix (module docstring, "One sRGB matrix"). Read-only.
SRGB_TO_XYZ = rgb_to_xyz_matrix(SRGB_PRIMARIES_XY, D65_WHITE_XY)
#: CIE XYZ -> linear sRGB: the inverse of :data:`SRGB_TO_XYZ` (the two conversions are exact inverses).
XYZ_TO_SRGB = np.linalg.inv(SRGB_TO_XYZ)
#: XYZ of sRGB white (1, 1, 1), Y = 1: D65 as the matrix has it, (0.95046, 1, 1.08906).
D65_WHITE_XYZ = SRGB_TO_XYZ.sum(axis=1)
for _matrix in (SRGB_TO_XYZ, XYZ_TO_SRGB, D65_WHITE_XYZ):
    _matrix.setflags(write=False)


def _wavelengths(wavelengths):
    try:
        values = np.asarray(wavelengths, dtype=np.float64)
    except (TypeError, ValueError):
        values = np.empty(0)
    if values.ndim != 1 or values.size < 1 or not np.all(np.isfinite(values) & (values > 0)):
        raise ValueError(f"wavelengths must be a 1D array of finite numbers > 0 nm, got {wavelengths!r:.80}")
    if values.size > 1 and not np.all(np.diff(values) > 0):
        raise ValueError(f"wavelengths must increase strictly, got {wavelengths!r:.80}")
    return values


def colour_matching_functions(wavelengths):
    """(xbar, ybar, zbar) at ``wavelengths`` [nm]: shape (N, 3), linear interpolation of the 1 nm table,
    zero outside 360 to 830 nm.

    Examples
    --------
    >>> colour_matching_functions([555.0]).round(4).tolist()
    [[0.5121, 1.0, 0.0057]]
    """
    table_wavelengths, values = _cmfs()
    wavelengths = _wavelengths(wavelengths)
    return np.stack([np.interp(wavelengths, table_wavelengths, values[:, k], left=0.0, right=0.0)
                     for k in range(3)], axis=-1)


def band_widths(wavelengths):
    """dlambda_i [nm] of each sample's cell: half-way to each neighbour, the ends mirrored (module
    docstring); a single wavelength gets 1 nm.

    Examples
    --------
    >>> band_widths([400.0, 410.0, 430.0]).tolist()
    [10.0, 15.0, 20.0]
    """
    w = _wavelengths(wavelengths)
    if w.size == 1:
        return np.ones(1)
    edges = np.concatenate([[w[0] - 0.5 * (w[1] - w[0])], 0.5 * (w[1:] + w[:-1]), [w[-1] + 0.5 * (w[-1] - w[-2])]])
    return np.diff(edges)


def spectral_to_xyz(radiance, wavelengths):
    """CIE 1931 XYZ of spectral radiance.

    Parameters
    ----------
    radiance : array_like, shape (..., N)
        Spectral radiance at ``wavelengths`` [W m^-2 sr^-1 nm^-1] (or any spectral quantity per nm).
    wavelengths : array_like, shape (N,)
        Increasing wavelengths [nm].

    Returns
    -------
    numpy.ndarray, shape (..., 3)
        X, Y, Z [cd/m^2 for radiance]: K_m sum_i L_i cmf(lambda_i) dlambda_i (module docstring).

    Examples
    --------
    A flat spectrum of 1 W m^-2 sr^-1 nm^-1 from 360 to 830 nm at 1 nm: Y = 683 x 106.86 cd/m^2.

    >>> round(float(spectral_to_xyz(np.ones(471), np.arange(360.0, 831.0))[1]))
    72983
    """
    wavelengths = _wavelengths(wavelengths)
    radiance = _radiances(radiance, wavelengths.size, "one per wavelength")
    return spectral_frame_to_xyz(radiance, wavelengths)


def spectral_frame_to_xyz(radiance, wavelengths):
    """:func:`spectral_to_xyz` of a frame the renderers made, whose values are finite and >= 0 by
    construction (the kernels' contract, tested at the extremes): the spectral animation's conversion,
    without the check of every value. Any other radiance: :func:`spectral_to_xyz`."""
    wavelengths = _wavelengths(wavelengths)
    radiance = np.asarray(radiance, dtype=np.float64)
    if radiance.shape[-1:] != wavelengths.shape:
        raise ValueError(f"radiance must have {wavelengths.size} values on its last axis (one per wavelength), "
                         f"got shape {radiance.shape}")
    weights = colour_matching_functions(wavelengths) * band_widths(wavelengths)[:, None] * MAX_LUMINOUS_EFFICACY
    return radiance @ weights


def xyz_to_linear_srgb(xyz):
    """Linear sRGB / Rec. 709 (D65 white) of XYZ (..., 3), same scale (:data:`XYZ_TO_SRGB`).

    Examples
    --------
    >>> xyz_to_linear_srgb([0.95047, 1.0, 1.08883]).round(3).tolist()     # the D65 white
    [1.0, 1.0, 1.0]
    """
    return np.asarray(xyz, dtype=np.float64) @ XYZ_TO_SRGB.T


def linear_srgb_to_xyz(rgb):
    """XYZ of linear sRGB (..., 3): the inverse of :func:`xyz_to_linear_srgb`."""
    return np.asarray(rgb, dtype=np.float64) @ SRGB_TO_XYZ.T


def luminance(xyz):
    """Y of XYZ (..., 3) [cd/m^2 for XYZ from radiance]."""
    xyz = as_real_array("xyz", xyz, "real numbers X, Y, Z on a last axis of 3")
    if xyz.shape[-1:] != (3,):
        raise ValueError(f"xyz must be real numbers X, Y, Z on a last axis of 3, got shape {xyz.shape}")
    return xyz[..., 1]


def _solar_interpolation_matrix(wavelengths):
    grid, cmfs = _cmfs()
    solar = solar_irradiance_astm_g173(np.clip(grid, 365.0, 835.0))    # the end bins' values beyond centres
    order = np.argsort(wavelengths)
    matrix = np.empty((3, 3))
    for position, channel in enumerate(order):
        hat = np.zeros(3)
        hat[position] = 1.0
        weight = np.interp(grid, wavelengths[order], hat)        # linear between samples, constant beyond
        matrix[:, channel] = MAX_LUMINOUS_EFFICACY * (cmfs * (solar * weight)[:, None]).sum(axis=0)
    return matrix / solar_irradiance_astm_g173(wavelengths)[None, :]


def _bruneton2017_matrix(wavelengths, power=BRUNETON_SKY_POWER):
    grid, cmfs = _cmfs()
    rgb_bar = cmfs @ XYZ_TO_SRGB.T                                    # (n, 3): r, g, b colour-matching functions
    solar = solar_irradiance_astm_g173(np.clip(grid, 365.0, 835.0))
    factors = np.zeros((3, 3))
    for rank, channel in enumerate(np.argsort(wavelengths)[::-1]):   # longest -> red, shortest -> blue
        lam = wavelengths[channel]
        shape = solar / solar_irradiance_astm_g173(lam) * (grid / lam) ** power
        factors[rank, channel] = MAX_LUMINOUS_EFFICACY * float(rgb_bar[:, rank] @ shape)
    return SRGB_TO_XYZ @ factors


#: Least channel kept by the power-law reconstruction, relative to the pixel's largest (a shadowed channel
#: of 0 would have no logarithm), and the largest exponent it extrapolates with beyond the end samples.
POWER_LAW_FLOOR, POWER_LAW_MAX_EXPONENT = 1e-12, 8.0
#: Pixels per block of :func:`_solar_power_law_xyz` (bounds its (block, 471) temporaries).
_POWER_LAW_BLOCK = 16384


def _solar_power_law_xyz(radiance, wavelengths):
    """XYZ (..., 3) of L = E_sun r, log r linear in log lambda between the samples and beyond them with
    the end segment's exponent (clipped to +-POWER_LAW_MAX_EXPONENT)."""
    grid, cmfs = _cmfs()
    solar_grid = solar_irradiance_astm_g173(np.clip(grid, 365.0, 835.0))
    weights = MAX_LUMINOUS_EFFICACY * cmfs * solar_grid[:, None]             # (n, 3), 1 nm steps
    order = np.argsort(wavelengths)
    lam = wavelengths[order]
    log_lam, log_grid = np.log(lam), np.log(grid)
    flat = np.asarray(radiance, dtype=np.float64).reshape(-1, 3)[:, order]
    ratio = flat / solar_irradiance_astm_g173(lam)[None, :]
    top = ratio.max(axis=1, keepdims=True)
    out = np.zeros((flat.shape[0], 3))
    segment = np.clip(np.searchsorted(lam, grid) - 1, 0, 1)                # which pair of samples
    for start in range(0, flat.shape[0], _POWER_LAW_BLOCK):
        block = slice(start, start + _POWER_LAW_BLOCK)
        lit = POWER_LAW_FLOOR * top[block, 0] > 0         # > 0 and its floor too (not subnormal to 0)
        log_r = np.log(np.maximum(ratio[block][lit], POWER_LAW_FLOOR * top[block][lit]))
        exponents = np.diff(log_r, axis=1) / np.diff(log_lam)[None, :]                # (m, 2)
        outside = (grid < lam[0]) | (grid > lam[-1])
        p = exponents[:, segment]                                                      # (m, n)
        p = np.where(outside[None, :], np.clip(p, -POWER_LAW_MAX_EXPONENT, POWER_LAW_MAX_EXPONENT), p)
        anchor = np.where(segment == 0, 0, 1)
        r = np.exp(log_r[:, anchor] + p * (log_grid - log_lam[anchor])[None, :])
        values = np.zeros((lit.size, 3))
        values[lit] = r @ weights
        out[block] = values
    return out.reshape(np.shape(radiance)[:-1] + (3,))


#: Steps of :func:`_solar_power_law_tabulated_xyz`'s tables: in q (the log ratio of two neighbouring
#: samples) for the part of the spectrum between them, in p (the exponent, |p| <= 8) beyond the end samples.
POWER_LAW_TABLE_STEPS = (1.0 / 512.0, 1.0 / 256.0)


@functools.lru_cache(maxsize=8)
def _power_law_tables(lam):
    """For increasing wavelengths ``lam`` (3 floats [nm]), per pair k of neighbouring samples:
    (Delta_k = log lam_(k+1) - log lam_k, B_k, O_k) with B_k(q) = sum_between W e^(q a / Delta_k) on the
    q nodes and O_k(p) = sum_beyond W e^(p a) on the p nodes, each as its X, Y and Z columns (3 contiguous
    arrays: the interpolation reads one channel at a time), a = log lambda - log lam_k, W = K_m cmf E_sun
    at 1 nm (the sums of :func:`_solar_power_law_xyz`, split by where lambda lies)."""
    grid, cmfs = _cmfs()
    weights = MAX_LUMINOUS_EFFICACY * cmfs * solar_irradiance_astm_g173(np.clip(grid, 365.0, 835.0))[:, None]
    lam = np.asarray(lam)
    log_lam, log_grid = np.log(lam), np.log(grid)
    segment = np.clip(np.searchsorted(lam, grid) - 1, 0, 1)
    outside = (grid < lam[0]) | (grid > lam[-1])
    step_q, step_p = POWER_LAW_TABLE_STEPS
    q_nodes = np.arange(-_Q_NODES, _Q_NODES + 1) * step_q
    p_nodes = np.arange(-_P_NODES, _P_NODES + 1) * step_p
    tables = []
    for k in (0, 1):
        a = log_grid - log_lam[k]
        delta = log_lam[k + 1] - log_lam[k]
        between, beyond = (segment == k) & ~outside, (segment == k) & outside
        inner = np.exp(np.outer(q_nodes, a[between] / delta)) @ weights[between]
        outer = np.exp(np.outer(p_nodes, a[beyond])) @ weights[beyond]
        tables.append((delta, _columns(inner), _columns(outer)))
    return tuple(tables)


def _columns(table):
    """The columns of ``table`` (n, 3) as 3 contiguous read-only arrays."""
    columns = tuple(np.ascontiguousarray(table[:, c]) for c in range(3))
    for column in columns:
        column.setflags(write=False)
    return columns


#: Half the node counts of the q and p tables: |q| <= log(1 / POWER_LAW_FLOOR) (two logarithms of
#: channels floored at POWER_LAW_FLOOR of the largest), |p| <= POWER_LAW_MAX_EXPONENT beyond the samples.
_Q_NODES = int(np.ceil(np.log(1.0 / POWER_LAW_FLOOR) / POWER_LAW_TABLE_STEPS[0]))
_P_NODES = int(round(POWER_LAW_MAX_EXPONENT / POWER_LAW_TABLE_STEPS[1]))


def _interpolate(columns, x, step, half):
    """Linear interpolation of a table's ``columns`` (3 arrays of 2 half + 1 values, :func:`_columns`) on the
    nodes (i - half) step at ``x`` (m,), clamped to the end nodes: its 3 columns (m,) at ``x``."""
    position = np.clip(x / step + half, 0.0, 2.0 * half)
    index = np.minimum(position.astype(np.intp), 2 * half - 1)
    t = position - index
    below, above = 1.0 - t, index + 1
    values = []
    # table[index] * (1 - t) + table[index + 1] * t, the same products and sum, one channel at a time (1-D
    # takes and products: a third less time than rows of 3), in place: every frame's pixels run it 4 times
    for column in columns:
        low = column.take(index)
        low *= below
        high = column.take(above)
        high *= t
        low += high
        values.append(low)
    return values


def _lit_ratios(radiance, wavelengths):
    """The power law's inputs: (lam, the wavelengths ascending; flat, radiance as (n, 3); ratio, each
    channel's L / E_sun(lambda) in ascending wavelength (3 arrays of n); lit, the pixels whose largest ratio
    is positive with a positive floor (one below about 5e-312 is taken as black: XYZ 0); floor,
    POWER_LAW_FLOOR times that largest ratio, lit pixels only). Shared by
    :func:`_solar_power_law_tabulated_xyz` and its device form (:mod:`clsky.colorimetry_cl`)."""
    order = np.argsort(wavelengths)
    lam = wavelengths[order]
    flat = np.asarray(radiance, dtype=np.float64).reshape(-1, 3)
    sun = solar_irradiance_astm_g173(lam)
    ratio = [flat[:, channel] / sun[k] for k, channel in enumerate(order)]
    top = np.maximum(np.maximum(ratio[0], ratio[1]), ratio[2])
    floor = POWER_LAW_FLOOR * top
    lit = floor > 0     # the largest ratio > 0, and its floor too: below about 5e-312 it is 0, whose log is -inf
    return lam, flat, ratio, lit, floor[lit]


def _solar_power_law_tabulated_xyz(radiance, wavelengths):
    """:func:`_solar_power_law_xyz`'s reconstruction, its sums over 1 nm tabulated (module docstring):
    XYZ = r_1 (B_1(q_1) + O_1(clip(q_1 / Delta_1))) + r_2 (B_2(q_2) + O_2(clip(q_2 / Delta_2))), with
    r_k the floored ratios L_k / E_sun(lambda_k) and q_k = log r_(k+1) - log r_k.

    The pixels are taken one channel at a time (1-D arrays; each value is computed by the same operations
    as on rows of 3, so the same bits): 14-15 against 21-35 CPU-ms a 512 x 512 frame with (n, 3) arrays,
    whose row-wise maximum, masked rows and row takes NumPy handles slowly."""
    lam, flat, ratio, lit, floor = _lit_ratios(radiance, wavelengths)
    ratio = [np.maximum(r[lit], floor) for r in ratio]
    log_r = [np.log(r) for r in ratio]
    step_q, step_p = POWER_LAW_TABLE_STEPS
    pairs = []                                   # each pair's X, Y, Z term
    for k, (delta, inner, outer) in enumerate(_power_law_tables(tuple(lam.tolist()))):
        q = log_r[k + 1] - log_r[k]
        exponent = np.clip(q / delta, -POWER_LAW_MAX_EXPONENT, POWER_LAW_MAX_EXPONENT)
        tables = zip(_interpolate(inner, q, step_q, _Q_NODES), _interpolate(outer, exponent, step_p, _P_NODES))
        pairs.append([ratio[k] * (between + beyond) for between, beyond in tables])
    values = np.zeros((lit.size, 3))
    # each channel written through the lit pixels' indices: NumPy's boolean index of rows of 3 copies them
    # one at a time (2 against 7 ms a 512 x 512 frame with the stack of the channels before it)
    lit_pixels = np.flatnonzero(lit)
    for channel, (first, second) in enumerate(zip(*pairs)):
        values[lit_pixels, channel] = first + second
    return values.reshape(np.shape(radiance)[:-1] + (3,))


#: Three-wavelength reconstructions (module docstring): name -> function of the wavelengths returning
#: the matrix, or (for the non-linear power law) of (radiance, wavelengths) returning XYZ.
THREE_WAVELENGTH_METHODS = {"solar_power_law": _solar_power_law_xyz,
                            "solar_power_law_tabulated": _solar_power_law_tabulated_xyz,
                            "solar_interpolation": _solar_interpolation_matrix, "bruneton2017": _bruneton2017_matrix}
#: The methods that are a 3 x 3 matrix (:func:`three_wavelength_to_xyz_matrix`).
LINEAR_METHODS = ("solar_interpolation", "bruneton2017")


#: The largest spectral radiance the checked conversions take [W m^-2 sr^-1 nm^-1]: far above any sky's (the
#: sun's disc is about 2e4), far enough below float64's largest that the power law's and the sums'
#: intermediates stay finite (1e308 gave inf).
MAX_RADIANCE = 1e100


def _radiances(radiance, count, what):
    """``radiance`` (..., count) as float64 if every value is finite, >= 0 and at most :data:`MAX_RADIANCE`;
    ValueError naming ``radiance`` otherwise (the power law would take NaN for black and clamp a negative
    channel, silently; the N-wavelength sum passed NaN and negative values through)."""
    valid = f"finite radiances in [0, {MAX_RADIANCE:g}], a last axis of {count} ({what})"
    array = as_real_array("radiance", radiance, valid)
    if array.shape[-1:] != (count,):
        raise ValueError(f"radiance must be {valid}, got shape {array.shape}")
    if array.size and not (array.min() >= 0.0 and array.max() <= MAX_RADIANCE):       # NaN fails the first
        bad = int(np.count_nonzero(~(np.isfinite(array) & (array >= 0.0) & (array <= MAX_RADIANCE))))
        raise ValueError(f"radiance must be {valid}, got {bad} NaN, infinite, negative or larger values")
    return array


def _three(wavelengths, method, methods):
    if not isinstance(method, str) or method not in methods:
        raise ValueError(f"method must be one of {sorted(methods)}, got {method!r}")
    try:
        values = np.asarray(wavelengths, dtype=np.float64)
    except (TypeError, ValueError):
        values = np.empty(0)
    if values.shape != (3,) or len(set(values.tolist())) != 3:
        raise ValueError(f"wavelengths must be 3 distinct numbers [nm], got {wavelengths!r}")
    return values


def three_wavelength_to_xyz_matrix(wavelengths, method="solar_interpolation"):
    """M (3, 3) with XYZ = M @ (L_1, L_2, L_3) for radiances at three wavelengths [nm] (module docstring).

    Parameters
    ----------
    wavelengths : sequence of 3 floats
        Distinct wavelengths [nm] in [365, 835] (the solar spectrum's range), in the radiance's channel order.
    method : str
        One of :data:`LINEAR_METHODS`.

    Examples
    --------
    >>> three_wavelength_to_xyz_matrix((650.0, 510.0, 475.0)).shape
    (3, 3)
    """
    values = _three(wavelengths, method, LINEAR_METHODS)
    return THREE_WAVELENGTH_METHODS[method](values)


def three_wavelength_to_xyz(radiance, wavelengths, method=DEFAULT_THREE_WAVELENGTH_METHOD, ctx=None):
    """XYZ (..., 3) of radiance (..., 3) [W m^-2 sr^-1 nm^-1] at three wavelengths [nm], by one of
    :data:`THREE_WAVELENGTH_METHODS` (module docstring). With ``ctx`` (a pyopencl.Context),
    ``solar_power_law_tabulated`` runs on its device (:mod:`clsky.colorimetry_cl`: the same values, bit for
    bit, in about half the CPU time on the 2-core machine); the other methods ignore it.

    Raises
    ------
    ValueError
        ``radiance`` has no last axis of 3, or holds NaN, infinite or negative values (the power law would
        take NaN for black and clamp a negative channel); an unknown ``method``; ``wavelengths`` not 3
        distinct numbers.
    """
    return three_wavelength_frame_to_xyz(_radiances(radiance, 3, "three wavelengths"), wavelengths, method, ctx)


def three_wavelength_frame_to_xyz(radiance, wavelengths, method=DEFAULT_THREE_WAVELENGTH_METHOD, ctx=None):
    """:func:`three_wavelength_to_xyz` of a frame the renderers made, whose values are finite and >= 0 by
    construction (the kernels' contract, tested at the extremes): the animation's conversion, without the
    check of every value (two passes over each frame). Any other radiance: :func:`three_wavelength_to_xyz`
    (here an infinite value ends in an IndexError of the tabulated power law)."""
    values = _three(wavelengths, method, THREE_WAVELENGTH_METHODS)
    if ctx is not None:                 # named before it is ignored (the linear methods) or used
        from ._cl import check_context

        check_context(ctx)
    if method in LINEAR_METHODS:
        return np.asarray(radiance, dtype=np.float64) @ THREE_WAVELENGTH_METHODS[method](values).T
    if ctx is not None and method == "solar_power_law_tabulated":
        from .colorimetry_cl import solar_power_law_xyz

        return solar_power_law_xyz(radiance, values, ctx)
    return THREE_WAVELENGTH_METHODS[method](radiance, values)
