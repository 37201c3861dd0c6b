// The machine check page: a profile's every axis on a slider within its travel, the machine
// moving live through FK computed in the page (kin.js, the server's FK written again), the tool
// tip and axis read out, and compared with the server's /v1/machines/{id}/fk on request.
import * as THREE from 'three';
import { chain, defaultTool, fk, joints } from './kin.js';
import { machineScene, sceneBox, stage } from './machine3d.js';

const $ = (id) => document.getElementById(id);
let view = null; // { ch, ms, st, words }

function fail(e) {
  $('error').textContent = e.message;
  $('error').hidden = false;
}

/** The axes of a profile, each with its slider's range (an unbounded rotary: ±360°). */
function axes(ch) {
  const out = ch.linear.filter(Boolean).map((l) => ({ name: l.name, min: l.min, max: l.max, unit: ch.units, step: (l.max - l.min) / 2000 }));
  for (const r of ch.rot) out.push({ name: r.name, min: r.min ?? -360, max: r.max ?? 360, unit: '°', step: 0.01 });
  return out;
}

function toolLength() {
  const v = Number($('tool_length').value);
  return Number.isFinite(v) && v >= 0 ? v : view.ch.defaultToolLength;
}

/** Poses the machine at the words on the sliders and reads out FK. */
function update() {
  const { ch, ms, words } = view;
  const L = toolLength();
  ms.setTool(defaultTool(ch, L));
  const { linear, actual } = joints(ch, words);
  ms.pose(linear, actual, L, [0, 0, 0]);
  if (view.st) view.st.render();
  const p = fk(ch, words, L);
  const f = (v) => v.map((x) => x.toFixed(4)).join(', ');
  const t = $('readout');
  t.replaceChildren();
  for (const [k, v] of [['Joints', Object.entries(words).map(([n, x]) => `${n}${x}`).join(' ')], ['Tip (part frame)', f(p.tip)], ['Tool axis', f(p.axis.map((x) => x))], ['Tool length', String(L)]]) {
    const tr = document.createElement('tr');
    const th = document.createElement('th');
    th.textContent = k;
    const td = document.createElement('td');
    td.textContent = v;
    td.dataset.k = k;
    tr.append(th, td);
    t.appendChild(tr);
  }
  $('compare').textContent = '';
}

function sliders(ch) {
  const el = $('sliders');
  el.replaceChildren();
  for (const a of axes(ch)) {
    const name = document.createElement('span');
    name.textContent = `${a.name} (${a.unit})`;
    const range = document.createElement('input');
    Object.assign(range, { type: 'range', min: a.min, max: a.max, step: a.step, value: Math.min(Math.max(0, a.min), a.max), id: 'axis-' + a.name });
    range.setAttribute('aria-label', a.name);
    const num = document.createElement('input');
    Object.assign(num, { type: 'number', min: a.min, max: a.max, step: 'any', value: range.value });
    num.setAttribute('aria-label', a.name + ' value');
    view.words[a.name] = Number(range.value);
    range.addEventListener('input', () => { num.value = range.value; view.words[a.name] = Number(range.value); update(); });
    num.addEventListener('change', () => {
      const v = Math.min(Math.max(Number(num.value) || 0, a.min), a.max);
      num.value = String(v);
      range.value = String(v);
      view.words[a.name] = v;
      update();
    });
    el.append(name, range, num);
  }
}

async function open(id) {
  if (view && view.st) view.st.dispose();
  $('error').hidden = true;
  const r = await fetch('/v1/machines/' + encodeURIComponent(id));
  if (!r.ok) throw new Error(`${id}: ${r.status} ${r.statusText}`);
  const model = await r.json();
  const ch = chain(model);
  const scene = new THREE.Scene();
  const ms = machineScene(ch);
  scene.add(ms.root);
  view = { ch, ms, st: null, words: {}, model };
  $('tool_length').value = String(ch.defaultToolLength);
  sliders(ch);
  ms.setTool(defaultTool(ch, ch.defaultToolLength));
  ms.pose([0, 0, 0], ch.rot.map(() => 0), ch.defaultToolLength, [0, 0, 0]);
  view.st = stage($('machine3d'), scene, sceneBox(ms.root));
  ms.loaded.then(() => view.st && view.st.render());
  $('machine-note').textContent = (ms.schematic
    ? `${model.name} (${id}) gives no bodies: a schematic (bed, carriage, a disc per rotary about its axis through its pivot) shows how the axes move, not the machine's shape.`
    : `${model.name} (${id}): ${ch.bodies.length} bodies from the profile, and the default tool.`) + ` ${model.kinematics}, ${model.units}.`;
  update();
  history.replaceState(null, '', '?machine=' + encodeURIComponent(id));
}

/** The server's FK at the sliders' joints, against the page's. */
async function compare() {
  const L = toolLength();
  const words = { ...view.words };
  const r = await fetch(`/v1/machines/${encodeURIComponent(view.ch.id)}/fk`, { method: 'POST', headers: { 'content-type': 'application/json' }, body: JSON.stringify({ joints: words, tool_length: L }) });
  if (!r.ok) throw new Error(`fk: ${r.status}`);
  const s = await r.json();
  const p = fk(view.ch, words, L);
  const d = Math.max(...p.tip.map((v, i) => Math.abs(v - s.tip[i])), ...p.axis.map((v, i) => Math.abs(v - s.axis[i])));
  $('compare').textContent = `The server's FK: tip ${s.tip.map((x) => x.toFixed(4)).join(', ')}; the page's differs by at most ${d.toExponential(1)}.`;
  return d;
}

window.kinepostCheck = {
  /** Sets axes by name (as the sliders do) and redraws; returns the page's FK. */
  set(words) {
    for (const [k, v] of Object.entries(words)) {
      view.words[k] = v;
      const el = $('axis-' + k);
      if (el) { el.value = String(v); el.nextSibling.value = String(v); }
    }
    update();
    return fk(view.ch, view.words, toolLength());
  },
  fk: (words, L) => fk(view.ch, words, L ?? toolLength()),
  state: () => view && { id: view.ch.id, words: { ...view.words }, webgl: Boolean(view.st), schematic: view.ms.schematic, bodies: view.ch.bodies.length },
  compare,
  open,
};

async function start() {
  const list = await (await fetch('/v1/machines')).json();
  const sel = $('machine');
  for (const m of list) {
    const o = document.createElement('option');
    o.value = m.id;
    o.textContent = `${m.name} (${m.id})`;
    sel.appendChild(o);
  }
  const want = new URLSearchParams(location.search).get('machine');
  sel.value = list.some((m) => m.id === want) ? want : list[0].id;
  await open(sel.value);
  sel.addEventListener('change', () => open(sel.value).catch(fail));
  $('tool_length').addEventListener('input', update);
  $('home').addEventListener('click', () => window.kinepostCheck.set(Object.fromEntries(Object.keys(view.words).map((k) => [k, 0]))));
  $('server').addEventListener('click', () => compare().catch(fail));
  window.kinepostCheck.ready = true;
}
start().catch(fail);
