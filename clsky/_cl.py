"""OpenCL plumbing: device choice, the one program loader, and the engine base class.

Kernel sources live in ``kernels/`` (shipped as the ``clsky.kernels`` resource package). A program is
an ordered list of those files plus, where needed, generated declarations (:class:`Source`); nothing
uses ``#include``. Programs are cached in-process by (context, sources, sorted options); on disk the
runtime caches them (PoCL, NVIDIA) or PyOpenCL does (the others).

Device choice (:func:`default_device`): ``PYOPENCL_CTX`` if set; else a GPU; else Intel's CPU OpenCL
runtime when it is registered (an opt-in, ``scripts/intel_opencl.sh``: the same frames as PoCL, the ray
march 1.4-1.5x faster on the development machine, README "Speed"); else the fastest PoCL build (PoCL
3.1+ vectorises about 4-5x better than the 3.0-rc2 pip build, README on scripts/setup.sh); else any CPU
device.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import importlib.resources
import logging
import os
import pathlib
import re
import stat
import tempfile
import threading
import warnings

import numpy as np

try:
    import pyopencl as cl
    import pyopencl.characterize
    import pyopencl.cltypes
    import pyopencl.tools
except ImportError as error:  # pragma: no cover - exercised only on broken installs
    raise ImportError("clsky needs pyopencl: pip install pyopencl (and an OpenCL driver, see README)") from error

from .errors import check_flag, check_instance

__all__ = ["KernelBuildError", "NoDeviceError", "Source", "Engine", "serialized", "memory_pool", "upload_padded",
           "list_devices",
           "default_device", "make_context", "check_context", "real_vector_dtype", "check_dtype",
           "INSTALL_HINT", "pocl_cache_problem", "no_device_hint", "host_blas_single_threaded", "host_cores",
           "quiet_compiler_output"]

INSTALL_HINT = ("install a CPU OpenCL driver: as root `apt-get install pocl-opencl-icd` (fast PoCL 3.1), "
                "or `pip install 'pyopencl[pocl]'` (PoCL pip build)")


class KernelBuildError(RuntimeError):
    """An OpenCL program failed to build; the message names files, options and device."""


class NoDeviceError(RuntimeError):
    """No usable OpenCL device (or none with the requested precision)."""


class DeviceSelectionError(NoDeviceError, ValueError):
    """PYOPENCL_CTX, the user's choice of device, selects none: bad input (the command line's exit status 2,
    as `clsky devices` gives it), not a missing driver."""


@dataclasses.dataclass(frozen=True)
class Source:
    """Generated OpenCL C text placed among the kernel files of a program (e.g. a struct declaration)."""

    label: str
    text: str


# Host BLAS beside a CPU device ----------------------------------------------------------------------------

def host_blas_single_threaded():
    """A context in which NumPy's BLAS (OpenBLAS, MKL, ...) runs on one thread (``threadpoolctl``).

    On a CPU device PoCL's worker threads own the cores; a multi-threaded BLAS call made meanwhile on
    the host (the physical mode's first-gather matrices, :func:`clsky.multiple.first_gather_matrix`)
    fought them: on the 2-core machine its CPU time was 0.5-1.2 s instead of 0.085 s on one thread
    (bench/bench_orders.py). BLAS splits a product's rows and columns among its threads, not the sum
    over the inner index, so the results are the same bit for bit.
    """
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1, user_api="blas")


def host_cores() -> int:
    """The CPU cores this process may run on (its affinity mask where the system has one, else the
    machine's count), at most what a cgroup CPU quota allows (:func:`cgroup_cpu_limit`: a container
    limited to 2 CPUs on a 64-core host gets 2): how many host threads a stretch of host work may use
    (:meth:`clsky.azimuth.HarmonicGather.first_gather`, ``clsky.anim.animate.host_frame_workers``)."""
    try:
        cores = max(1, len(os.sched_getaffinity(0)))
    except AttributeError:                          # no affinity masks (macOS, Windows)
        cores = max(1, os.cpu_count() or 1)
    limit = cgroup_cpu_limit()
    return cores if limit is None else min(cores, limit)


#: Where Linux states a cgroup's CPU quota: v2 "QUOTA PERIOD" ("max PERIOD": none), v1 the quota (-1: none)
#: and the period, in microseconds (the process's own cgroup, as a container sees it).
CGROUP_CPU_FILES = {"v2": pathlib.Path("/sys/fs/cgroup/cpu.max"),
                    "v1_quota": pathlib.Path("/sys/fs/cgroup/cpu/cpu.cfs_quota_us"),
                    "v1_period": pathlib.Path("/sys/fs/cgroup/cpu/cpu.cfs_period_us")}


def cgroup_cpu_limit() -> int | None:
    """The CPUs a cgroup CPU quota allows this process, ceil(quota / period) and at least 1; None where
    there is no quota or none can be read (cgroup v2's cpu.max, else v1's cfs files)."""
    try:
        quota, period = CGROUP_CPU_FILES["v2"].read_text().split()[:2]
        if quota == "max":
            return None
    except (OSError, ValueError):
        try:
            quota = CGROUP_CPU_FILES["v1_quota"].read_text().strip()
            period = CGROUP_CPU_FILES["v1_period"].read_text().strip()
        except OSError:
            return None
    try:
        quota, period = int(quota), int(period)
    except ValueError:
        return None
    if quota <= 0 or period <= 0:
        return None
    return max(1, -(-quota // period))


# PoCL's kernel cache -----------------------------------------------------------------------------------
#
# PoCL keeps compiled kernels in $POCL_CACHE_DIR, else $XDG_CACHE_HOME/pocl, else ~/.cache/pocl. When
# that directory cannot be created or written (a read-only HOME, as in some containers and CI sandboxes),
# PoCL lists its platform with no device at all, which looked like a missing driver (or, a file named by
# POCL_CACHE_DIR, a device that fails every build). Before the first device query, clsky checks the
# directory; if it is the default one (POCL_CACHE_DIR unset), clsky sets POCL_CACHE_DIR to a private
# directory under the system's temporary directory, and XDG_CACHE_HOME too where it came from HOME
# (PyOpenCL's own cache, pytools', lives under it: it failed there next), and says so once on stderr: the
# run works, only the compiled kernels are kept there instead. The private directory is clsky's only if it
# is a directory (not a link) of this user's, which no one else may write: a name in /tmp that another
# user made first would have received the kernels and supplied binaries to load. A POCL_CACHE_DIR the
# user set is never overridden: the error then names it, before any work (make_context).

_logger = logging.getLogger("clsky")


def _pocl_cache_directory():
    """(directory, the variable it comes from) of PoCL's kernel cache."""
    if os.environ.get("POCL_CACHE_DIR"):
        return pathlib.Path(os.environ["POCL_CACHE_DIR"]), "POCL_CACHE_DIR"
    if os.environ.get("XDG_CACHE_HOME"):
        return pathlib.Path(os.environ["XDG_CACHE_HOME"]) / "pocl", "XDG_CACHE_HOME"
    return pathlib.Path(os.path.expanduser("~")) / ".cache" / "pocl", "HOME"


#: Free space a kernel cache needs [bytes]: PoCL writes each program's binaries there (up to about a MB each);
#: on a full disk an empty test file was still created, and the first build failed with PyOpenCL's traceback.
MIN_CACHE_FREE_BYTES = 4 * 2**20


def _cache_unusable(directory: pathlib.Path):
    """None if ``directory`` exists or can be made, a file can be written in it, and it has
    :data:`MIN_CACHE_FREE_BYTES` free; else why not, in words ('is not a writable directory', 'has 0.04 MiB
    free, ...')."""
    try:
        directory.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=directory):
            pass
        status = os.statvfs(directory) if hasattr(os, "statvfs") else None
    except OSError:
        return "is not a writable directory"
    free = None if status is None else status.f_bavail * status.f_frsize
    if free is not None and free < MIN_CACHE_FREE_BYTES:
        return f"has {free / 2**20:.2g} MiB free, under the {MIN_CACHE_FREE_BYTES // 2**20} MiB its builds need"
    return None


def _private_directory(directory: pathlib.Path):
    """None if ``directory`` is (or is now made) a directory of this user's that no one else can write, not
    a symbolic link, where a file can be written (the fallback cache, in a shared directory): one of this
    user's that others may write (an earlier clsky's, made under a umask of 002) is made private; else why
    not, in words."""
    try:
        directory.mkdir(mode=0o700, exist_ok=True)
        status = os.lstat(directory)
    except OSError as error:
        return f"it cannot be made ({error.strerror or error})"
    if not stat.S_ISDIR(status.st_mode):
        return "it is a link or a file, not a directory"
    if hasattr(os, "getuid") and status.st_uid != os.getuid():
        return "another user owns it"
    if status.st_mode & 0o022:
        try:
            os.chmod(directory, stat.S_IMODE(status.st_mode) & ~0o022)
        except OSError:
            return "others may write it"
    unusable = _cache_unusable(directory)
    return None if unusable is None else f"it {unusable}"


@functools.lru_cache(maxsize=1)
def pocl_cache_problem():
    """None when PoCL's kernel cache is usable (after falling back to a temporary one if needed, see
    above); otherwise one sentence saying which directory is not writable and what to set."""
    directory, source = _pocl_cache_directory()
    reason = _cache_unusable(directory)
    if reason is None:
        return None
    if source == "POCL_CACHE_DIR":
        return (f"PoCL's kernel cache POCL_CACHE_DIR={directory} {reason} (PoCL then finds no device, or fails every "
                f"build); set POCL_CACHE_DIR to a writable directory with {MIN_CACHE_FREE_BYTES // 2**20} MiB free")
    fallback = pathlib.Path(tempfile.gettempdir()) / f"clsky-pocl-cache-{getattr(os, 'getuid', lambda: 'user')()}"
    unusable = _private_directory(fallback)
    if unusable is None:
        os.environ["POCL_CACHE_DIR"] = str(fallback)
        also = ""
        cache_home = directory.parent
        if source == "HOME" and _cache_unusable(cache_home) is not None:
            # PyOpenCL's own cache (pytools') is under XDG_CACHE_HOME, else ~/.cache: it failed there next
            os.environ["XDG_CACHE_HOME"] = str(fallback / "xdg")
            also = f", and {fallback / 'xdg'} for the caches under {cache_home}"
        _logger.warning(f"clsky: note: PoCL's kernel cache {directory} (from {source}) {reason}; "
                        f"using {fallback}{also} (set POCL_CACHE_DIR or XDG_CACHE_HOME to choose)")
        return None
    return (f"PoCL's kernel cache {directory} (from {source}) {reason}, and the fallback {fallback} is "
            f"not usable: {unusable} (PoCL then finds no device); set POCL_CACHE_DIR or XDG_CACHE_HOME to a "
            f"writable directory with {MIN_CACHE_FREE_BYTES // 2**20} MiB free")


def no_device_hint() -> str:
    """What to do when no device is found: fix PoCL's cache if that is the cause, else install a driver."""
    return pocl_cache_problem() or INSTALL_HINT


# Devices ----------------------------------------------------------------------------------------------

def _pocl_version(platform) -> tuple[int, ...]:
    match = re.search(r"PoCL (\d+)\.(\d+)", platform.version)
    return tuple(int(g) for g in match.groups()) if match else ()


def _release_rank(platform) -> int:
    """Release builds before release candidates of the same version (3.0 < 3.0-rc2 would be wrong)."""
    return 0 if re.search(r"-rc\d", platform.version) else 1


def _is_intel_cpu_runtime(device) -> bool:
    """Intel's CPU OpenCL runtime (platform 'Intel(R) OpenCL', a CPU device), not an Intel GPU's."""
    return device.platform.name.startswith("Intel(R) OpenCL") and bool(device.type & cl.device_type.CPU)


def _device_rank(device) -> tuple:
    is_gpu = bool(device.type & cl.device_type.GPU)
    platform = device.platform
    return (is_gpu, _is_intel_cpu_runtime(device), _pocl_version(platform), _release_rank(platform),
            device.max_compute_units)


def _all_devices():
    pocl_cache_problem()                 # before PoCL starts: it reads POCL_CACHE_DIR once
    try:
        platforms = cl.get_platforms()
    except cl.Error:
        return []
    return [d for p in platforms for d in p.get_devices()]


def has_fp64(device) -> bool:
    return bool(pyopencl.characterize.has_double_support(device))


def describe_device(device) -> str:
    """Short name of a device with its platform, e.g. 'pthread-skylake-avx512 (PoCL 3.1+debian)' or
    'AMD EPYC (Intel(R) OpenCL, OpenCL 3.1 LINUX)'."""
    match = re.search(r"PoCL [^ ]+", device.platform.version)
    if match:
        return f"{device.name} ({match.group(0)})"
    return f"{device.name} ({device.platform.name.strip()}, {device.platform.version.strip()})"


def default_device():
    """The device clsky uses when ``PYOPENCL_CTX`` is not set (see module docstring)."""
    devices = _all_devices()
    if not devices:
        raise NoDeviceError(f"no OpenCL device found; {no_device_hint()}")
    return max(devices, key=_device_rank)


_shared_contexts: dict = {}


def check_context(ctx):
    """``ctx`` if it is None (clsky's shared context, :func:`make_context`) or a pyopencl.Context;
    ValueError naming ``ctx`` otherwise (an engine or a memory check would end in AttributeError)."""
    return check_instance("ctx", ctx, cl.Context, "None (clsky's device) or a pyopencl.Context", optional=True)


def make_context(dtype=np.float64):
    """The context of the chosen device, shared by every engine of the process (so that programs
    built once are found in the in-process cache); NoDeviceError if that device lacks fp64 when
    float64 is asked."""
    selector = os.environ.get("PYOPENCL_CTX")
    problem = pocl_cache_problem()
    if selector not in _shared_contexts:
        if selector:
            try:
                context = cl.create_some_context(interactive=False)
            except (cl.Error, RuntimeError, ValueError) as error:
                if not _all_devices():        # no driver, or PoCL's cache: not the selector's fault
                    raise NoDeviceError(f"no OpenCL device found; {no_device_hint()}") from error
                raise DeviceSelectionError(f"PYOPENCL_CTX={selector!r} selects no device: {error}; "
                                           "run `clsky devices` to list them") from error
        else:
            context = cl.Context([default_device()])
        _shared_contexts[selector] = context
    context = _shared_contexts[selector]
    if problem and context.devices[0].platform.name.startswith("Portable Computing Language"):
        # PoCL may list its device with a cache it cannot write (POCL_CACHE_DIR a file): every build failed,
        # in a PyOpenCL traceback after the checks
        raise NoDeviceError(problem)
    check_dtype(context.devices[0], dtype)
    return context


def check_dtype(device, dtype):
    """Raise TypeError for a dtype other than float32/float64, NoDeviceError for float64 without fp64."""
    dtype = np.dtype(dtype)
    if dtype not in (np.float32, np.float64):
        raise TypeError(f"dtype must be float32 or float64, got {dtype}")
    if dtype == np.float64 and not has_fp64(device):
        raise NoDeviceError(f"device {device.name!r} has no double precision (cl_khr_fp64); use "
                            f"dtype=float32 or {INSTALL_HINT}")


def list_devices():
    """Every platform/device as a list of dicts (name, platform, version, fp64, chosen)."""
    devices = _all_devices()
    chosen = None
    if os.environ.get("PYOPENCL_CTX"):
        try:
            chosen = make_context(np.float32).devices[0]
        except NoDeviceError:
            chosen = None
    elif devices:
        chosen = default_device()
    return [{"platform": d.platform.name, "platform_version": d.platform.version, "device": d.name,
             "device_version": d.version, "type": cl.device_type.to_string(d.type),
             "compute_units": d.max_compute_units, "fp64": has_fp64(d), "chosen": d == chosen}
            for d in devices]


# Programs ---------------------------------------------------------------------------------------------

@functools.lru_cache(maxsize=1)
def kernel_directory():
    """Where the ``.cl`` files are: the installed ``clsky.kernels`` resources, or, when clsky runs
    from a source checkout (the package directory shadows the installed one), ``kernels/`` beside it."""
    try:
        return importlib.resources.files("clsky.kernels")
    except ModuleNotFoundError:
        checkout = pathlib.Path(__file__).resolve().parent.parent / "kernels"
        if checkout.is_dir():
            return checkout
        raise KernelBuildError("the OpenCL sources (clsky.kernels) are not installed; reinstall clsky") from None


def _kernel_text(name: str) -> str:
    return kernel_directory().joinpath(name).read_text(encoding="utf-8")


_program_cache: dict = {}
_program_cache_lock = threading.Lock()


def compiler_output_wanted() -> bool:
    """Whether the user asked for the compilers' logs (``PYOPENCL_COMPILER_OUTPUT`` set and not empty)."""
    return bool(os.environ.get("PYOPENCL_COMPILER_OUTPUT"))


@contextlib.contextmanager
def quiet_compiler_output():
    """Within: PyOpenCL's warnings about a *successful* build's log are not shown, unless
    ``PYOPENCL_COMPILER_OUTPUT`` is set (then PyOpenCL prints the whole log). Such logs are chatter, not
    problems: PoCL on CPUs without AVX-512 says that double8 arguments change the ABI, Intel's CPU runtime
    logs every build ("Compilation started", ...), also of PyOpenCL's own array kernels. A failed build
    still raises. Used around clsky's builds and by the command line around the whole command."""
    with warnings.catch_warnings():
        if not compiler_output_wanted():
            warnings.simplefilter("ignore", cl.CompilerWarning)
        yield


#: The OpenCL build option that inhibits all warning messages (every OpenCL version's clBuildProgram,
#: "Options to Request or Suppress Warnings"). PoCL's clang writes its diagnostics' count ("176 warnings
#: generated.") straight to the process's standard error, past Python's warning filters: on a CPU without
#: AVX-512 every program that calls a builtin on a double8 warns that the argument "changes the ABI" (a
#: note about calling conventions, not about our code), and a first ``clsky animate`` printed six such
#: lines between its plan and its progress bars. :func:`build_program` passes it unless
#: :func:`compiler_output_wanted`. Warnings are diagnostics only: the default animation's 123 files were
#: the same with it, byte for byte.
NO_WARNINGS = "-w"


def _compiler_options(options) -> list[str]:
    """The options handed to the OpenCL compiler: ``options`` plus :data:`NO_WARNINGS` unless the
    compiler's output was asked for."""
    return list(options) if compiler_output_wanted() else [*options, NO_WARNINGS]


def build_program(context, sources, options=()):
    """Build (or fetch from the in-process cache) the program made of ``sources`` in order.

    Each item of ``sources`` is a file name in ``kernels/`` or a :class:`Source`.
    """
    options = tuple(sorted(options))
    key = (context.int_ptr, tuple(sources), options)
    with _program_cache_lock:
        if key in _program_cache:
            return _program_cache[key]
    parts = []
    for item in sources:
        label, text = (item.label, item.text) if isinstance(item, Source) else (item, _kernel_text(item))
        parts.append(f"/* ---- {label} ---- */\n#line 1\n{text}\n")
    names = [s.label if isinstance(s, Source) else s for s in sources]
    try:
        with quiet_compiler_output():
            program = cl.Program(context, "".join(parts)).build(options=_compiler_options(options))
    except cl.Error as error:
        device = context.devices[0]
        raise KernelBuildError(f"building {names} with options {list(options)} on {device.name!r} "
                               f"({device.platform.version}) failed:\n{error}") from error
    with _program_cache_lock:
        _program_cache[key] = program
    return program


def real_vector_dtype(dtype, width: int):
    """NumPy dtype of the OpenCL vector ``real<width>`` for ``dtype`` (float32 or float64)."""
    base = "double" if np.dtype(dtype) == np.float64 else "float"
    return getattr(pyopencl.cltypes, f"{base}{width}")


@functools.lru_cache(maxsize=None)
def _struct(device, name, fields, dtype_str):
    dtype = np.dtype([(fname, ftype) for fname, ftype in fields])
    try:                # PyOpenCL builds a small program for the layout: its failure is a build's, named so
        dtype, declaration = pyopencl.tools.match_dtype_to_c_struct(device, name, dtype)
    except cl.Error as error:
        raise KernelBuildError(f"building the layout of the struct {name} on {device.name!r} "
                               f"({device.platform.version}) failed: {str(error).splitlines()[0]} (a kernel cache "
                               f"on a full disk fails every build: POCL_CACHE_DIR, XDG_CACHE_HOME)") from error
    dtype = pyopencl.tools.get_or_register_dtype(f"{name}_{dtype_str}", dtype)
    return dtype, declaration


def struct_dtype(device, name, fields, dtype):
    """(NumPy dtype, C declaration) of a struct, matched to the device's layout.

    ``fields`` is a tuple of (name, numpy dtype) pairs; the declaration is generated from it, so the C
    and NumPy views can never drift apart.
    """
    return _struct(device, name, tuple(fields), np.dtype(dtype).name)


# Engine -----------------------------------------------------------------------------------------------

def memory_pool(queue):
    """A pool of device buffers for the arrays of one computation on ``queue`` (PyOpenCL's
    ``MemoryPool``): a buffer its array frees is kept and handed to the next array of a similar size.

    Why: the table builds make and drop arrays of 100-300 MB per order; on a CPU device every fresh
    buffer is fresh memory whose pages the kernel faults in one by one (PoCL; about 27 000 faults per
    100 MB, some 0.1-0.3 s of system time each), where a reused one is already mapped. Safe on one
    in-order queue: a buffer goes back to the pool when its array is dropped, and any later command that
    writes it runs after every command already enqueued that reads it. The pool holds its buffers until
    it is dropped (or :meth:`free_held`): keep it to one computation.
    """
    import pyopencl.tools as cl_tools

    return cl_tools.MemoryPool(cl_tools.ImmediateAllocator(queue))


def upload_padded(queue, table, dtype, width=8, copies=1, allocator=None, interleaved=False, queues=None):
    """A host table (..., C), ``copies`` C <= ``width``, as a device array (..., width) of ``dtype`` whose
    channels are the table's (``copies`` times side by side: 2 for an order's nodes, whose channels 0-2
    and 3-5 both hold L) and then zeros (the kernels' padded tables: one real8 a cell): a zero fill, then
    a rectangular write a copy (rows of C values into rows of ``width``, clEnqueueWriteBufferRect)
    straight from the table, or from a copy of ``dtype`` where it has another type (a float32 device). No
    padded copy on the host: on a CPU device that copy was fresh memory faulted in (the default
    animation's gathered harmonics: 327 MB, 0.1-0.3 s a 100 MB, :func:`memory_pool`), and on an NVIDIA
    H200 the rectangular write of rows of 6 into rows of 8 was no slower than a contiguous one (17 ms for
    the default animation's table). With ``interleaved`` a stack of N tables (N, ..., C) arrives with its
    tables interleaved row by row, as (..., N, width): table n's rows a row pitch of N ``width`` apart
    (the gathered source's harmonics, :func:`clsky.transmittance.upload_gathered_source`). The writes are
    blocking: the table may go once this returns. The array comes from ``allocator`` if given.

    With ``queues`` (queues of ``queue``'s context), each queue fills and writes its own share of the rows,
    all of them waited for: PoCL copies each queue's commands on a thread of its own, so two queues take
    half the wall time of one on a CPU (the default animation's first gather, 117 MB into fresh memory:
    49-59 against 91-113 ms; the same CPU time). Default: ``queue`` alone."""
    import pyopencl.array as cla

    dtype = np.dtype(dtype)
    table = np.asarray(table)
    channels = table.shape[-1] if table.ndim else 0
    if table.ndim < 2 + bool(interleaved) or not 1 <= channels * copies <= width or copies < 1 or table.size == 0:
        stack = "a stack (N, ..., C)" if interleaved else "shape (..., C)"
        raise ValueError(f"upload_padded: table must have {stack} with 1 <= C <= {width // max(copies, 1)} "
                         f"({copies} copies a row of {width}) and values, got {table.shape}")
    tables = table if interleaved else table[None]
    shape = tables.shape[1:-1] + (len(tables), width) if interleaved else table.shape[:-1] + (width,)
    padded = cla.empty(queue, shape, dtype, allocator=allocator)
    size, rows, pitch = dtype.itemsize, tables[0].size // channels, len(tables) * width * dtype.itemsize
    queues = list(queues) if queues else [queue]
    sources = [np.ascontiguousarray(one, dtype=dtype).reshape(rows, channels) for one in tables]
    # other queues start after the commands of `queue` so far (a pool's buffer may still be read there)
    after = [cl.enqueue_marker(queue)] if any(share is not queue for share in queues) else None
    writes = []
    for part, share in enumerate(queues):
        first, end = rows * part // len(queues), rows * (part + 1) // len(queues)
        if end == first:
            continue
        cl.enqueue_fill_buffer(share, padded.data, np.zeros(1, dtype), padded.offset + first * pitch,
                               (end - first) * pitch, wait_for=after)
        writes += [cl.enqueue_copy(share, padded.data, source[first:end],
                                   buffer_origin=(padded.offset + first * pitch + (n * width + copy * channels) * size,
                                                  0, 0),
                                   host_origin=(0, 0, 0), region=(channels * size, end - first, 1),
                                   buffer_pitches=(pitch, 0), host_pitches=(channels * size, 0), is_blocking=False)
                   for n, source in enumerate(sources) for copy in range(copies)]
    cl.wait_for_events(writes)
    return padded


#: Cells or pixels per work-item of the kernels that integrate along rays (``-DVECTOR_WIDTH``, kernels/real.cl):
#: None (the default) for each device's own (:func:`default_vector_width`), else 1 or 8 on every device.
#: 8 is double8 (or float8) arithmetic: PoCL does not vectorise across work-items by itself, and its scalar
#: ray march costs 6.4x the CPU time, Intel's CPU runtime's 1.2x. 1 is one lane per work-item, what a GPU's
#: SIMT lanes want: on an NVIDIA H200 the scalar ray march took 3 ms a 512 x 512 frame against 7, the
#: sky-view map 3 against 5, the same frames (README "Speed", GPUs). tests/test_vector_width.py checks 1
#: against 8. An engine reads it when it is made (:attr:`Engine.vector_width`): its programs and its
#: launches keep that width.
VECTOR_WIDTH = None
#: The widths the kernels accept.
VECTOR_WIDTHS = (1, 8)


def default_vector_width(device) -> int:
    """1 on a GPU (its lanes are work-items), 8 on any other device (CPUs: double8 is their vector unit)."""
    return 1 if device.type & cl.device_type.GPU else 8


#: The work-group of the launches with one work-item a cell, row, chunk or query (add_into, combine_nodes,
#: pack_channels, the stopping test's running_sum and order_ratios, lookup, lookup4d, optical_depth), fixed.
#: Left to PoCL (local size None), every new global size got a divisor of it, up to 4096, as its local
#: size, and PoCL compiles a kernel object per local size (0.03-0.07 s each, once per machine): a new
#: table size cost its user a few of them, and the default suite on an empty kernel cache compiled 877
#: objects where it now compiles 519 (docs/speed-log.md); a prime count got work-groups of one item. 256,
#: side by side on the default animation's planned table (this AMD EPYC, 8 rounds): add_into,
#: combine_nodes and pack_channels as fast as with PoCL's 4096 (within the machine's noise, 10 %), the
#: stopping test's 416 chunks 11-13 ms on both cores against 16-20 ms in PoCL's one work-group.
#: :func:`launch_size` shrinks it where a kernel allows less (a GPU).
LINEAR_WORK_GROUP = (256,)


def launch_size(kernel, device, counts, group) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """Global and local sizes of a launch of ``kernel`` on ``device`` over ``counts`` work-items per axis
    in work-groups of ``group`` (a tuple of the same length): the group, each axis at most the device's
    (``max_work_item_sizes``: 64 along the third on NVIDIA's) and its largest axis halved (rounded up)
    until it fits the kernel's work-group size on the device, and each count rounded up to a multiple of
    it. The kernels return for work-items beyond their counts. A fixed group compiles one kernel object
    per program on PoCL, whatever the counts (:data:`LINEAR_WORK_GROUP`)."""
    if len(counts) != len(group) or min(group) < 1:
        raise ValueError(f"counts and group must be of one length, group >= 1; got {counts} and {group}")
    largest = kernel.get_work_group_info(cl.kernel_work_group_info.WORK_GROUP_SIZE, device)
    local = [min(size, most) for size, most in zip(group, device.max_work_item_sizes)]
    while np.prod(local) > largest:
        axis = int(np.argmax(local))
        local[axis] = -(-local[axis] // 2)
    return tuple(-(-max(int(n), 1) // g) * g for n, g in zip(counts, local)), tuple(local)


#: How a padded device table's rows of 8 values come to the host when only 3 or 6 of them are wanted (the
#: orders' nodes and the gathered sum, :mod:`clsky.azimuth`): None (the default) for each device's own
#: (:func:`rectangular_reads`); True, rectangular reads (clEnqueueReadBufferRect, rows of 3 or 6 values
#: straight into the host table); False, a packing kernel on the device and one contiguous read. On PoCL
#: here a node's 1.7 million rows of 3 read rectangularly in 6-8 ms, packed in 23-29 ms (scripts/gpu_checks.sh's
#: copies step, 2026-12-04); on an NVIDIA H200 rectangularly in 400-414 ms, against 26-32 ms for a contiguous
#: read of all 8: most of the planned table's 10.3 s there, which took 2.2 s with packed reads (README
#: "Speed", GPUs). The same bits either way (tests/test_azimuth.py).
RECTANGULAR_READS = None


def rectangular_reads(device) -> bool:
    """:data:`RECTANGULAR_READS` if set, else True on a CPU device and False on any other."""
    if RECTANGULAR_READS is not None:
        return bool(RECTANGULAR_READS)
    return bool(device.type & cl.device_type.CPU)


def upload_share_queues(queue, reuse=None):
    """Queues for :func:`upload_padded`'s ``queues`` on ``queue``'s device, the one place that decides
    whether uploads split: on a CPU two queues (PoCL copies each queue's commands on a thread of its own:
    half the wall time on the 2-core machine), ``reuse`` where given (queues of the caller's own on that
    device, such as a table build's copy queues), else two new ones; None elsewhere (a GPU's copies are its
    DMA engines', not measured split)."""
    if not queue.device.type & cl.device_type.CPU:
        return None
    return list(reuse) if reuse else [cl.CommandQueue(queue.context, queue.device) for _ in range(2)]


def packed_reads(device) -> bool:
    """True where a table build on ``device`` (a pyopencl.Device, or None: no device) packs its reads on
    the device (not :func:`rectangular_reads`): what its memory estimate counts
    (``clsky.resources.estimate_table_memory``'s ``packed_reads``)."""
    return device is not None and not rectangular_reads(device)


#: The build option that makes float32 division and square roots correctly rounded, as float64's always
#: are. Without it OpenCL allows them 2.5 and 3 ulp, and NVIDIA's compiler takes that: on an H200
#: (2026-12-04) float32 frames then differed from float64 ones by up to 1.27e-5 of the frame's maximum
#: (tests/test_extremes.py, horizon pixels seen from 100 km), against 3.8e-6 with it, as on PoCL. CPUs
#: divide correctly rounded anyway: the same bits on PoCL with and without it.
FP32_CORRECTLY_ROUNDED = "-cl-fp32-correctly-rounded-divide-sqrt"


def correctly_rounded_divide_sqrt(device) -> bool:
    """True if ``device`` accepts :data:`FP32_CORRECTLY_ROUNDED` (it lists
    CL_FP_CORRECTLY_ROUNDED_DIVIDE_SQRT among its single-precision capabilities)."""
    return bool(device.single_fp_config & cl.device_fp_config.CORRECTLY_ROUNDED_DIVIDE_SQRT)


#: How the kernels take the non-linear mapping's cube roots (kernels/mapping.cl, ``CUBE_ROOT_UNIT``):
#: "halley", a bit-pattern seed and three Halley steps, within 3 ulp of the exact root and
#: 2.5x cheaper than OpenCL's ``cbrt`` on PoCL here (in double precision; float32 always uses
#: ``cbrt``); "library", ``cbrt`` itself (``-DCUBE_ROOT_LIBRARY=1``): the kernels of the commits before
#: 2026-12-03's, bit for bit, which tests/pins.py holds them to. An engine reads it when it is made
#: (:attr:`Engine.cube_root`).
CUBE_ROOT = "halley"
#: The cube roots the kernels offer.
CUBE_ROOTS = ("halley", "library")


def serialized(method):
    """``method`` of an engine, or of an object holding one as ``self.engine`` (a renderer), run under that
    engine's :attr:`Engine.lock` and refused once it is closed (ValueError, as a closed file's methods are).

    A kernel object's arguments are set, then it is enqueued: two threads calling one renderer swapped
    each other's arguments in between (wrong frames without an error, or PoCL aborting the process). The
    public methods of the renderers and lookup engines are serialized: one object may be shared by threads,
    whose calls run one at a time (its device runs one launch at a time anyway)."""
    @functools.wraps(method)
    def run(self, *args, **kwargs):
        engine = self if isinstance(self, Engine) else self.engine
        with engine.lock:
            if engine.closed:
                raise ValueError(f"this {type(self).__name__} is closed (close() or the end of its with block): "
                                 f"make a new one")
            return method(self, *args, **kwargs)
    return run


class Engine:
    """Owns one OpenCL program: builds it once and fetches every kernel once.

    Subclasses set :attr:`sources` and may extend :meth:`build_options`. An engine's own calls are not
    thread-safe (use one engine per thread) but for the methods marked :func:`serialized`, which hold
    :attr:`lock`.

    Parameters
    ----------
    ctx : pyopencl.Context, optional
        Defaults to :func:`make_context`.
    dtype : numpy dtype
        float64 (default) or float32: the kernels' ``real`` type.
    profile : bool
        Keep (label, event) pairs of every launch in :attr:`events`.
    fast_math : bool
        Build with ``-cl-fast-relaxed-math`` (opt-in: it implies finite-math-only).
    queue : pyopencl.CommandQueue, optional
        Run on this queue (another engine's: their commands then run in order, with no wait between
        them) instead of a new one; ``ctx`` is then its context.
    allocator : pyopencl allocator, optional
        Where the device arrays the engine creates come from (:func:`memory_pool`: buffers freed by one
        order are reused by the next); None: a new buffer each time.

    Attributes
    ----------
    vector_width : int
        :data:`VECTOR_WIDTH` when the engine was made (None: :func:`default_vector_width` of its device):
        the ``-DVECTOR_WIDTH`` of its programs and the
        lanes per work-item of its launches.
    cube_root : str
        :data:`CUBE_ROOT` when the engine was made: how its programs take the mapping's cube roots.
    lock : threading.RLock
        Held by :func:`serialized` methods (of the engine, or of the renderer holding it) and by
        :meth:`close`.
    closed : bool
        :meth:`close` was called: :func:`serialized` methods refuse to run.
    """

    sources: tuple = ()

    def __init__(self, ctx=None, dtype=np.float64, profile=False, fast_math=False, queue=None, allocator=None):
        self.dtype = np.dtype(dtype)
        if VECTOR_WIDTH is not None and VECTOR_WIDTH not in VECTOR_WIDTHS:
            raise ValueError(f"clsky._cl.VECTOR_WIDTH must be None or one of {VECTOR_WIDTHS}, got {VECTOR_WIDTH!r}")
        if CUBE_ROOT not in CUBE_ROOTS:
            raise ValueError(f"clsky._cl.CUBE_ROOT must be one of {CUBE_ROOTS}, got {CUBE_ROOT!r}")
        self.cube_root = CUBE_ROOT
        if queue is not None:
            ctx = check_instance("queue", queue, cl.CommandQueue, "None or a pyopencl.CommandQueue").context
        self.ctx = check_context(ctx) if ctx is not None else make_context(self.dtype)
        self.device = self.ctx.devices[0]
        check_dtype(self.device, self.dtype)
        self.vector_width = VECTOR_WIDTH if VECTOR_WIDTH is not None else default_vector_width(self.device)
        self.fast_math = check_flag("fast_math", fast_math)
        if queue is None:
            properties = cl.command_queue_properties.PROFILING_ENABLE if profile else 0
            queue = cl.CommandQueue(self.ctx, properties=properties)
        self.queue = queue
        self.allocator = allocator
        self.profile = profile
        self.events: list = []
        self._feature_kernels: dict = {}
        self.lock = threading.RLock()
        self.closed = False

    @functools.cached_property
    def program(self):
        """The program of :meth:`program_sources` with :meth:`build_options`, built at its first use.

        An engine whose atmosphere has compile-time features (ozone, a ground: :meth:`kernels_with`) may
        never launch a kernel of the plain program: the physical preset's single-scattering and
        transmittance engines do not, nor the pilot's renderer; built in ``__init__``, those programs took
        7 of the default animation's 22 PoCL builds (22-60 ms each on one core; docs/speed-log.md). A build
        error now surfaces at the first launch. On Python 3.11 ``cached_property`` holds one lock for all
        instances, so two threads' first builds run one after the other (they would share the cores
        anyway)."""
        return build_program(self.ctx, self.program_sources(), self.build_options())

    @functools.cached_property
    def kernels(self) -> dict:
        """{name: kernel} of :attr:`program` (built at the first use of either)."""
        return {k.function_name: k for k in self.program.all_kernels()}

    def kernels_with(self, defines=()):
        """The kernels of this engine's program built with the extra ``-D`` options ``defines`` (an
        atmosphere's compile-time features, e.g. ``-DOZONE=1``; see
        ``clsky._atmosphere_cl.feature_defines``): :attr:`kernels` itself when there are none. Each
        variant is built once (in-process program cache) and its kernels fetched once."""
        if not defines:
            return self.kernels
        key = tuple(sorted(defines))
        if key not in self._feature_kernels:
            program = build_program(self.ctx, self.program_sources(), self.build_options() + list(key))
            self._feature_kernels[key] = {k.function_name: k for k in program.all_kernels()}
        return self._feature_kernels[key]

    def program_sources(self):
        return self.sources

    def build_options(self) -> list[str]:
        options = ["-DREAL_IS_DOUBLE=1"] if self.dtype == np.float64 else []
        if self.cube_root == "library":
            options.append("-DCUBE_ROOT_LIBRARY=1")
        if self.fast_math:
            options.append("-cl-fast-relaxed-math")
        elif self.dtype == np.float32 and correctly_rounded_divide_sqrt(self.device):
            options.append(FP32_CORRECTLY_ROUNDED)
        return options

    def real(self, value):
        return self.dtype.type(value)

    def real2(self, pair):
        """``pair`` as the kernels' ``real2`` (e.g. the sun axis' w range, mapping.cl)."""
        record = np.zeros((), dtype=real_vector_dtype(self.dtype, 2))
        record["x"], record["y"] = pair
        return record

    def real4(self, values):
        """``values`` (three numbers, e.g. r, g, b, or four) as the kernels' ``real4`` (.w = 0 for three)."""
        record = np.zeros((), dtype=real_vector_dtype(self.dtype, 4))
        for name, value in zip(("x", "y", "z", "w"), values):
            record[name] = value
        return record

    def real8(self, values):
        """``values`` (8 numbers) as the kernels' ``real8``."""
        return np.array(tuple(values), dtype=self.dtype).view(real_vector_dtype(self.dtype, 8)).reshape(())

    def _linear_size(self, kernel, items):
        """Global and local sizes of a launch of ``kernel`` over ``items`` work-items in work-groups of
        :data:`LINEAR_WORK_GROUP` (:func:`launch_size`)."""
        return launch_size(kernel, self.device, (items,), LINEAR_WORK_GROUP)

    def _record(self, label, event):
        if self.profile:
            self.events.append((label, event))
        return event

    def close(self):
        """Wait for the queue and drop the kernels; :func:`serialized` methods refuse to run from then on.
        Closing twice is harmless."""
        with self.lock:
            if self.closed:
                return
            self.closed = True
            self.queue.finish()
            self.kernels = {}
            self._feature_kernels = {}

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
