"""The reason a controller process's robot is failed with, from how it ended and what it wrote."""
import signal
from types import SimpleNamespace

from composed_sim.hosting import FAILURE_MARK
from composed_sim.hosts.multiprocess.children import died_reason

TRACEBACK = ("Traceback (most recent call last):\n  File \"raiser.py\", line 14, in on_scan\n"
             "AttributeError: 'Raiser' object has no attribute 'missing'\n")


def process(returncode: int, output: str):
    return SimpleNamespace(popen=SimpleNamespace(returncode=returncode), tail=lambda chars=2000: output[-chars:].strip())


def test_a_process_that_raised_and_ended_names_the_exception():
    reason = died_reason(process(1, f"{FAILURE_MARK} raiser:Raiser AttributeError 2\n{TRACEBACK}"))
    assert reason == "process exited with code 1: AttributeError: 'Raiser' object has no attribute 'missing'"


def test_a_process_stopped_in_its_clean_up_after_a_raise_names_the_exception_not_the_mark():
    # Its clean-up's time bound (SIGALRM) ended it after the exception: measured once in four runs.
    reason = died_reason(process(-signal.SIGALRM, f"{FAILURE_MARK} raiser:Raiser AttributeError 2\n{TRACEBACK}"))
    assert reason == ("process killed by SIGALRM after a callback raised: "
                      "AttributeError: 'Raiser' object has no attribute 'missing'")


def test_a_process_that_crashed_names_its_end_and_last_line():
    assert died_reason(process(-signal.SIGSEGV, "starting\nFatal Python error: Segmentation fault")) == \
        "process killed by SIGSEGV: Fatal Python error: Segmentation fault"
