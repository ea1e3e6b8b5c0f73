"""Per-frame quantities shared by every method that reads the same image (gray image, its mean).

In the closed loop several methods often read one emulated image (all start from the same
exposure; methods with the same target share one read-only array), and each used to
demosaic it again.  :data:`FRAME_MEMO` memoises such quantities by the identity of the
input array, for arrays that cannot change: read-only, owning their data or viewing only
read-only arrays.  A writeable array is never memoised (its content may change between
calls), so calling a method on a scratch buffer behaves exactly as before.  Values are
read-only views of read-only arrays the memo owns (no copy): ``setflags(write=True)`` on a
value raises, so a method cannot change it for the others by accident.

The entry keeps a reference to the input array, so its ``id`` cannot be reused by another
array while the entry lives; values are returned read-only.  Thread-safe (the playback runs
methods on threads); two threads asking for the same value at once may both compute it,
with the same result.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable

import numpy as np

__all__ = ["FrameMemo", "FRAME_MEMO", "is_immutable"]


def is_immutable(a) -> bool:
    """Whether the array's pixels cannot change: read-only all along its chain of bases, which
    ends in a base-less array or a ``bytes`` buffer (directly or through a ``memoryview``)."""
    while isinstance(a, np.ndarray):
        if a.flags.writeable:
            return False
        if a.base is None:
            return True
        a = a.base
    if isinstance(a, memoryview):
        a = a.obj
    return isinstance(a, bytes)


class FrameMemo:
    """A small LRU memo of per-frame values keyed by (id(frame), key), for immutable frames."""

    def __init__(self, size: int = 8) -> None:
        self.size = int(size)
        self._data: OrderedDict = OrderedDict()
        self._lock = threading.Lock()
        self.hits = 0
        self.misses = 0

    def get(self, frame: np.ndarray, key: Hashable, compute: Callable[[], object]):
        """``compute()``, memoised for ``frame`` if the frame is immutable (value made read-only)."""
        if not is_immutable(frame):
            return compute()
        k = (id(frame), key)
        with self._lock:
            entry = self._data.get(k)
            if entry is not None and entry[0] is frame:
                self._data.move_to_end(k)
                self.hits += 1
                return entry[1]
        value = compute()
        if isinstance(value, np.ndarray):
            # a read-only view of a read-only array: the view cannot be made writeable again
            # (emulator.autoexposure.isolation.readonly_view, without the import circle)
            if value.base is not None:  # a view of something a caller may hold: own it
                value = value.copy()
            value.setflags(write=False)
            value = value.view()
        with self._lock:
            self.misses += 1
            self._data[k] = (frame, value)
            self._data.move_to_end(k)
            while len(self._data) > self.size:
                self._data.popitem(last=False)
        return value

    def put(self, frame: np.ndarray, key: Hashable, value) -> None:
        """Record ``value`` (read-only) as ``key`` of ``frame`` (immutable), as :meth:`get` would after computing it."""
        if not is_immutable(frame):
            return
        if isinstance(value, np.ndarray):
            value.setflags(write=False)
        with self._lock:
            self._data[(id(frame), key)] = (frame, value)
            self._data.move_to_end((id(frame), key))
            while len(self._data) > self.size:
                self._data.popitem(last=False)

    def clear(self) -> None:
        with self._lock:
            self._data.clear()


#: The memo the methods share (a few frames: one cycle's emulated images).
FRAME_MEMO = FrameMemo()
