"""Radiance from the 4D scattering table on OpenCL (``kernels/lookup4d.cl``; clsky/table4d.py).

NumPy twin: :func:`clsky.reference.lookup4d`.
"""

from __future__ import annotations

import numpy as np

from . import _cl
from .atmosphere import AtmosphereParameters
from .lookup import TableLookupEngine, check_lookup
from .mapping import FULL_SUN_RANGE

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


class TableLookup4DEngine(TableLookupEngine):
    """Quadrilinear lookups in a 4D scattering table, phase functions at the true scattering angle."""

    sources = ("geometry.cl", "mapping.cl", "mapping4d.cl", "phase.cl", "lookup.cl", "lookup4d.cl")

    @_cl.serialized
    def radiance(self, atmosphere: AtmosphereParameters, data, altitude, cos_view, cos_sun, cos_scatter,
                 mapping="nonlinear", sun_cos_range=FULL_SUN_RANGE, *, table_checked=False):
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
        table_checked : bool
            ``data`` is a validated table's: its values are not scanned again (:func:`clsky.lookup.check_lookup`).

        Returns
        -------
        numpy.ndarray, broadcast shape + (3,)
            Radiance r, g, b (HDR).
        """
        data, queries, sun_cos_range = check_lookup(data, (altitude, cos_view, cos_sun, cos_scatter), sun_cos_range,
                                                    check_table4d_data, table_checked)
        azimuths, depth, height, width, channels = data.shape
        return self._lookup("lookup4d", atmosphere, data, (width, height, depth, azimuths, channels), queries,
                            mapping, sun_cos_range)
