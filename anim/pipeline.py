"""The overlapped frame pipeline: the next frame renders on a worker thread while host threads work on the
frames before it.

An animation's frame has two halves that need nothing of each other across frames: the device half
(:func:`clsky.anim.animate.render_frame` with ``convert=False``: the OpenCL kernels of both renderers
and their downloads) and the host half (:func:`clsky.anim.animate.convert_frames` to cd/m^2, the
auto-exposure's metering, display, comparison and composite). :func:`prefetched` runs the device half of
frame i + 1 on one worker thread while host threads run the host halves of the frames before it
(:func:`in_order`) and the caller's thread writes them (PNG, the hand-off to ffmpeg): PyOpenCL releases
the GIL while it waits for a kernel and its copy, and NumPy while it computes on whole frames, so they
overlap.

Host threads. The host half of the default animation's 512 x 512 frame is about 0.12 CPU-s on one
thread (conversion 37-45, display 73-80, comparison 46 CPU-ms on the 2-core machine, docs/speed-log.md;
about 0.25 CPU-s before its passes were trimmed), and the device half
shrinks with the device: a few ms on a GPU, about 0.5 CPU-s spread over the cores of a CPU (30 ms on 16,
if PoCL used them all); one host thread then bounds the animation (on the H200 of README "GPUs",
45-49 s for the default animation whose ray march took 3-7 ms a frame). :func:`in_order` gives the host
halves of several frames to a pool of threads and hands their results back in frame order; the one step
that must follow frame order, the auto-exposure's smoothing (``Display.next_ev``), waits on each thread
for the frame before (``clsky.anim.animate._ExposureOrder``) between the metering and the display, as a
frame farm's client smooths the EVs its workers metered (:mod:`clsky.anim.farm`).

Who owns the cores (docs/speed-log.md): PoCL's worker threads render on all of them; the host halves run
on ``clsky.anim.animate.check_animation_memory`` threads (one a core, at most 8, fewer where memory or
the frame count says so), their BLAS limited to one thread each
(:func:`clsky._cl.host_blas_single_threaded`; ``clsky.anim.animate.render_animation`` keeps NumPy's BLAS on
one thread throughout, the table's build and the display's set-up included); ffmpeg keeps x264's own threads (its
output may depend on their number). PoCL keeps every core while the host threads take their share by
time slicing, where limiting PoCL to fewer cores would make the device half alone longer than the whole
frame's share of them. On two cores one host thread was the default until 2026-12-05, when the default
level's cheaper table left the host halves the larger share: two measured 7-9 % less wall time for the
same CPU time (docs/speed-log.md).

The frames are the same with and without the overlap and with any number of host threads: each frame is
computed by the same calls on the same inputs, only on another thread, and the results are consumed in
order (tests/test_animate.py compares the files).
"""

from __future__ import annotations

import collections
import numbers
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Iterable, Iterator, Tuple, TypeVar

__all__ = ["prefetched", "in_order"]

Item = TypeVar("Item")
Result = TypeVar("Result")


def prefetched(function: Callable[[Item], Result], items: Iterable[Item],
               overlap: bool = True) -> Iterator[Tuple[Item, Result]]:
    """(item, function(item)) for every item, in order; with ``overlap``, ``function`` of the next item runs
    on one worker thread while the caller works on the current pair (one frame ahead, never more: two
    frames' results live at a time).

    With ``overlap`` the first call starts at once, before the first item is asked for: whatever the
    caller does between (an animation sets up its display, 0.9 s of importing colour-science on one core
    on the 2-core machine) runs beside the first render.

    ``function`` is only ever called from one thread at a time (the worker, or the caller's without
    ``overlap``), so an OpenCL engine used by it needs no locking (:class:`clsky._cl.Engine` is not
    thread-safe). An exception raised by ``function`` reaches the caller when it asks for that item. If
    the caller stops early (an exception, or ``close()``, also before the first item), the frame being
    rendered is finished and discarded before ``close()`` returns.
    """
    if not overlap:
        return ((item, function(item)) for item in items)
    return _Prefetched(function, list(items))


class _Prefetched:
    """:func:`prefetched`'s iterator with ``overlap``: the call of item 0 submitted at construction."""

    def __init__(self, function, items):
        self._function, self._items, self._next = function, items, 0
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="clsky-frames") if items else None
        self._pending = self._worker.submit(function, items[0]) if items else None

    def __iter__(self):
        return self

    def __next__(self):
        if self._pending is None:
            self.close()
            raise StopIteration
        try:
            result = self._pending.result()
        except BaseException:
            self._pending = None
            self.close()
            raise
        index = self._next
        self._next += 1
        self._pending = (self._worker.submit(self._function, self._items[self._next])
                         if self._next < len(self._items) else None)
        return self._items[index], result

    def close(self):
        """Drop the call not started yet, wait for a running one (it may hold the device), end the worker."""
        if self._pending is not None:
            self._pending.cancel()
            self._pending = None
        if self._worker is not None:
            self._worker.shutdown(wait=True)
            self._worker = None


def in_order(function: Callable[[Item], Result], items: Iterable[Item], workers: int = 1) -> Iterator[Result]:
    """function(item) for every item, yielded in order, computed on ``workers`` threads (0: on the caller's
    thread, one after the other).

    The caller's thread draws the items (drawing may wait, e.g. for a render) and submits each to the
    pool; at most ``workers`` + 1 are submitted and not yet yielded (``workers`` running, one waiting), so
    that the items and results held at once stay bounded. A result is yielded when it is the oldest and
    done, or when the window is full. An exception raised by ``function`` reaches the caller at its item;
    one raised while an item is drawn (an Exception: a failed render) reaches it after the results of the
    items submitted before it, so that the earliest failure is the one met, as one after the other.
    If the caller stops early (an exception, or closing the iterator), the items submitted (at most
    ``workers`` + 1) still run to their end before this returns and no other is drawn: none is cancelled,
    because a call may wait for the one before it (the exposure order of clsky.anim.animate), and a call
    cancelled while the next one had started would leave that one waiting for ever.
    """
    if isinstance(workers, bool) or not isinstance(workers, numbers.Integral) or workers < 0:
        raise ValueError(f"workers must be an integer >= 0, got {workers!r}")
    if workers == 0:
        for item in items:
            yield function(item)
        return
    items = iter(items)
    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="clsky-host") as pool:
        pending = collections.deque()
        while True:
            try:
                item = next(items)
            except StopIteration:
                break
            except Exception:
                while pending:           # the items before it first: their results, or the earliest error
                    yield pending.popleft().result()
                raise
            pending.append(pool.submit(function, item))
            while pending and (pending[0].done() or len(pending) > workers):
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()
