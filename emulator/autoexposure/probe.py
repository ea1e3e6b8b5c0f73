"""Installed plugins checked in a process of their own (:func:`probe_entry_points`).

Listing the installed methods (``exposim run --help``, a name in ``--methods``, the broken-plugin
warning) needs to know which entry points load.  Loading one imports its module, and a module can
change the process that imports it (patch ``cv2.cvtColor`` at import, which the run's process uses
for the built-ins' gray images).  So the imports run in a short-lived Python process started for the
purpose, which answers with JSON text (nothing is unpickled); the run's process keeps only the names,
the import paths and the errors.  A method is loaded in the run's process only where it is built
there (``--isolation inline``).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

__all__ = ["probe_entry_points", "PROBE_TIMEOUT_S"]

#: How long the imports of every installed plugin may take together, s.
PROBE_TIMEOUT_S = 120.0

_PROBE = r"""
import json, sys
from importlib.metadata import EntryPoint

args = json.loads(sys.stdin.read())
sys.path[:] = args["path"]
real, sys.stdout = sys.stdout, sys.stderr  # what an import prints never reaches the answer
out = {}
for name, value, group in args["plugins"]:
    try:
        factory = EntryPoint(name, value, group).load()
        out[name] = None if callable(factory) else f"{value} is not a class or factory"
    except BaseException as exc:
        out[name] = f"cannot load {value}: {type(exc).__name__}: {exc}"
    real.write(json.dumps({name: out[name]}) + "\n")  # one line each: an import that ends the process
    real.flush()                                      # leaves the others' answers
"""


def probe_entry_points(entry_points: list) -> dict[str, str | None]:
    """``name -> None`` (loads, callable) or the error of every entry point, found by importing them in a
    separate process; an import that ends or hangs that process is the error of its entry point alone
    (the entry points after it are checked in another)."""
    found: dict[str, str | None] = {}
    left = list(entry_points)
    while left:
        answers, why = _probe(left)
        found.update(answers)
        rest = [ep for ep in left if ep.name not in found]
        if rest:  # the first unanswered one ended or hung the process
            found[rest[0].name] = f"cannot load {rest[0].value}: {why}"
            rest = rest[1:]
        left = rest
    return found


def _probe(entry_points: list) -> tuple[dict, str]:
    request = json.dumps({"path": list(sys.path), "plugins": [[ep.name, ep.value, ep.group] for ep in entry_points]})
    why = "its import ended the checking process"
    try:
        done = subprocess.run([sys.executable, "-c", _PROBE], input=request, capture_output=True, text=True,
                              timeout=PROBE_TIMEOUT_S, env=dict(os.environ))
        out = done.stdout
        if done.returncode:
            why = f"its import ended the checking process (exit status {done.returncode})"
    except subprocess.TimeoutExpired as exc:
        out = exc.stdout.decode(errors="replace") if isinstance(exc.stdout, bytes) else (exc.stdout or "")
        why = f"its import did not finish within {PROBE_TIMEOUT_S:g} s"
    except OSError as exc:
        return {ep.name: f"cannot load {ep.value}: cannot start a process to import it ({exc})"
                for ep in entry_points}, ""
    answers = {}
    for line in out.splitlines():
        try:
            answer = json.loads(line)
        except ValueError:
            continue
        if isinstance(answer, dict):
            answers.update({str(k): (None if v is None else str(v)) for k, v in answer.items()})
    return answers, why
