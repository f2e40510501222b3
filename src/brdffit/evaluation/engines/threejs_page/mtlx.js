// Renders a sphere with the vertex and pixel shaders that MaterialX's ESSL generator made from
// an .mtlx document (/shader.json: sources, uniform values, a light or an environment whose
// maps are /environment.bin and /irradiance.bin) in the scene of /scene.json,
// into a float render target, and posts the linear RGBA pixels (Float32, rows bottom to top)
// to /result. three.js only supplies the sphere, the camera matrices and the render target:
// the shaders are compiled as they are (RawShaderMaterial, GLSL ES 3.00). Errors go to /error.
import * as THREE from 'three';
import { environmentTexture, floatRenderer, glInfo, post, renderFloat, sceneCamera } from './common.js';

function uniformValue(u) {
  const v = u.value;
  if (v === null || v === undefined) return null;
  switch (u.type) {
    case 'float': case 'integer': case 'boolean': return v;
    case 'vector2': return new THREE.Vector2().fromArray(v);
    case 'color3': case 'vector3': return new THREE.Vector3().fromArray(v);
    case 'color4': case 'vector4': return new THREE.Vector4().fromArray(v);
    // MaterialX's 16 values (row vectors, row-major) are GL's column-major upload order
    case 'matrix44': return new THREE.Matrix4().fromArray(v);
    default: return null;
  }
}

async function main() {
  const scene = await (await fetch('/scene.json')).json();
  const sh = await (await fetch('/shader.json')).json();
  const W = scene.width, H = scene.height;
  const renderer = floatRenderer(W, H);
  renderer.debug.checkShaderErrors = true;

  const cam = sceneCamera(scene, W, H);

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
  uniforms.u_refractionTwoSided = { value: false };
  if (sh.light) {
    // MaterialX's LightData of a directional light: direction of travel, colour, intensity
    uniforms.u_numActiveLightSources = { value: 1 };
    uniforms.u_lightData = { value: [{
      type: sh.light.type, direction: new THREE.Vector3().fromArray(sh.light.direction),
      color: new THREE.Vector3().fromArray(sh.light.color), intensity: sh.light.intensity }] };
  }
  if (sh.environment) {
    // MaterialX's environment lighting: the lat-long map with WebGL's mip chain (read by
    // filtered importance sampling) and the irradiance map; the other u_env* uniforms are
    // the generator's, set by the Python side
    const e = sh.environment;
    uniforms.u_envRadiance = { value: await environmentTexture('/environment.bin', e.width, e.height, true) };
    uniforms.u_envIrradiance = { value: await environmentTexture('/irradiance.bin', e.irradiance_width, e.irradiance_height) };
  }

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

  const pixels = renderFloat(renderer, world, cam, W, H, () => {
    const prog = renderer.properties.get(material).currentProgram;
    if (!prog || prog.diagnostics && !prog.diagnostics.runnable) {
      const d = prog && prog.diagnostics;
      throw new Error('MaterialX shaders did not compile: ' +
                      (d ? (d.vertexShader.log + ' ' + d.fragmentShader.log + ' ' + d.programLog) : 'no program'));
    }
  });
  await post('/info', JSON.stringify({
    three: THREE.REVISION, material_type: 'RawShaderMaterial (MaterialX ESSL)',
    ...glInfo(renderer) }), 'application/json');
  await post('/result', pixels.buffer, 'application/octet-stream');
}

main().catch((e) => post('/error', String(e && e.stack ? e.stack : e), 'text/plain'));
