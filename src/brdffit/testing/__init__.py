"""Test utilities shared by the test suites of every model (statistical checks of samplers).

* :mod:`brdffit.testing.chi2` – chi-square goodness-of-fit test of ``BRDF.sample`` against
  ``BRDF.pdf`` (after Mitsuba 3's ``mitsuba.chi2.ChiSquareTest``), and the integral of the
  pdf over the sphere.
"""

from .chi2 import Chi2Result, ChiSquareTest, check_sampling, pdf_integral

__all__ = ["Chi2Result", "ChiSquareTest", "check_sampling", "pdf_integral"]
