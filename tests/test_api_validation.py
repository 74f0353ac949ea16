"""Issue 9, class 7: the API raises the documented ValueError, at construction, and takes NumPy scalars
wherever it takes numbers."""

import datetime
import re

import numpy as np
import pytest

from clsky.anim.animate import AnimationConfig, quality
from clsky import AtmosphereParameters, ScatteringTable, TableSettings
from clsky.errors import ParameterError
from clsky.planner import Scene
from clsky.quality import level_for_budget

from conftest import black_preset


@pytest.fixture(scope="module")
def table():
    return ScatteringTable.build(black_preset("physical"), TableSettings(size=(4, 8, 4), mode="physical", orders=2),
                                 backend="numpy")


@pytest.mark.parametrize("position,name", [(0, "altitude"), (1, "cos_view"), (2, "cos_sun"), (3, "cos_scatter")])
@pytest.mark.parametrize("bad", ["a", [0.5, "x"], None, 1j, True])
def test_radiance_refuses_non_numbers_naming_the_query(table, position, name, bad):
    queries = [10.0, 0.5, 0.5, 0.5]
    queries[position] = bad
    with pytest.raises(ValueError, match=f"^{name} must be"):
        table.radiance(*queries, backend="numpy")


def test_radiance_takes_numpy_scalars(table):
    expected = table.radiance(10.0, 0.5, 0.5, 0.5, backend="numpy")
    got = table.radiance(np.float32(10.0), np.float64(0.5), np.float32(0.5), np.float64(0.5), backend="numpy")
    np.testing.assert_allclose(got, expected, rtol=1e-7)


@pytest.mark.parametrize("bad,name", [("1.0003", "refractive_index"), (None, "refractive_index"),
                                      (0.5, "refractive_index"), (float("nan"), "refractive_index")])
def test_from_refractive_index_refuses_bad_index(bad, name):
    with pytest.raises(ValueError, match=f"^{name} must be"):
        AtmosphereParameters.from_refractive_index(bad)


def test_from_refractive_index_checks_density_and_wavelengths():
    with pytest.raises(ValueError, match="^number_density must be"):
        AtmosphereParameters.from_refractive_index(1.0003, "2.5e25")
    with pytest.raises(ValueError, match="^wavelengths must be"):
        AtmosphereParameters.from_refractive_index(1.0003, 2.545e25, (650.0, 510.0))
    beta = AtmosphereParameters.from_refractive_index(np.float32(1.0003), np.float64(2.545e25)).rayleigh_scattering
    assert all(isinstance(b, float) for b in beta)


NUMERIC_FIELDS = {   # AnimationConfig field -> a valid value
    "frames": 4, "size": 32, "fov_deg": 60.0, "heading_deg": 90.0, "pitch_deg": 5.0, "altitude": 10.0,
    "error_budget": 0.5, "samples": 16, "start_elevation_deg": -5.0, "max_elevation_deg": 50.0,
    "start_hour": 1.0, "end_hour": 20.0, "step_minutes": 5.0, "fps": 24.0, "exposure": 2.0,
}
INTEGER_FIELDS = {"frames", "size", "samples"}


@pytest.mark.parametrize("field", sorted(NUMERIC_FIELDS))
def test_animation_config_takes_numpy_scalars(field):
    value = NUMERIC_FIELDS[field]
    kinds = (np.int64, np.int32) if field in INTEGER_FIELDS else (np.float32, np.float64)
    if field not in INTEGER_FIELDS and float(value).is_integer():
        kinds += (np.int64,)
    for kind in kinds:
        config = AnimationConfig(**{field: kind(value)})
        stored = getattr(config, field)
        assert type(stored) is (int if field in INTEGER_FIELDS else float) and stored == pytest.approx(value)


@pytest.mark.parametrize("field", sorted(NUMERIC_FIELDS))
@pytest.mark.parametrize("bad", ["1", True, [1.0], float("nan")])
def test_animation_config_refuses_wrong_types_at_construction(field, bad):
    with pytest.raises(ParameterError) as caught:
        AnimationConfig(**{field: bad})
    assert caught.value.field == field


def test_animation_config_float_budget_is_used_later():
    """The issue's example: np.float32(0.5) was accepted, then refused by the planner."""
    config = AnimationConfig(error_budget=np.float32(0.5))
    assert quality(config).name == "draft"
    assert level_for_budget(np.float32(0.5)).name == "draft"
    Scene(sun_elevations_deg=(np.float32(-5.0), np.int64(30)), error_budget=np.float32(0.5))


def test_animation_config_date():
    assert AnimationConfig(date="2026-01-01").date == datetime.date(2026, 1, 1)
    assert AnimationConfig(date=datetime.datetime(2026, 1, 1, 12)).date == datetime.date(2026, 1, 1)
    for bad in ("01/01/2026", 20260101, "2026-13-01"):
        with pytest.raises(ValueError, match="^date must be"):
            AnimationConfig(date=bad)
    # real positions need pvlib's Delta T (the years -1999 to 3000); the sweep reads no date
    for date, end_hour in (("9999-12-31", 24.0), ("3001-01-01", 1.0), ("3000-12-31", 24.0), ("3000-12-30", 48.0)):
        with pytest.raises(ParameterError, match="^date must be a day whose frames, to .* h UTC, fall in the years 1 "
                                                 "to 3000") as caught:
            AnimationConfig(location=(45.0, 5.0), date=date, end_hour=end_hour)
        assert caught.value.value == date
    assert AnimationConfig(location=(45.0, 5.0), date="3000-12-31", end_hour=23.5).date.year == 3000
    assert AnimationConfig(location=(45.0, 5.0), date="0001-01-01").date.year == 1
    assert AnimationConfig(date="9999-12-31").date.year == 9999


def test_animation_config_tuple_fields():
    config = AnimationConfig(table_size=np.array([4, 8, 4]), location=[45.0, np.float32(5.0)])
    assert config.table_size == (4, 8, 4) and config.location == (45.0, 5.0)
    with pytest.raises(ParameterError) as caught:
        AnimationConfig(table_size=(4, 8, 1))
    assert (caught.value.field, caught.value.index) == ("table_size", 2)
    for bad in ((45.0,), ("45", "5"), 45.0, (100.0, 0.0)):
        with pytest.raises(ValueError, match="^location must be"):
            AnimationConfig(location=bad)


@pytest.mark.parametrize("field,bad", [("camera", 1), ("method", None), ("preset", "venus"), ("mode", 3),
                                       ("quality", ["draft"]), ("dither", 1), ("hdr", "yes"), ("output", 3)])
def test_animation_config_other_fields(field, bad):
    with pytest.raises(ParameterError, match=f"^{field} must be"):
        AnimationConfig(**{field: bad})


def test_table_settings_and_scene_take_numpy_and_refuse_strings():
    settings = TableSettings(size=np.array([4, 8, 4]), view_steps=np.int64(10), order_tolerance=np.float32(1e-3),
                             sun_cos_range=np.array([-0.5, 0.5]))
    assert settings.size == (4, 8, 4) and type(settings.view_steps) is int
    with pytest.raises(ValueError, match="^sun_cos_range must be"):
        TableSettings(sun_cos_range=("-0.5", "0.5"))
    with pytest.raises(ValueError, match="^sun_elevations_deg must be"):
        Scene(sun_elevations_deg=("1", "2"))
    with pytest.raises(ValueError, match="^order_tolerance must be"):
        TableSettings(order_tolerance="0.1")


@pytest.mark.parametrize("arguments, message", [
    (("physical", "x"), "settings must be a TableSettings or None (the atmosphere's default), got 'x' (str)"),
    ((42,), "atmosphere must be an AtmosphereParameters or a preset name ['atmosphere-plus', 'physical'], "
            "got 42 (int)"),
    ((None,), "atmosphere must be an AtmosphereParameters or a preset name"),
    (("physical", None, "numpy", None, False, 3), "progress must be None or a callable progress(stage, done, total), "
                                                   "got 3 (int)"),
])
def test_build_refuses_wrong_types_naming_the_parameter(arguments, message):
    """Before: AttributeError ('str' object has no attribute 'is_4d') deep in the build."""
    with pytest.raises(ValueError, match=re.escape(message)):
        ScatteringTable.build(*arguments)


@pytest.mark.parametrize("arguments, message", [
    (("x",), "table must be a ScatteringTable (ScatteringTable.build or .load), got 'x' (str)"),
    ((None,), "table must be a ScatteringTable"),
    (("table", "y"), "ray_settings must be a TableSettings or None (the ray march's defaults), got 'y' (str)"),
])
def test_renderer_refuses_wrong_types_naming_the_parameter(table, arguments, message):
    """Before: AttributeError ('str' object has no attribute 'validate'), before any device work."""
    from clsky.render import SkyRenderer

    arguments = tuple(table if argument == "table" else argument for argument in arguments)
    with pytest.raises(ValueError, match=re.escape(message)):
        SkyRenderer(*arguments)


# Inputs a probe of the API found unchecked (2026-12-07): each ended in AttributeError, TypeError or
# IndexError deep inside, or was silently taken for something else.
def _renderer(table):
    from clsky.render import SkyRenderer

    return SkyRenderer(table)


@pytest.mark.parametrize("call, message", [
    (lambda t: _renderer(t).skyview_map((0.0, 0.0, 1.0), settings=(32, 64)),
     "settings must be None (the defaults) or a SkyViewSettings, got (32, 64) (tuple)"),
    (lambda t: _renderer(t).render_skyview(np.array([[0.0, 0.0, 1.0]]), (0.0, 0.0, 1.0), settings="x"),
     "settings must be None (the defaults) or a SkyViewSettings, got 'x' (str)"),
    (lambda t: _renderer(t).render_raymarch_suns(np.array([[0.0, 0.0, 1.0]]), None),
     "sun_directions must be a sequence of sun directions of 3 values each, got None (NoneType)"),
    (lambda t: _renderer(t).skyview_maps(5), "sun_directions must be a sequence of sun directions"),
    (lambda t: _renderer(t).view_zenith_angles(np.zeros((2, 3))), "directions must be directions prepared by prepare()"),
    (lambda t: _renderer(t).prepare(np.array([[0.0, 0.0, 1.0]] * 2), valid=[np.nan, 1.0]),   # NaN read as True
     "valid must be a mask of bools (or of 0 and 1)"),
    (lambda t: _renderer(t).prepare(np.array([[0.0, 0.0, 1.0]] * 2), valid=[None, None]),    # None as False
     "valid must be a mask of bools (or of 0 and 1)"),
    (lambda t: t.radiance(0.0, 0.5, 0.5, 0.5, engine="x"), "engine must be None or a TableLookupEngine"),
    (lambda t: t.save(None), "path must be a file path (a str or os.PathLike), got None (NoneType)"),
    (lambda t: t.save("a\0b.npz"), "path must not hold a NUL character"),
    (lambda t: t.save("x.npz", staging="x"), "staging must be None or a StagedWrites, got 'x' (str)"),
    (lambda t: ScatteringTable.load(5), "path must be a file path (a str or os.PathLike), got 5 (int)"),
    (lambda t: ScatteringTable.load(""), "path must be a file path, got an empty one"),   # pathlib: '.'
    (lambda t: t.save("x.npz", overwrite="yes"), "overwrite must be True or False, got 'yes' (str)"),
    (lambda t: ScatteringTable.build(t.atmosphere, t.settings, ctx="x"),
     "ctx must be None (clsky's device) or a pyopencl.Context, got 'x' (str)"),
])
def test_wrong_types_are_named(table, tmp_path, monkeypatch, call, message):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ValueError, match=re.escape(message)):
        call(table)
    assert not list(tmp_path.iterdir())                         # nothing written


@pytest.mark.parametrize("flag", ["no", 0, None, "False"])
def test_fast_math_takes_only_a_bool(flag):
    """``fast_math='no'`` turned fast math on (bool('no') is True), and the table said so in its metadata."""
    with pytest.raises(ValueError, match=re.escape("fast_math must be True or False, got")):
        ScatteringTable.build("atmosphere-plus", TableSettings(size=(4, 8, 4), orders=1), fast_math=flag)


@pytest.mark.parametrize("call, message", [
    (lambda: Scene(sun_elevations_deg=(0, 10), components=None), "components must be a subset of"),
    (lambda: AtmosphereParameters.from_dict(None), "an atmosphere's fields must be a dict, got None (NoneType)"),
    (lambda: TableSettings.from_dict([1]), "table settings must be a dict, got [1] (list)"),
    (lambda: __import__("clsky").preset([]), "preset must be one of ['atmosphere-plus', 'physical'], got []"),
    (lambda: __import__("clsky.solar").solar.with_solar_spectrum(None), "atmosphere must be an AtmosphereParameters"),
    (lambda: __import__("clsky.spectrum").spectrum.batch_atmospheres(None, 3), "base must be an AtmosphereParameters"),
    (lambda: __import__("clsky.spectrum").spectrum.SpectralRenderer(None), "spectral_table must be a SpectralTable"),
    (lambda: __import__("clsky.planner").planner.plan_scene("scene"), "scene must be a Scene"),
    (lambda: __import__("clsky.planner").planner.plan_scene(Scene(sun_elevations_deg=(0, 10)), mode="x"),
     "mode must be one of ['atmosphere-plus', 'physical'], got 'x'"),
    # twilight.ray_march checked its views after 11 s of planning and building, and named Scene's field
    (lambda: __import__("clsky.twilight").twilight.ray_march(None, -4.0, views=["zenith", "nope"]),
     "view must be one of ['zenith', 'toward', 'across', 'away'], got 'nope'"),
    (lambda: __import__("clsky.twilight").twilight.ray_march(None, -4.0, views="zenith"),
     "views must be None or a list of names of"),
    (lambda: __import__("clsky.twilight").twilight.ray_march(None, 95.0),
     "sun_elevation_deg must be a sun elevation in [-90, 90] deg, got 95"),
    (lambda: __import__("clsky.twilight").twilight.ray_march(None, -4.0, quality="draft", azimuth_harmonics=17),
     "azimuth_harmonics must be at most gather_phi_steps / 2 = 16 (each harmonic sampled twice a period by the "
     "gather), got 17"),                # after the plan's pilot
    (lambda: __import__("clsky.planner").planner.plan_scene(Scene(sun_elevations_deg=(40, 60)), ray_march="no"),
     "ray_march must be True or False, got 'no' (str)"),                  # was true
    (lambda: __import__("clsky.planner").planner.plan_scene(Scene(sun_elevations_deg=(40, 60)), ctx="gpu"),
     "ctx must be None (clsky's device) or a pyopencl.Context"),          # was an AttributeError
])
def test_more_wrong_types_are_named(call, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        call()


@pytest.mark.parametrize("arguments, message", [
    (dict(config={"frames": 2}), "config must be an AnimationConfig, got {'frames': 2} (dict)"),
    (dict(farm="x"), "farm must be None or a clsky.farm.Farm (started), got 'x' (str)"),
    (dict(report=5), "report must be None or a callable, got 5"),
    (dict(progress="bar"), "progress must be None or a callable, got 'bar'"),
    (dict(ctx="x"), "ctx must be None (clsky's device) or a pyopencl.Context, got 'x' (str)"),
])
def test_render_animation_refuses_wrong_arguments_before_any_work(tmp_path, arguments, message):
    """A dict for the configuration was an AttributeError, farm='x' an AttributeError after the table's
    build (3.6 s), report=5 a TypeError after the scene plan; each is refused first, nothing written."""
    from clsky.anim.animate import render_animation

    config = AnimationConfig(frames=2, size=16, quality="draft", output=str(tmp_path / "x.mp4"))
    with pytest.raises(ValueError, match=re.escape(message)):
        render_animation(**{"config": config, **arguments})
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("arguments, message", [
    (dict(positions=[]), "positions must be None or a non-empty list of clsky.anim.sunpath.SunPosition, got []"),
    (dict(positions=[1, 2]), "positions must be None or a non-empty list"),
    (dict(ctx="x"), "ctx must be None"),
])
def test_planned_animation_refuses_wrong_arguments(arguments, message):
    from clsky.anim.animate import planned_animation

    with pytest.raises(ValueError, match=re.escape(message)):
        planned_animation(AnimationConfig(frames=2, size=16, quality="draft"), **arguments)


def test_a_plan_the_build_would_refuse_is_refused_first():
    """plan_scene(scene, mode='atmosphere-plus') planned the physical preset's reflecting ground (its default
    atmosphere), a table the build then refused: now the plan refuses it, before the pilot's build."""
    from clsky.planner import plan_scene

    with pytest.raises(ValueError, match=r"^ground_albedo must be 0 with mode 'atmosphere-plus'"):
        plan_scene(Scene(sun_elevations_deg=(0, 10), components=("rayleigh", "mie")), mode="atmosphere-plus")


def test_angstrom_factor_that_overflows_names_the_wavelengths():
    """A wavelength of 1e-300 nm with an Angstrom exponent of 4 overflowed to inf, and 0 * inf made the Mie
    coefficient NaN, which the optical-depth check let through (NaN > 1000 is false)."""
    with pytest.raises(ValueError, match=r"^wavelengths must be such that the Angstrom law's factor"):
        AtmosphereParameters(wavelengths=(1e-300, 510, 475), mie_angstrom_exponent=4.0, mie_scattering=0.0)


def test_an_incident_light_that_would_render_infinities_is_refused():
    """An exposure and irradiance of 1e300 each (finite, > 0: valid before) rendered every pixel infinite:
    the incident light, their product, is at most 1e12 per channel."""
    with pytest.raises(ValueError, match=r"^exposure must be such that the incident light I_I = .* at most 1e\+12"):
        AtmosphereParameters(exposure=1e300, solar_irradiance=(1e300, 1e300, 1e300))
    bright = AtmosphereParameters(exposure=1e6, solar_irradiance=(2.0, 2.0, 2.0))     # far below the bound
    np.testing.assert_allclose(bright.incident_light, 1e6 * bright.replace(exposure=1.0).incident_light, rtol=1e-15)
