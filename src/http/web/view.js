// The program, seen: the CL path in 3D (three.js, vendored) and every axis word against block
// number or time (SVG). Data: GET /v1/jobs/{id}/preview. Pure drawing: app.js decides when.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { followBox, webgl } from './viewport.js';

const COLORS = { feed: 0x1d6fd8, rapid: 0xe76f51, axis: 0x7a9a3a, error: 0xd00000, warning: 0xf0a000, event: 0x8e44ad };
const SVGNS = 'http://www.w3.org/2000/svg';

/** What a marker is about: an error, a warning, or an unwind / branch change (info). */
export function markKind(diags) {
  if (diags.some((d) => d.severity === 'error')) return 'error';
  if (diags.some((d) => d.severity === 'warning')) return 'warning';
  return 'event';
}

/** Every marked place of a preview: blocks (marks) and unreachable poses (notes with a tip). */
export function markers(p) {
  const out = [];
  for (const m of p.marks) out.push({ n: m.n, line: m.line, nc: m.nc, cl: m.cl, tip: m.tip, axis: m.axis, diagnostics: m.diagnostics });
  for (const x of p.notes) out.push({ n: null, line: x.diagnostic.line ?? null, nc: null, cl: x.cl, tip: x.tip, axis: x.axis, diagnostics: [x.diagnostic] });
  return out;
}

/**
 * The 3D view in `el`. `onPick(marker)` when a marker is clicked. Returns a handle with
 * `select(marker)` (highlight) and `markerScreen(i)` (where marker i is drawn, in CSS pixels of
 * the canvas: what a click on it needs) and `dispose()`.
 */
export function view3d(el, p, list, onPick) {
  const renderer = webgl(el);
  if (!renderer) return { select() {}, markerScreen() { return null; }, dispose() {} };
  const w = el.clientWidth || 800;
  const h = el.clientHeight || 480;
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  renderer.setSize(w, h);
  // The page's own background (dark mode).
  renderer.setClearColor(new THREE.Color(getComputedStyle(el).backgroundColor || '#fff'));
  el.appendChild(renderer.domElement);

  const scene = new THREE.Scene();
  const pts = p.points;
  // Framed on the cutting (feed moves and marked poses): rapids to a far home position would
  // shrink the part to a dot. Everything is drawn; orbit and zoom reach the rest.
  const box = new THREE.Box3();
  for (const q of pts) if (!q.rapid) box.expandByPoint(new THREE.Vector3(...q.tip));
  for (const m of list) if (m.tip) box.expandByPoint(new THREE.Vector3(...m.tip));
  if (box.isEmpty()) for (const q of pts) box.expandByPoint(new THREE.Vector3(...q.tip));
  if (box.isEmpty()) box.expandByPoint(new THREE.Vector3(0, 0, 0));
  const size = box.getSize(new THREE.Vector3());
  const diag = Math.max(size.length(), 1);
  const centre = box.getCenter(new THREE.Vector3());

  // The path: each segment coloured by the motion that reaches its end (rapid or feed).
  const pos = new Float32Array(Math.max(pts.length - 1, 0) * 6);
  const col = new Float32Array(pos.length);
  const cFeed = new THREE.Color(COLORS.feed);
  const cRapid = new THREE.Color(COLORS.rapid);
  for (let i = 1; i < pts.length; i++) {
    const c = pts[i].rapid ? cRapid : cFeed;
    pos.set(pts[i - 1].tip, (i - 1) * 6);
    pos.set(pts[i].tip, (i - 1) * 6 + 3);
    col.set([c.r, c.g, c.b, c.r, c.g, c.b], (i - 1) * 6);
  }
  const path = new THREE.BufferGeometry();
  path.setAttribute('position', new THREE.BufferAttribute(pos, 3));
  path.setAttribute('color', new THREE.BufferAttribute(col, 3));
  scene.add(new THREE.LineSegments(path, new THREE.LineBasicMaterial({ vertexColors: true })));

  // The tool axis along the path: a few hundred needles, tip toward the spindle.
  const every = Math.max(1, Math.ceil(pts.length / 300));
  const len = diag * 0.05;
  const ax = [];
  for (let i = 0; i < pts.length; i += every) {
    const [x, y, z] = pts[i].tip;
    const [a, b, c] = pts[i].axis;
    ax.push(x, y, z, x + a * len, y + b * len, z + c * len);
  }
  const axGeo = new THREE.BufferGeometry();
  axGeo.setAttribute('position', new THREE.BufferAttribute(new Float32Array(ax), 3));
  scene.add(new THREE.LineSegments(axGeo, new THREE.LineBasicMaterial({ color: COLORS.axis, transparent: true, opacity: 0.6 })));

  // Markers: fixed-size points, coloured by what they are about.
  const placed = list.map((m, i) => [m, i]).filter(([m]) => m.tip);
  const mPos = new Float32Array(placed.length * 3);
  const mCol = new Float32Array(placed.length * 3);
  placed.forEach(([m], k) => {
    mPos.set(m.tip, k * 3);
    const c = new THREE.Color(COLORS[markKind(m.diagnostics)]);
    mCol.set([c.r, c.g, c.b], k * 3);
  });
  const mGeo = new THREE.BufferGeometry();
  mGeo.setAttribute('position', new THREE.BufferAttribute(mPos, 3));
  mGeo.setAttribute('color', new THREE.BufferAttribute(mCol, 3));
  scene.add(new THREE.Points(mGeo, new THREE.PointsMaterial({ size: 9, sizeAttenuation: false, vertexColors: true })));
  const selGeo = new THREE.BufferGeometry();
  selGeo.setAttribute('position', new THREE.BufferAttribute(new Float32Array(3), 3));
  const sel = new THREE.Points(selGeo, new THREE.PointsMaterial({ size: 18, sizeAttenuation: false, color: 0x000000, transparent: true, opacity: 0.45 }));
  sel.visible = false;
  scene.add(sel);

  const grid = new THREE.GridHelper(diag, 10, 0xbbbbbb, 0xdddddd);
  grid.rotation.x = Math.PI / 2; // the XY plane: Z is up, as on the machine
  grid.position.set(centre.x, centre.y, box.min.z);
  scene.add(grid);
  const triad = new THREE.AxesHelper(diag * 0.12);
  triad.position.copy(box.min);
  scene.add(triad);

  const camera = new THREE.PerspectiveCamera(40, w / h, diag / 1000, diag * 100);
  camera.up.set(0, 0, 1);
  camera.position.copy(centre).add(new THREE.Vector3(0.9, -1.3, 0.9).multiplyScalar(diag));
  const controls = new OrbitControls(camera, renderer.domElement);
  controls.target.copy(centre);
  controls.screenSpacePanning = true;
  controls.update();
  const render = () => renderer.render(scene, camera);
  controls.addEventListener('change', render);
  render();
  const unfollow = followBox(el, renderer, camera, render);

  const screenOf = (tip) => {
    const v = new THREE.Vector3(...tip).project(camera);
    const r = renderer.domElement.getBoundingClientRect();
    return { x: (v.x + 1) / 2 * r.width, y: (1 - v.y) / 2 * r.height, z: v.z };
  };
  // A click (not a drag) picks the nearest marker within 12 px.
  let down = null;
  renderer.domElement.addEventListener('pointerdown', (e) => { down = [e.clientX, e.clientY]; });
  renderer.domElement.addEventListener('pointerup', (e) => {
    if (!down || Math.hypot(e.clientX - down[0], e.clientY - down[1]) > 4) return;
    const r = renderer.domElement.getBoundingClientRect();
    const x = e.clientX - r.left;
    const y = e.clientY - r.top;
    let best = null;
    let bd = 12;
    for (const [m, i] of placed) {
      const s = screenOf(m.tip);
      const d = Math.hypot(s.x - x, s.y - y);
      if (s.z < 1 && d < bd) [best, bd] = [i, d];
    }
    if (best !== null) onPick(list[best]);
  });

  return {
    select(m) {
      sel.visible = Boolean(m && m.tip);
      if (sel.visible) {
        selGeo.attributes.position.array.set(m.tip);
        selGeo.attributes.position.needsUpdate = true;
      }
      render();
    },
    markerScreen(i) {
      return list[i] && list[i].tip ? screenOf(list[i].tip) : null;
    },
    dispose() {
      unfollow();
      controls.dispose();
      renderer.dispose();
    },
  };
}

/**
 * One SVG chart per axis word in `el`: the value against block number (`x = 'n'`) or estimated
 * time (`x = 't'`), the profile's limits as red bands beyond them, unwinds and branch changes as
 * vertical lines, warnings as ticks at the top. `onPick(marker)` when a line or tick is clicked;
 * `onSeek(n)` when the chart is clicked elsewhere (the block nearest the click). Returns
 * `{ cursor(n) }`: a vertical cursor at block `n` on every chart (the machine view's block).
 */
export function plots(el, p, list, x, onPick, onSeek) {
  el.replaceChildren();
  const pts = p.points;
  const cursors = [];
  const handle = {
    cursor(n) {
      if (!pts.length) return;
      const xc = sx(x === 't' ? tOf(n) : n).toFixed(1);
      for (const c of cursors) { c.setAttribute('x1', xc); c.setAttribute('x2', xc); c.setAttribute('visibility', 'visible'); c.dataset.n = n; }
    },
  };
  if (!pts.length) return handle;
  // Drawn at the width it is shown at, so text stays its size on a phone (a 900-wide drawing
  // shrunk to 390 px made the labels 5 px).
  const W = Math.max(320, Math.round(el.clientWidth || 900));
  const H = 110;
  const L = 70;
  const R = 10;
  const xs = pts.map((q) => (x === 't' ? q.t : q.n));
  const x0 = Math.min(...xs);
  const x1 = Math.max(...xs, x0 + 1e-9);
  const sx = (v) => L + (v - x0) / (x1 - x0) * (W - L - R);
  // Marks by block number; on the time axis, at the time of the nearest kept point before them.
  const tOf = (n) => {
    let lo = 0;
    let hi = pts.length - 1;
    while (lo < hi) {
      const mid = (lo + hi + 1) >> 1;
      if (pts[mid].n <= n) lo = mid; else hi = mid - 1;
    }
    return pts[lo].t;
  };
  const mx = (m) => sx(x === 't' ? tOf(m.n) : m.n);
  const node = (tag, attrs, parent) => {
    const e = document.createElementNS(SVGNS, tag);
    for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
    if (parent) parent.appendChild(e);
    return e;
  };
  p.axes.forEach((a, k) => {
    const vals = pts.map((q) => q.j[k]);
    let lo = Math.min(...vals);
    let hi = Math.max(...vals);
    if (a.limits) [lo, hi] = [Math.min(lo, a.limits[0]), Math.max(hi, a.limits[1])];
    const pad = Math.max((hi - lo) * 0.08, 1e-3);
    [lo, hi] = [lo - pad, hi + pad];
    const sy = (v) => 8 + (hi - v) / (hi - lo) * (H - 24);
    const svg = node('svg', { viewBox: `0 0 ${W} ${H}`, class: 'plot', 'data-axis': a.name, role: 'img' });
    node('title', {}, svg).textContent = `${a.name} (${a.kind === 'rotary' ? '°' : p.units}) against ${x === 't' ? 'time' : 'block number'}`;
    if (a.limits) {
      node('rect', { x: L, y: sy(hi), width: W - L - R, height: Math.max(sy(a.limits[1]) - sy(hi), 0), class: 'band' }, svg);
      node('rect', { x: L, y: sy(a.limits[0]), width: W - L - R, height: Math.max(sy(lo) - sy(a.limits[0]), 0), class: 'band' }, svg);
    }
    node('line', { x1: L, x2: L, y1: 8, y2: H - 16, class: 'frame' }, svg);
    node('line', { x1: L, x2: W - R, y1: H - 16, y2: H - 16, class: 'frame' }, svg);
    const unit = a.kind === 'rotary' ? '°' : p.units;
    const label = node('text', { x: 4, y: 22, class: 'name' }, svg);
    label.textContent = a.name;
    node('text', { x: 4, y: 40, class: 'tick' }, svg).textContent = unit;
    const digits = a.kind === 'rotary' ? 1 : 2;
    for (const v of [Math.max(...vals), Math.min(...vals)]) {
      const t = node('text', { x: L - 4, y: sy(v) + 4, class: 'tick', 'text-anchor': 'end' }, svg);
      t.textContent = v.toLocaleString(undefined, { minimumFractionDigits: digits, maximumFractionDigits: digits });
    }
    const end = node('text', { x: W - R, y: H - 3, class: 'tick', 'text-anchor': 'end' }, svg);
    end.textContent = x === 't' ? `${(x1 / 60).toLocaleString(undefined, { maximumFractionDigits: 1 })} min` : `block ${x1.toLocaleString()}`;
    let d = '';
    pts.forEach((q, i) => { d += `${i ? 'L' : 'M'}${sx(xs[i]).toFixed(1)} ${sy(vals[i]).toFixed(1)}`; });
    node('path', { d, class: 'trace' }, svg);
    for (const m of list) {
      if (m.n === null) continue;
      const codes = m.diagnostics.map((dg) => dg.code);
      const kind = codes.includes('unwind') ? 'unwind' : codes.includes('branch_change') ? 'branch' : markKind(m.diagnostics);
      const xm = mx(m);
      const e = kind === 'unwind' || kind === 'branch'
        ? node('line', { x1: xm, x2: xm, y1: 8, y2: H - 16, class: `mark ${kind}` }, svg)
        : node('line', { x1: xm, x2: xm, y1: 8, y2: 16, class: `mark ${kind}` }, svg);
      node('title', {}, e).textContent = `block ${m.n}: ${codes.join(', ')}`;
      e.addEventListener('click', (ev) => { ev.stopPropagation(); onPick(m); });
    }
    cursors.push(node('line', { x1: L, x2: L, y1: 4, y2: H - 16, class: 'cursor', visibility: 'hidden' }, svg));
    if (onSeek) {
      svg.addEventListener('click', (ev) => {
        const r = svg.getBoundingClientRect();
        const v = x0 + ((ev.clientX - r.left) / r.width * W - L) / (W - L - R) * (x1 - x0);
        let best = 0;
        xs.forEach((xv, i) => { if (Math.abs(xv - v) < Math.abs(xs[best] - v)) best = i; });
        onSeek(pts[best].n);
      });
    }
    el.appendChild(svg);
  });
  return handle;
}
