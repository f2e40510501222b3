"""The one BRDF protocol every measured table, analytic model and fitted model follows.

Conventions (the same everywhere in brdffit):

* Directions are unit vectors ``(..., 3)`` in the local shading frame, normal = +z, both
  ``wi`` (towards the light) and ``wo`` (towards the viewer) pointing *away* from the surface.
* :meth:`BRDF.eval` returns the BRDF value f_r in 1/sr, **not** multiplied by the cosine,
  as RGB ``(..., 3)`` (linear, the colour space of the source data), and 0 when either
  direction is at or below the horizon.
* :meth:`BRDF.measured` says where the values are measurements: fits weight only those
  direction pairs and errors are computed only over them (:attr:`BRDF.measured_domain` says
  it in words; ``None`` means everywhere above the horizon).
* :meth:`BRDF.sample` draws ``wo`` for a given ``wi`` from 2D uniform numbers and returns the
  direction with its solid-angle density; :meth:`BRDF.pdf` returns that density. The base
  class samples the cosine-weighted hemisphere, which is valid (if not efficient) for every
  BRDF; models with better strategies override both.
"""

from __future__ import annotations

import abc
from typing import Any

import numpy as np

from ._jit import lazy_numba
from .geometry import half_diff_to_io, io_to_half_diff

__all__ = ["BRDF", "IsotropicBRDF", "cosine_hemisphere_sample", "cosine_hemisphere_pdf",
           "cosine_pairs", "jittered_grid", "stratified_square", "measured_mask",
           "sample_arguments", "eval_hd_through_directions", "hd_through_directions"]

_numba = lazy_numba()


def _as_dirs(wi, wo) -> tuple[np.ndarray, np.ndarray]:
    wi = np.asarray(wi, dtype=np.float64)
    wo = np.asarray(wo, dtype=np.float64)
    if wi.shape[-1:] != (3,) or wo.shape[-1:] != (3,):
        raise ValueError(f"directions must have a last axis of size 3, got {wi.shape} and {wo.shape}")
    return np.broadcast_arrays(wi, wo)


def _dot3(a, b) -> np.ndarray:
    """``a·b`` over the last axis (size 3), summed left to right: the bits of
    ``np.sum(a * b, -1)`` without numpy's slow reduction over a short axis."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def _unit_half(wi, wo) -> np.ndarray:
    """The half vector ``(wi + wo) / max(|wi + wo|, 1e-300)`` (the norm as
    ``np.linalg.norm``'s, bit for bit)."""
    h = wi + wo
    return h / np.maximum(np.sqrt(_dot3(h, h)), 1e-300)[..., None]


def _visible_half_kernel(wi, wo, k, out):  # pragma: no cover  (compiled by numba)
    """``(True, unit half vector)`` of sample ``k`` (:func:`_unit_half`'s
    order) when both directions are above the surface; else ``False`` and the sample's
    ``out`` zeroed."""
    if not (wi[k, 2] > 0 and wo[k, 2] > 0):
        out[k, 0] = out[k, 1] = out[k, 2] = 0.0
        return False, 0.0, 0.0, 0.0
    hx, hy, hz = wi[k, 0] + wo[k, 0], wi[k, 1] + wo[k, 1], wi[k, 2] + wo[k, 2]
    hn = max(np.sqrt(hx * hx + hy * hy + hz * hz), 1e-300)
    return True, hx / hn, hy / hn, hz / hn


if _numba is not None:
    _visible_half_kernel = _numba.njit(cache=True, nogil=True, inline="always",
                                       error_model="numpy")(_visible_half_kernel)


def _run_per_sample(kernel, wi, wo, *args) -> np.ndarray:
    """``kernel(wi, wo, *args, out)`` on the directions ``(..., 3)`` as contiguous ``(n, 3)``
    rows (a compiled per-sample kernel); its ``out`` as ``(..., 3)``."""
    shape = wi.shape[:-1]
    wi, wo = (np.ascontiguousarray(w).reshape(-1, 3) for w in (wi, wo))
    out = np.empty(wi.shape)
    kernel(wi, wo, *args, out)
    return out.reshape(shape + (3,))


def sample_arguments(wi, u) -> tuple[np.ndarray, np.ndarray]:
    """``(wi, u)`` of a ``sample(wi, u)`` call as float64, broadcast against each other
    (``wi`` ``(..., 3)``, ``u`` ``(..., 2)``; read-only views)."""
    wi = np.asarray(wi, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    shape = np.broadcast_shapes(wi.shape, u.shape[:-1] + (3,))
    return np.broadcast_to(wi, shape), np.broadcast_to(u, shape[:-1] + (2,))


def cosine_hemisphere_sample(u) -> np.ndarray:
    """Cosine-weighted directions on the upper hemisphere from uniform ``u`` ``(..., 2)``."""
    u = np.asarray(u, dtype=np.float64)
    r = np.sqrt(u[..., 0])
    phi = 2.0 * np.pi * u[..., 1]
    z = np.sqrt(np.maximum(0.0, 1.0 - u[..., 0]))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def jittered_grid(rng, side: int, dim: int = 2) -> np.ndarray:
    """``side**dim`` points of ``[0, 1)^dim``, one uniform point (from ``rng``) per cell of a
    regular grid, cells in row-major order: ``(side**dim, dim)``."""
    cells = np.stack(np.meshgrid(*([np.arange(side)] * dim), indexing="ij"), -1)
    cells = cells.reshape(-1, dim)
    return (cells + rng.random(cells.shape)) / side


def stratified_square(n: int, seed: int = 0) -> np.ndarray:
    """``⌊√n⌋²`` jittered points of the unit square (:func:`jittered_grid` with
    ``numpy.random.default_rng(seed)``), ``(m, 2)``."""
    return jittered_grid(np.random.default_rng(seed), int(np.sqrt(n)))


def cosine_pairs(n: int, start: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """``n`` direction pairs ``(wi, wo)``, each cosine-distributed, from the 4-D Kronecker
    (R4) sequence of the generalised golden ratio ``g`` (``g**5 = g + 1``): deterministic and
    low-discrepancy, NumPy only (SciPy's Sobol generator costs ~0.3 s to import). ``start``
    is the sequence's offset in [0, 1): two offsets give two different pair sets (one to fit
    on, one to measure the error on)."""
    g = 1.1673039782614187
    alpha = 1.0 / g ** np.arange(1, 5)
    u = (start + np.arange(1, n + 1)[:, None] * alpha[None, :]) % 1.0
    u = np.clip(u, 1e-12, 1 - 1e-12)
    return cosine_hemisphere_sample(u[:, :2]), cosine_hemisphere_sample(u[:, 2:])


def cosine_hemisphere_pdf(wo) -> np.ndarray:
    """Solid-angle density ``max(cos θo, 0)/π`` of :func:`cosine_hemisphere_sample`."""
    return np.maximum(np.asarray(wo)[..., 2], 0.0) / np.pi


def measured_mask(brdf, wi, wo) -> np.ndarray | None:
    """``brdf.measured(wi, wo)`` when ``brdf`` has a restricted measured domain, else ``None``
    (every pair is data: callers skip the mask). Works on any object with ``eval``."""
    if getattr(brdf, "measured_domain", None) is None or not hasattr(brdf, "measured"):
        return None
    return np.asarray(brdf.measured(wi, wo), dtype=bool)


class BRDF(abc.ABC):
    """Abstract BRDF: subclasses implement :meth:`eval` (and optionally ``sample``/``pdf``).

    Attributes
    ----------
    name: str
        Human-readable material name.
    isotropic: bool
        True when the BRDF is invariant under rotation about the normal.
    source: str or None
        Where the data came from (file path, ``collection.zip:material``, ``synthetic:...``).
    """

    name: str = "brdf"
    isotropic: bool = False
    source: str | None = None
    #: The measured domain in words when it is smaller than the upper hemispheres (e.g.
    #: "θi ≤ 78.5°"); ``None`` when every pair above the horizon is data.
    measured_domain: str | None = None

    @abc.abstractmethod
    def eval(self, wi, wo) -> np.ndarray:
        """BRDF value f_r(wi, wo), shape ``broadcast(wi, wo).shape[:-1] + (3,)``."""

    def measured(self, wi, wo) -> np.ndarray:
        """True where ``f_r(wi, wo)`` is data rather than an extrapolation beyond what was
        measured, shape ``broadcast(wi, wo).shape[:-1]``. The base class: both directions
        above the horizon."""
        wi, wo = _as_dirs(wi, wo)
        return (wi[..., 2] > 0) & (wo[..., 2] > 0)

    def sample(self, wi, u) -> tuple[np.ndarray, np.ndarray]:
        """Draw ``wo`` given ``wi`` from uniform numbers ``u`` ``(..., 2)``.

        Returns ``(wo, pdf)`` where ``pdf`` is the solid-angle density of ``wo``. The default
        is cosine-weighted hemisphere sampling.
        """
        wo = cosine_hemisphere_sample(u)
        wo = np.broadcast_to(wo, np.broadcast_shapes(np.shape(wi), wo.shape)).copy()
        return wo, self.pdf(wi, wo)

    def pdf(self, wi, wo) -> np.ndarray:
        """Solid-angle density of :meth:`sample` at ``wo`` given ``wi``."""
        wi, wo = _as_dirs(wi, wo)
        return np.where(wi[..., 2] > 0, cosine_hemisphere_pdf(wo), 0.0)

    def eval_cos(self, wi, wo) -> np.ndarray:
        """``f_r(wi, wo) · max(cos θo, 0)`` (the integrand of the reflectance)."""
        wi, wo = _as_dirs(wi, wo)
        return self.eval(wi, wo) * np.maximum(wo[..., 2], 0.0)[..., None]

    def albedo(self, theta_i, n_samples: int = 65536, seed: int = 0) -> np.ndarray:
        """Directional albedo ∫ f_r cos θo dωo for incidence angles ``theta_i`` (radians).

        Monte Carlo with stratified cosine-weighted samples; returns ``(len(theta_i), 3)``.
        """
        theta_i = np.atleast_1d(np.asarray(theta_i, dtype=np.float64))
        wo = cosine_hemisphere_sample(stratified_square(n_samples, seed))
        out = np.empty((theta_i.size, 3))
        for k, t in enumerate(theta_i):
            wi = np.array([np.sin(t), 0.0, np.cos(t)])
            out[k] = np.pi * self.eval(np.broadcast_to(wi, wo.shape), wo).mean(axis=0)
        return out

    def describe(self) -> dict[str, Any]:
        """Metadata as a plain dict (name, class, isotropy, source)."""
        return {"name": self.name, "model": type(self).__name__,
                "isotropic": bool(self.isotropic), "source": self.source}

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name!r} isotropic={self.isotropic}>"


class IsotropicBRDF(BRDF):
    """An isotropic BRDF, also evaluable in Rusinkiewicz coordinates.

    Subclasses override :meth:`eval_hd` or :meth:`eval` (at least one); the other is derived.
    """

    isotropic = True

    def eval(self, wi, wo) -> np.ndarray:
        if type(self).eval_hd is IsotropicBRDF.eval_hd:
            raise NotImplementedError(f"{type(self).__name__} must override eval or eval_hd")
        wi, wo = _as_dirs(wi, wo)
        th, _, td, pd = io_to_half_diff(wi, wo)
        f = self.eval_hd(th, td, pd)
        above = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        return np.where(above[..., None], f, 0.0)

    def measured_hd(self, theta_h, theta_d, phi_d) -> np.ndarray:
        """:meth:`measured` at Rusinkiewicz coordinates (φh = 0)."""
        wi, wo = half_diff_to_io(theta_h, 0.0, theta_d, phi_d)
        return self.measured(wi, wo)

    def eval_hd(self, theta_h, theta_d, phi_d) -> np.ndarray:
        """BRDF value at Rusinkiewicz coordinates (φh irrelevant by isotropy), ``(..., 3)``."""
        if type(self).eval is IsotropicBRDF.eval:
            raise NotImplementedError(f"{type(self).__name__} must override eval or eval_hd")
        return eval_hd_through_directions(self, theta_h, theta_d, phi_d)


def eval_hd_through_directions(brdf, theta_h, theta_d, phi_d) -> np.ndarray:
    """``brdf.eval`` at the directions of Rusinkiewicz coordinates with φh = 0, ``(..., 3)``:
    the ``eval_hd`` of BRDFs without a form of their own in those coordinates."""
    wi, wo = half_diff_to_io(theta_h, 0.0, theta_d, phi_d)
    return brdf.eval(wi, wo)


def hd_through_directions(brdf) -> bool:
    """Whether ``brdf.eval_hd`` is :func:`eval_hd_through_directions`: a caller evaluating
    several such BRDFs at the same angles may convert the angles to directions once and call
    ``eval`` (the same values)."""
    return getattr(type(brdf), "eval_hd", None) in (eval_hd_through_directions,
                                                    IsotropicBRDF.eval_hd)
