"""Hostile AE plugins for test_plugins_faults.py and test_workers_faults.py beside this file (imported as ``hostile_plugins``).

Every class here misbehaves in one way; a run that includes it must give the other methods
exactly the bytes they get without it.
"""

from __future__ import annotations

import ctypes
import io
import os
import sys
import time
import warnings

import cv2
import numpy as np


class _Base:
    name = "base"

    def reset(self):
        pass

    def next_exposure(self, raw, exposure_ms):
        self.attack(raw)
        return float(exposure_ms) * 1.5

    def attack(self, raw):
        pass


# ------------------------------------------------------------------ write into the image
class Setflags(_Base):
    name = "h-setflags"

    def attack(self, raw):
        raw.setflags(write=True)
        raw[...] = 0


class NdarrayBuffer(_Base):
    name = "h-ndbuffer"

    def attack(self, raw):
        base = raw
        while isinstance(base, np.ndarray) and base.base is not None:
            base = base.base
        a = np.ndarray(raw.shape, raw.dtype, buffer=base)
        try:
            a.setflags(write=True)
        except ValueError:
            pass
        a[...] = 0


class FrombufferBase(_Base):
    name = "h-frombuffer"

    def attack(self, raw):
        a = np.frombuffer(raw.base if raw.base is not None else raw, dtype=np.uint16)
        a.setflags(write=True)
        a[...] = 0


class CtypesFromBuffer(_Base):
    name = "h-ctypes-buf"

    def attack(self, raw):
        base = raw.base if raw.base is not None else raw
        buf = (ctypes.c_char * raw.nbytes).from_buffer(base)
        ctypes.memset(ctypes.addressof(buf), 0, raw.nbytes)


class CtypesPointer(_Base):
    """Writes through the raw data pointer: no flag or buffer protocol is consulted."""

    name = "h-ctypes-ptr"

    def attack(self, raw):
        ctypes.memset(raw.ctypes.data, 0, raw.nbytes)


class _Iface:
    def __init__(self, raw):
        self.__array_interface__ = {"shape": raw.shape, "typestr": raw.dtype.str, "version": 3,
                                    "data": (raw.ctypes.data, False)}


class ArrayInterface(_Base):
    """A writeable NumPy view made from the image's address."""

    name = "h-array-iface"

    def attack(self, raw):
        np.asarray(_Iface(raw))[...] = 0


class Cv2Dst(_Base):
    name = "h-cv2-dst"

    def attack(self, raw):
        cv2.threshold(raw, 0, 0, cv2.THRESH_TRUNC, dst=raw)


class Cv2DstBase(_Base):
    name = "h-cv2-dst-base"

    def attack(self, raw):
        base = raw
        while isinstance(base, np.ndarray) and base.base is not None and isinstance(base.base, np.ndarray):
            base = base.base
        cv2.multiply(base, 0, dst=base)


class UfuncOut(_Base):
    name = "h-ufunc-out"

    def attack(self, raw):
        np.multiply(raw, 0, out=raw)


class InplaceBase(_Base):
    """In-place operations on every array up the ``.base`` chain."""

    name = "h-inplace-base"

    def attack(self, raw):
        a = raw
        while a is not None:
            if isinstance(a, np.ndarray):
                try:
                    a.setflags(write=True)
                except ValueError:
                    pass
                try:
                    a *= 0
                except (ValueError, TypeError):
                    pass
            elif isinstance(a, (bytearray, memoryview)):
                try:
                    a[:] = bytes(len(a))
                except TypeError:
                    pass
            a = getattr(a, "base", None) if not isinstance(a, (bytes, bytearray)) else None


class TryAllWritesQuietly(_Base):
    """Every refused route swallowed, then a normal answer: the method should run 'ok'."""

    name = "h-quiet"

    def attack(self, raw):
        for cls in (Setflags, NdarrayBuffer, FrombufferBase, CtypesFromBuffer, Cv2Dst, UfuncOut, InplaceBase):
            try:
                cls().attack(raw)
            except Exception:
                pass


# ------------------------------------------------------------------ process-wide state
class Seterr(_Base):
    name = "h-seterr"

    def attack(self, raw):
        np.seterr(all="raise")


class SeterrCall(_Base):
    name = "h-seterrcall"

    def attack(self, raw):
        def boom(kind, flag):
            raise FloatingPointError(f"hostile: {kind}")
        np.seterr(all="call")
        np.seterrcall(boom)


class WarningsError(_Base):
    name = "h-warnings-error"

    def attack(self, raw):
        warnings.simplefilter("error")


class GlobalRng(_Base):
    name = "h-global-rng"

    def attack(self, raw):
        np.random.seed(12345)
        np.random.random(1000)


class Chdir(_Base):
    name = "h-chdir"
    target = None  # set by the test

    def attack(self, raw):
        os.chdir(Chdir.target or "/")


class Printer(_Base):
    name = "h-printer"

    def __init__(self):
        print("hostile: printed in __init__")

    def reset(self):
        print("hostile: printed in reset")

    def attack(self, raw):
        print("hostile: printed in next_exposure {")
        print("hostile: to stderr", file=sys.stderr)
        sys.stdout.write("}}}not json")
        sys.stdout.flush()


class StdoutSwap(_Base):
    """Replaces sys.stdout for good (e.g. a library that redirects output)."""

    name = "h-stdout-swap"

    def attack(self, raw):
        sys.stdout = io.StringIO()
        sys.stderr = io.StringIO()


# ------------------------------------------------------------------ exits and BaseExceptions
class Exit0(_Base):
    name = "h-exit0"

    def attack(self, raw):
        sys.exit(0)


class Exit3(_Base):
    name = "h-exit3"

    def attack(self, raw):
        sys.exit(3)


class OsExitLike(BaseException):
    pass


class RaiseBase(_Base):
    name = "h-base-exc"

    def attack(self, raw):
        raise OsExitLike("a BaseException that is not an Exception")


class RaiseGeneratorExit(_Base):
    name = "h-genexit"

    def attack(self, raw):
        raise GeneratorExit("hostile")


class ExitInReset(_Base):
    name = "h-exit-reset"

    def reset(self):
        sys.exit(0)


class RaiseInReset(_Base):
    name = "h-raise-reset"

    def reset(self):
        raise RuntimeError("hostile reset")


class ExitInFactory(_Base):
    name = "h-exit-factory"

    def __init__(self):
        sys.exit(0)


class ExitLater(_Base):
    """Behaves for two cycles, then exits."""

    name = "h-exit-later"

    def __init__(self):
        self.n = 0

    def reset(self):
        self.n = 0

    def attack(self, raw):
        self.n += 1
        if self.n == 3:
            sys.exit(0)


# ------------------------------------------------------------------ bad return values
def _returns(value, label):
    class R(_Base):
        name = f"h-ret-{label}"

        def next_exposure(self, raw, exposure_ms):
            return value

    R.__name__ = f"Ret_{label}"
    return R


RetStr = _returns("12.5", "str")
RetTrue = _returns(True, "true")
RetNpBool = _returns(np.bool_(True), "npbool")
RetNan = _returns(float("nan"), "nan")
RetNeg = _returns(-1.0, "neg")
RetZero = _returns(0, "zero")
RetInf = _returns(float("inf"), "inf")
RetNone = _returns(None, "none")
RetHuge = _returns(1e300, "huge")
RetBigInt = _returns(10 ** 400, "bigint")
RetArray = _returns(np.array([3.0, 4.0]), "array")
RetComplex = _returns(3 + 0j, "complex")


class RetNanArray0d(_Base):
    name = "h-ret-nan0d"

    def next_exposure(self, raw, exposure_ms):
        return np.float32("nan")


# ------------------------------------------------------------------ slow
class Slow(_Base):
    name = "h-slow"

    def attack(self, raw):
        time.sleep(0.4)


# ------------------------------------------------------------------ names and attributes
class BadName(_Base):
    name = "../escape"


class BuiltinName(_Base):
    name = "classical-50"


class NonStrName(_Base):
    name = 42


class ResponseMutator(_Base):
    """Takes the recording's response and changes it for everyone."""

    name = "h-response"

    def __init__(self, response=None):
        self.response = response
        if response is None:
            return
        g = response.g
        try:
            g.setflags(write=True)
            g[:] = np.sqrt(g - g.min() + 1.0)  # still increasing, a different curve
        except ValueError:
            pass
        luts = getattr(response, "_luts", None)
        if luts is not None:
            try:
                luts.clear()
            except Exception:
                pass
        try:
            response.white_level = 100
        except Exception:
            pass


class HostileAttrs(_Base):
    """Attributes the loop may read (guard_count, config) raise SystemExit."""

    name = "h-attrs"

    @property
    def guard_count(self):
        sys.exit(0)

    def config(self):
        sys.exit(0)


class Interrupt(_Base):
    """Ctrl-C arriving while the method runs, at its third call."""

    name = "h-interrupt"

    def __init__(self):
        self.n = 0

    def attack(self, raw):
        self.n += 1
        if self.n == 3:
            raise KeyboardInterrupt


class Sleepy(_Base):
    """Slow enough that a signal arrives mid-run."""

    name = "h-sleepy"

    def attack(self, raw):
        time.sleep(0.3)


class ThreadPrinter(_Base):
    """Prints from a background thread (a logger, a progress thread) after its call returned."""

    name = "h-thread-printer"

    def attack(self, raw):
        import threading

        def later():
            time.sleep(0.02)
            print("hostile thread output {")

        threading.Thread(target=later, daemon=False).start()
