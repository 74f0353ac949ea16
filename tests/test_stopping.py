"""The orders' stopping test on the device (clsky.stopping.DeviceStoppingTest, kernels/stopping.cl) against
the host's (HostStoppingTest, clsky.orders.relative_addition): the same numbers, bit for bit.

The device's test is what the harmonic build uses on OpenCL; its results decide how many orders a table
has and which geometric tail it gets, so any difference, even in the last bit, would change tables. The
comparisons are exact (==): the kernels do the host's operations on the same values, each rounded once
(no fused multiply-add, correctly rounded double division), and take maxima, exact in any order.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
import pytest
from numpy.testing import assert_array_equal

from clsky.orders import relative_addition
from clsky.stopping import CHUNK_CELLS, DeviceStoppingTest, HostStoppingTest

#: (nodes, D, H, W): 3 x 5 x 7 x 41 = 4305 cells, two full chunks of 2048 cells and a partial one.
SHAPE = (3, 5, 7, 41)


def _orders(rng, count, dtype):
    """Single scattering's running sum and ``count`` orders: many dark cells (below 1 % of their
    channel's maximum), some exactly zero, orders of the size a real iteration has (shrinking by about
    0.3 an order), in the table's precision (float32 values are exact in float64)."""
    running = rng.uniform(0.0, 1.0, SHAPE + (3,)) ** 4
    running[0, 0, 0, :7] = 0.0
    orders = []
    for k in range(count):
        order = (rng.uniform(0.0, 0.3, SHAPE + (3,)) * 0.3 ** k * running).astype(dtype).astype(np.float64)
        orders.append(order)
    return running, orders


def _padded(queue, order, dtype):
    """An order as the scatter leaves it on the device: (..., 8), channels 0-2 and 3-5 both the order."""
    padded = np.zeros(order.shape[:-1] + (8,), dtype=dtype)
    padded[..., :3] = order
    padded[..., 3:6] = order
    return cla.to_device(queue, padded)


@pytest.mark.parametrize("keep_previous", [True, False], ids=["auto (with the tail)", "fixed orders"])
def test_device_test_equals_the_host_test_bit_for_bit(cl_context, dtype, keep_previous):
    """Five orders in a row, the last three with a geometric ratio when the previous order is kept: every
    relative addition and estimated error is the host's, and so are the running sum and the order
    before left on the device."""
    assert np.prod(SHAPE) > 2 * CHUNK_CELLS and np.prod(SHAPE) % CHUNK_CELLS    # chunks, and a partial one
    queue = cl.CommandQueue(cl_context)
    rng = np.random.default_rng(11)
    running, orders = _orders(rng, 5, dtype)
    host = HostStoppingTest(running.copy(), keep_previous)
    device = DeviceStoppingTest(iter(running), running.shape, keep_previous, dtype, queue=queue)
    seen = []
    for k, order in enumerate(orders):
        ratio = np.array([0.136, 0.245, 0.289]) + 0.01 * k if keep_previous and k >= 2 else None
        host.add(order, ratio)
        device.add(_padded(queue, order, dtype), ratio)
        assert device.result() == host.result(), k
        seen.append(host.result())
    assert_array_equal(device.running.get(), host.running)
    if keep_previous:
        assert_array_equal(device.previous.get(), orders[-1])
        assert all(error != addition for addition, error in seen[2:])      # the ratio's estimate was taken
    assert all(0.0 < addition < 1.0 for addition, _ in seen)


def test_host_test_is_relative_addition():
    """HostStoppingTest's numbers are relative_addition's on the running sum after the order (and the
    estimate with the order before), as clsky.orders defines them."""
    rng = np.random.default_rng(3)
    running, orders = _orders(rng, 3, np.float64)
    test = HostStoppingTest(running.copy(), True)
    total = running.copy()
    ratio = np.array([0.2, 0.25, 0.3])
    for k, order in enumerate(orders):
        total += order
        test.add(order, ratio if k else None)
        addition = relative_addition(order, total)
        error = relative_addition(order, total, orders[k - 1], ratio) if k else addition
        assert test.result() == (addition, error)


def test_cancellation_and_extreme_values_stay_exact(cl_context):
    """Orders that are NumPy's rounded product of the ratio and the order before, so that the host's
    |added - r P| cancels to exactly 0, where a fused multiply-add (r P unrounded) would leave the
    product's rounding error; values near 1e300 (bright) and 1e-300 (dark): still the host's numbers."""
    queue = cl.CommandQueue(cl_context)
    rng = np.random.default_rng(5)
    ratio = np.array([0.1359, 0.2449, 0.2893])
    running = rng.uniform(0.5, 1.0, (4, 600, 3))
    running[0, :3] = 1e300, 1e-300, 1e300
    before = rng.uniform(0.0, 0.1, running.shape) * running
    order = before * ratio                                      # r P to rounding
    host = HostStoppingTest(running.copy(), True)
    device = DeviceStoppingTest([running], running.shape, True, np.float64, queue=queue)
    for values, r in ((before, None), (order, ratio)):
        host.add(values, r)
        device.add(_padded(queue, values, np.float64), r)
        assert device.result() == host.result()
    assert host.result()[1] == 0.0                    # the estimate cancelled exactly


def test_refuses_what_it_cannot_test(cl_context):
    queue = cl.CommandQueue(cl_context)
    running = np.ones((2, 4, 3))
    with pytest.raises(ValueError, match="fill"):
        DeviceStoppingTest([running[0]], running.shape, True, queue=queue)          # one of two rows
    with pytest.raises(ValueError, match="shape must be"):
        DeviceStoppingTest([running], (2, 4, 6), True, queue=queue)
    test = DeviceStoppingTest([running], running.shape, True, queue=queue)
    with pytest.raises(ValueError, match="order before"):
        test.add(_padded(queue, running, np.float64), np.array([0.1, 0.2, 0.3]))    # no order before yet
    with pytest.raises(ValueError, match="padded float64 table"):
        test.add(_padded(queue, running, np.float32))
    with pytest.raises(ValueError, match="padded float64 table"):
        test.add(cla.to_device(queue, np.ones((2, 4, 3))))
    with pytest.raises(ValueError, match="order before"):
        HostStoppingTest(running.copy(), False).add(running, np.array([0.1, 0.2, 0.3]))
