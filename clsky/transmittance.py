"""Optical depth and transmittance along segments, and the 2D column-density table (OpenCL).

Kernels: ``kernels/transmittance.cl``. NumPy twins: :func:`clsky.reference.optical_depth` and
:func:`clsky.reference.transmittance_table`.
"""

from __future__ import annotations

import numpy as np
import pyopencl.array as cla

from . import _atmosphere_cl, _cl
from .atmosphere import AtmosphereParameters
from .errors import ParameterError, as_real_array, check_choice, check_integer
from .settings import SAMPLINGS

__all__ = ["TransmittanceEngine", "azimuth_defines", "check_segments", "column_channels", "upload_gathered_source",
           "gathered_source_reals", "NO_GATHERED_GRID"]

COMMON_SOURCES = ("real.cl", "geometry.cl", "column.cl", "transmittance_table.cl")


def sampling_defines(sampling):
    """The -D options of a node placement (settings.SAMPLINGS): 'keller_bohn' and 'ground_end' both
    place sun-ray nodes at (j/n)^2 (column.cl); 'ground_end' clusters the view nodes of ground-hitting
    rays at the ground (view_ray.cl)."""
    return {"uniform": [], "keller_bohn": ["-DKELLER_BOHN_SAMPLING=1"],
            "ground_end": ["-DKELLER_BOHN_SAMPLING=1", "-DGROUND_END_SAMPLING=1"]}[sampling]


def quadrature_defines(settings, vector_width):
    """The -D options of a program integrating along rays with ``settings``' quadrature (view and sun
    steps, node placement, sun transmittance method, the gathered source's stride) in ``vector_width``
    lanes."""
    options = [f"-DN_VIEW={settings.view_steps}", f"-DN_SUN={settings.sun_steps}", f"-DVECTOR_WIDTH={vector_width}"]
    options += sampling_defines(settings.sampling)
    if settings.sun_transmittance == "table":
        options.append("-DSUN_TRANSMITTANCE_TABLE=1")
    if settings.source_stride != 1:
        options.append(f"-DSOURCE_STRIDE={settings.source_stride}")
    return options


def azimuth_defines(settings, interleaved=False):
    """``-DAZIMUTH_HARMONICS=M`` for a table whose higher orders carry M > 0 azimuthal harmonics
    (``settings.azimuth_harmonics``; kernels/view_ray.cl: add_lookups), else none; with ``interleaved``,
    also ``-DGATHERED_INTERLEAVED``: the program reads the harmonics interleaved cell by cell, as
    :func:`upload_gathered_source` uploads them (a renderer's, the 4D table's), not as the orders' stack
    of one table a harmonic."""
    if not settings.azimuth_harmonics:
        return []
    return [f"-DAZIMUTH_HARMONICS={settings.azimuth_harmonics}"] + (["-DGATHERED_INTERLEAVED"] if interleaved else [])


#: The grid (D, H, W) of the zero table that stands in for the gathered source of a table without higher
#: orders (:func:`upload_gathered_source` of None): a valid buffer that the kernels do not read.
NO_GATHERED_GRID = (2, 2, 2)

#: Work-group of ``transmittance_table`` (columns, rows): PoCL's own choice for the default 64 x 256 table,
#: fixed so that any table size compiles one kernel object (:data:`clsky._cl.LINEAR_WORK_GROUP`).
TABLE_WORK_GROUP = (64, 64)


def upload_gathered_source(queue, gathered, dtype):
    """A table's gathered source (``ScatteringTable.gathered``: (D, H, W, 6), or with M azimuth harmonics
    (M + 1, D, H, W, 6)) on the device as the per-pixel and per-cell ray integrals read it with
    ``azimuth_defines(settings, interleaved=True)`` (kernels/view_ray.cl, GATHERED_INTERLEAVED): padded to
    (D, H, W, 8), the harmonics interleaved into (D, H, W, M + 1, 8) (:func:`clsky._cl.upload_padded`), so
    that a lookup's corner reads its M + 1 rows of 8 reals side by side, where the orders' stack (M + 1
    tables (D, H, W, 8)) puts them in M + 1 tables of their own: the default animation's ray march (M = 2)
    takes 3-8 % less CPU time for the same frames, 10-20 % less at dusk (docs/speed-log.md). None (no higher
    orders): zeros on :data:`NO_GATHERED_GRID`. Its size in reals: :func:`gathered_source_reals`. On a CPU its
    rows split between two queues (:func:`clsky._cl.upload_share_queues`): the default animation's 163 MB took
    123 ms on one PoCL thread, 61 on two."""
    if gathered is None:
        return cla.zeros(queue, NO_GATHERED_GRID + (8,), dtype)
    gathered = np.asarray(gathered)
    return _cl.upload_padded(queue, gathered, dtype, interleaved=gathered.ndim == 5,
                             queues=_cl.upload_share_queues(queue))


def gathered_source_reals(grid, harmonics=0) -> int:
    """Reals of :func:`upload_gathered_source`'s array on the grid (D, H, W) with M = ``harmonics``:
    8 (M + 1) D H W (a kernel's buffer check, from the grid and harmonics it is given)."""
    return 8 * (harmonics + 1) * int(np.prod(grid))


def column_channels(atmosphere) -> int:
    """Columns per node of the 2D table (``COLUMN_CHANNELS`` of kernels/column.cl): C_R, C_M, and C_O
    with ozone."""
    return 3 if atmosphere.has_ozone else 2


def check_segments(atmosphere, altitude, cos_zenith, length):
    """Broadcast and check segment arrays; ValueError names the bad parameter and its range."""
    altitude, cos_zenith, length = np.broadcast_arrays(*(as_real_array(name, a) for name, a in (
        ("altitude", altitude), ("cos_zenith", cos_zenith), ("length", length))))
    checks = (("altitude", altitude, 0.0, atmosphere.atmosphere_height, "m"),
              ("cos_zenith", cos_zenith, -1.0, 1.0, ""),
              ("length", length, 0.0, 2 * atmosphere.top_radius, "m"))
    for name, values, low, high, unit in checks:
        inside = np.isfinite(values) & (values >= low) & (values <= high)
        if not np.all(inside):             # the first value outside, as lookup.check_queries names it
            raise ParameterError(name, f"finite and in [{low:g}, {high:g}] {unit}".rstrip(), values[~inside].flat[0])
    return altitude, cos_zenith, length


class TransmittanceEngine(_cl.Engine):
    """Optical depth along segments by the trapezoidal rule, and the 2D column-density table.

    Parameters
    ----------
    steps : int
        Trapezoid steps per segment (default 30, as Bruneton & Neyret), in [1, 4096].
    sampling : {'uniform', 'keller_bohn', 'ground_end'}
        Uniform nodes, or Keller & Bohn's nodes t_j = d (j/n)^2 (which 'ground_end' keeps on sun rays).
    ctx, dtype, profile, fast_math
        See :class:`clsky._cl.Engine`.
    """

    def __init__(self, ctx=None, dtype=np.float64, profile=False, fast_math=False, *, steps=30,
                 sampling="uniform"):
        self.steps = check_integer("steps", steps, 1, 4096)
        self.sampling = check_choice("sampling", sampling, SAMPLINGS)
        super().__init__(ctx, dtype, profile, fast_math)

    def program_sources(self):
        declaration = _atmosphere_cl.declaration(self.ctx.devices[0], self.dtype)
        return ("real.cl", declaration) + COMMON_SOURCES[1:] + ("transmittance.cl",)

    def build_options(self):
        # Sun-ray nodes only: this program integrates no view ray, so 'ground_end' builds it as 'keller_bohn'.
        sampling = "keller_bohn" if self.sampling == "ground_end" else self.sampling
        return super().build_options() + [f"-DN_SUN={self.steps}"] + sampling_defines(sampling)

    def optical_depth(self, atmosphere: AtmosphereParameters, altitude, cos_zenith, length):
        """Optical depth of segments, per wavelength.

        Parameters
        ----------
        atmosphere : AtmosphereParameters
        altitude : array_like
            Altitude of the segment's start [m], in [0, Ha].
        cos_zenith : array_like
            Cosine of the segment direction's zenith angle at its start, in [-1, 1].
        length : array_like
            Segment length [m], in [0, 2 Ra]. The caller keeps the segment above the ground.

        Returns
        -------
        numpy.ndarray, shape broadcast + (3,)
            tau for r, g, b (dimensionless).
        """
        altitude, cos_zenith, length = check_segments(atmosphere, altitude, cos_zenith, length)
        shape = altitude.shape
        n = altitude.size
        inputs = [cla.to_device(self.queue, np.ascontiguousarray(a.ravel(), dtype=self.dtype))
                  for a in (altitude, cos_zenith, length)]
        tau_d = cla.empty(self.queue, (max(n, 1), 3), self.dtype)
        atmosphere_d = _atmosphere_cl.to_device(self.queue, atmosphere, self.dtype)
        if n:
            kernel = self.kernels_with(_atmosphere_cl.feature_defines(atmosphere))["optical_depth"]
            event = kernel(self.queue, *self._linear_size(kernel, n), atmosphere_d, np.int32(n),
                           *(a.data for a in inputs), tau_d.data)
            self._record("optical_depth", event)
        return tau_d.get()[:n].reshape(shape + (3,)).astype(np.float64)

    def transmittance(self, atmosphere, altitude, cos_zenith, length):
        """exp(-optical_depth) per wavelength; same parameters as :meth:`optical_depth`."""
        return np.exp(-self.optical_depth(atmosphere, altitude, cos_zenith, length))

    def column_density_table(self, atmosphere: AtmosphereParameters, size=(64, 256), queue_only=False):
        """The 2D table of column densities (C_R, C_M[, C_O]) [m] from each node to the top of the atmosphere.

        Axes in ``kernels/transmittance_table.cl``. Returns an array of shape (TH, TW, C) with C = 2, or
        3 with ozone (C_O: column of the ozone tent, :mod:`clsky.ozone`) (or, with ``queue_only``, the
        device array, for use by other kernels of the same context).
        """
        tw, th = (check_integer(f"size[{i}]", v, 2, 4096) for i, v in enumerate(size))
        table_d = cla.empty(self.queue, (th, tw, column_channels(atmosphere)), self.dtype)
        atmosphere_d = _atmosphere_cl.to_device(self.queue, atmosphere, self.dtype)
        kernel = self.kernels_with(_atmosphere_cl.feature_defines(atmosphere))["transmittance_table"]
        event = kernel(self.queue, *_cl.launch_size(kernel, self.device, (tw, th), TABLE_WORK_GROUP), atmosphere_d,
                       np.int32(tw), np.int32(th), table_d.data)
        self._record("transmittance_table", event)
        return table_d if queue_only else table_d.get()
