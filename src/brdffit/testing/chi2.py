"""Chi-square goodness-of-fit test of a BRDF's sampler against its pdf.

The procedure follows the one renderers use to validate their BSDF samplers (Mitsuba 3's
``mitsuba.chi2.ChiSquareTest``; Jakob's PBRT-v3 ``chi2test``), written here from the
textbook definition of Pearson's test:

1. The sphere of outgoing directions ``wo`` is cut into ``res_theta × res_phi`` bins of equal
   solid angle, uniform in ``(cos θo, φo) ∈ [-1, 1] × [0, 2π)`` (``dω = d cosθ dφ``).
   ``res_theta`` is even so that the horizon is a bin edge (pdfs jump there).
2. The expected count of each bin is ``N ∫_bin pdf(wi, wo) dωo``, integrated with an
   ``ires × ires`` Gauss-Legendre rule per bin, adaptively refined by quadrant splitting in
   the bins where refinement changes the result (so sharp lobes are integrated accurately).
3. ``N`` directions are drawn with ``brdf.sample(wi, u)`` and histogrammed. A sample whose
   returned pdf is 0 (or not finite) is *invalid* (e.g. a microfacet reflection below the
   horizon): it is not counted, and the pdf must then integrate to the valid fraction.
4. Bins with an expected count below ``min_expected`` (5) are pooled into one bin (and if the
   pool is still below 5 it is merged into the smallest remaining bin). Pearson's statistic
   ``Σ (O − E)² / E`` is compared with a χ² law of ``bins − 1`` degrees of freedom; the
   null hypothesis "samples follow pdf" is rejected when the p-value is below the Šidák
   corrected level ``1 − (1 − α)^(1/test_count)``.

Besides the p-value, :class:`Chi2Result` records the pdf integral over the sphere, the valid
fraction of samples (the two must agree), and the largest relative disagreement between the
pdf returned by ``sample`` and ``pdf(wi, wo)`` at the sampled directions.

Example
-------
>>> from brdffit.testing.chi2 import check_sampling
>>> ok, results = check_sampling(brdf, [[0, 0, 1], [0.5, 0, 0.866]])   # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import stats

__all__ = ["Chi2Result", "ChiSquareTest", "check_sampling", "pdf_integral"]


@dataclasses.dataclass
class Chi2Result:
    """Outcome of one :class:`ChiSquareTest` (one incident direction)."""

    wi: tuple
    p_value: float
    statistic: float
    dof: int
    threshold: float
    pdf_integral: float
    valid_fraction: float
    sample_pdf_mismatch: float
    n_samples: int
    passed: bool
    message: str

    def __str__(self) -> str:
        wi = ", ".join(f"{c:+.3f}" for c in self.wi)
        return (f"wi=({wi}) p={self.p_value:.4g} chi2={self.statistic:.1f} dof={self.dof} "
                f"∫pdf={self.pdf_integral:.4f} valid={self.valid_fraction:.4f} "
                f"{'PASS' if self.passed else 'FAIL'}{': ' + self.message if self.message else ''}")


def _integrate_rects(brdf, wi: np.ndarray, rects: np.ndarray, ires: int,
                     chunk: int = 1 << 18) -> np.ndarray:
    """``∫ pdf dωo`` over rectangles ``(c0, c1, φ0, φ1)`` in (cos θ, φ), ``ires²`` GL nodes."""
    x, w = np.polynomial.legendre.leggauss(ires)
    c0, c1, p0, p1 = rects.T
    hc, hp = 0.5 * (c1 - c0), 0.5 * (p1 - p0)
    CT = (0.5 * (c0 + c1))[:, None, None] + hc[:, None, None] * x[None, :, None]
    PH = (0.5 * (p0 + p1))[:, None, None] + hp[:, None, None] * x[None, None, :]
    CT, PH = np.broadcast_arrays(CT, PH)
    W = (hc * hp)[:, None, None] * (w[:, None] * w[None, :])[None]
    CT, PH, W = CT.ravel(), PH.ravel(), W.ravel()
    st = np.sqrt(np.maximum(0.0, 1.0 - CT * CT))
    wo = np.stack([st * np.cos(PH), st * np.sin(PH), CT], axis=-1)
    vals = np.empty(CT.size)
    for s in range(0, CT.size, chunk):
        sl = slice(s, s + chunk)
        vals[sl] = np.asarray(brdf.pdf(np.broadcast_to(wi, wo[sl].shape), wo[sl]),
                              dtype=np.float64).reshape(-1)
    vals = np.where(np.isfinite(vals), vals, np.nan)
    return (vals * W).reshape(len(rects), -1).sum(axis=-1)


def _split(rects: np.ndarray) -> np.ndarray:
    """Each rectangle into its 4 quadrants, shape ``(4 K, 4)`` (children of k at 4k..4k+3)."""
    c0, c1, p0, p1 = rects.T
    cm, pm = 0.5 * (c0 + c1), 0.5 * (p0 + p1)
    kids = np.stack([np.stack([c0, cm, p0, pm], -1), np.stack([cm, c1, p0, pm], -1),
                     np.stack([c0, cm, pm, p1], -1), np.stack([cm, c1, pm, p1], -1)], 1)
    return kids.reshape(-1, 4)


def _adaptive(brdf, wi, rects, coarse, ires, rel_tol, abs_tol, depth) -> np.ndarray:
    kids = _split(rects)
    fine = _integrate_rects(brdf, wi, kids, ires).reshape(-1, 4)
    total = fine.sum(-1)
    bad = np.abs(total - coarse) > np.maximum(rel_tol * np.abs(total), abs_tol)
    bad &= np.isfinite(total)
    if depth > 0 and np.any(bad):
        sub = fine[bad].ravel()
        refined = _adaptive(brdf, wi, kids.reshape(-1, 4, 4)[bad].reshape(-1, 4), sub, ires,
                            rel_tol, abs_tol / 4.0, depth - 1)
        fine[bad] = refined.reshape(-1, 4)
        total = fine.sum(-1)
    return total


def _bin_integrals(brdf, wi: np.ndarray, res_theta: int, res_phi: int, ires: int,
                   rel_tol: float = 1e-4, abs_tol: float = 1e-8, max_depth: int = 7
                   ) -> np.ndarray:
    """``∫_bin pdf(wi, wo) dωo`` for every (cos θ, φ) bin, shape ``(res_theta, res_phi)``.

    Gauss-Legendre with ``ires²`` nodes per bin, refined adaptively (quadrant splitting, up
    to ``max_depth`` levels) in the bins where one level of refinement changes the integral
    by more than ``max(rel_tol · I, abs_tol)`` — sharp lobes stay accurate.
    """
    ce = np.linspace(-1.0, 1.0, res_theta + 1)
    pe = np.linspace(0.0, 2.0 * np.pi, res_phi + 1)
    C0, P0 = np.meshgrid(ce[:-1], pe[:-1], indexing="ij")
    C1, P1 = np.meshgrid(ce[1:], pe[1:], indexing="ij")
    rects = np.stack([C0.ravel(), C1.ravel(), P0.ravel(), P1.ravel()], -1)
    coarse = _integrate_rects(brdf, wi, rects, ires)
    out = _adaptive(brdf, wi, rects, coarse, ires, rel_tol, abs_tol, max_depth)
    return out.reshape(res_theta, res_phi)


def pdf_integral(brdf, wi, res_theta: int = 64, res_phi: int = 128, ires: int = 6) -> float:
    """``∫_{S²} pdf(wi, wo) dωo`` by adaptive composite Gauss-Legendre in (cos θo, φo)."""
    wi = np.asarray(wi, dtype=np.float64)
    wi = wi / np.linalg.norm(wi)
    return float(np.sum(_bin_integrals(brdf, wi, res_theta, res_phi, ires)))


class ChiSquareTest:
    """Pearson chi-square test of ``brdf.sample(wi, ·)`` against ``brdf.pdf(wi, ·)``.

    Parameters
    ----------
    brdf:
        Any object with ``sample(wi, u) -> (wo, pdf)`` and ``pdf(wi, wo)`` (the
        :class:`brdffit.brdf.BRDF` protocol).
    wi:
        The incident direction (unit vector, normalised here).
    sample_count:
        Number of samples drawn.
    res_theta, res_phi:
        Bins in ``cos θo`` (made even) and ``φo``.
    ires:
        Gauss-Legendre nodes per bin and dimension for the expected counts.
    significance_level, test_count:
        α and the number of tests in the family (Šidák correction).
    seed:
        Seed of the uniform numbers fed to ``sample``.
    """

    def __init__(self, brdf, wi, sample_count: int = 200_000, res_theta: int = 32,
                 res_phi: int = 64, ires: int = 5, significance_level: float = 0.01,
                 test_count: int = 1, min_expected: float = 5.0, seed: int = 0):
        self.brdf = brdf
        wi = np.asarray(wi, dtype=np.float64).reshape(3)
        self.wi = wi / np.linalg.norm(wi)
        self.sample_count = int(sample_count)
        self.res_theta = int(res_theta) + (int(res_theta) % 2)
        self.res_phi = int(res_phi)
        self.ires = int(ires)
        self.significance_level = float(significance_level)
        self.test_count = int(test_count)
        self.min_expected = float(min_expected)
        self.seed = seed
        self.histogram: np.ndarray | None = None
        self.expected: np.ndarray | None = None

    # -- pieces ------------------------------------------------------------------------------
    def tabulate_histogram(self) -> tuple[np.ndarray, int, float]:
        """Draw the samples; return ``(histogram, n_valid, max relative pdf mismatch)``."""
        n = self.sample_count
        u = np.random.default_rng(self.seed).random((n, 2))
        wi = np.broadcast_to(self.wi, (n, 3))
        wo, pdf = self.brdf.sample(wi, u)
        wo = np.asarray(wo, dtype=np.float64).reshape(n, 3)
        pdf = np.asarray(pdf, dtype=np.float64).reshape(n)
        valid = np.isfinite(pdf) & (pdf > 0) & np.all(np.isfinite(wo), axis=-1)
        wo, pdf = wo[valid], pdf[valid]
        norm = np.linalg.norm(wo, axis=-1)
        if wo.size and np.max(np.abs(norm - 1.0)) > 1e-6:
            raise AssertionError(f"sample() returned non-unit directions (max | |wo| - 1 | = "
                                 f"{np.max(np.abs(norm - 1.0)):.3g})")
        mismatch = 0.0
        if wo.size:
            ref = np.asarray(self.brdf.pdf(wi[: wo.shape[0]], wo), dtype=np.float64).reshape(-1)
            mismatch = float(np.max(np.abs(ref - pdf) / np.maximum(np.abs(ref), 1e-300)))
        ct = np.clip(wo[:, 2], -1.0, 1.0)
        phi = np.mod(np.arctan2(wo[:, 1], wo[:, 0]), 2.0 * np.pi)
        it = np.minimum(((ct + 1.0) * 0.5 * self.res_theta).astype(np.int64), self.res_theta - 1)
        ip = np.minimum((phi / (2.0 * np.pi) * self.res_phi).astype(np.int64), self.res_phi - 1)
        hist = np.bincount(it * self.res_phi + ip, minlength=self.res_theta * self.res_phi)
        hist = hist.reshape(self.res_theta, self.res_phi).astype(np.float64)
        return hist, int(valid.sum()), mismatch

    def tabulate_pdf(self) -> np.ndarray:
        """Integral of the pdf over each bin, shape ``(res_theta, res_phi)``."""
        return _bin_integrals(self.brdf, self.wi, self.res_theta, self.res_phi, self.ires)

    def run(self) -> Chi2Result:
        """Run the test and return a :class:`Chi2Result`."""
        integ = self.tabulate_pdf()
        hist, n_valid, mismatch = self.tabulate_histogram()
        self.histogram, self.expected = hist, integ * self.sample_count
        threshold = 1.0 - (1.0 - self.significance_level) ** (1.0 / self.test_count)
        total = float(np.nansum(integ))
        valid_fraction = n_valid / self.sample_count
        common = dict(wi=tuple(float(c) for c in self.wi), threshold=threshold,
                      pdf_integral=total, valid_fraction=valid_fraction,
                      sample_pdf_mismatch=mismatch, n_samples=self.sample_count)
        if not np.all(np.isfinite(integ)):
            return Chi2Result(p_value=0.0, statistic=np.inf, dof=0, passed=False,
                              message="pdf() returned NaN or infinite values", **common)
        if np.any(integ < 0):
            return Chi2Result(p_value=0.0, statistic=np.inf, dof=0, passed=False,
                              message="pdf() returned negative values", **common)
        obs = hist.ravel()
        exp = self.expected.ravel()
        if np.any((exp == 0) & (obs > 0)):
            k = int(np.sum((exp == 0) & (obs > 0)))
            return Chi2Result(p_value=0.0, statistic=np.inf, dof=0, passed=False,
                              message=f"{k} bins received samples where the pdf integrates "
                                      "to zero", **common)
        order = np.argsort(exp)
        obs, exp = obs[order], exp[order]
        low = exp < self.min_expected
        pool_o, pool_e = obs[low].sum(), exp[low].sum()
        obs, exp = obs[~low], exp[~low]
        if pool_e > 0:
            if pool_e < self.min_expected and exp.size:
                obs = obs.copy()
                exp = exp.copy()
                obs[0] += pool_o
                exp[0] += pool_e
            else:
                obs = np.append(obs, pool_o)
                exp = np.append(exp, pool_e)
        dof = int(exp.size - 1)
        if dof < 1:
            return Chi2Result(p_value=0.0, statistic=np.inf, dof=dof, passed=False,
                              message="too few populated bins (increase sample_count)", **common)
        stat = float(np.sum((obs - exp) ** 2 / exp))
        p = float(stats.chi2.sf(stat, dof))
        msgs = []
        if p < threshold:
            msgs.append(f"p-value {p:.3g} below the Šidák-corrected level {threshold:.3g}")
        # The pdf must integrate to the fraction of valid samples (binomial 5σ + quadrature).
        tol = 5.0 * np.sqrt(max(valid_fraction * (1 - valid_fraction), 1e-12)
                            / self.sample_count) + 2e-3
        if abs(total - valid_fraction) > tol:
            msgs.append(f"pdf integrates to {total:.4f} but {valid_fraction:.4f} of the samples "
                        "are valid")
        if mismatch > 1e-3:
            msgs.append(f"pdf returned by sample() differs from pdf() by up to {mismatch:.3g} "
                        "(relative)")
        return Chi2Result(p_value=p, statistic=stat, dof=dof, passed=not msgs,
                          message="; ".join(msgs), **common)


def check_sampling(brdf, wis, significance_level: float = 0.01, **kwargs
                   ) -> tuple[bool, list[Chi2Result]]:
    """Run :class:`ChiSquareTest` for each incident direction, Šidák-corrected over all.

    Returns ``(all_passed, results)``; keyword arguments go to :class:`ChiSquareTest`
    (different seeds per direction unless ``seed`` is given).
    """
    wis = np.atleast_2d(np.asarray(wis, dtype=np.float64))
    seed = kwargs.pop("seed", 0)
    results = [ChiSquareTest(brdf, wi, significance_level=significance_level,
                             test_count=len(wis), seed=seed + k, **kwargs).run()
               for k, wi in enumerate(wis)]
    return all(r.passed for r in results), results
