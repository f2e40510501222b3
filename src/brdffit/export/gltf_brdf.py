"""The glTF 2.0 metallic-roughness BRDF (the specification's Appendix B, with the
``KHR_materials_specular``, ``_ior``, ``_clearcoat`` and ``_anisotropy`` extensions) as a BRDF
of the library: :class:`GLTFBRDF`, what an engine that follows the specification renders
for an exported material (:mod:`brdffit.export.gltf` maps fits to it, and
:mod:`brdffit.export.gltf_cycles` models Blender's Cycles on top of it). With Numba the
isotropic BRDF is evaluated by a compiled per-sample kernel (``_gltf_kernel``: the NumPy
path's operations in their order, its values to rounding)."""

from __future__ import annotations

import numpy as np

from .._jit import lazy_numba
from ..brdf import (IsotropicBRDF, _as_dirs, _dot3, _run_per_sample, _unit_half,
                    _visible_half_kernel)
from ..microfacet import GGX, MicrofacetBRDF, SchlickFresnel

__all__ = ["GLTFBRDF"]

_numba = lazy_numba()


def _core_dv_kernel(a, nl, nv, nh, il, iv):  # pragma: no cover  (compiled by numba)
    """:meth:`GLTFBRDF._core_dv` of one sample (``il``, ``iv``: L·H > 0, V·H > 0)."""
    a2 = a * a
    D = a2 * (1.0 if nh > 0 else 0.0) / (np.pi * (nh * nh * (a2 - 1.0) + 1.0) ** 2)
    V = ((1.0 if il and iv else 0.0)
         / ((abs(nl) + np.sqrt(a2 + (1.0 - a2) * nl * nl))
            * (abs(nv) + np.sqrt(a2 + (1.0 - a2) * nv * nv))))
    x = D * V
    if np.isnan(x):
        return 0.0
    return min(max(x, -1.7976931348623157e308), 1.7976931348623157e308)


def _gltf_kernel(wi, wo, a, base, metallic, f0_d, f90_d, coat, a_coat,
                 out):  # pragma: no cover  (compiled by numba)
    """:meth:`GLTFBRDF.eval` (isotropic) per sample, its order of operations."""
    for k in range(wi.shape[0]):
        visible, hx, hy, hz = _visible_half_kernel(wi, wo, k, out)
        if not visible:
            continue
        nl, nv = wi[k, 2], wo[k, 2]
        lh = wi[k, 0] * hx + wi[k, 1] * hy + nl * hz
        vh = wo[k, 0] * hx + wo[k, 1] * hy + nv * hz
        dv = _core_dv_kernel(a, nl, nv, hz, lh > 0, vh > 0)
        x5 = (1.0 - abs(vh)) ** 5.0
        fc = dvc = 0.0
        if coat > 0:
            fc = 0.04 + 0.96 * (1.0 - abs(nv)) ** 5.0
            dvc = _core_dv_kernel(a_coat, nl, nv, hz, lh > 0, vh > 0)
        for ch in range(3):
            b = base[ch]
            F_d = f0_d[ch] + (f90_d - f0_d[ch]) * x5
            F_m = b + (1.0 - b) * x5
            f = (1.0 - metallic) * ((1.0 - F_d) * b / np.pi + F_d * dv) + metallic * F_m * dv
            out[k, ch] = f * (1.0 - coat * fc) + coat * fc * dvc if coat > 0 else f


if _numba is not None:
    _core_dv_kernel = _numba.njit(cache=True, nogil=True, inline="always",
                                  error_model="numpy")(_core_dv_kernel)
    _gltf_kernel = _numba.njit(cache=True, nogil=True, error_model="numpy")(_gltf_kernel)


class GLTFBRDF(IsotropicBRDF):
    """The glTF 2.0 metallic-roughness BRDF (specification Appendix B, see module doc).

    Parameters: ``base_color`` (linear RGB), ``metallic`` and ``roughness`` (perceptual,
    α = roughness²) in [0, 1]; ``specular_factor`` (in [0, 1]), ``specular_color`` (RGB ≥ 0)
    of ``KHR_materials_specular`` and ``ior`` (≥ 1) of ``KHR_materials_ior`` (defaults: the
    core spec's 1, white, 1.5); optional ``anisotropy_strength`` s and
    ``anisotropy_rotation`` φ (radians, counter-clockwise from the tangent) of the
    ``KHR_materials_anisotropy`` extension: ``αt = mix(α, 1, s²)`` along ``t = (cos φ,
    sin φ, 0)``, ``αb = α`` along ``b = n × t``, the extension's anisotropic GGX D and its
    (non-normative, height-correlated) ``V = 0.5 / (N·L |(αt T·V, αb B·V, N·V)| + N·V |(αt T·L,
    αb B·L, N·L)|)`` (without the sample code's clamp of V to [0, 1], which cuts grazing
    values). With s = 0 the core Appendix B (separable V) is used.
    """

    def __init__(self, base_color, metallic: float, roughness: float, name: str = "gltf",
                 anisotropy_strength: float = 0.0, anisotropy_rotation: float = 0.0,
                 specular_factor: float = 1.0, specular_color=(1.0, 1.0, 1.0),
                 ior: float = 1.5, clearcoat: float = 0.0, clearcoat_roughness: float = 0.0):
        self.clearcoat = float(clearcoat)
        self.clearcoat_roughness = float(clearcoat_roughness)
        for nm, v in (("clearcoat", self.clearcoat),
                      ("clearcoat_roughness", self.clearcoat_roughness)):
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"GLTFBRDF: {nm} must be in [0, 1], got {v}")
        self.base_color = np.broadcast_to(np.asarray(base_color, float), (3,)).copy()
        self.specular_factor = float(specular_factor)
        self.specular_color = np.broadcast_to(np.asarray(specular_color, float), (3,)).copy()
        self.ior = float(ior)
        if not 0.0 <= self.specular_factor <= 1.0:
            raise ValueError(f"GLTFBRDF: specular_factor must be in [0, 1], got {specular_factor}")
        if not (np.all(np.isfinite(self.specular_color)) and np.all(self.specular_color >= 0)):
            raise ValueError(f"GLTFBRDF: specular_color must be finite and >= 0, got "
                             f"{self.specular_color.tolist()}")
        if not (np.isfinite(self.ior) and self.ior >= 1.0):
            raise ValueError(f"GLTFBRDF: ior must be >= 1, got {ior}")
        self.metallic = float(metallic)
        self.roughness = float(roughness)
        self.anisotropy_strength = float(anisotropy_strength)
        self.anisotropy_rotation = float(anisotropy_rotation)
        for nm, v in (("metallic", self.metallic), ("roughness", self.roughness),
                      ("anisotropy_strength", self.anisotropy_strength)):
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"GLTFBRDF: {nm} must be in [0, 1], got {v}")
        self.isotropic = self.anisotropy_strength == 0.0
        self.name = name
        self.source = None

    @staticmethod
    def _core_dv(a, wi, wo, h):
        """``D · V`` of the core spec's isotropic GGX of α = ``a`` (separable Smith V)."""
        nl, nv, nh = wi[..., 2], wo[..., 2], h[..., 2]
        a2 = a * a
        with np.errstate(divide="ignore", invalid="ignore"):
            D = a2 * (nh > 0) / (np.pi * (nh * nh * (a2 - 1.0) + 1.0) ** 2)
            V = ((_dot3(wi, h) > 0) * (_dot3(wo, h) > 0)
                 / ((np.abs(nl) + np.sqrt(a2 + (1.0 - a2) * nl * nl))
                    * (np.abs(nv) + np.sqrt(a2 + (1.0 - a2) * nv * nv))))
            return np.nan_to_num(D * V)

    def _specular_dv(self, wi, wo, h):
        """``D · V`` of the core spec (isotropic) or of KHR_materials_anisotropy."""
        nl, nv, nh = wi[..., 2], wo[..., 2], h[..., 2]
        a = self.roughness**2
        if self.anisotropy_strength == 0.0:
            return self._core_dv(a, wi, wo, h)
        with np.errstate(divide="ignore", invalid="ignore"):
            s2 = self.anisotropy_strength**2
            at, ab = a * (1.0 - s2) + s2, a
            c, s = np.cos(self.anisotropy_rotation), np.sin(self.anisotropy_rotation)

            def tb(w):
                return c * w[..., 0] + s * w[..., 1], -s * w[..., 0] + c * w[..., 1]

            th, bh = tb(h)
            tv, bv = tb(wo)
            tl, bl = tb(wi)
            a2 = at * ab
            f2 = (ab * th) ** 2 + (at * bh) ** 2 + (a2 * nh) ** 2
            w2 = a2 / f2
            D = a2 * w2 * w2 / np.pi
            ggxv = nl * np.sqrt((at * tv) ** 2 + (ab * bv) ** 2 + nv * nv)
            ggxl = nv * np.sqrt((at * tl) ** 2 + (ab * bl) ** 2 + nl * nl)
            V = 0.5 / (ggxv + ggxl)          # (the sample code's clamp to [0, 1] omitted)
            return np.nan_to_num(D * V)

    def dielectric_f0_f90(self) -> tuple[np.ndarray, float]:
        """``(f0_d, f90_d)`` of the dielectric part (KHR_materials_ior/specular)."""
        f0_ior = ((self.ior - 1.0) / (self.ior + 1.0)) ** 2
        f0 = np.minimum(f0_ior * self.specular_color, 1.0) * self.specular_factor
        return f0, self.specular_factor

    def eval(self, wi, wo) -> np.ndarray:
        """``f_r`` of Appendix B with the extensions: ``(1 − m)((1 − F_d) c/π + F_d D V)
        + m F_m D V`` (L = wi, V = wo; see the module docstring)."""
        wi, wo = _as_dirs(wi, wo)
        if (_numba is not None and self.anisotropy_strength == 0.0
                and _gltf_kernel.worth_compiling(wi[..., 0].size)):
            return self._eval_compiled(wi, wo)
        ok = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        h = _unit_half(wi, wo)
        vh = np.abs(_dot3(wo, h))
        dv = self._specular_dv(wi, wo, h)[..., None]
        x5 = ((1.0 - vh) ** 5)[..., None]
        f0_d, f90_d = self.dielectric_f0_f90()
        F_d = f0_d + (f90_d - f0_d) * x5
        F_m = self.base_color + (1.0 - self.base_color) * x5
        m = self.metallic
        f = (1.0 - m) * ((1.0 - F_d) * self.base_color / np.pi + F_d * dv) + m * F_m * dv
        if self.clearcoat > 0.0:      # KHR_materials_clearcoat: Fresnel of N·V, index 1.5
            fc = (0.04 + 0.96 * (1.0 - np.abs(wo[..., 2])) ** 5)[..., None]
            dvc = self._core_dv(self.clearcoat_roughness**2, wi, wo, h)[..., None]
            f = f * (1.0 - self.clearcoat * fc) + self.clearcoat * fc * dvc
        return np.where(ok[..., None], f, 0.0)

    def _eval_compiled(self, wi, wo) -> np.ndarray:
        """:meth:`eval` (isotropic) by :func:`_gltf_kernel` (the NumPy path's values to
        rounding)."""
        f0_d, f90_d = self.dielectric_f0_f90()
        return _run_per_sample(_gltf_kernel, wi, wo, self.roughness**2, self.base_color,
                               self.metallic, np.asarray(f0_d, float), float(f90_d),
                               self.clearcoat, self.clearcoat_roughness**2)

    def as_microfacet(self):
        """For a pure metal (metallic = 1): the identical ``MicrofacetBRDF`` (GGX α = r²,
        Schlick F0 = baseColor, uncorrelated Smith G), usable by the closed-form renderers."""
        if self.metallic != 1.0 or self.anisotropy_strength != 0.0 or self.clearcoat > 0.0:
            return None
        return MicrofacetBRDF(GGX(max(self.roughness**2, 1e-6)),
                              SchlickFresnel(np.clip(self.base_color, 0, 1)), correlated=False,
                              name=self.name)

    def describe(self) -> dict:
        d = super().describe()
        d.update(base_color=self.base_color.tolist(), metallic=self.metallic,
                 roughness=self.roughness, anisotropy_strength=self.anisotropy_strength,
                 anisotropy_rotation=self.anisotropy_rotation,
                 specular_factor=self.specular_factor,
                 specular_color=self.specular_color.tolist(), ior=self.ior,
                 clearcoat=self.clearcoat, clearcoat_roughness=self.clearcoat_roughness)
        return d
