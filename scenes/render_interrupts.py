"""One Mitsuba render, evaluated, with Ctrl-C kept for Python (:func:`render_array`).

Mitsuba's ``render`` puts its own C-level SIGINT handler in place (``integrator_v.cpp``:
"Received interrupt signal, winding down..").  With a JIT variant it is still in place after
``render`` has returned, while the kernel runs.  A Ctrl-C that reaches it then only sets the
integrator's stop flag; Python's handler, the command's own handler and the watchdog of
:mod:`emulator.orchestration.interrupts` never see it.  The command then went on rendering image after
image, and a test that sent one SIGINT waited in vain (seen under load: the signal had landed
while Mitsuba's handler was in place).

So after each render (kernel evaluated): in the main thread Python's own handler is put back,
and if the integrator says it was stopped, the interrupt is handed to Python as if it had just
arrived (``_thread.interrupt_main``, which also wakes the watchdog) and the partial image is
dropped with ``KeyboardInterrupt``: it is never returned, cached or written.
"""

from __future__ import annotations

import _thread
import signal
import threading

import numpy as np

__all__ = ["render_array", "keep_interrupts_for_python"]


def keep_interrupts_for_python(integrator) -> None:
    """After a Mitsuba render: Python's SIGINT handler back (main thread), and a Ctrl-C that Mitsuba
    caught during the render raised as ``KeyboardInterrupt`` (and handed to the main thread)."""
    if threading.current_thread() is threading.main_thread():
        handler = signal.getsignal(signal.SIGINT)
        if handler is not None:  # None: a handler not installed from Python, left alone
            signal.signal(signal.SIGINT, handler)
    if integrator is not None and integrator.should_stop():
        _thread.interrupt_main(signal.SIGINT)
        raise KeyboardInterrupt


def render_array(mi, mi_scene, **kwargs) -> np.ndarray:
    """``np.array(mi.render(mi_scene, **kwargs), float32)``, interrupts kept for Python (see the module)."""
    integrator = kwargs.get("integrator") or mi_scene.integrator()
    image = mi.render(mi_scene, **kwargs)
    try:
        return np.array(image, dtype=np.float32)
    finally:
        keep_interrupts_for_python(integrator)
