"""Shared fixtures and the per-dtype tolerance table of the clsky tests.

Device choice: ``PYOPENCL_TEST`` (PyOpenCL's test convention, e.g. ``PYOPENCL_TEST=portable``) if set,
else :func:`clsky._cl.make_context` (``PYOPENCL_CTX``, else a GPU, else the fastest PoCL). Engines
compile OpenCL (about 1 s the first time), so they are built once per session and cached by their
compile-time settings.
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import tempfile
import time

import numpy as np
import pyopencl as cl
import pytest

from clsky import TableSettings, preset
from clsky._cl import NoDeviceError, has_fp64, make_context
from clsky.render import RAYMARCH_DEFAULTS
from clsky.single import SingleScatteringEngine
from clsky.transmittance import TransmittanceEngine


# Workers (pytest-xdist) ----------------------------------------------------------------------------

#: Host memory a worker may take at its peak [bytes], for the number of workers ``-n auto`` starts: the
#: largest process of a default-suite run on 2026-12-06 (a worker, or a command a test started) peaked at
#: 3.1 GB resident (``/usr/bin/time -v``); 4 GiB leaves a quarter more.
WORKER_MEMORY = 4 * 2**30


def pytest_xdist_auto_num_workers(config):
    """``-n auto`` (pyproject's addopts): one worker per core this process may use (clsky._cl.host_cores:
    affinity and cgroup quota), no more than the available memory holds at WORKER_MEMORY each, at least 1.
    On a GPU all workers share the device."""
    from clsky._cl import host_cores
    from clsky.resources import host_available_bytes

    cores, available = host_cores(), host_available_bytes()
    return cores if available is None else max(1, min(cores, available // WORKER_MEMORY))


# The CI's time budget --------------------------------------------------------------------------------

#: Environment variable: a Unix time after which no test starts. .ci/run sets it for the slow tests so
#: that CI ends within its limit whatever the machine's speed: a test not started is reported as
#: skipped, its reason naming this variable (``pytest -rs`` lists them). Unset: every test runs.
DEADLINE_VARIABLE = "CLSKY_TEST_DEADLINE"


def _deadline():
    value = os.environ.get(DEADLINE_VARIABLE, "").strip()
    if not value:
        return None
    try:
        return float(value)
    except ValueError:
        raise pytest.UsageError(f"{DEADLINE_VARIABLE} must be a Unix time in seconds, got {value!r}") from None


def pytest_configure(config):
    _deadline()                                  # a malformed value stops the run before any test
    _one_blas_thread()
    if not os.environ.get("CLSKY_CACHE_DIR"):
        # clsky's disk cache (clsky/_cache.py: colour-science's constants) of this session alone, for it
        # and every process it starts: the tests neither depend on what earlier runs left in
        # ~/.cache/clsky nor fill it (PoCL's own cache stays where it is)
        directory = tempfile.mkdtemp(prefix="clsky-test-cache-")
        os.environ["CLSKY_CACHE_DIR"] = directory
        config.add_cleanup(lambda: shutil.rmtree(directory, ignore_errors=True))


def _one_blas_thread():
    """NumPy's and SciPy's BLAS on one thread in this test process (``threadpoolctl``; the commands the
    tests start keep their own). The default suite runs one worker per core and is CPU-bound (about 1100
    CPU-s on two cores): a BLAS call that spreads over two threads only takes the other worker's core,
    and OpenBLAS's threads spin while they wait. The Monte Carlo, orders and twilight tests took 72-76
    CPU-s with BLAS's two threads and 59-60 with one, in the same wall time (-n 0, 2026-12-07). BLAS
    splits a product's rows and columns among its threads, not the sums, so no value changes
    (clsky._cl.host_blas_single_threaded); the tests of clsky's own limit set two threads around them."""
    import importlib

    from threadpoolctl import threadpool_limits

    importlib.import_module("scipy.linalg")      # loads SciPy's BLAS, so that the limit reaches it too

    threadpool_limits(limits=1, user_api="blas")


#: Under a deadline these run first (in this order, the rest after them in their usual order): the
#: independent twilight check against the Monte Carlo tracer and the README's main job, so that a short
#: budget leaves out smoke runs and repeats rather than them.
FIRST_UNDER_A_DEADLINE = ("tests/test_twilight_montecarlo.py", "tests/test_main_job.py")


def pytest_collection_modifyitems(config, items):
    if _deadline() is None:
        return

    def rank(item):
        path = item.nodeid.split("::")[0]
        return FIRST_UNDER_A_DEADLINE.index(path) if path in FIRST_UNDER_A_DEADLINE else len(FIRST_UNDER_A_DEADLINE)

    items.sort(key=rank)                         # stable: the usual order within each rank


def pytest_runtest_setup(item):
    deadline = _deadline()
    if deadline is not None and time.time() > deadline:
        pytest.skip(f"not started: the time budget ran out ({DEADLINE_VARIABLE}="
                    f"{time.strftime('%H:%M:%S', time.localtime(deadline))})")


# Tolerances ---------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class Tolerance:
    """``assert_allclose(actual, desired, rtol=rtol, atol=atol_scale * max|desired|)``."""

    rtol: float
    atol_scale: float

    def atol(self, desired) -> float:
        """Absolute tolerance scaled to the largest magnitude of ``desired``."""
        return self.atol_scale * float(np.max(np.abs(desired), initial=0.0))


#: Kernel against its float64 NumPy twin, per kernel dtype and quantity. float64: the kernels and the
#: twins evaluate the same formulas at the same nodes, so they differ only by summation order and FMA
#: contraction: a few ulps per operation, amplified by exp(-x) with x = h/H up to ~83 (Mie at the top)
#: or tau up to ~30, i.e. <= ~1e-14 relative (measured: 4e-14 worst, column table). float32 kernels are
#: compared with the float64 twin (style.md): the unit roundoff 6e-8 times the same amplification
#: gives ~1e-5; the measured worst cases are in the comments.
TOLERANCES = {
    "float64": {
        "optical_depth": Tolerance(rtol=1e-12, atol_scale=1e-14),
        "column_density_table": Tolerance(rtol=1e-12, atol_scale=1e-14),
        "single_scattering": Tolerance(rtol=1e-12, atol_scale=1e-14),
        "single_scattering_table": Tolerance(rtol=1e-12, atol_scale=1e-14),
        # Gather: a sum of H positive products, same order in both: error <= (H + 2) u = 35 x 1.1e-16
        # = 4e-15 for H = 33. Measured 4.9e-16 relative, everywhere (tests/test_multiple.py, per channel).
        "gather": Tolerance(rtol=1e-12, atol_scale=1e-14),
        # Scatter: the single-scattering formulas plus a trilinear lookup per node; the kernel sums its
        # trapezoid as sum f_i (h_i + h_(i+1)) / 2, the twin as sum (f_(i-1) + f_i) h_i / 2 (a few ulps).
        # Cells far below the channel maximum (sun below the horizon, Mie at 100 km: 1e-40 of it) get
        # interpolation weights that cancel, hence the atol. Measured (atol per channel): 1.2e-13
        # relative above 1e-6 of the channel max, 8e-13 above 1e-8; every cell within the atol alone.
        "scatter": Tolerance(rtol=1e-12, atol_scale=1e-14),
        # compute_orders, OpenCL against backend='numpy', every order: each order inherits the previous
        # order's difference (the orders operator is a contraction, ratio <= 0.3 per order measured) and
        # adds its own 1e-12, so K orders stay below K x 1e-12 on cells above the atol; 1e-10 leaves
        # room for cells between 1e-12 and 1e-8 of the channel max, whose cbrt-mapped trilinear weights
        # amplify rounding (measured 1.6e-10 there, covered by the atol). Measured worst relative error
        # above the atol: 0 (every cell within 1e-14 of the channel max).
        "orders": Tolerance(rtol=1e-10, atol_scale=1e-14),
        # Per-pixel renderers (tests/test_render.py), atol scaled to the largest SKY radiance (the sun
        # disc, ~1e5 times brighter, is excluded from the scale). Same nodes and formulas as the twins;
        # they differ by FMA contraction, summation order and, for render_table, the association of the
        # trilinear weights (host slice at (h, mu_s), then the kernel's v interpolation). Measured over
        # both modes, orders=1, altitudes 0 / 3 km / 150 km, sun zeniths 30 / 89 / 95 deg, random and
        # fisheye directions: every pixel within 7.4e-15 of the sky max (the atol alone), 1.2e-14 relative.
        "render_table": Tolerance(rtol=1e-12, atol_scale=1e-14),
        "render_raymarch": Tolerance(rtol=1e-12, atol_scale=1e-14),
        # render_skyview: a bilinear read of the same map (4 products, 3 sums) after atan2, sqrt and sin
        # of the same direction; the coordinates differ by an ulp or two (FMA), moving the weights by
        # ~1e-15 times the map's row-to-row change. Measured (tests/test_skyview.py): 1.5e-14 relative
        # (from 150 km), 1.2e-15 from the ground.
        "render_skyview": Tolerance(rtol=1e-12, atol_scale=1e-14),
    },
    "float32": {
        # measured 2.2e-6 relative on random segments with tau up to 12: rtol 1e-5 (style.md start).
        "optical_depth": Tolerance(rtol=1e-5, atol_scale=1e-6),
        # Loosened: radii r = Rp + h are quantised to 0.5 m in float32 (ulp of 6.4e6), so nodes near
        # the ground shift by up to ~0.25-0.5 m, i.e. dC_M/C_M ~ 0.5 m / H_M (1200 m) ~ 4e-4 on the
        # tangent rays of the table's horizon row. Measured: 7e-4 relative (altitude 25 m, horizon).
        "column_density_table": Tolerance(rtol=2e-3, atol_scale=1e-6),
        # Marched sun rays: tau up to ~100 (one trapezoid step over 1000 km paths, or 20x Rayleigh near
        # the horizon) times the float32 relative error of tau (~1e-6: radii r = Rp + h rounded to 0.5 m)
        # gives ~1e-4. Measured on the (9, 33, 7) variants: 6.2e-5 (view_steps = sun_steps = 1, dense),
        # < 1e-6 beside the atol for 30 steps. rtol 1e-4, atol 1e-6 x max. NOT met on grids with nodes
        # near the ground and the horizon: see test_single_twin.py::test_near_ground_grid_matches_twin.
        "single_scattering": Tolerance(rtol=1e-4, atol_scale=1e-6),
        # Sun transmittance from the float32 column table inherits its 7e-4 near-horizon error
        # (times tau ~ 0.5-7): measured 1.9e-4 relative beside the atol (sun on the horizon, observer
        # on the ground, view just above the horizon; Keller & Bohn sampling, 5/4 steps). rtol 1e-3.
        "single_scattering_table": Tolerance(rtol=1e-3, atol_scale=1e-6),
        # Gather in float32 against the float64 twin: H = 33 positive products, each input rounded once:
        # error <= (H + 2) u = 35 x 6e-8 = 2.1e-6. Measured 4.6e-7. The atol only covers values that fall
        # below float32's normal range (1.2e-38, i.e. ~1e-36 of the channel max ~1e-2: deep Mie shadow).
        "gather": Tolerance(rtol=2e-6, atol_scale=1e-30),
        # Scatter in float32 against the float64 twin: the single-scattering errors (radii rounded to
        # 0.5 m, exp(-tau) amplification; see single_scattering) plus float32 texture coordinates.
        # Measured (atol per channel): 4.2e-6 relative above 1e-2 of the channel max, 2.7e-5 above 1e-4,
        # 2.7e-4 above 1e-6 (tau ~ 15 rays); with atol 1e-7 x channel max the rtol needed is 2.0e-6.
        # rtol 2e-5 (10x margin), atol 1e-7 x channel max.
        "scatter": Tolerance(rtol=2e-5, atol_scale=1e-7),
        # Renderers in float32 against the float64 twin, on the same table: the worst pixels lie a few
        # degrees from the sun, where the Mie forward peak amplifies the float32 rounding of
        # nu = dot(V, S): d ln F_M / d nu = 3 |g| / (1 + g^2 - 2 |g| nu) = 113 at nu -> 1 (g = -0.85),
        # times <= 3 u = 1.8e-7 for the 3-term dot product, gives 2.0e-5. Measured (atol 1e-6 x sky
        # max): 6.4e-6 relative (sun zenith 89 deg, pixel 2.4 deg from it, both renderers). The atol
        # covers near-black pixels (ground-bound rays, the night side) where exp(-tau) amplifies more.
        "render_table": Tolerance(rtol=2e-5, atol_scale=1e-6),
        "render_raymarch": Tolerance(rtol=2e-5, atol_scale=1e-6),
        # render_skyview, float32 kernel on its own float32 map against the float64 twin on that map:
        # 1.2e-5 relative everywhere but at the horizon (measured). The ground half's row is
        # sqrt((theta - theta_H) / beta) (ground_rows - 1): its derivative diverges at the horizon, so a
        # float32 direction (theta off by ~6e-8 rad) 1e-7 rad below the horizon moves its row by
        # 6e-8 / (2 sqrt(1e-7 beta)) (rows - 1) ~ 8e-4 rows, times a row-to-row change of up to 100 %
        # there: 7.1e-4 measured (3 km); 2e-3 leaves room for other altitudes.
        "render_skyview": Tolerance(rtol=2e-3, atol_scale=1e-6),
    },
}


# A small table and its frames, for comparing two builds of the kernels -----------------------------

#: A small table through every path of the orders (physical mode, azimuth harmonics M = 2), for the
#: tests that compare two builds of the same kernels (tests/test_vector_width.py, test_cube_root.py).
SMALL_TABLE = TableSettings(size=(9, 33, 7), gather_theta_steps=32, gather_phi_steps=16, mode="physical",
                            azimuth_harmonics=2)
#: A short ray march for the same tests.
SMALL_RAY = RAYMARCH_DEFAULTS.replace(view_steps=16, sun_steps=20, transmittance_size=(16, 32))


def build_and_render(atmosphere, settings, sun_zeniths):
    """The table (data and every order) and {"<renderer> <sun zenith>": frame} of every renderer (3D
    lookup, ray march with SMALL_RAY, sky-view map) on a 24 px fisheye from the ground, for each sun
    zenith [deg] in ``sun_zeniths`` (azimuth 150 deg)."""
    from clsky import ScatteringTable
    from clsky.anim.cameras import FisheyeCamera, sun_direction
    from clsky.render import SkyRenderer

    table = ScatteringTable.build(atmosphere, settings)
    renderer = SkyRenderer(table, ray_settings=SMALL_RAY)
    prepared = renderer.prepare(*FisheyeCamera(24).directions())
    frames = {}
    for zenith in sun_zeniths:
        sun = sun_direction(zenith, 150.0)
        frames[f"lookup {zenith:g}"] = renderer.render_table(prepared, sun, 0.0)
        frames[f"raymarch {zenith:g}"] = renderer.render_raymarch(prepared, sun, 0.0)
        frames[f"skyview {zenith:g}"] = renderer.render_skyview(prepared, sun, 0.0)
    return table, frames


def black_preset(name):
    """The preset ``name`` with a black ground (``ground_albedo`` 0).

    The twin, scheme and file tests below were written for the presets' air, haze and ozone, and many
    pair the physical preset with the atmosphere-plus scheme, which refuses a reflecting ground
    (clsky/ground.py). The physical preset's own ground (0.1) is tested where it matters:
    tests/test_ground.py (kernels, twins, Monte Carlo, energy), tests/test_physics_montecarlo.py and the
    command-line and animation tests, which use the real presets.
    """
    return preset(name).replace(ground_albedo=0.0)


def max_error_report(actual, desired, label=""):
    """One line with the largest absolute and relative errors and where they occur (for the log)."""
    actual = np.asarray(actual, dtype=np.float64)
    desired = np.asarray(desired, dtype=np.float64)
    error = np.abs(actual - desired)
    if error.size == 0:
        return f"{label}: empty"
    where_abs = np.unravel_index(np.argmax(error), error.shape)
    nonzero = np.abs(desired) > 0
    relative = np.where(nonzero, error / np.where(nonzero, np.abs(desired), 1.0), 0.0)
    where_rel = np.unravel_index(np.argmax(relative), relative.shape)
    scale = float(np.max(np.abs(desired)))
    return (f"{label}: max abs error {error[where_abs]:.3g} ({error[where_abs] / scale if scale else 0:.3g}"
            f" of max) at {tuple(int(i) for i in where_abs)}; max rel error {relative[where_rel]:.3g} at "
            f"{tuple(int(i) for i in where_rel)} (value {desired[where_rel]:.4g})")


# OpenCL context and engines -----------------------------------------------------------------------

def _test_context():
    if os.environ.get("PYOPENCL_TEST"):
        from pyopencl.tools import get_test_platforms_and_devices

        _, devices = get_test_platforms_and_devices()[0]
        return cl.Context([devices[0]])
    return make_context(np.float32)


@pytest.fixture(scope="session")
def cl_context():
    """One OpenCL context for the whole session (skips the OpenCL tests when there is no device)."""
    try:
        return _test_context()
    except (NoDeviceError, cl.Error) as error:
        pytest.skip(f"no OpenCL device: {error}")


@pytest.fixture(scope="session")
def stand_in_reference(cl_context):
    """The accuracy reference's four 24 x 24 fisheye frames and valid mask (anim/accuracy.py), rendered at
    the 'default' quality level (1 %) as a cheap stand-in for the 'reference' level (minutes to build);
    shared by tests/test_accuracy.py and tests/test_quality.py."""
    from clsky.anim import accuracy

    return accuracy.render_reference(size=24, level="default")


@pytest.fixture(scope="session")
def draft_stand_in_reference(cl_context):
    """The same four frames at the 'draft' level: 8 s to build against the 'default' stand-in's ~170 s
    (its four tables carry the azimuth harmonics, M = 2, since the reference does: measured 2026-12-02
    at load 3). For tests of the sweep's plumbing (which renderer, which columns), not of its numbers;
    those use :func:`stand_in_reference` and are marked slow."""
    from clsky.anim import accuracy

    return accuracy.render_reference(size=24, level="draft")


@pytest.fixture(scope="session")
def fp64_available(cl_context):
    """Whether the session's device supports double precision."""
    return has_fp64(cl_context.devices[0])


def require_dtype(context, dtype):
    """Skip the calling test when ``dtype`` is float64 and the device has no fp64."""
    if np.dtype(dtype) == np.float64 and not has_fp64(context.devices[0]):
        pytest.skip(f"{context.devices[0].name} has no double precision")


@pytest.fixture(params=["float64", "float32"])
def dtype(request, cl_context):
    """Kernel precision; float64 is skipped on devices without cl_khr_fp64."""
    require_dtype(cl_context, request.param)
    return request.param


@pytest.fixture(scope="session")
def single_engine(cl_context):
    """``single_engine(settings)``: a cached SingleScatteringEngine compiled for ``settings``.

    Size and mapping are per-call values (pass them to ``compute``), so they are not part of the key.
    """
    cache = {}

    def get(settings: TableSettings) -> SingleScatteringEngine:
        require_dtype(cl_context, settings.dtype)
        key = settings.replace(size=(2, 2, 2), mapping="nonlinear", mie_layout="per-wavelength")
        if key not in cache:
            cache[key] = SingleScatteringEngine(key, ctx=cl_context)
        return cache[key]

    yield get
    for engine in cache.values():
        engine.close()


@pytest.fixture(scope="session")
def transmittance_engine(cl_context):
    """``transmittance_engine(steps=30, sampling='uniform', dtype='float64')``: a cached engine."""
    cache = {}

    def get(steps=30, sampling="uniform", dtype="float64") -> TransmittanceEngine:
        require_dtype(cl_context, dtype)
        key = (steps, sampling, np.dtype(dtype).name)
        if key not in cache:
            cache[key] = TransmittanceEngine(cl_context, np.dtype(dtype), steps=steps, sampling=sampling)
        return cache[key]

    yield get
    for engine in cache.values():
        engine.close()


def compute_single(engine_factory, atmosphere, settings: TableSettings):
    """The OpenCL single-scattering table of ``settings`` (size and mapping included)."""
    return engine_factory(settings).compute(atmosphere, size=settings.size, mapping=settings.mapping)
