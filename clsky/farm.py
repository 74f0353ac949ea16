"""Farms on Dask: a ``dask.distributed`` cluster that renders frames or builds tables for one clsky run.

A :class:`Farm` is either an embedded ``LocalCluster`` of N worker processes (``workers=N``; the
command line's ``--workers N``) or a connection to an existing cluster's scheduler
(``scheduler='tcp://host:8786'``, ``--scheduler``). It is the one interface of farm runs: the table
sweep of ``clsky table --sweep`` (:meth:`Farm.map_ordered` over :func:`build_table_task`) and the frames
of ``clsky animate --workers`` (:mod:`clsky.anim.farm`) use it alike.

- The local workers are processes started with the ``spawn`` method (Dask's default, enforced here for
  the farm's lifetime): an OpenCL context inherited through ``fork`` hangs (PyOpenCL issue #156, pyFAI
  issue #1652), so each worker builds its own, lazily, on its first task.
- Results come back in submission order (:meth:`Farm.map_ordered`), at most ``window`` tasks in flight.
- A worker lost mid-run (killed, crashed) costs only the tasks it held: the scheduler reruns them, and
  those whose results it held, on the remaining workers (Dask's lineage; a LocalCluster's nanny also
  restarts the lost process). A task that has killed ``distributed.scheduler.allowed-failures`` + 1
  workers (Dask's default: 4) fails the run with :class:`FarmError`.
- Dask is an optional extra (``pip install 'clsky[dask]'``); without it, :func:`require_dask` says so.

Example
-------
>>> from clsky.farm import Farm
>>> with Farm(workers=2) as farm:                                        # doctest: +SKIP
...     squares = list(farm.map_ordered(pow, [(2, 2), (3, 2)]))
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import signal
import threading
import uuid

from .errors import ParameterError, check_integer, counted, short

__all__ = ["Farm", "FarmError", "INSTALL_HINT", "MAX_LOCAL_WORKERS", "require_dask", "check_workers",
           "check_scheduler", "build_table_task"]

#: How to install Dask for clsky (the ``dask`` extra of pyproject.toml: ``dask[distributed]``).
INSTALL_HINT = "pip install 'clsky[dask]'"

#: Most worker processes of an embedded LocalCluster: a sanity bound (each is a Python process with its own
#: OpenCL context, a few hundred MB); larger farms are clusters of their own (``scheduler=``).
MAX_LOCAL_WORKERS = 256

#: An existing scheduler's address: tcp:// or tls://, a host name, an IPv4 address or a bracketed IPv6
#: address, and a port.
_ADDRESS = re.compile(r"(tcp|tls)://([A-Za-z0-9](?:[A-Za-z0-9.-]*[A-Za-z0-9])?|\[[0-9A-Fa-f:.]+\]):([0-9]{1,5})")

#: Seconds to wait for an existing scheduler to answer, and more seconds for distributed to give up
#: before the farm gives up on it (:meth:`Farm._connect`).
CONNECT_TIMEOUT_S = 10
CONNECT_GRACE_S = 2


#: Dask's nanny starts its workers with glibc's MALLOC_TRIM_THRESHOLD_=65536 (to hand freed memory back to
#: the system). Set explicitly, it also pins glibc's mmap threshold at 128 KiB, so that every frame-sized
#: temporary array is a fresh mmap, zeroed page by page: on the 2-core machine a worker spent 3.5 s of
#: system CPU on 16 frames of 256 x 256 with it, 0.14 s without (user CPU 5.6 s and 5.2 s), and the frames
#: took 1.8 times the wall time. Embedded clusters start their workers without it (None unsets it).
MALLOC_TRIM_KEY = "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_"


class FarmError(RuntimeError):
    """A farm run failed on its cluster: a task killed its workers again and again, or the cluster went
    away. The message is one line."""


def require_dask(option="workers"):
    """Import ``dask.distributed``; ImportError naming ``option`` and :data:`INSTALL_HINT` without it."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise ImportError(f"{option} needs Dask (dask.distributed), which is not installed: {INSTALL_HINT}") from None


def check_workers(name, value) -> int:
    """``value`` as the worker count of an embedded LocalCluster: an integer in [1, MAX_LOCAL_WORKERS]."""
    return check_integer(name, value, 1, MAX_LOCAL_WORKERS)


def check_scheduler(name, value) -> str:
    """``value`` as a scheduler address 'tcp://HOST:PORT' (or tls://), port in [1, 65535]."""
    match = _ADDRESS.fullmatch(value) if isinstance(value, str) else None
    if match is None or not 1 <= int(match.group(3)) <= 65535:
        raise ParameterError(name, "a scheduler address tcp://HOST:PORT (or tls://), e.g. tcp://127.0.0.1:8786, "
                                   "port in [1, 65535]", value)
    return value


class Farm:
    """A Dask cluster for one run: an embedded LocalCluster of ``workers`` processes, or the cluster of
    the scheduler at ``scheduler``. Use it as a context manager (or :meth:`start` / :meth:`close`).

    Parameters
    ----------
    workers : int, optional
        Worker processes of an embedded LocalCluster, in [1, :data:`MAX_LOCAL_WORKERS`], one thread
        each (clsky's kernels already use every core of a CPU device).
    scheduler : str, optional
        Address of an existing cluster's scheduler, 'tcp://HOST:PORT'; its workers need this clsky
        installed. Exactly one of ``workers`` and ``scheduler``.

    Raises
    ------
    ValueError
        (:class:`clsky.errors.ParameterError`) ``workers`` or ``scheduler`` invalid, or both or neither
        given: checked on creation, before any work.
    ImportError
        Dask is not installed (:data:`INSTALL_HINT`).
    """

    def __init__(self, workers=None, scheduler=None):
        if (workers is None) == (scheduler is None):
            raise ParameterError("workers", "given alone, or scheduler alone (exactly one of the two)",
                                 (workers, scheduler))
        self.workers = None if workers is None else check_workers("workers", workers)
        self.scheduler = None if scheduler is None else check_scheduler("scheduler", scheduler)
        require_dask("scheduler" if workers is None else "workers")
        self.client = None
        self._cluster = None
        self._stack = contextlib.ExitStack()

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, *exc):
        self.close()

    def start(self):
        """Start the LocalCluster (or connect to the scheduler) and its client.

        Raises
        ------
        ConnectionError
            (:class:`OSError`) No scheduler answered at ``scheduler`` within :data:`CONNECT_TIMEOUT_S`.
        """
        import dask
        from distributed import Client, LocalCluster

        # Dask's nanny writes its workers' variables (OMP_NUM_THREADS=1, ...) into this process's environment
        # before it spawns them: they are undone when the farm closes
        self._stack.callback(_restore_environment, dict(os.environ))
        # what a FarmError reports in one line is not logged before it (for the farm's lifetime)
        reported = ReportedAsFarmErrorFilter()
        for name in reported.LOGGERS:
            logging.getLogger(name).addFilter(reported)
            self._stack.callback(logging.getLogger(name).removeFilter, reported)
        # spawn, never fork, for the farm's lifetime: the nanny restarts a lost worker with it too
        self._stack.enter_context(dask.config.set({"distributed.worker.multiprocessing-method": "spawn",
                                                   MALLOC_TRIM_KEY: None}))
        try:
            if self.scheduler is None:
                # the scheduler's HTTP server on a free port: another cluster on Dask's 8787 is no collision
                # preload: this module's dask_setup in each worker process, restarted ones included
                self._cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                             dashboard_address=":0", silence_logs=logging.ERROR,
                                             preload=[__name__])
                self.client = Client(self._cluster)
            else:
                self.client = self._connect(Client)
            self._check_versions()
        except BaseException:
            self.close()
            raise
        return self

    def _connect(self, client_type):
        """A client of the scheduler at ``scheduler``, or ConnectionError within about
        :data:`CONNECT_TIMEOUT_S`. distributed's own timeout bounds a refused connection and an unknown
        host, not a peer that accepts the connection and never speaks Dask's protocol (an HTTP server,
        Dask's dashboard port given for its scheduler's): its Client waited there forever. So the client
        is made on a daemon thread, waited for :data:`CONNECT_TIMEOUT_S` + :data:`CONNECT_GRACE_S`, and
        abandoned after it (its thread and IO loop are daemons: they end with the process); a client made after
        that is closed at once (it would have stayed open, the process's default Dask client)."""
        outcome, lock = {"abandoned": False}, threading.Lock()

        def attempt():
            try:
                client = client_type(self.scheduler, timeout=CONNECT_TIMEOUT_S)
            except BaseException as error:          # handed to the caller's thread
                outcome["error"] = error
                return
            with lock:
                outcome["client"] = client
                late = outcome["abandoned"]
            if late:
                with contextlib.suppress(Exception):
                    client.close()

        thread = threading.Thread(target=attempt, name="clsky-farm-connect", daemon=True)
        thread.start()
        thread.join(CONNECT_TIMEOUT_S + CONNECT_GRACE_S)
        with lock:
            outcome["abandoned"] = "client" not in outcome and "error" not in outcome
        if outcome["abandoned"]:
            raise ConnectionError(f"no Dask scheduler answered at {self.scheduler} within {CONNECT_TIMEOUT_S} s "
                                  f"(the connection opened, but no Dask scheduler answered in time: another "
                                  f"server, such as the dashboard's port, or a scheduler too busy to answer?)")
        error = outcome.get("error")
        if isinstance(error, (OSError, TimeoutError)):
            raise ConnectionError(f"no Dask scheduler answered at {self.scheduler} within "
                                  f"{CONNECT_TIMEOUT_S} s ({type(error).__name__})") from None
        if isinstance(error, TypeError) and self.scheduler.startswith("tls://"):
            # distributed's TypeError where no TLS context is configured (clsky passes no security=)
            raise ConnectionError(f"{self.scheduler} needs Dask's TLS configuration (distributed.comm.tls: the "
                                  f"CA file and this client's certificate and key), and none is set "
                                  f"({short(str(error))})") from None
        if error is not None:
            raise error
        return outcome["client"]

    def _check_versions(self):
        """FarmError unless every worker has this clsky: a worker without it cannot even read its tasks
        (Dask logs the failed message and the task waits forever), so this is checked first, through a
        function every Python has (``importlib.metadata.version``)."""
        import importlib.metadata

        wanted = installed_version()
        try:
            found = self.client.run(importlib.metadata.version, "clsky")
        except importlib.metadata.PackageNotFoundError:
            raise FarmError(f"a worker has no clsky installed: every worker needs clsky {wanted}") from None
        other = sorted({version for version in found.values() if version != wanted})
        if other:
            raise FarmError(f"workers run clsky {', '.join(other)}, this is clsky {wanted}: every worker needs "
                            f"the same clsky") from None

    def close(self):
        """Close the client and, for an embedded cluster, its workers (idempotent)."""
        with contextlib.suppress(Exception):
            if self.client is not None:
                self.client.close()
        with contextlib.suppress(Exception):
            if self._cluster is not None:
                self._cluster.close()
        self.client = self._cluster = None
        self._stack.close()

    @property
    def threads(self) -> int:
        """Worker threads of the cluster now (at least 1)."""
        return max(1, sum(self._require_client().nthreads().values()))

    def describe(self) -> str:
        """One line: where the farm runs and its workers now (a cluster without workers: its tasks wait
        for one to join)."""
        workers = self._require_client().nthreads()
        where = "an embedded Dask LocalCluster" if self.scheduler is None else f"the Dask cluster at {self.scheduler}"
        wait = "; the tasks wait for one to join" if not workers else ""
        count, threads = len(workers), sum(workers.values())
        return f"farm: {where}, {counted(count, 'worker')}, {counted(threads, 'thread')}{wait}"

    def _require_client(self):
        if self.client is None:
            raise RuntimeError("the farm is not started: use it as a context manager, or call start()")
        return self.client

    @staticmethod
    def new_token() -> str:
        """A unique name for one run's tasks (task keys and worker plugins carry it)."""
        return uuid.uuid4().hex[:12]

    def map_ordered(self, function, arguments, label="clsky-task", window=None):
        """``function(*args)`` for each tuple of ``arguments``, run on the workers; yields the results in
        order, keeping at most ``window`` tasks in flight (default: twice the workers' threads).

        Each task's key is ``'{label}-{token}-{index}'``. A lost worker's tasks are rerun elsewhere;
        an exception raised by ``function`` is raised here; :class:`FarmError` when Dask gives up on a
        task (it killed too many workers) or the cluster goes away. The tasks left are cancelled when
        the iteration stops early. ValueError naming ``window`` unless it is None or an integer in [1,
        :data:`MAX_WINDOW`], before any task is submitted (a negative one raised IndexError midway, 0 was
        the default).
        """
        client = self._require_client()
        window = check_window(window) or 2 * self.threads
        return self._in_order(client, function, arguments, label, window)

    def _in_order(self, client, function, arguments, label, window):
        """The generator of :meth:`map_ordered`."""
        token = self.new_token()
        pending = []
        try:
            with translate_errors():
                for index, args in enumerate(arguments):
                    pending.append(client.submit(function, *args, key=f"{label}-{token}-{index}", pure=False))
                    while len(pending) >= window:
                        yield result_of(pending.pop(0))
                while pending:
                    yield result_of(pending.pop(0))
        finally:
            if pending:
                with contextlib.suppress(Exception):
                    client.cancel(pending)


#: The most tasks a farm keeps in flight at the caller's request (each task's result is held until its turn).
MAX_WINDOW = 100_000


def check_window(window):
    """``window`` (tasks in flight) as an int in [1, :data:`MAX_WINDOW`], or None; ValueError naming it."""
    return check_integer("window", window, 1, MAX_WINDOW, optional=True)


def installed_version() -> str:
    """The installed clsky's version (its distribution's metadata, as the workers report theirs)."""
    import importlib.metadata

    return importlib.metadata.version("clsky")


def _restore_environment(saved):
    """Make ``os.environ`` ``saved`` again (only the variables that differ are touched)."""
    for name in set(os.environ) - set(saved):
        del os.environ[name]
    for name, value in saved.items():
        if os.environ.get(name) != value:
            os.environ[name] = value


def result_of(future):
    """``future.result()``, waited for on an event: a signal (Ctrl-C) that arrives while waiting raises
    here, in clsky's code, instead of inside Dask's blocking call, whose clean-up then logged a traceback
    (distributed 2026.8: a NameError in ``sync``'s cancel callback)."""
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    done.wait()
    return future.result()


@contextlib.contextmanager
def translate_errors():
    """Within the block, Dask's giving up on a task (KilledWorker) or losing its scheduler (CommClosedError)
    is raised as :class:`FarmError`, in one line."""
    from distributed import KilledWorker
    from distributed.comm.core import CommClosedError

    try:
        yield
    except KilledWorker as error:
        raise FarmError(f"a task killed its workers repeatedly and Dask gave up on it "
                        f"({str(error).splitlines()[0]})") from None
    except CommClosedError as error:
        raise FarmError(f"the Dask cluster went away ({str(error).splitlines()[0]})") from None



def dask_setup(worker):
    """Run by Dask in each worker process of an embedded LocalCluster at its start (``preload``).

    - The worker ignores SIGINT. Ctrl-C in a terminal reaches the whole process group; the client (clsky)
      turns it into a clean stop and closes the cluster, while the workers, interrupted too, printed a
      traceback each.
    - The worker's logger drops the connection errors of its own shutdown
      (:class:`ClosingWorkerConnectionFilter`).
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    logging.getLogger("distributed.worker").addFilter(ClosingWorkerConnectionFilter(worker))


class ReportedAsFarmErrorFilter(logging.Filter):
    """Drops the client process's Dask log records that say what a :class:`FarmError` then says in its one
    line (:func:`translate_errors`): the scheduler's "Task ... marked as failed because N workers died" (an
    embedded cluster's scheduler runs in this process) and the client's "Failed to reconnect to scheduler
    after ... seconds". They came on stderr before clsky's line, past the cluster's ``silence_logs``
    (ERROR). Every other record passes."""

    #: the start of each dropped record's format string (distributed 2026.8: scheduler.py, client.py)
    REPORTED = ("Task %s marked as failed because %d workers died", "Failed to reconnect to scheduler after")
    #: the loggers the filter is attached to while a farm runs
    LOGGERS = ("distributed.scheduler", "distributed.client")

    def filter(self, record: logging.LogRecord) -> bool:
        return not (isinstance(record.msg, str) and record.msg.startswith(self.REPORTED))


class ClosingWorkerConnectionFilter(logging.Filter):
    """Drops a worker's log records that carry a connection error (an :class:`OSError`, Dask's
    CommClosedError included) once the worker is closing (gracefully too: retired) or closed; every other
    record passes.

    A worker that closes stops its heartbeat's timer and then closes its connection pool, but a heartbeat
    already on its way to the scheduler is not cancelled: it fails on the closed pool and distributed
    (2026.8, ``Worker.heartbeat``) logs "Failed to communicate with scheduler during heartbeat." with the
    CommClosedError's traceback, at ERROR level, past the cluster's ``silence_logs``. That was a traceback on
    the terminal of a run that had succeeded (``clsky animate --workers 2``, once in CI). The same error while
    the worker runs (its scheduler gone mid-run) is still logged.
    """

    def __init__(self, worker):
        super().__init__()
        self.worker = worker

    def filter(self, record: logging.LogRecord) -> bool:
        from distributed.core import Status

        error = record.exc_info[1] if record.exc_info else None
        closing = getattr(self.worker, "status", None) in (Status.closing_gracefully, Status.closing, Status.closed)
        return not (closing and isinstance(error, OSError))


def build_table_task(atmosphere, settings, backend="opencl", fast_math=False):
    """The task of a table sweep on a worker: :meth:`clsky.ScatteringTable.build` (in the worker's own
    OpenCL context); the table comes back to the client, which saves it (validated, atomically)."""
    from .table import ScatteringTable

    return ScatteringTable.build(atmosphere, settings, backend=backend, fast_math=fast_math)
