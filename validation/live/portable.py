"""A study folder that can be committed as it is: no path outside it, every file it needs.

* :func:`relative_command`: the command line with every absolute path made relative to the study
  folder (``-o /tmp/study`` becomes ``-o .``), as results.json and report.md record it;
* :func:`outside_paths`: every absolute path that the folder's text files name outside the
  repository (a folder that names one is not ready to be committed to docs/results);
* :data:`STUDY_FILES`: what a complete study folder holds;
* :func:`study_command`: the command that ran a study's walks, as its walk records keep it;
* :func:`check_plan_files`: a folder judged by a plan (or a stop record) still holds it.
"""

from __future__ import annotations

import importlib.util
import os
import re
from pathlib import Path

from emulator.io.files import RESULTS_FILE, read_results, read_text
from validation.live.config import PREREG_FILE, STOP_FILE, LiveError

__all__ = ["ABSOLUTE_PATH", "STUDY_FILES", "REPOSITORY", "relative_command", "outside_paths", "missing_files",
           "named_files", "folder_check", "folder_markdown", "study_command", "check_plan_files"]

#: An absolute POSIX path of at least two parts (``/tmp/x``), or a Windows one (``C:\\x``), not inside a word or
#: a URL (``km/h``, ``tcp://host`` are not paths).
ABSOLUTE_PATH = re.compile(r"(?<![\w.:/~-])/(?:[\w.+@-]+/)+[\w.+@-]*|\b[A-Za-z]:\\[^\s\"'`|)]+")
#: The files of a complete study folder: the verdicts, the report, the walks table, the power analysis, and the
#: on-the-data calibration where this installation makes one.
STUDY_FILES = ("results.json", "report.md", "walks.csv", "power.json") + (
    ("calibration.json",) if importlib.util.find_spec("validation.verdicts.plasmode") is not None else ())
#: The repository's root (paths inside it are not outside paths).
REPOSITORY = Path(__file__).resolve().parents[2]
_DATA_URI = re.compile(r"data:[\w/+.-]+;base64,[A-Za-z0-9+/=]+")
#: Text files :func:`outside_paths` reads (images and binary files are skipped).
_TEXT = (".json", ".md", ".csv", ".txt", ".html")


def relative_command(command: str | None, folder) -> str | None:
    """``command`` with each absolute path written relative to ``folder`` (None stays None)."""
    if command is None:
        return None
    base = os.path.abspath(folder)

    def rel(m: re.Match) -> str:
        p = m.group(0)
        return os.path.relpath(p, base) if p.startswith("/") else p

    return ABSOLUTE_PATH.sub(rel, str(command))


def outside_paths(folder, root=REPOSITORY, limit: int = 50, skip=()) -> list[str]:
    """``"file: path"`` for each absolute path named in the text files under ``folder`` that lies outside ``root``
    (at most ``limit``; each file once per path; ``skip``: file names relative to ``folder`` not read)."""
    folder, root = Path(folder), Path(root).resolve()
    found: list[str] = []
    for path in sorted(folder.rglob("*")):
        if not path.is_file() or path.suffix.lower() not in _TEXT or str(path.relative_to(folder)) in skip:
            continue
        try:
            text = read_text(path, error=ValueError)
        except (OSError, ValueError):
            continue
        text = _DATA_URI.sub("", text)  # embedded images (base64 holds slashes)
        for p in dict.fromkeys(ABSOLUTE_PATH.findall(text)):
            if p.startswith("/") and Path(p).is_relative_to(root):
                continue
            found.append(f"{path.relative_to(folder)}: {p}")
            if len(found) >= limit:
                return found
    return found


def missing_files(folder, also=()) -> list[str]:
    """The :data:`STUDY_FILES` (and the files ``also`` names) that ``folder`` lacks."""
    return [f for f in dict.fromkeys((*STUDY_FILES, *also)) if not (Path(folder) / f).is_file()]


def named_files(results: dict) -> list[str]:
    """The files a study's ``results.json`` was drawn from beyond :data:`STUDY_FILES`: its pre-registration and
    stop record where it was judged by them, its seeds table and residual shares where it has them (a folder
    without them redraws to another look, or not at all)."""
    plan = results.get("preregistration") or {}
    return [f for f in (plan.get("file"), (plan.get("stop") or {}).get("file"), results.get("seeds_table"),
                        results.get("residual_shares_file")) if f]


#: Files the writer is about to write itself (their old content is not checked).
WRITTEN = ("results.json", "report.md", "report.html")


def folder_check(folder, also=()) -> dict:
    """results.json's ``study_folder``: the study files missing (``also``: more files it needs, :func:`named_files`;
    results.json and report.md are written after this check and count as present) and the files (relative to the
    folder) that name an absolute path outside the repository; the paths themselves are not copied (results.json
    must not name them either)."""
    found = outside_paths(folder, skip=WRITTEN, limit=10_000)
    return {"missing_files": [f for f in missing_files(folder, also) if f not in WRITTEN],
            "files_naming_outside_paths": list(dict.fromkeys(p.split(": ", 1)[0] for p in found))}


def folder_markdown(check: dict | None) -> str:
    """A line for the report when the folder is not complete or names paths outside the repository."""
    if not check or not (check["missing_files"] or check["files_naming_outside_paths"]):
        return ""
    parts = []
    if check["missing_files"]:
        parts.append("it lacks " + ", ".join(check["missing_files"]))
    files = check["files_naming_outside_paths"]
    if files:
        parts.append(f"{len(files)} of its files name paths outside the repository (first {files[0]}; results.json "
                     "lists the files)")
    return "**This study folder is not ready to be committed as it is**: " + "; ".join(parts) + ".\n\n"


def study_command(replicates, seeds, scenes) -> str | None:
    """The command that ran the walks of a study whose seed folders are in ``replicates`` (each walk's benchmarks
    record it: ``seed<S>/vo/<scene>/<run>/results.json``), from the first of ``seeds`` x ``scenes`` that has one;
    None where none does."""
    for seed in seeds:
        for scene in scenes:
            for res in sorted((Path(replicates) / f"seed{seed}" / "vo" / scene).glob(f"*/{RESULTS_FILE}")):
                command = read_results(res).get("command")
                if command:
                    return command
    return None


def check_plan_files(out: Path, previous: dict) -> None:
    """Refuse (:class:`~validation.live.config.LiveError`) to redraw a folder whose results.json (``previous``) was
    judged by a pre-registration (or a stop record) that the folder no longer holds: without it the look would
    silently become another one."""
    plan = previous.get("preregistration") or {}
    for name, needed in ((PREREG_FILE, bool(plan)), (STOP_FILE, bool(plan.get("stop")))):
        if needed and not (Path(out) / name).is_file():
            raise LiveError(f"{Path(out) / name}: not found, but {Path(out) / RESULTS_FILE} was judged by it; copy it "
                            "back beside the study's files to redraw its verdicts")
