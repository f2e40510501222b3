"""Helpers shared by the export targets: model inspection, errors, frames."""

from __future__ import annotations

import numpy as np

from ..errors import ExportError

__all__ = ["label", "fail", "principal_axes", "microfacet_parts", "is_elliptical", "LUMA"]

#: Rec. 709 / linear-sRGB luminance weights (used for RGL ``luminance`` and reports)
LUMA = np.array([0.2126, 0.7152, 0.0722])


def label(model) -> str:
    """``ClassName 'name'`` of a model, for messages."""
    return f"{type(model).__name__} {getattr(model, 'name', '')!r}"


def fail(model, target: str, need: str):
    """Raise the :class:`ExportError` of a model that cannot go to ``target``."""
    raise ExportError(f"cannot export {label(model)} to {target}: {need}")


def microfacet_parts(model):
    """``(distribution, fresnel, diffuse, specular, correlated)`` of a MicrofacetBRDF, else None."""
    from ..microfacet.model import MicrofacetBRDF

    if not isinstance(model, MicrofacetBRDF):
        return None
    return model.distribution, model.fresnel, model.diffuse, model.specular, model.correlated


def is_elliptical(dist, kinds=("ggx", "beckmann")) -> bool:
    """True for a GGX/Beckmann :class:`EllipticalSlopeDistribution` (kind in ``kinds``)."""
    from ..microfacet.shadowing import EllipticalSlopeDistribution

    return isinstance(dist, EllipticalSlopeDistribution) and getattr(dist, "kind", "") in kinds


def principal_axes(alpha_x: float, alpha_y: float, rho: float) -> tuple[float, float, float]:
    """Principal roughnesses and frame rotation of the slope scale matrix (Dupuy 2015 App. C).

    ``S = [[αx², ραxαy], [ραxαy, αy²]] = R(φ) diag(αu², αv²) R(φ)ᵀ``: an elliptical
    distribution with correlation ρ is the axis-aligned one (ρ = 0, roughnesses αu, αv) in the
    tangent frame rotated by φ about the normal (counter-clockwise, radians). Returns
    ``(αu, αv, φ)`` with φ in (−π/2, π/2]; ``φ = 0`` and ``(αx, αy)`` when ρ = 0.
    """
    if rho == 0.0:
        return float(alpha_x), float(alpha_y), 0.0
    S = np.array([[alpha_x**2, rho * alpha_x * alpha_y], [rho * alpha_x * alpha_y, alpha_y**2]])
    evals, evecs = np.linalg.eigh(S)
    # choose the eigenvector closest to the x axis as the new u axis
    k = int(np.argmax(np.abs(evecs[0])))
    u = evecs[:, k] * (1.0 if evecs[0, k] >= 0 else -1.0)
    phi = float(np.arctan2(u[1], u[0]))
    return float(np.sqrt(evals[k])), float(np.sqrt(evals[1 - k])), phi


def rotate_z(w, phi: float) -> np.ndarray:
    """Directions ``w`` (..., 3) expressed in the frame rotated by ``phi`` about +z."""
    c, s = np.cos(phi), np.sin(phi)
    w = np.asarray(w, dtype=np.float64)
    return np.stack([c * w[..., 0] + s * w[..., 1], -s * w[..., 0] + c * w[..., 1], w[..., 2]], -1)
