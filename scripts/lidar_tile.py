"""A synthetic aerial LiDAR tile in UTM metres, written by laspy (LAS 1.4,
point format 7: RGB, intensity, ASPRS classes, a WKT CRS): rolling ground,
flat-roofed and gabled buildings with walls, and round tree crowns, sampled
at the given density (points per square metre) like an airborne scanner
(mostly from above, sparser on walls).

    python lidar_tile.py OUT.laz --size 500 --density 4
    python lidar_tile.py OUT.laz --size 500 --density 60 --crop 200 220 50

--ply OUT.ply also writes every third point (positions about the tile's centre,
colours) as a PLY of points, for scripts/blender_points.py.

--crop X Y SIZE samples only the square [X, X+SIZE] x [Y, Y+SIZE] of the same
tile (the same buildings and trees), at the given density.

The tile's south-west corner is at (500000, 4100000) in EPSG:32633.
"""
import argparse

import laspy
import numpy as np

WKT = ('PROJCS["WGS 84 / UTM zone 33N",GEOGCS["WGS 84",DATUM["WGS_1984",SPHEROID["WGS 84",6378137,298.257223563]],'
       'PRIMEM["Greenwich",0],UNIT["degree",0.0174532925199433]],PROJECTION["Transverse_Mercator"],'
       'PARAMETER["central_meridian",15],PARAMETER["scale_factor",0.9996],PARAMETER["false_easting",500000],'
       'UNIT["metre",1],AUTHORITY["EPSG","32633"]]')
X0, Y0, Z0 = 500000.0, 4100000.0, 120.0


def ground(x, y, size):
    s = size / 500.0
    return 6 * np.sin(x / (90 * s)) * np.cos(y / (70 * s)) + 3 * np.sin((x + 2 * y) / (40 * s)) + 0.3 * np.sin(x / 3.1) * np.sin(y / 2.7)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--size", type=float, default=500.0, help="tile side, metres")
    ap.add_argument("--density", type=float, default=4.0, help="points per square metre")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--crop", type=float, nargs=3, metavar=("X", "Y", "SIZE"))
    ap.add_argument("--ply", help="also write every third point as a PLY of points")
    a = ap.parse_args()
    L = a.size
    cx0, cy0, cs = a.crop if a.crop else (0.0, 0.0, L)
    # The scene (buildings, trees) from its own stream, the samples from
    # another: a crop holds the same scene.
    scene = np.random.default_rng(a.seed)
    rng = np.random.default_rng(a.seed + 1000)
    n = int(cs * cs * a.density)
    x, y = cx0 + rng.uniform(0, cs, n), cy0 + rng.uniform(0, cs, n)
    z = ground(x, y, L)
    cls = np.full(n, 2, np.uint8)
    rgb = np.stack([110 + 30 * rng.random(n), 120 + 30 * rng.random(n), 70 + 20 * rng.random(n)], 1)
    # Buildings on a jittered grid: footprints 8-25 m, heights 5-18 m.
    nb = max(1, int((L / 60) ** 2))  # per tile
    walls = []
    for _ in range(nb):
        cx, cy = scene.uniform(0.1 * L, 0.9 * L, 2)
        w, d = scene.uniform(8, 25, 2)
        h = scene.uniform(5, 18)
        gable = scene.random() < 0.5
        inside = (np.abs(x - cx) < w / 2) & (np.abs(y - cy) < d / 2)
        base = ground(np.array([cx]), np.array([cy]), L)[0]
        roof = base + h + (np.where(gable, 0.35 * (w / 2 - np.abs(x - cx)), 0))
        z = np.where(inside, roof, z)
        cls[inside] = 6
        rgb[inside] = [160, 70, 55] if gable else [150, 150, 150]
        # Walls: sparser (the scanner sees them at a grazing angle).
        per = int(2 * (w + d) * h * a.density * 0.3)
        t = rng.uniform(0, 2 * (w + d), per)
        wx = np.where(t < w, cx - w / 2 + t, np.where(t < w + d, cx + w / 2, np.where(t < 2 * w + d, cx + w / 2 - (t - w - d), cx - w / 2)))
        wy = np.where(t < w, cy - d / 2, np.where(t < w + d, cy - d / 2 + (t - w), np.where(t < 2 * w + d, cy + d / 2, cy + d / 2 - (t - 2 * w - d))))
        wz = base + rng.uniform(0, h, per)
        walls.append((wx, wy, wz, np.full(per, 6, np.uint8), np.tile([200, 190, 170], (per, 1))))
    # Trees: crowns as noisy spheres above the ground.
    nt = int((L / 25) ** 2)
    trees = []
    for _ in range(nt):
        cx, cy = scene.uniform(0, L, 2)
        r = scene.uniform(2, 5)
        top = ground(np.array([cx]), np.array([cy]), L)[0] + scene.uniform(6, 14)
        per = int(np.pi * r * r * a.density * 1.5)
        u, v = rng.normal(size=(2, per)), rng.normal(size=per)
        d = np.stack([u[0], u[1], np.abs(v) * 0.8 + 0.2], 1)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        p = np.array([cx, cy, top - r]) + d * r * rng.uniform(0.85, 1.0, (per, 1))
        trees.append((p[:, 0], p[:, 1], p[:, 2], np.full(per, 5, np.uint8), np.stack([40 + 30 * rng.random(per), 100 + 50 * rng.random(per), 40 + 20 * rng.random(per)], 1)))
    parts = [(x, y, z, cls, rgb)] + walls + trees
    X = np.concatenate([p[0] for p in parts])
    Y = np.concatenate([p[1] for p in parts])
    Zs = np.concatenate([p[2] for p in parts])
    C = np.concatenate([p[3] for p in parts])
    RGB = np.concatenate([p[4] for p in parts]).clip(0, 255)
    keep = (X >= cx0) & (X <= cx0 + cs) & (Y >= cy0) & (Y <= cy0 + cs)
    X, Y, Zs, C, RGB = X[keep], Y[keep], Zs[keep], C[keep], RGB[keep]

    header = laspy.LasHeader(point_format=7, version="1.4")
    header.offsets = [X0, Y0, Z0]
    header.scales = [0.001, 0.001, 0.001]
    header.add_crs = None
    header.vlrs.append(laspy.vlrs.known.WktCoordinateSystemVlr(WKT))
    header.global_encoding.wkt = True
    las = laspy.LasData(header)
    las.x, las.y, las.z = X + X0, Y + Y0, Zs + Z0
    las.classification = C
    las.intensity = (np.where(C == 2, 900, np.where(C == 6, 1500, 600)) + 200 * rng.random(len(X))).astype(np.uint16)
    las.red, las.green, las.blue = [(RGB[:, k] * 257).astype(np.uint16) for k in range(3)]
    las.return_number = np.ones(len(X), np.uint8)
    las.number_of_returns = np.ones(len(X), np.uint8)
    las.write(a.out)
    if a.ply:
        keep3 = np.arange(0, len(X), 3)
        P = np.stack([X, Y, Zs], 1)[keep3]
        P -= P.mean(0)
        rec = np.zeros(len(keep3), dtype=[("p", "<f4", 3), ("c", "u1", 3)])
        rec["p"], rec["c"] = P, RGB[keep3].astype(np.uint8)
        head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(keep3)}\nproperty float x\nproperty float y\nproperty float z\n"
                "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n")
        with open(a.ply, "wb") as f:
            f.write(head.encode() + rec.tobytes())
    print(f"{a.out}: {len(X)} points, {cs:g} x {cs:g} m" + (f" of a {L:g} m tile" if a.crop else "") + f", {nb} buildings and {nt} trees in the tile")


if __name__ == "__main__":
    main()
