"""The test kit of the suite (not part of the product): malformed-file corpora and the
hostile-input runner (:mod:`.malformed_fits`, :mod:`.malformed_readers`, :mod:`.hostile`),
closed forms of the tabulated fit's paper (:mod:`.closed_forms`) and the NumPy twin of the
exported GLSL code (:mod:`.glsl_cpu`). What users check their own models with stays public:
``brdffit.testing.chi2`` (sampling) and ``brdffit.furnace`` (energy)."""
