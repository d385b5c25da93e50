#!/usr/bin/python3
"""Independent SSIM reference for tests/train: a direct (non-separable) 2-D implementation in NumPy of
the 3DGS `ssim()` (11x11 Gaussian window, sigma 1.5, zero padding "same", C1 = 0.01^2, C2 = 0.03^2,
mean over C*H*W). Writes tests/train/fixtures/ssim_{a,b}.npy (H x W x 3 float32) and ssim_value.npy.

Run: /usr/bin/python3 tools/make_ssim_fixture.py
"""
import pathlib
import numpy as np

def window():
    x = np.arange(11) - 5
    g = np.exp(-(x ** 2) / (2 * 1.5 ** 2))
    g /= g.sum()
    return np.outer(g, g)

def filt(img, w):
    h, wd = img.shape
    pad = np.zeros((h + 10, wd + 10))
    pad[5:-5, 5:-5] = img
    out = np.zeros((h, wd))
    for dy in range(11):
        for dx in range(11):
            out += w[dy, dx] * pad[dy:dy + h, dx:dx + wd]
    return out

def ssim(a, b):
    w = window()
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    maps = []
    for c in range(a.shape[2]):
        x, y = a[..., c].astype(np.float64), b[..., c].astype(np.float64)
        mx, my = filt(x, w), filt(y, w)
        sxx = filt(x * x, w) - mx * mx
        syy = filt(y * y, w) - my * my
        sxy = filt(x * y, w) - mx * my
        maps.append(((2 * mx * my + c1) * (2 * sxy + c2)) / ((mx ** 2 + my ** 2 + c1) * (sxx + syy + c2)))
    return float(np.mean(maps))

def main():
    rng = np.random.default_rng(7)
    h, w = 29, 37
    yy, xx = np.mgrid[0:h, 0:w]
    base = np.stack([0.5 + 0.4 * np.sin(xx / 5.0 + c) * np.cos(yy / 7.0) for c in range(3)], axis=-1)
    a = np.clip(base + 0.05 * rng.standard_normal(base.shape), 0, 1).astype(np.float32)
    b = np.clip(base + 0.10 * rng.standard_normal(base.shape), 0, 1).astype(np.float32)
    out = pathlib.Path(__file__).resolve().parent.parent / "tests/train/fixtures"
    out.mkdir(parents=True, exist_ok=True)
    np.save(out / "ssim_a.npy", a)
    np.save(out / "ssim_b.npy", b)
    np.save(out / "ssim_value.npy", np.array([ssim(a, b), ssim(a, a)], dtype=np.float64))
    print("ssim(a,b) =", ssim(a, b))

if __name__ == "__main__":
    main()
