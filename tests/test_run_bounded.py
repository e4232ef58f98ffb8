"""The suite's own harness: a program that hangs fails its test with where it hung
(conftest.run_bounded), so a hang seen once in many runs can be found from that one failure."""

from __future__ import annotations

import shutil
import sys

import pytest

from conftest import run_bounded

HANG = "import threading, time\ndef wait_here():\n    time.sleep(600)\nthreading.Thread(target=wait_here, daemon=True).start()\nwait_here()\n"


def test_a_program_that_finishes_gives_its_output_and_status():
    r = run_bounded([sys.executable, "-c", "import sys; print('out'); print('err', file=sys.stderr); sys.exit(3)"], 60)
    assert (r.returncode, r.stdout, r.stderr) == (3, "out\n", "err\n")


def test_a_hung_program_fails_the_test_with_every_threads_stack():
    # The program cannot end in its 600 s; the 3 s bound is what is under test, not a wait.
    with pytest.raises(pytest.fail.Exception) as failed:
        run_bounded([sys.executable, "-c", HANG], 3)
    message = str(failed.value)
    assert "still ran after 3 s" in message
    # faulthandler's Python stacks: the main thread and the other one, both in wait_here.
    assert message.count("in wait_here") >= 2, message
    assert "Current thread" in message and "Thread 0x" in message, message
    if shutil.which("gdb"):
        assert "#0 " in message, message  # gdb's native frames
