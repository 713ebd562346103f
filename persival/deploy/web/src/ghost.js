// The ghost arm: the forearm's bones once more, translucent, turned about the same hinge to the
// exercise's target angle, so the user sees where the arm should be.
import * as THREE from 'three';

export class GhostArm {
  constructor(scene) {
    this.scene = scene;
    const material = new THREE.MeshBasicMaterial({ color: 0x7fd1ff, transparent: true, opacity: 0.35, depthWrite: false });
    this.group = new THREE.Group();
    this.group.position.copy(scene.forearm.position);
    for (const child of scene.forearm.children) {
      const mesh = new THREE.Mesh(child.geometry, material);
      mesh.position.copy(child.position);
      this.group.add(mesh);
    }
    this.group.visible = false;
    scene.root.add(this.group);
  }

  // deg: the target angle, or null to hide the ghost
  set(deg) {
    this.group.visible = deg !== null && Number.isFinite(deg);
    if (this.group.visible) this.group.quaternion.setFromAxisAngle(this.scene.hingeAxis, THREE.MathUtils.degToRad(deg));
  }
}
