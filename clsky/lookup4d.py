"""Radiance from the 4D scattering table on OpenCL (``kernels/lookup4d.cl``; clsky/table4d.py).

NumPy twin: :func:`clsky.reference.lookup4d`.
"""

from __future__ import annotations

import numpy as np
import pyopencl.array as cla

from . import _atmosphere_cl, _cl
from .atmosphere import AtmosphereParameters
from .errors import check_choice
from .lookup import check_kernel_buffer, check_queries
from .mapping import FULL_SUN_RANGE, sun_w_range
from .settings import MAPPINGS

__all__ = ["TableLookup4DEngine", "check_table4d_data"]


def check_table4d_data(data):
    """The (A, D, H, W, C) array of a 4D table: C 6 or 9, A, D, W >= 2 (1 for a renderer's slice),
    H even >= 4, real numbers, fewer than 2**31 values; ValueError otherwise."""
    data = np.asarray(data)
    if (data.ndim != 5 or data.shape[4] not in (6, 9) or min(data.shape[:4]) < 1 or data.shape[2] % 2
            or data.shape[2] < 4):
        raise ValueError(f"4D table data must have shape (A, D, H, W, C) with C in (6, 9), H even >= 4, "
                         f"got {data.shape}")
    if data.dtype.kind not in "fiu":
        raise ValueError(f"table data must hold real numbers, got dtype {data.dtype}")
    if data.size > 2**31 - 1:
        raise ValueError(f"table data must have at most {2**31 - 1} values, got {data.size}")
    return data


class TableLookup4DEngine(_cl.Engine):
    """Quadrilinear lookups in a 4D scattering table, phase functions at the true scattering angle."""

    sources = ("geometry.cl", "mapping.cl", "mapping4d.cl", "phase.cl", "lookup.cl", "lookup4d.cl")

    def program_sources(self):
        return ("real.cl", _atmosphere_cl.declaration(self.ctx.devices[0], self.dtype)) + self.sources

    def radiance(self, atmosphere: AtmosphereParameters, data, altitude, cos_view, cos_sun, cos_scatter,
                 mapping="nonlinear", sun_cos_range=FULL_SUN_RANGE):
        """Radiance I = I_I (F_R Ibar_R + F_M Ibar_M + Lbar) for each query.

        Parameters
        ----------
        atmosphere : AtmosphereParameters
            The table's atmosphere (phase functions, I_I, radii).
        data : numpy.ndarray, shape (A, D, H, W, C)
            The 4D table (:mod:`clsky.table4d`), C = 9 (or 6: single scattering only).
        altitude : array_like
            Observer altitude [m], >= 0 (above the atmosphere: seen from space).
        cos_view, cos_sun, cos_scatter : array_like
            Cosines of the view zenith, the sun zenith and the scattering angle dot(Sun, V).
        mapping : {'nonlinear', 'linear'}
            The table's altitude and sun mapping.
        sun_cos_range : (low, high)
            The sun cosines the table's sun axis covers.

        Returns
        -------
        numpy.ndarray, broadcast shape + (3,)
            Radiance r, g, b (HDR).
        """
        data = check_table4d_data(data)
        check_choice("mapping", mapping, MAPPINGS)
        queries = check_queries(altitude, cos_view, cos_sun, cos_scatter)
        shape, n = queries[0].shape, queries[0].size
        azimuths, depth, height, width, channels = data.shape
        table_d = cla.to_device(self.queue, np.ascontiguousarray(data, dtype=self.dtype))
        queries_d = [cla.to_device(self.queue, np.ascontiguousarray(q.ravel(), dtype=self.dtype)) for q in queries]
        radiance_d = cla.empty(self.queue, (max(n, 1), 3), self.dtype)
        atmosphere_d = _atmosphere_cl.to_device(self.queue, atmosphere, self.dtype)
        check_kernel_buffer("lookup4d", "table", table_d, data.size, self.dtype)
        for name, query_d in zip(("altitude", "cos_view", "cos_sun", "cos_scatter"), queries_d):
            check_kernel_buffer("lookup4d", name, query_d, n, self.dtype)
        check_kernel_buffer("lookup4d", "radiance", radiance_d, 3 * max(n, 1), self.dtype)
        if n:
            event = self.kernels["lookup4d"](
                self.queue, (n,), None, atmosphere_d, table_d.data, np.int32(width), np.int32(height),
                np.int32(depth), np.int32(azimuths), np.int32(channels), np.int32(MAPPINGS[mapping]),
                self.real2(sun_w_range(mapping, sun_cos_range)), np.int32(n),
                *(q.data for q in queries_d), radiance_d.data)
            self._record("lookup4d", event)
        return radiance_d.get()[:n].reshape(shape + (3,)).astype(np.float64)
