"""The MERL sampling grid (Matusik et al. 2003), shared by the MERL reader and the fits.

90 θh × 90 θd × 180 φd samples. θh is sampled uniformly in ``sqrt(θh / (π/2))``:
sample ``i`` sits at ``θh = (i/90)² · π/2``; θd sample ``j`` at ``j · π/180``; φd sample ``k``
at ``k · π/180`` with φd in [0, π) by reciprocity (φd ≡ φd + π).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "N_THETA_H", "N_THETA_D", "N_PHI_D", "merl_theta_h", "merl_theta_d", "merl_phi_d",
    "theta_h_to_index", "theta_d_to_index", "phi_d_to_index", "tabulate_merl_grid",
    "merl_node_values", "usable", "eval_hd_chunked", "eval_chunked",
]

N_THETA_H, N_THETA_D, N_PHI_D = 90, 90, 180


def merl_theta_h() -> np.ndarray:
    """θh of the 90 MERL samples (radians)."""
    return (np.arange(N_THETA_H) / N_THETA_H) ** 2 * (np.pi / 2)


def merl_theta_d() -> np.ndarray:
    """θd of the 90 MERL samples (radians)."""
    return np.arange(N_THETA_D) * (np.pi / 2 / N_THETA_D)


def merl_phi_d() -> np.ndarray:
    """φd of the 180 MERL samples (radians, in [0, π))."""
    return np.arange(N_PHI_D) * (np.pi / N_PHI_D)


def theta_h_to_index(theta_h) -> np.ndarray:
    """Continuous MERL θh index ``sqrt(θh/(π/2))·90`` (floor gives MERL's own lookup)."""
    return np.sqrt(np.clip(theta_h, 0.0, np.pi / 2) / (np.pi / 2)) * N_THETA_H


def theta_d_to_index(theta_d) -> np.ndarray:
    """Continuous MERL θd index ``θd/(π/2)·90``."""
    return np.clip(theta_d, 0.0, np.pi / 2) / (np.pi / 2) * N_THETA_D


def phi_d_to_index(phi_d) -> np.ndarray:
    """Continuous MERL φd index after folding φd into [0, π) (reciprocity)."""
    return np.mod(phi_d, np.pi) / np.pi * N_PHI_D


def tabulate_merl_grid(brdf, chunk: int = 1 << 18) -> tuple[np.ndarray, np.ndarray]:
    """Evaluate an isotropic BRDF at every MERL sample.

    Returns ``(values, valid)`` with ``values`` of shape ``(90, 90, 180, 3)`` and a boolean
    ``valid`` mask of shape ``(90, 90, 180)``. A BRDF that *is* a MERL table (it has a
    ``merl_table`` attribute returning ``(values, valid)``) is returned as stored, so that
    invalid measurements stay marked. Otherwise every finite, non-negative value is valid.

    Samples outside the BRDF's measured domain (:meth:`brdffit.brdf.BRDF.measured`) are
    invalid too, so fits and errors computed from the grid use measurements only.

    A BRDF that never changes after it is made (a Neural-BRDF network) may carry an empty list
    ``_merl_grid_memo``: its tabulation is then computed once and returned read-only to every
    later caller (every fit and metric of a material tabulates the same reference).
    """
    table = _stored_table(brdf)
    if table is not None:
        return table
    memo = getattr(brdf, "_merl_grid_memo", None)    # opt-in for immutable BRDFs (NBRDF)
    if memo is not None:
        if not memo:
            values, valid = _evaluate(brdf, chunk)
            values.setflags(write=False)
            valid.setflags(write=False)
            memo.append((values, valid))
        return memo[0]
    return _evaluate(brdf, chunk)


def _evaluate(brdf, chunk: int) -> tuple[np.ndarray, np.ndarray]:
    values, measured = _evaluate_nodes(brdf, slice(None), slice(None), slice(None), chunk)
    return values, usable(values, measured)


def usable(values, measured) -> np.ndarray:
    """Where ``values (…, 3)`` are measured, finite and non-negative in every channel: the
    ``valid`` mask of :func:`tabulate_merl_grid`."""
    return measured & np.all(np.isfinite(values), axis=-1) & np.all(values >= 0, axis=-1)


def _evaluate_nodes(brdf, ih, jd, kp, chunk: int) -> tuple[np.ndarray, np.ndarray]:
    """``eval_hd`` at the nodes ``θh[ih] × θd[jd] × φd[kp]`` in chunks of ``chunk`` samples,
    and the BRDF's measured domain there."""
    th, td, pd = np.meshgrid(merl_theta_h()[ih], merl_theta_d()[jd], merl_phi_d()[kp],
                             indexing="ij")
    shape = th.shape
    th, td, pd = th.ravel(), td.ravel(), pd.ravel()
    out = eval_hd_chunked(brdf, th, td, pd, chunk)
    if getattr(brdf, "measured_domain", None) is None:
        return out.reshape(shape + (3,)), np.ones(shape, dtype=bool)
    return out.reshape(shape + (3,)), _measured_hd(brdf, th, td, pd).reshape(shape)


def eval_hd_chunked(brdf, th, td, pd, chunk: int = 1 << 18) -> np.ndarray:
    """``brdf.eval_hd`` at the flat angle arrays ``th``, ``td``, ``pd``, ``chunk`` samples at
    a time (bounded temporaries), as one ``(n, 3)`` array."""
    out = np.empty((np.size(th), 3))
    for s in range(0, np.size(th), chunk):
        sl = slice(s, s + chunk)
        out[sl] = brdf.eval_hd(th[sl], td[sl], pd[sl])
    return out


def eval_chunked(brdf, wi, wo, chunk: int = 1 << 18) -> np.ndarray:
    """``brdf.eval`` at the direction pairs ``wi``, ``wo`` ``(n, 3)``, ``chunk`` pairs at a
    time, as one ``(n, 3)`` array: with ``wi, wo = half_diff_to_io(th, 0, td, pd)``, the values
    of :func:`eval_hd_chunked` for a BRDF whose ``eval_hd`` converts to directions."""
    out = np.empty((len(wi), 3))
    for s in range(0, len(wi), chunk):
        out[s:s + chunk] = brdf.eval(wi[s:s + chunk], wo[s:s + chunk])
    return out


def _stored_table(brdf):
    table = getattr(brdf, "merl_table", None)
    if table is None:
        return None
    return table() if callable(table) else table


def _measured_hd(brdf, th, td, pd) -> np.ndarray:
    return np.broadcast_to(np.asarray(brdf.measured_hd(th, td, pd), dtype=bool),
                           np.broadcast_shapes(np.shape(th), np.shape(td), np.shape(pd)))


def merl_node_values(brdf, ih=slice(None), jd=slice(None), kp=slice(None),
                     chunk: int = 1 << 18) -> tuple[np.ndarray, np.ndarray]:
    """The BRDF at the MERL nodes ``θh[ih] × θd[jd] × φd[kp]`` (index arrays or slices).

    Returns ``(values (…, 3), measured (…))`` on that sub-grid. A MERL table
    (``merl_table``) is read as stored and ``measured`` is its valid mask; any other isotropic
    BRDF is evaluated with ``eval_hd`` (``chunk`` samples at a time) and ``measured`` is its
    measured domain (:meth:`brdffit.brdf.IsotropicBRDF.measured_hd`, all True when it has
    none). Values are returned as they come: callers clean non-finite or negative ones their
    own way.
    """
    table = _stored_table(brdf)
    if table is not None:
        values, valid = table
        return np.asarray(values)[ih][:, jd][:, :, kp], np.asarray(valid)[ih][:, jd][:, :, kp]
    return _evaluate_nodes(brdf, ih, jd, kp, chunk)
