// The machine on the page, in a real headless Chromium: for each machine kind (table-table,
// head-head, head-table, nutating, three-rotary) a CL made to crash (tests/it/collide.rs's programs
// and bodies) is posted as a job; the result page draws the machine, moves it with the block
// slider (the plots' cursor follows, a plot click moves it back), plays, and a click on a
// collision marker explains it (block, bodies, depth, CL line). The machine check page moves
// each profile from its sliders, its FK equal to the server's; without WebGL it still reads out.
// Screenshots: target/browser/machine-<kind>.png, check-<kind>.png. Needs a running kinepost
// (KINEPOST_URL) with an admin token (KINEPOST_ADMIN_TOKEN, default ci-fuzz: profiles with bodies
// are written over the API where the shipped ones have none) and Debian's chromium.
import { chromium } from 'playwright-core';
import { mkdirSync, readFileSync } from 'node:fs';
import { fileURLToPath } from 'node:url';
import path from 'node:path';

const here = path.dirname(fileURLToPath(import.meta.url));
const base = process.env.KINEPOST_URL || 'http://127.0.0.1:8080';
const token = process.env.KINEPOST_ADMIN_TOKEN || 'ci-fuzz';
const shots = path.join(here, '..', '..', 'target', 'browser');
mkdirSync(shots, { recursive: true });
let passed = 0, failed = 0;
const check = (ok, what) => { if (ok) { passed++; console.log('ok  ', what); } else { failed++; console.log('FAIL', what); } };

const UP = [0, 0, 1];
const tilted = (deg) => [Math.sin(deg * Math.PI / 180), 0, Math.cos(deg * Math.PI / 180)];
/** tests/it/collide.rs's `cl`: the header, then points; the CL line of each point. */
function cl(units, length, pts) {
  const s = ['PARTNO/COLLIDE', `UNITS/${units}`, `LOADTL/1,LENGTH,${length}`, 'SPINDL/6000,RPM,CLW', `FEDRAT/500,${units === 'MM' ? 'MMPM' : 'IPM'}`];
  const lines = [];
  for (const [rapid, p, a] of pts) {
    if (rapid) s.push('RAPID');
    s.push(`GOTO/${[...p, ...a].map((v) => +v.toFixed(6)).join(',')}`);
    lines.push(s.length);
  }
  s.push('SPINDL/OFF', 'FINI', '');
  return { text: s.join('\n'), lines };
}

// Per machine kind: a shipped profile, bodies (tests/it/collide.rs's) where it has none, a crash
// and the bodies it names.
const KINDS = [
  {
    kind: 'table-table', id: 'spinner-u5-620', stock: '-50,-50,0,50,50,40',
    bodies: `[[body]]\nname = "table"\non = "C"\ncylinder = { from = [0.0, 0.0, -60.0], to = [0.0, 0.0, 0.0], radius = 300.0 }\n[[body]]\nname = "cradle"\non = "B"\nbox = [-320.0, -340.0, -160.0, 320.0, 340.0, -80.0]\n[[body]]\nname = "base"\non = "bed"\nbox = [-700.0, -700.0, -900.0, 700.0, 700.0, -460.0]\n[[body]]\nname = "spindle housing"\non = "spindle"\ncylinder = { from = [0.0, 0.0, 5.0], to = [0.0, 0.0, 300.0], radius = 90.0 }\n[[body]]\nname = "ram"\non = "ram"\nbox = [-160.0, -160.0, 300.0, 160.0, 400.0, 900.0]\n`,
    cl: cl('MM', 100, [[true, [0, 0, 100], UP], [false, [0, 0, 60], UP], [true, [0, 0, 100], UP], [true, [0, 0, 100], tilted(85)], [false, [0, 0, 6], tilted(85)]]),
    crash: 4, names: ['holder', 'table'],
  },
  {
    kind: 'head-head', id: 'fryer-5x-45',
    bodies: `[[body]]\nname = "table"\non = "table"\nbox = [-20.0, -10.0, -2.0, 20.0, 10.0, 0.0]\n[[body]]\nname = "a fork"\non = "A"\nbox = [-2.5, -1.0, 4.0, 2.5, 1.0, 6.0]\n[[body]]\nname = "spindle housing"\non = "spindle"\ncylinder = { from = [0.0, 0.0, 0.3], to = [0.0, 0.0, 4.0], radius = 1.5 }\n[[body]]\nname = "c head"\non = "C"\nbox = [-3.0, -3.0, 7.0, 3.0, 3.0, 12.0]\n`,
    cl: cl('INCHES', 3, [[true, [0, 0, -10], UP], [false, [0, 0, -16], UP], [false, [0, 0, -18.5], UP]]),
    crash: 2, names: ['cutter', 'table'],
  },
  {
    kind: 'head-table', id: 'dmg-dmc75v',
    bodies: `[[body]]\nname = "table"\non = "C"\ncylinder = { from = [0.0, 0.0, -80.0], to = [0.0, 0.0, 0.0], radius = 300.0 }\n[[body]]\nname = "b head"\non = "B"\nbox = [-90.0, -120.0, 100.0, 90.0, 120.0, 220.0]\n[[body]]\nname = "spindle housing"\non = "spindle"\ncylinder = { from = [0.0, 0.0, 5.0], to = [0.0, 0.0, 100.0], radius = 70.0 }\n`,
    cl: cl('MM', 100, [[true, [0, 0, 300], UP], [false, [0, 0, 30], UP], [true, [0, 0, 300], UP], [true, [0, 0, 300], [-1, 0, 0]], [false, [0, 0, 30], [-1, 0, 0]]]),
    crash: 4, names: ['b head', 'table'],
  },
  {
    kind: 'nutating', id: 'dmu-nutating-45',
    bodies: `[[body]]\nname = "table"\non = "C"\ncylinder = { from = [0.0, 0.0, -40.0], to = [0.0, 0.0, 0.0], radius = 200.0 }\n[[body]]\nname = "nutating body"\non = "B"\ncylinder = { from = [0.0, 0.0, -200.0], to = [0.0, 0.0, -60.0], radius = 150.0 }\n`,
    cl: cl('MM', 100, [[true, [0, 0, 100], UP], [false, [0, 0, 10], UP], [true, [0, 0, 100], UP], [true, [0, 0, 100], tilted(40)], [false, [0, 0, 30], tilted(40)], [false, [0, 0, -8], UP]]),
    crash: 5, names: ['cutter', 'table'],
  },
  {
    kind: 'three-rotary', id: 'propeller-3r2l',
    bodies: `[[body]]\nname = "table"\non = "C"\ncylinder = { from = [0.0, 0.0, -100.0], to = [0.0, 0.0, 0.0], radius = 400.0 }\n[[body]]\nname = "b head"\non = "B"\ncylinder = { from = [-80.0, 0.0, 150.0], to = [80.0, 0.0, 150.0], radius = 60.0 }\n`,
    cl: cl('MM', 100, [[true, [0, 0, 300], UP], [false, [0, 0, 50], UP], [false, [0, 0, 50], tilted(30)], [false, [0, 0, -10], UP]]),
    crash: 3, names: ['cutter', 'table'],
  },
];

/** The profile to run a kind on: the shipped one where it has bodies, else a copy with the
 *  test's bodies written over the API (`<id>-bodies`). Returns [id, own bodies?]. */
async function profileFor(k) {
  const shipped = await (await fetch(`${base}/v1/machines/${k.id}`)).json();
  if (shipped.bodies && shipped.bodies.length) return [k.id, false];
  const id = `${k.id}-bodies`;
  const toml = await (await fetch(`${base}/v1/machines/${k.id}`, { headers: { accept: 'application/toml' } })).text();
  const body = toml.replace(/^id\s*=\s*"[^"]*"/m, `id = "${id}"`) + '\n' + k.bodies;
  const r = await fetch(`${base}/v1/machines/${id}`, { method: 'PUT', headers: { authorization: `Bearer ${token}`, 'content-type': 'application/toml' }, body });
  if (!r.ok) throw new Error(`PUT ${id}: ${r.status} ${await r.text()}`);
  return [id, true];
}

/** A copy of a shipped profile without its bodies (`<id>-bare`), written over the API. */
async function bareProfile(shippedId) {
  const id = `${shippedId}-bare`;
  const toml = await (await fetch(`${base}/v1/machines/${shippedId}`, { headers: { accept: 'application/toml' } })).text();
  const cut = toml.search(/^(# Geometry for the collision check|\[\[body\]\])/m);
  const body = (cut < 0 ? toml : toml.slice(0, cut)).replace(/^id\s*=\s*"[^"]*"/m, `id = "${id}"`);
  const r = await fetch(`${base}/v1/machines/${id}`, { method: 'PUT', headers: { authorization: `Bearer ${token}`, 'content-type': 'application/toml' }, body });
  if (!r.ok) throw new Error(`PUT ${id}: ${r.status} ${await r.text()}`);
  return id;
}

async function job(machine, text, query = '') {
  const r = await fetch(`${base}/v1/jobs?machine=${machine}${query}`, { method: 'POST', headers: { 'content-type': 'text/plain' }, body: text });
  const j = await r.json();
  if (!r.ok) throw new Error(`job: ${JSON.stringify(j)}`);
  for (let t = 0; t < 300; t++) {
    const s = await (await fetch(`${base}/v1/jobs/${j.id}`)).json();
    if (!['queued', 'running'].includes(s.state)) return s;
    await new Promise((res) => setTimeout(res, 100));
  }
  throw new Error('job did not finish');
}

/** Pixels of a canvas that differ from its corner (the background), and a coarse signature. */
const pixels = (sel) => (page) => page.evaluate((s) => {
  const c = document.querySelector(s);
  const t = document.createElement('canvas');
  [t.width, t.height] = [c.width, c.height];
  const g = t.getContext('2d');
  g.drawImage(c, 0, 0);
  const px = g.getImageData(0, 0, t.width, t.height).data;
  const bg = px.slice(0, 3);
  let n = 0;
  let sig = 0;
  for (let i = 0; i < px.length; i += 4) {
    if (Math.abs(px[i] - bg[0]) + Math.abs(px[i + 1] - bg[1]) + Math.abs(px[i + 2] - bg[2]) > 30) { n++; sig = (sig * 31 + i) % 1000000007; }
  }
  return { n, sig };
}, sel);
const machinePixels = pixels('#machine3d canvas');

/** Sets a range input as a user's drag does: value, then an input event. */
const slide = (page, sel, v) => page.evaluate(([s, x]) => { const e = document.querySelector(s); e.value = String(x); e.dispatchEvent(new Event('input', { bubbles: true })); }, [sel, v]);

const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
  args: ['--headless', '--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--disable-quic', '--no-first-run', '--disable-background-networking', '--disable-component-update', '--disable-sync'],
});
const made = [];
try {
  const page = await browser.newPage({ viewport: { width: 1280, height: 1000 } });
  for (const k of KINDS) {
    const [id, own] = await profileFor(k);
    if (own) made.push(id);
    const j = await job(id, k.cl.text, k.stock ? `&stock=${k.stock}` : '');
    check(j.state === 'succeeded' && j.summary.counts.collision > 0, `${k.kind} (${id}): the crash CL posts with ${j.summary.counts.collision} collision diagnostics`);
    await page.goto(`${base}/?job=${j.id}`);
    await page.waitForFunction(() => window.kinepostSim && window.kinepostSim.state(), null, { timeout: 60000 });
    const st0 = await page.evaluate(() => window.kinepostSim.state());
    const note = await page.textContent('#machine-note');
    check(st0.webgl && !st0.schematic && /bodies from the profile/.test(note), `${k.kind}: the machine is drawn from its bodies (${note.slice(0, 80)})`);
    await page.locator('#machine3d').scrollIntoViewIfNeeded();
    // The slider moves the machine, and the plots' cursor with it: to the block whose joints are
    // farthest from the first's.
    await slide(page, '#sim-slider', 0);
    const a = await machinePixels(page);
    const last = await page.evaluate(() => {
      const f = window.kinepostSim.frames;
      const far = f.map((q) => q.j.reduce((s, v, i) => s + Math.abs(v - f[0].j[i]), 0));
      return far.indexOf(Math.max(...far));
    });
    await slide(page, '#sim-slider', last);
    const b = await machinePixels(page);
    const st1 = await page.evaluate(() => window.kinepostSim.state());
    const cursor = await page.$$eval('#plots svg.plot line.cursor', (l) => l.map((e) => [e.getAttribute('visibility'), Number(e.dataset.n)]));
    check(a.n > 5000 && b.n > 5000 && a.sig !== b.sig && st1.index === last, `${k.kind}: the slider moves the machine (${a.n} → ${b.n} inked pixels, block ${st0.n} → ${st1.n}, joints ${st1.actualDeg.map((x) => x.toFixed(1)).join(', ')}°)`);
    check(cursor.length > 0 && cursor.every(([v, n]) => v === 'visible' && n === st1.n), `${k.kind}: every plot's cursor at block ${st1.n} (${cursor.length} plots)`);
    // A click on a plot moves the slider back to the block under it.
    await page.locator('#plots svg.plot').first().scrollIntoViewIfNeeded();
    const plot = await page.locator('#plots svg.plot').first().boundingBox();
    const lastN = await page.evaluate(() => window.kinepostSim.frames.at(-1).n);
    const early = st1.n > lastN / 2;
    await page.mouse.click(plot.x + plot.width * (early ? 0.1 : 0.97), plot.y + plot.height / 2);
    const st2 = await page.evaluate(() => window.kinepostSim.state());
    const cursor2 = await page.$$eval('#plots svg.plot line.cursor', (l) => l.map((e) => Number(e.dataset.n)));
    check((early ? st2.n < st1.n : st2.n > st1.n) && Number(await page.inputValue('#sim-slider')) === st2.index && cursor2.every((n) => n === st2.n),
      `${k.kind}: a plot click moves the machine, the slider and the cursors to block ${st2.n}`);
    await page.locator('#machine3d').screenshot({ path: path.join(shots, `machine-${k.kind}.png`) });
    // A collision marker: red, where the crash is; a click explains it.
    const hit = await page.evaluate(() => {
      const v = window.kinepostSim;
      const k = v.collisions.findIndex((m) => (m.contacts || []).some((c) => c.code === 'collision'));
      return k < 0 ? null : { k, n: v.collisions[k].n, line: v.collisions[k].line, at: v.markerScreen(k), contacts: v.collisions[k].contacts };
    });
    check(hit && hit.line === k.cl.lines[k.crash], `${k.kind}: a collision marker at CL line ${hit && hit.line} (the crash is line ${k.cl.lines[k.crash]}): ${JSON.stringify(hit && hit.contacts)}`);
    if (!hit) continue;
    await page.locator('#machine3d').scrollIntoViewIfNeeded();
    const box = await page.locator('#machine3d canvas').boundingBox();
    await page.mouse.click(box.x + hit.at.x, box.y + hit.at.y);
    await page.waitForSelector('#collision-info:not([hidden])', { timeout: 5000 }).catch(() => null);
    const info = (await page.textContent('#collision-info')) || '';
    const names = own ? k.names : [];
    check(info.startsWith(`Collision at NC block ${hit.n} (CL line ${hit.line})`) && /overlap by [\d.]+ (mm|inch)/.test(info) && names.every((n) => info.includes(n)) && info.includes('GOTO/'),
      `${k.kind}: the marker's click explains it: ${info.replace(/\n/g, ' | ').slice(0, 200)}`);
    const st3 = await page.evaluate(() => window.kinepostSim.state());
    const red = await page.evaluate(() => /touching/.test(document.getElementById('sim-where').textContent));
    check(st3.n === hit.n && red, `${k.kind}: the machine stands at block ${hit.n}, the bodies touching in red`);
    await page.locator('#machine3d').screenshot({ path: path.join(shots, `machine-${k.kind}-collision.png`) });
  }

  // A profile without bodies (a copy of haas-umc750's kinematics): a schematic moves with the
  // slider, and the page says so.
  const bare = await bareProfile('haas-umc750');
  {
    const text = readFileSync(path.join(here, '..', 'data', 'nx_clsf_mech491_variable_axis_inch_5ax.cls'), 'utf8');
    const j = await job(bare, text, '&mode=tcp');
    await page.goto(`${base}/?job=${j.id}`);
    await page.waitForFunction(() => window.kinepostSim && window.kinepostSim.state(), null, { timeout: 60000 });
    await page.locator('#machine3d').scrollIntoViewIfNeeded();
    const a = await machinePixels(page);
    await slide(page, '#sim-slider', Math.floor((await page.evaluate(() => window.kinepostSim.frames.length)) / 2));
    const b = await machinePixels(page);
    const note = await page.textContent('#machine-note');
    const st = await page.evaluate(() => window.kinepostSim.state());
    check(st.schematic && /schematic/.test(note) && a.sig !== b.sig && b.n > 3000, `${bare} (haas-umc750 without bodies, TCP): a schematic moves with the slider, the page says so (${note.slice(0, 70)}…)`);
    await page.locator('#machine3d').screenshot({ path: path.join(shots, 'machine-schematic.png') });
    made.push(bare);
  }

  // Play runs the program; pause stops it.
  await slide(page, '#sim-slider', 0);
  await page.selectOption('#sim-speed', '4');
  await page.click('#sim-play');
  await page.waitForTimeout(2000);
  const playing = await page.evaluate(() => window.kinepostSim.state().index);
  await page.click('#sim-play');
  const paused = await page.evaluate(() => window.kinepostSim.state().index);
  await page.waitForTimeout(400);
  const still = await page.evaluate(() => window.kinepostSim.state().index);
  check(playing > 0 && paused === still && !(await page.evaluate(() => window.kinepostSim.playing())), `play moves on (frame ${playing}), pause stops (frame ${still})`);

  // The machine check page: every kind's profile from the form's link, moved from its sliders.
  for (const k of KINDS) {
    const id = made.includes(`${k.id}-bodies`) ? `${k.id}-bodies` : k.id;
    await page.goto(`${base}/`);
    await page.waitForSelector(`#machine option[value="${id}"]`, { state: 'attached' });
    await page.selectOption('#machine', id);
    await page.click('#machine-check');
    await page.waitForFunction(() => window.kinepostCheck && window.kinepostCheck.ready, null, { timeout: 30000 });
    const cst = await page.evaluate(() => window.kinepostCheck.state());
    check(cst.id === id && cst.webgl && cst.bodies > 0, `${k.kind}: the form's link opens the machine check of ${cst.id} (${cst.bodies} bodies)`);
    await page.locator('#machine3d').scrollIntoViewIfNeeded();
    const home = await pixels('#machine3d canvas')(page);
    // The last rotary to the end of its travel, from the keyboard as a user would.
    const names = await page.$$eval('#sliders input[type=range]', (l) => l.map((e) => e.getAttribute('aria-label')));
    const rot = names[names.length - 1];
    await page.focus(`#axis-${rot}`);
    await page.keyboard.press('End');
    await page.focus(`#axis-${names[names.length - 2]}`);
    for (let i = 0; i < 40; i++) await page.keyboard.press('PageUp');
    const moved = await pixels('#machine3d canvas')(page);
    const words = await page.evaluate(() => window.kinepostCheck.state().words);
    check(home.sig !== moved.sig && moved.n > 3000, `${k.kind}: the sliders move the machine (${JSON.stringify(words, (_, v) => (typeof v === 'number' ? +v.toFixed(2) : v))})`);
    await page.locator('main').screenshot({ path: path.join(shots, `check-${k.kind}.png`) });
    await page.click('#server');
    await page.waitForFunction(() => /differs by at most/.test(document.getElementById('compare').textContent), null, { timeout: 10000 });
    const cmp = await page.textContent('#compare');
    const d = Number((cmp.match(/at most (\d\.\d+e[+-]\d+)/) || [])[1]);
    check(d <= 1e-6, `${k.kind}: the page's FK at the sliders equals the server's (${d})`);
  }

  // Without WebGL the check page says so, and the sliders still read out the tool.
  const flat = await browser.newPage();
  await flat.addInitScript(() => {
    const get = HTMLCanvasElement.prototype.getContext;
    HTMLCanvasElement.prototype.getContext = function (t, ...a) { return /webgl/.test(t) ? null : get.call(this, t, ...a); };
  });
  await flat.goto(`${base}/machine-check.html?machine=spinner-u5-620`);
  await flat.waitForFunction(() => window.kinepostCheck && window.kinepostCheck.ready, null, { timeout: 30000 });
  const msg = await flat.textContent('#machine3d');
  const before = await flat.textContent('#readout');
  await flat.focus('#axis-B');
  await flat.keyboard.press('End');
  const after = await flat.textContent('#readout');
  check(/No 3D view/.test(msg) && before !== after && /Tip/.test(after), `without WebGL: "${msg.slice(0, 50)}…", the readout follows the sliders`);
  await flat.close();
} catch (e) {
  failed++;
  console.log('FAIL', e.stack || e.message);
} finally {
  for (const id of made) await fetch(`${base}/v1/machines/${id}`, { method: 'DELETE', headers: { authorization: `Bearer ${token}` } }).catch(() => null);
  await browser.close();
}
console.log(`${passed} passed, ${failed} failed`);
process.exit(failed ? 1 : 0);
