"""The orders' stopping test over an iteration: the running sum, the order before, and each order's relative
addition and estimated error (:func:`clsky.orders.relative_addition`), on the host or on the OpenCL device.

:class:`HostStoppingTest` keeps the running sum and the order before on the host and calls
:func:`clsky.orders.relative_addition`. :class:`DeviceStoppingTest` keeps them on the device, beside the
orders the scatter leaves there (kernels/stopping.cl), and gives the same numbers bit for bit: the same
operations on the same values, each rounded once, and maxima, which are exact in any order. It is what
the harmonic build (:mod:`clsky.azimuth`) uses on OpenCL: on the host the test was the largest part of
the build's host work on each order (four passes of NumPy over 122 MB tables for the default animation's
table, some 0.25 s an order, of about 0.6), during which the device had nothing to do (docs/speed-log.md).

Both take an order's values as the backend holds them (``add(order, ratio)``, which ``reads`` names), and
``result()`` gives ``(relative addition, estimated error)``; the error is the relative addition when
``ratio`` is None.
"""

from __future__ import annotations

import math

import numpy as np

from . import _cl
from .orders import BRIGHT_FRACTION, relative_addition

__all__ = ["HostStoppingTest", "DeviceStoppingTest", "CHUNK_CELLS"]

#: Cells per work-item of the device's test (kernels/stopping.cl): each work-item writes its maxima, and
#: the host takes the maximum of a few thousand of them for the default animation's table.
CHUNK_CELLS = 2048


class HostStoppingTest:
    """The stopping test on the host.

    Parameters
    ----------
    running : ndarray (..., 3) float64
        The running sum so far (single scattering's, per wavelength): taken, and added to in place.
    keep_previous : bool
        Keep each order for the next one's estimated error (``orders="auto"``, which has a geometric tail).
    """

    #: What :meth:`add` takes: the order's host table.
    reads = "host"

    def __init__(self, running, keep_previous):
        self.running = running
        self.previous = None
        self.keep_previous = bool(keep_previous)
        self._result = None

    def add(self, order, ratio=None):
        """Add ``order`` (the running sum's shape) to the running sum and test it: :meth:`result` gives
        (its relative addition, its estimated error with the geometric ``ratio`` (r, g, b) and the order
        before, or the addition without a ratio)."""
        if ratio is not None and self.previous is None:
            raise ValueError("a geometric ratio needs the order before (keep_previous=True and an order added)")
        self.running += order
        addition = relative_addition(order, self.running)
        error = addition if ratio is None else relative_addition(order, self.running, self.previous, ratio)
        if self.keep_previous:
            if self.previous is None:
                self.previous = np.empty_like(order)
            np.copyto(self.previous, order)
        self._result = addition, error

    def result(self):
        """(relative addition, estimated error) of the last order added."""
        return self._result


class DeviceStoppingTest(_cl.Engine):
    """The stopping test on an OpenCL device with fp64 (kernels/stopping.cl), for orders held as padded
    device tables (..., 8), channels 0-2, of ``dtype`` (float32 or float64): the running sum and the order
    before are kept on the device in float64 (cells, 3), as the host keeps them.

    :meth:`add` enqueues the test after the commands already on the queue (the scatter that wrote the
    order) and returns; :meth:`result` waits for it alone, not for what was enqueued after it (the next
    order's gathers), so that the host's own work on the order overlaps both.

    Parameters
    ----------
    running : iterable of ndarray (..., 3) float64
        The running sum so far (single scattering's), as consecutive slabs along its first axis (each of
        one or more rows: ``shape[1:]`` or ``(n,) + shape[1:]``), uploaded one at a time, so that the host
        never holds the whole sum (122 MB for the default animation's table, which added to the build's
        peak where it was made).
    shape : tuple
        The running sum's shape (..., 3).
    keep_previous : bool
        As :class:`HostStoppingTest`.
    dtype : numpy dtype
        The orders' precision.
    queue, allocator
        As :class:`clsky._cl.Engine`: the orders' queue (in order) and their pool.

    The program is built without ``-cl-fast-relaxed-math`` whatever the table's settings: the test's
    divisions are those of the host.
    """

    sources = ("stopping.cl",)
    #: What :meth:`add` takes: the order's padded device table.
    reads = "backend"

    def __init__(self, running, shape, keep_previous, dtype=np.float64, queue=None, allocator=None):
        import pyopencl as cl
        import pyopencl.array as cla

        if queue is not None and not _cl.has_fp64(queue.device):
            raise _cl.NoDeviceError(f"the device's stopping test needs double precision, which "
                                    f"{queue.device.name!r} lacks: use HostStoppingTest")
        self.node_dtype = np.dtype(dtype)
        super().__init__(dtype=np.float64, queue=queue, allocator=allocator)
        self.shape = tuple(shape)
        if len(self.shape) < 2 or self.shape[-1] != 3:
            raise ValueError(f"shape must be (..., 3), got {self.shape}")
        self.cells = math.prod(self.shape) // 3
        self.items = -(-self.cells // CHUNK_CELLS)
        self.running = cla.empty(self.queue, self.shape, np.float64, allocator=allocator)
        offset = 0
        for slab in running:
            slab = np.ascontiguousarray(slab, dtype=np.float64)
            rows = slab.shape if slab.ndim == len(self.shape) else (1,) + slab.shape     # a slab, or one row
            if rows[1:] != self.shape[1:] or offset + slab.nbytes > self.running.nbytes:
                raise ValueError(f"the running sum's slabs must fill {self.shape} along its first axis, got a "
                                 f"slab {slab.shape} at byte {offset}")
            cl.enqueue_copy(self.queue, self.running.data, slab, dst_offset=offset, is_blocking=True)
            offset += slab.nbytes
        if offset != self.running.nbytes:
            raise ValueError(f"the running sum's slabs must fill {self.shape}, got {offset} of "
                             f"{self.running.nbytes} bytes")
        self.keep_previous = bool(keep_previous)
        self.previous = cla.empty(self.queue, self.shape, np.float64, allocator=allocator) if keep_previous else None
        self._have_previous = False
        self._maxima = cla.empty(self.queue, (self.items, 3), np.float64, allocator=allocator)
        self._threshold = cla.empty(self.queue, (4,), np.float64, allocator=allocator)
        self._ratios = cla.empty(self.queue, (self.items, 2), np.float64, allocator=allocator)
        self._host_ratios = np.empty((self.items, 2))
        self._pending = None

    def build_options(self):
        return ["-DNODE=" + ("double" if self.node_dtype == np.float64 else "float")]

    def add(self, order, ratio=None):
        """As :meth:`HostStoppingTest.add`, for ``order`` a padded device table (..., 8) of the running
        sum's cells in this test's dtype (the queue's commands before it write it)."""
        import pyopencl as cl

        if order.shape[:-1] != self.shape[:-1] or order.shape[-1] != 8 or order.dtype != self.node_dtype:
            raise ValueError(f"order must be a padded {self.node_dtype} table {self.shape[:-1] + (8,)}, got "
                             f"{order.dtype} {order.shape}")
        if ratio is not None and not self._have_previous:
            raise ValueError("a geometric ratio needs the order before (keep_previous=True and an order added)")
        cells, chunk = np.uint64(self.cells), np.uint32(CHUNK_CELLS)
        running_sum, order_ratios = self.kernels["running_sum"], self.kernels["order_ratios"]
        self._record("running_sum", running_sum(
            self.queue, *self._linear_size(running_sum, self.items), order.data, self.running.data, cells, chunk,
            self._maxima.data))
        self._record("bright_threshold", self.kernels["bright_threshold"](
            self.queue, (1,), None, self._maxima.data, np.uint32(self.items), np.float64(BRIGHT_FRACTION),
            self._threshold.data))
        if ratio is None:
            r = squared_complement = np.zeros(3)
        else:
            r = np.asarray(ratio, dtype=np.float64)
            squared_complement = (1.0 - r) ** 2        # as relative_addition
        previous = self.previous if self.previous is not None else self.running      # not read without `keep`
        self._record("order_ratios", order_ratios(
            self.queue, *self._linear_size(order_ratios, self.items), order.data, self.running.data, previous.data,
            cells, chunk, self._threshold.data, self.real4(r), self.real4(squared_complement),
            np.int32(ratio is not None), np.int32(self.keep_previous), self._ratios.data))
        self._pending = (cl.enqueue_copy(self.queue, self._host_ratios, self._ratios.data, is_blocking=False),
                         ratio is not None)
        self._have_previous = self.keep_previous

    def result(self):
        """(relative addition, estimated error) of the last order added: waits for its test only."""
        event, estimated = self._pending
        event.wait()
        addition, error = self._host_ratios.max(axis=0)
        return float(addition), (float(error) if estimated else float(addition))
