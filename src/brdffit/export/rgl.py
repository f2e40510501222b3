"""RGL-style ``.bsdf`` tensor file of an isotropic microfacet fit (Dupuy & Jakob 2018 layout).

Fields written (what :func:`brdffit.io.rgl.read_rgl` and Mitsuba 3's ``measured`` plugin
read; see :mod:`brdffit.io.rgl` for their meaning):

``ndf`` (2, K), ``sigma`` (2, K)
    The model's NDF D(θm) and projected area σ(θ) (Dupuy 2015 Eq. 3) on K nodes uniform in
    ``u = √(2θ/π)`` (two equal φ rows: isotropic). With a Lambertian term the stored D is
    the mixture ``(1 − w) D + w/π`` (σ likewise, ``σ_uniform = (1 + cos θ)/2``), ``w`` = the
    diffuse share of the albedo at normal incidence clipped to [0.05, 0.95]: the warps then
    cover the directions the diffuse term needs (deliberate deviation; the BRDF value is
    unchanged since rgb is divided by the stored D).
``theta_i`` (Nθ,), ``phi_i`` (1,)
    Incident (Mitsuba ``si.wi``, the viewer) elevations uniform in u, one azimuth (isotropic).
``vndf`` (1, Nθ, H, W)
    Visible normal density per θi in the (u_θm, u_φm) square, φm relative to φi:
    ``D(m) <wi, m>₊ · sin θm · π u_θ · 2π`` (the Jacobian of Mitsuba's parameterisation;
    slices are normalised by the reader).
``rgb`` (1, Nθ, 3, n, n), ``luminance`` (1, Nθ, n, n), ``jacobian`` = 1
    At the n × n sample-space points s, ``m = warp_vndf(s)``, ``wo = reflect(wi, m)``, the
    stored value is ``f_r(wo, wi) cos θo / (D(m) / (4 σ(wi)))`` with the file's own
    interpolated D and σ, so that ``Measured::eval`` returns ``f_r cos θo`` at the sample
    points; luminance = Rec. 709 Y of rgb (clamped ≥ 0, plus a tiny floor so every slice has
    a positive integral), used for importance sampling.

Every isotropic model maps. An isotropic :class:`~brdffit.microfacet.model.MicrofacetBRDF`
(tabulated fits in particular, also GGX/Beckmann/SGD) stores its own NDF and σ; other models
(per-channel SGD, NPF factors) store the NDF of their tabulated fit as the warp
(:func:`_proxy_warp`). Anisotropic models would need φi slices (not implemented). The resampling error is measured by reading the file back
(:func:`rgl_error`).
"""

from __future__ import annotations

import numpy as np

from ._common import LUMA, StagedFiles, check_output_path, fail, label, writing

__all__ = ["rgl_fields", "export_rgl", "rgl_error"]


def _u_grid(n):
    u = np.linspace(0.0, 1.0, n)
    return u, 0.5 * np.pi * u * u


def _dirs(theta, phi=0.0):
    return np.stack(np.broadcast_arrays(np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi),
                                        np.cos(theta)), -1)


def _diffuse_weight(model) -> float:
    """Weight of the uniform (cosine) NDF mixed into the stored D and σ when the model has a
    Lambertian term: the warps must reach the directions where the diffuse term dominates
    (the stored rgb is divided by the stored D, so any positive NDF-like warp is valid)."""
    if model.diffuse is None or not np.any(model.diffuse > 0):
        return 0.0
    a_s, a_d = model.lobe_weights(np.array([0.0, 0.0, 1.0]))
    return float(np.clip(float(a_d) / max(float(a_d + a_s), 1e-12), 0.05, 0.95))


def _proxy_warp(model):
    """``(distribution, diffuse weight)`` of the warps for a model that is not a single
    microfacet lobe (per-channel SGD, NPF factors, sums): the NDF of its tabulated fit
    (Dupuy 2015, which follows the shape of the model's specular peak) mixed with a uniform
    NDF at a fixed weight of 0.25, since such models carry no separate diffuse albedo. The
    warps only steer where the rgb samples sit; the stored values are the model's own
    ``f_r cos θo`` divided by this D, so the file still holds the model (deliberate
    deviation from the measured files, whose D is the material's)."""
    from ..fit.tabulated import fit_tabulated

    return fit_tabulated(model).distribution, 0.25


def rgl_fields(model, n_theta: int = 32, n_ndf: int = 256, vndf_res: int = 128,
               rgb_res: int = 64) -> dict:
    """The tensor-file fields of ``model`` (see module docstring)."""
    from ..io.rgl import _Marginal2D, phi_to_u, u_to_phi, u_to_theta
    from ..microfacet.model import MicrofacetBRDF

    if not getattr(model, "isotropic", False):
        fail(model, "RGL .bsdf", "an isotropic BRDF: the format's single phi_i slice cannot "
             "hold an anisotropic model (phi_i slices are not implemented); use --to json, "
             "glsl or mitsuba")
    if isinstance(model, MicrofacetBRDF):
        dist, wd = model.distribution, _diffuse_weight(model)
    else:
        dist, wd = _proxy_warp(model)

    def D_of(w):
        d = np.nan_to_num(np.asarray(dist.D(w), float), nan=0.0, posinf=0.0)
        return (1.0 - wd) * d + wd * np.where(w[..., 2] > 0, 1.0 / np.pi, 0.0)

    def sigma_of(w):
        return (1.0 - wd) * np.asarray(dist.sigma(w), float) + wd * 0.5 * (1.0 + w[..., 2])

    # ndf / sigma tables
    _, th = _u_grid(n_ndf)
    th_eval = np.minimum(th, 0.5 * np.pi - 1e-6)
    w = _dirs(th_eval)
    D = D_of(w)
    sig = sigma_of(w)
    ndf = np.repeat(D[None], 2, 0).astype(np.float32)
    sigma = np.repeat(sig[None], 2, 0).astype(np.float32)
    ndf_w = _Marginal2D(ndf, (), normalize=False, enable_sampling=False)
    sig_w = _Marginal2D(sigma, (), normalize=False, enable_sampling=False)
    # vndf per incident elevation
    _, theta_i = _u_grid(n_theta)
    uu = np.linspace(0.0, 1.0, vndf_res)
    ux, uy = np.meshgrid(uu, uu, indexing="xy")                 # (H=φ, W=θ)
    tm, pm = u_to_theta(ux), u_to_phi(uy)
    m = _dirs(np.minimum(tm, 0.5 * np.pi - 1e-6), pm)
    Dm = D_of(m)
    jac = np.sin(tm) * np.pi * ux * 2.0 * np.pi
    vndf = np.zeros((1, n_theta, vndf_res, vndf_res), np.float32)
    rgb = np.zeros((1, n_theta, 3, rgb_res, rgb_res), np.float32)
    s = np.linspace(0.0, 1.0, rgb_res)
    sx, sy = np.meshgrid(s, s, indexing="xy")
    samples = np.stack([sx.ravel(), sy.ravel()], -1)
    for k, t in enumerate(theta_i):           # loop over the Nθ slices, not over samples
        wi = _dirs(min(float(t), 0.5 * np.pi - 1e-3))
        v = Dm * np.maximum(np.einsum("hwk,k->hw", m, wi), 0.0) * jac
        v = np.maximum(v, 1e-12 * v.max())
        vndf[0, k] = v
        warp = _Marginal2D(vndf[0, k], ())
        u_m, _ = warp.sample(samples, warp.corners([]))
        mm = _dirs(u_to_theta(u_m[:, 0]), u_to_phi(u_m[:, 1]))
        wo = 2.0 * (mm @ wi)[:, None] * mm - wi
        wi_b = np.broadcast_to(wi, wo.shape)
        f = np.asarray(model.eval(wo, wi_b), float) * np.maximum(wo[:, 2], 0.0)[:, None]
        d = ndf_w.eval(np.stack([u_m[:, 0], np.full(len(u_m), phi_to_u(0.0))], -1),
                       ndf_w.corners([]))
        sg = sig_w.eval(np.array([[np.sqrt(2 * t / np.pi), phi_to_u(0.0)]]), sig_w.corners([]))
        with np.errstate(divide="ignore", invalid="ignore"):
            val = np.where(d[:, None] > 0, f / (d / (4.0 * sg))[:, None], 0.0)
        rgb[0, k] = np.nan_to_num(val).T.reshape(3, rgb_res, rgb_res)
    lum = np.einsum("c,ptcyx->ptyx", LUMA, np.maximum(rgb, 0.0).astype(np.float64))
    lum = lum + 1e-6 * max(float(lum.max()), 1e-12)
    return {"version": np.array([1, 0], np.uint32),
            "description": f"brdffit export of {label(model)}",
            "phi_i": np.zeros(1, np.float32), "theta_i": theta_i.astype(np.float32),
            "sigma": sigma, "ndf": ndf, "vndf": vndf, "luminance": lum.astype(np.float32),
            "rgb": rgb, "jacobian": np.array([1], np.uint8)}


def rgl_error(model, path, n: int = 1 << 14, seed: int = 0) -> dict:
    """Read ``path`` back with :func:`brdffit.io.rgl.read_rgl` and compare with ``model``:
    cosine-weighted relative error (:func:`brdffit.evaluation.metrics.brdf_metrics`)."""
    from ..evaluation.metrics import brdf_metrics
    from ..io.rgl import read_rgl

    back = read_rgl(path)
    return {"cos_rel_error": brdf_metrics(model, back, n, seed,
                                          metrics=("cos_rel_error",))["cos_rel_error"]}


def export_rgl(model, path, check: bool = True, n_theta: int = 32, n_ndf: int = 256,
               vndf_res: int = 128, rgb_res: int = 64, **_ignored) -> dict:
    """Write the RGL-style ``.bsdf`` file (atomically; with ``check`` it is read back before it
    is moved into place, and nothing is left when that fails); returns a summary with the
    read-back error when ``check``. Sizes as in :func:`rgl_fields`."""
    from ..errors import ExportError
    from ..io.tensorfile import write_tensor_file

    path = check_output_path(path)
    sizes = {"n_theta": n_theta, "n_ndf": n_ndf, "vndf_res": vndf_res, "rgb_res": rgb_res}
    for k, v in sizes.items():
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 2 <= v <= 4096:
            raise ExportError(f"expected {k} to be an integer in [2, 4096], found {v!r}")
    fields = rgl_fields(model, **{k: int(v) for k, v in sizes.items()})
    out = {"files": [str(path)], "target": "rgl",
           "shapes": {k: list(np.shape(v)) for k, v in fields.items() if not isinstance(v, str)}}
    with StagedFiles(path) as staged:
        tmp = staged.path(path)
        with writing(path):
            write_tensor_file(tmp, fields)
        if check:
            out["error"] = rgl_error(model, tmp)
    return out
