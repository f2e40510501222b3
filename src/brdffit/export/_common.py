"""Helpers shared by the export targets: model inspection, errors, frames, safe output.

Output files: every exporter writes through :func:`writing` (an ``OSError`` becomes
a one-line :class:`ExportError` naming the output file, what was expected and what was
found) and, when it writes several files, through :class:`StagedFiles` (all files are written
in a temporary folder next to the destination and moved into place only when all are
complete; on any error nothing is left and earlier outputs are kept). Names a user controls
are never pasted into generated code: see :func:`shown` for messages and each exporter for
its language's escaping.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import tempfile
from pathlib import Path

import numpy as np

from ..errors import BRDFError, ExportError
from .._atomic import WRITE_THROUGH, destination_kind, place
from ..brdf import cosine_hemisphere_sample
from ..evaluation.metrics import brdf_metrics
from ..fit.analytic import fit_analytic_diffuse
from ..microfacet.coat import coat_parts
from ..microfacet.model import MicrofacetBRDF
from ..microfacet.shadowing import EllipticalSlopeDistribution

__all__ = ["label", "fail", "finite_float", "principal_axes", "tangent_axes", "microfacet_parts",
           "is_elliptical", "LUMA", "shown", "check_output_path", "write_problem", "writing", "StagedFiles"]

#: Rec. 709 / linear-sRGB luminance weights (used for RGL ``luminance`` and reports)
LUMA = np.array([0.2126, 0.7152, 0.0722])


def label(model) -> str:
    """``ClassName 'name'`` of a model, for messages (the name as a Python ``repr``: quotes,
    newlines and control characters escaped, so it stays on one line)."""
    return f"{type(model).__name__} {getattr(model, 'name', '')!r}"


# ------------------------------------------------------------------------------------------
# output files: one-line errors naming the file, nothing partial left behind
# ------------------------------------------------------------------------------------------
def shown(path) -> str:
    """``path`` for a one-line message: as is when printable, else its ``repr`` (a name with
    a newline, NUL or escape sequence cannot break the line or the terminal)."""
    s = os.fsdecode(path) if isinstance(path, (bytes, os.PathLike)) else str(path)
    return s if s.isprintable() else repr(s)


def check_output_path(path) -> Path:
    """``path`` as a :class:`Path`; :class:`ExportError` when it cannot name a file (NUL
    character, empty name, ``.`` or ``..``)."""
    s = os.fsdecode(path) if isinstance(path, (bytes, os.PathLike)) else str(path)
    if "\x00" in s:
        raise ExportError(f"{shown(s)}: expected an output file name without NUL characters, "
                          "found one")
    p = Path(s)
    if not s or p.name in ("", ".", ".."):
        raise ExportError(f"{shown(s)}: expected an output file name, found "
                          f"{'nothing' if not s else 'a folder'}")
    return p


_SHORT_WRITE = re.compile(r"(\d+) requested and (\d+) written")


def write_problem(exc: BaseException) -> str:
    """What went wrong in a write, in words: ``could not write the file (no space left on
    device)``, or for NumPy's short writes (no errno) ``could not write 6144 bytes, only 4064
    were written (no space left on device or file size limit?)``."""
    if isinstance(exc, OSError) and exc.errno is not None and exc.strerror:
        why = exc.strerror[:1].lower() + exc.strerror[1:]
        return f"could not write the file ({why})"
    text = " ".join(str(exc).split())
    m = _SHORT_WRITE.search(text)
    if m:
        return (f"could not write {m[1]} bytes, only {m[2]} were written (no space left on "
                "device or file size limit?)")
    return f"could not write the file ({type(exc).__name__}: {text or 'no details'})"


@contextlib.contextmanager
def writing(path, catch: tuple = (OSError,)):
    """Turn an error of type ``catch`` (default ``OSError``) raised while writing ``path``
    into a one-line :class:`ExportError` naming ``path``; brdffit's own errors pass."""
    try:
        yield
    except BRDFError:
        raise
    except catch as exc:
        raise ExportError(f"{shown(path)}: {write_problem(exc)}") from exc


class StagedFiles:
    """The files of one export, written as a whole.

    ``with StagedFiles(main) as st:`` creates a hidden temporary folder next to ``main``
    (same filesystem); ``st.path(final)`` is where a writer writes the file that belongs at
    ``final`` (same suffix: some writers append one), ``st.open(final)`` opens it. When the
    block ends without error every file is put in place with :func:`brdffit._atomic.place`
    (``main`` last, so a script never appears before the data it loads; a device or FIFO is
    written through, and refused when the export has several files); if a move fails, the files
    already moved are restored to their previous content (or removed when they did not
    exist). On any error the temporary folder is removed: a failed export leaves the output
    folder as it was. Every ``OSError`` becomes a one-line :class:`ExportError` naming the
    final file (:func:`writing`).
    """

    def __init__(self, main):
        self.main = check_output_path(main)
        self.dir: Path | None = None
        self._files: list[tuple[Path, Path]] = []

    def __enter__(self) -> "StagedFiles":
        # a device or FIFO is written through: stage in the temporary folder, not in /dev
        special = destination_kind(self.main) in WRITE_THROUGH
        parent = Path(tempfile.gettempdir()) if special else self.main.parent
        with writing(self.main):
            parent.mkdir(parents=True, exist_ok=True)
            self.dir = Path(tempfile.mkdtemp(prefix=f".{self.main.name[:48]}.",
                                             suffix=".partial", dir=parent))
        return self

    def path(self, final) -> Path:
        """The temporary path for the file that belongs at ``final``."""
        final = check_output_path(final)
        tmp = self.dir / f"{len(self._files)}{final.suffix[:16]}"
        self._files.append((final, tmp))
        return tmp

    @contextlib.contextmanager
    def open(self, final, mode: str = "wb"):
        """Open the temporary file of ``final`` for writing (errors name ``final``)."""
        tmp = self.path(final)
        with writing(final):
            with open(tmp, mode) as fh:
                yield fh

    def __exit__(self, exc_type, exc, tb) -> bool:
        try:
            if exc_type is None:
                self._commit()
        finally:
            if self.dir is not None:
                shutil.rmtree(self.dir, ignore_errors=True)
        return False

    def _commit(self) -> None:
        order = sorted(self._files, key=lambda ft: ft[0] == self.main)   # main file last
        special = [(f, k) for f, _ in order if (k := destination_kind(f)) in WRITE_THROUGH]
        if special and len(order) > 1:
            final, kind = special[0]
            raise ExportError(f"{shown(final)}: this export writes {len(order)} files "
                              f"({', '.join(shown(f.name) for f, _ in order)}); expected a "
                              f"file name in a folder, found a {kind}")
        done: list[tuple[Path, Path | None, bool]] = []
        try:
            for i, (final, tmp) in enumerate(order):
                if not tmp.is_file():
                    raise ExportError(f"{shown(final)}: expected the file to be written, found "
                                      "nothing")
                existed = os.path.lexists(final)
                backup = None
                if existed and destination_kind(final) == "regular file":
                    backup = self.dir / f"previous{i}"
                    try:
                        os.link(final, backup, follow_symlinks=False)
                    except OSError:
                        backup = None
                with writing(final):
                    place(tmp, final)
                done.append((final, backup, existed))
        except BaseException:
            for final, backup, existed in reversed(done):
                with contextlib.suppress(OSError):
                    if backup is not None:
                        os.replace(backup, final)
                    elif not existed:
                        os.unlink(final)
            raise


def finite_float(x, where: str) -> float:
    """``float(x)``; :class:`ExportError` "cannot write the non-finite value ... {where}"
    when it is NaN or infinite (a scene or shader literal has no such value)."""
    x = float(x)
    if not np.isfinite(x):
        raise ExportError(f"cannot write the non-finite value {x!r} {where}; expected finite "
                          "parameters")
    return x


def fail(model, target: str, need: str):
    """Raise the :class:`ExportError` of a model that cannot go to ``target``."""
    raise ExportError(f"cannot export {label(model)} to {target}: {need}")


def microfacet_parts(model):
    """``(distribution, fresnel, diffuse, specular, correlated)`` of a MicrofacetBRDF, else None."""
    if not isinstance(model, MicrofacetBRDF):
        return None
    return model.distribution, model.fresnel, model.diffuse, model.specular, model.correlated


def is_elliptical(dist, kinds=("ggx", "beckmann")) -> bool:
    """True for a GGX/Beckmann :class:`EllipticalSlopeDistribution` (kind in ``kinds``)."""
    return isinstance(dist, EllipticalSlopeDistribution) and getattr(dist, "kind", "") in kinds


def single_lobe_of(coated):
    """A coated diffuse fit (:func:`brdffit.microfacet.coat.coat_parts`) approximated by one
    lobe: the diffuse fit of its family with ``coat="off"`` fitted to it (0.5-0.8 s). A
    target whose coat does not behave like the fit's (glTF's clearcoat has a Fresnel of N·V)
    may carry this closer than the coat (:func:`closer_to`)."""
    base = coat_parts(coated)[0]
    kind = "beckmann" if is_elliptical(base.distribution, ("beckmann",)) else "ggx"
    return fit_analytic_diffuse(coated, kind, coat="off", anisotropic=False,
                                name=getattr(coated, "name", None))


def closer_to(model, candidates: dict, make_brdf, n: int = 1 << 14) -> tuple[str, dict, dict]:
    """``(label, parameters, errors)``: of the exported ``candidates`` (label → parameters),
    the one whose BRDF (``make_brdf(parameters)``) has the lowest cosine-weighted relative
    error against ``model`` (:func:`brdffit.evaluation.metrics.brdf_metrics`, ``n`` pairs)."""
    errors = {k: brdf_metrics(model, make_brdf(p), n, metrics=("cos_rel_error",))
              ["cos_rel_error"] for k, p in candidates.items()}
    best = min(errors, key=errors.get)
    return best, candidates[best], errors


def principal_axes(alpha_x: float, alpha_y: float, rho: float) -> tuple[float, float, float]:
    """Principal roughnesses and frame rotation of the slope scale matrix (Dupuy 2015 App. C).

    ``S = [[αx², ραxαy], [ραxαy, αy²]] = R(φ) diag(αu², αv²) R(φ)ᵀ``: an elliptical
    distribution with correlation ρ is the axis-aligned one (ρ = 0, roughnesses αu, αv) in the
    tangent frame rotated by φ about the normal (counter-clockwise, radians). Returns
    ``(αu, αv, φ)`` with φ in (−π/2, π/2]; ``φ = 0`` and ``(αx, αy)`` when ρ = 0.
    """
    if rho == 0.0:
        return float(alpha_x), float(alpha_y), 0.0
    S = np.array([[alpha_x**2, rho * alpha_x * alpha_y], [rho * alpha_x * alpha_y, alpha_y**2]])
    evals, evecs = np.linalg.eigh(S)
    # choose the eigenvector closest to the x axis as the new u axis
    k = int(np.argmax(np.abs(evecs[0])))
    u = evecs[:, k] * (1.0 if evecs[0, k] >= 0 else -1.0)
    phi = float(np.arctan2(u[1], u[0]))
    return float(np.sqrt(evals[k])), float(np.sqrt(evals[1 - k])), phi


def tangent_axes(dist) -> tuple[float, float, float]:
    """``(αt, αb, rotation)`` of an elliptical distribution in the frame whose tangent t is
    its rougher principal axis (:func:`principal_axes`; αt ≥ αb), the rotation of t from x
    about the normal wrapped to (−π, π] (radians): the anisotropy parametrisation of glTF's
    ``KHR_materials_anisotropy`` and OpenPBR's ``specular_roughness_anisotropy``."""
    au, av, phi = principal_axes(dist.alpha_x, dist.alpha_y, dist.rho)
    if au >= av:
        at, ab, rot = au, av, phi
    else:
        at, ab, rot = av, au, phi + 0.5 * np.pi
    return at, ab, float(np.angle(np.exp(1j * rot)))


def rotate_z(w, phi: float) -> np.ndarray:
    """Directions ``w`` (..., 3) expressed in the frame rotated by ``phi`` about +z."""
    c, s = np.cos(phi), np.sin(phi)
    w = np.asarray(w, dtype=np.float64)
    return np.stack([c * w[..., 0] + s * w[..., 1], -s * w[..., 0] + c * w[..., 1], w[..., 2]], -1)


def diffuse_kept_fraction(make_brdf, n_pairs: int = 1 << 14, seed: int = 0) -> np.ndarray:
    """Per channel, how much of a Lambert base a layered material keeps: the cosine-weighted
    mean over direction pairs of ``π (f₁ − f₀)``, with ``f_b = make_brdf(b).eval`` for the base
    colour ``b`` = 1 and 0 (the layering must be linear in the base colour, as OpenPBR's and
    glTF's dielectrics are: the base is scaled by one minus the specular layer's
    reflectance). Dividing the fit's ``ρd`` by it gives the base colour whose diffuse
    albedo, averaged over every pair of directions with the weight ``cos θi cos θo``, is
    the fit's ``ρd`` (1 for a material that does not attenuate its base).

    Both directions are cosine-distributed (:func:`brdffit.brdf.cosine_hemisphere_sample`)
    from a fixed seed, so the result is deterministic; ``n_pairs`` = 2¹⁴ gives ~1e-4.
    """
    return (cosine_weighted_albedo(make_brdf(np.ones(3)), n_pairs, seed)
            - cosine_weighted_albedo(make_brdf(np.zeros(3)), n_pairs, seed))


def cosine_weighted_albedo(brdf, n_pairs: int = 1 << 14, seed: int = 0) -> np.ndarray:
    """Per channel, the directional albedo of ``brdf`` averaged over incident directions with
    the weight ``cos θi``: ``π`` times the mean of ``f(wi, wo)`` over direction pairs that are
    both cosine-distributed (:func:`brdffit.brdf.cosine_hemisphere_sample`, fixed seed: the
    same pairs for every call with the same ``n_pairs`` and ``seed``)."""
    u = np.random.default_rng(seed).random((2, n_pairs, 2))
    wi, wo = cosine_hemisphere_sample(u[0]), cosine_hemisphere_sample(u[1])
    return np.pi * np.mean(np.asarray(brdf.eval(wi, wo), dtype=np.float64), axis=0)


def base_for_albedo(make_brdf, target, n_pairs: int = 1 << 14, seed: int = 0):
    """Per channel, the base colour ``c ∈ [0, 1]`` whose material ``make_brdf(c)`` has the
    cosine-weighted mean albedo ``target`` (:func:`cosine_weighted_albedo`, same pairs for
    every call). Exact when that albedo is a polynomial of degree ≤ 2 in ``c`` — glTF's metal
    (Schlick F = c + (1 − c)(1 − V·H)⁵: affine) and OpenPBR's as MaterialX evaluates it (F
    times the energy compensation 1 + F(1 − E)/E: quadratic) — from its values at c = 0, ½, 1,
    taking the root on the increasing branch. Returns ``(c, unclipped)``; ``unclipped`` > 1
    means the target is out of the material's reach.
    """
    a0, ah, a1 = (cosine_weighted_albedo(make_brdf(np.full(3, c)), n_pairs, seed)
                  for c in (0.0, 0.5, 1.0))
    q = 2.0 * (a1 - 2.0 * ah + a0)                   # albedo = a0 + b c + q c²
    b = a1 - a0 - q
    t = np.asarray(target, dtype=np.float64) - a0
    with np.errstate(divide="ignore", invalid="ignore"):
        root = 2.0 * t / (b + np.sqrt(np.maximum(b * b + 4.0 * q * t, 0.0)))   # stable form
    wanted = np.where(np.isfinite(root), root, 0.0)
    return np.clip(wanted, 0.0, 1.0), wanted
