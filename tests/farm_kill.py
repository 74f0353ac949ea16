"""A Dask worker plugin for tests/test_farm.py: the worker that first finishes a chosen task kills its own
process (SIGKILL, as a crash or an out-of-memory kill would), once per marker file.

It lives in its own module so that the farm's spawned workers import it by name (a spawned process
gets the test process's sys.path) without importing the test module.
"""

from __future__ import annotations

import os
import signal

from distributed import WorkerPlugin


class KillOnce(WorkerPlugin):
    """Kill this worker's process when a task whose key starts with ``prefix`` and ends with ``suffix``
    reaches memory on it, if
    ``marker`` can still be created (O_EXCL: exactly one worker of the cluster dies, once); the marker
    holds the killed process's id."""

    name = "clsky-test-kill-once"

    def __init__(self, marker, prefix, suffix=""):
        self.marker, self.prefix, self.suffix = str(marker), prefix, suffix

    def transition(self, key, start, finish, **kwargs):
        if finish != "memory" or not (str(key).startswith(self.prefix) and str(key).endswith(self.suffix)):
            return
        try:
            descriptor = os.open(self.marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            return
        os.write(descriptor, str(os.getpid()).encode())
        os.close(descriptor)
        os.kill(os.getpid(), signal.SIGKILL)
