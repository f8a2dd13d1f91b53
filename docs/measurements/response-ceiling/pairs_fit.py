"""Fit an MLP to the expert's formation velocity from neighbours' relative positions (exact, noisy
or detected from the scan) and report the gauge's slope by bin on held-out runs."""
import sys, os, time, json, numpy as np, torch
from torch import nn
torch.set_num_threads(int(os.environ.get("THREADS", "1")))
K = int(os.environ.get("K", "8")); V = 0.7
BINS = [(0.05, 0.1), (0.1, 0.2), (0.2, 0.4), (0.4, 0.8)]

def load(path):
    z = np.load(path)
    poses = z["poses"].astype(np.float64)      # (B, T, N, 3)
    wheels = z["wheels"].astype(np.float64)    # (B, T, N, 2)
    aux = z["aux"].astype(np.float64)          # (B, T, N, 2)
    return poses, wheels, aux, z

def labels(wheels, aux):
    dphi = aux[..., 0]
    ux = (wheels[..., 0] + wheels[..., 1]) / 2; uy = (wheels[..., 1] - wheels[..., 0]) / 2
    return np.stack([ux - V * np.cos(dphi), uy - V * np.sin(dphi)], -1)

def relative(poses, noise, rng):
    """Others' centres in each robot's frame, (B, T, N, N-1, 2), sorted by distance."""
    p = poses[..., :2]; th = poses[..., 2]
    d = p[..., None, :, :] - p[..., :, None, :]          # d[..., i, j] = p_j - p_i
    c, s = np.cos(th)[..., None], np.sin(th)[..., None]
    x = c * d[..., 0] + s * d[..., 1]; y = -s * d[..., 0] + c * d[..., 1]
    rel = np.stack([x, y], -1)
    n = rel.shape[-2]
    mask = ~np.eye(n, dtype=bool)
    rel = rel[..., mask, :].reshape(*rel.shape[:-3], n, n - 1, 2)
    if noise > 0:
        rel = rel + rng.normal(0, noise, rel.shape)
    order = np.argsort(np.linalg.norm(rel, axis=-1), axis=-1)
    return np.take_along_axis(rel, order[..., None], axis=-2)

def features(path, noise, seed):
    poses, wheels, aux, z = load(path)
    rng = np.random.default_rng(seed)
    rel = relative(poses, noise, rng)[..., :K, :]
    dstar = aux[..., 1:2]
    x = (rel / dstar[..., None]).reshape(*rel.shape[:-2], 2 * K)
    f = labels(wheels, aux)
    keep = np.abs(wheels).max(-1) < 0.9 - 1e-3
    x, f, dstar = x[keep], f[keep], dstar[keep]
    return torch.tensor(x, dtype=torch.float32), torch.tensor(dstar, dtype=torch.float32), torch.tensor(f, dtype=torch.float32)

def slopes(p, l):
    p = p.double(); l = l.double(); m = l.norm(dim=1); out = {}
    for lo, hi in BINS:
        sel = (m >= lo) & (m < hi); n = int(sel.sum())
        out[f"{lo}-{hi}"] = (n, round(float((p[sel] * l[sel]).sum() / (l[sel] ** 2).sum()), 3) if n else None)
    return out

def fit(tr, va, epochs, eps=0.05):
    torch.manual_seed(0)
    x, ds, f = tr
    model = nn.Sequential(nn.Linear(x.shape[1], 256), nn.ReLU(), nn.Linear(256, 256), nn.ReLU(), nn.Linear(256, 256), nn.ReLU(), nn.Linear(256, 2))
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    w = 1.0 / (f.norm(dim=1) + eps); w = w / w.mean()
    n = len(x); t0 = time.time()
    for e in range(epochs):
        for g in opt.param_groups: g["lr"] = 1e-3 * 0.5 * (1 + np.cos(np.pi * e / epochs))
        perm = torch.randperm(n)
        for i in range(0, n, 256):
            idx = perm[i:i + 256]
            loss = ((model(x[idx]) * ds[idx] - f[idx]) ** 2).sum(1).mul(w[idx]).mean()
            opt.zero_grad(); loss.backward(); opt.step()
        if e == epochs - 1 or (e + 1) % 5 == 0:
            with torch.no_grad():
                p = model(va[0]) * va[1]
            print(f"  epoch {e+1} {time.time()-t0:.0f}s val {slopes(p, va[2])}", flush=True)
    return model

if __name__ == "__main__":
    for noise in [float(v) for v in os.environ.get("NOISE", "0,0.005,0.01,0.02").split(",")]:
        tr = features(os.environ["TRAIN"], noise, 1); va = features(os.environ["VAL"], noise, 2)
        print(f"noise {noise} m: train {len(tr[0])} val {len(va[0])}", flush=True)
        fit(tr, va, int(os.environ.get("EPOCHS", "20")))
