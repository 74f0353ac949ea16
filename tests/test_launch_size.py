"""Fixed work-group sizes (clsky._cl.launch_size): every launch of a kernel uses one local size whatever the
table, frame or query count, so that PoCL compiles one kernel object per program instead of one per local
size (left to PoCL, each new global size got a divisor of its own: the default suite on an empty kernel
cache compiled 877 kernel objects, now 519, docs/speed-log.md), and the padded work-items beyond a count
write nothing.

Exact comparisons: add_into and combine_nodes are one multiply-add per value, in the same order whatever
the launch shape, so the device gives NumPy's bits.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
import pytest

from clsky import _cl
from clsky.multiple import GATHER_WORK_GROUP, MultipleScatteringEngine
from clsky.render import RENDER_WORK_GROUP, SkyRenderer

from conftest import SMALL_RAY, SMALL_TABLE


class FakeKernel:
    """A kernel whose largest work-group on any device is ``largest`` (as a GPU's may be)."""

    def __init__(self, largest):
        self.largest = largest

    def get_work_group_info(self, param, device):
        assert param == cl.kernel_work_group_info.WORK_GROUP_SIZE
        return self.largest


class FakeDevice:
    """A device whose work-groups may be at most 1024 x 1024 x 64 work-items along their axes (NVIDIA's)."""

    max_work_item_sizes = [1024, 1024, 64]


@pytest.mark.parametrize("counts, group, largest, expected", [
    ((1000,), (256,), 4096, ((1024,), (256,))),             # rounded up to a multiple of the group
    ((1024,), (256,), 4096, ((1024,), (256,))),             # already a multiple
    ((0,), (256,), 4096, ((256,), (256,))),                 # no item: one group, whose items all return
    ((3,), (256,), 4096, ((256,), (256,))),
    ((5000,), (4096,), 512, ((5120,), (512,))),             # a kernel's limit: halved until it fits
    ((64, 256), (64, 64), 256, ((64, 256), (16, 16))),      # the largest axis halved first, in turn
    ((8, 32, 208), (8, 8, 1), 4096, ((8, 32, 208), (8, 8, 1))),
    ((3, 5, 7), (8, 8, 1), 4096, ((8, 8, 7), (8, 8, 1))),
    ((8, 8, 300), (1, 8, 256), 4096, ((8, 8, 320), (1, 8, 64))),    # the device's third axis: at most 64
])
def test_launch_size_rounds_counts_up_and_fits_the_kernel(counts, group, largest, expected):
    assert _cl.launch_size(FakeKernel(largest), FakeDevice(), counts, group) == expected


@pytest.mark.parametrize("counts, group", [((10,), (8, 8)), ((10, 10), (0, 8))])
def test_launch_size_refuses_a_bad_group(counts, group):
    with pytest.raises(ValueError, match="counts and group must be of one length"):
        _cl.launch_size(FakeKernel(4096), FakeDevice(), counts, group)


class Recorded:
    """A kernel whose launches' (name, global, local) are appended to ``launches``."""

    def __init__(self, name, kernel, launches):
        self.name, self.kernel, self.launches = name, kernel, launches

    def get_work_group_info(self, param, device):
        return self.kernel.get_work_group_info(param, device)

    def __call__(self, queue, global_size, local_size, *args):
        self.launches.append((self.name, tuple(global_size), None if local_size is None else tuple(local_size)))
        return self.kernel(queue, global_size, local_size, *args)


def recording(kernels, launches):
    """Every kernel of the dict ``kernels`` made :class:`Recorded` into ``launches``."""
    for name, kernel in list(kernels.items()):
        kernels[name] = Recorded(name, kernel, launches)


# Cell counts: a multiple of the group, a prime, one past a multiple of 4096 (PoCL's own local sizes were
# the largest divisors up to 4096: 256, 1009 and 1, as 12289 is prime).
SHAPES = [(4, 8, 8), (1, 1, 1009), (1, 1, 3 * 4096 + 1)]


def test_table_kernels_launch_one_local_size_and_match_numpy(cl_context):
    engine = MultipleScatteringEngine(ctx=cl_context)
    launches = []
    recording(engine.kernels, launches)
    rng = np.random.default_rng(7)
    for shape in SHAPES:
        total, addend = rng.random((2,) + shape + (8,)), rng.random((2,) + shape + (8,))
        total_d, addend_d = cla.to_device(engine.queue, total), cla.to_device(engine.queue, addend)
        engine.add_into(total_d, addend_d, slabs=1)             # the second slab must stay as it was
        expected = total.copy()
        expected[0] = 1.0 * total[0] + 1.0 * addend[0]
        np.testing.assert_array_equal(total_d.get(), expected)

        weights = np.array([0.25, -1.5])
        out_d = cla.empty(engine.queue, shape + (8,), np.float64)
        engine.combine_nodes(addend_d, weights, out_d)
        np.testing.assert_array_equal(out_d.get(), (1.0 * 0.0 + weights[0] * addend[0]) + weights[1] * addend[1])

        height = shape[1]
        engine.gather(rng.random((2, height, height)), total[0, ..., :6])
    engine.queue.finish()
    locals_by_kernel = {}
    for name, _, local in launches:
        locals_by_kernel.setdefault(name, set()).add(local)
    assert locals_by_kernel == {"add_into": {_cl.LINEAR_WORK_GROUP}, "combine_nodes": {_cl.LINEAR_WORK_GROUP},
                                "gather": {GATHER_WORK_GROUP}}


def test_renders_of_any_size_launch_one_local_size(cl_context):
    """Frames of 2 x 2, 7 x 9 and 40 x 40 pixels: one work-group size (RENDER_WORK_GROUP work-items, each
    vector_width pixels), the small frames padded to it."""
    import clsky
    from clsky.anim.cameras import FisheyeCamera, sun_direction

    table = clsky.ScatteringTable.build("atmosphere-plus", SMALL_TABLE, ctx=cl_context)
    with SkyRenderer(table, SMALL_RAY, ctx=cl_context) as sky:
        launches = []
        plain = sky.engine.kernels_with

        def kernels_with(defines=()):
            kernels = dict(plain(defines))
            recording(kernels, launches)
            return kernels

        sky.engine.kernels_with = kernels_with
        sun = sun_direction(60.0, 180.0)
        for size in (2, 40):
            directions, valid = FisheyeCamera(size).directions()
            assert np.isfinite(sky.render_raymarch(directions, sun, 0.0, valid=valid)).all()
        directions = np.tile([0.0, 0.6, 0.8], (7, 9, 1))
        assert np.isfinite(sky.render_table(directions, sun, 0.0)).all()
    assert len(launches) == 3
    assert {local for _, _, local in launches} == {(RENDER_WORK_GROUP,)}
