// The page's forward kinematics (src/http/web/kin.js, what the machine view and the machine check
// page pose the machine with) against the server's (POST /v1/machines/{id}/fk): random joints
// within travel, random tool lengths and work offsets, on every profile the server has; tip and
// axis agree to 1e-6. Also: the link poses kin.js draws the spindle and the work frame with put
// the tool tip where FK says. Needs a running kinepost (KINEPOST_URL). Prints "N passed, M failed".
import { chain, fk, joints, links, transform, controlledPoint } from '../../src/http/web/kin.js';

const base = process.env.KINEPOST_URL || 'http://127.0.0.1:8080';
let passed = 0, failed = 0;
const check = (ok, what) => { if (ok) { passed++; console.log('ok  ', what); } else { failed++; console.log('FAIL', what); } };

// A seeded generator: the same joints every run.
let seed = 20240531;
const rand = () => ((seed = (seed * 1103515245 + 12345) % 2147483648) / 2147483648);
const within = (lo, hi) => lo + (hi - lo) * rand();
const diff = (a, b) => Math.max(...a.map((v, i) => Math.abs(v - b[i])));

const SAMPLES = 40;
try {
  const models = await (await fetch(base + '/v1/machines')).json();
  check(models.length >= 11, `${models.length} profiles`);
  for (const model of models) {
    const ch = chain(model);
    let worstTip = 0, worstAxis = 0, worstLink = 0, worstTcp = 0;
    for (let k = 0; k < SAMPLES; k++) {
      const words = {};
      for (const l of ch.linear.filter(Boolean)) words[l.name] = within(l.min, l.max);
      for (const r of ch.rot) words[r.name] = within(r.min ?? -720, r.max ?? 720);
      const L = k === 0 ? 0 : within(0, model.units === 'inch' ? 8 : 200);
      const wo = k < 2 ? [0, 0, 0] : [within(-50, 50), within(-50, 50), within(-50, 50)];
      const r = await fetch(`${base}/v1/machines/${model.id}/fk`, {
        method: 'POST',
        headers: { 'content-type': 'application/json' },
        body: JSON.stringify({ joints: words, tool_length: L, work_offset: wo }),
      });
      if (!r.ok) { check(false, `${model.id}: fk ${r.status} ${await r.text()}`); break; }
      const server = await r.json();
      const page = fk(ch, words, L, wo);
      const scale = 1; // absolute: profile units
      worstTip = Math.max(worstTip, diff(page.tip, server.tip) / scale);
      worstAxis = Math.max(worstAxis, diff(page.axis, server.axis));
      // The drawn machine: the tip (gauge point − L along the spindle's z) seen from W.
      const { linear, actual } = joints(ch, words);
      const lk = links(ch, linear, actual, L, wo);
      const tipM = transform(lk.spindle, [0, 0, -L]);
      // W's point at the tip, carried by the work frame into M, lands on it.
      const tipW = transform(lk.work, server.tip);
      worstLink = Math.max(worstLink, diff(tipM, tipW) / scale);
      // TCP frames: the controlled point from the tip gives back the linears.
      const q = controlledPoint(ch, actual, server.tip, L, wo);
      worstTcp = Math.max(worstTcp, diff(q, linear) / scale);
    }
    check(worstTip <= 1e-6 && worstAxis <= 1e-6, `${model.id} (${model.kinematics}): the page's FK equals the server's on ${SAMPLES} random joints (tip ${worstTip.toExponential(1)}, axis ${worstAxis.toExponential(1)})`);
    check(worstLink <= 1e-6 && worstTcp <= 1e-6, `${model.id}: the drawn spindle and work frame meet at the tip (${worstLink.toExponential(1)}), the controlled point inverts FK (${worstTcp.toExponential(1)})`);
  }
} catch (e) {
  failed++;
  console.log('FAIL', e.message);
}
console.log(`${passed} passed, ${failed} failed`);
process.exit(failed ? 1 : 0);
