// The program run on the machine: the preview's points and marked blocks in block order, each
// posed through kin.js (the server's FK), with play, pause and a slider over block number linked
// to the axis plots; collisions as red markers that a click explains, the bodies they name red
// while the slider stands on them. Pure view: app.js wires it to the page.
import * as THREE from 'three';
import { chain, controlledPoint, defaultTool, joints as jointsOf } from './kin.js';
import { machineScene, sceneBox, stage } from './machine3d.js';

const D = Math.PI / 180;

/** The frames of a preview: its points and its marks (a mark is a block with its joints too),
 *  one per block number, in order. */
export function frames(p) {
  const byN = new Map();
  for (const q of p.points) byN.set(q.n, q);
  for (const m of p.marks) byN.set(m.n, { ...(byN.get(m.n) || {}), ...m });
  return [...byN.values()].sort((a, b) => a.n - b.n);
}

/** The tool in the spindle at block `n` (the preview's tools; the profile's length before any). */
function toolAt(p, ch, n) {
  let t = null;
  for (const x of p.tools || []) if (x.n <= n) t = x; else break;
  return t || (p.tools && p.tools[0]) || defaultTool(ch, ch.defaultToolLength);
}

/** What a collision mark says, for people: block, bodies, depth, CL line. */
export function explain(m, units) {
  const parts = (m.contacts || []).map((c) => c.code === 'collision'
    ? `${c.a} and ${c.b} overlap by ${c.depth} ${units}`
    : `${c.a} and ${c.b} come within ${c.distance} ${units}`);
  const what = parts.length ? parts.join('; ') : m.diagnostics.filter((d) => /collision/.test(d.code)).map((d) => d.message).join('; ');
  return `${(m.contacts || []).some((c) => c.code === 'collision') ? 'Collision' : 'Near collision'} at NC block ${m.n}` +
    (m.line ? ` (CL line ${m.line})` : '') + `: ${what}.` + (m.cl ? `\nCL line ${m.line}: ${m.cl}` : '') + (m.nc ? `\nNC block: ${m.nc}` : '');
}

/**
 * The machine view in `ui.view` with its controls (`ui.play`, `ui.slider`, `ui.speed`, `ui.where`,
 * `ui.note`, `ui.info`). `model`: the preview's machine (or the profile's). `onPick(mark)` when a
 * collision marker is clicked; `onFrame(n)` whenever the shown block changes.
 */
export function machineView(ui, p, model, onPick, onFrame) {
  const ch = chain(model);
  const fr = frames(p);
  const wo = p.work_offset || [0, 0, 0];
  const tcp = p.mode === 'tcp';
  const scene = new THREE.Scene();
  const ms = machineScene(ch, { stock: p.stock, fixtures: p.fixtures });
  scene.add(ms.root);
  ui.note.textContent = ms.schematic
    ? `${model.id} gives no bodies: a schematic (bed, carriage, a disc per rotary) shows how the axes move, not the machine's shape.`
    : `${model.id}: ${ch.bodies.length} bodies from the profile, the tool (cutter and holder) as the collision check sees it` +
      (p.stock && p.stock.length ? ', the stock' : '') + '.';

  // The path in W, turning with the table; collisions as red (near misses orange) markers.
  const pos = new Float32Array(Math.max(fr.length - 1, 0) * 6);
  const col = new Float32Array(pos.length);
  const cFeed = new THREE.Color(0x1d6fd8);
  const cRapid = new THREE.Color(0xe76f51);
  for (let i = 1; i < fr.length; i++) {
    const c = fr[i].rapid ? cRapid : cFeed;
    pos.set(fr[i - 1].tip, (i - 1) * 6);
    pos.set(fr[i].tip, (i - 1) * 6 + 3);
    col.set([c.r, c.g, c.b, c.r, c.g, c.b], (i - 1) * 6);
  }
  const path = new THREE.BufferGeometry();
  path.setAttribute('position', new THREE.BufferAttribute(pos, 3));
  path.setAttribute('color', new THREE.BufferAttribute(col, 3));
  ms.work.add(new THREE.LineSegments(path, new THREE.LineBasicMaterial({ vertexColors: true })));
  const hits = p.marks.filter((m) => (m.contacts || []).length || m.diagnostics.some((d) => d.code === 'collision' || d.code === 'near_collision'));
  const mPos = new Float32Array(hits.length * 3);
  const mCol = new Float32Array(hits.length * 3);
  hits.forEach((m, k) => {
    mPos.set(m.tip, k * 3);
    const c = new THREE.Color(m.diagnostics.some((d) => d.code === 'collision') ? 0xe00000 : 0xf08000);
    mCol.set([c.r, c.g, c.b], k * 3);
  });
  const mGeo = new THREE.BufferGeometry();
  mGeo.setAttribute('position', new THREE.BufferAttribute(mPos, 3));
  mGeo.setAttribute('color', new THREE.BufferAttribute(mCol, 3));
  ms.work.add(new THREE.Points(mGeo, new THREE.PointsMaterial({ size: 12, sizeAttenuation: false, vertexColors: true, depthTest: false })));

  let cur = -1;
  const state = (i) => {
    const q = fr[i];
    const words = {};
    p.axes.forEach((a, k) => { words[a.name] = q.j[k]; });
    const t = toolAt(p, ch, q.n);
    const { linear, actual } = jointsOf(ch, words);
    const lin = tcp ? controlledPoint(ch, actual, q.tip, t.length, wo) : linear;
    return { q, words, tool: t, linear: lin, actual };
  };
  const show = (i, quiet) => {
    if (!fr.length) return;
    i = Math.max(0, Math.min(fr.length - 1, Math.round(i)));
    const s = state(i);
    ms.setTool(s.tool);
    ms.pose(s.linear, s.actual, s.tool.length, wo);
    const names = (s.q.contacts || []).flatMap((c) => [c.a, c.b]);
    ms.highlight(names);
    cur = i;
    ui.slider.value = String(i);
    const ax = p.axes.map((a, k) => `${a.name}${s.q.j[k].toFixed(a.kind === 'rotary' ? 2 : 3)}`).join(' ');
    ui.where.textContent = `Block ${s.q.n.toLocaleString()} of ${p.blocks.toLocaleString()} · ${ax} · ${(s.q.t / 60).toFixed(2)} min` +
      (tcp ? ' · machine X Y Z ' + s.linear.map((v) => v.toFixed(3)).join(' ') : '') + (names.length ? ` · ${names.join(' / ')} touching` : '');
    if (st) st.render();
    if (!quiet && onFrame) onFrame(s.q.n);
  };

  // Framed on the machine at the first block, and the path.
  if (fr.length) { const s = state(0); ms.setTool(s.tool); ms.pose(s.linear, s.actual, s.tool.length, wo); }
  const frame = sceneBox(ms.root);
  const st = stage(ui.view, scene, frame);
  ms.loaded.then(() => st && st.render());

  ui.slider.min = '0';
  ui.slider.max = String(Math.max(fr.length - 1, 0));
  ui.slider.step = '1';
  const onSlide = () => { pause(); show(Number(ui.slider.value)); };
  ui.slider.addEventListener('input', onSlide);

  // Play: the whole program in 30 s at ×1 (by the cycle-time estimate; by block where it has none).
  let raf = 0;
  let clock = 0;
  let simT = 0;
  const total = fr.length ? fr[fr.length - 1].t : 0;
  const tick = (now) => {
    const dt = (now - clock) / 1000;
    clock = now;
    const speed = Number(ui.speed.value) || 1;
    let i = cur;
    if (total > 0) {
      simT += dt * speed * total / 30;
      while (i < fr.length - 1 && fr[i + 1].t <= simT) i++;
    } else {
      i = cur + Math.max(1, Math.round(dt * speed * fr.length / 30));
    }
    show(Math.min(i, fr.length - 1));
    if (cur >= fr.length - 1) { pause(); return; }
    raf = requestAnimationFrame(tick);
  };
  const play = () => {
    if (raf || fr.length < 2) return;
    if (cur >= fr.length - 1) show(0);
    ui.play.textContent = 'Pause';
    clock = performance.now();
    simT = fr[cur].t;
    raf = requestAnimationFrame(tick);
  };
  function pause() {
    if (raf) cancelAnimationFrame(raf);
    raf = 0;
    ui.play.textContent = 'Play';
  }
  const onPlay = () => (raf ? pause() : play());
  ui.play.addEventListener('click', onPlay);

  const markerWorld = (k) => new THREE.Vector3(...hits[k].tip).applyMatrix4(ms.work.matrixWorld);
  const markerScreen = (k) => {
    if (!st || !hits[k]) return null;
    ms.root.updateMatrixWorld(true);
    return st.screenOf(markerWorld(k));
  };
  const pickHit = (k) => {
    const m = hits[k];
    ui.info.textContent = explain(m, p.units);
    ui.info.hidden = false;
    const i = fr.findIndex((q) => q.n === m.n);
    if (i >= 0) { pause(); show(i); }
    if (onPick) onPick(m);
  };
  if (st) {
    let down = null;
    const cv = st.renderer.domElement;
    cv.addEventListener('pointerdown', (e) => { down = [e.clientX, e.clientY]; });
    cv.addEventListener('pointerup', (e) => {
      if (!down || Math.hypot(e.clientX - down[0], e.clientY - down[1]) > 4) return;
      const r = cv.getBoundingClientRect();
      let best = -1;
      let bd = 14;
      hits.forEach((_, k) => {
        const s = markerScreen(k);
        const d = Math.hypot(s.x - (e.clientX - r.left), s.y - (e.clientY - r.top));
        if (s.z < 1 && d < bd) [best, bd] = [k, d];
      });
      if (best >= 0) pickHit(best);
    });
  }
  show(0, true);

  return {
    frames: fr,
    collisions: hits,
    /** Shows the frame of block `n` (the last frame at or before it). */
    seek(n, quiet = true) {
      let i = 0;
      while (i < fr.length - 1 && fr[i + 1].n <= n) i++;
      show(i, quiet);
    },
    show,
    play,
    pause,
    playing: () => raf !== 0,
    state: () => (cur >= 0 ? { index: cur, n: fr[cur].n, frames: fr.length, linear: state(cur).linear, actualDeg: state(cur).actual.map((a) => a / D), webgl: Boolean(st), schematic: ms.schematic } : null),
    markerScreen,
    pickHit,
    dispose() {
      pause();
      ui.slider.removeEventListener('input', onSlide);
      ui.play.removeEventListener('click', onPlay);
      if (st) st.dispose();
    },
  };
}
