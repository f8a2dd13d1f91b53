"""Generate expert states at N robots with ground-truth poses, scans and labels (probe data)."""
import sys, json, numpy as np, time
from formation import Batch, Scenario, EpisodeOver
scen_path, out, seed, runs, every = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
sc = Scenario(scen_path)
b = Batch(sc, [seed] * runs, list(range(runs)), expert=True)
spec = json.loads(b.spec_json(0))
P, S, W, A, G, E = [], [], [], [], [], []
t0 = time.time(); tick = 0
while True:
    wheels = b.expert_actions()
    if tick % every == 0 and tick > 0:
        P.append(b.poses().astype(np.float32)); S.append(b.scans().astype(np.float16))
        W.append(wheels.astype(np.float32)); A.append(b.aux("delta_phi,d_star")); G.append(b.goals())
        E.append([b.edges(w) for w in range(runs)])
    try:
        b.step(wheels)
    except EpisodeOver:
        break
    tick += 1
    if b.over:
        break
np.savez(out, poses=np.stack(P, 1), scans=np.stack(S, 1), wheels=np.stack(W, 1), aux=np.stack(A, 1), goals=np.stack(G, 1), spec=json.dumps(spec), edges=np.array(json.dumps(E)))
print("ticks", tick, "samples", len(P), "s", time.time() - t0)
