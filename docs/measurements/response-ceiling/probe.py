"""Offline probe: which network reads small corrections from a robot's own view? Trains candidates
on expert states (unshaped labels, formation velocity) and reports the gauge's binned slope on
held-out runs."""
import sys, time, json, os
import numpy as np, torch
from torch import nn
sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[3] / "trainer-bridge" / "python"))
from formation_trainer import dataset
from formation_trainer.train import formation_velocity_targets
from formation_trainer.model import PolicyNet

torch.set_num_threads(int(sys.argv[2]) if len(sys.argv) > 2 else 2)
torch.manual_seed(0)
V_TRAIN = 0.7
def prep(path):
    s = dataset.load([path])
    f = formation_velocity_targets(s.wheels, s.aux, V_TRAIN)
    if os.environ.get("UNSAT"):
        keep = np.abs(s.wheels).max(1) < np.abs(s.wheels).max() - 1e-3
        return (torch.from_numpy(s.occupancy[keep]), torch.from_numpy(s.aux[keep]), torch.from_numpy(s.ranges[keep]), torch.from_numpy(f[keep]))
    return (torch.from_numpy(s.occupancy), torch.from_numpy(s.aux), torch.from_numpy(s.ranges), torch.from_numpy(f))
import os
tr = prep(os.environ["TRAIN"]); va = prep(os.environ["VAL"])
print("train", len(tr[0]), "val", len(va[0]), flush=True)

class Circ(nn.Module):
    def __init__(self, k, ch, feat, kernel=5):
        super().__init__()
        self.conv = nn.Conv1d(1, ch, kernel, padding=kernel // 2, padding_mode="circular")
        self.lin = nn.Linear(ch * k, feat)
    def forward(self, r):
        return torch.relu(self.lin(torch.relu(self.conv(r.unsqueeze(1))).flatten(1)))

class RangesOnly(nn.Module):
    def __init__(self, branch, width):
        super().__init__()
        self.branch = branch
        self.head = nn.Sequential(nn.Linear(width + 2, 256), nn.ReLU(), nn.Linear(256, 256), nn.ReLU(), nn.Linear(256, 2))
    def forward(self, occ, aux, r):
        return self.head(torch.cat([self.branch(r), aux], 1))

class ImagePlus(nn.Module):
    def __init__(self, branch, width):
        super().__init__()
        base = PolicyNet(50, "wide-head")
        self.features = base.features
        self.branch = branch
        self.head = nn.Sequential(nn.Linear(144 + 2 + width, 256), nn.ReLU(), nn.Linear(256, 256), nn.ReLU(), nn.Linear(256, 2))
    def forward(self, occ, aux, r):
        return self.head(torch.cat([self.features(occ), aux, self.branch(r)], 1))

def lin64():
    return nn.Sequential(nn.Linear(100, 64), nn.ReLU())

CANDIDATES = {
    "image+lin64": lambda: ImagePlus(lin64(), 64),
    "ranges-lin64": lambda: RangesOnly(lin64(), 64),
    "ranges-circ4": lambda: RangesOnly(Circ(100, 4, 64), 64),
    "image+circ4": lambda: ImagePlus(Circ(100, 4, 64), 64),
}

def batch(t, idx):
    occ = t[0][idx].unsqueeze(1).float() if t[0].dtype == torch.uint8 else t[0][idx]
    return occ, t[1][idx], t[2][idx], t[3][idx]

def slopes(model, t):
    model.eval(); ps = []
    with torch.no_grad():
        for i in range(0, len(t[0]), 4096):
            idx = torch.arange(i, min(i + 4096, len(t[0])))
            occ, aux, r, f = batch(t, idx)
            ps.append(model(occ, aux, r))
    p = torch.cat(ps).double(); l = t[3].double(); m = l.norm(dim=1)
    out = {}
    for lo, hi in [(0.05, 0.1), (0.1, 0.2), (0.2, 0.4), (0.4, 0.8)]:
        sel = (m >= lo) & (m < hi)
        n = int(sel.sum())
        s = float((p[sel] * l[sel]).sum() / (l[sel] ** 2).sum()) if n else float("nan")
        rms = float(((p[sel] - l[sel]) ** 2).sum(1).mean().sqrt()) if n else float("nan")
        out[f"{lo}-{hi}"] = (n, round(s, 3), round(rms, 4))
    model.train()
    return out

def train(name, epochs, eps=0.05, lr=1e-3, bs=128):
    model = CANDIDATES[name]()
    macs = sum(p.numel() for p in model.parameters())
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    n = len(tr[0]); w_all = 1.0 / (tr[3].norm(dim=1) + eps); w_all = w_all / w_all.mean()
    t0 = time.time()
    for e in range(epochs):
        perm = torch.randperm(n)
        for g in opt.param_groups: g["lr"] = lr * (0.5 ** e)
        for i in range(0, n, bs):
            idx = perm[i:i + bs]
            occ, aux, r, f = batch(tr, idx)
            loss = ((model(occ, aux, r) - f) ** 2).sum(1).mul(w_all[idx]).mean()
            opt.zero_grad(); loss.backward(); opt.step()
        print(name, "epoch", e + 1, f"{time.time() - t0:.0f}s", "val", slopes(model, va), flush=True)
    return model

for name in sys.argv[1].split(","):
    train(name, int(sys.argv[3]) if len(sys.argv) > 3 else 4)
