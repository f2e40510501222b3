"""MaterialX documents rendered by MaterialX's own shader generation, run in the browser.

A real MaterialX implementation for the export round trip: MaterialX's ESSL generator
(``MaterialX.PyMaterialXGenGlsl.EsslShaderGenerator``, GLSL ES 3.00 for WebGL 2, the one
MaterialX's own web viewer runs) turns the ``surfacematerial`` of an exported ``.mtlx``
(``brdffit export FIT --to materialx``: an ``open_pbr_surface``) into a vertex and a pixel
shader, with the standard data libraries (``mx.loadLibraries``) and one bound light shader
(``ND_directional_light``, for ``sphere-distant``);
no environment lighting (``SPECULAR_ENVIRONMENT_NONE``), no shadow map, no transparency,
linear output (``hwSrgbEncodeOutput`` off). The page (``threejs_page/mtlx.js``) compiles them
unchanged as a three.js ``RawShaderMaterial`` (three supplies only the sphere, the camera
matrices, the float render target and the read-back, as in :mod:`.threejs`), sets the
document's uniform values, which the generator reports with the shader, and the light:

* ``directional``: ``LightData{type, direction = direction of travel, color = 1, intensity =
  E}``; MaterialX's ``mx_directional_light`` gives ``intensity = color · intensity`` towards
  ``−direction`` and the surface shader adds ``intensity · f · (N·L)`` (the BSDF closures'
  ``response`` carry the cosine), i.e. irradiance E on a surface facing the light;
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
from pathlib import Path

import numpy as np

from .threejs import ThreeRender, run_page, scene_json
from ..render.scenes import DISTANT_LIGHT

__all__ = ["generate_essl", "render_mtlx"]

_LIGHTS = {"sphere-distant": ("ND_directional_light", 1)}


def _value(port):
    v = port.getValue()
    if v is None:
        return None
    d = v.getData()
    if isinstance(d, (bool, int, float)):
        return d
    try:
        return [float(x) for x in d]
    except TypeError:
        return None


def generate_essl(mtlx, scene: str = "sphere-distant") -> dict:
    """ESSL (WebGL 2) shaders of the first renderable element of the MaterialX document
    ``mtlx`` (path), with the light of ``scene`` bound: ``{"vertex", "fragment", "uniforms":
    {name: {"type", "value"}}, "light_type", "materialx", "element", "patches"}``."""
    import MaterialX as mx
    import MaterialX.PyMaterialXGenGlsl as mx_glsl
    import MaterialX.PyMaterialXGenShader as mx_gen

    if scene not in _LIGHTS:
        raise ValueError(f"MaterialX round trip: expected sphere-distant, got {scene!r} "
                         "(MaterialX's point light is not inverse-square: see the module doc)")
    path = Path(mtlx)
    if not path.is_file() or path.suffix.lower() != ".mtlx":
        raise ValueError(f"generate_essl: expected an existing .mtlx file, got {str(mtlx)!r}")
    lib = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), lib)
    doc = mx.createDocument()
    doc.importLibrary(lib)
    mx.readFromXmlFile(doc, str(path))
    ok, msg = doc.validate()
    if not ok:
        raise ValueError(f"{path}: MaterialX validate() failed: {msg}")
    elems = mx_gen.findRenderableElements(doc)
    if not elems:
        raise ValueError(f"{path}: no renderable element (surfacematerial)")
    gen = mx_glsl.EsslShaderGenerator.create()
    ctx = mx_gen.GenContext(gen)
    ctx.registerSourceCodeSearchPath(mx.getDefaultDataSearchPath())
    opt = ctx.getOptions()
    opt.hwSpecularEnvironmentMethod = mx_gen.HwSpecularEnvironmentMethod.SPECULAR_ENVIRONMENT_NONE
    opt.hwMaxActiveLightSources = 1
    opt.hwShadowMap = False
    opt.hwTransparency = False
    opt.hwSrgbEncodeOutput = False
    nd_name, light_id = _LIGHTS[scene]
    mx_gen.HwShaderGenerator.bindLightShader(lib.getNodeDef(nd_name), light_id, ctx)
    shader = gen.generate("brdffit_mtlx", elems[0], ctx)
    vert = shader.getSourceCode(mx_gen.VERTEX_STAGE)
    frag = shader.getSourceCode(mx_gen.PIXEL_STAGE)
    patches = []
    if "u_refractionTwoSided" in frag and "uniform bool u_refractionTwoSided" not in frag:
        frag = frag.replace("uniform vec3 u_viewPosition;",
                            "uniform vec3 u_viewPosition;\nuniform bool u_refractionTwoSided;", 1)
        patches.append("declared the uniform u_refractionTwoSided (bool, false)")
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
                if t in ("float", "integer", "boolean", "color3", "vector3", "color4", "vector4",
                         "vector2"):
                    uniforms[p.getVariable()] = {"type": t, "value": _value(p)}
    return {"vertex": vert, "fragment": frag, "uniforms": uniforms, "light_type": light_id,
            "materialx": mx.getVersionString(), "element": elems[0].getName(),
            "patches": patches}


def render_mtlx(mtlx, scene: str = "sphere-distant", resolution: int = 128,
                supersample: int = 4, segments: tuple[int, int] = (256, 128),
                timeout: float = 120.0) -> ThreeRender:
    """Render the MaterialX document ``mtlx`` on the unit sphere of ``scene``
    (``sphere-distant``) with MaterialX's ESSL shaders in headless Chromium (module
    docstring); linear float pixels."""
    sh = generate_essl(mtlx, scene)            # validates scene (sphere-distant) and the file
    sc = scene_json(scene, resolution, supersample, segments)
    d = np.asarray(DISTANT_LIGHT["direction"], float)
    light = {"type": sh["light_type"], "direction": (d / np.linalg.norm(d)).tolist(),
             "color": [1.0, 1.0, 1.0], "intensity": float(DISTANT_LIGHT["irradiance"])}
    payload = {"vertex": sh["vertex"], "fragment": sh["fragment"], "uniforms": sh["uniforms"],
               "light": light}
    r = run_page("mtlx.js", sc, resolution, supersample,
                 data={"/shader.json": json.dumps(payload).encode()}, timeout=timeout)
    r.info |= {"materialx": sh["materialx"], "element": sh["element"],
               "generator_patches": sh["patches"]}
    if not math.isfinite(float(np.sum(r.image))):
        raise RuntimeError("MaterialX shader produced non-finite pixels")
    return r
