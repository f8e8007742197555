// A volume for the page's renderer: fetched once from GET /api/volumes/{id}/texture (the
// browser keeps it: ETag + no-cache), with the block value ranges of empty-space skipping.
//
// Large volumes stream in with progress and their block ranges are computed a few slices at a
// time, yielding to the page in between, so a clinical volume never freezes the view. The
// request names the page's limits (its MAX_3D_TEXTURE_SIZE and a memory budget); the server
// downsamples to fit them and says by how much.

/**
 * Most blocks the empty-space-skipping grid may have: its edge is the smallest of 2, 4, 8, 16
 * cells that keeps it under this (2 for a 256³ volume; 8 for a clinical 512×512×600). Finer
 * blocks skip more of a fine structure's empty surroundings (the bonsai in software: a shaded
 * frame in 70 % of the time of 8-cell blocks with single-block skips), and cost memory (13 bytes
 * a block: its value range, its LUT index range, its byte) and time at each TF change (two
 * passes over the grid: 23–30 ms at 128³ blocks).
 */
export const MAX_BLOCKS = 1 << 21;

/** Blocks per coarse block edge: the grid on which jump distances are worked out. */
export const COARSE = 2;

/** The block edge (cells) for a volume of `dims` voxels (see MAX_BLOCKS). */
export function blockSize(dims) {
  for (const b of [2, 4, 8]) {
    if (dims.reduce((m, n) => m * blockCount(n, b), 1) <= MAX_BLOCKS) return b;
  }
  return 16;
}

let halfTable = null;

/** IEEE half float bits → float (a 65536-entry table, built once). */
function halfToFloat() {
  if (halfTable) return halfTable;
  halfTable = new Float32Array(65536);
  for (let h = 0; h < 65536; h++) {
    const s = h & 0x8000 ? -1 : 1;
    const e = (h >> 10) & 0x1f;
    const m = h & 0x3ff;
    let v;
    if (e === 0) v = m * 2 ** -24;
    else if (e === 31) v = m ? NaN : Infinity;
    else v = (1 + m / 1024) * 2 ** (e - 15);
    halfTable[h] = s * v;
  }
  return halfTable;
}

const nextTick = () => new Promise((r) => setTimeout(r, 0));

/**
 * Fetch a volume's texture. `limits` = {maxBytes, maxSide}; `onProgress(fraction)`; `signal`
 * aborts. Resolves to {id, dims, fullDims, spacing, step, format, map, lutSize, dtype, data}.
 */
export async function fetchVolume(id, limits, { onProgress, signal } = {}) {
  const q = new URLSearchParams({ max_bytes: String(Math.floor(limits.maxBytes)), max_side: String(limits.maxSide) });
  const resp = await fetch(`/api/volumes/${encodeURIComponent(id)}/texture?${q}`, {
    credentials: "same-origin",
    cache: "no-cache", // revalidate: a 304 when the browser's copy is current
    signal,
  });
  if (!resp.ok) {
    let detail = `HTTP ${resp.status}`;
    try {
      const j = await resp.json();
      detail = j.detail || detail;
    } catch (_) {
      /* not JSON */
    }
    throw new Error(detail);
  }
  const h = (k) => resp.headers.get(k) || "";
  const nums = (k) => h(k).split(",").map(Number);
  const dims = nums("X-Volume-Dims");
  const format = h("X-Volume-Format");
  const bytes = dims[0] * dims[1] * dims[2] * (format === "r8" ? 1 : 2);
  const buf = new Uint8Array(bytes);
  let got = 0;
  if (resp.body && resp.body.getReader) {
    const reader = resp.body.getReader();
    for (;;) {
      const { done, value } = await reader.read();
      if (done) break;
      if (got + value.length > bytes) throw new Error("The volume's texture is longer than its header says.");
      buf.set(value, got);
      got += value.length;
      if (onProgress) onProgress(got / bytes);
    }
  } else {
    const all = new Uint8Array(await resp.arrayBuffer());
    buf.set(all.subarray(0, bytes));
    got = all.length;
  }
  if (got !== bytes) throw new Error(`The volume's texture is ${got} bytes, its header says ${bytes}.`);
  const [scale, offset] = nums("X-Volume-Map");
  return {
    id,
    dims,
    fullDims: nums("X-Volume-Full-Dims"),
    spacing: nums("X-Volume-Spacing"),
    step: Number(h("X-Volume-Step")) || 1,
    format,
    map: [scale, offset],
    lutSize: Number(h("X-Volume-Lut-Size")) || 256,
    dtype: h("X-Volume-Dtype"),
    data: format === "r8" ? buf : new Uint16Array(buf.buffer),
  };
}

/** Number of blocks of `b` cells along an axis of n voxels (at least 1). */
export function blockCount(n, b) {
  return Math.max(1, Math.ceil((n - 1) / b));
}

/**
 * Per block of `size` cells a side (its voxels plus one: every trilinear sample in its cells is
 * a mix of them), the min and max normalised value its samples can take:
 * {nb: [nbx, nby, nbz], size, min, max} (Float32Arrays, x fastest). `size` defaults to the
 * volume's (blockSize). Works through the volume a slab at a time, yielding to the page
 * between slabs.
 */
export async function blockRanges(vol, size = blockSize(vol.dims)) {
  const [nx, ny, nz] = vol.dims;
  const nb = [blockCount(nx, size), blockCount(ny, size), blockCount(nz, size)];
  const nBlocks = nb[0] * nb[1] * nb[2];
  const bmin = new Float32Array(nBlocks).fill(Infinity);
  const bmax = new Float32Array(nBlocks).fill(-Infinity);
  const data = vol.data;
  const half = vol.format === "r8" ? null : halfToFloat();
  const rowMin = new Float32Array(nb[0]);
  const rowMax = new Float32Array(nb[0]);
  // The blocks (along one axis) that voxel i belongs to: floor(i / B) and, on a boundary, the one before.
  const owners = (i, n) => {
    const b = Math.floor(i / size);
    const out = [];
    if (b < n) out.push(b);
    if (i % size === 0 && b > 0) out.push(b - 1);
    return out;
  };
  const yOwners = Array.from({ length: ny }, (_, y) => owners(y, nb[1]));
  let lastYield = performance.now();
  for (let z = 0; z < nz; z++) {
    const zOwn = owners(z, nb[2]);
    for (let y = 0; y < ny; y++) {
      rowMin.fill(Infinity);
      rowMax.fill(-Infinity);
      const base = (z * ny + y) * nx;
      for (let bx = 0; bx < nb[0]; bx++) {
        const x0 = bx * size;
        const x1 = Math.min(x0 + size, nx - 1);
        let lo = Infinity;
        let hi = -Infinity;
        for (let x = x0; x <= x1; x++) {
          const v = half ? half[data[base + x]] : data[base + x];
          if (v < lo) lo = v;
          if (v > hi) hi = v;
        }
        rowMin[bx] = lo;
        rowMax[bx] = hi;
      }
      for (const bz of zOwn) {
        for (const by of yOwners[y]) {
          const o = (bz * nb[1] + by) * nb[0];
          for (let bx = 0; bx < nb[0]; bx++) {
            if (rowMin[bx] < bmin[o + bx]) bmin[o + bx] = rowMin[bx];
            if (rowMax[bx] > bmax[o + bx]) bmax[o + bx] = rowMax[bx];
          }
        }
      }
    }
    if (performance.now() - lastYield > 30) {
      await nextTick();
      lastYield = performance.now();
    }
  }
  // To normalised values (r8 holds the original integers: normalised = byte / 255 * scale + offset).
  const [scale, offset] = vol.format === "r8" ? [vol.map[0] / 255, vol.map[1]] : [1, 0];
  for (let i = 0; i < nBlocks; i++) {
    bmin[i] = bmin[i] * scale + offset;
    bmax[i] = bmax[i] * scale + offset;
  }
  return { nb, size, min: bmin, max: bmax };
}

/**
 * Per block, what a ray does there: one byte, x fastest (Uint8Array).
 * - 128 + q: the block is empty (its LUT index range [floor(min·(L-1)), ceil(max·(L-1))] holds
 *   no entry with non-zero alpha; `occ` from gl_tf.occupancy), and so is every block within q
 *   of it (chessboard distance, in blocks): the ray leaves that whole cube in one step.
 * - q < 128: the block is visible, and so is every block within q of it: the ray runs the
 *   samples of that whole cube with no lookup in between (a volume filled with visible fog
 *   costs a lookup per cube, not per block). Runs are worked out only when more than
 *   RUN_SHARE of the blocks are visible (else q = 0: block by block).
 * Both reaches are lower bounds worked out on a coarse grid (COARSE blocks a side, cheap at
 * every TF change): a coarse block at chessboard distance R from the nearest coarse block
 * with a visible block in it gives its empty blocks q = COARSE·(R - 1); one at distance R
 * from the nearest with an empty block gives its visible blocks q = COARSE·(R - 1). A jump
 * too long would skip visible samples; a run too long only samples empty space.
 */
export function visibleBlocks(blocks, occ, out) {
  const L = occ.length - 1;
  const n = blocks.min.length;
  const r = out && out.length === n ? out : new Uint8Array(n);
  const [nx, ny, nz] = blocks.nb;
  const cb = [Math.ceil(nx / COARSE), Math.ceil(ny / COARSE), Math.ceil(nz / COARSE)];
  const coarse = new Uint8Array(cb[0] * cb[1] * cb[2]).fill(255);
  const solid = new Uint8Array(cb[0] * cb[1] * cb[2]).fill(255);
  let visible = 0;
  const { lo, hi } = lutRanges(blocks, L);
  for (let z = 0, i = 0; z < nz; z++) {
    for (let y = 0; y < ny; y++) {
      const crow = (((z / COARSE) | 0) * cb[1] + ((y / COARSE) | 0)) * cb[0];
      for (let x = 0; x < nx; x++, i++) {
        if (occ[hi[i] + 1] > occ[lo[i]]) {
          r[i] = 0;
          coarse[crow + ((x / COARSE) | 0)] = 0;
          visible++;
        } else {
          r[i] = EMPTY;
          solid[crow + ((x / COARSE) | 0)] = 0;
        }
      }
    }
  }
  chessboardDistance(coarse, cb);
  const runs = visible > RUN_SHARE * n;
  if (runs) chessboardDistance(solid, cb);
  for (let z = 0, i = 0; z < nz; z++) {
    for (let y = 0; y < ny; y++) {
      const crow = (((z / COARSE) | 0) * cb[1] + ((y / COARSE) | 0)) * cb[0];
      for (let x = 0; x < nx; x++, i++) {
        const c = crow + ((x / COARSE) | 0);
        if (r[i]) {
          if (coarse[c] > 1) r[i] = EMPTY + Math.min(MAX_REACH, COARSE * (coarse[c] - 1));
        } else if (runs && solid[c] > 1) r[i] = Math.min(MAX_REACH, COARSE * (solid[c] - 1));
      }
    }
  }
  return r;
}

/**
 * Per block, the LUT entries its values can reach, [floor(min·(L-1)), ceil(max·(L-1))]
 * (Uint16Arrays), for a LUT of `L` entries: worked out once and kept with the blocks, so a TF
 * change only looks them up.
 */
function lutRanges(blocks, L) {
  if (blocks.lut && blocks.lut.L === L) return blocks.lut;
  const s = L - 1;
  const n = blocks.min.length;
  const lo = new Uint16Array(n);
  const hi = new Uint16Array(n);
  for (let i = 0; i < n; i++) {
    // A hair wider than the server's range, never narrower: skipping stays conservative.
    const a = Math.floor(blocks.min[i] * s - 1e-4);
    const b = Math.ceil(blocks.max[i] * s + 1e-4);
    lo[i] = a < 0 ? 0 : a > s ? s : a;
    hi[i] = b < 0 ? 0 : b > s ? s : b;
  }
  blocks.lut = { L, lo, hi };
  return blocks.lut;
}

/** Visible runs are worked out when more than this share of the blocks is visible. */
export const RUN_SHARE = 0.25;

/** The byte's high bit: the block is empty. */
export const EMPTY = 128;

/** Largest reach (blocks) the byte records. */
export const MAX_REACH = 127;

/**
 * In place: each cell's chessboard (L∞) distance, in cells, to the nearest zero cell (capped
 * at the cells' start value). Two raster passes, each taking one more than the minimum over
 * the half of the 26-neighbourhood already visited, give it exactly for this metric. The grid
 * is copied into one padded with a border of 255 (no bounds to check per neighbour: twice as
 * fast).
 */
export function chessboardDistance(d, [nx, ny, nz]) {
  const sy = nx + 2;
  const sz = sy * (ny + 2);
  const p = new Uint8Array(sz * (nz + 2)).fill(255);
  const row = (z, y) => (z + 1) * sz + (y + 1) * sy + 1;
  for (let z = 0; z < nz; z++) {
    for (let y = 0; y < ny; y++) p.set(d.subarray((z * ny + y) * nx, (z * ny + y + 1) * nx), row(z, y));
  }
  // The neighbours visited before a cell in a forward pass: the slab before (9), the row
  // before (3) and the cell before; a backward pass visits the mirror ones.
  const before = [];
  for (let dy = -1; dy <= 1; dy++) for (let dx = -1; dx <= 1; dx++) before.push(-sz + dy * sy + dx);
  for (let dx = -1; dx <= 1; dx++) before.push(-sy + dx);
  before.push(-1);
  for (const step of [1, -1]) {
    const offs = before.map((o) => o * step);
    for (let zz = 0; zz < nz; zz++) {
      const z = step > 0 ? zz : nz - 1 - zz;
      for (let yy = 0; yy < ny; yy++) {
        const y = step > 0 ? yy : ny - 1 - yy;
        relaxRow(p, step > 0 ? row(z, y) : row(z, y) + nx - 1, nx, step, offs);
      }
    }
  }
  for (let z = 0; z < nz; z++) {
    for (let y = 0; y < ny; y++) d.set(p.subarray(row(z, y), row(z, y) + nx), (z * ny + y) * nx);
  }
  return d;
}

/** One row of a chessboardDistance pass: `n` cells from `i` by `step`, neighbours at `offs`. */
function relaxRow(p, i, n, step, offs) {
  // The thirteen offsets as locals (a loop over an array of them is slower in V8).
  const [o0, o1, o2, o3, o4, o5, o6, o7, o8, o9, o10, o11, o12] = offs;
  for (let x = 0; x < n; x++, i += step) {
    const own = p[i];
    if (own === 0) continue;
    // Plain comparisons: Math.min over thirteen arguments runs at half the speed.
    let m = own;
    let v = p[i + o0];
    if (v < m) m = v;
    v = p[i + o1];
    if (v < m) m = v;
    v = p[i + o2];
    if (v < m) m = v;
    v = p[i + o3];
    if (v < m) m = v;
    v = p[i + o4];
    if (v < m) m = v;
    v = p[i + o5];
    if (v < m) m = v;
    v = p[i + o6];
    if (v < m) m = v;
    v = p[i + o7];
    if (v < m) m = v;
    v = p[i + o8];
    if (v < m) m = v;
    v = p[i + o9];
    if (v < m) m = v;
    v = p[i + o10];
    if (v < m) m = v;
    v = p[i + o11];
    if (v < m) m = v;
    v = p[i + o12];
    if (v < m) m = v;
    if (m + 1 < own) p[i] = m + 1;
  }
}

/**
 * The volume's central differences (one-sided at the borders, as the server's
 * kernels.central_gradient) along x, y and z for the voxels of row (y, z), in texel units
 * (bytes for r8, normalised values for r16f), into the row arrays gx, gy, gz.
 */
function rowDifferences(vol, half, y, z, gx, gy, gz) {
  const [nx, ny, nz] = vol.dims;
  const d = vol.data;
  const sy = nx;
  const sz = nx * ny;
  const base = (z * ny + y) * nx;
  // The neighbours' rows and the factor (0.5 inside, 1 at a border) along y and z.
  const yLo = y > 0 ? base - sy : base;
  const yHi = y < ny - 1 ? base + sy : base;
  const fy = ny < 2 ? 0 : y > 0 && y < ny - 1 ? 0.5 : 1;
  const zLo = z > 0 ? base - sz : base;
  const zHi = z < nz - 1 ? base + sz : base;
  const fz = nz < 2 ? 0 : z > 0 && z < nz - 1 ? 0.5 : 1;
  if (half) {
    for (let x = 0; x < nx; x++) {
      const xl = x > 0 ? x - 1 : x;
      const xh = x < nx - 1 ? x + 1 : x;
      const fx = nx < 2 ? 0 : x > 0 && x < nx - 1 ? 0.5 : 1;
      gx[x] = fx * (half[d[base + xh]] - half[d[base + xl]]);
      gy[x] = fy * (half[d[yHi + x]] - half[d[yLo + x]]);
      gz[x] = fz * (half[d[zHi + x]] - half[d[zLo + x]]);
    }
  } else {
    for (let x = 0; x < nx; x++) {
      const xl = x > 0 ? x - 1 : x;
      const xh = x < nx - 1 ? x + 1 : x;
      const fx = nx < 2 ? 0 : x > 0 && x < nx - 1 ? 0.5 : 1;
      gx[x] = fx * (d[base + xh] - d[base + xl]);
      gy[x] = fy * (d[yHi + x] - d[yLo + x]);
      gz[x] = fz * (d[zHi + x] - d[zLo + x]);
    }
  }
}

/**
 * How the page stores the volume's gradient in 8 bits: the largest difference (texel units)
 * over the volume sets the step, so that codes 1..255 (128 = 0) span it. Works a slab at a
 * time, yielding to the page. Returns {step, toNormalised} (a code's unit in texel units, and
 * texel units → normalised values), or null when the volume is changed meanwhile (`alive()`).
 */
export async function gradientCoding(vol, alive = () => true) {
  const [nx, ny, nz] = vol.dims;
  const half = vol.format === "r8" ? null : halfToFloat();
  const [gx, gy, gz] = [new Float32Array(nx), new Float32Array(nx), new Float32Array(nx)];
  let top = 0;
  let lastYield = performance.now();
  for (let z = 0; z < nz; z++) {
    for (let y = 0; y < ny; y++) {
      rowDifferences(vol, half, y, z, gx, gy, gz);
      for (let x = 0; x < nx; x++) {
        const m = Math.max(Math.abs(gx[x]), Math.abs(gy[x]), Math.abs(gz[x]));
        if (m > top) top = m;
      }
    }
    if (performance.now() - lastYield > 30) {
      await nextTick();
      if (!alive()) return null;
      lastYield = performance.now();
    }
  }
  return { step: top > 0 ? top / 127 : 1, toNormalised: vol.format === "r8" ? vol.map[0] / 255 : vol.map[0] };
}

/**
 * Gradient codes of slices [z0, z1) as RGBA8 (x fastest; alpha: the byte value of an r8
 * volume, so that one fetch gives a shaded sample all it needs) into `out`:
 * round(difference / step) + 128. Trilinear filtering of it is the server's interpolated
 * gradient to within half a step.
 */
export function gradientSlab(vol, z0, z1, coding, out) {
  const [nx, ny] = vol.dims;
  const half = vol.format === "r8" ? null : halfToFloat();
  const [gx, gy, gz] = [new Float32Array(nx), new Float32Array(nx), new Float32Array(nx)];
  const k = 1 / coding.step;
  const r8 = vol.format === "r8" ? vol.data : null;
  const code = (v) => {
    const c = (v < 0 ? -Math.round(-v * k) : Math.round(v * k)) + 128; // symmetric about 0
    return c < 1 ? 1 : c > 255 ? 255 : c;
  };
  let o = 0;
  for (let z = z0; z < z1; z++) {
    for (let y = 0; y < ny; y++) {
      rowDifferences(vol, half, y, z, gx, gy, gz);
      for (let x = 0; x < nx; x++) {
        out[o++] = code(gx[x]);
        out[o++] = code(gy[x]);
        out[o++] = code(gz[x]);
        out[o++] = r8 ? r8[(z * ny + y) * nx + x] : 255;
      }
    }
  }
  return out;
}
