"""The sun's extraterrestrial spectrum, and the units it gives the radiance.

The spectrum is ASTM G173-03's extraterrestrial (ETR) column, averaged over 10 nm bins from 360 to
840 nm, shipped in ``clsky/data/solar_irradiance_astm_g173_etr_10nm.csv`` (its header gives the source
and licence). Each bin average is read as the value at the bin's centre, with linear interpolation
between centres, exactly as :func:`clsky.ozone.cross_section_serdyuchenko2014` reads the ozone bins.

Units. The tables hold radiance per unit incident light [1/sr]; the renderer multiplies by the
atmosphere's incident light I_I = solar_irradiance * exposure * spectral_to_rgb
(:attr:`clsky.atmosphere.AtmosphereParameters.incident_light`). When I_I is this spectrum at the
channels' wavelengths (exposure 1, spectral_to_rgb 1: :func:`with_solar_spectrum`), the rendered
values are spectral radiances in W m^-2 sr^-1 nm^-1 (:data:`ABSOLUTE_UNITS`); otherwise, as in the
``atmosphere-plus`` preset with the notes' I_I, they are relative (:data:`RELATIVE_UNITS`).

References
----------
ASTM G173-03 (2012). Standard Tables for Reference Solar Spectral Irradiances. ASTM International,
doi:10.1520/G0173-03R12. Gueymard, C. A. (2004). The sun's total and spectral irradiance for solar
energy applications and solar radiation models. Solar Energy 76, 423-453,
doi:10.1016/j.solener.2003.08.039. Bruneton, E. (2017), github.com/ebruneton/precomputed_atmospheric_scattering
(atmosphere/demo/demo.cc: the binned values).
"""

from __future__ import annotations

import functools

import numpy as np

from ._data import interpolate_bin_centres, read_binned_table
from .errors import check_instance

__all__ = ["SOLAR_SPECTRUM_FILE", "ABSOLUTE_UNITS", "RELATIVE_UNITS", "solar_spectrum_table",
           "solar_irradiance_astm_g173", "with_solar_spectrum", "radiance_units"]

#: Name of the shipped spectrum inside the clsky package.
SOLAR_SPECTRUM_FILE = "data/solar_irradiance_astm_g173_etr_10nm.csv"
#: Units of rendered values when the incident light is the solar spectrum (:func:`radiance_units`).
ABSOLUTE_UNITS = "W m^-2 sr^-1 nm^-1"
#: Units of rendered values with any other incident light (the notes' I_I of the atmosphere-plus preset).
RELATIVE_UNITS = "relative (incident light I_I per sr)"
#: How close the incident light must be to the spectrum for :func:`radiance_units` to call it absolute.
_SAME = 1e-12


@functools.lru_cache(maxsize=1)
def solar_spectrum_table():
    """The shipped bins: (lower edge [nm], upper edge [nm], mean irradiance [W m^-2 nm^-1]), read-only,
    checked by :func:`clsky._data.read_binned_table` (DataFileError for a malformed file).

    Examples
    --------
    >>> low, high, irradiance = solar_spectrum_table()
    >>> float(low[0]), float(high[-1]), len(irradiance), float(irradiance[0])
    (360.0, 840.0, 48, 1.11776)
    """
    return read_binned_table(SOLAR_SPECTRUM_FILE, "irradiance_w_m2_nm")


def solar_irradiance_astm_g173(wavelengths_nm):
    """Extraterrestrial solar spectral irradiance at given wavelengths.

    Parameters
    ----------
    wavelengths_nm : array_like
        Wavelengths [nm], between the first and last bin centre (365 to 835 nm).

    Returns
    -------
    numpy.ndarray
        E_sun [W m^-2 nm^-1], one per wavelength.

    Raises
    ------
    ValueError
        For a wavelength outside the covered range.

    Examples
    --------
    >>> solar_irradiance_astm_g173([365.0, 550.0, 650.0]).round(5).tolist()
    [1.11776, 1.85094, 1.56312]
    """
    return interpolate_bin_centres(solar_spectrum_table(), wavelengths_nm, "the solar spectrum")


def with_solar_spectrum(atmosphere):
    """``atmosphere`` lit by the solar spectrum at its wavelengths: solar_irradiance = E_sun(lambda)
    [W m^-2 nm^-1], exposure 1, spectral_to_rgb 1, so that rendered values are spectral radiances
    [W m^-2 sr^-1 nm^-1]. Nothing else changes (the tables, which carry no I_I, are the same).

    Examples
    --------
    >>> from clsky import preset
    >>> radiance_units(with_solar_spectrum(preset("physical")))
    'W m^-2 sr^-1 nm^-1'
    """
    from .atmosphere import AtmosphereParameters

    check_instance("atmosphere", atmosphere, AtmosphereParameters, "an AtmosphereParameters")
    return atmosphere.replace(solar_irradiance=tuple(solar_irradiance_astm_g173(atmosphere.wavelengths)),
                              exposure=1.0, spectral_to_rgb=(1.0, 1.0, 1.0))


def radiance_units(atmosphere) -> str:
    """The units of the radiance rendered with ``atmosphere``: :data:`ABSOLUTE_UNITS` when its incident
    light is the solar spectrum at its wavelengths (:func:`with_solar_spectrum`), else
    :data:`RELATIVE_UNITS`.

    Examples
    --------
    >>> from clsky import preset
    >>> radiance_units(preset("atmosphere-plus"))
    'relative (incident light I_I per sr)'
    """
    from .atmosphere import AtmosphereParameters

    check_instance("atmosphere", atmosphere, AtmosphereParameters, "an AtmosphereParameters")
    try:
        expected = solar_irradiance_astm_g173(atmosphere.wavelengths)
    except ValueError:
        return RELATIVE_UNITS
    light = np.asarray(atmosphere.incident_light)
    return ABSOLUTE_UNITS if np.allclose(light, expected, rtol=_SAME, atol=0.0) else RELATIVE_UNITS
