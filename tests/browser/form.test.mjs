// The shop-floor form in a real headless Chromium: pick a machine, upload a corpus file through
// the page as a job, check the downloaded NC, the summary, the 3D view, the plots, a marker click
// and the shareable job link, the program view (NC beside CL, a 1 M-line program scrolled,
// linked lines, jumps, search) and Swagger UI. Screenshots land in target/browser/. Needs a running kinepost (KINEPOST_URL) and
// Debian's chromium (CHROMIUM, default /usr/bin/chromium). Prints "N passed, M failed".
import { chromium } from 'playwright-core';
import { readFileSync, mkdirSync } from 'node:fs';
import { fileURLToPath } from 'node:url';
import path from 'node:path';

const here = path.dirname(fileURLToPath(import.meta.url));
const base = process.env.KINEPOST_URL || 'http://127.0.0.1:8080';
const data = path.join(here, '..', 'data');
const shots = path.join(here, '..', '..', 'target', 'browser');
mkdirSync(shots, { recursive: true });
let passed = 0, failed = 0;
const check = (ok, what) => { if (ok) { passed++; console.log('ok  ', what); } else { failed++; console.log('FAIL', what); } };

const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
  // No GPU here: WebGL on SwiftShader, Chromium's software rasterizer.
  args: ['--headless', '--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--disable-quic', '--no-first-run', '--disable-background-networking', '--disable-component-update', '--disable-sync'],
});
/** Runs a CL file through the form as a job and waits for its result view (preview drawn). */
async function runJob(page, machine, mode, file) {
  const before = page.url();
  await page.selectOption('#machine', machine);
  await page.selectOption('#mode', mode);
  await page.setInputFiles('#file', path.join(data, file));
  await page.click('#go');
  await page.waitForURL((u) => u.href !== before);
  await page.waitForFunction(() => window.kinepostView && location.search.endsWith(window.kinepostView.id), null, { timeout: 60000 });
}

try {
  const page = await browser.newPage({ acceptDownloads: true });
  await page.goto(base + '/');
  await page.waitForSelector('#machine option[value="haas-umc750"]', { state: 'attached' });
  const machineIds = (await (await fetch(base + '/v1/machines')).json()).map((m) => m.id);
  check(await page.locator('#machine option').count() === machineIds.length && machineIds.length >= 11, 'the machine list comes from the API');
  await page.selectOption('#machine', 'haas-umc750');
  check((await page.textContent('#machine-info')).includes('table-table'), 'machine facts shown');
  // NX's CLSF carries no SPINDL: the speed comes from the form.
  await page.fill('#spindle_speed', '9000');
  await runJob(page, 'haas-umc750', 'tcp', 'nx_clsf_mech491_variable_axis_inch_5ax.cls');
  const status = await page.textContent('#status');
  check(status.includes('blocks from 348 CL points'), `status: ${status}`);
  const jobUrl = page.url();
  check(/\/\?job=[0-9a-f]{32}$/.test(jobUrl), `the result has its own URL: ${jobUrl}`);
  const summary = await page.textContent('#summary');
  check(summary.includes('FK replay') && summary.includes('C rotary') && summary.includes('travel 3856.6'), 'summary shows FK replay and rotary travel');
  // While a job runs, or when it failed, the button is hidden: `hidden` must win over .button.
  const hiddenShows = await page.evaluate(() => {
    const a = document.createElement('a');
    a.className = 'button';
    a.hidden = true;
    document.body.appendChild(a);
    const d = getComputedStyle(a).display;
    a.remove();
    return d;
  });
  check(hiddenShows === 'none', `a hidden button is not shown (display ${hiddenShows})`);
  const [download] = await Promise.all([page.waitForEvent('download'), page.click('#download')]);
  const file = path.join(shots, download.suggestedFilename());
  await download.saveAs(file);
  const nc = readFileSync(file, 'utf8');
  check(download.suggestedFilename() === 'nx_clsf_mech491_variable_axis_inch_5ax.nc', `download name ${download.suggestedFilename()}`);
  check(nc.startsWith('%\nO01000\n') && nc.trimEnd().endsWith('M30\n%') && nc.includes('G234 H1'), 'downloaded NC is a whole Haas TCP program');
  check(nc.includes('B-22.2015 C1.0496'), 'first orientation as the real NX post');
  check(/\nS9000 M3\nG234 H1\n/.test(nc), 'the spindle speed from the form started before TCP on');

  // The 3D view draws (WebGL, non-blank pixels) and the plots show every axis word.
  await page.waitForSelector('#view3d canvas');
  const inked = await page.evaluate(() => {
    const c = document.querySelector('#view3d canvas');
    const t = document.createElement('canvas');
    [t.width, t.height] = [c.width, c.height];
    const g = t.getContext('2d');
    g.drawImage(c, 0, 0);
    const px = g.getImageData(0, 0, t.width, t.height).data;
    let n = 0;
    for (let i = 0; i < px.length; i += 4) if (px[i] < 200 || px[i + 1] < 200 || px[i + 2] < 200) n++;
    return { n, webgl: Boolean(c.getContext('webgl2') || c.getContext('webgl')) };
  });
  check(inked.webgl && inked.n > 2000, `3D view rendered with WebGL: ${inked.n} inked pixels`);
  const axes = await page.$$eval('#plots svg.plot', (s) => s.map((e) => [e.dataset.axis, (e.querySelector('path.trace').getAttribute('d').match(/L/g) || []).length]));
  check(axes.map((a) => a[0]).join('') === 'XYZBC' && axes.every((a) => a[1] > 300), `plots of X Y Z B C: ${JSON.stringify(axes)}`);
  await page.screenshot({ path: path.join(shots, 'form.png'), fullPage: true });

  // Unwinds and branch changes: lines on the plots, markers in 3D; a marker click shows its block.
  await runJob(page, 'fryer-5x-45', 'joint', 'nx_clsf_mech491_project2_inch_5ax.cls');
  const lines = await page.$$eval('#plots svg.plot line.mark.unwind', (l) => l.length);
  check(lines > 0, `unwinds marked on the plots (${lines} lines)`);
  check((await page.textContent('#plots')).includes('C'), 'plot names its axis');
  await page.locator('#view3d canvas').scrollIntoViewIfNeeded();
  const target = await page.evaluate(() => {
    const v = window.kinepostView;
    const i = v.markers.findIndex((m) => m.n !== null && m.diagnostics.some((d) => d.code === 'unwind' || d.code === 'branch_change'));
    return { i, n: v.markers[i].n, at: v.markerScreen(i) };
  });
  const box = await page.locator('#view3d canvas').boundingBox();
  await page.mouse.click(box.x + target.at.x, box.y + target.at.y);
  const shown = await page.textContent('#cl-line');
  check(/^CL line \d+: .+\nNC block \d+: \S+/.test(shown) && /(unwind|branch_change)/.test(shown), `a marker click shows its block: ${shown.replace(/\n/g, ' | ').slice(0, 160)}`);
  const plotShot = path.join(shots, 'preview.png');
  await page.screenshot({ path: plotShot, fullPage: true });

  // The link opens the same result on another screen.
  const other = await browser.newPage();
  await other.goto(jobUrl);
  await other.waitForSelector('#status.ok, #status.warn', { timeout: 30000 });
  check((await other.textContent('#status')).includes('blocks from 348 CL points'), 'the job link shows the same result');
  check(await other.$eval('#machine', (s) => s.value) === 'haas-umc750', 'and the job\'s machine');
  const posted = await other.evaluate(() => ['mode', 'spindle_speed', 'dialect'].map((k) => document.getElementById(k).value));
  check(posted.join(' ') === 'tcp 9000 ', `and the settings it was posted with, to post again: ${posted.join(' ')}`);
  const dialects = await other.$$eval('#dialect option', (o) => o.map((x) => x.value).join(' '));
  const known = (await (await fetch(base + '/v1/dialects')).json()).map((d) => d.name);
  check(dialects === ' ' + known.join(' ') && known.includes('linuxcnc-switchkins'), `every dialect the service knows: ${dialects}`);
  await other.close();

  // A machine the pose cannot be reached on: each unreachable pose listed with its CL line.
  await runJob(page, 'vmc-3axis', 'joint', 'nx_clsf_mech491_variable_axis_inch_5ax.cls');
  await page.waitForSelector('#warnings tbody tr');
  const red = await page.$eval('#status', (s) => [s.className, s.textContent, getComputedStyle(s).color]);
  check(red[0] === 'error' && /^[\d,]+ errors: .*not fit to run/.test(red[1]) && red[2] === 'rgb(176, 0, 32)', `a job with errors is failed-with-output, in red: ${red.join(' | ')}`);
  const rows = await page.locator('#warnings tbody tr').allTextContents();
  check(rows.some((r) => /line \d+unreachable/.test(r)), `unreachable poses listed with their CL lines (${rows.length} rows)`);
  await page.locator('#warnings tbody tr', { hasText: 'unreachable' }).first().click();
  const cl = await page.textContent('#cl-line');
  check(/^CL line \d+: GOTO\//.test(cl), `a row opens its CL line: ${cl.slice(0, 60)}`);

  // The program beside its CL: the next error is a block marked ERROR, linked to its CL line.
  await page.waitForFunction(() => window.kinepostProgram, null, { timeout: 30000 });
  await page.click('[data-next=error]');
  await page.waitForSelector('#nc-pane .ln.sel.f-err');
  const errRow = await page.$eval('#nc-pane .ln.sel', (r) => r.textContent);
  const errState = await page.evaluate(() => window.kinepostProgram.state());
  check(/ERROR/.test(errRow) && errState.flags & 1 && errState.clOf > 0, `next error: NC line ${errState.ncSel + 1} (${errRow.slice(0, 70)}), from CL line ${errState.clOf}`);
  await page.waitForFunction((l) => document.querySelector(`#cl-pane .ln.sel[data-line="${l}"] .tx`)?.textContent.length > 0, errState.clOf - 1);
  const errCl = await page.$eval('#cl-pane .ln.sel .tx', (t) => t.textContent);
  check(/^GOTO\//.test(errCl), `and the CL pane shows CL line ${errState.clOf}: ${errCl.slice(0, 50)}`);

  // A 1 M-line program: posted through the API, opened by its link; only the rows in sight are
  // in the page while it scrolls to the end, and lines link both ways.
  const big = ['PARTNO/ONE MILLION', 'UNITS/MM', 'LOADTL/1', 'SPINDL/8000,RPM,CLW', 'RAPID', 'GOTO/-100,-100,20', 'FEDRAT/2000,MMPM'];
  for (let i = 0; i < 1000000; i++) {
    if (i === 600000) big.push('LOADTL/2', 'SPINDL/9000,RPM,CLW');
    const row = Math.floor(i / 2000);
    const x = row % 2 ? 100 - (i % 2000) * 0.1 : -100 + (i % 2000) * 0.1;
    big.push(`GOTO/${x.toFixed(3)},${(-100 + row * 0.4).toFixed(3)},${(Math.sin(i / 500) * 2).toFixed(4)}`);
  }
  big.push('SPINDL/OFF', 'END', 'FINI', '');
  const bigJob = await (await fetch(`${base}/v1/jobs?machine=vmc-3axis`, { method: 'POST', headers: { 'content-type': 'text/plain' }, body: big.join('\n') })).json();
  for (let t = 0; t < 600; t++) {
    const j = await (await fetch(`${base}/v1/jobs/${bigJob.id}`)).json();
    if (!['queued', 'running'].includes(j.state)) break;
    await new Promise((res) => setTimeout(res, 200));
  }
  const opening = Date.now();
  await page.goto(`${base}/?job=${bigJob.id}`);
  await page.waitForFunction(() => window.kinepostProgram && document.querySelector('#nc-pane .ln .tx .t-gm'), null, { timeout: 60000 });
  const openMs = Date.now() - opening;
  const bigLines = await page.evaluate(() => window.kinepostProgram.state().lines);
  check(bigLines > 1000000, `a ${bigLines.toLocaleString('en')}-line program opens in ${openMs} ms (line map and first rows in ${(await page.evaluate(() => window.kinepostProgram.state().openedMs)).toFixed(0)} ms)`);
  await page.locator('#nc-pane').scrollIntoViewIfNeeded();
  let most = 0;
  for (let k = 1; k <= 20; k++) {
    await page.evaluate((f) => { const e = document.getElementById('nc-pane'); e.scrollTop = (e.scrollHeight - e.clientHeight) * f; }, k / 20);
    await page.waitForTimeout(40);
    most = Math.max(most, await page.$$eval('#nc-pane .ln', (r) => r.length));
  }
  await page.waitForFunction(() => [...document.querySelectorAll('#nc-pane .ln .tx')].some((t) => /M30/.test(t.textContent)), null, { timeout: 10000 });
  const last = await page.$$eval('#nc-pane .ln', (r) => Number(r[r.length - 1].dataset.line));
  check(last === bigLines - 1 && most < 500, `scrolled to the end (line ${last + 1} shown, M30 in sight) with at most ${most} rows in the page`);
  await page.evaluate(() => { const e = document.getElementById('nc-pane'); e.scrollTop = (e.scrollHeight - e.clientHeight) * 0.4; });
  await page.waitForFunction(() => document.querySelectorAll('#nc-pane .ln .tx .t-ax').length > 5);
  await page.locator('#nc-pane .ln').nth(6).click();
  await page.waitForFunction(() => window.kinepostProgram.state().clDone, null, { timeout: 30000 });
  const picked = await page.evaluate(() => window.kinepostProgram.state());
  await page.waitForFunction((l) => document.querySelector(`#cl-pane .ln.sel[data-line="${l}"] .tx`)?.textContent.startsWith('GOTO/'), picked.clOf - 1, { timeout: 10000 });
  const ncRow = await page.$eval('#nc-pane .ln.sel .tx', (t) => t.textContent);
  const clRow = await page.$eval('#cl-pane .ln.sel .tx', (t) => t.textContent);
  const clX = Number((clRow.match(/^GOTO\/(-?[\d.]+)/) || [])[1]);
  const ncX = ncRow.match(/X(-?[\d.]+)/);
  check(picked.clOf > 400000 && picked.clSel === picked.clOf - 1 && (!ncX || Math.abs(Number(ncX[1]) - clX) < 0.01), `NC line ${picked.ncSel + 1} (${ncRow}) → CL line ${picked.clOf} (${clRow})`);
  await page.locator('#cl-pane .ln').nth(3).click();
  const back = await page.evaluate(() => window.kinepostProgram.state());
  const backNc = await page.$eval('#nc-pane .ln.sel .tx', (t) => t.textContent);
  check(back.clOf === back.clSel + 1 && back.clSel !== picked.clSel && backNc.length > 0, `CL line ${back.clSel + 1} → NC line ${back.ncSel + 1} (${backNc})`);
  await page.click('[data-next=tool]');
  await page.waitForFunction(() => /M6/.test(document.querySelector('#nc-pane .ln.sel .tx')?.textContent || ''));
  check((await page.$eval('#nc-pane .ln.sel .tx', (t) => t.textContent)).includes('T2'), `next tool change: ${await page.$eval('#nc-pane .ln.sel .tx', (t) => t.textContent)}`);
  await page.fill('#nc-search', 'm30');
  const searching = Date.now();
  await page.click('#nc-find button');
  await page.waitForFunction(() => /M30/.test(document.querySelector('#nc-pane .ln.sel .tx')?.textContent || ''), null, { timeout: 20000 });
  check(true, `search finds M30 from line ${back.ncSel + 1} in ${Date.now() - searching} ms`);
  await page.locator('#program').screenshot({ path: path.join(shots, 'nc-view.png') });

  // A phone: nothing wider than the screen (the error table here, the plots on the first job),
  // plot labels readable, units on the plots; then dark mode, as the device asks.
  await page.setViewportSize({ width: 390, height: 844 });
  const wideErrors = await page.evaluate(() => document.documentElement.scrollWidth);
  check(wideErrors <= 390, `the form with a file and a job's error table fit a 390 px phone (page ${wideErrors} px wide)`);
  await page.setViewportSize({ width: 1280, height: 900 });
  const phone = await browser.newPage({ viewport: { width: 390, height: 844 } });
  await phone.goto(jobUrl);
  await phone.waitForSelector('#plots svg.plot', { timeout: 30000 });
  const wide = await phone.evaluate(() => document.documentElement.scrollWidth);
  check(wide <= 390, `a result fits a 390 px phone (page ${wide} px wide)`);
  const tick = await phone.$eval('#plots svg.plot text.tick', (t) => t.getBoundingClientRect().height);
  check(tick >= 9, `plot labels readable on a phone (${tick.toFixed(1)} px)`);
  const xplot = await phone.$eval('#plots svg.plot[data-axis="X"]', (s) => [...s.querySelectorAll('text')].map((t) => t.textContent));
  check(xplot.includes('inch'), `the X plot says its unit: ${xplot.join(' | ')}`);
  await phone.screenshot({ path: path.join(shots, 'phone.png'), fullPage: true });
  await phone.emulateMedia({ colorScheme: 'dark' });
  const bg = await phone.evaluate(() => getComputedStyle(document.documentElement).backgroundColor);
  check(bg === 'rgb(18, 20, 23)', `dark mode follows the device (${bg})`);
  await phone.waitForTimeout(200);
  const dark3d = await phone.evaluate(() => {
    const c = document.querySelector('#view3d canvas');
    const t = document.createElement('canvas');
    [t.width, t.height] = [c.width, c.height];
    const g = t.getContext('2d');
    g.drawImage(c, 0, 0);
    return Array.from(g.getImageData(2, 2, 1, 1).data.slice(0, 3));
  });
  check(dark3d.every((v) => v < 80), `and so does the 3D view's background (${dark3d})`);
  await phone.screenshot({ path: path.join(shots, 'dark.png'), fullPage: true });
  await phone.locator('#program').screenshot({ path: path.join(shots, 'nc-phone-dark.png') });
  await phone.close();

  // Swagger UI lists the operations, the new ones too.
  const docs = await browser.newPage();
  await docs.goto(base + '/docs/');
  await docs.waitForSelector('.opblock-summary', { timeout: 30000 });
  const ops = await docs.$$eval('.opblock-summary', (o) => o.map((e) => e.textContent));
  check(ops.length >= 30 && ops.some((o) => o.includes('/v1/jobs/{id}/lines')) && ops.some((o) => o.includes('Submit CL data as a job')), `Swagger UI shows ${ops.length} operations, the job submission's summary among them`);
  await docs.close();

  // A bad request shows the server's problem detail (the page was opened by a link: no file yet).
  await page.setInputFiles('#file', path.join(data, 'nx_clsf_mech491_variable_axis_inch_5ax.cls'));
  await page.fill('#work_offset', '1,2');
  await page.evaluate(() => document.getElementById('work_offset').removeAttribute('pattern'));
  await page.click('#go');
  await page.waitForSelector('#error:not([hidden])', { timeout: 10000 });
  check((await page.textContent('#error')).includes('work_offset'), 'problem detail shown');
} catch (e) {
  failed++;
  console.log('FAIL', e.message);
} finally {
  await browser.close();
}
console.log(`${passed} passed, ${failed} failed`);
process.exit(failed ? 1 : 0);
