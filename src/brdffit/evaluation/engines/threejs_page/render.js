// Renders material 0 of /material.gltf on a sphere in the scene of /scene.json with three.js
// (MeshPhysicalMaterial, WebGL 2; a light, or an environment map from /environment.bin as
// scene.environment) into a float render target, and posts the linear RGBA
// pixels (Float32, rows bottom to top as WebGL reads them) to /result. Errors go to /error.
// The scene description is data (JSON), never code: see brdffit.evaluation.engines.threejs.
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { environmentTexture, floatRenderer, glInfo, post, renderFloat, sceneCamera } from './common.js';

async function main() {
  const scene = await (await fetch('/scene.json')).json();
  const W = scene.width, H = scene.height;
  const renderer = floatRenderer(W, H, { preserveDrawingBuffer: true });

  const loader = new GLTFLoader();
  const gltf = await loader.loadAsync('/material.gltf');
  const material = await gltf.parser.getDependency('material', scene.material_index);
  if (!material.isMeshStandardMaterial) {
    throw new Error('material ' + scene.material_index + ' is a ' + material.type +
                    ', expected a MeshStandardMaterial or MeshPhysicalMaterial');
  }

  const world = new THREE.Scene();
  world.background = null;
  const sphere = new THREE.Mesh(
    new THREE.SphereGeometry(1.0, scene.sphere_segments[0], scene.sphere_segments[1]), material);
  world.add(sphere);

  const cam = sceneCamera(scene, W, H);

  const L = scene.light;
  let envInfo = null;
  if (L.type === 'directional') {
    // three's DirectionalLight shines from its position towards its target; its intensity is
    // the irradiance on a surface facing it (physically based lights, no pi factor)
    const light = new THREE.DirectionalLight(0xffffff, L.irradiance);
    light.position.fromArray(L.direction.map((x) => -x));
    light.target.position.set(0, 0, 0);
    world.add(light); world.add(light.target);
  } else if (L.type === 'point') {
    // PointLight(colour, intensity, distance = 0: no cut-off, decay = 2: inverse square)
    const light = new THREE.PointLight(0xffffff, L.intensity, 0, 2);
    light.position.fromArray(L.position);
    world.add(light);
  } else if (L.type === 'environment') {
    // the map alone, through three's image-based lighting: PMREMGenerator prefilters it
    // (GGX levels from a mirror to roughness 1); no light, no background
    const map = await environmentTexture('/environment.bin', L.width, L.height);
    const pmrem = new THREE.PMREMGenerator(renderer);
    const target = pmrem.fromEquirectangular(map);
    world.environment = target.texture;
    envInfo = { pmrem_cube_size: target.width, pmrem_levels: target.texture.mipmaps.length,
                map: [L.width, L.height] };
    pmrem.dispose();
    map.dispose();
  } else {
    throw new Error('unknown light type ' + L.type);
  }

  const pixels = renderFloat(renderer, world, cam, W, H);

  const info = {
    three: THREE.REVISION, material_type: material.type, ...glInfo(renderer), environment: envInfo,
    material: { color: material.color.toArray(), metalness: material.metalness,
                roughness: material.roughness, ior: material.ior,
                specularIntensity: material.specularIntensity,
                specularColor: material.specularColor ? material.specularColor.toArray() : null,
                clearcoat: material.clearcoat, clearcoatRoughness: material.clearcoatRoughness,
                anisotropy: material.anisotropy },
  };
  await post('/info', JSON.stringify(info), 'application/json');
  await post('/result', pixels.buffer, 'application/octet-stream');
}

main().catch((e) => post('/error', String(e && e.stack ? e.stack : e), 'text/plain'));
