// Renders a sphere with the vertex and pixel shaders that MaterialX's ESSL generator made from
// an .mtlx document (/shader.json: sources, uniform values, light) in the scene of /scene.json,
// into a float render target, and posts the linear RGBA pixels (Float32, rows bottom to top)
// to /result. three.js only supplies the sphere, the camera matrices and the render target:
// the shaders are compiled as they are (RawShaderMaterial, GLSL ES 3.00). Errors go to /error.
import * as THREE from 'three';

async function post(path, body, type) {
  await fetch(path, { method: 'POST', headers: { 'Content-Type': type }, body });
}

function uniformValue(u) {
  const v = u.value;
  if (v === null || v === undefined) return null;
  switch (u.type) {
    case 'float': case 'integer': case 'boolean': return v;
    case 'vector2': return new THREE.Vector2().fromArray(v);
    case 'color3': case 'vector3': return new THREE.Vector3().fromArray(v);
    case 'color4': case 'vector4': return new THREE.Vector4().fromArray(v);
    default: return null;
  }
}

async function main() {
  const scene = await (await fetch('/scene.json')).json();
  const sh = await (await fetch('/shader.json')).json();
  const W = scene.width, H = scene.height;
  const canvas = document.createElement('canvas');
  canvas.width = W; canvas.height = H;
  document.body.appendChild(canvas);
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: false, alpha: true });
  renderer.setPixelRatio(1);
  renderer.setSize(W, H, false);
  renderer.toneMapping = THREE.NoToneMapping;
  renderer.setClearColor(0x000000, 0.0);
  renderer.debug.checkShaderErrors = true;
  const gl = renderer.getContext();
  if (!renderer.extensions.has('EXT_color_buffer_float')) {
    throw new Error('WebGL 2 without EXT_color_buffer_float: no float render target');
  }

  const cam = new THREE.PerspectiveCamera(scene.camera.fov, W / H, 0.1, 100.0);
  cam.position.fromArray(scene.camera.origin);
  cam.up.fromArray(scene.camera.up);
  cam.lookAt(new THREE.Vector3().fromArray(scene.camera.target));
  cam.updateMatrixWorld(true);
  cam.updateProjectionMatrix();

  const uniforms = {};
  for (const [name, u] of Object.entries(sh.uniforms)) {
    const v = uniformValue(u);
    if (v !== null) uniforms[name] = { value: v };
  }
  const identity = new THREE.Matrix4();
  uniforms.u_worldMatrix = { value: identity };
  uniforms.u_worldInverseTransposeMatrix = { value: identity };
  uniforms.u_viewProjectionMatrix = {
    value: new THREE.Matrix4().multiplyMatrices(cam.projectionMatrix, cam.matrixWorldInverse) };
  uniforms.u_viewPosition = { value: cam.position.clone() };
  uniforms.u_numActiveLightSources = { value: 1 };
  uniforms.u_refractionTwoSided = { value: false };
  // MaterialX's LightData of a directional light: direction of travel, colour, intensity
  uniforms.u_lightData = { value: [{
    type: sh.light.type, direction: new THREE.Vector3().fromArray(sh.light.direction),
    color: new THREE.Vector3().fromArray(sh.light.color), intensity: sh.light.intensity }] };

  // three writes the '#version 300 es' line itself (glslVersion GLSL3) before its own
  // defines: the generator's line is taken off so that it stays the first line
  const strip = (src) => src.replace(/^\s*#version 300 es\s*\n/, '');
  const material = new THREE.RawShaderMaterial({
    vertexShader: strip(sh.vertex), fragmentShader: strip(sh.fragment), uniforms,
    glslVersion: THREE.GLSL3, side: THREE.FrontSide });
  const geo = new THREE.SphereGeometry(1.0, scene.sphere_segments[0], scene.sphere_segments[1]);
  geo.computeTangents();
  geo.setAttribute('i_position', geo.getAttribute('position'));
  geo.setAttribute('i_normal', geo.getAttribute('normal'));
  geo.setAttribute('i_tangent', geo.getAttribute('tangent'));
  const world = new THREE.Scene();
  world.add(new THREE.Mesh(geo, material));

  const target = new THREE.WebGLRenderTarget(W, H, {
    type: THREE.FloatType, format: THREE.RGBAFormat, depthBuffer: true,
    minFilter: THREE.NearestFilter, magFilter: THREE.NearestFilter, samples: 0 });
  renderer.setRenderTarget(target);
  renderer.clear();
  renderer.render(world, cam);
  const props = renderer.properties.get(material);
  const prog = props.currentProgram;
  if (!prog || prog.diagnostics && !prog.diagnostics.runnable) {
    const d = prog && prog.diagnostics;
    throw new Error('MaterialX shaders did not compile: ' +
                    (d ? (d.vertexShader.log + ' ' + d.fragmentShader.log + ' ' + d.programLog) : 'no program'));
  }
  const pixels = new Float32Array(W * H * 4);
  renderer.readRenderTargetPixels(target, 0, 0, W, H, pixels);
  renderer.setRenderTarget(null);
  const dbg = gl.getExtension('WEBGL_debug_renderer_info');
  await post('/info', JSON.stringify({
    three: THREE.REVISION, material_type: 'RawShaderMaterial (MaterialX ESSL)',
    gl_renderer: dbg ? gl.getParameter(dbg.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER),
    gl_version: gl.getParameter(gl.VERSION) }), 'application/json');
  await post('/result', pixels.buffer, 'application/octet-stream');
}

main().catch((e) => post('/error', String(e && e.stack ? e.stack : e), 'text/plain'));
