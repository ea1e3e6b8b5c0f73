"""``exposim new-method NAME -o DIR``: write a starting AE method plugin and its test skeleton.

Writes ``DIR/<module>.py`` (a complete, working method: proportional mean-brightness control,
the README's example) and ``DIR/test_<module>.py`` (pytest properties on synthetic mosaics),
``<module>`` being NAME with ``-`` turned into ``_``.  Refuses to overwrite either file.  With
``examples/`` as DIR and NAME ``my-ae`` (``--class-name MyAE``) it writes the files shipped in
``examples/``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from emulator.commands.body import CommandBody

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "new-method",
        help="write a new AE method plugin module and its test skeleton",
        description=("Write DIR/<module>.py, a complete AE method (name, reset(), next_exposure(raw, exposure_ms)) "
                     "to edit, and DIR/test_<module>.py, its pytest skeleton; <module> is NAME with '-' as '_'. "
                     "Run it with: exposim run SEQ --methods all,<module>:<Class> (module importable), "
                     "or register it under the entry-point group exposim.methods. Never overwrites a file."),
    )
    p.add_argument("name", help="method name (letters, digits, '-', '_'; not a built-in's), e.g. my-ae")
    p.add_argument("-o", "--output", type=Path, default=Path("."), help="folder to write into (default: .)")
    p.add_argument("--class-name", default=None, help="class name (default: NAME in CamelCase, e.g. MyAe)")
    p.set_defaults(func=CommandBody("emulator.commands.new_method_body:new_method"))


register.order = 35  # place in `exposim --help`, after run
