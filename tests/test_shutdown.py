"""SIGTERM stops `tune` like Ctrl-C even when it lands in a finalizer, where Python ignores what a handler raises."""

import signal

import pytest

from driftlab.cli import shutdown


def test_a_sigterm_lost_in_a_finalizer_is_raised_again_at_the_next_check():
    class Finalized:
        def __del__(self):
            signal.raise_signal(signal.SIGTERM)  # the handler's KeyboardInterrupt is printed and dropped here

    previous = signal.getsignal(signal.SIGTERM)
    try:
        shutdown.stop_on_sigterm()
        shutdown.raise_if_terminated()  # no SIGTERM yet: nothing
        Finalized()  # collected at once
        with pytest.raises(KeyboardInterrupt):
            shutdown.raise_if_terminated()
    finally:
        signal.signal(signal.SIGTERM, previous)
        shutdown._terminated.clear()
