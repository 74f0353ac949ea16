"""The overlapped frame pipeline's scheduling (anim/pipeline.py: prefetched); that it leaves an
animation's files unchanged is tests/test_animate.py's test_overlapped_frames_are_the_bytes_of_serial_ones."""

from __future__ import annotations

import threading

import pytest

from clsky.anim.pipeline import in_order, prefetched


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


def failing_at_two(item):
    """item, but ValueError for item 2 (the exception tests of both schedulers)."""
    if item == 2:
        raise ValueError("item 2")
    return item


def test_an_exception_reaches_the_caller_at_its_item():
    received = []
    with pytest.raises(ValueError, match="item 2"):
        for item, result in prefetched(failing_at_two, range(4)):
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


def test_the_first_call_starts_before_the_first_item_is_asked_for():
    """With the overlap the first render runs while the caller still sets up (an animation's display):
    the call of item 0 starts at construction, and closing before any item waits for it to end and
    starts no other. The 10 s wait only bounds a failure (the call starts within milliseconds)."""
    started, release, calls = threading.Event(), threading.Event(), []

    def function(item):
        calls.append(item)
        started.set()
        release.wait(10.0)
        return item

    frames = prefetched(function, range(3))
    assert started.wait(10.0), "item 0's call did not start before the first item was asked for"
    closer = threading.Thread(target=frames.close)
    closer.start()
    closer.join(0.2)
    assert closer.is_alive()      # close() waits for the running call (it may hold the device)
    release.set()
    closer.join(10.0)
    assert not closer.is_alive() and calls == [0]
    assert list(frames) == []     # closed: nothing more

# in_order: the host threads of the frames' host halves ------------------------------------------------

def test_in_order_yields_in_order_from_a_bounded_window_of_threads():
    """Every result in item order, whatever order the calls finish in (later items are made faster); the
    calls run on at most ``workers`` threads other than the caller's, and at most ``workers`` + 1 items
    are drawn and not yet yielded."""
    import time

    workers, drawn, yielded, threads = 3, [], [], set()

    def items():
        for item in range(12):
            assert len(drawn) - len(yielded) <= workers, (drawn, yielded)   # before this item is drawn
            drawn.append(item)
            yield item

    def function(item):
        threads.add(threading.get_ident())
        time.sleep(0.002 * (12 - item))
        return item * item

    for result in in_order(function, items(), workers):
        yielded.append(result)
    assert yielded == [item * item for item in range(12)]
    assert 1 <= len(threads) <= workers and threading.get_ident() not in threads


def test_in_order_without_workers_runs_on_the_callers_thread():
    threads = []
    assert list(in_order(lambda item: threads.append(threading.get_ident()) or item + 1, [1, 2], 0)) == [2, 3]
    assert set(threads) == {threading.get_ident()}
    assert list(in_order(lambda item: item, [], 2)) == []


@pytest.mark.parametrize("workers", [-1, 1.5, "2"])
def test_in_order_refuses_a_bad_worker_count(workers):
    with pytest.raises(ValueError, match="workers"):
        list(in_order(lambda item: item, [1], workers))


@pytest.mark.parametrize("workers", [0, 1, 3])
def test_in_order_exception_reaches_the_caller_at_its_item(workers):
    received = []
    with pytest.raises(ValueError, match="item 2"):
        for result in in_order(failing_at_two, range(6), workers):
            received.append(result)
    assert received == [0, 1]


def test_in_order_stopping_early_finishes_the_submitted_calls_and_draws_no_other():
    """Closing after the first result with two threads: the items submitted by then (the window is 3)
    run to their end before close() returns, none is cancelled (a call may wait for the one before it),
    and the items after the window are never drawn."""
    import time

    calls, drawn = [], []

    def items():
        for item in range(8):
            drawn.append(item)
            yield item

    def function(item):
        time.sleep(0.01)
        calls.append(item)
        return item

    results = in_order(function, items(), 2)
    assert next(results) == 0
    results.close()
    done = list(calls)
    assert sorted(done) == list(range(len(drawn))) and max(drawn) <= 3, (done, drawn)
    time.sleep(0.05)
    assert calls == done          # nothing ran after close() returned


@pytest.mark.parametrize("workers", [0, 1, 3])
def test_in_order_a_failure_drawing_an_item_comes_after_the_earlier_items_results(workers):
    """Item 1's call fails, then drawing item 3 fails (a render) while the calls still run (they take
    50 ms, so that with three threads all three are submitted before any ends): the caller meets item
    1's error first, as one after the other, not the draw's."""
    import time

    def items():
        yield from range(3)
        raise RuntimeError("drawing item 3")

    def function(item):
        time.sleep(0.05)
        if item == 1:
            raise ValueError("item 1")
        return item

    received = []
    with pytest.raises(ValueError, match="item 1"):
        for result in in_order(function, items(), workers):
            received.append(result)
    assert received == [0]
    # without an earlier failure, the draw's own error after every earlier result
    received = []
    with pytest.raises(RuntimeError, match="drawing item 3"):
        for result in in_order(lambda item: item, items(), workers):
            received.append(result)
    assert received == [0, 1, 2]
