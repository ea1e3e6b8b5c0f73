"""Exposure emulation (paper eq. 2) through a per-ratio lookup table.

``I_target = f( (t_target / t_source) * f^-1(I_source) )``.  The source is an integer DN,
so for one ratio k the whole mapping is a table over all DN values,
``L_k[d] = clip(round(f(k * g(d))), black, white)``, built once per ratio (cached on the
:class:`~emulator.core.response.CameraResponse`) and applied with one gather.

Quantisation sets the accuracy floor: one source DN spans one bin of linear exposure and
the ratio stretches it, so emulating a longer exposure from a shorter one carries an error
of about k/2 + 1/2 DN for a linear response; emulating a shorter one is within 1 DN.

The validity mask marks pixels whose source value carried radiance information for the
target: unclipped sources, plus clips the ratio preserves (saturated high with k >= 1,
black with k <= 1).

Noise: the default (``noise="none"``) is exact eq. 2, so an emulated image carries its
source's noise scaled by the ratio; ``noise="consistent"`` adds the variance a capture at
the target would have had beyond that, from a :class:`emulator.noise.NoiseModel`, and
``return_excess`` reports where the source was already noisier (derivation in
:func:`emulate`, Notes).
"""

from __future__ import annotations

import numpy as np

from emulator.errors import EmulationError
from emulator.core.lut import apply_lut, check_exposure, check_raw  # re-exported: the DN lookups live in emulator.core.lut
from emulator.core.response import CameraResponse
from emulator.noise.model import NoiseModel
from emulator.noise.tables import check_rng, consistent_noise, excess_map

__all__ = [
    "emulate",
    "emulation_lut",
    "apply_lut",
    "validity_mask",
    "check_exposure",
    "check_raw",
    "NOISE_MODES",
    "UPWARD_RATIO_FLAG",
    "check_noise_model",
]

#: Noise options of :func:`emulate`.
NOISE_MODES = ("none", "consistent")

#: Upward ratios above this are flagged in a run's report: at k = 8 one source DN becomes an 8 DN
#: step (error about k/2 = 4 DN) and the shot noise is sqrt(8) = 2.8 times a capture's at the target;
#: a complete sweep of brackets a factor 2 apart never needs more than 2 (docs/commands.md, Reports).
UPWARD_RATIO_FLAG = 8.0


def emulation_lut(response: CameraResponse, source_ms: float, target_ms: float) -> tuple[np.ndarray, np.ndarray]:
    """The cached (uint16 table, bool validity table) for one source -> target ratio."""
    source_ms = check_exposure(source_ms, "source_ms")
    target_ms = check_exposure(target_ms, "target_ms")
    return response.lut(target_ms / source_ms)


def emulate(
    raw: np.ndarray,
    source_ms: float,
    target_ms: float,
    response: CameraResponse,
    *,
    return_mask: bool = False,
    noise: str = "none",
    noise_model=None,
    rng=None,
    return_excess: bool = False,
):
    """Emulate the image the camera would have captured at ``target_ms``.

    Parameters
    ----------
    raw : ndarray, shape (H, W), uint16
        Source image (Bayer mosaic, DN in ``0..response.white_level``) captured at ``source_ms``.
    source_ms, target_ms : float
        Exposure times in milliseconds, finite and positive.
    response : CameraResponse
        The camera's response; its black and white levels bound the output.
    return_mask : bool
        Also return the validity mask (bool, shape (H, W)).
    noise : {"none", "consistent"}
        ``"none"`` (default): exact eq. 2 through the per-ratio table; the result carries
        the source's noise scaled by the ratio.  ``"consistent"``: where the source is
        cleaner than a capture at the target (darkening), add the missing temporal noise so
        that the result has the noise variance of a live capture at ``target_ms``; where it
        is noisier (brightening) nothing can be removed, and ``return_excess`` says by how
        much (Notes).
    noise_model : emulator.noise.NoiseModel or None
        Conversion gain and read noise of the camera (from ``synth.noise_model.noise_model_of``
        or :func:`emulator.noise.estimate_noise_model`, or :func:`emulator.noise.read_noise_model`);
        its response must be ``response``.
        Required for ``noise="consistent"`` and for ``return_excess``.
    rng : numpy.random.Generator, numpy.random.SeedSequence or int
        Source of the added noise (required for ``noise="consistent"``; not used otherwise).
        The same inputs and seed give the same bytes; a Generator advances by
        ``ceil(H * W / 4)`` raw draws when noise is added, by none otherwise.
    return_excess : bool
        Also return the per-pixel noise variance ratio (float32, shape (H, W)): the
        variance of the returned image over that of a live capture at ``target_ms``,
        from the noise model.  1 means consistent; > 1 is excess noise the emulation
        cannot remove (brightening); < 1 (``noise="none"`` only) a too clean image.
        Meaningful where the validity mask is True.

    Returns
    -------
    ndarray, shape (H, W), uint16
        Emulated DN, rounded to nearest, clipped to ``[black_level, white_level]``.
    ndarray of bool, optional
        True where the source pixel carried the information the target needs (``return_mask``).
    ndarray of float32, optional
        The variance ratio (``return_excess``), after the mask when both are asked for.

    Raises
    ------
    EmulationError
        Bad exposures or image; an unknown ``noise``; ``noise="consistent"`` or
        ``return_excess`` without a :class:`~emulator.noise.NoiseModel`, with a model of
        another response, or without ``rng``.

    Notes
    -----
    *Noise of an emulated image.*  Let ``G`` be the conversion gain (electrons per unit of
    h = g(DN)), ``r`` the read noise (electrons), ``k = target_ms / source_ms`` and
    ``e_s`` the source pixel's mean electrons (vignetting and pixel sensitivity included:
    they scale e_s in both captures alike and drop out of everything below).  A source
    pixel holds ``e_s + n_s`` electrons with ``var(n_s) = e_s + r^2`` (shot + read), then
    quantisation to one DN, which spans ``G g'(d)`` electrons and adds
    ``Q_s = (G g'(d_s))^2 / 12`` (Sheppard's correction; a noise of a DN or more dithers
    it).  Emulation multiplies the linear exposure by k, so in electrons at the target

    ``var_emulated = k^2 (e_s + r^2 + Q_s) + Q_t``,

    where ``Q_t = (G g'(d_t))^2 / 12`` is the rounding of the output to a DN at the target
    DN ``d_t = f(k g(d_s))``.  A live capture at the target collects ``k e_s`` electrons:

    ``var_live = k e_s + r^2 + Q_t``.

    (For k = 1 the emulated image is the capture: both are ``var_live``.)  Darkening
    (k < 1) gives ``var_emulated < var_live`` (shot noise shrinks by k^2 instead of k,
    read noise by k^2 instead of not at all); brightening the reverse.

    *Consistent emulation.*  With ``e_s`` estimated from the observed DN,
    ``e_hat = G g(d_s)``, the emulator adds ``V_add = var_live - var_emulated`` evaluated
    at ``e_hat``, as Gaussian noise in the linear domain, then maps through the response
    and quantises and clips as the camera does:

    ``DN = clip(floor(f(k g(d_s) + sqrt(V_add) / G * z) + 1/2), black, white)``, z ~ N(0, 1).

    Because ``V_add = (k - k^2) e_hat + (1 - k^2) r^2 - k^2 Q_s`` is linear in ``e_hat``
    and ``E[e_hat] = e_s``, the law of total variance gives for the result (before the
    final rounding) ``k^2 var(e_hat) + E[V_add] = k^2 (e_s + r^2 + Q_s) + V_add(e_s)
    = k e_s + r^2``: exactly a live capture's variance, in electrons, although V_add is
    computed from a noisy estimate; the rounding then adds the live capture's own Q_t.
    Where ``V_add <= 0`` (brightening, or a source quantisation coarser than the target
    noise) the plain emulated DN is returned unchanged and ``return_excess`` gives
    ``var_emulated / var_live`` there.  Only the variance is matched, not the shape of
    the distribution (a Gaussian increment instead of a Poisson one), and the noise of the
    source and the noise added are independent between pixels, as a capture's is.  All
    terms depend on the source DN alone, so they are tables over DN built once per ratio
    (:meth:`emulator.noise.NoiseModel.tables`); per pixel the cost is two table gathers,
    one normal draw and the exact quantiser (:func:`emulator.noise.quantise`).
    """
    if noise not in NOISE_MODES:
        raise EmulationError(f"noise must be one of {', '.join(map(repr, NOISE_MODES))}, got {noise!r}")
    if not isinstance(response, CameraResponse):
        raise EmulationError(f"response must be a CameraResponse, got {type(response).__name__}")
    table, _ = emulation_lut(response, source_ms, target_ms)
    raw = check_raw(raw, response.white_level)
    out = apply_lut(table, raw)
    if noise == "none" and not return_excess:
        if not return_mask:
            return out
        return out, validity_mask(raw, target_ms / source_ms, response)
    ratio = float(target_ms) / float(source_ms)
    model = check_noise_model(noise_model, response, noise, return_excess)
    if noise == "consistent":
        out = consistent_noise(raw, out, ratio, model, check_rng(rng))
    results = [out]
    if return_mask:
        results.append(validity_mask(raw, ratio, response))
    if return_excess:
        results.append(excess_map(raw, ratio, model, consistent=noise == "consistent"))
    return tuple(results) if len(results) > 1 else results[0]


def check_noise_model(noise_model, response: CameraResponse, noise: str, return_excess: bool):
    """``noise_model`` if it is a NoiseModel of ``response``, else an EmulationError naming what is wrong."""
    why = f'noise="{noise}"' if noise != "none" else "return_excess"
    if noise_model is None:
        raise EmulationError(
            f"{why} needs a noise_model (emulator.noise.NoiseModel: from synth.noise_model.noise_model_of(camera) "
            "or emulator.noise.estimate_noise_model on the recording's bracket groups)"
        )
    if not isinstance(noise_model, NoiseModel):
        raise EmulationError(f"noise_model must be an emulator.noise.NoiseModel, got {type(noise_model).__name__}")
    if not noise_model.matches(response):
        raise EmulationError(
            f"noise_model {noise_model.name!r} refers to response {noise_model.response.name!r} "
            f"(levels {noise_model.black_level}..{noise_model.white_level}), not to the response given "
            f"({response.name!r}, levels {response.black_level}..{response.white_level})"
        )
    return noise_model


def validity_mask(raw: np.ndarray, ratio: float, response: CameraResponse) -> np.ndarray:
    """True where the source pixel carries what the target needs (see the module notes).

    Equal to ``response.lut(ratio)[1][raw]``, computed with one comparison: brightening
    keeps saturated pixels valid, so only black ones are invalid; darkening the reverse.
    """
    if ratio == 1.0:
        return np.ones(raw.shape, dtype=bool)
    if ratio > 1.0:
        return raw > response.black_level
    return raw < response.white_level
