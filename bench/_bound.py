"""The exp() bound of the ray march (issue 12): how fast the device evaluates exp() in the kernels' own
vector type, and how many exponentials a ray-marched frame cannot do without.

The bound of a march is the CPU time its unavoidable exponentials take at the measured rate; a march
within 2x of it spends no more on everything else (geometry, cube roots, table reads, stores) than on
its exponentials. Per ray node (kernels/view_ray.cl, integrate_gathered with the sun's columns from the
2D table) the march evaluates :data:`EXPS_PER_NODE` exponentials: the Rayleigh and Mie densities, the
view transmittance and the sun transmittance, each in r, g and b (3 + 3). A ray of N samples has N + 1
nodes; pixels outside a fisheye's circle are not marched.
"""

from __future__ import annotations

import time

import numpy as np
import pyopencl as cl

from clsky import _cl

#: exponentials per ray node: 2 densities, 3 view transmittances, 3 sun transmittances (r, g, b)
EXPS_PER_NODE = 8

_SOURCE = """
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
__kernel void exps(__global double *out, const int count)
{
    const int g = get_global_id(0);
    double8 x = (double8)(0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7) * 1e-3 + (double)g * 1e-6;
    double8 sum = (double8)(0.0);
    for (int i = 0; i < count; ++i) {     /* independent exponentials: throughput, not latency */
        sum += exp(-x);
        x += 1e-4;
    }
    vstore8(sum, g, out);
}
"""


def exp_rate(ctx=None, items=16384, count=1000, repeat=3) -> float:
    """Exponentials per CPU-second [1/s] of ``double8`` exp() on the device of ``ctx`` (default:
    :func:`clsky._cl.make_context`): the best of ``repeat`` runs of ``items`` work-items evaluating
    ``count`` independent exponentials of 8 lanes each, timed by the process CPU time (PoCL's workers
    included), after a warm-up run."""
    ctx = ctx if ctx is not None else _cl.make_context(np.float64)
    queue = cl.CommandQueue(ctx)
    kernel = cl.Kernel(_cl.build_program(ctx, (_cl.Source("exp_bound.cl", _SOURCE),)), "exps")
    out = cl.Buffer(ctx, cl.mem_flags.WRITE_ONLY, 8 * 8 * items)
    best = 0.0
    for run in range(repeat + 1):
        cpu = time.process_time()
        kernel(queue, (items,), (64,), out, np.int32(count))
        queue.finish()
        cpu = time.process_time() - cpu
        if run > 0 and cpu > 0:
            best = max(best, 8 * items * count / cpu)
    return best


def march_exps(pixels: int, samples: int) -> int:
    """Exponentials of a ray-marched frame: ``pixels`` marched rays of ``samples`` samples (N + 1 nodes)."""
    return EXPS_PER_NODE * (samples + 1) * pixels
