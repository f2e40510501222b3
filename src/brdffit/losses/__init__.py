"""Losses of the fitters, below :mod:`brdffit.fit` and :mod:`brdffit.evaluation`.

* :mod:`.objective` – the compressive-weighted objective of Bagher et al. 2016 (Eq. 7-12)
  on the MERL grid, used by the NPF and SGD fits and reported as a BRDF-space metric;
* :mod:`.l2` – the normalised L2 error of Bagher et al. 2012 §6.3 and its MERL-grid
  quadrature weights.

Both depend only on :mod:`brdffit.grid`, :mod:`brdffit.geometry` and :mod:`brdffit.brdf`,
so fitters can use them without importing the evaluation layer.
"""
