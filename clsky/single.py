"""The single-scattering 3D table on OpenCL (``kernels/single.cl``).

NumPy twin: :func:`clsky.reference.single_scattering`.
"""

from __future__ import annotations

import numpy as np
import pyopencl.array as cla

from . import _atmosphere_cl, _cl
from .atmosphere import AtmosphereParameters
from .settings import MAPPINGS, TableSettings
from .transmittance import COMMON_SOURCES, quadrature_defines, TransmittanceEngine

__all__ = ["SingleScatteringEngine"]

#: Sun nodes per work-item (-DSINGLE_SUN_NODES, kernels/single.cl): a view ray's nodes, altitudes, densities
#: and view columns do not depend on the sun, so one work-item marches a ray once for this many sun nodes,
#: the same table bit for bit (tests/test_single_twin.py). 8: about a quarter less CPU than one for the
#: default animation's table (its three azimuth nodes; docs/speed-log.md); 4 and 16 were no better.
SINGLE_SUN_NODES = 8
#: Sun-zenith layers per kernel launch (progress is reported between launches): a multiple of
#: SINGLE_SUN_NODES, so that no work-item computes sun nodes past its launch's slab.
SLAB_LAYERS = 2 * SINGLE_SUN_NODES
#: Work-group of the kernel (altitude blocks, view rows, sun blocks), explicit as the scatter's
#: (clsky.multiple.SCATTER_WORK_GROUP), whose private sums overflowed a PoCL worker's stack in the
#: work-group PoCL chose itself; here every work-item holds SINGLE_SUN_NODES x 12 realv (6 kB). The view
#: axis of the launch is padded to a multiple of its rows; the kernel skips the padding.
SINGLE_WORK_GROUP = (1, 8, 1)


class SingleScatteringEngine(_cl.Engine):
    """Builds single-scattering tables for the loop counts and sampling of ``settings``.

    One engine serves any atmosphere, table size and mapping: those are per-call values; the loop
    counts, sampling and sun-transmittance method are compiled in. The precision is ``settings.dtype``.

    Parameters
    ----------
    settings : TableSettings
    ctx, profile, fast_math
        See :class:`clsky._cl.Engine`.
    """

    def __init__(self, settings: TableSettings = TableSettings(), ctx=None, profile=False, fast_math=False):
        self.settings = settings
        self.sun_nodes = SINGLE_SUN_NODES                  # compiled in: its launches keep it
        super().__init__(ctx, np.dtype(settings.dtype), profile, fast_math)
        self._transmittance = None
        if settings.sun_transmittance == "table":
            self._transmittance = TransmittanceEngine(self.ctx, self.dtype, profile, fast_math,
                                                      steps=settings.sun_steps, sampling=settings.sampling)

    def program_sources(self):
        declaration = _atmosphere_cl.declaration(self.ctx.devices[0], self.dtype)
        return ("real.cl", declaration) + COMMON_SOURCES[1:] + ("mapping.cl", "view_ray.cl", "single.cl")

    def build_options(self):
        return (super().build_options() + quadrature_defines(self.settings, self.vector_width)
                + [f"-DSINGLE_SUN_NODES={self.sun_nodes}"])

    def compute(self, atmosphere: AtmosphereParameters, size=None, mapping=None, progress=None, cos_azimuth=1.0,
                out=None):
        """The single-scattering table.

        Parameters
        ----------
        atmosphere : AtmosphereParameters
        size : (W, H, D), optional
            Defaults to ``settings.size``.
        mapping : {'nonlinear', 'linear'}, optional
            Defaults to ``settings.mapping``.
        progress : callable, optional
            Called as ``progress(done, total)`` after each slab of sun-zenith layers.
        cos_azimuth : float
            Cosine of the view-sun azimuth of every cell: 1 (default) is the canonical frame of the 3D
            table; other values are the azimuth nodes of :mod:`clsky.azimuth`.
        out : numpy.ndarray, shape (D, H, W, 6), float64, optional
            Where to write the table (C-contiguous), instead of a new array: the azimuth nodes of a
            table go into one array without a stacked copy.

        Returns
        -------
        numpy.ndarray, shape (D, H, W, 6), float64
            Ibar^(1) [1/sr] per cell: Rayleigh r, g, b, Mie r, g, b (flat index x + y W + z W H).
        """
        settings = self.settings.replace(size=size or self.settings.size, mapping=mapping or self.settings.mapping)
        width, height, depth = settings.size
        atmosphere_d = _atmosphere_cl.to_device(self.queue, atmosphere, self.dtype)
        if self._transmittance is not None:
            tw, th = settings.transmittance_size
            sun_table_d = self._transmittance.column_density_table(atmosphere, (tw, th), queue_only=True)
            self._transmittance.queue.finish()    # built on the other engine's queue: wait for it
        else:
            tw = th = 2
            sun_table_d = cla.zeros(self.queue, 8, self.dtype)
        table_d = cla.empty(self.queue, (depth, height, width, 6), self.dtype)
        kernel = self.kernels_with(_atmosphere_cl.feature_defines(atmosphere))["single_scattering"]
        slabs = range(0, depth, SLAB_LAYERS)
        for done, z_offset in enumerate(slabs, start=1):
            slab = min(SLAB_LAYERS, depth - z_offset)
            items = (-(-width // self.vector_width), height, -(-slab // self.sun_nodes))
            event = kernel(self.queue, *_cl.launch_size(kernel, self.device, items, SINGLE_WORK_GROUP), atmosphere_d,
                           np.int32(width), np.int32(height), np.int32(depth), np.int32(z_offset),
                           np.int32(z_offset + slab), np.int32(MAPPINGS[settings.mapping]),
                           self.real2(settings.sun_w_range),
                           sun_table_d.data, np.int32(tw),
                           np.int32(th), self.real(cos_azimuth), table_d.data)
            self._record("single_scattering", event)
            if progress is not None:
                event.wait()
                progress(done, len(slabs))
        if out is None:
            return table_d.get().astype(np.float64, copy=False)   # no second copy of a float64 table
        if self.dtype == np.float64:
            return table_d.get(ary=out)
        out[...] = table_d.get()
        return out
