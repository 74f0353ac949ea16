"""Analytic checks of the transmittance, single-scattering, phase and mapping code.

Every expectation here comes from a closed form (or scipy.integrate.quad) written in this file, never
from clsky's kernels or NumPy twins, and every case runs against both backends: the OpenCL engines
(and small test kernels built from the ``.cl`` helpers) and the NumPy twins (clsky.reference,
clsky.phase, clsky.mapping). Each tolerance is justified next to it.
"""

from __future__ import annotations

import math

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
import pytest
from numpy.testing import assert_allclose
from scipy import integrate

from clsky import TableSettings
from clsky import _atmosphere_cl, _cl, reference
from clsky.phase import mie_phase, rayleigh_phase
from clsky import mapping as np_mapping
from clsky.settings import MAPPINGS

from conftest import black_preset, compute_single, max_error_report

EPS = np.finfo(np.float64).eps
DEFAULT = black_preset("atmosphere-plus")
RP, RA = DEFAULT.planet_radius, DEFAULT.top_radius
HA = RA - RP


# Backends ------------------------------------------------------------------------------------------

class NumPyBackend:
    """The NumPy twins (clsky.reference, clsky.phase, clsky.mapping)."""

    name = "numpy"

    def optical_depth(self, atmosphere, altitude, cos_zenith, length, steps=30, sampling="uniform"):
        return reference.optical_depth(atmosphere, altitude, cos_zenith, length, steps, sampling)

    def single_scattering(self, atmosphere, settings):
        return reference.single_scattering(atmosphere, settings)

    def phase(self, atmosphere, c):
        """(Rayleigh, Mie) phase values at cosines c."""
        return rayleigh_phase(atmosphere, c), mie_phase(atmosphere, c)

    def mapping(self, t, mapping, atmosphere_height):
        """(altitude(t), cos(t), u(altitude(t)), v(cos(t))) for texture coordinates t."""
        altitude = np_mapping.u_to_altitude(t, atmosphere_height, mapping)
        cosine = np_mapping.v_to_cos(t, mapping)
        return (altitude, cosine, np_mapping.altitude_to_u(altitude, atmosphere_height, mapping),
                np_mapping.cos_to_v(cosine, mapping))


#: Tiny test kernels around the device helpers of phase.cl and mapping.cl (style.md: test device
#: helpers on their own, with the .cl files as the program's preamble).
_TEST_KERNELS = _cl.Source("test kernels (tests/test_analytic.py)", """
__kernel void phase_values(__constant const atmosphere_t *atm, const int n, __global const real *c,
                           __global real *out)
{
    const int i = get_global_id(0);
    if (i >= n)
        return;
    out[2 * i] = phase_rayleigh(atm, c[i]);
    out[2 * i + 1] = phase_mie(atm, c[i]);
}

__kernel void mapping_values(const int mapping, const real ha, const int n, __global const real *t,
                             __global real *out)
{
    const int i = get_global_id(0);
    if (i >= n)
        return;
    const real ti = t[i];
    const real altitude = MAPPING_ALTITUDE(ti, mapping, ha);
    const real cosine = MAPPING_COS(ti, mapping);
    out[4 * i] = altitude;
    out[4 * i + 1] = cosine;
    out[4 * i + 2] = MAPPING_U(altitude, mapping, ha);
    out[4 * i + 3] = MAPPING_V(cosine, mapping);
}
""")


class OpenCLBackend:
    """The OpenCL engines (float64), plus the phase.cl/mapping.cl helpers through small test kernels."""

    name = "opencl"

    def __init__(self, context, single_engine, transmittance_engine):
        self.context = context
        self.queue = cl.CommandQueue(context)
        self._single_engine = single_engine
        self._transmittance_engine = transmittance_engine
        declaration = _atmosphere_cl.declaration(context.devices[0], np.float64)
        program = _cl.build_program(context, ("real.cl", declaration, "phase.cl", "mapping.cl", _TEST_KERNELS),
                                    ["-DREAL_IS_DOUBLE=1"])
        self.kernels = {k.function_name: k for k in program.all_kernels()}

    def optical_depth(self, atmosphere, altitude, cos_zenith, length, steps=30, sampling="uniform"):
        engine = self._transmittance_engine(steps, sampling)
        return engine.optical_depth(atmosphere, altitude, cos_zenith, length)

    def single_scattering(self, atmosphere, settings):
        return compute_single(self._single_engine, atmosphere, settings)

    def phase(self, atmosphere, c):
        c = np.asarray(c, dtype=np.float64)
        flat = np.atleast_1d(c).ravel()
        c_d = cla.to_device(self.queue, flat)
        out_d = cla.empty(self.queue, (flat.size, 2), np.float64)
        atmosphere_d = _atmosphere_cl.to_device(self.queue, atmosphere, np.float64)
        self.kernels["phase_values"](self.queue, (flat.size,), None, atmosphere_d, np.int32(flat.size),
                                     c_d.data, out_d.data)
        out = out_d.get()
        return out[:, 0].reshape(c.shape), out[:, 1].reshape(c.shape)

    def mapping(self, t, mapping, atmosphere_height):
        t = np.ascontiguousarray(t, dtype=np.float64)
        t_d = cla.to_device(self.queue, t.ravel())
        out_d = cla.empty(self.queue, (t.size, 4), np.float64)
        self.kernels["mapping_values"](self.queue, (t.size,), None, np.int32(MAPPINGS[mapping]),
                                       np.float64(atmosphere_height), np.int32(t.size), t_d.data, out_d.data)
        return tuple(column.reshape(t.shape) for column in out_d.get().T)


@pytest.fixture(scope="module")
def opencl_backend(cl_context, single_engine, transmittance_engine, fp64_available):
    if not fp64_available:
        pytest.skip("the analytic checks run in float64")
    return OpenCLBackend(cl_context, single_engine, transmittance_engine)


@pytest.fixture(params=["opencl", "numpy"])
def backend(request):
    """Each analytic check runs on the OpenCL engines and on the NumPy twins."""
    if request.param == "numpy":
        return NumPyBackend()
    return request.getfixturevalue("opencl_backend")


# Independent closed forms -------------------------------------------------------------------------

def exponential_column(height, scale_height):
    """Integral_0^height exp(-h / H) dh = H (1 - exp(-height / H)) [m]."""
    return scale_height * -math.expm1(-height / scale_height)


def uniform_trapezoid_of_exponential(height, scale_height, steps):
    """The composite trapezoid value of Integral_0^height exp(-h/H) dh with `steps` equal panels.

    With q = exp(-dh/H): dh [(1 + q)/2] (1 - q^n)/(1 - q) = exact * x coth(x), x = dh / (2 H). Exact
    algebra, so it predicts the kernels' uniform-sampling result to rounding.
    """
    x = height / steps / (2.0 * scale_height)
    return exponential_column(height, scale_height) * x / math.tanh(x)


def trapezoid_on_nodes(nodes, scale_height):
    """Trapezoid sum of exp(-s/H) on the given nodes (for Keller & Bohn's non-uniform nodes)."""
    f = np.exp(-nodes / scale_height)
    return float(np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(nodes)))


def trapezoid_error_bound(nodes, scale_height):
    """Bound on |trapezoid - integral| of exp(-s/H) over panels [s_{j-1}, s_j].

    Panel error is h_j^3 / 12 f''(xi_j); f'' = exp(-s/H)/H^2 is decreasing, so f''(xi_j) <= f''(s_{j-1}).
    For equal panels this sums to <= h^2/(12 H) (1 + h/H) (left Riemann sum <= H + h), much tighter than
    the textbook L h^2/12 max|f''| = L h^2 / (12 H^2) (which would allow 100 km / H = 12x-83x more).
    """
    h = np.diff(nodes)
    return float(np.sum(h**3 / 12.0 * np.exp(-nodes[:-1] / scale_height) / scale_height**2))


def vertical_optical_depth(atmosphere, height_of_column):
    """tau straight up from the ground: beta_R H_R (1 - e^{-Ha/H_R}) + beta_M^e H_M (1 - e^{-Ha/H_M})."""
    return (np.array(atmosphere.rayleigh_scattering)
            * exponential_column(height_of_column, atmosphere.rayleigh_scale_height)
            + atmosphere.mie_extinction * exponential_column(height_of_column, atmosphere.mie_scale_height))


def path_length(r, mu, planet_radius, top_radius):
    """Distance [m] from radius r along direction cosine mu to the ground (if hit) or to the top.

    Roots of |r z + s V|^2 = R^2: s = -r mu -+ sqrt(r^2 mu^2 - (r^2 - R^2)); the ray hits the ground when
    mu < 0 and the discriminant for Rp is >= 0. Conjugate forms avoid cancellation.
    """
    r, mu = np.broadcast_arrays(np.asarray(r, dtype=np.float64), np.asarray(mu, dtype=np.float64))
    above_ground = (r - planet_radius) * (r + planet_radius)
    discriminant_ground = (r * mu) ** 2 - above_ground
    hits_ground = (mu < 0) & (discriminant_ground >= 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        ground = np.where(above_ground > 0,
                          above_ground / (-r * mu + np.sqrt(np.maximum(discriminant_ground, 0.0))), 0.0)
        below_top = (top_radius - r) * (top_radius + r)
        root = np.sqrt((r * mu) ** 2 + below_top)
        top = np.where(mu > 0, below_top / (r * mu + root), root - r * mu)
    return np.where(hits_ground, ground, top)


def grid_axes(size, atmosphere_height, mapping="nonlinear"):
    """Node values of physics.md's table grid, written out: (u, v, w) = (x, y, z) / (size - 1),
    h = u^2 Ha (or u Ha), cos = (2 v - 1)^3 (or 2 v - 1)."""
    width, height, depth = size
    u = np.arange(width) / (width - 1)
    v = np.arange(height) / (height - 1)
    w = np.arange(depth) / (depth - 1)
    if mapping == "nonlinear":
        return u**2 * atmosphere_height, (2 * v - 1) ** 3, (2 * w - 1) ** 3
    return u * atmosphere_height, 2 * v - 1, 2 * w - 1


# Optical depth ------------------------------------------------------------------------------------

def test_vertical_optical_depth_converges_to_the_closed_form(backend):
    steps = 2000
    tau = backend.optical_depth(DEFAULT, 0.0, 1.0, HA, steps=steps)
    expected = vertical_optical_depth(DEFAULT, HA)
    nodes = np.linspace(0.0, HA, steps + 1)
    # Trapezoid error bound (see trapezoid_error_bound): dh = 50 m gives h^2/(12H)(1+h/H) = 0.026 m of
    # Rayleigh column and 0.181 m of Mie column, i.e. <= 5.7e-7 of tau (1.0e-5 relative); rounding of
    # 2000 terms adds <= 2000 * 2 eps * tau ~ 5e-14.
    bound = (np.array(DEFAULT.rayleigh_scattering) * trapezoid_error_bound(nodes, DEFAULT.rayleigh_scale_height)
             + DEFAULT.mie_extinction * trapezoid_error_bound(nodes, DEFAULT.mie_scale_height))
    print(max_error_report(tau, expected, f"{backend.name} vertical tau, {steps} steps"), "bound", bound)
    assert np.all(np.abs(tau - expected) <= bound + 4000 * EPS * expected)
    assert_allclose(tau, expected, rtol=1.1e-5, atol=0)   # = bound / tau, rounded up


@pytest.mark.parametrize("steps", [30, 2000])
def test_vertical_optical_depth_equals_the_exact_trapezoid_sum(backend, steps):
    """Uniform nodes: the trapezoid of an exponential has the closed form exact * x coth x."""
    tau = backend.optical_depth(DEFAULT, 0.0, 1.0, HA, steps=steps)
    expected = (np.array(DEFAULT.rayleigh_scattering)
                * uniform_trapezoid_of_exponential(HA, DEFAULT.rayleigh_scale_height, steps)
                + DEFAULT.mie_extinction * uniform_trapezoid_of_exponential(HA, DEFAULT.mie_scale_height, steps))
    print(max_error_report(tau, expected, f"{backend.name} vertical tau vs x coth x, {steps} steps"))
    # Same sum, different order: a rounding per term, <= steps * 2 eps relative; plus exp(-h/H) with
    # h/H <= 83 (Mie at the top): 83 eps. 1e-12 covers both with margin.
    assert_allclose(tau, expected, rtol=1e-12, atol=0)


def test_default_30_steps_error_is_within_the_trapezoid_bound(backend):
    """The default 30 uniform steps over 100 km (dh = 3.3 km > H_M = 1.2 km) over-estimate the column.

    Rayleigh: x coth x - 1 = 1.4% (x = dh / 2 H_R = 0.21); Mie: 57% (x = 1.39); tau (red): +4.1%. All
    within h^2/(12H)(1 + h/H) (164 m of Rayleigh column, 2.9 km of Mie column).
    """
    nodes = np.linspace(0.0, HA, 31)
    tau = backend.optical_depth(DEFAULT, 0.0, 1.0, HA, steps=30)
    expected = vertical_optical_depth(DEFAULT, HA)
    bound = (np.array(DEFAULT.rayleigh_scattering) * trapezoid_error_bound(nodes, DEFAULT.rayleigh_scale_height)
             + DEFAULT.mie_extinction * trapezoid_error_bound(nodes, DEFAULT.mie_scale_height))
    print(max_error_report(tau, expected, f"{backend.name} vertical tau, 30 steps"), "bound", bound,
          "relative error", tau / expected - 1)
    assert np.all(tau > expected)                        # f'' > 0: the trapezoid over-estimates
    assert np.all(tau - expected <= bound)
    # the Mie column alone: 57% too large, as the closed form of the trapezoid says
    mie_only = DEFAULT.replace(rayleigh_scattering=(0.0, 0.0, 0.0))
    mie_tau = backend.optical_depth(mie_only, 0.0, 1.0, HA, steps=30)
    x = HA / 30 / (2 * DEFAULT.mie_scale_height)
    assert_allclose(mie_tau / (DEFAULT.mie_extinction * exponential_column(HA, DEFAULT.mie_scale_height)),
                    x / math.tanh(x), rtol=1e-12, atol=0)   # same sum, rounding only


@pytest.mark.parametrize("steps", [30, 2000])
def test_keller_bohn_vertical_optical_depth(backend, steps):
    """Nodes s_j = Ha (j/n)^2: my own trapezoid sum on those nodes, and its error bound vs the integral."""
    tau = backend.optical_depth(DEFAULT, 0.0, 1.0, HA, steps=steps, sampling="keller_bohn")
    nodes = HA * (np.arange(steps + 1) / steps) ** 2
    beta = np.array(DEFAULT.rayleigh_scattering)
    by_nodes = (beta * trapezoid_on_nodes(nodes, DEFAULT.rayleigh_scale_height)
                + DEFAULT.mie_extinction * trapezoid_on_nodes(nodes, DEFAULT.mie_scale_height))
    # same nodes, same sum: rounding only (see the uniform case)
    assert_allclose(tau, by_nodes, rtol=1e-12, atol=0)
    exact = vertical_optical_depth(DEFAULT, HA)
    bound = (beta * trapezoid_error_bound(nodes, DEFAULT.rayleigh_scale_height)
             + DEFAULT.mie_extinction * trapezoid_error_bound(nodes, DEFAULT.mie_scale_height))
    print(max_error_report(tau, exact, f"{backend.name} Keller-Bohn vertical tau, {steps} steps"), "bound", bound)
    assert np.all(np.abs(tau - exact) <= bound + 4000 * EPS * exact)


# A uniform-density atmosphere ---------------------------------------------------------------------

#: Scale heights of 1e15 m: rho = exp(-h/H) = 1 - h/H >= 1 - 2e-10 for h <= 200 km.
UNIFORM = DEFAULT.replace(rayleigh_scale_height=1e15, mie_scale_height=1e15)


@pytest.mark.parametrize("sampling", ["uniform", "keller_bohn"])
@pytest.mark.parametrize("altitude, cos_zenith, length", [
    (0.0, 0.0, 100_000.0),            # horizontal along the ground
    (10_000.0, 0.0, 300_000.0),       # horizontal at 10 km (rises to ~17 km)
    (0.0, 0.5, 150_000.0),            # slanted up
    (50_000.0, -0.3, 100_000.0),      # slanted down (ground is 166 km away)
    (30_000.0, 1.0, 70_000.0),        # straight up to the top
    (90_000.0, -1.0, 90_000.0),       # straight down to the ground
])
def test_uniform_atmosphere_transmittance_is_beer_lambert(backend, sampling, altitude, cos_zenith, length):
    tau = backend.optical_depth(UNIFORM, altitude, cos_zenith, length, sampling=sampling)
    beta_extinction = np.array(UNIFORM.rayleigh_scattering) + UNIFORM.mie_extinction
    expected = beta_extinction * length
    # Density deficit <= max altitude / H <= 2e-10 (relative, one-sided); the trapezoid integrates a
    # constant exactly; rounding ~30 eps. rtol 1e-9.
    assert_allclose(tau, expected, rtol=1e-9, atol=0)
    assert_allclose(np.exp(-tau), np.exp(-expected), rtol=1e-9 * expected.max(), atol=0)   # dT/T = d tau


def test_uniform_atmosphere_vectorised_segments(backend):
    """Many segments at once (broadcasting altitude against lengths)."""
    altitude = np.array([0.0, 20_000.0, 60_000.0])[:, None]
    length = np.array([0.0, 1.0, 1_000.0, 250_000.0])[None, :]
    tau = backend.optical_depth(UNIFORM, altitude, 0.2, length)
    assert tau.shape == (3, 4, 3)
    expected = (np.array(UNIFORM.rayleigh_scattering) + UNIFORM.mie_extinction) * length[..., None]
    assert_allclose(tau, np.broadcast_to(expected, tau.shape), rtol=1e-9, atol=0)   # as above
    assert np.all(tau[:, 0] == 0.0)


# Phase functions ----------------------------------------------------------------------------------

def sphere_mean(function, peak=None, width=None):
    """0.5 Integral_{-1}^{1} F(c) dc by scipy quad, with break points around a narrow peak."""
    points = None
    if peak is not None:
        side = -1.0 if peak > 0 else 1.0
        points = sorted(p for k in (0.5, 1, 2, 5, 10, 30, 100)
                        if -1.0 < (p := peak + side * k * width) < 1.0)
    value, error = integrate.quad(lambda c: float(function(c)), -1.0, 1.0, points=points, limit=500,
                                  epsabs=0.0, epsrel=1e-12)
    return 0.5 * value, 0.5 * error


@pytest.mark.parametrize("name, expected", [("rayleigh", 1.0), ("modified_atmosphereplus", 0.8 * (1.4 + 1 / 6))])
def test_rayleigh_phase_means_over_the_sphere(backend, name, expected):
    atmosphere = DEFAULT.replace(rayleigh_phase=name)
    mean, error = sphere_mean(lambda c: backend.phase(atmosphere, c)[0])
    # polynomial of degree 2: Gauss-Kronrod is exact, so only rounding remains (~1e-16)
    assert_allclose(mean, expected, rtol=1e-14, atol=0)
    if name == "modified_atmosphereplus":
        assert_allclose(mean, 1.2533, rtol=0, atol=5e-5)     # the figure printed in physics.md (4 decimals)


@pytest.mark.parametrize("g", [-0.999, -0.99, -0.95, -0.85, -0.5, 0.0, 0.5, 0.85, 0.95, 0.999])
def test_cornette_shanks_mean_over_the_sphere_is_one(backend, g):
    atmosphere = DEFAULT.replace(mie_g=g)
    width = 1.0 - abs(g)
    mean, error = sphere_mean(lambda c: backend.phase(atmosphere, c)[1], peak=-math.copysign(1.0, g) if g else None,
                              width=width)
    # quad's own error estimate (<= 1e-12) plus the conditioning of the function's evaluation: near the
    # peak 1 + g^2 + 2gc = (1 - |g|)^2 is formed from terms of size ~2, so it carries ~2 eps / (1-|g|)^2
    # relative error, x 1.5 for the power: 1.3e-9 at |g| = 0.999 (measured 5.5e-11), 6e-16 at g = 0.
    rtol = 1e-12 + 3 * EPS * (1 + g * g) / width**2
    print(f"{backend.name} g={g}: mean - 1 = {mean - 1:.3g}, quad error {error:.2g}, rtol {rtol:.2g}")
    assert_allclose(mean, 1.0, rtol=rtol, atol=0)


def test_phase_values_match_the_formulas(backend):
    c = np.linspace(-1.0, 1.0, 201)
    for name, formula in (("rayleigh", 0.75 * (1 + c**2)), ("modified_atmosphereplus", 0.8 * (1.4 + 0.5 * c**2))):
        rayleigh, _ = backend.phase(DEFAULT.replace(rayleigh_phase=name), c)
        assert_allclose(rayleigh, formula, rtol=4 * EPS, atol=0)    # 3-4 roundings
    g = 0.85     # textbook sign: (1 + g^2 - 2 g c) with g = +0.85 equals the notes' g = -0.85
    textbook = 1.5 * (1 - g * g) / (2 + g * g) * (1 + c**2) / (1 + g * g - 2 * g * c) ** 1.5
    _, mie = backend.phase(DEFAULT, c)
    # conditioning near c = 1 as in the mean test: 2 eps / (1 - g)^2 x 1.5 = 3e-14
    assert_allclose(mie, textbook, rtol=1e-13, atol=0)


def test_mie_forward_lobe_points_at_the_sun(backend):
    """g = -0.85 (notes' convention): the maximum over c in [-1, 1] is at c = 1 (looking at the sun)."""
    c = np.linspace(-1.0, 1.0, 20_001)
    _, mie = backend.phase(DEFAULT, c)
    assert DEFAULT.mie_g == -0.85
    assert np.argmax(mie) == c.size - 1
    assert np.all(mie[:-1] < mie[-1])       # a strict, unique maximum
    g = DEFAULT.mie_g
    ratio = mie[-1] / mie[0]
    # F(1)/F(-1) = ((1 + g^2 - 2g)/(1 + g^2 + 2g))^(3/2) = ((1 - g)/(1 + g))^3 = (1.85/0.15)^3 = 1876
    assert_allclose(ratio, ((1 - g) / (1 + g)) ** 3, rtol=1e-13, atol=0)   # conditioning, as above
    assert ratio > 1000
    assert_allclose(mie[-1], 3 * (1 - g * g) / (2 + g * g) / (1 + g) ** 3, rtol=1e-13, atol=0)


# Mapping ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("mapping", ["nonlinear", "linear"])
def test_mapping_round_trips_and_node_values(backend, mapping):
    size = (32, 256, 32)
    width, height, depth = size
    altitude_nodes, cos_view_nodes, cos_sun_nodes = grid_axes(size, HA, mapping)
    for count, cos_nodes in ((height, cos_view_nodes), (depth, cos_sun_nodes)):
        t = np.arange(count) / (count - 1)
        altitude, cosine, u_back, v_back = backend.mapping(t, mapping, HA)
        # Round trips: each direction costs a few ulps of 1 (cube, cube root, sqrt: < 1e-15); 1e-12
        # leaves room for device libm (OpenCL allows cbrt/sqrt a few ulps) and never hides a wrong branch.
        print(max_error_report(v_back, t, f"{backend.name} {mapping} v -> cos -> v"))
        assert_allclose(v_back, t, rtol=0, atol=1e-12)
        # Node values against physics.md's formulas, written out (2-3 roundings of numbers <= 1).
        assert_allclose(cosine, cos_nodes, rtol=0, atol=4 * EPS)
        assert cosine[0] == -1.0 and cosine[-1] == 1.0          # exact end nodes (cos view = 1 at y = H - 1)
        if count % 2:
            assert cosine[count // 2] == 0.0
    t = np.arange(width) / (width - 1)
    altitude, _, u_back, _ = backend.mapping(t, mapping, HA)
    print(max_error_report(u_back, t, f"{backend.name} {mapping} u -> h -> u"))
    assert_allclose(u_back, t, rtol=0, atol=1e-12)
    assert_allclose(altitude, altitude_nodes, rtol=4 * EPS, atol=0)
    assert altitude[0] == 0.0 and altitude[-1] == HA
    # the forward maps written as in physics.md: u = sqrt(h/Ha), v = 0.5 (1 + sign(c) |c|^(1/3))
    if mapping == "nonlinear":
        c = cos_view_nodes
        assert_allclose(np.sqrt(altitude_nodes / HA), t, rtol=0, atol=1e-15)
        assert_allclose(0.5 * (1 + np.sign(c) * np.abs(c) ** (1 / 3)), np.arange(height) / (height - 1),
                        rtol=0, atol=1e-14)    # pow(x, 1/3) with 1/3 rounded: |ln x| eps ~ 1e-15


def test_reference_grid_coordinates_match_physics_md():
    for mapping in ("nonlinear", "linear"):
        expected = grid_axes((32, 256, 32), HA, mapping)
        for actual, desired in zip(np_mapping.grid_coordinates((32, 256, 32), HA, mapping), expected):
            assert_allclose(actual, desired, rtol=4 * EPS, atol=4 * EPS)   # a few roundings


# Planet shadow -------------------------------------------------------------------------------------

def shadow_classes(size, atmosphere, mapping, margin=10.0):
    """Cells (D, H, W) whose whole view ray is in the planet's shadow, and cells whose observer is lit.

    Canonical frame (x, z): observer Pa = (0, r0), V = (sin phi, cos phi), Sun = (sin delta, cos delta).
    The shadow {Sun.P < 0 and |P - (Sun.P) Sun| < Rp} is convex (half-space and cylinder), so the segment
    [Pa, Pb] is wholly in it iff both ends are. ``margin`` [m] keeps cells off the boundary.
    """
    rp, ra = atmosphere.planet_radius, atmosphere.top_radius
    h, mu_v, mu_s = np.meshgrid(*grid_axes(size, atmosphere.atmosphere_height, mapping), indexing="ij")
    h, mu_v, mu_s = (a.transpose(2, 1, 0) for a in (h, mu_v, mu_s))          # (D, H, W)
    r0 = rp + h
    length = path_length(r0, mu_v, rp, ra)
    sun = np.stack([np.sqrt(1 - mu_s**2), mu_s], axis=-1)
    view = np.stack([np.sqrt(1 - mu_v**2), mu_v], axis=-1)
    pa = np.stack([np.zeros_like(r0), r0], axis=-1)
    pb = pa + length[..., None] * view

    def depth_in_shadow(p):
        along = np.sum(p * sun, axis=-1)
        across = np.linalg.norm(p - along[..., None] * sun, axis=-1)
        return np.minimum(-along, rp - across)      # > 0 inside the shadow, < 0 outside

    in_shadow = (depth_in_shadow(pa) > margin) & (depth_in_shadow(pb) > margin)
    lit_observer = (depth_in_shadow(pa) < -margin) & (length > margin)
    return in_shadow, lit_observer


@pytest.mark.parametrize("mapping", ["nonlinear", "linear"])
@pytest.mark.parametrize("sun_transmittance", ["march", "table"])
def test_cells_in_the_planet_shadow_are_exactly_zero(backend, mapping, sun_transmittance):
    size = (9, 33, 17)
    settings = TableSettings(size=size, mapping=mapping, sun_transmittance=sun_transmittance)
    table = backend.single_scattering(DEFAULT, settings)
    in_shadow, lit_observer = shadow_classes(size, DEFAULT, mapping)
    print(f"{backend.name} {mapping} {sun_transmittance}: {in_shadow.sum()} cells in shadow, "
          f"{lit_observer.sum()} with a lit observer, of {in_shadow.size}")
    assert in_shadow.sum() > 500 and lit_observer.sum() > 2000     # both classes well represented
    # The sun at the nadir (cos delta = -1, the table's z = 0 layer): every cell in the shadow.
    assert np.all(in_shadow[0])
    assert np.all(table[0] == 0.0)
    # Shadow: no node is lit, so nothing is added: exactly 0, no tolerance.
    assert np.all(table[in_shadow] == 0.0)
    # A lit observer with a path of non-zero length gets a positive contribution from node 0.
    assert np.all(table[lit_observer] > 0.0)
    assert np.all(np.isfinite(table)) and np.all(table >= 0.0)


# Single scattering of an optically thin, uniform atmosphere ---------------------------------------

#: Uniform density (H = 1e15 m) and tiny coefficients, different per channel to catch mix-ups.
THIN = DEFAULT.replace(rayleigh_scale_height=1e15, mie_scale_height=1e15,
                       rayleigh_scattering=(1e-13, 2e-13, 3e-13), mie_scattering=1e-13)
#: Longest view or sun path in the atmosphere: a chord tangent to the ground, 2 sqrt(Ra^2 - Rp^2).
LONGEST_PATH = 2.0 * math.sqrt((RA - RP) * (RA + RP))
#: T = exp(-tau) >= 1 - tau with tau <= (max beta_R + beta_M^e) (view + sun path) = 1.9e-6; the density
#: deficit h/H <= 1e-10; the trapezoid integrates the near-constant integrand exactly.
THIN_RTOL = (max(THIN.rayleigh_scattering) + THIN.mie_extinction) * 2 * LONGEST_PATH + 1e-10


def thin_layer_expectation(atmosphere, length):
    """Ibar^(1) for T = 1, rho = 1: beta_s / (4 pi) * path length; channels R r, g, b, M r, g, b."""
    beta = np.concatenate([atmosphere.rayleigh_scattering, [atmosphere.mie_scattering] * 3])
    return beta / (4 * math.pi) * np.asarray(length)[..., None]


@pytest.mark.parametrize("settings", [TableSettings(size=(9, 65, 9)),
                                      TableSettings(size=(9, 65, 9), sampling="keller_bohn",
                                                    sun_transmittance="table")],
                         ids=["uniform-march", "keller_bohn-table"])
def test_thin_layer_looking_straight_up_from_the_ground(backend, settings):
    table = backend.single_scattering(THIN, settings)
    _, cos_view, cos_sun = grid_axes(settings.size, HA)
    assert cos_view[-1] == 1.0
    daylight = cos_sun >= 0
    assert daylight.sum() == 5
    up_from_ground = table[daylight, -1, 0]                  # z with the sun up, y = H - 1, x = 0
    expected = thin_layer_expectation(THIN, np.full(daylight.sum(), RA - RP))
    print(max_error_report(up_from_ground, expected, f"{backend.name} thin layer, zenith view"), "rtol", THIN_RTOL)
    # the vertical path crosses the whole atmosphere: tau <= (beta_R + beta_M^e) (Ha + sun path)
    assert_allclose(up_from_ground, expected, rtol=THIN_RTOL, atol=0)
    assert np.all(up_from_ground <= expected * (1 + 1e-12))     # rho T <= 1: never above the closed form


@pytest.mark.parametrize("mapping", ["nonlinear", "linear"])
def test_thin_layer_every_daylight_cell(backend, mapping):
    """With the sun above the horizon every point of every view ray is lit (the ray stays within 2300 km
    of the observer, far from the night side): Ibar = beta / (4 pi) * path length to the top or ground."""
    settings = TableSettings(size=(9, 65, 9), mapping=mapping)
    table = backend.single_scattering(THIN, settings)
    altitude, cos_view, cos_sun = grid_axes(settings.size, HA, mapping)
    daylight = cos_sun >= 0
    length = path_length(RP + altitude[None, :], cos_view[:, None], RP, RA)       # (H, W)
    expected = np.broadcast_to(thin_layer_expectation(THIN, length), (daylight.sum(),) + length.shape + (6,))
    actual = table[daylight]
    print(max_error_report(actual, expected, f"{backend.name} thin layer, {mapping}"), "rtol", THIN_RTOL)
    # atol: near-grazing rays have ill-conditioned lengths: sqrt(eps r^2) ~ 0.1 m of path; 1 m of path.
    atol = thin_layer_expectation(THIN, 1.0).max()
    assert_allclose(actual, expected, rtol=THIN_RTOL, atol=atol)
    assert np.all(actual <= expected * (1 + 1e-12) + atol)
    assert np.all(actual[:, cos_view > 0, -1] == 0.0)        # at the top looking up: no path


def test_thin_layer_twilight_shadow_boundary_on_a_vertical_ray(backend):
    """Sun below the horizon, observer on the ground looking up: the ray is lit above the shadow
    cylinder's edge r* = Rp / sqrt(1 - mu_s^2), so Ibar = beta/(4 pi) (Ra - max(Rp, r*))^+."""
    steps = 2000
    settings = TableSettings(size=(2, 3, 9), view_steps=steps, sun_steps=2)
    table = backend.single_scattering(THIN, settings)
    _, cos_view, cos_sun = grid_axes(settings.size, HA)
    assert cos_view[-1] == 1.0
    with np.errstate(divide="ignore"):          # cos_sun = -1: the edge is at infinity
        edge = RP / np.sqrt(1.0 - cos_sun**2)
    lit_length = np.clip(RA - np.where(cos_sun >= 0, RP, edge), 0.0, HA)
    assert np.any((lit_length > 0) & (lit_length < HA))        # the boundary crosses the ray somewhere
    expected = thin_layer_expectation(THIN, lit_length)
    actual = table[:, -1, 0]
    print(max_error_report(actual, expected, f"{backend.name} twilight vertical"), "lit lengths", lit_length)
    # The integrand jumps from 0 to ~1 at the edge: the trapezoid misplaces it by at most half a step,
    # Ha / (2 n) = 25 m of path; plus THIN_RTOL for T < 1.
    atol = thin_layer_expectation(THIN, HA / (2 * steps)).max()
    assert_allclose(actual, expected, rtol=THIN_RTOL, atol=atol)
    assert np.all(actual[lit_length == 0] == 0.0)
