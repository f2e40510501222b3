// What the round-trip pages share: posting results to the local server, a WebGL 2 renderer
// with float render targets, the scene's camera, and one render read back as linear floats.
import * as THREE from 'three';

export async function post(path, body, type) {
  await fetch(path, { method: 'POST', headers: { 'Content-Type': type }, body });
}

// A W x H canvas and renderer: no tone mapping, transparent black clear colour, float targets
// required. `options` adds WebGLRenderer options.
export function floatRenderer(W, H, options = {}) {
  const canvas = document.createElement('canvas');
  canvas.width = W; canvas.height = H;
  document.body.appendChild(canvas);
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: false, alpha: true, ...options });
  renderer.setPixelRatio(1);
  renderer.setSize(W, H, false);
  renderer.toneMapping = THREE.NoToneMapping;
  renderer.setClearColor(0x000000, 0.0);
  if (!renderer.extensions.has('EXT_color_buffer_float')) {
    throw new Error('WebGL 2 without EXT_color_buffer_float: no float render target');
  }
  return renderer;
}

// The camera of the scene description (/scene.json): position, up, target, vertical fov.
export function sceneCamera(scene, W, H) {
  const cam = new THREE.PerspectiveCamera(scene.camera.fov, W / H, 0.1, 100.0);
  cam.position.fromArray(scene.camera.origin);
  cam.up.fromArray(scene.camera.up);
  cam.lookAt(new THREE.Vector3().fromArray(scene.camera.target));
  cam.updateMatrixWorld(true);
  cam.updateProjectionMatrix();
  return cam;
}

// `world` seen by `cam` in a W x H RGBA float target; `afterRender()` runs before the read
// back (a check of the compiled program). Linear RGBA, rows bottom to top as WebGL reads them.
export function renderFloat(renderer, world, cam, W, H, afterRender = null) {
  const target = new THREE.WebGLRenderTarget(W, H, {
    type: THREE.FloatType, format: THREE.RGBAFormat, depthBuffer: true,
    minFilter: THREE.NearestFilter, magFilter: THREE.NearestFilter, samples: 0 });
  renderer.setRenderTarget(target);
  renderer.clear();
  renderer.render(world, cam);
  if (afterRender) afterRender();
  const pixels = new Float32Array(W * H * 4);
  renderer.readRenderTargetPixels(target, 0, 0, W, H, pixels);
  renderer.setRenderTarget(null);
  return pixels;
}

// The WebGL renderer's name and version.
export function glInfo(renderer) {
  const gl = renderer.getContext();
  const dbg = gl.getExtension('WEBGL_debug_renderer_info');
  return { gl_renderer: dbg ? gl.getParameter(dbg.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER),
           gl_version: gl.getParameter(gl.VERSION) };
}

// An environment map served as binary (`url`): width x height RGBA little-endian half floats,
// row 0 at texture v = 0 (the Python side put it in the convention of the shader that reads
// it). Repeats around u, clamps at the poles; with `mipmaps`, WebGL's own mip chain and
// trilinear filtering (MaterialX's filtered importance sampling reads mip levels), else
// bilinear filtering of level 0 (three's PMREMGenerator makes its own levels).
export async function environmentTexture(url, width, height, mipmaps = false) {
  const response = await fetch(url);
  if (!response.ok) throw new Error('environment map: ' + url + ' answered ' + response.status);
  const texels = new Uint16Array(await response.arrayBuffer());
  if (texels.length !== 4 * width * height) {
    throw new Error('environment map: expected ' + 4 * width * height + ' half floats, got ' +
                    texels.length);
  }
  const tex = new THREE.DataTexture(texels, width, height, THREE.RGBAFormat, THREE.HalfFloatType);
  tex.mapping = THREE.EquirectangularReflectionMapping;
  tex.colorSpace = THREE.LinearSRGBColorSpace;
  tex.wrapS = THREE.RepeatWrapping;
  tex.wrapT = THREE.ClampToEdgeWrapping;
  tex.magFilter = THREE.LinearFilter;
  tex.minFilter = mipmaps ? THREE.LinearMipmapLinearFilter : THREE.LinearFilter;
  tex.generateMipmaps = mipmaps;
  tex.flipY = false;
  tex.needsUpdate = true;
  return tex;
}
