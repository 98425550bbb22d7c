// The 3D view: a baked (or preview) GLB in three.js, orbitable, drawn only when something changed.
// Three ways to colour it, all from the file the service writes (README, "GLB out"):
//   baked     - the material as loaded: unlit, base colour x COLOR_0 (= exposure x radiosity up to
//               the knee of the file's tone curve, rolled off above it);
//   radiosity - the linear _RADIOSITY attribute times an exposure the user sets, its highlights
//               rolled off by the file's own tone curve (asset.extras.hemibake.tone);
//   base      - the base colour alone (factor and texture), without light.
// and the wireframe of the adaptive mesh (every leaf element's triangles) on top.
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { DRACOLoader } from 'three/addons/loaders/DRACOLoader.js';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

const kFov = 45;
const kBackground = 0x303036;

const kRadiosityVertex = /* glsl */ `
attribute vec3 _radiosity;
varying vec3 vRadiosity;
void main() {
  vRadiosity = _radiosity;
  gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0);
}`;

// The tone curve COLOR_0 was written with (README, "GLB out"): linear up to the knee, then a
// logarithmic shoulder that reaches 1 at the white point, applied to the mean of the channels with
// the hue kept; a file written with tone=clamp (or before the curve) clips each channel instead.
// At 0 EV no lit surface's radiosity reaches the white point (radiosity is base colour x light), so
// a bright pool rolls off here as in the baked view instead of clipping to white; more exposure
// pushes it up the shoulder.
const kRadiosityFragment = /* glsl */ `
uniform float exposure;
uniform bool shoulder;
uniform float knee;
uniform float white;
uniform float scale;
varying vec3 vRadiosity;
void main() {
  vec3 light = vRadiosity * exposure;
  float m = (light.r + light.g + light.b) / 3.0;
  if (shoulder && m > knee) {
    float f = m >= white || scale <= 0.0 ? 1.0 : knee + scale * log(1.0 + (m - knee) / scale);
    light *= min(f, 1.0) / m;
  }
  gl_FragColor = vec4(clamp(light, 0.0, 1.0), 1.0);
  #include <colorspace_fragment>
}`;

// The file's tone curve, for the shader: an older file, or one baked with tone=clamp, clips.
function toneOf(json) {
  const t = json?.asset?.extras?.hemibake?.tone;
  const knee = Number(t?.knee), white = Number(t?.white), scale = Number(t?.scale);
  if (t?.curve !== 'shoulder' || !(knee > 0) || !(white >= knee) || !(scale >= 0)) {
    return { shoulder: false, knee: 1, white: 1, scale: 0 };
  }
  return { shoulder: true, knee, white, scale };
}

export class Viewer {
  constructor(canvas) {
    this.canvas = canvas;
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: true });
    // A 4K screen at full density quadruples the fill cost for little gain on flat-shaded bakes.
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    this.renderer.setClearColor(kBackground, 1);
    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(kFov, 1, 0.01, 100);
    this.controls = new OrbitControls(this.camera, canvas);
    this.controls.listenToKeyEvents(canvas); // arrow keys pan when the canvas has the focus
    this.controls.addEventListener('change', () => this.requestDraw());
    this.model = null;
    this.mode = 'baked';
    this.wireframe = false;
    this.exposure = 1; // the file's exposure times 2^stops
    this.stops = 0;
    this.fileExposure = 1;
    this.framedFor = null; // the job whose model set the camera: its next models keep the view
    this.hasRadiosity = false;
    const draco = new DRACOLoader();
    draco.setDecoderPath('/assets/three/examples/jsm/libs/draco/');
    this.loader = new GLTFLoader();
    this.loader.setDRACOLoader(draco);
    new ResizeObserver(() => this.resize()).observe(canvas);
    this.resize();
  }

  resize() {
    const width = this.canvas.clientWidth;
    const height = this.canvas.clientHeight;
    if (width === 0 || height === 0) return;
    this.renderer.setSize(width, height, false);
    this.camera.aspect = width / height;
    this.camera.updateProjectionMatrix();
    this.requestDraw();
  }

  requestDraw() {
    if (this.pending) return;
    this.pending = true;
    requestAnimationFrame(() => {
      this.pending = false;
      this.renderer.render(this.scene, this.camera);
      this.drawn?.();
    });
  }

  /** Shows a GLB (ArrayBuffer). `key` names what it shows (a job): a new key frames the camera. */
  async show(buffer, key) {
    const gltf = await this.loader.parseAsync(buffer, '');
    const root = gltf.scene;
    this.fileExposure = Number(gltf.parser.json?.asset?.extras?.hemibake?.exposure) || 1;
    const tone = toneOf(gltf.parser.json);
    this.hasRadiosity = false;
    root.traverse((object) => {
      if (!object.isMesh) return;
      const baked = object.material;
      object.userData.materials = {
        baked,
        base: new THREE.MeshBasicMaterial({ color: baked.color, map: baked.map, side: baked.side }),
      };
      if (object.geometry.getAttribute('_radiosity')) {
        this.hasRadiosity = true;
        object.userData.materials.radiosity = new THREE.ShaderMaterial({
          uniforms: {
            exposure: { value: 1 },
            shoulder: { value: tone.shoulder },
            knee: { value: tone.knee },
            white: { value: tone.white },
            scale: { value: tone.scale },
          },
          vertexShader: kRadiosityVertex,
          fragmentShader: kRadiosityFragment,
          side: baked.side,
        });
      }
      for (const m of Object.values(object.userData.materials)) {
        // The solid sits a little behind the wireframe drawn on it.
        m.polygonOffset = true;
        m.polygonOffsetFactor = 1;
        m.polygonOffsetUnits = 1;
      }
      const lines = new THREE.LineSegments(
        new THREE.WireframeGeometry(object.geometry),
        new THREE.LineBasicMaterial({ color: 0x101014, transparent: true, opacity: 0.45 }));
      lines.visible = false;
      lines.userData.wireframe = true;
      object.add(lines);
    });
    const old = this.model;
    this.model = root;
    this.scene.add(root);
    if (old) {
      this.scene.remove(old);
      dispose(old);
    }
    this.apply();
    if (key !== this.framedFor) {
      this.frame();
      this.framedFor = key;
    }
    this.requestDraw();
    let triangles = 0;
    root.traverse((o) => {
      if (o.isMesh) triangles += (o.geometry.index ? o.geometry.index.count : o.geometry.getAttribute('position').count) / 3;
    });
    return { triangles, exposure: this.fileExposure, radiosity: this.hasRadiosity };
  }

  clear() {
    if (this.model) {
      this.scene.remove(this.model);
      dispose(this.model);
      this.model = null;
    }
    this.framedFor = null;
    this.requestDraw();
  }

  setMode(mode) {
    this.mode = mode;
    this.apply();
  }

  setWireframe(on) {
    this.wireframe = on;
    this.apply();
  }

  /** Exposure for the radiosity view, in stops relative to the file's own. */
  setStops(stops) {
    this.stops = stops;
    this.apply();
  }

  apply() {
    this.exposure = this.fileExposure * 2 ** this.stops;
    this.model?.traverse((object) => {
      if (object.userData.wireframe) object.visible = this.wireframe;
      const materials = object.userData.materials;
      if (!materials) return;
      object.material = materials[this.mode] ?? materials.baked;
      if (materials.radiosity) materials.radiosity.uniforms.exposure.value = this.exposure;
    });
    this.requestDraw();
  }

  /**
   * Looks at the model's bounding box from outside, raised by 20 degrees, from the nearest distance
   * at which the whole box fits the view (5 % margin). Of eight directions around it, one through
   * which a ray from the box's centre leaves the scene without meeting a surface is preferred (a
   * room's open side: a Cornell box is seen through its missing wall); among those, or if none is
   * open, the one facing the most surface (front faces towards the camera).
   */
  frame() {
    if (!this.model) return;
    this.model.updateMatrixWorld(true);
    const box = new THREE.Box3().setFromObject(this.model);
    if (box.isEmpty()) return;
    const centre = box.getCenter(new THREE.Vector3());
    const elevation = THREE.MathUtils.degToRad(20);
    const candidates = [];
    for (let i = 0; i < 8; ++i) {
      const a = Math.PI + (i * Math.PI) / 4; // from -z first: the glTF convention's front
      candidates.push(new THREE.Vector3(Math.sin(a) * Math.cos(elevation), Math.sin(elevation), Math.cos(a) * Math.cos(elevation)));
    }
    const { facing, open } = survey(this.model, centre, candidates);
    let best = 0;
    const score = (i) => facing[i] + (open[i] ? 1e30 : 0);
    candidates.forEach((_, i) => { if (score(i) > score(best) * 1.02) best = i; });
    const dir = candidates[best];

    const camera = this.camera;
    const right = new THREE.Vector3(0, 1, 0).cross(dir).normalize();
    const up = dir.clone().cross(right);
    const tanV = Math.tan(THREE.MathUtils.degToRad(kFov) / 2) / 1.05;
    const tanH = tanV * camera.aspect;
    let distance = 0;
    for (let corner = 0; corner < 8; ++corner) {
      const p = new THREE.Vector3(corner & 1 ? box.max.x : box.min.x, corner & 2 ? box.max.y : box.min.y,
        corner & 4 ? box.max.z : box.min.z).sub(centre);
      const z = p.dot(dir);
      distance = Math.max(distance, z + Math.abs(p.dot(right)) / tanH, z + Math.abs(p.dot(up)) / tanV);
    }
    const radius = box.getSize(new THREE.Vector3()).length() / 2;
    camera.position.copy(centre).addScaledVector(dir, distance);
    camera.near = Math.max(distance * 1e-3, (distance - radius) * 0.5);
    camera.far = distance + radius * 4;
    camera.updateProjectionMatrix();
    this.controls.target.copy(centre);
    this.controls.update();
    this.requestDraw();
  }
}

// For each direction: the area of the triangles whose front faces it (double-sided ones count
// either way; from a sample of at most 20 000 triangles per mesh), and whether a ray from `origin`
// along it meets no triangle at all (every triangle is tested, either side).
function survey(root, origin, directions) {
  const facing = directions.map(() => 0);
  const open = directions.map(() => true);
  const a = new THREE.Vector3();
  const b = new THREE.Vector3();
  const c = new THREE.Vector3();
  const e1 = new THREE.Vector3();
  const e2 = new THREE.Vector3();
  const n = new THREE.Vector3();
  const p = new THREE.Vector3();
  const t = new THREE.Vector3();
  const q = new THREE.Vector3();
  root.traverse((object) => {
    if (!object.isMesh) return;
    const position = object.geometry.getAttribute('position');
    const index = object.geometry.index;
    const count = (index ? index.count : position.count) / 3;
    const stride = Math.max(1, Math.floor(count / 20000));
    const twoSided = object.material.side === THREE.DoubleSide;
    for (let k = 0; k < count; ++k) {
      const v = (j) => (index ? index.getX(3 * k + j) : 3 * k + j);
      a.fromBufferAttribute(position, v(0)).applyMatrix4(object.matrixWorld);
      b.fromBufferAttribute(position, v(1)).applyMatrix4(object.matrixWorld);
      c.fromBufferAttribute(position, v(2)).applyMatrix4(object.matrixWorld);
      e1.subVectors(b, a);
      e2.subVectors(c, a);
      if (k % stride === 0) {
        n.crossVectors(e1, e2); // counter-clockwise front, length twice the area
        directions.forEach((d, i) => {
          const f = n.dot(d);
          facing[i] += twoSided ? Math.abs(f) : Math.max(0, f);
        });
      }
      // Moeller-Trumbore: does the ray origin + s d (s > 0) cross the triangle?
      t.subVectors(origin, a);
      directions.forEach((d, i) => {
        if (!open[i]) return;
        p.crossVectors(d, e2);
        const det = e1.dot(p);
        if (Math.abs(det) < 1e-12) return;
        const u = t.dot(p) / det;
        if (u < 0 || u > 1) return;
        q.crossVectors(t, e1);
        const w = d.dot(q) / det;
        if (w < 0 || u + w > 1) return;
        if (e2.dot(q) / det > 0) open[i] = false;
      });
    }
  });
  return { facing, open };
}

function dispose(root) {
  root.traverse((object) => {
    object.geometry?.dispose();
    const materials = object.userData.materials ? Object.values(object.userData.materials) : [object.material];
    for (const m of materials) {
      if (!m) continue;
      m.map?.dispose();
      m.dispose();
    }
  });
}
