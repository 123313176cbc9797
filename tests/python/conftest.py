"""Shared test set-up for the Python suite."""

import signal
import threading

import pytest


@pytest.fixture(autouse=True)
def python_sigint_handler():
    """Python's own SIGINT handler for every test, as an interactive session has it.

    A suite started in the background (`cmd &`, as a CI runner or `setsid` may start it)
    inherits SIGINT ignored; Python then installs no handler and `_thread.interrupt_main` (how
    the tests press Ctrl-C) does nothing. Installing the handler here makes the Ctrl-C tests
    test the module, not the way the suite was started."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
