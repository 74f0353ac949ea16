"""The overlapped frame pipeline's scheduling (anim/pipeline.py: prefetched); that it leaves an
animation's files unchanged is tests/test_animate.py's test_overlapped_frames_are_the_bytes_of_serial_ones."""

from __future__ import annotations

import threading

import pytest

from clsky.anim.pipeline import prefetched


def test_results_in_order_one_ahead_on_one_worker_thread():
    """Every item's result, in order; the function runs on one thread other than the caller's, never
    twice at once, and at most one item ahead of the one the caller holds."""
    calls, threads, active = [], set(), []
    lock = threading.Lock()

    def function(item):
        with lock:
            active.append(item)
            assert len(active) == 1, active          # never two calls at once
        threads.add(threading.get_ident())
        calls.append(item)
        with lock:
            active.remove(item)
        return item * item

    seen = []
    for item, result in prefetched(function, range(5)):
        assert result == item * item
        # the next item may have been started, never the one after it
        assert max(calls) <= item + 1, (item, calls)
        seen.append(item)
    assert seen == list(range(5)) and calls == list(range(5))
    assert threads and threading.get_ident() not in threads and len(threads) == 1


def test_serial_runs_on_the_callers_thread():
    threads = []
    results = list(prefetched(lambda item: threads.append(threading.get_ident()) or item + 1, [1, 2], overlap=False))
    assert results == [(1, 2), (2, 3)] and set(threads) == {threading.get_ident()}


def test_no_items():
    assert list(prefetched(lambda item: item, [])) == []


def test_an_exception_reaches_the_caller_at_its_item():
    def function(item):
        if item == 2:
            raise ValueError("item 2")
        return item

    received = []
    with pytest.raises(ValueError, match="item 2"):
        for item, result in prefetched(function, range(4)):
            received.append(result)
    assert received == [0, 1]


def test_stopping_early_finishes_the_running_call_and_starts_no_other():
    """Closing the iterator after the first item: the call for item 1 is either dropped before it starts
    or completes before close() returns (the pool waits for it: it may hold the device); items 2 and 3
    are never computed."""
    calls = []
    frames = prefetched(lambda item: calls.append(item) or item, range(4))
    assert next(frames) == (0, 0)
    frames.close()
    done = list(calls)
    assert done in ([0], [0, 1]), done
    assert calls == done          # nothing ran after close() returned
