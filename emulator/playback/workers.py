"""Method workers: every AE method of a run in its own process (:func:`start_methods`).

A :class:`MethodWorker` stands in the closed loop for one method.  Its process is forked
from Python's fork server (a fresh interpreter started for the purpose, which holds none of
the run's open files), builds the method itself (the plugin's import and factory run there,
never in the run's process), and answers one call at a time:

- the image reaches it through a shared-memory block owned by the run (one per worker, reserved
  in full before the first cycle, :mod:`emulator.playback.shmblock`, and written before each call;
  the worker copies it into an immutable buffer of its own, so nothing it does reaches the run's
  arrays or another method); where ``/dev/shm`` has no room for a block, through the pipe;
- it returns only the proposal, the method's fallback count and what the method printed, as JSON
  text (nothing a worker sends is unpickled, so no plugin module is imported in the run's process);
  the run process owns every file;
- the run waits for the answer at most the method time limit (``--method-timeout-s``,
  default :data:`DEFAULT_METHOD_TIMEOUT_S`), counted from the moment the call was sent (the
  closed loop sends it ahead, :meth:`MethodWorker.send_ahead`, and does the second camera's
  part of the shot meanwhile): past it the worker is killed (with any process it started)
  and the method fails with the reason, while the others go on;
- a worker that dies, forks (``os.fork``: the child exits at once), or leaves a thread or a process
  running after a call is killed the same way and its method fails, named.

A worker runs in its own session (a terminal's Ctrl-C reaches only the run, which stops its
workers) and dies with the run.  :func:`start_methods` with ``workers="inline"`` builds the
methods in the run's process instead (for debugging; the time limit is then checked only
after a call returns).
"""

from __future__ import annotations

import contextlib
import json
import multiprocessing
import os
import pickle
import signal
import sys
import threading
import time
import weakref

import numpy as np

from emulator.autoexposure.base import AutoExposureError, MethodFailed, to_gray
from emulator.errors import PlaybackError
from emulator.playback.worker_child import child_main, method_label
from emulator.playback.config import DEFAULT_METHOD_TIMEOUT_S, WORKER_MODES
from emulator.playback.seam import InlineMethod, MethodHandle, stop_methods
from emulator.playback.shmblock import reserve_block
from emulator.numpy_dispatch import forkserver_env
from emulator.autoexposure import METHOD_NAMES
from emulator.autoexposure.frame import FRAME_MEMO
from emulator.autoexposure.isolation import call_method as isolated_call, keep_output
from emulator.autoexposure.methodset import build_methods, latency_options, parse_methods
from emulator.autoexposure.registry import installed_methods

__all__ = ["MethodWorker", "start_methods", "stop_methods", "DEFAULT_METHOD_TIMEOUT_S",
           "WORKER_MODES"]

#: Largest reply a worker may send, bytes (what a method printed is kept up to 64 KiB, its config's values cut).
MAX_REPLY_BYTES = 16 << 20
_PRELOAD = ["emulator.playback.worker_preload"]  # imports the worker side too
_ctx = None
_ctx_lock = threading.Lock()


def _context():
    global _ctx
    with _ctx_lock:
        if _ctx is None:
            ctx = multiprocessing.get_context("forkserver")
            ctx.set_forkserver_preload(_PRELOAD)
            _ctx = ctx
        return _ctx


# ---------------------------------------------------------------- the run's side
def _kill(proc) -> None:
    """SIGKILL the worker and its process group (whatever it started), then reap it."""
    pid = proc.pid
    if pid is None:
        return
    try:
        if os.getpgid(pid) == pid:  # its own group (setsid): never the run's
            os.killpg(pid, signal.SIGKILL)
        else:
            proc.kill()
    except (ProcessLookupError, PermissionError, OSError):
        pass
    proc.join(5)


def _release(proc, shm_box) -> None:
    _kill(proc)
    shm = shm_box[0]
    if shm is not None:
        shm_box[0] = None
        try:
            shm.close()
            shm.unlink()
        except (OSError, BufferError):
            pass


def _ended(proc) -> str:
    proc.join(5)
    code = proc.exitcode
    if code is None:
        return "its process stopped answering"
    if code < 0:
        try:
            return f"its process was killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"its process was killed by signal {-code}"
    return f"its process exited with status {code}"


def _start(proc) -> None:
    """Start ``proc``, also from a daemonic process (a Dask worker of a dataset run), which
    multiprocessing refuses children: a method worker dies with the fork server, which dies with
    the process that started it, so nothing outlives the run."""
    from multiprocessing import spawn

    me = multiprocessing.current_process()
    real = spawn.get_preparation_data

    def without_main(name):  # a worker never runs the caller's main script again (a script, stdin, pytest)
        data = real(name)
        data.pop("init_main_from_path", None)
        data.pop("init_main_from_name", None)
        return data

    with _ctx_lock:
        daemon = me._config.get("daemon")
        try:
            if daemon:
                me._config["daemon"] = False
            spawn.get_preparation_data = without_main
            with forkserver_env():  # NumPy's kernels for the fork server, if this start launches it
                proc.start()
        finally:
            spawn.get_preparation_data = real
            if daemon:
                me._config["daemon"] = daemon


def _handoff(label: str, why) -> str:
    return (f"AE method {label} cannot be handed to a worker process ({why}); define its class at the top level "
            "of an importable module, or run it in the run's process (workers='inline', --isolation inline)")


class MethodWorker(MethodHandle):
    """One AE method running in its own process: a :class:`~emulator.playback.seam.MethodHandle` whose
    limit interrupts (its process is stopped past it)."""

    def __init__(self, item, *, mode: str, response, options: dict, timeout_s: float) -> None:
        ctx = _context()
        self.timeout_s = float(timeout_s)
        self.label = method_label(item)
        self.name = self.label
        self.failed: str | None = None
        self._guard = 0
        self._config: dict = {}
        self._gray_code = None
        self._shm_box: list = [None]
        self.shm_shortage: int | None = None  # bytes of the image block /dev/shm had no room for
        self._ahead = None  # (raw, exposure_ms, monotonic time) of a call sent ahead
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(target=child_main, args=(child, os.getpid()), daemon=True, name="exposim-method")
        _start(self._proc)
        child.close()
        self._finalizer = weakref.finalize(self, _release, self._proc, self._shm_box)
        try:
            self._conn.send(("build", item, mode, response, options, list(sys.path), os.getcwd(),
                            dict(os.environ)))
        except (pickle.PicklingError, TypeError, AttributeError) as exc:
            self.close()
            raise PlaybackError(_handoff(self.label, exc)) from None

    def built(self) -> "MethodWorker":
        """Wait for the worker to build its method; raise the build's error (naming the method)."""
        try:
            reply = self._ask(None, where="while it was built (its import, factory or constructor)")
        except MethodFailed as exc:
            self.close()
            raise AutoExposureError(f"AE method {self.label} could not be built: {exc}") from None
        if reply[0] == "fatal":
            self.close()
            raise AutoExposureError(f"AE method {self.label} could not be built: it {reply[1]}")
        if reply[0] == "error":
            self.close()
            if reply[1] == "handoff":
                raise PlaybackError(_handoff(self.label, reply[2]))
            raise (PlaybackError if reply[1] == "PlaybackError" else AutoExposureError)(reply[2])
        _, self.name, self._config, self._gray_code = reply
        return self

    def _ask(self, msg, sent_at: float | None = None, where: str = "in next_exposure"):
        try:
            if msg is not None:  # a worker that died since its last answer: its pipe is broken, say why
                self._conn.send(msg)
            # a call sent ahead (:meth:`send_ahead`) has been running since it was sent
            left = self.timeout_s if sent_at is None else max(0.0, self.timeout_s - (time.monotonic() - sent_at))
            if not self._conn.poll(left):
                self.failed = (f"did not return within the limit of {self.timeout_s:g} s (--method-timeout-s); "
                               "its process was stopped")
                self.kill()
                raise MethodFailed(self.failed)
            data = self._conn.recv_bytes(MAX_REPLY_BYTES)
        except (EOFError, OSError, ConnectionError):
            self.failed = f"{_ended(self._proc)} {where}" if msg is None or msg[0] == "call" else _ended(self._proc)
            self.kill()
            raise MethodFailed(self.failed) from None
        try:
            return json.loads(data)  # data only: nothing a worker sends is unpickled here
        except ValueError:
            self.failed = f"its process sent a reply that is not data {where}; it was stopped"
            self.kill()
            raise MethodFailed(self.failed) from None

    def _message(self, raw, exposure_ms) -> tuple:
        if isinstance(raw, np.ndarray) and not raw.dtype.hasobject:
            a = np.ascontiguousarray(raw)
            gray = self._gray(raw)
            size = a.nbytes + (0 if gray is None else gray.nbytes)
            gray_nbytes = 0 if gray is None else gray.nbytes
            shm = self._block(size)
            if shm is None:  # no room in /dev/shm: the pixels go through the pipe (the same bytes)
                data = a.tobytes() + (b"" if gray is None else np.ascontiguousarray(gray).tobytes())
                return ("call", None, a.nbytes, a.shape, a.dtype.str, exposure_ms, None, gray_nbytes, data)
            np.ndarray(a.shape, a.dtype, buffer=shm.buf)[...] = a
            if gray is not None:
                np.ndarray(gray.shape, gray.dtype, buffer=shm.buf, offset=a.nbytes)[...] = gray
            return ("call", shm.name, a.nbytes, a.shape, a.dtype.str, exposure_ms, None, gray_nbytes)
        return ("call", None, 0, None, None, exposure_ms, raw)

    def _block(self, size: int):
        """This worker's image block, reserved in full when made (:func:`reserve_block`); None once
        ``/dev/shm`` had no room for it (:attr:`shm_shortage` then holds the bytes it needed)."""
        shm = self._shm_box[0]
        if self.shm_shortage is not None:
            return None
        if shm is None or shm.size < size:
            if shm is not None:
                self._shm_box[0] = None
                shm.close()
                shm.unlink()
            shm = self._shm_box[0] = reserve_block(size)
            if shm is None:
                self.shm_shortage = size
        return shm

    def reserve(self, image_nbytes: int) -> bool:
        """Reserve this worker's image block for images of ``image_nbytes`` (and their gray image, for a
        built-in that takes it) before the first call; False where ``/dev/shm`` has no room for it."""
        if self.failed is not None:
            return True
        return self._block(int(image_nbytes) * (2 if self._gray_code is not None else 1)) is not None

    def send_ahead(self, raw, exposure_ms) -> None:
        """Start the call :meth:`next_exposure` will make with this very ``raw`` and ``exposure_ms``, so
        that the run can do other work while the method computes (the answer is read by that call;
        its time limit counts from now).  A worker that cannot take it now is left to that call."""
        if self.failed is not None or self._ahead is not None:
            return
        try:
            self._conn.send(self._message(raw, exposure_ms))
        except Exception:  # noqa: BLE001 - no shared memory, its process gone: the call meets it again and
            return  # fails this method alone, saying why, as it does when nothing was sent ahead
        self._ahead = (raw, exposure_ms, time.monotonic())

    def shot(self, tick, target_ms: float, want_right: bool):
        """The tick's shot at ``target_ms``; where the tick can split it, the call is sent ahead on the first
        camera's image and the method computes in its process while this thread adds the second camera's part."""
        split = getattr(tick, "split_shot", None)
        if split is None:
            return tick.shot(target_ms, want_right)
        shot, rest = split(target_ms, want_right)
        self.send_ahead(shot.left, shot.exposure_ms)
        rest()
        return shot

    def propose(self, raw, exposure_ms: float):
        return isolated_call(self, raw, exposure_ms)

    def next_exposure(self, raw, exposure_ms):
        if self.failed is not None:
            raise MethodFailed(self.failed)
        ahead, self._ahead = self._ahead, None
        if ahead is not None and ahead[0] is raw and ahead[1] == exposure_ms:
            msg, sent_at = None, ahead[2]
        else:
            if ahead is not None:  # pragma: no cover - the loop always makes the call it sent ahead
                raise PlaybackError(f"AE method {self.label}: a call was sent ahead for another image")
            msg, sent_at = self._message(raw, exposure_ms), None
        reply = self._ask(msg, sent_at)
        kind = reply[0]

        keep_output(self.name, reply[-2], reply[-1])
        if kind == "answer":
            self._guard = reply[2]
            return reply[1]
        if kind == "fatal":
            self.failed = reply[1]
            self.kill()
        raise MethodFailed(reply[1])

    def _gray(self, raw):
        """The method's gray image of ``raw``, computed once per image for every worker (the methods'
        own conversion and memo: the same bytes the method would compute)."""
        if self._gray_code is None or raw.ndim != 2 or raw.dtype != np.uint16:
            return None

        code = self._gray_code
        gray = FRAME_MEMO.get(raw, ("gray", code), lambda: to_gray(raw, code))
        return gray if gray.shape == raw.shape and gray.dtype == np.uint16 else None

    @property
    def guard_count(self) -> int:
        return self._guard

    def reset(self) -> None:
        if self.failed is None:
            self._ask(("reset",))

    def config(self) -> dict:
        return dict(self._config)

    def pid(self) -> int | None:  # noqa: D102
        return self._proc.pid

    def kill(self) -> None:
        """Stop the process now (a call waiting on it then fails); the shared memory stays until :meth:`close`."""
        _kill(self._proc)

    def close(self) -> None:
        """Stop the process and release its shared memory."""
        self._finalizer()
        with contextlib.suppress(OSError):
            self._conn.close()


def start_methods(spec, config, response) -> dict:
    """The run's methods by name, as handles that keep the run's limit (:attr:`RunConfig.method_timeout_applied_s`):
    :class:`MethodWorker` s (``config.workers`` ``process``), or :class:`~emulator.playback.seam.InlineMethod` s
    built in this process (``inline``); ``spec`` as for :func:`~emulator.autoexposure.methodset.build_methods`."""
    latency = config.latency_ticks
    options = latency_options(config.options, latency)  # fixed freezes one exposure with proposals in flight
    timeout = config.method_timeout_applied_s
    if config.workers == WORKER_MODES[1]:
        built = build_methods(spec, mode=config.mode, response=response, options=options)
        return {name: InlineMethod(method, timeout) for name, method in built.items()}
    items = parse_methods(spec) if isinstance(spec, str) else list(spec)
    for item in items:
        if not isinstance(item, str) and (not getattr(item, "name", None)
                                          or not callable(getattr(item, "next_exposure", None))):
            raise PlaybackError(f"{item!r} is neither a method name nor an AE method (name, next_exposure)")
    plugins = None
    for i, item in enumerate(items):
        if isinstance(item, str) and item not in METHOD_NAMES and ":" not in item:
            plugins = installed_methods() if plugins is None else plugins
            parse_methods([item], plugins=plugins)  # an unknown or broken plugin name: refused here, in one line
            items[i] = (item, plugins[item].value)
    started: list[MethodWorker] = []
    out: dict = {}
    try:
        for item in items:
            started.append(MethodWorker(item, mode=config.mode, response=response, options=options, timeout_s=timeout))
        for worker in started:
            worker.built()
            if worker.name in out:
                raise PlaybackError(f"two methods are named {worker.name!r}")
            out[worker.name] = worker
        unknown = set(options) - set(METHOD_NAMES) - set(out)
        if unknown:
            raise PlaybackError(f"options given for unknown method(s): {', '.join(sorted(unknown))}")
    except BaseException:
        stop_methods({str(i): w for i, w in enumerate(started)})
        raise
    return out
