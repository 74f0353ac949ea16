"""The kernels' cube root of the non-linear mapping (kernels/mapping.cl, ``cube_root_unit``) against
NumPy's, and the tables and frames it gives against those of OpenCL's ``cbrt`` (issue 12).

Since 2026-12-03 the kernels take the cube roots of the view and sun coordinates (``MAPPING_V``, one
each per ray node of the scatter and the ray march) from a bit-pattern seed and three Halley steps
instead of OpenCL's ``cbrt``, 2.5x cheaper on PoCL (``clsky._cl.CUBE_ROOT``; "library" keeps
``cbrt``, which the bit-for-bit pins of tests/pins.py use). The reference here is ``numpy.cbrt``
(glibc's; over the arguments below within 0.56 ulp of the exact root, measured against x86's 80-bit
long double), which shares no code with the kernels.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
import pytest

import clsky
from clsky import _cl

from conftest import SMALL_TABLE, build_and_render

DBL_MIN = np.finfo(np.float64).tiny

_TEST_KERNELS = _cl.Source("test kernels (tests/test_cube_root.py)", """
__kernel void halley_in_use(__global int *out)
{
    out[0] = CUBE_ROOT_HALLEY;
}

#if CUBE_ROOT_HALLEY
__kernel void cube_roots(__global const real *x, __global real *scalar, __global real *vector,
                         __global real *mapped)
{
    const int i = get_global_id(0);
    vstore8(cube_root_unit(vload8(i, x)), i, vector);
    for (int k = 8 * i; k < 8 * i + 8; ++k) {
        const real c = x[k];
        scalar[k] = cube_root_unit(c);
        mapped[k] = MAPPING_V(c, 1);
    }
}
#endif
""")


def _program(context):
    return _cl.build_program(context, ("real.cl", "mapping.cl", _TEST_KERNELS), ["-DREAL_IS_DOUBLE=1"])


def halley_in_use(context) -> bool:
    """Whether the device's compiler takes the Halley root (kernels/mapping.cl: clang-based compilers,
    PoCL's and Intel's among them; others take cbrt)."""
    queue = cl.CommandQueue(context)
    out = cla.zeros(queue, 1, np.int32)
    cl.Kernel(_program(context), "halley_in_use")(queue, (1,), None, out.data)
    return bool(out.get()[0])


@pytest.fixture(scope="module")
def cube_roots(cl_context, fp64_available):
    """``run(x)``: (scalar root, double8 root, MAPPING_V) of float64 ``x`` (a multiple of 8 values)."""
    if not fp64_available:
        pytest.skip("the Halley cube root is the float64 kernels'")
    if not halley_in_use(cl_context):
        pytest.skip(f"{cl_context.devices[0].name}'s compiler takes cbrt (kernels/mapping.cl: no clang)")
    kernel = cl.Kernel(_program(cl_context), "cube_roots")
    queue = cl.CommandQueue(cl_context)

    def run(x):
        x_d = cla.to_device(queue, np.ascontiguousarray(x, dtype=np.float64))
        outs = [cla.empty_like(x_d) for _ in range(3)]
        kernel(queue, (x.size // 8,), None, x_d.data, *(out.data for out in outs))
        return tuple(out.get() for out in outs)

    return run


def arguments():
    """2^20 cosines uniform in [-1, 1], 2^18 of random sign log-uniform from DBL_MIN to 1, and the ends."""
    rng = np.random.default_rng(20261203)
    uniform = rng.uniform(-1.0, 1.0, 2**20)
    spread = np.exp(rng.uniform(np.log(DBL_MIN), 0.0, 2**18)) * rng.choice([-1.0, 1.0], 2**18)
    ends = [1.0, -1.0, 0.125, -0.125, 0.5, -0.5, DBL_MIN, -DBL_MIN, np.nextafter(1.0, 0.0), 1e-300]
    return np.concatenate([uniform, spread, ends, np.zeros((-len(ends)) % 8)])


#: NumPy's own cube root is not correctly rounded where it is the C library's: on an AMD EPYC without
#: AVX-512 (glibc's cbrt; with AVX-512 NumPy takes its SIMD routine), 3.16 ulp from the exact root at most
#: over these arguments, and 5 ulp from the kernel's (2026-12-06). Bound on |kernel - NumPy|: the kernel's
#: 3 ulp plus NumPy's, rounded up to 4.
NUMPY_CBRT_ULP = 4.0


def test_cube_root_is_within_3_ulp_of_the_exact_root(cube_roots):
    """Three Halley steps from a seed within 3.3 % cube the error three times (3.3e-2 -> ~1e-5 ->
    ~1e-15 -> rounding): what is left is the last step's rounding, a few ulp. Bound: 3 ulp of the exact
    root (long double's cube root refined by one Newton step, a 64-bit mantissa), as measured over these
    arguments (2^20 + 2^18 values; 2.9 ulp at most); both overloads (double, double8). Against NumPy's
    root too (the only reference where long double is double), within 3 + NUMPY_CBRT_ULP."""
    x = arguments()
    expected = np.cbrt(x)
    ulp = np.spacing(np.abs(expected))
    roots = cube_roots(x)[:2]
    for name, root in zip(("double", "double8"), roots):
        error = np.abs(root - expected) / ulp
        worst = x[np.argmax(error)]
        assert error.max() <= 3.0 + NUMPY_CBRT_ULP, f"{name}: {error.max():.0f} ulp from NumPy's at x = {worst!r}"
    if np.finfo(np.longdouble).nmant < 63:
        return                                 # no extended precision here (long double is double)
    wide = x.astype(np.longdouble)
    exact = np.cbrt(wide)
    exact -= (exact * exact * exact - wide) / (3 * exact * exact + (exact == 0))
    for name, root in zip(("double", "double8"), roots):
        error = np.abs(root.astype(np.longdouble) - exact) / ulp
        worst = x[np.argmax(error)]
        assert error.max() <= 3.0, f"{name}: {float(error.max()):.2f} ulp from the exact root at x = {worst!r}"


def test_cube_root_is_exact_at_the_table_ends_and_keeps_signs(cube_roots):
    """The mapping's ends must map exactly: v(1) = 1 and v(-1) = 0 are the table's first and last
    nodes (and 1/8, whose root 1/2 is a binary number); zero gives zero with its sign."""
    x = np.array([1.0, -1.0, 0.125, -0.125, 0.0, -0.0, 1.0, -1.0])
    for root in cube_roots(x)[:2]:
        np.testing.assert_array_equal(root, [1.0, -1.0, 0.5, -0.5, 0.0, -0.0, 1.0, -1.0])
        np.testing.assert_array_equal(np.signbit(root), np.signbit(x))
    np.testing.assert_array_equal(cube_roots(x)[2], [1.0, 0.0, 0.75, 0.25, 0.5, 0.5, 1.0, 0.0])


def test_subnormal_arguments_map_to_the_middle(cube_roots):
    """Subnormal x is outside the 3-ulp promise (the seed's bit trick assumes a normal number): the
    root must still be finite, of x's sign and below 3e-103 (kernels/mapping.cl; the exact roots are
    below 2.82e-103), so that MAPPING_V gives exactly 0.5, as for the exact roots (far under 2^-54)."""
    rng = np.random.default_rng(7)
    x = np.exp(rng.uniform(np.log(5e-324), np.log(DBL_MIN), 4096)) * rng.choice([-1.0, 1.0], 4096)
    x[:2] = 5e-324, -5e-324
    scalar, vector, mapped = cube_roots(x)
    for root in (scalar, vector):
        assert np.isfinite(root).all()
        np.testing.assert_array_equal(np.signbit(root), np.signbit(x))
        assert np.abs(root).max() < 3e-103
    np.testing.assert_array_equal(mapped, 0.5)


def _table_and_frames(atmosphere, cube_root, monkeypatch):
    """{name: array} of SMALL_TABLE's data and gathered harmonics and of every renderer's frames by day
    and at dusk, with the kernels' cube root ``cube_root``."""
    monkeypatch.setattr(_cl, "CUBE_ROOT", cube_root)
    table, frames = build_and_render(atmosphere, SMALL_TABLE, [60.0, 93.0])
    return {"table": table.data, "gathered": table.gathered, **frames}


def test_tables_and_frames_match_those_of_cbrt(monkeypatch, fp64_available):
    """A table with the azimuth harmonics, ozone and a ground, and its ray-marched, looked-up and
    sky-view frames by day and at dusk, with the Halley root against ``cbrt``.

    Tolerance, 1e-13 of each quantity's maximum: a root off by 3 ulp (3.3e-16 for |root| <= 1) moves
    v = (1 + root) / 2 by at most 3e-16 with its rounding, a node's coordinate v (H - 1) by 1e-14
    (H = 33), and so each trilinear weight by 1e-14: a lookup moves by at most 1e-14 of the table's
    largest value, and a table sums a few such lookups per order. (Measured: below 1e-15.) That some
    values do change shows that the Halley root is the one in use (where the compiler takes it)."""
    if not fp64_available:
        pytest.skip("the Halley cube root is the float64 kernels'")
    atmosphere = clsky.preset("physical").replace(ground_albedo=0.3)
    halley = _table_and_frames(atmosphere, "halley", monkeypatch)
    library = _table_and_frames(atmosphere, "library", monkeypatch)
    changed = 0
    for key, value in halley.items():
        reference = library[key]
        assert np.isfinite(value).all(), key
        if key != "gathered":                                  # the harmonics m > 0 may be negative
            assert (value >= 0).all(), key
        scale = np.abs(reference).max()
        assert scale > 0, key
        error = np.abs(value - reference).max() / scale
        assert error <= 1e-13, f"{key}: Halley and cbrt differ by {error:.1e} of the maximum"
        changed += int(np.count_nonzero(value != reference))
    if halley_in_use(_cl.make_context()):
        assert changed > 0, "no value changed: the kernels did not take the Halley cube root"


def test_an_unknown_cube_root_is_refused(monkeypatch):
    monkeypatch.setattr(_cl, "CUBE_ROOT", "newton")
    with pytest.raises(ValueError, match=r"clsky._cl.CUBE_ROOT must be one of \('halley', 'library'\), "
                                         r"got 'newton'"):
        clsky.ScatteringTable.build(clsky.preset("physical"),
                                    clsky.TableSettings(size=(4, 8, 4), orders=1, mode="physical"))
