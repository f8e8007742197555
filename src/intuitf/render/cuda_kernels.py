"""CUDA kernels of the GPU ray caster (``numba.cuda``). Internal: see :mod:`.cuda_backend`.

They mirror :mod:`intuitf.render.kernels` line by line: the same rays (``cam`` layout, pixel
centres), the same box (voxel centres), the same sample positions ``t0 + k * dt``, the same
trilinear value (from the shading voxels' value codes when shaded) and LUT classification, the
same Blinn–Phong terms from the trilinear int16 gradient, the same front-to-back compositing,
early ray termination below ``t_stop`` and empty-space skipping (which changes no pixel). Two
things differ, both far below 1/255: arithmetic is float32 (the CPU kernels mix in float64;
consumer GPUs run float64 at 1/64 of the float32 rate, so every constant here is a float32 and
nothing promotes) except in the sample cache's build (``count_samples``, ``fill_samples``),
once per camera, which takes a float64 camera, step and inverse spacing, so its positions and
trilinear values follow the CPU's float64 and each value is rounded to the same LUT entry (in
float32 a few values per thousand landed on the neighbouring entry: on an H200, single pixels
up to 14 levels apart where a narrow Gaussian makes the LUT steep); and where the CPU writes
``RGBA`` and converts to 8 bits in a second pass, the GPU kernels can write the 8-bit picture
directly (a population's float images would cost 16 bytes per pixel over PCIe).

Threads and memory layout
-------------------------
One thread per (ray, candidate): a 1D grid of ``K * ceil(slots / 128)`` blocks of 128
threads, block ``b`` rendering candidate ``b % K`` on slots ``128 * (b // K)`` onwards. The K
candidates of the same rays therefore run side by side and read the same cache lines of the
volume or the sample cache from L2, so a population reads them from memory about once. Rays are numbered in *slots*: slot ``s`` is lane ``s % 32`` of tile ``s // 32``,
and a tile is an 8×4 patch of pixels (tiles row-major over the picture). So each warp holds
one tile: neighbouring rays that read neighbouring voxels (cache lines shared in L1/L2) and
have similar lengths (little divergence at early termination).

The sample cache is stored per tile, interleaved by lane: sample ``k`` of lane ``l`` of tile
``t`` sits at ``tile_base[t] + 32 * k + l``, each tile padded to its longest ray rounded up to
a 32-sample segment. When a warp's lanes read their k-th sample they read 32 consecutive
bytes: one memory transaction, where the CPU cache's CSR layout (each ray contiguous) would
cost one 32-byte sector per lane. The per-segment (min, max) used to skip empty runs is laid
out the same way, one entry per 32 samples of a lane.
"""

from __future__ import annotations

import math

import numpy as np

from intuitf.render.cuda_compat import prepare_numba_cuda
from intuitf.render.kernels import (
    FLAT_GRADIENT,
    GRAD_SCALE,
    SEG_SHIFT,
    VALUE_CODE_OFFSET,
    VALUE_CODE_SCALE,
)

prepare_numba_cuda()  # before numba.cuda is first imported (NumPy 2.5 with numba-cuda)
from numba import cuda as cuda  # noqa: E402  (re-exported: cuda_backend.cuda)

f32 = np.float32

ZERO = f32(0.0)
ONE = f32(1.0)
HALF = f32(0.5)
TWO = f32(2.0)
BIG = f32(1e30)
TINY = f32(1e-12)
SKIP_EPS = f32(1e-4)
FLAT = f32(FLAT_GRADIENT * GRAD_SCALE)
U8 = f32(255.0)
INV255 = f32(1.0 / 255.0)
#: A shading voxel's value code to its value (``kernels.value_codes``): float32 for the
#: marcher, float64 (Python floats) for the sample cache's build.
VALUE_SCALE = f32(VALUE_CODE_SCALE)
VALUE_OFFSET = f32(VALUE_CODE_OFFSET)
VALUE_SCALE64 = float(VALUE_CODE_SCALE)
VALUE_OFFSET64 = float(VALUE_CODE_OFFSET)

#: Rays per tile (one warp) and the tile's shape in pixels.
WARP = 32
TILE_W = 8
TILE_H = 4
#: Samples per empty-space-skipping segment of one ray (as on the CPU).
SEG = 1 << SEG_SHIFT
#: Threads per block: four tiles.
BLOCK = 128


# ---------------------------------------------------------------------------------------------
# Geometry (device functions)
# ---------------------------------------------------------------------------------------------
@cuda.jit(device=True)
def _pixel(slot, tiles_x):
    """(row, column) of the ray in ``slot``."""
    tile = slot // WARP
    lane = slot - tile * WARP
    ty = tile // tiles_x
    tx = tile - ty * tiles_x
    return ty * TILE_H + lane // TILE_W, tx * TILE_W + (lane % TILE_W)


@cuda.jit(device=True)
def _candidate_slot(n_candidates):
    """(candidate, slot) of this thread: the candidates of a block of slots run side by side."""
    bid = cuda.blockIdx.x
    block = bid // n_candidates
    return bid - block * n_candidates, block * cuda.blockDim.x + cuda.threadIdx.x


@cuda.jit(device=True)
def _ray(cam, i, j):
    """World origin and unit direction of the ray through pixel (row i, column j)."""
    x = ((f32(j) + HALF) / cam[17] * TWO - ONE - TWO * cam[15]) * cam[12]
    y = (ONE - (f32(i) + HALF) / cam[18] * TWO - TWO * cam[16]) * cam[13]
    if cam[14] > HALF:
        dx = cam[3] + x * cam[6] + y * cam[9]
        dy = cam[4] + x * cam[7] + y * cam[10]
        dz = cam[5] + x * cam[8] + y * cam[11]
        n = math.sqrt(dx * dx + dy * dy + dz * dz)
        return cam[0], cam[1], cam[2], dx / n, dy / n, dz / n
    ox = cam[0] + x * cam[6] + y * cam[9]
    oy = cam[1] + x * cam[7] + y * cam[10]
    oz = cam[2] + x * cam[8] + y * cam[11]
    return ox, oy, oz, cam[3], cam[4], cam[5]


@cuda.jit(device=True)
def _slab(o, d, hi, t0, t1):
    if abs(d) < TINY:
        if o < ZERO or o > hi:
            return ONE, ZERO
        return t0, t1
    ta = (ZERO - o) / d
    tb = (hi - o) / d
    if ta > tb:
        ta, tb = tb, ta
    return max(t0, ta), min(t1, tb)


@cuda.jit(device=True)
def _clip(oxi, oyi, ozi, dxi, dyi, dzi, nx, ny, nz):
    """Entry and exit t of an index-space ray with the box [0, n-1]^3 (t1 < t0: missed)."""
    t0, t1 = _slab(oxi, dxi, f32(nx - 1), ZERO, BIG)
    t0, t1 = _slab(oyi, dyi, f32(ny - 1), t0, t1)
    t0, t1 = _slab(ozi, dzi, f32(nz - 1), t0, t1)
    return t0, t1


@cuda.jit(device=True)
def _index_ray(cam, isp, i, j):
    """Origin and direction of pixel (i, j)'s ray in voxel-index space, and its world direction."""
    ox, oy, oz, dx, dy, dz = _ray(cam, i, j)
    return ox * isp[0], oy * isp[1], oz * isp[2], dx * isp[0], dy * isp[1], dz * isp[2], dx, dy, dz


@cuda.jit(device=True)
def _cell(p, n):
    hi = f32(n - 1)
    if p < ZERO:
        p = ZERO
    elif p > hi:
        p = hi
    i = int(p)
    if i > n - 2:
        i = n - 2
    return i, p - f32(i)


@cuda.jit(device=True)
def _trilinear_at(data, i, j, k, fx, fy, fz):
    gx = ONE - fx
    c00 = data[k, j, i] * gx + data[k, j, i + 1] * fx
    c01 = data[k, j + 1, i] * gx + data[k, j + 1, i + 1] * fx
    c10 = data[k + 1, j, i] * gx + data[k + 1, j, i + 1] * fx
    c11 = data[k + 1, j + 1, i] * gx + data[k + 1, j + 1, i + 1] * fx
    c0 = c00 * (ONE - fy) + c01 * fy
    c1 = c10 * (ONE - fy) + c11 * fy
    return c0 * (ONE - fz) + c1 * fz


@cuda.jit(device=True)
def _code_at(lit, i, j, k, fx, fy, fz, vscale, voff):
    """The value, trilinear in cell (i, j, k) of the shading voxels' value codes: the value a
    shaded CPU sample reads (``kernels._lit_at``, same corner weights in the same order), so
    a 16-bit or float volume's samples land on the same LUT entries as on the CPU."""
    ex = ONE - fx
    ey = ONE - fy
    ez = ONE - fz
    a = ZERO * fx
    for dk in range(2):
        wk = fz if dk else ez
        for dj in range(2):
            wjk = wk * (fy if dj else ey)
            for di in range(2):
                a += wjk * (fx if di else ex) * f32(lit[k + dk, j + dj, i + di, 3])
    return a * vscale + voff


@cuda.jit(device=True)
def _sample(data, lit, shading, px, py, pz, nx, ny, nz, vscale, voff):
    """The cell of index-space point p, its weights and the value there: from the shading
    voxels' codes when shading (as ``kernels._sample``), else from ``data``."""
    i, fx = _cell(px, nx)
    j, fy = _cell(py, ny)
    k, fz = _cell(pz, nz)
    if shading:
        v = _code_at(lit, i, j, k, fx, fy, fz, vscale, voff)
    else:
        v = _trilinear_at(data, i, j, k, fx, fy, fz)
    return i, j, k, fx, fy, fz, v


@cuda.jit(device=True)
def _gradient_at(lit, i, j, k, fx, fy, fz):
    """The index-space gradient, trilinear in cell (i, j, k) of the shading voxels."""
    ex = ONE - fx
    ey = ONE - fy
    ez = ONE - fz
    a0 = ZERO * fx
    a1 = ZERO * fx
    a2 = ZERO * fx
    for dk in range(2):
        wk = fz if dk else ez
        for dj in range(2):
            wjk = wk * (fy if dj else ey)
            for di in range(2):
                w = wjk * (fx if di else ex)
                a0 += w * f32(lit[k + dk, j + dj, i + di, 0])
                a1 += w * f32(lit[k + dk, j + dj, i + di, 1])
                a2 += w * f32(lit[k + dk, j + dj, i + di, 2])
    return a0, a1, a2


@cuda.jit(device=True)
def _shade_terms(gx, gy, gz, lx, ly, lz, hx, hy, hz, shin):
    """(|n.l|, |n.h|**shininess) for the world gradient (gx, gy, gz) (up to a scale)."""
    m = math.sqrt(gx * gx + gy * gy + gz * gz)
    if m < FLAT:
        return ONE, ZERO
    ndl = abs(gx * lx + gy * ly + gz * lz) / m
    ndh = abs(gx * hx + gy * hy + gz * hz) / m
    return ndl, ndh**shin


@cuda.jit(device=True)
def _half_vector(lx, ly, lz, dx, dy, dz):
    hx = lx - dx
    hy = ly - dy
    hz = lz - dz
    n = math.sqrt(hx * hx + hy * hy + hz * hz)
    if n < TINY:
        return lx, ly, lz
    return hx / n, hy / n, hz / n


@cuda.jit(device=True)
def _store(out_rgba, out_rgb, to8, bg, c, p, r, g, b, tr):
    """Write one pixel: premultiplied RGBA, or 8-bit RGB over the background."""
    if to8:
        out_rgb[c, p, 0] = int(min(U8, max(ZERO, (r + tr * bg[0]) * U8 + HALF)))
        out_rgb[c, p, 1] = int(min(U8, max(ZERO, (g + tr * bg[1]) * U8 + HALF)))
        out_rgb[c, p, 2] = int(min(U8, max(ZERO, (b + tr * bg[2]) * U8 + HALF)))
    else:
        out_rgba[c, p, 0] = r
        out_rgba[c, p, 1] = g
        out_rgba[c, p, 2] = b
        out_rgba[c, p, 3] = ONE - tr


# ---------------------------------------------------------------------------------------------
# Classification (device functions, as kernels._point, _segment, _classify, pair_entry, _entry)
# ---------------------------------------------------------------------------------------------
@cuda.jit(device=True)
def _point(luts, c, x):
    """Straight (alpha, r, g, b) at fractional LUT index ``x`` of candidate c's LUT."""
    nl = luts.shape[1]
    q = int(x)
    if q > nl - 2:
        q = nl - 2
    elif q < 0:
        q = 0
    f = x - f32(q)
    a = luts[c, q, 3] * (ONE - f) + luts[c, q + 1, 3] * f
    if a <= ZERO:
        return ZERO, ZERO, ZERO, ZERO
    return (
        a,
        luts[c, q, 0] * (ONE - f) + luts[c, q + 1, 0] * f,
        luts[c, q, 1] * (ONE - f) + luts[c, q + 1, 1] * f,
        luts[c, q, 2] * (ONE - f) + luts[c, q + 1, 2] * f,
    )


@cuda.jit(device=True)
def _segment(tables, c, xf, xb):
    """Straight (alpha, r, g, b), bilinear in candidate c's premultiplied table."""
    top = tables.shape[1] - 2
    i = min(max(int(xf), 0), top)
    j = min(max(int(xb), 0), top)
    fi = xf - f32(i)
    fj = xb - f32(j)
    w00 = (ONE - fi) * (ONE - fj)
    w01 = (ONE - fi) * fj
    w10 = fi * (ONE - fj)
    w11 = fi * fj
    a = w00 * tables[c, i, j, 3] + w01 * tables[c, i, j + 1, 3]
    a += w10 * tables[c, i + 1, j, 3] + w11 * tables[c, i + 1, j + 1, 3]
    if a <= ZERO:
        return ZERO, ZERO, ZERO, ZERO
    r = w00 * tables[c, i, j, 0] + w01 * tables[c, i, j + 1, 0]
    r += w10 * tables[c, i + 1, j, 0] + w11 * tables[c, i + 1, j + 1, 0]
    g = w00 * tables[c, i, j, 1] + w01 * tables[c, i, j + 1, 1]
    g += w10 * tables[c, i + 1, j, 1] + w11 * tables[c, i + 1, j + 1, 1]
    b = w00 * tables[c, i, j, 2] + w01 * tables[c, i, j + 1, 2]
    b += w10 * tables[c, i + 1, j, 2] + w11 * tables[c, i + 1, j + 1, 2]
    return a, r / a, g / a, b / a


@cuda.jit(device=True)
def _pair_entry(qf, qb, nl, np_):
    """Table entries (front, back) of two LUT entries (``kernels.pair_entry``)."""
    if nl == np_:
        return qf, qb
    ratio = f32(np_ - 1) / f32(nl - 1)
    return int(f32(qf) * ratio + HALF), int(f32(qb) * ratio + HALF)


@cuda.jit(device=True)
def _entry(tables, c, i, j):
    """Straight (alpha, r, g, b) of candidate c's premultiplied table entry (i, j)."""
    a = tables[c, i, j, 3]
    if a <= ZERO:
        return ZERO, ZERO, ZERO, ZERO
    return a, tables[c, i, j, 0] / a, tables[c, i, j, 1] / a, tables[c, i, j, 2] / a


@cuda.jit(device=True)
def _classify(luts, tables, c, preint, nearest, vf, vb):
    """``kernels._classify`` for candidate c."""
    nl = luts.shape[1]
    scale = f32(nl - 1)
    xb = vb * scale
    if nearest:
        xb = f32(int(xb + HALF))
        if preint:
            qf = int(vf * scale + HALF)
            i, j = _pair_entry(qf, int(xb), nl, tables.shape[1])
            if i != j:
                return _entry(tables, c, i, j)
        return _point(luts, c, xb)
    if preint:
        pscale = f32(tables.shape[1] - 1)
        pf = vf * pscale
        pb = vb * pscale
        if abs(pb - pf) >= ONE:
            return _segment(tables, c, pf, pb)
    return _point(luts, c, xb)


# ---------------------------------------------------------------------------------------------
# Direct ray marcher: K candidates per launch
# ---------------------------------------------------------------------------------------------
@cuda.jit(fastmath=True, cache=True)
def march(
    data, lit, shading, vis, bsize, luts, tables, preint, nearest, cam, isp, dt, shade, t_stop,
    tiles_x, bg, to8, out_rgba, out_rgb,
):  # fmt: skip
    """:func:`kernels.march` for candidate c (LUT ``luts[c]``, pre-integrated table
    ``tables[c]`` when ``preint``, visible blocks ``vis[c]``): the same samples classified the
    same way, the same segments kept where blocks are skipped (no 2³ grid: a sample it would
    pass over adds nothing).

    ``cam``, ``isp`` (1 / spacing), ``shade`` and ``bg`` are float32 arrays, ``dt`` and
    ``t_stop`` float32 scalars. Writes ``out_rgb[c, pixel]`` (uint8) when ``to8``, else
    ``out_rgba[c, pixel]`` (premultiplied float32).
    """
    c, slot = _candidate_slot(luts.shape[0])
    width = int(cam[17])
    height = int(cam[18])
    i, j = _pixel(slot, tiles_x)
    if i >= height or j >= width:
        return
    nz, ny, nx = data.shape
    nbz, nby, nbx = vis.shape[1], vis.shape[2], vis.shape[3]
    ka, kd, ks, shin = shade[0], shade[1], shade[2], shade[3]
    lx, ly, lz = -cam[3], -cam[4], -cam[5]
    oxi, oyi, ozi, dxi, dyi, dzi, dx, dy, dz = _index_ray(cam, isp, i, j)
    t0, t1 = _clip(oxi, oyi, ozi, dxi, dyi, dzi, nx, ny, nz)
    hx, hy, hz = _half_vector(lx, ly, lz, dx, dy, dz)
    r = ZERO
    g = ZERO
    b = ZERO
    tr = ONE
    if t1 >= t0:
        n = int((t1 - t0) / dt) + 1
        k = 0
        have = False  # vf holds sample k-1's value
        carry = False  # sample k-1 lay in a visible block
        vf = ZERO
        while k < n:
            t = t0 + f32(k) * dt
            px = oxi + t * dxi
            py = oyi + t * dyi
            pz = ozi + t * dzi
            bx = min(max(int(px), 0) // bsize, nbx - 1)
            by = min(max(int(py), 0) // bsize, nby - 1)
            bz = min(max(int(pz), 0) // bsize, nbz - 1)
            visible = vis[c, bz, by, bx] != 0
            kn = k + 1
            if not visible:
                # The first sample at or after the block's exit.
                tex = BIG
                if dxi > TINY:
                    tex = min(tex, (f32((bx + 1) * bsize) - oxi) / dxi)
                elif dxi < -TINY:
                    tex = min(tex, (f32(bx * bsize) - oxi) / dxi)
                if dyi > TINY:
                    tex = min(tex, (f32((by + 1) * bsize) - oyi) / dyi)
                elif dyi < -TINY:
                    tex = min(tex, (f32(by * bsize) - oyi) / dyi)
                if dzi > TINY:
                    tex = min(tex, (f32((bz + 1) * bsize) - ozi) / dzi)
                elif dzi < -TINY:
                    tex = min(tex, (f32(bz * bsize) - ozi) / dzi)
                kn = int(math.ceil((tex - t0) / dt - SKIP_EPS))
                if kn <= k:
                    kn = k + 1
                if not carry:
                    have = False
                    k = kn
                    continue
            ci, cj, ck, fx, fy, fz, v = _sample(
                data, lit, shading, px, py, pz, nx, ny, nz, VALUE_SCALE, VALUE_OFFSET
            )
            if preint and not have:
                vf = v
                if k > 0:
                    tp = t - dt
                    _, _, _, _, _, _, vf = _sample(
                        data, lit, shading, oxi + tp * dxi, oyi + tp * dyi, ozi + tp * dzi,
                        nx, ny, nz, VALUE_SCALE, VALUE_OFFSET,
                    )  # fmt: skip
            a, cr, cg, cb = _classify(luts, tables, c, preint, nearest, vf, v)
            vf = v
            have = True
            carry = preint and visible
            if a > ZERO:
                if shading:
                    gx, gy, gz = _gradient_at(lit, ci, cj, ck, fx, fy, fz)
                    ndl, sp = _shade_terms(
                        gx * isp[0], gy * isp[1], gz * isp[2], lx, ly, lz, hx, hy, hz, shin
                    )
                    light = ka + kd * ndl
                    cr = min(ONE, cr * light + ks * sp)
                    cg = min(ONE, cg * light + ks * sp)
                    cb = min(ONE, cb * light + ks * sp)
                w = tr * a
                r += w * cr
                g += w * cg
                b += w * cb
                tr *= ONE - a
                if tr < t_stop:
                    break
            if not visible:
                # The segment out of the visible blocks is classified; the rest of this
                # invisible block is skipped.
                have = kn == k + 1
            k = kn
    _store(out_rgba, out_rgb, to8, bg, c, i * width + j, r, g, b, tr)


# ---------------------------------------------------------------------------------------------
# Sample cache: build once per camera
# ---------------------------------------------------------------------------------------------
@cuda.jit(fastmath=True, cache=True)
def count_samples(cam, isp, nx, ny, nz, dt, tiles_x, counts, t0s):
    """Samples on each slot's ray (0 for slots outside the picture) and its entry ``t0``.

    Called with float64 ``cam``, ``isp``, ``dt`` and ``t0s`` (the device functions then run in
    float64), as :func:`fill_samples`: the same counts and entries as the CPU cache."""
    slot = cuda.grid(1)
    if slot >= counts.shape[0]:
        return
    i, j = _pixel(slot, tiles_x)
    n = 0
    t0 = ZERO
    if i < int(cam[18]) and j < int(cam[17]):
        oxi, oyi, ozi, dxi, dyi, dzi, dx, dy, dz = _index_ray(cam, isp, i, j)
        t0, t1 = _clip(oxi, oyi, ozi, dxi, dyi, dzi, nx, ny, nz)
        if t1 >= t0:
            n = int((t1 - t0) / dt) + 1
    counts[slot] = n
    t0s[slot] = t0


@cuda.jit(fastmath=True, cache=True)
def fill_samples(
    data, lit, shading, cam, isp, dt, nl, shin, tiles_x, counts, t0s, tile_base, samples,
    diffuse, specular, segmin, segmax,
):  # fmt: skip
    """:func:`kernels.fill_samples` into the tiled layout, with each segment's (min, max).

    In float64 (``cam``, ``isp``, ``dt``, ``shin``, ``t0s`` are float64), as the CPU kernel."""
    slot = cuda.grid(1)
    if slot >= counts.shape[0]:
        return
    n = counts[slot]
    if n == 0:
        return
    nz, ny, nx = data.shape
    i, j = _pixel(slot, tiles_x)
    tile = slot // WARP
    lane = slot - tile * WARP
    base = tile_base[tile] + lane
    sbase = tile_base[tile] // SEG + lane
    scale = f32(nl - 1)
    lx, ly, lz = -cam[3], -cam[4], -cam[5]
    oxi, oyi, ozi, dxi, dyi, dzi, dx, dy, dz = _index_ray(cam, isp, i, j)
    hx, hy, hz = _half_vector(lx, ly, lz, dx, dy, dz)
    t0 = t0s[slot]
    lo = 0
    hi = 0
    prev = 0
    for k in range(n):
        t = t0 + f32(k) * dt
        px = oxi + t * dxi
        py = oyi + t * dyi
        pz = ozi + t * dzi
        ci, cj, ck, fx, fy, fz, v = _sample(
            data, lit, shading, px, py, pz, nx, ny, nz, VALUE_SCALE64, VALUE_OFFSET64
        )
        q = int(v * scale + HALF)
        at = base + k * WARP
        samples[at] = q
        if shading:
            gx, gy, gz = _gradient_at(lit, ci, cj, ck, fx, fy, fz)
            ndl, sp = _shade_terms(
                gx * isp[0], gy * isp[1], gz * isp[2], lx, ly, lz, hx, hy, hz, shin
            )
            diffuse[at] = int(ndl * U8 + HALF)
            specular[at] = int(sp * U8 + HALF)
        r = k % SEG
        if r == 0:
            # The segment's range holds the sample before it too (``kernels.segment_minmax``).
            lo = q
            hi = q
            if k > 0:
                lo = min(lo, prev)
                hi = max(hi, prev)
        else:
            lo = min(lo, q)
            hi = max(hi, q)
        if r == SEG - 1 or k == n - 1:
            s = sbase + (k // SEG) * WARP
            segmin[s] = lo
            segmax[s] = hi
        prev = q


# ---------------------------------------------------------------------------------------------
# Sample cache: K candidates per launch
# ---------------------------------------------------------------------------------------------
@cuda.jit(fastmath=True, cache=True)
def composite(
    counts, tile_base, samples, diffuse, specular, segmin, segmax, occupied, luts, tables,
    preint, shading, shade, t_stop, tiles_x, width, height, bg, to8, out_rgba, out_rgb,
):  # fmt: skip
    """:func:`kernels.composite` (shaded, straight LUT) or :func:`kernels.composite_unshaded`
    (premultiplied LUT) of candidate c for the slot's ray.

    ``occupied[c, k]`` counts candidate c's LUT entries below k with non-zero alpha: a
    segment with values in [lo, hi] is empty, and skipped whole, when
    ``occupied[c, hi + 1] == occupied[c, lo]``.
    """
    c, slot = _candidate_slot(luts.shape[0])
    if slot >= counts.shape[0]:
        return
    i, j = _pixel(slot, tiles_x)
    if i >= height or j >= width:
        return
    n = counts[slot]
    tile = slot // WARP
    lane = slot - tile * WARP
    base = tile_base[tile] + lane
    sbase = tile_base[tile] // SEG + lane
    ka, kd, ks = shade[0], shade[1], shade[2]
    r = ZERO
    g = ZERO
    b = ZERO
    tr = ONE
    n_seg = (n + SEG - 1) // SEG
    s = 0
    done = False
    while s < n_seg and not done:
        at = sbase + s * WARP
        lo = int(segmin[at])
        hi = int(segmax[at])
        if occupied[c, hi + 1] != occupied[c, lo]:
            for k in range(s * SEG, min(s * SEG + SEG, n)):
                at = base + k * WARP
                q = int(samples[at])
                # Candidate c's LUT entry, or the segment from the previous sample (straight
                # colour when shading, premultiplied otherwise, as the LUTs).
                a = luts[c, q, 3]
                c0 = luts[c, q, 0]
                c1 = luts[c, q, 1]
                c2 = luts[c, q, 2]
                if preint and k > 0:
                    qf = int(samples[at - WARP])
                    if qf != q:
                        ti, tj = _pair_entry(qf, q, luts.shape[1], tables.shape[1])
                        if ti != tj:
                            a = tables[c, ti, tj, 3]
                            c0 = tables[c, ti, tj, 0]
                            c1 = tables[c, ti, tj, 1]
                            c2 = tables[c, ti, tj, 2]
                            if shading and a > ZERO:
                                c0 /= a
                                c1 /= a
                                c2 /= a
                if a > ZERO:
                    if shading:
                        lit = ka + kd * (f32(diffuse[at]) * INV255)
                        sp = ks * (f32(specular[at]) * INV255)
                        w = tr * a
                        r += w * min(ONE, c0 * lit + sp)
                        g += w * min(ONE, c1 * lit + sp)
                        b += w * min(ONE, c2 * lit + sp)
                    else:
                        r += tr * c0
                        g += tr * c1
                        b += tr * c2
                    tr *= ONE - a
                    if tr < t_stop:
                        done = True
                        break
        s += 1
    _store(out_rgba, out_rgb, to8, bg, c, i * width + j, r, g, b, tr)


@cuda.jit(fastmath=True, cache=True)
def attribute(
    counts, tile_base, samples, segmin, segmax, occupied, alpha, share, table, preint, gauss,
    t_stop, tiles_x, width, height, out,
):  # fmt: skip
    """:func:`kernels.attribute` for one TF into ``out`` (N, n_pixels), zero on entry
    (``table`` its (1, P, P, 4) pre-integrated table, ``gauss`` (N, 3) float32)."""
    slot = cuda.grid(1)
    if slot >= counts.shape[0]:
        return
    i, j = _pixel(slot, tiles_x)
    if i >= height or j >= width:
        return
    p = i * width + j
    n = counts[slot]
    ng = share.shape[1]
    tile = slot // WARP
    lane = slot - tile * WARP
    base = tile_base[tile] + lane
    sbase = tile_base[tile] // SEG + lane
    tr = ONE
    n_seg = (n + SEG - 1) // SEG
    s = 0
    done = False
    while s < n_seg and not done:
        at = sbase + s * WARP
        lo = int(segmin[at])
        hi = int(segmax[at])
        if occupied[hi + 1] != occupied[lo]:
            for k in range(s * SEG, min(s * SEG + SEG, n)):
                q = int(samples[base + k * WARP])
                a = alpha[q]
                ti = 0
                tj = 0
                if preint and k > 0:
                    qf = int(samples[base + (k - 1) * WARP])
                    if qf != q:
                        ti, tj = _pair_entry(qf, q, alpha.shape[0], table.shape[1])
                        if ti != tj:
                            a = table[0, ti, tj, 3]
                if a > ZERO:
                    w = tr * a
                    total = ZERO
                    lo_v = ZERO
                    hi_v = ZERO
                    if ti != tj:
                        pscale = f32(table.shape[1] - 1)
                        lo_v = f32(min(ti, tj)) / pscale
                        hi_v = f32(max(ti, tj)) / pscale
                        for m in range(ng):
                            total += _mass(gauss, m, lo_v, hi_v)
                    if total > ZERO:
                        for m in range(ng):
                            out[m, p] += w * _mass(gauss, m, lo_v, hi_v) / total
                    else:
                        for m in range(ng):
                            out[m, p] += w * share[q, m]
                    tr *= ONE - a
                    if tr < t_stop:
                        done = True
                        break
        s += 1


@cuda.jit(device=True)
def _mass(gauss, m, lo, hi):
    """``kernels._mass``: Gaussian m's opacity density over [lo, hi], up to a common factor."""
    mean, w, h = gauss[m, 0], gauss[m, 1], gauss[m, 2]
    k = ONE / (w * f32(1.4142135623730951))
    return h * w * (math.erf((hi - mean) * k) - math.erf((lo - mean) * k))


@cuda.jit(fastmath=True, cache=True)
def count_reads(
    counts, tile_base, samples, segmin, segmax, occupied, alpha, t_stop, tiles_x, width, height,
    reads,
):  # fmt: skip
    """For the benchmark's bandwidth figures: what :func:`composite` reads for candidate c.

    ``reads[c, slot]`` = (segment bounds checked, samples loaded) on the slot's ray, following
    the same skipping and early termination (``alpha`` (K, L) is the corrected LUT alpha).
    """
    c, slot = _candidate_slot(alpha.shape[0])
    if slot >= counts.shape[0]:
        return
    i, j = _pixel(slot, tiles_x)
    if i >= height or j >= width:
        return
    n = counts[slot]
    tile = slot // WARP
    lane = slot - tile * WARP
    base = tile_base[tile] + lane
    sbase = tile_base[tile] // SEG + lane
    tr = ONE
    n_seg = (n + SEG - 1) // SEG
    checked = 0
    loaded = 0
    s = 0
    done = False
    while s < n_seg and not done:
        at = sbase + s * WARP
        lo = int(segmin[at])
        hi = int(segmax[at])
        checked += 1
        if occupied[c, hi + 1] != occupied[c, lo]:
            for k in range(s * SEG, min(s * SEG + SEG, n)):
                loaded += 1
                a = alpha[c, int(samples[base + k * WARP])]
                if a > ZERO:
                    tr *= ONE - a
                    if tr < t_stop:
                        done = True
                        break
        s += 1
    reads[c, slot, 0] = checked
    reads[c, slot, 1] = loaded
