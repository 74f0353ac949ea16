"""HDR sky radiance per pixel on OpenCL (``kernels/render.cl``): by table lookup and by ray marching.

:class:`SkyRenderer` owns one :class:`RenderEngine` and a table uploaded once; each call renders
one frame for one sun direction and observer altitude. Directions are unit vectors in the observer's
local frame (x east, y north, z zenith). NumPy twins: :func:`clsky.reference.render_table`,
:func:`clsky.reference.render_raymarch` and :func:`clsky.reference.render_skyview` (the per-frame sky-view
map's sampling, :mod:`clsky.skyview`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pyopencl.array as cla

from . import _atmosphere_cl, _cl, reference
from .errors import as_real_array, check_instance, is_finite_real, short
from .ground import padded4
from .lookup import MAX_QUERY_ALTITUDE, check_kernel_buffer, check_table_data
from .resources import check_memory, device_of, estimate_directions_memory, estimate_render_memory
from .settings import MAPPINGS, TableSettings
from .table import ScatteringTable
from .transmittance import COMMON_SOURCES, NO_GATHERED_GRID, TransmittanceEngine, azimuth_defines, column_channels, \
    gathered_source_reals, quadrature_defines, upload_gathered_source

__all__ = ["SkyRenderer", "RenderEngine", "SUN_ANGULAR_RADIUS_DEG", "RAYMARCH_DEFAULTS", "RAY_MARCH_SUNS",
           "sun_disc_radiance", "check_directions", "check_render_table", "ray_march_suns", "ray_march_batch"]

#: Angular radius of the sun disc [deg].
SUN_ANGULAR_RADIUS_DEG = 0.2665
#: Quadrature of the per-pixel ray march (its "samples per ray"): Keller & Bohn nodes, which the
#: Monte Carlo comparison showed to converge fastest for observers near the ground, and the sun's
#: transmittance from a 2D table built with many steps (cheap: it is built once per renderer).
#: 48 samples: fisheye frames from the ground within 0.25 % (95th percentile of the relative luminance
#: error) of a 256-sample march by day, 2.3 % at most at sun elevation -2 deg (measured).
RAYMARCH_DEFAULTS = TableSettings(view_steps=48, sun_steps=256, sampling="keller_bohn", sun_transmittance="table",
                                  transmittance_size=(128, 512), orders=1)


#: How far from 1 a view direction's length may be (float32 unit vectors are within 1e-7; a float16 one is not).
DIRECTION_LENGTH_TOLERANCE = 1e-5


def check_directions(directions, sun_direction, altitude):
    """Validated (n, 3) directions, sun direction (3,) and altitude; ValueError names the bad one."""
    directions = as_real_array("directions", directions, "unit vectors of shape (..., 3)")
    if directions.ndim < 1 or directions.shape[-1] != 3:
        raise ValueError(f"directions must have shape (..., 3), got {directions.shape}")
    lengths = np.linalg.norm(directions, axis=-1)
    wrong = ~(np.abs(lengths - 1.0) <= DIRECTION_LENGTH_TOLERANCE)       # NaN and infinite lengths too
    if wrong.any():             # which and how many: one message for NaN, zero and non-unit vectors said neither
        first = tuple(int(i) for i in np.argwhere(wrong)[0]) if wrong.ndim else ()
        where = f"[{', '.join(map(str, first))}]" if first else ""
        shown = ", ".join(f"{v:.9g}" for v in directions[first])
        raise ValueError(f"directions must be finite unit vectors (length within {DIRECTION_LENGTH_TOLERANCE:g} of "
                         f"1, masked pixels too): {int(wrong.sum())} of {wrong.size} are not, the first "
                         f"directions{where} = ({shown})")
    sun = as_real_array("sun_direction", sun_direction, "a finite unit vector of 3 values")
    if sun.shape != (3,) or not np.all(np.isfinite(sun)) or abs(np.linalg.norm(sun) - 1.0) > 1e-6:
        raise ValueError(f"sun_direction must be a finite unit vector of 3 values, got {short(sun_direction)}")
    if not (is_finite_real(altitude) and 0.0 <= altitude <= MAX_QUERY_ALTITUDE):
        raise ValueError(f"altitude must be finite and in [0, {MAX_QUERY_ALTITUDE:g}] m, got {short(altitude)}")
    return directions, sun, float(altitude)


def check_render_table(table):
    """Check what the renderer uploads from ``table`` against its settings, even for a table whose
    attributes were replaced after construction: :meth:`ScatteringTable.validate` (data (D, H, W, C)
    with C = ``settings.channels``, gathered (D, H, W, 6) or None, their dtypes, every value finite and
    >= 0: one pass over the arrays, once per renderer) and the kernels' 32-bit index range.

    Raises
    ------
    ValueError
        ``table`` is no ScatteringTable, or (:class:`~clsky.table.TableFormatError`) naming the array and
        what is wrong.
    """
    check_instance("table", table, ScatteringTable, "a ScatteringTable (ScatteringTable.build or .load)")
    table.validate()
    if table.settings.is_4d:
        from .lookup4d import check_table4d_data

        check_table4d_data(table.data)
    else:
        check_table_data(table.data)


def sun_disc_radiance(atmosphere, sun_direction, altitude, steps=512):
    """Radiance of the sun disc seen from ``altitude``: I_I T_sun / Omega_sun (r, g, b).

    T_sun is the transmittance along the sun ray (every species, ozone included:
    :func:`clsky.reference.transmittance`; Keller & Bohn trapezoid with ``steps`` steps); 0
    when the sun is below the horizon (its ray hits the planet). Omega_sun = 2 pi (1 - cos 0.2665 deg).
    """
    rp, ra = atmosphere.planet_radius, atmosphere.top_radius
    # a sun direction is taken within 1e-6 of unit length: its cosine within [-1, 1], as the transmittance
    # twin requires (a cosine in range keeps its bits)
    mu = min(1.0, max(-1.0, float(sun_direction[2])))
    h = float(altitude)
    if mu < reference.horizon_cos(h, rp):
        return np.zeros(3)
    if h > atmosphere.atmosphere_height:     # from space: the sun ray may cross the atmosphere's limb
        r = rp + h
        impact = r * math.sqrt(max(1.0 - mu * mu, 0.0))
        if mu >= 0.0 or impact >= ra:
            transmittance = np.ones(3)
        else:
            chord = 2.0 * math.sqrt(ra * ra - impact * impact)
            entry_mu = -math.sqrt(max(1.0 - (impact / ra) ** 2, 0.0))
            transmittance = reference.transmittance(atmosphere, atmosphere.atmosphere_height, entry_mu, chord,
                                                    steps, "uniform")
    else:
        length = reference.distance_to_top(h, mu, rp, ra)
        transmittance = reference.transmittance(atmosphere, h, mu, length, steps, "keller_bohn")
    solid_angle = 2.0 * math.pi * (1.0 - math.cos(math.radians(SUN_ANGULAR_RADIUS_DEG)))
    return atmosphere.incident_light * transmittance / solid_angle


#: Work-items per work-group of the render kernels (each renders the engine's vector_width pixels).
RENDER_WORK_GROUP = 64

#: Suns (frames) a ray-march launch marches each pixel's ray for at once
#: (:meth:`SkyRenderer.render_raymarch_suns`, ``-DRAY_SUNS``, kernels/view_ray.cl): a ray's geometry,
#: densities, view transmittance and the lookups' altitude and view parts are computed once for all of
#: them, each sun's sums are the operations of its own march (the same frames, bit for bit on PoCL).
#: None: :func:`ray_march_suns` of the device. Measured in docs/speed-log.md ("The ray march of four
#: suns a launch").
RAY_MARCH_SUNS = None
#: At most this many bytes of float64 frames per ray-march launch (the frames it returns; its output on
#: the device no more): larger frames take fewer suns at once (:func:`ray_march_batch`).
RAY_MARCH_BATCH_BYTES = 64 * 2**20


def ray_march_suns(device) -> int:
    """:data:`RAY_MARCH_SUNS` if set, else the suns per ray-march launch for ``device`` (a pyopencl.Device):
    4 on CPUs, where the sun-independent share of a node was 43 % of the march's CPU (docs/speed-log.md),
    1 elsewhere (not measured on a GPU, whose march takes milliseconds)."""
    if RAY_MARCH_SUNS is not None:
        if RAY_MARCH_SUNS not in (1, 2, 4, 8):
            raise ValueError(f"clsky.render.RAY_MARCH_SUNS must be None, 1, 2, 4 or 8, got {RAY_MARCH_SUNS!r}")
        return RAY_MARCH_SUNS
    import pyopencl as cl

    return 4 if device.type & cl.device_type.CPU else 1


def ray_march_batch(pixels: int, suns: int) -> int:
    """Suns per ray-march launch for frames of ``pixels`` pixels: ``suns`` (:func:`ray_march_suns`), halved
    until the launch's float64 frames (pixels, 3) fit :data:`RAY_MARCH_BATCH_BYTES`, at least 1 (512 x 512
    frames: 8 suns at most)."""
    while suns > 1 and suns * max(pixels, 1) * 24 > RAY_MARCH_BATCH_BYTES:
        suns //= 2
    return suns


def skyview_settings(settings):
    """``settings`` for a sky-view map: a :class:`~clsky.skyview.SkyViewSettings`, or its defaults for None;
    ValueError naming ``settings`` otherwise."""
    from .skyview import SkyViewSettings

    check_instance("settings", settings, SkyViewSettings, "None (the defaults) or a SkyViewSettings", optional=True)
    return settings or SkyViewSettings()


def _mask(name, value) -> np.ndarray:
    """``value`` as a bool array if it holds bools, or integers 0 and 1; ValueError naming ``name`` otherwise:
    as bools, NaN read as True and None as False."""
    array = np.asarray(value)
    if array.dtype == bool:
        return array
    if array.dtype.kind in "iu" and ((array == 0) | (array == 1)).all():
        return array.astype(bool)
    raise ValueError(f"{name} must be a mask of bools (or of 0 and 1), got {short(value)} of dtype {array.dtype}")


def _sun_list(sun_directions) -> list:
    """``sun_directions`` (a sequence of suns) as a non-empty list; ValueError naming it otherwise."""
    try:
        suns = list(sun_directions)
    except TypeError:
        raise ValueError(f"sun_directions must be a sequence of sun directions of 3 values each, got "
                         f"{short(sun_directions)} ({type(sun_directions).__name__})") from None
    if not suns:
        raise ValueError("sun_directions must hold at least one sun direction")
    return suns


@dataclasses.dataclass(frozen=True)
class PreparedDirections:
    """A camera's directions on the device (:meth:`SkyRenderer.prepare`), with their shape and mask."""

    array: cla.Array
    shape: tuple
    valid: cla.Array        # uint8 per pixel: 0 renders black
    #: what the renderer derives from the directions alone, once for every frame (``"view_zenith"``: the
    #: sky-view lookup's angles, :meth:`SkyRenderer.view_zenith_angles`)
    derived: dict = dataclasses.field(default_factory=dict, compare=False, repr=False)


class RenderEngine(_cl.Engine):
    """The render program, built for the ray march's quadrature (``ray_settings``)."""

    def __init__(self, ray_settings: TableSettings = RAYMARCH_DEFAULTS, ctx=None, profile=False, fast_math=False):
        self.ray_settings = ray_settings
        super().__init__(ctx, np.dtype(ray_settings.dtype), profile, fast_math)

    def program_sources(self):
        declaration = _atmosphere_cl.declaration(self.ctx.devices[0], self.dtype)
        return (("real.cl", declaration) + COMMON_SOURCES[1:]
                + ("mapping.cl", "mapping4d.cl", "phase.cl", "view_ray.cl", "lookup.cl", "lookup4d.cl", "render.cl",
                   "skyview.cl"))

    def build_options(self):
        return super().build_options() + quadrature_defines(self.ray_settings, self.vector_width)


class SkyRenderer:
    """Renders HDR frames from a :class:`~clsky.table.ScatteringTable`, by lookup and by ray march.

    Parameters
    ----------
    table : ScatteringTable
        Its atmosphere, data and (for the ray march's higher orders) gathered in-scatter sum.
    ray_settings : TableSettings, optional
        Quadrature of the ray march (view_steps = samples per ray, sun_steps, sampling,
        sun_transmittance, transmittance_size, dtype); defaults to :data:`RAYMARCH_DEFAULTS` with the
        table's dtype.
    ctx, fast_math
        See :class:`clsky._cl.Engine`.

    The render methods share their conventions: ``directions`` are unit view vectors (..., 3) from the
    observer in the local (east, north, up) frame, or :meth:`prepare`'s result; ``sun_direction`` the
    unit vector toward the sun in the same frame; ``altitude`` the observer's height above the ground
    [m], in [0, 1e10] (above the atmosphere's top, rays enter it from space); ``valid`` an optional
    mask (invalid pixels are 0). They return float64 radiance (..., 3) at the table's three
    wavelengths, in the table's units (``table.metadata["units"]``, :func:`clsky.solar.radiance_units`):
    W m^-2 sr^-1 nm^-1 for an atmosphere lit by the solar spectrum (:func:`clsky.solar.with_solar_spectrum`,
    as the animations' absolute frames are), else relative: the incident light I_I per sr (both presets
    as they are). A sun outside the table's ``sun_cos_range`` is refused (``ValueError``) where the frame
    reads the table's sun axis: the lookups, and the ray march and sky-view map of a table with higher
    orders.

    Threads may share a renderer: its methods run one at a time (:func:`clsky._cl.serialized`; two
    threads' launches swapped their arguments, wrong frames or PoCL aborting). :meth:`close` (or the end
    of a ``with`` block) releases its device memory; its methods then raise ValueError.

    Raises
    ------
    InsufficientMemoryError
        When the table's device copies do not fit the device or the host
        (:func:`clsky.resources.check_memory`; :meth:`prepare` checks a camera's buffers).
    """

    def __init__(self, table: ScatteringTable, ray_settings: TableSettings | None = None, ctx=None,
                 fast_math=False):
        check_render_table(table)
        check_instance("ray_settings", ray_settings, TableSettings,
                       "a TableSettings or None (the ray march's defaults)", optional=True)
        self.table = table
        self.ray_settings = ray_settings or RAYMARCH_DEFAULTS.replace(dtype=table.settings.dtype)
        check_memory(estimate_render_memory(table.settings, (0, 0), ray_settings=self.ray_settings,
                                            count_table=False), device=device_of(ctx, self.ray_settings.dtype))
        self.engine = RenderEngine(self.ray_settings, ctx=ctx, fast_math=fast_math)
        self.queue = self.engine.queue
        dtype = self.engine.dtype
        # the kernels get the sizes of what was uploaded here, never re-read from the table
        self._table_shape = table.data.shape
        self._gathered_shape = None if table.gathered is None else table.gathered.shape
        self._has_gathered = table.gathered is not None
        self._atmosphere_d = _atmosphere_cl.to_device(self.queue, table.atmosphere, dtype)
        self._table_d = cla.to_device(self.queue, np.ascontiguousarray(table.data, dtype=dtype))
        self._defines = (_atmosphere_cl.feature_defines(table.atmosphere)
                         + (azimuth_defines(table.settings, interleaved=True) if self._has_gathered else []))
        # (D, H, W, 6) padded to (D, H, W, 8), or with azimuth harmonics (M + 1, D, H, W, 6) interleaved into
        # (D, H, W, M + 1, 8) on the device; without it a small zero table the kernel does not read
        self._gathered_d = upload_gathered_source(self.queue, table.gathered, dtype)
        # the sky's irradiance on a reflecting ground per sun node (D, 4); not read for a black ground
        self._ground_depth = table.settings.size[2] if table.atmosphere.has_ground else 2
        ground = padded4(table.ground_irradiance, dtype) if table.atmosphere.has_ground else np.zeros((2, 4), dtype)
        self._ground_d = cla.to_device(self.queue, ground)
        self._sun_table_size = (self.ray_settings.transmittance_size
                                if self.ray_settings.sun_transmittance == "table" else (2, 2))
        if self.ray_settings.sun_transmittance == "table":
            transmittance = TransmittanceEngine(self.engine.ctx, dtype, steps=self.ray_settings.sun_steps,
                                                sampling=self.ray_settings.sampling)
            self._sun_table_d = transmittance.column_density_table(table.atmosphere,
                                                                   self.ray_settings.transmittance_size,
                                                                   queue_only=True)
            transmittance.queue.finish()
        else:
            self._sun_table_d = cla.zeros(self.queue, 2 * 2 * column_channels(table.atmosphere), dtype)
        self._cos_sun_radius = math.cos(math.radians(SUN_ANGULAR_RADIUS_DEG))
        self._skyview_nodes = {}      # (settings, altitude) -> the sky-view map's prepared node directions

    @_cl.serialized
    def prepare(self, directions, valid=None):
        """Upload a camera's directions (..., 3) once, for many frames: pass the result as ``directions``."""
        directions, _, _ = check_directions(directions, (0.0, 0.0, 1.0), 0.0)
        shape = directions.shape[:-1]
        check_memory(estimate_directions_memory(int(np.prod(shape)), self.engine.dtype), device=self.engine.device)
        flat = np.ascontiguousarray(directions.reshape(-1, 3), dtype=self.engine.dtype)
        mask = np.ones(shape, dtype=bool) if valid is None else _mask("valid", valid)
        if mask.shape != shape:
            raise ValueError(f"valid must have the directions' shape {shape}, got {mask.shape}")
        return PreparedDirections(cla.to_device(self.queue, flat), shape,
                                  cla.to_device(self.queue, np.ascontiguousarray(mask.ravel(), dtype=np.uint8)))

    def _launch(self, name, directions, sun_direction, altitude, valid, extra_args, buffers, sun_disc=True):
        """Launch kernel ``name`` (render_table, render_table4d, render_skyview) for one sun: :meth:`_launch_suns`."""
        return self._launch_suns(name, directions, [sun_direction], altitude, valid, extra_args, buffers, sun_disc)[0]

    def _launch_suns(self, name, directions, sun_directions, altitude, valid, extra_args, buffers, sun_disc=True):
        """Frames (len(sun_directions), ..., 3) of kernel ``name`` once ``buffers`` ((argument, array_d, values
        indexed) for ``extra_args``) and the directions, mask and output have passed
        :func:`~clsky.lookup.check_kernel_buffer`; ``sun_disc`` False: without the sun's disc (its radiance
        passed as 0). render_raymarch takes the suns :func:`ray_march_batch` at a time (the last launch's
        missing suns repeat its last one, their frames dropped), the other kernels one sun."""
        directions = self._prepared(directions, valid)
        checked = [check_directions(np.zeros((0, 3)), sun_direction, altitude) for sun_direction in sun_directions]
        suns, altitude = [sun for _, sun, _ in checked], checked[0][2]
        if name in ("render_table", "render_table4d") or self._has_gathered:
            for sun in suns:
                self._check_sun_covered(sun)
        shape, directions_d = directions.shape, directions.array
        n = directions_d.shape[0]
        if math.prod(shape) != n:
            raise ValueError(f"{name}: prepared directions of shape {shape} hold {n} directions")
        if n == 0:                              # no pixel: nothing to launch
            return np.zeros((len(suns),) + shape + (3,))
        batch = (ray_march_batch(n, ray_march_suns(self.engine.device))
                 if name == "render_raymarch" and len(suns) > 1 else 1)
        out_d = cla.empty(self.queue, (batch, n, 3), self.engine.dtype)
        for argument, array_d, count in buffers + [("directions", directions_d, 3 * n),
                                                   ("out", out_d, batch * 3 * n)]:
            check_kernel_buffer(name, argument, array_d, count, self.engine.dtype)
        check_kernel_buffer(name, "valid", directions.valid, n, np.uint8)
        kernel = self.engine.kernels_with(self._defines + ([f"-DRAY_SUNS={batch}"] if batch > 1 else []))[name]
        global_size, local_size = self._work_size(kernel, n)
        # the frames of each launch copied out, so that none holds its launch's download (padded suns included)
        frames = np.empty((len(suns),) + shape + (3,)) if len(suns) > 1 else None
        for start in range(0, len(suns), batch):
            launch = suns[start:start + batch]
            launch += launch[-1:] * (batch - len(launch))
            discs = [sun_disc_radiance(self.table.atmosphere, sun, altitude) if sun_disc else np.zeros(3)
                     for sun in launch]
            if name == "render_raymarch":
                suns_d = cla.to_device(self.queue, np.array([np.concatenate([sun, [0.0], disc, [0.0]])
                                                             for sun, disc in zip(launch, discs)], self.engine.dtype))
                sun_args = (suns_d.data,)
            else:
                sun_args = (self.engine.real4(launch[0]),)
            kernel(self.queue, global_size, local_size, self._atmosphere_d, *extra_args, np.int32(n),
                   directions_d.data, directions.valid.data, *sun_args, self.engine.real(altitude),
                   *(() if name == "render_raymarch" else (self.engine.real4(discs[0]),)),
                   self.engine.real(self._cos_sun_radius), out_d.data)
            out = out_d.get()[:len(suns) - start, :n]
            if frames is None:                  # one sun: the download itself
                return out.reshape((1,) + shape + (3,)).astype(np.float64, copy=False)
            frames[start:start + batch] = out.reshape((len(out),) + shape + (3,))
        return frames

    def _prepared(self, directions, valid):
        """``directions`` as :class:`PreparedDirections`: prepared here with ``valid`` unless they are
        already (then ``valid`` must be None: the mask is given to :meth:`prepare`)."""
        if not isinstance(directions, PreparedDirections):
            return self.prepare(directions, valid)
        if valid is not None:
            raise ValueError("valid must be given to prepare(), not with prepared directions")
        if directions.array.context != self.engine.ctx:     # PoCL took them; OpenCL forbids another context's buffers
            raise ValueError("directions were prepared by a renderer of another OpenCL context: prepare them with "
                             "this renderer")
        return directions

    def _work_size(self, kernel, n):
        """Global and local sizes of a launch of ``kernel`` over ``n`` pixels, ``vector_width`` a work-item:
        an explicit work-group size (left to PoCL, a large frame got work-groups whose private arrays, the
        ray march's per-lane sums and ground values, overflowed its worker threads' stacks: segmentation
        fault at 256 x 256 with a ground), the same for every frame size (one kernel object per program on
        PoCL; a small frame's launch padded to it, :func:`clsky._cl.launch_size`); the kernels return for
        items beyond n."""
        return _cl.launch_size(kernel, self.engine.device, (-(-n // self.engine.vector_width),),
                               (RENDER_WORK_GROUP,))

    def _check_sun_covered(self, sun):
        """A table planned for a scene covers its sun path only (``sun_cos_range``): refuse a sun outside
        it rather than return the light of the range's end. The zenith cosine is the normalised vector's:
        a sun direction is taken within 1e-6 of unit length (:func:`check_directions`), and z = 1 + 9e-7
        is the zenith, not beyond it."""
        low, high = self.table.settings.sun_cos_range
        cos_sun = float(np.clip(sun[2] / np.linalg.norm(sun), -1.0, 1.0))
        if not low - 1e-12 <= cos_sun <= high + 1e-12:
            raise ValueError(f"sun_direction: its zenith cosine {cos_sun:.9g} is outside the table's "
                             f"sun_cos_range [{low:.9g}, {high:.9g}] (plan the table for this sun path)")

    @_cl.serialized
    def render_table(self, directions, sun_direction, altitude=0.0, valid=None):
        """HDR radiance (..., 3) by table lookup; ``directions`` (..., 3) unit vectors (or
        :meth:`prepare`'s result), ``valid`` an optional mask (invalid pixels are 0)."""
        t = self._check_table_unchanged()
        if t.settings.is_4d:
            raise ValueError("render_table: the table is 4D (parameterization '4d'): render it with render_lut4d")
        depth, height, width, channels = self._table_shape
        _, sun_direction, altitude = check_directions(np.zeros((0, 3)), sun_direction, altitude)
        inside = 0.0 <= altitude <= t.atmosphere.atmosphere_height
        view_slice = self._view_slice(altitude, float(sun_direction[2])) if inside else np.zeros((2, 1))
        slice_d = cla.to_device(self.queue, np.ascontiguousarray(view_slice, dtype=self.engine.dtype))
        args = (self._table_d.data, np.int32(width), np.int32(height), np.int32(depth), np.int32(channels),
                np.int32(MAPPINGS[t.settings.mapping]), self.engine.real2(t.settings.sun_w_range), slice_d.data,
                np.int32(inside))
        buffers = [("table", self._table_d, depth * height * width * channels),
                   ("slice", slice_d, height * channels if inside else slice_d.size)]
        return self._launch("render_table", directions, sun_direction, altitude, valid, args, buffers)

    def _check_table_unchanged(self):
        """The table, once the shapes of its data and gathered and its settings' size and channels are
        checked to be those of the upload (a frozen dataclass can still be changed with
        object.__setattr__): ValueError otherwise."""
        t = self.table
        uploaded = (self._table_shape, self._table_shape, self._gathered_shape)
        now = (np.shape(t.data), t.data_shape,
               None if t.gathered is None else np.shape(t.gathered))
        if now != uploaded:
            raise ValueError(f"the table changed since the renderer uploaded it (data, settings and gathered "
                             f"shapes {uploaded} then, {now} now): make a new SkyRenderer")
        return t

    def _view_slice(self, altitude, cos_sun):
        """The table interpolated (bilinearly, in texture space) at one altitude and sun cosine: (H, C)."""
        from .mapping import altitude_to_u, cos_to_sun_t

        t = self.table
        width, height, depth = t.settings.size
        position = []
        for coordinate, n in ((altitude_to_u(altitude, t.atmosphere.atmosphere_height, t.settings.mapping), width),
                              (cos_to_sun_t(cos_sun, t.settings.mapping, t.settings.sun_cos_range), depth)):
            f = float(coordinate) * (n - 1)
            lower = min(max(int(f), 0), n - 2)
            position.append((lower, f - lower))
        (x0, ax), (z0, az) = position
        data = t.data
        return ((1 - az) * ((1 - ax) * data[z0, :, x0] + ax * data[z0, :, x0 + 1])
                + az * ((1 - ax) * data[z0 + 1, :, x0] + ax * data[z0 + 1, :, x0 + 1]))

    @_cl.serialized
    def render_lut4d(self, directions, sun_direction, altitude=0.0, valid=None):
        """HDR radiance (..., 3) by lookup in a 4D table (``parameterization='4d'``, :mod:`clsky.table4d`):
        quadrilinear in altitude, view zenith (never across the horizon), sun zenith and azimuth, the
        phase functions at the exact scattering angle; ``directions`` and ``valid`` as :meth:`render_table`.
        Twin: :func:`clsky.reference.render_table4d`."""
        t = self._check_table_unchanged()
        if not t.settings.is_4d:
            raise ValueError("render_lut4d: the table is 3D (parameterization 'elek3d'): build it with "
                             "parameterization '4d', or render it with render_table")
        azimuths, depth, height, width, channels = self._table_shape
        _, sun_direction, altitude = check_directions(np.zeros((0, 3)), sun_direction, altitude)
        table_d, shape = self._table_d, self._table_shape
        if 0.0 <= altitude <= t.atmosphere.atmosphere_height:   # one (h, mu_s) per frame: a slice
            from .mapping import altitude_to_u, cos_to_sun_t
            from .reference import _node4d

            x0, ax = _node4d(altitude_to_u(altitude, t.atmosphere.atmosphere_height, t.settings.mapping)
                             * (width - 1), width)
            z0, az = _node4d(cos_to_sun_t(float(sun_direction[2]), t.settings.mapping, t.settings.sun_cos_range)
                             * (depth - 1), depth)
            data = t.data
            view_slice = ((1 - az) * ((1 - ax) * data[:, z0, :, x0] + ax * data[:, z0, :, x0 + 1])
                          + az * ((1 - ax) * data[:, z0 + 1, :, x0] + ax * data[:, z0 + 1, :, x0 + 1]))
            shape = (azimuths, 1, height, 1, channels)
            table_d = cla.to_device(self.queue, np.ascontiguousarray(view_slice.reshape(shape), dtype=self.engine.dtype))
        args = (table_d.data, np.int32(shape[3]), np.int32(height), np.int32(shape[1]), np.int32(azimuths),
                np.int32(channels), np.int32(MAPPINGS[t.settings.mapping]), self.engine.real2(t.settings.sun_w_range))
        buffers = [("table", table_d, math.prod(shape))]
        return self._launch("render_table4d", directions, sun_direction, altitude, valid, args, buffers)

    @_cl.serialized
    def render_raymarch(self, directions, sun_direction, altitude=0.0, valid=None, sun_disc=True):
        """HDR radiance (..., 3) by per-pixel ray marching (single scattering along the true ray, higher
        orders from the table's gathered in-scatter, and a reflecting ground lit by the sun at the ground
        point's true sun cosine and by the table's ground_irradiance); ``sun_disc`` False: the sky
        without the sun's disc (the sky-view map's nodes, :meth:`skyview_map`)."""
        return self._raymarch(directions, [sun_direction], altitude, valid, sun_disc)[0]

    @_cl.serialized
    def render_raymarch_suns(self, directions, sun_directions, altitude=0.0, valid=None, sun_disc=True):
        """:meth:`render_raymarch` for each of ``sun_directions`` (a sequence of suns, each 3 values):
        frames (len(sun_directions), ..., 3), each the same as :meth:`render_raymarch` for its sun alone.
        Each pixel's ray is marched once for several suns (:func:`ray_march_suns`, :func:`ray_march_batch`;
        on CPUs: elsewhere one sun a launch by default): its geometry, densities and view transmittance
        computed once for them (docs/speed-log.md)."""
        sun_directions = _sun_list(sun_directions)
        if np.ndim(sun_directions[0]) == 0:
            raise ValueError(f"sun_directions must be a sequence of sun directions of 3 values each, got "
                             f"{short(sun_directions)} (for one sun: render_raymarch)")
        check_directions(np.zeros((0, 3)), (0.0, 0.0, 1.0), altitude)         # the altitude, named as such
        for index, sun_direction in enumerate(sun_directions):
            try:
                check_directions(np.zeros((0, 3)), sun_direction, altitude)
            except ValueError as error:
                raise ValueError(f"sun_directions[{index}]: {error}") from None
        return self._raymarch(directions, sun_directions, altitude, valid, sun_disc)

    def _raymarch(self, directions, sun_directions, altitude, valid, sun_disc):
        t = self._check_table_unchanged()
        depth, height, width = self._gathered_shape[-4:-1] if self._has_gathered else NO_GATHERED_GRID
        tw, th = self._sun_table_size
        args = (self._gathered_d.data, np.int32(width), np.int32(height), np.int32(depth),
                np.int32(MAPPINGS[t.settings.mapping]), self.engine.real2(t.settings.sun_w_range),
                np.int32(self._has_gathered),
                np.int32(t.settings.mode == "physical"), self._sun_table_d.data, np.int32(tw), np.int32(th),
                self._ground_d.data, np.int32(self._ground_depth))
        harmonics = t.settings.azimuth_harmonics if self._has_gathered else 0
        buffers = [("gathered", self._gathered_d, gathered_source_reals((depth, height, width), harmonics)),
                   ("sun_table", self._sun_table_d, th * tw * column_channels(t.atmosphere)),
                   ("ground_irradiance", self._ground_d, 4 * self._ground_depth)]
        return self._launch_suns("render_raymarch", directions, sun_directions, altitude, valid, args, buffers,
                                 sun_disc)

    @_cl.serialized
    def skyview_map(self, sun_direction, altitude=0.0, settings=None):
        """The per-frame sky-view map (H, W, 3) of :mod:`clsky.skyview` (``settings``: a
        :class:`~clsky.skyview.SkyViewSettings`, default its defaults): :meth:`render_raymarch` without
        the sun's disc at the map's node directions, in the frame turned about the zenith that puts the
        sun's azimuth along +x. The nodes of the last (settings, altitude) stay uploaded."""
        return self.skyview_maps([sun_direction], altitude, settings)[0]

    @_cl.serialized
    def skyview_maps(self, sun_directions, altitude=0.0, settings=None):
        """:meth:`skyview_map` of each of ``sun_directions`` (k, H, W, 3), the nodes marched once for
        several suns (:meth:`render_raymarch_suns`: each map the same bits as its own; on the 2-core
        machine 8-10 against 13-16 CPU-ms a default map, four suns a launch)."""
        from . import skyview

        settings = skyview_settings(settings)
        sun_directions = _sun_list(sun_directions)
        checked = [check_directions(np.zeros((0, 3)), sun, altitude) for sun in sun_directions]
        altitude = checked[0][2]
        key = (settings, altitude)
        if key not in self._skyview_nodes:
            nodes = skyview.node_directions(settings, altitude, self.table.atmosphere.planet_radius)
            self._skyview_nodes = {key: self.prepare(nodes)}
        canonical = [skyview.canonical_sun(sun) for _, sun, _ in checked]
        return self.render_raymarch_suns(self._skyview_nodes[key], canonical, altitude, sun_disc=False)

    @_cl.serialized
    def render_skyview(self, directions, sun_direction, altitude=0.0, valid=None, settings=None, sky_map=None):
        """HDR radiance (..., 3) from a per-frame sky-view map (Hillaire 2020; :mod:`clsky.skyview`):
        :meth:`skyview_map` for this sun and altitude (or ``sky_map``, that map computed already, e.g. by
        :meth:`skyview_maps` with other suns'), read bilinearly per pixel (never across the horizon), plus
        the sun's disc. Arguments as :meth:`render_raymarch`; ``settings`` a
        :class:`~clsky.skyview.SkyViewSettings` (map size, azimuth mapping)."""
        from . import skyview

        settings = skyview_settings(settings)
        _, sun, altitude = check_directions(np.zeros((0, 3)), sun_direction, altitude)
        if sky_map is not None:
            expected = (settings.size[1], settings.size[0], 3)
            try:
                sky_map = np.asarray(sky_map, dtype=np.float64)
            except (TypeError, ValueError):
                raise ValueError(f"sky_map must be a sky-view map of shape {expected} (skyview_maps), got "
                                 f"{type(sky_map).__name__} {short(sky_map)}") from None
            # within the renderer's real type (a 16th of its largest: the bilinear read and the sun's disc
            # stay finite): 1e39 was finite in float64 and infinite in a float32 renderer's map, and every pixel
            # NaN. (A map is radiance with the incident light, up to 1e12, applied: no table's bound.)
            largest = float(np.finfo(self.engine.dtype).max) / 16
            if (sky_map.shape != expected or not np.isfinite(sky_map).all() or (sky_map < 0).any()
                    or (sky_map > largest).any()):
                raise ValueError(f"sky_map must be a sky-view map of shape {expected} (skyview_maps) with finite "
                                 f"values in [0, {largest:.3g}], got shape {sky_map.shape}"
                                 + (f", values in [{sky_map.min():.6g}, {sky_map.max():.6g}]"
                                    if sky_map.shape == expected else ""))
        directions = self._prepared(directions, valid)      # the angles are kept with prepared directions
        if sky_map is None:
            sky_map = self.skyview_map(sun, altitude, settings)
        map_d = cla.to_device(self.queue, np.ascontiguousarray(sky_map, dtype=self.engine.dtype))
        mu_h, angle = skyview.horizon(altitude, self.table.atmosphere.planet_radius)
        width, height = settings.size
        view_zenith_d = self.view_zenith_angles(directions)
        args = (map_d.data, np.int32(width), np.int32(settings.sky_rows), np.int32(settings.ground_rows),
                np.int32(skyview.AZIMUTH_MAPPINGS[settings.azimuth_mapping]), self.engine.real(mu_h),
                self.engine.real(angle), view_zenith_d.data)
        return self._launch("render_skyview", directions, sun, altitude, None, args,
                            [("sky_map", map_d, 3 * width * height),
                             ("view_zenith", view_zenith_d, directions.array.shape[0])])

    @_cl.serialized
    def view_zenith_angles(self, directions: PreparedDirections) -> cla.Array:
        """The view zenith angle atan2(|V_xy|, V_z) [rad] of each of ``directions`` (a :meth:`prepare`
        result), a device array (pixels,) computed on its first call (kernels/skyview.cl: view_zenith_angles)
        and kept with the directions: the sky-view lookup reads them every frame instead of taking a scalar
        atan2 per pixel (about three quarters of its time on PoCL, docs/speed-log.md)."""
        check_instance("directions", directions, PreparedDirections, "directions prepared by prepare()")
        angles = directions.derived.get("view_zenith")
        if angles is None:
            n = directions.array.shape[0]
            angles = cla.empty(self.queue, max(n, 1), self.engine.dtype)   # no empty buffers: nothing reads it then
            if n:
                check_kernel_buffer("view_zenith_angles", "directions", directions.array, 3 * n, self.engine.dtype)
                # from the program the sky-view lookup launches (the atmosphere's features: the same code
                # for this kernel, which reads none of them), not a plain program built for it alone
                kernel = self.engine.kernels_with(self._defines)["view_zenith_angles"]
                kernel(self.queue, *self._work_size(kernel, n), np.int32(n), directions.array.data, angles.data)
            angles = directions.derived.setdefault("view_zenith", angles)
        return angles

    def close(self):
        """Release the renderer's programs and device buffers (the table's copies, the sun table, the sky-view
        map's nodes; a with block's end calls it); its methods then raise ValueError. Closing twice is
        harmless. Directions it prepared keep their own buffers."""
        with self.engine.lock:
            self.engine.close()
            self._atmosphere_d = self._table_d = self._gathered_d = self._ground_d = self._sun_table_d = None
            self._skyview_nodes = {}

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
