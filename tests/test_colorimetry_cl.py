"""kernels/power_law.cl (clsky/colorimetry_cl.py) against its NumPy twin,
``clsky.colorimetry._solar_power_law_tabulated_xyz``: bit for bit.

Why no tolerance: the host computes what the kernel could round differently (NumPy's logarithms), and the
kernel does only IEEE +, -, *, / (correctly rounded in OpenCL's double precision), fmin / fmax and
truncations, in the twin's order, with contraction into fused multiply-adds switched off; any difference
is a bug. Both kernel forms (VECTOR_WIDTH 8 and 1, issue 12 item 5) on frames that reach every branch:
unlit pixels at the start, in runs and at the end, channels at 0 (floored), log ratios in the tables'
last intervals (the floor's bound), exponents beyond +-8 (clipped), pixel counts that are no multiple
of 8, one pixel, none lit; wavelengths in any order; engines reused across frame sizes and threads.
"""

from __future__ import annotations

import threading

import numpy as np
import pytest

from clsky import _cl, colorimetry
from clsky.colorimetry_cl import PowerLawEngine, solar_power_law_xyz

#: The animation's wavelengths (the physical preset's) and an unsorted order of three others.
WAVELENGTHS = [(650.0, 510.0, 475.0), (475.0, 680.0, 550.0)]


def sky_like(rng, shape):
    """Radiances (shape + (3,)) spanning six decades with smooth and random colours, some pixels unlit
    (all zero) in runs, at the start and at the end, some channels at 0, and pixels so red or blue that
    their log ratios reach the floor's bound."""
    n = int(np.prod(shape))
    base = 10.0 ** rng.uniform(-4.0, 2.0, n)
    colour = np.exp(rng.normal(0.0, 0.6, (n, 3)))
    values = base[:, None] * colour
    values[rng.random(n) < 0.2] = 0.0                             # scattered unlit pixels
    values[: n // 10] = 0.0                                       # a run at the start ...
    values[n // 2: n // 2 + n // 20] = 0.0                        # ... in the middle ...
    values[-(n // 10 or 1):] = 0.0                                # ... and at the end
    zero_channel = rng.random(n) < 0.05
    values[zero_channel, rng.integers(0, 3, int(zero_channel.sum()))] = 0.0
    extreme = rng.random(n) < 0.02                                # ratios 1e12 and more apart: floored
    values[extreme] = np.array([1e3, 1e-9, 1e-14])[rng.permutation(3)]
    return values.reshape(tuple(shape) + (3,))


@pytest.fixture(params=[8, 1], ids=["double8", "scalar"])
def engine(request, cl_context, monkeypatch):
    monkeypatch.setattr(_cl, "VECTOR_WIDTH", request.param)
    made = PowerLawEngine(cl_context)
    assert made.vector_width == request.param
    return made


def assert_same_bits(device, host):
    assert device.shape == host.shape and device.dtype == host.dtype == np.float64
    differ = np.flatnonzero(device.view(np.uint64) != host.view(np.uint64))
    assert differ.size == 0, f"{differ.size} of {host.size} values differ, first at {differ[:5]}"


@pytest.mark.parametrize("wavelengths", WAVELENGTHS)
@pytest.mark.parametrize("shape", [(1,), (7,), (9,), (1001,), (64, 48)])
def test_the_kernel_gives_the_twins_bits(engine, wavelengths, shape):
    radiance = sky_like(np.random.default_rng(sum(shape)), shape)
    if shape == (1,):
        radiance[0] = (0.2, 0.5, 0.9)                  # a lit single pixel (sky_like's end run unlit it)
    assert (radiance.reshape(-1, 3).max(axis=1) > 0).any(), "no lit pixel: the kernel would not run"
    expected = colorimetry._solar_power_law_tabulated_xyz(radiance, np.array(wavelengths))
    assert_same_bits(engine.xyz(radiance, wavelengths), expected)


def test_the_frames_reach_every_branch():
    """The frames above are what the docstring says: unlit pixels, log ratios at the floor's bound, clipped
    and unclipped exponents
    (so that a passing test covers those branches of the kernel)."""
    radiance = sky_like(np.random.default_rng(112), (64, 48)).reshape(-1, 3)
    lam = np.array(WAVELENGTHS[0])
    ratio = radiance[:, np.argsort(lam)] / colorimetry.solar_irradiance_astm_g173(np.sort(lam))
    top = ratio.max(axis=1)
    lit = top > 0
    assert 0 < lit.sum() < lit.size and not lit[0] and not lit[-1]
    assert lit.sum() % 8, "the lit pixels fill whole double8 vectors: the padded lanes go untested"
    logs = np.log(np.maximum(ratio[lit], colorimetry.POWER_LAW_FLOOR * top[lit, None]))
    q = np.diff(logs, axis=1)
    half_width = colorimetry._Q_NODES * colorimetry.POWER_LAW_TABLE_STEPS[0]
    delta = np.diff(np.log(np.sort(lam)))
    # the floor bounds |q| by log(1e12), just inside the inner table: its last interval is reached
    assert (np.abs(q) > half_width - colorimetry.POWER_LAW_TABLE_STEPS[0]).any()
    assert (np.abs(q / delta) > colorimetry.POWER_LAW_MAX_EXPONENT).any()    # clipped exponents
    assert (np.abs(q / delta) < colorimetry.POWER_LAW_MAX_EXPONENT).any()


def test_no_lit_pixel_gives_zeros(engine):
    radiance = np.zeros((5, 4, 3))
    result = engine.xyz(radiance, WAVELENGTHS[0])
    assert result.shape == (5, 4, 3) and not result.any()


def test_pixels_whose_floor_underflows_are_black_not_nan(engine):
    """A pixel whose largest channel is below about 5e-12 of the smallest normal double has a power-law floor
    (1e-12 of that channel) of 0, whose logarithm is -inf: its XYZ was NaN, in the twin and the kernel
    alike (a valid radiance, >= 0 and finite, such as exp() of a deep shadow's optical depth can give). Now
    it is black, as an unlit pixel; the least pixel whose floor stays positive keeps its colour."""
    tiny = np.array([[1e-315, 2e-315, 0.0], [5e-324] * 3, [0.0, 0.0, 0.0], [1e-300, 3e-300, 2e-300], [1.0, 2.0, 3.0]])
    host = colorimetry._solar_power_law_tabulated_xyz(tiny, np.array(WAVELENGTHS[0]))
    assert_same_bits(engine.xyz(tiny, WAVELENGTHS[0]), host)
    plain = colorimetry._solar_power_law_xyz(tiny, np.array(WAVELENGTHS[0]))
    for xyz in (host, plain):
        assert np.isfinite(xyz).all() and not xyz[:3].any()
        assert (xyz[3:] > 0).all()


@pytest.mark.parametrize("method", ["solar_power_law", "solar_power_law_tabulated", "solar_interpolation",
                                    "bruneton2017"])
@pytest.mark.parametrize("bad", [[np.nan, 1.0, 1.0], [-1.0, 1.0, 1.0], [np.inf, 1.0, 1.0], [1e308, 1.0, 1.0]])
def test_radiance_that_is_no_radiance_is_refused(cl_context, method, bad):
    """The power law took NaN for a black pixel, clamped a negative channel to 0, ended an infinite one in
    IndexError and overflowed to inf on 1e308; the linear methods passed them on. A radiance is finite, >= 0
    and at most MAX_RADIANCE (1e100): ValueError naming it."""
    radiance = np.ones((4, 3))
    radiance[2] = bad
    for ctx in (None, cl_context):
        with pytest.raises(ValueError, match=r"^radiance must be finite radiances in \[0, 1e\+100\], a last axis of 3 "
                                             r"\(three wavelengths\), got 1 NaN, infinite, negative or larger values$"):
            colorimetry.three_wavelength_to_xyz(radiance, WAVELENGTHS[0], method, ctx=ctx)
    with pytest.raises(ValueError, match=r"^radiance must be .* got shape \(2,\)$"):
        colorimetry.three_wavelength_to_xyz([1.0, 1.0], WAVELENGTHS[0], method)


def test_an_engine_reused_across_frame_sizes_and_wavelengths(engine):
    """Its buffers grow for a larger frame and serve a smaller one after it; its tables follow the
    wavelengths."""
    rng = np.random.default_rng(5)
    for shape, wavelengths in [((16, 16), WAVELENGTHS[0]), ((40, 30), WAVELENGTHS[1]), ((3, 5), WAVELENGTHS[0])]:
        radiance = sky_like(rng, shape)
        expected = colorimetry._solar_power_law_tabulated_xyz(radiance, np.array(wavelengths))
        assert_same_bits(engine.xyz(radiance, wavelengths), expected)


def test_threads_convert_side_by_side(cl_context):
    """clsky.colorimetry.three_wavelength_to_xyz with ``ctx`` from four threads at once (each its own
    engine, as the animation's host threads): every frame the twin's bits."""
    rng = np.random.default_rng(9)
    frames = [sky_like(rng, (32, 32)) for _ in range(8)]
    results, errors = {}, []

    def convert(indices):
        try:
            for i in indices:
                results[i] = colorimetry.three_wavelength_to_xyz(frames[i], WAVELENGTHS[0],
                                                                 "solar_power_law_tabulated", ctx=cl_context)
        except Exception as error:            # noqa: BLE001 -- reported below, in the test's thread
            errors.append(error)

    threads = [threading.Thread(target=convert, args=(range(k, 8, 4),)) for k in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert not errors, errors
    for i, frame in enumerate(frames):
        assert_same_bits(results[i], colorimetry._solar_power_law_tabulated_xyz(frame, np.array(WAVELENGTHS[0])))


def test_the_other_methods_ignore_the_context(cl_context):
    radiance = sky_like(np.random.default_rng(3), (10,))
    for method in ("solar_power_law", "solar_interpolation", "bruneton2017"):
        with_device = colorimetry.three_wavelength_to_xyz(radiance, WAVELENGTHS[0], method, ctx=cl_context)
        assert_same_bits(with_device, colorimetry.three_wavelength_to_xyz(radiance, WAVELENGTHS[0], method))


def test_the_module_function_keeps_one_engine_per_thread_and_context(cl_context):
    radiance = sky_like(np.random.default_rng(4), (20,))
    solar_power_law_xyz(radiance, WAVELENGTHS[0], cl_context)
    from clsky import colorimetry_cl

    engine = colorimetry_cl._engines.by_context[cl_context.int_ptr]
    solar_power_law_xyz(radiance, WAVELENGTHS[1], cl_context)
    assert colorimetry_cl._engines.by_context[cl_context.int_ptr] is engine


def test_a_device_without_double_precision_converts_on_the_host(cl_context, monkeypatch):
    """A float32 renderer's device may lack fp64: the conversion (float64) then stays on the host, the same
    values, and no engine is made for it."""
    import pyopencl as cl

    from clsky import colorimetry_cl

    context = cl.Context(devices=[cl_context.devices[0]])           # no engine of this thread's for it yet
    monkeypatch.setattr(_cl, "has_fp64", lambda device: False)
    monkeypatch.setattr(colorimetry_cl, "PowerLawEngine", None)      # making one would raise
    radiance = sky_like(np.random.default_rng(6), (30,))
    assert_same_bits(solar_power_law_xyz(radiance, WAVELENGTHS[1], context),
                     colorimetry._solar_power_law_tabulated_xyz(radiance, np.array(WAVELENGTHS[1])))
    assert colorimetry_cl._engines.by_context[context.int_ptr] is None


@pytest.mark.parametrize("call, message", [
    # spectral_to_xyz passed NaN through (NaN XYZ) and took negative radiance
    (lambda: colorimetry.spectral_to_xyz([np.nan, 1.0, 1.0], [400.0, 500.0, 600.0]),
     r"^radiance must be finite radiances in \[0, 1e\+100\], a last axis of 3 \(one per wavelength\), got 1 "),
    (lambda: colorimetry.spectral_to_xyz([-1.0, 1.0, 1.0], [400.0, 500.0, 600.0]), r"^radiance must be finite"),
    (lambda: colorimetry.spectral_to_xyz("abc", [400.0, 500.0, 600.0]), r"^radiance must be finite"),
    # numpy's "could not convert string to float", naming nothing
    (lambda: colorimetry.spectral_to_xyz([1.0, 1.0, 1.0], "abc"), r"^wavelengths must be a 1D array"),
    (lambda: colorimetry.three_wavelength_to_xyz([1.0, 1.0, 1.0], "abc"), r"^wavelengths must be 3 distinct"),
    # AttributeErrors
    (lambda: colorimetry.three_wavelength_to_xyz([1.0, 1.0, 1.0], WAVELENGTHS[0], "solar_power_law_tabulated",
                                                 ctx="abc"), r"^ctx must be None \(clsky's device\) or a "),
    (lambda: colorimetry.three_wavelength_to_xyz([1.0, 1.0, 1.0], WAVELENGTHS[0], "solar_interpolation",
                                                 ctx="abc"), r"^ctx must be None"),
    (lambda: __import__("clsky.solar").solar.radiance_units("physical"),
     r"^atmosphere must be an AtmosphereParameters, got 'physical' \(str\)$"),
])
def test_the_conversions_name_what_is_wrong(call, message):
    with pytest.raises(ValueError, match=message):
        call()
