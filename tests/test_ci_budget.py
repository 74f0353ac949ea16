"""The CI's time budget (tests/conftest.py, ``CLSKY_TEST_DEADLINE``, set by .ci/run for the slow tests):
past the deadline no test starts, and each is reported as skipped with the reason; a malformed value
stops the run before any test. Each case runs pytest on one quick test in a child process, in one
process as .ci/run runs the slow set (-n 0: the deadline's order needs one)."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

TARGET = "tests/test_anim_sunpath.py::test_sweep_defaults"
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def run_pytest(deadline):
    environment = {**os.environ, "CLSKY_TEST_DEADLINE": deadline}
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-rs", "-n", "0", "-p", "no:cacheprovider", TARGET],
                          cwd=ROOT, env=environment, capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("offset, outcome", [(-60, "1 skipped"), (3600, "1 passed")],
                         ids=["past: not started", "ahead: runs"])
def test_the_deadline_stops_tests_from_starting(offset, outcome):
    result = run_pytest(str(time.time() + offset))
    assert outcome in result.stdout, result.stdout + result.stderr
    assert ("the time budget ran out (CLSKY_TEST_DEADLINE=" in result.stdout) == (offset < 0)


def test_a_malformed_deadline_is_a_usage_error():
    result = run_pytest("in an hour")
    assert result.returncode == 4                 # pytest's usage error: no test ran
    assert "CLSKY_TEST_DEADLINE must be a Unix time in seconds, got 'in an hour'" in result.stdout + result.stderr


def test_under_a_deadline_the_physics_checks_run_first():
    """With the deadline set, the twilight Monte Carlo checks and the main job come first in the slow set,
    the other files after them in their usual order. Five files, given in an order that puts the main job
    second and the twilight checks last (pytest collects files in the order given): collecting all 70 took
    7-9 s, their imports and assert rewriting, and the ordering is by file (tests/conftest.py), so any
    other file ranks as these three do."""
    environment = {**os.environ, "CLSKY_TEST_DEADLINE": str(time.time() + 3600)}
    files = ["tests/test_readme.py", "tests/test_main_job.py", "tests/test_bench_smoke.py", "tests/test_accuracy.py",
             "tests/test_twilight_montecarlo.py"]
    # --assert=plain: the collection only lists the tests (PYTHONDONTWRITEBYTECODE: no cached rewrites)
    result = subprocess.run([sys.executable, "-m", "pytest", "-q", "-m", "slow", "-n", "0", "--collect-only", "-p",
                             "no:cacheprovider", "--assert=plain", *files], cwd=ROOT, env=environment,
                            capture_output=True, text=True, timeout=120)
    collected = [line.split("::")[0] for line in result.stdout.splitlines() if "::" in line]
    assert list(dict.fromkeys(collected)) == ["tests/test_twilight_montecarlo.py", "tests/test_main_job.py",
                                              "tests/test_readme.py", "tests/test_bench_smoke.py",
                                              "tests/test_accuracy.py"], result.stdout
