#!/usr/bin/env python3
"""Pictures of a LiDAR scan clear and foggy, for the docs (issue #41):

  bev   a bird's-eye view of the clear and the foggy scan side by side: each
        point at its (x, y) in the sensor's frame, coloured by intensity;
        the points `brume lidar fog` moved to the fog's peak (fog returns)
        drawn in magenta.
  proj  the camera image with the scan projected over it, clear (the clear
        image and scan) above foggy (the foggy image and scan), each point
        coloured by inverse range (turbo: near red, far blue), fog returns in
        magenta. KITTI's projection: x_img = P2 · R0_rect · Tr_velo_to_cam · x.

  python3 scripts/lidar_picture.py bev CLEAR.bin FOGGY.bin OUT.png [--title T]
  python3 scripts/lidar_picture.py proj CLEAR.bin FOGGY.bin CALIB.txt CLEAR_IMG FOGGY_IMG OUT.jpg

A point is a fog return when its position changed (the model moves a point
only along its beam, to the soft peak; an attenuated hard return keeps x, y,
z bit for bit).
"""
import argparse

import numpy as np
from matplotlib import cm
from PIL import Image, ImageDraw

FOG_RGB = (255, 0, 255)


def read_bin(path):
    a = np.fromfile(path, dtype="<f4")
    if a.size % 4:
        raise SystemExit(f"{path}: {a.size * 4} bytes is not a KITTI .bin (16 bytes a point)")
    return a.reshape(-1, 4)


def moved_points(a, clear, foggy):
    """The output's points that moved: by the effect's labels (one byte per input point: 0 kept,
    1 moved, 2 lost; the output holds those not lost) when given, else by comparing the scans."""
    if not a.labels:
        return moved_to_fog(clear, foggy)
    labels = np.fromfile(a.labels, dtype=np.uint8)
    if len(labels) != len(clear) or (labels != 2).sum() != len(foggy):
        raise SystemExit(f"{a.labels}: {len(labels)} labels do not match the scans ({len(clear)} and "
                         f"{len(foggy)} points)")
    return labels[labels != 2] == 1


def moved_to_fog(clear, foggy):
    if clear.shape != foggy.shape:
        raise SystemExit(f"the scans differ in point count: {len(clear)} and {len(foggy)}")
    return np.any(clear[:, :3] != foggy[:, :3], axis=1)


def read_calib(path):
    rows = {}
    for line in open(path):
        if ":" in line:
            k, v = line.split(":", 1)
            rows[k.strip()] = np.array([float(x) for x in v.split()])
    p2 = rows["P2"].reshape(3, 4)
    r0 = np.eye(4)
    r0[:3, :3] = rows["R0_rect"].reshape(3, 3)
    tr = np.eye(4)
    tr[:3, :4] = rows["Tr_velo_to_cam"].reshape(3, 4)
    return p2 @ r0 @ tr


def bev(a):
    clear, foggy = read_bin(a.clear), read_bin(a.foggy)
    fog = moved_points(a, clear, foggy)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(12, 6.2), sharex=True, sharey=True)
    for ax, pts, name in ((axes[0], clear, "clear"), (axes[1], foggy, a.title or "foggy")):
        hard = ~fog if pts is foggy else np.ones(len(pts), bool)
        ax.scatter(pts[hard, 0], pts[hard, 1], s=0.3, c=np.clip(pts[hard, 3], 0, 1), cmap="viridis",
                   vmin=0, vmax=1, linewidths=0)
        if pts is foggy and fog.any():
            ax.scatter(pts[fog, 0], pts[fog, 1], s=1.5, c=[np.array(FOG_RGB) / 255], linewidths=0,
                       label=f"{a.echoes} ({fog.sum()} of {len(pts)})")
            ax.legend(loc="upper right", markerscale=6)
        ax.set_title(name)
        ax.set_aspect("equal")
        ax.set_xlim(-5, a.range)
        ax.set_ylim(-a.range / 2, a.range / 2)
        ax.set_xlabel("x (forward) [m]")
    axes[0].set_ylabel("y (left) [m]")
    fig.tight_layout()
    fig.savefig(a.out, dpi=a.dpi)


def project(img_path, pts, fog, m, near, far):
    img = Image.open(img_path).convert("RGB")
    w, h = img.size
    x = np.c_[pts[:, :3], np.ones(len(pts))] @ m.T
    front = x[:, 2] > 0.1
    u, v = x[:, 0] / np.where(front, x[:, 2], 1), x[:, 1] / np.where(front, x[:, 2], 1)
    r = np.linalg.norm(pts[:, :3], axis=1)
    inside = front & (u >= 0) & (u < w) & (v >= 0) & (v < h)
    t = np.clip((1 / np.maximum(r, 1e-3) - 1 / far) / (1 / near - 1 / far), 0, 1)
    rgb = (cm.turbo(t)[:, :3] * 255 + 0.5).astype(np.uint8)
    d = ImageDraw.Draw(img)
    order = np.argsort(-r)  # far first: near points drawn over them
    for i in order[inside[order]]:
        c = FOG_RGB if fog[i] else tuple(int(k) for k in rgb[i])
        d.rectangle([u[i] - 1, v[i] - 1, u[i] + 1, v[i] + 1], fill=c)
    return img


def proj(a):
    clear, foggy = read_bin(a.clear), read_bin(a.foggy)
    fog = moved_points(a, clear, foggy)
    m = read_calib(a.calib)
    top = project(a.clear_image, clear, np.zeros(len(clear), bool), m, a.near, a.far)
    bottom = project(a.foggy_image, foggy, fog, m, a.near, a.far)
    out = Image.new("RGB", (top.width, top.height + bottom.height + 8), (255, 255, 255))
    out.paste(top, (0, 0))
    out.paste(bottom, (0, top.height + 8))
    out.save(a.out, quality=70)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="kind", required=True)
    b = sub.add_parser("bev")
    b.add_argument("clear")
    b.add_argument("foggy")
    b.add_argument("out")
    b.add_argument("--title", default="")
    b.add_argument("--range", type=float, default=60.0, help="metres shown ahead of the sensor")
    b.add_argument("--dpi", type=int, default=100)
    b.add_argument("--echoes", default="fog returns", help="the legend's name of the moved points")
    b.add_argument("--labels", default="", help="the effect's labels (--labels): points lost, points moved")
    p = sub.add_parser("proj")
    for k in ("clear", "foggy", "calib", "clear_image", "foggy_image", "out"):
        p.add_argument(k)
    p.add_argument("--near", type=float, default=4.0, help="range [m] at the red end")
    p.add_argument("--far", type=float, default=80.0, help="range [m] at the blue end")
    p.add_argument("--labels", default="", help="the effect's labels (--labels): points lost, points moved")
    a = ap.parse_args()
    bev(a) if a.kind == "bev" else proj(a)


if __name__ == "__main__":
    main()
