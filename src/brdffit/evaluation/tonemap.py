"""Tone mapping of the NPF paper (Bagher, Snyder, Nowrouzezahrai 2016, §5).

``output = (1 − 2^(−exposure · x))^(1/gamma)`` with ``exposure = 0.02`` and ``gamma = 2.2``
(the paper uses exposure 1, gamma 2.8 for its darker Ennis map). The result is in [0, 1)
and is written to PNG as is (the gamma plays the role of the display encoding).

Exposure and units. The paper's 0.02 matches its renderings, whose linear pixel values are in
the tens to hundreds (MERL units × Debevec light probes with no normalisation). Our renders
are in physical units of the environment maps (radiance of ``../shared/data/envmaps`` has a
mean of about 0.1–1), so that ``x·0.02`` would be nearly black. We therefore keep the paper's
formula and defaults in :func:`tonemap` (``exposure=0.02``) and add :func:`auto_exposure`,
which picks the exposure putting the median foreground value of a *reference* image at the
same point of the curve as the paper's typical pixel (``x·exposure = 1``, i.e. mid-grey
0.5^(1/2.2) ≈ 0.73 before quantisation). Use one exposure per scene (computed on the
reference) for all models so that images stay comparable. Deviation documented here:
``exposure="auto"`` is a brdffit convenience, not part of the paper.

Comparisons (:func:`brdffit.evaluation.compare.compare`) use the paper's *fixed*
operator by default: one exposure per *scene*, independent of the material, as the paper
fixes 0.02 (1 for its dark Ennis map) for all its renderings. Ours is
:func:`brdffit.evaluation.render.scenes.scene_exposure`, ``1 / mean radiance`` of the scene's
environment map (the same normalisation as above: a grey Lambertian of albedo ρ maps to
``x·exposure ≈ ρ``), with γ = 2.2; darker materials therefore look darker, as in the paper.
"""

from __future__ import annotations

import numpy as np

__all__ = ["tonemap", "auto_exposure", "DEFAULT_EXPOSURE", "DEFAULT_GAMMA"]

DEFAULT_EXPOSURE = 0.02
DEFAULT_GAMMA = 2.2


def auto_exposure(img, mask=None, target: float = 1.0) -> float:
    """Exposure that maps the median positive foreground value of ``img`` to ``target``.

    ``img`` ``(H, W, 3[+1])`` linear; ``mask`` ``(H, W)`` boolean (defaults to all pixels).
    Returns :data:`DEFAULT_EXPOSURE` when there is no positive value.
    """
    img = np.asarray(img, dtype=np.float64)[..., :3]
    vals = img.max(axis=-1)
    if mask is not None:
        vals = vals[np.asarray(mask, dtype=bool)]
    vals = vals[np.isfinite(vals) & (vals > 0)]
    if vals.size == 0:
        return DEFAULT_EXPOSURE
    return float(target / np.median(vals))


def tonemap(img, exposure: float | str = DEFAULT_EXPOSURE, gamma: float = DEFAULT_GAMMA,
            mask=None) -> np.ndarray:
    """Bagher 2016 §5 tone mapping ``(1 − 2^(−exposure·x))^(1/gamma)``, float in [0, 1].

    Negative and non-finite inputs map to 0. ``exposure="auto"`` uses
    :func:`auto_exposure` on ``img`` itself (restricted to ``mask`` when given).
    """
    x = np.nan_to_num(np.asarray(img, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    if isinstance(exposure, str):
        if exposure != "auto":
            raise ValueError(f"exposure must be a number or 'auto', got {exposure!r}")
        exposure = auto_exposure(x, mask)
    if not exposure > 0 or not gamma > 0:
        raise ValueError(f"exposure and gamma must be > 0, got {exposure} and {gamma}")
    return (1.0 - np.exp2(-exposure * np.maximum(x, 0.0))) ** (1.0 / gamma)
