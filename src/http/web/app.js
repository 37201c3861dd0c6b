// The shop-floor form: pick a machine, drop a CL file, watch the job, get the NC and see what
// kinepost noticed. Plain JS modules, no build step; the same API as CAM plugins (/v1/jobs).
// A result opens by URL (/?job=ID), so a link to it can be passed around the shop floor.
import { markers, plots, view3d } from './view.js';
import { programView } from './ncview.js';
import { machineView } from './simulate.js';

const $ = (id) => document.getElementById(id);
let machines = [];
let shown = null; // { id, preview, list, view, sim, plots }
let token = 0; // the job on screen; a newer one stops the older's polling
let program = null; // the program view (ncview.js) of the job on screen
let fields = []; // the post options, as the service defines them (its OpenAPI document)

async function problem(r) {
  const p = await r.json().catch(() => ({ detail: r.statusText }));
  return new Error((p.detail || p.title || r.statusText) + (p.line ? ` (CL line ${p.line}${p.column ? ', column ' + p.column : ''})` : ''));
}

async function loadMachines() {
  const r = await fetch('/v1/machines');
  machines = await r.json();
  const sel = $('machine');
  for (const m of machines) {
    const o = document.createElement('option');
    o.value = m.id;
    o.textContent = `${m.name} (${m.id})`;
    sel.appendChild(o);
  }
  showMachine();
}

/** Every dialect the service knows, after the machine's own default. */
async function loadDialects() {
  const r = await fetch('/v1/dialects');
  const sel = $('dialect');
  for (const d of await r.json()) {
    if (sel.querySelector(`option[value="${d.name}"]`)) continue;
    const o = document.createElement('option');
    o.value = d.name;
    o.textContent = d.title;
    sel.appendChild(o);
  }
}

/** The post options, named once by the service (`post::Settings`, the schema `PostParams` of
 *  its OpenAPI document): the form's own controls lay out the common ones; every other option
 *  gets a plain field under "More options", its description as its title, so an option the
 *  service adds is on the page without a change here. */
async function loadFields() {
  const r = await fetch('/openapi.json');
  const schema = (await r.json()).components.schemas.PostParams;
  const more = $('more-fields');
  fields = Object.keys(schema.properties).filter((k) => k !== 'machine');
  for (const k of fields) {
    if ($(k)) continue;
    const p = schema.properties[k];
    const kind = [].concat(p.type)[0];
    const label = document.createElement('label');
    const input = document.createElement('input');
    input.id = k;
    input.name = k;
    input.type = kind === 'boolean' ? 'checkbox' : (kind === 'number' || kind === 'integer') ? 'number' : 'text';
    if (input.type === 'number') input.step = 'any';
    input.title = p.description || '';
    label.append(k.replace(/_/g, ' ') + ' ', input);
    more.appendChild(label);
  }
}

/** A field's value as the form sends it ('' for none). */
function fieldValue(el) {
  return el.type === 'checkbox' ? (el.checked ? 'true' : '') : el.value.trim();
}

/** The form shows the settings a job was posted with: a link opens the job as it was posted,
 *  and posting again repeats them (a TCP job showed "Joint"). */
function showSettings(s) {
  if (!s) return;
  for (const k of fields) {
    const el = $(k);
    if (!el) continue;
    const v = s[k] === undefined || s[k] === null ? '' : String(s[k]);
    if (el.type === 'checkbox') el.checked = v === 'true';
    else el.value = v;
    // A choice without an empty one shows its first, the default ("Joint" for no mode).
    if (el.tagName === 'SELECT' && el.selectedIndex < 0) el.selectedIndex = 0;
  }
}

function showMachine() {
  const m = machines.find((x) => x.id === $('machine').value);
  if (m) $('machine-info').textContent = `${m.kinematics}, ${m.units}, ${m.controller}; axes ${m.linear.map((l) => l.name).join('')}${m.rotary.map((r) => r.name).join('')}` +
    (m.bodies && m.bodies.length ? `; ${m.bodies.length} bodies` : '; no bodies (no collision check)');
  $('machine-check').href = '/machine-check.html?machine=' + encodeURIComponent($('machine').value);
}

function setFile(f) {
  const dt = new DataTransfer();
  dt.items.add(f);
  $('file').files = dt.files;
  $('drop-text').textContent = f.name;
}

function fail(e) {
  $('error').textContent = e.message;
  $('error').hidden = false;
}

async function submit(ev) {
  ev.preventDefault();
  const f = $('file').files[0];
  if (!f) return;
  const q = new URLSearchParams({ machine: $('machine').value });
  for (const k of fields) if ($(k) && fieldValue($(k))) q.set(k, fieldValue($(k)));
  $('go').disabled = true;
  $('error').hidden = true;
  $('result').hidden = true; // never show the previous file's result as this one's
  try {
    const body = new FormData();
    body.append('file', f);
    const r = await fetch('/v1/jobs?' + q, { method: 'POST', body });
    if (!r.ok) throw await problem(r);
    const job = await r.json();
    history.pushState({ job: job.id }, '', '/?job=' + job.id);
    await showJob(job.id);
  } catch (e) {
    fail(e);
  } finally {
    $('go').disabled = false;
  }
}

/** A job's result view: progress while it runs, then summary, 3D view, plots and warnings. */
async function showJob(id) {
  const mine = ++token;
  $('result').hidden = false;
  $('details').hidden = true;
  $('download').hidden = true;
  $('cl-line').hidden = true;
  closeProgram();
  $('permalink').href = '/?job=' + id;
  $('permalink').textContent = location.origin + '/?job=' + id;
  const bar = $('progress');
  bar.hidden = false;
  bar.value = 0;
  $('status').className = '';
  let job;
  for (;;) {
    const r = await fetch('/v1/jobs/' + encodeURIComponent(id));
    if (!r.ok) throw await problem(r);
    job = await r.json();
    if (mine !== token) return;
    bar.value = job.progress.percent;
    if (['succeeded', 'failed', 'cancelled'].includes(job.state)) break;
    $('status').textContent = job.state === 'queued' ? 'Queued…' : `Post-processing… ${job.progress.percent.toFixed(0)} % (${job.progress.blocks} blocks)`;
    await new Promise((res) => setTimeout(res, 250));
  }
  bar.hidden = true;
  if (machines.some((m) => m.id === job.machine)) {
    $('machine').value = job.machine;
    showMachine();
  }
  showSettings(job.settings);
  const s = job.summary;
  if (job.state === 'succeeded') {
    const name = (job.filename || 'program').replace(/\.[^.]*$/, '') + '.nc';
    const a = $('download');
    a.href = job.links.nc;
    a.download = name;
    a.textContent = `Download ${name}`;
    a.hidden = false;
    // Written is not good: a program with errors is failed-with-output, never a success.
    const n = (x) => x.toLocaleString();
    if (s.errors > 0) {
      $('status').className = 'error';
      $('status').textContent = `${n(s.errors)} errors: ${n(s.blocks)} blocks written, not fit to run as they are (see the blocks marked ERROR)`;
    } else if (s.warnings > 0) {
      $('status').className = 'warn';
      $('status').textContent = `${n(s.blocks)} blocks from ${n(s.cl_points)} CL points, ${n(s.warnings)} warnings`;
    } else {
      $('status').className = 'ok';
      $('status').textContent = `${n(s.blocks)} blocks from ${n(s.cl_points)} CL points`;
    }
  } else {
    $('status').className = 'error';
    $('status').textContent = job.state === 'failed' ? `Stopped: ${job.error}` : 'Cancelled';
  }
  showSummary(s);
  if (job.state === 'succeeded') openProgram(job, mine);
  if (!job.links.preview) return;
  const r = await fetch(job.links.preview);
  if (!r.ok) throw await problem(r);
  const preview = await r.json();
  if (mine !== token) return;
  $('details').hidden = false;
  showPreview(id, preview);
  // A preview written before it carried the machine names it by id: the profile's as it is now.
  let model = preview.machine;
  if (typeof model !== 'object' || !model) {
    const m = await fetch('/v1/machines/' + encodeURIComponent(model || job.machine));
    model = m.ok ? await m.json() : null;
  }
  if (mine !== token) return;
  if (model) showMachineRun(preview, model);
}

/** The program on the machine (simulate.js), its slider linked to the plots' cursor. */
function showMachineRun(p, model) {
  if (shown.sim) shown.sim.dispose();
  $('collision-info').hidden = true;
  const ui = { view: $('machine3d'), play: $('sim-play'), slider: $('sim-slider'), speed: $('sim-speed'), where: $('sim-where'), note: $('machine-note'), info: $('collision-info') };
  shown.sim = machineView(ui, p, model, (m) => {
    const k = shown.list.findIndex((x) => x.n === m.n);
    if (k >= 0) pick(shown.list[k]);
  }, (n) => shown.plots && shown.plots.cursor(n));
  if (shown.plots) shown.plots.cursor(shown.sim.frames.length ? shown.sim.frames[0].n : 0);
  window.kinepostSim = shown.sim;
}

function closeProgram() {
  if (program) program.dispose();
  program = null;
  window.kinepostProgram = null;
  $('program').hidden = true;
}

/** The NC beside its CL, read a screenful at a time (ncview.js). */
async function openProgram(job, mine) {
  $('program').hidden = false;
  $('nc-where').textContent = 'Opening the program…';
  try {
    const view = await programView({ nc: $('nc-pane'), cl: $('cl-pane'), where: $('nc-where') }, job);
    if (mine !== token) { view.dispose(); return; }
    program = view;
    window.kinepostProgram = view;
  } catch (e) {
    $('nc-where').textContent = e.message;
  }
}

function showPreview(id, p) {
  if (shown && shown.view) shown.view.dispose();
  if (shown && shown.sim) shown.sim.dispose();
  window.kinepostSim = null;
  const list = markers(p);
  shown = { id, preview: p, list, view: null, sim: null, plots: null };
  $('path-info').textContent = `${p.points.length} of ${p.blocks} blocks drawn` +
    (p.stride > 1 ? ` (every ${p.stride}th, plus rapid/feed changes and the ends)` : '') +
    `; ${p.marks.length + p.notes.length} marked` + (p.marks_dropped + p.notes_dropped ? `, ${p.marks_dropped + p.notes_dropped} more not shown (see the diagnostics)` : '');
  shown.view = view3d($('view3d'), p, list, pick);
  drawPlots();
  const tb = $('warnings').querySelector('tbody');
  tb.replaceChildren();
  list.forEach((m, i) => {
    for (const d of m.diagnostics) {
      if (d.severity === 'info' && !['unwind', 'branch_change'].includes(d.code)) continue;
      const tr = document.createElement('tr');
      tr.tabIndex = 0;
      tr.className = 'link';
      tr.dataset.marker = i;
      tr.addEventListener('click', () => pick(m));
      tr.addEventListener('keydown', (e) => { if (e.key === 'Enter') pick(m); });
      for (const v of [m.n ?? '', m.line ? `line ${m.line}` : '', d.code, d.message]) {
        const td = document.createElement('td');
        td.textContent = v;
        tr.appendChild(td);
      }
      tb.appendChild(tr);
    }
  });
  window.kinepostView = { id, markers: list, markerScreen: (i) => shown.view.markerScreen(i) };
}

function drawPlots() {
  if (!shown) return;
  shown.plots = plots($('plots'), shown.preview, shown.list, $('xaxis').value, pick, (n) => shown.sim && shown.sim.seek(n, false));
  const st = shown.sim && shown.sim.state();
  if (st) shown.plots.cursor(st.n);
}

/** A marker picked (in the 3D view, a plot or the table): its block, CL line and diagnostics. */
function pick(m) {
  const lines = [];
  if (m.line) lines.push(`CL line ${m.line}: ${m.cl ?? ''}`);
  lines.push(m.n ? `NC block ${m.n}: ${m.nc}` : 'No NC block: the pose was skipped');
  for (const d of m.diagnostics) lines.push(`${d.severity} ${d.code}: ${d.message}`);
  const pre = $('cl-line');
  pre.textContent = lines.join('\n');
  pre.hidden = false;
  const i = shown.list.indexOf(m);
  for (const tr of $('warnings').querySelectorAll('tbody tr')) tr.classList.toggle('selected', Number(tr.dataset.marker) === i);
  shown.view.select(m);
}

function showSummary(s) {
  const t = $('summary');
  t.replaceChildren();
  if (!s) return;
  const rows = [
    ['Machine', `${s.machine} (${s.units}, ${s.mode})`],
    ['CL points / blocks', `${s.cl_points} / ${s.blocks} (${s.inserted_blocks} inserted)`],
    ['FK replay: largest deviation', `${s.max_tip_deviation.toExponential(2)} ${s.units}, ${s.max_axis_deviation_deg.toExponential(2)}°`],
    ['Estimated cycle time', `${(s.cycle_time_s / 60).toFixed(1)} min`],
    ['Errors / warnings', `${s.errors} / ${s.warnings}`],
  ];
  if (s.canned_holes) rows.splice(2, 0, ['Holes as canned cycles', String(s.canned_holes)]);
  for (const [ax, st] of Object.entries(s.axes)) {
    if (st.travel !== undefined) rows.push([`${ax} rotary`, `travel ${st.travel.toFixed(1)}°, largest step ${(st.largest_step || 0).toFixed(2)}°, range ${st.min.toFixed(2)}…${st.max.toFixed(2)}°`]);
  }
  for (const [code, n] of Object.entries(s.counts)) rows.push([`Diagnostics: ${code}`, String(n)]);
  for (const [k, v] of rows) {
    const tr = document.createElement('tr');
    const th = document.createElement('th');
    th.textContent = k;
    const td = document.createElement('td');
    td.textContent = v;
    tr.append(th, td);
    t.appendChild(tr);
  }
}

function fromUrl() {
  const id = new URLSearchParams(location.search).get('job');
  if (id) showJob(id).catch(fail);
  else $('result').hidden = true;
}

$('machine').addEventListener('change', showMachine);
$('xaxis').addEventListener('change', drawPlots);
// The plots are drawn at the width they are shown at: again when that changes.
let plotWidth = 0;
new ResizeObserver(() => {
  const w = $('plots').clientWidth;
  if (w && Math.abs(w - plotWidth) > 8) { plotWidth = w; drawPlots(); }
}).observe($('plots'));
$('file').addEventListener('change', () => $('file').files[0] && ($('drop-text').textContent = $('file').files[0].name));
$('post-form').addEventListener('submit', submit);
for (const b of document.querySelectorAll('[data-next]')) b.addEventListener('click', () => program && program.next(b.dataset.next));
$('nc-find').addEventListener('submit', (e) => { e.preventDefault(); if (program) program.find($('nc-search').value.trim()); });
const drop = $('drop');
drop.addEventListener('dragover', (e) => { e.preventDefault(); drop.classList.add('over'); });
drop.addEventListener('dragleave', () => drop.classList.remove('over'));
drop.addEventListener('drop', (e) => { e.preventDefault(); drop.classList.remove('over'); if (e.dataTransfer.files[0]) setFile(e.dataTransfer.files[0]); });
window.addEventListener('popstate', fromUrl);
// Both lists before a job's settings are shown in them.
Promise.all([loadMachines(), loadDialects(), loadFields()]).then(fromUrl, fail);
