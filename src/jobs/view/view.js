// brume view — the page: controls generated from the command's parameter
// table (meta.json: unit, range, default, help; a log slider where the range
// spans decades), the values it starts from on this scene (meta.start: each
// with its reason, shown over the picture and spelled out in the command),
// the frame asked of the server as a plan for every change and run by
// render.js, the before/after wipe, the depth view and its legend, the focal
// plane, "Copy command" and "Save record".
//
// Frames: while a control moves, the page draws drafts -- the frame at 1/k
// of the image's size, the blur at the same physical scale (the server
// scales every pixel length by 1/k) -- with k chosen from its own frame-time
// model (each pass's cost per megapixel, measured on every frame) so that a
// draft answers within BUDGET_MS; the full frame follows when the hand stops
// (IDLE_MS without a change), and gives way to the next change. The status
// line says which is shown.
//
// A value the page cannot send (empty, a partial number) is said beside its
// field and not sent; one the server refuses comes back as an answer (not an
// HTTP error) and is said beside its field and over the picture: nothing is
// thrown into the console.
//
// The test hook window.brume (docs/view.md): `await brume.set(name, value)`
// (CLI names; resolves once the full frame with every pending change is
// drawn), `brume.pixels({format})`, `brume.frameInfo()`, `brume.history()`,
// `brume.idle()`.
import {Renderer, srgb8, depthColour} from './render.js';

const BUDGET_MS = 300;    // a draft's target time, fetch included
const IDLE_MS = 400;      // no change for this long: the hand has stopped, the full frame follows
const FIRST_MPX = 0.06;   // the first frame's size before any pass has been timed (1600x1120: 1/6)
const SLICE_MS = 80;      // a full frame looks for a newer change this often

const $ = (id) => document.getElementById(id);
const state = {
  values: {}, meta: null, r: null, base: 1, gen: 0, busy: false, waiters: [], fullWanted: true,
  shown: {gen: -1, quality: null}, frame: null, error: null, idleTimer: null, rows: {}, starts: {},
  model: {obs: {}, seen: new Set(), floor: Infinity, plans: {}, ratio: {}}, fetchMs: 30, lastPlan: null,
  lastPlanScale: 1, history: [], dataVersion: 0, lastEdited: null,
};

// fetch() of the page's own server. A request that never got an answer
// (the server stopped, or the network between) rejects with the browser's
// bare "Failed to fetch": say which server and what to do instead.
async function serverFetch(url, init) {
  try {
    return await fetch(url, init);
  } catch (e) {
    throw new Error(`the brume view server at ${location.host} does not answer (${e.message}): ` +
                    'it has stopped (or cannot be reached); start brume view again and open the address it prints');
  }
}

async function fetchJSON(url, body) {
  const res = await serverFetch(url, body === undefined ? {} : {method: 'POST', body: JSON.stringify(body),
                                                        headers: {'Content-Type': 'application/json'}});
  const j = await res.json();
  if (!res.ok) throw new Error(j.error || res.statusText);
  return j;
}
async function fetchFloats(name, k) {
  const res = await serverFetch(`${name}.bin?scale=${k}`);
  if (!res.ok) throw new Error(`${name}: ${res.status}`);
  return new Float32Array(await res.arrayBuffer());
}

// A map a plan names (CommandDef::preview_data): its floats and its shape.
async function fetchMap(name) {
  const res = await serverFetch(`data.bin?name=${encodeURIComponent(name)}`);
  if (!res.ok) throw new Error(`map ${name}: ${res.status}`);
  const [width, height, channels] = (res.headers.get('X-Brume-Shape') || '').split(' ').map(Number);
  const data = new Float32Array(await res.arrayBuffer());
  if (!(width > 0 && height > 0 && [1, 2, 4].includes(channels)) || data.length !== width * height * channels)
    throw new Error(`map ${name}: a malformed answer (shape '${res.headers.get('X-Brume-Shape')}', ${data.length} values)`);
  return {width, height, channels, data};
}

// ---- controls --------------------------------------------------------------------------------

// The span a slider covers: the command's sampling range where it has one
// (loguniform -> log), else the declared range when finite; log where it
// spans two decades or more above 0. A span that does not hold the value
// the page starts from is moved to it (a scene far from the sampler's).
function sliderSpan(s, start) {
  let span = null;
  const m = /^(log)?uniform\(([^,]+),([^)]+)\)$/.exec((s.sampling || '').replace(/\s/g, ''));
  if (m) span = {lo: +m[2], hi: +m[3], log: !!m[1]};
  else if (s.min === null || s.max === null) {
    const d = parseFloat(start !== undefined ? start : s.default);
    if (s.min !== null && s.min >= 0 && d > 0) span = {lo: d / 100, hi: d * 100, log: true};
  } else {
    const log = s.min > 0 && s.max / s.min >= 100;
    span = {lo: log && s.min_open ? s.min * 1.0001 : s.min, hi: s.max, log};
  }
  const v = parseFloat(start);
  if (span && isFinite(v) && (v < span.lo || v > span.hi)) {
    if (span.log && v > 0) {
      const ratio = span.hi / span.lo;  // the same decades, centred on the value (log scale)
      span = {lo: v / Math.sqrt(ratio), hi: v * Math.sqrt(ratio), log: true};
      if (s.min !== null && span.lo < s.min) span.lo = s.min_open ? s.min * 1.0001 : s.min;
      if (s.max !== null && span.hi > s.max) span.hi = s.max;
    } else {
      span = {lo: Math.min(span.lo, v), hi: Math.max(span.hi, v), log: span.log};
    }
  }
  return span;
}

// What the page can send for a parameter of this kind (the server checks
// the range and the rest): null, or what the field needs.
const NUMBER = /^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$/;
function fieldProblem(s, text) {
  const unset = s.optional ? ` (or ${s.unset_word})` : '';
  if (text === '') return `give a value${unset}`;
  if (s.optional && text === s.unset_word) return null;
  if (s.kind === 'real' && !(NUMBER.test(text) || text === 'inf' || (s.words || []).includes(text))) return `needs a number${unset}`;
  if (s.kind === 'integer' && !/^[+-]?\d+$/.test(text)) return `needs a whole number${unset}`;
  if (s.kind === 'rgb' && !(s.words || []).includes(text)) {
    const parts = text.split(',');
    if (parts.length !== 3 || !parts.every((p) => NUMBER.test(p.trim()))) return `needs R,G,B: three numbers${unset}`;
  }
  if (s.kind === 'pair') {
    const parts = text.split(',');
    if (parts.length !== 2 || !parts.every((p) => NUMBER.test(p.trim()))) return `needs X,Y: two numbers${unset}`;
  }
  return null;
}

function control(s) {
  const row = document.createElement('div');
  row.className = 'row';
  row.title = `--${s.name}: ${s.help}`;
  const label = document.createElement('label');
  label.htmlFor = 'p-' + s.name;
  const name = document.createElement('span');
  name.textContent = s.name;
  label.appendChild(name);
  if (s.unit && s.unit !== '1') {
    const unit = document.createElement('span');
    unit.className = 'unit';
    unit.textContent = ` [${s.unit}]`;
    label.appendChild(unit);
  }
  row.appendChild(label);
  const msg = document.createElement('div');
  msg.className = 'msg';
  const start = state.starts[s.name];
  const initial = start ? start.value : s.default;
  if (start) {
    const mark = document.createElement('span');
    mark.className = 'start';
    mark.textContent = ' \u2022';
    mark.title = start.why;
    label.appendChild(mark);
    row.title += `\n\nThe page started here: ${start.why}`;
  }
  let input, slider = null;
  if (s.kind === 'choice') {
    input = document.createElement('select');
    for (const c of s.choices) input.add(new Option(c, c));
    input.value = initial;
    input.onchange = () => edited(s, input.value, false);
  } else if (s.kind === 'boolean') {
    input = document.createElement('input');
    input.type = 'checkbox';
    input.checked = initial === 'true';
    input.onchange = () => edited(s, String(input.checked), false);
    label.prepend(input);
  } else {
    input = document.createElement('input');
    input.type = 'text';
    input.value = initial;
    input.spellcheck = false;
    input.autocomplete = 'off';
    const span = s.kind === 'real' || s.kind === 'integer' ? sliderSpan(s, initial) : null;
    if (span) {
      slider = document.createElement('input');
      slider.type = 'range';
      slider.min = 0;
      slider.max = 1000;
      slider.setAttribute('aria-label', s.name);
      const to = (t) => span.log ? span.lo * Math.pow(span.hi / span.lo, t) : span.lo + t * (span.hi - span.lo);
      const from = (v) => span.log ? Math.log(v / span.lo) / Math.log(span.hi / span.lo) : (v - span.lo) / (span.hi - span.lo);
      const sync = () => {
        const v = parseFloat(input.value);
        if (isFinite(v) && !(span.log && v <= 0)) slider.value = Math.round(1000 * Math.min(1, Math.max(0, from(v))));
      };
      const value = () => {
        const v = to(slider.value / 1000);
        return s.kind === 'integer' ? String(Math.round(v)) : String(+v.toPrecision(4));
      };
      // While the hand moves: drafts; when it lets go (change), the full frame.
      slider.oninput = () => {
        input.value = value();
        edited(s, input.value, true);
      };
      slider.onchange = () => {
        input.value = value();
        edited(s, input.value, false);
      };
      sync();
      input.addEventListener('sync', sync);
      input.addEventListener('change', sync);
      row.appendChild(slider);
    }
    input.addEventListener('change', () => edited(s, input.value.trim(), false));
  }
  input.id = 'p-' + s.name;
  if (s.kind !== 'boolean') row.appendChild(input);
  row.appendChild(msg);
  state.rows[s.name] = {row, input, msg};
  return row;
}

// A control's new text: checked for what the page can send, then a frame.
function edited(s, text, moving) {
  const r = state.rows[s.name];
  const problem = fieldProblem(s, text);
  state.lastEdited = s.name;
  if (problem) {  // not sent: the frame keeps the last value that was
    r.msg.textContent = problem;
    r.row.classList.add('refused');
    return;
  }
  r.msg.textContent = '';
  r.row.classList.remove('refused');
  setText(s.name, text);
  change(moving).catch(() => {});  // (shown beside the field and over the picture)
}

function setText(name, text) {
  const s = state.meta.specs.find((p) => p.name === name);
  if (text === s.default && !state.starts[name]) delete state.values[name];
  else state.values[name] = text;  // (a value the page started from stays spelled out, even at the default)
}

// ---- frames ----------------------------------------------------------------------------------

function knownSize(k) {
  return [Math.floor(state.meta.width / k), Math.floor(state.meta.height / k)];
}

// ---- the frame-time model ---------------------------------------------------------------------
// A frame's time is the sum over its steps of draws x (a + b x megapixels):
// per pass, a fixed cost per draw (a software renderer's overhead: a few ms
// on SwiftShader, whatever the size) and a cost per megapixel, fitted to the
// times of the pass's last draws at the sizes drawn (each step is timed to
// its end; a pass's first draw, which compiles it, is left out). A
// diffusion's count of passes at another scale is the last plan's times the
// ratio measured between the plans of one change at the two scales (the
// blur scales with the size; how its count follows depends on the scheme),
// 1 until measured: a guess that draws the first drafts small.
function fit(pass) {
  const obs = state.model.obs[pass];
  if (!obs || !obs.length) return null;
  const xs = obs.map((o) => o.mpx), ys = obs.map((o) => o.ms);
  const n = obs.length, mx = xs.reduce((a, b) => a + b) / n, my = ys.reduce((a, b) => a + b) / n;
  let sxx = 0, sxy = 0;
  for (let i = 0; i < n; ++i) sxx += (xs[i] - mx) ** 2, sxy += (xs[i] - mx) * (ys[i] - my);
  if (n >= 2 && Math.max(...xs) > 1.5 * Math.min(...xs) && sxx > 0) {
    const b = Math.max(0, sxy / sxx);
    return {a: Math.max(0, my - b * mx), b};
  }
  const a = Math.min(state.model.floor, my);  // one size only: the overhead seen elsewhere, the rest per pixel
  return {a, b: Math.max(0, (my - a) / mx)};
}

function iterRatio(k) {
  const known = Object.keys(state.model.ratio).map(Number);
  if (k === state.base) return 1;
  if (!known.length) return 1;
  const near = known.reduce((x, y) => (Math.abs(y - k) < Math.abs(x - k) ? y : x));
  return state.model.ratio[near];
}

// The model's time for a frame at scale k (its fetch included), from the
// last plan's steps; null before every pass of it has been timed.
function predictMs(k) {
  const plan = state.lastPlan;
  if (!plan) return null;
  const [w, h] = knownSize(k);
  const mpx = w * h / 1e6;
  let ms = state.fetchMs;
  for (const step of plan.steps) {
    const c = fit(step.copy ? 'copy' : step.pass);
    if (!c) return null;
    const count = step.iterate
      ? Math.max(1, Math.round(step.iterate.count * iterRatio(k) / iterRatio(state.lastPlanScale))) : 1;
    ms += count * (c.a + c.b * mpx);
  }
  return ms;
}

// The smallest scale (a multiple of the texture limit's) whose frame the
// model puts within the budget; the first frame, before any measurement, at
// about FIRST_MPX.
function draftScale() {
  const b = state.base;
  const most = Math.max(b, Math.floor(Math.min(state.meta.width, state.meta.height) / 48));  // at least 48 px
  if (predictMs(b) === null) {
    let k = b;
    while (k < most && (state.meta.width / k) * (state.meta.height / k) > FIRST_MPX * 1e6) ++k;
    return k;
  }
  for (let k = b; k <= most; ++k) if (predictMs(k) <= BUDGET_MS) return k;
  return most;
}

// A frame's timed steps into the model; its plan's diffusion counts into the
// ratio between scales (against the other scale's plan of the same change).
function learn(timed, k, plan, gen) {
  const [w, h] = knownSize(k);
  const mpx = w * h / 1e6;
  const m = state.model;
  for (const t of timed) {
    if (!m.seen.has(t.pass)) {  // its first draw compiles it
      m.seen.add(t.pass);
      continue;
    }
    const per = t.ms / t.count;
    m.floor = Math.min(m.floor, per);
    const obs = m.obs[t.pass] || (m.obs[t.pass] = []);
    obs.push({mpx, ms: per});
    if (obs.length > 8) obs.shift();
  }
  const count = plan.steps.reduce((n, s) => n + (s.iterate ? s.iterate.count : 0), 0);
  m.plans[k] = {gen, count};
  const full = m.plans[state.base];
  for (const [kk, p] of Object.entries(m.plans))
    if (+kk !== state.base && full && p.gen === full.gen && full.count > 0) m.ratio[kk] = Math.max(p.count, 1) / full.count;
}

// The inputs at scale k, fetched once (again after the server re-read them for a new camera).
async function ensureLevel(k) {
  if (state.r.levels[k]) return;
  const [rgba, range, sky] = await Promise.all(['image', 'range', 'sky'].map((n) => fetchFloats(n, k)));
  const [w, h] = knownSize(k);
  state.r.upload(k, w, h, rgba, range, sky);
  if (k === state.base) {
    state.rgba = rgba;
    state.rangeHost = range;
    let lo = Infinity, hi = 0;
    for (let i = 0; i < range.length; ++i)
      if (range[i] > 0 && sky[i] < 0.5) lo = Math.min(lo, range[i]), hi = Math.max(hi, range[i]);
    state.rangeMin = isFinite(lo) ? lo : 1;
    state.rangeMax = hi > 0 ? hi : 1;
    legend();
  }
}

// A change of the values: a draft when the model says the full frame would
// not answer in time (always while a control moves), the full frame once the
// hand stops. Resolves when the full frame of this change is drawn.
function change(moving) {
  state.gen += 1;
  const mine = state.gen;
  const done = new Promise((resolve, reject) => state.waiters.push({gen: mine, resolve, reject}));
  clearTimeout(state.idleTimer);
  state.fullWanted = !moving;
  if (moving) {
    state.idleTimer = setTimeout(() => {
      state.fullWanted = true;
      pump();
    }, IDLE_MS);
  }
  pump();
  return done;
}

// What to draw next: {gen, quality, k}, or null.
function nextFrame() {
  const fullMs = predictMs(state.base);
  if (state.shown.gen < state.gen) {
    const fits = fullMs !== null && fullMs <= BUDGET_MS;
    if (state.fullWanted && fits) return {gen: state.gen, quality: 'full', k: state.base};
    const k = draftScale();
    return {gen: state.gen, quality: k === state.base ? 'full' : 'draft', k};
  }
  if (state.shown.quality === 'draft' && state.fullWanted) return {gen: state.gen, quality: 'full', k: state.base};
  return null;
}

async function pump() {
  if (state.busy) return;
  state.busy = true;
  try {
    for (let job = nextFrame(); job; job = nextFrame()) await draw(job);
  } finally {
    state.busy = false;
  }
}

function settle(gen, error) {
  const done = state.waiters.filter((w) => w.gen <= gen && (error || state.shown.quality === 'full'));
  state.waiters = state.waiters.filter((w) => !done.includes(w));
  for (const w of done) error ? w.reject(error) : w.resolve(state.lastMs);
}

async function draw(job) {
  const values = {...state.values};
  // what the model said when it chose this scale (and of the next finer one)
  const predicted = predictMs(job.k), finer = job.k > state.base ? predictMs(job.k - 1) : null;
  const t0 = performance.now();
  let f;
  try {
    f = await fetchJSON('frame', {values, scale: job.k, pixel_factor: state.base / job.k, refusal: 'inline'});
  } catch (e) {  // the server is gone, or a request it could not read
    state.shown = {gen: job.gen, quality: 'refused'};
    lacks(`not drawn: ${e.message}`);
    settle(job.gen, e);
    return;
  }
  if (f.refused) {
    refused(f.refused);
    state.shown = {gen: job.gen, quality: 'refused'};
    settle(job.gen, new Error(f.refused.message));
    return;
  }
  if (f.data_version !== state.dataVersion) {  // a new camera re-read the inputs
    state.dataVersion = f.data_version;
    state.r.drop();
  }
  try {
    await ensureLevel(state.base);
    await ensureLevel(job.k);
    for (const name of f.plan.data || [])
      if (!state.r.levels[job.k].inputs[name]) state.r.addInput(job.k, name, await fetchMap(name));
  } catch (e) {
    state.shown = {gen: job.gen, quality: 'refused'};
    lacks(`not drawn: ${e.message}`);
    settle(job.gen, e);
    return;
  }
  const fetched = performance.now() - t0;
  const stop = job.quality === 'full' ? () => state.gen !== job.gen || !state.fullWanted : null;
  if (job.quality === 'full' && !(predictMs(job.k) <= BUDGET_MS))
    status(`drawing the full frame (${knownSize(job.k).join('\u00d7')})\u2026` +
           (state.shown.quality === 'draft' ? ' a draft is shown' : ''));
  const t1 = performance.now();
  const timed = await state.r.run(f.plan, job.k, {stop, sliceMs: SLICE_MS});
  if (timed === false) return;  // a newer change: its frame comes next
  const ms = performance.now() - t1;
  learn(timed, job.k, f.plan, job.gen);
  state.fetchMs = 0.5 * state.fetchMs + 0.5 * fetched;
  state.lastPlan = f.plan;
  state.lastPlanScale = job.k;
  state.frame = f;
  state.lastMs = ms;
  state.shown = {gen: job.gen, quality: job.quality};
  for (const r of Object.values(state.rows)) {
    r.msg.textContent = '';
    r.row.classList.remove('refused');
  }
  lacks('');
  $('error').textContent = '';
  $('command').value = f.command;
  show();
  const [w, h] = knownSize(job.k);
  const info = {gen: job.gen, quality: job.quality, scale: job.k, width: w, height: h, ms, fetchMs: fetched,
                predictedMs: predicted, finerPredictedMs: finer, renderer: state.r.renderer};
  state.history.push(info);
  if (state.history.length > 200) state.history.shift();
  const d = f.plan.derived || {};
  const passes = (d.iterations !== undefined ? `, ${d.iterations} diffusion passes` : '') +
    (d.sigma_max_px !== undefined ? `, sigma_max ${(+d.sigma_max_px).toPrecision(3)} px` : '');
  const time = ms >= 1000 ? `${(ms / 1000).toFixed(1)} s` : `${ms.toFixed(0)} ms`;
  info.status = job.quality === 'draft'
    ? `draft at 1/${job.k / state.base} (${w}\u00d7${h}), ${time} on ${state.r.renderer}${passes}: ` +
      `the blur at the full frame's scale; the full frame follows when the hand stops`
    : `full frame ${w}\u00d7${h}, ${time} on ${state.r.renderer}${passes}`;
  status(info.status);
  settle(job.gen, null);
}

function status(text) { $('status').textContent = text; }

function lacks(text) {
  $('lacks').textContent = text;
  $('lacks').hidden = !text;
}

// A refused value: beside its field (the one the message is about, else the
// one last edited) and over the picture, which stays the last frame drawn.
function refused(r) {
  const name = r.param && state.rows[r.param] ? r.param : state.lastEdited;
  if (name && state.rows[name]) {
    state.rows[name].msg.textContent = r.message;
    state.rows[name].row.classList.add('refused');
  }
  lacks(`not drawn: ${r.message}` + (state.frame ? ' (the picture is the last frame drawn)' : ''));
}

function show() {
  if (!state.r.level) return;
  const focus = state.values['focus-distance'] || state.values['dof-focus-distance'];
  state.r.show({depth: $('depth').checked, wipe: +$('wipe').value / 1000, rangeMin: state.rangeMin,
                rangeMax: state.rangeMax, focus: $('focal').checked && focus ? parseFloat(focus) : 0,
                focusTol: (parseFloat(focus) || 0) * 0.02});
  $('legend').hidden = !$('depth').checked;
}

// The depth view's legend: the colour ramp over the known range's log span,
// ticks at 1, 2, 5 x 10^n metres, and the sky's hatching.
function legend() {
  const lo = state.rangeMin, hi = state.rangeMax;
  const stops = [];
  for (let i = 0; i <= 8; ++i) stops.push(`rgb(${depthColour(i / 8).join(',')}) ${(100 * i / 8).toFixed(1)}%`);
  const el = $('legend');
  el.textContent = '';
  const title = document.createElement('div');
  title.textContent = 'range (log scale): near warm, far cool';
  el.appendChild(title);
  const bar = document.createElement('div');
  bar.className = 'bar';
  bar.style.background = `linear-gradient(to right, ${stops.join(', ')})`;
  el.appendChild(bar);
  const ticks = document.createElement('div');
  ticks.className = 'ticks';
  const at = (r) => hi > lo ? Math.log(r / lo) / Math.log(hi / lo) : 0;
  const label = (r) => r >= 1000 ? `${+(r / 1000).toPrecision(3)} km` : `${+r.toPrecision(3)} m`;
  const marks = [lo];
  for (let e = Math.floor(Math.log10(lo)); e <= Math.ceil(Math.log10(hi)); ++e)
    for (const m of [1, 2, 5]) {
      const r = m * Math.pow(10, e);
      if (r > lo && r < hi) marks.push(r);
    }
  marks.push(hi);
  let last = -1;
  for (const r of marks) {  // (labels at least 14 % apart, 22 % from the ends, whose labels lie inside the bar)
    const x = at(r);
    if (r !== hi && r !== lo && (x - last < (last === 0 ? 0.22 : 0.14) || at(hi) - x < 0.22)) continue;
    const t = document.createElement('span');
    t.style.left = `${(100 * x).toFixed(1)}%`;
    if (r === lo) t.style.transform = 'none';  // (the ends' labels inside the bar's width)
    else if (r === hi) t.style.transform = 'translateX(-100%)';
    t.textContent = label(r);
    ticks.appendChild(t);
    last = x;
  }
  el.appendChild(ticks);
  const sky = document.createElement('div');
  sky.innerHTML = '<span class="sky"></span> sky and unknown range';
  el.appendChild(sky);
}

function pixelAt(ev) {
  const c = $('canvas').getBoundingClientRect();
  const [w, h] = knownSize(state.base);
  // object-fit: contain: the picture's box inside the canvas element
  const s = Math.min(c.width / w, c.height / h), ox = (c.width - w * s) / 2, oy = (c.height - h * s) / 2;
  const x = Math.floor((ev.clientX - c.left - ox) / s), y = Math.floor((ev.clientY - c.top - oy) / s);
  return [Math.min(w - 1, Math.max(0, x)), Math.min(h - 1, Math.max(0, y))];
}

function clickSample(ev) {
  const [x, y] = pixelAt(ev);
  const mode = $('click').value;
  const [w, h] = knownSize(state.base);
  if (mode === 'airlight') {  // the input's linear colour, 5x5 mean
    const acc = [0, 0, 0];
    let n = 0;
    for (let v = -2; v <= 2; ++v) for (let u = -2; u <= 2; ++u) {
      const xx = Math.min(w - 1, Math.max(0, x + u)), yy = Math.min(h - 1, Math.max(0, y + v));
      const i = (yy * w + xx) * 4;
      for (let c = 0; c < 3; ++c) acc[c] += state.rgba[i + c];
      ++n;
    }
    setValue('airlight', acc.map((a) => (+(a / n).toPrecision(4))).join(',')).catch(() => {});
  } else if (mode === 'focus') {
    const r = state.rangeHost[y * w + x];
    const name = state.meta.specs.some((s) => s.name === 'focus-distance') ? 'focus-distance' : 'dof-focus-distance';
    if (r > 0) setValue(name, String(+r.toPrecision(4))).catch(() => {});
  }
}

function setValue(name, value) {
  const s = state.meta.specs.find((p) => p.name === name);
  if (!s) return Promise.reject(new Error(`${name} is not a parameter of ${state.meta.effect}`));
  const text = String(value);
  const r = state.rows[name];
  if (r && r.input.type === 'checkbox') r.input.checked = text === 'true';
  else if (r) {
    r.input.value = text;
    r.input.dispatchEvent(new Event('sync'));  // its slider follows
  }
  state.lastEdited = name;
  const problem = fieldProblem(s, text.trim());
  if (problem) {
    if (r) r.msg.textContent = problem;
    return Promise.reject(new Error(`--${name} '${text}': ${problem}`));
  }
  setText(name, text.trim());
  return change(false);
}

// The panel: the effect's blocks in the table's order, the camera's (the
// depth flags' intrinsics and a fog's pose) after the first.
function buildControls(meta) {
  const blocks = new Map();
  for (const s of meta.specs) {
    const b = s.block === 'depth' ? 'camera' : s.block;
    if (!blocks.has(b)) blocks.set(b, []);
    blocks.get(b).push(s);
  }
  const order = [...blocks.keys()].filter((b) => b !== 'camera');
  if (blocks.has('camera')) order.splice(Math.min(1, order.length), 0, 'camera');
  for (const b of order) {
    const fs = document.createElement('fieldset');
    const lg = document.createElement('legend');
    lg.textContent = b;
    fs.appendChild(lg);
    for (const s of blocks.get(b)) fs.appendChild(control(s));
    $('controls').appendChild(fs);
  }
}

function notes(meta) {
  const el = $('notes');
  if (!meta.start.length) return;
  const close = document.createElement('button');
  close.textContent = '\u00d7';
  close.title = 'hide';
  close.onclick = () => { el.hidden = true; };
  el.appendChild(close);
  el.appendChild(document.createTextNode('The page started from these values (in the command too):'));
  const ul = document.createElement('ul');
  for (const s of meta.start) {
    const li = document.createElement('li');
    li.textContent = `--${s.name} ${s.value}: ${s.why}`;
    ul.appendChild(li);
  }
  el.appendChild(ul);
  el.hidden = false;
}

async function main() {
  const meta = await fetchJSON('meta.json');
  state.meta = meta;
  document.title = `brume view: ${meta.effect}`;
  $('title').textContent = `brume view \u2014 ${meta.effect} \u2014 ${meta.image}`;
  const r = new Renderer($('canvas'), meta);
  state.r = r;
  const big = Math.max(meta.width, meta.height);
  state.base = big > r.maxTexture ? Math.ceil(big / r.maxTexture) : 1;
  if (state.base > 1)
    $('notice').textContent = `The image (${meta.width}x${meta.height}) exceeds this browser's largest texture ` +
      `(${r.maxTexture}): shown at 1/${state.base} of its size, where every pixel scale (sigma0, the blur) is that ` +
      `of the smaller image. The command and the record render the full image.`;
  for (const s of meta.start) {
    state.starts[s.name] = s;
    state.values[s.name] = s.value;
  }
  buildControls(meta);
  notes(meta);
  const names = meta.specs.map((s) => s.name);
  const click = $('click');
  if (names.includes('airlight')) click.add(new Option('sample the airlight', 'airlight'));
  if (names.includes('focus-distance') || names.includes('dof-focus-distance')) {
    click.add(new Option('focus here', 'focus'));
    click.value = 'focus';
    $('focal-row').hidden = false;
  }
  $('canvas').onclick = clickSample;
  for (const id of ['wipe', 'depth', 'focal']) $(id).oninput = show;
  $('copy').onclick = async () => {
    $('command').select();
    try { await navigator.clipboard.writeText($('command').value); } catch (e) { document.execCommand('copy'); }
  };
  $('save').onclick = () => {
    if (!state.frame) return;
    const a = document.createElement('a');
    a.href = URL.createObjectURL(new Blob([JSON.stringify(state.frame.record, null, 2)], {type: 'application/json'}));
    a.download = `brume-view-${meta.effect.replace('+', '-')}.json`;
    a.click();
  };
  await ensureLevel(state.base);
  // The first frame: a draft where the image is large (the model has measured nothing yet), then the full one.
  const first = new Promise((resolve) => {
    const check = () => (state.shown.gen >= 1 ? resolve() : setTimeout(check, 20));
    check();
  });
  change(false).catch(() => {});
  await first;
}

// The test hook (docs/view.md).
window.brume = {
  set: (name, value) => setValue(name, value),
  values: () => ({...state.values}),
  starts: () => (state.meta ? state.meta.start : []),
  command: () => state.frame && state.frame.command,
  record: () => state.frame && state.frame.record,
  frameMs: () => state.lastMs,
  // The frame shown: {quality: 'draft'|'full'|'refused', scale, width, height, ms, predictedMs, renderer}.
  frameInfo: () => ({...(state.history[state.history.length - 1] || {}), quality: state.shown.quality}),
  history: () => state.history.slice(),
  model: () => Object.fromEntries(Object.keys(state.model.obs).map((p) => [p, fit(p)])),
  predictMs: (k) => predictMs(k),
  // Resolves when the full frame of the current values is drawn (or refused).
  idle: () => new Promise((resolve) => {
    const check = () => (!state.busy && state.shown.gen === state.gen && state.shown.quality !== 'draft'
      ? resolve(state.shown.quality) : setTimeout(check, 50));
    check();
  }),
  // The frame drawn last at its size, rows top-down, no wipe or overlay: 'u8'
  // as the 8-bit PNG output encodes it, 'f32' linear as the EXR output.
  pixels({format = 'u8'} = {}) {
    const f = state.r.readResult();
    const L = state.r.level;
    const n = L.w * L.h;
    const data = format === 'f32' ? new Float32Array(n * 3) : new Uint8Array(n * 3);
    for (let i = 0; i < n; ++i)
      for (let c = 0; c < 3; ++c) data[i * 3 + c] = format === 'f32' ? f[i * 4 + c] : srgb8(f[i * 4 + c]);
    return {width: L.w, height: L.h, channels: 3, format, data};
  },
  // The canvas as displayed (the effect, the wipe, the depth view), sRGB RGBA bytes, rows top-down.
  display() {
    const L = state.r.level;
    return {width: L.w, height: L.h, data: state.r.readDisplay()};
  },
};
window.brume.ready = main().catch((e) => {
  $('error').textContent = e.message;
  lacks(`not drawn: ${e.message}`);
  return Promise.reject(e);
});
window.brume.ready.catch(() => {});  // (said on the page; a test reads it from ready)
