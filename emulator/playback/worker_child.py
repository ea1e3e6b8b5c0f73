"""The worker's side of :mod:`emulator.playback.workers`: one AE method in its own process.

The process builds the method (a plugin's import and factory run here), then answers calls one
at a time: the image comes from the run's shared memory (or the pipe) into an immutable copy of its
own, the answer goes back as JSON text with the method's fallback count and what it printed
(:func:`plain`: its ``config()`` as data).  A fork (the child exits at once; a ``subprocess`` with
``preexec_fn`` named as such), a thread or a process (:func:`leftover_processes`) left running after
a call is reported, and the process then exits; it also ends once the run's process is gone, even
while a call hangs.
"""

from __future__ import annotations

import json
import numbers
import os
import signal
import sys
import threading
import time
from multiprocessing import shared_memory

import numpy as np

from emulator.autoexposure.base import AutoExposureError, MethodFailed
from emulator.errors import PlaybackError
from emulator.io.files import read_bytes
from emulator.autoexposure import METHOD_NAMES
from emulator.autoexposure.frame import FRAME_MEMO
from emulator.autoexposure.isolation import describe_error, captured_output, call_method
from emulator.autoexposure.methodset import build_methods
from emulator.autoexposure.registry import (
    is_import_path,
    plugin_from_path,
    MethodPlugin,
    build_plugin,
    load_import_path,
)
from emulator.pools import single_thread_pools
import emulator.pools as pools

_FORK_EXIT = 70  # exit status of the child of an os.fork inside a worker (it exits at once)


def _die_with_run(run_pid: int) -> None:
    """End this worker (and its group) once the run's process is gone, even while a call hangs; the
    run is watched itself, not the fork server, which a method could kill (taking every worker along)."""
    def watch():
        while True:
            time.sleep(1.0)
            try:
                os.kill(run_pid, 0)
            except ProcessLookupError:
                os.killpg(os.getpid(), signal.SIGKILL) if os.getpgid(0) == os.getpid() else os._exit(1)
            except OSError:
                pass

    threading.Thread(target=watch, daemon=True, name="exposim-run-watch").start()


#: glibc's mallopt parameters (malloc.h): M_TRIM_THRESHOLD, M_MMAP_THRESHOLD.
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
#: Freed memory a worker keeps for its next call instead of handing it back to the system, bytes.
KEEP_FREED_BYTES = 256 << 20
#: Largest block served from the worker's heap (glibc's ceiling on 64-bit): a frame's float64 arrays fit.
HEAP_BLOCK_BYTES = 32 << 20


def _keep_freed_memory() -> None:
    """Keep the memory a call frees for the next call (glibc only; elsewhere nothing changes).

    A call allocates the same large arrays every time (the image's own copy, its gray image, a
    method's per-pixel arrays: 18 MB for Zhang's derivatives at 1920x1200).  By default glibc
    hands such blocks back to the system when they are freed, and the next call then takes a
    page fault for every 4 KiB it touches again: measured in the closed loop, 11,700 faults per
    Zhang call and 1,300 per call of a method that only reads the image, a fifth of Zhang's CPU.
    Served from a heap that is not trimmed, the same blocks are reused; the pixels and every
    result are the same."""
    if not _glibc():  # the parameters' numbers are glibc's; another C library may read them otherwise
        return
    try:
        import ctypes  # a Python built without ctypes: the worker runs as it would without this

        mallopt = ctypes.CDLL("libc.so.6").mallopt
        mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
        mallopt(_M_MMAP_THRESHOLD, HEAP_BLOCK_BYTES)
        mallopt(_M_TRIM_THRESHOLD, KEEP_FREED_BYTES)
    except (ImportError, OSError, AttributeError):
        return


def _glibc() -> bool:
    """Whether this process runs on glibc (its version string, as ``os.confstr`` gives it)."""
    try:
        return bool(os.confstr("CS_GNU_LIBC_VERSION"))
    except (AttributeError, ValueError, OSError):  # not POSIX, or a C library without the name
        return False


def _fork_call() -> str:
    """What forked this process: ``subprocess with preexec_fn``, ``multiprocessing (fork)`` or ``os.fork``
    (read from the stack of the at-fork hook; a plain ``subprocess`` call forks without running it)."""
    frame = sys._getframe(2)  # the caller of the at-fork hook's lambda
    while frame is not None:
        module = frame.f_globals.get("__name__", "")
        if module == __name__:  # up to this worker's own call: the method's frames only
            break
        if module == "subprocess":
            return "subprocess with preexec_fn"
        if module.startswith("multiprocessing"):
            return "multiprocessing (fork start method)"
        frame = frame.f_back
    return "os.fork"


_PR_SET_CHILD_SUBREAPER = 36  # linux/prctl.h


def _adopt_orphans() -> None:
    """Make this worker the reaper of its orphaned descendants (Linux): a process a method starts and
    that double-forks (or calls setsid) stays this worker's descendant, where :func:`leftover_processes`
    finds it."""
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0)
    except (ImportError, OSError, AttributeError):
        pass


def leftover_processes() -> list[tuple[int, str]]:
    """(pid, command name) of this worker's live descendants (zombies left out), from ``/proc``; empty at
    once (one system call) when it has no child at all, as after any ordinary call."""
    try:
        os.waitid(os.P_ALL, 0, os.WEXITED | os.WNOHANG | os.WNOWAIT)  # leaves a child's status to its waiter
    except ChildProcessError:
        return []
    except (OSError, AttributeError):
        pass
    table = {}
    try:
        entries = os.listdir("/proc")
    except OSError:
        return []
    for entry in entries:
        if not entry.isdigit():
            continue
        try:
            stat = read_bytes(f"/proc/{entry}/stat").decode("ascii", "replace")
        except OSError:
            continue
        comm = stat[stat.find("(") + 1:stat.rfind(")")]
        fields = stat[stat.rfind(")") + 2:].split()
        if len(fields) > 1:
            table[int(entry)] = (int(fields[1]), fields[0], comm)
    found, todo = [], [os.getpid()]
    while todo:
        parent = todo.pop()
        for pid, (ppid, state, comm) in table.items():
            if ppid == parent:
                todo.append(pid)
                if state not in ("Z", "X"):
                    found.append((pid, comm))
    return sorted(found)


def child_main(conn, run_pid: int) -> None:
    """The method worker's main loop: build methods and answer calls over ``conn`` until told to stop or the run dies."""
    _adopt_orphans()
    _keep_freed_memory()
    try:
        os.setsid()  # own process group: stopped with whatever it starts; Ctrl-C goes to the run only
    except OSError:  # pragma: no cover
        pass
    _die_with_run(run_pid)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    _Child(conn).serve()


class _Child:
    def __init__(self, conn) -> None:
        self.conn = conn
        self.method = None
        self.name = None
        self.shm = None
        self.pending = None  # a failure found when the method was built, reported at its first call
        self.gray_code = None
        self.forked: list = []
        self.allowed = set(threading.enumerate())
        os.register_at_fork(after_in_parent=lambda: self.forked.append(_fork_call()),
                            after_in_child=lambda: os._exit(_FORK_EXIT))

    def serve(self) -> None:
        while True:
            try:
                msg = self.conn.recv()
            except (EOFError, OSError):
                os._exit(0)
            except Exception as exc:  # noqa: BLE001 - an object that cannot be rebuilt here (its class in a script)
                self._send(("error", "handoff", f"{type(exc).__name__}: {exc}"))
                continue
            if msg[0] == "stop":
                os._exit(0)
            try:
                reply = getattr(self, "do_" + msg[0])(*msg[1:])
            except BaseException as exc:  # noqa: BLE001 - e.g. an exception whose message itself raises
                reply = ("fatal", f"broke its process ({type(exc).__name__} while reporting its result)", "", 0)
            try:
                self._send(reply)
            except (EOFError, OSError):
                os._exit(0)
            if reply[0] == "fatal":
                os._exit(0)

    def _send(self, reply) -> None:
        """Send ``reply`` as data (JSON text): the run never unpickles anything a worker sends, so no
        plugin class is ever imported, nor any of its code run, in the run's process."""
        try:
            data = json.dumps(reply).encode("utf-8", "surrogatepass")
        except (TypeError, ValueError):  # pragma: no cover - replies hold plain values only
            data = json.dumps(["fatal", "broke its process (a reply that is not data)", "", 0]).encode()
        self.conn.send_bytes(data)

    def _left_threads(self) -> list[str]:
        pool = getattr(pools, "_LUT_POOL", None)
        ours = set(getattr(pool, "_threads", ()) or ())
        return [t.name for t in threading.enumerate() if t not in self.allowed and t not in ours and t.is_alive()]

    def _hostile(self, when: str) -> str | None:
        if self.forked:
            call = self.forked[0]
            if call.startswith("subprocess"):
                return (f"started a {call} {when} (the function would run Python in a forked child; refused: the "
                        "command never ran); its process was stopped")
            return f"forked a child process ({call}) {when}; its process was stopped"
        left = self._left_threads()
        if left:
            return (f"left {len(left)} thread{'s' if len(left) > 1 else ''} running {when} ({', '.join(left[:3])}); "
                    "its process was stopped")
        procs = leftover_processes()
        if procs:
            for pid, _ in procs:  # also those that left its process group (setsid): nothing outlives the call
                try:
                    os.kill(pid, signal.SIGKILL)
                except OSError:
                    pass
            shown = ", ".join(f"pid {pid} {comm}" for pid, comm in procs[:3])
            return (f"left {len(procs)} process{'es' if len(procs) > 1 else ''} running {when} ({shown}; "
                    "leftover_process); they and its process were stopped")
        return None

    def do_build(self, item, mode, response, options, sys_path, cwd, environ):
        sys.path[:] = sys_path  # the run's, now (the fork server has those of its start)
        os.environ.clear()
        os.environ.update(environ)
        try:
            os.chdir(cwd)
            name, self.method = _build_one(item, mode, response, options)
            self.name = str.__str__(name)  # checked text (registry.check_method_name); its plain str, not a subclass
        except (AutoExposureError, PlaybackError) as exc:
            return ("error", type(exc).__name__, str(exc))
        except BaseException as exc:  # noqa: BLE001 - KeyboardInterrupt included: Ctrl-C never reaches a worker
            where = "importing or building it" if isinstance(item, str) else "building it"
            return ("error", "AutoExposureError",
                    f"AE method {method_label(item)}: {where} {describe_error(exc).rstrip(': ')} in its worker process")
        config = {}
        if hasattr(self.method, "config"):
            try:
                config = dict(self.method.config())
            except BaseException as exc:  # noqa: BLE001
                config = {"config_error": f"config(): {describe_error(exc)}"}
        self.pending = self._hostile("after it was built")
        # a built-in's gray image is computed once per image by the run and handed over with it
        code = None if getattr(type(self.method), "private_images", False) else getattr(self.method, "gray_code", None)
        self.gray_code = code if isinstance(code, int) else None
        return ("built", self.name, plain(config), self.gray_code)

    def _image(self, shm_name, nbytes, shape, dtype, gray_nbytes, data=None):
        if data is not None:  # through the pipe (no room in /dev/shm): already this worker's own bytes
            raw = np.frombuffer(data, dtype=np.dtype(dtype), count=int(np.prod(shape))).reshape(shape)
            if gray_nbytes:
                gray = np.frombuffer(data[nbytes:nbytes + gray_nbytes], dtype=np.uint16).reshape(shape)
                FRAME_MEMO.put(raw, ("gray", self.gray_code), gray)
            return raw
        if self.shm is None or self.shm.name != shm_name:
            if self.shm is not None:
                self.shm.close()
            self.shm = shared_memory.SharedMemory(name=shm_name)  # the run owns (and removes) the block
        data = bytes(self.shm.buf[:nbytes])  # this worker's own immutable copy
        raw = np.frombuffer(data, dtype=np.dtype(dtype)).reshape(shape)
        if gray_nbytes:  # the run's gray image of this frame: what AutoExposureMethod.gray would compute
            gray = np.frombuffer(bytes(self.shm.buf[nbytes:nbytes + gray_nbytes]), dtype=np.uint16).reshape(shape)
            FRAME_MEMO.put(raw, ("gray", self.gray_code), gray)
        return raw

    def _output(self) -> tuple[str, int]:
        return captured_output(self.name, clear=True)

    def do_call(self, shm_name, nbytes, shape, dtype, exposure_ms, raw, gray_nbytes=0, data=None):
        if self.pending is not None:
            return ("fatal", self.pending, "", 0)
        if shape is not None:
            raw = self._image(shm_name, nbytes, shape, dtype, gray_nbytes, data)
        self.forked.clear()
        try:
            with single_thread_pools(user_api="blas"):  # results independent of the machine's cores
                value = call_method(self.method, raw, exposure_ms)
            guard = int(getattr(self.method, "guard_count", 0) or 0)
        except MethodFailed as exc:
            bad = self._hostile("in next_exposure")
            return ("fatal" if bad else "failed", bad or str(exc), *self._output())
        except BaseException as exc:  # noqa: BLE001 - KeyboardInterrupt raised by a method included
            return ("failed", describe_error(exc), *self._output())
        bad = self._hostile("in next_exposure")  # forks: in the call; threads: still running after it
        if bad:
            return ("fatal", bad, *self._output())
        return ("answer", _number(value), guard, *self._output())

    def do_reset(self):
        reset = getattr(self.method, "reset", None)
        if callable(reset):
            reset()
        return ("ok",)


#: Longest text kept of one value a plugin's ``config()`` holds that JSON cannot (its repr), characters.
REPR_CHARS = 200
#: Most items of one list or mapping of a ``config()`` kept as JSON; a longer one is its (cut) repr.
CONFIG_ITEMS = 1000


def plain(value, depth: int = 0):
    """``value`` (a method's ``config()``) as JSON data: mappings with text keys, lists, text, numbers,
    booleans and None (a NumPy scalar or a subclass as its plain value); anything else (a plugin's own
    object) as its ``repr``, cut to :data:`REPR_CHARS`.  Runs in the worker, so a plugin's code runs
    there too."""
    kind = type(value)
    if value is None or kind in (bool, int, float, str):
        return value
    try:  # a subclass or NumPy scalar of those: its plain value (np.float64(0.5) -> 0.5, a str Enum -> its text)
        if isinstance(value, (bool, np.bool_)):
            return bool(value)
        if isinstance(value, numbers.Integral):
            return int(value)
        if isinstance(value, numbers.Real):
            return float(value)
        if isinstance(value, str):
            return str.__str__(value)
    except BaseException:  # noqa: BLE001 - a conversion that raises: its text below
        pass
    if depth < 8 and isinstance(value, (dict, list, tuple)) and len(value) > CONFIG_ITEMS:
        return _text(value)
    if depth < 8 and isinstance(value, dict):
        return {_key(k): plain(v, depth + 1) for k, v in dict.items(value)}
    if depth < 8 and isinstance(value, (list, tuple)):
        return [plain(v, depth + 1) for v in value]
    return _text(value)


def _key(key) -> str:
    key = plain(key, 8)
    return key if type(key) is str else _text(key)


def _text(value) -> str:
    try:
        text = repr(value)
        text = text if type(text) is str else f"<{type(value).__name__}>"
    except BaseException:  # noqa: BLE001 - a repr that raises: the type's name
        text = f"<{type(value).__name__}>"
    return text if len(text) <= REPR_CHARS else text[:REPR_CHARS] + "..."


def _number(value):
    """A method's answer as data: text stays text (the loop's guard reads it as the run did), anything
    else its ``float`` taken here, in the worker (None where it has none: the guard replaces it)."""
    if type(value) is str:
        return value
    if isinstance(value, str):
        return str.__str__(value)
    try:
        number = float(value)
    except BaseException:  # noqa: BLE001 - a __float__ that raises or exits: not a number
        return None
    return number if type(number) is float else None


def method_label(item) -> str:
    """A ``--methods`` item (name, tuple or method object) as a short repr for messages."""
    if isinstance(item, tuple):
        return repr(item[0])
    return repr(item) if isinstance(item, str) else repr(getattr(item, "name", type(item).__name__))


def _build_one(item, mode, response, options):
    """(name, method) of one ``--methods`` item, built as :func:`build_methods` builds it."""
    if isinstance(item, tuple):  # an installed plugin: (name, entry point value), as the run found it
        name, value = item
        plugin = MethodPlugin(name, value, load_import_path(value))
        return name, build_plugin(plugin, mode=mode, response=response, options=options.get(name))
    if isinstance(item, str):
        key = plugin_from_path(item).name if item not in METHOD_NAMES and is_import_path(item) else item
    else:
        key = getattr(item, "name", None)
    subset = {key: options[key]} if key in options else {}
    built = build_methods([item], mode=mode, response=response, options=subset)
    return next(iter(built.items()))
