"""``python -m clsky`` and ``python -m clsky.anim`` command lines, each run in a process forked from one
that has already imported clsky (a fork server, as multiprocessing's ``forkserver`` start method).

The command-line tests run a few hundred short ``clsky`` processes, most of which print one error line
and exit. A new interpreter spends about 0.7 CPU-s on that, 0.5 s of it importing NumPy, PyOpenCL and
clsky (``python -X importtime``, 2026-12-07); a child forked from a server that has imported them takes
0.04 s for the same error line. The child is a new process all the same: its own PID, environment (the
test's), working directory, standard streams (files: not a terminal, as the pipes of
``subprocess.run(capture_output=True)``), signal dispositions and exit status, and no OpenCL context
(the server never creates one; PoCL starts in the child). It runs ``python -m``'s code,
:func:`runpy.run_module` of the package's ``__main__`` (or :func:`runpy.run_path` of a script), under
Python's default warning filters, the server's import-time warnings shown again on its stderr; whatever
ends it (SystemExit, an uncaught exception, the end of the module) ends the interpreter as it ends a
``python -m`` process: the traceback printed, the threads joined, the ``atexit`` functions run, the
streams flushed, the exit status set.

What a fork cannot give is a fresh import: a module's import-time work (an environment variable read then)
happened in the server. So a command runs in a new interpreter (``subprocess.run``) whenever its
environment is not the session's (an ``env`` argument, a monkeypatched variable), and ``python -m clsky``
is forked from a server that has imported clsky's command line only (a missing import in the core must
fail as it would). What still differs, and what no test here may rely on: the string hash seed is the
server's in every child (set iteration orders are fixed for a session), a traceback shows the server's
and runpy's frames above the command's, and the child's resident memory starts from the server's pages
(RSS measurements keep their own subprocesses). ``CLSKY_TEST_FORK=0`` runs every command line in a new
interpreter.
"""

from __future__ import annotations

import atexit
import contextlib
import json
import os
import select
import signal
import subprocess
import sys
import tempfile

#: The server: imports what every command line imports, then forks one child per request (a JSON line on
#: stdin: {"package" or "script", "args", "cwd", "environment", "stdout", "stderr"}), answering {"pid"} at
#: once and {"status"} (``os.waitstatus_to_exitcode``) when the child has ended.
SERVER = r'''
import json, os, runpy, sys, warnings

before = dict(os.environ)
with warnings.catch_warnings(record=True) as import_warnings:   # shown again by each child, as its own
    for module in sys.argv[1:]:                   # what the command lines import before they parse
        __import__(module)
# the variables those imports set (pyopencl's PYOPENCL_HOME, which PoCL's start needs), as they would in a
# new process whatever its environment
set_by_imports = {name: value for name, value in os.environ.items() if before.get(name) != value}


def run_child(request):
    # The child: the request's environment, folder and streams, then python -m PACKAGE (or SCRIPT) ARGS.
    # Whatever ends it (SystemExit, an uncaught exception, the end of the module: status 0) leaves the
    # server's loop and ends the interpreter as it ends `python -m` (threads joined, atexit, flush).
    os.environ.clear()                            # the test's (its PYTEST_CURRENT_TEST, as a subprocess sees)
    os.environ.update(request["environment"])
    os.environ.update(set_by_imports)
    stdin = os.open(os.devnull, os.O_RDONLY)
    os.dup2(stdin, 0)
    os.close(stdin)
    for fd, name in ((1, "stdout"), (2, "stderr")):
        target = os.open(request[name], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        os.dup2(target, fd)
        os.close(target)
    os.chdir(request["cwd"])
    for warning in import_warnings:
        warnings.showwarning(warning.message, warning.category, warning.filename, warning.lineno)
    if request["script"]:                         # python SCRIPT: the script's folder first on sys.path
        sys.argv = [request["script"], *request["args"]]
        sys.path[0] = os.path.dirname(os.path.abspath(request["script"]))
        runpy.run_path(request["script"], run_name="__main__")
    else:                                         # python -m PACKAGE: the working directory first
        sys.argv = [request["package"], *request["args"]]
        sys.path[0] = os.getcwd()
        runpy.run_module(request["package"], run_name="__main__", alter_sys=True)
    sys.exit(0)


for line in sys.stdin:
    request = json.loads(line)
    pid = os.fork()
    if pid == 0:
        run_child(request)                        # never returns: the child ends by an exception
    print(json.dumps({"pid": pid}), flush=True)
    _, status = os.waitpid(pid, 0)
    print(json.dumps({"status": os.waitstatus_to_exitcode(status)}), flush=True)
'''


def _environment():
    """The environment but for pytest's name of the running test (it changes with every test and no
    module reads it at import)."""
    return {name: value for name, value in os.environ.items() if name != "PYTEST_CURRENT_TEST"}


def _command(package, args, script=None):
    """The command line of a new interpreter: ``python -m package *args``, or ``python script *args``."""
    return [sys.executable, *(["-m", package] if script is None else [os.fspath(script)]), *args]


class ForkServer:
    """A server that has imported ``modules`` in ``environment``; :meth:`run` forks a command line from it."""

    def __init__(self, modules, environment):
        self.process = subprocess.Popen([sys.executable, "-c", SERVER, *modules], stdin=subprocess.PIPE,
                                        stdout=subprocess.PIPE, text=True, bufsize=1, env=environment)
        self._answers = b""                             # bytes read from the server, not yet a whole line

    def _answer(self, timeout=None):
        """The server's next JSON line; None if none came within ``timeout`` seconds (None: wait)."""
        fd = self.process.stdout.fileno()
        while b"\n" not in self._answers:
            ready, _, _ = select.select([fd], [], [], timeout)
            if not ready:
                return None
            chunk = os.read(fd, 4096)
            if not chunk:
                raise RuntimeError(f"the fork server ended (status {self.process.wait()})")
            self._answers += chunk
        line, self._answers = self._answers.split(b"\n", 1)
        return json.loads(line)

    def run(self, package, args, cwd, timeout=None, script=None):
        """A ``subprocess.CompletedProcess`` (text mode) of ``python -m package *args``, or of ``python
        script *args`` where ``script`` (a path) is given, run in ``cwd``.

        A failure to wait for the child (an interruption, a timeout) kills the child and the server: the
        next call starts a new server, never reading this call's answers as its own."""
        command = _command(package, args, script)
        if not os.path.isdir(cwd):                     # as subprocess.run, before any child exists
            raise FileNotFoundError(2, "No such file or directory", os.fspath(cwd))
        pid = None
        with tempfile.TemporaryDirectory(prefix="clsky-forked-") as streams:
            paths = {name: os.path.join(streams, name) for name in ("stdout", "stderr")}
            request = {"package": package, "script": script and os.fspath(script), "args": args,
                       "cwd": os.fspath(cwd), "environment": dict(os.environ), **paths}
            try:
                self.process.stdin.write(json.dumps(request) + "\n")
                self.process.stdin.flush()
                pid = self._answer()["pid"]
                answer = self._answer(timeout)
                if answer is None:
                    raise subprocess.TimeoutExpired(command, timeout)
            except BaseException:                      # as subprocess.run: the child killed, then raise
                self.kill(pid)
                raise
            output = {}
            for name, path in paths.items():
                with open(path) as stream:                 # the locale's encoding, as text=True decodes
                    output[name] = stream.read()
        return subprocess.CompletedProcess(command, answer["status"], output["stdout"], output["stderr"])

    def kill(self, child=None):
        """Kill ``child`` (a PID) if given, and the server."""
        for pid in (child, self.process.pid):
            if pid is not None:
                try:
                    os.kill(pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
        self.process.wait()

    def close(self):
        with contextlib.suppress(OSError):             # a killed server's pipe
            self.process.stdin.close()
        self.process.wait(timeout=30)
        self.process.stdout.close()


#: Environment variable: 0 runs every command line in a new interpreter (subprocess.run), as before the
#: fork server; a run now and then shows that no test depends on the fork (the string hash seed, for one,
#: is the server's in every child instead of a new one in each process).
FORK_VARIABLE = "CLSKY_TEST_FORK"

#: What each server imports: ``python -m clsky`` only clsky's own command line (its children must not
#: find the animation's modules imported: a missing import in the core would pass), ``python -m
#: clsky.anim`` and the bench scripts also the modules that anim's parser imports.
SERVER_MODULES = {"clsky": ("clsky.cli",), "clsky.anim": ("clsky.cli", "clsky.anim.cli", "clsky.anim.animate",
                                                           "clsky.anim.scene")}
_servers = {}
#: The environment the servers start with: the test session's, as this module is imported (at collection,
#: before any test monkeypatches a variable). A command run in another environment gets a new interpreter.
ENVIRONMENT = _environment()


def _run(package, args, cwd, env, timeout, script=None):
    args = [str(arg) for arg in args]
    if env is not None or _environment() != ENVIRONMENT or os.environ.get(FORK_VARIABLE, "1") == "0":
        return subprocess.run(_command(package, args, script), cwd=cwd, capture_output=True, text=True, env=env, timeout=timeout)
    modules = SERVER_MODULES[package or "clsky.anim"]
    server = _servers.get(modules)
    if server is None or server.process.poll() is not None:      # the first call, or killed by the last
        if server is not None:
            server.close()
        server = _servers[modules] = ForkServer(modules, ENVIRONMENT)
        atexit.register(server.close)
    return server.run(package, args, cwd, timeout=timeout, script=script)


def run(package, *args, cwd, env=None, timeout=None):
    """``python -m package *args`` (``package``: clsky or clsky.anim), forked from this process' server for
    the package (started at the first call, closed at exit); ``env`` given, a new interpreter."""
    return _run(package, args, cwd, env, timeout)


def run_script(script, *args, cwd, env=None, timeout=None):
    """``python script *args`` (a bench script), as :func:`run`."""
    return _run(None, args, cwd, env, timeout, script=script)
