"""The numeric core: arrays and numbers in, arrays and numbers out, no file I/O and no orchestration.

The lowest floor of :mod:`emulator` above its base modules (:mod:`emulator.errors`,
:mod:`emulator.version`, :mod:`emulator.extras`, :mod:`emulator.cells`, :mod:`emulator.pools`,
:mod:`emulator.numpy_dispatch`):
the camera response and levels, the emulation itself (:mod:`~emulator.core.emulate`,
:mod:`~emulator.core.lut`), bracket selection (:mod:`~emulator.core.select`), motion blur
(:mod:`~emulator.core.blur`, :mod:`~emulator.core.gyro`, :mod:`~emulator.core.native`), the
in-memory recording (:mod:`~emulator.core.dataset`) and the statistics the reports use
(:mod:`~emulator.core.stats`, :mod:`~emulator.core.settling`).  :mod:`emulator.noise` and
:mod:`emulator.autoexposure` sit on this floor too.  Nothing here imports a higher floor
(``tests/project/test_import_contract.py``).
"""
