"""interrupts_deferred (psyop.session.signals) as the session loop and the log rely on it: a SIGINT in the
block waits for its end, then raises KeyboardInterrupt; the handler in place before is back afterwards; an
exception in the block propagates as it is; nested blocks hold and restore in order; off the main thread it
does nothing."""

from __future__ import annotations

import os
import signal
import threading

import pytest

from psyop.session.signals import interrupts_deferred, stop_signals_as_interrupt


def _kill(signum: int) -> None:
    os.kill(os.getpid(), signum)


def test_sigint_waits_for_the_block_and_the_handler_is_restored():
    before = signal.getsignal(signal.SIGINT)
    done = []
    with pytest.raises(KeyboardInterrupt):
        with interrupts_deferred():
            _kill(signal.SIGINT)
            done.append("written")
    assert done == ["written"]
    assert signal.getsignal(signal.SIGINT) is before


def test_no_signal_no_interrupt_and_restored():
    before = signal.getsignal(signal.SIGINT)
    with interrupts_deferred():
        pass
    assert signal.getsignal(signal.SIGINT) is before


def test_a_custom_handler_in_place_before_is_restored():
    calls = []

    def mine(signum, frame):
        calls.append(signum)

    previous = signal.signal(signal.SIGINT, mine)
    try:
        with pytest.raises(KeyboardInterrupt):
            with interrupts_deferred():
                _kill(signal.SIGINT)
        assert signal.getsignal(signal.SIGINT) is mine
        _kill(signal.SIGINT)
        assert calls == [signal.SIGINT]
    finally:
        signal.signal(signal.SIGINT, previous)


def test_an_exception_in_the_block_propagates_unchanged():
    before = signal.getsignal(signal.SIGINT)
    with pytest.raises(ValueError, match="boom"):
        with interrupts_deferred():
            _kill(signal.SIGINT)
            raise ValueError("boom")
    assert signal.getsignal(signal.SIGINT) is before


def test_nested_blocks_hold_until_the_outer_one_ends():
    before = signal.getsignal(signal.SIGINT)
    done = []
    with pytest.raises(KeyboardInterrupt):
        with interrupts_deferred():
            with interrupts_deferred():
                done.append("inner")
            _kill(signal.SIGINT)
            done.append("outer")
    assert done == ["inner", "outer"]
    assert signal.getsignal(signal.SIGINT) is before


def test_sigterm_under_stop_signals_is_held_like_sigint():
    done = []
    with stop_signals_as_interrupt() as received:
        with pytest.raises(KeyboardInterrupt):
            with interrupts_deferred():
                _kill(signal.SIGTERM)
                done.append("written")
    assert done == ["written"] and received == [signal.SIGTERM]


def test_off_the_main_thread_it_does_nothing():
    seen = []

    def body():
        with interrupts_deferred():
            seen.append(signal.getsignal(signal.SIGINT))

    before = signal.getsignal(signal.SIGINT)
    thread = threading.Thread(target=body)
    thread.start()
    thread.join()
    assert seen == [before]
