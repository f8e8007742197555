// The page's WebGL2 volume renderer: the server's ray caster (render/kernels.py) in a fragment
// shader, for the volume view, the pick and the features strip.
//
// One instance owns one WebGL2 context (on its own canvas) and one volume texture. render()
// draws a picture into that canvas (the caller copies it where it is shown); attribution()
// renders each Gaussian's part of every pixel's opacity into float targets and reads them back
// for the pick. Defaults match VolumeRenderer's: sample distance 0.5 voxel, ambient 0.3,
// diffuse 0.7, specular 0.25, shininess 24, early stop at T < 1/255.

import { extentOf, frame } from "./gl_camera.js";
import { VERTEX, attributeSource, renderSource } from "./gl_shaders.js";
import { TABLE_SIZE, occupancy, preintegratedTable, tfKey, tfLut } from "./gl_tf.js";
import { gradientCoding, gradientSlab, visibleBlocks } from "./gl_volume.js";

/** Largest gradient texture (RGBA8, 4 bytes a voxel) the page builds; beyond it shading takes
 * central differences of the volume texture itself (the same picture, slower). */
const MAX_GRADIENT_BYTES = 256 * 1024 * 1024;

export const DEFAULTS = Object.freeze({
  sampleDistance: 0.5,
  shade: [0.3, 0.7, 0.25, 24],
  earlyStop: 1 / 255,
});

/** Why the page cannot render itself here (null when it can): for the note beside the view. */
export function webgl2Problem() {
  try {
    const c = document.createElement("canvas");
    const gl = c.getContext("webgl2");
    if (!gl) return "this browser offers no WebGL2";
    const lose = gl.getExtension("WEBGL_lose_context");
    if (lose) lose.loseContext();
    return null;
  } catch (err) {
    return `WebGL2 failed (${err && err.message ? err.message : err})`;
  }
}

function compile(gl, type, src) {
  const s = gl.createShader(type);
  gl.shaderSource(s, src);
  gl.compileShader(s);
  if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) {
    const log = gl.getShaderInfoLog(s);
    gl.deleteShader(s);
    throw new Error(`shader: ${log}`);
  }
  return s;
}

function program(gl, vs, fs) {
  const p = gl.createProgram();
  gl.attachShader(p, compile(gl, gl.VERTEX_SHADER, vs));
  gl.attachShader(p, compile(gl, gl.FRAGMENT_SHADER, fs));
  gl.linkProgram(p);
  if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(`program: ${gl.getProgramInfoLog(p)}`);
  const uniforms = {};
  const n = gl.getProgramParameter(p, gl.ACTIVE_UNIFORMS);
  for (let i = 0; i < n; i++) {
    const info = gl.getActiveUniform(p, i);
    const name = info.name.replace(/\[0\]$/, "");
    uniforms[name] = gl.getUniformLocation(p, info.name);
  }
  return { p, u: uniforms };
}

/** Trilinear filtering and the edge value outside: the bound 3-D texture as the server samples. */
function linearClampedTexture3D(gl) {
  gl.texParameteri(gl.TEXTURE_3D, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
  gl.texParameteri(gl.TEXTURE_3D, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
  for (const w of [gl.TEXTURE_WRAP_S, gl.TEXTURE_WRAP_T, gl.TEXTURE_WRAP_R]) gl.texParameteri(gl.TEXTURE_3D, w, gl.CLAMP_TO_EDGE);
}

export class GLVolumeRenderer {
  /** A renderer on `canvas` (a fresh one when omitted). Throws when WebGL2 is missing. */
  constructor(canvas = document.createElement("canvas")) {
    this.canvas = canvas;
    const gl = canvas.getContext("webgl2", {
      alpha: false,
      antialias: false,
      depth: false,
      stencil: false,
      premultipliedAlpha: false,
      preserveDrawingBuffer: true,
      powerPreference: "high-performance",
    });
    if (!gl) throw new Error("this browser offers no WebGL2");
    this.gl = gl;
    const dbg = gl.getExtension("WEBGL_debug_renderer_info");
    this.gpu = String(gl.getParameter(dbg ? dbg.UNMASKED_RENDERER_WEBGL : gl.RENDERER));
    /** True on a software rasteriser (SwiftShader, llvmpipe): frames may be slow. */
    this.software = /swiftshader|llvmpipe|software|softpipe/i.test(this.gpu);
    this.max3d = gl.getParameter(gl.MAX_3D_TEXTURE_SIZE);
    this.floatTargets = !!gl.getExtension("EXT_color_buffer_float");
    this.floatLinear = !!gl.getExtension("OES_texture_float_linear");
    this.maxTexture = gl.getParameter(gl.MAX_TEXTURE_SIZE);
    this.render = this.render.bind(this);
    this.progRender = {}; // per kind of picture (renderSource), compiled on first use
    this._program({ shading: true, gradient: false }); // fails here, not at the first frame
    this.progAttr = {}; // per number of targets, compiled on the first pick that needs it
    this.vao = gl.createVertexArray();
    this.volume = null;
    this.lutTex = gl.createTexture();
    this.tableTex = gl.createTexture(); // the pre-integrated table (gl_tf.preintegratedTable)
    this.visTex = gl.createTexture();
    this.volTex = null;
    // Until a volume's gradient texture is built, shading differentiates the volume texture.
    this.gradTex = null;
    this.gradCode = null;
    /** Resolves when the current volume's gradient texture is in use (true) or will not be. */
    this.gradientReady = Promise.resolve(false);
    this.lutState = { key: "", n: 0, occ: null };
    this.vis = null;
  }

  /** The page's limits for a volume texture: {maxBytes, maxSide}. */
  limits() {
    const mem = navigator.deviceMemory || 4; // GiB, coarse; absent outside Chromium
    // A quarter of the device's memory at most, 1 GiB on a GPU. In software a frame costs
    // in proportion to the voxels a ray crosses: 64 MiB (a 512×512×128 16-bit volume, or
    // 400³ 8-bit) keeps a frame of seconds, not tens of seconds, where the CPU draws.
    const cap = this.software ? 64 : 1024;
    return { maxBytes: Math.min(cap, mem * 256) * 1024 * 1024, maxSide: this.max3d };
  }

  /**
   * Upload a volume (from gl_volume.fetchVolume) and its block ranges, a few slices per
   * task so the page stays responsive. Resolves when the texture is complete.
   */
  async setVolume(vol, blocks) {
    const gl = this.gl;
    if (vol.lutSize > this.maxTexture) throw new Error(`its ${vol.lutSize}-entry lookup table is wider than this browser's textures (${this.maxTexture})`);
    if (this.volTex) gl.deleteTexture(this.volTex);
    const tex = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_3D, tex);
    const [nx, ny, nz] = vol.dims;
    const r8 = vol.format === "r8";
    gl.texStorage3D(gl.TEXTURE_3D, 1, r8 ? gl.R8 : gl.R16F, nx, ny, nz);
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
    const slab = Math.max(1, Math.floor((8 * 1024 * 1024) / (nx * ny * (r8 ? 1 : 2))));
    for (let z = 0; z < nz; z += slab) {
      const d = Math.min(slab, nz - z);
      const part = vol.data.subarray(z * nx * ny, (z + d) * nx * ny);
      gl.bindTexture(gl.TEXTURE_3D, tex);
      gl.texSubImage3D(gl.TEXTURE_3D, 0, 0, 0, z, nx, ny, d, gl.RED, r8 ? gl.UNSIGNED_BYTE : gl.HALF_FLOAT, part);
      if (z + d < nz) await new Promise((r) => setTimeout(r, 0));
    }
    linearClampedTexture3D(gl);
    this.volTex = tex;
    // The block grid: one byte per block, rewritten for each TF (storage is immutable: a
    // new texture per volume).
    gl.deleteTexture(this.visTex);
    this.visTex = gl.createTexture();
    this.vis = null;
    gl.bindTexture(gl.TEXTURE_3D, this.visTex);
    gl.texStorage3D(gl.TEXTURE_3D, 1, gl.R8, blocks.nb[0], blocks.nb[1], blocks.nb[2]);
    for (const k of [gl.TEXTURE_MIN_FILTER, gl.TEXTURE_MAG_FILTER]) gl.texParameteri(gl.TEXTURE_3D, k, gl.NEAREST);
    this.volume = vol;
    this.blocks = blocks;
    this.extent = extentOf(vol.dims, vol.spacing);
    const m = Math.min(...vol.spacing);
    this.invSpacing = vol.spacing.map((s) => m / s);
    this.lutState = { key: "", n: 0, occ: null };
    if (this.gradTex) gl.deleteTexture(this.gradTex);
    this.gradTex = null;
    this.gradientReady = this._buildGradient(vol);
  }

  /** The render program for `kind` ({shading, gradient}), compiled once. */
  _program(kind) {
    const blockSize = this.blocks ? this.blocks.size : 8;
    const full = { ...kind, shininess: DEFAULTS.shade[3], blockSize };
    const key = `${kind.shading ? "s" : "u"}${kind.gradient ? "g" : "d"}${kind.packed ? "p" : ""}${blockSize}`;
    if (!this.progRender[key]) this.progRender[key] = program(this.gl, VERTEX, renderSource(full));
    return this.progRender[key];
  }

  _renderProgram(shading) {
    const gradient = shading && !!this.gradTex;
    return this._program({ shading, gradient, packed: gradient && this.volume.format === "r8" });
  }

  /**
   * The volume's gradient as 8-bit codes in an RGBA8 texture, built a few slices per task
   * after the volume is shown: a shaded sample then takes its normal from one texture fetch
   * instead of six (the server's precomputed gradient, trilinearly filtered, as its kernels
   * do; the codes' step is 1/127 of the volume's largest difference). In software an 8-bit
   * fetch costs a fraction of a half-float one. Resolves to whether frames now use it.
   */
  async _buildGradient(vol) {
    const gl = this.gl;
    const [nx, ny, nz] = vol.dims;
    if (nx * ny * nz * 4 > MAX_GRADIENT_BYTES) return false;
    const coding = await gradientCoding(vol, () => this.volume === vol);
    if (!coding || this.volume !== vol) return false;
    const tex = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_3D, tex);
    gl.texStorage3D(gl.TEXTURE_3D, 1, gl.RGBA8, nx, ny, nz);
    const slab = Math.max(1, Math.floor((1024 * 1024) / (nx * ny)));
    const buf = new Uint8Array(Math.min(slab, nz) * nx * ny * 4);
    for (let z = 0; z < nz; z += slab) {
      await new Promise((r) => setTimeout(r, 0));
      if (this.volume !== vol) {
        gl.deleteTexture(tex);
        return false;
      }
      const d = Math.min(slab, nz - z);
      const part = buf.subarray(0, d * nx * ny * 4);
      gradientSlab(vol, z, z + d, coding, part);
      gl.bindTexture(gl.TEXTURE_3D, tex);
      gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
      gl.texSubImage3D(gl.TEXTURE_3D, 0, 0, 0, z, nx, ny, d, gl.RGBA, gl.UNSIGNED_BYTE, part);
    }
    linearClampedTexture3D(gl);
    if (this.volume !== vol) {
      gl.deleteTexture(tex);
      return false;
    }
    this.gradTex = tex;
    // A texel t (code / 255) is the difference (t - 128/255) · 255 · step, in normalised units.
    this.gradCode = [128 / 255, 255 * coding.step * coding.toNormalised];
    return true;
  }

  /** Make the LUT and block-visibility textures current for `tf` (cheap when unchanged). */
  _useTF(tf, sampleDistance) {
    const gl = this.gl;
    const n = this.volume.lutSize;
    const key = `${tfKey(tf)}|${n}|${sampleDistance}`;
    if (key === this.lutState.key) return this.lutState;
    const lut = tfLut(tf, n, sampleDistance);
    gl.bindTexture(gl.TEXTURE_2D, this.lutTex);
    // Linear filtering interpolates between entries as the server does; float32 where the
    // browser filters it, else half floats (always filterable).
    if (this.floatLinear) gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, n, 1, 0, gl.RGBA, gl.FLOAT, lut);
    else gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA16F, n, 1, 0, gl.RGBA, gl.FLOAT, lut);
    for (const k of [gl.TEXTURE_MIN_FILTER, gl.TEXTURE_MAG_FILTER]) gl.texParameteri(gl.TEXTURE_2D, k, gl.LINEAR);
    for (const k of [gl.TEXTURE_WRAP_S, gl.TEXTURE_WRAP_T]) gl.texParameteri(gl.TEXTURE_2D, k, gl.CLAMP_TO_EDGE);
    // The pre-integrated table, filtered bilinearly as the server's kernels interpolate it.
    const table = preintegratedTable(tf, sampleDistance);
    gl.bindTexture(gl.TEXTURE_2D, this.tableTex);
    const tfmt = this.floatLinear ? gl.RGBA32F : gl.RGBA16F;
    gl.texImage2D(gl.TEXTURE_2D, 0, tfmt, TABLE_SIZE, TABLE_SIZE, 0, gl.RGBA, gl.FLOAT, table);
    for (const k of [gl.TEXTURE_MIN_FILTER, gl.TEXTURE_MAG_FILTER]) gl.texParameteri(gl.TEXTURE_2D, k, gl.LINEAR);
    for (const k of [gl.TEXTURE_WRAP_S, gl.TEXTURE_WRAP_T]) gl.texParameteri(gl.TEXTURE_2D, k, gl.CLAMP_TO_EDGE);
    const occ = occupancy(lut, true);
    this.vis = visibleBlocks(this.blocks, occ, this.vis);
    const nb = this.blocks.nb;
    gl.bindTexture(gl.TEXTURE_3D, this.visTex);
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
    gl.texSubImage3D(gl.TEXTURE_3D, 0, 0, 0, 0, nb[0], nb[1], nb[2], gl.RED, gl.UNSIGNED_BYTE, this.vis);
    this.lutState = { key, n, occ, lut };
    return this.lutState;
  }

  _common(prog, opts) {
    const gl = this.gl;
    const u = prog.u;
    const vol = this.volume;
    const f = frame(opts.camera || {}, this.extent, opts.width, opts.height);
    gl.useProgram(prog.p);
    gl.activeTexture(gl.TEXTURE0);
    gl.bindTexture(gl.TEXTURE_3D, this.volTex);
    gl.uniform1i(u.u_vol, 0);
    gl.activeTexture(gl.TEXTURE1);
    gl.bindTexture(gl.TEXTURE_3D, this.visTex);
    gl.uniform1i(u.u_vis, 1);
    gl.activeTexture(gl.TEXTURE2);
    gl.bindTexture(gl.TEXTURE_2D, this.lutTex);
    gl.uniform1i(u.u_lut, 2);
    gl.activeTexture(gl.TEXTURE5);
    gl.bindTexture(gl.TEXTURE_2D, this.tableTex);
    if (u.u_table) gl.uniform1i(u.u_table, 5);
    if (u.u_grad && this.gradTex) {
      gl.activeTexture(gl.TEXTURE4);
      gl.bindTexture(gl.TEXTURE_3D, this.gradTex);
      gl.uniform1i(u.u_grad, 4);
      gl.uniform2f(u.u_gcode, this.gradCode[0], this.gradCode[1]);
    }
    gl.uniform3f(u.u_dims, vol.dims[0], vol.dims[1], vol.dims[2]);
    gl.uniform3f(u.u_invDims, 1 / vol.dims[0], 1 / vol.dims[1], 1 / vol.dims[2]);
    gl.uniform3i(u.u_nb, this.blocks.nb[0], this.blocks.nb[1], this.blocks.nb[2]);
    gl.uniform3f(u.u_is, this.invSpacing[0], this.invSpacing[1], this.invSpacing[2]);
    gl.uniform2f(u.u_map, vol.map[0], vol.map[1]);
    gl.uniform1i(u.u_nl, vol.lutSize);
    gl.uniform1f(u.u_dt, opts.sampleDistance);
    gl.uniform1f(u.u_tstop, DEFAULTS.earlyStop);
    gl.uniform3fv(u.u_eye, f.eye);
    gl.uniform3fv(u.u_fwd, f.fwd);
    gl.uniform3fv(u.u_right, f.right);
    gl.uniform3fv(u.u_up, f.up);
    gl.uniform4f(u.u_view, f.halfWidth, f.halfHeight, f.pan[0] || 0, f.pan[1] || 0);
    gl.uniform2f(u.u_size, opts.width, opts.height);
    gl.uniform1i(u.u_persp, f.perspective ? 1 : 0);
    gl.bindVertexArray(this.vao);
  }

  /**
   * Draw `tf` from `camera` at width × height into this renderer's canvas. Options: shading
   * (default true), background [r, g, b] in 0..1, sampleDistance. Returns the milliseconds
   * the GPU took (the call waits for the picture).
   */
  render({ tf, camera, width, height, shading = true, background = [0, 0, 0], sampleDistance = DEFAULTS.sampleDistance, sync = true, rows = null }) {
    const gl = this.gl;
    const t0 = performance.now();
    if (this.canvas.width !== width) this.canvas.width = width;
    if (this.canvas.height !== height) this.canvas.height = height;
    this._useTF(tf, sampleDistance);
    const prog = this._renderProgram(shading);
    this._common(prog, { camera, width, height, sampleDistance });
    const u = prog.u;
    if (u.u_shade) gl.uniform4fv(u.u_shade, DEFAULTS.shade);
    gl.uniform3f(u.u_bg, background[0], background[1], background[2]);
    gl.uniform1i(u.u_alphaOut, 0);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.viewport(0, 0, width, height);
    // `rows` [y0, y1) (from the bottom) draws one band: the rest of the canvas is kept.
    if (rows) {
      gl.enable(gl.SCISSOR_TEST);
      gl.scissor(0, rows[0], width, rows[1] - rows[0]);
    }
    gl.drawArrays(gl.TRIANGLES, 0, 3);
    if (rows) gl.disable(gl.SCISSOR_TEST);
    if (sync) {
      const px = new Uint8Array(4);
      gl.readPixels(0, rows ? rows[0] : 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px); // waits for the frame
    }
    return performance.now() - t0;
  }

  /**
   * Premultiplied RGBA bytes (rows top to bottom) of `tf` alone, not composited over a
   * background: for pictures the page composites itself (the features strip's ghosts).
   */
  renderRGBA({ tf, camera, width, height, shading = true, sampleDistance = DEFAULTS.sampleDistance }) {
    const gl = this.gl;
    this._useTF(tf, sampleDistance);
    const fb = gl.createFramebuffer();
    gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
    gl.activeTexture(gl.TEXTURE3);
    const t = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, t);
    gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGBA8, width, height);
    gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, t, 0);
    gl.drawBuffers([gl.COLOR_ATTACHMENT0]);
    const prog = this._renderProgram(shading);
    this._common(prog, { camera, width, height, sampleDistance });
    if (prog.u.u_shade) gl.uniform4fv(prog.u.u_shade, DEFAULTS.shade);
    gl.uniform3f(prog.u.u_bg, 0, 0, 0);
    gl.uniform1i(prog.u.u_alphaOut, 1);
    gl.viewport(0, 0, width, height);
    gl.drawArrays(gl.TRIANGLES, 0, 3);
    const px = new Uint8Array(width * height * 4);
    gl.readPixels(0, 0, width, height, gl.RGBA, gl.UNSIGNED_BYTE, px);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.deleteFramebuffer(fb);
    gl.deleteTexture(t);
    const out = new Uint8Array(width * height * 4);
    for (let y = 0; y < height; y++) out.set(px.subarray((height - 1 - y) * width * 4, (height - y) * width * 4), y * width * 4);
    return out;
  }

  /** The canvas's picture as RGB bytes, rows top to bottom (for tests and exports). */
  readRGB() {
    const gl = this.gl;
    const w = this.canvas.width;
    const h = this.canvas.height;
    const px = new Uint8Array(w * h * 4);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, px);
    const out = new Uint8Array(w * h * 3);
    for (let y = 0; y < h; y++) {
      const src = (h - 1 - y) * w * 4;
      for (let x = 0; x < w; x++) {
        out[(y * w + x) * 3] = px[src + x * 4];
        out[(y * w + x) * 3 + 1] = px[src + x * 4 + 1];
        out[(y * w + x) * 3 + 2] = px[src + x * 4 + 2];
      }
    }
    return out;
  }

  /**
   * Each Gaussian's part of every pixel's opacity: Float32Array (N × height × width), rows
   * top to bottom, as the server's SampleCache.attribution. Null without float targets.
   */
  attribution(opts) {
    const job = this._attrBegin(opts);
    if (!job) return null;
    this._attrBand(job, 0, opts.height);
    return this._attrEnd(job);
  }

  /**
   * attribution() drawn in `bands` horizontal bands, yielding to the page between them (other
   * drawing may happen meanwhile). `stale()` → true abandons it (resolves null).
   */
  async attributionBanded(opts, bands, stale) {
    const job = this._attrBegin(opts);
    if (!job) return null;
    const step = Math.ceil(opts.height / bands);
    for (let y0 = 0; y0 < opts.height; y0 += step) {
      this._attrBand(job, y0, Math.min(opts.height, y0 + step));
      await new Promise((r) => setTimeout(r, 0));
      if (stale()) {
        this._attrEnd(job);
        return null;
      }
    }
    return this._attrEnd(job);
  }

  _attrBegin({ tf, camera, width, height, sampleDistance = DEFAULTS.sampleDistance }) {
    const gl = this.gl;
    if (!this.floatTargets) return null;
    const ng = Math.min(16, tf.gaussians.length);
    const targets = Math.ceil(ng / 4);
    const akey = `${targets}:${this.blocks.size}`;
    if (!this.progAttr[akey]) this.progAttr[akey] = program(gl, VERTEX, attributeSource(targets, this.blocks.size));
    const gMean = new Float32Array(16);
    const gWidth = new Float32Array(16).fill(1);
    const gHeight = new Float32Array(16);
    tf.gaussians.slice(0, 16).forEach((x, i) => {
      gMean[i] = x.mean;
      gWidth[i] = x.width;
      gHeight[i] = x.height;
    });
    const fb = gl.createFramebuffer();
    gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
    gl.activeTexture(gl.TEXTURE3);
    const texs = [];
    for (let i = 0; i < targets; i++) {
      const t = gl.createTexture();
      gl.bindTexture(gl.TEXTURE_2D, t);
      gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGBA32F, width, height);
      gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0 + i, gl.TEXTURE_2D, t, 0);
      texs.push(t);
    }
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    const out = new Float32Array(ng * width * height);
    return { tf, camera, width, height, sampleDistance, ng, targets, program: akey, gMean, gWidth, gHeight, fb, texs, out };
  }

  /** Rows [y0, y1) (from the bottom) of an attribution job: drawn, read back into job.out. */
  _attrBand(job, y0, y1) {
    const gl = this.gl;
    const { width, height, ng, targets } = job;
    this._useTF(job.tf, job.sampleDistance);
    const prog = this.progAttr[job.program];
    gl.bindFramebuffer(gl.FRAMEBUFFER, job.fb);
    gl.drawBuffers(job.texs.map((_, i) => gl.COLOR_ATTACHMENT0 + i));
    // _common binds the LUT to texture unit 2 (after the targets exist: making a target binds
    // it on the active unit).
    this._common(prog, { camera: job.camera, width, height, sampleDistance: job.sampleDistance });
    gl.uniform4fv(prog.u.u_mean, job.gMean);
    gl.uniform4fv(prog.u.u_width, job.gWidth);
    gl.uniform4fv(prog.u.u_height, job.gHeight);
    gl.viewport(0, 0, width, height);
    gl.enable(gl.SCISSOR_TEST);
    gl.scissor(0, y0, width, y1 - y0);
    gl.drawArrays(gl.TRIANGLES, 0, 3);
    gl.disable(gl.SCISSOR_TEST);
    const rows = y1 - y0;
    const px = new Float32Array(width * rows * 4);
    for (let t = 0; t < targets; t++) {
      gl.readBuffer(gl.COLOR_ATTACHMENT0 + t);
      gl.readPixels(0, y0, width, rows, gl.RGBA, gl.FLOAT, px);
      for (let c = 0; c < 4 && t * 4 + c < ng; c++) {
        const plane = job.out.subarray((t * 4 + c) * width * height, (t * 4 + c + 1) * width * height);
        for (let r = 0; r < rows; r++) {
          const src = (rows - 1 - r) * width * 4; // GL row y1-1-r is picture row height-y1+r
          const dst = (height - y1 + r) * width;
          for (let x = 0; x < width; x++) plane[dst + x] = px[src + x * 4 + c];
        }
      }
    }
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
  }

  _attrEnd(job) {
    const gl = this.gl;
    gl.deleteFramebuffer(job.fb);
    job.texs.forEach((t) => gl.deleteTexture(t));
    return job.out;
  }

}

/** A feature counts as visible at a pixel with at least this share (session/views.py). */
export const VISIBLE_SHARE = 0.02;
/** ... and as under the cursor with at least this part of the pixel's opacity (PICK_SHARE). */
export const PICK_SHARE = 0.15;

/**
 * The share a feature needs at a pixel to compete for a pick there: PICK_SHARE of the pixel's
 * opacity, or the largest share where no feature holds that much. `visible`: [[i, share, area]].
 */
export function pickBar(visible) {
  const total = visible.reduce((s, v) => s + v[1], 0);
  return Math.min(PICK_SHARE * total, Math.max(...visible.map((v) => v[1])));
}

/**
 * The paper's rule over an attribution (N × H × W): of the features under (x, y) (visible there
 * and holding PICK_SHARE of the pixel's opacity), the one with the smallest projected area;
 * with `whole`, all of them (a structure several Gaussians draw). {index, visible: [[i, share,
 * area]], selected, mask} as the server's pick_smallest and pick_whole; mask is a Uint8Array
 * (H × W) of the selected features' pixels.
 */
export function pickSmallest(attr, n, width, height, x, y, whole = false) {
  const size = width * height;
  const visible = [];
  for (let i = 0; i < n; i++) {
    const plane = attr.subarray(i * size, (i + 1) * size);
    const here = plane[y * width + x];
    if (here < VISIBLE_SHARE) continue;
    let area = 0;
    for (let p = 0; p < size; p++) if (plane[p] >= VISIBLE_SHARE) area++;
    visible.push([i, here, area]);
  }
  visible.sort((a, b) => a[2] - b[2] || b[1] - a[1] || a[0] - b[0]);
  if (!visible.length) return { index: null, visible: [], selected: [], mask: null };
  const bar = pickBar(visible);
  const making = visible.filter((v) => v[1] >= bar).map((v) => v[0]);
  const selected = whole ? [...making].sort((a, b) => a - b) : [making[0]];
  return { index: making[0], visible, selected, mask: featureMask(attr, selected, width, height) };
}

/** Pixels where any of `indices` is visible: Uint8Array (H × W) of 0/1. */
export function featureMask(attr, indices, width, height) {
  const size = width * height;
  const mask = new Uint8Array(size);
  for (const i of indices) {
    const plane = attr.subarray(i * size, (i + 1) * size);
    if (plane.length < size) continue;
    for (let p = 0; p < size; p++) if (plane[p] >= VISIBLE_SHARE) mask[p] = 1;
  }
  return mask;
}
