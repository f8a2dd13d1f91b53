"""Structured probe: f = d* * sum_j w_j s(|x_j|) x_j/|x_j| over the K nearest neighbours x_j
(centres in the robot's frame / d*), w_j from pairwise features with the other K-1 (the
Gabriel veto), s a learned 1-D pair law. Trained end to end on the expert's formation velocity."""
import os, sys, time, numpy as np, torch
from torch import nn
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from pairs_fit import load, labels, relative, slopes
torch.set_num_threads(int(os.environ.get("THREADS", "1")))
K = int(os.environ.get("K", "8"))

import json
def data(path, noise, seed, det=None):
    poses, wheels, aux, z = load(path)
    B, T, N = poses.shape[:3]
    p = poses[..., :2]; th = poses[..., 2]
    d = p[..., None, :, :] - p[..., :, None, :]
    c, s_ = np.cos(th)[..., None], np.sin(th)[..., None]
    rel = np.stack([c * d[..., 0] + s_ * d[..., 1], -s_ * d[..., 0] + c * d[..., 1]], -1)   # (B,T,N,N,2)
    dist = np.linalg.norm(rel, axis=-1) + np.eye(N) * 1e9
    order = np.argsort(dist, -1)[..., :K]                                               # (B,T,N,K)
    rel = np.take_along_axis(rel, order[..., None], -2)
    adj = np.zeros((B, T, N, N), dtype=bool)
    for t_, es in enumerate(json.loads(str(z["edges"]))):
        for b, e in enumerate(es):
            for (i, j) in e:
                adj[b, t_, i, j] = adj[b, t_, j, i] = True
    if noise > 0:
        rel = rel + np.random.default_rng(seed).normal(0, noise, rel.shape)
    gate = np.take_along_axis(adj, order, -1).astype(np.float32)
    gate = np.take_along_axis(adj, order, -1).astype(np.float32)
    if det is not None:
        full = np.stack([c * d[..., 0] + s_ * d[..., 1], -s_ * d[..., 0] + c * d[..., 1]], -1) + (np.eye(N) * 1e6)[..., None]
        rel = np.load(det)[..., :K, :]
        # each detection's true robot: the nearest true centre
        dd = np.linalg.norm(rel[..., :, None, :] - full[..., None, :, :], axis=-1)   # (B,T,N,K,N)
        match = dd.argmin(-1)
        gate = np.take_along_axis(adj, match, -1).astype(np.float32) * (dd.min(-1) < 0.2)
    ds = aux[..., 1:2]
    x = rel / ds[..., None]
    f = labels(wheels, aux)
    keep = np.abs(wheels).max(-1) < 0.9 - 1e-3
    if det is not None and os.environ.get("OWN_GATE"):
        # the robot's own rule applied to what it detected: Gabriel (ratio >= 1.3) or one of its 2 nearest
        r2 = (x ** 2).sum(-1); dk = ((x[..., :, None, :] - x[..., None, :, :]) ** 2).sum(-1)
        ratio = (r2[..., None, :] + dk) / np.maximum(r2[..., :, None], 1e-12) + np.eye(K) * 1e9
        gate = (((ratio.min(-1) >= 1.3) | (np.arange(K) < 2)) & (np.sqrt(r2) < 50)).astype(np.float32)
    t = lambda a: torch.tensor(a[keep], dtype=torch.float32)
    return t(x), t(ds), t(f), t(gate)

class Net(nn.Module):
    def __init__(self, h=32):
        super().__init__()
        self.pair = nn.Sequential(nn.Linear(7, h), nn.ReLU(), nn.Linear(h, h), nn.ReLU())
        self.gate = nn.Sequential(nn.Linear(h + 3 + K, h), nn.ReLU(), nn.Linear(h, h), nn.ReLU(), nn.Linear(h, 1))
        self.law = nn.Sequential(nn.Linear(1, h), nn.ReLU(), nn.Linear(h, h), nn.ReLU(), nn.Linear(h, 1))
    def forward(self, x):                      # x: (B, K, 2)
        r2 = (x ** 2).sum(-1)                  # (B, K)
        r = r2.clamp_min(1e-9).sqrt()
        xj = x[:, :, None, :].expand(-1, -1, K, -1); xk = x[:, None, :, :].expand(-1, K, -1, -1)
        dk = ((xj - xk) ** 2).sum(-1)          # |x_j - x_k|^2
        ratio = (r2[:, None, :] + dk) / r2[:, :, None].clamp_min(1e-9)   # Gabriel witness ratio of k for pair j
        feats = torch.stack([xj[..., 0], xj[..., 1], xk[..., 0], xk[..., 1], r2[:, :, None].expand(-1, -1, K), dk, ratio], -1)
        e = self.pair(feats)
        eye = torch.eye(K, dtype=torch.bool)[None, :, :, None]
        pooled = e.masked_fill(eye, -1e9).max(2).values              # (B, K, h)
        rank = torch.eye(K)[None].expand(x.shape[0], -1, -1)
        w = torch.sigmoid(self.gate(torch.cat([pooled, x, r[..., None], rank], -1)))   # (B, K, 1)
        s = self.law(r[..., None] - 1.0)                             # (B, K, 1)
        w = w * (r < 50)[..., None]
        self.w, self.s = w[..., 0], s[..., 0]
        return (w * s * x / r[..., None]).sum(1)

def train(tr, vals, epochs, eps=0.05):
    torch.manual_seed(0)
    x, ds, f, gate = tr; model = Net()
    PAIR = float(os.environ.get("PAIR", "1")); MAIN = float(os.environ.get("MAIN", "1"))
    r = x.norm(dim=-1); law = 2 * (r ** 4 - 1) / r ** 3   # the pair law in d* units (gain 1.0)
    opt = torch.optim.Adam(model.parameters(), lr=2e-3)
    w = 1.0 / (f.norm(dim=1) + eps); w = w / w.mean(); n = len(x); t0 = time.time()
    for e in range(epochs):
        for g in opt.param_groups: g["lr"] = 2e-3 * 0.5 * (1 + np.cos(np.pi * e / epochs))
        perm = torch.randperm(n)
        for i in range(0, n, 256):
            idx = perm[i:i + 256]
            loss = MAIN * ((model(x[idx]) * ds[idx] - f[idx]) ** 2).sum(1).mul(w[idx]).mean()
            if PAIR:
                bce = nn.functional.binary_cross_entropy(model.w.clamp(1e-6, 1 - 1e-6), gate[idx])
                g = gate[idx] > 0.5
                lawloss = ((model.s - law[idx]) ** 2)[g].mean()
                loss = loss + PAIR * (bce + lawloss)
            opt.zero_grad(); loss.backward(); opt.step()
        if (e + 1) % 5 == 0 or e == epochs - 1:
            with torch.no_grad():
                for name, va in vals.items():
                    p = model(va[0]) * va[1]; acc = ((model.w > 0.5).float() == va[3]).float().mean().item()
                    print(f"  epoch {e+1} {time.time()-t0:.0f}s val[{name}] gate acc {acc:.4f} {slopes(p, va[2])}", flush=True)
    return model

if __name__ == "__main__":
    tn = float(os.environ.get("TRAIN_NOISE", "0"))
    tr = None if os.environ.get("TRAIN_DET") else data(os.environ["TRAIN"], tn, 1)
    vals = {f"{v}": data(os.environ["VAL"], v, 2) for v in [float(s) for s in os.environ.get("VAL_NOISE", "0,0.01").split(",")]}
    if os.environ.get("VAL_DET"):
        vals["detected"] = data(os.environ["VAL"], 0, 2, os.environ["VAL_DET"])
    if os.environ.get("TRAIN_DET"):
        parts = [data(p, 0, 1, d) for p, d in zip(os.environ["TRAIN"].split(","), os.environ["TRAIN_DET"].split(","))]
        tr = tuple(torch.cat([p[i] for p in parts]) for i in range(4))
    print("train", len(tr[0]), flush=True)
    m = train(tr, vals, int(os.environ.get("EPOCHS", "20")))
    if os.environ.get("SAVE"): torch.save(m.state_dict(), os.environ["SAVE"])

def save_if_asked(model):
    if os.environ.get("SAVE"):
        torch.save(model.state_dict(), os.environ["SAVE"])
