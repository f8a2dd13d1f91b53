"""Ceiling probe: detect neighbours in the 300-sector scan, estimate their centres, and see how well
an MLP on the K nearest centres predicts the expert's small corrections."""
import sys, os, time, numpy as np, torch
from torch import nn
sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[3] / "trainer-bridge" / "python"))
from formation_trainer import dataset
from formation_trainer.train import formation_velocity_targets
torch.set_num_threads(1); torch.manual_seed(0)
RHO, K, CLIP = 0.25, int(os.environ.get("K", "8")), 3.0

def features(s):
    out = []
    for i in range(0, len(s.ranges), 40000):
        out.append(features_of(s.ranges[i:i+40000], s.aux[i:i+40000]))
    return np.concatenate(out)

def features_of(ranges, aux):
    r = ranges.astype(np.float64); n, S = r.shape; dstar = aux[:, 1].astype(np.float64)
    rm = r * dstar[:, None]                              # metres
    valid = r < CLIP - 1e-4
    jump = np.abs(np.diff(rm, axis=1, prepend=rm[:, :1])) > 0.15
    start = valid & (~np.roll(valid, 1, axis=1) | jump); start[:, 0] = valid[:, 0]
    cid = np.cumsum(start, axis=1) * valid               # 0 = no cluster
    gid = (np.arange(n)[:, None] * (S + 1) + cid)[valid]
    sec = np.broadcast_to(np.arange(S), (n, S))[valid]
    G = n * (S + 1)
    cnt = np.bincount(gid, minlength=G); first = np.full(G, S, np.int64); np.minimum.at(first, gid, sec)
    last = np.full(G, -1, np.int64); np.maximum.at(last, gid, sec)
    centre = (first + last) / 2.0                        # in sectors
    alpha = (sec - centre[gid]) * 2 * np.pi / S
    rv = rm[valid]
    disc = RHO ** 2 - (rv * np.sin(alpha)) ** 2
    ok = disc >= 0
    dest = rv * np.cos(alpha) + np.sqrt(np.clip(disc, 0, None))
    dsum = np.bincount(gid[ok], weights=dest[ok], minlength=G); dn = np.bincount(gid[ok], minlength=G)
    has = dn > 0
    D = np.where(has, dsum / np.maximum(dn, 1), np.inf)
    if os.environ.get("MIN_RANGE"):
        dmin = np.full(G, np.inf); np.minimum.at(dmin, gid, rv)
        D = np.where(np.isfinite(dmin), dmin + RHO, np.inf)
    th = centre * 2 * np.pi / S
    D = D.reshape(n, S + 1); th = th.reshape(n, S + 1)
    order = np.argsort(D, axis=1)[:, :K]
    Dk = np.take_along_axis(D, order, 1); tk = np.take_along_axis(th, order, 1)
    present = np.isfinite(Dk)
    Dn = np.where(present, Dk, 0) / dstar[:, None]
    x = Dn * np.cos(tk); y = Dn * np.sin(tk)
    return np.concatenate([x, y, present.astype(np.float64), aux.astype(np.float64)], 1).astype(np.float32)

def prep(path):
    s = dataset.load([path]); f = formation_velocity_targets(s.wheels, s.aux, 0.7)
    keep = np.abs(s.wheels).max(1) < np.abs(s.wheels).max() - 1e-3
    if os.environ.get("POLICY_ONLY"): keep &= s.iteration > 0
    t = time.time(); x = features(s); print("features", path, x.shape, f"{time.time()-t:.0f}s", flush=True)
    return torch.from_numpy(x[keep]), torch.from_numpy(f[keep])
tr = prep(os.environ["TRAIN"]); va = prep(os.environ["VAL"])
def slopes(model, x, l):
    with torch.no_grad(): p = model(x).double()
    l = l.double(); m = l.norm(dim=1); out = {}
    for lo, hi in [(0.05, 0.1), (0.1, 0.2), (0.2, 0.4), (0.4, 0.8)]:
        sel = (m >= lo) & (m < hi)
        out[f"{lo}-{hi}"] = (int(sel.sum()), round(float((p[sel]*l[sel]).sum()/(l[sel]**2).sum()), 3), round(float(((p[sel]-l[sel])**2).sum(1).mean().sqrt()), 4))
    return out
model = nn.Sequential(nn.Linear(tr[0].shape[1], 256), nn.ReLU(), nn.Linear(256, 256), nn.ReLU(), nn.Linear(256, 2))
opt = torch.optim.Adam(model.parameters(), lr=1e-3)
w = 1 / (tr[1].norm(dim=1) + 0.05); w = w / w.mean(); n = len(tr[0])
for e in range(int(os.environ.get("EPOCHS", "8"))):
    for g in opt.param_groups: g["lr"] = 1e-3 * 0.6 ** e
    perm = torch.randperm(n)
    for i in range(0, n, 256):
        idx = perm[i:i+256]
        loss = ((model(tr[0][idx]) - tr[1][idx]) ** 2).sum(1).mul(w[idx]).mean()
        opt.zero_grad(); loss.backward(); opt.step()
    print("epoch", e + 1, slopes(model, *va), flush=True)
