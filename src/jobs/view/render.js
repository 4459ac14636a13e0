// brume view — runs a frame plan (include/brume/preview.hpp) in WebGL2 with
// the native backend's passes: the server sends each pass's whole fragment
// shader (src/gpu/passes.hpp: `#version 300 es`, topics, body) and the plan
// names the passes, their inputs, targets and uniforms. Every texture is
// NEAREST (samples between texels are interpolated in the shader, as
// `--gpu-filter shader`); render targets are float (EXT_color_buffer_float).

const FORMATS = {
  RGBA32F: ['RGBA32F', 'RGBA'], RGBA16F: ['RGBA16F', 'RGBA'], RG32F: ['RG32F', 'RG'], R32F: ['R32F', 'RED'],
};

// The display: the effect frame (or the input, left of the wipe) encoded
// with the sRGB curve as an 8-bit output would be, or the range colour-mapped
// as `brume demo`'s range-preview.png is (src/depth/preview.cpp): log range
// from the nearest known to the farthest, near warm (dark red, orange,
// yellow) to far cool (cyan, blue); the sky and unknown pixels hatched grey.
// The sRGB curve (IEC 61966-2-1), once: the display shader's enc() is
// written from the same constants as srgb8's JS curve.
const SRGB = {linearBelow: 0.0031308, slope: 12.92, scale: 1.055, gamma: 2.4, offset: 0.055};
const glslFloat = (x) => (Number.isInteger(x) ? x.toFixed(1) : String(x));
function srgbEncode(v) {
  return v <= SRGB.linearBelow ? SRGB.slope * v : SRGB.scale * Math.pow(v, 1 / SRGB.gamma) - SRGB.offset;
}

const DISPLAY_FS = `#version 300 es
precision highp float;
precision highp sampler2D;
uniform sampler2D uOut;
uniform sampler2D uImage;
uniform sampler2D uRange;
uniform sampler2D uSky;   // the preparation's sky weight
uniform int uMode;        // 0 effect, 1 depth
uniform float uWipe;      // x below which the input is shown
uniform float uRangeMin;  // the known range's span (the legend's ends)
uniform float uRangeMax;
uniform float uFocus;     // > 0: mark the focal plane (range within uFocusTol of uFocus)
uniform float uFocusTol;
out vec4 oColor;
float enc(float v) {
  v = max(v, 0.0);
  return v <= ${glslFloat(SRGB.linearBelow)} ? ${glslFloat(SRGB.slope)} * v
       : ${glslFloat(SRGB.scale)} * pow(v, 1.0 / ${glslFloat(SRGB.gamma)}) - ${glslFloat(SRGB.offset)};
}
vec3 ramp(float t) {  // sRGB-encoded, as range_preview's five stops
  vec3 k0 = vec3(0.5, 0.0, 0.05), k1 = vec3(0.95, 0.4, 0.05), k2 = vec3(0.95, 0.9, 0.3), k3 = vec3(0.3, 0.8, 0.9),
       k4 = vec3(0.1, 0.2, 0.7);
  float s = clamp(t, 0.0, 1.0) * 4.0;
  if (s < 1.0) return mix(k0, k1, s);
  if (s < 2.0) return mix(k1, k2, s - 1.0);
  if (s < 3.0) return mix(k2, k3, s - 2.0);
  return mix(k3, k4, s - 3.0);
}
void main() {
  ivec2 size = textureSize(uOut, 0);
  ivec2 p = ivec2(int(gl_FragCoord.x), size.y - 1 - int(gl_FragCoord.y));  // image rows top-down
  float r = texelFetch(uRange, p, 0).r;
  vec3 e;  // sRGB-encoded
  if (uMode == 1) {
    bool sky = r <= 0.0 || texelFetch(uSky, p, 0).r >= 0.5;
    float t = uRangeMax > uRangeMin ? log(max(r, uRangeMin) / uRangeMin) / log(uRangeMax / uRangeMin) : 0.0;
    bool stripe = ((p.x + p.y) / 4) % 2 == 0;
    e = sky ? (stripe ? vec3(0.42) : vec3(0.58)) : ramp(t);
  } else {
    vec3 c = float(p.x) < uWipe ? texelFetch(uImage, p, 0).rgb : texelFetch(uOut, p, 0).rgb;
    e = vec3(enc(c.r), enc(c.g), enc(c.b));
  }
  if (uFocus > 0.0 && r > 0.0 && abs(r - uFocus) < uFocusTol) e = mix(e, vec3(1.0, 0.0, 1.0), 0.45);
  oColor = vec4(e, 1.0);
}`;

// The depth view's colour at t in [0, 1] (0 near), as the display shader's
// ramp: the legend's gradient.
export function depthColour(t) {
  const k = [[0.5, 0.0, 0.05], [0.95, 0.4, 0.05], [0.95, 0.9, 0.3], [0.3, 0.8, 0.9], [0.1, 0.2, 0.7]];
  const s = Math.min(1, Math.max(0, t)) * 4, j = Math.min(3, Math.floor(s)), u = s - j;
  return k[j].map((a, c) => Math.round(255 * (a + u * (k[j + 1][c] - a))));
}

export class Renderer {
  constructor(canvas, meta) {
    const gl = canvas.getContext('webgl2', {antialias: false, preserveDrawingBuffer: true, alpha: false});
    if (!gl) throw new Error('this browser gives no WebGL2 context');
    if (!gl.getExtension('EXT_color_buffer_float'))
      throw new Error('this browser cannot render to float textures (no EXT_color_buffer_float)');
    this.gl = gl;
    this.canvas = canvas;
    this.maxTexture = gl.getParameter(gl.MAX_TEXTURE_SIZE);
    const info = gl.getExtension('WEBGL_debug_renderer_info');  // the real renderer (SwiftShader, a GPU's name)
    this.renderer = info ? gl.getParameter(info.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER);
    this.vao = gl.createVertexArray();
    this.programs = {};
    for (const [name, p] of Object.entries(meta.passes))
      this.programs[name] = this.link(name, meta.vertex, p.fragment, p.samplers);
    this.display = this.link('display', meta.vertex, DISPLAY_FS, ['uOut', 'uImage', 'uRange', 'uSky']);
    // The inputs at each scale the page draws (1/k of the files' size: the
    // texture limit, or a draft while a control moves), with their render
    // targets and maps: {w, h, inputs, targets, fbos}.
    this.levels = {};
    this.level = null;   // the one the last frame was drawn at
    this.result = null;  // that frame's result texture
  }

  link(name, vs, fs, samplers) {
    const gl = this.gl;
    const prog = gl.createProgram();
    for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
      const s = gl.createShader(type);
      gl.shaderSource(s, src);
      gl.compileShader(s);
      if (!gl.getShaderParameter(s, gl.COMPILE_STATUS))
        throw new Error(`pass ${name}: shader does not compile: ${gl.getShaderInfoLog(s)}`);
      gl.attachShader(prog, s);
    }
    gl.linkProgram(prog);
    if (!gl.getProgramParameter(prog, gl.LINK_STATUS))
      throw new Error(`pass ${name}: program does not link: ${gl.getProgramInfoLog(prog)}`);
    gl.useProgram(prog);
    samplers.forEach((s, i) => {  // sampler i on texture unit i, as the native context sets them
      const loc = gl.getUniformLocation(prog, s);
      if (loc) gl.uniform1i(loc, i);
    });
    const locs = {};
    const n = gl.getProgramParameter(prog, gl.ACTIVE_UNIFORMS);
    for (let i = 0; i < n; ++i) {
      const u = gl.getActiveUniform(prog, i);
      const base = u.name.replace(/\[0\]$/, '');
      locs[base] = gl.getUniformLocation(prog, base);
    }
    return {prog, locs, name};
  }

  texture(internal, format, w, h, data) {
    const gl = this.gl;
    const t = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, t);
    gl.texStorage2D(gl.TEXTURE_2D, 1, gl[internal], w, h);
    if (data) {
      gl.pixelStorei(gl.UNPACK_ALIGNMENT, 4);
      gl.texSubImage2D(gl.TEXTURE_2D, 0, 0, 0, w, h, gl[format], gl.FLOAT, data);
    }
    for (const [k, v] of [[gl.TEXTURE_MIN_FILTER, gl.NEAREST], [gl.TEXTURE_MAG_FILTER, gl.NEAREST],
                          [gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE], [gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE]])
      gl.texParameteri(gl.TEXTURE_2D, k, v);
    return t;
  }

  // A scale's inputs, once: linear RGBA, the prepared range (-1 unknown), the sky weight.
  upload(k, w, h, rgba, range, sky) {
    this.drop(k);
    this.levels[k] = {k, w, h, targets: {}, fbos: {}, inputs: {
      image: this.texture('RGBA32F', 'RGBA', w, h, rgba),
      range: this.texture('R32F', 'RED', w, h, range),
      sky: this.texture('R32F', 'RED', w, h, sky),
    }};
  }

  // Forgets a scale (or every scale): its textures and framebuffers.
  drop(k) {
    const gl = this.gl;
    for (const key of k === undefined ? Object.keys(this.levels) : [k]) {
      const L = this.levels[key];
      if (!L) continue;
      for (const t of [...Object.values(L.inputs), ...Object.values(L.targets)]) gl.deleteTexture(t);
      for (const f of Object.values(L.fbos)) gl.deleteFramebuffer(f);
      if (this.level === L) this.level = null, this.result = null;
      delete this.levels[key];
    }
  }

  // A map a plan names in its "data" ({width, height, channels 1|2|4, data}), once per scale.
  // A name "kind:key" replaces the older maps of its kind (dof's scale map per job).
  addInput(k, name, map) {
    const L = this.levels[k];
    const kind = name.split(':')[0];
    for (const old of Object.keys(L.inputs))
      if (old !== name && old.includes(':') && old.split(':')[0] === kind) {
        this.gl.deleteTexture(L.inputs[old]);
        delete L.inputs[old];
      }
    if (map.width > this.maxTexture || map.height > this.maxTexture)
      throw new Error(`map ${name} is ${map.width}x${map.height}, above this browser's largest texture ` +
                      `(${this.maxTexture}): this effect cannot be previewed here`);
    const [internal, format] = {1: ['R32F', 'RED'], 2: ['RG32F', 'RG'], 4: ['RGBA32F', 'RGBA']}[map.channels];
    L.inputs[name] = this.texture(internal, format, map.width, map.height, map.data);
  }

  target(L, name, format) {
    const key = name + ':' + format;
    if (!L.targets[key]) {
      const [internal, fmt] = FORMATS[format];
      L.targets[key] = this.texture(internal, fmt, L.w, L.h, null);
    }
    return L.targets[key];
  }

  fbo(L, textures) {
    const gl = this.gl;
    const key = textures.map((t) => t.key).join('|');
    if (!L.fbos[key]) {
      const f = gl.createFramebuffer();
      gl.bindFramebuffer(gl.FRAMEBUFFER, f);
      textures.forEach((t, i) => gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0 + i, gl.TEXTURE_2D, t.tex, 0));
      gl.drawBuffers(textures.map((_, i) => gl.COLOR_ATTACHMENT0 + i));
      const st = gl.checkFramebufferStatus(gl.FRAMEBUFFER);
      if (st !== gl.FRAMEBUFFER_COMPLETE) throw new Error('float render target incomplete: 0x' + st.toString(16));
      L.fbos[key] = f;
    }
    return L.fbos[key];
  }

  // Runs the plan's passes at scale k. Each step is timed to its end (a
  // one-pixel read after it: the page's frame-time model learns each pass's
  // cost per megapixel from these). `opts.stop()`: checked between passes
  // once `opts.sliceMs` have gone by since the last look, after yielding to
  // the page's events (a full frame that takes seconds in software GL gives
  // way to a moving control); returns false when it stopped, else the steps'
  // times [{pass, count, ms}].
  async run(plan, k, opts = {}) {
    const gl = this.gl;
    const L = this.levels[k];
    const tex = {};
    for (const [name, t] of Object.entries(L.inputs)) tex[name] = {tex: t, key: name};
    for (const [name, fmt] of Object.entries(plan.targets)) tex[name] = {tex: this.target(L, name, fmt), key: name + ':' + fmt};
    const timed = [];
    let mark = performance.now();
    const pause = async () => {  // lets the page's events in; true: stop
      if (!opts.stop || performance.now() - mark < (opts.sliceMs || 100)) return false;
      this.sync();
      await new Promise((r) => setTimeout(r, 0));
      mark = performance.now();
      return opts.stop();
    };
    const draw = (step, extra, src) => {
      const p = this.programs[step.pass];
      if (!p) throw new Error(`the plan names pass ${step.pass}, which the server did not send`);
      gl.useProgram(p.prog);
      for (const [u, v] of Object.entries({...step.uniforms, ...extra})) {
        const loc = p.locs[u];
        if (loc === undefined) continue;  // a uniform this compiler dropped
        if (v[0] === '1f') gl.uniform1f(loc, v[1]);
        else if (v[0] === '1i') gl.uniform1i(loc, v[1]);
        else if (v[0] === '2f') gl.uniform2f(loc, v[1], v[2]);
        else if (v[0] === '3f') gl.uniform3f(loc, v[1], v[2], v[3]);
        else if (v[0] === '4f') gl.uniform4f(loc, v[1], v[2], v[3], v[4]);
        else if (v[0] === '1fv') gl.uniform1fv(loc, new Float32Array(v[1]));
      }
      step.in.forEach((name, i) => {
        gl.activeTexture(gl.TEXTURE0 + i);
        gl.bindTexture(gl.TEXTURE_2D, name === '$src' ? src.tex : tex[name].tex);
      });
      gl.drawArrays(gl.TRIANGLES, 0, 3);
    };
    gl.bindVertexArray(this.vao);
    gl.viewport(0, 0, L.w, L.h);
    for (const step of plan.steps) {
      const t0 = performance.now();
      let count = 1;
      if (step.copy) {  // a plain copy: the diffusion's first texture from an input
        const from = this.fbo(L, [tex[step.copy.from]]), to = this.fbo(L, [tex[step.copy.to]]);
        gl.bindFramebuffer(gl.READ_FRAMEBUFFER, from);
        gl.bindFramebuffer(gl.DRAW_FRAMEBUFFER, to);
        gl.blitFramebuffer(0, 0, L.w, L.h, 0, 0, L.w, L.h, gl.COLOR_BUFFER_BIT, gl.NEAREST);
        gl.bindFramebuffer(gl.READ_FRAMEBUFFER, null);
        gl.bindFramebuffer(gl.DRAW_FRAMEBUFFER, null);
      } else if (step.iterate) {
        const it = step.iterate;
        count = it.count;
        let src = tex[it.ping], dst = tex[it.pong];
        for (let i = 0; i < it.count; ++i) {
          gl.bindFramebuffer(gl.FRAMEBUFFER, this.fbo(L, [dst]));
          draw(step, {[it.uniform]: ['1i', i]}, src);
          [src, dst] = [dst, src];
          if (await pause()) return false;
          gl.bindVertexArray(this.vao);
          gl.viewport(0, 0, L.w, L.h);
        }
        tex[it.last] = src;
      } else {
        gl.bindFramebuffer(gl.FRAMEBUFFER, this.fbo(L, step.out.map((n) => tex[n])));
        draw(step, {});
      }
      for (let i = 0; i < (step.in || []).length; ++i) {
        gl.activeTexture(gl.TEXTURE0 + i);
        gl.bindTexture(gl.TEXTURE_2D, null);
      }
      this.sync();
      timed.push({pass: step.copy ? 'copy' : step.pass, count, ms: performance.now() - t0});
      if (await pause()) return false;
      gl.bindVertexArray(this.vao);
      gl.viewport(0, 0, L.w, L.h);
    }
    this.level = L;
    this.result = tex[plan.result];
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    return timed;
  }

  // Draws the display (effect, wipe, depth view, focal plane) to the canvas,
  // at the size of the scale the last frame was drawn at.
  show(opts) {
    const gl = this.gl;
    const L = this.level;
    if (!L || !this.result) return;
    if (this.canvas.width !== L.w || this.canvas.height !== L.h) {
      this.canvas.width = L.w;
      this.canvas.height = L.h;
    }
    const p = this.display;
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.viewport(0, 0, L.w, L.h);
    gl.useProgram(p.prog);
    const set1f = (n, v) => p.locs[n] !== undefined && gl.uniform1f(p.locs[n], v);
    if (p.locs.uMode !== undefined) gl.uniform1i(p.locs.uMode, opts.depth ? 1 : 0);
    set1f('uWipe', opts.wipe * L.w);
    set1f('uRangeMin', opts.rangeMin || 1);
    set1f('uRangeMax', opts.rangeMax || 1);
    set1f('uFocus', opts.focus || 0);
    set1f('uFocusTol', opts.focusTol || 0);
    [this.result.tex, L.inputs.image, L.inputs.range, L.inputs.sky].forEach((t, i) => {
      gl.activeTexture(gl.TEXTURE0 + i);
      gl.bindTexture(gl.TEXTURE_2D, t);
    });
    gl.bindVertexArray(this.vao);
    gl.drawArrays(gl.TRIANGLES, 0, 3);
  }

  // Waits for the GPU (a one-pixel read is the portable fence).
  sync() {
    const gl = this.gl;
    const px = new Uint8Array(4);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
  }

  // The last frame at its scale, rows top-down: linear RGBA floats.
  readResult() {
    const gl = this.gl;
    const L = this.level;
    gl.bindFramebuffer(gl.FRAMEBUFFER, this.fbo(L, [this.result]));
    gl.readBuffer(gl.COLOR_ATTACHMENT0);
    const out = new Float32Array(L.w * L.h * 4);
    gl.readPixels(0, 0, L.w, L.h, gl.RGBA, gl.FLOAT, out);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    return out;
  }

  // The canvas as shown (the display), rows top-down, sRGB bytes RGBA.
  readDisplay() {
    const gl = this.gl;
    const L = this.level;
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    const out = new Uint8Array(L.w * L.h * 4);
    gl.readPixels(0, 0, L.w, L.h, gl.RGBA, gl.UNSIGNED_BYTE, out);
    const flipped = new Uint8Array(out.length), row = L.w * 4;
    for (let y = 0; y < L.h; ++y) flipped.set(out.subarray((L.h - 1 - y) * row, (L.h - y) * row), y * row);
    return flipped;
  }
}

// The 8-bit code an sRGB output file stores (src/io/srgb.cpp: the curve of
// max(v, 0), rounded half away from zero, clipped to 255).
export function srgb8(v) {
  if (!(v > 0)) return 0;
  return Math.min(255, Math.max(0, Math.round(srgbEncode(v) * 255)));
}
