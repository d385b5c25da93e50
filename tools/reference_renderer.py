#!/usr/bin/python3
"""Independent reference renderer for d2gs's rasterizer golden tests (NumPy only, float64).

Implements the conventions of the original 3DGS rasterizer (docs/rendering.md, method.md §2) from
scratch, without tiles for compositing: every pixel composites the depth-sorted Gaussians front to
back (vectorised over pixels, one Gaussian at a time). The only tile notion kept is the original's
getRect culling (a Gaussian is evaluated only at pixels whose 16x16 tile lies in its rectangle), which
is part of the convention. Writes small random scenes and the expected images as fixtures:

    /usr/bin/python3 tools/reference_renderer.py tests/render/fixtures

Each scene folder holds float32 .npy inputs (means N×3, log_scales N×3, quats N×4 (w,x,y,z),
opacity_logits N, sh_dc N×3, sh_rest N×15×3, multiplier N), camera.json (width, height, fx, fy, cx, cy
with pixel centres at +0.5, R_world_to_cam row-major, t_world_to_cam, background, sh_degree) and the
expected outputs rgb H×W×3, alpha H×W, depth H×W (float32) and radii N (int32).
"""
import json
import os
import sys

import numpy as np

TILE = 16
C0 = 0.28209479177387814
C1 = 0.4886025119029199
C2 = [1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396]
C3 = [-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
      -0.4570457994644658, 1.445305721320277, -0.5900435899266435]


def sh_colour(degree, dc, rest, d):
    """RGB = SH(d) + 0.5 clamped at 0; dc (3,), rest (15,3), d unit (3,)."""
    x, y, z = d
    b = [C0]
    if degree >= 1:
        b += [-C1 * y, C1 * z, -C1 * x]
    if degree >= 2:
        xx, yy, zz = x * x, y * y, z * z
        b += [C2[0] * x * y, C2[1] * y * z, C2[2] * (2 * zz - xx - yy), C2[3] * x * z, C2[4] * (xx - yy)]
    if degree >= 3:
        b += [C3[0] * y * (3 * xx - yy), C3[1] * x * y * z, C3[2] * y * (4 * zz - xx - yy),
              C3[3] * z * (2 * zz - 3 * xx - 3 * yy), C3[4] * x * (4 * zz - xx - yy), C3[5] * z * (xx - yy),
              C3[6] * x * (xx - 3 * yy)]
    coeffs = np.concatenate([dc[None, :], rest], axis=0)[: len(b)]
    rgb = np.asarray(b) @ coeffs + 0.5
    return np.maximum(rgb, 0.0)


def quat_to_matrix(q):
    w, x, y, z = q / max(np.linalg.norm(q), 1e-12)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def render(scene, cam):
    W, H = cam["width"], cam["height"]
    fx, fy, cx, cy = cam["fx"], cam["fy"], cam["cx"], cam["cy"]
    R = np.asarray(cam["R_world_to_cam"], np.float64).reshape(3, 3)
    t = np.asarray(cam["t_world_to_cam"], np.float64)
    bg = np.asarray(cam["background"], np.float64)
    degree = cam["sh_degree"]
    campos = -R.T @ t
    tiles_x, tiles_y = (W + TILE - 1) // TILE, (H + TILE - 1) // TILE
    # Jacobian clamp limits (general principal point; +-1.3 tan(fov/2) when cx = W/2).
    tan_x, tan_y = 0.5 * W / fx, 0.5 * H / fy
    lim_x = (-(cx / fx + 0.3 * tan_x), (W - cx) / fx + 0.3 * tan_x)
    lim_y = (-(cy / fy + 0.3 * tan_y), (H - cy) / fy + 0.3 * tan_y)

    means = scene["means"].astype(np.float64)
    n = means.shape[0]
    radii = np.zeros(n, np.int32)
    items = []  # (depth, index, mean2d, conic, opacity, colour, rect)
    for i in range(n):
        pc = R @ means[i] + t
        if pc[2] <= 0.2:
            continue
        Rq = quat_to_matrix(scene["quats"][i].astype(np.float64))
        S = np.diag(np.exp(scene["log_scales"][i].astype(np.float64)))
        sigma = Rq @ S @ S.T @ Rq.T
        u = min(max(pc[0] / pc[2], lim_x[0]), lim_x[1])
        v = min(max(pc[1] / pc[2], lim_y[0]), lim_y[1])
        J = np.array([[fx / pc[2], 0.0, -fx * u / pc[2]], [0.0, fy / pc[2], -fy * v / pc[2]]])
        cov = J @ R @ sigma @ R.T @ J.T + 0.3 * np.eye(2)
        det = cov[0, 0] * cov[1, 1] - cov[0, 1] ** 2
        if det <= 0:
            continue
        conic = np.array([cov[1, 1], -cov[0, 1], cov[0, 0]]) / det
        mid = 0.5 * (cov[0, 0] + cov[1, 1])
        lam = mid + np.sqrt(max(0.1, mid * mid - det))
        radius = int(np.ceil(3.0 * np.sqrt(lam)))
        # Original pixel frame: pixel (i, j) is evaluated at the integer point (i, j).
        m2 = np.array([fx * pc[0] / pc[2] + cx - 0.5, fy * pc[1] / pc[2] + cy - 0.5])
        rect = (min(tiles_x, max(0, int((m2[0] - radius) / TILE))),
                min(tiles_y, max(0, int((m2[1] - radius) / TILE))),
                min(tiles_x, max(0, int((m2[0] + radius + TILE - 1) / TILE))),
                min(tiles_y, max(0, int((m2[1] + radius + TILE - 1) / TILE))))
        if (rect[2] - rect[0]) * (rect[3] - rect[1]) == 0:
            continue
        radii[i] = radius
        d = means[i] - campos
        d = d / np.linalg.norm(d)
        colour = sh_colour(degree, scene["sh_dc"][i].astype(np.float64), scene["sh_rest"][i].astype(np.float64), d)
        opacity = 1.0 / (1.0 + np.exp(-float(scene["opacity_logits"][i]))) * float(scene["multiplier"][i])
        items.append((np.float32(pc[2]), i, m2, conic, opacity, colour, pc[2], rect))
    # Front to back by (float32) depth, ties by index (a stable sort).
    items.sort(key=lambda it: (it[0], it[1]))

    px, py = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    tile_x, tile_y = px.astype(int) // TILE, py.astype(int) // TILE
    T = np.ones((H, W))
    C = np.zeros((H, W, 3))
    D = np.zeros((H, W))
    done = np.zeros((H, W), bool)
    for _, _, m2, conic, opacity, colour, z, rect in items:
        in_rect = (tile_x >= rect[0]) & (tile_x < rect[2]) & (tile_y >= rect[1]) & (tile_y < rect[3])
        dx, dy = m2[0] - px, m2[1] - py
        power = -0.5 * (conic[0] * dx * dx + conic[2] * dy * dy) - conic[1] * dx * dy
        alpha = np.minimum(0.99, opacity * np.exp(power))
        ok = in_rect & ~done & (power <= 0) & (alpha >= 1.0 / 255.0)
        test_T = T * (1 - alpha)
        stop = ok & (test_T < 1e-4)
        done |= stop
        comp = ok & ~stop
        w = np.where(comp, alpha * T, 0.0)
        C += w[..., None] * colour
        D += w * z
        T = np.where(comp, test_T, T)
    rgb = C + T[..., None] * bg
    return rgb, 1.0 - T, D, radii


def random_scene(seed, n, W, H, degree=3):
    rng = np.random.default_rng(seed)
    fx, fy = 0.9 * W, 0.92 * W
    cx, cy = 0.5 * W + 5.3, 0.5 * H - 3.7  # off-centre principal point
    ang = 0.12
    Rz = np.array([[np.cos(ang), -np.sin(ang), 0], [np.sin(ang), np.cos(ang), 0], [0, 0, 1]])
    Rx = np.array([[1, 0, 0], [0, np.cos(-ang), -np.sin(-ang)], [0, np.sin(-ang), np.cos(-ang)]])
    R = Rz @ Rx
    centre = np.array([0.1, -0.05, -0.3])
    t = -R @ centre
    z = np.where(rng.random(n) < 0.05, rng.uniform(0.0, 0.2, n), 1.0 + 8.0 * rng.random(n) ** 2)
    xc = rng.uniform(-0.8, 0.8, n) * z * W / fx
    yc = rng.uniform(-0.8, 0.8, n) * z * H / fy
    pc = np.stack([xc, yc, z], axis=1)
    means = (pc - t) @ R  # R^T (pc - t)
    log_scales = np.log(z[:, None] * rng.uniform(1.0, 6.0, (n, 1)) / fx) + 0.4 * rng.standard_normal((n, 3))
    quats = rng.standard_normal((n, 4)) + np.array([1.0, 0, 0, 0])
    opacity = rng.uniform(0.05, 0.995, n)
    scene = {
        "means": means,
        "log_scales": log_scales,
        "quats": quats,
        "opacity_logits": np.log(opacity / (1 - opacity)),
        "sh_dc": 0.2 + 0.8 * rng.standard_normal((n, 3)),
        "sh_rest": 0.2 * rng.standard_normal((n, 15, 3)),
        "multiplier": np.where(rng.random(n) < 0.1, 0.0, np.where(rng.random(n) < 0.1, 0.5, 1.0)),
    }
    scene = {k: v.astype(np.float32) for k, v in scene.items()}
    cam = {"width": W, "height": H, "fx": fx, "fy": fy, "cx": cx, "cy": cy,
           "R_world_to_cam": [float(v) for v in R.astype(np.float32).reshape(-1)],
           "t_world_to_cam": [float(v) for v in t.astype(np.float32)],
           "sh_degree": degree}
    return scene, cam


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..", "tests", "render", "fixtures")
    configs = [(1, 300, 64, 48, 3, [0.0, 0.0, 0.0]), (2, 250, 61, 45, 2, [0.25, 0.5, 1.0])]
    for seed, n, W, H, degree, bg in configs:
        scene, cam = random_scene(seed, n, W, H, degree)
        cam["background"] = bg
        rgb, alpha, depth, radii = render(scene, cam)
        folder = os.path.join(out, f"scene{seed}")
        os.makedirs(folder, exist_ok=True)
        for k, v in scene.items():
            np.save(os.path.join(folder, k + ".npy"), v)
        with open(os.path.join(folder, "camera.json"), "w") as f:
            json.dump(cam, f, indent=1)
        np.save(os.path.join(folder, "rgb.npy"), rgb.astype(np.float32))
        np.save(os.path.join(folder, "alpha.npy"), alpha.astype(np.float32))
        np.save(os.path.join(folder, "depth.npy"), depth.astype(np.float32))
        np.save(os.path.join(folder, "radii.npy"), radii)
        print(f"{folder}: {n} Gaussians, {int((radii > 0).sum())} visible, mean alpha {alpha.mean():.3f}")


if __name__ == "__main__":
    main()
