"""Three models, one per colour channel: channel ``c`` of :class:`PerChannelBRDF` is channel ``c``
of its model ``c`` (the ``per_channel=True`` tabulated fit of Dupuy et al. 2015,
:func:`brdffit.fit.tabulated.fit_tabulated`).
"""

from __future__ import annotations

import numpy as np

from ..brdf import BRDF, sample_arguments
from ..schema import ListOf, Nested, Opt, Schema, Text
from ..serialization import SerializableModel
from .model import MicrofacetBRDF, channel_figures

__all__ = ["PerChannelBRDF"]


def _microfacet_schema() -> Schema:
    return MicrofacetBRDF.state_schema


class PerChannelBRDF(BRDF, SerializableModel):
    """Three single-channel fits (``per_channel=True``): channel ``c`` of the result is
    channel ``c`` of ``models[c]`` (one slope distribution and Fresnel per channel).

    Sampled as an equal-weight mixture of the three models' samplers; saved as fit kind
    ``"tabulated_per_channel"``.
    """

    fit_kind = "tabulated_per_channel"
    #: fit-file state (:mod:`brdffit.schema`): three ``microfacet`` states, arrays under
    #: ``c0.``, ``c1.``, ``c2.``
    state_schema = Schema(
        {"models": ListOf(Nested(_microfacet_schema), min_len=3, max_len=3,
                          item_prefix="c{index}."),
         "name": Opt(Text()), "source": Opt(Text())}, required=("models",))

    def __init__(self, models, name="brdf", source=None):
        self.models = list(models)
        if len(self.models) != 3:
            raise ValueError(f"PerChannelBRDF needs 3 models, got {len(self.models)}")
        self.name = name
        self.source = source
        self.isotropic = all(getattr(m, "isotropic", False) for m in self.models)
        self.fit_info = None
        self.fit_options = None

    def eval(self, wi, wo):
        return np.stack([m.eval(wi, wo)[..., c] for c, m in enumerate(self.models)], -1)

    def pdf(self, wi, wo):
        return sum(m.pdf(wi, wo) for m in self.models) / 3.0

    def sample(self, wi, u):
        wi, u = sample_arguments(wi, u)
        k = np.minimum((u[..., 0] * 3.0).astype(np.int64), 2)
        u2 = np.stack([np.clip(u[..., 0] * 3.0 - k, 0.0, 1.0 - 1e-16), u[..., 1]], -1)
        wo = np.zeros(wi.shape)
        for c, m in enumerate(self.models):  # three lobes, not a loop over samples
            sel = k == c
            if np.any(sel):
                wo[sel] = m.sample(wi[sel], u2[sel])[0]
        return wo, self.pdf(wi, wo)

    def figures(self) -> dict:
        """Channel c's figures from model c (:func:`~brdffit.microfacet.model.channel_figures`)."""
        return channel_figures(self.models)

    def to_state(self):
        params, arrays = {"name": self.name, "source": self.source, "models": []}, {}
        for c, m in enumerate(self.models):
            p, a = m.to_state()
            params["models"].append(p)
            arrays.update({f"c{c}.{k}": v for k, v in a.items()})
        return params, arrays

    @classmethod
    def from_state(cls, params, arrays):
        models = [MicrofacetBRDF.from_state(p, {k[len(f"c{c}."):]: v for k, v in arrays.items()
                                                if k.startswith(f"c{c}.")})
                  for c, p in enumerate(params["models"])]
        return cls(models, name=params.get("name"), source=params.get("source"))
