"""Abstract building blocks of microfacet BRDFs (Dupuy et al. 2015, §2).

:class:`SlopeDistribution` follows ``scipy.stats`` habits: ``pdf`` of slopes, ``sample``,
moments, plus the microfacet quantities derived from it: the NDF ``D`` (Eq. 7), the projected
area ``sigma`` and Smith ``G1`` (Eq. 3), Smith ``Lambda``, and visible-normal sampling.
Concrete distributions (Beckmann, GGX, SGD, tabulated fits) override what they have in closed
form; the generic fall-backs here are numerical.

:class:`ScaledDistribution` is the roughness scaling of any distribution (Eq. 9), the
generic :meth:`SlopeDistribution.scaled`.

:class:`Fresnel` maps ``cos θd`` to an RGB reflectance ``(..., 3)``.
"""

from __future__ import annotations

import abc

import numpy as np

from ..geometry import normal_to_slope, normalize, slope_to_normal

__all__ = ["SlopeDistribution", "ScaledDistribution", "Fresnel"]


def _check_float(name: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a real number, got {value!r}") from None
    if not np.isfinite(v):
        raise ValueError(f"{name} must be finite, got {v}")
    return v


class SlopeDistribution(abc.ABC):
    """A bivariate microfacet slope PDF ``P(x̃, ỹ)`` and everything derived from it.

    Roughness follows Dupuy 2015 Eq. 9: ``D(h; αx, αy) = P(x̃/αx, ỹ/αy) sec⁴θh / (αx αy)``.
    Subclasses must implement :meth:`pdf` and :meth:`sample`; they should override
    :meth:`sigma` (or :meth:`Lambda`) and :meth:`sample_visible` with exact forms when known.
    """

    isotropic: bool = True

    # -- slope space -------------------------------------------------------------------------
    @abc.abstractmethod
    def pdf(self, slopes) -> np.ndarray:
        """Slope PDF ``P22(x̃, ỹ)`` at slopes ``(..., 2)`` (integrates to 1 over R²)."""

    @abc.abstractmethod
    def sample(self, u) -> np.ndarray:
        """Slopes ``(..., 2)`` distributed with :meth:`pdf`, from uniform ``u`` ``(..., 2)``."""

    # -- figures -----------------------------------------------------------------------------
    def figures(self) -> dict:
        """The roughness users look for: ``{"alpha": [αx, αy, ρ], "alpha_kind": kind}``, the
        slope scales and correlation (Walter 2007 / Dupuy 2015 α, not "roughness"; glTF's is
        √α for GGX); ``{}`` for a distribution without them."""
        kind = getattr(self, "kind", None) or type(self).__name__.lower()
        if hasattr(self, "alpha_x"):
            return {"alpha": [float(self.alpha_x), float(getattr(self, "alpha_y", self.alpha_x)),
                              float(getattr(self, "rho", 0.0) or 0.0)], "alpha_kind": kind}
        alpha = getattr(self, "alpha", None)
        if alpha is not None and np.isscalar(alpha):
            return {"alpha": [float(alpha), float(alpha), 0.0], "alpha_kind": kind}
        return {}

    # -- hemisphere --------------------------------------------------------------------------
    def D(self, m) -> np.ndarray:
        """Normal distribution ``D(m) = P(m̃) / cos⁴θm`` (Eq. 7); 0 for ``m_z <= 0``."""
        m = np.asarray(m, dtype=np.float64)
        mz = m[..., 2]
        safe = np.where(mz > 0, mz, 1.0)
        slopes = normal_to_slope(np.where((mz > 0)[..., None], m, [0.0, 0.0, 1.0]))
        return np.where(mz > 0, self.pdf(slopes) / safe**4, 0.0)

    def Lambda(self, w) -> np.ndarray:
        """Smith Λ(w) with ``G1 = 1/(1 + Λ)`` (Heitz 2014); default from :meth:`sigma`."""
        w = np.asarray(w, dtype=np.float64)
        cz = w[..., 2]
        return np.where(cz > 0, self.sigma(w) / np.where(cz > 0, cz, 1.0) - 1.0, np.inf)

    def sigma(self, w) -> np.ndarray:
        """Projected area ``σ(w) = ∫ <w, m>₊ D(m) dm`` (denominator of Eq. 3)."""
        w = np.asarray(w, dtype=np.float64)
        return np.maximum(w[..., 2], 0.0) * (1.0 + self.Lambda(w))

    def G1(self, w, m=None) -> np.ndarray:
        """Smith monostatic shadowing ``cos θ / σ(w)`` (Eq. 3), times ``χ⁺(w·m)`` if ``m``."""
        w = np.asarray(w, dtype=np.float64)
        lam = self.Lambda(w)
        g = np.where(w[..., 2] > 0, 1.0 / (1.0 + lam), 0.0)
        if m is not None:
            g = np.where(np.sum(w * np.asarray(m), axis=-1) > 0, g, 0.0)
        return g

    def G2(self, wi, wo, m=None) -> np.ndarray:
        """Height-correlated Smith shadowing-masking (Dupuy 2015 Eq. 2).

        ``G1(i) G1(o) / (G1(i) + G1(o) − G1(i) G1(o)) = 1 / (1 + Λ(i) + Λ(o))``.
        """
        wi = np.asarray(wi, dtype=np.float64)
        wo = np.asarray(wo, dtype=np.float64)
        ok = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        with np.errstate(invalid="ignore"):
            g = np.where(ok, 1.0 / (1.0 + self.Lambda(wi) + self.Lambda(wo)), 0.0)
        if m is not None:
            m = np.asarray(m)
            g = np.where((np.sum(wi * m, -1) > 0) & (np.sum(wo * m, -1) > 0), g, 0.0)
        return g

    def pdf_visible(self, w, m) -> np.ndarray:
        """Density of visible normals ``<w, m>₊ D(m) / σ_v(w)`` (Heitz & d'Eon 2014; with
        ``σ_v = σ`` this is ``G1(w) <w, m>₊ D(m) / cos θw``): the density of
        :meth:`sample_visible`, normalised by :meth:`sigma_visible`."""
        w = np.asarray(w, dtype=np.float64)
        m = np.asarray(m, dtype=np.float64)
        wm = np.maximum(np.sum(w * m, axis=-1), 0.0)
        cz = w[..., 2]
        return np.where(cz > 0, wm * self.D(m) / np.where(cz > 0, self.sigma_visible(w), 1.0),
                        0.0)

    def sigma_visible(self, w) -> np.ndarray:
        """Normaliser ``∫ <w, m>₊ D(m) dm`` of the density :meth:`sample_visible` draws from.

        Equal to :meth:`sigma` when Λ is consistent with D (closed forms); distributions
        whose Λ comes from a separate approximation (tables) override it with the integral
        their sampler actually normalises by, so that :meth:`pdf_visible` is the sampler's
        density (a furnace test sees a few % of bias at grazing angles otherwise)."""
        return self.sigma(w)

    def sample_visible(self, w, u) -> np.ndarray:
        """Normals ``(..., 3)`` distributed with :meth:`pdf_visible` for direction ``w``."""
        raise NotImplementedError(f"{type(self).__name__} has no visible-normal sampling")

    # -- moments -----------------------------------------------------------------------------
    def slope_moments(self) -> dict[str, float]:
        """Slope-space moments used by Dupuy 2015 Appendix C (E|x̃|, E|ỹ|, E x̃², E ỹ², E x̃ỹ)."""
        raise NotImplementedError

    def params(self) -> dict:
        """Parameters as a JSON-serialisable dict (for the fit file and reports)."""
        return {}

    # -- roughness ---------------------------------------------------------------------------
    def scaled(self, ax: float, ay: float | None = None) -> "SlopeDistribution":
        """Roughness scaling of Dupuy 2015 Eq. 9: ``P(x̃/ax, ỹ/ay)/(ax ay)``.

        Generic version: a :class:`ScaledDistribution` wrapper (Λ and visible normals by
        stretch invariance); closed-form families override it.
        """
        return ScaledDistribution(self, ax, ay)


# ----------------------------------------------------------------------------------------
# Roughness scaling of an arbitrary distribution (Dupuy 2015 Eq. 9)
# ----------------------------------------------------------------------------------------
class ScaledDistribution(SlopeDistribution):
    """``P_a(x̃, ỹ) = P(x̃/ax, ỹ/ay)/(ax ay)`` for any base distribution (Dupuy 2015 Eq. 9).

    Smith Λ and visible-normal sampling follow from the base by the stretch invariance of
    Heitz 2014 §5.3: ``Λ_a(w) = Λ(normalize(ax wx, ay wy, wz))``.
    """

    kind = "scaled"

    def __init__(self, base: SlopeDistribution, ax: float, ay: float | None = None):
        ax = _check_float("ax", ax)
        ay = ax if ay is None else _check_float("ay", ay)
        if ax <= 0 or ay <= 0:
            raise ValueError(f"roughness scales must be > 0, got ax={ax}, ay={ay}")
        self.base, self.ax, self.ay = base, ax, ay
        self.isotropic = bool(base.isotropic and ax == ay)
        self._a = np.array([ax, ay])

    def params(self) -> dict:
        return {"ax": self.ax, "ay": self.ay, "base": type(self.base).__name__,
                "base_params": self.base.params()}

    def pdf(self, slopes) -> np.ndarray:
        s = np.asarray(slopes, dtype=np.float64)
        return self.base.pdf(s / self._a) / (self.ax * self.ay)

    def sample(self, u) -> np.ndarray:
        return np.asarray(self.base.sample(u)) * self._a

    def _stretch(self, w):
        w = np.asarray(w, dtype=np.float64)
        return normalize(np.concatenate([w[..., :2] * self._a, w[..., 2:3]], -1))

    def Lambda(self, w) -> np.ndarray:
        w = np.asarray(w, dtype=np.float64)
        return np.where(w[..., 2] > 0, self.base.Lambda(self._stretch(w)), np.inf)

    def sigma(self, w) -> np.ndarray:
        """``σ = cos θ (1 + Λ)`` above the horizon (0 below: only used for w_z > 0)."""
        w = np.asarray(w, dtype=np.float64)
        up = w[..., 2] > 0
        return np.where(up, np.where(up, w[..., 2], 0.0) * (1.0 + np.where(up, self.Lambda(w), 0.0)), 0.0)

    def sigma_visible(self, w) -> np.ndarray:
        """``cos θw · σ_v,base(w*)/cos θw*`` (stretch invariance, as :meth:`Lambda`), the
        normaliser of :meth:`sample_visible`."""
        w = np.asarray(w, dtype=np.float64)
        up = w[..., 2] > 0
        ws = self._stretch(w)
        cs = np.where(ws[..., 2] > 0, ws[..., 2], 1.0)
        return np.where(up, np.where(up, w[..., 2], 0.0) * self.base.sigma_visible(ws) / cs, 0.0)

    def sample_visible(self, w, u) -> np.ndarray:
        m0 = self.base.sample_visible(self._stretch(w), u)
        return slope_to_normal(normal_to_slope(m0) * self._a)

    def scaled(self, ax: float, ay: float | None = None):
        ay = ax if ay is None else ay
        return ScaledDistribution(self.base, self.ax * ax, self.ay * ay)


class Fresnel(abc.ABC):
    """A Fresnel reflectance as a function of ``cos θd`` returning RGB ``(..., 3)``."""

    @abc.abstractmethod
    def eval(self, cos_theta_d) -> np.ndarray:
        """Reflectance at ``cos θd`` (broadcast shape + ``(3,)``)."""

    def eval_channel(self, c: int, cos_theta_d) -> np.ndarray:
        """Channel ``c`` of :meth:`eval` (the same numbers), shape of ``cos_theta_d``."""
        return self.eval(cos_theta_d)[..., c]

    def __call__(self, cos_theta_d) -> np.ndarray:
        return self.eval(cos_theta_d)

    def params(self) -> dict:
        return {}
