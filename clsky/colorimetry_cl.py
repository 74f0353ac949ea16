"""The tabulated solar power law (:mod:`clsky.colorimetry`, ``solar_power_law_tabulated``) on an OpenCL device.

:func:`solar_power_law_xyz` gives, bit for bit, what ``colorimetry._solar_power_law_tabulated_xyz`` (its
NumPy twin) gives: the ratios to the sun, the pixels' floors and the logarithms stay in NumPy (an OpenCL
log may differ in the last bit), and kernels/power_law.cl does the rest, every operation the twin's in
its order (IEEE arithmetic, no fused multiply-adds). Why: the twin takes some 20 elementwise passes over
the lit pixels per table it reads (four tables: 13 of its 18-22 ms a 512 x 512 frame on the 2-core
machine), and the default animation converts two frames a sun (docs/speed-log.md).

Engines are per thread and per context (:class:`clsky._cl.Engine` is not thread-safe): the animation's
host threads each convert their own frames. Each engine keeps its device buffers (grown as frames need)
and the tables of the wavelengths it has seen.
"""

from __future__ import annotations

import threading

import numpy as np

from . import _cl, colorimetry
from .lookup import check_kernel_buffer

__all__ = ["PowerLawEngine", "solar_power_law_xyz"]

#: Most pixels a frame may have: the kernel takes pixel indices and counts as 32-bit integers.
MAX_PIXELS = np.iinfo(np.int32).max

#: Work-items per work-group of the kernel (any OpenCL device accepts 64; the global size is rounded up).
WORK_GROUP = 64


class PowerLawEngine(_cl.Engine):
    """kernels/power_law.cl: the tabulated solar power law's XYZ of three-wavelength radiance frames
    (float64 only: its twin's)."""

    sources = ("real.cl", "power_law.cl")

    def __init__(self, ctx=None, queue=None):
        super().__init__(ctx, np.float64, queue=queue)
        self._tables = {}           # wavelengths (ascending) -> _device_tables(wavelengths)
        self._buffers = {}          # name -> pyopencl.array.Array, reused while large enough

    def build_options(self):
        return super().build_options() + [f"-DVECTOR_WIDTH={self.vector_width}"]

    def _device_tables(self, lam):
        """(device tables, (Delta_0, Delta_1), (inner nodes, outer nodes)) of ``colorimetry._power_law_tables(lam)``:
        the device copies of B_0, O_0, B_1, O_1, each its X, Y, Z columns one after the other."""
        if lam not in self._tables:
            import pyopencl.array as cla

            tables, deltas = [], []
            for delta, inner, outer in colorimetry._power_law_tables(lam):
                tables += [cla.to_device(self.queue, np.concatenate(columns)) for columns in (inner, outer)]
                deltas.append(delta)
            self._tables[lam] = tables, tuple(deltas), (inner[0].size, outer[0].size)
        return self._tables[lam]

    def _buffer(self, name, size, dtype):
        """A device array of at least ``size`` values of ``dtype`` (kept for the next frame); its first
        ``size`` values as an array."""
        import pyopencl.array as cla

        held = self._buffers.get(name)
        if held is None or held.size < size:
            held = self._buffers[name] = cla.empty(self.queue, size, dtype)
        return held[:size]

    def xyz(self, radiance, wavelengths):
        """CIE 1931 XYZ (..., 3) of ``radiance`` (..., 3) at three distinct ``wavelengths`` [nm] (any order;
        checked by :func:`clsky.colorimetry.three_wavelength_to_xyz`): ``_solar_power_law_tabulated_xyz``'s
        values, bit for bit, for finite radiance (what the renderers give: no NaN or Inf leaves a kernel;
        with an infinite value the twin raises an IndexError and this returns non-finite values)."""
        if np.size(radiance) // 3 > MAX_PIXELS:
            raise ValueError(f"radiance has {np.size(radiance) // 3} pixels, more than the kernel indexes "
                             f"({MAX_PIXELS})")
        # the twin's first steps (its own function): ratios to the sun, the lit pixels, their floor; then logs
        lam, flat, ratio, lit, floor = colorimetry._lit_ratios(radiance, np.asarray(wavelengths, dtype=np.float64))
        n_lit = int(floor.size)
        if not n_lit:
            return np.zeros(np.shape(radiance)[:-1] + (3,))
        stride = -(-n_lit // self.vector_width) * self.vector_width
        rows = np.empty((6, stride))        # r_0, r_1, r_2, then log r_0, log r_1, log r_2; padding 0
        rows[:, n_lit:] = 0.0
        for k, r in enumerate(ratio):
            np.maximum(r[lit], floor, out=rows[k, :n_lit])
            np.log(rows[k, :n_lit], out=rows[3 + k, :n_lit])
        pixels = np.flatnonzero(lit).astype(np.int32)
        tables, (delta_0, delta_1), (n_inner, n_outer) = self._device_tables(tuple(lam.tolist()))
        rows_d = self._buffer("rows", rows.size, np.float64)
        pixels_d = self._buffer("pixels", n_lit, np.int32)
        xyz_d = self._buffer("xyz", flat.size, np.float64)
        rows_d.set(rows.ravel(), queue=self.queue)
        pixels_d.set(pixels, queue=self.queue)
        kernel = "power_law_xyz"
        check_kernel_buffer(kernel, "lit", rows_d, 6 * stride, np.float64)
        check_kernel_buffer(kernel, "pixels", pixels_d, n_lit, np.int32)
        for name, table_d, nodes in zip(("inner_0", "outer_0", "inner_1", "outer_1"), tables,
                                        (n_inner, n_outer, n_inner, n_outer)):
            check_kernel_buffer(kernel, name, table_d, 3 * nodes, np.float64)
        check_kernel_buffer(kernel, "xyz", xyz_d, flat.size, np.float64)
        items = stride // self.vector_width
        step_inner, step_outer = colorimetry.POWER_LAW_TABLE_STEPS
        launch = self.kernels[kernel]
        self._record(kernel, launch(
            self.queue, *_cl.launch_size(launch, self.device, (items,), (WORK_GROUP,)), rows_d.data, np.int32(stride),
            np.int32(n_lit), pixels_d.data, *(table.data for table in tables), np.int32(n_inner), np.int32(n_outer),
            np.float64(step_inner), np.float64(step_outer), np.float64(delta_0), np.float64(delta_1),
            np.float64(colorimetry.POWER_LAW_MAX_EXPONENT), np.int32(flat.shape[0]), xyz_d.data))
        values = np.empty(flat.shape)
        xyz_d.get(queue=self.queue, ary=values.reshape(-1))
        return values.reshape(np.shape(radiance)[:-1] + (3,))


_engines = threading.local()


def solar_power_law_xyz(radiance, wavelengths, ctx):
    """``colorimetry.three_wavelength_to_xyz(radiance, wavelengths, 'solar_power_law_tabulated')`` computed on
    the device of ``ctx`` (a pyopencl.Context), the same values bit for bit; this thread's engine for that
    context (made at its first call). A device without double precision (a float32 renderer's) leaves
    the conversion to the host: it is float64."""
    _cl.check_context(ctx)
    engines = _engines.__dict__.setdefault("by_context", {})
    if ctx.int_ptr not in engines:                    # None: a device without fp64
        engines[ctx.int_ptr] = PowerLawEngine(ctx) if _cl.has_fp64(ctx.devices[0]) else None
    engine = engines[ctx.int_ptr]
    if engine is None:
        return colorimetry._solar_power_law_tabulated_xyz(radiance, np.asarray(wavelengths, dtype=np.float64))
    return engine.xyz(radiance, wavelengths)
