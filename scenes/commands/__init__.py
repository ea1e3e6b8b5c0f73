"""The sub-commands of ``exposim`` that run scenes code: ``render`` and ``synth``.

Registered in pyproject.toml under the entry-point group ``exposim.commands``; each module
has ``register(subparsers)`` and only parses arguments and calls :mod:`scenes`.
"""
