"""Closed loop: every robot driven by the pair network on the neighbours it detects in its own
scan, against the expert on the same runs; success from the world's own metrics."""
import os, sys, json, time, numpy as np, torch
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from pairs_pairnet import Net, K
from pairs_circles import detect
from formation import Batch, Scenario, EpisodeOver
scen, n, runs, seed, ctl = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
dur = float(os.environ.get("DURATION", "60"))
sc = Scenario(scen, robots=n, overrides={"duration_s": dur})
first = int(os.environ.get("FIRST", "0")); record = os.environ.get("RECORD")
b = Batch(sc, [seed] * runs, list(range(first, first + runs)), expert=(ctl == "expert" or bool(record)))
REC = {k: [] for k in ["poses", "scans", "wheels", "aux", "goals", "edges"]}; tick = 0
model = None
def analytic(x):
    x = torch.as_tensor(x, dtype=torch.float64)
    r2 = (x ** 2).sum(-1); r = r2.sqrt()
    dk = ((x[:, :, None, :] - x[:, None, :, :]) ** 2).sum(-1)
    ratio = (r2[:, None, :] + dk) / r2[:, :, None]
    ratio = ratio + torch.eye(x.shape[1])[None] * 1e9
    gate = (ratio.min(-1).values >= 1.3) | (torch.arange(x.shape[1])[None] < 2)
    gate = gate & (r < 50)
    law = 2 * (r ** 4 - 1) / r ** 3
    return (gate[..., None] * law[..., None] * x / r[..., None]).sum(1).float()
if ctl == "analytic":
    model = analytic
elif ctl.startswith("gate:"):
    net = Net(); net.load_state_dict(torch.load(ctl[5:])); net.eval()
    def model(x):
        net(x); r = x.norm(dim=-1).clamp_min(1e-9)
        law = 2 * (r ** 4 - 1) / r ** 3
        return ((net.w > 0.5).float() * (r < 50) * law)[..., None].mul(x / r[..., None]).sum(1)
elif ctl != "expert":
    model = Net(); model.load_state_dict(torch.load(ctl)); model.eval()

t0 = time.time()
while not b.over:
    if model is None:
        act = b.expert_actions()
    else:
        scans = b.scans(); aux = b.aux("delta_phi,d_star")
        x = np.zeros((runs, n, K, 2), dtype=np.float32)
        for w in range(runs):
            for i in range(n):
                x[w, i] = detect(scans[w, i].astype(np.float64), K) / aux[w, i, 1]
        with torch.no_grad():
            f = model(torch.from_numpy(x.reshape(-1, K, 2))).numpy().reshape(runs, n, 2) * aux[..., 1:2]
        act = b.policy_actions(np.ascontiguousarray(f, dtype=np.float32), float(sc.v_star), "formation_velocity")
    if record and tick % 5 == 0 and tick > 0:
        REC["poses"].append(b.poses().astype(np.float32)); REC["scans"].append(b.scans().astype(np.float16))
        REC["wheels"].append(b.expert_actions().astype(np.float32)); REC["aux"].append(b.aux("delta_phi,d_star"))
        REC["goals"].append(b.goals()); REC["edges"].append([b.edges(w) for w in range(runs)])
    tick += 1
    try:
        b.step(act)
    except EpisodeOver:
        break
if record:
    np.savez(record, **{k: np.stack(v, 1) for k, v in REC.items() if k != "edges"}, edges=np.array(json.dumps(REC["edges"])))
ms = [json.loads(b.metrics_json(w)) for w in range(runs)]
s5=np.mean([m["success_5"] for m in ms]); s10=np.mean([m["success_10"] for m in ms]); conv=[m["convergence_s_10"] for m in ms]
print("success5", s5, "success10", s10, "conv10", conv, "collisions", sum(m["collisions"] for m in ms))
print(ctl, n, f"{time.time()-t0:.0f}s")
