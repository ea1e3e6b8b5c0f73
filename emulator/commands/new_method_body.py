"""What ``exposim new-method`` runs, imported when it runs (its arguments: :mod:`emulator.commands.new_method`)."""

from __future__ import annotations

import keyword
import re
from pathlib import Path
from string import Template

from emulator.errors import ExposimError, OutputExistsError
from emulator.autoexposure.registry import check_method_name
from emulator.io.files import write_text

__all__ = ["new_method"]


METHOD_TEMPLATE = Template('''\
import numpy as np


class ${class_name}:
    """Drive the mean of the raw 12-bit image towards ``target`` of full scale (4095 DN)."""

    name = "${name}"

    def __init__(self, target=0.4, gain=1.0):
        self.target, self.gain = float(target), float(gain)

    def reset(self):
        pass

    def next_exposure(self, raw: np.ndarray, exposure_ms: float) -> float:
        mean = max(float(raw.mean()) / 4095.0, 1e-3)  # raw: H x W uint16 Bayer, read-only
        return float(exposure_ms * (self.target / mean) ** self.gain)
''')


TEST_TEMPLATE = Template('''\
"""Test skeleton for an AE method plugin: copy beside your method and run ``pytest``.

Each test states a property the method must have on a synthetic mosaic (uint16, 12-bit),
so it runs without data.  Then run the method in closed loop on a recording:
``exposim run SEQ --methods all,${module}:${class_name} -o OUT`` (with ``${module}`` importable).
"""

import math

import numpy as np

from ${module} import ${class_name}


def flat(dn, shape=(32, 48)):
    return np.full(shape, dn, dtype=np.uint16)


def test_fixed_point_keeps_the_exposure():
    # A frame already at the target (40 % of 4095 DN = 1638 DN) keeps its exposure.
    assert math.isclose(${class_name}(target=0.4).next_exposure(flat(1638), 5.0), 5.0, rel_tol=1e-12)


def test_twice_as_bright_halves_the_exposure():
    ae = ${class_name}(target=0.4)
    assert math.isclose(ae.next_exposure(flat(3276), 8.0), 4.0, rel_tol=1e-12)


def test_black_frame_gives_a_finite_positive_exposure():
    t = ${class_name}().next_exposure(flat(0), 1.0)
    assert math.isfinite(t) and t > 0


def test_reset_then_same_answer():
    ae = ${class_name}()
    first = ae.next_exposure(flat(1000), 3.0)
    ae.reset()
    assert ae.next_exposure(flat(1000), 3.0) == first
''')


_CLASS_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def _shadows_a_module(module: str) -> bool:
    """Whether ``module`` names a standard-library or installed top-level module (``numpy``, ``os``)."""
    import importlib.util
    import sys

    if module in sys.stdlib_module_names or module in sys.builtin_module_names:
        return True
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        return False


def render(name: str, class_name: str | None = None) -> dict[str, str]:
    """File name -> text of a new method ``name`` (checked like a plugin's name) and its test."""
    check_method_name(name, f"new-method {name!r}")
    module = name.replace("-", "_")
    if not module.isidentifier() or module[0].isdigit():
        raise ExposimError(f"new-method {name!r}: the module name {module!r} is not a Python identifier; start the "
                           "name with a letter")
    if keyword.iskeyword(module) or keyword.issoftkeyword(module) or module in ("None", "True", "False"):
        raise ExposimError(f"new-method {name!r}: the module name {module!r} is a Python keyword; choose another NAME")
    if _shadows_a_module(module):
        raise ExposimError(f"new-method {name!r}: a module named {module!r} is already importable (it would shadow "
                           "it, or be shadowed); choose another NAME")
    class_name = class_name or "".join(part[:1].upper() + part[1:] for part in re.split(r"[-_]", name) if part)
    if not _CLASS_RE.match(class_name) or keyword.iskeyword(class_name) or keyword.issoftkeyword(class_name):
        raise ExposimError(f"new-method: --class-name {class_name!r} is not a Python identifier (or is a keyword)")
    values = {"name": name, "module": module, "class_name": class_name}
    return {f"{module}.py": METHOD_TEMPLATE.substitute(values),
            f"test_{module}.py": TEST_TEMPLATE.substitute(values)}


def new_method(args) -> int:
    files = render(args.name, args.class_name)
    out = Path(args.output)
    existing = [str(out / f) for f in files if (out / f).exists()]
    if existing:
        raise OutputExistsError(f"{', '.join(existing)}: already exists; new-method never overwrites (choose another "
                                "NAME or -o DIR)")
    out.mkdir(parents=True, exist_ok=True)
    for fname, text in files.items():
        write_text(out / fname, text, overwrite=False)
        print(f"wrote {out / fname}")
    module = next(iter(files))[:-3]
    cls = args.class_name or files[next(iter(files))].split("class ", 1)[1].split(":", 1)[0]
    if not _has_pytest():
        print("pytest is not installed (the 'all' extra does not bring it): pip install 'exposim[test]'")
    print(f"try it:  cd {out} && python -m pytest -q test_{module}.py && "
          f"PYTHONPATH=. exposim run SEQ --methods all,{module}:{cls} -o RUN")
    return 0


def _has_pytest() -> bool:
    """Whether ``python -m pytest`` can run the test skeleton (pytest comes with the ``test`` extra)."""
    import importlib.util

    try:
        return importlib.util.find_spec("pytest") is not None
    except (ImportError, ValueError):
        return False
