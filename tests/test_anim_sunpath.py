"""clsky.anim.sunpath: the synthetic sunrise-to-sunset sweep and the real sun from pvlib's NREL SPA."""

from __future__ import annotations

import dataclasses
import datetime
import math
import sys
import warnings
import zoneinfo

import numpy as np
import pytest
from numpy.testing import assert_allclose

from clsky.anim.cameras import sun_direction
from clsky.anim.sunpath import MAX_POSITIONS, SunPosition, real_positions, sweep

UTC = datetime.timezone.utc


def elevations(path):
    return np.array([p.elevation_deg for p in path])


def azimuths(path):
    return np.array([p.azimuth_deg for p in path])


# SunPosition --------------------------------------------------------------------------------------

def test_sun_position():
    sun = SunPosition(zenith_deg=60.0, azimuth_deg=180.0)
    assert sun.elevation_deg == 30.0 and sun.time is None
    assert_allclose(sun.direction, sun_direction(60.0, 180.0), rtol=0, atol=0)
    assert_allclose(sun.direction, (0.0, -math.sqrt(3) / 2, 0.5), rtol=0, atol=1e-15)
    with pytest.raises(dataclasses.FrozenInstanceError):
        sun.zenith_deg = 10.0
    for kwargs, parameter in [(dict(zenith_deg=-1.0, azimuth_deg=0.0), "zenith_deg"),
                              (dict(zenith_deg=181.0, azimuth_deg=0.0), "zenith_deg"),
                              (dict(zenith_deg=math.nan, azimuth_deg=0.0), "zenith_deg"),
                              (dict(zenith_deg=10.0, azimuth_deg=math.inf), "azimuth_deg"),
                              (dict(zenith_deg=10.0, azimuth_deg=0.0, time="noon"), "time")]:
        with pytest.raises(ValueError, match=parameter):
            SunPosition(**kwargs)


# Sweep --------------------------------------------------------------------------------------------

#: The sweep's end points and peak are exact by construction (sin(0) = 0, sin(pi / 2) = 1); the
#: elevation goes through zenith = 90 - e and back, which may round by an ulp of 90.
SWEEP_ATOL_DEG = 1e-13


def test_sweep_defaults():
    path = sweep()
    assert len(path) == 120 and all(isinstance(p, SunPosition) and p.time is None for p in path)
    e, a = elevations(path), azimuths(path)
    assert abs(e[0] + 6.0) <= SWEEP_ATOL_DEG and abs(e[-1] + 6.0) <= SWEEP_ATOL_DEG
    assert a[0] == 90.0 and a[-1] == 270.0
    assert np.all(np.diff(a) > 0)
    # Even frames: no frame at s = 0.5; the two middle frames straddle the peak symmetrically.
    assert abs(e[59] - e[60]) <= SWEEP_ATOL_DEG and e[59] < 60.0
    assert e.argmax() in (59, 60)
    assert a[59] < 180.0 < a[60]


@pytest.mark.parametrize("frames", [3, 61, 121])
@pytest.mark.parametrize("start, peak, end", [(-6.0, 60.0, None), (-10.0, 35.0, 2.0),
                                              (5.0, 5.0, 5.0), (-90.0, 90.0, -90.0)])
def test_sweep_end_points_and_peak(frames, start, peak, end):
    path = sweep(frames=frames, start_elevation_deg=start, max_elevation_deg=peak,
                 end_elevation_deg=end)
    e, a = elevations(path), azimuths(path)
    end = start if end is None else end
    assert len(path) == frames
    assert abs(e[0] - start) <= SWEEP_ATOL_DEG and abs(e[-1] - end) <= SWEEP_ATOL_DEG
    middle = frames // 2                         # odd frames: s = 0.5 exactly
    assert abs(e[middle] - peak) <= SWEEP_ATOL_DEG
    assert e.max() <= peak + SWEEP_ATOL_DEG
    # Rises to the middle, sets after it (strictly unless the arc is flat).
    if peak > start:
        assert np.all(np.diff(e[:middle + 1]) > 0)
    if peak > end:
        assert np.all(np.diff(e[middle:]) < 0)
    # Azimuth: linear from 90 (east) through 180 (south, the middle frame) to 270 (west).
    assert np.all(np.diff(a) > 0)
    assert a[middle] == 180.0
    assert_allclose(a, np.linspace(90.0, 270.0, frames), rtol=0, atol=1e-12)


def test_sweep_arc_formula_and_smoothness():
    frames, start, peak, end = 101, -6.0, 50.0, 4.0
    e = elevations(sweep(frames, start, peak, end))
    s = np.arange(frames) / (frames - 1)
    expected = np.where(s <= 0.5, start + (peak - start) * np.sin(np.pi * s),
                        end + (peak - end) * np.sin(np.pi * s))
    assert_allclose(e, expected, rtol=0, atol=1e-12)   # sin(pi s) vs sin(pi (1 - s)): ulps
    # C^1 at the top: the slope tends to 0 from both sides. Frame steps next to the peak are
    # O(h^2) (h = 1 / 100): (peak - start) (1 - cos(pi h)) = 56 x 4.9e-4 = 0.028 deg, versus
    # pi x 56 x h = 1.8 deg per frame at the start.
    middle = frames // 2
    assert abs(e[middle] - e[middle - 1]) < 0.03 and abs(e[middle] - e[middle + 1]) < 0.03
    assert abs(e[1] - e[0]) > 1.5


def test_sweep_other_azimuths_wrap_into_0_360():
    path = sweep(frames=5, rise_azimuth_deg=60.0, set_azimuth_deg=-60.0)   # through north
    assert_allclose(azimuths(path), [60.0, 30.0, 0.0, 330.0, 300.0], rtol=0, atol=1e-12)


@pytest.mark.parametrize("kwargs, parameter", [
    (dict(frames=1), "frames"), (dict(frames=2.0), "frames"), (dict(frames=True), "frames"),
    (dict(start_elevation_deg=-91.0), "start_elevation_deg"),
    (dict(start_elevation_deg=math.nan), "start_elevation_deg"),
    (dict(max_elevation_deg=90.5), "max_elevation_deg"),
    (dict(end_elevation_deg=-100.0), "end_elevation_deg"),
    (dict(start_elevation_deg=10.0, max_elevation_deg=5.0), "max_elevation_deg"),
    (dict(start_elevation_deg=0.0, max_elevation_deg=5.0, end_elevation_deg=6.0),
     "max_elevation_deg"),
    (dict(rise_azimuth_deg=math.inf), "rise_azimuth_deg"),
    (dict(set_azimuth_deg=math.nan), "set_azimuth_deg"),
    # a probe's: NumPy's "Maximum allowed size exceeded", and NaN azimuths blamed on azimuth_deg
    (dict(frames=10**400), r"frames must be an integer in \[2, 100000\], got 1e\+400"),
    (dict(rise_azimuth_deg=-1.7e308, set_azimuth_deg=1.7e308), r"rise_azimuth_deg must be a number in \[-360, 720\]"),
])
def test_sweep_invalid_parameters(kwargs, parameter):
    with pytest.raises(ValueError, match=parameter):
        sweep(**kwargs)


# Real positions (pvlib NREL SPA) ------------------------------------------------------------------

# Reda & Andreas (2004/2008), NREL/TP-560-34302, Table A5.1: inputs and published results.
SPA_TIME = datetime.datetime(2003, 10, 17, 12, 30, 30, tzinfo=datetime.timezone(-datetime.timedelta(hours=7)))
SPA_LATITUDE, SPA_LONGITUDE, SPA_ELEVATION = 39.742476, -105.1786, 1830.14
SPA_PRESSURE_PA, SPA_TEMPERATURE_C, SPA_DELTA_T_S = 82000.0, 11.0, 67.0
SPA_ZENITH_DEG = 50.11162      # topocentric zenith angle, refracted
SPA_AZIMUTH_DEG = 194.34024    # topocentric azimuth, from north clockwise
#: The published values have 5 decimals (+-5e-6 deg rounding) and SPA's stated uncertainty is
#: +-0.0003 deg; pvlib reproduces the example to ~1e-6. 1e-4 deg tests the inputs, units and columns.
SPA_ATOL_DEG = 1e-4


def spa_refraction_deg(elevation_deg, pressure_mbar, temperature_c):
    """SPA's refraction correction (Reda & Andreas 2004, eq. 42), standard refraction at sunrise."""
    return (pressure_mbar / 1010.0) * (283.0 / (273.0 + temperature_c)) * 1.02 / (
        60.0 * math.tan(math.radians(elevation_deg + 10.3 / (elevation_deg + 5.11))))


def test_pvlib_reproduces_the_spa_report_example():
    pvlib = pytest.importorskip("pvlib")
    pd = pytest.importorskip("pandas")
    table = pvlib.solarposition.get_solarposition(
        pd.DatetimeIndex([SPA_TIME]), SPA_LATITUDE, SPA_LONGITUDE, SPA_ELEVATION,
        pressure=SPA_PRESSURE_PA, temperature=SPA_TEMPERATURE_C, method="nrel_numpy",
        delta_t=SPA_DELTA_T_S)
    apparent, geometric = float(table["apparent_zenith"].iloc[0]), float(table["zenith"].iloc[0])
    assert abs(apparent - SPA_ZENITH_DEG) <= SPA_ATOL_DEG
    assert abs(float(table["azimuth"].iloc[0]) - SPA_AZIMUTH_DEG) <= SPA_ATOL_DEG
    # 'zenith' is the geometric (unrefracted) one: larger than the published refracted value by
    # SPA's refraction at that elevation, pressure and temperature (0.0163 deg here; both sides
    # evaluate the same formula, so only rounding differs).
    refraction = spa_refraction_deg(90.0 - geometric, SPA_PRESSURE_PA / 100.0, SPA_TEMPERATURE_C)
    assert 0.015 < refraction < 0.018
    assert abs(geometric - apparent - refraction) <= 1e-9


def test_real_positions_at_the_spa_report_example():
    pytest.importorskip("pvlib")
    path = real_positions(SPA_LATITUDE, SPA_LONGITUDE, SPA_TIME,
                          SPA_TIME + datetime.timedelta(minutes=1), step_minutes=1.0,
                          altitude_m=SPA_ELEVATION)
    assert len(path) == 2
    sun = path[0]
    assert sun.time == SPA_TIME and sun.time.utcoffset() == datetime.timedelta(hours=-7)
    # Geometric zenith = published refracted zenith + SPA's refraction (820 mbar, 11 C). Tolerance:
    # the publication's rounding and SPA's uncertainty as above; real_positions estimates delta_t
    # (~64.5 s for 2003) instead of the report's 67 s: 2.5 s of the sun's motion along the
    # ecliptic is 2.5 s x 360 deg / 365.25 d = 3e-5 deg.
    refraction = spa_refraction_deg(90.0 - sun.zenith_deg, SPA_PRESSURE_PA / 100.0,
                                    SPA_TEMPERATURE_C)
    assert abs(sun.zenith_deg - (SPA_ZENITH_DEG + refraction)) <= SPA_ATOL_DEG
    assert abs(sun.azimuth_deg - SPA_AZIMUTH_DEG) <= SPA_ATOL_DEG
    assert_allclose(sun.direction, sun_direction(sun.zenith_deg, sun.azimuth_deg), rtol=0, atol=0)


def test_real_positions_june_day_at_48_north():
    pytest.importorskip("pvlib")
    berlin = zoneinfo.ZoneInfo("Europe/Berlin")
    start = datetime.datetime(2024, 6, 21, 0, 0, tzinfo=berlin)
    end = datetime.datetime(2024, 6, 22, 0, 0, tzinfo=berlin)
    path = real_positions(48.0, 11.6, start, end, step_minutes=10.0)
    assert len(path) == 24 * 6 + 1                      # end is on the grid: included
    assert path[0].time == start and path[-1].time == end
    assert all(p.time.tzinfo is berlin for p in path)
    e, a = elevations(path), azimuths(path)
    crossings = np.flatnonzero(np.diff(np.sign(e)) != 0)
    assert len(crossings) == 2                          # sunrise and sunset, once each
    rise, set_ = crossings
    assert a[rise] < 90.0 and a[set_] > 270.0           # rises north of east, sets north of west
    # Noon elevation 90 - 48 + 23.44 = 65.44 deg at the solstice; 10 min samples miss the true
    # noon by <= 5 min, i.e. by ~0.02 deg of elevation (quadratic near the top).
    assert abs(e.max() - (90.0 - 48.0 + 23.44)) < 0.05
    assert 155.0 < a[e.argmax()] < 205.0
    # Geometric day length at 48 N: arccos(-tan 48 tan 23.44) x 2 / 15 = 15.84 h; sampled every
    # 10 minutes, so within 1/6 h.
    assert abs((set_ - rise) / 6.0 - 15.84) <= 1.0 / 6.0 + 0.02


def test_real_positions_steps_in_absolute_time_across_dst():
    pytest.importorskip("pvlib")
    berlin = zoneinfo.ZoneInfo("Europe/Berlin")
    # 2024-03-31 in Berlin: 02:00 CET jumps to 03:00 CEST, so 00:00 -> 04:00 local lasts 3 hours.
    path = real_positions(52.5, 13.4, datetime.datetime(2024, 3, 31, 0, 0, tzinfo=berlin),
                          datetime.datetime(2024, 3, 31, 4, 0, tzinfo=berlin), step_minutes=60.0)
    times = [p.time.astimezone(UTC) for p in path]
    assert len(times) == 4
    assert all(b - a == datetime.timedelta(hours=1) for a, b in zip(times, times[1:]))
    # Fractional minutes, end not on the grid: start + k step for start + k step <= end.
    start = datetime.datetime(2024, 1, 1, 12, 0, tzinfo=UTC)
    path = real_positions(0.0, 0.0, start, start + datetime.timedelta(seconds=100),
                          step_minutes=0.75)
    assert [p.time for p in path] == [start + datetime.timedelta(seconds=45 * k) for k in range(3)]


def test_real_positions_invalid_parameters():
    start = datetime.datetime(2024, 6, 21, tzinfo=UTC)
    end = start + datetime.timedelta(hours=1)
    naive = datetime.datetime(2024, 6, 21)
    cases = [
        (dict(latitude_deg=90.5), "latitude_deg"), (dict(latitude_deg=math.nan), "latitude_deg"),
        (dict(longitude_deg=-180.5), "longitude_deg"), (dict(longitude_deg=math.inf), "longitude_deg"),
        (dict(start=naive, end=naive + datetime.timedelta(hours=1)), "start"),
        (dict(end=naive + datetime.timedelta(hours=1)), "end"),
        (dict(start="2024-06-21T00:00Z"), "start"),
        (dict(step_minutes=0.0), "step_minutes"), (dict(step_minutes=-5.0), "step_minutes"),
        (dict(step_minutes=math.nan), "step_minutes"),
        (dict(end=start), "end"), (dict(end=start - datetime.timedelta(minutes=1)), "end"),
        (dict(altitude_m=math.nan), "altitude_m"),
        # pvlib's Delta T is known to the year 3000 (UTC); before the year 1 in UTC astimezone overflows
        (dict(end=datetime.datetime(3001, 1, 1, tzinfo=UTC)), "end must fall in the years 1 to 3000 in UTC"),
        (dict(end=datetime.datetime(3000, 12, 31, 23, tzinfo=datetime.timezone(-datetime.timedelta(hours=2)))),
         "end must fall in the years 1 to 3000"),
        (dict(start=datetime.datetime(1, 1, 1, tzinfo=datetime.timezone(datetime.timedelta(hours=5)))),
         "start must fall in the years 1 to 3000"),
        (dict(start=datetime.datetime(9999, 12, 31, tzinfo=UTC), end=datetime.datetime(9999, 12, 31, 1, tzinfo=UTC)),
         "start must fall"),
        # 1 year at 1 s steps: refused before anything is computed.
        (dict(end=start + datetime.timedelta(days=365), step_minutes=1 / 60), str(MAX_POSITIONS)),
        # a probe's: floor's OverflowError, NaN positions blamed on zenith_deg, pvlib's OverflowError
        (dict(step_minutes=5e-324), str(MAX_POSITIONS)),
        (dict(step_minutes=1e308), r"step_minutes must be a number in \(0, 2.6352e\+09\]"),
        (dict(altitude_m=1e300), r"altitude_m must be a number in \[-10000, 1e\+08\]"),
    ]
    for overrides, parameter in cases:
        kwargs = dict(latitude_deg=48.0, longitude_deg=11.6, start=start, end=end) | overrides
        with pytest.raises(ValueError, match=parameter):
            real_positions(**kwargs)


def test_real_positions_at_the_ends_of_the_years_they_take():
    """The years 1 and 3000 (UTC) are computed without pvlib's warning that its Delta T "is unknown" (an
    error under pytest's filter in this test); the sun is where an equinox puts it: near the zenith at
    noon on the equator (within 2.5 deg: the equinox's date drifts by a day or two over the centuries)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for year in (1, 3000):
            noon = datetime.datetime(year, 3, 20, 12, tzinfo=UTC)
            path = real_positions(0.0, 0.0, noon - datetime.timedelta(hours=1), noon, step_minutes=60.0)
            assert path[1].elevation_deg == pytest.approx(90.0, abs=2.5), year
            assert path[0].elevation_deg == pytest.approx(75.0, abs=2.5), year


def test_real_positions_without_pvlib_says_how_to_install_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "pvlib", None)               # import pvlib... -> ImportError
    monkeypatch.setitem(sys.modules, "pvlib.solarposition", None)
    start = datetime.datetime(2024, 6, 21, tzinfo=UTC)
    with pytest.raises(ImportError, match="pip install pvlib"):
        real_positions(48.0, 11.6, start, start + datetime.timedelta(hours=1))


def test_a_position_takes_the_azimuths_its_direction_does():
    """SunPosition took any finite azimuth while its direction (sun_direction) refuses those outside
    [-360, 720]: a bad position was found at render time, after the plan and the table."""
    from clsky.anim.sunpath import SunPosition

    with pytest.raises(ValueError, match=r"^azimuth_deg must be a number in \[-360, 720\] degrees, got 1000"):
        SunPosition(zenith_deg=60.0, azimuth_deg=1000.0)
    assert SunPosition(zenith_deg=60.0, azimuth_deg=720.0).direction.shape == (3,)
