"""Radiance from a scattering table on OpenCL (``kernels/lookup.cl``).

NumPy twin: :func:`clsky.reference.lookup`.
"""

from __future__ import annotations

import numpy as np
import pyopencl.array as cla

from . import _atmosphere_cl, _cl
from .atmosphere import ATMOSPHERE_HEIGHT_RANGE, AtmosphereParameters
from .errors import ParameterError, as_real_array, check_choice
from .mapping import FULL_SUN_RANGE, sun_w_range
from .settings import MAPPINGS, check_sun_cos_range

__all__ = ["TableLookupEngine", "check_queries", "check_table_data", "check_kernel_buffer"]


#: Highest observer altitude a lookup takes [m] (as the renderers, clsky/render.py): the highest top of
#: a valid atmosphere (:data:`clsky.atmosphere.ATMOSPHERE_HEIGHT_RANGE`), so that every observer inside
#: one is taken; far beyond it the squared radii of the entry-point geometry overflow (the NumPy twin gave
#: NaN from 1e155 m).
MAX_QUERY_ALTITUDE = ATMOSPHERE_HEIGHT_RANGE[1]


def check_queries(altitude, cos_view, cos_sun, cos_scatter):
    """Broadcast and check lookup queries; ValueError names the bad parameter and its range.

    Raises
    ------
    ValueError
        (:class:`clsky.errors.ParameterError`) for a query that is not numeric, does not broadcast,
        or lies outside its range: altitude in [0, 1e10] m (:data:`MAX_QUERY_ALTITUDE`), cosines in
        [-1, 1].
    """
    names = ("altitude", "cos_view", "cos_sun", "cos_scatter")
    ranges = ((0.0, MAX_QUERY_ALTITUDE), (-1.0, 1.0), (-1.0, 1.0), (-1.0, 1.0))
    arrays = []
    for name, value, (low, high) in zip(names, (altitude, cos_view, cos_sun, cos_scatter), ranges):
        valid = f"finite and in [{low:g}, {high:g}]" + (" m" if name == "altitude" else "")
        array = as_real_array(name, value, f"real numbers {valid}")
        if not np.all(np.isfinite(array) & (array >= low) & (array <= high)):
            bad = array[~(np.isfinite(array) & (array >= low) & (array <= high))].flat[0]
            raise ParameterError(name, valid, bad)
        arrays.append(array)
    try:
        return np.broadcast_arrays(*arrays)
    except ValueError:
        raise ValueError(f"altitude, cos_view, cos_sun and cos_scatter must broadcast together, got shapes "
                         f"{[a.shape for a in arrays]}") from None


#: Channels per cell a table may have: factored (6, or the notes' 4), plus 3 phased higher orders.
TABLE_CHANNELS = (6, 4, 9, 7)


#: Values a kernel may index with its 32-bit int flat indices.
MAX_KERNEL_VALUES = 2**31 - 1


#: The largest value a table's arrays may hold [1/sr, per unit of incident light]: radiances per unit
#: solar irradiance are of order 1 or less in any atmosphere the parameters admit (energy conservation;
#: a build's coarsest quadratures overestimate by tens), so a larger one can only come from a damaged or
#: forged file, where a finite 1e39 became infinite in a float32 kernel and 1e307 in a float64 render.
MAX_TABLE_VALUE = 1e12


def check_table_values(name, array, nonnegative=True, error=ValueError):
    """``error`` naming ``name`` unless every value of ``array`` is finite, at most :data:`MAX_TABLE_VALUE` in
    size and, with ``nonnegative``, >= 0: a table's values (:func:`clsky.table.check_finite_nonnegative`,
    the lookup engines' data). By the array's minimum and maximum only (NaN propagates through both), no
    array of their own: ``np.abs`` of the default animation's harmonics, checked as non-negative before,
    took 82 MB of memory, which cost 0.04-0.54 s of one core at the end of the table's build where the
    machine had not handed such memory out lately (docs/speed-log.md), against 0.02 s for the reductions.
    The values are counted only for the error."""
    if array.size == 0:
        return
    low, high = array.min(), array.max()
    if (low >= 0 if nonnegative else low >= -MAX_TABLE_VALUE) and high <= MAX_TABLE_VALUE:
        return
    finite = np.isfinite(array)
    counts = {"NaN values": np.isnan(array).sum(), "infinite values": np.isinf(array).sum(),
              "negative values": (array < 0).sum() if nonnegative else 0,
              f"values beyond {MAX_TABLE_VALUE:g}": (finite & (np.abs(array) > MAX_TABLE_VALUE)).sum()}
    found = " and ".join(f"{int(count)} {kind}" for kind, count in counts.items() if count)
    expected = "finite and >= 0" if nonnegative else "finite"
    raise error(f"{name} holds {found} (a table's values are {expected}, at most {MAX_TABLE_VALUE:g} in size)")


def check_table_data(data):
    """The (D, H, W, C) array of a table, C in :data:`TABLE_CHANNELS`, each axis >= 2, real numbers,
    fewer than 2**31 values (the kernels' int indices); ValueError otherwise."""
    data = np.asarray(data)
    if data.ndim != 4 or data.shape[3] not in TABLE_CHANNELS or min(data.shape[:3]) < 2:
        raise ValueError(f"table data must have shape (D, H, W, C) with C in {TABLE_CHANNELS} and "
                         f"D, H, W >= 2, got {data.shape}")
    if data.dtype.kind not in "fiu":
        raise ValueError(f"table data must hold real numbers, got dtype {data.dtype}")
    if data.size > MAX_KERNEL_VALUES:
        raise ValueError(f"table data must have at most {MAX_KERNEL_VALUES} values, got {data.size}")
    return data


def check_lookup(data, queries, sun_cos_range, check_shape=check_table_data, table_checked=False):
    """(data, queries, sun_cos_range) of a lookup, checked as the engines and their NumPy twins
    (:func:`clsky.reference.lookup`, ``lookup4d``) check them: the table's shape (``check_shape``) and
    values (:func:`check_table_values`: infinite data gave NaN radiance, negated data negative radiance;
    not with ``table_checked``, for a validated table's data, :meth:`clsky.table.ScatteringTable.radiance`:
    a full pass over a 300 MB table took 39 ms of a point query's 41), the queries (:func:`check_queries`)
    and the sun axis' range (:func:`clsky.settings.check_sun_cos_range`)."""
    data = check_shape(data)
    if not table_checked:
        check_table_values("data", data)
    return data, check_queries(*queries), check_sun_cos_range(sun_cos_range)


def check_kernel_buffer(kernel, name, array_d, count, dtype):
    """Check, right before a launch, that a buffer holds exactly what the kernel indexes.

    Parameters
    ----------
    kernel, name : str
        The kernel and its argument, for the message.
    array_d : pyopencl.array.Array
        The buffer passed to the kernel.
    count : int
        Values the kernel indexes, from the sizes passed with the buffer (e.g. D H W C).
    dtype : numpy.dtype
        The values' type in the kernel (``real`` is the engine's dtype).

    Raises
    ------
    ValueError
        The buffer's dtype or number of values differ: the kernel would read past it (or misread it).
    """
    dtype = np.dtype(dtype)
    if array_d.dtype != dtype or array_d.size != count:
        raise ValueError(f"{kernel}: buffer {name} holds {array_d.size} {array_d.dtype} values, the kernel "
                         f"indexes {count} {dtype} values (refused before the launch)")


class TableLookupEngine(_cl.Engine):
    """Trilinear lookups in a scattering table, phase functions at the true scattering angle. Threads may
    share one (its lookups run one at a time, :func:`clsky._cl.serialized`); closed, it refuses them."""

    sources = ("geometry.cl", "mapping.cl", "phase.cl", "lookup.cl")

    def program_sources(self):
        return ("real.cl", _atmosphere_cl.declaration(self.ctx.devices[0], self.dtype)) + self.sources

    @_cl.serialized
    def radiance(self, atmosphere: AtmosphereParameters, data, altitude, cos_view, cos_sun, cos_scatter,
                 mapping="nonlinear", sun_cos_range=FULL_SUN_RANGE, *, table_checked=False):
        """Radiance I = I_I (F_R Ibar_R + F_M Ibar_M) for each query.

        Parameters
        ----------
        atmosphere : AtmosphereParameters
            The table's atmosphere (phase functions, I_I, radii).
        data : numpy.ndarray, shape (D, H, W, C)
            Table values: C = 6 (or the notes' 4) factored channels, plus 3 phased higher orders in
            the physical mode (C = 9 or 7).
        altitude : array_like
            Observer altitude [m], >= 0 (above the atmosphere: seen from space).
        cos_view, cos_sun, cos_scatter : array_like
            Cosines of the view zenith, the sun zenith and the scattering angle dot(Sun, V).
        mapping : {'nonlinear', 'linear'}
            The table's texture mapping.
        sun_cos_range : (low, high)
            The sun cosines the table's sun axis covers (``TableSettings.sun_cos_range``).
        table_checked : bool
            ``data`` is a validated table's (its values checked): not scanned again (:func:`check_lookup`).

        Returns
        -------
        numpy.ndarray, broadcast shape + (3,)
            Radiance r, g, b (HDR, before exposure tone mapping).
        """
        data, queries, sun_cos_range = check_lookup(data, (altitude, cos_view, cos_sun, cos_scatter), sun_cos_range,
                                                    table_checked=table_checked)
        depth, height, width, channels = data.shape
        return self._lookup("lookup", atmosphere, data, (width, height, depth, channels), queries, mapping,
                            sun_cos_range)

    def _lookup(self, kernel, atmosphere, data, sizes, queries, mapping, sun_cos_range):
        """Launch ``kernel`` (``lookup`` or ``lookup4d``) on checked ``data`` whose node counts ``sizes``
        come first in the kernel's arguments, for the queries (altitude, cos_view, cos_sun, cos_scatter)."""
        check_choice("mapping", mapping, MAPPINGS)
        shape, n = queries[0].shape, queries[0].size
        table_d = cla.to_device(self.queue, np.ascontiguousarray(data, dtype=self.dtype))
        queries_d = [cla.to_device(self.queue, np.ascontiguousarray(q.ravel(), dtype=self.dtype)) for q in queries]
        radiance_d = cla.empty(self.queue, (max(n, 1), 3), self.dtype)
        atmosphere_d = _atmosphere_cl.to_device(self.queue, atmosphere, self.dtype)
        check_kernel_buffer(kernel, "table", table_d, int(np.prod(sizes)), self.dtype)
        for name, query_d in zip(("altitude", "cos_view", "cos_sun", "cos_scatter"), queries_d):
            check_kernel_buffer(kernel, name, query_d, n, self.dtype)
        check_kernel_buffer(kernel, "radiance", radiance_d, 3 * max(n, 1), self.dtype)
        if n:
            launch = self.kernels[kernel]
            event = launch(
                self.queue, *self._linear_size(launch, n), atmosphere_d, table_d.data,
                *(np.int32(size) for size in sizes), np.int32(MAPPINGS[mapping]),
                self.real2(sun_w_range(mapping, sun_cos_range)), np.int32(n), *(q.data for q in queries_d),
                radiance_d.data)
            self._record(kernel, event)
        return radiance_d.get()[:n].reshape(shape + (3,)).astype(np.float64)
