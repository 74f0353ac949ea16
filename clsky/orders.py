"""The host orchestrator: single scattering, then the orders k = 2, 3, ... until they converge.

Two schemes (``TableSettings.mode``):

``atmosphere-plus``
    The notes' factored scheme exactly: the Rayleigh and Mie chains stay apart,
    Gbar_s^(k) = Integral F_s(dot(omega, V)) Ibar_s^(k) d omega and
    Ibar_s^(k+1) = beta_s / (4 pi) Integral Gbar_s^(k) rho_s T ds; the renderer applies the phase of the
    first event, F_s(cos theta), to the sum over all orders. Approximations (from the notes): no
    azimuth, no Rayleigh <-> Mie cross terms, the first event's phase applied to every order.

``physical``
    A consistent scheme on the same grid. The radiance of order k arriving from omega is gathered by
    both species, each with its own phase: Gbar_s^(k) = Integral F_s(dot(omega, V)) L^(k)(omega) d omega
    and L^(k+1) = sum_s beta_s / (4 pi) Integral Gbar_s^(k) rho_s T ds. For k = 1, L^(1) carries the exact
    phase to the sun, F_R(nu) Ibar_R^(1) + F_M(nu) Ibar_M^(1); the orders k >= 2 are stored with their
    phase applied (3 channels, r, g, b) and averaged over the azimuth between view and sun, while single
    scattering stays factored so that the renderer applies its exact phase. Remaining approximations:
    (1) the table has no azimuth: higher orders are azimuth averages, and every order is computed in
    the canonical frame (sun and view in one vertical plane) along the ray (too bright at dusk: README,
    "Twilight against Monte Carlo"), unless ``settings.azimuth_harmonics`` > 0, where the orders carry
    a cosine series in the azimuth (:mod:`clsky.azimuth`, which this function hands the build to); (2) the ground is black
    unless ``atmosphere.ground_albedo`` > 0: then a Lambertian ground reflects a / pi of the irradiance
    of every order into the next one (:mod:`clsky.ground`; physical mode only); (3) quadrature and
    interpolation errors of the grid (view/sun steps, trilinear lookups).

Stopping rule of ``orders="auto"``: after each order k >= 2, for every channel c, the *bright part* is
the set of cells whose running sum S_c is at least :data:`BRIGHT_FRACTION` (1 %) of its maximum over
the table; the order's relative addition is max over channels and bright cells of A_c / S_c, where A
is what order k added. The iteration stops when the order's estimated error (its relative addition,
or with the geometric tail below, the tail's estimated error) falls below ``order_tolerance``
(converged), when ``max_orders`` orders have been computed (not converged: reported so), or when two
successive orders (from the fourth on) each carry more light than the one before (diverging: a
numerical artefact of a view-ray quadrature too coarse for the atmosphere's optical depth; reported
so). In the physical mode the running sum per wavelength is
Ibar_R^(1) + Ibar_M^(1) + sum_{k>=2} L^(k) (single scattering counted with phase 1, its mean over the
sphere).

Geometric tail (``orders="auto"``, from the third order on). Each order is the previous one through
the same linear operator (gather, then scatter), so the orders approach its dominant eigenvector and
their light shrinks by a constant ratio per order, as in a power iteration: per wavelength,
r = (light of order k) / (light of order k - 1) (:func:`_total`, :func:`geometric_ratio`). Measured on
the default animation's table (32 x 256 x 208, two azimuth harmonics), r settles to 4 digits from the
sixth order on (0.1359, 0.2449, 0.2893 for r, g, b). The orders after K then sum to about
L^(K) r / (1 - r) (:func:`tail_factor`), which the result adds: to the table, to the gathered source
of the ray march (G^(K+1) / (1 - r), the next order's source gathered exactly) and to the ground's
irradiance (E_K r / (1 - r)). Where a cell's own ratio is still r + d, the tail is off by about
L^(K) d / (1 - r)^2 ~ r L^(K-1) d / (1 - r)^2, while |L^(K) - r L^(K-1)| = L^(K-1) |d|; so the
order's estimated error tested against the tolerance is then |L^(k) - r L^(k-1)| / (1 - r)^2 over S
(1 / r times the error above: a margin for cells whose ratio settles slowly) instead of L^(k) / S
(:func:`relative_addition` with ``previous`` and ``ratio``). The tolerance then bounds the result's
error as estimated, where the plain sum's stopping rule bounds the size of the last order: the plain
sum's error is the orders left out, about L^(K) r / (1 - r), 0.4x its last relative addition at
r = 0.29 and 8x at r = 0.89 (an optically thick atmosphere). Measured against 16 orders on the
default animation's table: the plain sum stopped at order 10 was off by 2.3e-5 in the bright part and
1.8e-4 in the worst cell; with the tail the iteration stops at order 7, 2.1e-5 and 8.0e-4 (the worst
cells are dark ones, where the ratio settles last). The default level's table for preset("physical")
(sun from -90 deg, no harmonics), where the cells' ratios settle more slowly, stops at order 9
instead of 10. On the thick test atmosphere (tests/test_multiple.py) the tail's 68 orders are within
7.8e-5 where the plain sum's 72 were 8.0e-4 off. No tail where some
r is not in (0, 1), at ``max_orders`` (no next source gathered there), or for a fixed ``orders``:
those results are the plain sum of the orders computed.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import time
from typing import Callable

import numpy as np
import pyopencl as cl

from . import _atmosphere_cl, _cl
from .atmosphere import AtmosphereParameters
from .errors import NumericalError
from .multiple import CROSSED_PAIRS, DIRECT_PAIRS, SPECIES, first_gather_stack, gather_matrices
from .settings import TableSettings

__all__ = ["OrdersResult", "compute_orders", "BRIGHT_FRACTION", "relative_addition", "check_finite",
           "geometric_ratio", "tail_factor", "SUN_STRIDE_FROM_ORDER", "scatter_sun_stride"]

#: Cells whose running sum reaches this fraction of the channel's maximum form the "bright part".
BRIGHT_FRACTION = 1e-2

#: The first order whose scatter computes the sun nodes as ``TableSettings.orders_sun_stride`` says (both
#: orders loops, this module's and :mod:`clsky.azimuth`'s). Order 2, a fifth to a third of the light, stays
#: on every node: interpolated linearly along the sun axis from every other node it moved the default
#: animation's table six times more than the orders k >= 3 did (8.4e-4 against 1.4e-4 at the bright cells'
#: 95th percentile; 1.1e-4 for those interpolated in the logarithm, as the fill does: docs/speed-log.md).
SUN_STRIDE_FROM_ORDER = 3


def scatter_sun_stride(settings, k) -> int:
    """The sun stride of order k's scatter: ``settings.orders_sun_stride`` from order
    :data:`SUN_STRIDE_FROM_ORDER` on, else 1 (every sun node)."""
    return settings.orders_sun_stride if k >= SUN_STRIDE_FROM_ORDER else 1


@dataclasses.dataclass
class OrdersResult:
    """Every order's table, their combination, and the record of the iteration.

    Attributes
    ----------
    orders : list of numpy.ndarray
        orders[0] is single scattering (D, H, W, 6), factored. Later orders: (D, H, W, 6) factored
        (atmosphere-plus) or (D, H, W, 3) with the phase applied (physical).
    record : dict
        mode, tolerance, max_orders, converged, reason, per order (k >= 2) the relative additions and
        the estimated errors (what the stopping rule tested: with the geometric tail's ratio, its
        estimated error, else the relative addition), shares, the tail's ratio ``tail_ratio`` (r, g, b;
        None without a tail), seconds.
    gathered : numpy.ndarray (D, H, W, 6) or None
        Sum of the gathered in-scatter tables Gbar_s^(k) (Rayleigh r, g, b, Mie r, g, b) whose
        scatter produced the orders 2..K: the per-pixel ray march integrates it along the true ray
        to add the higher orders. None for single scattering only.
    ground_irradiance : numpy.ndarray (D, 3) or None
        With a reflecting ground: E_sky = sum_{k >= 1} E_k, the sky's irradiance on the ground per
        sun node [units of I_I] (:mod:`clsky.ground`), for the ray march. None for a black ground.
    tail : numpy.ndarray (3,) or None
        The geometric tail's factor r / (1 - r) per wavelength (module docstring; the record's
        ``tail_ratio`` is r), or None (no tail).
        ``gathered`` and ``ground_irradiance`` already hold their tails; :meth:`combined` adds the
        table's, ``tail`` times the last order.
    """

    orders: list
    record: dict
    gathered: np.ndarray | None = None
    ground_irradiance: np.ndarray | None = None
    tail: np.ndarray | None = None

    def combined(self, mode):
        """The table's channels: factored sum (atmosphere-plus), or single + sum of higher orders, with
        the geometric tail when there is one."""
        tables = list(self.orders)
        if self.tail is not None:
            tables.append(self.orders[-1] * per_channel(self.tail, self.orders[-1].shape[-1]))
        if mode == "atmosphere-plus":
            return _sum_in_order(tables)
        if len(tables) == 1:
            return tables[0]
        return np.concatenate([tables[0], _sum_in_order(tables[1:])], axis=-1)


def _sum_in_order(tables):
    """tables[0] + tables[1] + ... added one after the other, into one new array.

    The same sums, in the same order, as ``np.sum(tables, axis=0)`` (a reduction over the outer axis
    adds slice by slice), without that call's stacked copy of every table (K x the table's bytes).
    """
    total = np.array(tables[0], dtype=np.float64)
    for table in tables[1:]:
        total += table
    return total


#: Cells per block of the stopping test and the finiteness check (:func:`relative_addition`,
#: :func:`check_finite`): their temporary arrays (a ratio per value, masks) then stay small (about
#: 1.5 MB), and the allocator reuses them from block to block and order to order. As whole-table
#: temporaries (over 100 MB each for the default animation's table) they came as fresh pages, which the
#: kernel clears on first touch: about 0.7 ns a byte on the development machines, some 1.5 CPU-s of that
#: table's build.
BLOCK_CELLS = 1 << 16


def _cell_blocks(*tables):
    """Blocks of at most :data:`BLOCK_CELLS` cells (rows of the last axis) of tables of one shape, as
    2D views (cells, channels), in order."""
    flats = [table.reshape(-1, table.shape[-1]) for table in tables]
    for start in range(0, flats[0].shape[0], BLOCK_CELLS):
        yield tuple(flat[start:start + BLOCK_CELLS] for flat in flats)


def relative_addition(added, running_sum, previous=None, ratio=None):
    """max over channels and bright cells of added / running_sum (see module docstring); with
    ``previous`` (the order before ``added``, same shape) and the geometric ``ratio`` (r, g, b), of
    |added - r previous| / (1 - r)^2 / running_sum: the estimated error of the sum extrapolated by
    the geometric tail (module docstring)."""
    flat = running_sum.reshape(-1, running_sum.shape[-1])
    # each channel's maximum over one strided column: the same values as flat.max(axis=0), which NumPy
    # runs as a reduction over rows of 3 or 6 and took 20x longer (7 ms per order at 32 x 256 x 32)
    threshold = BRIGHT_FRACTION * np.array([flat[:, channel].max() for channel in range(flat.shape[1])])
    if ratio is not None:
        r = per_channel(ratio, flat.shape[1])
        squared_complement = (1.0 - r) ** 2
    # per block, the ratios of its bright cells (0 elsewhere: every ratio is >= 0); the largest of the
    # blocks' maxima is the maximum over the table (max is exact in any grouping; a NaN carries through)
    maxima = []
    for added_block, sum_block, *previous_block in _cell_blocks(added, running_sum,
                                                                *(() if ratio is None else (previous,))):
        bright = (sum_block >= threshold) & (sum_block > 0)
        if bright.any():
            if ratio is not None:
                # |added - r previous| / (1 - r)^2, the same operations in one temporary (half the time of
                # a fresh array per operation: 0.10 against 0.20 s per order of the default animation's table)
                estimate = np.multiply(r, previous_block[0])
                np.subtract(added_block, estimate, out=estimate)
                np.abs(estimate, out=estimate)
                np.divide(estimate, squared_complement, out=estimate)
                added_block = estimate
            maxima.append(np.divide(added_block, sum_block, out=np.zeros(sum_block.shape), where=bright).max())
    return float(np.max(maxima)) if maxima else 0.0


def per_channel(per_wavelength, channels):
    """Values (r, g, b) per channel of a table with ``channels`` channels: 3 (one per wavelength) or 6
    (Rayleigh r, g, b, Mie r, g, b: both species of a wavelength alike)."""
    per_wavelength = np.asarray(per_wavelength, dtype=np.float64)
    return per_wavelength if channels == 3 else np.tile(per_wavelength, channels // 3)


def species_sum(table):
    """Rayleigh + Mie per wavelength (..., 3) of a factored table (..., 6): ``table[..., :3] + table[..., 3:]``,
    summed a wavelength at a time. The same sums, but NumPy runs the slices' sum as a loop of 3 values
    a cell (15-21 against 7-9 ms for a node of the default animation's table, single scattering's
    running sum for the stopping test, on the host's path to the first scatter with the device idle).
    ValueError unless the table's last axis has 6 channels."""
    table = np.asarray(table)
    if table.ndim == 0 or table.shape[-1] != 6:
        raise ValueError(f"species_sum: table must have shape (..., 6), got {table.shape}")
    out = np.empty(table.shape[:-1] + (3,), dtype=table.dtype)
    cells, sums = table.reshape(-1, 6), out.reshape(-1, 3)
    for channel in range(3):
        np.add(cells[:, channel], cells[:, 3 + channel], out=sums[:, channel])
    return out


def geometric_ratio(totals):
    """The ratio r (r, g, b) of the last order's light to the one before's, from the orders' light
    ``totals`` (:func:`_total`, single scattering first), once the last two are higher orders (k >= 3);
    None before, or where some r is not in (0, 1) (no geometric tail: module docstring)."""
    if len(totals) < 3:
        return None
    previous = np.asarray(totals[-2], dtype=np.float64)
    ratio = np.divide(totals[-1], previous, out=np.full(previous.shape, np.inf), where=previous > 0)
    return ratio if np.all((ratio > 0) & (ratio < 1)) else None


def tail_factor(ratio):
    """r / (1 - r): the orders after the last one, sum_{j >= 1} r^j, in units of the last one."""
    return ratio / (1.0 - ratio)


def check_finite(order, k, atmosphere, settings, total=None):
    """``order`` (the table of order k) if all its values are finite; NumericalError otherwise (a
    table with NaN is never returned, saved, or called converged).

    ``total``: the order's :func:`_total`, where the caller has it. Finite, it proves every value finite
    (a NaN or an infinity among the values makes their sum NaN or infinite), and the pass over the order
    is skipped (10 ms an order of the default animation's table, on the build's critical path); otherwise
    (a NaN, an infinity, or a sum of finite values that overflows) the values are checked one by one."""
    if total is not None and np.isfinite(total).all():
        return order
    if not all(np.isfinite(block).all() for (block,) in _cell_blocks(order)):
        raise NumericalError(f"order {k} of the table has {100 * (1 - np.isfinite(order).mean()):.3g} % non-finite "
                             f"values ({settings.dtype}, planet radius {atmosphere.planet_radius:g} m, atmosphere "
                             f"{atmosphere.atmosphere_height:g} m): the numerics do not hold for these parameters")
    return order


def compute_orders(atmosphere: AtmosphereParameters, settings: TableSettings, backend="opencl", ctx=None,
                   fast_math=False, progress: Callable[[str, int, int], None] | None = None) -> OrdersResult:
    """Single scattering and the higher orders (see module docstring).

    Parameters
    ----------
    atmosphere : AtmosphereParameters
    settings : TableSettings
        ``mode``, ``orders``, ``order_tolerance``, ``max_orders`` and the gather quadrature matter here.
    backend : {'opencl', 'numpy'}
    progress : callable, optional
        ``progress(stage, done, total)``: stage 'single' with slabs, then 'orders' with orders done.

    Raises
    ------
    ValueError
        (:class:`clsky.errors.ParameterError`) for an atmosphere the kernels of ``settings.dtype``
        cannot resolve (:meth:`AtmosphereParameters.check_dtype`), or a reflecting ground with the
        atmosphere-plus mode (:func:`clsky.ground.check_ground_mode`).
    clsky.errors.NumericalError
        If an order comes out with non-finite values.
    """
    from . import ground

    start = time.perf_counter()
    atmosphere.check_dtype(settings.dtype)
    ground.check_ground_mode(atmosphere, settings.mode)
    if backend not in ("opencl", "numpy"):
        raise ValueError(f"backend must be one of ['opencl', 'numpy'], got {backend!r}")
    if settings.azimuth_harmonics:     # the higher orders carry azimuth (clsky/azimuth.py)
        from . import azimuth

        return azimuth.orders_result(atmosphere, settings, backend, ctx, fast_math, progress)
    if backend == "opencl":
        from .multiple import MultipleScatteringEngine
        from .single import SingleScatteringEngine

        single_engine = SingleScatteringEngine(settings, ctx=ctx, fast_math=fast_math)
        queue = cl.CommandQueue(single_engine.ctx)
        # the orders' tables reuse the buffers of the orders before (clsky._cl.memory_pool); a buffer goes
        # back to the pool when dropped, and the download of the copy queue that reads it has been waited
        # for by then (on_host) or is followed by no new array before that wait
        engine = MultipleScatteringEngine(settings, fast_math=fast_math, queue=queue,
                                          allocator=_cl.memory_pool(queue),
                                          features=_atmosphere_cl.feature_defines(atmosphere))
        # its program built on a host thread while single scattering runs, not at the first gather (in a fresh
        # process 40 ms of the main thread, the device idle: clsky.azimuth's _opencl_backend does the same)
        with concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="clsky-orders-setup") as builder:
            built = builder.submit(engine.kernels_with, engine.features)
            single = single_engine.compute(atmosphere, progress=None if progress is None else
                                           (lambda done, total: progress("single", done, total)))
            built.result()                      # re-raises a build's error
        device = _cl.describe_device(single_engine.device)

        def gather(terms, out=None):
            for matrices, table in terms:
                out = engine.gather(matrices, table, out=out, accumulate=out is not None)
            return out

        def to_host(gathered):
            return gathered.get()[..., :6].astype(np.float64)

        def accumulate(total, gathered, scale=None):
            """total + gathered (in place in total; gathered itself for total None, not a copy: the orders
            after it add into its buffer after its scatter on the queue), as azimuth.py's; with ``scale``
            (r, g, b), total + scale gathered per wavelength."""
            return gathered if total is None else engine.add_into(total, gathered, scale)

        kept = 3 if settings.mode == "physical" else 6    # channels of an order kept on the host

        upload = engine.upload_matrices
        copy_queue = cl.CommandQueue(engine.ctx)     # copies to the host overlap the next gather

        def scatter(gathered, ground_radiance, sun_stride):
            """The new order on the device, and a callable returning it on the host once copied."""
            new_d = engine.scatter(atmosphere, gathered, combine_species=settings.mode == "physical",
                                   ground_radiance=ground_radiance, sun_stride=sun_stride)
            host = np.empty(new_d.shape, dtype=new_d.dtype)
            copied = cl.enqueue_copy(copy_queue, host, new_d.data, wait_for=new_d.events, is_blocking=False)

            def on_host():
                copied.wait()
                return host[..., :kept].astype(np.float64)     # a copy: the padded buffer is dropped

            return new_d, on_host
    else:
        from . import reference

        single = reference.single_scattering(atmosphere, settings)
        device = "numpy"
        if progress is not None:
            progress("single", 1, 1)

        def gather(terms, out=None):
            for matrices, table in terms:
                term = reference.gather(matrices, table)
                out = term if out is None else out + term
            return out

        def to_host(gathered):
            return gathered

        def accumulate(total, gathered, scale=None):
            if total is None:
                return gathered.copy()
            total += gathered if scale is None else gathered * per_channel(scale, gathered.shape[-1])
            return total

        def upload(matrices):
            return matrices

        def scatter(gathered, ground_radiance, sun_stride):
            # the physical mode's species combined before the nodes between are filled, as the kernel does
            combined = settings.mode == "physical"
            new = reference.scatter(atmosphere, settings, gathered, combined, ground_radiance, sun_stride)
            if combined:
                return new, lambda: np.ascontiguousarray(new[..., :3])
            return new, lambda: new

    totals = [_total(single)]
    orders = [check_finite(single, 1, atmosphere, settings, totals[0])]
    ground_sky = pending_ground = None      # E_1 + ... + E_k so far, and a / pi of what is not yet scattered
    if atmosphere.has_ground:
        ground_sky = ground.sky_irradiance(atmosphere, settings, single, factored=True)
        pending_ground = ground.reflected_radiance(atmosphere, ground.direct_irradiance(atmosphere, settings)
                                                   + ground_sky)
    gathered_sum = tail = None
    additions, errors, converged, reason = [], [], False, "orders=1: single scattering only"
    wanted = settings.max_orders if settings.orders == "auto" else settings.orders
    if wanted > 1:
        per_species = gather_matrices(atmosphere, settings)
        same_species = upload(np.stack([per_species[s] for s in SPECIES]))  # (2, H, H): channel c -> c // 3
        if settings.mode == "physical":
            # one (2, D, H, H) stack of per-sun-node matrices at a time on the host, dropped once on the
            # device; the swapped single scattering lives only for its term
            gathered = gather([(upload(first_gather_stack(atmosphere, settings, DIRECT_PAIRS)), single)])
            gathered = gather([(upload(first_gather_stack(atmosphere, settings, CROSSED_PAIRS)),
                                np.concatenate([single[..., 3:], single[..., :3]], axis=-1))], out=gathered)
            running = species_sum(single)
        else:
            gathered = gather([(same_species, single)])
            running = single.copy()
        for k in range(2, wanted + 1):
            gathered_sum = accumulate(gathered_sum, gathered)
            next_input, on_host = scatter(gathered, pending_ground, scatter_sun_stride(settings, k))
            del gathered                  # summed and scattered: its (D, H, W, 8) buffer may go
            # gather the next order from the new one where it is (on the device for OpenCL) before
            # looking at it on the host, so that the copy and the stopping test overlap that work
            # (wasted once, when this order turns out to be the last)
            if k < wanted:
                gathered = gather([(same_species, next_input)])
            del next_input                # gathered: only its host copy is read from here on
            new = on_host()
            del on_host                   # and the padded download buffer behind that copy
            totals.append(_total(new))
            orders.append(check_finite(new, k, atmosphere, settings, totals[-1]))
            if ground_sky is not None:     # what order k lights the ground with joins order k + 1
                sky = ground.sky_irradiance(atmosphere, settings, new, factored=False)
                ground_sky = ground_sky + sky
                pending_ground = ground.reflected_radiance(atmosphere, sky)
            running += new
            additions.append(relative_addition(new, running))
            # the geometric tail's ratio, where it can apply (module docstring; it adds G^(k+1), gathered
            # only below the last allowed order)
            ratio = geometric_ratio(totals) if settings.orders == "auto" and k < wanted else None
            errors.append(additions[-1] if ratio is None else
                           relative_addition(new, running, previous=orders[-2], ratio=ratio))
            if _diverging(totals):
                reason = diverging_reason(k)
                break
            if progress is not None:
                progress("orders", k, wanted)
            if settings.orders == "auto" and errors[-1] < settings.order_tolerance:
                converged = True
                reason = convergence_reason(k, additions[-1], errors[-1], ratio, settings.order_tolerance)
                if ratio is not None:     # the orders after k: their table, source and ground light
                    tail = tail_factor(ratio)
                    gathered_sum = accumulate(gathered_sum, gathered, 1.0 + tail)   # G^(k+1) / (1 - r)
                    if ground_sky is not None:
                        ground_sky = ground_sky + sky * tail
                break
        else:
            reason = last_order_reason(settings, additions)
    result = OrdersResult(orders, {}, None if gathered_sum is None else to_host(gathered_sum), ground_sky, tail)
    result.record = orders_record(settings, converged, reason, additions, errors, None if tail is None else ratio,
                                  totals, time.perf_counter() - start, device)
    return result


def orders_record(settings: TableSettings, converged, reason, additions, errors, tail_ratio, totals, seconds,
                  device) -> dict:
    """The orders record of a build (:class:`OrdersResult`'s ``record``, a table's ``orders_record``): how
    the loop ended (``reason``, :func:`convergence_reason`, :func:`diverging_reason`,
    :func:`last_order_reason`), each order k >= 2's relative addition and estimated error, the geometric
    tail's ratio (r, g, b; None without a tail), the orders' shares of the light (from their
    :func:`_total`), the build's seconds and device. The one form of both orders loops (this module's and
    :mod:`clsky.azimuth`'s, which adds ``azimuth_harmonics``)."""
    return {"mode": settings.mode, "orders": len(totals), "requested": settings.orders,
            "tolerance": settings.order_tolerance, "max_orders": settings.max_orders,
            "converged": converged, "reason": reason, "relative_additions": list(additions),
            "estimated_errors": list(errors),
            "tail_ratio": None if tail_ratio is None else np.asarray(tail_ratio).tolist(),
            "shares": order_shares(totals), "seconds": seconds, "device": device}


def last_order_reason(settings: TableSettings, additions) -> str:
    """The record's reason for stopping after the last order the settings allow: single scattering alone,
    ``max_orders`` reached without converging (``orders="auto"``), or the fixed count asked for."""
    if not additions:
        return "orders=1: single scattering only"
    if settings.orders == "auto":
        return (f"not converged: stopped at max_orders = {settings.max_orders}; the last order added "
                f"{additions[-1]:.2e} (tolerance {settings.order_tolerance:g})")
    return f"orders={settings.orders} requested; the last order added {additions[-1]:.2e}"


def diverging_reason(k) -> str:
    """The record's reason for stopping at order k because it and the order before it each carry more light
    than the one before (:func:`_diverging`)."""
    return (f"diverging: orders {k - 1} and {k} each carry more light than the one before, which a dissipative "
            f"atmosphere cannot do with phase functions of mean 1: either a phase function adds light (the "
            f"modified Rayleigh phase's mean is 1.2533, so an optically thick atmosphere-plus sky grows) or the "
            f"view-ray quadrature is too coarse for this optical depth (more view_steps / multiple_view_steps)")


def convergence_reason(k, addition, error, ratio, tolerance):
    """The record's reason for stopping at order k (converged), with or without the geometric tail."""
    if ratio is None:
        return (f"converged: order {k} added at most {addition:.2e} of the running sum in the bright part "
                f"(tolerance {tolerance:g})")
    return (f"converged: after order {k} (relative addition {addition:.2e}) and the geometric tail of the "
            f"orders after it (ratio {', '.join(f'{r:.4f}' for r in ratio)} per order, r, g, b), the estimated "
            f"error is at most {error:.2e} of the running sum in the bright part (tolerance {tolerance:g})")


def _total(order):
    """Light an order carries per wavelength (r, g, b), summed over all cells (factored: R + M)."""
    flat = order.reshape(-1, order.shape[-1])
    # one strided column at a time: NumPy runs flat.sum(axis=0) as a reduction over rows of 3 or 6, 5x
    # slower (57 against 10 ms for an order of the default animation's table); its pairwise sums group
    # the cells differently, so a total changes in its last bits
    # a NaN or an infinity in the order, or a sum that overflows, gives a total that is not finite, silently:
    # check_finite takes it as its cue to look at the values
    with np.errstate(over="ignore", invalid="ignore"):
        per_channel = np.array([flat[:, channel].sum() for channel in range(flat.shape[1])])
        return per_channel[:3] + per_channel[3:6] if per_channel.size == 6 else per_channel


def _diverging(totals):
    """True when the last two orders (orders 4 and 5 at the earliest) each carry more light (per-order
    totals, :func:`_total`) than the one before in some wavelength: in an atmosphere that absorbs (black
    ground, Mie absorption, escape to space) the orders must decrease, so this only happens when the
    quadrature amplifies (optically thick steps)."""
    if len(totals) < 5:
        return False
    return bool(np.any((totals[-2] > totals[-3]) & (totals[-1] > totals[-2])))


def order_shares(totals):
    """Share of each order in the total, per wavelength (r, g, b), from the orders' :func:`_total`.

    Factored channels count Rayleigh + Mie (phase taken as 1, its mean over the sphere). Returns a list
    of [r, g, b] fractions, one per order, summing to 1 per wavelength.
    """
    totals = np.array(totals)
    grand = totals.sum(axis=0)
    return (totals / np.where(grand > 0, grand, 1.0)).tolist()
