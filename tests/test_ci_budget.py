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
    """With the deadline set, the twilight Monte Carlo checks and the main job come first in the slow set."""
    environment = {**os.environ, "CLSKY_TEST_DEADLINE": str(time.time() + 3600)}
    # --assert=plain: the collection only lists the tests, and rewriting every module's asserts took half its
    # 12-16 s (PYTHONDONTWRITEBYTECODE: no cached rewrites)
    result = subprocess.run([sys.executable, "-m", "pytest", "-q", "-m", "slow", "-n", "0", "--collect-only", "-p",
                             "no:cacheprovider", "--assert=plain"], cwd=ROOT, env=environment, capture_output=True,
                            text=True, timeout=120)
    files = [line.split("::")[0] for line in result.stdout.splitlines() if "::" in line]
    first = files.index("tests/test_main_job.py")
    assert set(files[:first]) == {"tests/test_twilight_montecarlo.py"} and "tests/test_accuracy.py" in files[first:]
