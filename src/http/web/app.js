// The shop-floor form: pick a machine, drop a CL file, get the NC and what kinepost noticed.
// Plain JS, no build step; talks to the same API as CAM plugins (NDJSON stream of /v1/post).
const $ = (id) => document.getElementById(id);
let machines = [];
let clLines = []; // the uploaded file's lines, to show the one a warning points at

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

function showMachine() {
  const m = machines.find((x) => x.id === $('machine').value);
  if (m) $('machine-info').textContent = `${m.kinematics}, ${m.units}, ${m.controller}; axes ${m.linear.map((l) => l.name).join('')}${m.rotary.map((r) => r.name).join('')}`;
}

function setFile(f) {
  const dt = new DataTransfer();
  dt.items.add(f);
  $('file').files = dt.files;
  $('drop-text').textContent = f.name;
}

async function submit(ev) {
  ev.preventDefault();
  const f = $('file').files[0];
  if (!f) return;
  const q = new URLSearchParams({ machine: $('machine').value, mode: $('mode').value });
  for (const k of ['dialect', 'tool_length', 'work_offset']) if ($(k).value.trim()) q.set(k, $(k).value.trim());
  $('go').disabled = true;
  $('error').hidden = true;
  $('result').hidden = true; // never show the previous file's result as this one's
  $('status').textContent = 'Post-processing…';
  $('cl-line').hidden = true;
  clLines = f.size < 64 * 1024 * 1024 ? (await f.text()).split(/\r?\n/) : [];
  try {
    const r = await fetch('/v1/post?' + q, { method: 'POST', body: f, headers: { 'content-type': 'text/plain', accept: 'application/x-ndjson' } });
    if (!r.ok) {
      const p = await r.json().catch(() => ({ detail: r.statusText }));
      throw new Error(p.detail + (p.line ? ` (CL line ${p.line}${p.column ? ', column ' + p.column : ''})` : ''));
    }
    const lines = (await r.text()).split('\n').filter((l) => l).map((l) => JSON.parse(l));
    const nc = [];
    const warn = [];
    let summary = null;
    let failed = null;
    for (const l of lines) {
      if (l.type === 'block') {
        nc.push(l.nc);
        for (const d of l.diagnostics || []) if (d.severity !== 'info') warn.push([l.n, d]);
      } else if (l.type === 'diagnostic' && l.diagnostic.severity !== 'info') warn.push(['', l.diagnostic]);
      else if (l.type === 'summary') summary = l.summary;
      else if (l.type === 'error') failed = l.error;
    }
    const name = f.name.replace(/\.[^.]*$/, '') + '.nc';
    const a = $('download');
    a.href = URL.createObjectURL(new Blob([nc.join('\n') + '\n'], { type: 'text/plain' }));
    a.download = name;
    a.textContent = `Download ${name}`;
    showSummary(summary);
    const tb = $('warnings').querySelector('tbody');
    tb.replaceChildren();
    for (const [n, d] of warn.slice(0, 500)) {
      const tr = document.createElement('tr');
      if (d.line) {
        tr.tabIndex = 0;
        tr.className = 'link';
        tr.addEventListener('click', () => showClLine(d.line));
      }
      for (const v of [n, d.line ? `line ${d.line}` : '', d.code, d.message]) {
        const td = document.createElement('td');
        td.textContent = v;
        tr.appendChild(td);
      }
      tb.appendChild(tr);
    }
    $('status').className = failed ? 'error' : 'ok';
    $('status').textContent = failed ? `Stopped: ${failed.detail}` : `${summary.blocks} blocks from ${summary.cl_points} CL points`;
    $('result').hidden = false;
  } catch (e) {
    $('error').textContent = e.message;
    $('error').hidden = false;
    $('status').textContent = '';
  } finally {
    $('go').disabled = false;
  }
}

function showClLine(n) {
  const pre = $('cl-line');
  const text = clLines[n - 1];
  pre.textContent = text === undefined ? `CL line ${n}` : `CL line ${n}: ${text}`;
  pre.hidden = false;
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

$('machine').addEventListener('change', showMachine);
$('file').addEventListener('change', () => $('file').files[0] && ($('drop-text').textContent = $('file').files[0].name));
$('post-form').addEventListener('submit', submit);
const drop = $('drop');
drop.addEventListener('dragover', (e) => { e.preventDefault(); drop.classList.add('over'); });
drop.addEventListener('dragleave', () => drop.classList.remove('over'));
drop.addEventListener('drop', (e) => { e.preventDefault(); drop.classList.remove('over'); if (e.dataTransfer.files[0]) setFile(e.dataTransfer.files[0]); });
loadMachines();
