"""How :class:`~emulator.playback.config.RunConfig`'s settings are written to and read from ``run.json``
where a setting is not one plain key (the noise and blur records, recorded files, older folders).

Each function is named by a setting's :class:`~emulator.playback.settings.Setting` (``encode``,
``decode``, ``recorded``, ``compare``); nothing else calls them.
"""

from __future__ import annotations

from pathlib import Path

from emulator.core.blur import DEFAULT_PLACEMENT

__all__ = ["noise_json", "blur_json", "recorded_blur", "common_figures", "recorded_noise_model", "recorded_response", "same_file"]


def noise_json(config, ctx) -> dict:
    if config.noise == "none":
        return {"noise": {"mode": "none"}}
    noise = {"mode": config.noise, "seed": config.noise_seed}
    model = ctx.get("noise_model")
    if model is not None:
        noise["model"] = {k: v for k, v in model.to_dict().items() if k != "response"}
    return {"noise": noise}


def blur_json(config, ctx) -> dict:
    hook = ctx.get("blur_hook")
    if hook is not None:
        return {"blur": hook.describe()}
    return {"blur": {"mode": config.blur, **({"placement": DEFAULT_PLACEMENT} if config.blur == "consistent" else {}),
                     **({"blur_aware": True} if config.blur_aware else {})}}


def recorded_blur(run_json) -> dict:
    blur = dict(run_json.get("blur") or {"mode": "none"})
    if blur.get("mode") == "consistent":  # folders from before tiled copies: uniform sub-instants
        blur.setdefault("placement", "uniform")
    return blur


def common_figures(a, b):
    """A noise or blur record as a resume compares it: the figures of a model or hook only where both sides have them."""
    return tuple({k: v for k, v in (x or {}).items() if k in ("mode", "seed", "blur_aware", "placement") or k in (y or {})}
                 for x, y in ((a, b), (b, a)))


def recorded_noise_model(run_json):
    model = run_json.get("noise_model_file") or run_json.get("noise_model")
    if model is not None and Path(model).name == "exposim.json":
        return None  # the recording's own: found again from the recording
    return model if model and Path(model).is_file() else None


def recorded_response(run_json):
    response = run_json.get("response_path") or run_json.get("response")
    return response if response and Path(response).is_file() else None


def same_file(a, b) -> bool:
    """Two recorded paths (relative ones to the working directory) name one existing file."""
    try:
        return bool(a) and bool(b) and Path(a).is_file() and Path(a).resolve() == Path(b).resolve()
    except OSError:
        return False
