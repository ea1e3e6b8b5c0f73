"""The exposure-integrated radiance of every shot of a synthetic walk, shared by the writer and live captures.

:func:`scenes.synthesize` captures each bracket from :meth:`WalkShots.radiance`; the live
closed loop (``validation.live``) captures a method's own exposure from the same object,
rebuilt from the dataset's ``exposim.json`` by :func:`walk_radiance`, so a live shot of T ms
integrates over ``[t, t + T]`` from the same renders (cache hits) as the brackets.
"""

from __future__ import annotations

import collections

import numpy as np

from scenes.errors import SceneError

__all__ = ["WalkShots", "walk_radiance", "shot_time_s"]

#: Renderers a :class:`WalkShots` keeps by default (each holds its render and depth: the two cameras of two
#: shots or sweeps).
KEEP_RENDERERS = 4


def shot_time_s(index: int, fps: float) -> float:
    """Seconds from the recording start of shot ``index`` (as :func:`synth.sequence.shot_schedule`)."""
    return int(round(index * 1e9 / fps)) * 1e-9


class WalkShots:
    """One :class:`scenes.blur.ShotRenderer` per shot (or per sweep) and camera of a walk.

    Parameters
    ----------
    scene, traj :
        The scene and its trajectory (left camera).
    render : dict
        ``width``, ``height``, ``spp``, ``fov_deg``, ``cache_dir``, ``variant``, ``denoise``
        (as :func:`scenes.render`) and ``render_seed``; optionally ``adaptive`` (as :func:`scenes.render`).
    fps, n_brackets : float, int
        The shot schedule.
    max_window_ms : float
        Longest exposure a shot's render is sized for (longer windows get their own render).
    baseline_m : float
        Stereo baseline of the right camera.
    render_per : str
        ``"shot"`` or ``"cycle"`` (one render per sweep, warped to its shots).
    integrate : bool
        True: a shot integrates over its exposure window.  False: every shot is the scene at
        its trigger instant, warped from the same renders (a window of 0 ms): the sharp twin of
        a blurred walk, which shares its render noise (validation.blur's live-versus-emulated table).
    margin_step_px : int
        Render margins are rounded up to a multiple of this (:class:`scenes.blur.ShotRenderer`).
    keep : int
        Renderers kept (the most recently used; a renderer dropped and needed again reads its render from the
        cache and renders its depth again): :data:`KEEP_RENDERERS`, or more for a caller that goes over the
        walk several times.
    """

    def __init__(self, scene, traj, *, render: dict, fps: float, n_brackets: int, max_window_ms: float,
                 baseline_m: float, render_per: str = "shot", integrate: bool = True, margin_step_px: int = 1,
                 keep: int = KEEP_RENDERERS):
        if render_per not in ("shot", "cycle"):
            raise SceneError(f"render_per must be 'shot' or 'cycle', got {render_per!r}")
        if isinstance(keep, bool) or not isinstance(keep, int) or keep < 1:
            raise SceneError(f"keep must be an integer >= 1, got {keep!r}")
        self.keep = keep
        self.scene, self.traj, self.render = scene, traj, dict(render)
        self.fps, self.n_brackets, self.max_window_ms = float(fps), int(n_brackets), float(max_window_ms)
        self.baseline_m, self.render_per, self.integrate = float(baseline_m), render_per, bool(integrate)
        self.margin_step_px = margin_step_px
        self._renderers: collections.OrderedDict = collections.OrderedDict()

    def seed(self, index: int, camera: str) -> int:
        """Render seed of shot ``index`` (the seeds :func:`scenes.synthesize` has always used)."""
        return (int(self.render["render_seed"]) * 1_000_003 + 2 * int(index) + (camera == "right")) % (1 << 32)

    def poses(self, camera: str):
        """``times_s -> (N, 4, 4)`` poses of one camera of the rig."""
        from scenes import trajectory as tr

        def poses(times_s):
            p = np.asarray(self.traj.poses(times_s), dtype=np.float64)
            return p if camera == "left" else np.stack([tr.stereo_right(m, self.baseline_m) for m in p])

        return poses

    def _make(self, first: int, camera: str, span_ms: float):
        from scenes.blur import ShotRenderer

        r = self.render
        return ShotRenderer(self.scene, self.poses(camera), shot_time_s(first, self.fps), span_ms, width=r["width"],
                            height=r["height"], spp=r["spp"], seed=self.seed(first, camera), fov_deg=r["fov_deg"],
                            cache_dir=r["cache_dir"], variant=r["variant"], denoise=r["denoise"],
                            margin_step_px=self.margin_step_px, adaptive=r.get("adaptive"))

    def renderer(self, index: int, camera: str):
        """The renderer serving shot ``index`` (its sweep's with ``render_per="cycle"``)."""
        first = index - index % self.n_brackets if self.render_per == "cycle" else int(index)
        key = (first, camera)
        if key not in self._renderers:
            span = self.max_window_ms + (1e3 * (self.n_brackets - 1) / self.fps if self.render_per == "cycle" else 0)
            self._renderers[key] = self._make(first, camera, span)
            while len(self._renderers) > self.keep:
                self._renderers.popitem(last=False)
        return self._renderers[key]

    def radiance(self, index: int, camera: str, exposure_ms: float) -> np.ndarray:
        """float32 (H, W, 3) radiance of shot ``index`` integrated over its ``exposure_ms`` window
        (at its trigger instant without ``integrate``)."""
        t0 = shot_time_s(index, self.fps)
        if not self.integrate:
            exposure_ms = 0.0
        shot = self.renderer(index, camera)
        if t0 + 1e-3 * float(exposure_ms) > shot.t0_s + 1e-3 * shot.max_exposure_ms + 1e-9:
            shot = self._make(index, camera, float(exposure_ms))  # longer than the renders were sized for
        return shot.radiance(exposure_ms, start_s=max(t0, shot.t0_s))[0]

    def describe(self) -> dict:
        return {"render_per": self.render_per, "max_window_ms": self.max_window_ms, "fps": self.fps,
                "n_brackets": self.n_brackets, "baseline_m": self.baseline_m, "integrate": self.integrate,
                "margin_step_px": self.margin_step_px}


def walk_radiance(dataset, scene, *, cache_dir=None, keep: int = KEEP_RENDERERS):
    """``radiance(timestamp_ns, camera, exposure_ms)`` of a dataset :func:`scenes.synthesize` wrote with blur.

    Rebuilt from its ``exposim.json`` (render settings, walk, schedule): the renders are the
    writer's (cache hits).  ``exposure_aware`` is True: a live capture of T ms integrates
    over ``[t, t + T]``.  ``keep``: renderers kept (:class:`WalkShots`; a caller that goes over the walk
    several times keeps each sweep's).  Returns None for a dataset written without exposure integration.
    """
    from pathlib import Path

    from emulator.io.borealhdr import read_recording_metadata
    from scenes.denoise import DenoiseSettings

    meta = read_recording_metadata(Path(dataset))
    src = meta.get("source") or {}
    render, blur = src.get("render") or {}, (src.get("render") or {}).get("blur_shots")
    if not blur:
        return None
    den = render["denoise"]
    settings = DenoiseSettings(name="off") if den.get("name") == "off" else DenoiseSettings(**den["settings"])
    traj_desc = src.get("trajectory") or {}
    kwargs = {} if traj_desc.get("speed_mps") is None else {"speed_mps": float(traj_desc["speed_mps"])}
    duration = meta["n_shots"] / float(meta["fps"]) + 1.0
    traj = scene.trajectory(duration, walk=traj_desc.get("walk"), **kwargs)
    shots = WalkShots(scene, traj, render=dict(width=render["width"], height=render["height"], spp=render["spp"],
                                               fov_deg=render["fov_deg"], variant=render["variant"], denoise=settings,
                                               render_seed=render["render_seed"], cache_dir=cache_dir,
                                               adaptive=render.get("adaptive")),
                      fps=blur["fps"], n_brackets=blur["n_brackets"], max_window_ms=blur["max_window_ms"],
                      baseline_m=blur["baseline_m"], render_per=blur["render_per"],
                      integrate=bool(blur.get("integrate", True)), margin_step_px=int(blur.get("margin_step_px", 1)),
                      keep=keep)
    start_ns = int(meta["start_time_ns"])

    def radiance(timestamp_ns: int, camera: str, exposure_ms: float) -> np.ndarray:
        index = int(round((int(timestamp_ns) - start_ns) * shots.fps / 1e9))
        return shots.radiance(index, camera, exposure_ms)

    radiance.exposure_aware = True
    radiance.shots = shots
    return radiance
