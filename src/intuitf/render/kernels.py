"""Numba kernels of the CPU ray caster. Internal: the public API is in renderer.py and cache.py.

Geometry shared by every kernel:

- ``cam`` is :meth:`ViewFrame.packed`: eye(3), forward(3), right(3), up(3), half width,
  half height, perspective flag, pan x, pan y, width, height (world coordinates).
- Rays are traversed in voxel-index space ``p_index = p_world / spacing``; the ray parameter
  ``t`` stays in world units, so steps of ``dt`` are equal world lengths whatever the spacing.
- The box is the voxel centres, ``[0, n - 1]`` along each axis. Samples sit at
  ``t0 + k * dt`` from box entry ``t0`` up to the exit.
- Compositing is front to back with premultiplied colour: ``C += T * a * c``, ``T *= 1 - a``;
  a ray stops once its transmittance ``T`` falls below ``t_stop``.
- Shading (Blinn–Phong, headlight, two-sided): ``c_lit = min(1, c * (ka + kd * |n.l|) +
  ks * |n.h| ** shininess)``; where the gradient vanishes the sample counts as fully lit
  facing the light, without highlight.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

#: int16 gradient scale: a difference of 1.0 (the whole normalised range) maps to 32767.
GRAD_SCALE = 32767.0
#: Gradient magnitude (normalised value per voxel) below which a sample counts as flat.
FLAT_GRADIENT = 1e-3
#: The value in a shading voxel (:func:`value_codes`): ``v = code * VALUE_CODE_SCALE +
#: VALUE_CODE_OFFSET``, 65536 levels over [0, 1] (an 8-bit volume's values exactly; a 16-bit
#: one's within 8e-6).
VALUE_CODE_SCALE = 1.0 / 65535.0
VALUE_CODE_OFFSET = 32768.0 / 65535.0
#: Cached samples are grouped in segments of 2**SEG_SHIFT for empty-space skipping.
SEG_SHIFT = 5
#: Rows are handed to the threads in this stride (made coprime with the height): each thread's
#: contiguous share of the loop then holds rows from all over the picture, so the threads get
#: alike amounts of work where the volume fills one half of the picture more than the other.
ROW_STRIDE = 389
#: The direct ray marcher walks the picture in square tiles of this many pixels a side:
#: neighbouring rays, taken one after another, read the same cache lines of the volume in
#: both picture directions (rows alone share them in one): about 15–20 % faster on oblique
#: views of a 256³ volume, the same pixels. The tiles go to the threads interleaved as rows
#: once did (:func:`row_stride`).
TILE = 16


# ---------------------------------------------------------------------------------------------
# Precomputation
# ---------------------------------------------------------------------------------------------
@njit(parallel=True, cache=True)
def central_gradient(data, out):
    """Index-space central differences of ``data`` [z, y, x] into ``out`` [z, y, x, 3] int16.

    Components are (d/dx, d/dy, d/dz) scaled by GRAD_SCALE; one-sided at the borders.
    """
    nz, ny, nx = data.shape
    for z in prange(nz):
        for y in range(ny):
            for x in range(nx):
                if x == 0:
                    gx = data[z, y, 1] - data[z, y, 0]
                elif x == nx - 1:
                    gx = data[z, y, x] - data[z, y, x - 1]
                else:
                    gx = 0.5 * (data[z, y, x + 1] - data[z, y, x - 1])
                if y == 0:
                    gy = data[z, 1, x] - data[z, 0, x]
                elif y == ny - 1:
                    gy = data[z, y, x] - data[z, y - 1, x]
                else:
                    gy = 0.5 * (data[z, y + 1, x] - data[z, y - 1, x])
                if z == 0:
                    gz = data[1, y, x] - data[0, y, x]
                elif z == nz - 1:
                    gz = data[z, y, x] - data[z - 1, y, x]
                else:
                    gz = 0.5 * (data[z + 1, y, x] - data[z - 1, y, x])
                out[z, y, x, 0] = np.int16(round(gx * GRAD_SCALE))
                out[z, y, x, 1] = np.int16(round(gy * GRAD_SCALE))
                out[z, y, x, 2] = np.int16(round(gz * GRAD_SCALE))


@njit(parallel=True, cache=True)
def value_codes(data, out):
    """``out[z, y, x, 3]``: the value of ``data`` as an int16 code (:data:`VALUE_CODE_SCALE`).

    With :func:`central_gradient` in components 0-2, ``out`` holds a shading voxel: what a
    shaded sample reads, value and gradient, in 8 bytes, so the eight corners of a sample
    take four cache lines instead of eight (with :func:`_lit_at`, shaded 512² stills of the
    bonsai, foot, CT head and chest 4-13 % faster).
    """
    nz, ny, nx = data.shape
    for z in prange(nz):
        for y in range(ny):
            for x in range(nx):
                v = min(max(data[z, y, x], 0.0), 1.0)
                out[z, y, x, 3] = np.int16(round(v * 65535.0) - 32768)


@njit(parallel=True, cache=True)
def block_minmax(data, bsize, bmin, bmax):
    """Min and max of the voxels each block's samples can touch (its cells plus one voxel)."""
    nz, ny, nx = data.shape
    nbz, nby, nbx = bmin.shape
    for bz in prange(nbz):
        z0 = bz * bsize
        z1 = min(z0 + bsize, nz - 1)
        for by in range(nby):
            y0 = by * bsize
            y1 = min(y0 + bsize, ny - 1)
            for bx in range(nbx):
                x0 = bx * bsize
                x1 = min(x0 + bsize, nx - 1)
                lo = np.float32(np.inf)
                hi = np.float32(-np.inf)
                for z in range(z0, z1 + 1):
                    for y in range(y0, y1 + 1):
                        for x in range(x0, x1 + 1):
                            v = data[z, y, x]
                            lo = min(lo, v)
                            hi = max(hi, v)
                bmin[bz, by, bx] = lo
                bmax[bz, by, bx] = hi


@njit(parallel=True, cache=True)
def visible_blocks(lo, hi, occupied, out):
    """``out[b] = 1`` where some LUT entry in block b's range [lo, hi] has alpha > 0.

    ``occupied`` is the running count of visible entries (``occupied[i]``: entries below i), so
    the test is one subtraction per block. All arrays are flat.
    """
    for b in prange(lo.shape[0]):
        out[b] = 1 if occupied[hi[b] + 1] > occupied[lo[b]] else 0


# ---------------------------------------------------------------------------------------------
# Rays
# ---------------------------------------------------------------------------------------------
@njit(cache=True, fastmath=True, inline="always")
def _ray(cam, i, j):
    """World origin and unit direction of the ray through pixel (row i, column j)."""
    x = ((j + 0.5) / cam[17] * 2.0 - 1.0 - 2.0 * cam[15]) * cam[12]
    y = (1.0 - (i + 0.5) / cam[18] * 2.0 - 2.0 * cam[16]) * cam[13]
    if cam[14] > 0.5:
        dx = cam[3] + x * cam[6] + y * cam[9]
        dy = cam[4] + x * cam[7] + y * cam[10]
        dz = cam[5] + x * cam[8] + y * cam[11]
        n = math.sqrt(dx * dx + dy * dy + dz * dz)
        return cam[0], cam[1], cam[2], dx / n, dy / n, dz / n
    ox = cam[0] + x * cam[6] + y * cam[9]
    oy = cam[1] + x * cam[7] + y * cam[10]
    oz = cam[2] + x * cam[8] + y * cam[11]
    return ox, oy, oz, cam[3], cam[4], cam[5]


@njit(cache=True)
def row_stride(height):
    """A stride coprime with ``height``: ``(k * stride) % height`` visits every row once."""
    s = ROW_STRIDE
    while True:
        a, b = s, height
        while b:
            a, b = b, a % b
        if a == 1:
            return s
        s += 2


@njit(cache=True)
def block_shift(bsize):
    """log2 of a power-of-two block size (block indices by shifting, not dividing)."""
    sh = 0
    while (1 << sh) < bsize:
        sh += 1
    return sh


@njit(cache=True, fastmath=True, inline="always")
def _slab(o, d, hi, t0, t1):
    if abs(d) < 1e-12:
        if o < 0.0 or o > hi:
            return 1.0, 0.0
        return t0, t1
    ta = (0.0 - o) / d
    tb = (hi - o) / d
    if ta > tb:
        ta, tb = tb, ta
    return max(t0, ta), min(t1, tb)


@njit(cache=True, fastmath=True, inline="always")
def _clip(oxi, oyi, ozi, dxi, dyi, dzi, nx, ny, nz):
    """Entry and exit t of an index-space ray with the box [0, n-1]^3 (t1 < t0: missed)."""
    t0, t1 = _slab(oxi, dxi, nx - 1.0, 0.0, 1e30)
    t0, t1 = _slab(oyi, dyi, ny - 1.0, t0, t1)
    t0, t1 = _slab(ozi, dzi, nz - 1.0, t0, t1)
    return t0, t1


@njit(cache=True, fastmath=True, inline="always")
def _cell(p, n):
    if p < 0.0:
        p = 0.0
    elif p > n - 1.0:
        p = n - 1.0
    i = int(p)
    if i > n - 2:
        i = n - 2
    return i, p - i


@njit(cache=True, fastmath=True, inline="always")
def _trilinear_at(data, i, j, k, fx, fy, fz):
    c00 = data[k, j, i] * (1.0 - fx) + data[k, j, i + 1] * fx
    c01 = data[k, j + 1, i] * (1.0 - fx) + data[k, j + 1, i + 1] * fx
    c10 = data[k + 1, j, i] * (1.0 - fx) + data[k + 1, j, i + 1] * fx
    c11 = data[k + 1, j + 1, i] * (1.0 - fx) + data[k + 1, j + 1, i + 1] * fx
    c0 = c00 * (1.0 - fy) + c01 * fy
    c1 = c10 * (1.0 - fy) + c11 * fy
    return c0 * (1.0 - fz) + c1 * fz


@njit(cache=True, fastmath=True, inline="always")
def _lit_at(lit, i, j, k, fx, fy, fz):
    """Gradient (x, y, z) and value, trilinear in cell (i, j, k) of the shading voxels.

    The four components from one set of corner weights: the compiler vectorises them (about
    5 % faster than one component at a time).
    """
    ex = 1.0 - fx
    ey = 1.0 - fy
    ez = 1.0 - fz
    a0 = 0.0
    a1 = 0.0
    a2 = 0.0
    a3 = 0.0
    for dk in range(2):
        wk = fz if dk else ez
        for dj in range(2):
            wjk = wk * (fy if dj else ey)
            for di in range(2):
                w = wjk * (fx if di else ex)
                a0 += w * lit[k + dk, j + dj, i + di, 0]
                a1 += w * lit[k + dk, j + dj, i + di, 1]
                a2 += w * lit[k + dk, j + dj, i + di, 2]
                a3 += w * lit[k + dk, j + dj, i + di, 3]
    return a0, a1, a2, a3 * VALUE_CODE_SCALE + VALUE_CODE_OFFSET


@njit(cache=True, fastmath=True, inline="always")
def _sample(data, lit, shading, px, py, pz, nx, ny, nz):
    """(gradient x, y, z, value) at index-space point p: all four from the shading voxels
    when shading, else the value from ``data`` (and a zero gradient)."""
    i, fx = _cell(px, nx)
    j, fy = _cell(py, ny)
    k, fz = _cell(pz, nz)
    if shading:
        return _lit_at(lit, i, j, k, fx, fy, fz)
    return 0.0, 0.0, 0.0, _trilinear_at(data, i, j, k, fx, fy, fz)


@njit(cache=True, fastmath=True, inline="always")
def _shade_terms(gx, gy, gz, lx, ly, lz, hx, hy, hz, shin):
    """(|n.l|, |n.h|**shininess) for the world gradient (gx, gy, gz) (up to a scale)."""
    m = math.sqrt(gx * gx + gy * gy + gz * gz)
    if m < FLAT_GRADIENT * GRAD_SCALE:
        return 1.0, 0.0
    ndl = abs(gx * lx + gy * ly + gz * lz) / m
    ndh = abs(gx * hx + gy * hy + gz * hz) / m
    return ndl, _power(ndh, shin)


@njit(cache=True, fastmath=True, inline="always")
def _power(x, e):
    """``x ** e``; whole exponents up to 64 by repeated squaring (a few multiplications in
    place of a call to ``pow``, on every shaded sample)."""
    k = int(e)
    if k != e or k < 0 or k > 64:
        return x**e
    r = 1.0
    b = x
    while k:
        if k & 1:
            r *= b
        b *= b
        k >>= 1
    return r


@njit(cache=True, fastmath=True, inline="always")
def _half_vector(lx, ly, lz, dx, dy, dz):
    hx = lx - dx
    hy = ly - dy
    hz = lz - dz
    n = math.sqrt(hx * hx + hy * hy + hz * hz)
    if n < 1e-12:
        return lx, ly, lz
    return hx / n, hy / n, hz / n


# ---------------------------------------------------------------------------------------------
# Classification
# ---------------------------------------------------------------------------------------------
@njit(cache=True, fastmath=True, inline="always")
def _point(lut, x):
    """Post-classification: straight (alpha, r, g, b) at fractional LUT index ``x``, linear
    between the two entries around it."""
    nl = lut.shape[0]
    q = int(x)
    if q > nl - 2:
        q = nl - 2
    elif q < 0:
        q = 0
    f = x - q
    a = lut[q, 3] * (1.0 - f) + lut[q + 1, 3] * f
    if a <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    return (
        a,
        lut[q, 0] * (1.0 - f) + lut[q + 1, 0] * f,
        lut[q, 1] * (1.0 - f) + lut[q + 1, 1] * f,
        lut[q, 2] * (1.0 - f) + lut[q + 1, 2] * f,
    )


@njit(cache=True, fastmath=True, inline="always")
def _segment(ptable, xf, xb):
    """Pre-integrated classification of the segment from fractional table index ``xf`` (front
    sample) to ``xb`` (back sample): straight (alpha, r, g, b), bilinear in the premultiplied
    table (:func:`intuitf.tf.preintegration.preintegrated_table`)."""
    top = ptable.shape[0] - 2
    i = min(max(int(xf), 0), top)
    j = min(max(int(xb), 0), top)
    fi = xf - i
    fj = xb - j
    w00 = (1.0 - fi) * (1.0 - fj)
    w01 = (1.0 - fi) * fj
    w10 = fi * (1.0 - fj)
    w11 = fi * fj
    a = w00 * ptable[i, j, 3] + w01 * ptable[i, j + 1, 3]
    a += w10 * ptable[i + 1, j, 3] + w11 * ptable[i + 1, j + 1, 3]
    if a <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    out_r = w00 * ptable[i, j, 0] + w01 * ptable[i, j + 1, 0]
    out_r += w10 * ptable[i + 1, j, 0] + w11 * ptable[i + 1, j + 1, 0]
    out_g = w00 * ptable[i, j, 1] + w01 * ptable[i, j + 1, 1]
    out_g += w10 * ptable[i + 1, j, 1] + w11 * ptable[i + 1, j + 1, 1]
    out_b = w00 * ptable[i, j, 2] + w01 * ptable[i, j + 1, 2]
    out_b += w10 * ptable[i + 1, j, 2] + w11 * ptable[i + 1, j + 1, 2]
    return a, out_r / a, out_g / a, out_b / a


@njit(cache=True, fastmath=True, inline="always")
def _classify(lut, ptable, preint, nearest, vf, vb):
    """Straight (alpha, r, g, b) of the sample of value ``vb`` whose ray came from the sample
    of value ``vf`` (equal for a ray's first sample).

    Without ``preint``, post-classification at ``vb`` (the LUT, linear between entries; with
    ``nearest``, its nearest entry). With ``preint``, the segment ``vf -> vb`` from the
    pre-integrated table when the two values lie at least one table entry apart, else the LUT
    at ``vb`` (which the table's diagonal equals; wider data keeps the LUT's finer entries).
    With ``nearest`` both values are rounded to their LUT entries first, then those to table
    entries, exactly as the sample cache does (:func:`pair_entry`).
    """
    scale = lut.shape[0] - 1.0
    xb = vb * scale
    if nearest:
        xb = float(int(xb + 0.5))
        if preint:
            xf = float(int(vf * scale + 0.5))
            i, j = pair_entry(xf, xb, scale, ptable.shape[0] - 1.0)
            if i != j:
                return _entry(ptable, i, j)
        return _point(lut, xb)
    if preint:
        pscale = ptable.shape[0] - 1.0
        pf = vf * pscale
        pb = vb * pscale
        if abs(pb - pf) >= 1.0:
            return _segment(ptable, pf, pb)
    return _point(lut, xb)


@njit(cache=True, fastmath=True, inline="always")
def pair_entry(qf, qb, scale, pscale):
    """Table entries (front, back) of two samples' LUT entries ``qf``, ``qb`` (as floats):
    the nearest entries of the table's coarser grid (the same grid for 8-bit data)."""
    if scale == pscale:
        return int(qf), int(qb)
    r = pscale / scale
    return int(qf * r + 0.5), int(qb * r + 0.5)


@njit(cache=True, fastmath=True, inline="always")
def _entry(ptable, i, j):
    """Straight (alpha, r, g, b) of premultiplied table entry (i, j)."""
    a = ptable[i, j, 3]
    if a <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    return a, ptable[i, j, 0] / a, ptable[i, j, 1] / a, ptable[i, j, 2] / a


# ---------------------------------------------------------------------------------------------
# Direct ray marcher
# ---------------------------------------------------------------------------------------------
@njit(parallel=True, cache=True, fastmath=True)
def march(
    data, lit, shading, vis, bsize, fine, fine_shift, lut, ptable, preint, nearest, cam,
    spacing, dt, shade_params, t_stop, out,
):  # fmt: skip
    """Render every pixel of ``cam`` into ``out`` (n_pixels, 4) premultiplied RGBA.

    Post-classification: the trilinear value indexes ``lut`` (L, 4 straight RGBA, alpha already
    corrected for ``dt``) with linear interpolation between entries. ``vis`` marks blocks of
    ``bsize`` cells whose values can have non-zero alpha; rays jump over the others, keeping
    the sample grid, so skipping changes no pixel. ``fine`` marks the same for blocks of
    ``2**fine_shift`` cells: inside a visible block, a sample in an invisible fine block is
    passed over without interpolating (often most of a visible block's samples: the bonsai's
    default TF classifies 19 M samples for 4 M visible ones with the 8³ grid alone).
    ``nearest`` rounds the value to the nearest entry instead of interpolating, exactly as
    the sample cache does (used to test the cache). With ``shading``, values and gradients
    are read from ``lit``, the shading voxels (:func:`value_codes`); else values from ``data``.
    ``bsize`` is a power of two. The picture is walked in tiles of :data:`TILE` pixels,
    handed to the threads interleaved (:func:`row_stride`).

    With ``preint``, each sample is classified with the segment from the ray's previous sample
    (:func:`_classify`, ``ptable`` the premultiplied pre-integrated table). Skipping then
    keeps every segment that can show: a sample whose block is invisible is still classified
    when the sample before it lay in a visible block (the segment leaving a structure crosses
    the values of its surface), and the first sample after a skipped stretch reads the value
    of the one before it (the segment entering a structure). ``vis`` and ``fine`` mark a
    block visible when its value range can show in the table (the LUT's occupancy widened by
    one table entry).
    """
    nz, ny, nx = data.shape
    nbz, nby, nbx = vis.shape
    width = int(cam[17])
    height = int(cam[18])
    isx = 1.0 / spacing[0]
    isy = 1.0 / spacing[1]
    isz = 1.0 / spacing[2]
    ka, kd, ks, shin = shade_params[0], shade_params[1], shade_params[2], shade_params[3]
    lx, ly, lz = -cam[3], -cam[4], -cam[5]
    bsh = block_shift(bsize)
    nfz, nfy, nfx = fine.shape[0] - 1, fine.shape[1] - 1, fine.shape[2] - 1
    tiles_x = (width + TILE - 1) // TILE
    ntiles = tiles_x * ((height + TILE - 1) // TILE)
    stride = row_stride(ntiles)
    for tt in prange(ntiles):
        tile = (tt * stride) % ntiles
        i0 = (tile // tiles_x) * TILE
        j0 = (tile % tiles_x) * TILE
        for i in range(i0, min(height, i0 + TILE)):
            for j in range(j0, min(width, j0 + TILE)):
                ox, oy, oz, dx, dy, dz = _ray(cam, i, j)
                oxi, oyi, ozi = ox * isx, oy * isy, oz * isz
                dxi, dyi, dzi = dx * isx, dy * isy, dz * isz
                t0, t1 = _clip(oxi, oyi, ozi, dxi, dyi, dzi, nx, ny, nz)
                hx, hy, hz = _half_vector(lx, ly, lz, dx, dy, dz)
                r = 0.0
                g = 0.0
                b = 0.0
                tr = 1.0
                if t1 >= t0:
                    n = int((t1 - t0) / dt) + 1
                    k = 0
                    done = False
                    # With preint: ``vf`` holds sample k-1's value when ``have``; ``carry``:
                    # sample k-1 lay in a visible block, so sample k's segment can show.
                    have = False
                    carry = False
                    vf = 0.0
                    while k < n and not done:
                        # Block by block, as the page's shader: a skipped block costs one
                        # lookup, a visible one runs its samples without looking up its
                        # block again (a sample just past the exit lies in a neighbour's
                        # cells, whose value range holds it: an invisible neighbour gives it
                        # alpha 0). About 3 % faster than a block lookup per sample.
                        t = t0 + k * dt
                        px = oxi + t * dxi
                        py = oyi + t * dyi
                        pz = ozi + t * dzi
                        bx = min(max(int(px), 0) >> bsh, nbx - 1)
                        by = min(max(int(py), 0) >> bsh, nby - 1)
                        bz = min(max(int(pz), 0) >> bsh, nbz - 1)
                        # The first sample at or after the block's exit.
                        tex = 1e30
                        if dxi > 1e-12:
                            tex = min(tex, ((bx + 1) * bsize - oxi) / dxi)
                        elif dxi < -1e-12:
                            tex = min(tex, (bx * bsize - oxi) / dxi)
                        if dyi > 1e-12:
                            tex = min(tex, ((by + 1) * bsize - oyi) / dyi)
                        elif dyi < -1e-12:
                            tex = min(tex, (by * bsize - oyi) / dyi)
                        if dzi > 1e-12:
                            tex = min(tex, ((bz + 1) * bsize - ozi) / dzi)
                        elif dzi < -1e-12:
                            tex = min(tex, (bz * bsize - ozi) / dzi)
                        kn = int(math.ceil((tex - t0) / dt - 1e-4))
                        if kn <= k:
                            kn = k + 1
                        kend = min(kn, n)
                        block_visible = vis[bz, by, bx] != 0
                        if not block_visible and not carry:
                            have = False
                            k = kn
                            continue
                        while k < kend:
                            t = t0 + k * dt
                            px = oxi + t * dxi
                            py = oyi + t * dyi
                            pz = ozi + t * dzi
                            visible = block_visible
                            if visible:
                                fbx = min(int(px) >> fine_shift, nfx)
                                fby = min(int(py) >> fine_shift, nfy)
                                fbz = min(int(pz) >> fine_shift, nfz)
                                visible = fine[fbz, fby, fbx] != 0
                            if not visible and not carry:
                                have = False
                                k += 1
                                if not block_visible:
                                    break
                                continue
                            gx, gy, gz, v = _sample(data, lit, shading, px, py, pz, nx, ny, nz)
                            if preint and not have:
                                vf = v
                                if k > 0:
                                    tp = t - dt
                                    _, _, _, vf = _sample(
                                        data, lit, shading, oxi + tp * dxi, oyi + tp * dyi,
                                        ozi + tp * dzi, nx, ny, nz,
                                    )  # fmt: skip
                            a, cr, cg, cb = _classify(lut, ptable, preint, nearest, vf, v)
                            vf = v
                            have = True
                            carry = preint and visible
                            if a > 0.0:
                                if shading:
                                    # Index-space differences divided by spacing: the world
                                    # gradient (up to a common scale).
                                    ndl, sp = _shade_terms(
                                        gx * isx, gy * isy, gz * isz, lx, ly, lz, hx, hy, hz, shin
                                    )
                                    light = ka + kd * ndl
                                    cr = min(1.0, cr * light + ks * sp)
                                    cg = min(1.0, cg * light + ks * sp)
                                    cb = min(1.0, cb * light + ks * sp)
                                w = tr * a
                                r += w * cr
                                g += w * cg
                                b += w * cb
                                tr *= 1.0 - a
                                if tr < t_stop:
                                    done = True
                                    break
                            k += 1
                            if not visible:
                                # The segment out of the visible blocks is classified: the
                                # rest of an invisible block is skipped.
                                if not block_visible:
                                    k = kn
                                    have = False
                                    break
                p = i * width + j
                out[p, 0] = r
                out[p, 1] = g
                out[p, 2] = b
                out[p, 3] = 1.0 - tr


# ---------------------------------------------------------------------------------------------
# Sample cache
# ---------------------------------------------------------------------------------------------
@njit(parallel=True, cache=True, fastmath=True)
def count_samples(cam, spacing, dims, dt, counts):
    """Number of samples on each pixel's ray (``counts`` has one entry per pixel)."""
    nx, ny, nz = dims[0], dims[1], dims[2]
    width = int(cam[17])
    height = int(cam[18])
    isx = 1.0 / spacing[0]
    isy = 1.0 / spacing[1]
    isz = 1.0 / spacing[2]
    for i in prange(height):
        for j in range(width):
            ox, oy, oz, dx, dy, dz = _ray(cam, i, j)
            t0, t1 = _clip(ox * isx, oy * isy, oz * isz, dx * isx, dy * isy, dz * isz, nx, ny, nz)
            counts[i * width + j] = int((t1 - t0) / dt) + 1 if t1 >= t0 else 0


@njit(parallel=True, cache=True, fastmath=True)
def fill_samples(
    data, lit, shading, cam, spacing, dt, nl, shin, offsets, samples, diffuse, specular
):
    """Sample every ray (same positions and values as :func:`march`) and store quantised values.

    ``samples[k] = round(v * (nl - 1))``; with shading, ``diffuse[k] = round(255 * |n.l|)`` and
    ``specular[k] = round(255 * |n.h| ** shininess)``.
    """
    nz, ny, nx = data.shape
    width = int(cam[17])
    height = int(cam[18])
    scale = nl - 1.0
    isx = 1.0 / spacing[0]
    isy = 1.0 / spacing[1]
    isz = 1.0 / spacing[2]
    lx, ly, lz = -cam[3], -cam[4], -cam[5]
    for i in prange(height):
        for j in range(width):
            ox, oy, oz, dx, dy, dz = _ray(cam, i, j)
            oxi, oyi, ozi = ox * isx, oy * isy, oz * isz
            dxi, dyi, dzi = dx * isx, dy * isy, dz * isz
            t0, t1 = _clip(oxi, oyi, ozi, dxi, dyi, dzi, nx, ny, nz)
            hx, hy, hz = _half_vector(lx, ly, lz, dx, dy, dz)
            p = i * width + j
            s0 = offsets[p]
            for k in range(offsets[p + 1] - s0):
                t = t0 + k * dt
                px = oxi + t * dxi
                py = oyi + t * dyi
                pz = ozi + t * dzi
                gx, gy, gz, v = _sample(data, lit, shading, px, py, pz, nx, ny, nz)
                samples[s0 + k] = int(v * scale + 0.5)
                if shading:
                    ndl, sp = _shade_terms(
                        gx * isx, gy * isy, gz * isz, lx, ly, lz, hx, hy, hz, shin
                    )
                    diffuse[s0 + k] = np.uint8(int(ndl * 255.0 + 0.5))
                    specular[s0 + k] = np.uint8(int(sp * 255.0 + 0.5))


@njit(parallel=True, cache=True)
def segment_minmax(samples, segmin, segmax):
    """Min and max quantised value of each run of 2**SEG_SHIFT consecutive samples and the
    sample before it (so that a segment from the previous sample, pre-integrated, lies in the
    range; the sample before may be another ray's, which only widens the range)."""
    n = samples.shape[0]
    seg = 1 << SEG_SHIFT
    for g in prange(segmin.shape[0]):
        a = g * seg
        b = min(a + seg, n)
        lo = samples[max(a - 1, 0)]
        hi = lo
        for k in range(a, b):
            v = samples[k]
            if v < lo:
                lo = v
            if v > hi:
                hi = v
        segmin[g] = lo
        segmax[g] = hi


@njit(parallel=True, cache=True, fastmath=True)
def composite_unshaded(
    offsets, samples, segmin, segmax, occupied, plut, ptable, preint, t_stop, out
):  # fmt: skip
    """:func:`composite` without shading, from a premultiplied LUT (r·a, g·a, b·a, a).

    Same result; the inner loop has no branch on empty samples (a zero-alpha entry adds
    nothing), which is what makes it faster on the per-candidate path.
    """
    scale = plut.shape[0] - 1.0
    pscale = ptable.shape[0] - 1.0
    for p in prange(offsets.shape[0] - 1):
        s0 = offsets[p]
        s1 = offsets[p + 1]
        r = 0.0
        g = 0.0
        b = 0.0
        tr = 1.0
        k = s0
        while k < s1:
            seg = k >> SEG_SHIFT
            e = min((seg + 1) << SEG_SHIFT, s1)
            if occupied[np.int64(segmax[seg]) + 1] == occupied[np.int64(segmin[seg])]:
                k = e
                continue
            for kk in range(k, e):
                q = samples[kk]
                if preint and kk > s0 and samples[kk - 1] != q:
                    i, j = pair_entry(float(samples[kk - 1]), float(q), scale, pscale)
                    if i != j:
                        r += tr * ptable[i, j, 0]
                        g += tr * ptable[i, j, 1]
                        b += tr * ptable[i, j, 2]
                        tr *= 1.0 - ptable[i, j, 3]
                        if tr < t_stop:
                            break
                        continue
                r += tr * plut[q, 0]
                g += tr * plut[q, 1]
                b += tr * plut[q, 2]
                tr *= 1.0 - plut[q, 3]
                if tr < t_stop:
                    break
            if tr < t_stop:
                break
            k = e
        out[p, 0] = r
        out[p, 1] = g
        out[p, 2] = b
        out[p, 3] = 1.0 - tr


@njit(parallel=True, cache=True, fastmath=True)
def composite(
    offsets, samples, diffuse, specular, segmin, segmax, occupied, lut, ptable, preint,
    shade_params, t_stop, out,
):  # fmt: skip
    """Render one TF, shaded, from a sample cache into ``out`` (n_rays, 4) premultiplied RGBA.

    Unshaded caches use :func:`composite_unshaded`.

    ``occupied[k]`` counts LUT entries below k with non-zero alpha, so a segment whose values
    lie in [lo, hi] is empty when ``occupied[hi + 1] == occupied[lo]`` and is skipped whole.

    With ``preint``, a sample is classified with the segment from the ray's previous one, as
    :func:`march` with ``nearest`` does (:func:`_classify`).
    """
    ka, kd, ks = shade_params[0], shade_params[1], shade_params[2]
    inv = 1.0 / 255.0
    scale = lut.shape[0] - 1.0
    pscale = ptable.shape[0] - 1.0
    for p in prange(offsets.shape[0] - 1):
        s0 = offsets[p]
        s1 = offsets[p + 1]
        r = 0.0
        g = 0.0
        b = 0.0
        tr = 1.0
        k = s0
        done = False
        while k < s1 and not done:
            seg = k >> SEG_SHIFT
            e = min((seg + 1) << SEG_SHIFT, s1)
            if occupied[np.int64(segmax[seg]) + 1] == occupied[np.int64(segmin[seg])]:
                k = e
                continue
            for kk in range(k, e):
                q = samples[kk]
                a, cr, cg, cb = lut[q, 3], lut[q, 0], lut[q, 1], lut[q, 2]
                if preint and kk > s0 and samples[kk - 1] != q:
                    i, j = pair_entry(float(samples[kk - 1]), float(q), scale, pscale)
                    if i != j:
                        a, cr, cg, cb = _entry(ptable, i, j)
                if a > 0.0:
                    lit = ka + kd * (diffuse[kk] * inv)
                    sp = ks * (specular[kk] * inv)
                    cr = min(1.0, cr * lit + sp)
                    cg = min(1.0, cg * lit + sp)
                    cb = min(1.0, cb * lit + sp)
                    w = tr * a
                    r += w * cr
                    g += w * cg
                    b += w * cb
                    tr *= 1.0 - a
                    if tr < t_stop:
                        done = True
                        break
            k = e
        out[p, 0] = r
        out[p, 1] = g
        out[p, 2] = b
        out[p, 3] = 1.0 - tr


@njit(parallel=True, cache=True, fastmath=True)
def attribute(
    offsets, samples, segmin, segmax, occupied, alpha, share, ptable, preint, gauss, t_stop,
    out,
):  # fmt: skip
    """Each Gaussian's part of every ray's accumulated opacity, into ``out`` (n_rays, N).

    At each sample the composited opacity ``T * a`` is split in proportion to ``share``
    (L, N): the Gaussians' opacity densities at that value, normalised to sum to one.
    The parts of a ray therefore sum to its alpha (up to float rounding).

    With ``preint``, a sample classified by its segment from the previous one (as
    :func:`composite` does) splits the segment's opacity in proportion to each Gaussian's
    integral over the segment's values (``gauss`` (N, 3): mean, width, height), so a thin
    Gaussian the segment crosses gets its part though neither sample's value shows it.
    """
    ng = share.shape[1]
    scale = alpha.shape[0] - 1.0
    pscale = ptable.shape[0] - 1.0
    for p in prange(offsets.shape[0] - 1):
        s0 = offsets[p]
        s1 = offsets[p + 1]
        tr = 1.0
        k = s0
        done = False
        while k < s1 and not done:
            seg = k >> SEG_SHIFT
            e = min((seg + 1) << SEG_SHIFT, s1)
            if occupied[np.int64(segmax[seg]) + 1] == occupied[np.int64(segmin[seg])]:
                k = e
                continue
            for kk in range(k, e):
                q = samples[kk]
                a = alpha[q]
                i = j = 0
                lo = hi = 0.0
                if preint and kk > s0 and samples[kk - 1] != q:
                    i, j = pair_entry(float(samples[kk - 1]), float(q), scale, pscale)
                    if i != j:
                        a = ptable[i, j, 3]
                if a > 0.0:
                    w = tr * a
                    total = 0.0
                    if i != j:
                        lo = min(i, j) / pscale
                        hi = max(i, j) / pscale
                        for c in range(ng):
                            total += _mass(gauss, c, lo, hi)
                    if total > 0.0:
                        for c in range(ng):
                            out[p, c] += w * _mass(gauss, c, lo, hi) / total
                    else:
                        for c in range(ng):
                            out[p, c] += w * share[q, c]
                    tr *= 1.0 - a
                    if tr < t_stop:
                        done = True
                        break
            k = e


@njit(cache=True, fastmath=True, inline="always")
def _mass(gauss, c, lo, hi):
    """Gaussian c's opacity density integrated over [lo, hi], up to a factor common to all
    Gaussians (sqrt(pi / 2)): ``height * width * (erf(z_hi) - erf(z_lo))``."""
    m, w, h = gauss[c, 0], gauss[c, 1], gauss[c, 2]
    k = 1.0 / (w * 1.4142135623730951)
    return h * w * (math.erf((hi - m) * k) - math.erf((lo - m) * k))


@njit(parallel=True, cache=True)
def to_rgb8(rgba, background, out):
    """Composite premultiplied ``rgba`` (n, 4) over ``background`` into uint8 ``out`` (n, 3)."""
    for p in prange(rgba.shape[0]):
        t = 1.0 - rgba[p, 3]
        for c in range(3):
            v = (rgba[p, c] + t * background[c]) * 255.0 + 0.5
            out[p, c] = np.uint8(min(255.0, max(0.0, v)))
