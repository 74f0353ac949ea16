"""Sunrise-to-sunset animations: render every frame by a lookup and by ray march, compare, write.

The lookup (:func:`lookup_of`) is the method's; the default, 'compare', compares the ray march with the
best lookup for the budget, the scene plan's choice (:mod:`clsky.renderer_choice`): the per-frame sky-view
map for the default scene, the 3D table lookup with an explicit ``table_size``.

The pipeline, one frame at a time: sun position (:mod:`clsky.anim.sunpath`) -> HDR frames
(:class:`clsky.render.SkyRenderer`, for the camera of :mod:`clsky.anim.cameras`; for every preset but
atmosphere-plus in absolute units, converted to linear sRGB in cd/m^2 by :mod:`clsky.colorimetry`) -> display values
(:mod:`clsky.anim.display`: white balance, exposure, tone curve, sRGB) -> metrics, error image and composite (:mod:`clsky.anim.metrics`) -> files
(:mod:`clsky.anim.writers`). The renderers never see files; the writers never see physics.

Example
-------
>>> from clsky.anim.animate import AnimationConfig, render_animation
>>> result = render_animation(AnimationConfig(frames=4, size=32, output="sky.mp4"))   # doctest: +SKIP
>>> result.summary                                                                     # doctest: +SKIP
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import datetime
import functools
import os
import pathlib
import threading
import time
from typing import Callable

import numpy as np

import clsky
from clsky._cl import check_context, host_blas_single_threaded, host_cores, packed_reads
from clsky._files import StagedWrites, check_output, check_suffix, is_utf8
from clsky.atmosphere import OVERRIDE_RANGES
from clsky.errors import (ParameterError, check_choice, check_flag, check_instance, check_integer, check_real, counted,
                          is_real_number)
from clsky.ground import check_ground_mode
from clsky.planner import Plan, Scene, azimuth_harmonics, plan_scene, sees_ground, sun_axis, view_sampling
from clsky.quality import QUALITY_LEVELS, QualityLevel, level_for_budget, quality_level
from clsky import colorimetry, skyview, spectrum
from clsky.solar import ABSOLUTE_UNITS, RELATIVE_UNITS, solar_irradiance_astm_g173, with_solar_spectrum
from clsky.render import SkyRenderer, ray_march_batch, ray_march_suns
from clsky.settings import SAMPLINGS
from clsky.resources import InsufficientMemoryError, MemoryEstimate, check_memory, device_of, \
    estimate_animation_memory, machine_limits

from . import display as display_pipeline
from . import pipeline as pipeline_module
from . import metrics, sunpath, tonemap, writers
from .cameras import AZIMUTH_RANGE_DEG, FOV_RANGE_DEG, camera_from_name
from .exr import PRECISIONS

__all__ = ["AnimationConfig", "AnimationResult", "METHODS", "LOOKUP_NAMES", "lookup_of", "comparison", "quality",
           "plan_animation", "PlannedAnimation", "planned_animation", "build_table", "make_renderer",
           "make_table", "renderer_of", "FrameOutputs", "frame_outputs", "exposure_reference",
           "spectral_frame_to_linear_srgb", "three_wavelength_frame_to_linear_srgb", "frame_units",
           "THREE_WAVELENGTH_CONVERSION",
           "ray_settings", "sun_positions", "check_outputs", "render_animation", "render_frame", "convert_frames",
           "metered_exposure",
           "memory_estimate", "display", "display_frames"]

#: What is rendered: table lookup only, ray march only, or both with the comparison.
#: 'lut4d' and 'compare4d' are 'lut' and 'compare' with the 4D table (clsky/table4d.py) for the lookup;
#: 'skyview' the per-frame sky-view map (:mod:`clsky.skyview`: a small map ray-marched per frame, read per pixel).
METHODS = ("compare", "lut", "raymarch", "lut4d", "compare4d", "skyview")
#: The lookups (:func:`lookup_of`), as the composites, metrics and summaries name them: the 3D table, the
#: 4D table, the per-frame sky-view map. Each is also the key of its HDR frame (:func:`render_frame`).
LOOKUP_NAMES = {"lut": "table lookup", "lut4d": "4D table", "skyview": "sky-view map"}
#: Azimuth harmonics of the 4D methods' higher orders when the quality level has none (M = 2 brings
#: the ray march within the Monte Carlo's noise down to -6 deg: README, "Twilight against Monte Carlo").
LUT4D_HARMONICS = 2
#: Most altitude and view nodes of the 4D methods' table (its sun axis is the plan's): 16 x 128 x 128 sun
#: nodes x 16 azimuths is 151 MB as float32 and within 0.6 % (day to sunset) and 2.1 % (-4 deg) of the
#: ray march of the same orders (README, "The 4D table"); the level's 32 x 128 would be twice that.
LUT4D_MAX_SIZE = (16, 128)

#: Render frame i + 1 on a worker thread while frame i is displayed, compared and written
#: (:func:`clsky.anim.pipeline.prefetched`); False: one after the other, on the calling thread.
OVERLAP_FRAMES = True

#: Host threads that convert, meter, display and compare frames side by side
#: (:func:`clsky.anim.pipeline.in_order`) with the overlap; None: :func:`host_frame_workers`'s choice.
HOST_FRAME_WORKERS = None
#: The most host threads :func:`host_frame_workers` chooses: each holds a frame's processing
#: (FRAME_BYTES_PER_PIXEL of clsky.resources, 80 MB at 512 x 512).
MAX_HOST_FRAME_WORKERS = 8

#: The conversion of absolute three-wavelength frames to XYZ (:func:`clsky.colorimetry.three_wavelength_to_xyz`):
#: the default ``solar_power_law`` reconstruction, tabulated. Measured per 512 x 512 frame (process CPU,
#: 2-core machine at load average 5.6): solar_power_law 2.3 s, solar_power_law_tabulated 0.067 s (5e-7
#: from it), the 3 x 3 matrices 0.005 s; the matrices are 11.5 dB (solar_interpolation) and 3.7 dB
#: (bruneton2017) further from 47 wavelengths by day (README, "Spectral radiance and units"), and the
#: exact one would add 2 x 120 x 2.3 s = 9 minutes to the default animation.
THREE_WAVELENGTH_CONVERSION = "solar_power_law_tabulated"


@dataclasses.dataclass(frozen=True)
class AnimationConfig:
    """Everything an animation needs; every field is validated on creation.

    Parameters
    ----------
    frames : int
        Number of frames, in [2, 100000] (sweep; default 120) (ignored with ``location``: the time range
        decides).
    size : int
        Image height [pixels] in [16, 8192] (default 512); the width follows from the camera (square
        fisheye, 2:1 panorama, 16:9 perspective).
    camera : {'fisheye', 'perspective', 'equirectangular'}
        Default 'fisheye'.
    fov_deg, heading_deg, pitch_deg : float
        Perspective camera: horizontal field of view in :data:`clsky.anim.cameras.FOV_RANGE_DEG`
        (default 90), azimuth of the optical axis (clockwise from north, in [-360, 720]; default 180,
        south), elevation in [-90, 90] (default 10). Fisheye: heading_deg is the azimuth at the top of
        the image (default 0, north up, east on the left as in all-sky photographs).
    altitude : float
        Observer altitude [m], in [0, 1e8] (default 0; above 100 km: seen from space).
    method : {'compare', 'lut', 'raymarch', 'lut4d', 'compare4d', 'skyview'}
        The frames: a lookup against the ray march ('compare': the best lookup for the budget, the
        scene plan's, :func:`lookup_of`; the 3D table lookup without a plan), either alone; the 4D
        methods look up the 4D table (parameterization '4d', clsky/table4d.py: mode 'physical', at least
        :data:`LUT4D_HARMONICS` azimuth harmonics) instead of the 3D one; 'skyview' reads a per-frame
        sky-view map (:mod:`clsky.skyview`). Default 'compare'.
    skyview_size : (W, H) or None
        Size of the per-frame sky-view map of ``method='skyview'``, and of 'compare' where the scene plan
        picks the map (:class:`clsky.skyview.SkyViewSettings`):
        W azimuth columns in [2, 4096], H rows in [4, 4096]; None (default): :data:`clsky.skyview.DEFAULT_SIZE`.
    preset : str
        Atmosphere preset (:data:`clsky.PRESETS`; default 'physical').
    ground_albedo : float or None
        Albedo of a Lambertian ground in [0, 1] instead of the preset's (None: the preset's, 0.1 for
        physical, 0 for atmosphere-plus); > 0 needs mode 'physical'.
    ozone_column_du : float or None
        Ozone column [Dobson units] in [0, 1e5] instead of the preset's (None: the preset's, 300 for
        physical, 0 for atmosphere-plus); 0 removes ozone (``clsky animate --ozone-column 0``).
    mode : {'atmosphere-plus', 'physical'}
        Scheme of the table's higher orders (default 'physical', unlike :class:`clsky.TableSettings`).
    error_budget : float
        Relative error allowed in the frames, in (0, 1] (default 0.01): the scene plan
        (:mod:`clsky.planner`) picks the fastest quality level within it.
    quality : str or None
        A named quality level ('draft', 'default', 'high', 'reference') instead of the budget's.
    table_size : (W, H, D) or None
        None (default): the table the scene plan asks for (the level's resolution, the sun axis on the
        sun path only). A size: a full table of that grid, unplanned (the level's other settings).
    samples : int or None
        Ray-march samples per ray (view steps), in [2, 4096]; None (default): the quality level's.
    sampling : str or None
        Node placement along rays (clsky.settings.SAMPLINGS) for the table and the ray march; None
        (default): the scene planner's choice for ``altitude`` (:func:`clsky.planner.view_sampling`):
        'ground_end' above the ground, Keller & Bohn's (the quality levels') on it (README, "Views
        from altitude").
    start_elevation_deg, max_elevation_deg : float
        Sweep: sun elevation [deg] before sunrise / after sunset (default -6), and at its highest (default
        60), each in [-90, 90], the highest at least the start.
    location : (latitude_deg, longitude_deg) or None
        Real sun positions (pvlib NREL SPA) instead of the sweep.
    date : datetime.date, str or None
        Day of the real positions (default today), from ``start_hour`` to ``end_hour`` UTC; an ISO
        string 'YYYY-MM-DD' is converted on creation (a datetime gives its date).
    start_hour, end_hour, step_minutes : float
        Time range [h, UTC] of the real positions, each in [0, 48], the end after the start (default 0 to
        24), and their step [minutes] in (0, 1440] (default 10), at most the range.
    fps : float
        Frames per second of the MP4, in :data:`FPS_RANGE` (default 30).
    exposure : float
        Exposure [EV] in [-40, 40] (default 0): frames are scaled by 2^exposure before the tone curve
        (EV 0 is the old multiplier 1; the old ``exposure=x`` is ``log2(x)``). With ``auto_exposure``,
        a compensation added to the metered EV.
    tone_map : str or None
        Tone curve (:data:`clsky.anim.display.TONE_CURVES`); None (default): ``'atmosphere-plus'`` (the notes'
        curve, frames bit for bit as before) for the atmosphere-plus preset, else
        :data:`clsky.anim.display.DEFAULT_TONE_MAP`.
    auto_exposure : bool or None
        Meter each frame's luminance, smoothed over time (:class:`clsky.anim.display.AutoExposure`). None
        (default): True for frames in absolute units (:attr:`absolute`: a fixed EV cannot show both
        the day sky, thousands of cd/m^2, and the dusk, tens), False for the atmosphere-plus preset's
        relative frames (the notes' fixed exposure, frames bit for bit as before).
    white_balance : {'d65', 'sun'} or None
        'd65': no balance, sRGB's own white; 'sun': the sun's colour adapted to D65 white (von Kries,
        CAT02): the sRGB of the solar spectrum for absolute frames, the incident light I_I for
        relative ones. None (default): 'sun' for absolute frames (the scene's illuminant shown white, as
        a camera's daylight balance does), 'd65' for the atmosphere-plus preset.
    dither : bool
        Dither the 8-bit frames against banding.
    output : str or path
        MP4 file; PNG frames go to ``<stem>_frames/``, metrics to ``<stem>_metrics.csv`` / ``.json``.
    wavelengths : int or None
        None (default): the table's three wavelengths; for the atmosphere-plus preset in the notes'
        relative units (I_I), shown as r, g, b; for any other preset lit by the solar spectrum
        (absolute units) and converted to CIE XYZ -> linear sRGB [cd/m^2]
        (:func:`three_wavelength_frame_to_linear_srgb`). An integer N in [12, 47]
        (:data:`clsky.spectrum.MIN_COLOUR_WAVELENGTHS`: fewer integrate to wrong colours): N wavelengths in
        absolute units (:mod:`clsky.spectrum`: batches of three, lit by the solar spectrum), each
        frame converted spectral -> CIE XYZ -> linear sRGB [cd/m^2] (:func:`spectral_frame_to_linear_srgb`).
        Absolute frames are thousands of times brighter than the notes' relative ones by day: hence
        auto-exposure by default (or an EV near -13 by day).
    hdr : {None, 'exr', 'hdr', 'npy'} or bool
        Also write each frame's HDR values beside the PNGs: the ray march's frame (with
        ``method='compare'`` or 'compare4d', the reference the lookup is compared with), else the frame the
        method renders. 'exr': an
        OpenEXR image per frame with its units, the clsky version and the sun in the header (an
        equirectangular panorama is tagged as a latitude-longitude environment map:
        :mod:`clsky.anim.exr`); 'hdr': a Radiance RGBE image with the same header lines but the scene
        (:mod:`clsky.anim.rgbe`,
        8-bit mantissas); 'npy': a float32 NumPy array. None or False (default): none; True is 'npy'
        (the former flag).
    hdr_precision : {'float', 'half'}
        Pixel type of the EXR frames: 32-bit (default, the frames' float32 values exactly) or 16-bit
        half floats (values above 65504, the sun's disc, clipped to it); 'half' needs ``hdr='exr'``.
    force : bool
        Overwrite existing outputs.

    Every number field takes NumPy scalars too (stored as Python ints and floats), and the tuple
    fields take lists and arrays of the right length.

    Raises
    ------
    ValueError
        (:class:`clsky.errors.ParameterError`, with ``field`` and, for ``table_size``, ``index``) for
        a field of the wrong type or outside its range.
    """

    frames: int = 120
    size: int = 512
    camera: str = "fisheye"
    fov_deg: float = 90.0
    heading_deg: float | None = None
    pitch_deg: float = 10.0
    altitude: float = 0.0
    method: str = "compare"
    skyview_size: tuple | None = None
    preset: str = "physical"
    mode: str = "physical"
    ground_albedo: float | None = None
    ozone_column_du: float | None = None
    error_budget: float = 0.01
    quality: str | None = None
    table_size: tuple | None = None
    samples: int | None = None
    sampling: str | None = None
    start_elevation_deg: float = -6.0
    max_elevation_deg: float = 60.0
    location: tuple | None = None
    date: datetime.date | None = None
    start_hour: float = 0.0
    end_hour: float = 24.0
    step_minutes: float = 10.0
    fps: float = 30.0
    exposure: float = 0.0
    tone_map: str | None = None
    auto_exposure: bool | None = None
    white_balance: str | None = None
    dither: bool = True
    output: str = "sky.mp4"
    hdr: str | None = None
    hdr_precision: str = "float"
    force: bool = False
    wavelengths: int | None = None

    def __post_init__(self):
        for name, check in _FIELD_CHECKS.items():
            object.__setattr__(self, name, check(name, getattr(self, name)))
        if self.max_elevation_deg < self.start_elevation_deg:
            raise ParameterError("max_elevation_deg", f"at least the start elevation ({self.start_elevation_deg:g})",
                                 self.max_elevation_deg)
        check_ground_mode(self.atmosphere, self.mode,
                          "" if self.ground_albedo is not None else f"the {self.preset} preset's ground")
        if self.hdr_precision != "float" and self.hdr != "exr":
            raise ParameterError("hdr_precision", "'float' unless hdr is 'exr' (--hdr exr; .npy and .hdr frames have "
                                 "no other pixel type)", self.hdr_precision)
        if self.end_hour <= self.start_hour:
            raise ParameterError("end_hour", f"after the start hour ({self.start_hour:g})", self.end_hour)
        if self.location is not None and self.date is not None:
            midnight, last = datetime.datetime(self.date.year, self.date.month, self.date.day), sunpath.DELTA_T_YEARS[1]
            if self.date.year > last or (midnight + datetime.timedelta(hours=self.end_hour)).year > last:
                raise ParameterError("date", f"a day whose frames, to {self.end_hour:g} h UTC, fall in the years 1 to "
                                     f"{last} (pvlib estimates Delta T = TT - UT1 for {sunpath.DELTA_T_YEARS[0]} "
                                     f"to {last})", self.date.isoformat())
        if self.location is not None:
            span = (self.end_hour - self.start_hour) * 60.0
            if self.step_minutes > span:      # one position: "need at least 2 frames" came after the table's build
                raise ParameterError("step_minutes", f"at most {span:.6g} minutes, the time from {self.start_hour:g} h "
                                                     f"to {self.end_hour:g} h (an animation takes at least 2 frames)",
                                     self.step_minutes)
            least = span / (sunpath.MAX_POSITIONS - 1)
            if self.step_minutes < least:
                raise ParameterError("step_minutes", f"at least {least:.6g} minutes from {self.start_hour:g} h to "
                                                     f"{self.end_hour:g} h (at most {sunpath.MAX_POSITIONS} positions)",
                                     self.step_minutes)
        object.__setattr__(self, "table_size", _check_table_size(self.table_size))
        if self.lookup4d and (self.mode != "physical" or self.wavelengths is not None):
            raise ParameterError("method", "'compare', 'lut', 'raymarch' or 'skyview' with mode 'atmosphere-plus' or "
                                 "wavelengths (the 4D table needs mode 'physical' and three wavelengths)", self.method)
        if self.lookup4d and self.table_size is not None:     # a grid asked for is built as asked, or refused
            width, height, _ = self.table_size
            if width > LUT4D_MAX_SIZE[0] or height > LUT4D_MAX_SIZE[1] or height % 2 or height < 4:
                raise ParameterError("table_size", f"W <= {LUT4D_MAX_SIZE[0]} altitude nodes and an even number H in "
                                                   f"[4, {LUT4D_MAX_SIZE[1]}] of view nodes with method "
                                                   f"{self.method!r} (the 4D table)", self.table_size)
        if self.tone_map is None:
            object.__setattr__(self, "tone_map", "atmosphere-plus" if self.preset == "atmosphere-plus"
                               else display_pipeline.DEFAULT_TONE_MAP)
        if self.auto_exposure is None:
            object.__setattr__(self, "auto_exposure", self.absolute)
        if self.white_balance is None:
            object.__setattr__(self, "white_balance", "sun" if self.absolute else "d65")

    @property
    def lookup4d(self) -> bool:
        """Whether the lookup frames come from the 4D table (methods 'lut4d', 'compare4d')."""
        return self.method in ("lut4d", "compare4d")

    @property
    def compares(self) -> bool:
        """Whether the animation renders both the lookup and the ray march and compares them."""
        return self.method in ("compare", "compare4d")

    @property
    def absolute(self) -> bool:
        """Whether the frames are in absolute units (linear sRGB, cd/m^2): with ``wavelengths``, and
        for every preset but atmosphere-plus (whose frames keep the notes' relative I_I)."""
        return self.wavelengths is not None or self.preset != "atmosphere-plus"

    @property
    def output_path(self) -> pathlib.Path:
        return pathlib.Path(self.output)

    @property
    def frames_directory(self) -> pathlib.Path:
        return self.output_path.with_name(self.output_path.stem + "_frames")

    def metrics_path(self, suffix) -> pathlib.Path:
        return self.output_path.with_name(self.output_path.stem + "_metrics" + suffix)

    @property
    def atmosphere(self) -> clsky.AtmosphereParameters:
        """The preset's atmosphere, with ``ground_albedo`` and ``ozone_column_du`` if given."""
        changes = {name: getattr(self, name) for name in OVERRIDE_RANGES if getattr(self, name) is not None}
        return clsky.preset(self.preset).replace(**changes)

    def image_shape(self):
        """(width, height) of a rendered frame."""
        if self.camera == "fisheye":
            return self.size, self.size
        if self.camera == "equirectangular":
            return 2 * self.size, self.size
        return (16 * self.size) // 9 // 2 * 2, self.size


def _integer(low, high, optional=False):
    """The field check ``(name, value) -> int`` of :func:`clsky.errors.check_integer` in [low, high]."""
    return lambda name, value: check_integer(name, value, low, high, optional=optional)


#: Frames per second of the MP4: ffmpeg takes the rate as imageio-ffmpeg writes it, with two decimals, so
#: below 0.005 it read 0 and wrote no video (an empty MP4 replaced the old one before the writer checked).
FPS_RANGE = (0.01, 240.0)


def _real(low, high, unit="", low_open=False, optional=False):
    """The field check ``(name, value) -> float`` of :func:`clsky.errors.check_real` in [low, high]."""
    return lambda name, value: check_real(name, value, low, high, low_open=low_open, unit=unit, optional=optional)


def _choice(choices, optional=False):
    """The field check ``(name, value) -> str`` of :func:`clsky.errors.check_choice`."""
    return lambda name, value: check_choice(name, value, choices, optional=optional)


def _optional_flag(name, value):
    return None if value is None else check_flag(name, value)


def check_location(name, value):
    """None or (latitude in [-90, 90], longitude in [-180, 180]) degrees, from any pair of numbers."""
    if value is None:
        return None
    valid = "None or (latitude in [-90, 90], longitude in [-180, 180]) degrees"
    items = tuple(value) if isinstance(value, (tuple, list, np.ndarray)) else ()
    if (len(items) != 2 or not all(is_real_number(v) for v in items)      # NaN, inf and 10**400 fail the ranges
            or not (-90 <= items[0] <= 90 and -180 <= items[1] <= 180)):
        raise ParameterError(name, valid, value)
    return float(items[0]), float(items[1])


def _date(name, value):
    """None, a datetime.date (a datetime gives its date), or an ISO date string 'YYYY-MM-DD'."""
    if value is None or (isinstance(value, datetime.date) and not isinstance(value, datetime.datetime)):
        return value
    if isinstance(value, datetime.datetime):
        return value.date()
    if isinstance(value, str):
        try:
            return datetime.date.fromisoformat(value)
        except ValueError:
            pass
    raise ParameterError(name, "None, a datetime.date or an ISO date 'YYYY-MM-DD'", value)


def _hdr(name, value):
    """None (or False), or a format of :attr:`clsky.anim.writers.FrameWriter.HDR_FORMATS` ('exr', 'hdr',
    'npy'); True, the former flag, is 'npy'."""
    if value is None or value is False or (isinstance(value, np.bool_) and not value):
        return None
    if value is True or isinstance(value, np.bool_):
        return "npy"
    formats = [f for f in writers.FrameWriter.HDR_FORMATS if f is not None]
    if not isinstance(value, str) or value not in formats:
        # the formats first: a scene's output.hdr (TOML) can hold a string only, and None or False no key
        raise ParameterError(name, f"one of {formats} (in the API also None or False for none, True for 'npy')",
                             value)
    return value


def _output(name, value):
    """A path NAME.mp4 (:func:`clsky._files.check_suffix`: no NUL character, UTF-8 text), as typed."""
    valid = "a path ending in .mp4 after a file name (NAME.mp4)"
    if not isinstance(value, (str, pathlib.PurePath)):
        raise ParameterError(name, valid, value)
    try:
        check_suffix(value, ".mp4", name)
    except ValueError:
        text = os.fspath(value)
        if "\0" in text:
            valid += " without a NUL character"
        elif not is_utf8(text):
            valid += " in UTF-8 text (its name goes into the frames' metadata)"
        raise ParameterError(name, valid, value) from None
    return value


def _check_table_size(value):
    """None, or three node counts (W, H, D) as TableSettings checks them, errors naming table_size."""
    if value is None:
        return None
    try:
        return clsky.TableSettings(size=value).size
    except ParameterError as error:
        raise ParameterError("table_size", error.valid, error.value, error.index) from None


_FIELD_CHECKS = {
    "frames": _integer(2, 100_000), "size": _integer(16, 8192),
    "camera": _choice(("fisheye", "perspective", "equirectangular")),
    "fov_deg": _real(*FOV_RANGE_DEG, " degrees"), "heading_deg": _real(*AZIMUTH_RANGE_DEG, " degrees", optional=True),
    "pitch_deg": _real(-90.0, 90.0, " degrees"), "altitude": _real(0.0, 1e8, " m"), "method": _choice(METHODS),
    "skyview_size": lambda name, value: None if value is None else skyview.check_size(name, value),
    "preset": _choice(tuple(sorted(clsky.PRESETS))), "mode": _choice(("atmosphere-plus", "physical")),
    "ground_albedo": _real(*OVERRIDE_RANGES["ground_albedo"], optional=True),
    "ozone_column_du": _real(*OVERRIDE_RANGES["ozone_column_du"], optional=True),
    "samples": _integer(2, 4096, optional=True), "sampling": _choice(SAMPLINGS, optional=True),
    "error_budget": _real(0.0, 1.0, low_open=True),
    "quality": _choice(tuple(QUALITY_LEVELS), optional=True),
    "start_elevation_deg": _real(-90.0, 90.0, " degrees"), "max_elevation_deg": _real(-90.0, 90.0, " degrees"),
    "location": check_location, "date": _date, "start_hour": _real(0.0, 48.0, " h"), "end_hour": _real(0.0, 48.0, " h"),
    "step_minutes": _real(0.0, 1440.0, " minutes", low_open=True), "fps": _real(*FPS_RANGE),
    "exposure": _real(-40.0, 40.0, " EV"), "tone_map": _choice(tuple(display_pipeline.TONE_CURVES), optional=True),
    "auto_exposure": _optional_flag, "white_balance": _choice(display_pipeline.WHITE_BALANCES, optional=True),
    "dither": check_flag, "output": _output, "hdr": _hdr, "hdr_precision": _choice(tuple(PRECISIONS)),
    "force": check_flag,
    "wavelengths": _integer(spectrum.MIN_COLOUR_WAVELENGTHS, spectrum.MAX_WAVELENGTHS, optional=True),
}


@dataclasses.dataclass
class AnimationResult:
    """Per-frame metric rows, the temporal jumps, the written files, a one-line summary, and the
    stale frames of an earlier run that a forced run deleted."""

    rows: list
    temporal: dict
    paths: list
    seconds: float
    summary: str
    removed: list = dataclasses.field(default_factory=list)


def quality(config: AnimationConfig) -> QualityLevel:
    """The quality level of the animation: the named one, or the fastest within its error budget."""
    return quality_level(config.quality) if config.quality else level_for_budget(config.error_budget)


def plan_animation(config: AnimationConfig, positions, directions, valid, ctx=None) -> Plan | None:
    """The scene plan of the animation (None with an explicit ``table_size``): its sun path, its
    observer altitude, the view elevations its camera sees (from the valid pixels' directions) and its
    error budget or quality; the ray march is planned for whenever the animation renders it."""
    if config.table_size is not None:
        return None
    # the 4D table over a reflecting ground carries the ground's light in its higher orders' channels: a plan
    # that dropped them (an observer far above the air) ended in an error about 'orders' after its work; so
    # does the 3D table for its lookup, which --method lut asks for where its cameras see the ground (a plan
    # that dropped them drew the ground black: 147 against 9065 cd/m^2 from 1 km)
    scene = _scene(config, positions, directions, valid)
    lookup_ground = config.method == "lut" and sees_ground(config.atmosphere, scene)
    plan = plan_scene(scene, config.atmosphere, config.mode, ctx=ctx, ray_march=config.method not in ("lut", "lut4d"),
                      samples=config.samples, sampling=config.sampling,
                      keep_orders=config.atmosphere.has_ground and (config.lookup4d or lookup_ground))
    return _with_frames_notes(config, plan)


def _with_frames_notes(config: AnimationConfig, plan: Plan) -> Plan:
    """``plan`` with what the frames make of it said in its lines too: the 4D table a lookup4d method
    builds from the plan's grid (the plan printed the 3D table's size and its azimuth harmonics), and a
    table lookup asked for (``--method lut``) where the plan's renderer is another, which the budget needs
    (nothing said the frames were over it)."""
    notes = []
    if config.lookup4d:
        table = _with_lookup(plan.table, config)
        w, h, d = table.size
        measured = ("; its error was measured from the ground: from above it the frames may miss the budget "
                    "(17 % off the ray march from 30 km, sun at -4 deg, draft)" if config.altitude > 0.0 else "")
        notes.append(("4D table", f"{w} x {h} x {d} x {table.azimuth_size} azimuths, M = {table.azimuth_harmonics}",
                      f"--method {config.method}: the plan's grid, at most {LUT4D_MAX_SIZE[0]} x {LUT4D_MAX_SIZE[1]} "
                      f"altitude and view nodes (the work line is the 3D grid's){measured}"))
    elif config.method in ("lut", "skyview") and plan.renderer != config.method:
        notes.append(("frames", f"{LOOKUP_NAMES[config.method]} (--method {config.method})",
                      "not the plan's renderer, for the renderer line's reason: the frames may miss the budget"))
    return dataclasses.replace(plan, decisions=plan.decisions + tuple(notes)) if notes else plan


@dataclasses.dataclass(frozen=True)
class PlannedAnimation:
    """What an animation's frames are made from before any table: its sun positions
    (:func:`sun_positions`), its camera, the camera's pixel directions (H, W, 3) and valid mask (H, W), and
    its scene plan (:func:`plan_animation`; None with an explicit ``table_size``)."""

    positions: list
    camera: object
    directions: np.ndarray
    valid: np.ndarray
    plan: Plan | None


def planned_animation(config: AnimationConfig, positions=None, ctx=None) -> PlannedAnimation:
    """The animation's sun positions (``positions`` if given, else :func:`sun_positions`), camera and scene
    plan, as :func:`render_animation` makes them: the one place where the camera and the plan are made from
    a configuration, so that a benchmark or a test of "the default animation's table" plans what
    ``clsky animate`` renders. ValueError naming an argument of the wrong kind, before any work."""
    check_arguments(config, ctx=ctx, positions=positions)
    positions = sun_positions(config) if positions is None else positions
    camera = _camera(config)
    directions, valid = camera.directions()
    return PlannedAnimation(positions, camera, directions, valid,
                            plan_animation(config, positions, directions, valid, ctx=ctx))


def _scene(config: AnimationConfig, positions, directions, valid) -> Scene:
    """The scene of the animation: its sun path, observer altitude, the view elevations of the valid
    pixels' ``directions``, its error budget or quality, and its frames' rendered (valid) pixels."""
    elevations = [90.0 - p.zenith_deg for p in positions]
    seen = np.degrees(np.arcsin(np.clip(directions[valid][:, 2], -1.0, 1.0)))
    return Scene(sun_elevations_deg=(min(elevations), max(elevations)),
                 altitudes_m=(config.altitude, config.altitude),
                 view_elevations_deg=(float(seen.min()), float(seen.max())),
                 error_budget=config.error_budget, quality=config.quality, pixels=int(np.count_nonzero(valid)))


def host_frame_workers() -> int:
    """The host threads of the frames' host halves (:func:`clsky.anim.pipeline.in_order`):
    :data:`HOST_FRAME_WORKERS` if set, else one a core this process may use (at least 1, at most
    :data:`MAX_HOST_FRAME_WORKERS`), beside the device half's render (PoCL's threads on a CPU device), the
    writer and ffmpeg, which share the cores with them; 0 without the overlap (:data:`OVERLAP_FRAMES`:
    all on the calling thread). Measured (docs/speed-log.md, bench/bench_animate.py): on the 2-core machine
    two threads take 7-9 % less wall time than one for the same CPU time (since the default level's
    cheaper table, 2026-12-05; half the cores, one, was the default before); on the H200 machine's 16
    cores the cap's eight. Not measured: 4 to 12 cores."""
    if not OVERLAP_FRAMES:
        return 0
    if HOST_FRAME_WORKERS is not None:
        return check_integer("HOST_FRAME_WORKERS", HOST_FRAME_WORKERS, 1, 256)
    return max(1, min(MAX_HOST_FRAME_WORKERS, host_cores()))


def check_animation_memory(config: AnimationConfig, positions, device=None, options=None) -> int:
    """Refuse, before any work, an animation that does not fit the machine (:func:`memory_estimate`
    against ``device``'s and the host's limits, :func:`clsky.resources.check_memory` with its
    ``options``), and return the host threads its frames may use: :func:`host_frame_workers` (no more
    than the frames), fewer where the frames in flight would not fit, InsufficientMemoryError where
    even one does not."""
    workers = min(host_frame_workers(), len(positions))
    limits = machine_limits(device)
    while True:
        try:
            check_memory(memory_estimate(config, positions, workers, device), limits, options=options)
            return workers
        except InsufficientMemoryError:
            if workers <= 1:
                raise
            workers -= 1


def memory_estimate(config: AnimationConfig, positions, host_workers=None, device=None) -> MemoryEstimate:
    """Peak memory of the animation (:func:`clsky.resources.estimate_animation_memory`), from its
    settings alone: no pilot, no full-size camera; with ``host_workers`` frames processed at once
    (default :func:`host_frame_workers`; never more than the frames), on ``device`` (a pyopencl.Device,
    or None: no device), whose table build may pack its reads (:func:`clsky._cl.packed_reads`) and whose
    ray march takes :func:`ray_march_suns_of` suns a launch (never more than the frames).

    The table is the plan's sun axis (view elevations from the camera at 64 pixels, ray-march margins)
    with the higher orders kept, an upper bound of the plan (whose pilot may drop them); with
    ``table_size``, that full table; with ``wavelengths``, one such table per batch of three.
    """
    level = quality(config)
    if config.table_size is not None:
        settings = level.table.replace(size=tuple(config.table_size), mode=config.mode)
    else:
        directions, valid = _camera(dataclasses.replace(config, size=64)).directions()
        scene = _scene(config, positions, directions, valid)
        cos_range, nodes, _, _ = sun_axis(config.atmosphere, scene, level, level.table.mapping)
        harmonics, _ = azimuth_harmonics(level, scene.sun_elevations_deg, config.mode)
        settings = level.table.replace(mode=config.mode, size=level.table.size[:2] + (nodes,),
                                       sun_cos_range=cos_range, azimuth_harmonics=harmonics)
    batches = None if config.wavelengths is None else len(spectrum.wavelength_batches(config.wavelengths))
    return estimate_animation_memory(_with_lookup(_with_sampling(settings, config), config), config.image_shape(),
                                     config.method,
                                     ray_settings(config), hdr_output=config.hdr is not None, batches=batches,
                                     overlapped=OVERLAP_FRAMES,
                                     host_workers=min(host_frame_workers() if host_workers is None else host_workers,
                                                      len(positions)), packed_reads=packed_reads(device),
                                     ray_march_suns=min(ray_march_suns_of(config, device), len(positions)),
                                     device_conversion=config.absolute and config.wavelengths is None,
                                     frames=len(positions))


def build_table(config: AnimationConfig, plan: Plan | None = None, ctx=None, progress=None) -> clsky.ScatteringTable:
    """The scattering table of the animation: the plan's, or a full table of ``config.table_size``
    at the quality level's other settings (orders until converged). For absolute frames
    (``config.absolute``) its atmosphere is lit by the solar spectrum (:func:`clsky.solar.with_solar_spectrum`:
    the same table data, rendered in W m^-2 sr^-1 nm^-1); the scene plan itself is made on the preset's."""
    atmosphere, settings = _base(config, plan)
    if config.absolute:
        atmosphere = with_solar_spectrum(atmosphere)
    return clsky.ScatteringTable.build(atmosphere, settings, ctx=ctx, progress=progress)


def _base(config: AnimationConfig, plan: Plan | None):
    """(atmosphere, table settings) of the animation's tables: the plan's, or the config's atmosphere
    and a full table of ``config.table_size`` (default: the quality level's size) at the level's
    other settings; with ``config.sampling`` if given."""
    if plan is not None:
        return plan.atmosphere, _with_lookup(_with_sampling(plan.table, config), config)
    size = tuple(config.table_size) if config.table_size is not None else quality(config).table.size
    settings = _with_sampling(quality(config).table.replace(size=size, mode=config.mode), config)
    return config.atmosphere, _with_lookup(settings, config)


def _with_lookup(settings: clsky.TableSettings, config: AnimationConfig) -> clsky.TableSettings:
    """``settings`` as the 4D table for the 4D methods (:data:`LUT4D_HARMONICS` azimuth harmonics when
    the level has none; at most :data:`LUT4D_MAX_SIZE` altitude and view nodes, an even number of the
    latter: a plan's grid reduced to that, a ``table_size`` already within it, AnimationConfig refusing
    any other), else unchanged. The table's higher orders are computed on that grid too (a plan keeps them
    over a reflecting ground: :func:`plan_animation`)."""
    if not config.lookup4d:
        return settings
    width = min(settings.size[0], LUT4D_MAX_SIZE[0])
    height = max(4, min(settings.size[1], LUT4D_MAX_SIZE[1]))
    height += height % 2
    return settings.replace(parameterization="4d", size=(width, height, settings.size[2]),
                            azimuth_harmonics=settings.azimuth_harmonics or LUT4D_HARMONICS)


def _with_sampling(settings: clsky.TableSettings, config: AnimationConfig) -> clsky.TableSettings:
    """``settings`` with ``config.sampling`` if given, else with the view nodes the scene planner picks
    for the observer's altitude (:func:`clsky.planner.view_sampling`; a plan's table has them already)."""
    sampling = config.sampling or view_sampling((config.altitude, config.altitude))[0]
    return settings.replace(sampling=sampling)


def make_renderer(config: AnimationConfig, plan: Plan | None = None, ctx=None, progress=None):
    """(renderer, table) of the animation: :func:`renderer_of` :func:`make_table`'s table."""
    table = make_table(config, plan, ctx=ctx, progress=progress)
    return renderer_of(config, table, ctx=ctx), table


def make_table(config: AnimationConfig, plan: Plan | None = None, ctx=None, progress=None):
    """The table the frames read: :func:`build_table`'s, or with ``config.wavelengths`` a
    :class:`clsky.spectrum.SpectralTable` of N wavelengths over the same base atmosphere and settings
    (the plan's, or the config's); only the data and gathered sum of each table are kept (the higher
    orders are dropped)."""
    if config.wavelengths is None:
        return dataclasses.replace(build_table(config, plan, ctx=ctx, progress=progress), orders=())
    base, settings = _base(config, plan)
    return spectrum.SpectralTable.build(base, config.wavelengths, settings, ctx=ctx, progress=progress,
                                        keep_orders=False)


def renderer_of(config: AnimationConfig, table, ctx=None):
    """The renderer of :func:`make_table`'s ``table``: a :class:`~clsky.render.SkyRenderer`, or with
    ``config.wavelengths`` a :class:`clsky.spectrum.SpectralRenderer`, with :func:`ray_settings`."""
    if config.wavelengths is None:
        return SkyRenderer(table, ray_settings(config), ctx=ctx)
    return spectrum.SpectralRenderer(table, ray_settings(config), ctx=ctx)


def spectral_frame_to_linear_srgb(frame, wavelengths):
    """The frame conversion of spectral animations: spectral radiance (..., N) [W m^-2 sr^-1 nm^-1] ->
    CIE 1931 XYZ -> linear sRGB (..., 3) [cd/m^2] (:mod:`clsky.colorimetry`); negative components of
    colours outside the sRGB gamut are clipped to 0 (the display takes non-negative values)."""
    rgb = colorimetry.xyz_to_linear_srgb(colorimetry.spectral_frame_to_xyz(frame, wavelengths))
    return np.maximum(rgb, 0.0)


def three_wavelength_frame_to_linear_srgb(frame, wavelengths, ctx=None):
    """The frame conversion of absolute three-wavelength animations: spectral radiance (..., 3)
    [W m^-2 sr^-1 nm^-1] at three ``wavelengths`` [nm] -> CIE 1931 XYZ (:data:`THREE_WAVELENGTH_CONVERSION`;
    on the device of ``ctx`` when given, the same values) -> linear sRGB (..., 3) [cd/m^2]; negative
    components clipped to 0 (as :func:`spectral_frame_to_linear_srgb`)."""
    xyz = colorimetry.three_wavelength_frame_to_xyz(frame, wavelengths, THREE_WAVELENGTH_CONVERSION, ctx=ctx)
    return np.maximum(colorimetry.xyz_to_linear_srgb(xyz), 0.0)


def frame_units(config: AnimationConfig, table) -> str:
    """The units of the HDR frames: linear sRGB in cd/m^2 for absolute frames (``config.absolute``),
    else the table's relative radiance units (r, g, b at its three wavelengths)."""
    if config.wavelengths is not None:
        return "linear sRGB [cd/m^2] (spectral radiance -> CIE 1931 XYZ -> sRGB)"
    wavelengths = ", ".join(f"{w:g}" for w in table.atmosphere.wavelengths)
    if config.absolute:
        return (f"linear sRGB [cd/m^2] (spectral radiance [{ABSOLUTE_UNITS}] at {wavelengths} nm -> CIE 1931 XYZ "
                f"({THREE_WAVELENGTH_CONVERSION}) -> sRGB)")
    return f"{table.metadata.get('units', RELATIVE_UNITS)} at the table's three wavelengths ({wavelengths} nm)"


def _hdr_attributes(config: AnimationConfig, table, sun) -> dict:
    """The header of the EXR or RGBE frame of sun position ``sun`` (:func:`clsky.anim.exr.frame_attributes`)."""
    from .exr import frame_attributes

    width, height = config.image_shape()
    # channel wavelengths only for relative frames (atmosphere-plus), which are r, g, b at the table's three
    # wavelengths; absolute frames are linear sRGB, whose channels are no wavelengths
    wavelengths = None if config.absolute else table.atmosphere.wavelengths
    return frame_attributes(frame_units(config, table), config.camera, width, height, sun.zenith_deg,
                            sun.azimuth_deg, config.altitude, wavelengths_nm=wavelengths,
                            radiance_view=_camera(config).radiance_view())


def ray_settings(config: AnimationConfig) -> clsky.TableSettings:
    """The ray march's quadrature: the quality level's, with ``config.samples`` and ``config.sampling``
    if given."""
    ray = quality(config).ray
    return _with_sampling(ray if config.samples is None else ray.replace(view_steps=config.samples), config)


def sun_positions(config: AnimationConfig):
    """The sun positions of the frames: the sweep, or real positions for a location and date."""
    if config.location is None:
        return sunpath.sweep(config.frames, config.start_elevation_deg, config.max_elevation_deg)
    date = config.date or datetime.date.today()
    midnight = datetime.datetime(date.year, date.month, date.day, tzinfo=datetime.timezone.utc)
    return sunpath.real_positions(config.location[0], config.location[1],
                                  midnight + datetime.timedelta(hours=config.start_hour),
                                  midnight + datetime.timedelta(hours=config.end_hour), config.step_minutes,
                                  altitude_m=min(config.altitude, 8000.0))


def _camera(config):
    width, height = config.image_shape()
    options = {}
    if config.camera == "perspective":
        heading = 180.0 if config.heading_deg is None else config.heading_deg
        options = dict(fov_deg=config.fov_deg, heading_deg=heading, pitch_deg=config.pitch_deg)
    elif config.camera == "fisheye":
        options = dict(heading_deg=(config.heading_deg or 0.0) % 360.0)
    return camera_from_name(config.camera, width, height, **options)


def lookup_of(config: AnimationConfig, plan: Plan | None = None) -> str | None:
    """The lookup the animation renders, a key of :data:`LOOKUP_NAMES` (None for 'raymarch'), chosen once
    per animation: the method's own ('lut'; 'lut4d' for 'lut4d' and 'compare4d'; 'skyview'), and for
    'compare' the best lookup for the budget, the scene plan's renderer
    (:attr:`clsky.planner.Plan.renderer`, :mod:`clsky.renderer_choice`): the sky-view map when the plan
    picks it, or when it picks the ray march (no lookup fits the budget; the sky-view map, the ray march
    read at its nodes, is then the closest lookup), else the 3D table lookup; without a plan (an explicit
    ``table_size``) the 3D table lookup."""
    if config.method == "raymarch":
        return None
    if config.lookup4d:
        return "lut4d"
    if config.method == "compare" and plan is not None and plan.renderer in ("skyview", "raymarch"):
        return "skyview"
    return "skyview" if config.method == "skyview" else "lut"


def render_frame(renderer: SkyRenderer, prepared, sun_direction, config: AnimationConfig, lookup=None,
                 convert=True, raymarch=None, sky_map=None):
    """HDR frames {lookup: ..., 'raymarch': ...} of one sun position, as ``config.method`` asks: the lookup
    ``lookup`` (a key of :data:`LOOKUP_NAMES`; default :func:`lookup_of` without a plan) and the ray
    march (``raymarch`` if given: its frame, rendered already with other suns'; ``sky_map`` likewise the
    sky-view lookup's map); in the animation's units (:func:`convert_frames`), or as the renderer returns
    them with ``convert`` False (the device's work alone)."""
    lookup = lookup_of(config) if lookup is None else lookup
    frames = {}
    if lookup == "lut":
        frames["lut"] = renderer.render_table(prepared, sun_direction, config.altitude)
    elif lookup == "lut4d":
        frames["lut4d"] = renderer.render_lut4d(prepared, sun_direction, config.altitude)
    elif lookup == "skyview":
        frames["skyview"] = renderer.render_skyview(prepared, sun_direction, config.altitude,
                                                    settings=skyview_settings(config), sky_map=sky_map)
    if marches(config):
        frames["raymarch"] = (renderer.render_raymarch(prepared, sun_direction, config.altitude) if raymarch is None
                              else raymarch)
    return convert_frames(renderer, config, frames) if convert else frames


def skyview_settings(config: AnimationConfig) -> skyview.SkyViewSettings:
    """The sky-view map's settings of the animation (``config.skyview_size``, else the default size)."""
    return skyview.SkyViewSettings(config.skyview_size or skyview.DEFAULT_SIZE)


def marches(config: AnimationConfig) -> bool:
    """Whether the animation's frames include the per-pixel ray march (its method, or a comparison)."""
    return config.method == "raymarch" or config.compares


def ray_march_suns_of(config: AnimationConfig, device) -> int:
    """Suns per ray-march launch of a single-process animation on ``device`` (None: 1):
    :func:`clsky.render.ray_march_batch` of its frames for :func:`clsky.render.ray_march_suns` of the device;
    1 for a spectral animation (its renderer marches one sun at a time) or one without a ray march."""
    if device is None or config.wavelengths is not None or not marches(config):
        return 1
    width, height = config.image_shape()
    return ray_march_batch(width * height, ray_march_suns(device))


def frames_rendered(renderer: SkyRenderer, prepared, config: AnimationConfig, lookup, positions):
    """``render(sun)``: :func:`render_frame` (``convert`` False) of each of ``positions`` in turn, to be called
    with them in their order and from one thread at a time (:func:`clsky.anim.pipeline.prefetched`), the
    ray march of :func:`ray_march_suns_of` suns per launch (:meth:`SkyRenderer.render_raymarch_suns`: each
    frame the same as its own march), and the sky-view lookup's maps :func:`clsky.render.ray_march_suns` a
    launch (:meth:`SkyRenderer.skyview_maps`, likewise), the frames and maps of the suns after this one kept
    until their turn."""
    batches = isinstance(renderer, SkyRenderer)          # a spectral renderer marches one sun at a time
    march_batch = ray_march_suns_of(config, renderer.engine.device) if batches else 1
    map_batch = ray_march_suns(renderer.engine.device) if batches and lookup == "skyview" else 1
    marched, maps = collections.deque(), collections.deque()
    turns = iter(range(len(positions)))

    def suns_from(index, batch):
        return [position.direction for position in positions[index:index + batch]]

    def render(sun):
        index = next(turns)
        if positions[index] is not sun:
            raise ValueError(f"frames_rendered: sun {index} called out of order")
        raymarch = sky_map = None
        if march_batch > 1 and marches(config):
            if not marched:
                marched.extend(renderer.render_raymarch_suns(prepared, suns_from(index, march_batch), config.altitude))
            raymarch = marched.popleft()
        if map_batch > 1:
            if not maps:
                maps.extend(renderer.skyview_maps(suns_from(index, map_batch), config.altitude,
                                                  skyview_settings(config)))
            sky_map = maps.popleft()
        return render_frame(renderer, prepared, sun.direction, config, lookup, convert=False, raymarch=raymarch,
                            sky_map=sky_map)
    return render


def convert_frames(renderer: SkyRenderer, config: AnimationConfig, frames):
    """The renderer's HDR frames ``frames`` ({name: frame}) in the animation's units: absolute frames
    converted to linear sRGB [cd/m^2] (:func:`spectral_frame_to_linear_srgb` with ``config.wavelengths``,
    else :func:`three_wavelength_frame_to_linear_srgb` on the renderer's device: bit for bit the host's
    values, for half their CPU time, docs/speed-log.md), relative ones as they are."""
    if config.wavelengths is not None:
        frames = {name: spectral_frame_to_linear_srgb(frame, renderer.wavelengths) for name, frame in frames.items()}
    elif config.absolute:
        wavelengths = renderer.table.atmosphere.wavelengths
        frames = {name: three_wavelength_frame_to_linear_srgb(frame, wavelengths, renderer.engine.ctx)
                  for name, frame in frames.items()}
    return frames


#: How near auto-exposure's limit a frame's EV counts as at it [EV]: the smoothing (:func:`clsky.anim.display.
#: smoothed_ev`) halves the distance a frame, steps of 2 EV at most, so a path that stays too dark to meter is
#: within it in 6 frames from 3 EV below it, in 8 from 10 EV below (the sun at -18 deg).
EXPOSURE_LIMIT_MARGIN_EV = 0.05


def exposure_limit_note(config: AnimationConfig, evs) -> str:
    """'' or the note that frames of exposures ``evs`` [EV] were metered at auto-exposure's upper limit
    (:class:`clsky.anim.display.AutoExposure`'s ``max_ev``, with the --exposure compensation): a sky too dark to
    meter (the sun far below the horizon, a polar night: some 3e-7 cd/m^2 on average at +20 EV), lifted to the
    display's key as if it were a dim day sky, grey instead of black."""
    if not config.auto_exposure:
        return ""
    limit = display_pipeline.AutoExposure().max_ev
    at_limit = sum(ev >= limit + config.exposure - EXPOSURE_LIMIT_MARGIN_EV for ev in evs)
    if not at_limit:
        return ""
    return (f"{counted(at_limit, 'frame')} at auto-exposure's {limit:+g} EV limit: a sky too dark to meter, "
            f"shown brighter than it is (--no-auto-exposure --exposure EV fixes one exposure)")


def display(config: AnimationConfig, table) -> display_pipeline.Display:
    """The display pipeline of the animation's frames (:class:`clsky.anim.display.Display`) for ``table`` (a
    ScatteringTable, or with ``config.wavelengths`` a :class:`clsky.spectrum.SpectralTable`)."""
    auto = display_pipeline.AutoExposure() if config.auto_exposure else None
    # absolute frames are linear sRGB already (render_frame); the sun's colour is its spectrum's sRGB,
    # through the frames' own conversion
    if config.wavelengths is not None:
        wavelengths = table.wavelengths
        sun_white = spectral_frame_to_linear_srgb(solar_irradiance_astm_g173(wavelengths), wavelengths)
    elif config.absolute:
        wavelengths = table.atmosphere.wavelengths
        sun_white = three_wavelength_frame_to_linear_srgb(solar_irradiance_astm_g173(wavelengths), wavelengths)
    else:
        # relative frames (the notes' I_I): r, g, b taken as linear Rec. 709, the sun's colour as I_I
        sun_white = table.atmosphere.incident_light
    return display_pipeline.Display(config.tone_map, config.exposure, auto, config.white_balance,
                                    sun_white=sun_white, source="rec709")


def display_frames(pipeline: display_pipeline.Display, hdr, valid, config: AnimationConfig, seed=0, ev=None):
    """(EV, {name: 8-bit frame}, Delta E display) of one sun position's HDR frames: the exposure is
    metered on the reference (:func:`exposure_reference`, the ray march when there is one) and shows
    every frame at that EV (or at ``ev`` [EV] if given: a frame farm's, smoothed in order). The
    Delta E display is the ``display`` of :func:`clsky.anim.metrics.compare_frames`: with both frames, their
    display-linear values (ray march, table lookup), computed once with the 8-bit frames
    (:meth:`clsky.anim.display.Display.encode_and_linear`; the tone curve and gamut mapping were half the
    frame loop's host time when Delta E evaluated them again); else the pipeline at that EV."""
    if ev is None:
        ev = pipeline.exposure(exposure_reference(hdr), valid)
    shown = {name: pipeline.encode_and_linear(frame, ev) for name, frame in hdr.items()}
    # every frame of the sun position takes the same dither pattern (the same seed): drawn once
    noise = tonemap.dither_noise(next(iter(shown.values()))[0].shape, seed) if config.dither else None
    images = {name: tonemap.to_uint8(encoded, dither=config.dither, seed=seed, noise=noise)
              for name, (encoded, _) in shown.items()}
    if "raymarch" in shown and len(shown) == 2:
        lookup = next(name for name in shown if name != "raymarch")
        return ev, images, (shown["raymarch"][1], shown[lookup][1])
    return ev, images, (lambda pixels: pipeline.linear(pixels, ev))


def exposure_reference(hdr):
    """The frame of one sun position's HDR frames that the exposure is metered on: the ray march when
    there is one, else the lookup (table or sky-view map)."""
    return hdr["raymarch"] if "raymarch" in hdr else next(iter(hdr.values()))


@dataclasses.dataclass
class FrameOutputs:
    """What the writer needs of one frame (:func:`frame_outputs`): its index, the 8-bit image (any size:
    the writer pads the MP4's), its metrics row, the mean luminance of each HDR frame (for the temporal
    jumps), and the HDR
    frame to write (None without ``config.hdr``)."""

    index: int
    image: np.ndarray
    row: dict
    means: dict
    hdr: np.ndarray | None


def frame_outputs(pipeline: display_pipeline.Display, hdr, valid, config: AnimationConfig, sun, index: int,
                  ev=None) -> FrameOutputs:
    """Display values, metrics and composite of frame ``index`` (sun position ``sun``) from its HDR
    frames (:func:`render_frame`): everything a frame costs after the render, the same wherever it runs
    (this process, or a frame farm's worker, :mod:`clsky.anim.farm`, with ``ev`` given)."""
    ev, images, shown = display_frames(pipeline, hdr, valid, config, seed=index, ev=ev)
    row = {"frame": index, "sun_zenith_deg": sun.zenith_deg, "sun_azimuth_deg": sun.azimuth_deg,
           "time": sun.time.isoformat() if sun.time is not None else "", "exposure_ev": ev}
    if config.compares:
        image, numbers, means = comparison(hdr, images, shown, valid)
        row.update(numbers)
        frame_hdr = hdr["raymarch"]
    else:
        name = next(iter(hdr))                   # the one frame rendered
        image, frame_hdr = images[name], hdr[name]
        means = {name: metrics.mean_luminance(frame_hdr[None], valid)[0]}
    return FrameOutputs(index, image, row, means, frame_hdr if config.hdr else None)


def comparison(hdr, images, shown, valid):
    """(composite, numbers, means) of one sun position's compared HDR frames ``hdr`` ({lookup: ...,
    'raymarch': ...}, :func:`render_frame`) and their :func:`display_frames` ``images`` and ``shown``: the
    composite of the lookup (labelled with :data:`LOOKUP_NAMES`), the ray march and their relative error
    (:func:`clsky.anim.metrics.composite`), the metrics of :func:`clsky.anim.metrics.compare_frames` with
    ``'lookup'``, the lookup's name, and each frame's mean luminance ({name: value}, for the temporal
    jumps)."""
    lookup = next(name for name in hdr if name != "raymarch")
    # the error map of the third panel and the means are those of the statistics: checked and computed once
    compared = metrics.frame_comparison(hdr["raymarch"], hdr[lookup], valid, display=shown)
    image = metrics.composite([images[lookup], images["raymarch"], metrics.error_image(compared.error_map, valid)],
                              [LOOKUP_NAMES[lookup], "ray march", "relative error"])
    means = dict(zip(("raymarch", lookup), compared.mean_luminance))
    return image, {"lookup": LOOKUP_NAMES[lookup], **compared.numbers}, means


def _frame_writer(config: AnimationConfig, total_frames: int, staging=None) -> writers.FrameWriter:
    return writers.FrameWriter(directory=config.frames_directory, mp4_path=config.output_path, fps=config.fps,
                               total_frames=total_frames, hdr=config.hdr, hdr_precision=config.hdr_precision,
                               force=config.force, prefix="frame", staging=staging, text=metadata(config))


def metadata(config: AnimationConfig) -> dict:
    """What every output of the animation carries (PNG text chunks, EXR header, metrics JSON): clsky's
    version and the TOML scene that reproduces it (``clsky animate --scene``; :mod:`clsky.anim.scene`)."""
    from . import scene

    return scene.output_metadata(scene.scene_text(scene.scene_values(config, "animate"), "animate"))


def check_outputs(config: AnimationConfig, total_frames: int | None = None, option: str | None = None):
    """Check every output of the animation before any work: the MP4, the frame directory (and the
    frames of an earlier run, refused without ``force``), the metrics CSV and JSON.

    Parameters
    ----------
    config : AnimationConfig
    total_frames : int, optional
        Number of frames (default ``config.frames``): the longest frame name.
    option : str, optional
        The command-line option naming the outputs ('--output'): it starts the messages.

    Raises
    ------
    FileExistsError, IsADirectoryError, FileNotFoundError, NotADirectoryError, PermissionError, ValueError
        See :func:`clsky._files.check_output`; nothing is written.
    """
    check_instance("config", config, AnimationConfig, "an AnimationConfig")
    total_frames = check_integer("total_frames", total_frames, 1, writers.MAX_FRAMES, optional=True)
    _frame_writer(config, config.frames if total_frames is None else total_frames).check(option)
    for suffix in (".csv", ".json"):
        check_output(config.metrics_path(suffix), config.force, option)


def render_animation(config: AnimationConfig, ctx=None, progress: Callable[[str, int, int], None] | None = None,
                     report: Callable[[str], None] | None = None, farm=None) -> AnimationResult:
    """Render, compare and write a whole animation (see the module docstring).

    With ``farm`` (a started :class:`clsky.farm.Farm`), the table is built here once and the frames are
    rendered by the farm's Dask workers (:func:`clsky.anim.farm.animation_frames`); they come back in
    order to this process's writer: the same outputs, bit for bit, written the same way.

    ``progress(stage, done, total)`` is called for the table build ('single', 'orders') and for each
    frame ('frames'); ``report(text)`` receives the scene plan before the table is built.

    Every output is checked first (:func:`check_outputs`), and the memory the animation needs
    (:func:`memory_estimate`; InsufficientMemoryError when it does not fit the machine), before the
    table is built. The MP4, the frames and the metrics are written to temporary files and land
    together at the end (frames, metrics, then the MP4; a forced run deletes the stale frames of an
    earlier, longer run): an exception or an interruption leaves the earlier outputs as they were and
    no temporary file. See :class:`clsky._files.StagedWrites` for a failure while the files are renamed.

    NumPy's BLAS runs on one thread throughout, as in the frames' loop (clsky.anim.pipeline: PoCL's workers
    own the cores; the same values on any number of threads): OpenBLAS's threads, woken by the table build's
    and the display set-up's host products and the closing metrics, each spun about 0.1 s on the cores PoCL
    renders on (perf: about 0.2 CPU-s of the default animation; docs/speed-log.md).
    """
    check_arguments(config, ctx=ctx, progress=progress, report=report, farm=farm)
    with host_blas_single_threaded():
        return _render_animation(config, ctx, progress, report, farm)


def check_arguments(config, ctx=None, positions=None, progress=None, report=None, farm=None):
    """ValueError (:class:`clsky.errors.ParameterError`) naming the argument of :func:`render_animation`
    or :func:`planned_animation` that is of the wrong kind, before any work (a dict for ``config`` was an
    AttributeError, ``farm='x'`` one after the table's build, ``report=5`` a TypeError after the plan)."""
    from clsky.farm import Farm

    check_instance("config", config, AnimationConfig, "an AnimationConfig")
    check_context(ctx)
    for name, function in (("progress", progress), ("report", report)):
        if function is not None and not callable(function):
            raise ParameterError(name, "None or a callable", function)
    check_instance("farm", farm, Farm, "None or a clsky.farm.Farm (started)", optional=True)
    if positions is not None:
        items = list(positions) if isinstance(positions, (list, tuple)) else None
        if not items or not all(isinstance(item, sunpath.SunPosition) for item in items):
            raise ParameterError("positions", "None or a non-empty list of clsky.anim.sunpath.SunPosition",
                                 positions)


def _render_animation(config, ctx, progress, report, farm) -> AnimationResult:
    """:func:`render_animation`'s work, under its BLAS limit."""
    start = time.perf_counter()
    positions = sun_positions(config)
    check_outputs(config, len(positions))
    device = device_of(ctx)
    if farm is None:
        workers = check_animation_memory(config, positions, device)
    else:
        check_memory(memory_estimate(config, positions, 1, device), device=device)
    planned = planned_animation(config, positions, ctx=ctx)
    camera, directions, valid, plan = planned.camera, planned.directions, planned.valid, planned.plan
    if plan is not None and report is not None:
        report(plan.describe())
    lookup = lookup_of(config, plan)
    # the frames need the data and the gathered sum only: the higher orders (K - 1 tables) go
    if farm is None:
        renderer, table = make_renderer(config, plan, ctx=ctx, progress=progress)
        frames = _local_frames(config, positions, renderer, renderer.prepare(directions, valid), valid, lookup,
                               workers)
    else:
        from .farm import animation_frames

        table = make_table(config, plan, ctx=ctx, progress=progress)
        frames = animation_frames(farm, config, table, positions, lookup)
    had_frames_directory = config.frames_directory.is_dir()
    try:
        with StagedWrites() as staging:
            rows, temporal, paths, removed = _write_animation(config, positions, frames, table, plan, lookup,
                                                              staging, progress)
    except BaseException:
        if not had_frames_directory:             # created for the temporaries of the frames
            with contextlib.suppress(OSError):
                config.frames_directory.rmdir()  # only if empty
        raise
    seconds = time.perf_counter() - start
    summary = f"{len(positions)} frames {camera.width}x{camera.height} ({config.method}) in {seconds:.1f} s"
    if config.compares:
        worst = max(rows, key=lambda r: r["p95_rel"])
        summary += (f"; {LOOKUP_NAMES[lookup]} against the ray march, worst frame {worst['frame']} "
                    f"(sun zenith {worst['sun_zenith_deg']:.1f} deg): "
                    f"95th-percentile error {100 * worst['p95_rel']:.1f} %, mean Delta E {worst['mean_delta_e']:.2f}; "
                    f"worst temporal jumps at frames {temporal['worst_frames'][:3]}")
    if note := exposure_limit_note(config, [row["exposure_ev"] for row in rows]):
        summary += f"; {note}"
    if removed:
        summary += f"; deleted {counted(len(removed), 'stale frame file')} of an earlier run"
    summary += f" -> {config.output_path}"
    return AnimationResult(rows, temporal, paths, seconds, summary, removed)


class _ExposureOrder:
    """:meth:`clsky.anim.display.Display.next_ev`, the auto-exposure's smoothing, in frame order for frames
    shown on several threads (:func:`clsky.anim.pipeline.in_order`): frame i's call waits for frame
    i - 1's. The threads take the frames in order, so whichever frame waits, the one before it is running
    or done. A frame that fails before its call (:meth:`fail`) or in it stops the order there: the frames
    before it go on, those after it raise instead of waiting, and the caller, taking the results in order,
    meets the failed frame's own error first."""

    def __init__(self, pipeline: display_pipeline.Display):
        self._pipeline = pipeline
        self._turn = threading.Condition()
        self._next = 0
        self._failed_at = None          # the first frame that failed, if any

    def _stopped_before(self, index):
        return self._failed_at is not None and self._failed_at < index

    def next_ev(self, index: int, metered):
        with self._turn:
            self._turn.wait_for(lambda: self._next == index or self._stopped_before(index))
            if self._stopped_before(index):
                raise RuntimeError(f"frame {index} not shown: frame {self._failed_at} before it failed")
            try:
                return self._pipeline.next_ev(metered)
            except BaseException:
                self._fail(index)
                raise
            finally:
                self._next += 1
                self._turn.notify_all()

    def fail(self, index: int):
        """Frame ``index`` failed before its call."""
        with self._turn:
            self._fail(index)
            self._turn.notify_all()

    def _fail(self, index):
        self._failed_at = index if self._failed_at is None else min(self._failed_at, index)


def metered_exposure(pipeline: display_pipeline.Display, hdr, valid):
    """The auto-exposure's metered EV of one sun position's HDR frames (``Display.metered_ev`` of
    :func:`exposure_reference`, before smoothing): what a host thread here and a frame farm's worker
    (:mod:`clsky.anim.farm`) compute beside each other's frames; None without auto-exposure."""
    return pipeline.metered_ev(exposure_reference(hdr), valid)


def _local_frames(config, positions, renderer, prepared, valid, lookup, workers):
    """The frame source of a single-process run: ``frames(pipeline_of)`` yields each frame's
    :class:`FrameOutputs` in order, rendered and shown here (clsky.anim.pipeline): frame i + 1 renders on
    a worker thread while ``workers`` host threads convert, meter, display and compare the frames before
    it (:func:`clsky.anim.pipeline.in_order`; the exposures smoothed in frame order, :class:`_ExposureOrder`)
    and this thread writes them; 0 ``workers`` (OVERLAP_FRAMES = False) does all of it here, one frame
    after the other. The same frames either way. ``pipeline_of()`` returns the display pipeline: it is
    called once the first frame's render has started (on the worker thread), so that the display's
    set-up (importing colour-science, on one core) runs beside that render."""
    def frames(pipeline_of):
        rendered = pipeline_module.prefetched(frames_rendered(renderer, prepared, config, lookup, positions),
                                              positions, overlap=OVERLAP_FRAMES)
        with contextlib.closing(rendered):
            yield from _shown_frames(pipeline_of(), rendered)

    def _shown_frames(pipeline, rendered):
        order = _ExposureOrder(pipeline)

        def shown(job):
            # job: [index, sun, rendered frames], the last taken out of it so that they go once converted and
            # no longer referenced where they were drawn (the last frame drawn stays referenced there, by the
            # render's generator, until the next draw: the frame the memory estimate counts as waiting)
            index, sun, raw = job[0], job[1], job.pop()
            try:
                hdr = convert_frames(renderer, config, raw)
                del raw
                metered = metered_exposure(pipeline, hdr, valid)
            except BaseException:
                order.fail(index)
                raise
            return frame_outputs(pipeline, hdr, valid, config, sun, index, ev=order.next_ev(index, metered))

        def jobs():
            for index, (sun, raw) in enumerate(rendered):
                job = [index, sun, raw]
                del raw
                yield job

        yield from pipeline_module.in_order(shown, jobs(), workers)
    return frames


def _write_animation(config, positions, frames, table, plan, lookup, staging, progress):
    """Stage the frames of ``frames(pipeline_of)`` (:class:`FrameOutputs` in order: :func:`_local_frames`,
    or a farm's; ``pipeline_of()`` returns the display pipeline, set up at its first call), the MP4 and the
    metrics in ``staging``; returns the metric rows, the temporal jumps, the target paths and the stale
    frames to be deleted."""
    rows, means = [], {name: [] for name in (*LOOKUP_NAMES, "raymarch")}
    with contextlib.ExitStack() as stack:
        writer = stack.enter_context(_frame_writer(config, len(positions), staging))

        def set_up_display():
            """The display pipeline, set up when the frame source asks for it (a local one starts its first
            render before: _local_frames); then the frames' host products (sRGB and white-balance matrices,
            Oklab, XYZ for Delta E) go to one BLAS thread: beside PoCL's workers OpenBLAS's threads cost
            ~100x the CPU of one (docs/speed-log.md). Limited after the set-up, whose colour-science import
            may load a BLAS of its own (SciPy's), which a limit set before would not see."""
            pipeline = display(config, table)
            stack.enter_context(host_blas_single_threaded())
            return pipeline

        pipeline_of = functools.cache(set_up_display)
        produced = stack.enter_context(contextlib.closing(frames(pipeline_of)))
        for out in produced:
            sun = positions[out.index]
            for name, value in out.means.items():
                means[name].append(value)
            writer.write(out.index, out.image, hdr=out.hdr,
                         hdr_attributes=_hdr_attributes(config, table, sun) if config.hdr in ("exr", "hdr") else None)
            rows.append(out.row)
            if progress is not None:
                progress("frames", out.index + 1, len(positions))
        pipeline = pipeline_of()        # the frame source's (set up inside the stack, whatever the source did)
    paths = list(writer.paths)          # the frames and the MP4: they land when ``staging`` commits
    temporal = {}
    if config.compares:
        # the floor: what is invisible at the most sensitive exposure shown (with a fixed EV, that EV)
        jumps = metrics.temporal_jumps(np.array(means[lookup]), np.array(means["raymarch"]),
                                       exposure=2.0 ** max(row["exposure_ev"] for row in rows))
        temporal = {"lookup": LOOKUP_NAMES[lookup], "table_jumps": np.asarray(jumps["table_jumps"]).tolist(),
                    "raymarch_jumps": np.asarray(jumps["raymarch_jumps"]).tolist(),
                    "excess": np.asarray(jumps["excess"]).tolist(),
                    "worst_frames": [int(i) for i in jumps["worst_frames"]]}
        for row, excess in zip(rows, temporal["excess"]):
            row["temporal_excess_jump"] = float(excess)
    paths.append(writers.write_csv(config.metrics_path(".csv"), rows, force=config.force, staging=staging))
    paths.append(writers.write_json(config.metrics_path(".json"), {
        **metadata(config),
        "config": {k: (str(v) if isinstance(v, (datetime.date, pathlib.Path)) else v)
                   for k, v in dataclasses.asdict(config).items()},
        "table": {"settings": table.settings.to_dict(), "orders": table.orders_record,
                  "metadata": table.metadata, "frame_units": frame_units(config, table)},
        "display": pipeline.describe(),
        "lookup": None if lookup is None else LOOKUP_NAMES[lookup],
        "plan": None if plan is None else {"quality": plan.level.name, "work_fraction": plan.work_fraction,
                                           "renderer": plan.renderer,
                                           "decisions": [list(d) for d in plan.decisions]},
        "frames": rows, "temporal": temporal}, force=config.force, staging=staging))
    return rows, temporal, paths, list(writer.stale_paths)
