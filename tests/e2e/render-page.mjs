// Runs in Chromium, served by render.mjs: loads /model.glb with three.js (GLTFLoader + DRACOLoader),
// frames it, renders one frame and leaves the outcome in window.__result or window.__error.
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { DRACOLoader } from 'three/addons/loaders/DRACOLoader.js';

const config = window.__config;

// The default view looks at the bounding box's centre (or --target) from the +z side, raised by
// this angle so that a floor is not seen edge-on.
const kElevation = THREE.MathUtils.degToRad(15);
const kFov = 45; // vertical, degrees

function frame(box, aspect) {
  const camera = new THREE.PerspectiveCamera(kFov, aspect);
  const centre = box.isEmpty() ? new THREE.Vector3() : box.getCenter(new THREE.Vector3());
  const radius = box.isEmpty() ? 1 : Math.max(box.getSize(new THREE.Vector3()).length() / 2, 1e-6);
  const target = config.target ? new THREE.Vector3(...config.target) : centre;
  if (config.camera) {
    camera.position.set(...config.camera);
  } else {
    // Nearest distance along the view direction at which all eight corners of the box are inside
    // both fields of view (with a 5% margin).
    const dir = new THREE.Vector3(0, Math.sin(kElevation), Math.cos(kElevation)); // towards camera
    const right = new THREE.Vector3(0, 1, 0).cross(dir).normalize();
    const up = dir.clone().cross(right);
    const tanV = Math.tan(THREE.MathUtils.degToRad(kFov) / 2) / 1.05;
    const tanH = tanV * aspect;
    let distance = radius;
    if (!box.isEmpty()) {
      for (let corner = 0; corner < 8; ++corner) {
        const p = new THREE.Vector3(
          corner & 1 ? box.max.x : box.min.x, corner & 2 ? box.max.y : box.min.y,
          corner & 4 ? box.max.z : box.min.z).sub(target);
        const z = p.dot(dir);
        distance = Math.max(distance, z + Math.abs(p.dot(right)) / tanH, z + Math.abs(p.dot(up)) / tanV);
      }
    }
    camera.position.copy(target).addScaledVector(dir, distance);
  }
  const view = target.clone().sub(camera.position);
  if (view.lengthSq() === 0) throw new Error('--camera and --target are the same point');
  // lookAt needs an up vector that is not parallel to the view direction.
  if (view.clone().normalize().cross(camera.up).lengthSq() < 1e-6) camera.up.set(0, 0, -1);
  camera.lookAt(target);
  const far = camera.position.distanceTo(centre) + radius;
  camera.near = Math.max(far * 1e-4, (far - 2 * radius) * 0.9);
  camera.far = far * 1.1;
  camera.updateProjectionMatrix();
  return { camera, target };
}

// Statistics of the pixels the model covers (alpha > 0; the background is cleared to alpha 0),
// in 8-bit sRGB as displayed: mean colour, the root mean square over pixels and channels of the
// difference from that mean, the number of distinct colours, and the covered fraction of the image.
function pixelStats(gl, width, height) {
  const data = new Uint8Array(width * height * 4);
  gl.readPixels(0, 0, width, height, gl.RGBA, gl.UNSIGNED_BYTE, data);
  const sum = [0, 0, 0];
  const sumSq = [0, 0, 0];
  const distinct = new Set();
  let covered = 0;
  for (let i = 0; i < data.length; i += 4) {
    if (data[i + 3] === 0) continue;
    ++covered;
    for (let c = 0; c < 3; ++c) {
      sum[c] += data[i + c];
      sumSq[c] += data[i + c] * data[i + c];
    }
    distinct.add((data[i] << 16) | (data[i + 1] << 8) | data[i + 2]);
  }
  const mean = sum.map((s) => (covered ? s / covered : 0));
  const variance = covered ? sumSq.reduce((v, s, c) => v + s / covered - mean[c] * mean[c], 0) / 3 : 0;
  const round = (x) => Math.round(x * 1000) / 1000;
  return {
    mean: mean.map(round),
    stddev: round(Math.sqrt(Math.max(0, variance))),
    distinct: distinct.size,
    nonBackground: round(covered / (width * height)),
  };
}

async function main() {
  const started = performance.now();
  const { width, height } = config;
  const canvas = document.getElementById('canvas');
  const renderer = new THREE.WebGLRenderer({
    canvas, antialias: false, alpha: true, premultipliedAlpha: false, preserveDrawingBuffer: true,
  });
  renderer.setPixelRatio(1);
  renderer.setSize(width, height, false);
  renderer.outputColorSpace = THREE.SRGBColorSpace;
  renderer.setClearColor(new THREE.Color(config.background), 0);

  const draco = new DRACOLoader().setDecoderPath('/three/examples/jsm/libs/draco/');
  const loader = new GLTFLoader().setDRACOLoader(draco);
  let gltf;
  try {
    gltf = await loader.loadAsync('/model.glb');
  } finally {
    draco.dispose();
  }
  const scene = gltf.scene ?? gltf.scenes[0];
  if (!scene) throw new Error('the file has no scene');

  let meshes = 0;
  let triangles = 0;
  scene.traverse((o) => {
    if (!o.isMesh) return;
    ++meshes;
    const g = o.geometry;
    triangles += Math.floor((g.index ? g.index.count : g.attributes.position.count) / 3);
  });

  const box = new THREE.Box3().setFromObject(scene);
  const { camera, target } = frame(box, width / height);
  renderer.render(scene, camera);

  const gl = renderer.getContext();
  const debugInfo = gl.getExtension('WEBGL_debug_renderer_info');
  return {
    loaded: true,
    meshes,
    triangles,
    pixels: pixelStats(gl, width, height),
    camera: { position: camera.position.toArray(), target: target.toArray(), fov: camera.fov },
    bounds: box.isEmpty() ? null : { min: box.min.toArray(), max: box.max.toArray() },
    size: [width, height],
    webgl: gl.getParameter(debugInfo ? debugInfo.UNMASKED_RENDERER_WEBGL : gl.RENDERER),
    pageMs: Math.round(performance.now() - started),
  };
}

// Loaders reject with Errors, strings or plain objects (DRACOLoader's worker sends {error: "..."}).
function describe(error) {
  if (error instanceof Error) return error.stack ?? error.message;
  if (typeof error === 'string') return error;
  if (typeof error?.error === 'string') return error.error;
  if (typeof error?.message === 'string') return error.message;
  try { return JSON.stringify(error); } catch { return String(error); }
}

main().then(
  (result) => { window.__result = result; },
  (error) => { window.__error = describe(error) || 'unknown error'; },
);
