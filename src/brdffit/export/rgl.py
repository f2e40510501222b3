"""RGL-style ``.bsdf`` tensor file of a microfacet fit (Dupuy & Jakob 2018 layout).

Fields written (what :func:`brdffit.io.rgl.read_rgl` and Mitsuba 3's ``measured`` plugin
read; see :mod:`brdffit.io.rgl` for their meaning). Nφ = 1 for isotropic models, else the
number of ``phi_i`` slices (below):

``ndf`` (J, K), ``sigma`` (J, K)
    The model's NDF D(θm, φm) and projected area σ(θ, φ) (Dupuy 2015 Eq. 3) on K = ``n_ndf``
    nodes uniform in ``u = √(2θ/π)`` and J nodes uniform in ``u_φ = (φ + π)/2π`` (J = 2
    equal rows for isotropic models, J = ``n_ndf`` otherwise). With a Lambertian term the
    stored D is the mixture ``(1 − w) D + w/π`` (σ likewise, ``σ_uniform = (1 + cos θ)/2``),
    ``w`` = the diffuse share of the albedo at normal incidence clipped to [0.05, 0.95]: the
    warps then cover the directions the diffuse term needs (deliberate deviation; the BRDF
    value is unchanged since rgb is divided by the stored D).
``theta_i`` (Nθ,), ``phi_i`` (Nφ,)
    Incident (Mitsuba ``si.wi``, the viewer) elevations uniform in u; azimuths: one (0) for an
    isotropic model, else Nφ ≥ 3 uniform azimuths from −π to −π + 2π/r, both ends included,
    where r ∈ {1, 2, 4} is the symmetry reduction of the model (:func:`rgl_reduction`).
``vndf`` (Nφ, Nθ, H, W)
    Visible normal density per (φi, θi) in the (u_θm, u_φm) square:
    ``D(m) <wi, m>₊ · sin θm · π u_θ · 2π`` (the Jacobian of Mitsuba's parameterisation;
    slices are normalised by the reader). φm is relative to φi for isotropic models and
    absolute for anisotropic ones (``Measured::eval``: ``phi2u(m_isotropic ? φm − φi : φm)``).
``rgb`` (Nφ, Nθ, 3, n, n), ``luminance`` (Nφ, Nθ, n, n), ``jacobian`` = 1
    At the n × n sample-space points s, ``m = warp_vndf(s)``, ``wo = reflect(wi, m)``, the
    stored value is ``f_r(wo, wi) cos θo / (D(m) / (4 σ(wi)))`` with the file's own
    interpolated D and σ, so that ``Measured::eval`` returns ``f_r cos θo`` at the sample
    points; luminance = Rec. 709 Y of rgb (clamped ≥ 0, plus a tiny floor so every slice has
    a positive integral), used for importance sampling.

Anisotropic models (``phi_i`` slices). Mitsuba's ``measured`` plugin (``src/bsdfs/
measured.cpp``) treats a file as isotropic when ``phi_i`` has at most two entries; otherwise
it interpolates the VNDF, luminance and rgb tables linearly in (φi, θi) with φi =
``atan2(wi.y, wi.x)``, reads the 2-D ndf at the half vector's absolute (θm, φm) and σ at
(θi, φi), and first folds ``wi`` (and ``wo`` with it) into the stored azimuth range, by the
reduction ``r = rint(2π / (φi[−1] − φi[0]))``: r = 2 negates x and y when wi.y ≥ 0 (a
rotation by π, into φi ∈ [−π, 0]); r = 4 negates x when wi.x ≥ 0 and y when wi.y ≥ 0 (the
two mirrors, into φi ∈ [−π, −π/2]); r = 1 stores the full circle [−π, π] (both ends, which
are the same azimuth). The exporter picks the largest r the model obeys
(:func:`rgl_reduction`: f(T wi, T wo) = f(wi, wo) for the rotation by π and the mirrors
φ → −φ, φ → π − φ, checked numerically), so a correlated (ρ ≠ 0) GGX lobe stores half
the circle and an axis-aligned one a quarter. Default Nφ (:func:`default_n_phi`): one slice
every 22.5° of the stored range plus the closing one (5, 9 or 17 slices for r = 4, 2, 1).
Measured on the anisotropic tabulated fit of ``aniso-ggx`` (r = 2), read-back error
(:func:`rgl_error`) against Nφ at the other defaults (vndf 128²): 3 slices 2.2 %, 5 slices
0.96 %, 9 slices 0.48 %, 13 slices 0.36 % (rgb 32² instead of 64²: 0.83 %; Nθ 16: 0.64 %);
storing the full circle (r = 1) at the same 22.5° spacing gives the same 0.44 %, so the fold
costs nothing. The default anisotropic file (9 slices, vndf 64²) is 0.50 %, 23 MiB, written
and read back in 2 s (2 cores); r = 4 (axis-aligned fit, 5 slices): 0.46 %, 13 MiB, 0.7 s;
r = 1: 43 MiB (an isotropic file: 4 MiB; the RGL database's: 0.7 MB). Anisotropic models that are not one microfacet lobe warp with their
tabulated fit's NDF plus 25 % uniform (:func:`_proxy_warp`), which interpolates worse between
φi slices: ``aniso-ggx`` itself goes to 0.38 % with its own NDF (r = 1 forced) but 2.6 % when
wrapped so that it takes the proxy route; the non-symmetric test model of the tests: 2.5 %.
Isotropic models are written with one ``phi_i`` slice.

Every model maps. A :class:`~brdffit.microfacet.model.MicrofacetBRDF` (tabulated fits in
particular, also GGX/Beckmann/SGD) stores its own NDF and σ; other models (per-channel SGD,
NPF factors, sums) store the NDF of their tabulated fit as the warp (:func:`_proxy_warp`).
The resampling error is measured by reading the file back (:func:`rgl_error`).
"""

from __future__ import annotations

import numpy as np

from ..io.rgl import phi_i_reduction  # noqa: F401 - re-exported (the reader's rule)
from ._common import LUMA, StagedFiles, check_output_path, label, writing
from ..errors import ExportError
from ..evaluation.metrics import brdf_metrics
from ..fit.tabulated import fit_tabulated
from ..io._limits import MAX_TENSOR_FILE_BYTES
from ..io.rgl import _Marginal2D, phi_to_u, read_rgl, u_to_phi, u_to_theta
from ..io.tensorfile import write_tensor_file
from ..microfacet.model import MicrofacetBRDF

__all__ = ["rgl_fields", "export_rgl", "rgl_error", "rgl_reduction", "default_n_phi",
           "phi_i_reduction"]

#: the signs (x, y) of the symmetries behind Mitsuba's reductions 2 (rotation by π) and 4
#: (rotation plus the two mirrors)
_SYMMETRIES = {2: ((-1.0, -1.0),), 4: ((-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0))}


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
    (Dupuy 2015, which follows the shape of the model's specular peak; anisotropic for an
    anisotropic model) mixed with a uniform NDF at a fixed weight of 0.25, since such models
    carry no separate diffuse albedo. The warps only steer where the rgb samples sit; the
    stored values are the model's own ``f_r cos θo`` divided by this D, so the file still
    holds the model (deliberate deviation from the measured files, whose D is the
    material's)."""
    return fit_tabulated(model).distribution, 0.25


def rgl_reduction(model, n: int = 4096, seed: int = 0, rtol: float = 1e-6) -> int:
    """The symmetry reduction r ∈ {1, 2, 4} of Mitsuba's ``measured`` plugin that ``model``
    obeys (1 for an isotropic model: its single slice needs none).

    r = 2 needs f(T wi, T wo) = f(wi, wo) for the rotation by π about the normal
    (T = diag(−1, −1, 1)); r = 4 also for the mirrors φ → −φ and φ → π − φ (see the module
    docstring for how the plugin folds). Checked on ``n`` pairs (wi uniform on the
    hemisphere; wo uniform for half of them and, for the other half, wi reflected about half
    vectors of Gaussian slopes with scales 0.01 to 1, so that the specular peak of any lobe
    about the normal is probed), each symmetry holding when every value agrees to
    ``rtol`` relative (plus 1e-12 of the largest value): anything but round-off breaks it,
    and the file then stores the wider range, which is exact for any model (a fit of measured
    anisotropic data is stored on the full circle).
    """
    if getattr(model, "isotropic", False):
        return 1
    rng = np.random.default_rng(seed)
    half = max(int(n) // 2, 1)
    v = rng.normal(size=(2 * half, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    v[:, 2] = np.abs(v[:, 2]) + 1e-3
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    wi, wo = v[:half], v[half:]
    scale = np.array([0.01, 0.03, 0.1, 0.3, 1.0])[np.arange(half) % 5]
    h = np.concatenate([rng.normal(size=(half, 2)) * scale[:, None], np.ones((half, 1))], -1)
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    wo_peak = 2.0 * np.sum(wi * h, -1, keepdims=True) * h - wi
    wi, wo = np.concatenate([wi, wi]), np.concatenate([wo, wo_peak])
    f0 = np.nan_to_num(np.asarray(model.eval(wi, wo), float))
    floor = 1e-12 * max(float(np.abs(f0).max()), 1e-300)

    def holds(sx, sy):
        s = np.array([sx, sy, 1.0])
        f1 = np.nan_to_num(np.asarray(model.eval(wi * s, wo * s), float))
        return bool(np.all(np.abs(f1 - f0) <= rtol * np.maximum(np.abs(f0), np.abs(f1)) + floor))

    best = 1
    for r in (2, 4):
        if all(holds(*s) for s in _SYMMETRIES[r]):
            best = r
        else:
            break
    return best


def default_n_phi(reduction: int) -> int:
    """Default number of ``phi_i`` slices for a symmetry reduction r ∈ {1, 2, 4}: one slice
    every 22.5° of the stored range 2π/r, plus the closing one (17, 9, 5)."""
    return 16 // int(reduction) + 1


def _phi_grid(reduction: int, n_phi: int) -> np.ndarray:
    """``phi_i`` of an anisotropic file: ``n_phi`` uniform azimuths over [−π, −π + 2π/r]
    (what Mitsuba folds into; both ends stored so that ``rint(2π / span)`` = r)."""
    return -np.pi + (2.0 * np.pi / reduction) * np.linspace(0.0, 1.0, n_phi)


def _check_sizes(sizes: dict, n_slices: int) -> None:
    """:class:`ExportError` for a size that is not an integer in [2, 4096], or tables whose
    file would exceed what :func:`brdffit.io.rgl.read_rgl` reads back (the read-back check)."""
    for k, v in sizes.items():
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 2 <= v <= 4096:
            raise ExportError(f"expected {k} to be an integer in [2, 4096], found {v!r}")
    n_ndf = sizes["n_ndf"]
    floats = (n_slices * sizes["n_theta"] * (sizes["vndf_res"] ** 2 + 4 * sizes["rgb_res"] ** 2)
              + 2 * n_ndf * (n_ndf if n_slices > 1 else 2))
    if 4 * floats > MAX_TENSOR_FILE_BYTES:
        raise ExportError(f"expected tables within the {MAX_TENSOR_FILE_BYTES >> 20} MiB that "
                          f"brdffit's RGL reader accepts, found {4 * floats / 2**20:.0f} MiB "
                          f"for {n_slices} phi_i x {sizes['n_theta']} theta_i slices of "
                          f"vndf {sizes['vndf_res']}^2 and rgb {sizes['rgb_res']}^2; lower "
                          "n_phi, n_theta, vndf_res or rgb_res")


def rgl_fields(model, n_theta: int = 32, n_ndf: int = 256, vndf_res: int | None = None,
               rgb_res: int = 64, n_phi: int | None = None) -> dict:
    """The tensor-file fields of ``model`` (see module docstring).

    ``vndf_res`` defaults to 128 for isotropic models and 64 for anisotropic ones (per slice:
    the read-back error of the anisotropic tabulated fit of ``aniso-ggx`` is 0.50 % at 64
    and 0.48 % at 128, and 64 keeps the default files within the 64 MiB the reader accepts).
    ``n_phi`` (anisotropic models only, ≥ 3: two or fewer would make Mitsuba read the file as
    isotropic) defaults to :func:`default_n_phi` of the model's :func:`rgl_reduction`."""
    isotropic = bool(getattr(model, "isotropic", False))
    if vndf_res is None:
        vndf_res = 128 if isotropic else 64
    sizes = {"n_theta": n_theta, "n_ndf": n_ndf, "vndf_res": vndf_res, "rgb_res": rgb_res}
    _check_sizes(sizes, 1)
    n_theta, n_ndf, vndf_res, rgb_res = (int(v) for v in sizes.values())
    phi_i = np.zeros(1, np.float32) if isotropic else _anisotropic_phi_i(model, n_phi, sizes)
    D_of, sigma_of = _warp_functions(model)
    ndf, sigma = _ndf_sigma(D_of, sigma_of, n_ndf, isotropic)
    theta_i = _u_grid(n_theta)[1].astype(np.float32)
    vndf, rgb = _vndf_rgb(model, D_of, (ndf, sigma), phi_i, theta_i, (vndf_res, rgb_res),
                          isotropic)
    lum = np.einsum("c,ptcyx->ptyx", LUMA, np.maximum(rgb, 0.0).astype(np.float64))
    lum = lum + 1e-6 * max(float(lum.max()), 1e-12)
    return {"version": np.array([1, 0], np.uint32),
            "description": f"brdffit export of {label(model)}",
            "phi_i": phi_i, "theta_i": theta_i,
            "sigma": sigma, "ndf": ndf, "vndf": vndf, "luminance": lum.astype(np.float32),
            "rgb": rgb, "jacobian": np.array([1], np.uint8)}


def _anisotropic_phi_i(model, n_phi, sizes: dict) -> np.ndarray:
    """The ``phi_i`` grid (float32) of an anisotropic model: ``n_phi`` (default
    :func:`default_n_phi`) azimuths over the model's :func:`rgl_reduction`."""
    reduction = rgl_reduction(model)
    n_phi = default_n_phi(reduction) if n_phi is None else n_phi
    if isinstance(n_phi, bool) or not isinstance(n_phi, (int, np.integer)) \
            or not 3 <= n_phi <= 4096:
        raise ExportError(f"expected n_phi to be an integer in [3, 4096] for an anisotropic "
                          f"model (Mitsuba reads 2 or fewer phi_i as isotropic), found "
                          f"{n_phi!r}")
    _check_sizes(sizes, int(n_phi))
    return _phi_grid(reduction, int(n_phi)).astype(np.float32)


def _warp_functions(model):
    """``(D_of, sigma_of)``: the NDF and projected area σ of the distribution the file
    samples, the model's own (microfacet models) or a proxy, mixed with the uniform NDF
    (D = 1/π, σ = (1 + cos θ)/2) at the weight ``wd`` of the diffuse part."""
    if isinstance(model, MicrofacetBRDF):
        dist, wd = model.distribution, _diffuse_weight(model)
    else:
        dist, wd = _proxy_warp(model)

    def D_of(w):
        d = np.nan_to_num(np.asarray(dist.D(w), float), nan=0.0, posinf=0.0)
        return (1.0 - wd) * d + wd * np.where(w[..., 2] > 0, 1.0 / np.pi, 0.0)

    def sigma_of(w):
        return (1.0 - wd) * np.asarray(dist.sigma(w), float) + wd * 0.5 * (1.0 + w[..., 2])

    return D_of, sigma_of


def _ndf_sigma(D_of, sigma_of, n_ndf: int, isotropic: bool):
    """The ``ndf`` and ``sigma`` tables (float32): J rows of φ, K columns of θ; two equal
    rows when isotropic."""
    _, th = _u_grid(n_ndf)
    th_eval = np.minimum(th, 0.5 * np.pi - 1e-6)
    if isotropic:
        w = _dirs(th_eval)
        ndf = np.repeat(D_of(w)[None], 2, 0).astype(np.float32)
        sigma = np.repeat(sigma_of(w)[None], 2, 0).astype(np.float32)
        return ndf, sigma
    ph = u_to_phi(np.linspace(0.0, 1.0, n_ndf))
    w = _dirs(th_eval[None, :], ph[:, None])
    return D_of(w).astype(np.float32), sigma_of(w).astype(np.float32)


def _vndf_rgb(model, D_of, tables, phi_i, theta_i, res: tuple[int, int], isotropic: bool):
    """The ``vndf`` and ``rgb`` tables (float32) for each ``phi_i``, all θi slices at once:
    the visible NDF on the (u_θm, u_φm) grid (φm relative to φi = 0 or absolute: same grid),
    and the model's cosine-weighted value divided by the sampling density at the samples
    the VNDF warp maps a ``rgb_res``² grid to. ``tables`` = ``(ndf, sigma)``, ``res`` =
    ``(vndf_res, rgb_res)``."""
    vndf_res, rgb_res = res
    ndf_w = _Marginal2D(tables[0], (), normalize=False, enable_sampling=False)
    sig_w = _Marginal2D(tables[1], (), normalize=False, enable_sampling=False)
    n_theta = theta_i.size
    th_i = np.minimum(theta_i.astype(np.float64), 0.5 * np.pi - 1e-3)
    uu = np.linspace(0.0, 1.0, vndf_res)
    ux, uy = np.meshgrid(uu, uu, indexing="xy")                 # (H=φ, W=θ)
    tm, pm = u_to_theta(ux), u_to_phi(uy)
    m = _dirs(np.minimum(tm, 0.5 * np.pi - 1e-6), pm)
    Dm = D_of(m)
    jac = np.sin(tm) * np.pi * ux * 2.0 * np.pi
    n_p, n_s = phi_i.size, rgb_res * rgb_res
    vndf = np.zeros((n_p, n_theta, vndf_res, vndf_res), np.float32)
    rgb = np.zeros((n_p, n_theta, 3, rgb_res, rgb_res), np.float32)
    s = np.linspace(0.0, 1.0, rgb_res)
    sx, sy = np.meshgrid(s, s, indexing="xy")
    samples = np.tile(np.stack([sx.ravel(), sy.ravel()], -1), (n_theta, 1))
    slice_of = np.repeat(np.arange(n_theta), n_s)             # the θi slice of every sample
    for p, phi in enumerate(phi_i.astype(np.float64)):  # loop over the Nφ azimuths only
        wi = _dirs(th_i, phi)                                   # (Nθ, 3)
        v = Dm[None] * np.maximum(np.einsum("hwk,tk->thw", m, wi), 0.0) * jac[None]
        v = np.maximum(v, 1e-12 * v.max(axis=(1, 2), keepdims=True))
        vndf[p] = v
        # each sample's corner is its own slice (weight 1), as Marginal2D's lookup at a
        # parameter node
        warp = _Marginal2D(vndf[p], (theta_i,))
        u_m, _ = warp.sample(samples, [(slice_of, np.ones(slice_of.size))])
        mm = _dirs(u_to_theta(u_m[:, 0]), u_to_phi(u_m[:, 1]) + (phi if isotropic else 0.0))
        wi_b = wi[slice_of]
        wo = 2.0 * np.sum(mm * wi_b, -1)[:, None] * mm - wi_b
        f = np.asarray(model.eval(wo, wi_b), float) * np.maximum(wo[:, 2], 0.0)[:, None]
        d = ndf_w.eval(u_m, ndf_w.corners([]))
        u_wi = np.stack([np.sqrt(2.0 * theta_i.astype(np.float64) / np.pi),
                         np.full(n_theta, phi_to_u(phi))], -1)
        sg = sig_w.eval(u_wi, sig_w.corners([]))[slice_of]
        with np.errstate(divide="ignore", invalid="ignore"):
            val = np.where(d[:, None] > 0, f / (d / (4.0 * sg))[:, None], 0.0)
        rgb[p] = np.nan_to_num(val).reshape(n_theta, n_s, 3).transpose(0, 2, 1) \
            .reshape(n_theta, 3, rgb_res, rgb_res)
    return vndf, rgb


def rgl_error(model, path, n: int = 1 << 14, seed: int = 0) -> dict:
    """Read ``path`` back with :func:`brdffit.io.rgl.read_rgl` and compare with ``model``:
    cosine-weighted relative error (:func:`brdffit.evaluation.metrics.brdf_metrics`)."""
    back = read_rgl(path)
    return {"cos_rel_error": brdf_metrics(model, back, n, seed,
                                          metrics=("cos_rel_error",))["cos_rel_error"]}


def export_rgl(model, path, check: bool = True, n_theta: int = 32, n_ndf: int = 256,
               vndf_res: int = 0, rgb_res: int = 64, n_phi: int = 0, **_ignored) -> dict:
    """Write the RGL-style ``.bsdf`` file (atomically; with ``check`` it is read back before it
    is moved into place, and nothing is left when that fails); returns a summary with the
    read-back error when ``check``, the ``reduction`` and the file size in bytes. Sizes as in
    :func:`rgl_fields` (``vndf_res``, ``n_phi`` = 0: their defaults for the model)."""

    def auto(v):
        return None if type(v) is int and v == 0 else v

    path = check_output_path(path)
    fields = rgl_fields(model, n_theta=n_theta, n_ndf=n_ndf, vndf_res=auto(vndf_res),
                        rgb_res=rgb_res, n_phi=auto(n_phi))
    out = {"files": [str(path)], "target": "rgl", "reduction": phi_i_reduction(fields["phi_i"]),
           "shapes": {k: list(np.shape(v)) for k, v in fields.items() if not isinstance(v, str)}}
    with StagedFiles(path) as staged:
        tmp = staged.path(path)
        with writing(path):
            write_tensor_file(tmp, fields)
        out["bytes"] = tmp.stat().st_size
        if check:
            out["error"] = rgl_error(model, tmp)
    return out
