"""Shared fixtures: paths to ../shared (never copied into the repository), a temporary render cache."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

# The interrupt tests send SIGINT to an ``exposim`` sub-process, as Ctrl-C reaches a command run in
# a terminal.  A test run started in the background by a non-interactive shell (``cmd &``, or
# ``nohup``) inherits SIGINT ignored, every process it starts inherits that through exec, and a
# Python started with SIGINT ignored keeps ignoring it (the Unix convention that protects
# background jobs from Ctrl-C, which exposim follows).  The tests then wait for a signal that
# cannot arrive.  Here the test processes take Python's own SIGINT handler back, so that their
# sub-processes start as a terminal's foreground command would, whatever started the test run.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


def _find_shared() -> Path:
    """``../shared`` beside the repository; from a git worktree (``/work/wt/NAME``) the first
    ``shared/`` folder found further up, so the sample tests run there too instead of skipping."""
    for parent in REPO.parents:
        if (parent / "shared" / "data").is_dir():
            return parent / "shared"
    return REPO.parent / "shared"


SHARED = _find_shared()
SAMPLE = SHARED / "data" / "borealhdr_sample"
SAMPLE_SEQ = SAMPLE / "backpack_2023-09-25-15-05-03"
PCALIB = SAMPLE / "calibration" / "pcalib_inside1.txt"
#: The render cache's environment variable (scenes.cache.ENV_CACHE_DIR; not imported here so
#: that collecting the tests does not import scenes).
ENV_CACHE_DIR = "EXPOSIM_CACHE"


def in_ci() -> bool:
    """True where the environment variable ``CI`` says a CI service runs the tests (``true``, ``1``, ``yes``)."""
    return os.environ.get("CI", "").strip().lower() in ("true", "1", "yes")


def missing_shared(reason: str):
    """A test that needs ``../shared`` and does not find it: skipped, or failed under CI (``CI=true``),
    where a skip would pass a weaker suite without a word."""
    if in_ci():
        pytest.fail(f"{reason} (CI is set: the shared data must be present; see tests/conftest.py)", pytrace=False)
    pytest.skip(reason)


def pytest_report_header(config):
    """One line at the top of every run: where the shared data is, or that the tests needing it skip."""
    if SAMPLE_SEQ.is_dir():
        return f"shared data: {SHARED}"
    return (f"shared data: not found at {SHARED}: the tests that need it "
            f"{'fail (CI is set)' if in_ci() else 'are skipped (set CI=true to fail them)'}")


@pytest.fixture(scope="session", autouse=True)
def render_cache(tmp_path_factory) -> Path:
    """Every test renders into one temporary cache for the session, never into ``~/.cache``.

    Set in ``os.environ`` so that ``exposim`` sub-processes the tests start inherit it; the
    caller's value is restored at the end.
    """
    cache = tmp_path_factory.getbasetemp() / "render-cache"
    cache.mkdir(exist_ok=True)
    previous = os.environ.get(ENV_CACHE_DIR)
    os.environ[ENV_CACHE_DIR] = str(cache)
    yield cache
    if previous is None:
        os.environ.pop(ENV_CACHE_DIR, None)
    else:
        os.environ[ENV_CACHE_DIR] = previous


@pytest.fixture
def default_render_env(render_cache, monkeypatch) -> Path:
    """The session's render cache, and the default render variant and denoiser (the caller's
    ``EXPOSIM_MITSUBA_VARIANT`` and ``EXPOSIM_DENOISE`` unset): for tests of the render path itself."""
    monkeypatch.setenv(ENV_CACHE_DIR, str(render_cache))
    monkeypatch.delenv("EXPOSIM_MITSUBA_VARIANT", raising=False)
    monkeypatch.delenv("EXPOSIM_DENOISE", raising=False)
    return render_cache


@pytest.fixture(scope="session")
def sample_seq() -> Path:
    if not SAMPLE_SEQ.is_dir():
        missing_shared(f"shared BorealHDR sample not found at {SAMPLE_SEQ}")
    return SAMPLE_SEQ


@pytest.fixture(scope="session")
def pcalib_path() -> Path:
    if not PCALIB.is_file():
        missing_shared(f"shared pcalib file not found at {PCALIB}")
    return PCALIB


class SynthesizeCalled(Exception):
    """Raised by the ``stop_at_synthesize`` fixture's stand-in: the study got as far as rendering."""


@pytest.fixture
def stop_at_synthesize(monkeypatch) -> dict:
    """Replace :func:`scenes.synthesize.synthesize` by a stand-in that records its keyword
    arguments in the returned dict and raises :class:`SynthesizeCalled` (for plumbing tests)."""
    import scenes.synthesize

    seen: dict = {}

    def stand_in(*args, **kwargs):
        seen.update(kwargs)
        raise SynthesizeCalled

    monkeypatch.setattr(scenes.synthesize, "synthesize", stand_in)
    return seen


def static_chart_recording(folder: Path, width: int, height: int, *, dynamic_range_db: float = 60.0,
                           **capture) -> Path:
    """A synthetic stereo recording of a static HDR chart (right camera one baseline along x), written by
    ``synth.capture_sequence(..., **capture)`` into ``folder``: what the native-rate tests emulate."""
    import numpy as np

    import synth
    from synth.procedural import hdr_chart
    from synth.sequence import BASELINE_M

    chart = hdr_chart(width, height, seed=3, dynamic_range_db=dynamic_range_db)
    right = np.eye(4)
    right[0, 3] = BASELINE_M

    def source(t, cam):
        return chart, (np.eye(4) if cam == "left" else right)

    cam = synth.Camera.preset("borealhdr", width=width, height=height)
    return synth.capture_sequence(source, folder, cam, seed=5, **capture)
