// The machine's kinematics in the page: forward kinematics and the pose of every link from the
// joints, written as src/kinematics/fk.rs and src/collide/links.rs write them (same order, same
// Rodrigues formula), so that what the page draws is where kinepost computes the machine to be.
// No three.js here: the Node test (tests/browser/fk.test.mjs) imports this file and compares
// `fk` with the API's /v1/machines/{id}/fk on every profile.

const D = Math.PI / 180;

/** A machine as the API gives it (GET /v1/machines/{id}, or a job preview's `machine`), made
 *  ready for FK: unit axes, radians, the angle error's coefficients in radians. */
export function chain(model) {
  const linear = ['X', 'Y', 'Z'].map((n) => model.linear.find((l) => l.name === n) || null);
  const rot = model.rotary.map((r) => {
    const [x, y, z] = r.axis;
    const n = Math.sqrt(x * x + y * y + z * z);
    let err = null;
    if (r.angle_error) {
      // Δ_rad(x) = d · Σ c_i (x/d)^i  ⇒  k_i = c_i · d^(1-i), as angle_error.rs.
      const k = r.angle_error.coefficients.map((c, i) => c * Math.pow(D, 1 - i));
      err = { k, range: [r.angle_error.range[0] * D, r.angle_error.range[1] * D] };
    }
    return {
      name: r.name,
      mount: r.on,
      axis: [x / n, y / n, z / n],
      pivot: r.pivot.slice(),
      min: r.min ?? null,
      max: r.max ?? null,
      err,
    };
  });
  return { id: model.id, units: model.units, linear, rot, bodies: model.bodies || [], defaultToolLength: model.default_tool_length || 0, model };
}

/** The angle (radians) a rotary stands at when its word (radians) is commanded. */
export function actualAngle(r, word) {
  if (!r.err) return word;
  const x = Math.min(Math.max(word, r.err.range[0]), r.err.range[1]);
  let acc = 0;
  for (let i = r.err.k.length - 1; i >= 0; i--) acc = acc * x + r.err.k[i];
  return word + acc;
}

/** Rodrigues: `v c + (k × v) s + k (k·v)(1 − c)` (fk.rs's `rotate`). */
export function rotate(k, c, s, v) {
  const d = (k[0] * v[0] + k[1] * v[1] + k[2] * v[2]) * (1 - c);
  return [
    v[0] * c + (k[1] * v[2] - k[2] * v[1]) * s + k[0] * d,
    v[1] * c + (k[2] * v[0] - k[0] * v[2]) * s + k[1] * d,
    v[2] * c + (k[0] * v[1] - k[1] * v[0]) * s + k[2] * d,
  ];
}

const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];

/** Joint words by name (X Y Z in profile units, rotaries in degrees) → linear[3] and the
 *  actual rotary angles (radians, chain order). */
export function joints(ch, words) {
  const linear = [0, 1, 2].map((i) => (ch.linear[i] ? Number(words['XYZ'[i]] ?? 0) : 0));
  const actual = ch.rot.map((r) => actualAngle(r, Number(words[r.name] ?? 0) * D));
  return { linear, actual };
}

/** Tip relative to the controlled point, and the tool axis, in M (fk.rs's `head_offset`). */
function headOffset(ch, actual, L) {
  let v = [0, 0, 0];
  let a = [0, 0, 1];
  for (let i = ch.rot.length - 1; i >= 0; i--) {
    const r = ch.rot[i];
    if (r.mount !== 'head') continue;
    const q = add(r.pivot, [0, 0, L]);
    const [c, s] = [Math.cos(actual[i]), Math.sin(actual[i])];
    v = add(q, rotate(r.axis, c, s, sub(v, q)));
    a = rotate(r.axis, c, s, a);
  }
  return [v, a];
}

/** The tool pose in W for actual angles (fk.rs's `fk_actual`): `{ tip, axis }`. */
export function fkActual(ch, linear, actual, L = 0, wo = [0, 0, 0]) {
  const [off, a0] = headOffset(ch, actual, L);
  let p = add(linear, off);
  let axis = a0;
  ch.rot.forEach((r, i) => {
    if (r.mount !== 'table') return;
    const [c, s] = [Math.cos(-actual[i]), Math.sin(-actual[i])];
    p = add(r.pivot, rotate(r.axis, c, s, sub(p, r.pivot)));
    axis = rotate(r.axis, c, s, axis);
  });
  return { tip: sub(p, wo), axis };
}

/** FK of joint words (rotaries in degrees), as POST /v1/machines/{id}/fk answers. */
export function fk(ch, words, L = 0, wo = [0, 0, 0]) {
  const { linear, actual } = joints(ch, words);
  return fkActual(ch, linear, actual, L, wo);
}

/** The controlled point X Y Z that puts the tip at `tipW` (fk.rs's `controlled_point`): what a
 *  TCP program's machine axes stand at. */
export function controlledPoint(ch, actual, tipW, L = 0, wo = [0, 0, 0]) {
  const [off] = headOffset(ch, actual, L);
  let p = add(tipW, wo);
  for (let i = ch.rot.length - 1; i >= 0; i--) {
    const r = ch.rot[i];
    if (r.mount !== 'table') continue;
    const [c, s] = [Math.cos(actual[i]), Math.sin(actual[i])];
    p = add(r.pivot, rotate(r.axis, c, s, sub(p, r.pivot)));
  }
  return sub(p, off);
}

// A rigid motion: { R: 3×3 row-major, t: [3] }, x ↦ R x + t.
const IDENTITY = { R: [1, 0, 0, 0, 1, 0, 0, 0, 1], t: [0, 0, 0] };
const apply = (R, v) => [R[0] * v[0] + R[1] * v[1] + R[2] * v[2], R[3] * v[0] + R[4] * v[1] + R[5] * v[2], R[6] * v[0] + R[7] * v[1] + R[8] * v[2]];
function compose(a, b) {
  const R = new Array(9);
  for (let i = 0; i < 3; i++) for (let j = 0; j < 3; j++) R[i * 3 + j] = a.R[i * 3] * b.R[j] + a.R[i * 3 + 1] * b.R[3 + j] + a.R[i * 3 + 2] * b.R[6 + j];
  return { R, t: add(apply(a.R, b.t), a.t) };
}
/** The turn by `angle` about `axis` through `pivot` (collide/links.rs's `turn`). */
function turn(axis, pivot, angle) {
  const [c, s] = [Math.cos(angle), Math.sin(angle)];
  const cols = [[1, 0, 0], [0, 1, 0], [0, 0, 1]].map((e) => rotate(axis, c, s, e));
  const R = [cols[0][0], cols[1][0], cols[2][0], cols[0][1], cols[1][1], cols[2][1], cols[0][2], cols[1][2], cols[2][2]];
  return { R, t: sub(pivot, apply(R, pivot)) };
}
export const transform = (m, v) => add(apply(m.R, v), m.t);

/** Every link's pose in M at these joints (collide/links.rs's `Links::at`): `bed`, each rotary by
 *  name, `table` (after every table rotary), `ram`, `spindle` (after every head rotary) and
 *  `work` (W: the table's, moved by the work offset). */
export function links(ch, linear, actual, L = 0, wo = [0, 0, 0]) {
  const out = { bed: IDENTITY };
  let t = IDENTITY;
  let h = { R: IDENTITY.R, t: [linear[0], linear[1], linear[2] + L] };
  out.ram = h;
  ch.rot.forEach((r, i) => {
    if (r.mount === 'table') out[r.name] = t = compose(t, turn(r.axis, r.pivot, actual[i]));
    else out[r.name] = h = compose(h, turn(r.axis, r.pivot, actual[i]));
  });
  out.table = t;
  out.spindle = h;
  out.work = compose(t, { R: IDENTITY.R, t: wo.slice() });
  return out;
}

/** A 4×4 column-major matrix of a pose (three.js's Matrix4.fromArray order). */
export function matrix4(m) {
  const R = m.R;
  return [R[0], R[3], R[6], 0, R[1], R[4], R[7], 0, R[2], R[5], R[8], 0, m.t[0], m.t[1], m.t[2], 1];
}

/** Bodies for a profile that gives none: a bed with its linear carriage, a disc per rotary
 *  about its axis through its pivot, a ram and a spindle nose, sized from the travels. Drawn to
 *  show the motion, not the machine's shape. */
export function schematic(ch) {
  const spans = ch.linear.filter(Boolean).map((l) => l.max - l.min);
  const S = Math.max(...spans, ch.units === 'inch' ? 10 : 250);
  const out = [];
  const tables = ch.rot.filter((r) => r.mount === 'table');
  const low = Math.min(0, ...tables.map((r) => r.pivot[2])) - 0.35 * S;
  out.push({ name: 'bed (schematic)', on: 'bed', box: [-0.6 * S, -0.45 * S, low - 0.08 * S, 0.6 * S, 0.45 * S, low] });
  if (!tables.length) out.push({ name: 'table (schematic)', on: 'table', box: [-0.4 * S, -0.3 * S, -0.05 * S, 0.4 * S, 0.3 * S, 0] });
  const disc = (r, radius, thick, name) => {
    const a = r.axis;
    return { name, on: r.name, cylinder: { from: sub(r.pivot, a.map((v) => v * thick)), to: r.pivot.slice(), radius } };
  };
  tables.forEach((r, k) => out.push(disc(r, (0.3 - 0.08 * k) * S, 0.05 * S, `${r.name} disc (schematic)`)));
  ch.rot.filter((r) => r.mount === 'head').forEach((r, k) => out.push(disc(r, (0.09 - 0.02 * k) * S, 0.03 * S, `${r.name} disc (schematic)`)));
  out.push({ name: 'ram (schematic)', on: 'ram', box: [-0.06 * S, -0.06 * S, 0.25 * S, 0.06 * S, 0.06 * S, 0.7 * S] });
  out.push({ name: 'spindle nose (schematic)', on: 'spindle', cylinder: { from: [0, 0, 0.01 * S], to: [0, 0, 0.2 * S], radius: 0.045 * S } });
  return out;
}

/** The tool's cutter and holder as the collision check builds them (collide/geometry.rs's
 *  `ToolShape::holder` and `cutter`), on the spindle, relative to the gauge point. */
export function toolBodies(t) {
  const L = t.length;
  const stick = Math.max(L - t.holder_length, L * 0.2);
  const out = [];
  if (t.holder_length > 0 && t.holder_diameter > 0) out.push({ name: 'holder', on: 'spindle', cylinder: { from: [0, 0, -Math.max(L - stick, 1e-3)], to: [0, 0, 0], radius: t.holder_diameter / 2 } });
  if (L > 0) out.push({ name: 'cutter', on: 'spindle', cylinder: { from: [0, 0, -L], to: [0, 0, -(L - stick)], radius: t.diameter / 2 } });
  return out;
}

/** The tool kinepost assumes where nothing says (collide/geometry.rs's `ToolShape::default_for`). */
export function defaultTool(ch, length) {
  const k = ch.units === 'inch' ? 1 / 25.4 : 1;
  return { n: 1, length, diameter: 10 * k, corner_radius: 0, holder_diameter: 40 * k, holder_length: 40 * k };
}
