"""The run settings' spine: each setting of a run declared once, as a field of
:class:`~emulator.playback.config.RunConfig` with a :class:`Setting` in its metadata.

A setting says its command-line flag (``exposim run``; its help, choices, argparse type), its
``run.json`` key (how it is written, how it is read back, the value a folder from before the
setting reads as), whether a ``--resume`` compares it, and where the rebuilt command line
(``run.json``'s ``command``) places it.  Everything that used to list the settings derives from
here: :func:`add_arguments` (the parser), :func:`given` (the values a command line gives),
:func:`to_json` / :func:`values_from_json` (``run.json``), :func:`resume_keys` (the resume
comparison), :func:`command_words` (the rebuilt command line) and :func:`flag_of` (errors name
the flag).  A new setting is one new field::

    my_level: int = setting(0, flag="--my-level", help="...", key="my_level", resume=True,
                            cli={"type": int})

Every function takes the configuration class, so a subclass that adds fields (a test's) is
served the same way.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from emulator.errors import PlaybackError

__all__ = ["Setting", "setting", "settings_of", "add_arguments", "given", "flag_of", "to_json", "values_from_json",
           "resume_keys", "recorded_value", "compared", "command_words", "parse_option", "parse_options", "METADATA_KEY"]

#: The key of a field's metadata that holds its :class:`Setting`.
METADATA_KEY = "setting"
_MISSING = object()


@dataclass(frozen=True)
class Setting:
    """What one run setting declares besides its field (name, type, default).

    flag, aliases, help, cli
        The ``exposim run`` flag (None: no flag), older spellings, help text and further
        ``argparse`` keywords (``type``, ``choices``, ``nargs``, ``metavar``, ``action``, ``default``).
    key
        The ``run.json`` key (None: written inside another setting's value, or not at all).
    encode
        ``encode(config, context) -> {key: value}``: the keys this setting writes to ``run.json``
        (``context``: the resolved noise model and blur hook); default ``{key: value}``.
    decode
        ``decode(run_json) -> value`` of the field; default the key's value, :attr:`old` where
        the key is absent or null.
    old
        The value of a folder written before the setting existed (default: the field's default).
    resume
        A ``--resume`` compares the key (recorded against given).
    recorded
        ``recorded(run_json)``: the recorded JSON value a resume compares (default: the key's).
    compare
        ``compare(mine, theirs) -> (mine, theirs)``: what of the two a resume compares.
    per_run
        How this run computes, not what (``jobs``, ``workers``): written again on every resume.
    command, shown_unless_default
        Rank in the rebuilt command line; list the flag only where the value differs from the default.
    native_only
        The flag is refused without ``--rate native``.
    """

    flag: str | None = None
    help: str = ""
    cli: Mapping[str, Any] = field(default_factory=dict)
    aliases: tuple[str, ...] = ()
    key: str | None = None
    encode: Callable | None = None
    decode: Callable | None = None
    old: Any = _MISSING
    resume: bool = False
    recorded: Callable | None = None
    compare: Callable | None = None
    per_run: bool = False
    command: int | None = None
    shown_unless_default: bool = False
    native_only: bool = False


def setting(default=_MISSING, *, default_factory=_MISSING, **meta):
    """A dataclass field carrying a :class:`Setting` (keywords as its attributes)."""
    md = {METADATA_KEY: Setting(**meta)}
    if default_factory is not _MISSING:
        return field(default_factory=default_factory, metadata=md)
    return field(default=default, metadata=md)


def settings_of(cls) -> list[tuple[dataclasses.Field, Setting]]:
    """Every (field, setting) of the configuration class ``cls``, in field order."""
    return [(f, f.metadata[METADATA_KEY]) for f in dataclasses.fields(cls) if METADATA_KEY in f.metadata]


def _default(f: dataclasses.Field):
    return f.default_factory() if f.default is dataclasses.MISSING else f.default


# ------------------------------------------------------------------ the command line
def add_arguments(parser, cls) -> None:
    """One argument per setting with a flag (dest: the field's name; absent: None)."""
    for f, s in settings_of(cls):
        if s.flag is None:
            continue
        kw = {"default": None, **dict(s.cli)}
        parser.add_argument(s.flag, *s.aliases, dest=f.name, help=s.help, **kw)


def given(args, cls) -> dict:
    """The settings a parsed command line gives: field name -> value (None: not given)."""
    out = {}
    for f, s in settings_of(cls):
        if s.flag is None:
            continue
        value = getattr(args, f.name, None)
        if value is False:  # a switch not set: not given
            value = None
        elif isinstance(value, list):
            value = tuple(value)
        elif value is not None and hasattr(value, "__fspath__"):
            value = str(value)
        out[f.name] = value
    return out


def flag_of(cls, name: str) -> str | None:
    """The flag of field ``name`` (None: it has none)."""
    return next((s.flag for f, s in settings_of(cls) if f.name == name), None)


def command_words(args, cls) -> list[tuple[int, list[str]]]:
    """``(rank, words)`` of every setting the command line gave, for the rebuilt command line."""
    out = []
    for f, s in settings_of(cls):
        if s.flag is None or s.command is None:
            continue
        value = getattr(args, f.name, None)
        if value is None or value is False or (s.shown_unless_default and value == _default(f)):
            continue
        if value is True:
            words = [s.flag]
        elif isinstance(value, (list, tuple)):
            words = [s.flag, *(str(v) for v in value)]
        else:
            words = [s.flag, str(value)]
        out.append((s.command, words))
    return out


# ------------------------------------------------------------------ run.json
def to_json(config, context: Mapping | None = None, *, per_run: bool | None = None) -> dict:
    """The ``run.json`` keys of ``config``, in field order (``per_run``: only those settings, or only the others)."""
    out: dict = {}
    for f, s in settings_of(type(config)):
        if per_run is not None and s.per_run != per_run:
            continue
        if s.encode is not None:
            out.update(s.encode(config, context or {}))
        elif s.key is not None:
            out[s.key] = getattr(config, f.name)
    return out


def values_from_json(cls, run_json: Mapping) -> dict:
    """The field values a ``run.json`` records (a folder from before a setting: its :attr:`Setting.old`)."""
    out = {}
    for f, s in settings_of(cls):
        if s.decode is not None:
            out[f.name] = s.decode(run_json)
        elif s.key is not None:
            value = run_json.get(s.key)
            out[f.name] = value if value is not None else (_default(f) if s.old is _MISSING else s.old)
    return out


def resume_keys(cls) -> tuple[str, ...]:
    """The ``run.json`` keys a ``--resume`` compares."""
    return tuple(s.key for _, s in settings_of(cls) if s.resume)


def recorded_value(cls, key: str, run_json: Mapping):
    """What a resume compares of ``key`` in a recorded ``run.json`` (older spellings and defaults applied)."""
    s = next(s for _, s in settings_of(cls) if s.key == key)
    return s.recorded(run_json) if s.recorded is not None else run_json.get(key)


def compared(cls, key: str, mine, theirs):
    """``(mine, theirs)`` as a resume compares them."""
    s = next(s for _, s in settings_of(cls) if s.key == key)
    return s.compare(mine, theirs) if s.compare is not None else (mine, theirs)


# ------------------------------------------------------------------ --option METHOD.KEY=VALUE
def parse_option(text: str) -> tuple[str, str, object]:
    """``METHOD.KEY=VALUE`` -> (method, key, value); VALUE parsed as JSON when it can be."""
    head, sep, value = str(text).partition("=")
    method, dot, key = head.partition(".")
    if not sep or not dot or not method.strip() or not key.strip():
        raise PlaybackError(f"--option {text!r}: expected METHOD.KEY=VALUE, e.g. kim.seed=3")
    try:
        parsed = json.loads(value)
    except json.JSONDecodeError:
        parsed = value
    return method.strip(), key.strip(), parsed


def parse_options(texts: Iterable[str], base: Mapping | None = None) -> dict[str, dict]:
    """Every ``--option`` text folded into ``{method: {key: value}}`` (over ``base``)."""
    out = {str(k): dict(v) for k, v in dict(base or {}).items()}
    for text in texts:
        method, key, value = parse_option(text)
        out.setdefault(method, {})[key] = value
    return out
