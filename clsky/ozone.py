"""Ozone: an absorbing species with a tent-shaped density profile and tabulated cross-sections.

Ozone absorbs and does not scatter: it adds to the extinction only (``docs/physics.md``),

    beta_O3^e(h, lambda) = sigma(lambda) n_O3(h),   n_O3(h) = n_max f(h),
    f(h) = max(0, 1 - |h - h_peak| / w)                                   (Bruneton 2017's tent)

with h_peak = 25 km and half width w = 15 km by default (zero below 10 km and above 40 km). The column
of the tent is Integral n_O3 dh = n_max w, so a column of D Dobson units gives n_max = D DU / w, with
1 DU = 2.687e20 molecules/m^2 (300 DU: n_max = 5.374e18 m^-3).

The kernels integrate f along rays (a column [m], like the dimensionless densities rho_R, rho_M of
the other species) and multiply by the per-wavelength extinction at the peak, sigma(lambda) n_max [1/m]
(:attr:`clsky.atmosphere.AtmosphereParameters.ozone_extinction`).

Cross-sections: Serdyuchenko et al. (2014) at 233 K, averaged over 10 nm bins, shipped in
``clsky/data/ozone_cross_section_serdyuchenko2014_233K.csv`` (its header gives the source and licence).

References
----------
Serdyuchenko, A., Gorshelev, V., Weber, M., Chehade, W., Burrows, J. P. (2014). High spectral resolution
ozone absorption cross-sections - Part 2: Temperature dependence. Atmos. Meas. Tech. 7, 625-636,
doi:10.5194/amt-7-625-2014.
Bruneton, E. (2017). A qualitative and quantitative evaluation of 8 clear sky models. IEEE TVCG 23(12),
doi:10.1109/TVCG.2016.2622272; code: github.com/ebruneton/precomputed_atmospheric_scattering.
"""

from __future__ import annotations

import functools

import numpy as np

from ._data import interpolate_bin_centres, read_binned_table
from .errors import ParameterError, as_real_array, check_real

__all__ = ["DOBSON_UNIT", "CROSS_SECTION_FILE", "cross_section_table", "cross_section_serdyuchenko2014",
           "tent_profile", "tent_number_density_max"]

#: 1 Dobson unit [molecules / m^2].
DOBSON_UNIT = 2.687e20
#: Name of the shipped cross-section file inside the clsky package.
CROSS_SECTION_FILE = "data/ozone_cross_section_serdyuchenko2014_233K.csv"


@functools.lru_cache(maxsize=1)
def cross_section_table():
    """The shipped bins: (lower edge [nm], upper edge [nm], mean cross-section [m^2]), three read-only
    arrays, checked by :func:`clsky._data.read_binned_table` (DataFileError for a malformed file).

    Examples
    --------
    >>> low, high, sigma = cross_section_table()
    >>> float(low[0]), float(high[-1]), len(sigma)
    (360.0, 840.0, 48)
    """
    return read_binned_table(CROSS_SECTION_FILE, "cross_section_m2")


def cross_section_serdyuchenko2014(wavelengths_nm):
    """O3 absorption cross-section at 233 K (Serdyuchenko et al. 2014) at given wavelengths.

    Parameters
    ----------
    wavelengths_nm : array_like
        Wavelengths [nm], between the first and the last bin centre of the shipped file (365 to 835 nm).

    Returns
    -------
    numpy.ndarray
        sigma [m^2 per molecule], one per wavelength.

    Raises
    ------
    ValueError
        For a wavelength outside the covered range.

    Notes
    -----
    Each 10 nm bin average is read as the value at the bin's centre, with linear interpolation in
    wavelength between centres. (Bruneton's demo uses a bin's average at its lower edge instead: that
    reading gives 2.238e-25, 1.602e-25 and 6.34e-26 m^2 at 650, 510 and 475 nm; this one 2.450e-25,
    1.541e-25 and 4.924e-26 m^2.)

    Examples
    --------
    >>> (cross_section_serdyuchenko2014([650, 510, 475]) * 1e25).round(4).tolist()    # [1e-25 m^2]
    [2.45, 1.541, 0.4924]
    """
    return interpolate_bin_centres(cross_section_table(), wavelengths_nm, "the ozone cross-sections")


def tent_profile(altitude, peak_altitude=25_000.0, half_width=15_000.0):
    """Relative ozone density f(h) = max(0, 1 - |h - h_peak| / w) (dimensionless, 1 at the peak).

    Parameters
    ----------
    altitude : array_like
        h [m].
    peak_altitude, half_width : float
        h_peak and w [m].

    Examples
    --------
    >>> tent_profile([0.0, 10e3, 17.5e3, 25e3, 40e3]).tolist()
    [0.0, 0.0, 0.5, 1.0, 0.0]

    Raises
    ------
    ValueError
        (:class:`~clsky.errors.ParameterError`) naming a parameter that is not finite, or a half width
        that is not > 0 (0 gave NaN, a negative one densities far above the peak's).
    """
    h = as_real_array("altitude", altitude, "finite altitudes [m]")
    if not np.all(np.isfinite(h)):
        raise ParameterError("altitude", "finite altitudes [m]", altitude)
    peak_altitude = check_real("peak_altitude", peak_altitude, unit=" m")
    half_width = check_real("half_width", half_width, 0.0, low_open=True, unit=" m")
    return tent(h, peak_altitude, half_width)


def tent(h, peak_altitude, half_width):
    """:func:`tent_profile` of checked arguments (an atmosphere's, whose parameters are checked): the
    NumPy twins' densities (:func:`clsky.reference.densities`) on their ray nodes."""
    return np.maximum(1.0 - np.abs(h - peak_altitude) / half_width, 0.0)


def tent_number_density_max(column_du, half_width=15_000.0):
    """Peak number density n_max = column / w [1/m^3] of a tent of half width w [m] holding ``column_du``
    Dobson units.

    Examples
    --------
    >>> round(tent_number_density_max(300.0) / 1e18, 3)
    5.374

    Raises
    ------
    ValueError
        (:class:`~clsky.errors.ParameterError`) naming a column that is not finite and >= 0 (a negative one
        gave a negative density) or a half width that is not finite and > 0.
    """
    column_du = check_real("column_du", column_du, 0.0, unit=" DU")
    half_width = check_real("half_width", half_width, 0.0, low_open=True, unit=" m")
    return column_du * DOBSON_UNIT / half_width
