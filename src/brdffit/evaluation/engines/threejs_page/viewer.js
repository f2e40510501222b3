// The report's live viewer: each element with a data-brdffit-viewer attribute (the id of a
// <script type="application/json"> holding the viewer's data, written by
// brdffit.evaluation.report_viewer) fills its canvas where the glTF material of a fit, on a unit
// sphere, is lit by the page's environment map (image-based lighting of three.js: the map
// prefiltered by PMREMGenerator), seen by the scenes' camera and tone-mapped as the page's
// images, (1 - 2^(-exposure x))^(1/gamma), with orbit controls. Bundled into a classic script
// (vendor/viewer.bundle.js) so that it runs from file://, where module scripts and fetch are
// blocked.
// All data arrive as JSON and reach the page as text (textContent), never as code or markup.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';

const HALF_ONE = 0x3c00;   // 1.0 as an IEEE half float: the alpha of the environment map

function base64Bytes(s) {
  const bin = atob(s);
  const out = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; i++) out[i] = bin.charCodeAt(i);
  return out;
}

// The environment map: lat-long RGB half floats (little-endian), rows from the nadir up and
// columns in three's equirectangular convention (report_viewer converts Mitsuba's).
function environmentTexture(env) {
  const rgb = new Uint16Array(base64Bytes(env.rgb_f16).buffer);
  const n = env.width * env.height;
  if (rgb.length !== 3 * n) {
    throw new Error('environment map: expected ' + 3 * n + ' values, got ' + rgb.length);
  }
  const rgba = new Uint16Array(4 * n);
  for (let i = 0; i < n; i++) {
    rgba[4 * i] = rgb[3 * i]; rgba[4 * i + 1] = rgb[3 * i + 1]; rgba[4 * i + 2] = rgb[3 * i + 2];
    rgba[4 * i + 3] = HALF_ONE;
  }
  const tex = new THREE.DataTexture(rgba, env.width, env.height, THREE.RGBAFormat,
                                    THREE.HalfFloatType);
  tex.mapping = THREE.EquirectangularReflectionMapping;
  tex.colorSpace = THREE.LinearSRGBColorSpace;
  tex.magFilter = THREE.LinearFilter;
  tex.minFilter = THREE.LinearFilter;
  tex.generateMipmaps = false;
  tex.needsUpdate = true;
  return tex;
}

// The page's tone map as three's custom tone mapping (toneMappingExposure is the exposure).
function useReportToneMap(gamma) {
  const g = Number(gamma);
  if (!(g > 0 && isFinite(g))) throw new Error('tone map: gamma must be a positive number');
  const chunks = THREE.ShaderChunk;
  chunks.tonemapping_pars_fragment = chunks.tonemapping_pars_fragment.replace(
    /vec3 CustomToneMapping\( vec3 color \) \{[^}]*\}/,
    'vec3 CustomToneMapping( vec3 color ) { return pow( max( vec3( 1.0 ) - exp2( '
    + '- toneMappingExposure * max( color, vec3( 0.0 ) ) ), vec3( 0.0 ) ), vec3( '
    + (1.0 / g).toFixed(8) + ' ) ); }');
}

async function loadMaterial(doc) {
  const gltf = await new GLTFLoader().parseAsync(JSON.stringify(doc), '');
  const material = await gltf.parser.getDependency('material', 0);
  if (!material.isMeshStandardMaterial) throw new Error('the glTF material is a ' + material.type);
  return material;
}

function makeRenderer(canvas, data) {
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: true,
                                             preserveDrawingBuffer: true });
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  renderer.setSize(data.size, data.size, false);
  renderer.toneMapping = THREE.CustomToneMapping;
  renderer.toneMappingExposure = data.exposure;
  renderer.outputColorSpace = THREE.LinearSRGBColorSpace;   // the gamma is in the tone map
  renderer.setClearColor(0x000000, 1.0);                     // hidden emitter: black background
  return renderer;
}

function makeCamera(c) {
  const cam = new THREE.PerspectiveCamera(c.fov, 1.0, 0.1, 100.0);
  cam.position.fromArray(c.origin);
  cam.up.fromArray(c.up);
  cam.lookAt(new THREE.Vector3().fromArray(c.target));
  return cam;
}

function modelSelect(root, models, onChange) {
  const select = root.querySelector('select');
  models.forEach((m, i) => {
    const opt = document.createElement('option');
    opt.value = String(i);
    opt.textContent = m.name;
    select.appendChild(opt);
  });
  select.hidden = models.length < 2;
  select.addEventListener('change', () => onChange(Number(select.value)));
}

async function start(root) {
  const status = root.querySelector('.viewer-status');
  const data = JSON.parse(document.getElementById(root.dataset.brdffitViewer).textContent);
  useReportToneMap(data.gamma);
  const canvas = root.querySelector('canvas');
  const renderer = makeRenderer(canvas, data);
  const world = new THREE.Scene();
  const pmrem = new THREE.PMREMGenerator(renderer);
  world.environment = pmrem.fromEquirectangular(environmentTexture(data.environment)).texture;
  pmrem.dispose();
  const sphere = new THREE.Mesh(new THREE.SphereGeometry(1.0, 128, 64));
  world.add(sphere);
  const cam = makeCamera(data.camera);
  const controls = new OrbitControls(cam, canvas);
  controls.target.fromArray(data.camera.target);
  controls.update();
  const render = () => renderer.render(world, cam);
  controls.addEventListener('change', render);
  const show = async (i) => {
    sphere.material = await loadMaterial(data.models[i].gltf);
    render();
    root.dataset.viewerModel = data.models[i].name;
    root.querySelector('.viewer-model').textContent = 'glTF of ' + data.models[i].name;
    // asked for in the address (the browser test): the canvas as a PNG on the element
    if (location.hash === '#brdffit-viewer-image') {
      root.dataset.viewerImage = canvas.toDataURL('image/png');
    }
  };
  modelSelect(root, data.models, (i) => show(i).catch((e) => fail(root, status, e)));
  await show(0);
  status.textContent = 'three.js r' + THREE.REVISION + ': drag to orbit, scroll to zoom.';
  root.dataset.viewerStatus = 'ok';
}

function fail(root, status, e) {
  root.dataset.viewerStatus = 'error';
  status.textContent = 'Live viewer failed: ' + String(e && e.message ? e.message : e);
}

function startAll() {
  document.querySelectorAll('[data-brdffit-viewer]').forEach((root) => {
    const status = root.querySelector('.viewer-status');
    start(root).catch((e) => fail(root, status, e));
  });
}

if (document.readyState === 'loading') document.addEventListener('DOMContentLoaded', startAll);
else startAll();
