"""The 4D scattering table: altitude x view zenith x sun zenith x view-sun azimuth (issue 11, item 3).

``TableSettings(parameterization="4d")``. The 3D table (Elek 2009, Atmosphere Plus) drops the view-sun
azimuth: its lookup is 22 to 43 % off at sunset and 860 to 1740 % in civil twilight, whatever the
knob (README, "Speed versus accuracy"). This table keeps it, as Bruneton (2017) does with (r, mu,
mu_s, nu), and stores, at every node (h, mu, mu_s, phi) along the true ray of that geometry
(nu = mu mu_s + sqrt(1 - mu^2) sqrt(1 - mu_s^2) cos phi):

* channels 0-5: single scattering's Ibar_R, Ibar_M (r, g, b each), without phase: the lookup applies
  F_R(nu), F_M(nu) with the exact nu (kernels/lookup4d.cl), so the sharp Mie peak toward the sun never
  passes through the interpolation, as in the 3D physical mode and in Bruneton's tables;
* channels 6-8: the higher orders, phase inside: the integral along the ray of the gathered source of
  the orders 2..K (:mod:`clsky.azimuth`: a cosine series of ``azimuth_harmonics`` harmonics, or the
  azimuth average for 0), what the per-pixel ray march adds (kernels/render.cl).

Both come from the view-ray integrals the ray march uses (kernels/view_ray.cl), with the table's
quadrature (``view_steps``, ``sun_steps``, ``sampling``, ``sun_transmittance``): the 4D lookup differs
from a ray march of the same quadrature only by its interpolation. The orders themselves are computed
once, by the orders loop of the 3D physical table (:func:`clsky.orders.compute_orders`, on the 3D grid
of ``size`` and ``mapping``), whose ``orders``, ``gathered`` and ``ground_irradiance`` the table keeps:
no second orders loop.

Mappings (clsky/mapping.py, kernels/mapping4d.cl): altitude and sun zenith as the 3D table
(``mapping``, ``sun_cos_range``: the whole axis by default, sun elevations -90 to 90 deg, its nodes
clustered at the horizon by the cube-root mapping); view zenith split at the horizon into H / 2 nodes
for rays that hit the ground and H / 2 for rays that reach space, linear in the ray's length (after
Bruneton 2017); azimuth phi uniform in [0, pi] (``azimuth_size`` nodes).

Layout: ``data`` (A, D, H, W, C), C = 9 (6 with single scattering only).

A reflecting ground (``ground_albedo`` > 0): channels 6-8 also hold what the ray sees of the ground,
T a / pi (mu_sun T_sun + E_sky(mu_sun)), as the ray march adds it (the orders' ``ground_irradiance``
E_sky); such a table needs the higher orders (``orders`` != 1).
"""

from __future__ import annotations

import numpy as np

from . import _atmosphere_cl, _cl
from .atmosphere import AtmosphereParameters
from .errors import ParameterError
from .mapping import grid4d_coordinates, scatter_cos
from .settings import MAPPINGS, TableSettings
from .transmittance import COMMON_SOURCES, NO_GATHERED_GRID, azimuth_defines, column_channels, gathered_source_reals, \
    quadrature_defines, upload_gathered_source

__all__ = ["Table4DEngine", "compute_data", "check_atmosphere", "node_rays", "data_shape"]

#: Work-items per work-group of ``table4d_cells`` (as the render kernels: private arrays per lane).
WORK_GROUP = 64


def check_atmosphere(atmosphere: AtmosphereParameters, settings: TableSettings):
    """ParameterError naming ``orders`` for a reflecting ground with single scattering only (the
    ground's light goes in the higher orders' channels, which such a table lacks)."""
    if atmosphere.has_ground and not settings.has_multiple_block:
        raise ParameterError("orders", "more than 1 for a reflecting ground (ground_albedo > 0) with the '4d' "
                             "parameterization", settings.orders)


def data_shape(settings: TableSettings) -> tuple:
    """(A, D, H, W, C) of a 4D table's ``data``."""
    width, height, depth = settings.size
    return (settings.azimuth_size, depth, height, width, settings.channels)


def node_rays(atmosphere: AtmosphereParameters, settings: TableSettings, azimuth_index: int):
    """The rays (h0, mu_v, mu_s, nu), each (D, H, W) flattened, of the nodes of one azimuth."""
    altitudes, cos_view, cos_sun, azimuths = grid4d_coordinates(settings, atmosphere.planet_radius,
                                                                atmosphere.top_radius)
    depth, height, width = settings.size[2], settings.size[1], settings.size[0]
    h0 = np.broadcast_to(altitudes[None, None, :], (depth, height, width))
    mu_v = np.broadcast_to(cos_view.T[None, :, :], (depth, height, width))
    mu_s = np.broadcast_to(cos_sun[:, None, None], (depth, height, width))
    nu = scatter_cos(mu_v, mu_s, azimuths[azimuth_index])
    return tuple(np.ascontiguousarray(a).ravel() for a in (h0, mu_v, mu_s, nu))


class Table4DEngine(_cl.Engine):
    """The ``table4d_cells`` program (kernels/table4d.cl), built for the quadrature of ``settings``."""

    def __init__(self, settings: TableSettings, ctx=None, profile=False, fast_math=False):
        self.settings = settings
        super().__init__(ctx, np.dtype(settings.dtype), profile, fast_math)

    def program_sources(self):
        declaration = _atmosphere_cl.declaration(self.ctx.devices[0], self.dtype)
        return ("real.cl", declaration) + COMMON_SOURCES[1:] + ("mapping.cl", "view_ray.cl", "table4d.cl")

    def build_options(self):
        return super().build_options() + quadrature_defines(self.settings, self.vector_width)

    def compute(self, atmosphere: AtmosphereParameters, gathered=None, ground_irradiance=None):
        """``data`` (A, D, H, W, C) of the 4D table (float64), ``gathered`` the orders' gathered source
        ((D, H, W, 6), or (M + 1, D, H, W, 6)) on the 3D grid of the settings, None for single scattering;
        ``ground_irradiance`` (D, 3) E_sky with a reflecting ground."""
        import pyopencl.array as cla

        from .lookup import check_kernel_buffer
        from .transmittance import TransmittanceEngine

        from .ground import padded4

        settings = self.settings
        check_atmosphere(atmosphere, settings)
        width, height, depth = settings.size
        has_multiple = gathered is not None
        channels = 9 if has_multiple else 6
        gathered_d = upload_gathered_source(self.queue, gathered, self.dtype)    # zeros, unread, without them
        if settings.sun_transmittance == "table":
            tw, th = settings.transmittance_size
            engine = TransmittanceEngine(self.ctx, self.dtype, steps=settings.sun_steps, sampling=settings.sampling)
            sun_table_d = engine.column_density_table(atmosphere, settings.transmittance_size, queue_only=True)
            engine.queue.finish()
        else:
            tw = th = 2
            sun_table_d = cla.zeros(self.queue, 2 * 2 * column_channels(atmosphere), self.dtype)
        ground_d = cla.to_device(self.queue, padded4(ground_irradiance, self.dtype) if atmosphere.has_ground
                                 else np.zeros((2, 4), self.dtype))     # not read without -DGROUND
        if atmosphere.has_ground:
            check_kernel_buffer("table4d_cells", "ground_irradiance", ground_d, 4 * depth, self.dtype)
        defines = _atmosphere_cl.feature_defines(atmosphere) + (azimuth_defines(settings, interleaved=True)
                                                                if has_multiple else [])
        kernel = self.kernels_with(defines)["table4d_cells"]
        atmosphere_d = _atmosphere_cl.to_device(self.queue, atmosphere, self.dtype)
        n = width * height * depth
        out = np.empty((settings.azimuth_size, n, channels))
        out_d = cla.empty(self.queue, (n, channels), self.dtype)
        grid, harmonics = (((depth, height, width), settings.azimuth_harmonics) if has_multiple
                           else (NO_GATHERED_GRID, 0))
        check_kernel_buffer("table4d_cells", "gathered", gathered_d, gathered_source_reals(grid, harmonics), self.dtype)
        check_kernel_buffer("table4d_cells", "sun_table", sun_table_d, tw * th * column_channels(atmosphere),
                            self.dtype)
        work_size = _cl.launch_size(kernel, self.device, (-(-n // self.vector_width),), (WORK_GROUP,))
        for a in range(settings.azimuth_size):
            cells = np.ascontiguousarray(np.stack(node_rays(atmosphere, settings, a), axis=1), dtype=self.dtype)
            cells_d = cla.to_device(self.queue, cells)
            check_kernel_buffer("table4d_cells", "cells", cells_d, 4 * n, self.dtype)
            event = kernel(self.queue, *work_size, atmosphere_d, gathered_d.data,
                           np.int32(width), np.int32(height), np.int32(depth), np.int32(MAPPINGS[settings.mapping]),
                           self.real2(settings.sun_w_range), np.int32(has_multiple), sun_table_d.data, np.int32(tw),
                           np.int32(th), ground_d.data, np.int32(n), cells_d.data, np.int32(channels), out_d.data)
            self._record("table4d_cells", event)
            out[a] = out_d.get()
        return out.reshape((settings.azimuth_size, depth, height, width, channels))


def compute_data(atmosphere: AtmosphereParameters, settings: TableSettings, gathered=None, backend="opencl",
                 ctx=None, fast_math=False, ground_irradiance=None):
    """``data`` (A, D, H, W, C) of the 4D table of ``settings`` from the orders' ``gathered`` source
    (None: single scattering only) and, with a reflecting ground, their ``ground_irradiance`` (D, 3), on
    OpenCL (:class:`Table4DEngine`) or with the NumPy twin (:func:`clsky.reference.table4d_cells`)."""
    check_atmosphere(atmosphere, settings)
    if backend == "opencl":
        with Table4DEngine(settings, ctx=ctx, fast_math=fast_math) as engine:
            return engine.compute(atmosphere, gathered, ground_irradiance)
    if backend != "numpy":
        raise ParameterError("backend", "one of ['opencl', 'numpy']", backend)
    from .reference import CHUNK_ELEMENTS, table4d_cells

    shape = data_shape(settings)
    out = np.empty((shape[0], int(np.prod(shape[1:4])), shape[4]))
    chunk = max(1, CHUNK_ELEMENTS // ((settings.view_steps + 1) * 8 * 6 * (settings.azimuth_harmonics + 1)))
    for a in range(settings.azimuth_size):
        rays = node_rays(atmosphere, settings, a)
        for start in range(0, rays[0].size, chunk):
            part = slice(start, start + chunk)
            out[a, part] = table4d_cells(atmosphere, settings, gathered, *(r[part] for r in rays),
                                         ground_irradiance=ground_irradiance)
    return out.reshape(shape)
