"""Methods isolated from each other and from the run: the one way the closed loops call a method.

:func:`call_method` runs ``method.next_exposure(raw, exposure_ms)`` so that nothing the
method does can change what another method, or the run, sees:

- **images**: a built-in method gets a read-only view whose ``setflags(write=True)`` raises
  and which OpenCV refuses as ``dst=``, so decoded brackets and emulated images shared
  between methods cannot be written through it.  The closed loops hand out such views of
  the arrays they own (:func:`readonly_view`; no copy, the same view for every method, so
  per-frame values such as the gray image stay shared, :mod:`emulator.autoexposure.frame`);
  any other input (a writeable array, an array owning its data) is replaced by a view of an
  immutable ``bytes`` copy (:func:`frozen`, one per source array).  A plugin
  (``private_images``) gets a private ``bytes`` copy on every call, so that even a write
  through the data pointer (ctypes, ``__array_interface__``) or up the ``.base`` chain
  reaches only its own copy.
- **NumPy's floating-point error state** (``np.seterr``, ``np.seterrcall``; per thread) is
  saved before the call and restored after it.
- the **warning filters** (``warnings.simplefilter("error")``) and the **working directory**
  are process-wide: they are saved when a call starts while no other is running and restored
  when the last of the overlapping calls ends (with ``--jobs 1``: around every call), so that
  one method's call cannot reset the filters another sets for itself meanwhile.  The run's
  output paths are absolute anyway (:func:`absolute`).
- **stdout and stderr**: what the method prints goes to a per-method buffer
  (:func:`captured_output`), never to the run's output (``--json`` stays one JSON document).
  Python-level writes only: a C library writing to file descriptor 1 is not captured.
- **exceptions**: anything the method raises, ``SystemExit`` included (``KeyboardInterrupt``
  aside, which stops the run), becomes :class:`~emulator.autoexposure.registry.MethodFailed`
  with the reason; the loop records it as that method's failure and the run goes on.

:func:`call_factory` does the same for building a method (a factory that exits or prints).
"""

from __future__ import annotations

import io
import os
import sys
import threading
import warnings
import weakref
from pathlib import Path

import numpy as np

from emulator.autoexposure.base import AutoExposureError
from emulator.autoexposure.base import MethodFailed
from emulator.autoexposure.frame import is_immutable

__all__ = ["call_method", "call_factory", "frozen", "is_frozen", "readonly_view", "is_readonly_view",
           "absolute", "captured_output", "keep_output", "MAX_CAPTURED_CHARS",
           "describe_error", "run_isolated"]

#: Characters of a method's printed output kept per method (the rest is counted, not kept).
MAX_CAPTURED_CHARS = 65536

_freeze_lock = threading.Lock()
_frozen_by_id: dict[int, tuple] = {}


def is_frozen(a) -> bool:
    """Whether ``a`` is a view of an immutable ``bytes`` buffer (no flag can make it writeable)."""
    while isinstance(a, np.ndarray):
        a = a.base
    if isinstance(a, memoryview):
        a = a.obj
    return isinstance(a, bytes)


def readonly_view(a: np.ndarray) -> np.ndarray:
    """``a`` made read-only and a read-only view of it returned (no copy): the view's
    ``setflags(write=True)`` raises while ``a`` stays read-only.  For arrays the loop owns
    and hands to built-in methods (:func:`is_readonly_view`)."""
    a.setflags(write=False)
    return a.view()


def is_readonly_view(a) -> bool:
    """Whether ``a`` is a read-only view over read-only arrays (or an immutable buffer): no flag
    set on ``a`` itself can make it writeable (what :func:`readonly_view` returns)."""
    return isinstance(a, np.ndarray) and a.base is not None and is_immutable(a)


def _bytes_view(a: np.ndarray) -> np.ndarray:
    data = np.ascontiguousarray(a).tobytes()
    out = np.frombuffer(data, dtype=a.dtype).reshape(a.shape)
    return out


def frozen(a):
    """A read-only copy of ``a`` whose buffer is a ``bytes`` object (the same one for the same
    source array while it lives); ``a`` itself if it is already such a view; non-arrays pass."""
    if not isinstance(a, np.ndarray) or is_frozen(a):
        return a
    key = id(a)
    with _freeze_lock:
        hit = _frozen_by_id.get(key)
        if hit is not None and hit[0]() is a:
            return hit[1]
    out = _bytes_view(a)
    try:
        ref = weakref.ref(a, lambda _r, key=key: _drop(key, _r))
    except TypeError:  # not weak-referenceable: no sharing
        return out
    with _freeze_lock:
        _frozen_by_id[key] = (ref, out)
    return out


def _drop(key: int, ref) -> None:
    with _freeze_lock:
        hit = _frozen_by_id.get(key)
        if hit is not None and hit[0] is ref:
            del _frozen_by_id[key]


def absolute(path) -> Path:
    """``path`` made absolute against the working directory now (a method's ``os.chdir``
    later cannot split a run folder)."""
    return Path(os.path.abspath(os.fspath(path)))


# ---------------------------------------------------------------- output capture
_local = threading.local()
_stream_lock = threading.Lock()
_depth = 0
_saved: tuple | None = None
_outputs: dict[str, list] = {}


class _Router(io.TextIOBase):
    """sys.stdout / sys.stderr while methods run: a thread inside a method call writes to its
    buffer, any other thread to the original stream."""

    def __init__(self, original, which: str) -> None:
        self.original = original
        self.which = which

    def write(self, text):
        buf = getattr(_local, "buffer", None)
        if buf is None:
            return self.original.write(text)
        buf.append(text)
        return len(text)

    def flush(self):
        if getattr(_local, "buffer", None) is None:
            self.original.flush()

    def writable(self):
        return True

    @property
    def encoding(self):
        return getattr(self.original, "encoding", "utf-8")

    def fileno(self):
        return self.original.fileno()

    def isatty(self):
        return False


def _enter_capture() -> None:
    """Start a window of method calls (calls on other threads overlap): at its start the
    process-wide state is saved (streams routed, warning filters, working directory)."""
    global _depth, _saved
    with _stream_lock:
        if _depth == 0:
            _saved = (sys.stdout, sys.stderr, list(warnings.filters), os.getcwd())
            sys.stdout = _Router(sys.stdout, "stdout")
            sys.stderr = _Router(sys.stderr, "stderr")
        _depth += 1


def _leave_capture() -> None:
    """End a call; the last call of a window puts the process-wide state back.  Restoring only
    then keeps one method's call from resetting the filters that a method running beside it
    set for itself (Kim's ``warnings.catch_warnings``) under ``--jobs 2``."""
    global _depth, _saved
    with _stream_lock:
        _depth -= 1
        if _depth == 0 and _saved is not None:
            out, err, filters, cwd = _saved
            # restore only our routers (something else may have replaced them since)
            if isinstance(sys.stdout, _Router):
                sys.stdout = out
            if isinstance(sys.stderr, _Router):
                sys.stderr = err
            if warnings.filters != filters:  # warnings.simplefilter("error") and the like
                warnings.filters[:] = filters
                getattr(warnings, "_filters_mutated", lambda: None)()
            if os.getcwd() != cwd:
                os.chdir(cwd)
            _saved = None


def _keep_output(name: str, parts: list) -> None:
    if not parts:
        return
    text = "".join(str(p) for p in parts)
    with _stream_lock:
        kept = _outputs.setdefault(name, ["", 0])
        room = MAX_CAPTURED_CHARS - len(kept[0])
        kept[0] += text[: max(room, 0)]
        kept[1] += len(text)


def keep_output(name: str, text: str, total: int) -> None:
    """Add what a method printed elsewhere (its worker process): ``text`` kept of ``total`` characters."""
    if not total:
        return
    with _stream_lock:
        kept = _outputs.setdefault(name, ["", 0])
        room = MAX_CAPTURED_CHARS - len(kept[0])
        kept[0] += text[: max(room, 0)]
        kept[1] += int(total)


def captured_output(name: str | None = None, *, clear: bool = False):
    """What methods printed: ``{name: (kept text, total characters)}``, or one method's pair."""
    with _stream_lock:
        if name is not None:
            out = tuple(_outputs.get(name, ("", 0)))
            if clear:
                _outputs.pop(name, None)
            return out
        out = {k: tuple(v) for k, v in _outputs.items()}
        if clear:
            _outputs.clear()
        return out


# ---------------------------------------------------------------- the calls
def describe_error(exc: BaseException) -> str:
    """What a method did, in words: ``raised ValueError: ...`` or ``called sys.exit(2)``."""
    if isinstance(exc, SystemExit):
        return f"called sys.exit({exc.code!r})"
    return f"raised {type(exc).__name__}: {exc}"


def run_isolated(fn, name: str, on_error):
    """``fn()`` with its output kept under ``name`` and NumPy's error state restored; a failure becomes ``on_error(exc)``."""
    err = np.geterr()  # NumPy's error state is per thread
    errcall = np.geterrcall()
    parts: list = []
    outer = getattr(_local, "buffer", None)
    _local.buffer = parts
    _enter_capture()
    routers = (sys.stdout, sys.stderr)
    try:
        return fn()
    except KeyboardInterrupt:
        raise
    except MethodFailed:
        raise
    except BaseException as exc:  # SystemExit and GeneratorExit included: the method fails alone
        raise on_error(exc) from exc
    finally:
        # a method that replaced sys.stdout / sys.stderr for good gets them put back
        if isinstance(routers[0], _Router) and sys.stdout is not routers[0]:
            sys.stdout = routers[0]
        if isinstance(routers[1], _Router) and sys.stderr is not routers[1]:
            sys.stderr = routers[1]
        _leave_capture()  # warning filters and working directory: when the last overlapping call ends
        _local.buffer = outer
        np.seterr(**err)
        np.seterrcall(errcall)
        _keep_output(name, parts)


def call_method(method, raw, exposure_ms):
    """``method.next_exposure(raw, exposure_ms)``, isolated (module docstring).

    Raises :class:`MethodFailed` naming what the method did, for any exception but
    ``KeyboardInterrupt``.
    """
    name = str(getattr(method, "name", type(method).__name__))
    # built-ins share the loop's read-only view (or one frozen copy of anything else) and its
    # per-frame values; a plugin gets a private copy, so that even a write through the data
    # pointer (ctypes, __array_interface__) reaches only its own copy
    private = getattr(type(method), "private_images", False)  # registry.PluginMethod: a plugin
    if private and isinstance(raw, np.ndarray):
        image = _bytes_view(raw)
    else:
        image = raw if is_readonly_view(raw) else frozen(raw)
    return run_isolated(lambda: method.next_exposure(image, exposure_ms), name,
                     lambda exc: MethodFailed(describe_error(exc)))


def call_factory(factory, name: str, source: str, **kwargs):
    """``factory(**kwargs)``, isolated; any failure, ``SystemExit`` included, is an
    :class:`AutoExposureError` naming the method and where it comes from."""
    return run_isolated(lambda: factory(**kwargs), name, lambda exc: AutoExposureError(
        f"AE method {name!r} ({source}) could not be built: {describe_error(exc)}"))
