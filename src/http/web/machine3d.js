// The machine in three.js: its bodies on their links (or a schematic where the profile gives
// none), the tool on the spindle, stock and fixtures in W, each link posed from the joints by
// kin.js (the FK the server computes). The result page animates a program on it (view.js's
// `machineView`), the machine check page moves it from sliders (check.js).
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { followBox, webgl } from './viewport.js';
import { links, matrix4, schematic, toolBodies } from './kin.js';

const PALETTE = { bed: 0x8d99ae, table: 0x6c7a89, ram: 0xa3b1c2, spindle: 0xc9d3de, tool: 0xd4a017, holder: 0x5c6b7a, stock: 0x2a9d8f, fixture: 0x9c6644, hit: 0xe00000 };

/** The triangles of a binary STL (as GET /v1/machines/{id}/meshes/{file} serves them). */
export function stlGeometry(buf) {
  const dv = new DataView(buf);
  const n = buf.byteLength >= 84 ? dv.getUint32(80, true) : 0;
  if (84 + 50 * n !== buf.byteLength) throw new Error('not a binary STL');
  const pos = new Float32Array(n * 9);
  for (let i = 0; i < n; i++) {
    for (let k = 0; k < 9; k++) pos[i * 9 + k] = dv.getFloat32(84 + i * 50 + 12 + k * 4, true);
  }
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(pos, 3));
  g.computeVertexNormals();
  return g;
}

/**
 * A mesh body: its bounding box until `url`'s triangles arrive, then them. Resolves when drawn
 * (or left a box: the page goes on without the file).
 */
function meshBody(mesh, url) {
  return fetch(url)
    .then((r) => (r.ok ? r.arrayBuffer() : Promise.reject(new Error(`${url}: ${r.status}`))))
    .then((buf) => {
      const g = stlGeometry(buf);
      mesh.geometry.dispose();
      mesh.geometry = g;
      mesh.position.set(0, 0, 0);
      mesh.children.forEach((e) => { e.geometry.dispose(); e.geometry = new THREE.EdgesGeometry(g, 30); });
    })
    .catch((e) => console.warn(`mesh ${mesh.userData.body}: ${e.message}`));
}

/** A mesh of a body (box, cylinder or STL mesh, in its link's coordinates). */
export function bodyMesh(b, color, opacity = 1) {
  const mat = new THREE.MeshStandardMaterial({ color, roughness: 0.7, metalness: 0.1, transparent: opacity < 1, opacity, side: b.mesh ? THREE.DoubleSide : THREE.FrontSide });
  let mesh;
  if (b.box || b.mesh) {
    const [x0, y0, z0, x1, y1, z1] = b.box || b.mesh.bounds;
    mesh = new THREE.Mesh(new THREE.BoxGeometry(x1 - x0, y1 - y0, z1 - z0), mat);
    mesh.position.set((x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2);
  } else {
    const { from, to, radius } = b.cylinder;
    const d = new THREE.Vector3(to[0] - from[0], to[1] - from[1], to[2] - from[2]);
    const len = d.length();
    mesh = new THREE.Mesh(new THREE.CylinderGeometry(radius, radius, len, 40), mat);
    mesh.quaternion.setFromUnitVectors(new THREE.Vector3(0, 1, 0), d.normalize());
    mesh.position.set((from[0] + to[0]) / 2, (from[1] + to[1]) / 2, (from[2] + to[2]) / 2);
  }
  mesh.userData.body = b.name;
  mesh.userData.color = color;
  const edges = new THREE.LineSegments(new THREE.EdgesGeometry(mesh.geometry, 30), new THREE.LineBasicMaterial({ color: 0x303030, transparent: true, opacity: 0.35 }));
  mesh.add(edges);
  if (b.mesh && b.url) mesh.userData.loaded = meshBody(mesh, b.url);
  return mesh;
}

function colorOf(ch, on) {
  if (PALETTE[on]) return PALETTE[on];
  const r = ch.rot.find((x) => x.name === on);
  return r && r.mount === 'head' ? 0xb8c4d0 : 0x7f8fa0;
}

/**
 * The machine's scene graph: one group per link (posed by `pose`), the bodies in them. `extra`:
 * `{ stock, fixtures }` boxes in W. Returns `{ root, work, schematic, pose(linear, actual, L),
 * setTool(t), highlight(names) , meshes, loaded }`; `work` is the W group (a path drawn in it turns with
 * the table).
 */
export function machineScene(ch, extra = {}) {
  const root = new THREE.Group();
  const groups = {};
  const group = (on) => {
    if (!groups[on]) {
      const g = new THREE.Group();
      g.matrixAutoUpdate = false;
      groups[on] = g;
      root.add(g);
    }
    return groups[on];
  };
  for (const on of ['bed', 'table', 'ram', 'spindle', 'work', ...ch.rot.map((r) => r.name)]) group(on);
  const isSchematic = ch.bodies.length === 0;
  const bodies = isSchematic ? schematic(ch) : ch.bodies;
  const meshes = new Map();
  const loads = [];
  for (const b0 of bodies) {
    const url = b0.mesh && `/v1/machines/${encodeURIComponent(ch.id)}/meshes/${encodeURIComponent(b0.mesh.file)}`;
    const b = url ? { ...b0, url } : b0;
    const m = bodyMesh(b, colorOf(ch, b.on), isSchematic ? 0.55 : 0.8);
    if (m.userData.loaded) loads.push(m.userData.loaded);
    group(b.on).add(m);
    meshes.set(b.name, m);
  }
  (extra.stock || []).forEach((box) => {
    const m = bodyMesh({ name: 'stock', box }, PALETTE.stock, 0.45);
    group('work').add(m);
    meshes.set('stock', m);
  });
  (extra.fixtures || []).forEach((box, i) => {
    const m = bodyMesh({ name: `fixture ${i + 1}`, box }, PALETTE.fixture, 0.7);
    group('work').add(m);
    meshes.set(`fixture ${i + 1}`, m);
  });
  let tool = null;
  let toolMeshes = [];
  const setTool = (t) => {
    if (tool && ['length', 'diameter', 'holder_diameter', 'holder_length', 'corner_radius'].every((k) => tool[k] === t[k])) return;
    tool = t;
    for (const m of toolMeshes) { group('spindle').remove(m); meshes.delete(m.userData.body); m.geometry.dispose(); }
    toolMeshes = toolBodies(t).map((b) => bodyMesh(b, b.name === 'cutter' ? PALETTE.tool : PALETTE.holder, 1));
    for (const m of toolMeshes) { group('spindle').add(m); meshes.set(m.userData.body, m); }
  };
  let lit = [];
  const highlight = (names) => {
    for (const m of lit) m.material.color.setHex(m.userData.color);
    lit = names.map((n) => meshes.get(n)).filter(Boolean);
    for (const m of lit) m.material.color.setHex(PALETTE.hit);
  };
  const pose = (linear, actual, L, wo) => {
    const p = links(ch, linear, actual, L, wo);
    for (const [on, g] of Object.entries(groups)) {
      const m = p[on] || p.bed;
      g.matrix.fromArray(matrix4(m));
      g.matrixWorldNeedsUpdate = true;
    }
    return p;
  };
  // `loaded`: every mesh body drawn (render again then).
  return { root, work: groups.work, groups, schematic: isSchematic, meshes, pose, setTool, highlight, loaded: Promise.all(loads) };
}

/**
 * A renderer, lights, camera and orbit controls around `scene` in `el`; `frame` is a Box3 to look
 * at. Returns `{ renderer, camera, render(), dispose() }`, or `null` (with a message in `el`)
 * where the browser gives no WebGL.
 */
export function stage(el, scene, frame) {
  const renderer = webgl(el);
  if (!renderer) return null;
  const w = el.clientWidth || 800;
  const h = el.clientHeight || 480;
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  renderer.setSize(w, h);
  renderer.setClearColor(new THREE.Color(getComputedStyle(el).backgroundColor || '#fff'));
  el.appendChild(renderer.domElement);
  scene.add(new THREE.AmbientLight(0xffffff, 1.6));
  const sun = new THREE.DirectionalLight(0xffffff, 2.2);
  sun.position.set(1, -1.5, 2);
  scene.add(sun);
  const size = frame.getSize(new THREE.Vector3());
  const diag = Math.max(size.length(), 1e-3);
  const centre = frame.getCenter(new THREE.Vector3());
  const camera = new THREE.PerspectiveCamera(40, w / h, diag / 1000, diag * 100);
  camera.up.set(0, 0, 1);
  camera.position.copy(centre).add(new THREE.Vector3(1.0, -1.5, 0.8).multiplyScalar(diag * 0.6));
  const controls = new OrbitControls(camera, renderer.domElement);
  controls.target.copy(centre);
  controls.screenSpacePanning = true;
  controls.update();
  const render = () => renderer.render(scene, camera);
  controls.addEventListener('change', render);
  const unfollow = followBox(el, renderer, camera, render);
  return {
    renderer,
    camera,
    render,
    /** Where a world point is drawn, in CSS pixels of the canvas. */
    screenOf(v) {
      const p = v.clone().project(camera);
      const r = renderer.domElement.getBoundingClientRect();
      return { x: (p.x + 1) / 2 * r.width, y: (1 - p.y) / 2 * r.height, z: p.z };
    },
    dispose() {
      unfollow();
      controls.dispose();
      renderer.dispose();
    },
  };
}

/** The box the machine's scene fills at its current pose. */
export function sceneBox(obj) {
  obj.updateMatrixWorld(true);
  const box = new THREE.Box3().setFromObject(obj);
  if (box.isEmpty()) box.expandByPoint(new THREE.Vector3(0, 0, 0));
  return box;
}
