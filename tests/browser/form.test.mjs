// The shop-floor form in a real headless Chromium: pick a machine, upload a corpus file through
// the page, check the downloaded NC and the summary. Needs a running kinepost (KINEPOST_URL) and
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
  args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run', '--disable-background-networking', '--disable-component-update', '--disable-sync'],
});
try {
  const page = await browser.newPage({ acceptDownloads: true });
  await page.goto(base + '/');
  await page.waitForSelector('#machine option[value="haas-umc750"]', { state: 'attached' });
  check(await page.locator('#machine option').count() === 10, 'the machine list comes from the API');
  await page.selectOption('#machine', 'haas-umc750');
  await page.selectOption('#mode', 'tcp');
  check((await page.textContent('#machine-info')).includes('table-table'), 'machine facts shown');
  await page.setInputFiles('#file', path.join(data, 'nx_clsf_mech491_variable_axis_inch_5ax.cls'));
  await page.click('#go');
  await page.waitForSelector('#result:not([hidden])', { timeout: 30000 });
  const status = await page.textContent('#status');
  check(status.includes('blocks from 348 CL points'), `status: ${status}`);
  const summary = await page.textContent('#summary');
  check(summary.includes('FK replay') && summary.includes('C rotary') && summary.includes('travel 3856.6'), 'summary shows FK replay and rotary travel');
  const [download] = await Promise.all([page.waitForEvent('download'), page.click('#download')]);
  const file = path.join(shots, download.suggestedFilename());
  await download.saveAs(file);
  const nc = readFileSync(file, 'utf8');
  check(download.suggestedFilename() === 'nx_clsf_mech491_variable_axis_inch_5ax.nc', `download name ${download.suggestedFilename()}`);
  check(nc.startsWith('%\nO01000\n') && nc.trimEnd().endsWith('M30\n%') && nc.includes('G234 H1'), 'downloaded NC is a whole Haas TCP program');
  check(nc.includes('B-22.2015 C1.0496'), 'first orientation as the real NX post');
  await page.screenshot({ path: path.join(shots, 'form.png'), fullPage: true });

  // A machine the pose cannot be reached on: warnings (errors) listed with their CL lines.
  await page.selectOption('#machine', 'vmc-3axis');
  await page.selectOption('#mode', 'joint');
  await page.click('#go');
  await page.waitForSelector('#result:not([hidden])', { timeout: 30000 });
  const rows = await page.locator('#warnings tbody tr').allTextContents();
  check(rows.some((r) => /line \d+unreachable/.test(r)), `unreachable poses listed with their CL lines (${rows.length} rows)`);
  await page.locator('#warnings tbody tr', { hasText: 'unreachable' }).first().click();
  const shown = await page.textContent('#cl-line');
  check(/^CL line \d+: GOTO\//.test(shown), `a row opens its CL line: ${shown.slice(0, 60)}`);

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
