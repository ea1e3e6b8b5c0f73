"""``exposim validate NAME``: one sub-command per registered study.

A study is a :class:`~validation.protocol.Study` (name, help, extras, options, run).  Studies
register under the entry-point group ``exposim.studies`` (pyproject.toml, the same way
``exposim.commands`` and ``exposim.methods`` are registered), each entry's value the
package's ``Study``.  This project's own studies are also listed here (:data:`OWN_STUDIES`,
equal to pyproject.toml's entries: a test says so), so that a checkout whose installed
metadata predates a study still offers it; studies other distributions register follow
them.  A study that fails to load is offered by name and says why when run.
"""

from __future__ import annotations

import argparse
from importlib import metadata

from emulator.errors import ExposimError
from validation.protocol import DefaultsFormatter, Study

__all__ = ["STUDY_GROUP", "OWN_STUDIES", "study_entry_points", "load_studies", "register"]

#: The entry-point group studies register under.
STUDY_GROUP = "exposim.studies"
#: This project's studies in ``exposim validate --help`` order: (name, ``module:attribute`` of its Study).
OWN_STUDIES = (
    ("emulation", "validation.commands.experiments:EMULATION"),
    ("selectors", "validation.commands.experiments:SELECTORS"),
    ("motion", "validation.commands.experiments:MOTION"),
    ("speed", "validation.commands.experiments:SPEED"),
    ("ae-study", "validation.ae_study.cli:STUDY"),
    ("live", "validation.live.cli:STUDY"),
    ("render", "validation.render_study.cli:STUDY"),
    ("blur", "validation.blur.cli:STUDY"),
    ("native", "validation.native_loo.cli:STUDY"),
    ("calibration", "validation.calibration_study.cli:STUDY"),
    ("verdict-rates", "validation.verdict_studies.calibrate:STUDY"),
    ("study-power", "validation.verdict_studies.study_power:STUDY"),
    ("study-calibration", "validation.verdict_studies.study_calibration:STUDY"),
    ("own-residuals", "validation.verdict_studies.own_residuals:STUDY"),
    ("level-shift", "validation.verdict_studies.live_checks:LEVEL_SHIFT"),
    ("monte-carlo", "validation.verdict_studies.live_checks:MONTE_CARLO"),
)


def study_entry_points(installed=None) -> list[metadata.EntryPoint]:
    """This project's studies (:data:`OWN_STUDIES`), then the other installed ``exposim.studies`` entries.

    ``installed`` (for tests) replaces the installed entry points.  An installed entry with the
    name of one of this project's studies is this project's own registration and is skipped.
    """
    own = [metadata.EntryPoint(name, value, STUDY_GROUP) for name, value in OWN_STUDIES]
    installed = metadata.entry_points(group=STUDY_GROUP) if installed is None else installed
    names = {name for name, _ in OWN_STUDIES}
    others, seen = [], set()
    for ep in installed:
        if ep.name not in names and ep.name not in seen:
            seen.add(ep.name)
            others.append(ep)
    return own + others


def load_studies(entry_points=None) -> list[Study | tuple[str, str]]:
    """Every study of :func:`study_entry_points` loaded: a :class:`Study`, or ``(name, why)`` when it fails to load."""
    studies = []
    for ep in study_entry_points() if entry_points is None else entry_points:
        try:
            study = ep.load()
        except Exception as exc:  # a broken plugin: offered by name, never swallowed
            studies.append((ep.name, f"cannot load {ep.value}: {type(exc).__name__}: {exc}"))
            continue
        if not isinstance(study, Study) or study.name != ep.name:
            studies.append((ep.name, f"{ep.value} is not the Study '{ep.name}'"))
            continue
        studies.append(study)
    return studies


def _broken(why: str):
    def run(args) -> int:
        raise ExposimError(f"this study is broken ({why})")

    return run


def register(sub: argparse._SubParsersAction, studies=None) -> None:
    """Add ``validate`` and one sub-command per study (``studies``: :func:`load_studies` unless given)."""
    p = sub.add_parser(
        "validate",
        help="render-and-validate experiments on synthetic ground truth (writes results.json, PNGs, report.md)",
        description="Validate the emulator, the bracket selectors, motion between brackets and speed on "
                    "synthetic scenes with exact ground truth.",
        formatter_class=DefaultsFormatter,
    )
    vsub = p.add_subparsers(dest="experiment", metavar="EXPERIMENT", required=True)
    for study in load_studies() if studies is None else studies:
        if isinstance(study, Study):
            study.register(vsub)
            continue
        name, why = study
        broken = vsub.add_parser(name, help=f"(broken: {why})")
        broken.add_argument("args", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
        broken.set_defaults(func=_broken(why), experiment=name, extras=())


register.order = 80  # place in `exposim --help`
