"""Sun positions for animations: a synthetic sunrise-to-sunset sweep, or the real sun from pvlib.

Angles follow :mod:`clsky.anim.cameras`: zenith angle from the zenith, azimuth from north clockwise seen
from above (east = 90 deg), both in degrees. Positions are geometric (no atmospheric refraction):
clsky's atmosphere has no refraction, so the sun is drawn where it geometrically is.

Examples
--------
>>> from clsky.anim.sunpath import sweep
>>> path = sweep(frames=5, start_elevation_deg=0.0, max_elevation_deg=60.0)
>>> [round(p.elevation_deg, 6) for p in path]
[0.0, 42.426407, 60.0, 42.426407, 0.0]
>>> [p.azimuth_deg for p in path]
[90.0, 135.0, 180.0, 225.0, 270.0]
"""

from __future__ import annotations

import dataclasses
import datetime
import math

import numpy as np

from clsky.errors import short

from clsky.errors import check_integer, check_real
from .cameras import AZIMUTH_RANGE_DEG, sun_direction

__all__ = ["SunPosition", "sweep", "real_positions", "MAX_POSITIONS", "DELTA_T_YEARS"]

#: Largest number of positions :func:`real_positions` computes in one call.
MAX_POSITIONS = 100_000
#: Observer altitudes above sea level real_positions takes [m] (an animation's own, 0 to 1e8 m, with room below).
ALTITUDE_RANGE_M = (-1e4, 1e8)
#: The largest time step [min]: the span of the years pvlib's Delta T covers (5000 years).
MAX_STEP_MINUTES = 5000 * 366 * 24 * 60.0

#: The years (UTC) :func:`real_positions` computes: where pvlib estimates Delta T = TT - UT1
#: (``pvlib.spa.calculate_deltat``, NASA's polynomials for -1999 to 3000; outside them it warns that
#: its values "are not intended to be used"), within the SPA's own range (-2000 to 6000). Python's
#: datetimes begin with the year 1.
DELTA_T_YEARS = (-1999, 3000)


@dataclasses.dataclass(frozen=True)
class SunPosition:
    """Where the sun is, seen by the observer.

    Parameters
    ----------
    zenith_deg : float
        Geometric zenith angle [deg], in [0, 180].
    azimuth_deg : float
        Azimuth [deg], from north clockwise seen from above (east = 90), in [-360, 720].
    time : datetime.datetime or None
        The instant (timezone-aware) for real positions, None for synthetic ones.

    Raises
    ------
    ValueError
        Naming the field and its valid range.

    Examples
    --------
    >>> sun = SunPosition(zenith_deg=60.0, azimuth_deg=180.0)
    >>> sun.elevation_deg
    30.0
    >>> [round(float(c), 6) for c in sun.direction]
    [0.0, -0.866025, 0.5]
    """

    zenith_deg: float
    azimuth_deg: float
    time: datetime.datetime | None = None

    def __post_init__(self):
        object.__setattr__(self, "zenith_deg", check_real("zenith_deg", self.zenith_deg, 0.0, 180.0))
        object.__setattr__(self, "azimuth_deg", check_real("azimuth_deg", self.azimuth_deg, *AZIMUTH_RANGE_DEG,
                                                           unit=" degrees"))    # sun_direction's range
        if self.time is not None and not isinstance(self.time, datetime.datetime):
            raise ValueError(f"time must be a datetime.datetime or None, got {self.time!r}")

    @property
    def elevation_deg(self) -> float:
        """Elevation above the horizon [deg]: 90 - zenith_deg."""
        return 90.0 - self.zenith_deg

    @property
    def direction(self) -> np.ndarray:
        """Unit vector toward the sun, (east, north, up), float64 shape (3,)."""
        return sun_direction(self.zenith_deg, self.azimuth_deg)


def _elevation_arc(s, start, peak, end):
    """Elevation [deg] at sweep parameters s in [0, 1]: see :func:`sweep`."""
    s = np.asarray(s, dtype=np.float64)
    rising = start + (peak - start) * np.sin(np.pi * s)
    setting = end + (peak - end) * np.sin(np.pi * (1.0 - s))   # sin(pi (1 - s)) = sin(pi s), but
    return np.where(s <= 0.5, rising, setting)                  # exactly 0 at s = 1


def sweep(frames=120, start_elevation_deg=-6.0, max_elevation_deg=60.0, end_elevation_deg=None,
          rise_azimuth_deg=90.0, set_azimuth_deg=270.0):
    """A synthetic sunrise-to-sunset sweep of the sun across the sky.

    Parameters
    ----------
    frames : int
        Number of positions, an integer in [2, :data:`MAX_POSITIONS`] (default 120).
    start_elevation_deg : float
        Elevation of the first position [deg], in [-90, 90] (default -6: civil twilight).
    max_elevation_deg : float
        Elevation at mid-sweep [deg], in [-90, 90], >= the start and end elevations (default 60).
    end_elevation_deg : float or None
        Elevation of the last position [deg], in [-90, 90] (default None: the start elevation).
    rise_azimuth_deg, set_azimuth_deg : float
        Azimuths of the first and last positions [deg], from north clockwise (defaults 90 and 270:
        east to west through south). Each in [-360, 720], a camera heading's range; set < rise sweeps
        counter-clockwise.

    Returns
    -------
    list of SunPosition
        ``frames`` positions with ``time=None``.

    Raises
    ------
    ValueError
        Naming the parameter and its valid range.

    Notes
    -----
    With ``s = k / (frames - 1)``, k = 0 ... frames - 1:

    - azimuth ``phi(s) = (phi_rise + (phi_set - phi_rise) s) mod 360``, linear in s (through south,
      180 deg, at s = 0.5 with the defaults);
    - elevation ``e(s) = e_start + (e_max - e_start) sin(pi s)`` for s <= 0.5 and
      ``e(s) = e_end + (e_max - e_end) sin(pi (1 - s))`` for s > 0.5.

    The arc is continuous and its derivative vanishes from both sides at s = 0.5, so it is smooth
    (C^1) at the top; it is C^infinity when start = end. ``e(0) = e_start``, ``e(1) = e_end`` and
    ``e(0.5) = e_max`` exactly (the middle frame when ``frames`` is odd).

    Examples
    --------
    >>> path = sweep(frames=3, start_elevation_deg=-6.0, max_elevation_deg=45.0,
    ...              end_elevation_deg=0.0)
    >>> [p.elevation_deg for p in path], [p.azimuth_deg for p in path]
    ([-6.0, 45.0, 0.0], [90.0, 180.0, 270.0])
    """
    frames = check_integer("frames", frames, 2, MAX_POSITIONS)         # 10**400 asked NumPy for as many
    start = check_real("start_elevation_deg", start_elevation_deg, -90.0, 90.0)
    peak = check_real("max_elevation_deg", max_elevation_deg, -90.0, 90.0)
    end = start if end_elevation_deg is None else check_real("end_elevation_deg",
                                                              end_elevation_deg, -90.0, 90.0)
    if peak < start or peak < end:
        raise ValueError(f"max_elevation_deg must be >= start_elevation_deg ({short(start)}) and "
                         f"end_elevation_deg ({short(end)}), got {short(peak)}")
    # a camera heading's range: +-1.7e308 made set - rise infinite, and the azimuths NaN
    rise = check_real("rise_azimuth_deg", rise_azimuth_deg, *AZIMUTH_RANGE_DEG)
    set_ = check_real("set_azimuth_deg", set_azimuth_deg, *AZIMUTH_RANGE_DEG)

    s = np.arange(int(frames), dtype=np.float64) / (int(frames) - 1)
    elevation = _elevation_arc(s, start, peak, end)
    azimuth = np.mod(rise + (set_ - rise) * s, 360.0)
    return [SunPosition(zenith_deg=90.0 - float(e), azimuth_deg=float(a))
            for e, a in zip(elevation, azimuth)]


def _check_aware(name, value):
    if not isinstance(value, datetime.datetime):
        raise ValueError(f"{name} must be a timezone-aware datetime.datetime, got {value!r}")
    if value.tzinfo is None or value.utcoffset() is None:
        raise ValueError(f"{name} must be timezone-aware (e.g. tzinfo=zoneinfo.ZoneInfo("
                         f"'Europe/Paris') or datetime.timezone.utc), got the naive {value!r}")
    return value


def real_positions(latitude_deg, longitude_deg, start, end, step_minutes=5.0, altitude_m=0.0):
    """The real sun seen from a place, every ``step_minutes`` from ``start`` to ``end``.

    Parameters
    ----------
    latitude_deg : float
        Observer latitude [deg], north positive, in [-90, 90].
    longitude_deg : float
        Observer longitude [deg], east positive, in [-180, 180].
    start, end : datetime.datetime
        First and last instants, timezone-aware, end > start, both in the years 1 to 3000 in UTC
        (:data:`DELTA_T_YEARS`). The positions are at
        ``start + k step`` (absolute time: daylight-saving changes neither skip nor repeat a step)
        for every k with ``start + k step <= end``; ``end`` is included when it falls on a step.
        Times keep the timezone of ``start``.
    step_minutes : float
        Time step [min], in (0, :data:`MAX_STEP_MINUTES`] (default 5).
    altitude_m : float
        Observer altitude above sea level [m], in :data:`ALTITUDE_RANGE_M` (default 0).

    Returns
    -------
    list of SunPosition
        Geometric (unrefracted) topocentric zenith and azimuth, with ``time`` set.

    Raises
    ------
    ValueError
        Naming the parameter and its valid range, for naive datetimes, instants after the year 3000,
        or when more than :data:`MAX_POSITIONS` (100000) positions would be computed.
    ImportError
        If pvlib is not installed (``pip install pvlib``).

    Notes
    -----
    Computed by pvlib's NumPy implementation of NREL's Solar Position Algorithm (SPA) [1]_ [2]_,
    uncertainty +-0.0003 deg over the years -2000 to 6000 given Delta T:
    ``pvlib.solarposition.get_solarposition(times, latitude, longitude, altitude, method='nrel_numpy',
    delta_t=None)``, ``delta_t = TT - UT1`` being estimated from each date
    (``pvlib.spa.calculate_deltat``, for the years -1999 to 3000 only). The 'zenith' and 'azimuth'
    columns are used (geometric), not 'apparent_zenith' (refracted).

    References
    ----------
    .. [1] I. Reda and A. Andreas, "Solar position algorithm for solar radiation applications",
       Solar Energy 76(5), 577-589 (2004), doi:10.1016/j.solener.2003.12.003; NREL/TP-560-34302
       (revised 2008).
    .. [2] W. F. Holmgren, C. W. Hansen and M. A. Mikofski, "pvlib python: a python package for
       modeling solar energy systems", J. Open Source Softw. 3(29), 884 (2018),
       doi:10.21105/joss.00884.

    Examples
    --------
    >>> import datetime
    >>> utc = datetime.timezone.utc
    >>> path = real_positions(0.0, 0.0, datetime.datetime(2024, 3, 20, 11, 0, tzinfo=utc),
    ...                       datetime.datetime(2024, 3, 20, 13, 0, tzinfo=utc), step_minutes=60.0)
    >>> len(path), bool(path[1].elevation_deg > 88.0)   # equinox noon on the equator: overhead
    (3, True)
    """
    latitude = check_real("latitude_deg", latitude_deg, -90.0, 90.0)
    longitude = check_real("longitude_deg", longitude_deg, -180.0, 180.0)
    altitude = check_real("altitude_m", altitude_m, *ALTITUDE_RANGE_M)           # 1e300: pvlib's OverflowError
    start = _check_aware("start", start)
    end = _check_aware("end", end)
    # (0, the years' span]: 1e308 minutes was an infinite step in microseconds, and NaN positions
    step = check_real("step_minutes", step_minutes, 0.0, MAX_STEP_MINUTES, low_open=True)
    # Convert to UTC before subtracting: two datetimes sharing one tzinfo object subtract as wall
    # clocks in Python, which is wrong across a daylight-saving change.
    utc = datetime.timezone.utc
    for name, value in (("start", start), ("end", end)):
        try:
            year = value.astimezone(utc).year
        except OverflowError:           # in UTC before the year 1 (or after 9999): outside too
            year = None
        if year is None or year > DELTA_T_YEARS[1]:
            raise ValueError(f"{name} must fall in the years 1 to {DELTA_T_YEARS[1]} in UTC (pvlib estimates Delta T "
                             f"= TT - UT1 for {DELTA_T_YEARS[0]} to {DELTA_T_YEARS[1]}), got {value.isoformat()}")
    duration_us = (end.astimezone(utc) - start.astimezone(utc)) / datetime.timedelta(microseconds=1)
    if duration_us <= 0.0:
        raise ValueError(f"end must be after start, got start={start.isoformat()}, "
                         f"end={end.isoformat()}")
    step_us = step * 60e6
    # 1e-9: a duration that is a whole number of steps up to float rounding includes end.
    count = duration_us / step_us + 1e-9
    if not count + 1 <= MAX_POSITIONS:              # 5e-324 minutes: an infinite count, floor's OverflowError
        raise ValueError(f"at most {MAX_POSITIONS} positions: (end - start) / step_minutes + 1 = "
                         f"{math.floor(count) + 1 if math.isfinite(count) else count}; use a larger "
                         f"step_minutes or a shorter interval")
    steps = math.floor(count)

    try:
        import pandas as pd
        import pvlib.solarposition
    except ImportError as error:
        raise ImportError("real_positions needs pvlib: pip install pvlib") from error

    offsets = pd.to_timedelta(np.round(np.arange(steps + 1) * step_us).astype(np.int64), unit="us")
    times = pd.DatetimeIndex(pd.Timestamp(start) + offsets)   # tz-aware: added in absolute time
    table = pvlib.solarposition.get_solarposition(times, latitude, longitude, altitude,
                                                  method="nrel_numpy", delta_t=None)
    zenith = table["zenith"].to_numpy(dtype=np.float64)
    azimuth = table["azimuth"].to_numpy(dtype=np.float64)
    return [SunPosition(zenith_deg=float(z), azimuth_deg=float(a), time=t.to_pydatetime())
            for z, a, t in zip(zenith, azimuth, times)]
