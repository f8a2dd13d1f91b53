"""Every robot's detected neighbours for a probe dataset (pairs_gen.py): pairs_circles.detect on each scan."""
import os
import sys, numpy as np, time
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from pairs_circles import detect
src, out, k = sys.argv[1], sys.argv[2], int(sys.argv[3])
z = np.load(src); S = z['scans']
B, T, N, _ = S.shape; res = np.zeros((B, T, N, k, 2)); t0 = time.time()
for b in range(B):
    for t in range(T):
        for i in range(N):
            res[b, t, i] = detect(S[b, t, i].astype(np.float64), k)
np.save(out, res); print('done', time.time() - t0)
