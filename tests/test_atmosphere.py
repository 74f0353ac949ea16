"""Validation, presets, derived constants and identity of AtmosphereParameters and TableSettings.

Published values come from ``docs/physics.md`` (constants of the Atmosphere Plus notes).
"""

from __future__ import annotations

import dataclasses
import json
import math
import re

import numpy as np
import pytest
from numpy.testing import assert_allclose

from clsky import PRESETS, AtmosphereParameters, TableSettings, preset
from clsky.atmosphere import EARTH_GROUND_ALBEDO, MAX_MIE_G, MIN_SCALE_HEIGHT_FRACTION
from clsky.atmosphere import MIE_PHASE_METHODS, rayleigh_scattering_coefficient

SCALAR_FIELDS = ("planet_radius", "top_radius", "rayleigh_scale_height", "mie_scale_height",
                 "mie_scattering", "mie_extinction_ratio", "mie_g", "exposure")
RGB_FIELDS = ("rayleigh_scattering", "wavelengths", "solar_irradiance", "spectral_to_rgb")


def raises_naming(field):
    """``pytest.raises(ValueError)`` whose message must name ``field`` (not as part of a longer name)."""
    return pytest.raises(ValueError, match=rf"(?<![\w\[]){re.escape(field)}(?![\w\[])")


# AtmosphereParameters: invalid values ------------------------------------------------------------

@pytest.mark.parametrize("field, value", [
    ("planet_radius", -6_371_000.0),
    ("planet_radius", 0.0),
    ("top_radius", -1.0),
    ("top_radius", 6_371_000.0),          # == planet_radius
    ("top_radius", 6_000_000.0),          # < planet_radius
    ("rayleigh_scale_height", 0.0),
    ("rayleigh_scale_height", -8000.0),
    ("mie_scale_height", 0.0),
    ("mie_scale_height", -1200.0),
    ("mie_scattering", -1e-6),
    ("mie_extinction_ratio", 0.0),
    ("mie_extinction_ratio", 1.5),
    ("mie_extinction_ratio", -0.9),
    ("mie_g", 1.0),
    ("mie_g", -1.0),
    ("mie_g", 1.5),
    ("mie_g", -1.0000001),
    ("mie_g", 0.99991),
    ("mie_g", -0.99991),
    ("exposure", 0.0),
    ("exposure", -1.0),
])
def test_out_of_range_scalar_raises_naming_the_field(field, value):
    with raises_naming(field):
        AtmosphereParameters(**{field: value})


@pytest.mark.parametrize("field, value", [
    ("rayleigh_scattering", (-1e-6, 1e-5, 2e-5)),
    ("wavelengths", (650.0, 0.0, 475.0)),
    ("wavelengths", (650.0, 510.0, -475.0)),
    ("solar_irradiance", (0.15, -0.19, 0.2)),
    ("spectral_to_rgb", (133.0, 88.0, -1.0)),
])
def test_out_of_range_rgb_raises_naming_the_field(field, value):
    with raises_naming(field):
        AtmosphereParameters(**{field: value})


def test_valid_edge_values_are_accepted():
    """Closed ends of the documented ranges: zero scattering, ratio 1, |g| = MAX_MIE_G, scale heights and
    the ozone tent's half width at their least (1e-4 of the atmosphere's height)."""
    atmosphere = AtmosphereParameters(mie_scattering=0.0, rayleigh_scattering=(0.0, 0.0, 0.0),
                                      mie_extinction_ratio=1.0, mie_g=-MAX_MIE_G, solar_irradiance=(0, 0, 0))
    assert atmosphere.mie_extinction == 0.0
    assert AtmosphereParameters(mie_g=MAX_MIE_G).mie_g == 0.9999
    least = MIN_SCALE_HEIGHT_FRACTION * atmosphere.atmosphere_height
    assert least == 10.0
    thin = preset("physical").replace(mie_scale_height=least, ozone_half_width=least)
    assert thin.ozone_half_width == least and np.isfinite(thin.ozone_number_density_max)


def test_mie_g_beyond_its_range_names_the_range():
    with pytest.raises(ValueError, match=r"^mie_g must be in \[-0.9999, 0.9999\] \(a narrower lobe is beyond "
                                         r"the quadratures\), got 0.99999"):
        AtmosphereParameters(mie_g=0.99999)


@pytest.mark.parametrize("field", ["rayleigh_scale_height", "mie_scale_height", "ozone_half_width"])
def test_layers_thinner_than_the_least_are_refused(field):
    """A thinner layer falls between the quadrature's nodes (an ozone tent 1e-290 m wide made its peak
    density infinite and the build fail after its work): refused by name, before any work."""
    with pytest.raises(ValueError, match=rf"^{field} must be finite and >= 10 m \(0.0001 of the atmosphere's "
                                         r"height: thinner layers fall between the quadrature's nodes\), got 9.99"):
        preset("physical").replace(**{field: 9.99})


def test_without_ozone_the_tent_may_be_thinner():
    """The tent's least width is ozone's: an atmosphere without ozone (a 1e9 m high one whose least layer
    is 1e5 m) keeps the preset's tent of 15 km."""
    tall = preset("atmosphere-plus").replace(top_radius=6_371_000.0 + 1e9, rayleigh_scale_height=1e6,
                                             mie_scale_height=1e6)
    assert tall.ozone_column_du == 0.0 and tall.ozone_half_width == 15e3
    with pytest.raises(ValueError, match=r"^ozone_half_width must be finite and >= 100000 m"):
        tall.replace(ozone_column_du=300.0, ozone_peak_altitude=2e5)


@pytest.mark.parametrize("changes, message", [
    # Mie's scattering alone (2e-6 1/m over its 1200 m scale height: 2.4e-3) would fit: the ratio is to blame
    (dict(mie_extinction_ratio=1e-12), r"mie_extinction_ratio must be at least 2.4e-06 for a vertical optical "
                                       r"depth <= 1000 \(the range the quadratures are tested for; here 2.4e\+09\)"),
    (dict(mie_scattering=1.0), "mie_scattering must be small enough for a vertical optical depth <= 1000"),
    (dict(mie_scattering=1.0, mie_extinction_ratio=0.5), "mie_scattering must be small enough"),
    (dict(rayleigh_scattering=(1.0, 1.0, 1.0)), "rayleigh_scattering must be small enough"),
])
def test_an_optical_depth_beyond_the_bound_names_the_field_that_makes_it(changes, message):
    """The field whose column is the largest, and for Mie the extinction ratio where the scattering alone
    fits: a ratio too small is refused with its least value, not as too large (it was named mie_scattering
    first, then "small enough")."""
    with pytest.raises(ValueError, match=rf"^{message}"):
        preset("physical").replace(**changes)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
@pytest.mark.parametrize("field", SCALAR_FIELDS)
def test_non_finite_scalar_raises_naming_the_field(field, bad):
    with raises_naming(field):
        AtmosphereParameters(**{field: bad})


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
@pytest.mark.parametrize("position", [0, 1, 2])
@pytest.mark.parametrize("field", RGB_FIELDS)
def test_non_finite_rgb_component_raises_naming_the_field(field, position, bad):
    value = list(getattr(AtmosphereParameters(), field))
    value[position] = bad
    with raises_naming(field):
        AtmosphereParameters(**{field: tuple(value)})


@pytest.mark.parametrize("value", [1e-5, (1e-5, 1e-5), (1e-5,) * 4, ((1e-5, 1e-5, 1e-5),), np.zeros((3, 1)),
                                   ()])
@pytest.mark.parametrize("field", RGB_FIELDS)
def test_rgb_of_wrong_shape_raises_naming_the_field(field, value):
    with raises_naming(field):
        AtmosphereParameters(**{field: value})


@pytest.mark.parametrize("value", [True, False, np.True_, [1.0], (1.0, 2.0), np.array([1.0]), np.array(1.0),
                                   None])
@pytest.mark.parametrize("field", SCALAR_FIELDS)
def test_scalar_of_wrong_type_raises_naming_the_field(field, value):
    """bool is an int subclass, but True must not pass as 1.0 (nor arrays/sequences as scalars)."""
    with raises_naming(field):
        AtmosphereParameters(**{field: value})


def test_numpy_scalars_are_accepted_and_stored_as_float():
    atmosphere = AtmosphereParameters(planet_radius=np.float32(6.0e6), top_radius=np.int64(6_100_000),
                                      exposure=np.float64(2.0))
    assert type(atmosphere.planet_radius) is float and atmosphere.planet_radius == 6.0e6
    assert type(atmosphere.top_radius) is float and atmosphere.top_radius == 6.1e6
    assert all(type(v) is float for v in atmosphere.rayleigh_scattering)


# Validation gaps found while writing these tests (fixed since): each case is invalid, and was
# accepted or rejected with a message that did not name the field.
@pytest.mark.parametrize("field", RGB_FIELDS)
def test_bool_inside_rgb_raises_naming_the_field(field):
    with raises_naming(field):
        AtmosphereParameters(**{field: (True, 1.0, 1.0)})


@pytest.mark.parametrize("field", SCALAR_FIELDS)
def test_string_scalar_raises_naming_the_field(field):
    with raises_naming(field):
        AtmosphereParameters(**{field: str(getattr(AtmosphereParameters(), field))})


@pytest.mark.parametrize("value", [((1.0, 2.0), (3.0,), 4.0), ("a", "b", "c"), "abc"])
def test_unconvertible_rgb_raises_naming_the_field(value):
    with raises_naming("rayleigh_scattering"):
        AtmosphereParameters(rayleigh_scattering=value)


@pytest.mark.parametrize("field, value", [
    ("rayleigh_phase", "Rayleigh"),
    ("rayleigh_phase", "modified"),
    ("rayleigh_phase", "cornette_shanks"),
    ("rayleigh_phase", ""),
    ("rayleigh_phase", None),
    ("mie_phase", "henyey_greenstein"),
    ("mie_phase", "rayleigh"),
    ("mie_phase", None),
])
def test_unknown_phase_name_raises_naming_the_field(field, value):
    with raises_naming(field):
        AtmosphereParameters(**{field: value})


def test_unknown_preset_lists_the_names():
    with pytest.raises(ValueError, match=r"preset.*atmosphere-plus.*physical"):
        preset("earth")


def test_from_dict_rejects_unknown_fields():
    data = AtmosphereParameters().to_dict()
    data["ozone"] = 1.0
    with pytest.raises(ValueError, match="ozone"):
        AtmosphereParameters.from_dict(data)


def test_replace_validates_again():
    with raises_naming("top_radius"):
        AtmosphereParameters().replace(top_radius=1.0)


# Presets and published constants -----------------------------------------------------------------

def test_presets_differ_only_in_the_rayleigh_phase_ozone_and_ground():
    artistic = preset("atmosphere-plus").replace(ozone_column_du=300.0, ground_albedo=0.1).to_dict()
    physical = preset("physical").to_dict()
    assert artistic.pop("rayleigh_phase") == "modified_atmosphereplus"
    assert physical.pop("rayleigh_phase") == "rayleigh"
    assert artistic == physical
    assert preset("physical").ozone_column_du == 300.0 and preset("atmosphere-plus").ozone_column_du == 0.0
    assert preset("physical").ground_albedo == EARTH_GROUND_ALBEDO == 0.1
    assert preset("atmosphere-plus").ground_albedo == 0.0
    assert set(PRESETS) == {"atmosphere-plus", "physical"}
    assert preset("atmosphere-plus") == AtmosphereParameters()


def test_default_constants_match_physics_md():
    atmosphere = preset("atmosphere-plus")
    assert atmosphere.planet_radius == 6_371_000.0
    assert atmosphere.top_radius == 6_471_000.0
    assert atmosphere.atmosphere_height == 100_000.0
    assert atmosphere.rayleigh_scale_height == 8000.0
    assert atmosphere.mie_scale_height == 1200.0
    assert atmosphere.mie_scattering == 2e-6
    assert atmosphere.mie_g == -0.85
    assert atmosphere.wavelengths == (650.0, 510.0, 475.0)
    # beta_M^e = beta_M / 0.9; one division, so exact to 1 ulp
    assert_allclose(atmosphere.mie_extinction, 2e-6 / 0.9, rtol=2e-16, atol=0)


def test_rayleigh_coefficient_matches_the_printed_values():
    """beta_R = 8 pi^3 (n^2 - 1)^2 / (3 N lambda^4) with N = 2.545e25 (physics.md)."""
    beta = rayleigh_scattering_coefficient(1.0003, 2.545e25, (650, 510, 475))
    printed = np.array([6.554e-6, 1.7293e-5, 2.2982e-5])
    # The printed values carry 4-5 significant digits, i.e. they are rounded to 1e-9 1/m: the exact
    # value is within half a unit of that digit (5e-10), i.e. < 1e-4 relative (7.6e-5 for 6.554e-6).
    assert_allclose(beta, printed, rtol=0, atol=0.5e-9)
    assert_allclose(beta, printed, rtol=1e-4, atol=0)
    # Independent check of the formula itself, term by term (float64 rounding only: 1e-14).
    expected = [8 * math.pi**3 * (1.0003**2 - 1) ** 2 / (3 * 2.545e25 * (lam * 1e-9) ** 4)
                for lam in (650, 510, 475)]
    assert_allclose(beta, expected, rtol=1e-14, atol=0)


def test_transposed_number_density_would_not_reproduce_the_notes():
    """physics.md: N = 2.454e25 is a typo; it gives beta_R ~3.7% too large."""
    wrong = rayleigh_scattering_coefficient(1.0003, 2.454e25, (650, 510, 475))
    assert np.all(np.abs(wrong / np.array([6.554e-6, 1.7293e-5, 2.2982e-5]) - 1) > 0.03)


def test_preset_beta_rayleigh_is_the_formula_rounded_to_three_digits():
    """The preset stores (6.55e-6, 1.73e-5, 2.30e-5): the formula rounded to 3 significant digits."""
    exact = rayleigh_scattering_coefficient(1.0003, 2.545e25, (650, 510, 475))
    stored = np.array(preset("atmosphere-plus").rayleigh_scattering)
    half_unit_of_third_digit = 0.5 * 10.0 ** (np.floor(np.log10(exact)) - 2)   # 5e-9, 5e-8, 5e-8
    assert np.all(np.abs(stored - exact) <= half_unit_of_third_digit), (stored, exact)
    assert_allclose(stored, [6.55e-6, 1.73e-5, 2.30e-5], rtol=0, atol=0)
    # and from_refractive_index gives the unrounded coefficients
    derived = AtmosphereParameters.from_refractive_index()
    assert_allclose(derived.rayleigh_scattering, exact, rtol=1e-15, atol=0)


def test_incident_light_is_the_product_of_the_printed_factors():
    light = preset("atmosphere-plus").incident_light
    # The product itself: irradiance * exposure * spectral-to-RGB, 2 roundings (<= 2.2e-16 each).
    factors = np.array([0.1526, 0.191, 0.208]) * 1.0 * np.array([133.3209, 88.51855, 112.7552])
    assert_allclose(light, factors, rtol=5e-16, atol=0)
    # Against the figures printed in physics.md, the products (20.34476934, 16.90704305, 23.4530816)
    # rounded to 6 decimals: within half a unit of the last printed digit (it printed 20.344770, 16.907042
    # and 23.453083 until 2026-12-07, each one unit off in that digit).
    assert_allclose(light, [20.344769, 16.907043, 23.453082], rtol=0, atol=0.5e-6)
    assert_allclose(preset("physical").incident_light, light, rtol=0, atol=0)


def test_incident_light_scales_with_exposure():
    base = AtmosphereParameters()
    assert_allclose(base.replace(exposure=2.5).incident_light, 2.5 * base.incident_light, rtol=1e-15, atol=0)


# Identity: digest, dict round trip, immutability -------------------------------------------------

def _changed_value(field, value):
    """A different valid value of ``field``."""
    if isinstance(value, tuple):
        return tuple(v * 1.5 for v in value)
    if field == "rayleigh_phase":
        return "rayleigh" if value != "rayleigh" else "modified_atmosphereplus"
    if field == "mie_phase":
        others = sorted(set(MIE_PHASE_METHODS) - {value})
        return others[0] if others else None     # today only one Mie phase exists
    if field in ("mie_g",):
        return value / 2
    if field == "mie_extinction_ratio":
        return 0.5
    if field == "top_radius":
        return value + 1.0
    if field == "planet_radius":
        return value - 1.0
    if field == "ozone_column_du":     # 0 by default
        return value + 300.0
    if field == "mie_angstrom_exponent":     # 0 by default
        return value + 1.3
    if field == "ground_albedo":       # 0 (black) by default
        return value + 0.3
    return value * 1.25


def test_digest_is_stable():
    first = AtmosphereParameters().digest()
    assert first == AtmosphereParameters().digest()
    assert first == AtmosphereParameters.from_dict(AtmosphereParameters().to_dict()).digest()
    assert re.fullmatch(r"[0-9a-f]{64}", first)
    # same values given as ints/lists instead of floats/tuples: same canonical JSON, same digest
    assert AtmosphereParameters(planet_radius=6_371_000, rayleigh_scattering=[6.55e-6, 1.73e-5, 2.30e-5]
                                ).digest() == first


@pytest.mark.parametrize("field", [f.name for f in dataclasses.fields(AtmosphereParameters)])
def test_digest_changes_with_every_field(field):
    base = AtmosphereParameters()
    new_value = _changed_value(field, getattr(base, field))
    if new_value is None:
        pytest.skip(f"{field} has a single valid value")
    changed = base.replace(**{field: new_value})
    assert changed != base
    assert changed.digest() != base.digest()


@pytest.mark.parametrize("position", [0, 1, 2])
def test_digest_changes_with_each_rgb_component(position):
    base = AtmosphereParameters()
    value = list(base.rayleigh_scattering)
    value[position] = np.nextafter(value[position], 1.0)     # one ulp is enough
    assert base.replace(rayleigh_scattering=tuple(value)).digest() != base.digest()


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_dict_round_trip(name):
    original = preset(name)
    data = original.to_dict()
    assert json.loads(json.dumps(data)) == data        # plain JSON types only
    restored = AtmosphereParameters.from_dict(json.loads(json.dumps(data)))
    assert restored == original
    assert restored.digest() == original.digest()


def test_parameters_are_immutable():
    atmosphere = AtmosphereParameters()
    with pytest.raises(dataclasses.FrozenInstanceError):
        atmosphere.planet_radius = 1.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        atmosphere.rayleigh_phase = "rayleigh"
    assert isinstance(atmosphere.rayleigh_scattering, tuple)      # no mutable list inside
    assert hash(atmosphere) == hash(AtmosphereParameters())


# TableSettings -----------------------------------------------------------------------------------

def test_table_settings_defaults():
    settings = TableSettings()
    assert settings.size == (32, 256, 32)
    assert (settings.view_steps, settings.sun_steps) == (30, 30)
    assert settings.mapping == "nonlinear"
    assert settings.dtype == "float64"
    assert settings.channels == 6
    assert TableSettings(mie_layout="notes").channels == 4


@pytest.mark.parametrize("field, value, named", [
    ("size", (32, 256), "size"),
    ("size", (32, 256, 32, 4), "size"),
    ("size", 32, "size"),
    ("size", None, "size"),
    ("size", (1, 256, 32), "size[0]"),
    ("size", (32, 0, 32), "size[1]"),
    ("size", (32, 256, -4), "size[2]"),
    ("size", (32, 4097, 32), "size[1]"),
    ("size", (32.0, 256, 32), "size[0]"),
    ("size", (32, True, 32), "size[1]"),
    ("size", (32, 256, "32"), "size[2]"),
    ("size", (4096, 4096, 4096), "size"),      # every axis valid, too many cells for int32 indices
    ("transmittance_size", (64,), "transmittance_size"),
    ("transmittance_size", (64, 256, 1), "transmittance_size"),
    ("transmittance_size", (1, 256), "transmittance_size[0]"),
    ("transmittance_size", (64, 5000), "transmittance_size[1]"),
    ("transmittance_size", (64.5, 256), "transmittance_size[0]"),
    ("view_steps", 0, "view_steps"),
    ("view_steps", -30, "view_steps"),
    ("view_steps", 4097, "view_steps"),
    ("view_steps", 30.0, "view_steps"),
    ("view_steps", True, "view_steps"),
    ("view_steps", "30", "view_steps"),
    ("sun_steps", 0, "sun_steps"),
    ("sun_steps", 10_000, "sun_steps"),
    ("sun_steps", 2.5, "sun_steps"),
    ("sun_steps", np.True_, "sun_steps"),
    ("mapping", "log", "mapping"),
    ("mapping", "Linear", "mapping"),
    ("mapping", None, "mapping"),
    ("sampling", "keller-bohn", "sampling"),
    ("sampling", "gauss", "sampling"),
    ("sun_transmittance", "lut", "sun_transmittance"),
    ("sun_transmittance", None, "sun_transmittance"),
    ("mie_layout", "per_wavelength", "mie_layout"),
    ("mie_layout", 4, "mie_layout"),
    ("dtype", "float16", "dtype"),
    ("dtype", "int32", "dtype"),
    ("dtype", "double-ish", "dtype"),
    ("dtype", np.complex128, "dtype"),
    ("sun_cos_range", (0.5, 0.5), "sun_cos_range"),          # empty
    ("sun_cos_range", (0.5, -0.5), "sun_cos_range"),         # reversed
    ("sun_cos_range", (-1.5, 0.5), "sun_cos_range"),         # beyond a cosine's range
    ("sun_cos_range", (0.0, 0.0005), "sun_cos_range"),       # narrower than 1e-3
    ("sun_cos_range", (float("nan"), 0.5), "sun_cos_range"),
    ("sun_cos_range", (0.1,), "sun_cos_range"),
    ("sun_cos_range", "ab", "sun_cos_range"),
    ("sun_cos_range", None, "sun_cos_range"),
])
def test_invalid_table_settings_raise_naming_the_field(field, value, named):
    with raises_naming(named):
        TableSettings(**{field: value})


def test_dtype_none_raises_naming_the_field():
    with raises_naming("dtype"):
        TableSettings(dtype=None)


@pytest.mark.parametrize("value, expected", [("float32", "float32"), (np.float32, "float32"), ("f8", "float64"),
                                             (np.dtype("float64"), "float64")])
def test_table_settings_dtype_is_normalised(value, expected):
    assert TableSettings(dtype=value).dtype == expected


def test_table_settings_edge_sizes_are_accepted():
    assert TableSettings(size=(2, 2, 2), transmittance_size=(2, 4096)).size == (2, 2, 2)
    assert TableSettings(size=np.array([4, 5, 6])).size == (4, 5, 6)
    assert type(TableSettings(size=np.array([4, 5, 6])).size[0]) is int
    assert TableSettings(view_steps=1, sun_steps=4096).sun_steps == 4096
    assert TableSettings(sun_cos_range=np.array([-1, 1])).sun_cos_range == (-1.0, 1.0)
    assert TableSettings(sun_cos_range=(0.2, 0.201)).sun_w_range[1] > TableSettings(sun_cos_range=(0.2, 0.201)).sun_w_range[0]


def test_table_settings_round_trip_and_immutability():
    settings = TableSettings(size=(9, 33, 7), sampling="keller_bohn", dtype="float32", sun_cos_range=(-0.3, 0.5))
    data = settings.to_dict()
    assert json.loads(json.dumps(data)) == data
    assert TableSettings.from_dict(data) == settings
    with pytest.raises(ValueError, match="resolution"):
        TableSettings.from_dict({**data, "resolution": 3})
    with pytest.raises(dataclasses.FrozenInstanceError):
        settings.view_steps = 3
    with raises_naming("view_steps"):
        settings.replace(view_steps=0)


@pytest.mark.parametrize("options, message", [
    (dict(number_density=-2.5e25), r"^number_density must be a finite number > 0 1/m\^3, got -2.5e\+25$"),
    (dict(number_density=0), r"^number_density must be a finite number > 0"),
    (dict(refractive_index=float("nan")), r"^refractive_index must be a finite real number, got nan$"),
    (dict(refractive_index="1.0003"), r"^refractive_index must be a finite real number"),
])
def test_spectral_batches_name_the_air_parameters(options, message):
    """batch_atmospheres named rayleigh_scattering, a field its caller never typed, for a bad refractive index
    or number density (or raised TypeError): the coefficient's own check names them, as
    from_refractive_index's did."""
    from clsky.spectrum import batch_atmospheres

    with pytest.raises(ValueError, match=message):
        batch_atmospheres(preset("physical"), 12, **options)


def test_the_rayleigh_coefficient_refuses_no_wavelength():
    """0 nm gave an infinite coefficient."""
    from clsky.atmosphere import rayleigh_scattering_coefficient

    with pytest.raises(ValueError, match=r"^wavelengths_nm must be finite wavelengths > 0 nm"):
        rayleigh_scattering_coefficient(1.0003, 2.5e25, (0.0, 510.0, 475.0))
