"""Multiple scattering: the gather operator, and the OpenCL engine that applies it and scatters.

The gather at a point integrates the previous order over the sphere (physics.md):
    Gbar(h, mu_v, mu_s) = Integral_{4 pi} F(dot(omega, V)) Ibar(h, omega, mu_s) d omega.
The 3D table has no azimuth, so Ibar depends on omega only through its zenith cosine cos(Theta), and
the 2D trapezoid over (Theta, Phi) factors into one matrix over the view-zenith axis:
    M[i, j] = sum_a wT_a sin(Theta_a) K(i, a) P(a, j),
    K(i, a) = sum_b wP_b F(cos(Theta_a) mu_i + sin(Theta_a) sqrt(1 - mu_i^2) cos(Phi_b)),
with trapezoid weights wT (Theta in [0, pi]) and wP (Phi in [0, 2 pi]), and P the linear interpolation
in texture space from the view nodes to cos(Theta_a) (as the lookup does). Each row of K is rescaled
so that the discrete sphere integral of the phase is exactly 4 pi x its mean (energy conservation;
essential for sharp Mie peaks, |g| near 1, that the Theta steps cannot follow). M is computed once per grid,
quadrature and phase function; the gather is then a batched matrix product, so a fine quadrature
(default 256 x 128 nodes) costs nothing per order.

In the ``physical`` mode the first gather sees the single-scattered light with its own phase at the
true angle to the sun; averaged over the azimuth of V (the table has none), the Phi integrals of the
two phase functions separate:
    M_{s,s'}(z)[i, j] = sum_a wT_a sin(Theta_a) K_s(i, a) K_s'(z, a) / (2 pi) P(a, j),
where K_s'(z, a) is K of the second phase at the sun node z.

NumPy twins of the kernels: :func:`clsky.reference.gather` and :func:`clsky.reference.scatter`.
"""

from __future__ import annotations

import contextlib
import functools
import math

import numpy as np
import pyopencl.array as cla

from . import _atmosphere_cl, _cl
from .atmosphere import AtmosphereParameters
from .mapping import cos_to_v, grid_coordinates
from .phase import MIE_PHASES, PHASE_MEANS, RAYLEIGH_PHASES
from .settings import MAPPINGS, TableSettings, computed_sun_nodes
from .transmittance import COMMON_SOURCES, azimuth_defines, quadrature_defines

__all__ = ["keeping_first_gather_stacks", "gather_quadrature", "phase_azimuth_integrals", "gather_matrix", "gather_matrices",
           "first_gather_matrices", "first_gather_matrix", "first_gather_stack", "DIRECT_PAIRS",
           "CROSSED_PAIRS", "MultipleScatteringEngine", "SPECIES"]

SPECIES = ("rayleigh", "mie")
#: Rows and cells of the gather computed per work-item (-DGATHER_ROWS, -DGATHER_CELLS of kernels/multiple.cl).
GATHER_ROWS = 4
GATHER_CELLS = 4
#: Work-group of the gather (cell blocks, row blocks, sun nodes): PoCL's own choice for the default
#: animation's planned table (32 x 128 x 208: 8 x 32 x 208 work-items), fixed so that any table size
#: compiles one kernel object (:data:`clsky._cl.LINEAR_WORK_GROUP`). Side by side in one process, 5 to
#: 12 rounds, this AMD EPYC: as fast as PoCL's choices within the machine's noise (about 10 %) for that
#: table and the full default one (8 x 64 x 8 there); nor did 15 other shapes, 16 to 4096 work-items,
#: beat it beyond the noise (docs/speed-log.md).
GATHER_WORK_GROUP = (8, 8, 1)
#: Sun nodes per scatter work-item (-DSCATTER_SUN_NODES): a view ray's geometry, densities and
#: transmittances do not depend on the sun, so one work-item marches a ray once for this many sun nodes
#: (8: 12 % less CPU than 4 for the scatter reading one harmonic, 4 % for three, on PoCL; 16 gained 5 %
#: more for one harmonic, lost 3 % for three, and doubles the work-item's private sums).
SCATTER_SUN_NODES = 8
#: Work-group of the scatter kernel (altitude blocks, view rows, sun blocks). Explicit, because PoCL's own
#: choice (thousands of work-items) keeps every work-item's private sums in one work-group frame on a
#: worker thread's stack: SCATTER_SUN_NODES x 512 bytes each overflowed it (a crash). The view axis of
#: the launch is padded to a multiple of its rows; the kernel skips the padding.
SCATTER_WORK_GROUP = (1, 8, 1)


def gather_quadrature(theta_steps, phi_steps):
    """Trapezoid nodes and weights over Theta in [0, pi] and Phi in [0, 2 pi].

    Returns (theta, theta_weights, phi, phi_weights), each weight vector summing to pi and 2 pi.
    """
    theta = np.linspace(0.0, math.pi, theta_steps + 1)
    phi = np.linspace(0.0, 2.0 * math.pi, phi_steps + 1)
    theta_weights = np.full(theta_steps + 1, math.pi / theta_steps)
    phi_weights = np.full(phi_steps + 1, 2.0 * math.pi / phi_steps)
    theta_weights[[0, -1]] *= 0.5
    phi_weights[[0, -1]] *= 0.5
    return theta, theta_weights, phi, phi_weights


def _phase(atmosphere, species):
    if species == "rayleigh":
        return RAYLEIGH_PHASES[atmosphere.rayleigh_phase]
    return functools.partial(MIE_PHASES[atmosphere.mie_phase], g=atmosphere.mie_g)


def _gather_key(atmosphere: AtmosphereParameters):
    """The atmosphere as the gather matrices see it: its height (the grid's altitudes) and phase
    functions, nothing that depends on the wavelengths. Atmospheres that differ only in coefficients,
    wavelengths or sun (the batches of a spectral build, :mod:`clsky.spectrum`) share their cache entries."""
    return AtmosphereParameters(planet_radius=atmosphere.planet_radius, top_radius=atmosphere.top_radius,
                                rayleigh_scale_height=atmosphere.rayleigh_scale_height,
                                mie_scale_height=atmosphere.mie_scale_height,
                                rayleigh_scattering=(0.0, 0.0, 0.0), mie_scattering=0.0,
                                mie_g=atmosphere.mie_g, rayleigh_phase=atmosphere.rayleigh_phase,
                                mie_phase=atmosphere.mie_phase)


def phase_azimuth_integrals(phase, cosines, theta, phi, phi_weights):
    """K(i, a) = sum_b wP_b F(cos(Theta_a) c_i + sin(Theta_a) sqrt(1 - c_i^2) cos(Phi_b)).

    The azimuthal integral of a phase function between a direction of zenith cosine c_i and the
    directions (Theta_a, Phi_b); shape (len(cosines), len(theta)).
    """
    sines = np.sqrt(np.maximum(1.0 - cosines * cosines, 0.0))
    k = np.zeros((cosines.size, theta.size))
    for cos_phi, weight in zip(np.cos(phi), phi_weights):       # few hundred steps; each step is whole-array
        k += weight * phase(np.cos(theta) * cosines[:, None] + np.sin(theta) * sines[:, None] * cos_phi)
    return k


def interpolation_matrix(cosines, height, mapping):
    """P(a, j): weights of view nodes j in the linear (texture-space) interpolation at cosines[a]."""
    f = cos_to_v(cosines, mapping) * (height - 1)
    lower = np.clip(f.astype(np.int64), 0, height - 2)
    alpha = f - lower
    p = np.zeros((cosines.size, height))
    rows = np.arange(cosines.size)
    np.add.at(p, (rows, lower), 1.0 - alpha)
    np.add.at(p, (rows, lower + 1), alpha)
    return p


def _gather_parts(atmosphere: AtmosphereParameters, settings: TableSettings):
    return _gather_parts_cached(_gather_key(atmosphere), settings)


@functools.lru_cache(maxsize=4)
def _gather_parts_cached(atmosphere: AtmosphereParameters, settings: TableSettings):
    theta, theta_weights, phi, phi_weights = gather_quadrature(settings.gather_theta_steps,
                                                               settings.gather_phi_steps)
    _, cos_view, cos_sun = grid_coordinates(settings.size, atmosphere.atmosphere_height, settings.mapping,
                                            settings.sun_cos_range)
    p = interpolation_matrix(np.cos(theta), settings.size[1], settings.mapping)
    weights = theta_weights * np.sin(theta)
    view, sun = {}, {}
    for species in SPECIES:
        phase, mean = _phase(atmosphere, species), _phase_mean(atmosphere, species)
        for parts, cosines in ((view, cos_view), (sun, cos_sun)):
            k = phase_azimuth_integrals(phase, cosines, theta, phi, phi_weights)
            parts[species] = _read_only(_conserving(k, weights, mean))
    return _read_only(p), _read_only(weights), view, sun      # cached, shared: read-only


def _phase_mean(atmosphere, species):
    return PHASE_MEANS[atmosphere.rayleigh_phase if species == "rayleigh" else atmosphere.mie_phase]


def _conserving(k, weights, mean):
    """K with each row rescaled so that its sphere integral sum_a weights_a K(i, a) is exactly 4 pi x the
    phase's mean: the discrete gather then conserves energy (a uniform field gathers to 4 pi mean F).

    The trapezoid misses that integral by its leading error term, 6e-4 at the notes' g = -0.85, but by
    factors of 0.13 to 96 when the Mie peak (width ~ (1 - |g|) rad) is narrower than the Theta step
    (0.7 deg at 256 steps): at g = -0.999 the unscaled gather multiplied the light at every order.
    """
    integrals = k @ weights
    return k * (4.0 * math.pi * mean / integrals)[:, None]


def _read_only(array):
    array.flags.writeable = False
    return array


def gather_matrix(atmosphere: AtmosphereParameters, settings: TableSettings, species):
    """M (H, H) of one species' phase function: Gbar[:, j-axis] = M @ Ibar (see module docstring)."""
    p, weights, view, _ = _gather_parts(atmosphere, settings)
    with _cl.host_blas_single_threaded():
        return (view[species] * weights) @ p


def _quadrature_key(settings: TableSettings) -> TableSettings:
    """The settings the gather matrices depend on (grid, mapping, sun range, quadrature), others at
    defaults."""
    return TableSettings(size=settings.size, mapping=settings.mapping, gather_theta_steps=settings.gather_theta_steps,
                         gather_phi_steps=settings.gather_phi_steps, sun_cos_range=settings.sun_cos_range)


def gather_matrices(atmosphere, settings):
    """{species: M} for the Rayleigh and Mie phase functions (read-only, cached per grid and phase)."""
    return _gather_matrices(_gather_key(atmosphere), _quadrature_key(settings))


@functools.lru_cache(maxsize=8)
def _gather_matrices(atmosphere, settings):
    return {s: _read_only(gather_matrix(atmosphere, settings, s)) for s in SPECIES}


#: Species pairs (s, s') of the physical mode's first gather, as the two (2, D, H, H) stacks the gather
#: kernel takes: same species (Rayleigh, Mie), then crossed (Rayleigh seeing Mie, Mie seeing Rayleigh).
DIRECT_PAIRS = (("rayleigh", "rayleigh"), ("mie", "mie"))
CROSSED_PAIRS = (("rayleigh", "mie"), ("mie", "rayleigh"))
#: Sun nodes per matrix product in :func:`first_gather_matrix`: bounds its (nodes, H, Theta) temporary.
FIRST_GATHER_CHUNK = 16


def first_gather_matrix(atmosphere, settings, pair, out=None):
    """M_{s,s'} of shape (D, H, H) for one species pair (s, s') (module docstring).

    Computed FIRST_GATHER_CHUNK sun nodes at a time, into ``out`` if given (float64, (D, H, H)): the
    temporary of the product is (chunk, H, Theta + 1) instead of (D, H, Theta + 1). Each sun node's matrix
    is its own matrix product, so chunking changes no value; BLAS runs on one thread
    (:func:`clsky._cl.host_blas_single_threaded`: beside PoCL that is 6-10x less CPU time, same values).
    """
    p, weights, view, sun = _gather_parts(atmosphere, _quadrature_key(settings))
    species, other = pair
    depth, height = sun[other].shape[0], view[species].shape[0]
    out = np.empty((depth, height, p.shape[1])) if out is None else out
    factor = weights * sun[other] / (2.0 * math.pi)           # (D, Theta + 1)
    with _cl.host_blas_single_threaded():
        for start in range(0, depth, FIRST_GATHER_CHUNK):
            stop = min(start + FIRST_GATHER_CHUNK, depth)
            np.matmul(view[species][None] * factor[start:stop, None, :], p, out=out[start:stop])
    return out


def first_gather_stack(atmosphere, settings, pairs):
    """The (2, D, H, H) float64 stack of the first-gather matrices of two species pairs
    (:data:`DIRECT_PAIRS` or :data:`CROSSED_PAIRS`), as :meth:`MultipleScatteringEngine.gather` takes it.

    Not cached: 2 D H^2 x 8 bytes (0.87 GB at the high quality level's 32 x 256 x 414) is worth freeing
    once uploaded rather than keeping for a next build of the same grid; except inside
    :func:`keeping_first_gather_stacks`, which the batches of one spectral build share.
    """
    key = (_gather_key(atmosphere), _quadrature_key(settings), tuple(pairs))
    if _KEPT_STACKS is not None and key in _KEPT_STACKS:
        return _KEPT_STACKS[key]
    depth, height = settings.size[2], settings.size[1]
    stack = np.empty((2, depth, height, height))
    for index, pair in enumerate(pairs):
        first_gather_matrix(atmosphere, settings, pair, out=stack[index])
    if _KEPT_STACKS is not None:
        _KEPT_STACKS[key] = _read_only(stack)
    return stack


#: The first-gather stacks kept while :func:`keeping_first_gather_stacks` is active (else None).
_KEPT_STACKS = None


@contextlib.contextmanager
def keeping_first_gather_stacks():
    """Within this context, :func:`first_gather_stack` keeps its stacks (read-only) and returns the kept
    one for the same grid, quadrature and phase functions: the batches of a spectral build
    (:mod:`clsky.spectrum`) differ only in wavelengths, so they compute the physical mode's first gather
    once. The stacks are dropped on leaving (2 x 2 D H^2 x 8 bytes: 67 MB at the default 32 x 256 x 32).
    Not thread-safe, like the engines."""
    global _KEPT_STACKS
    outer = _KEPT_STACKS
    _KEPT_STACKS = {} if outer is None else outer
    try:
        yield
    finally:
        _KEPT_STACKS = outer


def first_gather_matrices(atmosphere, settings):
    """{(s, s'): M_{s,s'} of shape (D, H, H)}: the physical mode's first gather (module docstring).

    Not cached (4 D H^2 x 8 bytes); a build uses :func:`first_gather_stack`, one stack at a time.
    """
    return {pair: first_gather_matrix(atmosphere, settings, pair) for pair in DIRECT_PAIRS + CROSSED_PAIRS}


def _scatter_items(width, height, sun_nodes, vector_width):
    """The scatter kernel's work-items per axis: ``vector_width`` cells, one view row and SCATTER_SUN_NODES
    of the ``sun_nodes`` computed sun nodes per work-item (the launch rounds each axis up to
    SCATTER_WORK_GROUP, :func:`clsky._cl.launch_size`)."""
    return -(-width // vector_width), height, -(-sun_nodes // SCATTER_SUN_NODES)


class MultipleScatteringEngine(_cl.Engine):
    """Applies gather matrices and scatters gathered tables along view rays (``kernels/multiple.cl``).

    Parameters
    ----------
    settings : TableSettings
        Its view_steps, sampling and dtype are compiled in.
    ctx, profile, fast_math, queue, allocator
        See :class:`clsky._cl.Engine`.
    features : sequence of str, optional
        The compile-time features (:func:`clsky._atmosphere_cl.feature_defines`) of the atmosphere that
        it will scatter in. Its gathers, sums and copies read none, but take their kernels from the program
        built with them, so that an engine scattering in that atmosphere builds one program, not a plain one
        as well (two of the default animation's builds, 36 and 66 ms of its main thread; docs/speed-log.md).
        Any value is correct: ``scatter`` builds the variant of the atmosphere it is given.
    """

    def __init__(self, settings: TableSettings = TableSettings(), ctx=None, profile=False, fast_math=False,
                 queue=None, allocator=None, features=()):
        self.settings = settings.scatter_settings           # its view steps are those of the scatter
        self.features = tuple(features)
        super().__init__(ctx, np.dtype(settings.dtype), profile, fast_math, queue, allocator)

    def _featureless_kernels(self):
        """The kernels that read no compile-time feature (gather, combine_nodes, pack_channels, add_into,
        fill_between_suns), from the program built with this engine's ``features``."""
        return self.kernels_with(self.features)

    def program_sources(self):
        declaration = _atmosphere_cl.declaration(self.ctx.devices[0], self.dtype)
        return ("real.cl", declaration) + COMMON_SOURCES[1:] + ("mapping.cl", "view_ray.cl", "multiple.cl")

    def build_options(self):
        return (super().build_options() + quadrature_defines(self.settings, self.vector_width)
                + [f"-DGATHER_ROWS={GATHER_ROWS}", f"-DGATHER_CELLS={GATHER_CELLS}",
                   f"-DSCATTER_SUN_NODES={SCATTER_SUN_NODES}"] + azimuth_defines(self.settings))

    def to_device(self, table):
        """A host table (D, H, W, 6) as a padded device table (D, H, W, 8) (channels 6, 7 zero)."""
        table = np.asarray(table)
        if table.ndim != 4 or table.shape[3] != 6:
            raise ValueError(f"table must have shape (D, H, W, 6), got {table.shape}")
        return _cl.upload_padded(self.queue, table, self.dtype, allocator=self.allocator)

    def upload_matrices(self, matrices):
        """Gather matrices on the device, to reuse across orders."""
        return cla.to_device(self.queue, np.ascontiguousarray(matrices, dtype=self.dtype), allocator=self.allocator)

    def _check_out(self, out, shape, node):
        """ValueError unless ``out`` is a padded device table of ``shape`` (D, H, W, 8) and this engine's
        dtype, or a stack (N,) + ``shape`` of them with 0 <= ``node`` < N (the slab written; 0 for a table)."""
        if (out.shape[-4:] != tuple(shape) or out.ndim not in (4, 5) or out.dtype != self.dtype
                or not 0 <= node < (out.shape[0] if out.ndim == 5 else 1)):
            raise ValueError(f"out must be a padded {self.dtype} table {tuple(shape)} or a stack (N,) + "
                             f"{tuple(shape)} with node < N, got {out.dtype} {out.shape} and node {node}")

    def gather(self, matrices, table, out=None, accumulate=False, node=0):
        """out[z, i, x, c] (+)= sum_j M[c // 3][(z,) i, j] table[z, j, x, c].

        Parameters
        ----------
        matrices : array (2, H, H) or (2, D, H, H), host or device (:meth:`upload_matrices`)
            Rayleigh and Mie gather matrices (optionally one per sun node).
        table : host array (D, H, W, 6) or padded device array (D, H, W, 8)
        out : padded device array (D, H, W, 8) or (N, D, H, W, 8), optional
            Of the second shape, its slab ``node`` receives the result (the harmonics of
            :mod:`clsky.azimuth`, gathered into one stack without a copy each).
        accumulate : bool
            Add to ``out`` instead of overwriting it.

        Returns the padded device array ``out``.
        """
        table_d = table if isinstance(table, cla.Array) else self.to_device(table)
        depth, height, width, _ = table_d.shape
        if not isinstance(matrices, cla.Array):
            matrices = np.asarray(matrices)
        if matrices.shape not in ((2, height, height), (2, depth, height, height)):
            raise ValueError(f"matrices must have shape (2, H, H) or (2, D, H, H) with D, H = {depth}, "
                             f"{height}, got {matrices.shape}")
        matrices_d = matrices if isinstance(matrices, cla.Array) else self.upload_matrices(matrices)
        if out is None:
            out = cla.empty(self.queue, table_d.shape, self.dtype, allocator=self.allocator)
            accumulate = False
        else:
            self._check_out(out, table_d.shape, node)
        per_node = matrices.ndim == 4
        kernel = self._featureless_kernels()["gather"]
        groups = (-(-width // GATHER_CELLS), -(-height // GATHER_ROWS), depth)
        event = kernel(
            self.queue, *_cl.launch_size(kernel, self.device, groups, GATHER_WORK_GROUP), matrices_d.data,
            np.int32(matrices.size // 2), np.int32(height * height if per_node else 0), table_d.data,
            out.data, np.uint64(node * table_d.size), np.int32(accumulate), np.int32(width), np.int32(height),
            np.int32(depth))
        self._record("gather", event)
        return out

    def scatter(self, atmosphere: AtmosphereParameters, gathered, combine_species=False, ground_radiance=None,
                cos_azimuth=1.0, out=None, node=0, sun_stride=1):
        """Next order from a gathered table, as a padded device array (D, H, W, 8): ``out`` if given,
        a padded device array (N, D, H, W, 8) whose slab ``node`` receives it (the nodes of
        :mod:`clsky.azimuth`), else a new one.

        ``sun_stride`` 2 computes every other sun node and the last, and fills the nodes between with
        the geometric mean of their neighbours (``TableSettings.orders_sun_stride``; kernels/multiple.cl:
        scatter, fill_between_suns); 1 (default) computes every node.

        With ``combine_species`` (physical mode) channels 0-2 and 3-5 both hold Rayleigh + Mie. With a
        reflecting ground (``atmosphere.has_ground``, which needs ``combine_species``), rays that end on
        the ground add T L_g, ``ground_radiance`` (D, 3) the ground's radiance per sun node
        (:mod:`clsky.ground`). With ``settings.azimuth_harmonics`` = M > 0, ``gathered`` is the padded
        device array (M + 1, D, H, W, 8) of the harmonics and ``cos_azimuth`` the cells' view-sun azimuth
        (:mod:`clsky.azimuth`).
        """
        from .ground import padded4

        gathered_d = gathered if isinstance(gathered, cla.Array) else self.to_device(gathered)
        depth, height, width, _ = gathered_d.shape[-4:]
        computed = len(computed_sun_nodes(depth, sun_stride))       # checks the stride: 1 or 2
        if atmosphere.has_ground:
            if not combine_species:
                raise ValueError("a reflecting ground (ground_albedo > 0) needs combine_species (mode 'physical')")
            ground = np.asarray(ground_radiance, dtype=np.float64) if ground_radiance is not None else None
            if ground is None or ground.shape != (depth, 3):
                raise ValueError(f"ground_radiance must have shape (D, 3) = ({depth}, 3), got "
                                 f"{None if ground is None else ground.shape}")
            ground_d = cla.to_device(self.queue, padded4(ground, self.dtype), allocator=self.allocator)
        else:
            ground_d = cla.zeros(self.queue, 4, self.dtype, allocator=self.allocator)   # not read without -DGROUND
        if out is None:
            out = cla.empty(self.queue, (depth, height, width, 8), self.dtype, allocator=self.allocator)
        else:
            self._check_out(out, (depth, height, width, 8), node)
        atmosphere_d = _atmosphere_cl.to_device(self.queue, atmosphere, self.dtype)
        kernel = self.kernels_with(_atmosphere_cl.feature_defines(atmosphere))["scatter"]
        offset = np.uint64(node * depth * height * width)
        items = _scatter_items(width, height, computed, self.vector_width)
        event = kernel(
            self.queue, *_cl.launch_size(kernel, self.device, items, SCATTER_WORK_GROUP),
            atmosphere_d, np.int32(width),
            np.int32(height), np.int32(depth), np.int32(MAPPINGS[self.settings.mapping]),
            self.real2(self.settings.sun_w_range), np.int32(bool(combine_species)), self.real(cos_azimuth),
            gathered_d.data, ground_d.data, out.data, offset, np.int32(sun_stride))
        self._record("scatter", event)
        between = (depth - computed) * height * width            # the cells of the nodes between computed ones
        if between:
            fill = self._featureless_kernels()["fill_between_suns"]
            event = fill(self.queue, *self._linear_size(fill, between), out.data, offset, np.int32(depth),
                         np.uint64(height * width))
            self._record("fill_between_suns", event)
        out.add_event(event)
        return out

    def combine_nodes(self, nodes, weights, out):
        """out = sum_n weights[n] nodes[n]: the padded device tables (N, D, H, W, 8) ``nodes`` combined
        into the padded device table ``out`` (D, H, W, 8) (an azimuth harmonic of an order's nodes,
        :mod:`clsky.azimuth`; kernels/multiple.cl: combine_nodes).

        ``weights`` (N,) on the host, or already on the device (:meth:`upload_matrices`): a host array is
        uploaded with a blocking copy, which waits for every command before it on the queue; weights
        uploaded once let the caller enqueue a whole chain of gathers and go on with its own work."""
        if not isinstance(weights, cla.Array):
            weights = np.ascontiguousarray(weights, dtype=self.dtype)
        cells = out.size // 8
        if (weights.shape != (nodes.shape[0],) or weights.dtype != self.dtype or nodes.shape[1:] != out.shape
                or out.shape[-1] != 8):
            raise ValueError(f"nodes (N, D, H, W, 8), weights (N,) and out (D, H, W, 8) must agree, got "
                             f"{nodes.shape}, {weights.shape} and {out.shape}")
        weights_d = weights if isinstance(weights, cla.Array) else cla.to_device(self.queue, weights,
                                                                                 allocator=self.allocator)
        kernel = self._featureless_kernels()["combine_nodes"]
        event = kernel(self.queue, *self._linear_size(kernel, cells), nodes.data, weights_d.data,
                       np.int32(weights.size), np.uint64(cells), self.real(1.0), self.real(0.0), out.data)
        self._record("combine_nodes", event)
        return out

    def pack_channels(self, padded, channels, out):
        """out = padded[..., :channels] as one contiguous device array (kernels/multiple.cl: pack_channels):
        the padded device table ``padded`` (..., 8) and ``out`` (..., channels) of the same leading shape,
        1 <= channels <= 8. Returns the kernel's event (``out`` is ready once it completes), for a read on
        another queue to wait for."""
        if (padded.shape[-1] != 8 or out.shape != padded.shape[:-1] + (channels,) or not 1 <= channels <= 8
                or out.dtype != self.dtype or padded.dtype != self.dtype or not padded.flags.c_contiguous
                or not out.flags.c_contiguous):
            raise ValueError(f"padded (..., 8) and out (..., channels) must agree, 1 <= channels <= 8, in "
                             f"{self.dtype}, C-contiguous; got {padded.shape} {padded.dtype}, {out.shape} {out.dtype}")
        rows = padded.size // 8
        kernel = self._featureless_kernels()["pack_channels"]
        event = kernel(self.queue, *self._linear_size(kernel, rows), padded.data, np.uint64(rows), np.int32(channels),
                       out.data)
        self._record("pack_channels", event)
        return event

    def add_into(self, total, addend, scale=None, slabs=None):
        """total += addend, padded device tables of one shape (kernels/multiple.cl: add_into); with
        ``scale`` (r, g, b), total += scale[c % 3] addend on channel c < 6 (the orders' geometric tail:
        both species' channels of a wavelength scale alike); with ``slabs``, only in the first that many
        slabs of stacks (N, D, H, W, 8) (clsky.azimuth: an order's gathered azimuth average, the first
        harmonic, into the gathered sum's)."""
        if total.shape != addend.shape or total.shape[-1] != 8:
            raise ValueError(f"total and addend must be padded tables (..., 8) of one shape, got {total.shape} "
                             f"and {addend.shape}")
        if slabs is not None and not (total.ndim == 5 and 1 <= slabs <= total.shape[0]):
            raise ValueError(f"slabs must be in [1, N] for stacks (N, D, H, W, 8), got {slabs} for {total.shape}")
        scale = np.ones(8) if scale is None else np.concatenate([scale, scale, [0.0, 0.0]])
        cells = (total.size if slabs is None else total.size // total.shape[0] * slabs) // 8
        kernel = self._featureless_kernels()["add_into"]
        event = kernel(self.queue, *self._linear_size(kernel, cells), total.data, addend.data, np.uint64(cells),
                       self.real(1.0), self.real8(scale))
        self._record("add_into", event)
        return total
