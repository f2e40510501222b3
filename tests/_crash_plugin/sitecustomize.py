"""Test-only fault injection in brdffit's child processes (never on a user's path).

The containment tests put this folder on ``PYTHONPATH``; every Python process they start
(the demo's workers, the renderer's child) then imports it at start-up and, per
``BRDFFIT_TEST_CRASH``, kills itself with SIGSEGV — what a fault in a JIT-compiled kernel
does — at one point:

* ``render:SCENE``: when :class:`MultiRenderer` renders scene ``SCENE``;
* ``fit:MATERIAL``: when a model is fitted to the reference named ``MATERIAL``.
"""

import os
import signal

_what = os.environ.get("BRDFFIT_TEST_CRASH", "")


def _die():
    os.kill(os.getpid(), signal.SIGSEGV)


if _what.startswith("render:"):
    from brdffit.evaluation.render import core

    _scene = _what.split(":", 1)[1]
    _render = core.MultiRenderer.render

    def render(self, *args, **kwargs):
        if self.spec.name == _scene:
            _die()
        return _render(self, *args, **kwargs)

    core.MultiRenderer.render = render
elif _what.startswith("fit:"):
    from brdffit.evaluation import compare

    _material = _what.split(":", 1)[1]
    _fit = compare.fit_model

    def fit_model(name, reference, options=None):
        if getattr(reference, "name", None) == _material:
            _die()
        return _fit(name, reference, options)

    compare.fit_model = fit_model
