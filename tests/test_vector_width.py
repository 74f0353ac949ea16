"""The kernels in scalar form (-DVECTOR_WIDTH=1: one cell or pixel per work-item) against the double8 form
clsky runs (issue 12, item 5: nothing may rely on double8 being the fast path).

On CPUs clsky builds every kernel with VECTOR_WIDTH 8 (eight cells or pixels per work-item in double8
arithmetic: PoCL does not vectorise across work-items, its scalar ray march takes 6.4x the CPU time, and on
Intel's CPU runtime, which does, the scalar ray march took 1.2x); on GPUs with 1, one lane per work-item
(on an NVIDIA H200 the scalar ray march took 3 ms a frame against 7, the same 8-bit frames; README "Speed",
GPUs). Both forms must build on every device and give the same numbers; these tests passed on the H200 too.
clsky._cl.VECTOR_WIDTH is set to 1 (every engine made afterwards builds and launches its kernels with it)
and the whole chain is compared with the double8 one: a table with every order, the azimuth harmonics, ozone and
a ground (single scattering, scatter, gather), the 4D table's cells, and every renderer on a fisheye.

Tolerance: the two forms run the same operations per lane; only the vector and scalar builds of exp, sqrt
and the divisions may round differently (PoCL's vector math library against its scalar one), by an ulp or so
per call. Through the table's orders (about 10, each summing some 50 trapezoid terms of products of such
values), 1e-12 of each quantity's maximum leaves room for thousands of such roundings and is still 9 orders
of magnitude below any physical effect (measured: 2.4e-20 of the maximum for the ray march, 512 x 512).
"""

from __future__ import annotations

import numpy as np
import pytest

import clsky
from clsky import _cl
from clsky.anim.cameras import FisheyeCamera, sun_direction
from clsky.render import SkyRenderer

from conftest import SMALL_RAY as RAY, SMALL_TABLE as SETTINGS, build_and_render

RTOL_OF_MAX = 1e-12


def assert_close_to_max(scalar, vector, what):
    scalar, vector = np.asarray(scalar), np.asarray(vector)
    assert scalar.shape == vector.shape and np.isfinite(scalar).all(), what
    scale = np.abs(vector).max()
    assert scale > 0, what
    error = np.abs(scalar - vector).max() / scale
    assert error <= RTOL_OF_MAX, f"{what}: scalar and double8 differ by {error:.2e} of the maximum"


def scalar_programs():
    """The kernel files of the programs built so far with -DVECTOR_WIDTH=1 (clsky._cl's program cache)."""
    return {name for (_, sources, options) in _cl._program_cache if "-DVECTOR_WIDTH=1" in options
            for name in sources if isinstance(name, str)}


@pytest.fixture
def scalar_kernels(monkeypatch):
    """The test starts with VECTOR_WIDTH 8 (double8 on any device: a GPU's own default is 1);
    ``use()``: from then on in the test, every kernel is built and launched with VECTOR_WIDTH 1;
    ``built(files)`` checks that the scalar programs of those kernel files were built (so that a
    comparison cannot pass by comparing double8 with double8)."""
    monkeypatch.setattr(_cl, "VECTOR_WIDTH", 8)

    class Scalar:
        @staticmethod
        def use():
            monkeypatch.setattr(_cl, "VECTOR_WIDTH", 1)

        @staticmethod
        def built(files):
            missing = set(files) - scalar_programs()
            assert not missing, f"no scalar build of {sorted(missing)}"
    return Scalar


@pytest.mark.parametrize("sun_zenith", [40.0, 96.0])
def test_scalar_kernels_give_the_double8_tables_and_frames(cl_context, scalar_kernels, sun_zenith):
    atmosphere = clsky.preset("physical").replace(ground_albedo=0.3)
    vector_table, vector_frames = build_and_render(atmosphere, SETTINGS, [sun_zenith])
    scalar_kernels.use()
    scalar_table, scalar_frames = build_and_render(atmosphere, SETTINGS, [sun_zenith])
    scalar_kernels.built(["single.cl", "multiple.cl", "render.cl"])
    assert scalar_table.orders_record["orders"] == vector_table.orders_record["orders"]
    assert_close_to_max(scalar_table.data, vector_table.data, "table")
    for index, (scalar_order, vector_order) in enumerate(zip(scalar_table.orders, vector_table.orders)):
        assert_close_to_max(scalar_order, vector_order, f"order {index + 1}")
    for name in vector_frames:
        assert_close_to_max(scalar_frames[name], vector_frames[name], f"{name} frame")


def test_scalar_kernels_give_the_double8_4d_table(cl_context, scalar_kernels):
    settings = SETTINGS.replace(size=(5, 16, 5), parameterization="4d", azimuth_size=5)
    atmosphere = clsky.preset("physical")
    vector = clsky.ScatteringTable.build(atmosphere, settings)
    scalar_kernels.use()
    scalar = clsky.ScatteringTable.build(atmosphere, settings)
    assert_close_to_max(scalar.data, vector.data, "4D table")
    directions, valid = FisheyeCamera(24).directions()
    sun = sun_direction(85.0, 150.0)
    frames = []
    for table in (vector, scalar):
        renderer = SkyRenderer(table)
        frames.append(renderer.render_lut4d(renderer.prepare(directions, valid), sun, 0.0))
    assert_close_to_max(frames[1], frames[0], "4D lookup frame")
    scalar_kernels.built(["table4d.cl", "render.cl"])


def test_scalar_kernels_give_the_double8_strided_ray_march(cl_context, scalar_kernels):
    """The ray march with the higher orders' source on every other node (source_stride 2, the draft and
    default levels' choice), at 15 samples (the last node, odd, looked up itself), with the azimuth
    harmonics."""
    table = clsky.ScatteringTable.build("physical", SETTINGS.replace(azimuth_harmonics=2))
    ray = RAY.replace(view_steps=15, source_stride=2)
    directions, valid = FisheyeCamera(24).directions()
    sun = sun_direction(94.0, 150.0)
    frames = []
    for use in (lambda: None, scalar_kernels.use):
        use()
        renderer = SkyRenderer(table, ray_settings=ray)
        frames.append(renderer.render_raymarch(renderer.prepare(directions, valid), sun, 0.0))
    scalar_kernels.built(["render.cl"])
    assert_close_to_max(frames[1], frames[0], "strided ray march")


def test_an_engine_keeps_its_width_and_refuses_another(cl_context, monkeypatch):
    """An engine reads the width once, when it is made: programs and launches agree even if the setting
    changes afterwards; a width the kernels do not accept is refused by name."""
    table = clsky.ScatteringTable.build(clsky.preset("physical"), SETTINGS.replace(azimuth_harmonics=0))
    renderer = SkyRenderer(table, ray_settings=RAY)
    prepared = renderer.prepare(*FisheyeCamera(24).directions())
    sun = sun_direction(60.0, 150.0)
    before = renderer.render_raymarch(prepared, sun, 0.0)
    made_with = renderer.engine.vector_width
    assert made_with == _cl.default_vector_width(renderer.engine.device)
    monkeypatch.setattr(_cl, "VECTOR_WIDTH", 1 if made_with == 8 else 8)
    assert renderer.engine.vector_width == made_with
    np.testing.assert_array_equal(renderer.render_raymarch(prepared, sun, 0.0), before)
    monkeypatch.setattr(_cl, "VECTOR_WIDTH", 4)
    with pytest.raises(ValueError, match=r"clsky._cl.VECTOR_WIDTH must be None or one of \(1, 8\), got 4"):
        SkyRenderer(table, ray_settings=RAY)
