"""clsky.allocator: the C allocator of a process that renders frames keeps what the frames free.

Each case runs in a subprocess, whose allocator it may change for good (pytest's stays as it is).
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys

import pytest

from clsky import allocator

glibc = pytest.mark.skipif(platform.system() != "Linux" or platform.libc_ver()[0] != "glibc",
                           reason="glibc's mallopt: elsewhere reuse_freed_memory does nothing")

#: In a worker thread, 3 launches' frames (25 MB each) and 6 frame temporaries (6.3 MB each) allocated and
#: freed 10 times after 3 warm-up rounds, as an animation's frames are; prints what reuse_freed_memory set and
#: the thread's minor page faults a round.
_ROUNDS = """
import resource, sys, threading
import numpy as np
from clsky.allocator import reuse_freed_memory
tuned = reuse_freed_memory() if sys.argv[1] == "tune" else {}
def frames():
    arrays = [np.ones((4, 512, 512, 3)) for _ in range(3)]
    arrays += [np.ones((512, 512, 3)) * k for k in range(6)]
def work(out):
    for _ in range(3):
        frames()
    before = resource.getrusage(resource.RUSAGE_THREAD).ru_minflt
    for _ in range(10):
        frames()
    out.append((resource.getrusage(resource.RUSAGE_THREAD).ru_minflt - before) / 10)
out = []
thread = threading.Thread(target=work, args=(out,))
thread.start()
thread.join()
print(sorted(tuned), out[0])
"""


def _rounds(mode, **environment):
    env = {name: value for name, value in os.environ.items()
           if name != "GLIBC_TUNABLES" and not name.startswith("MALLOC_")}
    env.update(environment)
    result = subprocess.run([sys.executable, "-c", _ROUNDS, mode], capture_output=True, text=True, env=env,
                            timeout=120, check=True)
    names, faults = result.stdout.rsplit(" ", 1)
    return names, float(faults)


@glibc
def test_a_worker_threads_frames_reuse_freed_memory():
    """With the defaults, a worker thread's arrays of a launch and a frame fault in fresh pages every round
    (3608 faults a round measured, 14 MB; the launch's 75 MB outgrow a thread heap's 64 MB, which is
    unmapped when it empties); after reuse_freed_memory none (0 measured): at most 550, 1.5 % of the 37 000
    pages a round allocates. Without it at least 200 (a tenth of the measured): the case shows the difference."""
    names, tuned = _rounds("tune")
    assert names == str(sorted(allocator.FRAME_LOOP_MALLOPT))
    assert tuned <= 550, tuned
    names, default = _rounds("default")
    assert names == "[]"
    assert default >= 200, default


@glibc
@pytest.mark.parametrize("environment", [{"GLIBC_TUNABLES": "glibc.malloc.trim_threshold=1000000"},
                                         {"MALLOC_ARENA_MAX": "2"}])
def test_an_allocator_the_environment_configures_is_left_alone(environment):
    """GLIBC_TUNABLES naming a glibc.malloc parameter, or a MALLOC_* variable: nothing set."""
    names, _ = _rounds("tune", **environment)
    assert names == "[]"
    assert allocator.configured_by_environment(environment)


def test_configured_by_environment_reads_only_the_allocators_settings():
    assert not allocator.configured_by_environment({})
    assert not allocator.configured_by_environment({"GLIBC_TUNABLES": "glibc.rtld.nns=8", "PATH": "/bin"})
    assert allocator.configured_by_environment({"GLIBC_TUNABLES": "glibc.rtld.nns=8:glibc.malloc.arena_max=2"})
    assert allocator.configured_by_environment({"MALLOC_TRIM_THRESHOLD_": "0"})


def test_clsky_animate_tunes_its_process_first(monkeypatch, tmp_path):
    """run_animate calls reuse_freed_memory before it does anything (here --print-scene, which returns
    before any work or thread)."""
    from clsky.anim import cli

    calls = []
    monkeypatch.setattr("clsky.allocator.reuse_freed_memory", lambda environ=None: calls.append("allocator") or {})
    monkeypatch.chdir(tmp_path)
    assert cli.main(["animate", "--frames", "2", "--size", "16", "--print-scene"]) == 0
    assert calls == ["allocator"]
