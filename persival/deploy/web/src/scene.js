// The three.js scene: bones from metadata.skeleton (the forearm group turns about the hinge),
// the five muscles as one indexed mesh whose buffers the model overwrites in place each frame.
import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
import { MuscleBuffers } from './mesh.js';

function boneGeometry(bone) {
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.Float32BufferAttribute(bone.points.flat(), 3));
  g.setIndex(bone.triangles.flat());
  g.computeVertexNormals();
  return g;
}

// A headlight that moves with the camera (whatever faces the viewer is lit, from any side the
// user turns to), a key light from above the camera's shoulder for shape, and a cool sky fill.
function lights(scene, camera) {
  scene.add(new THREE.HemisphereLight(0xdfe8ff, 0x2a2218, 0.9));
  const head = new THREE.DirectionalLight(0xffffff, 1.6);
  head.position.set(0, 0, 1);
  const key = new THREE.DirectionalLight(0xfff4e6, 1.4);
  key.position.set(0.6, 0.9, 0.5);
  for (const light of [head, key]) { light.target.position.set(0, 0, -1); camera.add(light, light.target); }
  scene.add(camera);
}

export class ArmScene {
  constructor(canvas, meta) {
    // Opaque, not preserved: the compositor neither blends the canvas over the page nor copies its
    // buffer every frame (docs/viewer.md, "Frame rate"). Antialiasing on request (?aa=1).
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: new URLSearchParams(location.search).get('aa') === '1',
      alpha: false, preserveDrawingBuffer: false });
    this.maxScale = Math.min(window.devicePixelRatio, 2);
    this.renderScale = this.maxScale;
    this.renderer.setPixelRatio(this.renderScale);
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0x0f1318);
    this.camera = new THREE.PerspectiveCamera(32, 1, 1, 10000);
    lights(this.scene, this.camera);
    // The model is z-up in mm (shoulder at the top); three.js is y-up: turn the arm once.
    this.root = new THREE.Group();
    this.root.rotation.x = -Math.PI / 2;
    this.scene.add(this.root);
    this.addBones(meta.skeleton);
    this.addMuscles(meta);
    this.frame(meta);
    this.camera.aspect = window.innerWidth / window.innerHeight;
    this.placeCamera();
    this.controls = new OrbitControls(this.camera, canvas);
    this.controls.target.copy(this.centre);
    this.controls.enableDamping = true;
    this.resize();
    window.addEventListener('resize', () => this.resize());
  }

  addBones(skeleton) {
    const material = new THREE.MeshLambertMaterial({ color: 0xd8cdb4 });
    const { centre, axis } = skeleton.hinge;
    this.hingeAxis = new THREE.Vector3(...axis).normalize();
    // centre + R (p - centre): the group sits at the centre, its children are shifted by -centre.
    this.forearm = new THREE.Group();
    this.forearm.position.set(...centre);
    this.root.add(this.forearm);
    for (const bone of skeleton.bones) {
      const mesh = new THREE.Mesh(boneGeometry(bone), material);
      if (bone.segment === 'forearm') {
        mesh.position.set(-centre[0], -centre[1], -centre[2]);
        this.forearm.add(mesh);
      } else {
        this.root.add(mesh);
      }
    }
  }

  addMuscles(meta) {
    const reference = new Float32Array(meta.reference_points.flat());
    const index = new Uint32Array(meta.triangles.flat());
    this.buffers = new MuscleBuffers(reference, index, meta.surfaces.map((s) => [s.node_start, s.node_count]));
    const g = new THREE.BufferGeometry();
    this.attr = {
      position: new THREE.BufferAttribute(this.buffers.positions, 3).setUsage(THREE.DynamicDrawUsage),
      normal: new THREE.BufferAttribute(this.buffers.normals, 3).setUsage(THREE.DynamicDrawUsage),
      color: new THREE.BufferAttribute(this.buffers.colors, 3).setUsage(THREE.DynamicDrawUsage),
    };
    for (const [k, a] of Object.entries(this.attr)) g.setAttribute(k, a);
    g.setIndex(new THREE.BufferAttribute(index, 1));
    this.buffers.computeNormals();
    g.computeBoundingSphere();
    // Lambert: diffuse light only; Phong's highlights cost a fifth of a software renderer's frame at full resolution
    const material = new THREE.MeshLambertMaterial({ vertexColors: true });
    this.muscles = new THREE.Mesh(g, material);
    this.muscles.frustumCulled = false; // positions change every frame; no bounding-sphere refresh
    this.root.add(this.muscles);
  }

  frame(meta) {
    // Frame the forearm's whole sweep (hanging, mid-range, full flexion). setFromObject reads world
    // matrices, which three.js updates only when drawing.
    const [lo, hi] = meta.models.activation_angle?.range_deg ?? meta.elbow_angle_range_deg ?? [0, 120];
    this.points = [];
    for (const deg of [lo, (lo + hi) / 2, hi]) {
      this.setElbowAngle(deg);
      this.root.updateMatrixWorld(true);
      const box = new THREE.Box3().setFromObject(this.root);
      for (const x of [box.min.x, box.max.x]) for (const y of [box.min.y, box.max.y]) for (const z of [box.min.z, box.max.z]) {
        this.points.push(new THREE.Vector3(x, y, z));
      }
    }
    this.setElbowAngle(0);
    this.centre = new THREE.Box3().setFromPoints(this.points).getCenter(new THREE.Vector3());
    this.viewDirection = this.sideDirection(lo, hi);
    this.placeCamera();
  }

  // From the side: along the hinge axis, so flexion turns the forearm in the image plane; of the
  // two sides, the one where flexion lifts the forearm towards the right of the picture.
  sideDirection(lo, hi) {
    const axis = this.hingeAxis.clone().transformDirection(this.root.matrixWorld);
    const tip = (deg) => {
      this.setElbowAngle(deg);
      this.root.updateMatrixWorld(true);
      return new THREE.Box3().setFromObject(this.forearm).getCenter(new THREE.Vector3());
    };
    const travel = tip(hi).sub(tip(lo));
    this.setElbowAngle(0);
    const up = new THREE.Vector3(0, 1, 0);
    const right = new THREE.Vector3().crossVectors(axis.clone().negate(), up); // camera at +axis looks along -axis
    return travel.dot(right) >= 0 ? axis : axis.negate();
  }

  // |cos| of the angle between the line of sight and the hinge axis: 1 when flexion lies in the image plane
  viewAlongHinge() {
    const axis = this.hingeAxis.clone().transformDirection(this.root.matrixWorld);
    return Math.abs(this.camera.getWorldDirection(new THREE.Vector3()).dot(axis));
  }

  placeCamera() {
    const t = Math.tan(THREE.MathUtils.degToRad(this.camera.fov / 2));
    const dir = this.viewDirection.clone().normalize();
    const up = new THREE.Vector3(0, 1, 0).addScaledVector(dir, -dir.y).normalize();
    const right = new THREE.Vector3().crossVectors(up, dir);
    // half extents of the swept arm across and along the view, from the framed corner points
    let w = 0, h = 0, d = 0;
    for (const p of this.points) {
      const q = p.clone().sub(this.centre);
      w = Math.max(w, Math.abs(q.dot(right))); h = Math.max(h, Math.abs(q.dot(up))); d = Math.max(d, q.dot(dir));
    }
    // the control panel may cover the left of the canvas (narrow windows), the graphs its bottom
    const free = 1 - (this.bottomInset || 0) / window.innerHeight;
    const c = this.renderer.domElement, underPanel = c.offsetLeft < 100 && c.clientWidth > 720;
    const aspect = underPanel ? Math.max(this.camera.aspect * 0.78, 0.5) : this.camera.aspect;
    const dist = 1.1 * Math.max(h / (t * free), w / (t * aspect)) + d;
    this.camera.position.copy(this.centre).addScaledVector(dir, dist);
    this.camera.up.copy(up);
    this.camera.near = dist / 20;
    this.camera.far = dist * 10;
    this.camera.lookAt(this.centre);
  }

  setElbowAngle(deg) {
    this.forearm.quaternion.setFromAxisAngle(this.hingeAxis, THREE.MathUtils.degToRad(deg));
  }

  setPositions(positions) {
    this.buffers.update(positions);
    for (const a of Object.values(this.attr)) a.needsUpdate = true;
  }

  // In AR the recording's graphs follow as a panel below the arm (a texture of the graphs'
  // canvas, refreshed when they grow), for headsets without the DOM overlay.
  addGraphPanel(canvas) {
    const texture = new THREE.CanvasTexture(canvas);
    const width = 0.5, height = (width * canvas.height) / Math.max(canvas.width, 1);
    const panel = new THREE.Mesh(new THREE.PlaneGeometry(width, height),
      new THREE.MeshBasicMaterial({ map: texture, transparent: true, opacity: 0.92 }));
    panel.position.set(0, -0.25 - height / 2, -0.6);
    this.scene.add(panel);
    this.graphPanel = { panel, texture };
    return panel;
  }

  refreshGraphPanel() { if (this.graphPanel) this.graphPanel.texture.needsUpdate = true; }

  async enterAR(session, graphCanvas = null) {
    const r = this.renderer, root = this.root, background = this.scene.background;
    const panel = graphCanvas && graphCanvas.width > 0 ? this.addGraphPanel(graphCanvas) : null;
    const saved = { position: root.position.clone(), scale: root.scale.clone() };
    r.xr.enabled = true;
    r.xr.setReferenceSpaceType('local');
    this.scene.background = null; // the camera image shows through
    // mm -> m, the arm's centre 0.6 m in front of the viewer
    root.scale.setScalar(0.001);
    root.position.copy(this.centre).multiplyScalar(-0.001).add(new THREE.Vector3(0, 0, -0.6));
    await r.xr.setSession(session);
    session.addEventListener('end', () => {
      r.xr.enabled = false;
      this.scene.background = background;
      root.position.copy(saved.position);
      root.scale.copy(saved.scale);
      if (panel) { this.scene.remove(panel); this.graphPanel = null; }
    });
  }

  // Dynamic resolution: the drawing buffer shrinks (down to half) while the frame rate is below
  // target and grows back when there is headroom; software renderers are fill-rate bound.
  adaptResolution(fps, target = 60) {
    if (this.fixedScale) return;
    let next = this.renderScale;
    if (fps < target) next = Math.max(0.5 * this.maxScale, this.renderScale * 0.85);
    else if (fps > 1.6 * target) next = Math.min(this.maxScale, this.renderScale * 1.1);
    if (Math.abs(next - this.renderScale) > 1e-3) {
      this.renderScale = next;
      this.renderer.setPixelRatio(next);
      this.resize();
    }
  }

  // Hold the render scale (benchmarks: the cost of full resolution); null lets it adapt again.
  fixScale(scale) {
    this.fixedScale = scale;
    if (scale) { this.renderScale = scale; this.renderer.setPixelRatio(scale); this.resize(); }
  }

  resize() {
    const c = this.renderer.domElement, w = c.clientWidth || window.innerWidth, h = c.clientHeight || window.innerHeight;
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    // Centre the arm in the part of the window the control panel (left) and the graphs (bottom,
    // while a recording is open) leave free.
    const panel = w > 720 && c.offsetLeft < 100 ? 150 : 0, below = (this.bottomInset || 0) / 2;
    if (this.viewDirection && below !== this.placedBelow) { this.placedBelow = below; this.placeCamera(); }
    if ((panel || below) && !this.renderer.xr.isPresenting) this.camera.setViewOffset(w, h, -panel, below, w, h);
    else this.camera.clearViewOffset();
    this.camera.updateProjectionMatrix();
  }

  render() {
    this.controls.update();
    this.renderer.render(this.scene, this.camera);
  }
}
