"""Ctrl-C during a Mitsuba render reaches Python (scenes.render_interrupts).

Mitsuba's render installs a C-level SIGINT handler of its own that only sets the integrator's
stop flag; a Ctrl-C it caught never reached Python, and a command went on rendering."""

from __future__ import annotations

import ctypes
import os
import signal
import time

import pytest

from scenes.render_interrupts import keep_interrupts_for_python, render_array


class _Integrator:
    def __init__(self, stop: bool) -> None:
        self.stop = stop

    def should_stop(self) -> bool:
        return self.stop


def _wait_for(got, n=1):
    deadline = time.monotonic() + 5
    while len(got) < n and time.monotonic() < deadline:
        time.sleep(0.01)


@pytest.fixture
def python_handler():
    got = []
    old = signal.signal(signal.SIGINT, lambda s, f: got.append(s))
    try:
        yield got
    finally:
        signal.signal(signal.SIGINT, old)


def test_pythons_handler_is_put_back_in_place_of_a_c_level_one(python_handler):
    """A C-level handler installed behind Python's back (as Mitsuba's render does; here SIG_IGN
    through libc) would swallow the signal; after a render Python's handler is in place again."""
    libc = ctypes.CDLL(None)
    libc.signal.restype = ctypes.c_void_p
    libc.signal.argtypes = (ctypes.c_int, ctypes.c_void_p)
    libc.signal(signal.SIGINT, 1)  # SIG_IGN, unknown to Python
    keep_interrupts_for_python(_Integrator(stop=False))
    os.kill(os.getpid(), signal.SIGINT)
    _wait_for(python_handler)
    assert python_handler == [signal.SIGINT]


def test_a_ctrl_c_the_renderer_caught_reaches_python_and_drops_the_image(python_handler):
    with pytest.raises(KeyboardInterrupt):
        keep_interrupts_for_python(_Integrator(stop=True))
    _wait_for(python_handler)
    assert python_handler == [signal.SIGINT]  # the command's own handler (and the watchdog) see it


def test_render_array_returns_the_evaluated_image_or_nothing(python_handler):
    class _Scene:
        def __init__(self, stop):
            self._i = _Integrator(stop)

        def integrator(self):
            return self._i

    class _Mi:
        @staticmethod
        def render(scene, **kw):
            return [[1.0, 2.0], [3.0, 4.0]]

    out = render_array(_Mi, _Scene(False), spp=1)
    assert out.dtype.name == "float32" and out.tolist() == [[1.0, 2.0], [3.0, 4.0]]
    with pytest.raises(KeyboardInterrupt):
        render_array(_Mi, _Scene(True), spp=1)
    given = _Integrator(stop=True)  # an integrator passed in is the one asked
    with pytest.raises(KeyboardInterrupt):
        render_array(_Mi, _Scene(False), integrator=given, spp=1)
    _wait_for(python_handler, 2)
    assert python_handler == [signal.SIGINT] * 2
