"""Higher orders that carry azimuth: a cosine series in the view-sun azimuth (issue 11, item 2).

The physical scheme of :mod:`clsky.orders` computes every order k >= 2 on the 3D grid (h, mu, mu_s) in
the canonical frame (view and sun in one vertical plane, the view on the sun's side) and averages it
over azimuth. At dusk that spreads the light of the lit, sunward atmosphere into the shadowed
anti-solar sky (README, "Twilight against Monte Carlo"). Here the radiance keeps its dependence on
the azimuth phi between the horizontal directions of the view and of the sun. The atmosphere is
symmetric about the sun's vertical plane, so a cosine series holds it:

    L(h, mu, mu_s, phi) = sum_{m=0..M} L_m(h, mu, mu_s) cos(m phi).

Nodes and harmonics. Every order is computed at the M + 1 azimuths phi_n = n pi / M (n = 0..M; only
phi_0 = 0 for M = 0) along the *true* view ray of that azimuth, and turned into the M + 1 coefficients
of the cosine series that interpolates those nodes (a type-I discrete cosine transform,
:func:`harmonic_transform`).

Gather. A phase function depends only on dot(omega, V), so the sphere integral decouples per
harmonic. With omega = (Theta, Phi), V at zenith cosine mu_i and azimuth phi_V:

    G_{s,m}(mu_i) = sum_a wT_a sin(Theta_a) K_{s,m}(i, a) (P L_m)(a),
    K_{s,m}(i, a) = sum_b wP_b F_s(cos Theta_a mu_i + sin Theta_a sin_i cos Phi_b) cos(m Phi_b),

the trapezoid and interpolation P of :mod:`clsky.multiple`, whose energy-conserving row rescaling of
K_{s,0} is applied to every harmonic of that row (so M = 0 is the existing gather matrix exactly).

First gather. Single scattering arrives with the exact phase to the sun, L^(1)(Theta, Phi) =
sum_s' F_s'(cos Theta mu_s + sin Theta sin_s cos Phi) Ibar_s'^(1)(Theta, Phi), Ibar^(1) computed at the
azimuth nodes from the true geometry. Its harmonic m, which is all that the gather's harmonic m needs
(the gather is a convolution in azimuth), is

    p_{s',m}(a) = sum_n C_{s',m,n}(z, a) (P Ibar_{s',n})(a),
    C_{s',m,n}(z, a) = eps_m / (2 pi) sum_b wP_b F_s'(cos Theta_a mu_z + sin Theta_a sin_z cos Phi_b)
                       cos(m Phi_b) cos(n Phi_b),

eps_0 = 1, eps_m = 2: the sharp Mie peak to the sun is integrated on the gather's fine Phi grid, never
through the truncated series. M = 0 is the existing first gather, K_s K_s' / (2 pi).

Scatter. The order k + 1 at a cell (h0, mu, mu_s) and azimuth node phi_n integrates the gathered
source along that true ray (nu = mu mu_s + sqrt(1 - mu^2) sqrt(1 - mu_s^2) cos phi_n), where the local
altitude, view cosine, sun cosine and azimuth change:

    G_s(P) = max(0, sum_m G_{s,m}(h, mu_view, mu_sun) T_m(cos phi_local)),
    cos phi_local = (nu - mu_view mu_sun) / (sqrt(1 - mu_view^2) sqrt(1 - mu_sun^2))
                  (evaluated without cancellation near the vertical: :func:`local_cos_azimuth`),

T_m the Chebyshev polynomials (cos(m phi) = T_m(cos phi)), and the clamp at 0 keeping a truncated
series that rings negative from adding negative light (Fejer factors were not needed: with the clamp,
M = 2, 4 and 8 agree within 3 %, README "Twilight against Monte Carlo"). The scatter of the orders
k > 2 reads only the azimuth average G_0 of their source (:data:`HARMONIC_SOURCE_ORDERS`: within
0.085 % of reading every harmonic, at a third less cost). The ray march
(:func:`raymarch_higher_orders`) integrates the whole series of the gathered tables of all orders
along each pixel's ray.

Summed harmonics. Where the next order reads G_0 alone, the harmonics m >= 1 of an order's gathered
G^(k) are only ever added to the gathered sum, and the gather is linear: sum_k A_m L_m^(k) =
A_m sum_k L_m^(k). So such an order gathers its azimuth average alone (the next order's source), the
host sums the nodes of those orders as the gathered sum takes them (the geometric tail's 1 + r / (1 -
r) included, an order that converged without a tail left out), and the harmonics m >= 1 of that sum
are gathered once after the orders: 8 gathers instead of 18 for the default animation's table, the
same sum to rounding (6e-16 of its largest value there; tests/test_azimuth.py against every order
gathered), for one more table of nodes on the host (docs/speed-log.md).

Ground. A Lambertian ground (``ground_albedo`` > 0) works as in :mod:`clsky.ground`: the rays of every
azimuth node that end on the ground see its radiance at their true ground point's sun cosine; the
horizontal ground's irradiance of an order k >= 2 is that of its azimuth average (m = 0), and single
scattering's is :meth:`HarmonicGather.single_ground_irradiance`.

The ray integrals run on OpenCL or in their NumPy twins here (``backend``); M = 0 reproduces the
physical mode of :func:`clsky.orders.compute_orders` to rounding.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import dataclasses
import functools
import math

import numpy as np

from . import _atmosphere_cl, _cl, ground, reference
from .atmosphere import AtmosphereParameters
from .errors import ParameterError, is_integer
from .mapping import altitude_to_u, cos_to_sun_t, cos_to_v, grid_coordinates
from .multiple import SPECIES, _gather_key, _gather_parts, _phase, _quadrature_key, _read_only, gather_quadrature
from .orders import (_diverging, _total, check_finite, diverging_reason, geometric_ratio, per_channel,
                     scatter_sun_stride, species_sum, tail_factor)
from .settings import MAX_AZIMUTH_HARMONICS, TableSettings
from .stopping import DeviceStoppingTest, HostStoppingTest

__all__ = ["azimuth_nodes", "harmonic_transform", "harmonic_phase_integrals",
           "HarmonicGather", "harmonic_gather", "single_scattering_nodes", "scatter_nodes", "HarmonicOrders",
           "compute_orders", "orders_result", "azimuth_average", "gathered_along",
           "raymarch_higher_orders", "local_cos_azimuth"]

#: Orders k whose scatter reads the harmonics m >= 1 of their gathered source; later orders read its
#: azimuth average G_0 (still along the true rays of every azimuth node, and still gathered per
#: harmonic for the ray march). None: every order. Only order 2's source, gathered from single
#: scattering with its sharp phase to the sun, has azimuth structure that matters: reading G_0 alone
#: from order 3 on changed the ray march's twilight views by at most 0.085 % at -6 deg, 0.013 % at
#: -2 deg and 0.005 % at 0 and +5 deg (draft level, every view and channel; from order 2 on it
#: would be 0.86 % at -6 deg), and an order's scatter at each node then costs the azimuth average's
#: one lookup per sample instead of M + 1 (0.68 instead of 1.12 CPU-s per node on the default
#: animation's 32 x 256 x 139 table).
HARMONIC_SOURCE_ORDERS = 2


def _add_nodes(total, nodes, scale=None):
    """total + nodes, or + scale nodes per wavelength (scale (r, g, b)): the host's sum of orders' nodes
    (M + 1, D, H, W, 3), in place (for total None, a new sum), the scaled nodes a sun layer at a time (no
    temporary of the whole table)."""
    if scale is None:
        if total is None:
            return nodes.copy()
        total += nodes
        return total
    total = np.zeros_like(nodes) if total is None else total
    scale = per_channel(scale, nodes.shape[-1])
    for layer in range(nodes.shape[1]):
        total[:, layer] += nodes[:, layer] * scale
    return total


def _reads_harmonics(k):
    """Whether order k's scatter reads every harmonic of its source (:data:`HARMONIC_SOURCE_ORDERS`)."""
    return HARMONIC_SOURCE_ORDERS is None or k <= HARMONIC_SOURCE_ORDERS


def _check_harmonics(harmonics):
    if not is_integer(harmonics) or not 0 <= harmonics <= MAX_AZIMUTH_HARMONICS:
        raise ParameterError("azimuth_harmonics", f"an integer in [0, {MAX_AZIMUTH_HARMONICS}]", harmonics)
    return int(harmonics)


def azimuth_nodes(harmonics: int) -> np.ndarray:
    """The M + 1 azimuths [rad] n pi / M, n = 0..M, at which orders are computed ([0] for M = 0)."""
    harmonics = _check_harmonics(harmonics)
    if harmonics == 0:
        return np.zeros(1)
    return np.arange(harmonics + 1) * (math.pi / harmonics)


def harmonic_transform(harmonics: int) -> np.ndarray:
    """(M + 1, M + 1) matrix H: coefficients c = H f of the cosine series sum_m c_m cos(m phi) through
    the values f_n at :func:`azimuth_nodes` (type-I DCT: c_m = (2 / M) sum''_n f_n cos(m n pi / M),
    halved for m = 0 and m = M; sum'' halves the end nodes). [[1]] for M = 0."""
    harmonics = _check_harmonics(harmonics)
    if harmonics == 0:
        return np.ones((1, 1))
    m = np.arange(harmonics + 1)
    h = (2.0 / harmonics) * np.cos(np.outer(m, m) * (math.pi / harmonics))
    h[:, [0, -1]] *= 0.5
    h[[0, -1], :] *= 0.5
    return h


def chebyshev(cos_phi, harmonics):
    """T_m(cos_phi) = cos(m phi) for m = 0..M on a new last axis."""
    out = np.empty(np.shape(cos_phi) + (harmonics + 1,))
    out[..., 0] = 1.0
    if harmonics >= 1:
        out[..., 1] = cos_phi
    for m in range(2, harmonics + 1):
        out[..., m] = 2.0 * cos_phi * out[..., m - 1] - out[..., m - 2]
    return out


def local_cos_azimuth(r0, s, mu_v, mu_s, nu):
    """cos of the azimuth between the horizontal projections of V and Sun at distance s [m] along a ray
    from radius r0 [m] whose view and sun cosines at its start are mu_v, mu_s, with dot(V, Sun) = nu
    (``ray_azimuth_cos`` and ``add_lookups`` of kernels/view_ray.cl; cancellation-free near the vertical):
    (r0 (nu - mu_v mu_s) + s (mu_v nu - mu_s)) / (sqrt(1 - mu_v^2) |P x Sun|), 1 where the view or the
    sun is vertical (no azimuth)."""
    cross2 = (r0 * r0 * np.maximum(1.0 - mu_s * mu_s, 0.0) + 2.0 * r0 * s * (mu_v - mu_s * nu)
              + s * s * np.maximum(1.0 - nu * nu, 0.0))
    denominator = np.sqrt(np.maximum(1.0 - mu_v * mu_v, 0.0)) * np.sqrt(np.maximum(cross2, 0.0))
    numerator = r0 * (nu - mu_v * mu_s) + s * (mu_v * nu - mu_s)
    with np.errstate(divide="ignore", invalid="ignore"):
        value = np.where(denominator > 0.0, numerator / denominator, 1.0)
    return np.clip(value, -1.0, 1.0)


def harmonic_phase_integrals(phase, cosines, theta, phi, phi_weights, harmonics):
    """K_m(i, a) = sum_b wP_b F(cos Theta_a c_i + sin Theta_a s_i cos Phi_b) cos(m Phi_b), (M + 1, n, Theta).

    m = 0 is :func:`clsky.multiple.phase_azimuth_integrals` (same sums in the same order)."""
    sines = np.sqrt(np.maximum(1.0 - cosines * cosines, 0.0))
    k = np.zeros((harmonics + 1, cosines.size, theta.size))
    for cos_phi, angle, weight in zip(np.cos(phi), phi, phi_weights):
        value = weight * phase(np.cos(theta) * cosines[:, None] + np.sin(theta) * sines[:, None] * cos_phi)
        k[0] += value
        for m in range(1, harmonics + 1):
            k[m] += value * math.cos(m * angle)
    return k


class HarmonicGather:
    """The per-harmonic gather operators of one grid, quadrature and pair of phase functions.

    Attributes
    ----------
    view : dict species -> (M + 1, H, Theta + 1)
        wT_a sin(Theta_a) K_{s,m}(i, a), rows rescaled as the m = 0 gather's (energy conservation).
    sun : dict species -> (M + 1, M + 1, D, Theta + 1)
        C_{s,m,n}(z, a) of the first gather (module docstring), rows rescaled likewise.
    p : (Theta + 1, H)
        Interpolation from the view nodes to cos(Theta_a).
    """

    def __init__(self, atmosphere: AtmosphereParameters, settings: TableSettings, harmonics: int):
        self.harmonics = harmonics = _check_harmonics(harmonics)
        key = _quadrature_key(settings)
        p, weights, view0, sun0 = _gather_parts(atmosphere, key)
        theta, _, phi, phi_weights = gather_quadrature(key.gather_theta_steps, key.gather_phi_steps)
        _, cos_view, cos_sun = grid_coordinates(key.size, atmosphere.atmosphere_height, key.mapping,
                                                key.sun_cos_range)
        self.p, self.weights, self.cos_theta = p, weights, np.cos(theta)
        self.view, self.sun = {}, {}
        m = np.arange(harmonics + 1)
        eps = np.where(m == 0, 1.0, 2.0)
        for species in SPECIES:
            phase = _phase(atmosphere, species)
            raw = harmonic_phase_integrals(phase, cos_view, theta, phi, phi_weights, harmonics)
            scale = view0[species] / np.where(raw[0] != 0.0, raw[0], 1.0)     # the m = 0 rescaling, per row
            self.view[species] = raw * scale[None] * weights
            self.view[species][0] = view0[species] * weights                 # m = 0 exactly as today
            # C_{m,n}: the azimuth integral of F_s' cos(m Phi) cos(n Phi), from products of harmonics:
            # cos(m Phi) cos(n Phi) = (cos((m + n) Phi) + cos((m - n) Phi)) / 2
            raw_sun = harmonic_phase_integrals(phase, cos_sun, theta, phi, phi_weights, 2 * harmonics)
            scale_sun = sun0[species] / np.where(raw_sun[0] != 0.0, raw_sun[0], 1.0)
            k_sun = raw_sun * scale_sun[None]
            k_sun[0] = sun0[species]
            c = np.empty((harmonics + 1, harmonics + 1) + k_sun.shape[1:])
            for i in m:
                for j in m:
                    if i == 0 and j == 0:
                        c[i, j] = k_sun[0]
                    else:
                        c[i, j] = 0.5 * (k_sun[i + j] + k_sun[abs(i - j)])
            self.sun[species] = c * (eps / (2.0 * math.pi))[:, None, None, None]

    def single_ground_irradiance(self, single_nodes):
        """E_1 (D, 3) on the ground of single scattering at the azimuth nodes (M + 1, D, H, W, 6) [units
        of I_I]: sum_s sum_a wT_a sin(Theta_a) max(cos(Theta_a), 0) 2 pi sum_n C_{s,0,n}(z, a)
        (P Ibar_{s,n})(a) at altitude 0 (its harmonics Ibar_{s,n} of the nodes there alone), the azimuth
        integral of the phase to the sun times each harmonic (M = 0 is :func:`clsky.ground.sky_irradiance`
        of a factored order)."""
        hemisphere = self.weights * np.maximum(self.cos_theta, 0.0)
        single_harmonics = _to_harmonics(single_nodes[:, :, :, 0])                        # (n, D, H, 6)
        total = 0.0
        for index, species in enumerate(SPECIES):
            seen = np.matmul(self.p, single_harmonics[..., 3 * index:3 * index + 3])      # (n, D, Theta, 3)
            total = total + 2.0 * math.pi * np.einsum("a,nza,nzac->zc", hemisphere, self.sun[species][0], seen)
        return total

    def gather(self, harmonics_table, first=0):
        """G_{s,m} (N, D, H, W, 6) of an order's harmonics L_m (N, D, H, W, 3), m = ``first`` .. ``first``
        + N - 1 (default all M + 1 from m = 0), phase applied."""
        count, depth, height, width, _ = harmonics_table.shape
        out = np.empty((count, depth, height, width, 6))
        for index_m in range(count):
            columns = harmonics_table[index_m].reshape(depth, height, width * 3)
            seen = np.matmul(self.p, columns)                               # (D, Theta + 1, W * 3)
            for index, species in enumerate(SPECIES):
                out[index_m, ..., 3 * index:3 * index + 3] = np.matmul(self.view[species][first + index_m],
                                                                       seen).reshape(depth, height, width, 3)
        return out

    def first_gather(self, single_nodes):
        """G_{s,m} (M + 1, D, H, W, 6) of single scattering at the azimuth nodes (M + 1, D, H, W, 6),
        factored (Rayleigh r, g, b, Mie r, g, b without phase), through its harmonics Ibar_{s',n}
        (:func:`harmonic_transform`).

        Done :data:`FIRST_GATHER_LAYERS` sun layers at a time: each block's harmonics, their
        interpolation P Ibar, its sun weighting (:meth:`_sun_weighted`) and its gathers, so that their
        temporaries are a few MB that stay in the cache instead of tables of the whole grid (the
        harmonics, 245 MB for the default animation's table, and two of 250 MB and two of 123 MB,
        faulted in fresh). Every value is the same bits as the whole-grid products: BLAS multiplies each
        (sun layer, harmonic) matrix on its own, whichever batch it is in, and each cell's harmonics
        are the same three products and sums in any block (tested).

        The interpolation's columns are the harmonics' with each species' channels together, (species,
        W, 3) rather than (W, 6): its products are the same (each column's own), and the sun weighting
        then multiplies each species' values as contiguous runs of W x 3 instead of runs of 3: the whole
        first gather of the default animation's table in 0.61-0.71 against 0.73-0.94 CPU-s on one
        thread, the same bits (docs/speed-log.md).

        The blocks are independent and the device waits for all of them (the orders start from their
        sum): :meth:`first_gather_threads` host threads take them, each with a one-thread BLAS (NumPy
        releases the GIL in its loops and in BLAS); the same bits on any number of threads."""
        count, depth, height, width, _ = single_nodes.shape
        out = np.empty((count, depth, height, width, 6))

        def gather_block(z0):
            z1 = min(z0 + self.FIRST_GATHER_LAYERS, depth)
            # one product for both species' columns (P is the same), each species' columns together
            harmonics = _to_harmonics(single_nodes[:, z0:z1]).reshape(count, z1 - z0, height, width, len(SPECIES), 3)
            columns = np.ascontiguousarray(harmonics.transpose(0, 1, 2, 4, 3, 5)).reshape(count, z1 - z0, height, -1)
            seen = np.matmul(self.p, columns).reshape(count, z1 - z0, -1, len(SPECIES), width, 3)
            harmonic = self._sun_weighted(seen, z0).reshape(count, z1 - z0, -1, width * 3)
            for index, species in enumerate(SPECIES):
                gathered = np.matmul(self.view[species][:, None], harmonic)            # (m, layers, H, W * 3)
                out[:, z0:z1, ..., 3 * index:3 * index + 3] = gathered.reshape(count, z1 - z0, height, width, 3)

        with _cl.host_blas_single_threaded(), \
                concurrent.futures.ThreadPoolExecutor(self.first_gather_threads(depth)) as pool:
            for _ in pool.map(gather_block, range(0, depth, self.FIRST_GATHER_LAYERS)):
                pass                    # map's results re-raise a block's exception here
        return out

    #: Sun layers per block of :meth:`first_gather`: 2.4 MB of interpolated single scattering per
    #: layer of the default animation's table (M = 2).
    FIRST_GATHER_LAYERS = 2

    #: Host threads of :meth:`first_gather` (None: one per core the process may use, ``_cl.host_cores``).
    #: The default animation's planned table on the 2-core machine: 0.58-0.65 s wall and 1.14-1.19 CPU-s
    #: on two threads against 0.79-1.34 s and 1.58-2.65 CPU-s on one thread with OpenBLAS's own threads.
    FIRST_GATHER_THREADS = None

    @classmethod
    def first_gather_threads(cls, depth):
        """Threads of :meth:`first_gather` for ``depth`` sun layers: :data:`FIRST_GATHER_THREADS` (or
        the host's cores), at most one a block of :data:`FIRST_GATHER_LAYERS` layers."""
        threads = cls.FIRST_GATHER_THREADS or _cl.host_cores()
        return max(1, min(threads, -(-depth // cls.FIRST_GATHER_LAYERS)))

    #: Sun layers per block of :meth:`_sun_weighted`: its operands (a few hundred kB a layer for the
    #: default animation's table) then stay in the cache between the block's operations.
    SUN_LAYERS_PER_BLOCK = 2

    def _sun_weighted(self, seen, first_layer=0):
        """p_m (M + 1, L, Theta + 1, W, 3) = sum_s' sum_n C_{s',m,n}(z, a) seen_{n,s'}(z, a) of the seen
        harmonics ``seen`` (M + 1, L, Theta + 1, 2, W, 3) of the L sun layers from ``first_layer`` on, each
        species s' (Rayleigh, Mie) its r, g, b of every W together (:meth:`first_gather`'s layout), summed
        over the species s' seen (both gathering species apply the same K_{s,m} to it: one matrix product
        per gathering species, not two).

        The sums are those of ``np.einsum("mnza,nzawc->mzawc", ...)`` per species s' (over n in order),
        the second species' added to the first's, bit for bit; done a few sun layers at a time, they
        take a quarter of einsum's time (0.25 against 0.95 s for the default animation's table), whose
        broadcast products went through the whole 250 MB table once per term."""
        count, depth = seen.shape[:2]
        harmonic = np.empty(seen.shape[:3] + seen.shape[4:])
        layers = self.SUN_LAYERS_PER_BLOCK
        product, other_term = np.empty((2, layers) + harmonic.shape[2:])
        for z0 in range(0, depth, layers):
            z1 = min(z0 + layers, depth)
            product_block, other_block = product[:z1 - z0], other_term[:z1 - z0]
            for m in range(count):
                for index, species in enumerate(SPECIES):
                    weights = self.sun[species][m, :, first_layer + z0:first_layer + z1, :, None, None]
                    part = seen[:, z0:z1, :, index]
                    term = harmonic[m, z0:z1] if index == 0 else other_block
                    np.multiply(weights[0], part[0], out=term)
                    for n in range(1, count):
                        term += np.multiply(weights[n], part[n], out=product_block)
                    if index > 0:
                        harmonic[m, z0:z1] += other_block
        return harmonic

    def gather_matrices(self, harmonic):
        """(2, H, H) Rayleigh and Mie matrices A_{s,m} = (wT sin K_{s,m}) P of harmonic m, as
        :meth:`clsky.multiple.MultipleScatteringEngine.gather` takes them (m = 0:
        :func:`clsky.multiple.gather_matrix`, the same product)."""
        with _cl.host_blas_single_threaded():
            return np.stack([self.view[species][harmonic] @ self.p for species in SPECIES])


def harmonic_gather(atmosphere: AtmosphereParameters, settings: TableSettings, harmonics: int) -> HarmonicGather:
    """The :class:`HarmonicGather` of a grid, quadrature, pair of phase functions and M = ``harmonics``,
    cached, its arrays read-only.

    Keyed as :func:`clsky.multiple.gather_matrices` is: atmospheres that differ only in coefficients,
    wavelengths or sun (the batches of a spectral build) and a process's later builds of the same grid
    share one; computing it took 0.27-0.53 CPU-s for the default animation's table (docs/speed-log.md)."""
    return _harmonic_gather(_gather_key(atmosphere), _quadrature_key(settings), _check_harmonics(harmonics))


@functools.lru_cache(maxsize=2)
def _harmonic_gather(atmosphere, settings, harmonics):
    operators = HarmonicGather(atmosphere, settings, harmonics)
    for array in (operators.cos_theta, *operators.view.values(), *operators.sun.values()):
        _read_only(array)                       # p and weights: clsky.multiple's cached parts, read-only
    return operators


def _cos_scatter(cos_view, cos_sun, azimuth):
    return cos_view * cos_sun + np.sqrt(np.maximum(1.0 - cos_view * cos_view, 0.0)
                                        * np.maximum(1.0 - cos_sun * cos_sun, 0.0)) * math.cos(azimuth)


def single_scattering_nodes(atmosphere: AtmosphereParameters, settings: TableSettings):
    """Ibar^(1) (M + 1, D, H, W, 6) at the azimuth nodes of M = ``settings.azimuth_harmonics``, along the
    true view rays; twin of ``SingleScatteringEngine.compute`` at each node's cos_azimuth (node 0 is
    :func:`clsky.reference.single_scattering`)."""
    altitudes, cos_view, cos_sun = grid_coordinates(settings.size, atmosphere.atmosphere_height,
                                                    settings.mapping, settings.sun_cos_range)
    sun_table = None
    if settings.sun_transmittance == "table":
        sun_table = reference.transmittance_table(atmosphere, settings.transmittance_size, settings.sun_steps,
                                                  settings.sampling)
    out = []
    for azimuth in azimuth_nodes(settings.azimuth_harmonics):
        def cells(x, y, z, azimuth=azimuth):
            nu = None if azimuth == 0.0 else _cos_scatter(cos_view[y], cos_sun[z], azimuth)
            return reference._single_scattering_cells(atmosphere, settings, altitudes[x], cos_view[y], cos_sun[z],
                                                      sun_table, nu)
        out.append(reference._cells_in_chunks(settings, (settings.view_steps + 1) * (settings.sun_steps + 1), cells))
    return np.stack(out)


def gathered_along(atmosphere, ray_settings, gathered, grid_settings, h0, mu_v, mu_s, nu=None):
    """beta_s / (4 pi) Integral rho_s T(P, Pa) G_s(P) ds (n, 6) along rays, G_s the clamped cosine series
    of ``gathered`` (M + 1, D, H, W, 6) at the local azimuth (module docstring); nu None: canonical; taken at
    the nodes as ``ray_settings.source_stride`` says (:func:`clsky.reference.source_at_stride`)."""
    count = gathered.shape[0]
    width, height, depth = grid_settings.size
    rays = reference._ViewRays(atmosphere, ray_settings, h0, mu_v, mu_s, nu)
    stacked = np.moveaxis(gathered, 0, -2).reshape(depth, height, width, count * 6)
    g = reference.trilinear(stacked,
                            altitude_to_u(rays.h, atmosphere.atmosphere_height, grid_settings.mapping) * (width - 1),
                            cos_to_v(rays.mu_view, grid_settings.mapping) * (height - 1),
                            cos_to_sun_t(rays.mu_sun, grid_settings.mapping, grid_settings.sun_cos_range) * (depth - 1))
    if count > 1:
        g = g.reshape(g.shape[:-1] + (count, 6))
        if nu is None:
            nu = _cos_scatter(np.asarray(mu_v), np.asarray(mu_s), 0.0)
        column = (lambda a: np.asarray(a, dtype=np.float64)[:, None])
        cos_phi = local_cos_azimuth(atmosphere.planet_radius + column(h0), rays.s, column(mu_v), column(mu_s),
                                    column(nu))
        weights = chebyshev(cos_phi, count - 1)
        g = np.maximum(np.einsum("cnm,cnmk->cnk", weights, g), 0.0)
    g = reference.source_at_stride(g, rays.nodes, ray_settings.source_stride)
    transmittance = np.exp(-reference._optical_depth_of(atmosphere, *rays.view))
    return rays.integrate(atmosphere, transmittance, g[..., 0:3], g[..., 3:6])


def scatter_nodes(atmosphere: AtmosphereParameters, settings: TableSettings, gathered, ground_radiance=None,
                  source_harmonics=None, sun_stride=1):
    """The next order L^(k+1) (M + 1, D, H, W, 3) at the azimuth nodes from the gathered harmonics
    ``gathered`` (M + 1, D, H, W, 6, or its first ``source_harmonics`` + 1 alone), phase applied and
    both species combined (M from ``settings.azimuth_harmonics``); twin of
    ``MultipleScatteringEngine.scatter(combine_species=True)`` at each node's cos_azimuth. With a
    reflecting ground, rays that end on it add T L_g(mu_sun there), ``ground_radiance`` L_g (D, 3) per
    sun node (:mod:`clsky.ground`), as :func:`clsky.reference.scatter` does along the true ray.
    ``source_harmonics`` (0 .. M): the rays read only that many harmonics of the source (0: its
    azimuth average, the M = 0 kernel at each node's cos_azimuth); None: all. ``sun_stride`` 2: the sun
    nodes between every other one and the last filled (:func:`clsky.reference.fill_between_sun_nodes`)."""
    from .ground import interpolate_sun_axis

    count = settings.azimuth_harmonics + 1
    source = gathered if source_harmonics is None else gathered[:source_harmonics + 1]
    altitudes, cos_view, cos_sun = grid_coordinates(settings.size, atmosphere.atmosphere_height,
                                                    settings.mapping, settings.sun_cos_range)
    scatter_settings = settings.scatter_settings
    out = []
    for azimuth in azimuth_nodes(count - 1):
        def cells(x, y, z, azimuth=azimuth):
            nu = None if azimuth == 0.0 else _cos_scatter(cos_view[y], cos_sun[z], azimuth)
            value = gathered_along(atmosphere, scatter_settings, source, settings, altitudes[x], cos_view[y],
                                   cos_sun[z], nu)
            value = value[:, :3] + value[:, 3:]
            if atmosphere.has_ground:
                rays = reference._ViewRays(atmosphere, scatter_settings, altitudes[x], cos_view[y], cos_sun[z], nu)
                transmittance, mu_ground = reference._ground_seen(atmosphere, rays)
                value = value + transmittance * interpolate_sun_axis(np.asarray(ground_radiance), mu_ground, settings)
            return value
        out.append(reference._cells_in_chunks(settings, (scatter_settings.view_steps + 1) * 8 * 6 * count, cells, 3))
    return reference.fill_between_sun_nodes(np.stack(out), sun_stride)


def _to_harmonics(nodes):
    """Coefficients (M + 1, ...) of node values (M + 1, ...) (:func:`harmonic_transform`)."""
    transform = harmonic_transform(nodes.shape[0] - 1)
    return np.tensordot(transform, nodes, axes=1)


@dataclasses.dataclass
class HarmonicOrders:
    """What :func:`compute_orders` returns.

    Attributes
    ----------
    single : (D, H, W, 6)
        Single scattering in the canonical frame (node 0), factored, as the 3D table stores it.
    gathered : (M + 1, D, H, W, 6) or None
        Sum over the orders 2..K of the gathered harmonics G_{s,m} (Rayleigh r, g, b, Mie r, g, b; phase
        inside), with the geometric tail's G^(K+1) / (1 - r) when there is one (:mod:`clsky.orders`), for
        :func:`raymarch_higher_orders`.
    orders : list of (M + 1, D, H, W, 3), or of (D, H, W, 3)
        L^(k) at the azimuth nodes, k = 2..K; with ``keep_nodes=False``, their azimuth averages.
    record : dict
        harmonics, orders, converged, relative additions, the estimated errors (clsky.orders), the
        geometric tail's ratio r per wavelength (``tail_ratio``: None without a tail; the orders do not
        include the tail, the table's is r / (1 - r) times the last order), device.
    ground_irradiance : (D, 3) or None
        With a reflecting ground, E_sky = sum_{k >= 1} E_k on the ground per sun node (:mod:`clsky.ground`),
        with the geometric tail's E_K r / (1 - r).
    """

    single: np.ndarray
    gathered: np.ndarray | None
    orders: list
    record: dict
    ground_irradiance: np.ndarray | None = None


@dataclasses.dataclass
class _Backend:
    """Where an order's ray integrals and gathers run.

    single: Ibar^(1) at the azimuth nodes (M + 1, D, H, W, 6) on the host; upload(gathered): the
    host's gathered harmonics (M + 1, D, H, W, 6) in the backend's form; scatter(gathered,
    ground_radiance, source_harmonics=None, sun_stride=1): a pair (a callable returning the order's nodes
    (M + 1, D, H, W, 3) on the host once they are there, valid until the next call; the same nodes in the
    backend's form);
    gather(that form, harmonics=None): the next order's gathered harmonics (backend's form), only the
    first ``harmonics`` of them computed (default all); accumulate(total, gathered, scale=None,
    harmonics=None): total + gathered, or total + scale gathered per wavelength (scale (r, g, b)), in
    the first ``harmonics`` harmonics only (default all) (for total None gathered itself or a copy, to
    which later calls may add in place); gather_summed(total, node_sum): total + A_m L_m in each
    harmonic m >= 1, L_m the harmonics of ``node_sum`` (M + 1, D, H, W, 3) on the host (in place);
    to_host(gathered): (M + 1, D, H, W, 6) float64; stopping_test(single, keep_previous): the orders' stopping test
    (:mod:`clsky.stopping`), its running sum starting from single scattering ``single``
    (M + 1, D, H, W, 6) as R + M per wavelength, whose ``add`` takes an order as ``reads`` says,
    'host' (what the first of scatter's pair returns) or 'backend' (the second); device: its
    description."""

    single: np.ndarray
    upload: object
    scatter: object
    gather: object
    accumulate: object
    gather_summed: object
    to_host: object
    stopping_test: object
    device: str


def _numpy_backend(atmosphere, settings, operators):
    """The NumPy twins: the ray integrals of :func:`single_scattering_nodes` and :func:`scatter_nodes`,
    the gathers of :meth:`HarmonicGather.gather` (``operators()`` returns the :class:`HarmonicGather`)."""
    single = single_scattering_nodes(atmosphere, settings)
    operators = operators()

    def scatter(gathered, ground_radiance, source_harmonics=None, sun_stride=1):
        nodes = scatter_nodes(atmosphere, settings, gathered, ground_radiance, source_harmonics, sun_stride)
        return (lambda: nodes), nodes

    def gather(nodes, harmonics=None):
        return operators.gather(_to_harmonics(nodes)[:harmonics])

    def accumulate(total, gathered, scale=None, harmonics=None):
        if total is None:
            return gathered.copy()
        out = total.copy()
        addend = gathered[:harmonics]
        out[:addend.shape[0]] += addend if scale is None else addend * per_channel(scale, addend.shape[-1])
        return out

    def gather_summed(total, node_sum):
        total[1:] += operators.gather(_to_harmonics(node_sum)[1:], first=1)
        return total

    def stopping_test(single, keep_previous):
        return HostStoppingTest(species_sum(single), keep_previous)

    return _Backend(single, lambda gathered: gathered, scatter, gather, accumulate, gather_summed,
                    lambda gathered: gathered, stopping_test, "numpy")


def _opencl_backend(atmosphere, settings, operators, ctx, fast_math, background=None):
    """The same on OpenCL: ``SingleScatteringEngine.compute`` and ``MultipleScatteringEngine.scatter`` at
    each azimuth node's cos_azimuth (kernels/view_ray.cl: table_cell, add_lookups), and the gathers of
    every harmonic with the gather kernel (``MultipleScatteringEngine.gather``, the azimuth average's
    kernel, with :meth:`HarmonicGather.gather_matrices`): an order's nodes, their harmonics and the
    gathered harmonics stay on the device, and so does the stopping test (:class:`clsky.stopping.DeviceStoppingTest`,
    where the device has fp64); only the nodes are copied to the host (the orders' light, the table's
    azimuth average).

    Every engine runs on one queue and takes its device arrays from one pool (:func:`clsky._cl.memory_pool`):
    an order reuses the buffers of the one before (they are the same sizes) instead of faulting in fresh
    memory. The nodes come to the host on copy queues of their own, their 3 channels (no padded copy on the
    host; by rectangular reads on a CPU, half a slab a queue, packed on the device and read at once elsewhere:
    :func:`clsky._cl.rectangular_reads`), into one reused host table, while the first queue gathers them: what
    ``scatter`` returns is valid until its next call. The gathered sum comes down the same way, and the first
    gather goes up by a rectangular write (rows of 6 values into rows of 8: 17 ms on an H200, no slower than a
    contiguous write; on a CPU half the rows on each copy queue, as the summed nodes after the orders). The
    pool goes with the backend. ``operators()`` returns the :class:`HarmonicGather`, called once single
    scattering is done. With ``background`` (a concurrent.futures executor), the orders' scatter programs
    are built on it while single scattering runs, not at their first launch."""
    import pyopencl as cl
    import pyopencl.array as cla

    from .multiple import MultipleScatteringEngine
    from .single import SingleScatteringEngine

    single_engine = SingleScatteringEngine(settings, ctx=ctx, fast_math=fast_math)
    queue = cl.CommandQueue(single_engine.ctx)
    pool = _cl.memory_pool(queue)
    # its gathers from the scatter's program (no plain program built for them)
    features = _atmosphere_cl.feature_defines(atmosphere)
    engine = MultipleScatteringEngine(settings, fast_math=fast_math, queue=queue, allocator=pool, features=features)
    # the nodes' downloads overlap the order's gathers; a CPU's rectangular reads split over two queues, which
    # PoCL's threads copy side by side: the gathered sum's download ends the build alone on the device, 0.29-0.47 s
    # on one core faulting in its fresh host table, 0.24-0.27 s on two (docs/speed-log.md)
    copy_queues = [cl.CommandQueue(engine.ctx) for _ in range(2)]
    rectangular = _cl.rectangular_reads(queue.device)
    # the uploads of the first gather and of the summed nodes split on a CPU, on the copy queues: each was one
    # PoCL thread's fill and write of 156 MB of fresh memory (85 and 100 ms) while the device waited for it
    upload_queues = _cl.upload_share_queues(queue, reuse=copy_queues)
    # the scatter's engines: every harmonic of the source, and the azimuth average alone where a later order
    # reads only that (HARMONIC_SOURCE_ORDERS)
    engines = {settings.azimuth_harmonics: engine}
    if settings.azimuth_harmonics and not _reads_harmonics(settings.max_orders if settings.orders == "auto"
                                                           else settings.orders):
        engines[0] = MultipleScatteringEngine(settings.replace(azimuth_harmonics=0), fast_math=fast_math,
                                              queue=queue, allocator=pool, features=features)
    # their programs built meanwhile on the background's thread: in a fresh process each build took 40-60 ms of
    # the main thread at its first scatter, the device idle (docs/speed-log.md); a build error surfaces there
    built = background.submit(lambda: [e.kernels_with(e.features) for e in engines.values()]) if background else None
    cosines = np.cos(azimuth_nodes(settings.azimuth_harmonics))
    width, height, depth = settings.size
    single = np.empty((cosines.size, depth, height, width, 6))
    for node, c in enumerate(cosines):
        single_engine.compute(atmosphere, cos_azimuth=c, out=single[node])
    transform = harmonic_transform(settings.azimuth_harmonics)
    operators = operators()         # made on a host thread meanwhile (compute_orders)
    matrices = [engine.upload_matrices(operators.gather_matrices(m)) for m in range(cosines.size)]
    # on the device once, so that enqueueing an order's gathers does not wait for them (compute_orders
    # enqueues them before its host work on the order)
    transform_rows = [engine.upload_matrices(row) for row in transform]
    host_nodes = []         # the host table (M + 1, D, H, W, 3) that scatter returns (allocated once)

    def download(table_d, into, channels):
        """Enqueues into = table_d[..., :channels] for the padded device table (N, D, H, W, 8) on the copy
        queues, after every command enqueued on the queue so far, straight into ``into`` (through a host table
        of the device's type for a float32 device). Where :func:`clsky._cl.rectangular_reads` holds (CPUs),
        rectangular reads (rows of ``channels`` values out of rows of 8, clEnqueueReadBufferRect), each half of
        each slab n on a copy queue of its own; elsewhere the device packs the channels into a contiguous array
        of the pool (``MultipleScatteringEngine.pack_channels``, on the queue) and one contiguous read takes it
        all.
        Returns a callable that waits for the reads and returns ``into``."""
        target = into if into.dtype == engine.dtype else np.empty(into.shape, engine.dtype)
        held = []           # the packed array, until its read is done (in the pool sooner, a kernel could reuse it)
        if rectangular:
            size = engine.dtype.itemsize
            rows = int(np.prod(table_d.shape[1:-1]))                       # cells of a slab
            after = [cl.enqueue_marker(queue)]
            parts = [(rows * p // len(copy_queues), rows * (p + 1) // len(copy_queues))
                     for p in range(len(copy_queues))]
            reads = [cl.enqueue_copy(copy_queue, target[n].reshape(rows, channels)[first:end], table_d.data,
                                     is_blocking=False, wait_for=after,
                                     buffer_origin=(table_d.offset + (n * rows + first) * 8 * size, 0, 0),
                                     host_origin=(0, 0, 0),
                                     region=(channels * size, end - first, 1), buffer_pitches=(8 * size, 0),
                                     host_pitches=(channels * size, 0))
                     for n in range(table_d.shape[0])
                     for copy_queue, (first, end) in zip(copy_queues, parts) if end > first]
        else:
            held.append(cla.empty(queue, into.shape, engine.dtype, allocator=pool))
            packed = engine.pack_channels(table_d, channels, held[0])
            reads = [cl.enqueue_copy(copy_queues[0], target, held[0].data, is_blocking=False, wait_for=[packed])]

        def on_host():
            cl.wait_for_events(reads)
            held.clear()
            if target is not into:
                np.copyto(into, target)
            return into
        return on_host

    def upload(gathered):
        """The first gather's harmonics (M + 1, D, H, W, 6) as a padded device table (M + 1, D, H, W, 8)
        from the pool (:func:`clsky._cl.upload_padded`: a zero fill and one rectangular write, on a CPU half
        the rows a copy queue)."""
        return _cl.upload_padded(queue, gathered, engine.dtype, allocator=pool, queues=upload_queues)

    def scatter(gathered_d, ground_radiance, source_harmonics=None, sun_stride=1):
        """The nodes, (M + 1, D, H, W, 3) on the host and padded (M + 1, D, H, W, 8) on the device; the
        rays read ``source_harmonics`` harmonics of the source (the first ones of the padded
        (M + 1, D, H, W, 8) buffer: a kernel built for fewer harmonics reads only those); the sun nodes
        as ``sun_stride`` says (``MultipleScatteringEngine.scatter``)."""
        read = settings.azimuth_harmonics if source_harmonics is None else source_harmonics
        if built is not None:
            built.result()          # waits for the builds (done long before); re-raises a build's error
        if read not in engines:
            engines[read] = MultipleScatteringEngine(settings.replace(azimuth_harmonics=read), fast_math=fast_math,
                                                     queue=queue, allocator=pool, features=features)
        nodes_d = cla.empty(queue, (cosines.size,) + gathered_d.shape[1:], engine.dtype, allocator=pool)
        for node, c in enumerate(cosines):
            engines[read].scatter(atmosphere, gathered_d, combine_species=True, ground_radiance=ground_radiance,
                                  cos_azimuth=c, out=nodes_d, node=node, sun_stride=sun_stride)
        if not host_nodes:
            host_nodes.append(np.empty(nodes_d.shape[:-1] + (3,)))
        return download(nodes_d, host_nodes[0], 3), nodes_d                # after the scatters

    def gather_harmonics(nodes_d, out, harmonics, accumulate=False):
        """out[m] (+)= A_m L_m for each m of ``harmonics``, L_m = sum_n H[m, n] L(phi_n) of the padded nodes
        (channels 0-2 and 3-5 both hold L), each gathered straight into its slab of the stack ``out`` (no
        table and copy of its own)."""
        harmonic = cla.empty(queue, nodes_d.shape[1:], engine.dtype, allocator=pool)
        for m in harmonics:
            engine.gather(matrices[m], engine.combine_nodes(nodes_d, transform_rows[m], harmonic), out=out, node=m,
                          accumulate=accumulate)
        return out

    def gather(nodes_d, harmonics=None):
        """The order's gathered harmonics G_m = A_m L_m, only the first ``harmonics`` (default all) computed:
        the stack keeps its M + 1 slabs, so that it takes the buffer of the stack before it from the pool
        (no new memory)."""
        out = cla.empty(queue, nodes_d.shape, engine.dtype, allocator=pool)
        return gather_harmonics(nodes_d, out, range(len(transform_rows))[:harmonics])

    def accumulate(total, gathered_d, scale=None, harmonics=None):
        """The first order's gathered harmonics become the sum itself, not a copy: a copy was PoCL's one-thread
        copy of a whole stack into fresh memory (85 ms of the default animation's table, the device's other
        thread idle); the orders after it add in place into that buffer, after its scatter on the queue."""
        return gathered_d if total is None else engine.add_into(total, gathered_d, scale, slabs=harmonics)

    def gather_summed(total_d, node_sum):
        """total_d[m] += A_m L_m for m >= 1, L_m the harmonics of the host's ``node_sum`` (M + 1, D, H, W,
        3), uploaded as padded nodes (both channel sets L) into the pool's buffer of an order's nodes."""
        nodes_d = _cl.upload_padded(queue, node_sum, engine.dtype, copies=2, allocator=pool, queues=upload_queues)
        return gather_harmonics(nodes_d, total_d, range(1, len(transform_rows)), accumulate=True)

    def to_host(gathered_d):
        return download(gathered_d, np.empty(gathered_d.shape[:-1] + (6,)), 6)()

    def stopping_test(single, keep_previous):
        """On the device beside the orders (clsky.stopping; the same numbers), where it has fp64, its
        running sum uploaded a node at a time. Its buffers are its own, not the pool's, so that they are
        freed with it before the gathered sum's download (held by the pool, they raised the build's peak
        by their 245 MB there)."""
        if not _cl.has_fp64(queue.device):
            return HostStoppingTest(species_sum(single), keep_previous)
        return DeviceStoppingTest((species_sum(node) for node in single), single.shape[:-1] + (3,),
                                  keep_previous, engine.dtype, queue=queue)

    return _Backend(single, upload, scatter, gather, accumulate, gather_summed, to_host, stopping_test,
                    _cl.describe_device(single_engine.device))


def compute_orders(atmosphere: AtmosphereParameters, settings: TableSettings, backend="numpy", ctx=None,
                   fast_math=False, progress=None, keep_nodes=True) -> HarmonicOrders:
    """Single scattering and the orders k >= 2 with M = ``settings.azimuth_harmonics`` azimuthal
    harmonics (module docstring), with the physical mode's stopping rule (:mod:`clsky.orders`).

    Parameters
    ----------
    backend : {'numpy', 'opencl'}
        Where the ray integrals and the gathers run (single scattering and the scatter at each azimuth
        node); the first gather is matrix products on the host either way (:class:`HarmonicGather`).
    progress : callable, optional
        ``progress(k, relative_addition)`` after each order.
    keep_nodes : bool
        Keep each order at its azimuth nodes (default), or only its azimuth average (what the 3D table
        stores: a third of the memory for M = 2, and the average is taken once, for the ground and the
        table alike).

    Raises
    ------
    ValueError
        (ParameterError) for a mode other than 'physical' or an unknown backend.
    """
    harmonics = settings.azimuth_harmonics
    if settings.mode != "physical":
        raise ParameterError("mode", "'physical' with azimuth harmonics", settings.mode)
    if backend not in ("numpy", "opencl"):
        raise ParameterError("backend", "one of ['numpy', 'opencl']", backend)
    _check_harmonics(harmonics)
    # the gather operators (NumPy: 0.27-0.53 s for the default animation's table, single-threaded; cached for
    # the next build of the grid), and the OpenCL backend's scatter programs, on a host thread while single
    # scattering runs: the device waited for them with a core idle (docs/speed-log.md)
    with concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="clsky-orders-setup") as pool:
        operators = pool.submit(harmonic_gather, atmosphere, settings, harmonics).result
        if backend == "numpy":
            run = _numpy_backend(atmosphere, settings, operators)
        else:
            run = _opencl_backend(atmosphere, settings, operators, ctx, fast_math, background=pool)
        operators = operators()
    single_nodes, run.single = run.single, None      # the backend's reference goes: the nodes are dropped below
    wanted = settings.max_orders if settings.orders == "auto" else settings.orders
    record = {"harmonics": harmonics, "converged": False, "relative_additions": [], "estimated_errors": [],
              "tail_ratio": None, "device": run.device}
    ground_sky = pending_ground = None      # as in clsky.orders: E_1 + ... + E_k, and a / pi of what is pending
    if atmosphere.has_ground:               # E_1 even for single scattering alone: the table's ground term needs it
        ground_sky = operators.single_ground_irradiance(single_nodes)
    if wanted == 1:
        record["orders"] = 1
        return HarmonicOrders(single_nodes[0], None, [], record, ground_sky)
    gathered = run.upload(operators.first_gather(single_nodes))
    if atmosphere.has_ground:
        pending_ground = ground.reflected_radiance(atmosphere, ground.direct_irradiance(atmosphere, settings)
                                                   + ground_sky)
    # single scattering's light (the first of the orders' totals) and the copy of its canonical node that the
    # orders keep, on a host thread while the stopping test sums and uploads its running sum: one after the
    # other they held the first scatter back by 40-70 ms more, the other core idle (docs/speed-log.md)
    with concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="clsky-orders-totals") as pool:
        single_total, single_copy = pool.submit(_total, single_nodes), pool.submit(np.copy, single_nodes[0])
        stopping = run.stopping_test(single_nodes, settings.orders == "auto")
        totals, single = [single_total.result()], single_copy.result()
    gathered_sum, orders = None, []
    # the sum of the nodes of the orders whose gathered harmonics m >= 1 join the gathered sum alone, and
    # whether the order before was one (its gathered G^(k - 1) then holds the azimuth average alone)
    node_sum, summed = None, False
    # what the orders no longer read goes before them: single scattering's nodes but the canonical one,
    # copied above (the build's peak memory is what a build pays for on these VMs, docs/speed-log.md)
    del single_nodes
    # the host's BLAS (azimuth averages, ground irradiances) on one thread beside the OpenCL device's
    # workers, as clsky._cl.host_blas_single_threaded explains (the first gather above has its own threads)
    with _cl.host_blas_single_threaded() if backend == "opencl" else contextlib.nullcontext():
        for k in range(2, wanted + 1):
            gathered_sum = run.accumulate(gathered_sum, gathered, harmonics=1 if summed else None)
            on_host, state = run.scatter(gathered, pending_ground, None if _reads_harmonics(k) else 0,
                                         scatter_sun_stride(settings, k))
            # first: the pool hands its buffer to the next gather (no more memory); the first order's is the
            # gathered sum's (accumulate), and the next gather takes the memory a copy of it would have
            del gathered
            # the next order's source (on OpenCL enqueued on the device, where the order is), before the
            # host waits for the order's nodes, so that their download overlaps it and the host's work on
            # the order overlaps the rest (the last order needs the source only for the geometric tail,
            # which needs k < wanted). Where the next order reads its source's azimuth average alone, only
            # that is gathered: the other harmonics of G^(k), A_m L_m^(k), only ever join the gathered sum,
            # so their L_m^(k) are summed instead and gathered once after the orders (module docstring)
            summed = k < wanted and harmonics > 0 and not _reads_harmonics(k + 1)
            gathered = run.gather(state, 1 if summed else None) if k < wanted else None
            new = on_host()
            totals.append(_total(new))
            # the geometric tail (clsky.orders), where it can apply: it adds G^(k+1), gathered below max_orders
            ratio = geometric_ratio(totals) if settings.orders == "auto" and k < wanted else None
            # the stopping test (on OpenCL enqueued on the device, after the gathers), read below
            stopping.add(new if stopping.reads == "host" else state, ratio)
            del state
            check_finite(new, k, atmosphere, settings, totals[-1])
            average = azimuth_average(new) if ground_sky is not None or not keep_nodes else None
            orders.append(new.copy() if keep_nodes else average)     # the backend reuses `new` next order
            if ground_sky is not None:     # the horizontal ground sees the azimuth average (m = 0)
                sky = ground.sky_irradiance(atmosphere, settings, average, factored=False)
                ground_sky = ground_sky + sky
                pending_ground = ground.reflected_radiance(atmosphere, sky)
            addition, error = stopping.result()
            record["relative_additions"].append(addition)
            record["estimated_errors"].append(error)
            if _diverging(totals):      # as clsky.orders: the orders grow, a quadrature's artefact; G^(k) left out
                record["reason"] = diverging_reason(k)
                break
            if progress is not None:
                progress(k, addition)
            converged = settings.orders == "auto" and error < settings.order_tolerance
            tail = tail_factor(ratio) if converged and ratio is not None else None
            # G^(k) joins the gathered sum (next order, or with the tail's 1 + tail now), but for an order
            # converged without a tail: so do its summed harmonics' nodes
            if summed and not (converged and tail is None):
                node_sum = _add_nodes(node_sum, new, None if tail is None else 1.0 + tail)
            if converged:
                record["converged"] = True
                if tail is not None:      # the orders after k: their source and ground light (the table's: the caller)
                    record["tail_ratio"] = ratio.tolist()
                    gathered_sum = run.accumulate(gathered_sum, gathered, 1.0 + tail,    # G^(k+1) / (1 - r)
                                                  harmonics=1 if summed else None)
                    if ground_sky is not None:
                        ground_sky = ground_sky + sky * tail
                break
    record["orders"] = len(orders) + 1
    del stopping, gathered                              # before the gathered sum's download
    if node_sum is not None:
        gathered_sum = run.gather_summed(gathered_sum, node_sum)
        del node_sum
    return HarmonicOrders(single, run.to_host(gathered_sum), orders, record, ground_sky)


def azimuth_average(order_nodes):
    """The m = 0 harmonic (M + 1, ...) -> (...): the azimuth average of an order, what the 3D table's
    lookup (which has no azimuth) stores: the first row of :func:`harmonic_transform` alone (a third of
    the work of every harmonic for M = 2, and the same values there; within rounding of that row of
    :func:`_to_harmonics` for M > 2, whose matrix product sums in another order)."""
    return np.tensordot(harmonic_transform(order_nodes.shape[0] - 1)[0], order_nodes, axes=1)


def orders_result(atmosphere: AtmosphereParameters, settings: TableSettings, backend="opencl", ctx=None,
                  fast_math=False, progress=None):
    """:func:`compute_orders` as :class:`clsky.orders.OrdersResult` (what :func:`clsky.orders.compute_orders`
    returns for ``settings.azimuth_harmonics`` > 0): orders[0] single scattering in the canonical frame
    (factored, the lookup applies its exact phase), orders k >= 2 their azimuth average (the 3D lookup
    has no azimuth), ``gathered`` the (M + 1, D, H, W, 6) harmonics for the ray march."""
    import time

    from .orders import OrdersResult, convergence_reason, last_order_reason, orders_record

    start = time.perf_counter()
    result = compute_orders(atmosphere, settings, backend=backend, ctx=ctx, fast_math=fast_math,
                            progress=None if progress is None else (lambda k, _: progress("orders", k, 0)),
                            keep_nodes=False)
    orders = [result.single] + result.orders
    additions, errors = result.record["relative_additions"], result.record["estimated_errors"]
    ratio, converged = result.record["tail_ratio"], result.record["converged"]
    if "reason" in result.record:                       # diverging (compute_orders)
        reason = result.record["reason"]
    elif converged:
        reason = convergence_reason(len(orders), additions[-1], errors[-1], ratio, settings.order_tolerance)
    else:
        reason = last_order_reason(settings, additions)
    record = orders_record(settings, converged, reason, additions, errors, ratio,
                           [_total(order) for order in orders], time.perf_counter() - start, result.record["device"])
    record["azimuth_harmonics"] = settings.azimuth_harmonics
    return OrdersResult(orders, record, result.gathered, result.ground_irradiance,
                        None if ratio is None else tail_factor(np.array(ratio)))


def raymarch_higher_orders(atmosphere, ray_settings, gathered, grid_settings, directions, sun_direction, altitude):
    """The higher orders the ray march adds per pixel, I_I times the integral of the gathered series
    along each pixel's ray (..., 3); add it to ``render_raymarch(..., gathered=None)``."""
    shape = np.shape(directions)[:-1]
    _, nu, h, mu_v, mu_s, inside = reference._pixel_geometry(atmosphere, directions, sun_direction, altitude)
    more = gathered_along(atmosphere, ray_settings, gathered, grid_settings, h, mu_v, mu_s, nu)
    value = (more[:, :3] + more[:, 3:]) * np.asarray(atmosphere.incident_light) * inside[:, None]
    return value.reshape(shape + (3,))
