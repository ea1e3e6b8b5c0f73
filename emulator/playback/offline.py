"""The offline closed loop on a bracketed recording: :func:`iter_run` (a generator) and :func:`run` (in memory).

Both are :func:`emulator.playback.loop.closed_loop` over an
:class:`~emulator.playback.emulated.EmulatedProvider`, configured by one
:class:`~emulator.playback.config.RunConfig`.  Nothing here prints.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import NamedTuple

from emulator.core.dataset import Sequence
from emulator.playback.config import RunConfig
from emulator.playback.loop import closed_loop
from emulator.playback.records import CycleStep, MethodStep, RunResult, RunStats
from emulator.io.borealhdr import load_sequence
from emulator.playback import workers  # called through the module: tests replace workers.start_methods

__all__ = ["iter_run", "run", "prepare_run", "at_rate", "Prepared", "resolve_sequence"]


def resolve_sequence(sequence, *, imu_warning: bool = True) -> Sequence:
    """A loaded :class:`~emulator.core.dataset.Sequence`, or the recording at this path (``imu_warning``:
    :func:`~emulator.io.borealhdr.load_sequence`'s)."""
    return sequence if isinstance(sequence, Sequence) else load_sequence(sequence, imu_warning=imu_warning)


class Prepared(NamedTuple):
    """What a run needs once its configuration is valid (:func:`prepare_run`)."""

    sequence: Sequence
    response: object
    methods: dict
    provider: object  #: :class:`EmulatedProvider` or :class:`~emulator.playback.native.NativeProvider`
    noise_model: object
    noise_source: str | None
    blur: object


def prepare_run(sequence, methods, config: RunConfig, response=None, *, stats: RunStats | None = None,
                blur=None) -> Prepared:
    """Resolve the recording's side of a run: the response at the recording's levels, the methods
    (built by name with ``config.mode``, ``config.options[name]`` and that response, each in its
    own worker process unless ``config.workers == "inline"``; :mod:`emulator.playback.workers`),
    the noise model, the blur hook (``blur``, else ``config``'s), and the image provider of ``config.rate``.  The
    workers stop when the closed loop over them ends (or :func:`~emulator.playback.workers.stop_methods`)."""
    seq = resolve_sequence(sequence, imu_warning=config.blur != "none")  # the IMU is read only for blur
    response = config.response_for(seq, response)
    built = workers.start_methods(methods, config, response)  # one worker process per method (config.workers)
    try:
        model, source = config.noise_for(seq, response)
        hook = blur if blur is not None else config.blur_for(seq, response)
        provider = config.provider_for(seq, response, noise=None if model is None else (model, config.noise_seed),
                                       stats=stats, blur=hook)  # a tick per bracket sweep, or per recorded frame
    except BaseException:
        workers.stop_methods(built)
        raise
    return Prepared(seq, response, built, provider, model, source, hook)


def at_rate(prep: Prepared, config: RunConfig) -> Prepared:
    """``prep`` as it is: :func:`prepare_run` makes the provider of ``config.rate`` already
    (:meth:`RunConfig.provider_for`); kept for callers written before it did."""
    return prep


def iter_run(
    sequence,
    methods,
    config: RunConfig | None = None,
    *,
    response=None,
    emulate_right: bool = False,
    keep_images: bool = False,
    on_step: Callable[[MethodStep], None] | None = None,
    stats: RunStats | None = None,
    blur=None,
    **settings,
) -> Iterator[CycleStep]:
    """Run the closed loop cycle by cycle, yielding a :class:`CycleStep` per cycle.

    Parameters
    ----------
    sequence : Sequence or path
        The recording (BorealHDR layout).
    methods : "all", "m1,m2", names, or AE method instances
        Methods built by name get the mode, their options and the response (zhang).
    config : RunConfig or None
        The run's settings; keyword ``settings`` (``initial_ms``, ``range_ms``, ``selector``,
        ``mode``, ``options``, ``jobs``, ``noise``, ``noise_model``, ``noise_seed``,
        ``method_timeout_s``) override it, validated by :class:`RunConfig`.
    response : CameraResponse or None
        Default: the sequence's own (:func:`emulator.io.borealhdr.sequence_response`).
    emulate_right, keep_images : bool
        Also emulate the right image (its fractions are computed anyway); keep the emulated
        images on the yielded steps (else they are dropped after ``on_step``).
    on_step : callable(MethodStep) or None
        Called in the worker right after each method's step, with the images attached.
    stats : RunStats or None
        Filled with counters and timings.
    blur : hook or None
        Blur-consistent emulation (:class:`~emulator.playback.emulated.EmulatedProvider`).

    A method that fails (raises :class:`~emulator.autoexposure.registry.MethodFailed`,
    returns a bad value through the plugin wrapper, or exceeds ``method_timeout_s``) gets no
    step from that cycle on; :attr:`CycleStep.failed` names it with the reason and the other
    methods go on.  The configuration is checked when this is called, before the first cycle.
    """
    cfg = RunConfig.from_kwargs(config, **settings)
    stats = stats if stats is not None else RunStats()
    prep = prepare_run(sequence, methods, cfg, response, stats=stats, blur=blur)
    return closed_loop(prep.provider, prep.methods, cfg, want_right=emulate_right, keep_images=keep_images, on_step=on_step,
                       stats=stats)


def run(
    sequence,
    methods="all",
    config: RunConfig | None = None,
    *,
    response=None,
    progress: Callable[[int, int], None] | None = None,
    **settings,
) -> RunResult:
    """Run the closed loop over a whole sequence in memory (no images kept); see :func:`iter_run`.

    ``progress(done, total)`` is called after every cycle.
    """
    cfg = RunConfig.from_kwargs(config, **settings)
    stats = RunStats()
    prep = prepare_run(sequence, methods, cfg, response, stats=stats)
    seq, built = prep.sequence, prep.methods
    steps: dict[str, list[MethodStep]] = {name: [] for name in built}
    skipped: list[tuple[int, str]] = []
    failed: dict[str, str] = {}
    for i, cs in enumerate(closed_loop(prep.provider, built, cfg, stats=stats), 1):
        failed.update(cs.failed)
        if cs.skipped:
            skipped.append((cs.cycle, cs.skipped))
        for name, st in cs.steps.items():
            steps[name].append(st)
        if progress is not None:
            progress(i, len(prep.provider.tick_indices))
    return RunResult(steps, skipped, built, stats, failed)
