// The program, read: the NC beside the CL it came from, each NC line linked to its CL line both
// ways, with jumps to the next error, warning, unwind or tool change and a search. Virtualised:
// only the rows in sight are in the page, their text read by HTTP Range. The NC's line offsets,
// CL lines and flags come from the job's line map (GET /v1/jobs/{id}/lines); the CL's line
// offsets are found by reading it once, as a stream, when the view opens.

const ROW = 20; // px: every row is this tall (.code .ln in style.css)
const PAGE = 256; // lines per Range request while scrolling
const SCAN = 16384; // lines per Range request while searching
// Browsers cap an element's height (Firefox near 17.9 M px): beyond this, scrolling maps to rows
// by proportion.
const MAXH = 1.5e7;
export const FLAGS = { error: 1, warning: 2, unwind: 4 | 8, tool: 16 };

/** Lines of a text file read by Range: line i spans bytes start(i) … start(i + 1) - 1. */
class RangedText {
  constructor(url, start, count, done) {
    Object.assign(this, { url, start, count, done });
    this.pages = new Map(); // page number → lines (least recently used first)
    this.pending = new Map();
  }

  line(i) {
    const p = Math.floor(i / PAGE);
    const page = this.pages.get(p);
    if (!page) return undefined;
    this.pages.delete(p);
    this.pages.set(p, page);
    return page[i - p * PAGE];
  }

  /** Lines a … b - 1 (all known to the index). */
  async read(a, b) {
    if (b <= a) return [];
    const [from, to] = [this.start(a), this.start(b)];
    if (to <= from) return new Array(b - a).fill('');
    const r = await fetch(this.url, { headers: { Range: `bytes=${from}-${to - 1}` } });
    if (!r.ok) throw new Error(`${this.url}: ${r.status}`);
    let buf = await r.arrayBuffer();
    if (r.status === 200) buf = buf.slice(from, to); // a server that ignored the Range
    const lines = new TextDecoder().decode(buf).split('\n');
    return lines.slice(0, b - a).map((l) => (l.endsWith('\r') ? l.slice(0, -1) : l));
  }

  load(p) {
    if (this.pending.has(p)) return this.pending.get(p);
    const a = p * PAGE;
    const b = Math.min(a + PAGE, this.count());
    const whole = b - a === PAGE || this.done();
    const job = this.read(a, b).then((lines) => {
      this.pending.delete(p);
      if (whole) {
        this.pages.set(p, lines);
        if (this.pages.size > 200) this.pages.delete(this.pages.keys().next().value);
      }
      return lines;
    }, (e) => { this.pending.delete(p); throw e; });
    this.pending.set(p, job);
    return job;
  }
}

/** A scrolling list of `count` fixed-height rows of which only those in sight are elements. */
class VList {
  constructor(el, text, paint, rowClass, onPick) {
    Object.assign(this, { el, text, paint, rowClass, n: 0, sel: -1 });
    el.replaceChildren();
    this.spacer = document.createElement('div');
    this.spacer.className = 'spacer';
    this.rows = document.createElement('div');
    this.rows.className = 'rows';
    el.append(this.spacer, this.rows);
    el.addEventListener('scroll', () => this.draw(), { passive: true });
    this.rows.addEventListener('click', (e) => {
      const r = e.target.closest('.ln');
      if (r) onPick(Number(r.dataset.line));
    });
    this.resized = new ResizeObserver(() => this.draw());
    this.resized.observe(el);
  }

  setCount(n) {
    if (n === this.n) return;
    this.n = n;
    this.spacer.style.height = `${Math.min(n * ROW, MAXH)}px`;
    this.draw();
  }

  scaled() { return this.n * ROW > MAXH; }

  /** The first row in sight. */
  first() {
    const h = this.el.clientHeight;
    if (!this.scaled()) return Math.floor(this.el.scrollTop / ROW);
    const room = Math.max(this.spacer.offsetHeight - h, 1);
    return Math.round(Math.min(this.el.scrollTop / room, 1) * Math.max(this.n - Math.floor(h / ROW), 0));
  }

  /** Row i in the middle of the view, selected. */
  show(i) {
    this.sel = i;
    const h = this.el.clientHeight;
    const top = Math.max(0, i - Math.floor(h / ROW / 2));
    if (!this.scaled()) this.el.scrollTop = top * ROW;
    else this.el.scrollTop = top / Math.max(this.n - Math.floor(h / ROW), 1) * (this.spacer.offsetHeight - h);
    this.draw();
  }

  draw() {
    const h = this.el.clientHeight || 400;
    const a = Math.max(0, Math.min(this.first(), this.n - 1));
    const over = this.scaled() ? 0 : 8;
    const from = Math.max(0, a - over);
    const to = Math.min(this.n, a + Math.ceil(h / ROW) + 1 + over);
    const top = this.scaled() ? Math.min(this.el.scrollTop, Math.max(this.spacer.offsetHeight - (to - from) * ROW, 0)) : from * ROW;
    this.rows.style.transform = `translateY(${top}px)`;
    const rows = this.rows.children;
    while (rows.length < to - from) {
      const r = document.createElement('div');
      r.className = 'ln';
      r.append(document.createElement('span'), document.createElement('span'));
      r.firstChild.className = 'no';
      r.lastChild.className = 'tx';
      this.rows.appendChild(r);
    }
    while (rows.length > to - from) this.rows.lastChild.remove();
    const missing = new Set();
    for (let k = 0; k < to - from; k++) {
      const i = from + k;
      const r = rows[k];
      const t = this.text.line(i);
      if (t === undefined) missing.add(Math.floor(i / PAGE));
      const key = `${i}|${t === undefined ? '' : 't'}|${i === this.sel}`;
      if (r.dataset.key === key) continue;
      r.dataset.key = key;
      r.dataset.line = i;
      r.firstChild.textContent = i + 1;
      r.lastChild.innerHTML = t === undefined ? '<span class="wait">…</span>' : this.paint(t, i);
      r.className = `ln ${this.rowClass(i)}${i === this.sel ? ' sel' : ''}`;
    }
    for (const p of missing) this.text.load(p).then(() => this.draw(), () => {});
  }

  dispose() { this.resized.disconnect(); }
}

const esc = (s) => s.replace(/[&<>]/g, (c) => ({ '&': '&amp;', '<': '&lt;', '>': '&gt;' }[c]));
const span = (cls, s) => `<span class="${cls}">${esc(s)}</span>`;

/** An NC line, coloured: G/M codes and cycle words, axis words, F/S/T, comments, ERROR comments. */
export function paintNc(t) {
  // `(` opens a comment after a blank, not a Sinumerik call's arguments (CYCLE800(…)).
  let cut = t.search(/;|(^|\s)\(/);
  if (cut >= 0 && t[cut] !== ';' && t[cut] !== '(') cut++;
  const code = cut < 0 ? t : t.slice(0, cut);
  const rest = cut < 0 ? '' : t.slice(cut);
  const out = code.replace(/([A-Z]+=?)([+-]?[\d.]+)?|[^A-Z]+/g, (m, word, num) => {
    if (!word) return /^\s*\d+\s*$/.test(m) && m === code.slice(0, m.length) ? span('t-n', m) : esc(m);
    const w = word[0];
    if (num === undefined) return span('t-kw', m); // TNC/Sinumerik keywords: L, FMAX, TOOL CALL, TRAORI
    if (w === 'G' || w === 'M') return span('t-gm', m);
    if ('XYZABCUVWIJKR'.includes(w) && word.length === 1) return span('t-ax', m);
    if ('FST'.includes(w) && word.length === 1) return span('t-fst', m);
    if (w === 'N' && word.length === 1) return span('t-n', m);
    return esc(m);
  });
  if (!rest) return out;
  return out + span(/\bERROR\b/.test(rest) ? 't-err' : 't-cmt', rest);
}

/** A CL line: its record word and its comments. */
export function paintCl(t) {
  const m = t.match(/^(\s*)([A-Z][A-Z0-9]*)(\/|\s|$)(.*)$/);
  if (t.trim().startsWith('$$')) return span('t-cmt', t);
  if (!m) return esc(t);
  const [, lead, word, sep, rest] = m;
  const c = rest.indexOf('$$');
  const body = c < 0 ? rest : rest.slice(0, c);
  return esc(lead) + span(word === 'GOTO' ? 't-ax' : 't-gm', word) + esc(sep + body) + (c < 0 ? '' : span('t-cmt', rest.slice(c)));
}

/** Reads the CL as a stream once, recording where each line starts; calls `grew()` as it does. */
async function indexCl(url, idx, grew) {
  const r = await fetch(url);
  if (!r.ok || !r.body) throw new Error(`${url}: ${r.status}`);
  const reader = r.body.getReader();
  let pos = 0;
  let last = 0;
  for (;;) {
    const { done, value } = await reader.read();
    if (done) break;
    for (let k = value.indexOf(10); k >= 0; k = value.indexOf(10, k + 1)) idx.push(pos + k + 1);
    pos += value.length;
    if (idx.n - last > 20000 || last === 0) { last = idx.n; grew(); }
  }
  if (idx.at(idx.n - 1) < pos) idx.push(pos);
  idx.done = true;
  grew();
}

/** Line starts, growing. */
class Starts {
  constructor() { this.a = new Float64Array(1 << 16); this.n = 1; this.done = false; }
  push(v) {
    if (this.n === this.a.length) { const b = new Float64Array(this.a.length * 2); b.set(this.a); this.a = b; }
    this.a[this.n++] = v;
  }
  at(i) { return this.a[i]; }
}

/**
 * The program view of a succeeded job in `els` ({ nc, cl, where, search }): returns a handle
 * with `next(kind)` (kind: error, warning, unwind, tool), `find(text)`, `pickNc(i)`,
 * `pickCl(j)`, `state()` and `dispose()`.
 */
export async function programView(els, job) {
  const t0 = performance.now();
  const r = await fetch(job.links.lines);
  if (!r.ok) throw new Error(r.status === 404 ? 'This job has no line map (it finished before the program view existed): download the NC to read it.' : `line map: ${r.status}`);
  const map = new Uint32Array(await r.arrayBuffer());
  const n = map.length / 4;
  const ncBytes = job.progress.nc_bytes;
  const ncStart = (i) => (i >= n ? ncBytes : map[4 * i] + map[4 * i + 1] * 2 ** 32);
  const clOf = (i) => map[4 * i + 2];
  const flags = (i) => map[4 * i + 3];
  // CL line (1-based) → the first NC line from it.
  let top = 0;
  for (let i = 0; i < n; i++) top = Math.max(top, clOf(i));
  const ncOf = new Int32Array(top + 1).fill(-1);
  for (let i = n - 1; i >= 0; i--) if (clOf(i)) ncOf[clOf(i)] = i;

  const starts = new Starts();
  const clCount = () => starts.n - 1;
  const ncText = new RangedText(job.links.nc, ncStart, () => n, () => true);
  const clText = new RangedText(job.links.input, (i) => starts.at(i), clCount, () => starts.done);
  const flagClass = (i) => {
    const f = flags(i);
    return f & FLAGS.error ? 'f-err' : f & FLAGS.warning ? 'f-warn' : f & FLAGS.unwind ? 'f-unw' : f & FLAGS.tool ? 'f-tool' : '';
  };
  let waiting = -1; // a CL line (0-based) picked before the index reached it
  const nc = new VList(els.nc, ncText, paintNc, flagClass, (i) => pickNc(i));
  const cl = new VList(els.cl, clText, paintCl, () => '', (j) => pickCl(j));
  nc.setCount(n);
  const say = (s) => { els.where.textContent = s; };

  function pickNc(i) {
    nc.show(i);
    const c = clOf(i);
    waiting = c > clCount() ? c - 1 : -1;
    if (c) cl.show(c - 1);
    else { cl.sel = -1; cl.draw(); }
    say(`NC line ${(i + 1).toLocaleString()}` + (c ? ` ← CL line ${c.toLocaleString()}` : ' (no CL line of its own)'));
  }
  function pickCl(j) {
    cl.show(j);
    let i = -1;
    let at = j + 1;
    for (; at <= top && i < 0; at++) i = ncOf[at];
    at--;
    if (i < 0) { nc.sel = -1; nc.draw(); say(`CL line ${(j + 1).toLocaleString()}: no NC line after it`); return; }
    nc.show(i);
    say(at === j + 1 ? `CL line ${(j + 1).toLocaleString()} → NC line ${(i + 1).toLocaleString()}` : `CL line ${(j + 1).toLocaleString()} writes no block; the next one is NC line ${(i + 1).toLocaleString()} (CL line ${at.toLocaleString()})`);
  }
  function next(kind) {
    const bit = FLAGS[kind];
    for (let k = 1; k <= n; k++) {
      const i = (nc.sel + k) % n;
      if (flags(i) & bit) { pickNc(i); return i; }
    }
    say(`No ${kind === 'tool' ? 'tool change' : kind} in this program`);
    return -1;
  }
  async function find(q) {
    if (!q) return -1;
    const needle = q.toUpperCase();
    let a = (nc.sel + 1) % n;
    for (let left = n; left > 0; a = (a + SCAN) % n) {
      const b = Math.min(a + SCAN, n, a + left);
      const lines = await ncText.read(a, b);
      const k = lines.findIndex((l) => l.toUpperCase().includes(needle));
      if (k >= 0) { pickNc(a + k); return a + k; }
      left -= b - a;
      if (b === n) a = -SCAN; // on from the first line
    }
    say(`“${q}” is not in the NC`);
    return -1;
  }

  let opened = 0;
  const grew = () => {
    cl.setCount(clCount());
    if (waiting >= 0 && waiting < clCount()) { cl.show(waiting); waiting = -1; }
  };
  const indexing = indexCl(job.links.input, starts, grew).catch((e) => say(`CL: ${e.message}`));
  await ncText.load(0);
  nc.draw();
  opened = performance.now() - t0;
  say(`${n.toLocaleString()} NC lines; click one to see its CL line`);
  return {
    next, find, pickNc, pickCl, indexing,
    state: () => ({ lines: n, clLines: clCount(), clDone: starts.done, ncSel: nc.sel, clSel: cl.sel, clOf: nc.sel >= 0 ? clOf(nc.sel) : 0, flags: nc.sel >= 0 ? flags(nc.sel) : 0, openedMs: opened }),
    dispose() { nc.dispose(); cl.dispose(); },
  };
}
