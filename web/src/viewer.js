// One 3D view: the renderer, an orbiting camera with the standard views, the skin (picked with
// three-mesh-bvh) and an overlay group for the plan, its handles and the sutures. Draws on demand.
import {
  AmbientLight,
  Box3,
  Color,
  DirectionalLight,
  Group,
  HemisphereLight,
  PerspectiveCamera,
  Raycaster,
  Scene,
  Sphere,
  Vector2,
  Vector3,
  WebGLRenderer,
} from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
import { acceleratedRaycast, computeBoundsTree, disposeBoundsTree } from 'three-mesh-bvh';

// three-mesh-bvh: BVH-accelerated raycasts on every mesh that has a bounds tree.
import { BufferGeometry, Mesh } from 'three';
BufferGeometry.prototype.computeBoundsTree = computeBoundsTree;
BufferGeometry.prototype.disposeBoundsTree = disposeBoundsTree;
Mesh.prototype.raycast = acceleratedRaycast;

// Directions from the head's centre to the camera for the standard views (glTF frame: x = the
// patient's left, y = superior, z = anterior) and the camera's up.
const kViews = {
  front: { dir: [0, 0, 1], up: [0, 1, 0] },
  left: { dir: [1, 0, 0], up: [0, 1, 0] },
  right: { dir: [-1, 0, 0], up: [0, 1, 0] },
  top: { dir: [0, 1, 0], up: [0, 0, -1] },
  oblique: { dir: [0.7, 0.35, 0.7], up: [0, 1, 0] },
};

// Whether WebGL runs in software (SwiftShader, llvmpipe): there multisampling costs about as much
// as the rest of the frame (bench/bench_planner_page.mjs: 1.0 s -> 0.4-0.6 s from the result's
// arrival to its frame drawn, on this 2-core machine), so it is left off.
function isSoftwareGl() {
  try {
    const gl = document.createElement('canvas').getContext('webgl2') ??
      document.createElement('canvas').getContext('webgl');
    if (!gl) return false;
    const info = gl.getExtension('WEBGL_debug_renderer_info');
    const name = String(gl.getParameter(info ? info.UNMASKED_RENDERER_WEBGL : gl.RENDERER));
    gl.getExtension('WEBGL_lose_context')?.loseContext();
    return /swiftshader|llvmpipe|software/i.test(name);
  } catch {
    return false;
  }
}
const kAntialias = !isSoftwareGl();

export class Viewer {
  constructor(container) {
    this.container = container;
    this.renderer = new WebGLRenderer({ antialias: kAntialias, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio, 2));
    this.renderer.setClearColor(new Color(0x1d2327));
    container.appendChild(this.renderer.domElement);
    this.renderer.domElement.tabIndex = 0;
    this.scene = new Scene();
    this.camera = new PerspectiveCamera(35, 1, 0.005, 10);
    this.scene.add(this.camera);
    this.scene.add(new HemisphereLight(0xffffff, 0x555566, 1.2));
    this.scene.add(new AmbientLight(0xffffff, 0.25));
    const key = new DirectionalLight(0xffffff, 1.6);
    key.position.set(0.3, 0.5, 1);
    this.camera.add(key);  // a head lamp: the lit side is always the one looked at
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.addEventListener('change', () => this.requestRender());
    this.overlay = new Group();
    this.scene.add(this.overlay);
    this.guides = new Group();  // drawn beside the overlay: the skin lines
    this.scene.add(this.guides);
    this.skin = null;
    this.raycaster = new Raycaster();
    this.raycaster.firstHitOnly = true;
    this.centre = new Vector3();
    this.radius = 0.12;
    this.listeners = [];
    new ResizeObserver(() => this.resize()).observe(container);
    this.resize();
  }

  resize() {
    const w = Math.max(1, this.container.clientWidth), h = Math.max(1, this.container.clientHeight);
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.requestRender();
  }

  requestRender() {
    if (this.pending) return;
    this.pending = requestAnimationFrame(() => {
      this.pending = 0;
      this.renderer.render(this.scene, this.camera);
      for (const f of [...this.listeners]) f();
    });
  }

  /** Resolves once the next frame is drawn (asking for one): reading a pixel back waits until
   * the GL has finished drawing it, not only until it was asked to. */
  nextFrame() {
    return new Promise((resolve) => {
      const once = () => {
        this.listeners = this.listeners.filter((f) => f !== once);
        const gl = this.renderer.getContext();
        gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, new Uint8Array(4));
        resolve();
      };
      this.listeners.push(once);
      this.requestRender();
    });
  }

  /** Calls `f` after each frame drawn (e.g. to keep another view in step). */
  onRender(f) {
    this.listeners.push(f);
  }

  /** Shows `mesh` as the skin (replacing the one shown); with `pickable`, builds its BVH so that
   * clicks find their point on it (the model's skin; a simulation's is only looked at). */
  setSkin(mesh, { pickable = false } = {}) {
    if (this.skin) this.scene.remove(this.skin);
    this.skin = mesh;
    if (pickable) {
      this.pickTarget = mesh;  // kept while another skin is shown: clicks land on the model's
      if (!mesh.geometry.boundsTree) mesh.geometry.computeBoundsTree();
    }
    this.scene.add(mesh);
    const box = new Box3().setFromObject(mesh);
    const sphere = box.getBoundingSphere(new Sphere());
    const first = !this.framed;
    this.centre.copy(sphere.center);
    this.radius = sphere.radius;
    if (first) {
      this.framed = true;
      this.setView('front');
    }
    this.requestRender();
  }

  /** One of the standard views (front, left, right, top, oblique), the whole head in view. */
  setView(name) {
    const v = kViews[name];
    if (!v) return;
    const dir = new Vector3(...v.dir).normalize();
    this.lookFrom(this.centre, dir, this.radius * 2.9, new Vector3(...v.up));
  }

  /** Looks at `target` (glTF frame) from along `dir`, `distance` away (m). */
  lookFrom(target, dir, distance, up = new Vector3(0, 1, 0)) {
    this.controls.target.copy(target);
    this.camera.up.copy(up);
    this.camera.position.copy(target).addScaledVector(dir.clone().normalize(), distance);
    this.camera.lookAt(target);
    this.controls.update();
    this.requestRender();
  }

  /** The camera of `other` copied into this view (two views in step). */
  copyCamera(other) {
    this.camera.position.copy(other.camera.position);
    this.camera.up.copy(other.camera.up);
    this.controls.target.copy(other.controls.target);
    this.camera.lookAt(this.controls.target);
    this.controls.update();
    this.requestRender();
  }

  /** The objects under the pointer event `e` among `objects` (nearest first). */
  hits(e, objects, recursive = false) {
    const r = this.renderer.domElement.getBoundingClientRect();
    const ndc = new Vector2(((e.clientX - r.left) / r.width) * 2 - 1,
      -((e.clientY - r.top) / r.height) * 2 + 1);
    this.raycaster.setFromCamera(ndc, this.camera);
    return this.raycaster.intersectObjects(objects, recursive);
  }

  /** The point of the pickable skin (the model's) under the pointer event `e` (glTF frame), or
   * null. */
  pickSkin(e) {
    if (!this.pickTarget) return null;
    const hit = this.hits(e, [this.pickTarget])[0];
    return hit ? hit.point : null;
  }

  /** Replaces the guides' objects (the skin lines), which the overlay's changes leave alone. */
  setGuides(objects) {
    this.guides.clear();
    for (const o of objects) this.guides.add(o);
    this.requestRender();
  }

  /** Replaces the overlay's objects. */
  setOverlay(objects) {
    this.overlay.clear();
    for (const o of objects) this.overlay.add(o);
    this.requestRender();
  }
}
