"""MaterialX documents rendered by MaterialX's own shader generation, run in the browser.

A real MaterialX implementation for the export round trip: MaterialX's ESSL generator
(``MaterialX.PyMaterialXGenGlsl.EsslShaderGenerator``, GLSL ES 3.00 for WebGL 2, the one
MaterialX's own web viewer runs) turns the ``surfacematerial`` of an exported ``.mtlx``
(``brdffit export FIT --to materialx``: an ``open_pbr_surface``) into a vertex and a pixel
shader, with the standard data libraries (``mx.loadLibraries``) and one bound light shader
(``ND_directional_light``, for ``sphere-distant``; no environment lighting,
``SPECULAR_ENVIRONMENT_NONE``) or, for the environment-map scenes, no light and MaterialX's
own environment lighting (below); no shadow map, no transparency, linear output
(``hwSrgbEncodeOutput`` off). The page (``threejs_page/mtlx.js``) compiles them
unchanged as a three.js ``RawShaderMaterial`` (three supplies only the sphere, the camera
matrices, the float render target and the read-back, as in :mod:`.threejs`), sets the
document's uniform values, which the generator reports with the shader, and the light:

* ``directional``: ``LightData{type, direction = direction of travel, color = 1, intensity =
  E}``; MaterialX's ``mx_directional_light`` gives ``intensity = color · intensity`` towards
  ``−direction`` and the surface shader adds ``intensity · f · (N·L)`` (the BSDF closures'
  ``response`` carry the cosine), i.e. irradiance E on a surface facing the light;
* ``sphere-env`` (the procedural map) and ``sphere-<map>`` (a shared map, as the paper
  suite's ``sphere-courtyard``, ``sphere-studio``, ``sphere-sunrise``;
  :func:`~.threejs.resolve_scene`): ``hwSpecularEnvironmentMethod =
  SPECULAR_ENVIRONMENT_FIS``, filtered importance sampling (Křivánek & Colbert 2008), what
  MaterialXView renders with. Each specular lobe sums ``u_envRadianceSamples`` GGX-VNDF
  samples (a spherical-Fibonacci set: deterministic) of the lat-long ``u_envRadiance``, each
  read at the mip level whose texel matches the sample's share of the lobe
  (``mx_latlong_compute_lod``, over ``u_envRadianceMips`` levels: WebGL's box-filtered mip
  chain of the map, as MaterialXView's); diffuse lobes read ``u_envIrradiance`` at the
  normal. Chosen over ``SPECULAR_ENVIRONMENT_PREFILTER`` because FIS needs only the map and
  its mip chain (PREFILTER needs MaterialX's prefilter pass run on the map first) and its
  error falls with the sample count, which is a parameter here (:data:`ENV_SAMPLES`).
  The uniforms are the generator's: ``u_envMatrix`` keeps the value it declares, a half turn
  about +Y (``(x, y, z) → (−x, y, −z)``), under which MaterialX's lat-long projection
  ``u = atan2(x, −z)/2π + 1/2``, ``v = 1/2 − asin(y)/π`` reads Mitsuba's ``u = atan2(x,
  −z)/2π`` with ``v = 0`` at the zenith: the map is sent as Mitsuba reads it
  (:func:`~.threejs.environment_rgba` ``"mitsuba"``, own resolution, half floats, clamped at
  0); ``u_envLightIntensity`` = 1; ``u_envRadianceMips`` = ``log2(width) + 1``.
  ``u_envIrradiance`` is computed here (:func:`irradiance_map`) by brute-force convolution,
  not spherical harmonics: the order-2 SH irradiance of a map with a sun (sunrise: 58 % of
  the energy in it) rings by several per cent and goes negative behind the sun, while the
  direct sum is the clamped-cosine integral itself. MaterialX's diffuse closures add
  ``Li · colour`` with ``Li`` read from that map, so it holds ``E(n)/π`` (the radiance of a
  white Lambertian);
* ``sphere-point`` is refused: MaterialX's ``mx_point_light`` (1.39.5) attenuates by
  ``(d + 1)^decay_rate``, not ``d²``, so no uniform setting gives Mitsuba's ``I / d²`` over
  the sphere (d = 5.1-6.0 on its lit side: the two differ by 36-43 %, varying across the
  image).

Why this implementation: it is MaterialX's reference code generation (the shaders of
MaterialXView and of the MaterialX web viewer, the same BSDF library every MaterialX GLSL
renderer uses), it runs offline in the Chromium and WebGL 2 (SwiftShader) of the three.js
round trip with no new dependency (``materialx`` is already one), and its output can be read
back as float pixels like three's. Alternatives not taken: ``MaterialXView`` needs a desktop
OpenGL context (none here), a path tracer reading ``.mtlx`` (Arnold, RenderMan, Karma) is not
installable from PyPI or Debian.

Generator work-around (stated, not a change of the shading): with
``SPECULAR_ENVIRONMENT_NONE`` the 1.39.5 generator still references the private uniform
``u_refractionTwoSided`` in ``mx_surface_transmission`` without declaring it; the declaration
``uniform bool u_refractionTwoSided;`` (false) is added to the pixel shader when it is missing
(transmission is 0 in our exports).
"""

from __future__ import annotations

import json
import math
from functools import lru_cache
from pathlib import Path

import numpy as np

from .threejs import (ThreeRender, environment_rgba, resolve_scene, rgba_half, run_page,
                      scene_json)
from ..render.scenes import DISTANT_LIGHT
from ..report_viewer import environment_image

__all__ = ["generate_essl", "render_mtlx", "irradiance_map", "irradiance_from", "ENV_SAMPLES",
           "IRRADIANCE_WIDTH"]

_LIGHTS = {"sphere-distant": ("ND_directional_light", 1)}
#: FIS samples per specular lobe and pixel (``u_envRadianceSamples``; MaterialXView's default
#: is 16)
ENV_SAMPLES = 256
#: width of the irradiance map (height half of it) and of the map it is summed from
IRRADIANCE_WIDTH, _IRRADIANCE_SOURCE = 128, 256
_UNIFORM_TYPES = ("float", "integer", "boolean", "color3", "vector3", "color4", "vector4",
                  "vector2", "matrix44")


def _latlong_directions(height: int, width: int) -> np.ndarray:
    """``(height·width, 3)`` directions of the texel centres of a lat-long map in Mitsuba's
    convention: θ from +Y, ``φ = 2π u``, ``d = (sin θ sin φ, cos θ, −sin θ cos φ)``."""
    t = (np.arange(height) + 0.5) / height * np.pi
    p = (np.arange(width) + 0.5) / width * 2.0 * np.pi
    T, P = np.meshgrid(t, p, indexing="ij")
    return np.stack([np.sin(T) * np.sin(P), np.cos(T), -np.sin(T) * np.cos(P)], -1).reshape(-1, 3)


def irradiance_from(src: np.ndarray, width: int = IRRADIANCE_WIDTH) -> np.ndarray:
    """``E(n)/π = (1/π) Σ_k L_k max(0, n·ω_k) ΔΩ_k`` of the lat-long map ``src`` ((h, w, 3),
    Mitsuba's convention) at the texel centres n of a ``(width/2, width, 3)`` map: the sum
    over the texels k of ``src`` at their centres ω_k, ΔΩ_k the exact solid angle of the
    texel (its band's ``(2π/w)(cos θ0 − cos θ1)``, so a constant map of 1 gives 1)."""
    src = np.asarray(src, np.float64)
    if src.ndim != 3 or src.shape[-1] != 3:
        raise ValueError(f"irradiance_from: expected an (h, w, 3) map, got shape {src.shape}")
    if isinstance(width, bool) or not isinstance(width, int) or not (8 <= width <= 512
                                                                     and width % 4 == 0):
        raise ValueError(f"irradiance map width must be a multiple of 4 in [8, 512], got "
                         f"{width!r}")
    h, w = src.shape[:2]
    edges = np.arange(h + 1) / h * np.pi
    solid = (2.0 * np.pi / w) * (np.cos(edges[:-1]) - np.cos(edges[1:]))
    radiance = (src * solid[:, None, None]).reshape(-1, 3).astype(np.float32)
    d_in = _latlong_directions(h, w).astype(np.float32)
    d_out = _latlong_directions(width // 2, width).astype(np.float32)
    out = np.empty((d_out.shape[0], 3), np.float64)
    for i in range(0, d_out.shape[0], 512):
        out[i:i + 512] = np.maximum(d_out[i:i + 512] @ d_in.T, 0.0) @ radiance
    return (out / np.pi).reshape(width // 2, width, 3).astype(np.float32)


@lru_cache(maxsize=8)
def _irradiance(envmap: str | None, width: int) -> np.ndarray:
    return irradiance_from(environment_image(envmap, _IRRADIANCE_SOURCE), width)


def irradiance_map(envmap: str | None = None, width: int = IRRADIANCE_WIDTH) -> np.ndarray:
    """MaterialX's ``u_envIrradiance`` for a map (``None``: the procedural one): ``(width/2,
    width, 3)`` float32 in Mitsuba's lat-long order, :func:`irradiance_from` of the map
    area-averaged to 256 × 128 (:func:`~brdffit.evaluation.report_viewer.environment_image`:
    sin θ weighted, the map's power kept). A copy."""
    if isinstance(width, bool) or not isinstance(width, int):
        raise ValueError(f"irradiance map width must be a multiple of 4 in [8, 512], got "
                         f"{width!r}")
    return _irradiance(envmap, width).copy()


def _value(port):
    """A uniform's value as JSON data: a number, or the list of its components (a matrix's 16
    in MaterialX's row-major order, from its value string); ``None`` when it has none."""
    v = port.getValue()
    if v is None:
        return None
    if port.getType().getName() == "matrix44":
        return [float(x) for x in v.getValueString().split(",")]
    d = v.getData()
    if isinstance(d, (bool, int, float)):
        return d
    try:
        return [float(x) for x in d]
    except TypeError:
        return None


def _uniforms(shader, mx_gen) -> dict:
    """``{name: {"type", "value"}}`` of the shader's private and public uniforms of plain
    types (textures and closures are left to the page)."""
    uniforms = {}
    for stage in (mx_gen.VERTEX_STAGE, mx_gen.PIXEL_STAGE):
        st = shader.getStage(stage)
        for block in ("PrivateUniforms", "PublicUniforms"):
            try:
                blk = st.getUniformBlock(block)
            except LookupError:
                continue
            for i in range(blk.size()):
                p = blk[i]
                t = p.getType().getName()
                if t in _UNIFORM_TYPES:
                    uniforms[p.getVariable()] = {"type": t, "value": _value(p)}
    return uniforms


def _document(path: Path, mx):
    """The validated document at ``path`` with the standard libraries, and the libraries."""
    lib = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), lib)
    doc = mx.createDocument()
    doc.importLibrary(lib)
    mx.readFromXmlFile(doc, str(path))
    ok, msg = doc.validate()
    if not ok:
        raise ValueError(f"{path}: MaterialX validate() failed: {msg}")
    return doc, lib


def generate_essl(mtlx, scene: str = "sphere-distant") -> dict:
    """ESSL (WebGL 2) shaders of the first renderable element of the MaterialX document
    ``mtlx`` (path), with the light of ``scene`` bound (``sphere-distant``) or MaterialX's
    FIS environment lighting (``sphere-env``, ``sphere-<map>``): ``{"vertex", "fragment",
    "uniforms": {name: {"type", "value"}}, "light_type" (None with an environment),
    "environment" (bool), "materialx", "element", "patches"}``."""
    import MaterialX as mx
    import MaterialX.PyMaterialXGenGlsl as mx_glsl
    import MaterialX.PyMaterialXGenShader as mx_gen

    base = resolve_scene(scene)[0]
    if base not in ("sphere-distant", "sphere-env"):
        raise ValueError(f"MaterialX round trip: expected sphere-distant, sphere-env or "
                         f"sphere-<map>, got {scene!r} (MaterialX's point light is not "
                         "inverse-square: see the module doc)")
    path = Path(mtlx)
    if not path.is_file() or path.suffix.lower() != ".mtlx":
        raise ValueError(f"generate_essl: expected an existing .mtlx file, got {str(mtlx)!r}")
    doc, lib = _document(path, mx)
    elems = mx_gen.findRenderableElements(doc)
    if not elems:
        raise ValueError(f"{path}: no renderable element (surfacematerial)")
    gen = mx_glsl.EsslShaderGenerator.create()
    ctx = mx_gen.GenContext(gen)
    ctx.registerSourceCodeSearchPath(mx.getDefaultDataSearchPath())
    opt = ctx.getOptions()
    env = base == "sphere-env"
    methods = mx_gen.HwSpecularEnvironmentMethod
    opt.hwSpecularEnvironmentMethod = (methods.SPECULAR_ENVIRONMENT_FIS if env
                                       else methods.SPECULAR_ENVIRONMENT_NONE)
    opt.hwMaxActiveLightSources = 0 if env else 1
    opt.hwShadowMap = False
    opt.hwTransparency = False
    opt.hwSrgbEncodeOutput = False
    light_id = None
    if not env:
        nd_name, light_id = _LIGHTS[base]
        mx_gen.HwShaderGenerator.bindLightShader(lib.getNodeDef(nd_name), light_id, ctx)
    shader = gen.generate("brdffit_mtlx", elems[0], ctx)
    vert = shader.getSourceCode(mx_gen.VERTEX_STAGE)
    frag = shader.getSourceCode(mx_gen.PIXEL_STAGE)
    patches = []
    if "u_refractionTwoSided" in frag and "uniform bool u_refractionTwoSided" not in frag:
        frag = frag.replace("uniform vec3 u_viewPosition;",
                            "uniform vec3 u_viewPosition;\nuniform bool u_refractionTwoSided;", 1)
        patches.append("declared the uniform u_refractionTwoSided (bool, false)")
    return {"vertex": vert, "fragment": frag, "uniforms": _uniforms(shader, mx_gen),
            "light_type": light_id, "environment": env, "materialx": mx.getVersionString(),
            "element": elems[0].getName(), "patches": patches}


def _environment(scene: str, uniforms: dict, samples: int) -> tuple[dict, dict]:
    """The page's environment (``{"width", "height", "irradiance_width",
    "irradiance_height"}``), its texels (``/environment.bin``, ``/irradiance.bin``), and the
    generator's environment uniforms set (samples, mip count, intensity 1)."""
    envmap = resolve_scene(scene)[1]
    radiance, w, h = environment_rgba(envmap, "mitsuba")
    irr = irradiance_map(envmap)
    for name, value in (("u_envRadianceSamples", int(samples)),
                        ("u_envRadianceMips", int(math.log2(max(w, h))) + 1),
                        ("u_envLightIntensity", 1.0)):
        if name not in uniforms:
            raise RuntimeError(f"the generated shader declares no {name}")
        uniforms[name]["value"] = value
    env = {"width": w, "height": h, "irradiance_width": int(irr.shape[1]),
           "irradiance_height": int(irr.shape[0])}
    return env, {"/environment.bin": radiance, "/irradiance.bin": rgba_half(irr)}


def render_mtlx(mtlx, scene: str = "sphere-distant", resolution: int = 128,
                supersample: int = 4, segments: tuple[int, int] = (256, 128),
                timeout: float = 120.0, env_samples: int = ENV_SAMPLES) -> ThreeRender:
    """Render the MaterialX document ``mtlx`` on the unit sphere of ``scene``
    (``sphere-distant``, ``sphere-env`` or ``sphere-<map>``) with MaterialX's ESSL shaders in
    headless Chromium (module docstring); linear float pixels. ``env_samples``: FIS samples
    per specular lobe (environment scenes)."""
    if isinstance(env_samples, bool) or not isinstance(env_samples, int) or not (
            1 <= env_samples <= 4096):
        raise ValueError(f"render_mtlx: env_samples must be an integer in [1, 4096], got "
                         f"{env_samples!r}")
    sh = generate_essl(mtlx, scene)            # validates scene and the file
    sc = scene_json(scene, resolution, supersample, segments)
    payload = {"vertex": sh["vertex"], "fragment": sh["fragment"], "uniforms": sh["uniforms"],
               "light": None, "environment": None}
    data = {}
    if sh["environment"]:
        payload["environment"], data = _environment(scene, sh["uniforms"], env_samples)
    else:
        d = np.asarray(DISTANT_LIGHT["direction"], float)
        payload["light"] = {"type": sh["light_type"], "direction": (d / np.linalg.norm(d)).tolist(),
                            "color": [1.0, 1.0, 1.0],
                            "intensity": float(DISTANT_LIGHT["irradiance"])}
    data["/shader.json"] = json.dumps(payload).encode()
    r = run_page("mtlx.js", sc, resolution, supersample, data=data, timeout=timeout)
    r.info |= {"materialx": sh["materialx"], "element": sh["element"],
               "generator_patches": sh["patches"]}
    if sh["environment"]:
        r.info |= {"env_samples": int(env_samples), "specular_environment": "FIS",
                   "environment": payload["environment"]}
    if not math.isfinite(float(np.sum(r.image))):
        raise RuntimeError("MaterialX shader produced non-finite pixels")
    return r
