// The shop-floor form in a real headless Chromium: pick a machine, upload a corpus file through
// the page as a job, check the downloaded NC, the summary, the 3D view, the plots, a marker click
// and the shareable job link. Screenshots land in target/browser/. Needs a running kinepost (KINEPOST_URL) and
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
  check(await page.locator('#machine option').count() === 10, 'the machine list comes from the API');
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
  check(dialects === ' fanuc haas siemens heidenhain linuxcnc', `every dialect the service knows: ${dialects}`);
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
  await phone.close();

  // A bad request shows the server's problem detail.
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
