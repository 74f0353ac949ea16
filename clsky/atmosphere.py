"""Atmosphere parameters: a validated, immutable description of the planet, its air and its sun.

Two presets share one atmosphere of air and haze:

``atmosphere-plus``
    The constants of the Atmosphere Plus notes (after Elek 2009) with the notes' *modified* Rayleigh
    phase 0.8 (7/5 + c^2/2), an artistic choice whose mean over the sphere is 1.2533, not 1. No ozone.
``physical``
    The same air with the true Rayleigh phase 3/4 (1 + c^2) and ozone: Bruneton 2017's tent (10 to
    40 km, peak at 25 km) holding 300 Dobson units, cross-sections of Serdyuchenko et al. 2014
    (:mod:`clsky.ozone`), and a Lambertian ground of albedo :data:`EARTH_GROUND_ALBEDO` (0.1,
    clsky/ground.py). A reflecting ground needs the physical scheme of the higher orders
    (``TableSettings(mode="physical")``, the default of the quality levels, of ``clsky animate`` and of
    ``clsky table --preset physical``); the atmosphere-plus scheme refuses it (README, "Ground albedo").

The atmosphere-plus preset has a black ground.

All lengths are in metres, scattering coefficients in 1/m, wavelengths in nanometres.

References
----------
Elek, O. (2009). Rendering parametrizable planetary atmospheres with multiple scattering in real time.
Proc. CESCG. Nishita, T. et al. (1993). Display of the earth taking into account atmospheric
scattering. SIGGRAPH '93, doi:10.1145/166117.166140. ``docs/physics.md`` (constants and the notes'
typos: N_R = 2.545e25 m^-3, not 2.454e25).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from typing import Any

import numpy as np

from .errors import (ParameterError, as_real_array, check_instance, dataclass_from_dict, is_finite_real,
                     is_real_number)
from .ozone import DOBSON_UNIT, cross_section_serdyuchenko2014

__all__ = [
    "AtmosphereParameters",
    "PRESETS",
    "preset",
    "as_atmosphere",
    "rayleigh_scattering_coefficient",
    "RAYLEIGH_PHASE_METHODS",
    "MIE_PHASE_METHODS",
]

#: Rayleigh phase functions the kernels know, name -> index passed to OpenCL.
RAYLEIGH_PHASE_METHODS = {"rayleigh": 0, "modified_atmosphereplus": 1}
#: Mie phase functions the kernels know, name -> index passed to OpenCL.
MIE_PHASE_METHODS = {"cornette_shanks": 0}


def rayleigh_scattering_coefficient(refractive_index, number_density, wavelengths_nm):
    """Rayleigh scattering coefficient of air.

    Parameters
    ----------
    refractive_index : float
        Refractive index of air at sea level n (1.0003 in the notes).
    number_density : float
        Molecular number density at sea level N [1/m^3] (2.545e25).
    wavelengths_nm : array_like
        Wavelengths [nm].

    Returns
    -------
    numpy.ndarray
        beta_R = 8 pi^3 (n^2 - 1)^2 / (3 N lambda^4) [1/m], one per wavelength.

    Notes
    -----
    Nishita et al. (1993), eq. 2 (with the King factor omitted, as the notes do).

    Examples
    --------
    >>> rayleigh_scattering_coefficient(1.0003, 2.545e25, [650, 510, 475]).round(10)
    array([6.55410e-06, 1.72935e-05, 2.29821e-05])

    Raises
    ------
    ValueError
        (:class:`clsky.errors.ParameterError`) naming ``refractive_index`` (in [1, MAX_REFRACTIVE_INDEX]),
        ``number_density`` (finite, > 0 1/m^3: a negative one gave negative coefficients) or
        ``wavelengths_nm`` (finite, > 0: 0 nm gave an infinite coefficient).
    """
    for name, value in (("refractive_index", refractive_index), ("number_density", number_density)):
        if not is_finite_real(value):
            raise ParameterError(name, "a finite real number", value)
    if not 1.0 <= refractive_index <= MAX_REFRACTIVE_INDEX:
        raise ParameterError("refractive_index", f"a real number in [1, {MAX_REFRACTIVE_INDEX:g}]", refractive_index)
    if number_density <= 0.0:
        raise ParameterError("number_density", "a finite number > 0 1/m^3", number_density)
    wavelengths = as_real_array("wavelengths_nm", wavelengths_nm, "finite wavelengths > 0 nm")
    if not np.all(np.isfinite(wavelengths) & (wavelengths > 0.0)):
        raise ParameterError("wavelengths_nm", "finite wavelengths > 0 nm", wavelengths_nm)
    wavelength_m = wavelengths * 1e-9
    n2m1 = refractive_index**2 - 1.0
    return 8.0 * math.pi**3 * n2m1**2 / (3.0 * number_density * wavelength_m**4)


_is_real_number = is_real_number

#: Largest incident light I_I per channel (the solar irradiance, 1.5-2 W m^-2 nm^-1 in the visible, times
#: the exposure and the spectral-to-RGB factor): renders are I_I times radiances per unit irradiance of
#: order 1, so this keeps every render finite with room to spare, float32's included.
MAX_INCIDENT_LIGHT = 1e12

#: Largest refractive index :meth:`AtmosphereParameters.from_refractive_index` takes (air's is 1.0003; a gas
#: far beyond would exceed the optical-depth limit anyway, and n^2 would overflow long before 1e200).
MAX_REFRACTIVE_INDEX = 10.0

#: Supported ranges (float64; see :class:`AtmosphereParameters`, Notes).
PLANET_RADIUS_RANGE = (1e3, 1e10)
ATMOSPHERE_HEIGHT_RANGE = (1.0, 1e10)
#: Least scale height (and half width of the ozone tent), as a fraction of the atmosphere's height.
MIN_SCALE_HEIGHT_FRACTION = 1e-4
#: Largest |g| of the Mie phase: the lobe's width, about 1 - |g| rad, is then 1e-4 rad, far below what
#: the gather's sphere quadrature resolves (256 x 128 steps: 0.012 rad); beyond it the tables of higher
#: orders overflowed (g = +0.999999: values of 1e7 where the radiance per unit irradiance is of order 1,
#: 1e12 at 1 - 1e-9).
MAX_MIE_G = 0.9999
#: Largest vertical optical depth (Rayleigh + Mie extinction, per wavelength).
MAX_VERTICAL_OPTICAL_DEPTH = 1e3
#: Float32 kernels: the largest planet radius [m], and the least atmosphere height as a fraction of
#: the planet radius (measured against float64, tests/test_scales.py: within 2e-6 inside; 5e-4 at a
#: radius of 1e9 m, 1 % at 1e10 m, all zero at 1e15 m; all zero for a shell 1e-10 of the radius).
FLOAT32_MAX_PLANET_RADIUS = 1e8
FLOAT32_MIN_HEIGHT_FRACTION = 1e-6

#: Default r, g, b wavelengths [nm] and their O3 cross-sections [m^2] (:mod:`clsky.ozone`).
DEFAULT_WAVELENGTHS = (650.0, 510.0, 475.0)
DEFAULT_OZONE_CROSS_SECTION = tuple(float(v) for v in cross_section_serdyuchenko2014(DEFAULT_WAVELENGTHS))
#: The ozone fields and their defaults (Bruneton 2017's tent, no column): see :meth:`AtmosphereParameters.to_dict`.
OZONE_DEFAULTS = {"ozone_column_du": 0.0, "ozone_peak_altitude": 25_000.0, "ozone_half_width": 15_000.0,
                  "ozone_cross_section": DEFAULT_OZONE_CROSS_SECTION}
#: The Angstrom fields and their defaults (a wavelength-independent Mie coefficient): see
#: :meth:`AtmosphereParameters.to_dict`.
ANGSTROM_DEFAULTS = {"mie_angstrom_exponent": 0.0, "mie_reference_wavelength": 550.0}
#: Largest Angstrom exponent accepted (continental aerosols reach about 2.5; beyond 4 haze would scatter
#: more steeply than air).
MAX_ANGSTROM_EXPONENT = 4.0
#: The ground field and its default (black): left out of :meth:`AtmosphereParameters.to_dict` when 0.
GROUND_DEFAULTS = {"ground_albedo": 0.0}
#: A ground albedo for the Earth: Bruneton 2017's demo value (kGroundAlbedo = 0.1), close to the visible
#: mean of the Earth's surface, 71 % ocean (about 0.06) and 29 % land (0.15 to 0.3).
EARTH_GROUND_ALBEDO = 0.1

#: The fields a scene may set over its preset's (``clsky table``'s and the animation's --ground-albedo and
#: --ozone-column, AnimationConfig's fields of the same names), with their ranges (low, high, unit), the
#: same everywhere: 1e5 DU is 300 times the Earth's column (the table's check of the optical depth alone
#: reported 1e308 DU as "here 6.58e+303", in no unit one types).
OVERRIDE_RANGES = {"ground_albedo": (0.0, 1.0, ""), "ozone_column_du": (0.0, 1e5, " DU")}


def _as_rgb(name: str, value) -> tuple[float, float, float]:
    items = tuple(value) if isinstance(value, (tuple, list, np.ndarray)) else None
    if items is None or len(items) != 3 or not all(_is_real_number(v) for v in items):
        raise ParameterError(name, "3 real numbers (r, g, b)", value)
    try:
        return tuple(float(v) for v in items)
    except OverflowError:                           # an integer beyond float's range (10**400)
        raise ParameterError(name, "3 finite real numbers (r, g, b)", value) from None


def _column(scale_height, atmosphere_height):
    """Vertical column of rho = exp(-h / H) from the ground to the top [m]: H (1 - exp(-Ha / H))."""
    return -scale_height * math.expm1(-atmosphere_height / scale_height)


@dataclasses.dataclass(frozen=True)
class AtmosphereParameters:
    """Planet, air and sun of a simulated sky. Immutable; every field is checked on creation.

    Parameters
    ----------
    planet_radius : float
        Rp [m], in [1e3, 1e10].
    top_radius : float
        Ra [m], radius of the top of the atmosphere: Ra - Rp in [1, 1e10] m.
    rayleigh_scale_height, mie_scale_height : float
        H_R, H_M [m], >= 1e-4 (Ra - Rp): densities are rho(h) = exp(-h / H).
    rayleigh_scattering : tuple of 3 floats
        beta_R at the three wavelengths [1/m], >= 0 (Rayleigh extinction equals scattering).
    mie_scattering : float
        beta_M [1/m], >= 0, at ``mie_reference_wavelength`` (at every wavelength with the default
        Angstrom exponent 0). With beta_R, at most a vertical optical depth of 1000 per wavelength.
    mie_extinction_ratio : float
        beta_M / beta_M^e in (0, 1]: the notes' 0.9 gives beta_M^e = beta_M / 0.9.
    mie_angstrom_exponent : float
        Angstrom exponent alpha in [0, 4]: per channel, beta_M(lambda) = beta_M (lambda / lambda_0)^-alpha
        (:attr:`mie_scattering_channels`; the extinction scales alike). 0, the default, is
        wavelength-independent haze, bit for bit the coefficient of clsky before the exponent.
    mie_reference_wavelength : float
        lambda_0 [nm], > 0, the wavelength at which ``mie_scattering`` holds (default 550 nm).
    mie_g : float
        Cornette-Shanks asymmetry in the notes' sign convention, in [-:data:`MAX_MIE_G`, MAX_MIE_G]
        ([-0.9999, 0.9999]); negative g peaks toward the sun.
    rayleigh_phase : str
        One of :data:`RAYLEIGH_PHASE_METHODS`.
    mie_phase : str
        One of :data:`MIE_PHASE_METHODS`.
    wavelengths : tuple of 3 floats
        The r, g, b wavelengths [nm], > 0. beta_R is given, not derived from them
        (:meth:`from_refractive_index` derives it); they set the Mie coefficient per channel when
        ``mie_angstrom_exponent`` is not 0 (:attr:`mie_scattering_channels`), the solar spectrum's
        irradiance (:func:`clsky.solar.with_solar_spectrum`), and the conversion of absolute frames to
        CIE XYZ (:func:`clsky.anim.animate.three_wavelength_frame_to_linear_srgb`).
    solar_irradiance, spectral_to_rgb : tuple of 3 floats
        Factors of the incident light, >= 0.
    exposure : float
        Exposure factor of the incident light, > 0; the incident light (the three factors' product) is
        at most :data:`MAX_INCIDENT_LIGHT` in each channel.
    ozone_column_du : float
        Ozone column [Dobson units, 1 DU = 2.687e20 molecules/m^2], >= 0; 0 (the default) is no ozone,
        and the kernels are then built without it (bit-for-bit the ozone-free program).
    ozone_peak_altitude, ozone_half_width : float
        The tent profile n_O3(h) = n_max max(0, 1 - |h - peak| / half_width) [m]; half_width > 0, and
        with ozone at least :data:`MIN_SCALE_HEIGHT_FRACTION` of the atmosphere's height (10 m for the
        Earth's), as the scale heights; peak >= half_width (the tent lies above the ground, so its column
        is n_max half_width). Ozone above the top of the atmosphere is ignored.
    ozone_cross_section : tuple of 3 floats
        O3 absorption cross-section sigma at the three wavelengths [m^2], >= 0; defaults to
        Serdyuchenko et al. (2014) at 650, 510, 475 nm (:func:`clsky.ozone.cross_section_serdyuchenko2014`).
    ground_albedo : float
        Albedo a of a Lambertian ground in [0, 1], the same at every wavelength: it reflects the
        radiance a / pi E (E the irradiance on the horizontal ground, direct sun and sky). 0 (the
        default) is a black ground, and the kernels are then built without it (bit-for-bit the
        ground-free program). A ground needs the ``physical`` scheme (TableSettings.mode).

    Raises
    ------
    ValueError
        (:class:`clsky.errors.ParameterError`, with the field's name as ``field``) for a value
        outside its range.

    Notes
    -----
    The ranges are those the numerics are tested for (tests/test_scales.py), with margin: in float64
    the geometry is exact to 1e-6 relative up to radii of 1e15 m, but beyond the radii and heights
    above, ray lengths times coefficients overflow (a planet of 1e300 m gave 98 % NaN). A scale height
    below 1e-4 of the atmosphere's height falls between the quadrature's first nodes (the table comes
    out zero), and beyond a vertical optical depth of 1000 the 30-step quadratures overflow. The
    float32 kernels also need Rp <= 1e8 m and Ra - Rp >= 1e-6 Rp (:meth:`check_dtype`, checked when a
    table is built): radii carry 7 digits; beyond, tables drift from float64's (5e-4 at 1e9 m, 1 % at
    1e10 m) and end all zero (1e15 m planets did).
    """

    planet_radius: float = 6_371_000.0
    top_radius: float = 6_471_000.0
    rayleigh_scale_height: float = 8_000.0
    mie_scale_height: float = 1_200.0
    rayleigh_scattering: tuple = (6.55e-6, 1.73e-5, 2.30e-5)
    mie_scattering: float = 2e-6
    mie_extinction_ratio: float = 0.9
    mie_g: float = -0.85
    rayleigh_phase: str = "modified_atmosphereplus"
    mie_phase: str = "cornette_shanks"
    wavelengths: tuple = (650.0, 510.0, 475.0)
    solar_irradiance: tuple = (0.1526, 0.191, 0.208)
    spectral_to_rgb: tuple = (133.3209, 88.51855, 112.7552)
    exposure: float = 1.0
    ozone_column_du: float = 0.0
    ozone_peak_altitude: float = 25_000.0
    ozone_half_width: float = 15_000.0
    ozone_cross_section: tuple = DEFAULT_OZONE_CROSS_SECTION
    ground_albedo: float = 0.0
    mie_angstrom_exponent: float = 0.0
    mie_reference_wavelength: float = 550.0

    def __post_init__(self):
        for name in ("rayleigh_scattering", "wavelengths", "solar_irradiance", "spectral_to_rgb",
                     "ozone_cross_section"):
            object.__setattr__(self, name, _as_rgb(name, getattr(self, name)))
        for name in ("planet_radius", "top_radius", "rayleigh_scale_height", "mie_scale_height",
                     "mie_scattering", "mie_extinction_ratio", "mie_g", "exposure", "ozone_column_du",
                     "ozone_peak_altitude", "ozone_half_width", "ground_albedo", "mie_angstrom_exponent",
                     "mie_reference_wavelength"):
            value = getattr(self, name)
            if not _is_real_number(value):
                raise ParameterError(name, "a real number", value)
            try:
                object.__setattr__(self, name, float(value))
            except OverflowError:                   # an integer beyond float's range (10**400)
                raise ParameterError(name, "a finite real number", value) from None

        def check(name, ok, valid_range):
            values = np.atleast_1d(getattr(self, name))
            if not (np.all(np.isfinite(values)) and ok(values)):
                raise ParameterError(name, valid_range, getattr(self, name))

        low, high = PLANET_RADIUS_RANGE
        check("planet_radius", lambda v: (low <= v) & (v <= high),
              f"in [{low:g}, {high:g}] m (the range the geometry is tested for)")
        rp = self.planet_radius
        low, high = ATMOSPHERE_HEIGHT_RANGE
        check("top_radius", lambda v: (v - rp >= low) & (v - rp <= high),
              f"{low:g} to {high:g} m above planet_radius")
        least = MIN_SCALE_HEIGHT_FRACTION * self.atmosphere_height
        layers = ["rayleigh_scale_height", "mie_scale_height"]
        if self.ozone_column_du > 0:            # without ozone, the tent may be as thin as it likes
            layers.append("ozone_half_width")
        for name in layers:
            check(name, lambda v: v >= least, f"finite and >= {least:g} m ({MIN_SCALE_HEIGHT_FRACTION:g} of the "
                                              f"atmosphere's height: thinner layers fall between the "
                                              f"quadrature's nodes)")
        check("ozone_half_width", lambda v: v > 0, "finite and > 0 m")
        check("rayleigh_scattering", lambda v: np.all(v >= 0), "finite and >= 0 1/m")
        check("mie_scattering", lambda v: v >= 0, "finite and >= 0 1/m")
        check("mie_extinction_ratio", lambda v: (v > 0) & (v <= 1), "in (0, 1]")
        check("mie_g", lambda v: np.abs(v) <= MAX_MIE_G,
              f"in [-{MAX_MIE_G:g}, {MAX_MIE_G:g}] (a narrower lobe is beyond the quadratures)")
        check("wavelengths", lambda v: np.all(v > 0), "finite and > 0 nm")
        check("solar_irradiance", lambda v: np.all(v >= 0), "finite and >= 0")
        check("spectral_to_rgb", lambda v: np.all(v >= 0), "finite and >= 0")
        check("exposure", lambda v: v > 0, "finite and > 0")
        check("ozone_column_du", lambda v: v >= 0, "finite and >= 0 DU")
        check("ozone_peak_altitude", lambda v: v >= self.ozone_half_width,
              f"finite and >= ozone_half_width ({self.ozone_half_width:g} m): the tent must lie above the ground")
        check("ozone_cross_section", lambda v: np.all(v >= 0), "finite and >= 0 m^2")
        check("mie_angstrom_exponent", lambda v: (v >= 0) & (v <= MAX_ANGSTROM_EXPONENT),
              f"in [0, {MAX_ANGSTROM_EXPONENT:g}]")
        check("mie_reference_wavelength", lambda v: v > 0, "finite and > 0 nm")
        check("ground_albedo", lambda v: (v >= 0) & (v <= 1), "in [0, 1]")
        with np.errstate(over="ignore"):
            light = np.array(self.solar_irradiance) * self.exposure * np.array(self.spectral_to_rgb)
        if not np.all(light <= MAX_INCIDENT_LIGHT):   # 1e300 each rendered infinities from valid parameters
            raise ParameterError("exposure", f"such that the incident light I_I = solar_irradiance x exposure x "
                                             f"spectral_to_rgb is at most {MAX_INCIDENT_LIGHT:g} in each channel "
                                             f"(renders scale with it; here {np.max(light):.3g})", self.exposure)
        with np.errstate(over="ignore"):
            angstrom = (np.array(self.wavelengths) / self.mie_reference_wavelength) ** -self.mie_angstrom_exponent
        if not np.all(np.isfinite(angstrom)):      # 0 * inf would make a Mie coefficient NaN
            raise ParameterError("wavelengths", f"such that the Angstrom law's factor (wavelength / "
                                                f"mie_reference_wavelength) ** -mie_angstrom_exponent is finite "
                                                f"(mie_reference_wavelength {self.mie_reference_wavelength:g} nm, "
                                                f"exponent {self.mie_angstrom_exponent:g})", self.wavelengths)
        self._check_optical_depth()
        if not isinstance(self.rayleigh_phase, str) or self.rayleigh_phase not in RAYLEIGH_PHASE_METHODS:
            raise ParameterError("rayleigh_phase", f"one of {sorted(RAYLEIGH_PHASE_METHODS)}", self.rayleigh_phase)
        if not isinstance(self.mie_phase, str) or self.mie_phase not in MIE_PHASE_METHODS:
            raise ParameterError("mie_phase", f"one of {sorted(MIE_PHASE_METHODS)}", self.mie_phase)

    def _check_optical_depth(self):
        """ParameterError naming the coefficient that makes a vertical optical depth exceed
        :data:`MAX_VERTICAL_OPTICAL_DEPTH` (beyond it, quadratures of 30 steps amplify and overflow)."""
        rayleigh = np.array(self.rayleigh_scattering) * _column(self.rayleigh_scale_height, self.atmosphere_height)
        mie = self.mie_extinction_channels * _column(self.mie_scale_height, self.atmosphere_height)
        ozone = np.array(self.ozone_cross_section) * self.ozone_column_du * DOBSON_UNIT   # the whole tent's column
        depth = float(np.max(rayleigh + mie + ozone))
        if not depth <= MAX_VERTICAL_OPTICAL_DEPTH:     # NaN too
            why = f"a vertical optical depth <= {MAX_VERTICAL_OPTICAL_DEPTH:g} (the range the quadratures are " \
                  f"tested for; here {depth:.3g})"
            name = max((np.max(ozone), "ozone_column_du"), (np.max(mie), "mie_scattering"),
                       (np.max(rayleigh), "rayleigh_scattering"))[1]
            scattering = self.mie_scattering_channels * _column(self.mie_scale_height, self.atmosphere_height)
            room = MAX_VERTICAL_OPTICAL_DEPTH - rayleigh - ozone       # what Mie's extinction may take
            if name == "mie_scattering" and np.all(scattering <= room):    # a larger ratio would do
                least = float(np.max(scattering / room))
                raise ParameterError("mie_extinction_ratio", f"at least {least:.3g} for {why}",
                                     self.mie_extinction_ratio)
            raise ParameterError(name, f"small enough for {why}", getattr(self, name))

    def check_dtype(self, dtype):
        """ParameterError if the kernels of ``dtype`` cannot resolve this atmosphere: float32 needs a
        planet radius <= :data:`FLOAT32_MAX_PLANET_RADIUS` and an atmosphere at least
        :data:`FLOAT32_MIN_HEIGHT_FRACTION` of it high (radii carry 7 digits; beyond, tables drift
        from float64's and end all zero)."""
        if np.dtype(dtype) != np.float32:
            return
        if self.planet_radius > FLOAT32_MAX_PLANET_RADIUS:
            raise ParameterError("planet_radius", f"<= {FLOAT32_MAX_PLANET_RADIUS:g} m in float32 (use dtype "
                                                  f"float64)", self.planet_radius)
        least = FLOAT32_MIN_HEIGHT_FRACTION * self.planet_radius
        if self.atmosphere_height < least:
            raise ParameterError("top_radius", f"at least planet_radius + {least:g} m in float32 (an atmosphere "
                                               f"{FLOAT32_MIN_HEIGHT_FRACTION:g} of the planet radius high; use "
                                               f"dtype float64)", self.top_radius)

    # Derived quantities -----------------------------------------------------------------------------
    @property
    def atmosphere_height(self) -> float:
        """Ha = Ra - Rp [m]."""
        return self.top_radius - self.planet_radius

    @property
    def mie_extinction(self) -> float:
        """beta_M^e = beta_M / ratio [1/m]."""
        return self.mie_scattering / self.mie_extinction_ratio

    @property
    def mie_scattering_channels(self) -> np.ndarray:
        """beta_M per channel [1/m]: beta_M (lambda / lambda_0)^-alpha at the three wavelengths (Angstrom
        1929). With alpha = 0 every channel is exactly ``mie_scattering`` (x ** -0.0 is 1.0)."""
        ratio = np.asarray(self.wavelengths) / self.mie_reference_wavelength
        return self.mie_scattering * ratio ** -self.mie_angstrom_exponent

    @property
    def mie_extinction_channels(self) -> np.ndarray:
        """beta_M^e per channel [1/m]: :attr:`mie_scattering_channels` / ratio."""
        return self.mie_scattering_channels / self.mie_extinction_ratio

    @property
    def has_ozone(self) -> bool:
        """True when the ozone column is > 0 (the kernels are then built with -DOZONE)."""
        return self.ozone_column_du > 0.0

    @property
    def has_ground(self) -> bool:
        """True when the ground reflects (albedo > 0; the kernels are then built with -DGROUND)."""
        return self.ground_albedo > 0.0

    @property
    def ozone_number_density_max(self) -> float:
        """n_max = column / half_width [1/m^3], the tent's peak (0 without ozone)."""
        from .ozone import tent_number_density_max

        return tent_number_density_max(self.ozone_column_du, self.ozone_half_width)

    @property
    def ozone_extinction(self) -> np.ndarray:
        """sigma n_max per channel [1/m]: ozone's extinction at the tent's peak (zeros without ozone)."""
        return np.array(self.ozone_cross_section) * self.ozone_number_density_max

    @property
    def incident_light(self) -> np.ndarray:
        """I_I = irradiance * exposure * spectral-to-RGB, one value per channel (r, g, b)."""
        return (np.array(self.solar_irradiance) * self.exposure * np.array(self.spectral_to_rgb))

    # Construction and identity ----------------------------------------------------------------------
    @classmethod
    def from_refractive_index(cls, refractive_index=1.0003, number_density=2.545e25,
                              wavelengths=(650.0, 510.0, 475.0), **fields):
        """Parameters whose beta_R is derived from n, N and the wavelengths
        (:func:`rayleigh_scattering_coefficient`), and, unless given, the ozone cross-sections too
        (:func:`clsky.ozone.cross_section_serdyuchenko2014`).

        Raises
        ------
        ValueError
            (:class:`clsky.errors.ParameterError`) naming ``refractive_index`` (a real number >= 1),
            ``number_density`` (> 0 1/m^3) or ``wavelengths`` (3 numbers > 0 nm), or any field.
        """
        wavelengths = _as_rgb("wavelengths", wavelengths)
        if not all(math.isfinite(w) and w > 0 for w in wavelengths):
            raise ParameterError("wavelengths", "3 finite numbers > 0 nm", wavelengths)
        beta = rayleigh_scattering_coefficient(refractive_index, number_density, wavelengths)
        fields.setdefault("ozone_cross_section", tuple(cross_section_serdyuchenko2014(wavelengths)))
        return cls(rayleigh_scattering=tuple(beta), wavelengths=tuple(wavelengths), **fields)

    def replace(self, **changes) -> "AtmosphereParameters":
        """A copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-serialisable dictionary of every field.

        An atmosphere without ozone whose ozone fields all keep their defaults (:data:`OZONE_DEFAULTS`)
        leaves them out, so that its dictionary and :meth:`digest` (and the hash of its saved tables)
        are those of clsky before ozone; :meth:`from_dict` restores the defaults. A black ground
        (:data:`GROUND_DEFAULTS`) and the Angstrom fields (:data:`ANGSTROM_DEFAULTS`) are left out the
        same way.
        """
        data = {k: (list(v) if isinstance(v, tuple) else v) for k, v in dataclasses.asdict(self).items()}
        for defaults in (OZONE_DEFAULTS, GROUND_DEFAULTS, ANGSTROM_DEFAULTS):
            if all(getattr(self, name) == value for name, value in defaults.items()):
                for name in defaults:
                    del data[name]
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "AtmosphereParameters":
        """Inverse of :meth:`to_dict`; unknown fields raise ValueError."""
        return dataclass_from_dict(cls, data, "an atmosphere's fields", "atmosphere fields")

    def digest(self) -> str:
        """SHA-256 of the canonical JSON of every field: identifies the atmosphere of a saved table."""
        text = json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()


#: Named presets (see module docstring).
PRESETS = {
    "atmosphere-plus": AtmosphereParameters(),
    "physical": AtmosphereParameters(rayleigh_phase="rayleigh", ozone_column_du=300.0,
                                     ground_albedo=EARTH_GROUND_ALBEDO),
}


def preset(name: str) -> AtmosphereParameters:
    """The preset called ``name``; ValueError lists the valid names."""
    if not isinstance(name, str) or name not in PRESETS:
        raise ValueError(f"preset must be one of {sorted(PRESETS)}, got {name!r}")
    return PRESETS[name]


def as_atmosphere(atmosphere, name="atmosphere") -> AtmosphereParameters:
    """``atmosphere`` as :class:`AtmosphereParameters`: a preset's name (:func:`preset`) or parameters;
    ValueError (:class:`~clsky.errors.ParameterError`) naming ``name`` for anything else."""
    valid = f"an AtmosphereParameters or a preset name {sorted(PRESETS)}"
    if isinstance(atmosphere, str):
        if atmosphere not in PRESETS:
            raise ParameterError(name, valid, atmosphere)
        return PRESETS[atmosphere]
    return check_instance(name, atmosphere, AtmosphereParameters, valid)
