"""Neighbour centres from one scan: clusters of consecutive returns, each fitted with a circle of
the known body radius (Gauss-Newton on sum (|p - c| - R)^2)."""
import numpy as np
R = 0.25; MAX = 10.0; JUMP = 0.15

def detect(scan, k):
    n = len(scan); ang = 2 * np.pi * np.arange(n) / n
    hit = scan < MAX - 1e-6
    if not hit.any():
        return np.zeros((k, 2)) + 1e3
    pts = np.stack([scan * np.cos(ang), scan * np.sin(ang)], 1)
    # cluster breaks: no hit, or a jump
    brk = ~hit | (np.abs(np.diff(scan, prepend=scan[-1])) > JUMP)
    # rotate so a break is at index 0 (wraparound)
    start = int(np.argmax(brk)) if brk.any() else 0
    idx = np.roll(np.arange(n), -start)
    centres = []
    cur = []
    for i in idx:
        if brk[i] and cur:
            centres.append(cur); cur = []
        if hit[i]:
            cur.append(i)
    if cur: centres.append(cur)
    out = []
    for c in centres:
        if len(c) < 3: continue
        p = pts[c]
        m = p.mean(0); u = m / np.linalg.norm(m)
        x = m + u * R * 0.8
        for _ in range(6):
            d = p - x; dist = np.linalg.norm(d, axis=1)
            res = dist - R; J = -d / dist[:, None]
            x = x - np.linalg.lstsq(J, res, rcond=None)[0]
        out.append(x)
    out = np.array(out) if out else np.zeros((0, 2))
    out = out[np.argsort(np.linalg.norm(out, axis=1))][:k]
    if len(out) < k:
        out = np.concatenate([out, np.zeros((k - len(out), 2)) + 1e3])
    return out
