# Placement and pixel checks for georef_placement.sh (numpy). Subcommands:
#
#   compare OURS.bil REF.bil W H BANDS LO HI NAME [NODATA_COLS]
#       OURS: RGBA8 from `vts extract`; REF: gdalwarp's Float32 BANDS colour bands + alpha on the
#       same grid. REF's values are mapped to 0..255 as --range LO,HI does. Checks transparency,
#       colours, and measures the sub-texel shift of OURS against REF; prints one line
#       "NAME: shift dx dy ..." and exits 1 when a bound is exceeded.
#   calibrate OURS.bil REF_SHIFTED.bil W H BANDS WANT_DX WANT_DY
#       The measurement itself: REF_SHIFTED is gdalwarp's reference on a grid moved by a known
#       fraction of a texel, and OURS rolled by one whole texel; both must measure what was done.
#
# Shift: ours(x, y) ~ ref(x + dx, y + dy), in texels (x east, y south). Estimated by iterated
# least squares (Lucas-Kanade): ref is resampled at (x + dx, y + dy) with a Keys cubic, and the
# residual ours - ref' is fitted by gx * ddx + gy * ddy over the texels opaque in both, at least
# 4 texels inside the opaque area and the grid, and textured (the top half by gradient).
import sys

import numpy as np

BOUND = 0.25  # texels; see georef_placement.sh's header


def load(ours_path, ref_path, w, h, bands):
    ours = np.fromfile(ours_path, dtype=np.uint8)
    assert ours.size == w * h * 4, (ours_path, ours.size, w, h)
    ours = ours.reshape(h, w, 4).astype(np.float64)
    ref = np.fromfile(ref_path, dtype="<f4")
    assert ref.size == w * h * (bands + 1), (ref_path, ref.size, w, h, bands)
    ref = ref.reshape(h, w, bands + 1).astype(np.float64)
    if bands == 1:
        ref = np.concatenate([ref[:, :, :1]] * 3 + [ref[:, :, 1:]], axis=2)
    return ours, ref


def to_codes(ref, lo, hi):
    out = ref.copy()
    out[:, :, :3] = np.clip((ref[:, :, :3] - lo) * (255.0 / (hi - lo)), 0, 255)
    return out


def cubic_shift(a, d, axis):
    """a sampled at i + d along axis (Keys cubic, a = -0.5; edges wrap, masked out later)."""
    i = int(np.floor(d))
    f = d - i
    t = np.array([1 + f, f, 1 - f, 2 - f])
    w = np.where(t <= 1, 1.5 * t**3 - 2.5 * t**2 + 1, -0.5 * t**3 + 2.5 * t**2 - 4 * t + 2)
    out = np.zeros_like(a)
    for k, wk in zip((-1, 0, 1, 2), w):
        out += wk * np.roll(a, -(i + k), axis=axis)
    return out


def erode(m, n):
    m = m.copy()
    m[:n, :] = m[-n:, :] = False
    m[:, :n] = m[:, -n:] = False
    for _ in range(n):
        e = m.copy()
        e[1:, :] &= m[:-1, :]
        e[:-1, :] &= m[1:, :]
        e[:, 1:] &= m[:, :-1]
        e[:, :-1] &= m[:, 1:]
        m = e
    return m


def measure(ours, ref, opaque):
    """(dx, dy, texels): the shift of ours against ref (H x W x 3 colour), over opaque texels."""
    m = erode(opaque, 4)
    ys, xs = np.nonzero(m)
    assert ys.size >= 2000, ("too few opaque interior texels to measure a shift", int(ys.size))
    y0, y1, x0, x1 = max(ys.min() - 8, 0), ys.max() + 9, max(xs.min() - 8, 0), xs.max() + 9
    m, ours = m[y0:y1, x0:x1], ours[y0:y1, x0:x1].mean(axis=2)
    ref = g = ref[y0:y1, x0:x1].mean(axis=2)
    gx = np.zeros_like(g)
    gy = np.zeros_like(g)
    gx[:, 1:-1] = (g[:, 2:] - g[:, :-2]) / 2
    gy[1:-1, :] = (g[2:, :] - g[:-2, :]) / 2
    mag = np.hypot(gx, gy)
    m &= mag >= np.median(mag[m])
    dx = dy = 0.0
    for _ in range(12):
        r = cubic_shift(cubic_shift(ref, dx, 1), dy, 0)
        rx = np.zeros_like(r)
        ry = np.zeros_like(r)
        rx[:, 1:-1] = (r[:, 2:] - r[:, :-2]) / 2
        ry[1:-1, :] = (r[2:, :] - r[:-2, :]) / 2
        A = np.stack([rx[m].ravel(), ry[m].ravel()], axis=1)
        b = (ours[m] - r[m]).ravel()
        (ddx, ddy), *_ = np.linalg.lstsq(A, b, rcond=None)
        dx, dy = dx + ddx, dy + ddy
        if abs(ddx) < 1e-4 and abs(ddy) < 1e-4:
            break
    return dx, dy, int(m.sum())


def compare(argv):
    ours_p, ref_p, w, h, bands, lo, hi, name = argv[:8]
    w, h, bands, lo, hi = int(w), int(h), int(bands), float(lo), float(hi)
    ours, ref = load(ours_p, ref_p, w, h, bands)
    ref = to_codes(ref, lo, hi)
    oa, ra = ours[:, :, 3], ref[:, :, 3]
    # Ours rounds alpha to 8 bits: transparent exactly where gdalwarp's alpha is below 0.5.
    alpha_bad = int(((oa > 0) != (ra >= 0.5)).sum())
    opaque = (oa == 255) & (ra >= 254.5)
    n = int(opaque.sum())
    assert n >= 5000, (name, "too few texels opaque in both", n)
    # Colours against gdalwarp's rounded to codes, as its 8-bit output would be.
    d = np.abs(ours[:, :, :3] - np.floor(ref[:, :, :3] + 0.5))[opaque]
    mean, p99 = float(d.mean()), float(np.percentile(d, 99))
    dx, dy, used = measure(ours[:, :, :3], ref[:, :, :3], opaque)
    print(f"{name}: shift dx {dx:+.4f} dy {dy:+.4f} texels (|shift| {np.hypot(dx, dy):.4f}, over "
          f"{used} textured texels); colours over {n} opaque texels: mean |diff| {mean:.3f}, "
          f"p99 {p99:.2f}; alpha disagrees on {alpha_bad} of {w * h}")
    ok = True
    if np.hypot(dx, dy) > BOUND:
        print(f"{name}: placed {np.hypot(dx, dy):.3f} texels from gdalwarp's (bound {BOUND})")
        ok = False
    if mean > 1.0 or p99 > 4:
        print(f"{name}: colours differ from gdalwarp's (mean {mean:.3f} > 1 or p99 {p99} > 4)")
        ok = False
    if alpha_bad > 0.002 * w * h:
        print(f"{name}: transparency differs from gdalwarp's on {alpha_bad} texels")
        ok = False
    if len(argv) > 8:  # NODATA_COLS C0,C1: columns the input's nodata covers, all transparent
        c0, c1 = map(int, argv[8].split(","))
        rows = np.nonzero(ra.max(axis=1) >= 0.5)[0]  # the rows the input covers
        seen = oa[rows, c0 + 2 : c1 - 2]
        if seen.size == 0 or seen.max() != 0:
            print(f"{name}: the nodata columns {c0}..{c1} are not transparent")
            ok = False
    return 0 if ok else 1


def calibrate(argv):
    ours_p, ref_p, w, h, bands, want_dx, want_dy = argv
    w, h, bands, want_dx, want_dy = int(w), int(h), int(bands), float(want_dx), float(want_dy)
    ours, ref = load(ours_p, ref_p, w, h, bands)
    ref = to_codes(ref, 0, 255)
    opaque = (ours[:, :, 3] == 255) & (ref[:, :, 3] >= 254.5)
    ok = True
    dx, dy, _ = measure(ours[:, :, :3], ref[:, :, :3], opaque)
    err = np.hypot(dx - want_dx, dy - want_dy)
    print(f"calibration: gdalwarp's reference on a moved grid: want dx {want_dx:+.2f} "
          f"dy {want_dy:+.2f}, measured dx {dx:+.4f} dy {dy:+.4f} (error {err:.4f})")
    ok &= err <= 0.05
    # Ours moved one texel west and one north: ours'(x, y) = ours(x + 1, y + 1).
    rolled = np.roll(np.roll(ours, -1, axis=1), -1, axis=0)
    op2 = np.roll(np.roll(opaque, -1, axis=1), -1, axis=0) & opaque
    dx1, dy1, _ = measure(rolled[:, :, :3], ours[:, :, :3], op2)
    print(f"calibration: ours moved by (+1, +1) texel measures dx {dx1:+.4f} dy {dy1:+.4f}")
    ok &= np.hypot(dx1 - 1, dy1 - 1) <= 0.05
    if not ok:
        print("calibration: the shift measurement does not measure known shifts")
    return 0 if ok else 1


if __name__ == "__main__":
    cmd, args = sys.argv[1], sys.argv[2:]
    sys.exit(compare(args) if cmd == "compare" else calibrate(args))
