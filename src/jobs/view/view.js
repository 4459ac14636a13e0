// brume view — the page: controls generated from the command's parameter
// table (meta.json: unit, range, default, help; a log slider where the range
// spans decades), the frame asked of the server as a plan for every change
// and run by render.js, the before/after wipe, the depth view, the focal
// plane, the frame time, "Copy command" and "Save record". The test hook
// window.brume: `await brume.set(name, value)` (CLI names; resolves once the
// frame with every pending change is drawn) and `brume.pixels({format})`.
import {Renderer, srgb8} from './render.js';

const $ = (id) => document.getElementById(id);
const state = {values: {}, meta: null, r: null, scale: 1, frame: null, gen: 0, drawn: 0, waiters: [], busy: false,
               error: null, click: 'none'};

async function fetchJSON(url, body) {
  const res = await fetch(url, body === undefined ? {} : {method: 'POST', body: JSON.stringify(body),
                                                        headers: {'Content-Type': 'application/json'}});
  const j = await res.json();
  if (!res.ok) throw new Error(j.error || res.statusText);
  return j;
}
async function fetchFloats(name) {
  const res = await fetch(`${name}.bin?scale=${state.scale}`);
  if (!res.ok) throw new Error(`${name}: ${res.status}`);
  return new Float32Array(await res.arrayBuffer());
}

// A map a plan names (CommandDef::preview_data): its floats and its shape.
async function fetchMap(name) {
  const res = await fetch(`data.bin?name=${encodeURIComponent(name)}`);
  if (!res.ok) throw new Error(`map ${name}: ${res.status}`);
  const [width, height, channels] = (res.headers.get('X-Brume-Shape') || '').split(' ').map(Number);
  const data = new Float32Array(await res.arrayBuffer());
  if (!(width > 0 && height > 0 && [1, 2, 4].includes(channels)) || data.length !== width * height * channels)
    throw new Error(`map ${name}: a malformed answer (shape '${res.headers.get('X-Brume-Shape')}', ${data.length} values)`);
  return {width, height, channels, data};
}

// The span a slider covers: the command's sampling range where it has one
// (loguniform -> log), else the declared range when finite; log where it
// spans two decades or more above 0.
function sliderSpan(s) {
  const m = /^(log)?uniform\(([^,]+),([^)]+)\)$/.exec((s.sampling || '').replace(/\s/g, ''));
  if (m) return {lo: +m[2], hi: +m[3], log: !!m[1]};
  if (s.min === null || s.max === null) {
    const d = parseFloat(s.default);
    if (s.min !== null && s.min >= 0 && d > 0) return {lo: d / 100, hi: d * 100, log: true};
    return null;
  }
  const log = s.min > 0 && s.max / s.min >= 100;
  return {lo: log && s.min_open ? s.min * 1.0001 : s.min, hi: s.max, log};
}

function control(s) {
  const row = document.createElement('div');
  row.className = 'row';
  row.title = `--${s.name}: ${s.help}`;
  const label = document.createElement('label');
  label.textContent = s.name + (s.unit && s.unit !== '1' ? ` [${s.unit}]` : '');
  row.appendChild(label);
  let input;
  const set = (text) => {
    if (text === s.default) delete state.values[s.name];
    else state.values[s.name] = text;
    schedule();
  };
  if (s.kind === 'choice') {
    input = document.createElement('select');
    for (const c of s.choices) input.add(new Option(c, c));
    input.value = s.default;
    input.onchange = () => set(input.value);
  } else if (s.kind === 'boolean') {
    input = document.createElement('input');
    input.type = 'checkbox';
    input.checked = s.default === 'true';
    input.onchange = () => set(String(input.checked));
  } else {
    input = document.createElement('input');
    input.type = 'text';
    input.value = s.default;
    input.size = 9;
    const span = s.kind === 'real' || s.kind === 'integer' ? sliderSpan(s) : null;
    if (span) {
      const slider = document.createElement('input');
      slider.type = 'range';
      slider.min = 0;
      slider.max = 1000;
      const to = (t) => span.log ? span.lo * Math.pow(span.hi / span.lo, t) : span.lo + t * (span.hi - span.lo);
      const from = (v) => span.log ? Math.log(v / span.lo) / Math.log(span.hi / span.lo) : (v - span.lo) / (span.hi - span.lo);
      const sync = () => {
        const v = parseFloat(input.value);
        if (isFinite(v)) slider.value = Math.round(1000 * Math.min(1, Math.max(0, from(v))));
      };
      slider.oninput = () => {
        const v = to(slider.value / 1000);
        input.value = s.kind === 'integer' ? String(Math.round(v)) : String(+v.toPrecision(4));
        set(input.value);
      };
      sync();
      input.addEventListener('change', sync);
      input.addEventListener('sync', sync);
      row.appendChild(slider);
    }
    input.onchange = () => set(input.value.trim());
  }
  input.id = 'p-' + s.name;
  row.appendChild(input);
  return row;
}

function schedule() {
  state.gen += 1;
  const mine = state.gen;
  const done = new Promise((resolve, reject) => state.waiters.push({gen: mine, resolve, reject}));
  if (!state.busy) pump();
  return done;
}

// Draws frames until the newest values are shown; settles the waiters.
async function pump() {
  state.busy = true;
  while (state.drawn < state.gen) {
    const gen = state.gen;
    try {
      const f = await fetchJSON('frame', {values: state.values, scale: state.scale});
      for (const name of f.plan.data || [])
        if (!state.r.inputs[name]) state.r.addInput(name, await fetchMap(name));
      const t0 = performance.now();
      state.r.run(f.plan);
      state.r.sync();
      const ms = performance.now() - t0;
      state.frame = f;
      state.error = null;
      show();
      const d = f.plan.derived || {};
      $('time').textContent = `frame ${ms.toFixed(0)} ms on ${state.r.renderer}` +
        (d.iterations !== undefined ? `, ${d.iterations} diffusion passes` : '') +
        (d.sigma_max_px !== undefined ? `, sigma_max ${(+d.sigma_max_px).toPrecision(3)} px` : '');
      $('command').value = f.command;
      $('error').textContent = '';
      state.lastMs = ms;
    } catch (e) {
      state.error = e;
      $('error').textContent = e.message;
    }
    state.drawn = gen;
    const settle = state.waiters.filter((w) => w.gen <= gen);
    state.waiters = state.waiters.filter((w) => w.gen > gen);
    for (const w of settle) state.error ? w.reject(state.error) : w.resolve(state.lastMs);
  }
  state.busy = false;
}

function show() {
  const focus = state.values['focus-distance'] || state.values['dof-focus-distance'];
  state.r.show({depth: $('depth').checked, wipe: +$('wipe').value / 1000, rangeMax: state.rangeMax,
                focus: $('focal').checked && focus ? parseFloat(focus) : 0, focusTol: (parseFloat(focus) || 0) * 0.02});
}

function pixelAt(ev) {
  const c = $('canvas').getBoundingClientRect();
  const x = Math.floor((ev.clientX - c.left) / c.width * state.r.w), y = Math.floor((ev.clientY - c.top) / c.height * state.r.h);
  return [Math.min(state.r.w - 1, Math.max(0, x)), Math.min(state.r.h - 1, Math.max(0, y))];
}

function clickSample(ev) {
  const [x, y] = pixelAt(ev);
  const mode = $('click').value;
  if (mode === 'airlight') {  // the input's linear colour, 5x5 mean
    const acc = [0, 0, 0];
    let n = 0;
    for (let v = -2; v <= 2; ++v) for (let u = -2; u <= 2; ++u) {
      const xx = Math.min(state.r.w - 1, Math.max(0, x + u)), yy = Math.min(state.r.h - 1, Math.max(0, y + v));
      const i = (yy * state.r.w + xx) * 4;
      for (let c = 0; c < 3; ++c) acc[c] += state.rgba[i + c];
      ++n;
    }
    setValue('airlight', acc.map((a) => (+(a / n).toPrecision(4))).join(','));
  } else if (mode === 'focus') {
    const r = state.rangeHost[y * state.r.w + x];
    const name = state.meta.specs.some((s) => s.name === 'focus-distance') ? 'focus-distance' : 'dof-focus-distance';
    if (r > 0) setValue(name, String(+r.toPrecision(4)));
  }
}

function setValue(name, value) {
  const s = state.meta.specs.find((p) => p.name === name);
  if (!s) return Promise.reject(new Error(`${name} is not a parameter of ${state.meta.effect}`));
  const text = String(value);
  const el = $('p-' + name);
  if (el && el.type === 'checkbox') el.checked = text === 'true';
  else if (el) {
    el.value = text;
    el.dispatchEvent(new Event('sync'));  // its slider follows
  }
  if (text === s.default) delete state.values[name];
  else state.values[name] = text;
  return schedule();
}

async function main() {
  const meta = await fetchJSON('meta.json');
  state.meta = meta;
  document.title = `brume view: ${meta.effect}`;
  $('title').textContent = `brume view — ${meta.effect} — ${meta.image}`;
  const r = new Renderer($('canvas'), meta);
  state.r = r;
  const big = Math.max(meta.width, meta.height);
  state.scale = big > r.maxTexture ? Math.ceil(big / r.maxTexture) : 1;
  if (state.scale > 1)
    $('notice').textContent = `The image (${meta.width}x${meta.height}) exceeds this browser's largest texture ` +
      `(${r.maxTexture}): shown at 1/${state.scale} of its size, where every pixel scale (sigma0, the blur) is that ` +
      `of the smaller image. The command and the record render the full image.`;
  const [rgba, range, sky] = await Promise.all(['image', 'range', 'sky'].map((n) => fetchFloats(n)));
  const w = Math.floor(meta.width / state.scale), h = Math.floor(meta.height / state.scale);
  r.upload(w, h, rgba, range, sky);
  state.rgba = rgba;
  state.rangeHost = range;
  let rmax = 0;
  for (let i = 0; i < range.length; ++i) if (range[i] > rmax && sky[i] < 0.5) rmax = range[i];
  state.rangeMax = rmax;
  const blocks = {};
  for (const s of meta.specs) (blocks[s.block] = blocks[s.block] || []).push(s);
  for (const [b, specs] of Object.entries(blocks)) {
    const fs = document.createElement('fieldset');
    const lg = document.createElement('legend');
    lg.textContent = b;
    fs.appendChild(lg);
    for (const s of specs) fs.appendChild(control(s));
    $('controls').appendChild(fs);
  }
  const names = meta.specs.map((s) => s.name);
  const click = $('click');
  if (names.includes('airlight')) click.add(new Option('sample the airlight', 'airlight'));
  if (names.includes('focus-distance') || names.includes('dof-focus-distance')) {
    click.add(new Option('focus here', 'focus'));
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
  await schedule();
}

// The test hook (docs/view.md).
window.brume = {
  set: (name, value) => setValue(name, value),
  values: () => ({...state.values}),
  command: () => state.frame && state.frame.command,
  record: () => state.frame && state.frame.record,
  frameMs: () => state.lastMs,
  // The effect frame at image size, rows top-down, no wipe or overlay: 'u8'
  // as the 8-bit PNG output encodes it, 'f32' linear as the EXR output.
  pixels({format = 'u8'} = {}) {
    const f = state.r.readResult();
    const n = state.r.w * state.r.h;
    const data = format === 'f32' ? new Float32Array(n * 3) : new Uint8Array(n * 3);
    for (let i = 0; i < n; ++i)
      for (let c = 0; c < 3; ++c) data[i * 3 + c] = format === 'f32' ? f[i * 4 + c] : srgb8(f[i * 4 + c]);
    return {width: state.r.w, height: state.r.h, channels: 3, format, data};
  },
};
window.brume.ready = main().catch((e) => {
  $('error').textContent = e.message;
  throw e;
});
