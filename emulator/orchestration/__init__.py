"""Run orchestration: a closed-loop run written to a folder, dataset runs, Dask, interrupts.

The floor above :mod:`emulator.playback` (the loop itself) and :mod:`emulator.report`:
:mod:`~emulator.orchestration.runner` (one run to a run folder, ``--resume``),
:mod:`~emulator.orchestration.datasetrun` (many recordings), :mod:`~emulator.orchestration.distributed` (a Dask
client), :mod:`~emulator.orchestration.interrupts` (Ctrl-C and cleanup) and
:mod:`~emulator.orchestration.framecache` (building a recording's decoded-frame cache).  Only
:mod:`emulator.commands` sits above it.
"""
