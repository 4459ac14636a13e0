#!/usr/bin/env python3
# Writes docs/aerial.md's virtual object for `brume insert`: tower.png (sRGB colour,
# straight alpha, 1-px soft edges) and tower_range.pfm (450 m where the object
# is, NaN elsewhere), 800x560 like `brume demo --width 800 --height 560`.
# Standard library only.
import math, struct, sys, zlib

W, H = 800, 560
out = sys.argv[1] if len(sys.argv) > 1 else "."


def png_rgba(path, px):
    raw = b"".join(b"\x00" + bytes(px[y * W * 4:(y + 1) * W * 4]) for y in range(H))
    def chunk(t, d):
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xFFFFFFFF)
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", W, H, 8, 6, 0, 0, 0)) +
                chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


px = bytearray(W * H * 4)
rng = [float("nan")] * (W * H)
cx, half, top, bottom = 470.0, 9.0, 60, 245  # a striped tower, 450 m away
for y in range(top, bottom):
    for x in range(W):
        d = abs(x + 0.5 - cx)
        if d >= half + 1:
            continue
        a = 1.0 if d <= half else half + 1 - d
        t = min(max((x + 0.5 - (cx - half)) / (2 * half), 0.0), 1.0)
        shade = 0.55 + 0.45 * math.sin(math.pi * t)
        col = (0.85, 0.12, 0.08) if ((y - top) // 25) % 2 else (0.93, 0.93, 0.9)
        i = (y * W + x) * 4
        for c in range(3):
            v = col[c] * shade
            v = 12.92 * v if v <= 0.0031308 else 1.055 * v ** (1 / 2.4) - 0.055
            px[i + c] = int(round(255 * min(max(v, 0.0), 1.0)))
        px[i + 3] = int(round(255 * a))
        rng[y * W + x] = 450.0
png_rgba(out + "/tower.png", px)
with open(out + "/tower_range.pfm", "wb") as f:  # PFM: rows bottom to top, little endian
    f.write(b"Pf\n%d %d\n-1.0\n" % (W, H))
    for y in range(H - 1, -1, -1):
        f.write(struct.pack("<%df" % W, *rng[y * W:(y + 1) * W]))
