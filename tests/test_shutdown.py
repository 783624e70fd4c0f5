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


def test_a_stopped_calibration_says_what_it_kept_and_exits_130(tmp_path, capsys):
    """Ctrl-C or SIGTERM (here one lost in a finalizer, so the flag alone) stops `driftlab calibrate` at its next
    batch with one line and exit 130, as `tune` and `study` stop: no traceback."""
    from driftlab.cli import main

    previous = signal.getsignal(signal.SIGTERM)
    shutdown._terminated.set()
    try:
        code = main(["calibrate", "--plant", "commonroad_std", "--set", "plant.model_drive_coupling=false",
                     "--set", "mpc.steer_limit_rad=0.6", "--points", "0.5@44", "--iterations", "2", "--seeds", "1",
                     "--workers", "1", "--db", str(tmp_path / "lab.db")])
    finally:
        signal.signal(signal.SIGTERM, previous)
        shutdown._terminated.clear()
    err = capsys.readouterr().err
    assert code == 130 and "calibration stopped" in err and "Traceback" not in err
