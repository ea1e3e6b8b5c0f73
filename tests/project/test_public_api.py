"""The package-level API of ``emulator``: the user verbs, no shadowed submodule, the version from metadata."""

from __future__ import annotations

import importlib
import importlib.metadata
import types

import emulator


def test_user_verbs_are_exported_and_are_the_library_functions():
    from emulator.autoexposure import make_method
    from emulator.io.borealhdr import load_sequence
    from emulator.playback import RunConfig, run
    from emulator.orchestration.runner import run_to_folder
    from emulator.core.emulate import emulate
    from emulator.core.select import select

    assert emulator.load_sequence is load_sequence
    assert emulator.run is run and emulator.run_to_folder is run_to_folder
    assert emulator.make_method is make_method and emulator.RunConfig is RunConfig
    assert emulator.select_bracket is select
    assert emulator.emulate_image is emulate
    assert set(emulator.__all__) <= set(dir(emulator))


def test_no_export_shadows_a_submodule():
    import emulator.core.select as s

    assert isinstance(s, types.ModuleType) and s.__name__ == "emulator.core.select"
    import emulator.playback as p

    assert isinstance(p, types.ModuleType)
    import emulator.core.emulate as e

    assert isinstance(e, types.ModuleType) and e.__name__ == "emulator.core.emulate"
    from emulator import emulate  # the module too, as ``from emulator import select``

    assert emulate is e and emulator.core.emulate is e and callable(e.emulate)
    from emulator import select

    assert isinstance(select, types.ModuleType)
    for name in emulator.__all__:
        try:
            importlib.import_module(f"emulator.{name}")
        except ModuleNotFoundError:
            continue
        raise AssertionError(f"emulator.{name} is both an export and a submodule")
    assert "emulate" not in emulator.__all__ and "select" not in emulator.__all__


def test_version_comes_from_the_package_metadata():
    assert emulator.__version__ == importlib.metadata.version("exposim")
