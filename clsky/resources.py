"""Memory a request needs, against what the machine has: say "too big" before any work.

A table build, a renderer and an animation allocate a few large arrays whose sizes follow from their
settings. :func:`estimate_table_memory`, :func:`estimate_render_memory` and
:func:`estimate_animation_memory` list them phase by phase (:class:`Phase`, :class:`Allocation`);
:func:`check_memory` compares the peak with what the machine has and raises
:class:`InsufficientMemoryError`, in one line that says how much is needed and how much there is.

Three limits are checked, in this order:

1. every OpenCL buffer against the device's ``max_mem_alloc_size`` (PoCL refuses a larger one with
   CL_INVALID_BUFFER_SIZE);
2. the OpenCL buffers alive at once against the device's ``global_mem_size`` (PoCL refuses an
   allocation past it, ``total_alloc_limit``);
3. the host's peak against the memory available now (``MemAvailable`` of /proc/meminfo, lowered to
   what a cgroup v2 limit leaves; else ``sysconf`` free pages; unknown: not checked).

On a CPU device (PoCL) and on devices that report ``host_unified_memory``, a buffer *is* host memory,
allocated by the driver beside NumPy's arrays: the host check then counts the host arrays plus the
buffers, each once (a host array and its device copy are two allocations). On a discrete GPU the two
memories are separate and the host check counts the host arrays only.

The estimate is of the arrays, not of the process: Python, NumPy, PyOpenCL and PoCL with its
compiled programs add :data:`BASE_PROCESS_BYTES` (measured; up to about 150 MiB more while LLVM
compiles a program that is not in PyOpenCL's disk cache), which is already resident when the check
runs. An ``orders="auto"`` build is estimated at :func:`expected_orders` orders; each further order
keeps one more (D, H, W, 3) (physical) or (D, H, W, 6) (atmosphere-plus) float64 table.
"""

from __future__ import annotations

import dataclasses
import math
import os
import pathlib

import numpy as np

from .errors import counted
from .settings import TableSettings

__all__ = ["InsufficientMemoryError", "Allocation", "Phase", "MemoryEstimate", "MemoryLimits",
           "estimate_table_memory", "estimate_spectral_table_memory", "estimate_render_memory",
           "estimate_animation_memory", "expected_orders",
           "estimate_directions_memory", "machine_limits", "device_of", "check_memory", "check_table_memory",
           "host_available_bytes",
           "format_bytes", "BASE_PROCESS_BYTES", "FRAME_BYTES_PER_PIXEL", "NEXT_FRAME_BYTES_PER_PIXEL"]

#: Resident memory of a process that imported clsky and built a small table with cached programs [bytes]
#: (127 MiB measured, PoCL 3.1 on the 2-core development machine).
BASE_PROCESS_BYTES = 130 * 2**20
#: Orders before the geometric tail's test applies and orders per decade of the tolerance, for
#: :func:`expected_orders` (an upper bound for the memory estimate): with the tail (:mod:`clsky.orders`),
#: preset("physical") converges at order 6 for the draft level (tolerance 1e-2), 9 for the default (1e-4)
#: and 11 for the high (1e-5); the default animation's planned table at 7 (measured 2026-12-03).
FIRST_ORDERS, ORDERS_PER_DECADE = 3, 1.6
#: Host bytes per pixel of one frame's processing beyond the directions, buffers and HDR frames, per
#: method: conversion to cd/m^2, exposure metering, tone map, 8-bit frames, metrics, error image,
#: composite, PNG and MP4 encoding. Measured as the growth of peak RSS between 2-frame 256^2 and 1024^2
#: fisheye animations of the default (physical) preset, draft level, table 16 x 64 x 16, with glibc's
#: allocator untuned (``clsky animate``'s, :mod:`clsky.allocator`, grows by 0.82-0.84 of that in four
#: runs), without the overlap, the largest of 3 runs, less the arrays the estimate lists on a CPU device
#: (2 suns a ray-march launch): 530 bytes per pixel in all (compare; listed 243), 288 (lut; 123), 315
#: (raymarch; 219), 298 (skyview; 123) (2026-12-05; the runs of one method within 16 bytes). The ray
#: march's processing is the lookup's (one frame): it took the lookup's 165, not the 96 its own runs
#: leave, because its listed arrays count each launch's frames beside the HDR frame in hand (an upper
#: bound; earlier constants: 305 / 185 / 185 / 205 from 2026-12-04, 340 / 210 / 210 / 210 from 2026-12-02).
#: Since the conversion to cd/m^2 runs on the device (its buffers listed, ``device_conversion``) the ray
#: march's 165 overstated its animations' growth by a third (1.32 of it with two host threads and with
#: one, 2026-12-05, Intel Xeon, the slow slope test's way): 75 brings it to 1.06 and 1.10 by those runs'
#: growth (the slope test then measured 1.02); the comparison's 0.99 and 0.88 and the lookups' 1.10 and
#: 1.12 (two threads) were left as they are. Measured again on 2026-12-06 the slope test's way (two host
#: threads, the largest of 3 and of 5 runs): 0.97 (compare), 1.10-1.15 (lut), 1.06 (raymarch), 1.10-1.18
#: (skyview); kept (README "Memory": an over-estimate is the safe side).
FRAME_BYTES_PER_PIXEL = {"compare": 287, "lut": 165, "raymarch": 75, "skyview": 175}
#: Host bytes per pixel that an animation's overlapped pipeline (anim/pipeline.py) adds with one
#: host thread beyond the frames it holds (one more set of HDR frames, waiting for the thread): the next
#: frame, rendered on the worker thread while this one is processed. Measured as FRAME_BYTES_PER_PIXEL
#: with the overlap and one host thread, less the listed arrays and FRAME_BYTES_PER_PIXEL: 588 bytes per
#: pixel (compare), 326 (lut), 327 (raymarch), 351 (skyview), the largest of 3 runs, 2026-12-05: 10, 14,
#: -12 (0 here) and 29. The next frame's render peaks while no frame is being processed: since the host
#: threads of 2026-12-04 the conversion is theirs, and the 190 / 170 / 180 / 155 measured before (the
#: render's conversion beside this frame's processing) overstated it. With two host threads the estimate
#: is 1.03 (compare), 0.94 (lut), 1.09 (raymarch) and 1.00 (skyview) of the largest of 3 runs.
NEXT_FRAME_BYTES_PER_PIXEL = {"compare": 10, "lut": 15, "raymarch": 0, "skyview": 30}
#: Host bytes an animation keeps of each frame until its end, whatever its pixels: its metrics row (some 470
#: bytes of Python objects), the names of its staged files, the means of the temporal jumps. Measured as the
#: resident memory's growth over the frames of 16 x 16 animations (2026-12-07, Intel Xeon): 1.7 kB a frame
#: over 20 000 and over 100 000 frames (344 to 378 MB and 351 to 520 MB); rounded up. The metrics JSON is
#: streamed to its file at the end (``clsky.anim.writers.write_json``), no copy of them all as one string.
FRAME_RECORD_BYTES = 2048


class InsufficientMemoryError(ValueError):
    """A request needs more memory than the machine has; the one-line message says how much of each."""


@dataclasses.dataclass(frozen=True)
class Allocation:
    """Arrays of one kind alive in a phase.

    Attributes
    ----------
    label : str
        What they hold, e.g. 'padded tables (D, H, W, 8)'.
    nbytes : int
        Bytes of one array [bytes].
    count : int
        How many such arrays are alive at once.
    on_device : bool
        An OpenCL buffer (else a NumPy array).
    source : {'table', 'frames', 'sequence'}
        The part of the request it grows with (names the option in messages): the table, the frames'
        pixels, or an animation's frame count.
    """

    label: str
    nbytes: int
    count: int = 1
    on_device: bool = False
    source: str = "table"

    @property
    def total(self) -> int:
        """nbytes x count [bytes]."""
        return int(self.nbytes) * int(self.count)


@dataclasses.dataclass(frozen=True)
class Phase:
    """The arrays alive at one moment of the work (its local peak)."""

    name: str
    allocations: tuple

    def bytes(self, on_device=None) -> int:
        """Bytes of the host arrays (False), of the buffers (True) or of both (None)."""
        return sum(a.total for a in self.allocations if on_device is None or a.on_device == on_device)


@dataclasses.dataclass(frozen=True)
class MemoryEstimate:
    """The memory of a request, phase by phase.

    Attributes
    ----------
    what : str
        The request, for messages (e.g. 'the table 32 x 256 x 139').
    phases : tuple of Phase
    """

    what: str
    phases: tuple

    @property
    def host_bytes(self) -> int:
        """Peak of the host (NumPy) arrays over the phases [bytes]."""
        return max(p.bytes(False) for p in self.phases)

    @property
    def device_bytes(self) -> int:
        """Peak of the OpenCL buffers alive at once [bytes]."""
        return max(p.bytes(True) for p in self.phases)

    @property
    def largest_device_buffer(self) -> Allocation | None:
        """The allocation with the largest single OpenCL buffer, or None without buffers."""
        buffers = [a for p in self.phases for a in p.allocations if a.on_device]
        return max(buffers, key=lambda a: a.nbytes) if buffers else None

    def peak_bytes(self, unified=True) -> int:
        """Peak of host arrays + buffers when they share one memory (``unified``), else of the host
        arrays [bytes]; add :data:`BASE_PROCESS_BYTES` for the process' peak resident memory."""
        return max(p.bytes(None if unified else False) for p in self.phases)

    def peak_phase(self, unified=True, on_device=None) -> Phase:
        """The phase of the peak (of both memories if ``unified``, else of ``on_device``'s)."""
        kind = None if unified else bool(on_device)
        return max(self.phases, key=lambda p: p.bytes(kind))


@dataclasses.dataclass(frozen=True)
class MemoryLimits:
    """What the machine has (None: unknown, not checked).

    Attributes
    ----------
    host_available : int or None
        Host memory available now [bytes].
    device_global : int or None
        The device's ``global_mem_size`` [bytes].
    device_max_alloc : int or None
        The device's ``max_mem_alloc_size`` [bytes].
    unified : bool
        The device's buffers are host memory (CPU device, or ``host_unified_memory``).
    device_name : str
    """

    host_available: int | None
    device_global: int | None = None
    device_max_alloc: int | None = None
    unified: bool = True
    device_name: str = "no OpenCL device"


def format_bytes(nbytes) -> str:
    """``nbytes`` in KiB, MiB, GiB or TiB with 3 significant digits, e.g. '2.10 GiB'.

    >>> format_bytes(2.1 * 2**30), format_bytes(512 * 2**20), format_bytes(25.31 * 2**30)
    ('2.10 GiB', '512 MiB', '25.3 GiB')
    """
    value = float(nbytes)
    if value < 1024.0:
        return f"{int(value)} bytes"
    for unit in ("KiB", "MiB", "GiB", "TiB"):
        value /= 1024.0
        rounded = float(f"{value:.3g}")                 # 3 significant digits, before choosing the unit
        if rounded < 1000.0 or unit == "TiB":
            break
    digits = max(0, 2 - int(math.floor(math.log10(rounded))))
    return f"{rounded:.{digits}f} {unit}"


def expected_orders(settings: TableSettings) -> int:
    """Orders a build computes: ``settings.orders``, or for 'auto' FIRST_ORDERS + ORDERS_PER_DECADE per
    decade of the tolerance below 1, rounded up (at least 2, at most ``max_orders``)."""
    if settings.orders != "auto":
        return settings.orders
    estimate = math.ceil(FIRST_ORDERS - ORDERS_PER_DECADE * math.log10(settings.order_tolerance))
    return min(settings.max_orders, max(2, estimate))


def _table_sizes(settings: TableSettings):
    width, height, depth = settings.size
    cells = width * height * depth
    itemsize = np.dtype(settings.dtype).itemsize
    return cells, height, depth, itemsize


def estimate_table_memory(settings: TableSettings, backend="opencl", saving=False,
                          packed_reads=False) -> MemoryEstimate:
    """Peak memory of :meth:`clsky.table.ScatteringTable.build` with ``settings``.

    Parameters
    ----------
    settings : TableSettings
    backend : {'opencl', 'numpy'}
        The NumPy twins hold their arrays on the host (counted as host arrays; a rough estimate).
    saving : bool
        Then :meth:`~clsky.table.ScatteringTable.save`: float32 copies of every order beside the table.
    packed_reads : bool
        The device packs what the harmonics' orders read back (not :func:`clsky._cl.rectangular_reads`
        of the device: GPUs): the packed nodes and gathered sum on the device too.

    Returns
    -------
    MemoryEstimate
        With N = W H D cells, s the kernels' bytes per value, K the orders (:func:`expected_orders`),
        c = 3 channels kept per higher order (physical; 6 atmosphere-plus), phase by phase: the
        single-scattering download (N 6 s, + N 6 8 if s != 8); the physical mode's first gather
        (a (2, D, H, H) matrix stack on the host, 16 x 8 D H^2, one on the device, 16 s D H^2, single
        scattering and its swap, 2 x N 6 8, a staging copy and three padded device tables,
        4 x N 8 s); the
        orders (K - 1 kept tables N c 8, the running sum N c 8, three padded device tables 3 x N 8 s,
        the download N 8 s or else the stopping test's temporaries, 11 N c); the combination into the
        table (N C 8) beside the gathered sum (N 6 8); with ``saving``, float32 copies of the orders.
        With azimuth harmonics and ``packed_reads``, also the packed nodes (n N 3 s) on the device, and
        the gathered sum's read (n N 6 s packed) once the stopping test's buffers are gone.
    """
    cells, _, _, s = _table_sizes(settings)
    orders = expected_orders(settings)
    phases = [_single_phase(settings)]
    if orders > 1 and settings.azimuth_harmonics:
        phases.extend(_harmonic_phases(settings, orders, packed_reads))
    elif orders > 1:
        if settings.mode == "physical":
            phases.append(_first_gather_phase(settings))
        phases.extend(_orders_phases(settings, orders))
    table = _table_held(settings, cells, orders, keep_orders=True)
    phases.append(_combine_phase(settings, table, orders))
    phases.append(Phase("table", table))
    if saving:
        phases.append(_save_phase(settings, table, orders))
    if backend != "opencl":
        phases = [Phase(p.name, tuple(dataclasses.replace(a, on_device=False) for a in p.allocations))
                  for p in phases]
    width, height, depth = settings.size
    return MemoryEstimate(f"the table {width} x {height} x {depth} ({settings.mode}, {settings.dtype})",
                          tuple(phases))


_F64 = 8   # bytes of a float64: the host keeps every table in float64


def _single(cells):
    return Allocation("single scattering (D, H, W, 6) float64", cells * 6 * _F64)


def _kept_channels(settings):
    """Channels of a higher order kept on the host: 3 phased (physical), 6 factored (atmosphere-plus)."""
    return 3 if settings.mode == "physical" else 6


def _single_phase(settings):
    """The single-scattering table on the device and its download."""
    cells, _, _, s = _table_sizes(settings)
    allocations = [Allocation("single scattering (D, H, W, 6)", cells * 6 * s, on_device=True),
                   Allocation("transmittance table", int(np.prod(settings.transmittance_size)) * 2 * s, on_device=True),
                   Allocation("single scattering download (D, H, W, 6)", cells * 6 * s)]
    if s != _F64:
        allocations.append(_single(cells))
    return Phase("single scattering", tuple(allocations))


def _first_gather_phase(settings):
    """The physical mode's first gather, same species then crossed, counted as one moment (an upper
    bound): a (2, D, H, H) float64 matrix stack on the host and one on the device (the same-species
    stack goes once its gather ran), single scattering and its swap, for a float32 device a copy of the
    kernels' type to upload (:func:`clsky._cl.upload_padded`), and three padded device tables."""
    from .multiple import FIRST_GATHER_CHUNK

    cells, height, depth, s = _table_sizes(settings)
    stack = 2 * depth * height * height
    padded = cells * 8 * s
    return Phase("first gather", (
        _single(cells), Allocation("swapped single scattering (D, H, W, 6)", cells * 6 * _F64),
        Allocation("first-gather matrix stack (2, D, H, H) float64", stack * _F64),
        Allocation("first-gather product temporary",
                   FIRST_GATHER_CHUNK * height * (settings.gather_theta_steps + 1) * _F64),
        Allocation("first-gather matrix stack (2, D, H, H)", stack * s, on_device=True),
        Allocation("padded tables (D, H, W, 8)", padded, count=3, on_device=True))
        + _upload_staging(cells * 6, s))


def _upload_staging(values, s):
    """What :func:`clsky._cl.upload_padded` adds on the host to upload ``values`` float64 values to a
    device of ``s`` bytes a real: nothing for float64 (it writes from the table itself), else a copy
    of the kernels' type."""
    return () if s == _F64 else (Allocation("upload staging in the kernels' type (..., 6)", values * s),)


def _orders_phases(settings, orders):
    """The orders loop (at its last order) and the download of the gathered sum after it."""
    cells, height, _, s = _table_sizes(settings)
    kept = _kept_channels(settings)
    padded = cells * 8 * s
    common = (_single(cells),
              Allocation("gather matrices (2, H, H)", 2 * height * height * s, on_device=True),
              Allocation(f"higher orders kept (D, H, W, {kept}) float64", cells * kept * _F64, count=orders - 1),
              Allocation(f"running sum (D, H, W, {kept}) float64", cells * kept * _F64))
    return [
        Phase("orders", common + (
            # on the device: the gathered sum, the order just scattered, the next gather's input or output
            Allocation("padded tables (D, H, W, 8)", padded, count=3, on_device=True),
            # the padded download of the order (dropped once copied), then the stopping test's arrays
            Allocation("order download or stopping test temporaries", max(padded, cells * kept * (_F64 + 3))))),
        Phase("gathered download", common + (
            Allocation("padded tables (D, H, W, 8)", padded, count=2, on_device=True),
            Allocation("gathered sum download (D, H, W, 8)", padded),
            Allocation("gathered sum (D, H, W, 6) float64", cells * 6 * _F64)))]


def _harmonic_phases(settings, orders, packed_reads=False):
    """The orders of a table with azimuth harmonics (:mod:`clsky.azimuth`, n = M + 1 azimuth nodes): the
    first gather on the host (single scattering at the n nodes, the n gathered harmonics (for a float32
    device also as float32, uploaded from there), and on each of its threads a block of B sun layers'
    temporaries: the block's harmonics of single scattering and the copy of its nodes that their product
    takes, both seen species' interpolation (n, B, Theta + 1, W 6), their harmonic sum and a species'
    gathers), then the orders loop (single scattering at the canonical node, every order's
    azimuth average kept on the host, the order's n nodes and the sum of the summed orders' nodes, and
    for a float32 device the same as read
    from it; on the device the gathered sum, the gathered harmonics and the order's n nodes, padded, and
    a harmonic, and the stopping test's running sum at the nodes (:class:`clsky.stopping.DeviceStoppingTest`);
    for ``orders="auto"``, the order before at the nodes, on the device too, which the geometric tail's
    test reads). With ``packed_reads``, the nodes' 3 channels packed on the device for their read
    (kernels/multiple.cl: pack_channels) in the orders, and a phase for the gathered sum's read: the orders'
    arrays but the stopping test's, and the gathered harmonics' 6 channels packed (the pool holds both
    packed arrays then)."""
    from .azimuth import HarmonicGather

    cells, height, depth, s = _table_sizes(settings)
    n = settings.azimuth_harmonics + 1
    padded = cells * 8 * s
    block = min(HarmonicGather.FIRST_GATHER_LAYERS, depth)
    threads = HarmonicGather.first_gather_threads(depth)
    seen = n * block * (settings.gather_theta_steps + 1) * settings.size[0] * 3 * _F64
    single = Allocation("single scattering at the azimuth nodes (n, D, H, W, 6) float64", cells * 6 * _F64, count=n)
    first = Phase("first gather", (
        single,
        # B sun layers at a time (HarmonicGather.first_gather), a block on each of its threads: the
        # block's harmonics, their copy by species and the copy of its nodes (n, B, H, W, 6), both species
        # interpolated at once (n, B, Theta + 1, W 6), the harmonic sums of both (n, B, Theta + 1, W 3) and
        # a species' gathers
        Allocation("a block's single scattering at the nodes (a copy), its harmonics and their copy with each "
                   "species' channels together (n, B, H, W, 6) on each first-gather thread",
                   n * block * height * settings.size[0] * 6 * _F64, count=3 * threads),
        Allocation("a block's interpolated single scattering, its harmonic sums and gathers (n, B, Theta + 1, W 3)"
                   " on each first-gather thread", seen, count=4 * threads),
        Allocation("gathered harmonics (n, D, H, W, 6) float64", cells * 6 * _F64, count=n))
        + ((Allocation("gathered harmonics in the device's type for the upload (n, D, H, W, 6)",
                       cells * 6 * s, count=n),) if s != _F64 else ())
        + (Allocation("gathered harmonics on the device (n, D, H, W, 8)", padded, count=n, on_device=True),))
    loop = Phase("orders", (
        _single(cells),                 # the canonical node's: the other nodes and the harmonics go before the loop
        Allocation("gather matrices (n, 2, H, H)", 2 * height * height * s, count=n, on_device=True),
        Allocation("higher orders kept as their azimuth averages (D, H, W, 3) float64", cells * 3 * _F64,
                   count=orders - 1),
        Allocation("the order at its nodes on the host (n, D, H, W, 3) float64", cells * 3 * _F64, count=n),
        # the orders whose gathered harmonics m >= 1 are summed (clsky.azimuth, "Summed harmonics")
        Allocation("the summed orders' nodes on the host (n, D, H, W, 3) float64", cells * 3 * _F64, count=n),
        Allocation("running sum at the nodes (n, D, H, W, 3) float64", cells * 3 * _F64, count=n, on_device=True),
        # the harmonics are gathered straight into their slabs of the gathered stack (no table of their own)
        Allocation("padded tables: gathered sum, gathered, nodes, a harmonic", padded, count=3 * n + 1,
                   on_device=True))
        # a float32 device's nodes are read into a host table of its type, then widened
        + ((Allocation("the order at its nodes as read from the device (n, D, H, W, 3)", cells * 3 * s, count=n),)
           if s != _F64 else ())
        + ((Allocation("the order before at its nodes (n, D, H, W, 3) float64", cells * 3 * _F64, count=n,
                       on_device=True),)
           if settings.orders == "auto" else ())
        + ((Allocation("the order at its nodes packed for its read (n, D, H, W, 3) in the kernels' type",
                       cells * 3 * s, count=n, on_device=True),)
           if packed_reads else ()))
    if not packed_reads:
        return [first, loop]
    # the gathered sum's read comes after the stopping test's buffers went (clsky.azimuth.compute_orders);
    # the pool still holds the packed nodes beside the gathered harmonics packed
    stopping_test = ("running sum at the nodes", "the order before at its nodes (")
    read = Phase("the gathered harmonics' read",
                 tuple(a for a in loop.allocations if not a.label.startswith(stopping_test))
                 + (Allocation("the gathered harmonics packed for their read (n, D, H, W, 6) in the kernels' type",
                               cells * 6 * s, count=n, on_device=True),))
    return [first, loop, read]


def _combine_phase(settings, table, orders):
    """The orders summed into the table's data, beside everything the built table holds."""
    cells = _table_sizes(settings)[0]
    kept = _kept_channels(settings)
    combined = 9 if settings.mode == "physical" and orders > 1 else 6
    allocations = [a for a in table if not a.label.startswith("table data")]
    allocations.append(Allocation(f"combined table (D, H, W, {combined}) float64", cells * combined * _F64))
    if orders > 1 and settings.mode == "physical":
        allocations.append(Allocation(f"sum of the higher orders (D, H, W, {kept})", cells * kept * _F64))
    if orders > 1 and settings.orders == "auto":
        allocations.append(Allocation(f"the geometric tail, the last order times r / (1 - r) (D, H, W, {kept})",
                                      cells * kept * _F64))
    if settings.mie_layout == "notes":
        allocations.append(Allocation("table in the notes' layout", cells * settings.channels * _F64))
    return Phase("combine", tuple(allocations))


def _save_phase(settings, table, orders):
    """:meth:`~clsky.table.ScatteringTable.save`: float32 copies of every order beside the table."""
    cells = _table_sizes(settings)[0]
    kept = _kept_channels(settings)
    copies = [Allocation("order 1 as float32 (D, H, W, 6)", cells * 6 * 4)]
    if orders > 1:
        copies.append(Allocation(f"higher orders as float32 (D, H, W, {kept})", cells * kept * 4, count=orders - 1))
    return Phase("save", table + tuple(copies))


def _data_cells(settings, cells):
    """Cells of a table's ``data``: W H D, times ``azimuth_size`` for the 4D parameterization."""
    return cells * (settings.azimuth_size if settings.is_4d else 1)


def _table_held(settings, cells, orders, keep_orders=True):
    """The host arrays of a built table: data, gathered sum and, with ``keep_orders``, its orders
    (single scattering, the table's first order, and the higher orders). An animation drops the
    orders once its table is built (:func:`clsky.anim.animate.make_table`), single scattering with them."""
    kept = _kept_channels(settings)
    held = [Allocation(f"table data (D, H, W, {settings.channels}) float64", _data_cells(settings, cells)
                       * settings.channels * 8)]
    if keep_orders:
        held.append(Allocation("single scattering (D, H, W, 6) float64", cells * 6 * 8))
    if orders > 1:
        # with azimuth harmonics (clsky/azimuth.py) the gathered sum is M + 1 such tables
        held.append(Allocation("gathered sum (D, H, W, 6) float64", cells * 6 * 8,
                               count=settings.azimuth_harmonics + 1))
        if keep_orders:
            held.append(Allocation(f"higher orders kept (D, H, W, {kept}) float64", cells * kept * 8,
                                   count=orders - 1))
    return tuple(held)


def estimate_render_memory(settings: TableSettings, image_shape, method="compare",
                           ray_settings: TableSettings | None = None, keep_orders=False,
                           hdr_output=False, count_table=True, batches=1, overlapped=False,
                           host_workers=1, ray_march_suns=1, device_conversion=False) -> MemoryEstimate:
    """Peak memory of rendering frames of ``image_shape`` from a table of ``settings``.

    Parameters
    ----------
    settings : TableSettings
        The table's (its host arrays are counted as held: :func:`estimate_table_memory`'s last phase).
    image_shape : (width, height)
        Pixels of a frame (0 x 0: the renderer's table upload only).
    method : {'compare', 'lut', 'raymarch', 'lut4d', 'compare4d'} (the 4D methods count as lut and compare)
        What each frame renders (:mod:`clsky.anim.animate`).
    ray_settings : TableSettings, optional
        The ray march's quadrature (its transmittance table); default :data:`clsky.render.RAYMARCH_DEFAULTS`.
    keep_orders : bool
        Whether the table still holds its higher orders (``clsky render``; an animation drops them).
    hdr_output : bool
        Also a float32 HDR copy per frame for the .npy files.
    count_table : bool
        Count the table's host arrays (False where the table exists already, e.g. in
        :class:`clsky.render.SkyRenderer`: the memory available then no longer includes them).
    batches : int
        Tables rendered side by side (:class:`clsky.spectrum.SpectralRenderer`: one per batch of three
        wavelengths, ceil(N / 3)); 1: a :class:`~clsky.render.SkyRenderer`.
    overlapped : bool
        The frames go through an animation's overlapped pipeline (``clsky.anim.animate.OVERLAP_FRAMES``),
        which holds the next frame as this one is processed: :data:`NEXT_FRAME_BYTES_PER_PIXEL`, plus a
        spectral animation's next spectral frames.
    host_workers : int
        Frames processed at once on host threads (``clsky.anim.animate.host_frame_workers``; with the
        overlap, the pipeline also holds one more frame's HDR frames, waiting for a thread): each
        processing counts :data:`FRAME_BYTES_PER_PIXEL` and its HDR frames.
    ray_march_suns : int
        Suns per ray-march launch (:meth:`clsky.render.SkyRenderer.render_raymarch_suns`, an animation's
        :func:`clsky.render.ray_march_batch`): the launch's output and download hold that many frames, and
        its float64 frames wait on the host until their turn.
    device_conversion : bool
        Absolute three-wavelength frames converted to XYZ on the device (:mod:`clsky.colorimetry_cl`): each
        host thread's engine keeps its buffers (6 reals and an index a lit pixel, XYZ a pixel: 76 bytes a
        pixel at most) and packs 72 bytes a pixel on the host (the rows it uploads, the XYZ it downloads).
        Added on 2026-12-05 when the conversion moved: the 2-frame animations' growth went from about 0.9
        to 1.17 GiB between 256^2 and 1024^2 (tests/test_memory.py, slow).

    Returns
    -------
    MemoryEstimate
        The table held on the host, its device copy (N C s) and padded gathered sum (N 8 s), and per
        pixel: directions (24 bytes host, 3 s device), the mask, the output buffer (3 s device, 3 s
        host), the HDR frames (24 bytes each) and :data:`FRAME_BYTES_PER_PIXEL` of frame processing.
        With B = ``batches`` > 1: B tables on the host and on the device, B copies of the directions
        and masks on the device (each batch's renderer prepares its own), and the spectral frames
        before their conversion to sRGB: each method's (pixels, 3 B) float64 assembly, and while the
        last is assembled its B (pixels, 3) pieces (:meth:`clsky.spectrum.SpectralTable.assemble`).
    """
    from .render import RAYMARCH_DEFAULTS
    from .transmittance import NO_GATHERED_GRID, gathered_source_reals

    ray_settings = ray_settings or RAYMARCH_DEFAULTS
    method = {"lut4d": "lut", "compare4d": "compare"}.get(method, method)   # the 4D lookup's frames are the lut's
    cells, _, _, s = _table_sizes(settings)
    orders = expected_orders(settings)
    width, height = image_shape
    pixels = int(width) * int(height)
    held = _table_held(settings, cells, orders, keep_orders) if count_table else ()
    held = tuple(dataclasses.replace(a, count=a.count * batches) for a in held)
    gathered = s * (gathered_source_reals(settings.size, settings.azimuth_harmonics) if orders > 1
                    else gathered_source_reals(NO_GATHERED_GRID))
    upload = (Allocation(f"table data on the device (D, H, W, {settings.channels})",
                         _data_cells(settings, cells) * settings.channels * s,
                         count=batches, on_device=True),
              Allocation("padded gathered sum on the device (D, H, W, 8)", gathered, count=batches, on_device=True),
              # 2 columns per node, 3 with ozone (transmittance.column_channels): counted as 3
              Allocation("ray-march transmittance table", int(np.prod(ray_settings.transmittance_size)) * 3 * s,
                         count=batches, on_device=True))
    phases = [Phase("renderer", held + upload + _upload_staging(gathered // (8 * s) * 6 if orders > 1 else 0, s))]
    if pixels:
        frames = 2 if method == "compare" else 1
        processing = max(1, int(host_workers))
        # the frames a host thread processes, and with the overlap one more waiting for a thread, each
        # held as rendered (a spectral frame before its conversion) and as converted
        held_frames = frames * (processing + (1 if overlapped else 0))
        spectral, next_spectral = (), 0
        if batches > 1:
            # the next frame's spectral frames and, while the last is assembled, its pieces
            next_spectral = pixels * 24 * batches * frames + pixels * 24 * batches
            spectral = (Allocation(f"spectral frames (pixels, 3 x {batches}) float64", pixels * 24 * batches,
                                   count=held_frames, source="frames"),
                        Allocation("spectral frame pieces (pixels, 3) float64", pixels * 24, count=batches,
                                   source="frames"))
        per_pixel = spectral + (
            Allocation("ray directions (pixels, 3) float64", pixels * 24, source="frames"),
            Allocation("pixel mask", pixels * 2, source="frames"),
            Allocation("ray directions on the device (pixels, 3)", pixels * 3 * s, count=batches, on_device=True,
                       source="frames"),
            Allocation("pixel mask on the device", pixels, count=batches, on_device=True, source="frames"),
            Allocation("frame output on the device (pixels, 3)", pixels * 3 * s, on_device=True, source="frames"),
            Allocation("frame download (pixels, 3)", pixels * 3 * s, source="frames"),
            Allocation("HDR frames (pixels, 3) float64", pixels * 24, count=held_frames, source="frames"),
            Allocation("frame processing (tone map, metrics, composite, encoding)",
                       pixels * (FRAME_BYTES_PER_PIXEL[method] + (12 if hdr_output else 0)), count=processing,
                       source="frames"))
        if device_conversion and batches == 1:
            per_pixel += (
                Allocation("the conversion's buffers on the device (lit pixels: 6 reals, an index; XYZ)",
                           pixels * (6 * 8 + 4 + 3 * 8), count=processing, on_device=True, source="frames"),
                Allocation("the conversion's host rows and XYZ (pixels, 6 + 3) float64", pixels * 72,
                           count=processing, source="frames"))
        if ray_march_suns > 1 and method in ("compare", "raymarch"):
            more = int(ray_march_suns) - 1
            per_pixel += (
                Allocation("the ray march's other suns: output on the device (pixels, 3)", pixels * 3 * s,
                           count=more, on_device=True, source="frames"),
                Allocation("the ray march's other suns: download (pixels, 3)", pixels * 3 * s, count=more,
                           source="frames"),
                Allocation("the ray march's frames of a launch (pixels, 3) float64", pixels * 24,
                           count=int(ray_march_suns), source="frames"))
        if overlapped:
            per_pixel += (Allocation("the next frame, rendered meanwhile (overlapped pipeline)",
                                     pixels * NEXT_FRAME_BYTES_PER_PIXEL[method] + next_spectral, source="frames"),)
        phases.append(Phase("frames", held + upload + per_pixel))
    w, h, d = settings.size
    return MemoryEstimate(f"rendering {width} x {height} frames from the table {w} x {h} x {d}", tuple(phases))


def estimate_directions_memory(pixels, dtype="float64") -> MemoryEstimate:
    """What :meth:`clsky.render.SkyRenderer.prepare` and a frame add for ``pixels`` directions: their
    device copy (3 s each), the mask, their view zenith angles (s each, kept for the sky-view lookup:
    :meth:`~clsky.render.SkyRenderer.view_zenith_angles`), one output buffer (3 s), and the download (3 s)."""
    s = np.dtype(dtype).itemsize
    pixels = int(pixels)
    return MemoryEstimate(f"{pixels} ray directions", (Phase("frame", (
        Allocation("ray directions on the device (pixels, 3)", pixels * 3 * s, on_device=True, source="frames"),
        Allocation("pixel mask on the device", pixels, on_device=True, source="frames"),
        Allocation("view zenith angles on the device (pixels)", pixels * s, on_device=True, source="frames"),
        Allocation("frame output on the device (pixels, 3)", pixels * 3 * s, on_device=True, source="frames"),
        Allocation("frame download (pixels, 3)", pixels * 3 * s, source="frames"))),))


def estimate_spectral_table_memory(settings: TableSettings, batches: int, packed_reads=False) -> MemoryEstimate:
    """Peak memory of :meth:`clsky.spectrum.SpectralTable.build` with ``keep_orders=False`` (what an
    animation builds): ``batches`` tables built one after the other.

    Returns
    -------
    MemoryEstimate
        The last batch's build (:func:`estimate_table_memory`'s phases: the batches grow, the last is
        the largest) beside the B - 1 built tables without their orders (data and
        gathered sum) and, for the physical mode's higher orders, the two first-gather stacks
        (2, D, H, H) float64 that :func:`clsky.multiple.keeping_first_gather_stacks` keeps for the
        whole build (the last batch computes none: its first-gather phase holds the kept two instead
        of one of its own). ``packed_reads``: :func:`estimate_table_memory`'s.
    """
    cells, height, depth, _ = _table_sizes(settings)
    orders = expected_orders(settings)
    built = tuple(dataclasses.replace(a, count=a.count * (batches - 1))
                  for a in _table_held(settings, cells, orders, keep_orders=False))
    kept = ()
    if settings.mode == "physical" and orders > 1:
        kept = (Allocation("first-gather matrix stacks kept for the batches (2, D, H, H) float64",
                           2 * depth * height * height * _F64, count=2),)
    phases = []
    for phase in estimate_table_memory(settings, packed_reads=packed_reads).phases:
        own = tuple(a for a in phase.allocations if not a.label.startswith("first-gather matrix stack (2, D, H, H) "
                                                                           "float64"))
        phases.append(Phase(f"last batch: {phase.name}", (built if batches > 1 else ()) + kept + own))
    width, height, depth = settings.size
    return MemoryEstimate(f"{counted(batches, 'table')} {width} x {height} x {depth} ({settings.mode}, {settings.dtype})",
                          tuple(phases))


def estimate_animation_memory(settings: TableSettings, image_shape, method="compare",
                              ray_settings: TableSettings | None = None, hdr_output=False,
                              batches=None, overlapped=True, host_workers=1,
                              packed_reads=False, ray_march_suns=1, device_conversion=False,
                              frames=0) -> MemoryEstimate:
    """The table build, then the frames (:func:`estimate_table_memory`, :func:`estimate_render_memory`
    without the higher orders, which an animation drops once the table is built). ``batches``: None
    for the three-wavelength animation, else the spectral one's ceil(N / 3) batches
    (:func:`estimate_spectral_table_memory`, ``estimate_render_memory(..., batches=B)``).
    ``overlapped``, ``host_workers``: the frames go through the overlapped pipeline with that many host
    threads, and ``ray_march_suns``, ``device_conversion``: ``estimate_render_memory``'s. ``packed_reads``:
    :func:`estimate_table_memory`'s. ``frames``: the animation's frame count, whose records it keeps to its
    end (:data:`FRAME_RECORD_BYTES` each, in the last phase; source 'sequence' for the messages)."""
    if batches is None:
        build = estimate_table_memory(settings, packed_reads=packed_reads)
    else:
        build = estimate_spectral_table_memory(settings, batches, packed_reads)
    render = estimate_render_memory(settings, image_shape, method, ray_settings, keep_orders=False,
                                    hdr_output=hdr_output, batches=batches or 1, overlapped=overlapped,
                                    host_workers=host_workers, ray_march_suns=ray_march_suns,
                                    device_conversion=device_conversion)
    phases = build.phases + render.phases
    if frames:
        records = Allocation("the frames' records (metrics rows, staged file names)", FRAME_RECORD_BYTES,
                             count=int(frames), source="sequence")
        phases = phases[:-1] + (Phase(phases[-1].name, phases[-1].allocations + (records,)),)
    width, height = image_shape
    w, h, d = settings.size
    tables = f"table {w} x {h} x {d}" if batches is None else f"{counted(batches, 'table')} {w} x {h} x {d}"
    return MemoryEstimate(f"the animation ({width} x {height} frames, {tables})", phases)


def host_available_bytes() -> int | None:
    """Host memory available now [bytes]: MemAvailable (/proc/meminfo), lowered to what a cgroup v2
    memory limit leaves; else free pages (sysconf); None if unknown."""
    available = None
    try:
        for line in pathlib.Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                available = int(line.split()[1]) * 1024
                break
    except (OSError, ValueError, IndexError):
        available = None
    if available is None:
        try:
            available = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (ValueError, OSError, AttributeError):
            available = None
    try:
        limit = pathlib.Path("/sys/fs/cgroup/memory.max").read_text().strip()
        if limit != "max":
            used = int(pathlib.Path("/sys/fs/cgroup/memory.current").read_text().strip())
            left = max(0, int(limit) - used)
            available = left if available is None else min(available, left)
    except (OSError, ValueError):
        pass
    return available


def device_of(ctx=None, dtype="float64"):
    """The device work on ``ctx`` (default: clsky's shared context, :func:`clsky._cl.make_context`) runs on."""
    from . import _cl

    return (_cl.check_context(ctx) if ctx is not None else _cl.make_context(np.dtype(dtype))).devices[0]


def machine_limits(device=None) -> MemoryLimits:
    """The host's available memory and ``device``'s (a pyopencl.Device, or None: no device) limits."""
    host = host_available_bytes()
    if device is None:
        return MemoryLimits(host)
    import pyopencl as cl

    unified = bool(device.type & cl.device_type.CPU)
    try:
        unified = unified or bool(device.host_unified_memory)
    except (cl.Error, AttributeError):
        pass
    return MemoryLimits(host, int(device.global_mem_size), int(device.max_mem_alloc_size), unified,
                        device.name.strip())


def _largest(allocations):
    return max(allocations, key=lambda a: a.total)


def _prefix(allocation, options):
    option = (options or {}).get(allocation.source)
    return f"{option}: " if option else ""


def check_memory(estimate: MemoryEstimate, limits: MemoryLimits | None = None, device=None, options=None):
    """Raise InsufficientMemoryError if ``estimate`` does not fit ``limits``.

    Parameters
    ----------
    estimate : MemoryEstimate
    limits : MemoryLimits, optional
        Default :func:`machine_limits` of ``device``.
    device : pyopencl.Device, optional
        The device the work will run on (None: host memory only).
    options : dict, optional
        {'table': ..., 'frames': ..., 'sequence': ...}: the command-line option each part of the request
        comes from (:class:`Allocation`'s ``source``);
        the message starts with the one of the largest allocation.

    Raises
    ------
    InsufficientMemoryError
        One line: what needs how much, and how much there is (3 significant digits).
    """
    limits = limits or machine_limits(device)
    largest = estimate.largest_device_buffer
    if largest is not None and limits.device_max_alloc is not None and largest.nbytes > limits.device_max_alloc:
        raise InsufficientMemoryError(
            f"{_prefix(largest, options)}{estimate.what} needs an OpenCL buffer of {format_bytes(largest.nbytes)} "
            f"({largest.label}); the device {limits.device_name} allows {format_bytes(limits.device_max_alloc)} "
            f"per buffer (max_mem_alloc_size)")
    if limits.device_global is not None and estimate.device_bytes > limits.device_global:
        phase = estimate.peak_phase(unified=False, on_device=True)
        biggest = _largest([a for a in phase.allocations if a.on_device])
        raise InsufficientMemoryError(
            f"{_prefix(biggest, options)}{estimate.what} needs {format_bytes(estimate.device_bytes)} of OpenCL "
            f"buffers at once ({biggest.label}: {format_bytes(biggest.total)}); the device {limits.device_name} "
            f"has {format_bytes(limits.device_global)} (global_mem_size)")
    need = estimate.peak_bytes(limits.unified)
    if limits.host_available is not None and need > limits.host_available:
        phase = estimate.peak_phase(limits.unified)
        biggest = _largest([a for a in phase.allocations if limits.unified or not a.on_device])
        where = ("host arrays and OpenCL buffers, one memory on this CPU device" if limits.unified
                 else "host arrays")
        raise InsufficientMemoryError(
            f"{_prefix(biggest, options)}{estimate.what} needs {format_bytes(need)} of memory ({where}; "
            f"most: {biggest.label}, {format_bytes(biggest.total)}); {format_bytes(limits.host_available)} "
            f"is available")


def check_table_memory(settings: TableSettings, backend="opencl", ctx=None, saving=False, options=None):
    """Refuse, before any work, a table build of ``settings`` (with its save: ``saving``) that does not fit
    the machine: :func:`estimate_table_memory` against the host and, with the OpenCL backend, the device
    it runs on (``ctx``'s, default clsky's), counting the reads that device packs
    (:func:`clsky._cl.packed_reads`); ``options`` as :func:`check_memory`'s. What
    :meth:`clsky.table.ScatteringTable.build` and ``clsky table`` check."""
    from ._cl import packed_reads

    device = device_of(ctx, settings.dtype) if backend == "opencl" else None
    check_memory(estimate_table_memory(settings, backend, saving=saving, packed_reads=packed_reads(device)),
                 device=device, options=options)
