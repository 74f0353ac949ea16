"""The overlapped frame pipeline: the next frame renders on a worker thread while the caller works on the
current one.

An animation's frame has two halves that need nothing of each other across frames: the device half
(:func:`clsky.anim.animate.render_frame`: the OpenCL kernels of both renderers and the conversion to
cd/m^2) and the host half (display, comparison, PNG encoding, the hand-off to ffmpeg, all on the main
thread). :func:`prefetched` runs the device half of frame i + 1 on one worker thread while the caller
runs the host half of frame i: PyOpenCL releases the GIL while it waits for a kernel and its copy, and
NumPy while it computes on whole frames, so the two halves overlap.

Who owns the two cores (README, "Speed"): PoCL's two worker threads render on both; the host half is one
thread (its BLAS limited to one thread, :func:`clsky._cl.host_blas_single_threaded`); ffmpeg keeps x264's
own threads (its output may depend on their number). With the overlap three busy threads share two cores:
the device half is the larger (about 0.5 CPU-s of a 0.8 CPU-s frame), so PoCL keeping both cores while
the host thread takes its share by time slicing leaves no core idle, where limiting PoCL to one core
would make the device half alone longer than the whole frame's share of two cores.

The frames are the same with and without the overlap: each frame is computed by the same calls on the
same inputs, only on another thread, and the results are consumed in order (tests/test_animate.py
compares the files of both).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Iterable, Iterator, Tuple, TypeVar

__all__ = ["prefetched"]

Item = TypeVar("Item")
Result = TypeVar("Result")


def prefetched(function: Callable[[Item], Result], items: Iterable[Item],
               overlap: bool = True) -> Iterator[Tuple[Item, Result]]:
    """(item, function(item)) for every item, in order; with ``overlap``, ``function`` of the next item runs
    on one worker thread while the caller works on the current pair (one frame ahead, never more: two
    frames' results live at a time).

    ``function`` is only ever called from one thread at a time (the worker, or the caller's without
    ``overlap``), so an OpenCL engine used by it needs no locking (:class:`clsky._cl.Engine` is not
    thread-safe). An exception raised by ``function`` reaches the caller when it asks for that item. If
    the caller stops early (an exception, or closing the iterator), the frame being rendered is finished
    and discarded before this returns.
    """
    if not overlap:
        for item in items:
            yield item, function(item)
        return
    items = list(items)
    if not items:
        return
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="clsky-frames") as worker:
        pending = worker.submit(function, items[0])
        try:
            for index, item in enumerate(items):
                result = pending.result()
                pending = worker.submit(function, items[index + 1]) if index + 1 < len(items) else None
                yield item, result
        finally:
            if pending is not None:
                pending.cancel()     # not started yet: dropped; running: the pool waits for it
