"""The C allocator of a process that renders frames: memory the frames free, kept for the next frames.

An animation's frames allocate and free the same large arrays again and again (a launch's HDR frames,
25 MB for 4 suns of 512 x 512; a frame's host temporaries, 6 MB each), most of them on worker threads
(:mod:`clsky.anim.pipeline`). With glibc's defaults such memory often goes back to the system when it
is freed: allocations above the mmap threshold (adjusted by glibc between 128 kB and 32 MB) are mapped
and unmapped one by one, and a worker thread's arena gives up a heap (64 MB at most) whenever it
empties. The next frame then touches fresh pages, which the kernel must fault in and clear (on the
2-core development machine at about 0.7 ns a byte, ``clear_page_erms`` 5 % of the default animation's
CPU samples). :func:`reuse_freed_memory` sets glibc's ``mallopt`` parameters so that the process keeps
what it frees (docs/speed-log.md: the default animation's CPU time and page faults with and without).

It changes the whole process, for the rest of its life (glibc cannot go back to its adaptive
threshold): ``clsky animate`` calls it at its start; a program that renders an animation through the
library may call it itself. It leaves the allocator alone where the environment configures it already
(``GLIBC_TUNABLES`` with ``glibc.malloc.*`` parameters, or a ``MALLOC_*`` variable of glibc's) and where
the C library is not glibc (musl, macOS, Windows).

References: glibc manual, "Memory Allocation Tunables"; mallopt(3).
"""

from __future__ import annotations

import ctypes
import os
import platform

__all__ = ["FRAME_LOOP_MALLOPT", "reuse_freed_memory"]

#: glibc's mallopt parameter numbers (malloc.h).
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD, M_ARENA_MAX = -1, -3, -8

#: What :func:`reuse_freed_memory` sets, name -> (mallopt parameter, value):
#:   arena_max 1: every thread allocates from the main arena (the program break), not from per-thread
#:     heaps of 64 MB that are unmapped when they empty (the frames' threads take a few dozen large
#:     blocks a frame: no contention to speak of);
#:   mmap_threshold 32 MiB (glibc's largest): blocks below it come from the arena and are reused, above
#:     it (a table build's buffers of 50-160 MB) they are mapped and given back when freed, as before;
#:   trim_threshold 256 MiB: the arena's free top is given back only beyond this (glibc's adaptive
#:     value is twice the mmap threshold: 64 MiB at most, less than two host threads' frames free at
#:     once). The default animation's page faults: 412 000-422 000 with 256 MiB, 593 000 with 64 MiB,
#:     664 000-1 136 000 untuned (docs/speed-log.md); its peak resident memory did not grow (1.14 GB).
FRAME_LOOP_MALLOPT = {"arena_max": (M_ARENA_MAX, 1), "mmap_threshold": (M_MMAP_THRESHOLD, 32 * 2**20),
                      "trim_threshold": (M_TRIM_THRESHOLD, 256 * 2**20)}

#: Environment variables through which glibc's allocator is configured (besides GLIBC_TUNABLES).
GLIBC_MALLOC_VARIABLES = ("MALLOC_ARENA_MAX", "MALLOC_ARENA_TEST", "MALLOC_MMAP_THRESHOLD_", "MALLOC_MMAP_MAX_",
                          "MALLOC_TRIM_THRESHOLD_", "MALLOC_TOP_PAD_", "MALLOC_PERTURB_", "MALLOC_CHECK_")


def configured_by_environment(environ=None) -> bool:
    """True where ``environ`` (default ``os.environ``) configures glibc's allocator: ``GLIBC_TUNABLES``
    naming a ``glibc.malloc.`` parameter, or one of :data:`GLIBC_MALLOC_VARIABLES` set."""
    environ = os.environ if environ is None else environ
    return ("glibc.malloc." in environ.get("GLIBC_TUNABLES", "")
            or any(name in environ for name in GLIBC_MALLOC_VARIABLES))


def reuse_freed_memory(environ=None) -> dict:
    """Set :data:`FRAME_LOOP_MALLOPT` in this process's glibc (module docstring), unless ``environ``
    (default ``os.environ``) configures the allocator already or the C library is not glibc.

    Returns the parameters set ({name: value}; empty where nothing was set). Call it before the frames'
    threads start: an arena a thread holds already stays its own."""
    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc" or configured_by_environment(environ):
        return {}
    mallopt = ctypes.CDLL(None).mallopt
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return {name: value for name, (parameter, value) in FRAME_LOOP_MALLOPT.items() if mallopt(parameter, value) == 1}
